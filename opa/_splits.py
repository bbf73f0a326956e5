"""Where the sampled systems' impact sequences split, and where x(t, xi) stops being smooth.

Every Monte Carlo sample is the deterministic impact oscillator with its own value of the
uncertain parameter ``p``. Its *event sequence* up to a horizon H is the list of its
impacts, stick and release events, each tagged with the impulse interval it falls in. Where
that sequence changes as ``p`` varies, x(t, xi) stops being smooth in xi for t past the
change, and a polynomial expansion in xi (OPA) cannot follow it.

:func:`find_splits` scans ``p`` over an interval with single deterministic runs, bisects
every change of the sequence to a given tolerance, and says what happens there:

``grazing``
    a new impact appears with a vanishing velocity (the trajectory touches the wall);
``extra impact``
    one side has an extra impact at a finite velocity (e.g. an impulse drives it into the
    wall);
``chatter``
    the sequences differ inside a chatter burst (at least ``CHATTER_BURST`` impacts within
    a tenth of a forcing period around the change) or in a sequence that ends in sticking;
``impulse order``
    an impact moves across an impulse time, so impact and kick change order;
``horizon``
    an event slides across the end of the horizon: the count within H changes but x(t, xi)
    stays continuous for t < H (not a discontinuity; kept to delimit impact counts);
``output crossing``
    (:func:`scan_splits` with output times) no change of the sequence, but an impact time
    crosses an output time t_j: x(t_j, xi) stays continuous in xi and has a kink there
    (one side is sampled just before the impact, the other just after it).

Near a grazing x(t, xi) is continuous too, with a square-root singularity: the new
impact's speed, and so the change it makes to x at later times, grows like
sqrt(|p - p_s|).

Because the samples at intensity sigma are the parameter values ``p_bar + sigma xi``, the
splits in ``p`` serve every sigma at once: at sigma the ensemble contains the split at
``p_s`` when ``|p_s - p_bar| < sigma``.
"""

from __future__ import annotations

import math
import numbers
from bisect import bisect_right
from dataclasses import dataclass

import numpy as np

from opa._model import Oscillator, SolverOptions
from opa._run import Events, run, run_batch
from opa._system import System, as_system

SPLIT_KINDS = ("grazing", "extra impact", "chatter", "impulse order", "horizon",
               "output crossing")
# The most splits one scan locates (and, apart, the most output crossings): past it the
# brackets left over are reported (SplitScan.truncated, complete_within), never dropped
# silently.
MAX_SPLITS = 1024
# Output crossings located per scan, nearest to the centre first: each costs a bisection
# of its own, and a cause needs only the nearest (the default map spent 18 s of its
# profile on a thousand of them over 50 periods); the radius they cover is reported.
MAX_CROSSINGS = 64
# The nearest splits a scan with needed_within keeps locating before it stops early (the
# limit before the complete split lists: a cause needs only the nearest).
MIN_SPLITS = 64
# Brackets bisected together in one wave of order="nearest" (one parallel batch of runs
# per level of the bisection).
WAVE = 16
# A new impact slower than this at the located split is a grazing (its velocity vanishes
# like sqrt(|p - p_s|); at the default tolerance it is ~1e-5). Named apart from the
# solver's graze flag, which marks single impacts.
SPLIT_GRAZE_SPEED = 1e-3
# Impacts within a tenth of a forcing period around a change that make it a chatter burst.
CHATTER_BURST = 4
# Half the width of that window, in forcing periods; the runs go this far past the horizon,
# so that a burst at the horizon is told from its impacts on both sides.
CHATTER_WINDOW = 0.05
# An extra event this close to the horizon's end slides across it (time units).
HORIZON_SLACK = 1e-4
# Two runs whose corresponding events are further apart in time than this share of a
# forcing period are on two sides of a split (also where the count is the same).
TIME_SLACK = 0.01

_IMPACT, _STICK, _RELEASE = "I", "S", "R"


