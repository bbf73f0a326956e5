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
from dataclasses import dataclass, field

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
# an event's kind as a number (its index here): what the vectorised comparisons compare
_KIND_NAMES = np.array([_IMPACT, _STICK, _RELEASE])
# the kernel's event kinds (opa._run.Events) as those numbers; -1: none of them
_KIND_OF_EVENT = np.full(max(Events.IMPACT, Events.GRAZE, Events.KICK, Events.STICK,
                             Events.RELEASE) + 1, -1, np.int8)
_KIND_OF_EVENT[[Events.IMPACT, Events.GRAZE, Events.KICK]] = 0
_KIND_OF_EVENT[Events.STICK] = 1
_KIND_OF_EVENT[Events.RELEASE] = 2


@dataclass(frozen=True)
class EventSequence:
    """The events of one deterministic run, in order: time, velocity, kind, interval.

    Derived (not compared): ``codes``, each kind as a number (0 impact, 1 stick, 2
    release), and ``keys``, each event's kind and interval as one number
    (:meth:`key`).
    """

    time: np.ndarray
    velocity: np.ndarray
    kind: tuple[str, ...]  # "I" impact (graze included), "S" stick, "R" release
    interval: np.ndarray  # index j of the impulse interval [j T1, (j+1) T1) of the event
    codes: np.ndarray = field(init=False, compare=False, repr=False)
    keys: np.ndarray = field(init=False, compare=False, repr=False)

    def __post_init__(self):
        names = np.array(list(self.kind), dtype=str)
        codes = np.full(len(names), -1, np.int8)
        for code, name in enumerate(_KIND_NAMES):
            codes[names == name] = code
        if (codes < 0).any():
            raise ValueError(f"event kinds must be 'I', 'S' or 'R', got {self.kind!r}")
        object.__setattr__(self, "codes", codes)
        object.__setattr__(self, "keys", _keys(self.interval, codes))

    @classmethod
    def _decoded(cls, time, velocity, kind, interval, codes, keys) -> EventSequence:
        """A sequence whose derived fields are known (decoded from the kernel's log)."""
        sequence = object.__new__(cls)
        for name, value in (("time", time), ("velocity", velocity), ("kind", kind),
                            ("interval", interval), ("codes", codes), ("keys", keys)):
            object.__setattr__(sequence, name, value)
        return sequence

    def _end(self, horizon: float) -> int:
        return int(np.searchsorted(self.time, horizon, side="right"))

    def signature(self, horizon: float) -> tuple:
        """What must not change for x(t, xi) to stay smooth on [0, horizon]."""
        n = self._end(horizon)
        return tuple(zip(self.kind[:n], self.interval[:n].tolist()))

    def key(self, horizon: float) -> np.ndarray:
        """:meth:`signature` as one integer per event (kind and impulse interval): two runs
        have the same signature exactly when their keys are equal."""
        return self.keys[:self._end(horizon)]

    def same_as(self, other: "EventSequence", horizon: float, slack: float) -> bool:
        """Whether x(t, p) can be continuous between the two runs on [0, horizon]: the same
        events in the same impulse intervals, each at nearly the same time (within
        ``slack``). A jump of an event time means that the events in between changed, e.g.
        a new grazing impact that moves every later impact, with the count unchanged."""
        mine, theirs = self.key(horizon), other.key(horizon)
        if len(mine) != len(theirs) or not np.array_equal(mine, theirs):
            return False
        n = len(mine)
        return bool(np.all(np.abs(self.time[:n] - other.time[:n]) <= slack))

    def slowest_impact(self, horizon: float) -> tuple[float, float]:
        """Speed and time of the slowest impact up to ``horizon`` (NaN, NaN if none)."""
        n = self._end(horizon)
        idx = np.flatnonzero(self.codes[:n] == 0).tolist()
        if not idx:
            return math.nan, math.nan
        i = min(idx, key=lambda j: abs(self.velocity[j]))
        return float(abs(self.velocity[i])), float(self.time[i])

    def count(self, horizon: float) -> int:
        """Impacts (grazes included) up to ``horizon``."""
        return int(np.count_nonzero(self.codes[:self._end(horizon)] == 0))


