"""The OPA surrogate: what an OPA run says about each sampled system.

An OPA run of any number of elements K and any law of xi defines, on element k,

    x_hat(t, xi) = sum_j x_j^(k)(t) phi_j^(k)(xi),     xi in [e_k, e_{k+1}],

with ``phi_j^(k)`` the orthonormal polynomials of xi's conditional law on the element (the
Chebyshev polynomials U_j for the paper's single-element semicircle OPA), and likewise
``v_hat`` from the velocity coefficients. Its moments follow exactly from the
coefficients: ``E[x_hat] = sum_k P_k x_0^(k)`` (the run's ``x_mean``) and
``E[x_hat^2] = sum_k P_k sum_j (x_j^(k))^2`` (``x_var + x_mean^2``).

Evaluated at the same xi as a true sampled system, the surrogate gives the paired
difference ``x(t, xi) - x_hat(t, xi)`` that certifies the run (``compare.verify``).
"""

from __future__ import annotations

import numpy as np

from opa._basis import chebyshev_u
from opa._dataset import check_opa_layout
from opa._measure import Measure, parse


def run_measure(ds) -> Measure:
    """The law of xi an OPA run was computed for, rebuilt from its ``distribution``
    attribute (a chaospy law, named but not stored, is refused)."""
    name = ds.attrs.get("distribution", "semicircle")
    try:
        return parse(name)
    except ValueError:
        raise ValueError(f"the run's law of xi {name!r} cannot be rebuilt from its name "
                         f"(a chaospy distribution): pass it as measure=") from None


def surrogate(ds, xi, *, measure: Measure | None = None) -> tuple[np.ndarray, np.ndarray]:
    """x_hat(t, xi) and v_hat(t, xi) of an OPA run at the points ``xi``.

    Parameters
    ----------
    ds : an OPA dataset (:func:`opa.simulate_opa`, any number of elements, any law).
    xi : (M,) points of the uncertain variable inside the law's support.
    measure : the law of xi (default: rebuilt from ``ds.attrs["distribution"]``).

    Returns
    -------
    (x_hat, v_hat), each (M, T).

    Examples
    --------
    >>> import opa
    >>> ds = opa.simulate_opa(opa.Oscillator(), sigma=0.01, order=2, periods=1)
    >>> x_hat, _ = surrogate(ds, [0.0])
    >>> float(abs(x_hat[0, 0] - ds.x0))   # every sample starts at x0
    0.0
    """
    check_opa_layout(ds)
    measure = run_measure(ds) if measure is None else measure
    xi = np.atleast_1d(np.asarray(xi, dtype=float))
    if xi.ndim != 1 or not np.isfinite(xi).all():
        raise ValueError("xi must be a finite 1-D array of points of the uncertain variable")
    edges = ds.element_edges.values
    if xi.size and (xi.min() < edges[0] or xi.max() > edges[-1]):
        raise ValueError(f"xi must lie in the law's support [{edges[0]:g}, {edges[-1]:g}], "
                         f"got values in [{xi.min():g}, {xi.max():g}]")
    x_coef, v_coef = ds.element_x_coef.values, ds.element_v_coef.values  # (K, N+1, T)
    order = x_coef.shape[1] - 1
    x_hat = np.empty((xi.size, x_coef.shape[2]))
    v_hat = np.empty_like(x_hat)
    # the element of each point: the last edge closes the last element
    which = np.clip(np.searchsorted(edges, xi, side="right") - 1, 0, len(edges) - 2)
    single_semicircle = (len(edges) == 2 and measure.name == "semicircle"
                         and ds.attrs.get("distribution", "semicircle") == "semicircle")
    for k in np.unique(which):
        here = which == k
        if single_semicircle:  # the closed-form basis the single-element OPA runs in
            phi = chebyshev_u(order, xi[here])
        else:
            phi = measure.restrict(float(edges[k]), float(edges[k + 1])).basis(order, xi[here])
        x_hat[here] = phi.T @ x_coef[k]
        v_hat[here] = phi.T @ v_coef[k]
    return x_hat, v_hat


def surrogate_moments(ds) -> dict[str, np.ndarray]:
    """Exact E[x_hat], E[x_hat^2], E[v_hat], E[v_hat^2] over time from the coefficients."""
    check_opa_layout(ds)
    P = ds.element_probability.values
    P = P / P.sum()
    out = {}
    for name in ("x", "v"):
        coef = ds[f"element_{name}_coef"].values
        out[f"{name}_mean"] = P @ coef[:, 0]
        out[f"{name}_second"] = P @ (coef**2).sum(axis=1)
    return out


__all__ = ["run_measure", "surrogate", "surrogate_moments"]