@dataclass(frozen=True)
class EventSequence:
    """The events of one deterministic run, in order: time, velocity, kind, interval."""

    time: np.ndarray
    velocity: np.ndarray
    kind: tuple[str, ...]  # "I" impact (graze included), "S" stick, "R" release
    interval: np.ndarray  # index j of the impulse interval [j T1, (j+1) T1) of the event

    def signature(self, horizon: float) -> tuple:
        """What must not change for x(t, xi) to stay smooth on [0, horizon]."""
        n = int(np.searchsorted(self.time, horizon, side="right"))
        return tuple(zip(self.kind[:n], self.interval[:n].tolist()))

    def same_as(self, other: "EventSequence", horizon: float, slack: float) -> bool:
        """Whether x(t, p) can be continuous between the two runs on [0, horizon]: the same
        events in the same impulse intervals, each at nearly the same time (within
        ``slack``). A jump of an event time means that the events in between changed, e.g.
        a new grazing impact that moves every later impact, with the count unchanged."""
        if self.signature(horizon) != other.signature(horizon):
            return False
        n = int(np.searchsorted(self.time, horizon, side="right"))
        return bool(np.all(np.abs(self.time[:n] - other.time[:n]) <= slack))

    def slowest_impact(self, horizon: float) -> tuple[float, float]:
        """Speed and time of the slowest impact up to ``horizon`` (NaN, NaN if none)."""
        n = int(np.searchsorted(self.time, horizon, side="right"))
        idx = [i for i in range(n) if self.kind[i] == _IMPACT]
        if not idx:
            return math.nan, math.nan
        i = min(idx, key=lambda j: abs(self.velocity[j]))
        return float(abs(self.velocity[i])), float(self.time[i])

    def count(self, horizon: float) -> int:
        """Impacts (grazes included) up to ``horizon``."""
        n = int(np.searchsorted(self.time, horizon, side="right"))
        return sum(k == _IMPACT for k in self.kind[:n])


def event_sequence(system: System | Oscillator, options: SolverOptions,
                   t_end: float) -> EventSequence:
    """Run the deterministic system to ``t_end`` and return its events."""
    system = as_system(system, options).deterministic()
    rec = run(system.kernel_inputs(options), system.initial_state(), np.array([0.0, t_end]),
              rtol=options.rtol, atol=options.atol, label="sampled system")
    return _sequence(system, rec.events)


def event_sequences(system: System | Oscillator, options: SolverOptions, parameter: str,
                    values, t_end: float) -> list[EventSequence]:
    """The event sequences of the sampled systems with ``parameter`` at each of ``values``
    (absolute values), run in parallel by the compiled kernel."""
    system = as_system(system, options).deterministic()
    values = np.asarray(values, dtype=float)
    if parameter not in ("mu", "a", "c"):  # not a kernel-side uncertain parameter
        return [event_sequence(system.replace(**{parameter: float(v)}), options, t_end)
                for v in values]
    batch = run_batch(system.replace(uncertain=parameter).sampled_inputs(options, values=values),
                      system.initial_state(), np.array([0.0, t_end]), rtol=options.rtol,
                      atol=options.atol, capacity=256)
    out = []
    for m, value in enumerate(values):
        if not batch.ok[m] or not batch.log_complete(m):  # the single run raises or has room
            out.append(event_sequence(system.replace(**{parameter: float(value)}), options,
                                      t_end))
        else:  # mu, a and c leave the impulse schedule alone: the system's intervals hold
            out.append(_sequence(system, batch.events(m)))
    return out


def _sequence(system: System, events: Events) -> EventSequence:
    return EventSequence(events.time, events.velocity,
                         tuple(events.names(_IMPACT, _STICK, _RELEASE)),
                         system.impulse_interval(events.time))


@dataclass(frozen=True)
class Split:
    """A change of the event sequence at parameter value ``value`` (located within ``tol``).

    ``time``/``speed``: time and pre-impact speed of the first event that differs, taken
    on the side that has it; ``left``/``right``: impacts up to the horizon on each side.
    """

    value: float
    tol: float
    kind: str
    time: float
    speed: float
    left: int
    right: int


@dataclass(frozen=True)
class SplitScan:
    """What :func:`scan_splits` found over [lo, hi] up to one horizon.

    ``splits``: the changes of the event sequence, in increasing value; ``crossings``:
    the values where an impact time crosses an output time (kind ``"output crossing"``),
    in increasing value; ``truncated``: whether the limit ``limit`` left brackets
    unopened; ``complete_within``: every change with ``|p - center| < complete_within``
    is in ``splits`` (``inf``: every change the scan sees over [lo, hi]);
    ``crossings_within``: the same for ``crossings``; ``stopped_early``: whether the scan
    stopped before the limit because it could no longer become complete within the next
    radius of ``needed_within`` (the radii asked of it, increasing; empty: none asked).
    """

    splits: list[Split]
    crossings: list[Split]
    truncated: bool
    complete_within: float
    crossings_within: float
    limit: int
    stopped_early: bool = False
    needed_within: tuple[float, ...] = ()