def event_sequence(system: System | Oscillator, options: SolverOptions,
                   t_end: float) -> EventSequence:
    """Run the deterministic system to ``t_end`` and return its events."""
    system = as_system(system, options, several=True).deterministic()
    rec = run(system.kernel_inputs(options), system.initial_state(), np.array([0.0, t_end]),
              rtol=options.rtol, atol=options.atol, label="sampled system")
    return _sequence(system, rec.events)


def event_sequences(system: System | Oscillator, options: SolverOptions, parameter: str,
                    values, t_end: float) -> list[EventSequence]:
    """The event sequences of the sampled systems with ``parameter`` at each of ``values``
    (absolute values), run in parallel by the compiled kernel."""
    system = as_system(system, options, several=True).deterministic()
    values = np.asarray(values, dtype=float)
    if parameter not in ("mu", "a", "c"):  # not a kernel-side uncertain parameter
        return [event_sequence(system.replace(**{parameter: float(v)}), options, t_end)
                for v in values]
    batch = run_batch(system.replace(uncertain=parameter).sampled_inputs(options, values=values),
                      system.initial_state(), np.array([0.0, t_end]), rtol=options.rtol,
                      atol=options.atol, capacity=256)
    ok = batch.ok
    whole = [m for m in range(len(values)) if ok[m] and batch.log_complete(m)]
    # decoded together; mu, a and c leave the impulse schedule alone: the system's
    # intervals hold
    logs = [batch.log(m) for m in whole]
    made = dict(zip(whole, _sequences(system, Events.of(np.concatenate(logs) if logs else
                                                        np.empty((0, 3))),
                                      [len(log) for log in logs])))
    return [made[m] if m in made else  # else the single run raises or has room
            event_sequence(system.replace(**{parameter: float(value)}), options, t_end)
            for m, value in enumerate(values)]


def _sequence(system: System, events: Events) -> EventSequence:
    return _sequences(system, events, [len(events)])[0]


def _keys(interval, codes) -> np.ndarray:
    return np.asarray(interval, dtype=np.int64) * len(_KIND_NAMES) + codes


def _sequences(system: System, events: Events, lengths: list[int]) -> list[EventSequence]:
    """The event sequences of several runs whose events are ``events``, one run after the
    other (``lengths`` each), decoded together: each sequence holds its part of one
    array."""
    kinds = np.asarray(events.kind, dtype=np.intp)
    known = (kinds >= 0) & (kinds < len(_KIND_OF_EVENT))
    codes = np.where(known, _KIND_OF_EVENT[np.where(known, kinds, 0)], -1).astype(np.int8)
    if (codes < 0).any():
        raise ValueError(f"unknown event kinds {sorted(set(kinds[codes < 0].tolist()))}")
    time, velocity = events.time, events.velocity
    interval = system.impulse_interval(time)
    keys = _keys(interval, codes)
    names = _KIND_NAMES[codes].tolist()
    ends = np.cumsum(lengths, dtype=np.int64).tolist()
    return [EventSequence._decoded(time[a:b], velocity[a:b], tuple(names[a:b]), interval[a:b],
                                   codes[a:b], keys[a:b]) for a, b in zip([0] + ends[:-1], ends)]


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


def _first_difference(a: EventSequence, b: EventSequence, n: int, slack: float) -> int:
    """The first of the first ``n`` events where the two runs differ (kind, interval, or
    time by more than ``slack``); ``n`` where none does."""
    same = ((a.codes[:n] == b.codes[:n]) & (a.interval[:n] == b.interval[:n])
            & (np.abs(a.time[:n] - b.time[:n]) <= slack))
    return int(np.argmin(same)) if not same.all() else n


def _classify_events(a: EventSequence, b: EventSequence, horizon: float, period: float):
    # events on the two sides of a located split correspond one to one, at nearly equal
    # times, up to the first one that differs; "nearly" is a hundredth of a period
    slack = TIME_SLACK * period
    na = int(np.searchsorted(a.time, horizon, side="right"))
    nb = int(np.searchsorted(b.time, horizon, side="right"))
    i = _first_difference(a, b, min(na, nb), slack)
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


