"""Errors of an OPA run against a Monte Carlo ensemble on the same time grid.

The MC statistics carry their own standard errors, so every error is read against the
MC noise: an OPA mean is "within MC noise" at time t when
``|x_0(t) - E_MC[x](t)| <= z * SE(t) + floor`` (``floor`` absorbs the integrator's
tolerance where the ensemble has not spread yet, e.g. at t = 0), and likewise the
variance against ``x_var_sem`` and each coefficient ``x_i = E[x U_i]`` against
``x_coef_sem``. A NaN standard error (a Gauss-quadrature ensemble has no sampling error)
leaves the band at ``floor``.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from compare._inputs import (
    check_attribute_number, check_dataset, check_finite, check_number,
    check_standard_error, require_attributes, require_time, require_variables, several,
)


def _check_same_grid(a: xr.Dataset, b: xr.Dataset) -> None:
    ta, tb = a.time.values, b.time.values
    if ta.shape != tb.shape or not np.allclose(ta, tb, rtol=1e-12, atol=1e-12):
        raise ValueError(
            f"the datasets must share their time grid, got {ta.size} and {tb.size} times "
            f"(ends {ta[-1]:.6g} and {tb[-1]:.6g})"
        )


#: what makes two runs runs of the same system (besides the time grid): every model
#: parameter, the uncertainty and its law, the impulse model
SYSTEM_ATTRS = ("uncertain", "distribution", "sigma", "mu", "a", "c", "f", "omega", "eta",
                "delta", "F0", "a1", "omega1", "n", "x0", "v0", "impulse", "pulse_width",
                "impulse_at_zero")


#: the fields of SYSTEM_ATTRS that are words; the others are numbers
_WORDS = ("uncertain", "distribution", "impulse")


def _check_same_system(a: xr.Dataset, b: xr.Dataset) -> None:
    """Refuse, naming the field, two runs of different systems. A field neither dataset
    carries (a dataset built by hand) is not compared; the law of xi defaults to the
    semicircle, as in every run before it was recorded. A field one run lacks (an older
    or partial dataset) cannot be compared: refused, naming the run that lacks it."""
    def shown(value):
        if isinstance(value, str):
            return repr(value)
        return ",".join(f"{float(v):g}" for v in np.atleast_1d(value))

    for name in SYSTEM_ATTRS:
        default = "semicircle" if name == "distribution" else None
        va, vb = a.attrs.get(name, default), b.attrs.get(name, default)
        if va is None and vb is None:
            continue
        if va is None or vb is None:
            lacking, other, value = (("opa", "mc", vb) if va is None else
                                     ("mc", "opa", va))
            raise ValueError(f"the {lacking} dataset lacks the attribute {name} "
                             f"({shown(value)} in the {other} dataset): the runs cannot be "
                             f"told to be of one system")
        vector = name == "sigma" and (np.ndim(va) > 0 or np.ndim(vb) > 0)
        if vector:  # several uncertain parameters: one scale each
            va, vb = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (va, vb))
            same = va.shape == vb.shape and bool(np.isclose(va, vb, rtol=1e-12,
                                                            atol=0.0).all())
        else:
            if name not in _WORDS:
                for side, ds in (("opa", a), ("mc", b)):
                    check_attribute_number(ds, f"the {side} dataset", name)
            same = (va == vb if name in _WORDS
                    else np.isclose(float(va), float(vb), rtol=1e-12, atol=0.0))
        if not same:
            raise ValueError(f"the runs are of different systems: {name} = {shown(va)} in "
                             f"the opa dataset, {shown(vb)} in the mc dataset")


def _check_models(opa_ds: xr.Dataset, mc_ds: xr.Dataset) -> None:
    for name, ds, want in (("opa_ds", opa_ds, "opa"), ("mc_ds", mc_ds, "mc")):
        check_dataset(ds, name, f"an {want} run")
        model = ds.attrs.get("model", want)
        if model != want:
            raise ValueError(f"{name} must be an {want} run, got model = {model!r}")


#: the element layout, from which the coefficients of a run without x_coef follow
_ELEMENTS = ("element_x_coef", "element_edges", "element_probability")


def _check_contents(opa_ds: xr.Dataset, mc_ds: xr.Dataset) -> None:
    """Refuse, naming the dataset and the culprit, a run that lacks what compare_runs
    reads or holds a non-finite value in it. NaN is documented, and accepted, in two
    places only (docs/datasets.md): the standard errors of a Gauss quadrature
    (``sampler = "gauss"``: no sampling error), and an OPA run that stopped
    (``simulate_opa(partial=True)``: ``attrs["failure"]``, NaN from the stop on)."""
    opa, mc = "the opa dataset", "the mc dataset"
    require_time(opa_ds, opa)
    require_time(mc_ds, mc)
    require_attributes(opa_ds, opa, ("omega",), hint=" (the forcing frequency: the "
                       "forcing period of error_metrics' windows)")
    check_attribute_number(opa_ds, opa, "omega", positive=True)
    require_variables(opa_ds, opa, ("x_mean", "x_var"))
    if several(opa_ds):  # coefficients compared only when both have one basis
        coefficients = ("x_coef",) if "x_coef" in opa_ds else ()
    else:
        coefficients = ("x_coef",) if "x_coef" in opa_ds else _ELEMENTS
        for needed in ((("x_coef", "element_x_coef"),), coefficients):
            require_variables(opa_ds, opa, needed, hint=" (its coefficients: x_coef, or "
                              "the element layout element_x_coef, element_edges, "
                              "element_probability)")
    require_variables(mc_ds, mc, ("x_mean", "x_var", "x_coef"))
    missing = [name for name in ("x_sem", "x_var_sem", "x_coef_sem") if name not in mc_ds]
    if missing:
        raise ValueError(f"the mc dataset lacks the standard errors {missing} (written by "
                         f"an older simulate_mc?); run the ensemble again")
    # a run that stopped: NaN from its first non-finite output on, and only there
    allowed, where = None, ""
    if "failure" in opa_ds.attrs:
        t = opa_ds["time"].values
        stopped = ~np.isfinite(np.asarray(opa_ds.x_mean.values, dtype=float))
        stop = t[np.argmax(stopped)] if stopped.any() else np.inf
        allowed = xr.DataArray(t >= stop, dims="time", coords={"time": opa_ds["time"]})
        where = " before the run stopped"
    for name in ("x_mean", "x_var") + coefficients:
        ok = None if allowed is None or "time" not in opa_ds[name].dims else \
            allowed.broadcast_like(opa_ds[name]).transpose(*opa_ds[name].dims).values
        check_finite(opa_ds, opa, name, allowed=ok, where=where if ok is not None else "")
    for name in ("x_mean", "x_var", "x_coef"):
        check_finite(mc_ds, mc, name)
    quadrature = mc_ds.attrs.get("sampler") == "gauss"
    for name in ("x_sem", "x_var_sem", "x_coef_sem"):
        check_standard_error(mc_ds, mc, name, nan=quadrature)


def _several_coefficients(opa_ds: xr.Dataset, mc_ds: xr.Dataset):
    """The terms both runs of several parameters carry in one basis (the OPA run's single
    element and the ensemble's multi-index set agree on their first rows): (n, OPA
    coefficients (n, T)), or (0, None) when they cannot be compared (boxes)."""
    if "x_coef" not in opa_ds or "multi_index" not in opa_ds or "multi_index" not in mc_ds:
        return 0, None
    a, b = opa_ds.multi_index.values, mc_ds.multi_index.values
    n = min(len(a), len(b))
    if a.shape[1] != b.shape[1] or not np.array_equal(a[:n], b[:n]):
        return 0, None
    return n, opa_ds.x_coef.values[:n]


def _opa_coefficients(opa_ds: xr.Dataset, order: int):
    """The OPA run's coefficients in the whole law's orthonormal basis (order+1, T), or
    None where they cannot be formed (a chaospy law of xi, which the dataset names but
    does not store)."""
    if "x_coef" in opa_ds:
        return opa_ds.x_coef.values[: order + 1]
    if "element_x_coef" not in opa_ds:
        return None
    from opa.engine import global_coefficients
    from opa.engine import parse

    try:
        measure = parse(opa_ds.attrs.get("distribution", "semicircle"))
    except ValueError:
        return None
    return global_coefficients(opa_ds.element_x_coef.values, opa_ds.element_edges.values,
                               opa_ds.element_probability.values, measure, order)


def _within(err: np.ndarray, sem: np.ndarray, z: float, floor: float) -> np.ndarray:
    """1 where ``|err| <= z sem + floor`` (a NaN sem counts as no noise), else 0."""
    noise = np.where(np.isfinite(sem), z * sem, 0.0) + floor
    return (np.abs(err) <= noise).astype(np.int8)


def compare_runs(opa_ds: xr.Dataset, mc_ds: xr.Dataset, *, z: float = 3.0,
                 floor: float = 1e-7) -> xr.Dataset:
    """Pointwise comparison of an ``opa`` dataset with an ``mc`` dataset.

    Each OPA statistic is compared with its MC estimate and the error is read against that
    estimate's standard error: the verdict ``*within_noise`` is 1 where

        |err| <= z SE + floor,

    i.e. where the difference cannot be told from the MC noise at ``z`` standard errors
    (a NaN SE, from a Gauss-quadrature ensemble, leaves only ``floor``).

    Any OPA run (one element or several, any law of xi) against any Monte Carlo run of the
    same system: the coefficients of a multi-element run are those of its piecewise
    surrogate in the whole law's orthonormal basis (``opa._elements.global_coefficients``),
    which is what the ensemble's ``x_coef`` estimates.

    Parameters
    ----------
    opa_ds : ``opa`` dataset: ``x_mean, x_var (time)``, and ``x_coef (order, time)`` or
        the element layout (``element_x_coef``, ``element_edges``,
        ``element_probability``).
    mc_ds : ``mc`` dataset of :func:`mc.simulate_mc` of the same system (every model
        parameter, ``sigma``, ``uncertain``, ``distribution``, the impulse model) on the
        same time grid: the estimates
        ``x_mean, x_var``, ``x_coef`` and their standard errors ``x_sem, x_var_sem``,
        ``x_coef_sem``.
    z : width of the noise band in standard errors (a finite number >= 0).
    floor : absolute tolerance added to the band (the integrators' accuracy where the
        ensemble has no spread, e.g. the mean at t = 0; a finite number >= 0).

    Returns
    -------
    xarray.Dataset with, for the mean, ``err_mean(time)`` = x_0 - E_MC[x],
    ``mc_sem(time)`` and ``within_noise(time)``; for the variance ``err_var(time)`` =
    OPA variance - MC variance, ``var_sem(time)`` and ``var_within_noise(time)``; for
    With several uncertain parameters the moments are compared the same way, and the
    coefficients over ``term`` where both runs carry them in one basis (a single-element
    run and the ensemble's multi-index set); a run on boxes gives no coefficient rows.
    In one dimension,
    the coefficients of the orders both carry ``err_coef(order, time)`` = x_i -
    E_MC[x U_i], ``coef_sem(order, time)`` and ``coef_within_noise(order, time)``.

    Raises
    ------
    ValueError
        Runs of different systems (naming the field), different time grids, or an ``mc``
        dataset without the standard errors (written before ``x_coef_sem`` existed: run
        the ensemble again); a dataset that is not an ``opa`` (``mc``) run, lacks a
        variable, ``omega`` or the coordinate ``time`` (``periods`` in older files), holds
        a non-finite value where its data contract has none (NaN is accepted in the
        standard errors of a Gauss quadrature, ``sampler = "gauss"``, and after the stop
        of an OPA run that stopped, ``attrs["failure"]``), or a negative standard error;
        ``z`` or ``floor`` not a finite number >= 0. Each message names the dataset and
        the culprit.

    Examples
    --------
    At t = 0 every sample starts at x0, so E[x U_i] = 0 for i >= 1; the MC estimate
    x0 mean(U_i(xi)) is not, but its error lies within the noise::

        cmp = compare_runs(simulate_opa(osc, sigma=0.05, order=4),
                           simulate_mc(osc, sigma=0.05, samples=256, sampler="random"))
        cmp.err_coef[1:, 0]           # up to ~0.1
        cmp.coef_within_noise[1:, 0]  # all 1
    """
    _check_models(opa_ds, mc_ds)
    z = check_number("z", z)
    floor = check_number("floor", floor)
    _check_contents(opa_ds, mc_ds)
    _check_same_system(opa_ds, mc_ds)
    _check_same_grid(opa_ds, mc_ds)
    if several(opa_ds):
        n, coef = _several_coefficients(opa_ds, mc_ds)
        dim = "term"
    else:
        n = min(opa_ds.sizes["order"], mc_ds.sizes["order"])
        coef = _opa_coefficients(opa_ds, n - 1)
        dim = "order"
    if coef is None and not several(opa_ds):
        raise ValueError(f"the opa dataset's coefficients cannot be compared: its law of xi "
                         f"{opa_ds.attrs.get('distribution')!r} is not one opa-mc can "
                         f"rebuild from its name")
    err = opa_ds.x_mean.values - mc_ds.x_mean.values
    sem = mc_ds.x_sem.values
    err_var = opa_ds.x_var.values - mc_ds.x_var.values
    var_sem = mc_ds.x_var_sem.values
    T = len(err)
    err_coef = (coef - mc_ds.x_coef.values[:n]) if n else np.zeros((0, T))
    coef_sem = mc_ds.x_coef_sem.values[:n] if n else np.zeros((0, T))
    band = f"{z} SE + {floor}"
    ds = xr.Dataset(
        {
            "err_mean": ("time", err, {"long_name": "x_0 - E_MC[x]", "units": "1"}),
            "mc_sem": ("time", sem, {"long_name": "MC standard error of E[x]", "units": "1"}),
            "err_var": ("time", err_var,
                        {"long_name": "OPA variance - MC variance", "units": "1"}),
            "var_sem": ("time", var_sem,
                        {"long_name": "MC standard error of Var[x]", "units": "1"}),
            "err_coef": ((dim, "time"), err_coef,
                         {"long_name": "x_i - E_MC[x U_i]", "units": "1"}),
            "coef_sem": ((dim, "time"), coef_sem,
                         {"long_name": "MC standard error of E[x U_i]", "units": "1"}),
            "within_noise": ("time", _within(err, sem, z, floor),
                             {"long_name": f"1 where |err_mean| <= {band}", "units": "1"}),
            "var_within_noise": ("time", _within(err_var, var_sem, z, floor),
                                 {"long_name": f"1 where |err_var| <= {band}",
                                  "units": "1"}),
            "coef_within_noise": ((dim, "time"), _within(err_coef, coef_sem, z, floor),
                                  {"long_name": f"1 where |err_coef| <= {band}",
                                   "units": "1"}),
        },
        coords={"time": opa_ds.time, dim: np.arange(n)},
        attrs={"z": float(z), "floor": float(floor), "omega": float(opa_ds.attrs["omega"])},
    )
    return ds


def error_metrics(cmp: xr.Dataset, *, window_periods: float | None = None,
                  until: float | None = None) -> dict[str, float]:
    """Scalar summaries of a :func:`compare_runs` result.

    ``rms_error``/``max_error`` of the mean over the window (the first
    ``window_periods`` forcing periods, or all), ``strobe_rms_error`` at the
    stroboscopic points t = k 2 pi/omega in the window, ``sem_rms`` (the MC noise
    floor), ``var_rms_error``, and ``agree_periods``: the time, in forcing periods, of
    the first output where the error leaves the MC noise band (inf if never).
    ``until`` (a time) further restricts the window to ``t < until``, e.g. to the time
    before the first impact.

    ``cmp`` must be a :func:`compare_runs` result (``err_mean``, ``mc_sem``,
    ``within_noise``, ``err_var`` over ``time``, the attribute ``omega``);
    ``window_periods`` a finite number > 0 or None, ``until`` a number or None (inf: no
    limit). Anything else is refused with a ValueError naming it.
    """
    check_dataset(cmp, "cmp", "a compare_runs result")
    require_time(cmp, "cmp")
    require_attributes(cmp, "cmp", ("omega",), hint=" (a compare_runs result carries it)")
    omega = check_attribute_number(cmp, "cmp", "omega", positive=True)
    require_variables(cmp, "cmp", ("err_mean", "mc_sem", "within_noise", "err_var"),
                      hint=" (not a compare_runs result?)")
    if window_periods is not None:
        window_periods = check_number("window_periods", window_periods, strict=True)
    if until is not None:
        until = check_number("until", until, least=-np.inf, finite=False)
    T = 2 * np.pi / omega
    t = cmp.time.values
    in_window = np.ones(t.size, bool) if window_periods is None else t <= window_periods * T + 1e-9
    if until is not None:
        in_window &= t < until
    if not in_window.any():
        nan = float("nan")
        return dict.fromkeys(("rms_error", "max_error", "strobe_rms_error", "sem_rms",
                              "var_rms_error"), nan) | {"agree_periods": nan}
    err = cmp.err_mean.values[in_window]
    tw = t[in_window]
    phase = tw / T
    strobe = np.abs(phase - np.round(phase)) < 1e-9
    sem = cmp.mc_sem.values[in_window]
    outside = np.flatnonzero(cmp.within_noise.values == 0)
    return {
        "rms_error": float(np.sqrt(np.mean(err**2))),
        "max_error": float(np.max(np.abs(err))),
        "strobe_rms_error": float(np.sqrt(np.mean(err[strobe] ** 2))) if strobe.any() else np.nan,
        "sem_rms": float(np.sqrt(np.nanmean(sem**2))) if np.isfinite(sem).any() else np.nan,
        "var_rms_error": float(np.sqrt(np.mean(cmp.err_var.values[in_window] ** 2))),
        "agree_periods": float(t[outside[0]] / T) if len(outside) else np.inf,
    }