def _burst(a: EventSequence, b: EventSequence, t: float, period: float) -> bool:
    near = [np.sum(np.abs(x.time - t) <= CHATTER_WINDOW * period) for x in (a, b)]
    return max(near) >= CHATTER_BURST


def _classify(a: EventSequence, b: EventSequence, horizon: float,
              period: float) -> tuple[str, float, float]:
    """Kind of the change between two neighbouring sequences, with the time and speed of
    the first differing event."""
    kind, t, v = _classify_events(a, b, horizon, period)
    if kind in ("grazing", "extra impact") and _burst(a, b, t, period):
        kind = "chatter"
    return kind, t, v


def _same(x: EventSequence, i: int, y: EventSequence, j: int, slack: float) -> bool:
    return (x.kind[i] == y.kind[j] and x.interval[i] == y.interval[j]
            and abs(x.time[i] - y.time[j]) <= slack)


def _classify_events(a: EventSequence, b: EventSequence, horizon: float, period: float):
    # events on the two sides of a located split correspond one to one, at nearly equal
    # times, up to the first one that differs; "nearly" is a hundredth of a period
    slack = TIME_SLACK * period
    na = int(np.searchsorted(a.time, horizon, side="right"))
    nb = int(np.searchsorted(b.time, horizon, side="right"))
    i = 0
    while i < min(na, nb) and _same(a, i, b, i, slack):
        i += 1
    if i >= min(na, nb):  # one is a prefix of the other: extra events at the end
        longer = a if na > nb else b
        t, v = float(longer.time[i]), float(longer.velocity[i])
        if horizon - t < HORIZON_SLACK:
            return "horizon", t, v
        if _STICK in a.kind[i:na] + b.kind[i:nb] or longer.kind[i] != _IMPACT:
            return "chatter", t, v
        return ("grazing" if abs(v) < SPLIT_GRAZE_SPEED else "extra impact"), t, v
    if _STICK in a.kind[i:na] + b.kind[i:nb]:
        return "chatter", float(min(a.time[i], b.time[i])), 0.0
    # an extra impact at i on one side, after which the other side's next event lines up
    for x, nx, y in ((a, na, b), (b, nb, a)):
        if x.kind[i] == _IMPACT and i + 1 < nx and _same(x, i + 1, y, i, slack):
            t, v = float(x.time[i]), float(x.velocity[i])
            return ("grazing" if abs(v) < SPLIT_GRAZE_SPEED else "extra impact"), t, v
    first = a if a.time[i] <= b.time[i] else b
    t, v = float(first.time[i]), float(first.velocity[i])
    if a.kind[i] == b.kind[i] == _IMPACT and a.interval[i] != b.interval[i]:
        return "impulse order", t, v
    return ("grazing" if abs(v) < SPLIT_GRAZE_SPEED else "extra impact"), t, v


def find_splits(
    system: System | Oscillator,
    options: SolverOptions,
    parameter: str,
    lo: float,
    hi: float,
    horizon: float,
    *,
    scan: int = 129,
    tol: float = 1e-8,
    max_splits: int = MAX_SPLITS,
    center: float | None = None,
    cache: dict | None = None,
    order: str = "nearest",
) -> tuple[list[Split], bool]:
    """The changes of the event sequence up to ``horizon`` for ``parameter`` in [lo, hi]
    and whether ``max_splits`` cut the list: :func:`scan_splits` without the output
    crossings (its ``splits`` and ``truncated``)."""
    found = scan_splits(system, options, parameter, lo, hi, horizon, scan=scan, tol=tol,
                        max_splits=max_splits, center=center, cache=cache, order=order)
    return found.splits, found.truncated