# -- the scan ------------------------------------------------------------------------------
@dataclass(frozen=True)
class ScanOptions:
    """How :func:`scan_splits` scans, bisects and stops (its docstring says what each does).

    ``scan``: the equally spaced values run first (>= 2); ``tol``: the bracket length at
    which a bisection stops; ``max_splits``: the limit, the most splits located;
    ``min_splits``: the splits located before an early stop; ``max_crossings``: the most
    output crossings located; ``center``: where brackets are counted nearest from (None:
    the middle of the interval); ``order``: ``"nearest"`` or ``"generation"``;
    ``needed_within``: the radii the list is asked to be complete within (a radius,
    several, or None), kept increasing and without repeats.

    >>> ScanOptions(needed_within=(0.03, 0.01, 0.03)).needed_within
    (0.01, 0.03)
    """

    scan: int = 129
    tol: float = 1e-8
    max_splits: int = MAX_SPLITS
    min_splits: int = MIN_SPLITS
    max_crossings: int = MAX_CROSSINGS
    center: float | None = None
    order: str = "nearest"
    needed_within: tuple[float, ...] = ()

    def __post_init__(self):
        scan, tol = self.scan, self.tol
        if not (isinstance(scan, numbers.Integral) and scan >= 2):
            raise ValueError(f"scan must be an integer >= 2, got {scan!r}")
        if isinstance(tol, bool) or not (isinstance(tol, numbers.Real) and tol > 0
                                         and math.isfinite(tol)):
            raise ValueError(f"tol must be a finite number > 0, got {tol!r}")
        for name, least in (("max_splits", 1), ("max_crossings", 1), ("min_splits", 0)):
            value = getattr(self, name)
            if not (isinstance(value, numbers.Integral) and not isinstance(value, bool)
                    and value >= least):
                raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")
        needed = () if self.needed_within is None else np.atleast_1d(self.needed_within)
        if not all(isinstance(r, numbers.Real) and not isinstance(r, (bool, np.bool_))
                   and r > 0 for r in needed):
            raise ValueError(f"needed_within must be a radius > 0, several, or None, got "
                             f"{self.needed_within!r}")
        object.__setattr__(self, "needed_within", tuple(sorted({float(r) for r in needed})))
        if self.order not in ("nearest", "generation"):
            raise ValueError(f"order must be 'nearest' or 'generation', got {self.order!r}")


class SampledRuns:
    """The deterministic runs of the sampled systems, one per value of ``parameter``, kept
    for every scan that reads them: the scans of several horizons share them.

    New runs go to ``t_end``. A kept run serves every scan whose ``t_end`` it reaches,
    and :meth:`until` gives the same runs with new ones to another end: a shorter
    horizon's scan reads the longer runs already made and bisects with runs to its own
    end. (A value whose kept run is too short for the end asked is run again, and the
    longer run kept.)
    """

    def __init__(self, system: System | Oscillator, options: SolverOptions, parameter: str,
                 t_end: float):
        self.system = as_system(system, options, several=True).deterministic()
        self.options = options
        self.parameter = parameter
        self.t_end = _end_time(t_end)
        self._kept: dict[float, tuple[float, EventSequence]] = {}

    def until(self, t_end: float) -> SampledRuns:
        """The same runs (shared, not copied), new ones to ``t_end``."""
        view = object.__new__(SampledRuns)
        view.__dict__.update(self.__dict__, t_end=_end_time(t_end))
        return view

    def _serves(self, value: float) -> bool:
        kept = self._kept.get(value)
        return kept is not None and kept[0] >= self.t_end

    def ensure(self, values) -> None:
        """Run every value without a kept run to ``t_end``, in one parallel batch."""
        todo = sorted({float(v) for v in values if not self._serves(float(v))})
        if todo:
            made = event_sequences(self.system, self.options, self.parameter, todo, self.t_end)
            for v, sequence in zip(todo, made):
                self._kept[v] = (self.t_end, sequence)

    def __getitem__(self, value: float) -> EventSequence:
        """The kept run at ``value`` (:meth:`ensure` it first)."""
        return self._kept[value][1]

    def get(self, value: float, default=None):
        """The kept run at ``value`` if it reaches ``t_end``, else ``default``."""
        return self._kept[value][1] if self._serves(float(value)) else default

    def values(self, lo: float, hi: float) -> list[float]:
        """The values in [lo, hi] with a kept run to ``t_end``, in the order they were run."""
        return [v for v, (end, _) in self._kept.items() if lo <= v <= hi and end >= self.t_end]


