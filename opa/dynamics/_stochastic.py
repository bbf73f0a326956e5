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

**Several uncertain parameters** (an :class:`opa.System` of d >= 2, or ``uncertain="mu,c"``
with one sigma each): the boundaries are not located (continuation in xi follows one
parameter: it is one-dimensional by nature; the log says so in one line and the
dataset's attribute ``boundaries`` says why); the probabilities are the shares of
``samples`` systems at points of the problem's law, the same points at every control
value (:meth:`opa.Problem.sample`: scrambled Sobol' in ``SCRAMBLINGS`` independent
scramblings of ``samples / SCRAMBLINGS`` points each). A share's standard error is the
spread of the scramblings' shares, ``sd / sqrt(SCRAMBLINGS)``: the binomial
``sqrt(p (1 - p) / M)`` assumes M independent points, which scrambled Sobol' points are
not (their error is usually smaller). The other initial states classify the first
``coexist`` samples again, as in one dimension; the EMR's sweep (one uncertain
parameter) is refused.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import numbers
import os
from dataclasses import dataclass
from string import Formatter
from typing import TYPE_CHECKING

import numpy as np

from opa._execution import Execution
from opa._model import Oscillator, SolverOptions
from opa._problem import Problem
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
#: most other initial states (points on a circle of radius 1 around the origin): each
#: classifies the interval middles and the checked samples again, and in Python (one
#: loop per run and chunk), so 100000 of them ran for minutes at a tiny transient
MAX_EXTRA_STATES = 1000
#: the continuation in xi at one control value costs about as much as this many forcing
#: periods of one system (the work estimate): section 3.1 at c = 0.04 takes 0.2 s with
#: samples=0, extra_states=0, of which the grid's and the middles' runs take 0.02 s
CONTINUATION_PERIODS = 20_000
#: the boundaries' tolerance in xi: below 1e-15 double precision cannot locate them, above
#: 1e-2 they would be coarser than the grid that seeds them
XTOL_RANGE = (1e-15, 1e-2)
#: samples p_bar + sigma xi that differ by less than this (relative to p_bar) over the
#: whole support are one system in double precision; and sigma * xtol must stay above
#: TINY (the boundaries are root-found to xtol * sigma in the uncertain parameter)
RESOLUTION = 1e-12
TINY = 1e-300
#: several uncertain parameters: the samples are this many independent scramblings of
#: Sobol' points, whose shares' spread gives the standard errors
SCRAMBLINGS = 8


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


@dataclass(frozen=True)
class SampledTask:
    """One control value of a diagram of several uncertain parameters (picklable; its
    ``repr``, the problem included, keys the value's part)."""

    value: float
    oscillator: Oscillator  # with the control parameter at ``value``
    problem: Problem
    samples: int
    seed: int
    options: SolverOptions
    settings: Settings
    extra_states: int
    coexist: int

    def points(self) -> np.ndarray:
        """The sample points xi (samples, d): the same for every control value."""
        return self.problem.sample(self.samples, "sobol", seed=self.seed,
                                   replicates=SCRAMBLINGS)


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


def compute_slice(task: SliceTask | SampledTask) -> dict:
    """The diagram at one control value (module docstring), as arrays (a store part)."""
    import time

    clock = time.process_time()
    if isinstance(task, SampledTask):
        return _sampled_slice(task, clock)
    at = _Slice(task)
    grid, grid_found = at.grid()
    seeds = at.seeds_of(grid, grid_found)
    note, found = at.continuation(seeds)
    intervals, boundaries, mids, mid_found = at.intervals_of(found)
    rng = np.random.default_rng(task.seed)
    xi = at.measure.ppf(rng.random(task.samples)) if task.samples else np.zeros(0)
    mc = at(xi)
    mc_types = [a.type for a in mc]
    known = {kind for _, _, kind, _ in intervals}
    missed = [j for j, a in enumerate(mc) if a.type not in known]
    if not note and missed and len(missed) > 1:
        # samples on a periodic type no interval has: a branch the grid did not seed;
        # continue from a few of them too (the nearest to each end of their range)
        picks = sorted({missed[0], missed[-1], *[j for j in missed
                                                  if mc_types[j] != mc_types[missed[0]]][:2]})
        extra = at.seeds_of(xi[picks], [mc[j] for j in picks])
        if extra:
            note, found = at.continuation(seeds + extra)
            intervals, boundaries, mids, mid_found = at.intervals_of(found)
    interval_other, mc_coexist = _coexistence(at, intervals, mids, mid_found, xi, mc)
    prob, note, coexist_mass = _interval_masses(at.measure, intervals, interval_other,
                                                mc_types, note, task.samples)
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
        "mc_points": _last_points(mc),
        "mc_coexist": mc_coexist,
        "mc_mismatch": _mismatch(xi, mc_types, intervals),
        "cpu_seconds": time.process_time() - clock,
    }


def _sampled_slice(task: SampledTask, clock: float) -> dict:
    """One control value of several uncertain parameters: its samples classified from
    (x0, v0), the first ``coexist`` from the other initial states too."""
    import time

    xi = task.points()
    system = System(task.oscillator, uncertain=task.problem, order=0)
    inputs = system.sampled_inputs(task.options, xi=xi)

    def settled(rows, state):
        sub = type(inputs)(*(np.asarray(a)[rows] for a in (
            inputs.p, inputs.cfg, inputs.table, inputs.weights, inputs.basis)))
        states = np.repeat(np.asarray(state, dtype=float)[None], len(rows), axis=0)
        return settle_batch(system, sub, states, options=task.options,
                            settings=task.settings)

    osc = task.oscillator
    mc = settled(np.arange(len(xi)), (osc.x0, osc.v0))
    checked = np.arange(min(task.coexist, len(xi)))
    others = [settled(checked, st) for st in initial_states(osc, task.extra_states)[1:]]
    mc_coexist = np.array([any(not same_attractor(r[j], mc[j]) for r in others)
                           for j in checked], dtype=np.int8)
    return {
        "value": float(task.value), "method": 1, "note": SEVERAL_NOTE,
        "samples": int(task.samples), "mc_xi": xi,
        "mc_type": np.array([a.type for a in mc], dtype=str),
        "mc_lyapunov": np.array([a.lyapunov for a in mc], dtype=float),
        "mc_periods": np.array([a.periods for a in mc], dtype=np.int64),
        "mc_settled": np.array([a.settled for a in mc], dtype=np.int8),
        "mc_points": _last_points(mc), "mc_coexist": mc_coexist,
        "prob_type": np.zeros(0, dtype=str), "prob_value": np.zeros(0),
        "cpu_seconds": time.process_time() - clock,
    }


#: why a diagram of several uncertain parameters has no boundaries (its ``method_note``)
SEVERAL_NOTE = ("no boundaries: continuation in xi is one-dimensional by nature; the "
                "probabilities are the shares of sampled systems")