def scan_splits(
    system: System | Oscillator,
    options: SolverOptions,
    parameter: str,
    lo: float,
    hi: float,
    horizon: float,
    *,
    scan: int = 129,
    tol: float = 1e-8,
    max_splits: int = MAX_SPLITS,
    center: float | None = None,
    cache: dict | None = None,
    order: str = "nearest",
    outputs=None,
    max_crossings: int = MAX_CROSSINGS,
    needed_within=None,
    min_splits: int = MIN_SPLITS,
) -> SplitScan:
    """Every change of the event sequence up to ``horizon`` for ``parameter`` in [lo, hi],
    and (with ``outputs``, the output times) every value where an impact time crosses an
    output time.

    The interval is scanned at ``scan`` equally spaced values; each pair of neighbours
    whose sequences differ (:meth:`EventSequence.same_as`: other events, or an event time
    that jumps by more than ``TIME_SLACK`` forcing periods) is bisected (single
    deterministic runs) until the bracket is shorter than ``tol``; a third sequence met
    inside a bracket is followed as a split of its own. Changes between two scan points
    with equal sequences (an even number of them) are not seen; a bracket whose ends end
    up matching (fast but continuous event times) is dropped.

    **The limit.** Brackets are bisected nearest to ``center`` (default: the middle) first
    (``order="nearest"``, in waves of ``WAVE`` brackets), or (``order="generation"``) every
    scan bracket before any bracket found inside another, nearest first within a
    generation (a cascade of splits packed into one scan interval cannot then use up the
    limit before the other changes are seen). No bracket is opened once ``max_splits``
    splits are located; the brackets left over are the ones cut off, ``truncated`` says
    that some were, and ``complete_within`` is the distance from ``center`` of the nearest
    of them: every change of the scanned sequence with ``|p - center| <
    complete_within`` is in the list (``inf`` when nothing was cut off). With
    ``order="nearest"`` that radius is as large as the limit allows.

    **The early stop.** ``needed_within`` (a radius or several: the sigmas the list serves,
    as the ensemble at sigma is counted in full where ``complete_within >= sigma``) lets
    the scan stop before the limit where the limit would cut the list short of the radius
    anyway: once the smallest of these radii that the list is not yet complete within
    can no longer be reached by ``max_splits``, the scan stops before the next wave,
    though not before ``min_splits`` splits are located (the nearest, which the causes
    use). ``stopped_early`` says that it did; ``truncated`` and ``complete_within``
    report the brackets left over as above. The rule is exact, not a guess. A bracket
    whose ends have different signatures (:meth:`EventSequence.signature`) keeps a
    sub-bracket with different signatures at every level of its bisection, so it yields
    at least one split; if it lies wholly within the radius r of ``center``, so do its
    sub-brackets, and the scan must bisect them all to become complete within r. Before
    each wave the scan bisects such sub-brackets of the brackets left over within r
    breadth first, one level per parallel batch (runs it needs anyway if it is to become
    complete within r), and counts them; when the splits located plus these brackets
    exceed ``max_splits``, the scan without the early stop cannot become complete within r
    either. So the list is complete within every radius of ``needed_within`` that the
    scan without the early stop is complete within, and where it does not stop it is that
    scan. (Changes whose two sides differ only in event times, most of them over long
    horizons, are not counted: a bracket of those can come to nothing.)

    **Output crossings.** Between two neighbouring runs with the same events (no split
    between them) each impact time moves continuously with ``p``; where it passes an
    output time t_j (0 < t_j < horizon), x(t_j, p) has a kink in ``p`` (one side is
    before the impact, the other after it). Each such crossing seen between neighbouring
    runs within ``complete_within`` is bisected to ``tol`` on ``t_impact(p) - t_j`` and
    returned as a :class:`Split` of kind ``"output crossing"`` (``time``: the output time,
    ``speed``: the impact's speed there, ``left == right``: the impacts up to the
    horizon). At most ``max_crossings`` crossings, nearest to ``center`` first;
    ``crossings_within`` is the radius within which the crossing list is complete, as
    ``complete_within`` for the splits. As for splits, two crossings of one output time
    between neighbouring runs cancel and are not seen.

    ``cache`` (value -> EventSequence) lets calls for several horizons share runs: the
    runs go to ``cache["t_end"]`` (default: the first call's horizon), and a run to a
    later time serves a shorter horizon as well.
    """
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ValueError(f"need finite lo < hi, got [{lo}, {hi}]")
    system = as_system(system, options).deterministic()
    oscillator = system.oscillator
    if not (isinstance(scan, numbers.Integral) and scan >= 2):
        raise ValueError(f"scan must be an integer >= 2, got {scan!r}")
    if isinstance(tol, bool) or not (isinstance(tol, numbers.Real) and tol > 0
                                     and math.isfinite(tol)):
        raise ValueError(f"tol must be a finite number > 0, got {tol!r}")
    # a bracket cannot shrink below a few ulps of its ends: such a tol would bisect for
    # ever; above it the bisection takes at most log2((hi - lo) / tol) < 53 halvings
    reach = 4.0 * np.finfo(float).eps * max(abs(lo), abs(hi))
    if tol < reach:
        raise ValueError(f"tol = {tol:g} is below what doubles resolve near "
                         f"{parameter} = {max(abs(lo), abs(hi)):g}: use tol >= {reach:.3g}")
    if not (isinstance(max_splits, numbers.Integral) and not isinstance(max_splits, bool)
            and max_splits >= 1):
        raise ValueError(f"max_splits must be an integer >= 1, got {max_splits!r}")
    if not (isinstance(max_crossings, numbers.Integral)
            and not isinstance(max_crossings, bool) and max_crossings >= 1):
        raise ValueError(f"max_crossings must be an integer >= 1, got {max_crossings!r}")
    needed = () if needed_within is None else np.atleast_1d(needed_within)
    if not all(isinstance(r, numbers.Real) and not isinstance(r, (bool, np.bool_)) and r > 0
               for r in needed):
        raise ValueError(f"needed_within must be a radius > 0, several, or None, got "
                         f"{needed_within!r}")
    needed = tuple(sorted({float(r) for r in needed}))
    if not (isinstance(min_splits, numbers.Integral) and not isinstance(min_splits, bool)
            and min_splits >= 0):
        raise ValueError(f"min_splits must be an integer >= 0, got {min_splits!r}")
    if order not in ("nearest", "generation"):
        raise ValueError(f"order must be 'nearest' or 'generation', got {order!r}")
    if not (isinstance(horizon, numbers.Real) and math.isfinite(horizon) and horizon > 0):
        raise ValueError(f"horizon must be a positive number, got {horizon!r}")
    if outputs is not None:
        outputs = np.asarray(outputs, dtype=float).ravel()
        if not np.isfinite(outputs).all():
            raise ValueError("outputs must be finite times")
        outputs = np.unique(outputs[(outputs > 0.0) & (outputs < horizon)])
    cache = {} if cache is None else cache
    t_end = cache.setdefault("t_end", horizon)
    if horizon > t_end:
        raise ValueError(f"horizon {horizon} is past the cached runs' end {t_end}")

    def seq(value: float) -> EventSequence:
        return cache[value]

    def ensure(values) -> None:
        """Run every value not in the cache, in one parallel batch."""
        todo = sorted({float(v) for v in values if float(v) not in cache})
        if todo:
            for v, sq in zip(todo, event_sequences(system, options, parameter, todo, t_end)):
                cache[v] = sq

    slack = TIME_SLACK * oscillator.forcing_period
    # what EventSequence.same_as compares, per value: the signature up to the horizon
    # and the event times there (the look-ahead and the waves compare each run often)
    seen: dict[float, tuple[tuple, np.ndarray]] = {}

    def seen_at(x: float) -> tuple[tuple, np.ndarray]:
        if x not in seen:
            sq = seq(x)
            n = int(np.searchsorted(sq.time, horizon, side="right"))
            seen[x] = (sq.signature(horizon), sq.time[:n])
        return seen[x]

    def differ(x: float, y: float) -> bool:  # not seq(x).same_as(seq(y), horizon, slack)
        (sx, tx), (sy, ty) = seen_at(x), seen_at(y)
        return sx != sy or not bool(np.all(np.abs(tx - ty) <= slack))

    def bisect(a: float, b: float) -> list[tuple[float, float]]:
        """The brackets one bisection level below [a, b] (its midpoint run): the half
        with the change, or both halves where the midpoint has a third sequence."""
        m = 0.5 * (a + b)
        if not differ(m, a):
            return [(m, b)]
        if not differ(m, b):
            return [(a, m)]
        return [(a, m), (m, b)]

    values = [float(v) for v in np.linspace(lo, hi, scan)]
    ensure(values)
    # (generation, a, b): the scan's brackets are generation 0; a bracket set aside when
    # a third sequence turns up inside another is one generation later. The brackets of
    # one wave are bisected together, each level of the bisection one parallel batch of
    # runs.
    pending = [(0, x, y) for x, y in zip(values[:-1], values[1:]) if differ(x, y)]
    center = 0.5 * (lo + hi) if center is None else float(center)

    def distance(bracket):
        x, y = bracket[-2:]
        return 0.0 if x <= center <= y else min(abs(x - center), abs(y - center))

    # the early stop (see the docstring): the look-ahead's brackets, with ends of
    # different signatures, inside the brackets left over
    ahead: list[tuple[float, float]] = []

    def certain(x: float, y: float) -> bool:
        return seen_at(x)[0] != seen_at(y)[0]

    def owed(r: float) -> list[tuple[float, float]]:
        """Brackets the scan has yet to bisect to become complete within r, each of which
        yields a split: those of the look-ahead inside the brackets left over within r,
        and the brackets left over with none of them inside, where certain."""
        spans = sorted(br[1:] for br in pending if distance(br) < r)
        starts = [x for x, _ in spans]
        found: dict[tuple[float, float], list] = {span: [] for span in spans}
        for x, y in ahead:
            i = bisect_right(starts, x) - 1
            if i >= 0 and y <= spans[i][1]:
                found[spans[i]].append((x, y))
        return [node for span, nodes in found.items()
                for node in (nodes or ([span] if certain(*span) else []))]

    def reachable(r: float) -> bool:
        """Whether the list can still become complete within r by max_splits: bisects the
        look-ahead's brackets within r, breadth first (a level per parallel batch), until
        they exceed the splits left or are all shorter than tol."""
        nonlocal ahead
        while True:
            ahead = owed(r)
            whole = sum(max(abs(x - center), abs(y - center)) < r for x, y in ahead)
            if len(splits) + whole > max_splits:
                return False
            opening = {(x, y) for x, y in ahead if y - x > tol and distance((x, y)) < r}
            if not opening:
                return True
            ensure(0.5 * (x + y) for x, y in opening)
            ahead = [sub for node in ahead
                     for sub in (bisect(*node) if node in opening else [node])
                     if certain(*sub)]

    splits: list[Split] = []
    hopeless = stopped_early = False
    while pending and len(splits) < max_splits:
        if needed and not hopeless:
            within = min(distance(br) for br in pending)
            aim = next((r for r in needed if r > within), None)
            hopeless = aim is not None and not reachable(aim)
        if hopeless and len(splits) >= min_splits:
            stopped_early = True
            break
        if order == "generation":
            pending.sort(key=lambda br: (br[0], distance(br)))
            size = max_splits - len(splits)
        else:
            pending.sort(key=distance)
            size = min(WAVE, max_splits - len(splits))
        wave = [list(br) for br in pending[:size]]
        del pending[: len(wave)]
        while True:
            open_ = [br for br in wave if br[2] - br[1] > tol]
            if not open_:
                break
            ensure(0.5 * (br[1] + br[2]) for br in open_)
            for br in open_:
                halves = bisect(br[1], br[2])
                if len(halves) == 2:  # a third sequence: the nearer half stays in the wave
                    halves.sort(key=distance)
                    pending.append((br[0] + 1, *halves[1]))
                br[1:] = halves[0]
        for _, a, b in wave:
            if not differ(a, b):  # event times that moved fast, continuously: no split
                continue
            kind, t, v = _classify(seq(a), seq(b), horizon, oscillator.forcing_period)
            splits.append(Split(0.5 * (a + b), b - a, kind, t, v, seq(a).count(horizon),
                                seq(b).count(horizon)))
    within = min((distance(br) for br in pending), default=math.inf)
    splits.sort(key=lambda s: s.value)
    crossings, crossings_within = [], within
    if outputs is not None and len(outputs):
        crossings, crossings_within = _output_crossings(
            seq, ensure, differ, [v for v in cache if isinstance(v, float) and lo <= v <= hi],
            outputs, horizon, tol, center, within, max_crossings)
    return SplitScan(splits, crossings, bool(pending), within, crossings_within, max_splits,
                     stopped_early, needed)