def _end_time(t_end) -> float:
    if isinstance(t_end, bool) or not (isinstance(t_end, numbers.Real) and math.isfinite(t_end)
                                       and t_end > 0):
        raise ValueError(f"t_end must be a positive number, got {t_end!r}")
    return float(t_end)


def _distance(a, b, center: float) -> np.ndarray:
    """How far each bracket [a, b] is from ``center`` (0 where it holds it)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return np.where((a <= center) & (center <= b), 0.0,
                    np.minimum(np.abs(a - center), np.abs(b - center)))


class _Rows:
    """What a scan at one horizon compares of each run, kept per value: its events up to
    the horizon, their keys (:meth:`EventSequence.key`) and times; and the comparisons of
    many pairs of runs at once, on one flat table of their events."""

    def __init__(self, runs: SampledRuns, horizon: float, slack: float):
        self._runs, self._horizon, self._slack = runs, horizon, slack
        self._rows: dict[float, tuple[int, np.ndarray, np.ndarray]] = {}

    def _load(self, x: float) -> tuple[int, np.ndarray, np.ndarray]:
        sequence = self._runs[x]
        n = int(np.searchsorted(sequence.time, self._horizon, side="right"))
        row = self._rows[x] = n, sequence.keys[:n], sequence.time[:n]
        return row

    def table(self, values) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The events up to the horizon of the runs at ``values``, one after the other:
        (events of each run, where each run's start in the table, keys, times)."""
        rows = list(map(self._rows.get, values))
        if None in rows:
            rows = [row or self._load(x) for x, row in zip(values, rows)]
        n = np.array([row[0] for row in rows], dtype=np.int64)
        if not rows:
            return n, n, np.empty(0, np.int64), np.empty(0)
        return (n, np.cumsum(n) - n, np.concatenate([row[1] for row in rows]),
                np.concatenate([row[2] for row in rows]))

    def pairs(self, table, ix, iy, times: bool = True) -> np.ndarray:
        """For each pair of the table's runs ix[k], iy[k], whether they differ: other events
        (another count, kind or impulse interval) or, with ``times``, an event time that
        jumps by more than the slack."""
        n, start, keys, when = table
        out = n[ix] != n[iy]
        owner, within = _spread(np.where(out, 0, n[ix]))
        px, py = start[ix][owner] + within, start[iy][owner] + within
        bad = keys[px] != keys[py]
        if times:
            bad |= ~(np.abs(when[px] - when[py]) <= self._slack)
        out |= np.bincount(owner[bad], minlength=len(out)) > 0
        return out

    def differ(self, xs, ys) -> np.ndarray:
        """For each pair, whether the runs at xs[k] and ys[k] are on two sides of a split:
        not :meth:`EventSequence.same_as` (other events, or an event time that jumps)."""
        k = np.arange(len(xs))
        return self.pairs(self.table([*xs, *ys]), k, k + len(xs))

    def neighbours(self, values) -> np.ndarray:
        """:meth:`differ` of each value and the next."""
        k = np.arange(len(values) - 1)
        return self.pairs(self.table(values), k, k + 1)

    def halves(self, a, m, b) -> tuple[np.ndarray, np.ndarray]:
        """For each bracket [a, b] and its midpoint m: :meth:`differ` (m, a), (m, b)."""
        k = np.arange(len(m))
        table = self.table([*m, *a, *b])
        return self.pairs(table, k, k + len(m)), self.pairs(table, k, k + 2 * len(m))

    def certain(self, xs, ys) -> np.ndarray:
        """For each pair, whether the two runs' signatures differ (a split between them
        for certain)."""
        k = np.arange(len(xs))
        return self.pairs(self.table([*xs, *ys]), k, k + len(xs), times=False)


def _spread(count) -> tuple[np.ndarray, np.ndarray]:
    """For items with ``count`` entries each: each entry's item and its index within it
    (items in order, entries in order within each)."""
    count = np.asarray(count, dtype=np.int64)
    owner = np.repeat(np.arange(len(count)), count)
    return owner, np.arange(len(owner)) - (np.cumsum(count) - count)[owner]


