"""Convergence of multi-element OPA against Monte Carlo, with its cost beside the peers.

One run (:func:`run_convergence`) computes, on one model and one sigma over a window of
forcing periods:

* a Monte Carlo reference (scrambled Sobol, ``reference`` samples, its own seed);
* multi-element OPA against the number of elements K at fixed N (equal-probability
  elements, and the adaptive edges at the splits with refinement, for a budget of
  elements), and against N at fixed K, for the ``mean`` and ``saltation`` impact laws;
* the non-intrusive twin, multi-element Gauss collocation (Q nodes per element, each a
  true impact system), on the same edges;
* single-element OPA for N = 0..8, single-element collocation, and plain Monte Carlo and
  scrambled Sobol at increasing M (seeds other than the reference's);
* control variates: M true systems at stratified randomised-QMC points (the law of xi cut
  at the changes of the impact sequence, as the trust map's ensembles are) paired with the
  adaptive ME-OPA of ``order_budget`` elements (saltation law) as the control;

each with its RMS error of the mean x_0 (and of the standard deviation) over the window,
its right-hand-side evaluations (for OPA also times the Q nodes each one evaluates) and
its wall time. Slopes are fitted to log error against log K. The errors are meaningful
down to the reference's own standard error, which is stored beside them.

With several uncertain parameters (``uncertain="mu,c"``, ``sigma`` one scale per
parameter) the study runs what is sound in d dimensions: single-element OPA over the
orders (the multi-index basis), uniform boxes with K pieces per parameter (the K of
``uniform`` whose K^d boxes stay within ``MAX_BOXES``), adaptive boxes over the budgets,
the plain and Sobol' ladders (points of the product law in d dimensions) and the
reference. The parts built on the one-dimensional law of xi (the collocation twins on
element edges; the control-variate ladder, stratified at the splits along xi) are left
out, and :func:`skipped_parts` says why (in the log, the dataset's ``skipped`` and the
report). An OPA row's node right-hand sides are its right-hand sides times the nodes of
its cubature rule (``attrs["nodes"]``) in d dimensions, times Q = 2N + 1 in one.

The MC, Sobol and control-variate ladders are nested: each is one ensemble of its
largest M, run rung by rung, each rung's points held by the next (every replicate's, or
every stratum's, Sobol' sequence goes on). A rung's points are those of a separate
ensemble of that size (``sample_xi``; :func:`compare._strata.replicate_points`), so its
estimate is the one a separate ensemble would give; its cost (right-hand sides, seconds)
is that of all the true systems it holds. The runs of the study are listed by
:func:`study_runs`.
"""

from __future__ import annotations

import os
import re
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from functools import cached_property, partial

import numpy as np
import xarray as xr

from mc import cv_estimates, sample_xi, simulate_mc
from opa.engine import (
    collocation, ElementBudgetWarning, Execution, take_execution, MAX_BOXES, Oscillator, parse,
    preset, provenance_attrs,
    quadrature_order, run_measure, simulate_opa, SimulationError, SolverOptions, surrogate,
    surrogate_moments, System, time_grid, true_runs, uniform_edges, write_netcdf,
)
from compare._pairs import REPLICATES
from compare._strata import build_strata, replicate_allocation, replicate_points, split_values
from compare._verify import verify

STUDY_LAWS = ("mean", "saltation")
#: Sobol samples of the reference when a control-variate reference has no control
PLAIN_REFERENCE = 32768


