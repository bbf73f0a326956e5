"""The attractor one deterministic system settles on, classified as soon as it has settled.

Runs advance together in chunks of ``check`` forcing periods (``settle_batch``: one
parallel kernel call per chunk for the whole batch; ``record`` periods per chunk after
``4 record``); after each chunk the stroboscopic points of each run are examined and a run
leaves the batch once its type is known:

* **settled periodic**: the smallest p for which the points repeat,
  ``|s_{k+p} - s_k| <= settle_tol max|s|`` over at least two repeats (on the last
  ``2 check`` points, then on the last ``record``), with a repeat distance that does not
  grow from the older to the newer half of the window (a run drifting away from an
  unstable orbit does not count), and not still approaching the orbit of half the
  period. Its type is the label ``z = n/p`` (n = p forcing periods, the impacts in one
  repeat, at either wall; ``n/?`` when the count is not steady), or ``sticking`` when it
  rests on a wall (either of two) at every point of the window.
* **the approach through a multiplier near -1.** Near a period doubling a run approaches
  its period-q orbit as an alternating deviation, and looks period-2q to any tolerance
  long before it looks period-q (a fixed 1000-period transient calls such runs 2q). The
  deviation obeys the flip normal form ``x -> -(1 - eps) x + beta x^3``; its decay rate
  against its amplitude squared (``_flip_fit``, over the last half of the run) gives eps:
  eps > 0 is the approach to q (decided early once most of the decay is exponential),
  eps < 0 the approach to the 2q-cycle.
* **chaotic**: a twin run, ``d0`` away, is carried beside a run with no period within
  ``TWIN_GATE`` after ``lyapunov_after`` periods and renormalised after every chunk
  (Benettin's two-trajectory estimate of the largest Lyapunov exponent, as
  ``lyapunov_benettin``, with plain kernel runs). Once it has run ``lyapunov_periods``
  periods with an exponent above ``chaos_threshold`` (per unit time, ``CHAOS_THRESHOLD``)
  the run stops: ``chaotic``.
* otherwise the run goes on to ``transient + record`` periods and its last ``record``
  are classified: a period within ``period_tol`` (a sweep's rule; halved while the flip
  fit says the run approaches half of it) is ``n/p``, not settled; without one a twin
  over the last ``lyapunov_periods`` decides: ``chaotic`` above the threshold, else
  ``quasi-periodic`` (no period within the record and no exponential divergence: a
  torus, a period longer than ``record / 2``, or a transient slower than the horizon).
* when the forcing has no common period (impulses incommensurate with the forcing, or
  a common period longer than ``record / 2``) no stroboscopic period exists: the twin
  alone decides, early (chaotic above the threshold, ``quasi-periodic`` below minus the
  threshold: nearby runs converge on a forced torus) or at the horizon.
* a run the kernel cannot finish is ``escape`` (the state left every bound) or
  ``failed`` (step limit, step collapse).

Settling early is what makes a thousand samples per control value affordable: in section
3.1 (F0 = 0) a run takes 168 periods on average over c in [0.01, 0.1] (docs/stochastic.md),
where a fixed transient integrates 1064.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from opa._model import SolverOptions
from opa._run import STATUS_NAMES, Events, Inputs, run_batch
from opa._system import System
from opa.dynamics._orbits import impulse_cycle
from opa.dynamics._sections import PERIOD_TOL, impacts_per_period, period_label

#: a run is settled when its stroboscopic points repeat to this (relative) tolerance
SETTLE_TOL = 1e-6
#: largest Lyapunov exponent (per unit time) above which a run without a period is chaotic
CHAOS_THRESHOLD = 0.01
#: a run approaches the orbit of half its apparent period when the repeat distance at
#: that half shrinks at least this fraction as fast as the one at the period (log scale)
APPROACH_RATIO = 0.25
#: a twin (for the Lyapunov exponent) runs only beside a run with no period within this
#: relative tolerance: one that converges to a period, however slowly, needs no exponent
TWIN_GATE = 1e-2
#: two runs that have not both settled count as on one orbit within this (relative)
UNSETTLED_TOL = 1e-2
#: the types that are not periodic labels "n/p"
NON_PERIODIC = ("quasi-periodic", "chaotic", "sticking", "escape", "failed")


@dataclass(frozen=True)
class Settings:
    """How a run is classified (module docstring); every field a plain number."""

    transient: int = 1000
    record: int = 64
    check: int = 16
    settle_tol: float = SETTLE_TOL
    period_tol: float = PERIOD_TOL
    lyapunov_after: int = 48
    lyapunov_periods: int = 96
    chaos_threshold: float = CHAOS_THRESHOLD
    d0: float = 1e-8

    def __post_init__(self):
        for name in ("transient", "record", "check", "lyapunov_after", "lyapunov_periods"):
            value = getattr(self, name)
            try:  # None, a string, NaN or inf are refused here too, not by int()
                whole = not isinstance(value, bool) and int(value) == value and value >= 1
            except (TypeError, ValueError, OverflowError):
                whole = False
            if not whole:
                raise ValueError(f"{name} must be a whole number >= 1, got {value!r}")
            object.__setattr__(self, name, int(value))  # 50.0 is 50: a count of periods
        if self.record < 4:
            raise ValueError(f"record must be >= 4 periods, got {self.record}")
        for name in ("settle_tol", "period_tol", "chaos_threshold", "d0"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


@dataclass
class Attractor:
    """What one run settled on."""

    type: str  # "n/p", quasi-periodic, chaotic, sticking, escape, failed
    period: int = 0  # stroboscopic period (0: none)
    impacts: int = -1  # impacts per period (-1: none or not steady)
    settled: bool = False  # stopped early: periodic to settle_tol, or chaotic
    periods: int = 0  # forcing periods integrated
    lyapunov: float = math.nan  # largest exponent per unit time (NaN: not estimated)
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (k, 2) x, v
    residual: float = 0.0  # largest repeat distance at the period over the last window
    state: np.ndarray = field(default_factory=lambda: np.zeros(2))  # the state at the end

    @property
    def periodic(self) -> bool:
        return self.period > 0


def sample_inputs(system: System, options: SolverOptions, values) -> Inputs:
    """The kernel's inputs of the deterministic systems with the uncertain parameter at
    each of ``values`` (absolute), stacked (row b: ``row(inputs, b)``)."""
    return system.sampled_inputs(options, values=np.asarray(values, dtype=float))


def row(inputs: Inputs, b: int) -> Inputs:
    """System b of stacked inputs."""
    return Inputs(inputs.p[b], inputs.cfg[b], inputs.table[b], inputs.weights[b],
                  inputs.basis[b])


def settle(system: System, inputs: Inputs, state, *, options: SolverOptions,
           settings: Settings = Settings()) -> Attractor:
    """The attractor of one system (``inputs`` one row of ``sample_inputs``) from
    ``state`` (x, v) at t = 0: :func:`settle_batch` of one."""
    stacked = Inputs(*(np.asarray(a)[None] for a in (inputs.p, inputs.cfg, inputs.table,
                                                      inputs.weights, inputs.basis)))
    return settle_batch(system, stacked, np.asarray(state, dtype=float)[None],
                        options=options, settings=settings)[0]


def settle_batch(system: System, inputs: Inputs, states, *, options: SolverOptions,
                 settings: Settings = Settings()) -> list[Attractor]:
    """Run the B deterministic systems of ``inputs`` (``sample_inputs``; ``system`` gives
    their forcing period, wall and impulse train) from ``states`` (B, 2) at t = 0 until
    each attractor is known (module docstring).

    The runs advance together, ``check`` periods at a time, in one parallel kernel call
    (``opa._run.run_batch`` from each run's own state), with the twins of the runs that
    carry one; a run leaves the batch once its type is decided."""
    osc = system.oscillator
    T, delta = osc.forcing_period, osc.delta
    walls = (osc.delta_minus, delta)  # -inf: no lower wall
    # periods are multiples of the forcing's cycle; None: it has none (and, with the
    # record holding at most record / 2, neither has a cycle longer than that)
    cycle = impulse_cycle(osc)
    if cycle is not None and cycle > settings.record // 2:
        cycle = None
    s = settings
    total = s.transient + s.record
    states = np.asarray(states, dtype=float)
    B = len(states)
    y = states.copy()
    strobe = np.full((B, total, 2), np.nan)
    impacts = [[] for _ in range(B)]  # impact times, an array per chunk
    complete = np.ones(B, dtype=bool)  # every event of the run was logged
    result: list[Attractor | None] = [None] * B
    # the twin runs twice: from lyapunov_after for lyapunov_periods (chaos decided early),
    # and over the last lyapunov_periods (the final decision); not in between
    twin = np.full((B, 2), np.nan)
    twin_on = np.zeros(B, dtype=bool)
    phase = [""] * B
    growth: list[list] = [[] for _ in range(B)]
    lam_early = np.full(B, np.nan)
    u = np.full((B, 2), 1.0 / math.sqrt(2.0))
    active = np.arange(B)
    k = 0
    while k < total and len(active):
        # short chunks while most runs settle, then whole records (fewer checks)
        n = min(s.check if k < 4 * s.record else s.record, total - k)
        times = (k + np.arange(n + 1)) * T
        if system.impulsive:
            times = system.snap_to_impulses(times, 1e-9 * T)
        twins = active[twin_on[active]]
        rows = np.concatenate([active, twins])
        sub = Inputs(*(np.asarray(a)[rows] for a in (inputs.p, inputs.cfg, inputs.table,
                                                     inputs.weights, inputs.basis)))
        batch = run_batch(sub, np.concatenate([y[active], twin[twins]]), times,
                          rtol=options.rtol, atol=options.atol, capacity=16 * n + 64,
                          include_start=k == 0)
        A = len(active)
        position = {int(b): i for i, b in enumerate(active)}
        for j, b in enumerate(twins):
            i = position[int(b)]
            if batch.ok[A + j] and batch.ok[i]:
                diff = batch.states[A + j, -1] - batch.states[i, -1]
                dist = float(np.linalg.norm(diff))
                if dist > 0 and math.isfinite(dist):
                    growth[b].append((n, math.log(dist / s.d0)))
                    u[b] = diff / dist
        for i, b in enumerate(active):
            if not batch.ok[i]:
                name = STATUS_NAMES[int(batch.status[i])]
                kind = "escape" if name in ("escaped", "diverged") else "failed"
                result[b] = Attractor(kind, periods=k, state=y[b].copy())
                continue
            y[b] = batch.states[i, -1]
            strobe[b, k:k + n] = batch.states[i, 1:]
            complete[b] &= batch.log_complete(i)
            impacts[b].append(batch.log(i))  # decoded only once the run has settled
        k += n
        W = min(k, s.record)
        for b in active:
            if result[b] is not None:
                continue
            result[b] = _decide(b, k, total, W, strobe[b, :k], impacts[b], complete[b], y[b],
                                T, walls, s, phase, growth, lam_early, cycle)
            if result[b] is None:
                twin_on[b] = phase[b] in ("early", "final")
                if twin_on[b]:
                    if not walls[0] <= y[b, 0] + s.d0 * u[b, 0] <= delta:  # beyond a wall
                        u[b] = -u[b]
                    twin[b] = y[b] + s.d0 * u[b]
        active = np.array([b for b in active if result[b] is None], dtype=int)
    return result


def _decide(b, k, total, W, history, impacts, complete, y, T, walls, s, phase, growth,
            lam_early, cycle) -> Attractor | None:
    """The attractor of run b after k periods, or None to go on (updating its twin's
    ``phase``, ``growth`` and ``lam_early``). ``cycle`` None: the forcing has no common
    period, no stroboscopic period exists, and the exponent alone decides. ``walls``:
    (delta_minus, delta)."""
    window = history[k - W:k]
    # settled: first on the last 2 check periods (periods up to check, clear of the
    # transient sooner), then on the whole window
    for span in dict.fromkeys((min(2 * s.check, W), W)) if cycle else ():
        if span >= 2 * s.check or k == total:
            p = _settled_period(history[k - span:k], s.settle_tol,
                                final=span == s.record or k == total)
            if p:
                return _periodic(history[k - span:k], p, impacts, complete, k, T, walls, y,
                                 settled=True)
    periodic = _period_within(window, s.period_tol) if cycle else 0
    lam = (_exponent(growth[b], T) if growth[b] else lam_early[b]) if k == total else math.nan
    if cycle and (k >= 4 * s.record or k == total):
        p = _approached_period(history, window, s.period_tol, final=k == total,
                               cycle=cycle)
        # (without a period within tol, a flip approach does not outvote chaos)
        if p and (periodic or not lam > s.chaos_threshold):
            return _periodic(window, p, impacts, complete, k, T, walls, y, settled=k < total)
    if k == total:
        kind = "chaotic" if lam > s.chaos_threshold else "quasi-periodic"
        return Attractor(kind, periods=k, lyapunov=lam, points=window.copy(), state=y.copy())
    if phase[b] == "early" and sum(m for m, _ in growth[b]) >= s.lyapunov_periods:
        lam_early[b] = _exponent(growth[b], T)
        if lam_early[b] > s.chaos_threshold and not periodic:
            return Attractor("chaotic", settled=True, periods=k, lyapunov=lam_early[b],
                             points=window.copy(), state=y.copy())
        if cycle is None and lam_early[b] < -s.chaos_threshold:
            # no period can exist, and nearby runs converge: a forced torus
            return Attractor("quasi-periodic", settled=True, periods=k,
                             lyapunov=lam_early[b], points=window.copy(), state=y.copy())
        phase[b] = "paused"
    if (phase[b] == "" and k >= s.lyapunov_after or phase[b] == "paused"
            and k >= total - s.lyapunov_periods) and not (cycle and _period_within(
                history[k - min(W, 2 * s.check):k], TWIN_GATE)):
        # a twin only beside a run without a period in sight: one that converges
        # slowly to a period needs no exponent
        phase[b] = "early" if phase[b] == "" else "final"
        growth[b] = []
    return None


def _exponent(growth, T) -> float:
    """The mean log growth per unit time of the twin's chunks ``(periods, log growth)``."""
    periods = sum(m for m, _ in growth)
    return sum(g for _, g in growth) / (periods * T) if periods else math.nan


def repeat_distance(window: np.ndarray, p: int) -> np.ndarray:
    """``d[k] = max_j |s[k + p, j] - s[k, j]|``, k = 0 .. W - p - 1: the repeat distances
    at the candidate period p along a window of stroboscopic points (W, 2)."""
    return np.abs(window[p:] - window[:-p]).max(axis=1)


def _scale(window: np.ndarray) -> float:
    return max(float(np.abs(window).max()), 1e-300)


def _smallest_period(window: np.ndarray, tol: float, scale: float) -> int:
    """The smallest p <= W / 2 whose repeat distance over the window is within
    ``tol * scale`` (0: none). A period within tol over the window is one at its newest
    point, which picks the candidates cheaply."""
    W = len(window)
    last = np.abs(window[-1] - window[-2:-W // 2 - 2:-1]).max(axis=1)
    for p in np.flatnonzero(last <= tol * scale) + 1:
        if repeat_distance(window, p).max() <= tol * scale:
            return int(p)
    return 0


def _period_within(window: np.ndarray, tol: float) -> int:
    """The smallest period of the window within ``tol`` (0: none)."""
    return _smallest_period(window, tol, _scale(window))


def _block_maxima(window: np.ndarray, q: int, p: int, count: int) -> np.ndarray:
    """The maxima of the repeat distance at q over the last ``count`` blocks of p."""
    row_ = repeat_distance(window, q)
    return row_[len(row_) - count * p:].reshape(count, p).max(axis=1)


def _converges_to(window: np.ndarray, q: int, scale: float) -> bool | None:
    """Whether a run that looks period-2q is still approaching a period-q orbit (None: the
    window holds fewer than three blocks of 2q to tell).

    Through a multiplier near -1 a run approaches a period-q orbit as an alternating
    deviation: its repeat distance at 2q reaches any tolerance long before the one at q
    does, but the two go to zero together (at the same rate when the multiplier is
    -(1 - eps); at the doubling itself, where the decay is algebraic, the distance at q
    shrinks a third as fast as the one at 2q on a log scale). A period-2q orbit approached
    slowly has a distance at 2q going to zero and one at q tending to the orbit's split,
    which hardly shrinks. So: approaching q when the distance at 2q still shrinks
    measurably (from above round-off, by more than 1 % over the window) and the one at q
    shrinks at least a quarter as fast on a log scale (``APPROACH_RATIO``)."""
    p = 2 * q
    count = (len(window) - p) // p
    if count < 3:
        return None
    Dp = _block_maxima(window, p, p, count)
    Dq = _block_maxima(window, q, p, count)
    if Dp[0] <= 1e-9 * scale or Dq[0] <= 0:
        return False  # the whole window is at round-off
    floor = 1e-13 * scale
    fp, fq = max(Dp[-1], floor) / Dp[0], max(Dq[-1], floor) / Dq[0]
    return bool(fp < 0.99 and math.log(fq) <= APPROACH_RATIO * math.log(fp))


def _settled_period(window: np.ndarray, tol: float, final: bool) -> int:
    """The period p of a settled window (0: not settled): the smallest p within ``tol``
    whose repeat distance does not grow from the older half of the window to the newer,
    and whose run is not still approaching the orbit of period p / 2 (``_converges_to``;
    a window too short to judge defers the decision, unless it is ``final``)."""
    scale = _scale(window)
    p = _smallest_period(window, tol, scale)
    if not p:
        return 0
    row_ = repeat_distance(window, p)
    half = len(row_) // 2
    if row_[half:].max() > max(row_[:half].max(), 1e-9 * scale):
        return 0
    if p % 2 == 0:
        approaching = _converges_to(window, p // 2, scale)
        if approaching or (approaching is None and not final):
            return 0
    return p


def _flip_fit(history: np.ndarray, q: int, scale: float):
    """``(eps, rate)`` of a run that approaches a period-q orbit, or leaves it for a
    period-2q one, through a multiplier near -1; None where the run is not in that regime
    or the record cannot tell.

    Near a period doubling the deviation x from the period-q orbit obeys the normal form
    ``x -> -(1 - eps) x - beta x^3``: it decays at the rate ``eps + beta x^2`` per q
    periods (exponentially to 0 when eps > 0; towards the 2q-cycle at
    ``x^2 = -eps / beta`` when eps < 0; algebraically at the doubling). The repeat
    distance at q measures |x|: over the last half of the run its maxima over blocks of
    2q give the decay rate at each amplitude, and a straight line fitted to rate against
    amplitude squared gives eps as its intercept (``rate`` is the last rate measured).
    Needs eight blocks, the repeat distance at 2q below half the one at q (the
    alternating deviation of a flip), a shrinking distance at q, and amplitudes that
    vary by at least 20 % in square."""
    p = 2 * q
    seg = history[len(history) // 2:]
    n = len(seg) - p
    count = n // p
    if count < 8:
        return None
    dq = np.abs(seg[q:q + n] - seg[:n]).max(axis=1)
    dp = np.abs(seg[p:p + n] - seg[:n]).max(axis=1)
    Dq = dq[n - count * p:].reshape(count, p).max(axis=1)
    Dp = dp[n - count * p:].reshape(count, p).max(axis=1)
    keep = Dq > 1e-8 * scale
    if keep.sum() < 8 or not (Dp[keep][-1] < 0.5 * Dq[keep][-1] and Dq[keep][-1] < Dq[0]):
        return None
    Dq = Dq[keep]
    rate = np.log(Dq[:-1] / Dq[1:]) / 2.0  # per q periods
    amp2 = Dq[:-1] * Dq[1:]
    if amp2.max() < 1.2 * amp2.min():
        return None
    beta, eps = np.polyfit(amp2, rate, 1)
    return float(eps), float(rate[-1])


def _approached_period(history: np.ndarray, window: np.ndarray, tol: float, *,
                       final: bool, cycle: int = 1) -> int:
    """The period of a run that has not settled to ``settle_tol`` (0: none): the smallest
    p within ``tol`` over the window (a sweep's rule), halved while the run approaches
    the orbit of half the period (``_flip_fit``: eps > 0; the half a multiple of the
    forcing's ``cycle``). Before the ``final`` decision an approach counts only when most
    of its decay is exponential (eps at least half the last rate), so that a run still in
    the algebraic decay at a doubling is not called early; 0 then unless the period is
    halved. Without a p within ``tol`` (``final`` only), the smallest multiple q of the
    cycle with a flip fit of eps > 0 whose repeat distance at q is already below 5 % of
    the section's size."""
    scale = _scale(window)
    p = _smallest_period(window, tol, scale)
    halved = False
    if p:
        while p % (2 * cycle) == 0:
            fit = _flip_fit(history, p // 2, scale)
            if fit is None or fit[0] <= (0.5 * fit[1] if not final else 0.0):
                break
            p //= 2
            halved = True
        return p if final or halved else 0
    if not final:
        return 0
    for q in range(cycle, len(window) // 4 + 1, cycle):
        if repeat_distance(window[-4 * q:], q).max() > 0.05 * scale:
            continue
        fit = _flip_fit(history, q, scale)
        if fit is not None and fit[0] > 0:
            return q
    return 0


def same_attractor(a: Attractor, b: Attractor, tol: float = 1e-3) -> bool:
    """Whether two runs found the same attractor: the same type and, for periodic ones,
    the same orbit (every point of each within ``tol`` of the section's size, plus both
    runs' residuals, of a point of the other: a run settled on its approach is still that
    far from its orbit; a run that has not settled, ``UNSETTLED_TOL``). Two chaotic or
    quasi-periodic runs of the same type count as the same (nothing here tells their
    attractors apart)."""
    if a.type != b.type:
        return False
    if not (a.periodic and b.periodic) or len(a.points) == 0 or len(b.points) == 0:
        return True
    scale = max(float(np.abs(a.points).max()), float(np.abs(b.points).max()), 1e-300)
    if not (a.settled and b.settled):
        tol = max(tol, UNSETTLED_TOL)  # still on its way, slower than its residual says
    reach = tol * scale + a.residual + b.residual
    gap = np.abs(a.points[:, None, :] - b.points[None, :, :]).max(axis=2)
    return bool(gap.min(axis=1).max() <= reach and gap.min(axis=0).max() <= reach)


def _periodic(window, p, impacts, complete, k, T, walls, y, *, settled) -> Attractor:
    """The attractor of a run whose last ``len(window)`` points have period p (impacts
    counted at both walls; ``walls`` (delta_minus, delta), sticking on either)."""
    lower, delta = walls
    W = len(window)
    end = k * T
    ev = Events.of(np.concatenate(impacts) if impacts else np.zeros((0, 3)))
    times = ev.time[ev.impacts]
    count = (impacts_per_period(times[times > end - W * T - 1e-9 * T], end, T, p, W // p)
             if complete else -1)
    resting = ((np.all(window[:, 0] >= delta - 1e-12) or np.all(window[:, 0] <= lower + 1e-12))
               and np.all(window[:, 1] == 0.0))
    kind = "sticking" if resting else period_label(p, count)
    return Attractor(kind, period=p, impacts=count, settled=settled, periods=k,
                     points=window[-p:].copy(), state=y.copy(),
                     residual=float(repeat_distance(window, p).max()) if p < W else 0.0)


def initial_states(oscillator, extra: int) -> np.ndarray:
    """The paper's start (x0, v0) and ``extra`` others, (1 + extra, 2): points on a circle
    of radius 1 around the origin, moved inside the walls where they lie beyond one (to
    0.5 from it, or a quarter of the gap between two walls if that is less)."""
    states = [(oscillator.x0, oscillator.v0)]
    upper, lower = oscillator.delta, oscillator.delta_minus
    margin = min(0.5, (upper - lower) / 4)  # 0.5 with one wall
    for j in range(extra):
        angle = 2 * math.pi * (j + 0.5) / extra
        x, v = math.cos(angle), math.sin(angle)
        states.append((min(max(x, lower + margin), upper - margin), v))
    return np.array(states, dtype=float)


__all__ = ["Attractor", "CHAOS_THRESHOLD", "NON_PERIODIC", "SETTLE_TOL", "Settings",
           "initial_states", "row", "same_attractor", "sample_inputs", "settle",
           "settle_batch"]