class SplitScanner:
    """One scan of :func:`scan_splits` (its arguments checked there), in named steps:

    - :meth:`scan`: the equally spaced runs and the brackets between neighbours that
      differ;
    - :meth:`bisect`: one level of the bisection of some brackets (their midpoints, one
      parallel batch of runs);
    - :meth:`wave`: the nearest brackets bisected down to ``tol`` together, and the splits
      they hold located;
    - :meth:`look_ahead`: whether the list can still become complete within a radius;
    - :meth:`stop`: whether to stop before the next wave (the early stop);
    - :meth:`crossings`: the output crossings between neighbouring runs.

    :meth:`run` takes them in turn. The scanner owns what it compares of each run at its
    horizon; the runs are ``runs``' (shared with other scans).
    """

    def __init__(self, runs: SampledRuns, lo: float, hi: float, horizon: float,
                 settings: ScanOptions, outputs: np.ndarray | None = None):
        self.runs, self.lo, self.hi, self.horizon = runs, lo, hi, horizon
        self.settings, self.outputs = settings, outputs
        self.center = 0.5 * (lo + hi) if settings.center is None else float(settings.center)
        self.period = runs.system.oscillator.forcing_period
        self.rows = _Rows(runs, horizon, TIME_SLACK * self.period)
        # (generation, a, b): the scan's brackets are generation 0; a bracket set aside
        # when a third sequence turns up inside another is one generation later
        self.pending: list[tuple[int, float, float]] = []
        self.splits: list[Split] = []
        # the look-ahead's brackets, with ends of different signatures, inside the
        # brackets left over (kept from one look-ahead to the next)
        self.ahead = (np.empty(0), np.empty(0))
        self.hopeless = self.stopped_early = False

    def run(self) -> SplitScan:
        """The scan, the waves until the limit, the list is complete or the early stop,
        then the output crossings."""
        s = self.settings
        self.scan()
        while self.pending and len(self.splits) < s.max_splits:
            if self.stop():
                self.stopped_early = True
                break
            self.wave()
        within = float(self._pending_distance().min()) if self.pending else math.inf
        self.splits.sort(key=lambda sp: sp.value)
        crossings, crossings_within = [], within
        if self.outputs is not None and len(self.outputs):
            crossings, crossings_within = self.crossings(within)
        return SplitScan(self.splits, crossings, bool(self.pending), within, crossings_within,
                         s.max_splits, self.stopped_early, s.needed_within)

    def scan(self) -> None:
        """Run the equally spaced values; a bracket between each two neighbours that
        differ."""
        values = [float(v) for v in np.linspace(self.lo, self.hi, self.settings.scan)]
        self.runs.ensure(values)
        split = self.rows.neighbours(values)
        self.pending = [(0, values[k], values[k + 1]) for k in np.flatnonzero(split)]

    def bisect(self, a: np.ndarray, b: np.ndarray):
        """One level below the brackets [a, b]: their midpoints m (run in one parallel
        batch), and for each whether its lower half [a, m] and its upper half [m, b] hold
        a change. One of them does; both where m has a third sequence."""
        m = 0.5 * (a + b)
        self.runs.ensure(m)
        lower, other = self.rows.halves(a, m, b)
        return m, lower, ~lower | other

    def wave(self) -> None:
        """The nearest brackets (``WAVE`` of them; with ``order="generation"`` every one of
        the oldest generation, up to the limit) bisected together down to ``tol``, a
        parallel batch per level; a third sequence's farther half waits in ``pending``
        one generation later. Then each bracket whose ends still differ is a split."""
        s, c = self.settings, self.center
        left = s.max_splits - len(self.splits)
        if s.order == "generation":
            order = np.lexsort((self._pending_distance(), [br[0] for br in self.pending]))
            size = left
        else:
            order = np.argsort(self._pending_distance(), kind="stable")
            size = min(WAVE, left)
        self.pending = [self.pending[k] for k in order]
        wave, self.pending = self.pending[:size], self.pending[size:]
        gen = np.array([br[0] for br in wave])
        a, b = np.array([br[1] for br in wave]), np.array([br[2] for br in wave])
        while True:
            open_ = np.flatnonzero(b - a > s.tol)
            if not open_.size:
                break
            ao, bo = a[open_], b[open_]
            m, lower, upper = self.bisect(ao, bo)
            # the nearer half stays in the wave (the lower one where they are as near)
            upper_kept = upper & ~(lower & (_distance(ao, m, c) <= _distance(m, bo, c)))
            for k in np.flatnonzero(lower & upper):
                far = (ao[k], m[k]) if upper_kept[k] else (m[k], bo[k])
                self.pending.append((int(gen[open_[k]]) + 1, float(far[0]), float(far[1])))
            a[open_], b[open_] = np.where(upper_kept, m, ao), np.where(upper_kept, bo, m)
        for k in np.flatnonzero(self.rows.differ(a, b)):  # else event times that moved
            self.splits.append(self._split(float(a[k]), float(b[k])))  # fast: no split

    def _split(self, a: float, b: float) -> Split:
        sa, sb = self.runs[a], self.runs[b]
        kind, t, v = _classify(sa, sb, self.horizon, self.period)
        return Split(0.5 * (a + b), b - a, kind, t, v, sa.count(self.horizon),
                     sb.count(self.horizon))

    def _pending_distance(self) -> np.ndarray:
        return _distance([br[1] for br in self.pending], [br[2] for br in self.pending],
                         self.center)

    def stop(self) -> bool:
        """Whether to stop before the next wave: once the smallest radius of
        ``needed_within`` that the list is not yet complete within cannot be reached by
        ``max_splits`` (:meth:`look_ahead`; asked until it says so once), as soon as
        ``min_splits`` splits are located."""
        s = self.settings
        if s.needed_within and not self.hopeless:
            within = self._pending_distance().min()
            aim = next((r for r in s.needed_within if r > within), None)
            self.hopeless = aim is not None and not self.look_ahead(aim)
        return self.hopeless and len(self.splits) >= s.min_splits

    def look_ahead(self, r: float) -> bool:
        """Whether the list can still become complete within r by ``max_splits``: bisects
        the brackets owed within r (:func:`_owed`), breadth first (a level per parallel
        batch), until they exceed the splits left or are all shorter than ``tol``."""
        s, c = self.settings, self.center
        while True:
            ax, ay = self.ahead = _owed(self.pending, self.ahead, self.center, r,
                                        self.rows.certain)
            whole = np.count_nonzero(np.maximum(np.abs(ax - c), np.abs(ay - c)) < r)
            if len(self.splits) + whole > s.max_splits:
                return False
            opening = (ay - ax > s.tol) & (_distance(ax, ay, c) < r)
            if not opening.any():
                return True
            m, lower, upper = self.bisect(ax[opening], ay[opening])
            # each bracket becomes its halves with a change, the lower one first (or stays
            # as it is where it was not opened): two slots per bracket, the second (m, y)
            o = np.flatnonzero(opening)
            fx, fy, sx = np.array(ax), np.array(ay), np.zeros(len(ax))
            fx[o], fy[o], sx[o] = np.where(lower, ax[o], m), np.where(lower, m, ay[o]), m
            second = np.zeros(len(ax), bool)
            second[o] = lower & upper
            keep = np.stack([np.ones(len(ax), bool), second], axis=1).ravel()
            xs = np.stack([fx, sx], axis=1).ravel()[keep]
            ys = np.stack([fy, ay], axis=1).ravel()[keep]
            certain = self.rows.certain(xs, ys)
            self.ahead = xs[certain], ys[certain]

    def crossings(self, within: float) -> tuple[list[Split], float]:
        """The crossings of output times by impact times between neighbouring runs with
        the same events within ``within`` of the centre (see :func:`scan_splits`), nearest
        to the centre first, and the radius the list is complete within."""
        c, tol = self.center, self.settings.tol
        points = sorted(v for v in self.runs.values(self.lo, self.hi) if abs(v - c) <= within)
        a, b, i, tj, sign = _crossing_brackets(self.rows, points, self.outputs, c)
        radius = within
        if len(a) > self.settings.max_crossings:
            radius = min(radius, float(_distance(a, b, c)[self.settings.max_crossings]))
            a, b, i, tj, sign = (x[:self.settings.max_crossings] for x in (a, b, i, tj, sign))
        while len(a):
            open_ = np.flatnonzero(b - a > tol)
            if not open_.size:
                break
            m = 0.5 * (a[open_] + b[open_])
            self.runs.ensure(m)
            # a change the scan did not see: give that crossing up
            lost = np.logical_or(*self.rows.halves(a[open_], m, b[open_]))
            go, m = open_[~lost], m[~lost]
            t = np.array([self.runs[x].time[k] for x, k in zip(m.tolist(), i[go].tolist())])
            below = np.copysign(1.0, t - tj[go]) == sign[go]
            a[go], b[go] = np.where(below, m, a[go]), np.where(below, b[go], m)
            keep = np.ones(len(a), bool)
            keep[open_[lost]] = False
            a, b, i, tj, sign = (x[keep] for x in (a, b, i, tj, sign))
        out = []
        for x, y, k, t in zip(a.tolist(), b.tolist(), i.tolist(), tj.tolist()):
            sx, sy = self.runs[x], self.runs[y]
            speed = 0.5 * (abs(sx.velocity[k]) + abs(sy.velocity[k]))
            n = sx.count(self.horizon)
            out.append(Split(0.5 * (x + y), y - x, "output crossing", t, float(speed), n, n))
        out.sort(key=lambda sp: sp.value)
        return out, radius


