"""The trust map: where does OPA agree with Monte Carlo, where does it stop, and why?

Over a grid of the intensity sigma and one model parameter q (default: omega over the
section 3.2 range), each point runs

* a Monte Carlo ensemble of the true sampled impact system (scrambled Sobol, randomised-QMC
  standard errors of the mean and the variance), with more samples only while a verdict
  is undecided (:func:`judge`: three-valued, as :func:`compare.verify`'s);
* the OPA equivalent system for every N and every variant (impact law x truncation),
  all compared with that one ensemble; under a law of xi other than the semicircle
  (``distribution``) the single element runs in that law's orthonormal basis and the
  ``paper`` truncation (eq. (27), the semicircle's) is left out;
* with ``elements`` (K, or ``"adaptive"`` with a budget), multi-element OPA under the
  mean, ensemble and saltation impact laws at N = Nmax, each with its own verdicts and
  sigma* beside the single-element ones. These are what ``simulate_opa`` with elements
  gives: an element whose OPA system diverges is computed by collocation of the true
  systems (counted in ``variant_collocated``). The single-element variants are the
  paper's OPA: a run that cannot be completed is NaN from there on, and disagrees;

and gives, per horizon, the RMS error of x_0 and of the variance (absolute, in MC standard
errors, relative to the spread) with the verdict of :mod:`compare._trust`. For each q,
``sigma*`` -- the largest sigma at which OPA at the highest N is certified to agree (an
undecided verdict counts as not agreeing) -- is located by
bisection in sigma between the last agreeing and the first failing grid value. The sampled
systems' impact sequences are scanned along the uncertain parameter
(:func:`opa._splits.scan_splits`): their splits, what happens there, and the distribution
of impact counts at every grid point say *why* the boundary is where it is.

Every piece of work is written to ``OUTDIR/parts/`` as it finishes, a store
(:class:`opa._dataset.Store`) shared by every map written to OUTDIR, and reused by a
rerun, so an interrupted map resumes and a finished one is reassembled without
integrating anything. Each part is keyed by a hash of the inputs of the call that
computes it (the System, the output times, the options, ...), which its file name ends
in and its file stores::

    mc_<q><value>_sigma<sigma>_M<samples>_<key>.nc   a Monte Carlo ensemble's moments
    opa_<q><value>_sigma<sigma>_N<order>_<key>.npz   OPA at one N, the single-element variants
    elements_<q><value>_sigma<sigma>_N<order>_<key>.npz  multi-element OPA (N = Nmax), per law
    splits_<q><value>_<key>.npz                      the split scan at one value
    details_<q><value>_sigma<sigma>_<key>.nc         phase portraits, EMR_0 against DMR
    frontier_<run>_<key>.npz                         one run of the cost-accuracy study

A part that cannot be read, or stores another key (a file copied or left from other
inputs), is named in the log, moved aside to ``<name>.bad`` and computed again;
temporaries left by a killed run are removed when the next one starts. A parts folder
of a version before the store is refused, naming it: remove it to start over.

The map itself is assembled per point (:mod:`compare._mapdata`): each grid point (value,
sigma) gives a dataset (``point_dataset``: its errors, verdicts, Monte Carlo moments,
impact counts), each swept value one more (``value_dataset``: sigma*, the bisection
probes, the splits); a value's are joined into its slice of the map (``value_slice``),
its bulk (the time series) written to ``OUTDIR/slices/`` as the value is done
(``spill``), and ``combine_slices`` joins the slices, the bulk read lazily from those
files, with the map-wide variables: ``run_validation`` writes validate.nc from them
without holding the whole map in memory, then removes the files.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
import xarray as xr

from compare._config import ELEMENT_TOLERANCE, ValidateConfig, noise_floor
from compare._mapdata import (NOT_FORMED, HorizonSplits, Point, combine_slices, point_dataset,
                              splits_from_arrays, splits_to_arrays, value_dataset, value_slice)
from compare._mapdata import spill as spill_slice
from compare._ledger import Ledger, Work
from compare._pairs import REPLICATES, Control, Pairs, pair_point
from compare._strata import (CONTINUOUS_KINDS, Strata, build_strata, grown_rows,
                             replicate_allocation, replicate_points)
from compare._trust import (band_multiplier, bisect_boundary, bound_excess, excess,
                            window_errors_all)
from mc import simulate_mc
from opa.engine import (
    CHATTER_WINDOW, Execution, MAX_CROSSINGS, MAX_SPLITS, MIN_SPLITS, adaptive_edges,
    collocate_element,
    true_runs,
    Measure, opa_variants, provenance_attrs, run_elements, SampledRuns, scan_splits,
    ScanOptions,
    simulate_dmr, simulate_opa, SimulationError, SolverOptions, Store, System,
    time_grid, true_system_work, uniform_edges,
)

#: the variance criterion's floor holds this many units of roundoff of E[x^2]
VAR_ROUNDOFF = 16
#: how the map's verdicts are formed (a part stored under another rule is not reused)
RULE = ("bounded: Bonferroni t band, alpha / 2^round; replicates stratified at the splits; "
        "variance floor with roundoff")


def _name(cfg: ValidateConfig, value, sigma=None) -> str:
    name = f"{cfg.parameter}{value:g}"
    return name if sigma is None else f"{name}_sigma{sigma:.6g}"


def _outputs(cfg: ValidateConfig) -> list[int]:
    """The outputs up to each horizon (in ``cfg.horizons`` order), the first included."""
    return [int(round(h * cfg.per_period)) + 1 for h in cfg.horizons]


# -- one point -----------------------------------------------------------------------------
def design(cfg: ValidateConfig, work: Work, value, sigma, times) -> tuple[Strata, np.ndarray]:
    """The point's strata and points per stratum in each replicate at the first round.

    The law of xi is cut at the changes of the impact sequence up to the point's last
    output that the value's split scan located within sigma (continuous kinds left
    out; cascades are zones, merged until at most half the first round's points per
    replicate, :func:`compare._strata.build_strata`), so a rare region that makes
    other impacts has points of its own in every replicate and every replicate is an
    estimate of the same quantity (the failure of plain replicates the certificate
    suite measured). ``complete``: the scan listed every such change within sigma."""
    measure = cfg.measure()
    centre, scans = value_splits(cfg, work, value)
    end = float(times[-1]) / cfg.oscillator_at(value).forcing_period
    reach = [scan for scan in scans if scan.horizon <= end + 1e-9]
    lo, hi = measure.lo, measure.hi
    cuts = sorted({(sp.value - centre) / sigma for scan in reach for sp in scan.splits
                   if sp.kind not in CONTINUOUS_KINDS})
    cuts = np.array([c for c in cuts if lo < c < hi])
    complete = all(scan.complete_within >= sigma for scan in reach)
    per_replicate = cfg.samples // REPLICATES
    strata = build_strata(measure, [lo, hi], cuts, complete=complete,
                          max_strata=max(1, per_replicate // 2))
    return strata, replicate_allocation(per_replicate, strata.probability)


def ensemble(cfg: ValidateConfig, work: Work, value, sigma, samples, times, design,
             previous=None) -> dict:
    """The true sampled systems of the point's stratified design (:func:`design`:
    ``design`` = its strata and points per stratum in each replicate) at ``samples``
    points in ``REPLICATES`` replicates: x (M, T) with replicate r in rows r M/R .. (r+1)
    M/R - 1, xi (M,), weights (M,), impacts (M,), rhs and wall seconds. The points at 2M
    hold those at M (each stratum's Sobol' sequence goes on), so given the ensemble at
    M/2 (``previous``) only the new half is run; the result is the same to the bit."""
    with work.clock("Monte Carlo runs"):
        start = time.perf_counter()
        system = cfg.system_at(value, sigma=sigma, order=0)
        strata, allocation = design
        scale = samples // cfg.samples
        xi, weights, _ = replicate_points(cfg.measure(), strata, allocation, REPLICATES,
                                          cfg.seed, scale)
        if previous is None:
            old = np.zeros(0, dtype=np.int64)
        else:
            old = grown_rows(allocation, REPLICATES, scale // 2)
        new = np.setdiff1d(np.arange(len(xi)), old)
        paths, rhs, impacts = true_runs(system, cfg.options, xi[new], times,
                                        what="Monte Carlo sample", impacts=True)
        work.count(mc_runs=1, true_runs=len(new), true_periods=len(new) * float(times[-1])
                   / system.oscillator.forcing_period)
        x = np.empty((len(xi), len(times)))
        count = np.empty(len(xi), dtype=np.int64)
        x[new], count[new] = paths[:, :, 0], impacts
        if len(old):
            x[old], count[old] = previous["x"], previous["impacts"]
        return {"x": x, "xi": xi, "weights": weights, "impacts": count,
                "strata": len(strata), "complete": strata.complete,
                "rhs": (previous["rhs"] if previous is not None else 0) + rhs,
                "seconds": time.perf_counter() - start}


@dataclass(frozen=True)
class PointOpa:
    """What the OPA runs at one point give its Monte Carlo rounds: the parts' inputs
    (a round's part depends on them), the controls and their elements' probabilities
    per (variant, N) (:func:`compare._pairs.pair_point`), the moments (variant, N,
    output) and the first impacts (variant, N) in forcing periods."""

    inputs: list
    controls: dict
    probabilities: dict
    mean: np.ndarray
    var: np.ndarray
    first: np.ndarray


def mc_round(cfg: ValidateConfig, work: Work, value, sigma, samples, times, opa: PointOpa,
             state: dict, rounds: int) -> dict:
    """One round of the point's Monte Carlo: the ensemble of ``samples`` true systems,
    paired with every OPA run (:func:`compare._pairs.pair_point`) and judged
    (:func:`judge`, round ``rounds`` of the point's doubling). The part keeps the
    verdicts (undecided ones are what the next round's decision needs) and the
    reference curves, not the paths: ``state["paths"]`` holds the last ensemble run at
    the point in this task, which the next round extends."""
    T = cfg.oscillator_at(value).forcing_period
    shape = opa.mean.shape[:2]

    def compute():
        previous = state.get("paths")
        if previous is not None and len(previous["xi"]) != samples // 2:
            previous = None
        ens = ensemble(cfg, work, value, sigma, samples, times, (strata, allocation),
                       previous)
        state["paths"] = ens
        pairs = pair_point(ens["x"], ens["xi"], opa.controls, cfg.measure(),
                           opa.probabilities, shape, weights=ens["weights"])
        judged = judge(cfg, pairs, opa, times / T, rounds, complete)
        ref = pairs.reference
        return {**judged, "x_mean": ref["x_mean"], "x_var": ref["x_var"],
                "x_sem": ref["x_sem"], "x_var_sem": ref["x_var_sem"],
                "control": np.array(ref["control"] or (-1, -1), np.int64),
                "reduction": pairs.reduction,
                "impacts": np.array([ens["impacts"].min(), ens["impacts"].max()]),
                "strata": ens["strata"], "rhs": ens["rhs"], "seconds": ens["seconds"]}

    strata, allocation = design(cfg, work, value, sigma, times)
    _, scans = value_splits(cfg, work, value)
    # per horizon: whether its split list is complete within sigma (else nothing over
    # it is certified: a change the scan did not reach may hide inside a stratum)
    complete = np.array([scan.complete_within >= sigma for scan in scans])
    inputs = {"system": cfg.system_at(value, sigma=sigma, order=0), "samples": samples,
              "sampler": "stratified sobol", "seed": cfg.seed, "replicates": REPLICATES,
              "design": [strata.cuts.tolist(), allocation.tolist(), complete.tolist()],
              "times": times, "options": cfg.options, "opa": opa.inputs,
              "criterion": [cfg.tolerance, cfg.var_tolerance, cfg.alpha,
                            noise_floor(cfg.options), list(cfg.horizons), RULE, rounds],
              "estimator": "every run against the best control-variate reference"}
    return work.parts.get(f"mc_{_name(cfg, value, sigma)}_M{samples}", inputs,
                          work.timed("pairs and verdicts", compute))


def opa_part(cfg: ValidateConfig, work: Work, value, sigma, order, times) -> dict:
    """Every single-element variant of OPA at one N: x_mean, x_var (variant, output),
    first_impact (variant,) in time units, and the wall time. Under the semicircle the
    paper's system (:func:`opa.opa_variants`); under another law one element over
    the whole support, in that law's orthonormal basis (:func:`element_variants`)."""
    def compute():
        start = time.perf_counter()
        system = cfg.system_at(value, sigma=sigma, order=order)
        if cfg.semicircle:
            mean, var, first, status, coef = opa_variants(
                system, list(cfg.single_variants), times, cfg.options, coefficients=True)
        else:
            measure = cfg.measure()
            whole = np.array([measure.lo, measure.hi])
            run = element_variants(system, cfg.options, measure,
                                   [law for law, _ in cfg.single_variants],
                                   [whole] * len(cfg.single_variants), times)
            mean, var, first = run["x_mean"], run["x_var"], run["first_impact"]
            status, coef = run["status"], np.concatenate(run["x_coef"])
        work.count(opa_runs=1)
        return {"x_mean": mean, "x_var": var, "first_impact": first,
                "status": np.asarray(status, np.int64), "x_coef": coef,
                "seconds": time.perf_counter() - start}

    return work.parts.get(f"opa_{_name(cfg, value, sigma)}_N{order}",
                          opa_inputs(cfg, value, sigma, order, times),
                          work.timed("OPA runs", compute))


def opa_inputs(cfg: ValidateConfig, value, sigma, order, times) -> dict:
    """What :func:`opa_part` depends on."""
    return {"system": cfg.system_at(value, sigma=sigma, order=order),
            "variants": cfg.single_variants, "times": times, "options": cfg.options,
            "stores": "coefficients"}


def _element_law(cfg: ValidateConfig, system, law, times) -> tuple[dict, np.ndarray]:
    """One multi-element variant: its run (:func:`element_variants`, the collocation
    fallback on) and its edges, adaptive (:func:`opa._elements.adaptive_edges`) or
    uniform."""
    measure = cfg.measure()
    if cfg.elements == "adaptive":
        runs, _ = adaptive_edges(system.replace(impact_law=law), cfg.options, measure,
                                 times=times, tolerance=ELEMENT_TOLERANCE,
                                 max_elements=cfg.budget)
        edges = np.array([r.a for r in runs] + [runs[-1].b])
    else:
        edges = uniform_edges(measure, int(cfg.elements))
    run = element_variants(system, cfg.options, measure, [law], [edges], times,
                           fallback=True)
    return run, edges


def elements_part(cfg: ValidateConfig, work: Work, value, sigma, order, times) -> dict:
    """The multi-element variants at one N (one per law of ``cfg.element_laws``):
    x_mean, x_var (law, output), first_impact (law,), elements (law,) and the wall
    time. Adaptive edges are chosen per law (:func:`opa._elements.adaptive_edges`).
    As in ``simulate_opa`` with elements, an element whose OPA system cannot be
    completed is computed by collocation of the true systems (counted in
    ``collocated``); where even that fails the variant is NaN throughout and
    ``failure`` says why."""
    def compute():
        start = time.perf_counter()
        system = cfg.system_at(value, sigma=sigma, order=order)
        L = len(cfg.element_laws)
        mean, var = np.full((L, len(times)), np.nan), np.full((L, len(times)), np.nan)
        first, count = np.full(L, np.nan), np.zeros(L, np.int64)
        collocated = np.zeros(L, np.int64)
        failures, coefficients = [], {}
        for ell, law in enumerate(cfg.element_laws):
            try:
                run, edges = _element_law(cfg, system, law, times)
            except SimulationError as err:  # even the true systems' collocation failed
                failures.append(f"{law}: {err}")
                continue
            mean[ell], var[ell] = run["x_mean"][0], run["x_var"][0]
            first[ell], count[ell] = run["first_impact"][0], run["elements"][0]
            collocated[ell] = run["collocated"][0]
            coefficients[f"x_coef_{ell}"] = run["x_coef"][0]
            coefficients[f"edges_{ell}"] = np.asarray(edges, float)
        work.count(opa_runs=1)
        return {"x_mean": mean, "x_var": var, "first_impact": first, "elements": count,
                "collocated": collocated, "failure": " | ".join(failures),
                "seconds": time.perf_counter() - start, **coefficients}

    return work.parts.get(f"elements_{_name(cfg, value, sigma)}_N{order}",
                          elements_inputs(cfg, value, sigma, order, times),
                          work.timed("multi-element OPA runs", compute))


def elements_inputs(cfg: ValidateConfig, value, sigma, order, times) -> dict:
    """What :func:`elements_part` depends on."""
    return {"system": cfg.system_at(value, sigma=sigma, order=order),
            "laws": cfg.element_laws, "elements": cfg.elements,
            "budget": cfg.budget if cfg.elements == "adaptive" else None,
            "tolerance": ELEMENT_TOLERANCE, "fallback": "collocation", "times": times,
            "options": cfg.options, "stores": "coefficients"}


def point_opa(cfg: ValidateConfig, work: Work, value, sigma, orders, times) -> tuple:
    """The OPA runs at one point, every N of ``orders`` (the multi-element variants at
    N = Nmax only, NaN at the other N): a :class:`PointOpa`, and the point's
    ``elements``, ``collocated``, ``status`` (variant, N; -1: not run), ``failure`` and
    wall ``seconds`` (a dict)."""
    T = cfg.oscillator_at(value).forcing_period
    measure = cfg.measure()
    S, V, N = len(cfg.single_variants), len(cfg.variants), len(orders)
    mean, var = np.full((V, N, len(times)), np.nan), np.full((V, N, len(times)), np.nan)
    first = np.full((V, N), np.nan)
    info = {"elements": np.zeros(V, np.int64), "collocated": np.zeros(V, np.int64),
            "status": np.full((V, N), -1, np.int64), "failure": "", "seconds": 0.0}
    info["elements"][:S] = 1
    controls, probabilities = {}, {}
    whole = np.array([measure.lo, measure.hi])
    for k, order in enumerate(orders):  # the variants of one N run in parallel
        run = opa_part(cfg, work, value, sigma, order, times)
        mean[:S, k], var[:S, k] = run["x_mean"], run["x_var"]
        first[:S, k] = run["first_impact"] / T
        info["status"][:S, k] = run["status"]
        info["seconds"] += run["seconds"]
        for v in range(S):
            controls[v, k] = Control(run["x_coef"][v][None], whole, cfg.semicircle)
            probabilities[v, k] = np.ones(1)
        if not (cfg.element_laws and order == cfg.nmax):
            continue
        run = elements_part(cfg, work, value, sigma, order, times)
        mean[S:, k], var[S:, k] = run["x_mean"], run["x_var"]
        first[S:, k] = run["first_impact"] / T
        info["elements"][S:], info["collocated"][S:] = run["elements"], run["collocated"]
        info["status"][S:, k] = np.where(run["elements"] > 0, 0, -1)
        info["failure"] = str(run["failure"])
        info["seconds"] += run["seconds"]
        for ell in range(len(cfg.element_laws)):
            if f"x_coef_{ell}" in run:
                cuts = run[f"edges_{ell}"]
                controls[S + ell, k] = Control(run[f"x_coef_{ell}"], cuts)
                probabilities[S + ell, k] = np.array([
                    measure.restrict(a, b).probability() for a, b in zip(cuts[:-1], cuts[1:])])
        if info["failure"]:
            work.point_log(f"{_name(cfg, value, sigma)}, N = {order}: multi-element "
                           f"variant not run ({info['failure']})")
    inputs = [opa_inputs(cfg, value, sigma, order, times) for order in orders]
    if cfg.element_laws and cfg.nmax in orders:
        inputs.append(elements_inputs(cfg, value, sigma, cfg.nmax, times))
    return PointOpa(inputs, controls, probabilities, mean, var, first), info


def evaluate_point(cfg: ValidateConfig, value: float, sigma: float, *,
                   work: Work | None = None, orders=None, focus=None,
                   horizon: int | None = None) -> Point:
    """OPA (``orders``, default all) and Monte Carlo at one point, with verdicts.

    The multi-element variants run at N = Nmax only (NaN at the other N). With
    ``horizon`` (an index into ``cfg.horizons``) everything runs up to that horizon
    only, and the verdicts of the longer horizons are not formed (a bisection probe
    of that horizon's sigma*). The Monte Carlo doubles while a verdict at N = Nmax is
    undecided (``focus`` = (variant, horizon, criterion): that one only), up to
    ``cfg.max_samples``. The point's wall time is that of its runs (OPA, and every Monte
    Carlo ensemble it took), as stored in the parts: a reused point reports what it
    cost. ``work``: the task's :class:`compare._ledger.Work` (its parts, counts and
    caches), default a fresh one on ``cfg.outdir``."""
    work = Work(cfg.outdir) if work is None else work
    osc = cfg.oscillator_at(value)
    end = max(cfg.horizons) if horizon is None else cfg.horizons[horizon]
    times = time_grid(osc.omega, end, cfg.per_period)
    evaluated = np.array([n <= len(times) for n in _outputs(cfg)])
    orders = cfg.orders if orders is None else orders
    opa, info = point_opa(cfg, work, value, sigma, orders, times)
    # the last ensemble this task ran at the point, which a next round extends
    state = work.ensembles.setdefault((value, sigma, len(times)), {})
    samples, mc_seconds, rounds = cfg.samples, 0.0, 1
    while True:
        judged = mc_round(cfg, work, value, sigma, samples, times, opa, state, rounds)
        mc_seconds += float(judged["seconds"])
        if samples * 2 > cfg.max_samples or not _undecided(judged, focus):
            break
        samples *= 2
        rounds += 1
    control = tuple(int(i) for i in judged["control"])
    mc = {name: judged[name] for name in ("x_mean", "x_var", "x_sem", "x_var_sem")}
    mc.update(impacts=tuple(int(i) for i in judged["impacts"]),
              seconds=mc_seconds, rhs=int(judged["rhs"]),
              control=None if control[0] < 0 else control)
    verdict = np.where(evaluated[:, None], judged["verdict"], NOT_FORMED).astype(np.int8)
    return Point(sigma, samples, mc, opa.mean, opa.var, opa.first, judged["errors"],
                 judged["pre"], judged["disagree"], verdict == 1,
                 seconds=info["seconds"] + mc_seconds, elements=info["elements"],
                 collocated=info["collocated"], failure=info["failure"],
                 status=info["status"], reduction=judged["reduction"], verdict=verdict,
                 evaluated=evaluated)


def _undecided(judged: dict, focus=None) -> bool:
    """Whether a verdict at N = Nmax (the order sigma* reads) is undecided: any of
    them, or with ``focus`` = (variant, horizon, criterion) that one, which a
    bisection probe decides. A verdict at a lower N does not double the samples (it
    may stay undecided, and counts as not agreeing), nor does one over a horizon whose
    split list is incomplete within sigma (more samples cannot certify it)."""
    open_ = judged["open"]
    if focus is None:
        return bool(open_[:, -1].any())
    v, h, c = focus
    return bool(open_[v, -1, h, c])


def judge(cfg: ValidateConfig, pairs: Pairs, opa: PointOpa, periods, rounds: int,
          complete) -> dict:
    """The verdicts at one point from the paired estimates (:mod:`compare._pairs`), as
    :func:`compare.verify` forms its own (:func:`compare._trust.bounded_verdict`).

    Round ``rounds`` of the point's doubling spends ``alpha / 2^rounds`` of the error
    rate: per horizon H (its n outputs) a Bonferroni band of Student's t intervals
    (R - 1 degrees of freedom, R replicates) holds for the reference's E[x] and Var[x]
    at all n outputs at once, so each verdict (variant, N, H, criterion) is wrong with
    probability <= alpha over all the rounds. Inside the band the running RMS error is
    bounded above and below: 1 (agrees) when the upper bound is within the tolerance at
    every output up to H, -1 (disagrees) when the lower bound exceeds it somewhere, 0
    (undecided) otherwise. An OPA run that stopped (NaN) disagrees from where it
    stopped. Over a horizon h whose split list is incomplete within sigma
    (``complete[h]`` False) nothing else is certified: a change of the impact sequence
    the scan did not reach may hide inside a stratum, where no standard error sees it;
    such a verdict is undecided and not ``open`` (more samples cannot decide it).
    Returns verdict (variant, N, horizon, criterion), open (the same shape: undecided
    on the bounds, which more samples may decide), errors (variant, N,
    horizon, criterion, 3), disagree (variant, N, criterion): the first time, in
    periods, at which the estimated running RMS error exceeds the tolerance, over the
    longest horizon the point reaches (inf: never), and pre (variant, N): the RMS error
    of the mean before OPA's first impact."""
    V, N, T = opa.mean.shape
    H = len(cfg.horizons)
    ref = pairs.reference
    errors = np.full((V, N, H, 2, 3), np.nan)
    verdict = np.zeros((V, N, H, 2), np.int8)
    open_ = np.zeros((V, N, H, 2), bool)
    disagree = np.full((V, N, 2), np.inf)
    spent = cfg.alpha / 2**rounds
    floor = noise_floor(cfg.options)
    # the variance's floor: the solvers' squared, and the roundoff of E[x^2] - E[x]^2
    # (4e-16 at x = 1: at t = 0, where every sample is x0, it is all there is)
    second = float(np.nanmax(ref["x_var"] + ref["x_mean"] ** 2))
    var_floor = floor**2 + VAR_ROUNDOFF * np.finfo(float).eps * second
    quantities = (
        (pairs.err_mean, pairs.err_mean_se, opa.mean, cfg.tolerance, floor),
        (pairs.err_var, pairs.err_var_se, opa.var, cfg.var_tolerance, var_floor))
    for h, n in sorted(enumerate(_outputs(cfg)), key=lambda item: item[1]):
        if n > T:  # a horizon past the point's outputs: not judged
            continue
        c_band = float(band_multiplier(spent, n, REPLICATES - 1))
        var, var_band = ref["x_var"][:n], c_band * ref["x_var_sem"][:n]
        var_low, var_high = np.maximum(var - var_band, 0), np.maximum(var + var_band, 0)
        scales = ((np.sqrt(var_low), np.sqrt(var_high)), (var_low, var_high))
        for c, (err, sem, values, tol, c_floor) in enumerate(quantities):
            upper, lower = bound_excess(err[..., :n], c_band * sem[..., :n], *scales[c],
                                        tol=tol, floor=c_floor)
            stopped = ~np.isfinite(values[..., :n])  # the OPA run stopped: over from there
            lower = np.where(stopped, np.inf, lower)
            upper = np.where(stopped, np.inf, upper)
            known = np.logical_and.accumulate(np.isfinite(lower) | stopped, axis=-1)
            bounded = np.where((known & (lower > 0)).any(-1), -1,
                               np.where((upper <= 0).all(-1), 1, 0))
            if complete[h]:
                verdict[:, :, h, c], open_[:, :, h, c] = bounded, bounded == 0
            else:
                verdict[:, :, h, c] = np.where(stopped.any(-1), -1, 0)
            scale = np.sqrt(np.maximum(ref["x_var"], 0)) if c == 0 else ref["x_var"]
            # not <= 0 rather than > 0: a run that stopped (NaN) is over from there
            over = ~(excess(err[..., :n], scale[:n], sem[..., :n], tol=tol,
                            floor=c_floor) <= 0)
            disagree[:, :, c] = np.where(over.any(-1), periods[np.argmax(over, axis=-1)],
                                         np.inf)
            errors[:, :, h, c] = window_errors_all(err, scale, sem, n)
    with np.errstate(invalid="ignore"):
        before = periods[None, None, :] < opa.first[:, :, None]
        square = np.where(before, pairs.err_mean**2, 0.0)
        count = before.sum(-1)
        pre = np.where(count > 0, np.sqrt(square.sum(-1) / np.maximum(count, 1)), np.nan)
    return {"verdict": verdict, "open": open_, "errors": errors, "disagree": disagree,
            "pre": pre}


# -- one value of the swept parameter ------------------------------------------------------
def _scan_value(cfg: ValidateConfig, value: float) -> dict:
    """The split scans at one value, per horizon (the arrays of
    :func:`compare._mapdata.splits_to_arrays`)."""
    osc = cfg.oscillator_at(value)
    centre = osc.value(cfg.uncertain)
    smax = max(cfg.sigmas)
    T = osc.forcing_period
    found, runs, longest = {}, None, None
    # the longest horizon first; a shorter one reuses its runs (they hold the events
    # up to the shorter horizon) and bisects with runs to its own horizon, and the
    # chatter window past it (a burst at the horizon is told from both sides, as
    # in the longer runs)
    for h in sorted(cfg.horizons, reverse=True):
        end = (h + (CHATTER_WINDOW if runs else 0.0)) * T
        runs = (runs.until(end) if runs else
                SampledRuns(cfg.system_at(value), cfg.options, cfg.uncertain, end))
        found[h] = scan_splits(
            cfg.system_at(value), cfg.options, cfg.uncertain, centre - smax,
            centre + smax, h * T,
            ScanOptions(tol=cfg.split_resolution * min(cfg.sigmas), center=centre,
                        needed_within=cfg.sigmas,
                        max_splits=MAX_SPLITS if h == min(cfg.horizons) else cfg.long_splits),
            runs=runs, outputs=time_grid(osc.omega, h, cfg.per_period))
        longest = longest or runs
    seq_centre = longest.get(centre) or _sequence(cfg.system_at(value), cfg,
                                                  {"t_end": longest.t_end}, centre)
    scans = []
    for h in cfg.horizons:
        speed, when = seq_centre.slowest_impact(h * T)
        scan = found[h]
        scans.append(HorizonSplits(
            h, sorted(scan.splits + scan.crossings, key=lambda sp: sp.value),
            scan.truncated, speed, when / T, seq_centre.count(h * T),
            scan.complete_within, scan.crossings_within))
    return splits_to_arrays(scans)


def value_splits(cfg: ValidateConfig, work: Work, value: float
                 ) -> tuple[float, list[HorizonSplits]]:
    """The centre of the ensembles and, per horizon (in ``cfg.horizons`` order), the
    splits of the sampled systems' event sequences over the largest ensemble, kept as a
    part (read once per task: every round's design reads it)."""
    centre = cfg.oscillator_at(value).value(cfg.uncertain)
    inputs = {"system": cfg.system_at(value), "uncertain": cfg.uncertain,
              "sigmas": [min(cfg.sigmas), max(cfg.sigmas)], "horizons": cfg.horizons,
              "tol": cfg.split_resolution, "per_period": cfg.per_period,
              "options": cfg.options,
              "limits": [MAX_SPLITS, cfg.long_splits, MAX_CROSSINGS, MIN_SPLITS],
              "needed_within": list(cfg.sigmas), "runs": ["own horizon", CHATTER_WINDOW]}
    if value not in work.scans:
        stored = work.parts.get(f"splits_{_name(cfg, value)}", inputs,
                                work.timed("split scans", lambda: _scan_value(cfg, value)))
        work.scans[value] = centre, splits_from_arrays(stored)
    return work.scans[value]


def boundary(cfg: ValidateConfig, work: Work, value, grid: dict[float, Point], found=None):
    """sigma* for every (variant, horizon, criterion) at N = Nmax, by bisection.

    A bisection of horizon h's sigma* starts from the grid's verdicts and probes with
    runs up to h only (``evaluate_point(..., horizon=h)``); the probes of one horizon
    serve all its bisections, and the horizons are independent of each other
    (:func:`boundary_at`; ``found``: their results, computed elsewhere, in
    ``cfg.horizons`` order). Returns the brackets, the steps, and every sigma
    evaluated with its verdicts (variant, horizon, criterion) at N = Nmax (1 agrees, 0
    undecided, -1 disagrees, ``NOT_FORMED``)."""
    k = -1  # N = Nmax; the probes run that order only
    V, H, C = len(cfg.variants), len(cfg.horizons), 2
    star = np.full((V, H, C, 2), np.nan)
    steps = np.zeros((V, H, C), dtype=np.int64)
    verdicts = {s: point.verdict[:, k].astype(np.int8) for s, point in grid.items()}
    for h in range(H):
        star[:, h], steps[:, h], rows = (boundary_at(cfg, work, value, grid, h)
                                         if found is None else found[h])
        for s, row_h in rows.items():
            row = verdicts.setdefault(s, np.full((V, H, C), NOT_FORMED, np.int8))
            row[:, h] = row_h
    return star, steps, verdicts


def boundary_at(cfg: ValidateConfig, work: Work, value, grid: dict[float, Point], h: int):
    """The bisections of horizon ``h`` (an index into ``cfg.horizons``) at one value
    (:func:`boundary`): the brackets (variant, criterion, 2), the steps (variant,
    criterion), and the verdicts (variant, criterion) at N = Nmax of every sigma
    probed that is not on the grid."""
    k = -1
    V, C = len(cfg.variants), 2
    star = np.full((V, C, 2), np.nan)
    steps = np.zeros((V, C), dtype=np.int64)
    probes: dict[float, Point] = dict(grid)
    for v in range(V):
        for c in range(C):
            def agrees(s, v=v, c=c):
                s = float(np.round(s, 12))
                known = probes.get(s)
                # a probe another bisection made may leave this verdict
                # undecided: its rounds go on (the ones done are read back)
                if known is None or (known.verdict[v, -1, h, c] == 0
                                     and known.samples * 2 <= cfg.max_samples):
                    probes[s] = evaluate_point(cfg, value, s, work=work, orders=(cfg.nmax,),
                                               focus=(v, h, c), horizon=h)
                    work.tick()
                return bool(probes[s].agrees[v, k, h, c])

            known = sorted(probes)
            for s in known:  # the probes of other bisections, decided for this one
                if s not in grid:
                    agrees(s)
            failing = [s for s in known if not probes[s].agrees[v, k, h, c]]
            if not failing:
                star[v, c] = (known[-1], np.nan)  # agrees at every sigma tried
                continue
            hi = failing[0]
            lo = max([s for s in known if s < hi], default=0.0)
            with work.clock("bisection"):
                lo, hi, n = bisect_boundary(agrees, lo, hi, cfg.resolution)
            # the probes are stored under sigma rounded to 12 digits
            star[v, c] = (np.round(lo, 12), np.round(hi, 12))
            steps[v, c] = n
    rows = {s: point.verdict[:, k, h] for s, point in probes.items() if s not in grid}
    return star, steps, rows


def grid_points(cfg: ValidateConfig, work: Work, value: float) -> dict[float, Point]:
    """The grid's points at one value (:func:`evaluate_point` at every sigma)."""
    grid = {}
    for sigma in cfg.sigmas:
        grid[float(sigma)] = evaluate_point(cfg, value, float(sigma), work=work)
        if work.bar is not None:
            work.bar.update(1)
    return grid


def value_work(cfg: ValidateConfig, work: Work, value: float, found=None) -> dict:
    """Everything at one swept value: its split scan, its grid of points, the
    bisections of its sigma* (``found``: those of every horizon, computed elsewhere,
    :func:`boundary`); returns its point datasets (``points``), its value dataset
    (``value``) and the sigma of its phase portraits (``phase_sigma``)."""
    cdf = None if cfg.semicircle else cfg.measure().cdf
    work.log(f"{cfg.parameter} = {value:g}: impact-sequence splits, then "
             f"{len(cfg.sigmas)} sigmas x {len(cfg.variants) * len(cfg.orders)} OPA "
             f"runs against Monte Carlo ...")
    centre, scans = value_splits(cfg, work, value)
    grid = grid_points(cfg, work, value)
    star, steps, probes = boundary(cfg, work, value, grid, found)
    work.ensembles.clear()
    with work.clock("assembly"):
        points = [point_dataset(cfg, value, grid[float(s)], centre, scans, cdf)
                  for s in cfg.sigmas]
        value_ds = value_dataset(cfg, value, centre, scans, star, steps, probes)
    return {"points": points, "value": value_ds, "phase_sigma": _phase_sigma(cfg, grid)}


def value_part(cfg: ValidateConfig, work: Work, value: float, found=None,
               spill: bool = True) -> dict:
    """:func:`value_work`, its datasets joined into the value's slice of the map
    (:func:`compare._mapdata.value_slice`), its bulk written to ``OUTDIR/SLICES``
    with ``spill`` (:func:`compare._mapdata.spill`); returns the slice (``slice``)
    and the sigma of the phase portraits (``phase_sigma``)."""
    result = value_work(cfg, work, value, found)
    with work.clock("assembly"):
        part = value_slice(cfg, value, result["points"], result["value"])
        if spill:
            part = spill_slice(part, os.path.join(cfg.outdir, SLICES), _name(cfg, value))
    return {"slice": part, "phase_sigma": result["phase_sigma"]}


def details_part(cfg: ValidateConfig, work: Work, sigma: float) -> xr.Dataset:
    """:func:`_details` at the first swept value and ``sigma`` (the first grid sigma
    where mean/galerkin fails over the first horizon there), kept as a part."""
    value = cfg.values[0]
    inputs = {"system": cfg.system_at(value, sigma=float(sigma), order=cfg.nmax),
              "horizons": cfg.horizons, "per_period": cfg.per_period, "seed": cfg.seed,
              "dense_per_period": DENSE_PER_PERIOD, "options": cfg.options}
    return work.parts.get(f"details_{_name(cfg, value, sigma)}", inputs,
                          work.timed("phase portraits", lambda: _details(cfg, sigma)),
                          ".nc")


# -- the map -------------------------------------------------------------------------------
def run_map(cfg: ValidateConfig, *, progress: bool, log, tasks=None) -> xr.Dataset:
    """The map's dataset, with the phase table and the counts of this run (``phase_*``
    attributes: seconds not charged to a named phase go to "other": parts read back,
    loops): the ledger of this process's own work plus those the tasks returned.

    ``tasks(cfg, work, bar)``: the values' results and the frontier computed elsewhere,
    and the sum of those tasks' ledgers (:func:`compare._mapflow.run_map_tasks`);
    without it every value is computed here, one after the other."""
    work = Work(cfg.outdir, log=log)
    before = true_system_work()
    start = time.perf_counter()
    with work.clock("other"):
        results, elsewhere = _compute(cfg, work, progress, tasks)
        ds = _assemble(cfg, work, results)
    after = true_system_work()
    ledger = work.ledger((after[0] - before[0], after[1] - before[1])) + elsewhere
    # what this run did (the rest of the dataset is the same for a rerun)
    ds.attrs["wall_seconds"] = time.perf_counter() - start
    ds.attrs.update(ledger.attrs())
    ds.attrs["ran_on"] = (f"Dask cluster at {cfg.scheduler}" if cfg.scheduler is not None
                          else f"{cfg.processes} local processes" if cfg.processes > 1
                          else "one process")
    return ds


def _compute(cfg: ValidateConfig, work: Work, progress: bool, tasks) -> tuple[dict, Ledger]:
    """Every value's slice and the frontier (here, or by ``tasks``), and the ledger of
    the work done elsewhere."""
    stale = clear_slices(os.path.join(cfg.outdir, SLICES))
    if stale:
        work.log(f"slices: removed {len(stale)} file(s) an interrupted run left behind")
    if work.parts.removed:
        work.log(f"parts: removed {len(work.parts.removed)} temporary file(s) an "
                 f"interrupted run left behind: "
                 f"{', '.join(os.path.basename(p) for p in work.parts.removed)}")
    total = len(cfg.values) * len(cfg.sigmas)
    # the one progress display of every batch (opa.Execution.bar)
    with Execution(progress=bool(progress)).bar(total, unit="point", desc="trust map") as bar:
        if tasks is not None:
            return tasks(cfg, work, bar)
        work.bar = bar
        results = {i: value_part(cfg, work, value) for i, value in enumerate(cfg.values)}
        work.bar = None
        if cfg.frontier:
            work.log("cost-accuracy frontier at the largest sigma ...")
            with work.clock("frontier"):
                results["frontier"] = frontier(cfg, parts=work.parts)
    return results, Ledger()


def _assemble(cfg: ValidateConfig, work: Work, results: dict) -> xr.Dataset:
    """The map from the values' slices, the phase portraits and the frontier."""
    with work.clock("assembly"):
        # each value's slice, its bulk on disk (compare._mapdata.spill): the map is
        # written from them without ever being whole in this process's memory
        ds = combine_slices(cfg, [results[i]["slice"] for i in range(len(cfg.values))])
    ds = xr.merge([ds, details_part(cfg, work, results[0]["phase_sigma"])],
                  combine_attrs="drop_conflicts")
    if cfg.frontier:
        ds = xr.merge([ds, results["frontier"]], combine_attrs="drop_conflicts")
    ds.attrs.update(_attrs(cfg))
    return ds.rename({"value": cfg.parameter})  # the sweep dimension (docs/datasets.md)


class _Map:
    """The map's run in the main process (:func:`run_map`), and the points and split
    scans of one configuration for scripts (:func:`evaluate_point`,
    :func:`value_splits`), sharing one :class:`compare._ledger.Work`."""

    def __init__(self, cfg: ValidateConfig, *, progress: bool, log):
        self.cfg, self.progress, self.log = cfg, progress, log
        self._work = None  # opened when first used: a run opens its own

    @property
    def work(self) -> Work:
        if self._work is None:
            self._work = Work(self.cfg.outdir, log=self.log)
        return self._work

    def run(self, tasks=None) -> xr.Dataset:
        return run_map(self.cfg, progress=self.progress, log=self.log, tasks=tasks)

    def evaluate(self, value: float, sigma: float, **kwargs) -> Point:
        return evaluate_point(self.cfg, value, sigma, work=self.work, **kwargs)

    def splits(self, value: float) -> tuple[float, list[HorizonSplits]]:
        return value_splits(self.cfg, self.work, value)


#: the folder of OUTDIR where the bulk of each value's slice of the map waits, from the
#: value's end to validate.nc's (a scratch: removed once validate.nc is written)
SLICES = "slices"


def clear_slices(folder: str) -> list[str]:
    """Remove the ``.npy`` files in a map's ``SLICES`` folder (its scratch: nothing else
    is kept there), and the folder once empty; returns the names removed. A map calls it
    as it starts (what a killed run left) and once validate.nc is written."""
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    removed = []
    for entry in entries:
        if entry.name.endswith(".npy") and entry.is_file(follow_symlinks=False):
            try:
                os.remove(entry.path)
                removed.append(entry.name)
            except OSError:
                pass
    try:
        os.rmdir(folder)
    except OSError:  # not empty: something else lives there
        pass
    return sorted(removed)


FRONTIER_BUDGETS = (8, 16, 32, 64)
FRONTIER_SAMPLES = (256, 512, 1024, 2048, 4096, 8192)
#: true systems of the frontier's reference, a control variate on the adaptive ME-OPA of
#: 64 elements (compare.verify): RMS standard error 1.1e-6 in the default map (omega =
#: 3.98, sigma = 0.05, 10 periods), where 32768 plain Sobol samples gave 2.4e-5
FRONTIER_REFERENCE = 4096


def frontier_study(cfg: ValidateConfig):
    """The :class:`compare._convergence.ConvergenceConfig` of the map's frontier
    (:func:`frontier`)."""
    from compare._convergence import ConvergenceConfig

    return ConvergenceConfig(
        oscillator=cfg.oscillator_at(cfg.values[0]), options=cfg.options,
        sigma=float(max(cfg.sigmas)), uncertain=cfg.uncertain, periods=cfg.horizons[0],
        per_period=cfg.per_period, order=1, orders=tuple(sorted({0, 1, cfg.nmax})),
        uniform=(), budgets=FRONTIER_BUDGETS, order_budget=FRONTIER_BUDGETS[-1],
        single_nodes=(1, 2, 4, 8), mc_samples=FRONTIER_SAMPLES,
        reference=FRONTIER_REFERENCE, reference_method="control", seed=cfg.seed + 1,
        outdir=cfg.outdir,
        allow_negative=True, impulse=cfg.impulse, pulse_width=cfg.pulse_width,
        impulse_at_zero=cfg.impulse_at_zero, distribution=cfg.distribution)


def frontier_part(run: str) -> str:
    """The name of the part that keeps the frontier's run ``run``."""
    return f"frontier_{run}"


def frontier_runs(cfg: ValidateConfig, known: dict):
    """The frontier's runs (:func:`compare._convergence.study_runs` of
    :func:`frontier_study`) that can be named given the runs ``known``: the reference
    alone until it is known, then every row's and ladder's run, and the adaptive
    collocation rows once the adaptive runs whose edges they take are known."""
    from compare._convergence import study_runs

    return study_runs(frontier_study(cfg), known)


def frontier(cfg: ValidateConfig, parts: Store | None = None,
             known: dict | None = None) -> xr.Dataset:
    """Cost against accuracy at the first swept value, the largest sigma and the first
    horizon, under the map's law of xi: the paper's OPA (N = 0..Nmax), adaptive multi-element
    OPA (mean and
    saltation laws, element budgets 8..64), multi-element collocation, single-element
    collocation, MC, scrambled Sobol and control variates (nested ladders), against the
    control-variate estimate of ``FRONTIER_REFERENCE`` true systems on the adaptive ME-OPA
    of 64 elements (:func:`compare._convergence.run_convergence`). Variables are prefixed
    ``frontier_``. With ``parts``, every run of the study is kept there
    (``frontier_<run>_<key>.npz``); ``known`` (name -> result of every run
    :func:`frontier_runs` lists) instead gives the runs."""
    from compare._convergence import assemble_study, run_convergence

    def quiet(*args):
        return None

    study = frontier_study(cfg)
    if known is not None:
        ds = assemble_study(study, known, log=quiet)
    else:
        memo = None
        if parts is not None:
            def memo(run, spec, compute):
                return parts.get(frontier_part(run), spec, compute)
        ds = run_convergence(study, log=quiet, write=False, memo=memo)
    out = ds.rename({name: f"frontier_{name}" for name in ds.data_vars} | {"run": "frontier_run"})
    out.attrs = {"frontier_" + k: v for k, v in ds.attrs.items()
                 if k in ("sigma", "periods", "reference_samples", "reference_sem",
                          "reference_method", "reference_text", "wall_seconds")}
    out.attrs["frontier_value"] = float(cfg.values[0])
    out.attrs["frontier_omega"] = float(cfg.oscillator_at(cfg.values[0]).omega)
    return out


def element_variants(system: System, options: SolverOptions, measure: Measure, laws,
                     edges, times: np.ndarray, *, fallback: bool = False):
    """Multi-element OPA (:mod:`opa._elements`) under several impact laws: law ``laws[l]``
    on the elements cut at ``edges[l]``, each element's system in the orthonormal basis of
    the law of xi conditioned on it (:func:`opa._elements.element_rule`), one parallel
    batch per law. Mean and variance are assembled exactly as
    :func:`opa._elements.assemble` does. An element whose OPA system cannot be completed
    is NaN from where it stopped, or with ``fallback`` computed by collocation of the true
    systems (:func:`opa._elements.collocate_element`, as ``simulate_opa`` does with
    elements). The first impact is the earliest of any element's mean (inf: none).

    Returns a dict of x_mean, x_var, v_mean (L, T), first_impact (L,), elements (L,),
    collocated (L,): the elements computed by the fallback, status (L,): the kernel
    status of the first element that stopped and was not computed again (0: none), and
    x_coef: per law the elements' coefficients x_j (E, N+1, T), the surrogate's
    (:func:`opa._surrogate.surrogate_values`)."""
    order = system.order
    L = len(laws)
    mean, var = np.empty((L, len(times))), np.empty((L, len(times)))
    v_mean = np.empty((L, len(times)))
    first, count = np.full(L, np.inf), np.zeros(L, np.int64)
    collocated, status = np.zeros(L, np.int64), np.zeros(L, np.int64)
    coefficients = []
    for ell, (law, cuts) in enumerate(zip(laws, edges)):
        own = system.replace(impact_law=law, truncation="galerkin")
        cells = [measure.restrict(a, b) for a, b in zip(cuts[:-1], cuts[1:])]
        runs = run_elements(own, options, cells, times=times, partial=True, events=True)
        out = np.stack([np.concatenate([r.x_coef, r.v_coef]).T for r in runs])
        for e, run in enumerate(runs):
            if run.failure and fallback:
                run = collocate_element(own, options, cells[e], times=times)
                out[e][:, : order + 1], out[e][:, order + 1:] = run.x_coef.T, run.v_coef.T
                collocated[ell] += 1
            elif run.status and not status[ell]:
                status[ell] = run.status
            first[ell] = min(first[ell], runs[e].first_impact)
        E = len(cells)
        P = np.array([m.probability() for m in cells])
        P = P / P.sum()
        m = out[:, :, 0]
        s = (out[:, :, 1: order + 1] ** 2).sum(axis=2)
        mean[ell] = P @ m
        var[ell] = np.maximum(P @ (s + (m - mean[ell]) ** 2), 0.0)
        v_mean[ell] = P @ out[:, :, order + 1]
        count[ell] = E
        coefficients.append(out[:, :, : order + 1].transpose(0, 2, 1).copy())
    return {"x_mean": mean, "x_var": var, "v_mean": v_mean, "first_impact": first,
            "elements": count, "collocated": collocated, "status": status,
            "x_coef": coefficients}


def _sequence(system, cfg, cache, value):
    from opa.engine import event_sequence

    seq = event_sequence(system.replace(**{cfg.uncertain: value}), cfg.options,
                         cache["t_end"])
    cache[value] = seq
    return seq


DENSE_PER_PERIOD = 64


def _phase_sigma(cfg: ValidateConfig, grid: dict[float, Point]) -> float:
    """The first grid sigma where mean/galerkin fails over the first horizon, else the last."""
    return next((s for s in cfg.sigmas if not grid[float(s)].agrees[0, -1, 0, 0]),
                cfg.sigmas[-1])


def _details(cfg: ValidateConfig, sig: float) -> xr.Dataset:
    """Dense-output phase portraits at the first swept value and ``sig``, and how far EMR_0
    (sigma = 0, N = Nmax) stays from the DMR, at each horizon."""
    value = cfg.values[0]
    osc = cfg.oscillator_at(value)
    times = time_grid(osc.omega, cfg.horizons[0], DENSE_PER_PERIOD)
    curves = {}
    laws = ("mean", "ensemble")
    if cfg.semicircle:
        for law in laws:
            # a run that stops (at a large sigma) is drawn up to where it stopped
            ds = simulate_opa(cfg.system_at(value, sigma=sig, order=cfg.nmax, impact_law=law),
                              times=times, options=cfg.options, partial=True)
            curves[law] = (ds.x_mean.values, ds.v_mean.values)
    else:  # one element in the law's own basis
        measure = cfg.measure()
        run = element_variants(cfg.system_at(value, sigma=sig, order=cfg.nmax), cfg.options,
                               measure, laws, [np.array([measure.lo, measure.hi])] * 2, times)
        for ell, law in enumerate(laws):
            curves[law] = (run["x_mean"][ell], run["v_mean"][ell])
    ens = simulate_mc(cfg.system_at(value, sigma=sig, order=0), samples=256, sampler="sobol",
                      seed=cfg.seed, times=times, options=cfg.options, progress=False,
                      keep_paths=True)
    pick = np.argsort(ens.xi.values)[np.linspace(0, 255, 7).astype(int)]
    long = time_grid(osc.omega, max(cfg.horizons), cfg.per_period)
    dmr = simulate_dmr(cfg.system_at(value), times=long, options=cfg.options).x.values
    # sigma = 0: the law of xi plays no part (the higher coefficients stay zero)
    emr0 = simulate_opa(cfg.system_at(value, sigma=0.0, order=cfg.nmax).replace(
        distribution=None), times=long, options=cfg.options).x_mean.values
    diff = [float(np.max(np.abs(emr0[: int(round(h * cfg.per_period)) + 1]
                                - dmr[: int(round(h * cfg.per_period)) + 1])))
            for h in cfg.horizons]
    emr1 = simulate_opa(cfg.system_at(value, sigma=0.0, order=0).replace(distribution=None),
                        times=long, options=cfg.options).x_mean.values
    one = {"units": "1"}
    return xr.Dataset(
        {
            "phase_opa_x": (("law", "phase_time"), np.stack([curves[k][0] for k in curves]),
                            {"long_name": "OPA x_0 at N = Nmax", **one}),
            "phase_opa_v": (("law", "phase_time"), np.stack([curves[k][1] for k in curves]),
                            {"long_name": "OPA v_0 at N = Nmax", **one}),
            "phase_mc_x": ("phase_time", ens.x_mean.values, {"long_name": "MC mean E[x]",
                                                             **one}),
            "phase_mc_v": ("phase_time", ens.v_mean.values, {"long_name": "MC mean E[x']",
                                                             **one}),
            "phase_sample_x": (("phase_sample", "phase_time"), ens.x.values[pick],
                               {"long_name": "sample paths x", **one}),
            "phase_sample_v": (("phase_sample", "phase_time"), ens.v.values[pick],
                               {"long_name": "sample paths x'", **one}),
            "phase_sample_xi": ("phase_sample", ens.xi.values[pick],
                                {"long_name": "xi of the sample path", **one}),
            "emr0_dmr_difference": ("horizon", np.array(diff),
                                    {"long_name": "max |x_0 - x_DMR| with sigma = 0, N = Nmax",
                                     **one}),
            "emr0_n0_dmr_difference": ((), float(np.max(np.abs(emr1 - dmr))),
                                       {"long_name": "max |x_0 - x_DMR| with sigma = 0, N = 0, "
                                        "longest horizon", **one}),
        },
        coords={"law": ("law", np.array(["mean", "ensemble"], dtype=object),
                        {"long_name": "impact law of the phase portrait's OPA run"}),
                "phase_time": ("phase_time", times / osc.forcing_period,
                               {"long_name": "dense-output time in forcing periods",
                                "units": "forcing periods"}),
                "phase_sample": ("phase_sample", np.arange(len(pick)),
                                 {"long_name": "index of a drawn sample path (ascending xi)",
                                  **one})},
        attrs={"phase_value": float(value), "phase_sigma": float(sig)},
    )


def _attrs(cfg: ValidateConfig) -> dict:
    attrs = provenance_attrs("validate", cfg.system_at(cfg.values[0], sigma=max(cfg.sigmas),
                                                        order=cfg.nmax),
                             cfg.options, seed=cfg.seed, sampler="sobol")
    # a grid dataset: sigma, N and the swept parameter are coordinates, not one value
    for name in ("sigma", "N", cfg.parameter):
        if name != cfg.uncertain:
            attrs.pop(name, None)
    attrs.update({"truncation": ",".join(dict.fromkeys(t for _, t in cfg.single_variants)),
                  "impact_law": "mean,ensemble,saltation"})
    attrs.update(
        distribution=cfg.distribution,
        elements=("none" if cfg.elements is None else str(cfg.elements)),
        variants_dropped=(", ".join(cfg.dropped_variants) + (
            " (eq. (27) closes a coefficient of the paper's force law; a user's law, and an "
            "uncertain eta, delta, f, omega or F0, have the Galerkin projection only)"
            if cfg.oscillator.force is not None or cfg.uncertain not in ("mu", "a", "c") else
            " (eq. (27) truncates the semicircle's basis; under another law only the "
            "Galerkin projection exists)")) if cfg.dropped_variants else "none",
    )
    if cfg.elements is not None:
        attrs.update(element_order=int(cfg.nmax), element_text=(
            "Galerkin truncation, every element its own OPA system in the orthonormal basis "
            "of the law of xi conditioned on it, run at N = Nmax only"))
    if cfg.elements == "adaptive":
        attrs.update(max_elements=int(cfg.budget), element_tolerance=ELEMENT_TOLERANCE)
    attrs.update(
        preset=cfg.preset, parameter=cfg.parameter, samples=int(cfg.samples),
        max_samples=int(cfg.max_samples), per_period=int(cfg.per_period),
        tolerance=float(cfg.tolerance), var_tolerance=float(cfg.var_tolerance),
        alpha=float(cfg.alpha),
        resolution=float(cfg.resolution), split_resolution=float(cfg.split_resolution),
        long_splits=int(cfg.long_splits),
        floor=noise_floor(cfg.options),
        criterion_text=(
            "agrees over H when an upper confidence bound of the running RMS error is <= tol "
            "x the running RMS of the MC spread (variance: of the MC variance) + floor "
            "(variance: floor squared) at every output t <= H; disagrees when a lower bound "
            "exceeds it at some output; else undecided (counted as not agreeing). The bounds "
            "come from a Bonferroni band of Student's t intervals (15 degrees of freedom) "
            "over the outputs, round r of the doubling spending alpha / 2^r, so each "
            "verdict is wrong with probability <= alpha"),
    )
    return attrs


__all__ = ["frontier", "frontier_part", "frontier_runs", "frontier_study"]
