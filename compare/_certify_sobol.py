"""Certified Sobol indices of the true impact systems: the OPA surrogate's exact indices
beside pick-freeze Monte Carlo estimates of the true systems' with standard errors.

An OPA run with d >= 2 uncertain parameters gives the surrogate
``x_hat(t, xi) = sum_alpha x_alpha(t) Psi_alpha(xi)`` and its Sobol indices exactly
(``opa.engine.sobol_indices`` of the coefficients, Sudret 2008). Whether they are the
indices of the *true* sampled impact systems is what this module certifies:

1. **Two independent samples A and B** of xi, each M points of the problem's law: the
   first d and the last d columns of M scrambled Sobol' points in **2d dimensions**
   (Saltelli 2010), each column through its marginal's quantile function. Each row
   ``(A_m, B_m)`` is then uniform on the 2d-cube, so ``A_m`` and ``B_m`` are independent,
   as pick-freeze needs (``E[f(B) f(A_B^(i))] = E[f]^2 + V_i`` holds only then). Two
   obvious alternatives are wrong: the two halves of one d-dimensional sequence of 2M
   points (the second half fills the gaps of the first: dependent by construction), and
   two scramblings of the same d-dimensional sequence with two seeds (scipy's scrambling
   is a linear matrix scramble plus a digital shift of the same digits, so column j of B
   is a fixed function of column j of A: measured here, the total index of c of the
   no-impact test case came out 0.06 against 0.99). ``sampler="random"``: independent
   uniform points instead (the delta-method standard errors assume independent rows;
   with Sobol' rows they are conservative, the estimates' spread being smaller).
2. The d matrices ``A_B^(i)`` (:func:`compare._sobol.pick_freeze_design`) and the true
   systems at all ``(d + 2) M`` points (one ``run_batch`` per block, in chunks).
3. ``f`` = x(t) and v(t) of the true systems, ``g`` = the surrogate at the same points,
   and :func:`compare._sobol.pick_freeze_indices` without and with ``g`` as control
   variate (its exact indices known): both standard errors are reported, the
   controlled one certifies (unless ``control=False``).

The indices within the noise are reported as ``[0, upper]``, never as negative numbers
(the readings of :mod:`compare._sobol`).
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import xarray as xr

from compare._inputs import check_dataset, require_variables
from compare._sobol import (
    READINGS, pick_freeze_design, pick_freeze_indices, surrogate_agreement,
)
from opa.engine import (
    PARAMETER_NAMES, SimulationError, SobolIndices, SolverOptions, System, check_count,
    check_memory, check_work, provenance_attrs, run_batch, simulate_opa, sobol_indices,
    surrogate_several, time_coord,
)

#: true-system states (runs x outputs x 2) in one ``run_batch`` call of the certificate
PICK_FREEZE_CHUNK = 1 << 21
#: the certificate's run grid when no OPA run is given
SOBOL_PERIODS, SOBOL_PER_PERIOD = 10, 8
#: how A and B are drawn, by sampler (the dataset's ``sampling`` attribute)
SAMPLINGS = {
    "sobol": "A and B: the first d and the last d columns of M scrambled Sobol' points in "
             "2d dimensions (Saltelli 2010); the true systems at A, B and each A_B^(i)",
    "random": "A and B: M independent points each of the law of xi; the true systems at "
              "A, B and each A_B^(i)",
}
#: the reading codes as netCDF attributes (CF flags)
READING_FLAGS = {"flag_values": np.arange(len(READINGS), dtype=np.int8),
                 "flag_meanings": " ".join(r.replace(" ", "_") for r in READINGS)}


def certify_sobol(system: System, *, opa: xr.Dataset | None = None, samples: int = 1024,
                  seed: int = 0, periods: float | None = None, per_period: int | None = None,
                  basis: str | None = None, options: SolverOptions | None = None,
                  control: bool = True, z: float = 1.96, sampler: str = "sobol") -> xr.Dataset:
    """First-order and total Sobol indices of x(t) and v(t) of the true impact systems,
    certified by pick-freeze Monte Carlo, beside the OPA surrogate's exact ones.

    Parameters
    ----------
    system : opa.System
        With d >= 2 uncertain parameters (``System(uncertain="mu,c", ...)``).
    opa : xarray.Dataset, optional
        The OPA run of ``system`` (``simulate_opa(system, ...)``); made here when omitted,
        on ``periods`` (default 10) x ``per_period`` (default 8) outputs with ``basis``
        (default ``total``). Given, its times are used, and ``periods``, ``per_period``
        and ``basis`` are refused.
    samples : int
        M, the rows of A and of B: a power of two >= 8 (with ``sampler="sobol"``). The
        true systems run ``(d + 2) M`` times. The intervals rest on the delta method's
        normal approximation: with the control variate and random points they covered
        the exact indices of the free oscillator's test case at 0.89 (M = 32) and 0.93
        (M = 64) instead of 0.95, and 0.95-0.965 at M = 128 (50 seeds, 4 indices).
    seed : int
        Seed of the scrambling (or of the random points): a whole number >= 0.
    options : opa.SolverOptions, optional
        The solver of the true systems and of the OPA run made here.
    control : bool
        Certify with the surrogate as control variate (default); False: the plain
        pick-freeze estimates certify (both standard errors are reported either way).
    z : float
        Half-width of the intervals in standard errors (1.96: 95 %).
    sampler : {"sobol", "random"}
        How A and B are drawn (module docstring): scrambled Sobol' in 2d dimensions
        (``samples`` a power of two), or independent random points (any ``samples`` >= 8;
        the standard errors are then exact to first order, not conservative).

    Returns
    -------
    xarray.Dataset
        Dims (parameter, time). For each state s in (x, v) and kind k in (first, total):
        ``s_sobol_k`` (the certified index where resolved, NaN elsewhere: never a
        negative number), ``s_sobol_k_se``, ``s_sobol_k_lower`` and ``_upper`` (the
        reported interval, ``[0, upper]`` within the noise), ``s_sobol_k_reading`` (codes
        0 resolved, 1 within noise, 2 undefined; ``flag_meanings``), ``s_sobol_k_se_plain``
        (plain Monte Carlo's standard error) and ``s_sobol_k_surrogate`` (the OPA
        surrogate's exact index); ``s_var`` and ``s_var_se`` (the true variance).
        Attributes: ``samples``, ``true_system_runs``, ``agreement`` (the share of outputs,
        x and v together, where every surrogate index lies in its certified interval),
        ``agreement_x``, ``agreement_v``, ``se_reduction`` (median plain / controlled
        standard error), ``verdict`` (a sentence), ``sampling``, and the run's provenance.

    Raises
    ------
    ValueError
        Naming the argument: ``system`` not an opa.System or with one uncertain parameter,
        a keyword out of range, ``opa`` not a run of ``system``.
    opa.SimulationError
        When a true system cannot be integrated.

    Examples
    --------
    >>> import opa
    >>> free = opa.Oscillator(mu=0.3, a=1.0, c=0.5, f=0.4, omega=1.3, delta=50.0, F0=0.0,
    ...                       x0=0.5)
    >>> s = opa.System(free, uncertain="mu,c", sigma=(0.06, 0.2), order=5)
    >>> ds = certify_sobol(s, samples=64, periods=2, per_period=2)
    >>> ds.attrs["true_system_runs"], ds.x_sobol_total_reading.values[:, -1].tolist()
    (256, [0, 0])
    """
    samples, seed, z = _check_keywords(system, samples, seed, control, z, sampler)
    options = SolverOptions() if options is None else options
    if not isinstance(options, SolverOptions):
        raise ValueError(f"options must be opa.SolverOptions or None, got {options!r:.80}")
    run = _opa_run(system, opa, periods, per_period, basis, options)
    times = run.time.values
    d, T = system.dimension, len(times)
    span = float(times[-1] - times[0]) / system.oscillator.forcing_period
    check_work("these Sobol indices", (d + 2) * samples * span,
               [("samples", samples), ("periods", f"{span:g}")], oscillator=system.oscillator)
    check_memory("the pick-freeze paths", (d + 2) * samples * T * 4 * 8,
                 f"(d + 2) {d + 2} x samples {samples} x {T} outputs x 2 states x 2 models")
    a, b = _independent_blocks(system, samples, seed, sampler)
    points = np.concatenate([a[None], b[None], pick_freeze_design(a, b)])  # (d + 2, M, d)
    paths = _true_paths(system, options, points, times)                   # (d + 2, M, T, 2)
    data, agreement, ratios = {}, {}, []
    for k, state in enumerate(("x", "v")):
        exact = _surrogate_indices(run, state)
        f = paths[..., k]
        g = surrogate_several(run, system.problem.measures, points.reshape(-1, d),
                              state).reshape(f.shape)
        with np.errstate(all="ignore"):
            floor = _solver_floor(f[0], f[1], options)
            plain = pick_freeze_indices(f[0], f[1], f[2:], z=z, floor=floor)
            cv = pick_freeze_indices(f[0], f[1], f[2:], surrogate=(g[0], g[1], g[2:]),
                                     exact=exact, z=z, floor=floor)
        chosen = cv if control else plain
        data.update(_variables(state, chosen, plain, exact))
        agreement[state] = (surrogate_agreement(chosen, exact.first, exact.total),
                            int(np.sum(np.asarray(chosen.variance) > 0)))
        ratios.append(_se_ratio(plain, cv))
    ds = xr.Dataset(data, coords={**time_coord(times, system.oscillator.omega),
                                  "parameter": ("parameter", list(system.problem.names))},
                    attrs=provenance_attrs("sobol", system, options, seed=seed,
                                           sampler=sampler))
    ds.attrs.update(_summary(ds, run, samples, control, z, agreement,
                             float(np.nanmedian(np.concatenate(ratios)))))
    ds.attrs["sampling"] = SAMPLINGS[sampler]
    return ds


def _check_keywords(system, samples, seed, control, z, sampler) -> tuple[int, int, float]:
    if not isinstance(system, System):
        raise ValueError(f"system must be an opa.System, got {type(system).__name__}")
    if system.dimension < 2:
        raise ValueError("Sobol indices need at least two uncertain parameters")
    if sampler not in ("sobol", "random"):
        raise ValueError(f"sampler must be sobol or random, got {sampler!r:.40}")
    samples = check_count("samples", samples, minimum=8)
    if sampler == "sobol" and samples & (samples - 1):
        raise ValueError(f"samples must be a power of two >= 8 (scrambled Sobol' points), "
                         f"got {samples}")
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) \
            or seed < 0:
        raise ValueError(f"seed must be a whole number >= 0, got {seed!r}")
    if not isinstance(control, (bool, np.bool_)):
        raise ValueError(f"control must be True or False, got {control!r}")
    if isinstance(z, (bool, np.bool_)) or not isinstance(z, numbers.Real) \
            or not (math.isfinite(z) and z > 0):
        raise ValueError(f"z must be a finite number > 0, got {z!r}")
    system.check_samples()
    return samples, int(seed), float(z)


def _solver_floor(f_a, f_b, options) -> np.ndarray:
    """The numerical error of an index (...) from the true systems' tolerances: each value
    carries an error up to ~(rtol |f| + atol), each pick-freeze product twice that, so an
    index up to ~2 (rtol E[f^2] + atol E|f|) / V; ten times that, as the certificate's
    floor (``compare._verify``: 10 (rtol + atol)). Before the first impact the surrogate
    matches the true systems to about that, and the control variate's standard errors
    alone fall below it."""
    both = np.concatenate([f_a, f_b])
    variance = both.var(axis=0, ddof=1)
    error = 20.0 * (options.rtol * (both ** 2).mean(axis=0)
                    + options.atol * np.abs(both).mean(axis=0))
    return np.where(variance > 0, error / np.where(variance > 0, variance, 1.0), np.inf)


def _surrogate_indices(run: xr.Dataset, state: str) -> SobolIndices:
    """The surrogate's exact indices of ``state``: from its coefficients (one element,
    Sudret 2008), or as the run computed them on its boxes (exact quadrature of the
    piecewise expansion, :mod:`opa._boxes`)."""
    if "element_lower" not in run:
        return sobol_indices(run[f"{state}_coef"].values, run.multi_index.values)
    return SobolIndices(run[f"{state}_sobol_first"].values, run[f"{state}_sobol_total"].values,
                        run[f"{state}_var"].values)


def _opa_run(system, opa, periods, per_period, basis, options) -> xr.Dataset:
    """The OPA run: made here, or the given one checked to be a complete d-dimensional
    run of ``system`` from its deterministic start."""
    if opa is None:
        return simulate_opa(system, periods=SOBOL_PERIODS if periods is None else periods,
                            per_period=SOBOL_PER_PERIOD if per_period is None else per_period,
                            options=options, basis="total" if basis is None else basis)
    for name, value in (("periods", periods), ("per_period", per_period), ("basis", basis)):
        if value is not None:
            raise ValueError(f"{name} is the given opa run's own: leave it out with opa "
                             f"(got {name}={value!r:.40})")
    check_dataset(opa, "opa", "an OPA run with several uncertain parameters")
    boxes = "element_lower" in opa
    coefficients = (("element_x_coef", "element_v_coef", "element_upper", "x_sobol_first",
                     "x_sobol_total", "v_sobol_first", "v_sobol_total", "x_var", "v_var")
                    if boxes else ("x_coef", "v_coef"))
    require_variables(opa, "opa", (*coefficients, "multi_index", "time", "parameter"),
                      hint=" (an OPA run with several uncertain parameters, "
                           "simulate_opa(System(uncertain='mu,c', ...)))")
    if "failure" in opa.attrs:
        raise ValueError(f"opa did not complete ({opa.attrs['failure']}): nothing to certify")
    names = [str(n) for n in opa.parameter.values]
    if names != list(system.problem.names):
        raise ValueError(f"opa is a run of the uncertain parameters {','.join(names)}, the "
                         f"system's are {','.join(system.problem.names)}")
    expected = provenance_attrs("opa", system, options)
    for name in ("force_law", "force_constants"):  # the paper's law has neither
        if str(opa.attrs.get(name, "")) != str(expected.get(name, "")):
            raise ValueError(f"opa was run with the force law {opa.attrs.get(name, 'none')!r:.60}"
                             f", the system has {expected.get(name, 'none')!r:.60} ({name})")
    for name in (*PARAMETER_NAMES, "distribution"):
        if name in opa.attrs and not np.array_equal(opa.attrs[name], expected[name]):
            raise ValueError(f"opa was run with {name} = {opa.attrs[name]}, the system has "
                             f"{expected[name]}")
    if "sigma" in opa.attrs and not np.allclose(np.asarray(opa.attrs["sigma"], dtype=float),
                                                system.problem.scales, rtol=0, atol=0):
        raise ValueError(f"opa was run with sigma = {opa.attrs['sigma']}, the system has "
                         f"{system.problem.scales}")
    for name in coefficients[:2]:
        if not np.all(np.isfinite(opa[name].values)):
            raise ValueError(f"opa's {name} holds non-finite values")
    start = np.zeros(opa.sizes["term"])
    start[0] = system.oscillator.x0
    x_first, v_first = ((opa.element_x_coef.values[..., 0], opa.element_v_coef.values[..., 0])
                        if boxes else (opa.x_coef.values[None, :, 0],
                                       opa.v_coef.values[None, :, 0]))
    if float(opa.time[0]) == 0.0 and not (
            np.allclose(x_first, start, rtol=0, atol=1e-12)
            and np.allclose(v_first[:, 1:], 0.0, rtol=0, atol=1e-12)):
        raise ValueError("opa does not start from the system's x0, v0 (a run continued with "
                         "initial=...): its true systems are not known")
    return opa


def _independent_blocks(system, samples, seed, sampler) -> tuple[np.ndarray, np.ndarray]:
    """A and B: the first d and the last d columns of M points in 2d dimensions
    (scrambled Sobol' or independent uniform), each column sent through its marginal's
    quantile function."""
    from scipy.stats import qmc

    problem = system.problem
    d = problem.dimension
    rng = np.random.default_rng(seed)
    if sampler == "sobol":
        u = qmc.Sobol(d=2 * d, scramble=True, seed=rng).random_base2(
            int(samples).bit_length() - 1)
    else:
        u = rng.random((samples, 2 * d))
    xi = np.column_stack([problem.measures[j % d].ppf(u[:, j]) for j in range(2 * d)])
    return xi[:, :d], xi[:, d:]


def _true_paths(system, options, points, times) -> np.ndarray:
    """x and v of the true systems at each block's points: (blocks, M, T, 2)."""
    blocks, m, _ = points.shape
    out = np.empty((blocks, m, len(times), 2))
    y0 = system.deterministic().initial_state()
    chunk = max(1, PICK_FREEZE_CHUNK // (2 * len(times)))
    for k in range(blocks):
        for lo in range(0, m, chunk):
            xi = points[k, lo:lo + chunk]
            batch = run_batch(system.sampled_inputs(options, xi=xi), y0, times,
                              rtol=options.rtol, atol=options.atol, stop_on_failure=True)
            bad = np.flatnonzero(batch.failed)
            if len(bad):
                raise SimulationError(
                    f"the true system at xi = {np.round(xi[bad[0]], 6).tolist()} could not "
                    f"be integrated: {batch.message(bad[0])}",
                    status=int(batch.status[bad[0]]))
            out[k, lo:lo + len(xi)] = batch.states
    return out


def _variables(state, chosen, plain, exact) -> dict:
    """The dataset's variables of one state."""
    dims = ("parameter", "time")
    out = {}
    for kind in ("first", "total"):
        est, raw = getattr(chosen, kind), getattr(plain, kind)
        low, high = est.interval
        name = f"{state}_sobol_{kind}"
        what = f"{kind}{'-order' if kind == 'first' else ''} Sobol index of {state}"
        out[name] = (dims, est.value, {
            "long_name": f"certified {what} (pick-freeze Monte Carlo of the true systems; "
                         f"NaN unless resolved)", "units": "1"})
        out[f"{name}_se"] = (dims, est.standard_error, {
            "long_name": f"standard error of the certified {what}", "units": "1"})
        out[f"{name}_lower"] = (dims, low, {
            "long_name": f"lower end of the certified interval of the {what} (0 within "
                         f"the noise)", "units": "1"})
        out[f"{name}_upper"] = (dims, high, {
            "long_name": f"upper end of the certified interval of the {what}",
            "units": "1"})
        out[f"{name}_reading"] = (dims, est.code.astype(np.int8), {
            "long_name": f"reading of the {what}", **READING_FLAGS})
        out[f"{name}_se_plain"] = (dims, raw.standard_error, {
            "long_name": f"standard error of the plain pick-freeze {what} (no control "
                         f"variate)", "units": "1"})
        out[f"{name}_surrogate"] = (dims, getattr(exact, kind), {
            "long_name": f"the OPA surrogate's exact {what} (NaN where its variance is 0)",
            "units": "1"})
    out[f"{state}_var"] = ("time", chosen.variance, {
        "long_name": f"variance of {state} of the true systems (A and B pooled)",
        "units": "1"})
    out[f"{state}_var_se"] = ("time", chosen.variance_se, {
        "long_name": f"standard error of {state}_var", "units": "1"})
    return out


def _se_ratio(plain, cv) -> np.ndarray:
    """Plain over controlled standard errors of every defined index."""
    ratios = []
    for kind in ("first", "total"):
        a = getattr(plain, kind).standard_error
        b = getattr(cv, kind).standard_error
        with np.errstate(all="ignore"):
            r = a / b
        ratios.append(r[np.isfinite(r)])
    return np.concatenate(ratios)


def _worst(ds) -> str:
    """The surrogate index farthest outside its certified interval, in words."""
    worst, where = 0.0, ""
    for state in ("x", "v"):
        for kind, symbol in (("first", "S"), ("total", "S_T")):
            name = f"{state}_sobol_{kind}"
            s = ds[f"{name}_surrogate"].values
            low, high = ds[f"{name}_lower"].values, ds[f"{name}_upper"].values
            with np.errstate(invalid="ignore"):
                gap = np.nan_to_num(np.maximum(low - s, s - high), nan=0.0)
            if gap.max() > worst:
                p, t = np.unravel_index(np.argmax(gap), gap.shape)
                worst = float(gap.max())
                where = (f"; the largest departure: {symbol}({ds.parameter.values[p]}) of "
                         f"{state} at t = {float(ds.time[t]):.4g}, surrogate {s[p, t]:.4g} "
                         f"against [{low[p, t]:.4g}, {high[p, t]:.4g}]")
    return where


def _summary(ds, run, samples, control, z, agreement, reduction) -> dict:
    """The certificate's attributes: counts, agreement and the verdict sentence."""
    d = ds.sizes["parameter"]
    (ax, nx), (av, nv) = agreement["x"], agreement["v"]
    counted = nx + nv
    share = (float("nan") if counted == 0 else
             (np.nan_to_num(ax) * nx + np.nan_to_num(av) * nv) / counted)
    level = 2.0 * (0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))) - 1.0
    floor = max(0.0, 1.0 - 2 * d * (1.0 - level))
    how = (f"the surrogate as control variate ({reduction:.3g} times smaller standard "
           f"errors, median)" if control else "plain Monte Carlo (no control variate)")
    verdict = (
        f"The OPA surrogate's Sobol indices (N = {run.attrs.get('N', '?')}, "
        f"{run.sizes['term']} terms) lie in the "
        f"certified {100 * level:.0f} % intervals at {100 * share:.0f} % of the "
        f"{counted} outputs of x and v (if they were the true systems' indices, at least "
        f"about {100 * floor:.0f} % would); certified by {samples} pick-freeze samples, "
        f"{(d + 2) * samples} true systems, with {how}{_worst(ds)}.")
    return dict(samples=int(samples), true_system_runs=int((d + 2) * samples),
                agreement=float(share), agreement_x=float(ax), agreement_v=float(av),
                se_reduction=float(reduction), control=int(bool(control)), z=float(z),
                N=int(run.attrs.get("N", -1)),
                basis=str(run.attrs.get("basis", "total")), terms=int(run.sizes["term"]),
                verdict=verdict)