def _output_crossings(seq, ensure, differ, points, outputs, horizon, tol, center, within,
                      limit) -> tuple[list[Split], float]:
    """The crossings of output times by impact times between neighbouring runs with the
    same events (see :func:`scan_splits`), nearest to ``center`` first."""
    points = sorted(v for v in points if abs(v - center) <= within)
    impacts: dict[float, np.ndarray] = {}

    def impacts_of(x: float) -> np.ndarray:
        """Indices of the impacts up to the horizon in the events of run x."""
        if x not in impacts:
            sq = seq(x)
            n = int(np.searchsorted(sq.time, horizon, side="right"))
            impacts[x] = np.flatnonzero([k == _IMPACT for k in sq.kind[:n]])
        return impacts[x]

    tasks = []  # [distance, a, b, impact index, output time, sign of t_i(a) - t_j]
    for x, y in zip(points[:-1], points[1:]):
        if differ(x, y):  # else the same events: the impacts correspond one to one
            continue
        idx = impacts_of(x)
        tx, ty = seq(x).time[idx], seq(y).time[idx]
        # the outputs strictly between the two times of each impact
        first = np.searchsorted(outputs, np.minimum(tx, ty), side="right")
        stop = np.searchsorted(outputs, np.maximum(tx, ty), side="left")
        for k in np.flatnonzero(stop > first):
            d = 0.0 if x <= center <= y else min(abs(x - center), abs(y - center))
            for tj in outputs[first[k]:stop[k]]:
                tasks.append([d, x, y, int(idx[k]), float(tj), math.copysign(1.0, tx[k] - tj)])
    tasks.sort(key=lambda task: task[0])
    radius = within
    if len(tasks) > limit:
        radius = min(radius, tasks[limit][0])
        tasks = tasks[:limit]
    out = []
    while tasks:
        open_ = [tk for tk in tasks if tk[2] - tk[1] > tol]
        if not open_:
            break
        ensure(0.5 * (tk[1] + tk[2]) for tk in open_)
        for tk in open_:
            _, a, b, i, tj, sign = tk
            m = 0.5 * (a + b)
            if differ(m, a) or differ(m, b):  # a change the scan did not see: give up
                tasks.remove(tk)
                continue
            if math.copysign(1.0, seq(m).time[i] - tj) == sign:
                tk[1] = m
            else:
                tk[2] = m
    for _, a, b, i, tj, _ in tasks:
        speed = 0.5 * (abs(seq(a).velocity[i]) + abs(seq(b).velocity[i]))
        n = seq(a).count(horizon)
        out.append(Split(0.5 * (a + b), b - a, "output crossing", tj, float(speed), n, n))
    out.sort(key=lambda s: s.value)
    return out, radius