class _Slice:
    """One control value's attractors along xi: ``self(xi)`` classifies the sampled
    systems at ``xi``; the grid that seeds the continuation, the continuation of its
    periodic attractors to the boundaries, and the intervals between them."""

    def __init__(self, task: SliceTask):
        from opa._measure import parse

        self.task = task
        self.measure = parse(task.distribution)
        self.osc, self.sigma = task.oscillator, task.sigma
        self.centre = self.osc.value(task.uncertain)
        self.lo, self.hi = self.measure.lo, self.measure.hi
        self.cycle = impulse_cycle(self.osc) or 1

    def __call__(self, xi, state=None):
        task = self.task
        return attractors(self.osc, task.uncertain,
                          self.centre + self.sigma * np.asarray(xi, dtype=float),
                          options=task.options, settings=task.settings, state=state)

    def grid(self):
        """The grid: equal steps of the CDF, and both ends of the support (a type confined
        to a thin layer at an end is seeded too), with its attractors."""
        lo, hi = self.lo, self.hi
        ends = [lo + GRID_END * (hi - lo), hi - GRID_END * (hi - lo)]
        grid = np.sort(np.concatenate([self.measure.ppf((np.arange(GRID) + 0.5) / GRID),
                                       ends]))
        return grid, self(grid)

    def seeds_of(self, xis, found):
        """The continuation's seeds: the periodic attractors found at ``xis``."""
        T = self.osc.forcing_period
        return [(self.centre + self.sigma * x, a.state, a.periods * T, a.points)
                for x, a in zip(xis, found) if a.periodic and a.type not in NON_PERIODIC
                and a.period <= MAX_SEED_PERIOD * self.cycle]

    def continuation(self, seeds):
        """(note, located (xi, kind) in the support)"""
        if not seeds:
            return "no periodic attractor on the grid to continue", []
        centre, sigma, task = self.centre, self.sigma, self.task
        try:
            located = locate_bifurcations(self.osc, task.uncertain, centre + sigma * self.lo,
                                          centre + sigma * self.hi, options=task.options,
                                          seeds=seeds, xtol=task.xtol * sigma)
        except ValueError as err:  # e.g. no common period of the forcing
            return f"continuation refused: {err}", []
        found = sorted(((p.value - centre) / sigma, p.kind) for p in located)
        return "", [(x, k) for x, k in found if self.lo < x < self.hi]

    def intervals_of(self, found):
        """(intervals (lo, hi, type, last mid), boundaries, mids, their attractors)"""
        edges = [self.lo, *[x for x, _ in found], self.hi]
        mids = [0.5 * (a + b) for a, b in zip(edges[:-1], edges[1:])]
        mid_found = self(mids)
        intervals, boundaries = [], []
        start = edges[0]
        for i, a in enumerate(mid_found):  # merge neighbours of the same type
            last = i == len(mid_found) - 1
            if last or mid_found[i + 1].type != a.type:
                intervals.append((start, edges[i + 1], a.type, i))
                if not last:
                    boundaries.append((edges[i + 1], found[i][1]))
                    start = edges[i + 1]
        return intervals, boundaries, mids, mid_found


def _coexistence(at: _Slice, intervals, mids, mid_found, xi, mc):
    """Coexisting attractors: the same points from other initial states. (Each
    interval's other types, joined by "|"; 1 for each checked sample whose attractor
    depends on the start.)"""
    task = at.task
    others = initial_states(at.osc, task.extra_states)[1:]
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
    return interval_other, mc_coexist


def _interval_masses(measure, intervals, interval_other, mc_types, note, samples):
    """(type -> law mass of its intervals, the note saying why continuation does not
    decide, the law mass of the intervals with coexisting attractors)."""
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
    if note and not samples:
        note += ("; without samples the probabilities are the law mass of the types at "
                 "the interval middles")
    return prob, note, coexist_mass


def _last_points(mc) -> np.ndarray:
    """Each sample's last Poincare points (at most ``POINTS``; NaN padded)."""
    points = np.full((len(mc), POINTS, 2), np.nan, dtype=np.float32)
    for j, a in enumerate(mc):
        kept = a.points[-POINTS:]
        points[j, :len(kept)] = kept
    return points


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


#: why omega cannot be the diagram's uncertain parameter
OMEGA_REFUSED = ("{uncertain} {0}: omega cannot be uncertain in the stochastic diagram: each "
                 "sampled system has its own forcing period 2 pi/omega_i, and the attractors are "
                 "classified at the nominal period's stroboscopic times (a period-1 orbit would "
                 "read as quasi-periodic); sweep omega instead")


class DiagramInputError(ValueError):
    """An input of :func:`stochastic_diagram` refused before any work starts: one line
    naming the keyword and its value.

    The message is a template whose fields are keywords (``{sigma}``) and values
    (``{0!r}``); :meth:`message` writes each keyword as ``names`` says (the CLI: its
    flags, as ``opa._work.WorkBudgetError.message`` does), else as itself.

    >>> str(DiagramInputError("{sigma} must be positive, got {0!r}", -1.0))
    'sigma must be positive, got -1.0'
    >>> DiagramInputError("{sigma} must be positive, got {0!r}", -1.0).message(
    ...     {"sigma": "--sigma"})
    '--sigma must be positive, got -1.0'
    """

    def __init__(self, template: str, *values):
        self.template, self.values = template, values
        super().__init__(self.message())

    def message(self, names: dict[str, str] | None = None) -> str:
        return Formatter().vformat(self.template, self.values, _Names(names or {}))


class _Names(dict):
    """A keyword without a name of its own is written as itself."""

    def __missing__(self, key):
        return key


def _quoted(text) -> str:
    """``text`` as literal text of a DiagramInputError's template."""
    return str(text).replace("{", "{{").replace("}", "}}")


def _named(keyword: str, err: Exception, *shown) -> DiagramInputError:
    """A message from elsewhere (``err``) as a refusal naming ``keyword`` (and the value
    ``shown``, where given)."""
    text = " ".join(str(err).split())
    if text.startswith(keyword + " "):  # it names the keyword already
        return DiagramInputError("{" + keyword + "}" + _quoted(text[len(keyword):]))
    return DiagramInputError("{" + keyword + "}" + (" {0!r}" if shown else "") + ": "
                             + _quoted(text), *shown)