@dataclass(frozen=True)
class ConvergenceConfig:
    """The section 3.2 set at omega = 3.98, sigma = 0.05, 10 periods, 2^16 Sobol samples.

    ``uncertain`` may name several parameters (``"mu,c"``), with ``sigma`` one scale or one
    per parameter and ``distribution`` one law or one per parameter (``"semicircle,uniform"``),
    as :class:`opa.System` takes them (and checks them)."""

    oscillator: Oscillator = field(default_factory=lambda: preset("3.2"))
    options: SolverOptions = field(default_factory=lambda: SolverOptions(rtol=1e-9, atol=1e-9))
    sigma: float | tuple[float, ...] = 0.05
    uncertain: str = "mu"
    distribution: str = "semicircle"
    periods: float = 10.0
    per_period: int = 8
    order: int = 1
    orders: tuple[int, ...] = (0, 1, 2, 4, 8)
    uniform: tuple[int, ...] = (1, 2, 4, 8, 16, 32, 64, 128)
    budgets: tuple[int, ...] = (4, 8, 16, 24, 32, 48, 64, 96, 128, 192, 256)
    order_budget: int = 64
    nodes: int = 2
    single_nodes: tuple[int, ...] = (1, 2, 4, 8, 16)
    mc_samples: tuple[int, ...] = (256, 512, 1024, 2048, 4096, 8192, 16384, 32768)
    reference: int = 65536
    #: the reference: "sobol" (``reference`` scrambled Sobol samples) or "control" (the
    #: control-variate estimate of ``reference`` true systems paired with the adaptive
    #: ME-OPA of ``order_budget`` elements, saltation law: compare.verify, stratified)
    reference_method: str = "sobol"
    seed: int = 1
    outdir: str = "results-elements"
    allow_negative: bool = False
    impulse: str = "dirac"  # the impulse model: opa.System's fields of the same names
    pulse_width: float = 0.1
    impulse_at_zero: bool = True

    @cached_property
    def system(self) -> System:
        """The :class:`opa.System` of the study (N = ``order``), built once."""
        return System(self.oscillator, sigma=self.sigma, uncertain=self.uncertain,
                      distribution=self.distribution, allow_negative=self.allow_negative,
                      order=self.order, impulse=self.impulse, pulse_width=self.pulse_width,
                      impulse_at_zero=self.impulse_at_zero)

    @property
    def dimension(self) -> int:
        """The number of uncertain parameters d."""
        return self.system.dimension

    def __post_init__(self):
        if isinstance(self.sigma, list):  # a frozen dataclass: JSON gives lists
            object.__setattr__(self, "sigma", tuple(self.sigma))
        self.system  # noqa: B018 -- validates the system's fields (sigma's count, laws)
        if not all(s > 0 for s in np.atleast_1d(self.sigma)):
            raise ValueError(f"sigma must be > 0, got {self.sigma}")
        for name in ("uniform", "budgets", "mc_samples", "orders", "single_nodes"):
            seq = getattr(self, name)
            if any(int(v) != v or v < 0 for v in seq):
                raise ValueError(f"{name} must be non-negative integers, got {seq}")
        if not self.budgets or not self.mc_samples:
            raise ValueError("budgets and mc_samples must not be empty")
        from opa.engine import MAX_ELEMENTS

        # the element rules of simulate_opa: counts 1..MAX_ELEMENTS, budgets 2..MAX_ELEMENTS
        # (boxes: K per parameter, K^d within MAX_BOXES, else left out; budgets 2..MAX_BOXES)
        most = MAX_ELEMENTS if self.dimension == 1 else MAX_BOXES
        for name, least, what in (("uniform", 1, "element counts of the uniform runs"),
                                  ("budgets", 2, "element budgets of the adaptive runs")):
            bad = [int(v) for v in getattr(self, name) if not least <= v <= most]
            if bad:
                raise ValueError(f"{name} ({what}) must be integers in {least}.."
                                 f"{most}, got {bad[0]}")
        if self.reference < 1024:
            raise ValueError(f"reference must be >= 1024 samples, got {self.reference}")
        if self.reference_method not in ("sobol", "control"):
            raise ValueError(f"reference_method must be 'sobol' or 'control', got "
                             f"{self.reference_method!r}")
        if self.reference_method == "control" and self.reference & (self.reference - 1):
            raise ValueError(f"a control-variate reference draws a power of two of true "
                             f"systems, got reference = {self.reference}")


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


@dataclass(frozen=True)
class StudyRun:
    """One run of the study: ``name`` (its part's name, file-name safe), ``spec`` (a
    JSON-able dict of everything it depends on) and ``compute()``, which does it and
    returns a dict of arrays, numbers and strings (a partial of a module function, so a
    run pickles and can be sent to a worker as it is)."""

    name: str
    spec: dict
    compute: Callable[[], dict]


@dataclass(frozen=True)
class _Setting:
    """What every run of one study shares: the law of xi, the System, the outputs."""

    measure: object
    base: System
    times: np.ndarray
    settings: dict


def _setting(cfg: ConvergenceConfig) -> _Setting:
    several = cfg.dimension > 1
    # several parameters: the System's product law (opa.Problem) is the law of xi
    measure = cfg.system.problem if several else parse(cfg.distribution)
    osc, opts = cfg.oscillator, cfg.options
    # what every run depends on; the errors also depend on the reference (samples, seed)
    sigma = list(np.atleast_1d(cfg.sigma).astype(float)) if several else cfg.sigma
    settings = {"oscillator": osc.as_dict(), "options": asdict(opts), "sigma": sigma,
                "uncertain": cfg.uncertain, "distribution": cfg.distribution,
                "periods": cfg.periods, "per_period": cfg.per_period,
                "allow_negative": cfg.allow_negative, "reference": cfg.reference,
                "seed": cfg.seed}
    if cfg.reference_method == "control":
        # "certificate": the version of compare.verify's design (2: stratified at the
        # splits), so that parts kept from the earlier design are not read back
        settings["reference_control"] = {"budget": int(cfg.order_budget),
                                         "order": int(cfg.order), "certificate": 2}
    if (cfg.impulse, cfg.pulse_width, cfg.impulse_at_zero) != ("dirac", 0.1, True):
        settings["impulse"] = [cfg.impulse, cfg.pulse_width, cfg.impulse_at_zero]
    base = cfg.system if several else cfg.system.replace(distribution=measure)
    return _Setting(measure, base, time_grid(osc.omega, cfg.periods, cfg.per_period), settings)


def uniform_counts(cfg: ConvergenceConfig) -> list[int]:
    """The K of ``uniform`` the study runs: all in one dimension; with d parameters those
    whose K^d boxes stay within ``MAX_BOXES``."""
    return [int(k) for k in cfg.uniform if int(k) ** cfg.dimension <= MAX_BOXES]


def skipped_parts(cfg: ConvergenceConfig) -> list[str]:
    """The parts of the study left out, each with why (none in one dimension)."""
    d = cfg.dimension
    if d == 1:
        return []
    out = [f"collocation (multi-element and one element) skipped: its Gauss nodes on "
           f"element edges are a rule of one uncertain parameter; this study has {d} "
           f"({','.join(cfg.system.uncertain)})",
           f"control-variate ladder skipped: its strata are cut at the splits along xi, "
           f"which exist for one uncertain parameter; this study has {d}"]
    big = [int(k) for k in cfg.uniform if int(k) ** d > MAX_BOXES]
    if big:
        out.append(f"uniform boxes K = {', '.join(map(str, big))} skipped: K^{d} boxes is "
                   f"more than {MAX_BOXES}")
    return out


def _run(setting: _Setting, name: str, spec: dict, compute, *args) -> StudyRun:
    return StudyRun(name, {**setting.settings, "run": name, **spec}, partial(compute, *args))


