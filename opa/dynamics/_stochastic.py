"""The stochastic bifurcation diagram: which attractors the random system settles on, with
what probability, and where in xi the type changes.

For each value of a control parameter (e.g. c of section 3.1) each sample of the uncertain
parameter ``p = p_bar + sigma xi`` is a deterministic impact oscillator that settles on
some attractor. Its *type* (``opa.dynamics._attractor.settle``) is the period label
``z = n/p`` (n forcing periods, p impacts), ``quasi-periodic``, ``chaotic`` (largest
Lyapunov exponent above ``CHAOS_THRESHOLD``), ``sticking``, ``escape`` or ``failed``.
At one control value:

1. **A grid** of ``GRID`` points of xi (equal steps of the law's CDF) is classified from
   the paper's start (x0, v0); its periodic attractors seed the continuation.
2. **Boundaries by continuation in xi.** The bifurcations of those attractors along
   ``p`` over the support are located (:func:`locate_bifurcations`: pseudo-arclength
   continuation of the fixed points of the stroboscopic map, period doublings and folds
   root-found, grazings extrapolated; ``xtol`` in xi) and mapped to
   ``xi = (p - p_bar) / sigma``.
3. **The type between boundaries** is that of the run from (x0, v0) at the middle of each
   interval; neighbours of the same type merge (a boundary between them changes nothing
   a user sees).
4. **Probabilities** are the law's mass between the boundaries, ``F(xi_b) - F(xi_a)``:
   exact up to the boundaries' error, for any law of xi.
5. **Monte Carlo beside it**: ``samples`` random points of xi, each classified from
   (x0, v0); shares with binomial standard errors ``sqrt(p (1 - p) / M)``, checked against
   the continuation's probabilities (``agree``: within 3 SE, or one sample).
6. **Coexisting attractors**: the interval middles and the first ``coexist`` samples are
   classified again from ``extra_states`` other initial states (``initial_states``); an
   interval whose type depends on the start is reported with the other types
   (hysteresis), and so is the share of those samples.

Where continuation cannot follow (a type that is not periodic, more than one sample of a
type no interval has, or no periodic attractor to continue) the control value's
probabilities are the Monte Carlo ones, and ``method`` says so (``note`` says why).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from opa._model import Oscillator, SolverOptions
from opa._system import System
from opa.dynamics._attractor import (
    NON_PERIODIC,
    Settings,
    initial_states,
    same_attractor,
    sample_inputs,
    settle_batch,
)
from opa.dynamics._continuation import locate_bifurcations
from opa.dynamics._orbits import impulse_cycle

if TYPE_CHECKING:  # scipy.stats loads scipy.optimize: not at import opa
    from opa._measure import Measure

#: the continuation's probabilities agree with Monte Carlo within this many binomial SE
AGREEMENT_SE = 3.0
#: points of xi classified first, to seed the continuation (equal steps of the CDF), and
#: where the two more sit at the ends of the support (this fraction of its length inside)
GRID = 9
GRID_END = 1e-3
#: longest period (in impulse cycles) of a grid attractor that seeds the continuation:
#: the windows of long periods inside chaos are not followed (they cost seconds each and
#: the value is sampled anyway)
MAX_SEED_PERIOD = 8
#: Poincaré points kept per Monte Carlo sample (a period up to this is kept whole)
POINTS = 16
#: the EMR's sweep beside the diagram (the paper's: 500 transient periods)
EMR_TRANSIENT, EMR_RECORD = 500, 100
#: default: other initial states, and the samples classified from them
EXTRA_STATES = 2
COEXIST_SAMPLES = 64


@dataclass(frozen=True)
class SliceTask:
    """Everything one control value needs (picklable: a worker process computes it)."""

    value: float
    oscillator: Oscillator  # with the control parameter at ``value``
    uncertain: str
    sigma: float
    distribution: str | None
    samples: int
    seed: int
    options: SolverOptions
    settings: Settings
    xtol: float
    extra_states: int
    coexist: int


def classify(oscillator: Oscillator, uncertain: str, values, *, options: SolverOptions,
             transient: int = 1000, record: int = 64, state=None,
             settings: Settings | None = None) -> list[str]:
    """The attractor type of the system with ``uncertain`` at each of ``values``
    (absolute), each from ``state`` (default x0, v0), by ``settle``."""
    return [a.type for a in attractors(oscillator, uncertain, values, options=options,
                                       state=state, settings=settings or Settings(
                                           transient=transient, record=record))]


def attractors(oscillator: Oscillator, uncertain: str, values, *, options: SolverOptions,
               settings: Settings, state=None) -> list:
    """The ``Attractor`` of the system with ``uncertain`` at each of ``values``."""
    values = np.asarray(values, dtype=float).ravel()
    if not len(values):
        return []
    system = System(oscillator, sigma=0.0, uncertain=uncertain, order=0)
    inputs = sample_inputs(system, options, values)
    start = (oscillator.x0, oscillator.v0) if state is None else state
    states = np.repeat(np.asarray(start, dtype=float)[None], len(values), axis=0)
    return settle_batch(system, inputs, states, options=options, settings=settings)


def compute_slice(task: SliceTask) -> dict:
    """The diagram at one control value (module docstring), as arrays (a store part)."""
    import time

    from opa._measure import parse

    clock = time.process_time()
    measure = parse(task.distribution)
    osc, sigma, s = task.oscillator, task.sigma, task.settings
    centre = float(getattr(osc, task.uncertain))
    lo, hi = measure.lo, measure.hi
    T = osc.forcing_period

    def at(xi, state=None):
        return attractors(osc, task.uncertain, centre + sigma * np.asarray(xi, dtype=float),
                          options=task.options, settings=s, state=state)

    # the grid: equal steps of the CDF, and both ends of the support (a type confined to
    # a thin layer at an end is seeded too)
    ends = [lo + GRID_END * (hi - lo), hi - GRID_END * (hi - lo)]
    grid = np.sort(np.concatenate([measure.ppf((np.arange(GRID) + 0.5) / GRID), ends]))
    grid_found = at(grid)
    cycle = impulse_cycle(osc) or 1

    def seeds_of(xis, found_):
        return [(centre + sigma * x, a.state, a.periods * T, a.points)
                for x, a in zip(xis, found_) if a.periodic and a.type not in NON_PERIODIC
                and a.period <= MAX_SEED_PERIOD * cycle]

    def continuation(seeds):
        """(note, located (xi, kind) in the support)"""
        if not seeds:
            return "no periodic attractor on the grid to continue", []
        try:
            located = locate_bifurcations(osc, task.uncertain, centre + sigma * lo,
                                          centre + sigma * hi, options=task.options,
                                          seeds=seeds, xtol=task.xtol * sigma)
        except ValueError as err:  # e.g. no common period of the forcing
            return f"continuation refused: {err}", []
        found_ = sorted(((p.value - centre) / sigma, p.kind) for p in located)
        return "", [(x, k) for x, k in found_ if lo < x < hi]

    def intervals_of(found_):
        """(intervals (lo, hi, type, last mid), boundaries, mids, their attractors)"""
        edges = [lo, *[x for x, _ in found_], hi]
        mids_ = [0.5 * (a + b) for a, b in zip(edges[:-1], edges[1:])]
        mid_found_ = at(mids_)
        intervals_, boundaries_ = [], []
        start = edges[0]
        for i, a in enumerate(mid_found_):  # merge neighbours of the same type
            last = i == len(mid_found_) - 1
            if last or mid_found_[i + 1].type != a.type:
                intervals_.append((start, edges[i + 1], a.type, i))
                if not last:
                    boundaries_.append((edges[i + 1], found_[i][1]))
                    start = edges[i + 1]
        return intervals_, boundaries_, mids_, mid_found_

    seeds = seeds_of(grid, grid_found)
    note, found = continuation(seeds)
    intervals, boundaries, mids, mid_found = intervals_of(found)
    rng = np.random.default_rng(task.seed)
    xi = measure.ppf(rng.random(task.samples)) if task.samples else np.zeros(0)
    mc = at(xi)
    mc_types = [a.type for a in mc]
    known = {kind for _, _, kind, _ in intervals}
    missed = [j for j, a in enumerate(mc) if a.type not in known]
    if not note and missed and len(missed) > 1:
        # samples on a periodic type no interval has: a branch the grid did not seed;
        # continue from a few of them too (the nearest to each end of their range)
        picks = sorted({missed[0], missed[-1], *[j for j in missed
                                                  if mc_types[j] != mc_types[missed[0]]][:2]})
        extra = seeds_of(xi[picks], [mc[j] for j in picks])
        if extra:
            note, found = continuation(seeds + extra)
            intervals, boundaries, mids, mid_found = intervals_of(found)
    # coexisting attractors: the same points from other initial states
    others = initial_states(osc, task.extra_states)[1:]
    checked = np.arange(min(task.coexist, task.samples))
    mid_other = [at(mids, state=st) for st in others]
    mc_other = [at(xi[checked], state=st) for st in others]
    interval_other = []
    for _, _, kind, i in intervals:
        alt = set()
        for j in _members(intervals, i, mid_found):
            for r in mid_other:
                if not same_attractor(r[j], mid_found[j]):
                    alt.add(r[j].type if r[j].type != kind else f"{kind} (another orbit)")
        interval_other.append("|".join(sorted(alt)))
    mc_coexist = np.array([any(not same_attractor(r[j], mc[j]) for r in mc_other)
                           for j in range(len(checked))], dtype=np.int8)
    cdf = measure.cdf
    prob = {}
    for a, b, kind, _ in intervals:
        prob[kind] = prob.get(kind, 0.0) + float(cdf(b) - cdf(a))
    counts = {k: mc_types.count(k) for k in set(mc_types)}
    unseen = {k: n for k, n in counts.items() if k not in prob}
    if not note and any(k in NON_PERIODIC for k in prob):
        note = "a type between the boundaries is not periodic: " + ", ".join(
            sorted(k for k in prob if k in NON_PERIODIC))
    if not note and any(n > 1 for n in unseen.values()):
        note = "Monte Carlo samples of types no interval has: " + ", ".join(
            f"{k} ({n})" for k, n in sorted(unseen.items()) if n > 1)
    coexist_mass = sum(float(cdf(b) - cdf(a)) for (a, b, _, _), o in
                       zip(intervals, interval_other) if o)
    points = np.full((len(mc), POINTS, 2), np.nan, dtype=np.float32)
    for j, a in enumerate(mc):
        kept = a.points[-POINTS:]
        points[j, :len(kept)] = kept
    return {
        "value": float(task.value), "method": int(bool(note)), "note": note,
        "samples": int(task.samples),
        "located_xi": np.array([x for x, _ in found], dtype=float),
        "located_kind": np.array([k for _, k in found], dtype=str),
        "boundary_xi": np.array([x for x, _ in boundaries], dtype=float),
        "boundary_kind": np.array([k for _, k in boundaries], dtype=str),
        "interval_lo": np.array([a for a, _, _, _ in intervals], dtype=float),
        "interval_hi": np.array([b for _, b, _, _ in intervals], dtype=float),
        "interval_type": np.array([k for _, _, k, _ in intervals], dtype=str),
        "interval_other": np.array(interval_other, dtype=str),
        "coexist_probability": coexist_mass,
        "prob_type": np.array(list(prob), dtype=str),
        "prob_value": np.array(list(prob.values()), dtype=float),
        "grid_xi": grid, "grid_type": np.array([a.type for a in grid_found], dtype=str),
        "mc_xi": xi, "mc_type": np.array(mc_types, dtype=str),
        "mc_lyapunov": np.array([a.lyapunov for a in mc], dtype=float),
        "mc_periods": np.array([a.periods for a in mc], dtype=np.int64),
        "mc_settled": np.array([a.settled for a in mc], dtype=np.int8),
        "mc_points": points,
        "mc_coexist": mc_coexist,
        "mc_mismatch": _mismatch(xi, mc_types, intervals),
        "cpu_seconds": time.process_time() - clock,
    }


def _mismatch(xi, types, intervals) -> int:
    """How many samples have a type other than that of the interval holding their xi."""
    count = 0
    for x, kind in zip(xi, types):
        for a, b, interval_kind, _ in intervals:
            if a <= x <= b:
                count += kind != interval_kind
                break
    return count


def _members(intervals, i, mid_found) -> list[int]:
    """The indices of the unmerged intervals that merged into the one ending at ``i``."""
    ends = [j for _, _, _, j in intervals]
    k = ends.index(i)
    first = ends[k - 1] + 1 if k else 0
    return list(range(first, i + 1))


def stochastic_slice(oscillator: Oscillator, uncertain: str, sigma: float,
                     measure: "Measure | str | None", *, samples: int, seed: int,
                     options: SolverOptions, settings: Settings | None = None,
                     xtol: float = 1e-10, extra_states: int = EXTRA_STATES,
                     coexist: int = COEXIST_SAMPLES) -> dict:
    """The diagram at one control value (module docstring), as :func:`compute_slice`."""
    distribution = getattr(measure, "name", measure)
    return compute_slice(SliceTask(
        value=math.nan, oscillator=oscillator, uncertain=uncertain, sigma=float(sigma),
        distribution=distribution, samples=int(samples), seed=int(seed), options=options,
        settings=settings or Settings(), xtol=float(xtol), extra_states=int(extra_states),
        coexist=int(coexist)))


def _check(name: str, value, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def stochastic_diagram(oscillator: Oscillator | System, parameter: str, values, *,
                       sigma: float, uncertain: str = "mu", distribution=None,
                       samples: int = 1024, seed: int = 0,
                       options: SolverOptions | None = None, transient: int = 1000,
                       record: int = 64, xtol: float = 1e-10,
                       extra_states: int = EXTRA_STATES, coexist: int = COEXIST_SAMPLES,
                       emr: bool = False, emr_order: int = 4, workers: int = 1,
                       scheduler=None, parts: str | None = None, log=None):
    """Attractor types and their probabilities along ``parameter`` (module docstring).

    Parameters
    ----------
    oscillator : the deterministic model (an :class:`opa.Oscillator`, or a System's).
    parameter : the control parameter swept over ``values`` (not the uncertain one).
    sigma, uncertain, distribution : the uncertainty ``p = p_bar + sigma xi`` and the law
        of xi (default the semicircle).
    samples, seed : Monte Carlo samples classified at each value (0: none).
    transient, record : the longest run before a type is decided from its last
        ``record`` periods (a run stops as soon as it has settled, ``settle``).
    xtol : tolerance of the located boundaries in xi.
    extra_states, coexist : other initial states (``initial_states``), and how many of
        the samples are classified from them too (the interval middles always are).
    emr, emr_order : also sweep the EMR (the OPA system of order ``emr_order`` at the
        same sigma, semicircle law only: the paper's diagrams) over the values, 500
        transient and 100 recorded periods from the paper's start, for the figure.
    workers : processes; the control values are shared out among them.
    scheduler : a Dask scheduler address or ``distributed.Client``: the control values
        (and the EMR sweep) run there as tasks instead, each with one numba thread; the
        result is the same to the bit.
    parts : a folder where each finished control value is kept as it finishes, a
        :class:`opa._dataset.Store` keyed by everything the value depends on; a rerun
        with the same folder reads them back instead of computing them again (an
        interrupted diagram resumes), and a damaged file (unreadable, or edited since it
        was written: each part carries the digest of its content) is set aside, named
        (``log``, else a warning) and computed again. The folder is locked while the
        diagram runs: another process writing it is refused (ValueError naming it).
        None: nothing is kept.
    log : callable taking a progress line, or None.

    Returns
    -------
    xarray.Dataset over ``parameter`` and ``type`` (every attractor type seen): the
    probabilities ``probability`` (continuation, or Monte Carlo where it cannot follow),
    ``mc_probability`` and its ``mc_sem``, ``agree`` (1 where every type's two
    probabilities are within 3 binomial SE, or one sample), ``method`` (0 continuation,
    1 sampling) and ``method_note``; over (``parameter``, ``boundary``) the boundaries
    ``boundary_xi`` and ``boundary_kind``; over (``parameter``, ``interval``) the
    intervals with their type and the types reached from other initial states
    (``interval_other``), ``coexist_probability`` (their mass) and ``mc_coexist`` (the
    share of the checked samples whose type depends on the start); over (``parameter``,
    ``sample``) each sample's ``mc_xi``, ``mc_type``, ``mc_lyapunov``, ``mc_periods``,
    ``mc_settled`` and its Poincaré points ``mc_x, mc_v`` (``point``: at most 16).

    Examples
    --------
    >>> from opa import preset
    >>> ds = stochastic_diagram(preset("3.1", F0=0.0), "c", [0.0396996668], sigma=0.03,
    ...                         samples=0, extra_states=0)
    >>> abs(round(float(ds.boundary_xi[0, 0]), 6)), str(ds.boundary_kind.values[0, 0])
    (0.0, 'period-doubling')
    >>> [round(float(p), 6) for p in ds.probability[0].values]   # half and half
    [0.5, 0.5]
    """
    from opa._dataset import Store, package_version
    from opa._measure import parse

    if isinstance(oscillator, System):
        oscillator = oscillator.oscillator
    if not isinstance(oscillator, Oscillator):
        raise ValueError(f"oscillator must be an opa.Oscillator or System, got "
                         f"{type(oscillator).__name__}")
    if uncertain not in ("mu", "a", "c"):
        raise ValueError(f"uncertain must be mu, a or c, got {uncertain!r}")
    if parameter == uncertain or not hasattr(oscillator, parameter) or parameter in (
            "x0", "v0"):
        raise ValueError(f"parameter must be a model parameter other than the uncertain "
                         f"one ({uncertain}) and x0, v0, got {parameter!r}")
    if isinstance(sigma, bool) or not (isinstance(sigma, (int, float)) and sigma > 0
                                       and math.isfinite(sigma)):
        raise ValueError(f"sigma must be a positive number, got {sigma!r}")
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) \
            or samples < 0 or samples == 1:
        raise ValueError(f"samples must be 0 or an integer >= 2, got {samples!r}")
    extra_states = _check("extra_states", extra_states, 0)
    coexist = _check("coexist", coexist, 0)
    workers = _check("workers", workers, 1)
    if not (isinstance(xtol, (int, float)) and math.isfinite(xtol) and xtol > 0):
        raise ValueError(f"xtol must be a finite number > 0, got {xtol!r}")
    settings = Settings(transient=transient, record=record)
    values = np.asarray(values, dtype=float)
    if values.ndim != 1 or not len(values) or not np.isfinite(values).all():
        raise ValueError("values must be a non-empty 1-D array of finite numbers")
    from opa._work import check_work

    # at most: every sample and extra state of every value runs transient + record periods
    check_work("this stochastic diagram",
               len(values) * (max(samples, 1) + extra_states) * (transient + record),
               [("values", len(values)), ("samples", samples),
                ("transient + record", f"({transient} + {record})")])
    if not isinstance(emr, bool):
        raise ValueError(f"emr must be True or False, got {emr!r}")
    if emr:
        emr_order = _check("emr_order", emr_order, 1)
        if parse(distribution).name != "semicircle":
            raise ValueError("emr: the EMR is the paper's OPA system, whose sweeps use the "
                             f"semicircle law, not {parse(distribution).name}")
        if np.any(np.diff(values) <= 0):
            raise ValueError("emr: the values must increase")
    options = options or SolverOptions()
    measure = parse(distribution)
    system = System(oscillator, sigma=float(sigma), uncertain=uncertain,
                    distribution=distribution)
    system.check_samples()
    tasks = [SliceTask(value=float(v), oscillator=oscillator.replace(**{parameter: float(v)}),
                       uncertain=uncertain, sigma=float(sigma), distribution=measure.name,
                       samples=int(samples), seed=seed + i, options=options,
                       settings=settings, xtol=float(xtol), extra_states=extra_states,
                       coexist=min(coexist, int(samples)))
             for i, v in enumerate(values)]
    store = (None if parts is None else
             Store(parts, "stochastic diagram", log=log, lock=True))
    try:  # the lock of the parts folder is held until the diagram is assembled
        def inputs(task):
            return {"task": repr(task), "version": package_version()}

        def name(task):
            return f"slice-{parameter}{task.value:g}"

        results = {}
        todo = []
        for i, task in enumerate(tasks):
            found = None if store is None else store.load(name(task), inputs(task))
            if found is not None:
                results[i] = found
                _log(log, i, len(tasks), parameter, found, reused=True)
            else:
                todo.append(i)

        def finish(i, piece):
            if store is not None:
                store.save(name(tasks[i]), inputs(tasks[i]), piece)
                piece = store.load(name(tasks[i]), inputs(tasks[i]))  # as a rerun reads it
            results[i] = piece
            _log(log, i, len(tasks), parameter, piece, reused=False)

        if scheduler is not None and todo:
            _run_slices_dask(tasks, todo, finish, scheduler)
        else:
            _run_slices(tasks, todo, finish, workers)
        slices = [results[i] for i in range(len(tasks))]
        ds = _dataset(slices, parameter, values, system, options, measure, settings, seed,
                      samples, xtol, extra_states, coexist)
        if emr:
            from opa.dynamics._sweep import sweep

            if log is not None:
                log(f"the EMR (OPA N = {emr_order}, sigma = {sigma:g}) over {len(values)} "
                    f"values of {parameter}")
            opa = sweep("opa", parameter, values, system.replace(order=emr_order),
                        transient=EMR_TRANSIENT, record=EMR_RECORD, options=options,
                        workers=workers, scheduler=scheduler, progress=False, locate=False)
            ds["emr_x"] = ((parameter, "emr_point"), opa.section_x.values, {
                "long_name": f"stroboscopic x_0 of the EMR (OPA N = {emr_order}) after "
                f"{EMR_TRANSIENT} periods, {EMR_RECORD} recorded", "units": "1"})
            ds.attrs.update(emr_order=int(emr_order), emr_transient=EMR_TRANSIENT,
                            emr_record=EMR_RECORD)
        return ds
    finally:
        if store is not None:
            store.close()


def _run_slices(tasks, todo, finish, workers) -> None:
    """Compute the control values ``todo``, here or in ``workers`` processes."""
    if workers <= 1 or len(todo) <= 1:
        for i in todo:
            finish(i, compute_slice(tasks[i]))
        return
    from concurrent.futures import FIRST_COMPLETED, wait

    from opa.dynamics._sweep import local_executor

    executor = local_executor(min(workers, len(todo)))
    pending = {}
    try:
        # the slowest values (chaotic ones, at small c in section 3.1) are not known in
        # advance: the pool hands out one value at a time
        pending = {executor.submit(compute_slice, tasks[i]): i for i in todo}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                finish(pending.pop(fut), fut.result())
    except BaseException:
        for fut in pending:
            fut.cancel()
        raise
    finally:
        executor.shutdown(wait=True, cancel_futures=True)


def _single_threaded_slice(task: SliceTask) -> dict:
    """:func:`compute_slice` with one numba thread (a Dask worker runs several tasks at
    once; the cores are shared out by its thread count)."""
    import numba

    numba.set_num_threads(1)
    return compute_slice(task)


def _run_slices_dask(tasks, todo, finish, scheduler) -> None:
    """Compute the control values ``todo`` as tasks on a Dask cluster."""
    from distributed import as_completed, Client

    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout=5) if own else scheduler
    except (OSError, TimeoutError) as err:
        raise ValueError(f"scheduler {scheduler!r} did not answer as a Dask scheduler "
                         f"within 5 s ({type(err).__name__})") from None
    try:
        futures = {client.submit(_single_threaded_slice, tasks[i], pure=False): i
                   for i in todo}
        for future in as_completed(futures):
            finish(futures[future], future.result())
    finally:
        if own:
            client.close()


def _log(log, i, count, parameter, piece, *, reused) -> None:
    if log is None:
        return
    shown = ", ".join(f"{k} {p:.3f}" for k, p in sorted(_probabilities(piece).items(),
                                                         key=lambda kp: type_order(kp[0]))
                      if p >= 0.005) or "(every type below 0.005)"
    how = "sampling" if int(piece["method"]) else "continuation"
    log(f"{i + 1}/{count} {parameter} = {float(piece['value']):g}: {shown} ({how}; "
        f"{float(piece['cpu_seconds']):.1f} s CPU{', read back' if reused else ''})")


def _probabilities(piece) -> dict:
    """type -> probability of one slice: continuation, or Monte Carlo when sampled."""
    if int(piece["method"]) or not len(piece["prob_type"]):
        return _shares(piece)
    return dict(zip((str(k) for k in piece["prob_type"]), map(float, piece["prob_value"])))


def _shares(piece) -> dict:
    types = [str(t) for t in np.atleast_1d(piece["mc_type"])]
    return {k: types.count(k) / len(types) for k in set(types)} if types else {}


def _dataset(slices, parameter, values, system, options, measure, settings, seed, samples,
             xtol, extra_states, coexist):
    import xarray as xr

    from opa._dataset import provenance_attrs

    probs = [_probabilities(s) for s in slices]
    shares = [_shares(s) for s in slices]
    kinds = sorted({k for p in (*probs, *shares) for k in p}, key=type_order)
    P = np.array([[p.get(k, 0.0) for k in kinds] for p in probs]).reshape(len(slices), -1)
    M = np.array([[m.get(k, 0.0) for k in kinds] for m in shares]).reshape(len(slices), -1)
    n = float(samples)
    with np.errstate(invalid="ignore", divide="ignore"):
        sem = np.full_like(P, np.nan) if n == 0 else np.sqrt(P * (1 - P) / n)
        # a type of probability 0 or 1 has no binomial spread: one sample off is allowed
        tol = np.maximum(AGREEMENT_SE * sem, 1.0 / n) if n else sem
    agree = (np.all(np.abs(P - M) <= tol + 1e-12, axis=1).astype(np.int8) if n
             else np.full(len(slices), -1, dtype=np.int8))

    def padded(key, fill, dtype):
        width = max([len(np.atleast_1d(s[key])) for s in slices] + [0])
        out = np.full((len(slices), width), fill, dtype=dtype)
        for i, s in enumerate(slices):
            item = np.atleast_1d(s[key])
            out[i, :len(item)] = item
        return out

    one = {"units": "1"}
    dims_b, dims_i = (parameter, "boundary"), (parameter, "interval")
    dims_s, dims_p = (parameter, "sample"), (parameter, "sample", "point")
    mc_points = (np.stack([s["mc_points"] for s in slices]) if samples
                 else np.zeros((len(slices), 0, POINTS, 2), dtype=np.float32))
    checked = min(coexist, samples)
    data = {
        "probability": ((parameter, "type"), P, {
            "long_name": "probability of each attractor type (law mass between the "
            "located boundaries, or Monte Carlo where continuation cannot follow)", **one}),
        "mc_probability": ((parameter, "type"), M, {
            "long_name": "share of the Monte Carlo samples on each type", **one}),
        "mc_sem": ((parameter, "type"), sem, {
            "long_name": "binomial standard error sqrt(p (1 - p) / M) of the probability",
            **one}),
        "agree": (parameter, agree, {
            "long_name": "1 where every type's probability is within 3 binomial SE (or one "
            "sample) of the Monte Carlo share; -1 without samples", **one}),
        "method": (parameter, np.array([int(s["method"]) for s in slices], dtype=np.int8),
                   {"long_name": "0: continuation in xi; 1: Monte Carlo sampling", **one}),
        "method_note": (parameter, np.array([str(s["note"]) for s in slices], dtype=str),
                        {"long_name": "why continuation could not follow (empty: it did)"}),
        "boundary_xi": (dims_b, padded("boundary_xi", np.nan, float), {
            "long_name": "xi where the attractor type changes (located bifurcation)", **one}),
        "boundary_kind": (dims_b, padded("boundary_kind", "", object).astype(str), {
            "long_name": "the bifurcation at the boundary"}),
        "located_xi": ((parameter, "located"), padded("located_xi", np.nan, float), {
            "long_name": "every located bifurcation in the support, xi", **one}),
        "located_kind": ((parameter, "located"),
                         padded("located_kind", "", object).astype(str),
                         {"long_name": "every located bifurcation in the support, kind"}),
        "interval_lo": (dims_i, padded("interval_lo", np.nan, float), {
            "long_name": "lower end in xi of an interval of one type", **one}),
        "interval_hi": (dims_i, padded("interval_hi", np.nan, float), {
            "long_name": "upper end in xi of an interval of one type", **one}),
        "interval_type": (dims_i, padded("interval_type", "", object).astype(str), {
            "long_name": "attractor type from (x0, v0) on the interval"}),
        "interval_other": (dims_i, padded("interval_other", "", object).astype(str), {
            "long_name": "other attractor types reached on the interval from the other "
            "initial states ('|'-separated; empty: none)"}),
        "coexist_probability": (parameter, np.array(
            [float(s["coexist_probability"]) for s in slices]), {
            "long_name": "law mass of the intervals whose type depends on the initial "
            "state (coexisting attractors)", **one}),
        "mc_coexist": (parameter, np.array(
            [float(np.mean(s["mc_coexist"])) if checked else np.nan for s in slices]), {
            "long_name": f"share of the first {checked} samples whose type depends on the "
            "initial state", **one}),
        "mc_mismatch": (parameter, np.array([int(s["mc_mismatch"]) for s in slices]), {
            "long_name": "samples whose type is not that of the interval (between the "
            "located boundaries) holding their xi", **one}),
        "mc_xi": (dims_s, padded("mc_xi", np.nan, float), {
            "long_name": "xi of each Monte Carlo sample", **one}),
        "mc_type": (dims_s, padded("mc_type", "", object).astype(str), {
            "long_name": "attractor type of each sample from (x0, v0)"}),
        "mc_lyapunov": (dims_s, padded("mc_lyapunov", np.nan, float), {
            "long_name": "largest Lyapunov exponent per unit time (two-trajectory "
            "estimate; NaN where the run settled on a period first)", **one}),
        "mc_periods": (dims_s, padded("mc_periods", 0, np.int64), {
            "long_name": "forcing periods integrated before the type was decided", **one}),
        "mc_settled": (dims_s, padded("mc_settled", 0, np.int8), {
            "long_name": "1 where the run stopped early (settled on a period, or chaotic); "
            "0 where its type was read off the last record periods", **one}),
        "mc_x": (dims_p, mc_points[..., 0], {
            "long_name": "stroboscopic x of the sample's attractor (one period, or the last "
            "points of the record; NaN padded)", **one}),
        "mc_v": (dims_p, mc_points[..., 1], {
            "long_name": "stroboscopic dx/dt of the sample's attractor", **one}),
    }
    ds = xr.Dataset(
        data,
        coords={parameter: (parameter, values, {"long_name": f"control parameter "
                                                 f"{parameter}", **one}),
                "type": ("type", np.array(kinds, dtype=str),
                         {"long_name": "attractor type: period label z = n/p (n forcing "
                          "periods, p impacts), quasi-periodic, chaotic, sticking, escape, "
                          "failed"})},
        attrs=provenance_attrs("stochastic", system, options, seed=seed),
    )
    ds.attrs[parameter] = math.nan  # swept: its values are the coordinate
    ds.attrs.update(distribution=measure.name, sweep_parameter=parameter,
                    samples=int(samples), transient=int(settings.transient),
                    record=int(settings.record), settle_tol=float(settings.settle_tol),
                    chaos_threshold=float(settings.chaos_threshold),
                    lyapunov_periods=int(settings.lyapunov_periods), xtol=float(xtol),
                    extra_states=int(extra_states), coexist_samples=int(checked))
    return ds


def type_order(kind: str):
    """Sort key of attractor types: periodic labels by period and impacts, then the rest
    in the order of ``NON_PERIODIC``."""
    if "/" in kind:
        n, p = kind.split("/")
        return (0, int(n), int(p) if p.isdigit() else -1, "")
    return (1, NON_PERIODIC.index(kind) if kind in NON_PERIODIC else 99, 0, kind)


__all__ = ["AGREEMENT_SE", "SliceTask", "attractors", "classify", "compute_slice",
           "stochastic_diagram", "stochastic_slice", "type_order"]