def _owed(pending, ahead, center: float, r: float, certain) -> tuple[np.ndarray, np.ndarray]:
    """The brackets a scan has yet to bisect to become complete within r, each of which
    yields a split: those of the look-ahead (``ahead``: arrays of their ends) inside the
    brackets left over (``pending``: (generation, a, b)) within r, and the brackets left
    over with none of them inside, where ``certain`` (their ends' signatures differ).
    Grouped by bracket left over, in increasing order; within one, in ``ahead``'s order."""
    pa = np.array([br[1] for br in pending], dtype=float)
    pb = np.array([br[2] for br in pending], dtype=float)
    inside = _distance(pa, pb, center) < r
    sa, sb = pa[inside], pb[inside]
    order = np.lexsort((sb, sa))
    sa, sb = sa[order], sb[order]
    fresh = np.ones(len(sa), bool)
    fresh[1:] = (sa[1:] != sa[:-1]) | (sb[1:] != sb[:-1])
    sa, sb = sa[fresh], sb[fresh]
    if not len(sa):
        return np.empty(0), np.empty(0)
    ax, ay = ahead
    span = np.searchsorted(sa, ax, side="right") - 1
    held = (span >= 0) & (ay <= sb[np.maximum(span, 0)])
    bare = np.flatnonzero(np.bincount(span[held], minlength=len(sa)) == 0)
    bare = bare[certain(sa[bare], sb[bare])]
    order = np.lexsort((np.concatenate([np.flatnonzero(held), np.zeros(len(bare), int)]),
                        np.concatenate([span[held], bare])))
    return (np.concatenate([ax[held], sa[bare]])[order],
            np.concatenate([ay[held], sb[bare]])[order])