# -- the runs ------------------------------------------------------------------------------
def _control(cfg: ConvergenceConfig) -> tuple[xr.Dataset, float]:
    """The control: adaptive ME-OPA of ``order_budget`` elements (saltation law), and
    its wall time."""
    setting = _setting(cfg)
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ElementBudgetWarning)
        control = simulate_opa(
            setting.base.replace(order=cfg.order, impact_law="saltation"),
            elements="adaptive", tolerance=1e-14, max_elements=cfg.order_budget,
            times=setting.times, options=cfg.options)
    return control, time.perf_counter() - t


def _reference(cfg: ConvergenceConfig) -> dict:
    """The reference: the control-variate estimate of ``reference`` true systems on the
    control (:func:`compare.verify`, stratified), or ``reference`` Sobol samples; a
    control that cannot serve leaves ``PLAIN_REFERENCE`` Sobol samples (``note`` says
    why)."""
    t0 = time.perf_counter()
    if cfg.reference_method == "control":
        try:
            control, control_seconds = _control(cfg)
            t0 -= control_seconds
            cv = verify(control, samples=cfg.reference, max_samples=cfg.reference,
                        sequential=False, seed=cfg.seed)
        except (SimulationError, ValueError) as err:  # no control: plain Sobol
            note = (f"  the control run cannot serve ({err}): the reference is "
                    f"{PLAIN_REFERENCE} Sobol samples")
            return {**_plain_reference(cfg, PLAIN_REFERENCE, t0), "note": note}
        return {"x_mean": cv.cv_x_mean.values, "x_var": cv.cv_x_var.values,
                "x_sem": cv.cv_x_mean_sem.values,
                "rhs": int(control.attrs["rhs_evaluations"])
                + int(cv.attrs["verify_rhs_evaluations"]),
                "seconds": time.perf_counter() - t0,
                "text": reference_text(cfg.reference, "control", cfg.order_budget)}
    return _plain_reference(cfg, cfg.reference, t0)


def _plain_reference(cfg: ConvergenceConfig, samples: int, t0: float) -> dict:
    setting = _setting(cfg)
    ref = simulate_mc(setting.base.replace(order=0), samples=samples, sampler="sobol",
                      seed=cfg.seed, progress=False, times=setting.times,
                      options=cfg.options)
    return {"x_mean": ref.x_mean.values, "x_var": ref.x_var.values,
            "x_sem": ref.x_sem.values, "rhs": int(ref.attrs["rhs_evaluations"]),
            "seconds": time.perf_counter() - t0,
            "text": reference_text(samples, "sobol", cfg.order_budget),
            "samples": int(samples)}


def _errors(ref: dict, mean, var) -> tuple[float, float]:
    """RMS errors of the mean and of the standard deviation against the reference."""
    return (_rms(mean - ref["x_mean"]),
            _rms(np.sqrt(np.maximum(var, 0.0)) - np.sqrt(ref["x_var"])))


def _opa(cfg: ConvergenceConfig, ref: dict, law: str, order: int, kw: dict) -> dict:
    """One OPA row: ``simulate_opa`` with ``kw`` (elements, budget); a diverged OPA
    system gives ``failure`` instead of an error."""
    setting = _setting(cfg)
    t = time.perf_counter()
    try:
        with warnings.catch_warnings():  # the budget is the study's variable
            warnings.simplefilter("ignore", ElementBudgetWarning)
            ds = simulate_opa(setting.base.replace(order=order, impact_law=law),
                              times=setting.times, options=cfg.options, **kw)
    except SimulationError as err:  # a diverged OPA system: no error to report
        return {"failure": str(err), "seconds": time.perf_counter() - t}
    sec = time.perf_counter() - t
    e, s = _errors(ref, ds.x_mean.values, ds.x_var.values)
    out = {"error": e, "sd_error": s, "rhs": int(ds.attrs["rhs_evaluations"]),
           "elements": int(ds.attrs["elements"]), "nodes": int(ds.attrs.get("nodes", 1)),
           "seconds": sec}
    if "element_edges" in ds:
        out["edges"] = ds.element_edges.values
    return out


def _collocation(cfg: ConvergenceConfig, ref: dict, edges, nodes: int) -> dict:
    """One collocation row: ``nodes`` Gauss nodes on each element cut at ``edges``."""
    setting = _setting(cfg)
    t = time.perf_counter()
    mean, var, rhs = collocation(setting.base, cfg.options, setting.measure,
                                 np.asarray(edges, float), nodes, times=setting.times)
    sec = time.perf_counter() - t
    e, s = _errors(ref, mean, var)
    return {"error": e, "sd_error": s, "rhs": int(rhs), "seconds": sec}


def ladder_sizes(cfg: ConvergenceConfig) -> list[int]:
    """The rungs of the MC and Sobol ladders (ascending)."""
    return sorted({int(m) for m in cfg.mc_samples})


def ladder_replicates(cfg: ConvergenceConfig) -> int:
    """The Sobol ladder's independent scramblings: 16 when every rung is a multiple of 16
    and >= 64 (``simulate_mc``'s default at each rung), else 1."""
    return 16 if all(m % 16 == 0 and m >= 64 for m in ladder_sizes(cfg)) else 1


