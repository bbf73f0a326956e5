"""An OPA run as the control variate of a Monte Carlo ensemble: ``simulate_mc(control=run)``.

The run's surrogate x_hat(t, xi) = sum_j x_j(t) phi_j(xi) (:func:`opa.engine.surrogate`)
has exact moments E[x_hat], E[x_hat^2] (:func:`opa.engine.surrogate_moments`). Over the
same scrambled Sobol' points as the ensemble, replicate r gives

    E_cv[x]_r = E[x_hat] + mean_r(x) - mean_r(x_hat)
    Var_cv[x]_r = E[x_hat^2] + mean_r(x^2) - mean_r(x_hat^2) - E_cv[x]_r^2

unbiased for E[x] (and Var[x] up to the replicate's own mean's variance), and the spread
of the R replicate estimates over sqrt(R) is their standard error, as for the plain
estimates (Glasserman 2004, ch. 4). Only replicate means are needed: those of x and x^2
are the ensemble's streamed sums, those of x_hat and x_hat^2 follow from the points, so
memory stays O(R T) whatever M.
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from opa.engine import (PARAMETER_NAMES, check_opa_layout, run_measure, surrogate,
                        surrogate_moments, surrogate_several)

#: points whose surrogate values are formed at once (memory: this many x T doubles)
CHUNK = 4096


def cv_estimates(x1, x2, mean, second, h1, h2) -> dict:
    """Per-replicate control-variate estimates from the replicate means of x and x^2
    (``x1``, ``x2``) and of x_hat and x_hat^2 (``h1``, ``h2``), all (R, T), with the exact
    E[x_hat] = ``mean`` and E[x_hat^2] = ``second`` (T,). Returns ``d`` = E[x - x_hat],
    ``mean`` = E_cv[x], ``var`` = Var_cv[x], each with ``<name>_se``: the spread of the R
    replicate estimates over sqrt(R).

    >>> one = np.ones((4, 1))
    >>> est = cv_estimates(one, one, np.ones(1), np.ones(1), one, one)
    >>> float(est["mean"][0]), float(est["var"][0]), float(est["mean_se"][0])
    (1.0, 0.0, 0.0)
    """
    R = x1.shape[0]
    d = x1 - h1
    mean_r = mean + d
    var_r = second + (x2 - h2) - mean_r**2
    out = {}
    for name, per_replicate in (("d", d), ("mean", mean_r), ("var", var_r)):
        out[name] = per_replicate.mean(axis=0)
        out[f"{name}_se"] = per_replicate.std(axis=0, ddof=1) / math.sqrt(R)
    return out


def check_control(control, system, times: np.ndarray | None) -> np.ndarray:
    """The output times of an ensemble controlled by ``control`` (its own when ``times``
    is None), after checking that it is an OPA run of the ensemble's system: every
    oscillator parameter, sigma, the uncertain parameter and the law of xi, named when
    they differ."""
    if not isinstance(control, xr.Dataset):
        raise ValueError(f"control must be an OPA run (an xarray Dataset of simulate_opa), "
                         f"got {type(control).__name__}")
    if system.dimension > 1:
        _check_several(control, system)
    else:
        check_opa_layout(control, "control")
    if "failure" in control.attrs:
        raise ValueError(f"control: the run did not complete ({control.attrs['failure']})")
    attrs = control.attrs
    ours = {name: float(getattr(system.oscillator, name)) for name in PARAMETER_NAMES}
    for name, value in system.oscillator.law_attrs().items():  # the force law too
        if str(attrs.get(name, "")) != value:
            raise ValueError(f"control: {name} = {str(attrs.get(name, 'none'))!r:.60} in the "
                             f"run, {value!r:.60} in the ensemble")
    if "force_law" in attrs and system.oscillator.force is None:
        raise ValueError(f"control: the run has the force law {attrs['force_law']!r:.60}, the "
                         f"ensemble the paper's")
    if system.dimension == 1:
        ours.update(sigma=float(system.sigma))
    for name, value in ours.items():
        if name in attrs and not math.isclose(float(attrs[name]), value, rel_tol=0.0,
                                              abs_tol=1e-15 * max(1.0, abs(value))):
            raise ValueError(f"control: {name} = {float(attrs[name]):g} in the run, "
                             f"{value:g} in the ensemble")
    for name, value in (() if system.dimension > 1 else (
            ("uncertain", system.uncertain),
            ("distribution", "semicircle" if system.semicircle else system.measure.name))):
        if str(attrs.get(name, "semicircle" if name == "distribution" else "")) != value:
            raise ValueError(f"control: {name} = {attrs.get(name)!r} in the run, {value!r} "
                             f"in the ensemble")
    own = control.time.values
    if times is None:
        return own
    times = np.asarray(times, dtype=float)
    if times.shape != own.shape or not np.allclose(times, own, rtol=1e-12, atol=0.0):
        raise ValueError(f"control: the run's {len(own)} output times differ from the "
                         f"ensemble's {len(times)}: pass times=control.time.values")
    return own


def _check_several(control: xr.Dataset, system) -> None:
    """A control run of several uncertain parameters: the same names, scales and laws."""
    attrs, problem = control.attrs, system.problem
    for name in ("multi_index", "x_mean", "x_var"):
        if name not in control:
            raise ValueError(f"control lacks {name}: it is not an OPA run of several "
                             f"uncertain parameters")
    ours = problem.attrs()
    if str(attrs.get("uncertain")) != ours["uncertain"] or \
            str(attrs.get("distribution")) != ours["distribution"]:
        raise ValueError(f"control: uncertain = {attrs.get('uncertain')!r} with laws "
                         f"{attrs.get('distribution')!r} in the run, {ours['uncertain']!r} "
                         f"with {ours['distribution']!r} in the ensemble")
    sigma = np.atleast_1d(np.asarray(attrs.get("sigma", np.nan), dtype=float))
    if sigma.shape != ours["sigma"].shape or not np.allclose(sigma, ours["sigma"], rtol=0.0,
                                                             atol=1e-15):
        raise ValueError(f"control: sigma = {sigma.tolist()} in the run, "
                         f"{ours['sigma'].tolist()} in the ensemble")


def controlled(ds: xr.Dataset, x_rep, x2_rep, rep_weight, xi: np.ndarray, replicates: int,
               control: xr.Dataset, problem=None) -> xr.Dataset:
    """``ds`` (the ensemble) with the control-variate estimates ``cv_x_mean``,
    ``cv_x_var`` and their standard errors, and the attributes ``variance_reduction``
    (the squared standard error of E[x] without the control over that with it, summed
    over the outputs: how many times fewer runs the control needs for the same error)
    and ``control`` (the run in words)."""
    R = replicates
    n = len(xi) // R
    weight = np.asarray(rep_weight, float)[:, None]
    x1, x2 = x_rep / weight, x2_rep / weight
    several = problem is not None and problem.dimension > 1
    measure = None if several else run_measure(control)
    T = x1.shape[1]
    h1, h2 = np.zeros((R, T)), np.zeros((R, T))
    for r in range(R):
        for lo in range(r * n, (r + 1) * n, CHUNK):
            hi = min(lo + CHUNK, (r + 1) * n)
            x_hat = (surrogate_several(control, problem.measures, xi[lo:hi]) if several
                     else surrogate(control, xi[lo:hi], measure=measure)[0])
            h1[r] += x_hat.sum(axis=0)
            h2[r] += (x_hat**2).sum(axis=0)
    h1, h2 = h1 / n, h2 / n
    moments = (surrogate_moments(control) if not several else
               {"x_mean": control.x_mean.values,
                "x_second": control.x_var.values + control.x_mean.values ** 2})
    est = cv_estimates(x1, x2, moments["x_mean"], moments["x_second"], h1, h2)
    one = {"units": "1"}
    out = ds.copy()
    out["cv_x_mean"] = ("time", est["mean"], {
        "long_name": "control-variate estimate of E[x] (OPA surrogate + paired "
                     "differences)", **one})
    out["cv_x_mean_sem"] = ("time", est["mean_se"], {
        "long_name": "standard error of cv_x_mean", **one})
    out["cv_x_var"] = ("time", est["var"], {"long_name": "control-variate estimate of "
                                                         "Var[x]", **one})
    out["cv_x_var_sem"] = ("time", est["var_se"], {"long_name": "standard error of cv_x_var",
                                                   **one})
    plain = float(np.sum(ds.x_sem.values**2))
    paired = float(np.sum(est["mean_se"] ** 2))
    elements = int(control.sizes.get("element", 1))
    out.attrs.update(
        variance_reduction=plain / paired if paired > 0 else math.inf,
        control=(f"OPA N = {int(control.attrs.get('N', control.sizes.get('order', 0) - 1))}, "
                 f"{control.attrs.get('impact_law', '?')} law, {elements} element(s)"))
    return out


__all__ = ["CHUNK", "check_control", "controlled", "cv_estimates"]
