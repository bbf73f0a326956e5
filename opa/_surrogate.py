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
    closed = (len(edges) == 2 and measure.name == "semicircle"
              and ds.attrs.get("distribution", "semicircle") == "semicircle")
    return (surrogate_values(x_coef, edges, measure, xi, closed_form=closed),
            surrogate_values(v_coef, edges, measure, xi, closed_form=closed))


def surrogate_values(coef: np.ndarray, edges, measure: Measure, xi: np.ndarray, *,
             closed_form: bool = False) -> np.ndarray:
    """``sum_j coef[k, j] phi_j^(k)(xi)`` at the points ``xi`` (M,): (M, T).

    ``coef`` (K, N+1, T): the coefficients of K elements cut at ``edges`` (K + 1), each in
    the orthonormal basis of ``measure`` conditioned on its element; ``closed_form``: one
    element in the Chebyshev polynomials U_j (the paper's single-element semicircle OPA).
    A point on an inner edge belongs to the element on its right; the last edge closes
    the last element. NaN coefficients (a run that stopped) give NaN from there on.

    >>> coef = np.array([[[1.0], [2.0]]])        # x_hat = 1 + 2 U_1(xi) = 1 + 4 xi
    >>> surrogate_values(coef, [-1.0, 1.0], None, np.array([0.5]), closed_form=True)
    array([[3.]])
    """
    coef = np.asarray(coef, dtype=float)
    edges = np.asarray(edges, dtype=float)
    order = coef.shape[1] - 1
    out = np.empty((xi.size, coef.shape[2]))
    which = np.clip(np.searchsorted(edges, xi, side="right") - 1, 0, len(edges) - 2)
    for k in np.unique(which):
        here = which == k
        if closed_form:
            phi = chebyshev_u(order, xi[here])
        else:
            phi = measure.restrict(float(edges[k]), float(edges[k + 1])).basis(order, xi[here])
        out[here] = phi.T @ coef[k]
    return out


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


def surrogate_several(ds, measures, xi, state: str = "x") -> np.ndarray:
    """x_hat (M, T) of an OPA run of several uncertain parameters (:mod:`opa._galerkin`,
    :mod:`opa._boxes`) at the points ``xi`` (M, d), ``measures`` the marginals of xi: the
    expansion over ``multi_index``, on each box in its own conditional basis (a point on
    a shared side belongs to the first box listed); ``state`` "v": v_hat.

    >>> import opa
    >>> system = opa.System(uncertain="mu,c", sigma=0.01, order=2)
    >>> ds = opa.simulate_opa(system, periods=1)
    >>> x_hat = surrogate_several(ds, system.problem.measures, np.zeros((1, 2)))
    >>> float(abs(x_hat[0, 0] - ds.x0))   # every sample starts at x0
    0.0
    """
    from opa._boxes import Box
    from opa._chaos import ChaosBasis

    xi = np.asarray(xi, dtype=float)
    if xi.ndim != 2 or xi.shape[1] != len(measures) or not np.isfinite(xi).all():
        raise ValueError(f"xi must be a finite array of shape (M, {len(measures)})")
    indices = ds.multi_index.values
    if "element_lower" not in ds:
        return ChaosBasis(tuple(measures), indices).evaluate(xi) @ ds[f"{state}_coef"].values
    out = np.full((len(xi), ds.sizes["time"]), np.nan)
    lower, upper = ds.element_lower.values, ds.element_upper.values
    taken = np.zeros(len(xi), dtype=bool)
    for e in range(ds.sizes["element"]):
        inside = ~taken & np.all((xi >= lower[e]) & (xi <= upper[e]), axis=1)
        if inside.any():
            box = Box(tuple(lower[e]), tuple(upper[e])).measures(measures)
            out[inside] = ChaosBasis(box, indices).evaluate(xi[inside]) \
                @ ds[f"element_{state}_coef"].values[e]
            taken |= inside
    return out


__all__ = ["run_measure", "surrogate", "surrogate_moments", "surrogate_several",
           "surrogate_values"]