def ladder_rows(sizes, replicates: int) -> list[np.ndarray]:
    """The rows of the largest ensemble that each rung holds: with R replicates of P =
    max / R points each (replicate r in rows r P .. (r + 1) P - 1), rung M holds the first
    M / R points of every replicate, which is ``sample_xi``'s set of M points (each
    replicate's Sobol' sequence goes on from M to 2M); with one replicate, the first M.

    >>> [r.tolist() for r in ladder_rows([2, 4], 2)]
    [[0, 2], [0, 1, 2, 3]]
    """
    most = max(sizes)
    per = most // replicates
    return [np.concatenate([np.arange(r * per, r * per + m // replicates)
                            for r in range(replicates)]) for m in sizes]


def _ladder_paths(cfg: ConvergenceConfig, sampler: str, replicates: int):
    """The largest ensemble of the ladder, run rung by rung (each rung only its new
    rows): x (M, T), xi (M,), and per rung the rows, the right-hand sides and the wall
    seconds of every true system it holds."""
    setting = _setting(cfg)
    sizes = ladder_sizes(cfg)
    if cfg.dimension > 1:  # the points simulate_mc draws in d dimensions (M, d)
        xi = cfg.system.problem.sample(sizes[-1], sampler, cfg.seed + 1, replicates)
    else:
        xi, _ = sample_xi(sampler, sizes[-1], cfg.seed + 1, replicates=replicates,
                          distribution=setting.measure)
    rows = ladder_rows(sizes, replicates)
    x = np.empty((len(xi), len(setting.times)))
    system = setting.base.replace(order=0)
    rhs, seconds, done = [], [], np.zeros(0, np.int64)
    total_rhs, total_seconds = 0, 0.0
    for held in rows:
        new = np.setdiff1d(held, done)
        t = time.perf_counter()
        paths, n_rhs = true_runs(system, cfg.options, xi[new], setting.times,
                                 what=f"{sampler} ladder sample")
        x[new] = paths[:, :, 0]
        total_rhs += n_rhs
        total_seconds += time.perf_counter() - t
        rhs.append(total_rhs)
        seconds.append(total_seconds)
        done = held
    return x, xi, rows, np.array(rhs, np.int64), np.array(seconds)


def _mc_ladder(cfg: ConvergenceConfig, ref: dict) -> dict:
    """Plain Monte Carlo at every rung, the rungs nested prefixes of one ensemble of
    independent points (``sample_xi("random")``: the first M of the largest are the
    M points of a run of M): the mean and the sample variance (Bessel's M / (M - 1))."""
    x, _, rows, rhs, seconds = _ladder_paths(cfg, "random", 1)
    err = np.array([_errors(ref, x[r].mean(axis=0), x[r].var(axis=0, ddof=1))
                    for r in rows])
    return {"sizes": np.array([len(r) for r in rows]), "error": err[:, 0],
            "sd_error": err[:, 1], "rhs": rhs, "seconds": seconds}


def _sobol_ladder(cfg: ConvergenceConfig, ref: dict) -> dict:
    """Scrambled Sobol' at every rung, over one ensemble whose rungs are nested
    (:func:`ladder_rows`): the mean, and the variance about it plus the replicates'
    variance of the mean (as ``simulate_mc``)."""
    R = ladder_replicates(cfg)
    x, _, rows, rhs, seconds = _ladder_paths(cfg, "sobol", R)
    err = []
    for r in rows:
        xs = x[r].reshape(R, -1, x.shape[1])
        means = xs.mean(axis=1)
        sem2 = means.var(axis=0, ddof=1) / R if R > 1 else 0.0
        err.append(_errors(ref, xs.mean(axis=(0, 1)), xs.var(axis=(0, 1)) + sem2))
    error, sd_error = np.array(err).T
    return {"sizes": np.array([len(r) for r in rows]), "error": error, "sd_error": sd_error,
            "rhs": rhs, "seconds": seconds}


def cv_sizes(cfg: ConvergenceConfig) -> list[int]:
    """The rungs of the control-variate ladder: those of ``mc_samples`` that are powers
    of two, at least 2 points per replicate (``REPLICATES`` of them) on the first."""
    return [m for m in ladder_sizes(cfg) if m >= 2 * REPLICATES and not m & (m - 1)]


def stratified_rows(allocation, replicates: int, scale: int, most: int) -> np.ndarray:
    """The rows of :func:`compare._strata.replicate_points` at ``scale`` among those at
    ``most`` (a multiple of it): in each replicate and stratum, the first ``scale *
    allocation[j]`` of its ``most * allocation[j]`` points (each stratum's Sobol'
    sequence goes on).

    >>> stratified_rows([1, 2], 2, 1, 2).tolist()
    [0, 2, 3, 6, 8, 9]
    """
    counts = np.asarray(allocation, int)
    starts = np.concatenate([[0], np.cumsum(counts * most)[:-1]])
    per = int(counts.sum()) * most
    return np.concatenate([r * per + start + np.arange(scale * n)
                           for r in range(replicates) for start, n in zip(starts, counts)])


def _cv_design(cfg: ConvergenceConfig):
    """The control-variate ladder's points: the law of xi cut at the changes of the
    impact sequence over the window (:func:`compare._strata.split_values`, zones merged to
    at most half the first rung's points per replicate), stratified randomised QMC in
    ``REPLICATES`` replicates (:func:`compare._strata.replicate_points`) at the largest
    rung; returns xi, weights, the allocation and the strata."""
    setting = _setting(cfg)
    sizes = cv_sizes(cfg)
    per_replicate = sizes[0] // REPLICATES
    split_xi, complete = split_values(setting.base.replace(order=0), cfg.options,
                                      setting.measure, float(setting.times[-1]))
    lo, hi = setting.measure.lo, setting.measure.hi
    strata = build_strata(setting.measure, [lo, hi], split_xi, complete=complete,
                          max_strata=max(1, per_replicate // 2))
    allocation = replicate_allocation(per_replicate, strata.probability)
    xi, weights, _ = replicate_points(setting.measure, strata, allocation, REPLICATES,
                                      cfg.seed + 1, sizes[-1] // sizes[0])
    return xi, weights, allocation, strata


def _cv_ladder(cfg: ConvergenceConfig, ref: dict) -> dict:
    """Control variates at every rung of :func:`cv_sizes`: the true systems at the points
    of one stratified design (:func:`_cv_design`; a rung's points are the first of every
    stratum's Sobol' sequence in every replicate, the same as a design of that size)
    paired with the surrogate of the adaptive ME-OPA of ``order_budget`` elements
    (saltation law): per replicate the weighted means of x, x^2, x_hat, x_hat^2, and
    :func:`mc.cv_estimates`. Each rung pays for the control run and its true systems."""
    setting = _setting(cfg)
    sizes = cv_sizes(cfg)
    if not sizes:
        return {"sizes": np.zeros(0, np.int64), "error": np.zeros(0),
                "sd_error": np.zeros(0), "rhs": np.zeros(0, np.int64), "seconds": np.zeros(0)}
    control, control_seconds = _control(cfg)
    t = time.perf_counter()
    xi, weights, allocation, _ = _cv_design(cfg)
    most = sizes[-1] // sizes[0]
    x_hat = surrogate(control, xi, measure=run_measure(control))[0]
    moments = surrogate_moments(control)
    x = np.empty_like(x_hat)
    system, done = setting.base.replace(order=0), np.zeros(0, np.int64)
    rhs, seconds, err, total = [], [], [], int(control.attrs["rhs_evaluations"])
    for m in sizes:
        held = stratified_rows(allocation, REPLICATES, m // sizes[0], most)
        new = np.setdiff1d(held, done)
        paths, n_rhs = true_runs(system, cfg.options, xi[new], setting.times,
                                 what="control-variate sample")
        x[new], done, total = paths[:, :, 0], held, total + n_rhs
        # each replicate's weights sum to 1 (P_j / n_j, n_j the stratum's points here)
        w = (weights[held] * (most * sizes[0] // m)).reshape(REPLICATES, -1, 1)
        xs, hs = x[held].reshape(REPLICATES, -1, len(setting.times)), \
            x_hat[held].reshape(REPLICATES, -1, len(setting.times))
        est = cv_estimates((w * xs).sum(1), (w * xs**2).sum(1), moments["x_mean"],
                           moments["x_second"], (w * hs).sum(1), (w * hs**2).sum(1))
        err.append(_errors(ref, est["mean"], est["var"]))
        rhs.append(total)
        seconds.append(control_seconds + time.perf_counter() - t)
    error, sd_error = np.array(err).T
    return {"sizes": np.array(sizes), "error": error, "sd_error": sd_error,
            "rhs": np.array(rhs, np.int64), "seconds": np.array(seconds)}


# -- the list of runs ----------------------------------------------------------------------
def _opa_specs(cfg: ConvergenceConfig) -> list[tuple]:
    """(method, law, size, order, simulate_opa keywords) of every OPA row, in row order."""
    specs = []
    adaptive = dict(elements="adaptive", tolerance=1e-14)
    for law in STUDY_LAWS:
        specs += [("ME-OPA uniform", law, int(k), cfg.order, dict(elements=int(k)))
                  for k in uniform_counts(cfg)]
        specs += [("ME-OPA adaptive", law, None, cfg.order, {**adaptive,
                                                             "max_elements": int(b)})
                  for b in cfg.budgets]
        for n in cfg.orders:
            specs.append(("ME-OPA adaptive, N", law, None, n,
                          {**adaptive, "max_elements": cfg.order_budget}))
            specs.append(("OPA (one element), N", law, 1, n, dict(elements=1)))
    return specs


def _opa_name(method: str, law: str, order: int, kw: dict) -> str:
    return _slug(f"{method}-{law}-N{order}-K{kw.get('max_elements', kw.get('elements'))}")


def _collocation_specs(cfg: ConvergenceConfig, known: dict) -> list[tuple]:
    """(method, edges, nodes) of every collocation row whose edges are known, in row
    order: the adaptive rows take the edges the adaptive ME-OPA (saltation law) of the
    same budget chose, once that run is ``known``. None with several parameters."""
    if cfg.dimension > 1:
        return []
    measure = parse(cfg.distribution)
    specs = [("ME-collocation uniform", uniform_edges(measure, int(k)), cfg.nodes)
             for k in cfg.uniform]
    for b in cfg.budgets:
        run = known.get(_opa_name("ME-OPA adaptive", "saltation", cfg.order,
                                  {"max_elements": int(b)}))
        if run is not None and "edges" in run:
            specs.append(("ME-collocation adaptive", np.asarray(run["edges"], float),
                          cfg.nodes))
    whole = np.array([measure.lo, measure.hi])
    specs += [("collocation (one element), Q", whole, int(q)) for q in cfg.single_nodes]
    return specs


def _collocation_name(method: str, edges, nodes: int) -> str:
    return _slug(f"{method}-K{len(edges) - 1}-Q{nodes}")


def _ladder_names(cfg: ConvergenceConfig) -> tuple[str, ...]:
    """The ladders' run names: MC, Sobol and (one parameter only) control variates."""
    most = ladder_sizes(cfg)[-1]
    names = (_slug(f"MC ladder-M{most}"), _slug(f"QMC (Sobol) ladder-M{most}"),
             _slug(f"CV-K{cfg.order_budget} ladder-M{most}"))
    return names if cfg.dimension == 1 else names[:2]


def study_runs(cfg: ConvergenceConfig, known: dict) -> list[StudyRun]:
    """Every run of the study that can be named given the runs ``known`` (name -> result):
    the reference alone until it is known (every row's error depends on it); then every
    OPA row, the collocation rows (the adaptive ones once the adaptive ME-OPA run whose
    edges they take is known), and the two nested ladders. The study is complete when
    every run listed is known; the list is the same whoever computes the runs."""
    setting = _setting(cfg)
    runs = [_run(setting, "reference", {}, _reference, cfg)]
    if "reference" not in known:
        return runs
    ref = {name: np.asarray(known["reference"][name]) for name in ("x_mean", "x_var")}
    for method, law, _, order, kw in _opa_specs(cfg):
        runs.append(_run(setting, _opa_name(method, law, order, kw),
                         {"method": method, "law": law, "order": order, **kw},
                         _opa, cfg, ref, law, order, kw))
    for method, edges, nodes in _collocation_specs(cfg, known):
        runs.append(_run(setting, _collocation_name(method, edges, nodes),
                         {"method": method, "edges": edges.tolist(), "nodes": int(nodes)},
                         _collocation, cfg, ref, edges, int(nodes)))
    mc, sobol, *cv = _ladder_names(cfg)
    ladder = {"samples": ladder_sizes(cfg), "ladder_seed": cfg.seed + 1, "nested": 1}
    runs.append(_run(setting, mc, {**ladder, "sampler": "random"}, _mc_ladder, cfg, ref))
    runs.append(_run(setting, sobol, {**ladder, "sampler": "sobol",
                                      "replicates": ladder_replicates(cfg)},
                     _sobol_ladder, cfg, ref))
    runs += [_run(setting, name, {**ladder, "samples": cv_sizes(cfg),
                                   "sampler": "stratified sobol at the splits",
                                   "replicates": REPLICATES,
                                   "control": {"budget": int(cfg.order_budget),
                                               "order": int(cfg.order)}},
                  _cv_ladder, cfg, ref) for name in cv]
    unique = {run.name: run for run in runs}  # two budgets may stop at the same edges
    return list(unique.values())


def pending_runs(cfg: ConvergenceConfig, known: dict) -> list[StudyRun]:
    """The runs of :func:`study_runs` not yet ``known``."""
    return [run for run in study_runs(cfg, known) if run.name not in known]


def run_convergence(cfg: ConvergenceConfig, *, write: bool = True, memo=None,
                    execution: Execution | None = None, **legacy) -> xr.Dataset:
    """Run the study; returns its dataset (also written to OUTDIR/convergence.nc unless
    ``write`` is false).

    The runs are those :func:`study_runs` lists, computed stage by stage (the reference;
    then the rows and ladders; then the adaptive collocation rows, which take the adaptive
    runs' edges) until every run listed is known, and the dataset is assembled from them
    (:func:`assemble_study`). With ``memo``, each run is ``memo(name, spec, compute)``,
    which returns ``compute()`` or the result an identical earlier call returned (the
    trust map keeps them in its parts, :class:`opa._dataset.Store`). The dataset's
    ``wall_seconds`` is the sum of the runs' wall times (for reused runs, the time they
    took when they were done).

    ``execution`` (:class:`opa.Execution`): with ``workers`` > 1 or a Dask ``scheduler``
    (and no ``memo``), each stage's runs are tasks side by side
    (:func:`compare._scaleout.run_tasks`), and the rows are the same as in one process;
    its ``log`` takes the progress lines. Default: in this process, lines to ``print``;
    the keywords ``log``, ``workers`` and ``scheduler`` of earlier releases are still
    taken.
    """
    where, log = _convergence_run(execution, legacy)
    pooled = (where.workers > 1 or where.scheduler is not None) and memo is None
    log(f"reference: {reference_text(cfg.reference, cfg.reference_method, cfg.order_budget)}"
        f" ...")
    known: dict = {}
    while todo := pending_runs(cfg, known):
        if pooled and todo[0].name != "reference":
            from compare._scaleout import run_tasks

            log(f"{len(todo)} runs of the study as tasks ...")
            tasks = [(run.name, run.compute, ()) for run in todo]
            known.update(run_tasks(tasks, execution=where))
            continue
        for run in todo:
            known[run.name] = run.compute() if memo is None else memo(run.name, run.spec,
                                                                      run.compute)
    ds = assemble_study(cfg, known, log=log)
    if write:
        write_netcdf(ds, os.path.join(cfg.outdir, "convergence.nc"))
    return ds


def _convergence_run(execution, legacy: dict) -> tuple[Execution, Callable]:
    """(where the study runs, its log) of :func:`run_convergence`'s inputs."""
    unknown = sorted(set(legacy) - {"log", "workers", "scheduler"})
    if unknown:
        raise TypeError(f"run_convergence() got an unexpected keyword argument "
                        f"{unknown[0]!r}")
    log = legacy.pop("log", None)
    if execution is not None and log is not None:
        raise ValueError("run_convergence: give log inside execution=Execution(...), not "
                         "beside it")
    run = take_execution(execution, legacy, "run_convergence").only(
        "run_convergence", "workers", "scheduler", "connect_timeout", "worker_timeout")
    if execution is not None:
        return run, run.log or (lambda line: None)
    return run, print if log is None else log


# -- the dataset ---------------------------------------------------------------------------
def _rows(cfg: ConvergenceConfig, known: dict, log) -> tuple[list, list[str]]:
    """(method, law, size, N, error, sd error, rhs, node rhs, seconds) of every row, in
    the study's order, and the OPA runs that failed (left out)."""
    rows, failures = [], []
    for method, law, size, order, kw in _opa_specs(cfg):
        result = known[_opa_name(method, law, order, kw)]
        if "failure" in result:
            log(f"  {method} ({law}), N = {order}, {kw}: {result['failure']}")
            failures.append(f"{method} ({law} law), N = {order}, "
                            f"{kw.get('max_elements', kw.get('elements'))}: "
                            f"{result['failure']}")
            continue
        rhs = int(result["rhs"])
        # the nodes each right-hand side evaluates: Q = 2N + 1, or the cubature's in d dims
        q = (int(result["nodes"]) if cfg.dimension > 1
             else 1 if order == 0 else quadrature_order(order))
        rows.append((method, law, size if size is not None else int(result["elements"]),
                     order, float(result["error"]), float(result["sd_error"]), rhs, rhs * q,
                     float(result["seconds"])))
    # the row order of the collocation: uniform, adaptive, one element (as listed)
    for method, edges, nodes in _collocation_specs(cfg, known):
        result = known[_collocation_name(method, edges, nodes)]
        rows.append((method, "true system", len(edges) - 1, int(nodes),
                     float(result["error"]), float(result["sd_error"]), int(result["rhs"]),
                     int(result["rhs"]), float(result["seconds"])))
    names = ("MC", "QMC (Sobol)", f"control variate (ME-OPA K={cfg.order_budget})")
    for name, run in zip(names, _ladder_names(cfg)):
        ladder = known[run]
        for k, m in enumerate(ladder["sizes"]):
            rows.append((name, "true system", int(m), 0, float(ladder["error"][k]),
                         float(ladder["sd_error"][k]), int(ladder["rhs"][k]),
                         int(ladder["rhs"][k]), float(ladder["seconds"][k])))
    return rows, failures


def assemble_study(cfg: ConvergenceConfig, known: dict, *, log=print) -> xr.Dataset:
    """The study's dataset from its runs ``known`` (every run :func:`study_runs` lists)."""
    ref = known["reference"]
    if "note" in ref:
        log(str(ref["note"]))
    skipped = skipped_parts(cfg)
    if skipped:
        log("multi-element OPA (boxes) and the Monte Carlo and Sobol ladders ...")
        for line in skipped:
            log(f"  {line}")
    else:
        log("multi-element OPA, collocation, the Monte Carlo and Sobol ladders and control "
            "variates on the adaptive ME-OPA (saltation law) ...")
    rows, failures = _rows(cfg, known, log)
    setting = _setting(cfg)
    cols = list(zip(*rows))
    one = {"units": "1"}
    ds = xr.Dataset(
        {
            "method": ("run", np.array(cols[0], dtype=object),
                       {"long_name": "method of the run (ME-OPA uniform or adaptive, "
                        "collocation, MC, QMC (Sobol), control variate, ...)"}),
            "law": ("run", np.array(cols[1], dtype=object),
                    {"long_name": "impact law of the OPA system, or 'true system'"}),
            "size": ("run", np.array(cols[2], dtype=np.int64),
                     {"long_name": "elements (OPA, collocation) or samples (MC)", **one}),
            "order": ("run", np.array(cols[3], dtype=np.int64),
                      {"long_name": "N (OPA) or nodes per element (collocation)", **one}),
            "error": ("run", np.array(cols[4]), {"long_name": "RMS error of E[x] over the "
                                                 "window against the reference", **one}),
            "sd_error": ("run", np.array(cols[5]), {"long_name": "RMS error of the standard "
                                                    "deviation of x", **one}),
            "rhs_evaluations": ("run", np.array(cols[6], dtype=np.int64),
                                {"long_name": "right-hand-side evaluations", **one}),
            "node_rhs_evaluations": ("run", np.array(cols[7], dtype=np.int64),
                                     {"long_name": "right-hand sides times the nodes each "
                                      "evaluates (OPA: Q = 2N + 1)", **one}),
            "seconds": ("run", np.array(cols[8]), {"long_name": "wall time", "units": "s"}),
        },
        coords={"run": ("run", np.arange(len(rows)), {"long_name": "run index", **one})},
        attrs=provenance_attrs("convergence", setting.base, cfg.options, seed=cfg.seed,
                               sampler="sobol"),
    )
    ds.attrs.update(
        periods=float(cfg.periods), per_period=int(cfg.per_period),
        distribution=(setting.measure.name if cfg.dimension == 1
                      else str(cfg.system.problem.attrs()["distribution"])),
        skipped=" | ".join(skipped) if skipped else "none",
        reference_samples=int(ref.get("samples", cfg.reference)),
        reference_method="sobol" if "samples" in ref else cfg.reference_method,
        reference_text=str(ref.get("text", reference_text(cfg.reference, cfg.reference_method,
                                                          cfg.order_budget))),
        reference_sem=_rms(ref["x_sem"]), reference_seconds=float(ref["seconds"]),
        reference_rhs_evaluations=int(ref["rhs"]),
        # every run once (a ladder's rungs share its runs)
        wall_seconds=float(sum(float(np.max(r["seconds"], initial=0.0))
                               for r in known.values())),
        failures=len(failures),
        failure_text=" | ".join(failures) if failures else "none",
    )
    return ds


def reference_text(samples: int, method: str, budget: int) -> str:
    """The reference in words."""
    if method == "control":
        return (f"the control-variate estimate from {samples} true systems on the adaptive "
                f"ME-OPA (K = {budget}, saltation law)")
    return f"{samples} Sobol samples"


def _slug(text: str) -> str:
    """A file-name-safe form of a run's name."""
    return re.sub(r"[^A-Za-z0-9.]+", "-", text).strip("-")


def _select(ds, method, law=None):
    sel = ds.method.values == method
    if law is not None:
        sel &= ds.law.values == law
    return np.flatnonzero(sel)


def slope(ds, method, law, lo=None) -> float:
    """Fitted slope of log error against log K (elements), over K >= lo."""
    idx = _select(ds, method, law)
    k = ds["size"].values[idx].astype(float)
    e = ds.error.values[idx]
    ok = (k >= (lo or 1)) & (e > 0)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(k[ok]), np.log(e[ok]), 1)[0])


def cheapest_reaching(ds, method, target, law=None):
    """The run of ``method`` with the fewest right-hand sides reaching ``target``."""
    idx = [i for i in _select(ds, method, law) if ds.error.values[i] <= target]
    return min(idx, key=lambda i: ds.rhs_evaluations.values[i]) if idx else None


def table(ds, *, markdown=True) -> str:
    head = ["method", "law", "K / M", "N / Q", "RMS error E[x]", "RMS error sd", "RHS",
            "node RHS", "wall [s]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i in range(ds.sizes["run"]):
        lines.append("| " + " | ".join([
            str(ds.method.values[i]), str(ds.law.values[i]), str(int(ds["size"].values[i])),
            str(int(ds.order.values[i])), f"{ds.error.values[i]:.2e}",
            f"{ds.sd_error.values[i]:.2e}", f"{int(ds.rhs_evaluations.values[i]):,}",
            f"{int(ds.node_rhs_evaluations.values[i]):,}", f"{ds.seconds.values[i]:.2f}",
        ]) + " |")
    return "\n".join(lines)


def summary_lines(ds) -> list[str]:
    out = []
    a = ds.attrs
    reference = a.get("reference_text", f"{a['reference_samples']} Sobol samples")
    out.append(f"Reference: {reference}, RMS standard error "
               f"{a['reference_sem']:.1e} (errors near it are not resolved). An adaptive "
               f"run's wall time includes its split search unless one of the last 8 "
               f"searches was of the same problem with the same split budget.")
    if a.get("failures", 0):
        out.append(f"{a['failures']} OPA runs diverged and are left out: {a['failure_text']}")
    if a.get("skipped", "none") != "none":
        out += [f"{part[0].upper()}{part[1:]}." for part in str(a["skipped"]).split(" | ")]
    for law in STUDY_LAWS:
        for method in ("ME-OPA uniform", "ME-OPA adaptive"):
            idx = _select(ds, method, law)
            if len(idx) >= 2:
                e = ds.error.values[idx]
                k = ds["size"].values[idx]
                out.append(f"{method}, {law} law, N = {int(ds.order.values[idx[0]])}: error "
                           f"{e[0]:.1e} (K = {k[0]}) → {e[-1]:.1e} (K = {k[-1]}); fitted slope "
                           f"{slope(ds, method, law, lo=2):.2f} in K for K ≥ 2.")
    for target in (1e-3, 1e-4):
        me = cheapest_reaching(ds, "ME-OPA adaptive", target, "saltation")
        qmc = cheapest_reaching(ds, "QMC (Sobol)", target)
        if me is None:
            out.append(f"Adaptive ME-OPA (saltation) does not reach {target:g} within the "
                       f"budgets tried.")
            continue
        text = (f"To reach {target:g}: adaptive ME-OPA (saltation law) with K = "
                f"{int(ds['size'].values[me])} elements, {int(ds.rhs_evaluations.values[me]):,}"
                f" right-hand sides ({int(ds.node_rhs_evaluations.values[me]):,} node "
                f"evaluations), {ds.seconds.values[me]:.2f} s")
        if qmc is not None:
            r = ds.rhs_evaluations.values[qmc] / ds.rhs_evaluations.values[me]
            rn = ds.rhs_evaluations.values[qmc] / ds.node_rhs_evaluations.values[me]
            text += (f"; Sobol with M = {int(ds['size'].values[qmc])}: "
                     f"{int(ds.rhs_evaluations.values[qmc]):,} right-hand sides, "
                     f"{ds.seconds.values[qmc]:.2f} s — {r:.0f}× more right-hand sides "
                     f"({rn:.0f}× more node evaluations).")
        else:
            text += "; no Sobol run of the ladder reaches it."
        out.append(text)
    return out


def write_report(ds, outdir, *, draw, command="opa-mc converge") -> list[str]:
    """convergence.md and convergence.png in ``outdir``; ``draw(ds, path)`` draws the
    figure (``compare._report.plot_frontier``, the trust map's frontier figure: the study
    is the same)."""
    os.makedirs(outdir, exist_ok=True)
    png = draw(ds, os.path.join(outdir, "convergence.png"))
    md = os.path.join(outdir, "convergence.md")
    with open(md, "w") as fh:
        fh.write(f"# Multi-element OPA against Monte Carlo\n\nCommand: `{command}` "
                 f"({ds.attrs['wall_seconds']:.0f} s)\n\n")
        fh.write("\n".join(f"- {line}" for line in summary_lines(ds)) + "\n\n")
        fh.write(table(ds) + "\n\n![convergence](convergence.png)\n")
    return [md, png]


__all__ = ["ConvergenceConfig", "StudyRun", "assemble_study", "cheapest_reaching", "cv_sizes",
           "ladder_rows", "pending_runs", "run_convergence", "skipped_parts", "slope",
           "stratified_rows", "study_runs", "summary_lines", "table", "uniform_counts",
           "write_report"]