def _crossing_brackets(rows: _Rows, points: list[float], outputs: np.ndarray, center: float):
    """Between each two neighbouring ``points`` (increasing) with the same events (then
    their impacts correspond one to one), each impact whose times on the two sides
    straddle output times: a bracket [a, b] per output time t_j strictly between them,
    with the impact's index i among the events, t_j and the sign of t_i(a) - t_j; nearest
    to ``center`` first (in the order pair, impact, output time among brackets as
    near)."""
    if len(points) < 2:
        return np.empty(0), np.empty(0), np.empty(0, int), np.empty(0), np.empty(0)
    table = rows.table(points)
    n, start, keys, when = table
    k = np.arange(len(points) - 1)
    pair = k[~rows.pairs(table, k, k + 1)]
    owner, i = _spread(n[pair])
    owner = pair[owner]
    px = start[owner] + i
    impact = keys[px] % len(_KIND_NAMES) == 0
    owner, i, px = owner[impact], i[impact], px[impact]
    tx, ty = when[px], when[start[owner + 1] + i]
    first = np.searchsorted(outputs, np.minimum(tx, ty), side="right")
    count = np.maximum(np.searchsorted(outputs, np.maximum(tx, ty), side="left") - first, 0)
    row, j = _spread(count)
    x, y = np.asarray(points)[owner[row]], np.asarray(points)[owner[row] + 1]
    tj = outputs[first[row] + j]
    order = np.argsort(_distance(x, y, center), kind="stable")
    return (x[order], y[order], i[row][order], tj[order],
            np.copysign(1.0, tx[row] - tj)[order])


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
    runs: SampledRuns | None = None,
    order: str = "nearest",
) -> tuple[list[Split], bool]:
    """The changes of the event sequence up to ``horizon`` for ``parameter`` in [lo, hi]
    and whether ``max_splits`` cut the list: :func:`scan_splits` without the output
    crossings (its ``splits`` and ``truncated``)."""
    settings = ScanOptions(scan=scan, tol=tol, max_splits=max_splits, center=center,
                           order=order)
    found = scan_splits(system, options, parameter, lo, hi, horizon, settings, runs=runs)
    return found.splits, found.truncated