def _whole(keyword: str, value, low: int, high: int | None = None, why: str = "") -> int:
    """``value`` as an int: an integer (not a bool) in [low, high]."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < low:
        raise DiagramInputError("{" + keyword + f"}} must be an integer >= {low}, got "
                                "{0!r}", value)
    if high is not None and value > high:
        raise DiagramInputError("{" + keyword + f"}} must be at most {high}{_quoted(why)}, "
                                "got {0!r}", value)
    return int(value)


@dataclass(frozen=True)
class DiagramInputs:
    """The inputs of :func:`stochastic_diagram` once checked (:func:`check_diagram`)."""

    oscillator: Oscillator
    parameter: str
    values: np.ndarray
    oscillators: tuple  # the oscillator at each value
    sigma: float
    uncertain: str
    measure: "Measure"
    system: System
    samples: int
    seed: int
    options: SolverOptions
    settings: Settings
    xtol: float
    extra_states: int
    coexist: int  # the samples classified from the other states (at most ``samples``)
    emr: bool
    emr_order: int
    execution: Execution  # workers, scheduler, the parts folder (checkpoint) and log

    @property
    def workers(self) -> int:
        return self.execution.workers


@dataclass(frozen=True)
class EMR:
    """The EMR beside a stochastic diagram (the OPA system of ``order`` at the same
    sigma, semicircle law only: the paper's diagrams), swept over the increasing values,
    500 transient and 100 recorded periods from the paper's start, for the figure."""

    order: int = 4


#: the keywords of earlier releases, by the record or object that now holds them
_LEGACY = {
    "uncertainty": ("sigma", "uncertain", "distribution"),  # the System
    "settle": ("transient", "record"),  # Settings
    "emr": ("emr_order",),  # EMR
    "execution": ("workers", "scheduler", "parts", "log"),  # Execution
}


def check_diagram(oscillator, parameter, values, *, samples=1024, seed=0, options=None,
                  settle=None, xtol=1e-10, extra_states=EXTRA_STATES, coexist=None,
                  emr=False, execution=None, **legacy) -> DiagramInputs:
    """The inputs of :func:`stochastic_diagram` (same keywords) checked before any work:
    a :class:`DiagramInputError` (a ValueError) naming the first keyword that is wrong,
    of the wrong type, out of range, or without effect in the combination; a
    ``opa._work.WorkBudgetError`` for a diagram beyond the work budget. The CLI calls it
    first, and names its flags (``DiagramInputError.message``)."""
    allowed = {k for keys in _LEGACY.values() for k in keys}
    unknown = sorted(set(legacy) - allowed)
    if unknown:
        raise TypeError(f"stochastic_diagram() got an unexpected keyword argument "
                        f"{unknown[0]!r}")
    execution_keywords = {k: legacy.pop(k) for k in _LEGACY["execution"] if k in legacy}
    workers, scheduler, parts, log = _execution_keywords(execution, execution_keywords)
    sigma, uncertain, distribution = _uncertainty(oscillator, legacy)
    transient, record = _settle_keywords(settle, legacy)
    emr, emr_order = _emr_keywords(emr, legacy)
    checked = _check_inputs(
        oscillator, parameter, values, sigma=sigma, uncertain=uncertain,
        distribution=distribution, samples=samples, seed=seed, options=options,
        transient=transient, record=record, xtol=xtol, extra_states=extra_states,
        coexist=coexist, emr=emr, emr_order=emr_order, workers=workers,
        scheduler=scheduler, parts=parts, log=log)
    if settle is not None:  # its other fields (check, tolerances) too
        checked = dataclasses.replace(checked, settings=settle)
    return checked


def _uncertainty(oscillator, legacy: dict) -> tuple:
    """(sigma, uncertain, distribution): the keywords, or a System's own."""
    if "sigma" in legacy:
        return (legacy["sigma"], legacy.get("uncertain", "mu"),
                legacy.get("distribution"))
    if isinstance(oscillator, System):
        if "uncertain" in legacy or "distribution" in legacy:
            raise DiagramInputError("{oscillator}: a System holds its uncertainty; give "
                                    "{sigma} too, or none of {uncertain}, {distribution}")
        return oscillator.sigma, oscillator.uncertain, oscillator.distribution
    raise DiagramInputError("{sigma} is required with an opa.Oscillator (or pass an "
                            "opa.System, which holds its uncertainty)")


def _settle_keywords(settle, legacy: dict) -> tuple:
    """(transient, record): a Settings record's, or the keywords (1000, 64)."""
    if settle is None:
        return legacy.get("transient", 1000), legacy.get("record", 64)
    if not isinstance(settle, Settings):
        raise DiagramInputError("{settle} must be an opa.dynamics Settings record or None, "
                                "got {0!r}", settle)
    given = sorted(k for k in _LEGACY["settle"] if k in legacy)
    if given:
        raise DiagramInputError("{settle}: give " + ", ".join(given) + " inside it, not "
                                "beside it")
    return settle.transient, settle.record


def _emr_keywords(emr, legacy: dict) -> tuple:
    """(emr, emr_order) of ``emr`` (False, True or an :class:`EMR`) and the keyword
    ``emr_order`` of earlier releases."""
    if isinstance(emr, EMR):
        if "emr_order" in legacy:
            raise DiagramInputError("{emr}: give emr_order inside EMR(...), not beside it")
        return True, emr.order
    return emr, legacy.get("emr_order")


def _check_inputs(oscillator, parameter, values, *, sigma, uncertain, distribution, samples,
                  seed, options, transient, record, xtol, extra_states, coexist, emr,
                  emr_order, workers, scheduler, parts, log) -> DiagramInputs:
    """:func:`check_diagram` on the keywords of every input, one part after the other."""
    oscillator, system, values, measure, sigma, xtol = _check_model(
        oscillator, parameter, values, sigma, uncertain, distribution, xtol)
    samples, seed, settings, extra_states, coexist = _check_sampling(
        samples, seed, transient, record, extra_states, coexist)
    if system.dimension > 1:
        _check_several_sampling(samples, emr, system)
    emr, emr_order = _check_emr(emr, emr_order, measure, values, system)
    execution = _check_execution(workers, scheduler, parts, log, values)
    if options is None:
        options = SolverOptions()
    elif not isinstance(options, SolverOptions):
        raise DiagramInputError("{options} must be an opa.SolverOptions or None, got {0!r}",
                                options)
    _check_work(len(values), samples, extra_states, coexist, settings.transient,
                settings.record, continued=system.dimension == 1)
    _check_memory(len(values), samples, settings.transient, settings.record, settings.check,
                  min(execution.workers, len(values)))
    oscillators = _check_spans(oscillator, parameter, values, settings, emr)
    return DiagramInputs(
        oscillator=oscillator, parameter=parameter, values=values,
        oscillators=tuple(oscillators), sigma=sigma, uncertain=uncertain, measure=measure,
        system=system, samples=samples, seed=seed, options=options, settings=settings,
        xtol=xtol, extra_states=extra_states, coexist=coexist, emr=emr, emr_order=emr_order,
        execution=execution)


def _check_model(oscillator, parameter, values, sigma, uncertain, distribution, xtol):
    """The model, the control parameter and its values, the uncertainty and its law."""
    from opa._measure import parse

    given = oscillator
    if isinstance(oscillator, System):
        oscillator = oscillator.oscillator
    if not isinstance(oscillator, Oscillator):
        raise DiagramInputError("{oscillator} must be an opa.Oscillator or System, got {0}",
                                type(oscillator).__name__)
    names = _several(uncertain)
    if "omega" in (names or (uncertain,)):
        raise DiagramInputError(OMEGA_REFUSED, "omega")
    if names:
        return _check_several(given, oscillator, parameter, values, sigma, names,
                              distribution, xtol)
    if not (isinstance(uncertain, str) and uncertain in oscillator.uncertain_names):
        raise DiagramInputError("{uncertain} must be one of {0}, got {1!r}",
                                ", ".join(oscillator.uncertain_names), uncertain)
    if isinstance(given, System) and (given.uncertain != uncertain or given.sigma != sigma):
        raise DiagramInputError(
            "{oscillator}: the System's uncertainty ({0}, sigma {1:g}) is not the diagram's "
            "({uncertain} {2}, {sigma} {3!r}): pass its .oscillator, or the same", given.uncertain,
            given.sigma, uncertain, sigma)
    if not (isinstance(parameter, str) and parameter in oscillator.sweepable_names) \
            or parameter in (uncertain, "x0", "v0"):
        raise DiagramInputError("{parameter} must be a model parameter other than the "
                                "uncertain one ({0}) and x0, v0, got {1!r}", uncertain,
                                parameter)
    values = _values(values)
    if isinstance(sigma, (bool, np.bool_)) or not (
            isinstance(sigma, numbers.Real) and math.isfinite(sigma) and sigma > 0):
        raise DiagramInputError("{sigma} must be a positive number, got {0!r}", sigma)
    sigma = float(sigma)
    if isinstance(xtol, (bool, np.bool_)) or not (
            isinstance(xtol, numbers.Real) and XTOL_RANGE[0] <= xtol <= XTOL_RANGE[1]):
        raise DiagramInputError("{xtol} (the boundaries' tolerance in xi) must be a "
                                "number in [{0:g}, {1:g}], got {2!r}", *XTOL_RANGE, xtol)
    xtol = float(xtol)
    try:
        measure = parse(distribution)
    except ValueError as err:
        raise _named("distribution", err, distribution) from None
    _check_spread(oscillator, uncertain, sigma, measure, xtol)
    system = System(oscillator, sigma=sigma, uncertain=uncertain, distribution=distribution)
    return oscillator, system, values, measure, sigma, xtol


def _several(uncertain) -> tuple | None:
    """The names of several uncertain parameters (``"mu,c"`` or a sequence of two or
    more), else None (one parameter, or something the one-parameter checks refuse)."""
    if isinstance(uncertain, str):
        names = tuple(n.strip() for n in uncertain.split(","))
    elif isinstance(uncertain, (tuple, list)):
        names = tuple(uncertain)
    else:
        return None
    return names if len(names) > 1 else None


def _check_several(given, oscillator, parameter, values, sigma, names, distribution, xtol):
    """:func:`_check_model` of several uncertain parameters: the problem (its refusals
    name ``sigma``, ``uncertain`` or ``distribution``), the control parameter and values;
    ``xtol`` has no effect (no boundaries are located). The measure is None."""

    if isinstance(given, System) and (tuple(given.uncertain), given.sigma) != (names, sigma):
        raise DiagramInputError(
            "{oscillator}: the System's uncertainty ({0}) is not the diagram's ({uncertain} "
            "{1}): pass its .oscillator, or the same", _quoted(",".join(given.uncertain)),
            _quoted(",".join(map(str, names))))
    try:
        system = (given.replace(order=0) if isinstance(given, System) else
                  System(oscillator, sigma=sigma, uncertain=names, distribution=distribution,
                         order=0))
    except ValueError as err:
        text = " ".join(str(err).split())
        raise _named(next((k for k in ("uncertain", "distribution") if text.startswith(k)),
                          "sigma"), err) from None
    if any(s <= 0 for s in system.problem.scales):
        raise DiagramInputError("{sigma} must be positive for each uncertain parameter, got "
                                "{0}", _quoted(",".join(f"{s:g}" for s in system.sigma)))
    for name, scale, (lo, _) in zip(names, system.sigma, system.problem.support):
        mean = oscillator.value(name)
        if mean + scale * lo < 0.0 <= mean and not system.allow_negative:
            raise DiagramInputError(
                "{sigma} {0:g} makes {1} = {2:g} + sigma xi negative for xi below {3:.3g} "
                "(the law of xi reaches {4:g}); at most {5:.6g} keeps it >= 0", scale, name,
                mean, -mean / scale, lo, mean / -lo if lo < 0 else math.inf)
    if not (isinstance(parameter, str) and parameter in oscillator.sweepable_names) \
            or parameter in (*names, "x0", "v0"):
        raise DiagramInputError("{parameter} must be a model parameter other than the "
                                "uncertain ones ({0}) and x0, v0, got {1!r}",
                                _quoted(",".join(names)), parameter)
    if xtol != 1e-10:  # not the default: stochastic_diagram's
        raise DiagramInputError("{xtol} {0!r} has no effect with {1} uncertain parameters: "
                                "no boundaries are located (continuation in xi is "
                                "one-dimensional by nature)", xtol, len(names))
    return oscillator, system, _values(values), None, tuple(system.sigma), float(xtol)


def _check_several_sampling(samples, emr, system) -> None:
    """Several uncertain parameters: the samples are whole scramblings, and the EMR (a
    sweep of one uncertain parameter) is refused."""
    d, names = system.dimension, ",".join(system.uncertain)
    if emr:
        raise DiagramInputError("{emr}: the EMR's sweep takes one uncertain parameter; "
                                "this diagram has {0} ({1})", d, names)
    if samples < 2 * SCRAMBLINGS or samples % SCRAMBLINGS:
        raise DiagramInputError(
            "{samples} must be a multiple of {0} and at least {1} with {2} uncertain "
            "parameters ({3} independent scramblings of Sobol' points give the standard "
            "errors; no boundaries are located, so the samples are the probabilities), "
            "got {4!r}", SCRAMBLINGS, 2 * SCRAMBLINGS, d, SCRAMBLINGS, samples)


def _check_sampling(samples, seed, transient, record, extra_states, coexist):
    """The Monte Carlo samples and seed, the classification's runs, the other states."""
    if isinstance(samples, (bool, np.bool_)) or not isinstance(samples, (int, np.integer)) \
            or samples < 0 or samples == 1:
        raise DiagramInputError("{samples} must be 0 or an integer >= 2, got {0!r}", samples)
    samples = int(samples)
    seed = _whole("seed", seed, 0)
    if seed and not samples:
        raise DiagramInputError("{seed} {0} has no effect with {samples} 0 (no Monte Carlo "
                                "samples are drawn)", seed)
    transient = _whole("transient", transient, 1)
    if isinstance(record, (bool, np.bool_)) or not isinstance(record, (int, np.integer)) \
            or record < 4:
        raise DiagramInputError("{record} must be >= 4 periods (an integer: periods up to "
                                "record / 2 are found), got {0!r}", record)
    settings = Settings(transient=transient, record=int(record))
    extra_states = _whole("extra_states", extra_states, 0, MAX_EXTRA_STATES,
                          " (other initial states on a circle of radius 1)")
    if coexist is None:
        return samples, seed, settings, extra_states, min(COEXIST_SAMPLES, samples)
    coexist = _whole("coexist", coexist, 0)
    if not extra_states:
        raise DiagramInputError("{coexist} {0} has no effect with {extra_states} 0 (no "
                                "other initial states)", coexist)
    if not samples:
        raise DiagramInputError("{coexist} {0} has no effect with {samples} 0 (no "
                                "samples to classify again)", coexist)
    if coexist > samples:
        raise DiagramInputError("{coexist} {0} is more than the {samples} {1}: only "
                                "samples can be classified again", coexist, samples)
    return samples, seed, settings, extra_states, coexist


def _check_emr(emr, emr_order, measure, values, system) -> tuple[bool, int]:
    """The EMR beside the diagram: whether, and its order."""
    if not isinstance(emr, (bool, np.bool_)):
        raise DiagramInputError("{emr} must be True or False, got {0!r}", emr)
    emr = bool(emr)
    if not emr and emr_order is not None:
        raise DiagramInputError("{emr_order} {0!r} has no effect without {emr}", emr_order)
    emr_order = 4 if emr_order is None else _whole("emr_order", emr_order, 1)
    if emr:
        if measure.name != "semicircle":
            raise DiagramInputError("{emr}: the EMR is the paper's OPA system, whose sweeps "
                                    "use the semicircle law, not {0}", measure.name)
        if np.any(np.diff(values) <= 0):
            raise DiagramInputError("{values} must increase with {emr} (the EMR's sweep "
                                    "goes up the control parameter)")
        try:
            system.replace(order=emr_order)
        except ValueError as err:
            raise _named("emr_order", err, emr_order) from None
    return emr, emr_order


def _check_execution(workers, scheduler, parts, log, values) -> Execution:
    """Where the control values run, where they are kept, and the log."""
    workers = _whole("workers", workers, 1)
    if scheduler is not None:
        if workers != 1:
            raise DiagramInputError("{workers} {0} has no effect with {scheduler} (the "
                                    "control values run there as tasks)", workers)
        if not (isinstance(scheduler, str) and scheduler.strip()
                or type(scheduler).__name__ == "Client"):
            raise DiagramInputError("{scheduler} must be a Dask scheduler address such as "
                                    "tcp://host:8786 or a distributed.Client, got {0!r}",
                                    scheduler)
        if isinstance(scheduler, str):
            from opa._model import check_scheduler_address

            try:  # nothing is contacted yet: the address must read as one
                check_scheduler_address(scheduler)
            except ValueError as err:
                raise _named("scheduler", err, scheduler) from None
    elif workers > 1 and len(values) == 1:
        raise DiagramInputError("{workers} {0} has no effect with one control value (the "
                                "values are shared out among the workers)", workers)
    if parts is not None and not (isinstance(parts, (str, os.PathLike))
                                  and os.fspath(parts).strip()):
        raise DiagramInputError("{parts} must be a folder's path or None, got {0!r}", parts)
    if log is not None and not callable(log):
        raise DiagramInputError("{log} must be a callable taking one line, or None, got "
                                "{0!r}", log)
    return Execution(workers=workers, scheduler=scheduler, checkpoint=parts, log=log,
                     progress=False)


def _check_spans(oscillator, parameter, values, settings, emr) -> list:
    """The oscillator at each control value, each run's span checked."""
    from opa._model import check_span

    transient, record = settings.transient, settings.record
    oscillators = []
    for v in values:
        try:
            oscillators.append(oscillator.replace(**{parameter: float(v)}))
        except ValueError as err:
            raise _at_value(parameter, v, err) from None
    for v, osc in _span_checked(parameter, values, oscillators):
        try:
            check_span(osc, osc.forcing_period)
        except ValueError as err:
            raise _at_value(parameter, v, err) from None
        try:
            check_span(osc, (transient + record) * osc.forcing_period)
        except ValueError as err:
            raise DiagramInputError("{transient} + {record} ({0} + {1}) periods at {2} = "
                                    "{3:g}: " + _quoted(err), transient, record, parameter,
                                    v) from None
        if emr:
            try:
                check_span(osc, (EMR_TRANSIENT + EMR_RECORD) * osc.forcing_period)
            except ValueError as err:
                raise DiagramInputError("{emr} (its sweep runs {0} + {1} periods) at {2} = "
                                        "{3:g}: " + _quoted(err), EMR_TRANSIENT, EMR_RECORD,
                                        parameter, v) from None
    return oscillators


#: the execution keywords the diagram took before :class:`opa.Execution` (still taken)
_EXECUTION_KEYWORDS = ("workers", "scheduler", "parts", "log")


def _execution_keywords(execution, legacy: dict) -> tuple:
    """(workers, scheduler, parts, log) of an ``execution`` (its checkpoint is the parts
    folder) or of the keywords of earlier releases; unknown keywords are a TypeError as
    for any function."""
    unknown = sorted(set(legacy) - set(_EXECUTION_KEYWORDS))
    if unknown:
        raise TypeError(f"stochastic_diagram() got an unexpected keyword argument "
                        f"{unknown[0]!r}")
    if execution is None:
        return (legacy.get("workers", 1), legacy.get("scheduler"), legacy.get("parts"),
                legacy.get("log"))
    if not isinstance(execution, Execution):
        raise DiagramInputError("{execution} must be an opa.Execution or None, got {0!r}",
                                execution)
    if legacy:
        raise DiagramInputError("{execution}: give " + ", ".join(sorted(legacy)) +
                                " inside it, not beside it")
    execution.only("stochastic_diagram", "workers", "scheduler", "checkpoint")
    return execution.workers, execution.scheduler, execution.checkpoint, execution.log


def _at_value(parameter: str, value: float, err: Exception) -> DiagramInputError:
    """A control value refused (by the model's checks, or the run's span)."""
    return DiagramInputError("{values}: at {0} = {1:g}, " + _quoted(" ".join(str(err).split())),
                             parameter, value)


def _values(values) -> np.ndarray:
    """The control values: a non-empty 1-D array of distinct finite real numbers."""
    try:
        array = np.asarray(values)
    except (TypeError, ValueError):
        array = np.asarray([None])
    if array.dtype.kind not in "iuf" or array.ndim != 1 or not len(array) \
            or not np.isfinite(array).all():
        raise DiagramInputError("{values} must be a non-empty 1-D array of finite numbers, "
                                "got {0}", _quoted(f"{values!r:.60}"))
    array = array.astype(float)
    if len(np.unique(array)) != len(array):
        raise DiagramInputError("{values} must be distinct, got {0}",
                                _quoted(f"{values!r:.60}"))
    return array


def _span_checked(parameter, values, oscillators):
    """The (value, oscillator) pairs whose forcing and impulse periods differ: each for
    a parameter they depend on, else the first."""
    pairs = list(zip(values, oscillators))
    return pairs if parameter in ("omega", "omega1", "f", "F0") else pairs[:1]


def _check_spread(oscillator, uncertain: str, sigma: float, measure, xtol: float) -> None:
    """Refuse a sigma whose samples ``p_bar + sigma xi`` leave the uncertain parameter's
    range (negative, or beyond the floats) or that double precision cannot resolve."""
    mean = oscillator.value(uncertain)
    lowest, highest = mean + sigma * measure.lo, mean + sigma * measure.hi
    if not (math.isfinite(lowest) and math.isfinite(highest)):
        raise DiagramInputError("{sigma} {0:g} takes {1} = {2:g} + sigma xi beyond the "
                                "floating-point range", sigma, uncertain, mean)
    if lowest < 0.0 == mean:
        raise DiagramInputError("{sigma} {0:g} makes {1} = 0 + sigma xi negative for every xi "
                                "below 0: no sigma keeps it >= 0 (make {1} positive)", sigma,
                                uncertain)
    if lowest < 0.0 < mean:
        raise DiagramInputError(
            "{sigma} {0:g} makes {1} = {2:g} + sigma xi negative for xi below {3:.3g} (the "
            "law of xi reaches {4:g}); at most {5:.6g} keeps it >= 0", sigma, uncertain,
            mean, -mean / sigma, measure.lo, mean / -measure.lo)
    spread = sigma * (measure.hi - measure.lo)
    if spread <= RESOLUTION * abs(mean) or sigma * xtol < TINY:
        raise DiagramInputError(
            "{sigma} {0:g} is below what double precision resolves around {1} = {2:g}: "
            "the samples {1} + sigma xi (and the boundaries, to xtol {3:g} in xi) would "
            "not differ", sigma, uncertain, mean, xtol)


def _check_work(count, samples, extra_states, coexist, transient, record, *,
                continued=True) -> None:
    """Refuse (``opa._work.WorkBudgetError``) a diagram beyond the work budget: at each
    value the grid, at least one interval's middle and the samples run from (x0, v0),
    the middle and the checked samples from each other state, each at most transient +
    record periods, and the continuation in xi (``CONTINUATION_PERIODS``)."""
    from opa._work import check_work

    others = extra_states * (1 + coexist)
    periods = count * ((GRID + 3 + samples + others) * (transient + record)
                       + CONTINUATION_PERIODS) if continued else \
        count * (samples + extra_states * coexist) * (transient + record)
    drivers = [("values", count)]
    if samples and samples >= others:
        drivers.append(("samples", samples))
    elif others:
        drivers.append(("extra_states", extra_states))
    check_work("this stochastic diagram", periods,
               drivers + [("transient + record", f"({transient} + {record})")])


def _check_memory(count, samples, transient, record, check, processes) -> None:
    """Refuse runs whose memory exceeds the budget: each run holds its stroboscopic
    points (x, v over transient + record periods) and a chunk's kernel output and event
    log (``settle_batch``; twice: its twin); the largest batch is the samples (or the
    grid) of a value, one per process at a time. The dataset holds every sample's
    points."""
    from opa._memory import check_memory

    chunk = max(check, record)
    per_run = 16 * (transient + record) + 2 * (24 * (16 * chunk + 64) + 16 * (chunk + 1)) \
        + 1024
    batch = max(samples, GRID + 2)
    try:
        check_memory("the batch", processes * batch * per_run,
                     f"{processes} x {batch} runs x {per_run} bytes")
    except ValueError as err:
        at_once = " in each of {workers} {2}" if processes > 1 else ""
        raise DiagramInputError("{samples} {0} runs at once" + at_once + ", each of "
                                "{transient} + {record} ({1}) periods: " + _quoted(err),
                                samples, f"{transient} + {record}", processes) from None
    try:
        check_memory("the dataset", count * max(samples, 1) * (POINTS * 8 + 96))
    except ValueError as err:
        raise DiagramInputError("{values} ({0}) x {samples} {1}: " + _quoted(err), count,
                                samples) from None


def stochastic_diagram(oscillator: Oscillator | System, parameter: str, values, *,
                       samples: int = 1024, seed: int = 0,
                       options: SolverOptions | None = None, settle: Settings | None = None,
                       xtol: float = 1e-10, extra_states: int = EXTRA_STATES,
                       coexist: int | None = None, emr: bool | EMR = False,
                       execution: Execution | None = None, **legacy):
    """Attractor types and their probabilities along ``parameter`` (module docstring).

    Parameters
    ----------
    oscillator : an :class:`opa.System`: the deterministic model and the uncertainty ``p
        = p_bar + sigma xi`` with the law of xi; or an :class:`opa.Oscillator` with the
        keywords ``sigma``, ``uncertain`` (default mu) and ``distribution`` (default the
        semicircle).
    parameter : the control parameter swept over ``values`` (not the uncertain one).
    samples, seed : Monte Carlo samples classified at each value (0: none).
    settle : how a run is classified (:class:`opa.dynamics._attractor.Settings`): the
        longest run, ``transient`` periods, before a type is decided from its last
        ``record`` periods (a run stops as soon as it has settled); default 1000 and 64,
        also given as the keywords ``transient`` and ``record``.
    xtol : tolerance of the located boundaries in xi.
    extra_states, coexist : other initial states (``initial_states``; at most
        ``MAX_EXTRA_STATES``), and how many of the samples are classified from them too
        (the interval middles always are; default 64, or all the samples if fewer; at
        most ``samples``, and only with samples and other states).
    emr : also sweep the EMR (:class:`EMR`: the OPA system of its ``order``, at the same
        sigma, semicircle law only: the paper's diagrams) over the increasing values, 500
        transient and 100 recorded periods from the paper's start, for the figure;
        ``True`` is ``EMR()`` (order 4, or the keyword ``emr_order``).
    Every input is checked before any work (:func:`check_diagram`): a ValueError names the
    keyword that is wrong, of the wrong type, out of range or without effect in the
    combination (``seed`` without samples, ``emr_order`` without ``emr``), or a sigma
    that makes the uncertain parameter negative for some xi or that double precision
    cannot resolve; a diagram beyond the work budget (``opa._work``) or the memory budget
    is refused naming the inputs its cost grows with.
    execution : how the control values run (:class:`opa.Execution`): ``workers``
        processes share the control values out (1 with a ``scheduler``, and with one
        value); ``scheduler``, a Dask scheduler address or ``distributed.Client``: the
        control values (and the EMR sweep) run there as tasks instead, each with one
        numba thread, and the result is the same to the bit; ``checkpoint``, a folder
        where each finished control value is kept as it finishes, a
        :class:`opa._dataset.Store` keyed by everything the value depends on: a rerun with
        the same folder reads them back instead of computing them again (an interrupted
        diagram resumes), and a damaged file (unreadable, or edited since it was written:
        each part carries the digest of its content) is set aside, named (``log``, else a
        warning) and computed again; the folder is locked while the diagram runs (another
        process writing it is refused: ValueError naming it); None: nothing is kept;
        ``log``, a callable taking a progress line, or None. The keywords ``workers``,
        ``scheduler``, ``parts`` (the checkpoint) and ``log`` are still taken on their
        own, as before.

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
    Without samples, a value where continuation cannot follow has the law mass of the
    types at the interval middles as its probabilities (``method_note`` says so).

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
    checked = check_diagram(
        oscillator, parameter, values, samples=samples, seed=seed, options=options,
        settle=settle, xtol=xtol, extra_states=extra_states, coexist=coexist, emr=emr,
        execution=execution, **legacy)
    run = checked.execution
    with contextlib.ExitStack() as held:
        # the scheduler answers before the parts folder is made: a refusal leaves nothing
        client = None
        if run.scheduler is not None:
            client, own = _connect(run.scheduler, run.connect_timeout)
            if own:
                held.callback(client.close)
        store = _parts_store(run)
        if store is not None:
            held.callback(store.close)
        if checked.system.dimension > 1:
            run.say(f"{_skipped(checked.system)}: the probabilities are the shares of "
                    f"{checked.samples} sampled systems at each value")
            ds = _dataset_several(_slices(checked, store, client), checked)
            return ds
        slices = _slices(checked, store, client)
        ds = _dataset(slices, checked.parameter, checked.values, checked.system,
                      checked.options, checked.measure, checked.settings, checked.seed,
                      checked.samples, checked.xtol, checked.extra_states, checked.coexist)
        if checked.emr:
            ds = _with_emr(ds, checked, client)
        return ds


def _parts_store(run: Execution):
    """The store of the diagram's parts (``run.checkpoint``), locked until the diagram
    is assembled, or None."""
    from opa._dataset import Store

    if run.checkpoint is None:
        return None
    try:
        return Store(run.checkpoint, "stochastic diagram", log=run.log, lock=True)
    except (ValueError, OSError) as err:
        raise _named("parts", err, os.fspath(run.checkpoint)) from None


def _slices(checked: DiagramInputs, store, client) -> list[dict]:
    """Every control value's slice, in order: read back from ``store`` or computed here,
    on local processes or on ``client``'s cluster (each kept as it finishes)."""
    from opa._dataset import package_version

    run, parameter = checked.execution, checked.parameter
    tasks = _tasks(checked)

    def inputs(task):
        return {"task": repr(task), "version": package_version()}

    def name(task):
        return f"slice-{parameter}{task.value:g}"

    results, todo = {}, []
    for i, task in enumerate(tasks):
        found = None if store is None else store.load(name(task), inputs(task))
        if found is not None:
            results[i] = found
            _log(run.log, i, len(tasks), parameter, found, reused=True)
        else:
            todo.append(i)

    def finish(i, piece):
        if store is not None:
            store.save(name(tasks[i]), inputs(tasks[i]), piece)
            piece = store.load(name(tasks[i]), inputs(tasks[i]))  # as a rerun reads it
        results[i] = piece
        _log(run.log, i, len(tasks), parameter, piece, reused=False)

    if todo and run.log is not None:
        # a value can take minutes: say at once what is being computed (issue 45, item 5)
        where = ("on the Dask cluster" if client is not None else
                 f"on {min(run.workers, len(todo))} worker process"
                 f"{'es' if min(run.workers, len(todo)) > 1 else ''}")
        run.log(f"computing {len(todo)} of {len(tasks)} values of {parameter} "
                f"({checked.samples} samples each) {where}; a line as each is done")
    if client is not None and todo:
        _run_slices_dask(tasks, todo, finish, client, run)
    else:
        _run_slices(tasks, todo, finish, run.workers)
    return [results[i] for i in range(len(tasks))]


def _tasks(checked: DiagramInputs) -> list:
    """Each control value's task: with one uncertain parameter its own seed (seed + i),
    with several the same sample points at every value (one seed)."""
    if checked.system.dimension > 1:
        return [SampledTask(value=float(v), oscillator=osc, problem=checked.system.problem,
                            samples=checked.samples, seed=checked.seed,
                            options=checked.options, settings=checked.settings,
                            extra_states=checked.extra_states, coexist=checked.coexist)
                for v, osc in zip(checked.values, checked.oscillators)]
    return [SliceTask(value=float(v), oscillator=osc, uncertain=checked.uncertain,
                      sigma=checked.sigma, distribution=checked.measure.name,
                      samples=checked.samples, seed=checked.seed + i,
                      options=checked.options, settings=checked.settings,
                      xtol=checked.xtol, extra_states=checked.extra_states,
                      coexist=checked.coexist)
            for i, (v, osc) in enumerate(zip(checked.values, checked.oscillators))]


def _with_emr(ds, checked: DiagramInputs, client):
    """``ds`` with the EMR's stroboscopic points over the same values (``emr_x``)."""
    from opa.dynamics._sweep import Window, sweep

    run, order, values = checked.execution, checked.emr_order, checked.values
    run.say(f"the EMR (OPA N = {order}, sigma = {checked.sigma:g}) over {len(values)} "
            f"values of {checked.parameter}")
    opa = sweep("opa", checked.parameter, values, checked.system.replace(order=order),
                window=Window(transient=EMR_TRANSIENT, record=EMR_RECORD),
                options=checked.options, locate=False,
                execution=run.replace(scheduler=client, log=None, checkpoint=None))
    ds["emr_x"] = ((checked.parameter, "emr_point"), opa.section_x.values, {
        "long_name": f"stroboscopic x_0 of the EMR (OPA N = {order}) after "
        f"{EMR_TRANSIENT} periods, {EMR_RECORD} recorded", "units": "1"})
    ds.attrs.update(emr_order=int(order), emr_transient=EMR_TRANSIENT,
                    emr_record=EMR_RECORD)
    return ds


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
    from opa._run import set_threads

    set_threads(1)
    return compute_slice(task)


def _connect(scheduler, timeout: float):
    """(a distributed.Client, whether it is ours to close) for ``scheduler``, an address
    or a Client, by the one connection rule (:func:`opa._execution.connect_scheduler`: the
    address is checked before anything is contacted, and must answer as a Dask scheduler
    within its timeout); a refusal names the keyword."""
    from opa._execution import connect_scheduler

    try:
        return connect_scheduler(scheduler, timeout)
    except ValueError as err:
        raise _named("scheduler", err, scheduler) from None


def _run_slices_dask(tasks, todo, finish, client, run: Execution) -> None:
    """Compute the control values ``todo`` as tasks on a Dask cluster (``client``)."""
    futures = {client.submit(_single_threaded_slice, tasks[i], pure=False): i for i in todo}
    watchdog = run.watchdog(client, lambda: len(futures), "control values")
    try:
        for future in watchdog.finished(list(futures)):
            i = futures.pop(future)
            finish(i, watchdog.result(future, f"the control value {tasks[i].value:g}"))
    finally:
        client.cancel(list(futures))


def _log(log, i, count, parameter, piece, *, reused) -> None:
    if log is None:
        return
    shown = ", ".join(f"{k} {p:.3f}" for k, p in sorted(_probabilities(piece).items(),
                                                         key=lambda kp: type_order(kp[0]))
                      if p >= 0.005) or "(every type below 0.005)"
    how = ("continuation" if not int(piece["method"]) else "sampling"
           if len(np.atleast_1d(piece["mc_type"])) else "interval middles, no samples")
    log(f"{i + 1}/{count} {parameter} = {float(piece['value']):g}: {shown} ({how}; "
        f"{float(piece['cpu_seconds']):.1f} s CPU{', read back' if reused else ''})")


def _probabilities(piece) -> dict:
    """type -> probability of one slice: continuation, or Monte Carlo when sampled; with
    no samples to fall back on, the law mass of the intervals' types (the types at their
    middles, whatever they are: the intervals cover the support, so these sum to 1)."""
    if int(piece["method"]) and len(np.atleast_1d(piece["mc_type"])) \
            or not len(piece["prob_type"]):
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


def _skipped(system) -> str:
    """Why a diagram of several uncertain parameters locates no boundaries."""
    return (f"boundaries not located: continuation in xi is one-dimensional by nature, and "
            f"this diagram has {system.dimension} uncertain parameters "
            f"({','.join(system.uncertain)})")


def _scrambling_sem(types: np.ndarray, kinds) -> np.ndarray:
    """Each type's standard error from the shares of the ``SCRAMBLINGS`` blocks of
    ``types`` (one control value's samples, block after block): sd / sqrt(R)."""
    blocks = np.asarray(types).reshape(SCRAMBLINGS, -1)
    shares = np.array([(blocks == k).mean(axis=1) for k in kinds]).reshape(len(kinds), -1)
    return shares.std(axis=1, ddof=1) / math.sqrt(SCRAMBLINGS)


def _dataset_several(slices, checked: DiagramInputs):
    """The dataset of several uncertain parameters: the Monte Carlo part's variables
    (``probability`` is ``mc_probability``), ``mc_xi`` over (sample, parameter)."""
    import xarray as xr

    from opa._dataset import provenance_attrs

    param, system, settings = checked.parameter, checked.system, checked.settings
    shares = [_shares(s) for s in slices]
    kinds = sorted({k for m in shares for k in m}, key=type_order)
    P = np.array([[m.get(k, 0.0) for k in kinds] for m in shares]).reshape(len(slices), -1)
    types = np.stack([np.asarray(s["mc_type"]).astype(str) for s in slices])
    sem = np.array([_scrambling_sem(t, kinds) for t in types]).reshape(P.shape)
    points = np.stack([s["mc_points"] for s in slices])
    one, dims_s = {"units": "1"}, (param, "sample")
    checked_samples = min(checked.coexist, checked.samples)
    per = checked.samples // SCRAMBLINGS
    data = {
        "probability": ((param, "type"), P, {
            "long_name": "probability of each attractor type (share of the sampled "
            "systems: no boundaries with several uncertain parameters)", **one}),
        "mc_probability": ((param, "type"), P, {
            "long_name": "share of the Monte Carlo samples on each type", **one}),
        "mc_sem": ((param, "type"), sem, {
            "long_name": f"standard error of the share: spread of the shares of "
            f"{SCRAMBLINGS} independent scramblings of Sobol' points ({per} each), "
            f"sd / sqrt({SCRAMBLINGS})", **one}),
        "agree": (param, np.full(len(slices), -1, dtype=np.int8), {
            "long_name": "-1: no continuation to compare the samples with", **one}),
        "method": (param, np.ones(len(slices), dtype=np.int8),
                   {"long_name": "0: continuation in xi; 1: Monte Carlo sampling", **one}),
        "method_note": (param, np.array([str(s["note"]) for s in slices], dtype=str),
                        {"long_name": "why continuation could not follow (empty: it did)"}),
        "mc_coexist": (param, np.array(
            [float(np.mean(s["mc_coexist"])) if checked_samples else np.nan
             for s in slices]), {
            "long_name": f"share of the first {checked_samples} samples whose type depends "
            "on the initial state", **one}),
        "mc_xi": (("sample", "parameter"), np.asarray(slices[0]["mc_xi"], dtype=float), {
            "long_name": "xi of each sample (the same points at every control value)",
            **one}),
        "mc_type": (dims_s, types, {
            "long_name": "attractor type of each sample from (x0, v0)"}),
        "mc_lyapunov": (dims_s, np.stack([s["mc_lyapunov"] for s in slices]), {
            "long_name": "largest Lyapunov exponent per unit time (two-trajectory "
            "estimate; NaN where the run settled on a period first)", **one}),
        "mc_periods": (dims_s, np.stack([s["mc_periods"] for s in slices]), {
            "long_name": "forcing periods integrated before the type was decided", **one}),
        "mc_settled": (dims_s, np.stack([s["mc_settled"] for s in slices]), {
            "long_name": "1 where the run stopped early (settled on a period, or chaotic); "
            "0 where its type was read off the last record periods", **one}),
        "mc_x": ((*dims_s, "point"), points[..., 0], {
            "long_name": "stroboscopic x of the sample's attractor (NaN padded)", **one}),
        "mc_v": ((*dims_s, "point"), points[..., 1], {
            "long_name": "stroboscopic dx/dt of the sample's attractor", **one}),
    }
    ds = xr.Dataset(data, coords={
        param: (param, checked.values, {"long_name": f"control parameter {param}", **one}),
        "type": ("type", np.array(kinds, dtype=str), {"long_name": "attractor type"}),
        "parameter": ("parameter", np.array(system.uncertain, dtype=str),
                      {"long_name": "uncertain parameter"})},
        attrs=provenance_attrs("stochastic", system, checked.options, seed=checked.seed,
                               sampler="sobol"))
    ds.attrs[param] = math.nan  # swept: its values are the coordinate
    ds.attrs.update(sweep_parameter=param, samples=int(checked.samples),
                    scramblings=SCRAMBLINGS, boundaries=_skipped(system),
                    transient=int(settings.transient), record=int(settings.record),
                    settle_tol=float(settings.settle_tol),
                    chaos_threshold=float(settings.chaos_threshold),
                    lyapunov_periods=int(settings.lyapunov_periods),
                    extra_states=int(checked.extra_states),
                    coexist_samples=int(checked_samples))
    return ds


def type_order(kind: str):
    """Sort key of attractor types: periodic labels by period and impacts, then the rest
    in the order of ``NON_PERIODIC``."""
    if "/" in kind:
        n, p = kind.split("/")
        return (0, int(n), int(p) if p.isdigit() else -1, "")
    return (1, NON_PERIODIC.index(kind) if kind in NON_PERIODIC else 99, 0, kind)


__all__ = ["AGREEMENT_SE", "DiagramInputError", "DiagramInputs", "EMR", "MAX_EXTRA_STATES",
           "SCRAMBLINGS", "SampledTask", "SliceTask", "attractors", "check_diagram",
           "classify", "compute_slice", "stochastic_diagram", "stochastic_slice",
           "type_order"]