def count_probabilities(splits, center: float, sigma: float, count_at_center: int, cdf,
                        complete_within: float = math.inf) -> tuple[dict[int, float], float]:
    """P(k impacts up to the horizon) for the ensemble ``center + sigma xi``, xi on
    [-1, 1] with the distribution function ``cdf``, from the located changes of the
    count (``splits``, each with the counts ``left``/``right`` on its two sides; output
    crossings, ``left == right``, change nothing).

    Exact where the split list is complete: only the part of the ensemble with
    ``|p - center| < complete_within`` is assigned a count; the mass beyond it is
    returned apart as ``unknown`` (0 when ``complete_within >= sigma``). Returns
    ``(probabilities, unknown)``.
    """
    for name, value in (("center", center), ("sigma", sigma)):
        if not (isinstance(value, numbers.Real) and math.isfinite(value)):
            raise ValueError(f"{name} must be a finite number, got {value!r}")
    if not sigma > 0:
        raise ValueError(f"sigma must be > 0, got {sigma!r}")
    if not (isinstance(complete_within, numbers.Real) and complete_within >= 0):
        raise ValueError(f"complete_within must be >= 0, got {complete_within!r}")
    reach = min(float(sigma), float(complete_within))
    if reach == 0.0:
        return {}, 1.0
    edge = reach / sigma
    inside = sorted((s for s in splits if abs(s.value - center) < reach),
                    key=lambda s: s.value)
    edges = [-edge] + [(s.value - center) / sigma for s in inside] + [edge]
    counts = [inside[0].left] + [s.right for s in inside] if inside else [count_at_center]
    prob: dict[int, float] = {}
    for lo, hi, n in zip(edges[:-1], edges[1:], counts):
        prob[int(n)] = prob.get(int(n), 0.0) + float(cdf(hi) - cdf(lo))
    unknown = 0.0 if edge >= 1.0 else float(1.0 - (cdf(edge) - cdf(-edge)))
    return prob, unknown


__all__ = ["CHATTER_WINDOW", "EventSequence", "MAX_CROSSINGS", "MAX_SPLITS", "MIN_SPLITS",
           "SPLIT_KINDS", "Split", "SplitScan", "count_probabilities", "event_sequence",
           "event_sequences", "find_splits", "scan_splits"]