def scan_splits(
    system: System | Oscillator,
    options: SolverOptions,
    parameter: str,
    lo: float,
    hi: float,
    horizon: float,
    settings: ScanOptions = ScanOptions(),
    *,
    runs: SampledRuns | None = None,
    outputs=None,
) -> SplitScan:
    """Every change of the event sequence up to ``horizon`` for ``parameter`` in [lo, hi],
    and (with ``outputs``, the output times) every value where an impact time crosses an
    output time. ``settings`` (:class:`ScanOptions`) says how the scan goes; the steps
    are :class:`SplitScanner`'s.

    The interval is scanned at ``settings.scan`` equally spaced values; each pair of
    neighbours whose sequences differ (:meth:`EventSequence.same_as`: other events, or an
    event time that jumps by more than ``TIME_SLACK`` forcing periods) is bisected (single
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

    ``runs`` (:class:`SampledRuns` of the same system, options and parameter) lets scans
    for several horizons share runs: new runs go to its ``t_end``, and a run to a later
    time serves a shorter horizon as well. Without it the scan's runs go to ``horizon``.
    """
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ValueError(f"need finite lo < hi, got [{lo}, {hi}]")
    if not isinstance(settings, ScanOptions):
        raise TypeError(f"settings must be a ScanOptions, got {type(settings).__name__}")
    system = as_system(system, options, several=True).deterministic()
    # a bracket cannot shrink below a few ulps of its ends: such a tol would bisect for
    # ever; above it the bisection takes at most log2((hi - lo) / tol) < 53 halvings
    reach = 4.0 * np.finfo(float).eps * max(abs(lo), abs(hi))
    if settings.tol < reach:
        raise ValueError(f"tol = {settings.tol:g} is below what doubles resolve near "
                         f"{parameter} = {max(abs(lo), abs(hi)):g}: use tol >= {reach:.3g}")
    if not (isinstance(horizon, numbers.Real) and math.isfinite(horizon) and horizon > 0):
        raise ValueError(f"horizon must be a positive number, got {horizon!r}")
    if outputs is not None:
        outputs = np.asarray(outputs, dtype=float).ravel()
        if not np.isfinite(outputs).all():
            raise ValueError("outputs must be finite times")
        outputs = np.unique(outputs[(outputs > 0.0) & (outputs < horizon)])
    if runs is None:
        runs = SampledRuns(system, options, parameter, horizon)
    elif (runs.system, runs.options, runs.parameter) != (system, options, parameter):
        raise ValueError("runs must be of the scan's system, solver options and parameter")
    if horizon > runs.t_end:
        raise ValueError(f"horizon {horizon} is past the cached runs' end {runs.t_end}")
    return SplitScanner(runs, lo, hi, horizon, settings, outputs).run()


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
           "SPLIT_KINDS", "SampledRuns", "ScanOptions", "Split", "SplitScan", "SplitScanner",
           "count_probabilities", "event_sequence", "event_sequences", "find_splits",
           "scan_splits"]
