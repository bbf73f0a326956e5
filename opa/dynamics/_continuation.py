"""Branches of periodic orbits along a parameter: pseudo-arclength continuation of the
fixed points of the stroboscopic map, bifurcation detection and location, branch
switching at period doubling, the branch dataset and its figure.

Along a branch ``G(y, lambda) = P^k(y; lambda) - y = 0`` is followed by pseudo-arclength
continuation (secant/tangent predictor, Newton corrector on ``G = 0`` plus the arclength
condition) in the scaled parameter ``lambda / L`` (``L = |stop - start|``), so folds are
passed and unstable orbits are followed as readily as stable ones. The Jacobian
``DP^k`` is exact (``opa.dynamics._orbits``); ``dP/dlambda`` is a central difference.

Test functions between consecutive points:

- period doubling: ``det(DP^k + I)`` changes sign (a real multiplier crosses -1);
  located by Brent's method in the parameter to ``xtol`` (default 1e-10), with a Newton
  solve at each trial value, then the doubled branch ``P^{2k}`` is started from the
  bifurcation point along the eigenvector of -1 (the pitchfork of ``P^{2k}``);
- fold: the parameter component of the tangent changes sign (a multiplier must be
  near +1, else the turn is a non-smooth point of the map and the branch ends); located
  by Brent's method on ``det(DP^k - I)`` along the chord between the two points;
- Neimark-Sacker: the number of complex multipliers outside the unit circle changes
  (approximate, linear interpolation of their modulus);
- grazing: the number of impacts per period changes, or a free-flight maximum reaches
  the wall; impulse-impact: an impact meets an impulse time (the branch ends, or goes
  on with the two events swapped). The gap, the squared impact velocity and the
  impact-impulse separation vanish linearly in the parameter, so these points are
  located by extrapolating them to zero from orbits ever nearer to it (``locate_edge``).

``locate_bifurcations`` puts it together for a parameter interval: it continues the
periodic attractors found at seed values (e.g. those a brute-force sweep observed) and
returns the bifurcations that change an attractor, each located (``Located``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from opa._lazy import lazy
from opa._model import Oscillator, SolverOptions, check_instance
from opa._run import SimulationError
from opa._system import System
from opa.dynamics._orbits import (
    ConvergenceError,
    ImpactSystem,
    PeriodicOrbit,
    _minimal_period,
    _orbit,
    _residual,
    check_count,
    check_time,
    default_tolerance,
    flow,
    impulse_cycle,
    periodic_orbit,
    poincare_map,
    shoot,
)

xr = lazy("xarray")

BIFURCATION_KINDS = ("period-doubling", "fold", "neimark-sacker", "grazing", "impulse-impact")
FOLD_MULTIPLIER = 0.25  # a turn of the branch is a fold only with a multiplier this close to 1
NEAR = 1e-2  # a branch end is put down to grazing / an impulse when these are this small
# Hard bounds on the loops: step halvings of the corrector (from step down to min_step)
# and branches per call (doubled branches and branches across impulse-impact borders).
MAX_HALVINGS = 64
MAX_BRANCHES = 200
# Newton iterations allowed where the guess is an orbit next to the one sought (across an
# impulse-impact border, towards the end of a branch): a failing Newton costs up to
# LINE_SEARCH_HALVINGS maps per iteration, and a genuine orbit converges within a few.
SHOOT_NEAR = 6


@dataclass(eq=False)
class Bifurcation:
    """A bifurcation point on a branch.

    ``value``: parameter value; ``located``: True when found to ``xtol`` by root
    finding (period doubling, fold) or by extrapolation from orbits ever closer to it
    (grazing, impulse-impact: ``locate_edge``), False for interpolated estimates;
    ``orbit``: the orbit at the point when located; ``child``: index of the branch
    switched onto, or -1; ``attracting``: an orbit next to the point is stable, so the
    bifurcation changes an attractor (what a brute-force diagram can show);
    ``between``: the indices on the branch of the orbits on either side.
    """

    kind: str
    value: float
    branch: int
    located: bool
    orbit: PeriodicOrbit | None = None
    x: float = math.nan
    v: float = math.nan
    child: int = -1
    attracting: bool = False
    between: tuple = (-1, -1)


@dataclass(eq=False)
class Branch:
    """The orbits along one branch, in continuation order."""

    parameter: str
    periods: int
    values: list = field(default_factory=list)
    orbits: list = field(default_factory=list)
    parent: int = -1
    end: str = ""


# --------------------------------------------------------------------------- one branch
class _Continuation:
    """Pseudo-arclength continuation of the fixed points of ``P^k`` in one parameter."""

    def __init__(self, system, parameter, lo, hi, periods, t0, *, tol, scale):
        if parameter not in system.continuable:
            raise ValueError(f"parameter must be one of {', '.join(system.continuable)}, got "
                             f"{parameter!r}")
        self.system = system
        self.name = parameter
        self.lo, self.hi = lo, hi
        self.k = periods
        self.t0 = t0
        self.tol = tol
        self.L = scale
        self.dlam = 1e-4 * scale

    def at(self, lam):
        return self.system.with_parameter(self.name, lam)

    def residual_map(self, y, lam, jacobian=True):
        sys_ = self.at(lam)
        return poincare_map(sys_, y, periods=self.k, t0=self.t0, jacobian=jacobian)

    def g_lambda(self, y, lam):
        """dG/d(theta) = L dP/dlambda, central difference."""
        h = self.dlam
        yp, _ = self.residual_map(y, lam + h, jacobian=False)
        ym, _ = self.residual_map(y, lam - h, jacobian=False)
        return self.L * (yp - ym) / (2.0 * h)

    def tangent(self, y, lam, J, t_prev=None, direction=1.0):
        D = len(y)
        A = np.hstack([J - np.eye(D), self.g_lambda(y, lam)[:, None]])
        if t_prev is None:
            _, _, vt = np.linalg.svd(A)
            t = vt[-1]
            if t[-1] * direction < 0:
                t = -t
        else:
            M = np.vstack([A, t_prev[None, :]])
            rhs = np.zeros(D + 1)
            rhs[-1] = 1.0
            t = np.linalg.solve(M, rhs)
        return t / np.linalg.norm(t)

    def correct(self, u_pred, t, max_iter=8):
        """Newton on [G(u); t . (u - u_pred)] = 0; returns (y, lam, J, iterations)."""
        D = len(u_pred) - 1
        delta = self.system.oscillator.delta
        u = u_pred.copy()
        g_lam = None
        res = math.inf
        for it in range(max_iter):
            y, lam = u[:D], u[D] * self.L
            if y[0] > delta or not (self.lo - 0.5 * self.L <= lam <= self.hi + 0.5 * self.L):
                return None
            y1, J = self.residual_map(y, lam)
            G = y1 - y
            if g_lam is None:
                g_lam = self.g_lambda(y, lam)
            res_prev, res = res, _residual(y, y1)
            arc = float(t @ (u - u_pred))
            floor = res < 100.0 * self.tol and res > 0.5 * res_prev  # integration noise
            if (res < self.tol or floor) and abs(arc) < 1e-9:
                return y.copy(), lam, J, it
            M = np.zeros((D + 1, D + 1))
            M[:D, :D] = J - np.eye(D)
            M[:D, D] = g_lam
            M[D] = t
            try:
                du = np.linalg.solve(M, -np.concatenate([G, [arc]]))
            except np.linalg.LinAlgError:
                return None
            u = u + du
        return None


def _stability_count(orbit: PeriodicOrbit) -> tuple[int, int]:
    """(unstable real multipliers, unstable complex multipliers)."""
    mu = orbit.multipliers
    out = np.abs(mu) > 1.0
    cplx = np.abs(mu.imag) > 1e-12 * np.maximum(1.0, np.abs(mu))
    return int(np.sum(out & ~cplx)), int(np.sum(out & cplx))


def _near_one(orbit: PeriodicOrbit) -> bool:
    mu = orbit.multipliers
    return bool(np.any((np.abs(mu.imag) < 1e-9) & (np.abs(mu.real - 1.0) < FOLD_MULTIPLIER)))


def _pd_test(orbit: PeriodicOrbit) -> float:
    return float(np.prod(orbit.multipliers + 1.0).real)


def follow(system: ImpactSystem, parameter: str, orbit: PeriodicOrbit, stop: float, *,
           step: float = 0.02, max_step: float = 0.05, min_step: float = 1e-6,
           max_points: int = 500, tol: float | None = None, bounds: tuple | None = None,
           initial_tangent: np.ndarray | None = None, max_multiplier: float = 1e3
           ) -> tuple[Branch, list]:
    """Follow the branch of ``orbit`` in ``parameter`` towards ``stop``.

    ``step``, ``max_step``, ``min_step`` are arclength steps in the scaled variables
    (state, parameter / L with L the length of ``bounds``). ``initial_tangent`` (D + 1)
    starts the continuation in a given direction (branch switching). The branch is
    abandoned where its largest multiplier exceeds ``max_multiplier`` in modulus. Returns the branch
    and the raw list of detected events ``(kind, index_a, index_b)`` between points.
    """
    start = system.parameter(parameter)
    _check_steps(step, max_step, max_points, min_step)
    if not math.isfinite(stop):
        raise ValueError(f"stop must be finite, got {stop}")
    tol = default_tolerance(system) if tol is None else tol
    lo, hi = bounds if bounds is not None else (min(start, stop), max(start, stop))
    L = max(hi - lo, 1e-12)
    k, t0 = orbit.periods, orbit.t0
    k0 = impulse_cycle(system.oscillator) or k
    cont = _Continuation(system, parameter, lo, hi, k, t0, tol=tol, scale=L)
    branch = Branch(parameter=parameter, periods=k)
    branch.values.append(start)
    branch.orbits.append(orbit)
    direction = 1.0 if stop >= start else -1.0
    y, lam, J = orbit.state.copy(), start, orbit.jacobian
    if initial_tangent is not None:
        t = initial_tangent / np.linalg.norm(initial_tangent)
    else:
        t = cont.tangent(y, lam, J, direction=direction)
    ds = step
    events = []
    while len(branch.orbits) < max_points:
        u = np.concatenate([y, [lam / L]])
        got = None
        for _ in range(MAX_HALVINGS):
            if ds < min_step:
                break
            try:
                got = cont.correct(u + ds * t, t)
            except (SimulationError, ValueError):
                got = None
            if got is not None:
                y_new, lam_new, J_new, iters = got
                # a too-large step can jump to another branch: require the new point
                # to lie ahead of the old one, within a few steps
                if np.linalg.norm(np.concatenate([y_new, [lam_new / L]]) - u) <= 3.0 * ds:
                    break
                got = None
            ds *= 0.5
        if got is None:
            branch.end = "corrector failed (step below min_step)"
            events.append(("end", len(branch.orbits) - 1, len(branch.orbits) - 1))
            break
        y_new, lam_new, J_new, iters = got
        if lam_new < lo or lam_new > hi:
            # land exactly on the end of the interval
            end = hi if lam_new > hi else lo
            frac = (end - lam) / (lam_new - lam) if lam_new != lam else 1.0
            guess = y + frac * (y_new - y)
            try:
                o = shoot(system.with_parameter(parameter, end), guess, periods=k, t0=t0, tol=tol)
                _append(branch, end, o, events)
            except (ConvergenceError, SimulationError):
                pass
            branch.end = "reached the end of the interval"
            break
        sys_new = system.with_parameter(parameter, lam_new)
        o = _orbit(sys_new, y_new, k, t0, J_new, _residual(y_new, flow(
            sys_new, y_new, [t0, t0 + k * sys_new.forcing_period]).states[-1]), iters)
        prev = branch.orbits[-1]
        if prev.impacts == o.impacts and prev.impulse_order != o.impulse_order:
            # an impact crossed an impulse time: the map jumps there, the new orbit lies on
            # another sheet of it
            branch.end = ("an impact crossed an impulse time (the map is discontinuous there)"
                          if system.impulse == "dirac" else
                          "an impact crossed a pulse edge (the map is not smooth there)")
            events.append(("impulse-impact", len(branch.orbits) - 1, len(branch.orbits) - 1))
            break
        if k >= 2 * k0 and _minimal_period(o.points, k, k0, 1e-6) < k:
            # the corrector slid onto an orbit of a divisor of the period (a doubled
            # branch back at its parent): not this branch any more
            branch.end = "collapsed onto an orbit of a shorter period (its period doubling)"
            events.append(("collapse", len(branch.orbits) - 1, len(branch.orbits) - 1))
            break
        t_new = cont.tangent(y_new, lam_new, J_new, t_prev=t)
        if t_new[-1] * t[-1] < 0:
            if not (_near_one(branch.orbits[-1]) or _near_one(o)):
                # the branch turned with no multiplier near +1: the map is not smooth here
                branch.end = ("the branch turned back with no multiplier near +1: non-smooth "
                              "point of the map")
                events.append(("end", len(branch.orbits) - 1, len(branch.orbits) - 1))
                break
            events.append(("fold", len(branch.orbits) - 1, len(branch.orbits)))
        _append(branch, lam_new, o, events)
        if o.spectral_radius > max_multiplier:
            branch.end = f"a multiplier exceeds max_multiplier = {max_multiplier:g}"
            break
        y, lam, J, t = y_new, lam_new, J_new, t_new
        ds = min(ds * 1.5, max_step) if iters <= 3 else ds
    else:
        branch.end = f"max_points ({max_points}) reached"
    return branch, events


def _check_steps(step, max_step, max_points, min_step=None) -> None:
    """Arclength steps finite and positive (min_step <= step); max_points >= 1."""
    steps = [("step", step), ("max_step", max_step)]
    if min_step is not None:
        steps.append(("min_step", min_step))
    for name, value in steps:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not (
                math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    if min_step is not None and min_step > step:
        raise ValueError(f"min_step must be <= step, got min_step = {min_step}, step = {step}")
    check_count("max_points", max_points, 1)


def _append(branch: Branch, value: float, orbit: PeriodicOrbit, events: list) -> None:
    if branch.orbits:
        prev = branch.orbits[-1]
        i = len(branch.orbits) - 1
        if np.sign(_pd_test(prev)) != np.sign(_pd_test(orbit)):
            events.append(("period-doubling", i, i + 1))
        if _stability_count(prev)[1] != _stability_count(orbit)[1]:
            events.append(("neimark-sacker", i, i + 1))
        if prev.impacts != orbit.impacts:
            events.append(("grazing", i, i + 1))
    branch.values.append(value)
    branch.orbits.append(orbit)


# --------------------------------------------------------------------------- location
def locate_period_doubling(system: ImpactSystem, parameter: str, a: tuple, b: tuple, *,
                           xtol: float = 1e-10, tol: float | None = None) -> PeriodicOrbit:
    """The period-doubling point between two orbits ``a = (value, orbit)``, ``b``.

    Brent's method on ``det(DP^k + I)`` in the parameter, each trial value solved by
    Newton shooting from the linear interpolation of the two states. Returns the orbit
    at the bifurcation (its system carries the parameter value).
    """
    (la, oa), (lb, ob) = a, b
    k, t0 = oa.periods, oa.t0
    cache = {}

    def solve(lam):
        if lam not in cache:
            frac = (lam - la) / (lb - la)
            guess = oa.state + frac * (ob.state - oa.state)
            cache[lam] = shoot(system.with_parameter(parameter, lam), guess, periods=k, t0=t0,
                               tol=tol)
        return cache[lam]

    fa, fb = _pd_test(oa), _pd_test(ob)
    if np.sign(fa) == np.sign(fb):
        raise ValueError("the two orbits do not bracket a period doubling")
    from scipy.optimize import brentq

    root = brentq(lambda lam: _pd_test(solve(lam)), la, lb, xtol=xtol, rtol=4 * np.finfo(float).eps,
                  maxiter=200)
    return solve(root)


def locate_fold(system: ImpactSystem, parameter: str, a: tuple, b: tuple, *, scale: float,
                xtol: float = 1e-12, tol: float | None = None) -> PeriodicOrbit:
    """The fold (multiplier +1, turning point in the parameter) between two orbits.

    The branch between ``a = (value, orbit)`` and ``b`` is parametrised by the fraction
    s of the chord from a to b (each point: Newton on ``G = 0`` in the hyperplane normal
    to the chord, in the variables (y, value / scale)), and Brent's method finds the
    sign change of ``det(DP^k - I)`` in s. The parameter is quadratic in s at a fold,
    so it is located far more precisely than s.
    """
    (la, oa), (lb, ob) = a, b
    tol = default_tolerance(system) if tol is None else tol
    lo, hi = min(la, lb), max(la, lb)
    cont = _Continuation(system, parameter, lo - scale, hi + scale, oa.periods, oa.t0, tol=tol,
                         scale=scale)
    ua = np.concatenate([oa.state, [la / scale]])
    chord = np.concatenate([ob.state, [lb / scale]]) - ua
    normal = chord / np.linalg.norm(chord)
    eye = np.eye(system.dim)
    cache = {}

    def point(frac):
        if frac not in cache:
            got = cont.correct(ua + frac * chord, normal, max_iter=12)
            if got is None:
                raise ConvergenceError(f"no orbit on the chord at fraction {frac:.6g}")
            cache[frac] = got
        return cache[frac]

    def test(frac):
        if frac == 0.0:
            return float(np.linalg.det(oa.jacobian - eye))
        if frac == 1.0:
            return float(np.linalg.det(ob.jacobian - eye))
        return float(np.linalg.det(point(frac)[2] - eye))

    if np.sign(test(0.0)) == np.sign(test(1.0)):
        raise ValueError("the two orbits do not bracket a fold")
    from scipy.optimize import brentq

    root = brentq(test, 0.0, 1.0, xtol=xtol, maxiter=200)
    y, lam, J, iters = point(root) if 0.0 < root < 1.0 else (
        (oa.state, la, oa.jacobian, 0) if root == 0.0 else (ob.state, lb, ob.jacobian, 0))
    sys_ = system.with_parameter(parameter, lam)
    res = _residual(y, flow(sys_, y, [oa.t0, oa.t0 + oa.periods * sys_.forcing_period]
                            ).states[-1])
    return _orbit(sys_, y, oa.periods, oa.t0, J, res, iters)


def _collapsed(system: ImpactSystem, parameter: str, o: PeriodicOrbit, value: float,
               d: float, *, xtol: float, tol: float) -> PeriodicOrbit | None:
    """The period-doubling point where a doubled branch meets its parent.

    Followed towards its period-doubling point, a doubled branch (fixed points of
    ``P^{2k}``) turns there like a fold, or the corrector slides onto the period-k orbit
    (a fixed point of ``P^{2k}`` as well): its two halves are the same orbit shifted by
    k periods, and they meet the period-k orbit, whose multiplier -1 is a +1 of
    ``P^{2k}``. If ``o``, an orbit of the branch next to ``value``, nearly repeats after
    half its period, the period-k orbit is solved within a few ``d`` on both sides of
    ``value`` and the doubling located on it (``locate_period_doubling``). Returns the
    period-k orbit at the doubling, or None (an ordinary fold).
    """
    k = o.periods
    k0 = impulse_cycle(system.oscillator) or k
    if k % (2 * k0):
        return None
    half = k // 2
    scale = 1.0 + np.max(np.abs(o.points))
    if np.max(np.abs(o.points[half] - o.points[0])) > 0.05 * scale:
        return None
    # near the turn the corrector may have slid onto the period-k orbit itself, so
    # bracket the doubling generously on both sides of it
    d = max(d, 1e-9)
    for width in (2.0 * d, 8.0 * d, 32.0 * d):
        sides = []
        for lam in (value - width, value + width):
            try:
                sides.append((lam, shoot(system.with_parameter(parameter, lam), o.state,
                                         periods=half, t0=o.t0, tol=tol,
                                         max_iter=SHOOT_NEAR)))
            except (ConvergenceError, SimulationError, ValueError):
                return None
        if np.max(np.abs(sides[0][1].state - sides[1][1].state)) > 0.05 * scale:
            return None
        if np.sign(_pd_test(sides[0][1])) != np.sign(_pd_test(sides[1][1])):
            try:
                return locate_period_doubling(system, parameter, *sides, xtol=xtol, tol=tol)
            except (ConvergenceError, SimulationError, ValueError):
                return None
    return None


def _separation(orbit: PeriodicOrbit) -> float:
    return orbit.impulse_separation


def _graze_measure(orbit: PeriodicOrbit) -> float:
    return min(orbit.min_gap, orbit.min_impact_velocity ** 2)


def _gap(orbit: PeriodicOrbit) -> float:
    return orbit.min_gap


def locate_edge(system: ImpactSystem, parameter: str, a: tuple, b: tuple, measure, *,
                xtol: float = 1e-10, tol: float | None = None, max_iter: int = 12
                ) -> tuple[float, PeriodicOrbit]:
    """Where a family of orbits ends because ``measure(orbit)`` (>= 0) goes to zero.

    ``a = (value, orbit)`` and ``b`` are two orbits of a branch, ``b`` the nearer to the
    end. For an impact meeting an impulse time (``measure``: the impact-impulse
    separation) or a grazing (the gap of a free flight to the wall, or the square of
    the slowest impact velocity): both vanish linearly in the parameter, and beyond the
    point the orbit does not exist or lies on another sheet of the map (with an extra
    impact, where the square-root singularity of grazing defeats Newton's method), so
    there is nothing to bracket. Instead the zero is extrapolated linearly from the two
    nearest orbits, a new orbit is solved 9/10 of the way there (Newton shooting, the
    same impacts and impulse order), and so on until the extrapolation moves by less
    than ``xtol``; the error of each extrapolation is quadratic in the distance to the
    end. Returns the value and the nearest orbit; ``ConvergenceError`` if none can be
    found nearer than ``1e3 xtol``.
    """
    (la, oa), (lb, ob) = a, b
    est = math.nan
    for _ in range(check_count("max_iter", max_iter, 1)):
        ma, mb = measure(oa), measure(ob)
        if not (math.isfinite(ma) and math.isfinite(mb)) or ma == mb or la == lb:
            raise ConvergenceError("the measure does not change along the branch")
        est = lb + mb * (lb - la) / (ma - mb)
        if abs(est - lb) <= xtol:
            return est, ob
        for frac in (0.9, 0.5, 0.2):
            lam = lb + frac * (est - lb)
            guess = ob.state + (lam - lb) / (lb - la) * (ob.state - oa.state)
            try:
                o = shoot(system.with_parameter(parameter, lam), guess, periods=ob.periods,
                          t0=ob.t0, tol=tol, max_iter=SHOOT_NEAR)
            except (ConvergenceError, SimulationError, ValueError):
                continue
            if (o.impacts == ob.impacts and o.impulse_order == ob.impulse_order
                    and measure(o) < mb):
                break
        else:
            raise ConvergenceError(f"no orbit found nearer to the end of the branch than "
                                   f"{abs(est - lb):.2g} in {parameter}")
        (la, oa), (lb, ob) = (lb, ob), (lam, o)
    if abs(est - lb) > 1e3 * xtol:
        raise ConvergenceError(f"the end of the branch is not located to better than "
                               f"{abs(est - lb):.2g} after {max_iter} steps")
    return est, ob


def _interpolate(kind, branch, ia, ib):
    """Approximate location of a fold, Neimark-Sacker or grazing point."""
    la, lb = branch.values[ia], branch.values[ib]
    oa, ob = branch.orbits[ia], branch.orbits[ib]
    if kind == "fold":
        i0 = max(ia - 1, 0)
        i2 = min(ib, len(branch.values) - 1)
        # parabola lambda(s) through three points, s = cumulative state distance
        pts = [i0, ia, i2] if i2 - i0 == 2 else [i0, ia, ib]
        s = [0.0]
        for i, j in zip(pts[:-1], pts[1:]):
            s.append(s[-1] + np.linalg.norm(branch.orbits[j].state - branch.orbits[i].state))
        lam = [branch.values[i] for i in pts]
        if len(set(s)) == 3:
            c2, c1, c0 = np.polyfit(s, lam, 2)
            if c2 != 0:
                sm = -c1 / (2 * c2)
                if s[0] <= sm <= s[-1]:
                    return float(c0 + c1 * sm + c2 * sm * sm)
        return float(lam[1])
    if kind == "neimark-sacker":
        def radius(o):
            cplx = np.abs(o.multipliers.imag) > 1e-12
            return np.abs(o.multipliers[cplx]).max() if cplx.any() else np.nan
        ra, rb = radius(oa), radius(ob)
        if np.isfinite(ra) and np.isfinite(rb) and ra != rb:
            return float(la + (1.0 - ra) * (lb - la) / (rb - ra))
        return 0.5 * (la + lb)
    if kind == "impulse-impact":
        i0 = max(ib - 1, 0)
        sa, sb = branch.orbits[i0].impulse_separation, branch.orbits[ib].impulse_separation
        l0 = branch.values[i0]
        if i0 != ib and sa != sb and np.isfinite(sa) and np.isfinite(sb):
            return float(lb + sb * (lb - l0) / (sa - sb))
        return lb
    # grazing: v^2 (side with the extra impact) or the gap (other side) vanish linearly
    fa = oa.min_gap if np.isfinite(oa.min_gap) else -oa.min_impact_velocity ** 2
    fb = ob.min_gap if np.isfinite(ob.min_gap) else -ob.min_impact_velocity ** 2
    if oa.impacts != ob.impacts:
        fa = oa.min_gap if oa.impacts < ob.impacts else -oa.min_impact_velocity ** 2
        fb = ob.min_gap if ob.impacts < oa.impacts else -ob.min_impact_velocity ** 2
    if np.isfinite(fa) and np.isfinite(fb) and fa != fb and np.sign(fa) != np.sign(fb):
        return float(la + fa * (lb - la) / (fa - fb))
    return 0.5 * (la + lb)


# --------------------------------------------------------------------------- branches
def _check_positive(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not (
            math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class ContinuationOptions:
    """The numerical settings of pseudo-arclength continuation, as
    :class:`opa.SolverOptions` are those of the integrator (``continue_orbits``,
    ``locate_bifurcations``).

    Attributes
    ----------
    step, max_step : first and largest arclength step, in units of the interval length
        (the state counts with its own scale); a step grows by 1.5 after an easy
        correction, up to ``max_step``.
    max_points : the most orbits on one branch.
    max_multiplier : a branch is abandoned once a Floquet multiplier exceeds this in
        modulus (far from an attractor, where nothing a diagram shows can happen).
    switch_amplitude : distance along the -1 eigenvector from a period-doubling orbit to
        the first orbit of the doubled branch.
    tol : Newton tolerance of the shooting (None: ``default_tolerance(system)``).
    transient : forcing periods integrated from a seed before its periodic orbit is
        sought.

    Examples
    --------
    >>> ContinuationOptions(step=0.01, max_points=100).max_step
    0.05
    >>> ContinuationOptions(step=0.0)
    Traceback (most recent call last):
    ...
    ValueError: step must be a finite number > 0, got 0.0
    """

    step: float = 0.02
    max_step: float = 0.05
    max_points: int = 500
    max_multiplier: float = 1e3
    switch_amplitude: float = 1e-3
    tol: float | None = None
    transient: int = 300

    def __post_init__(self):
        _check_steps(self.step, self.max_step, self.max_points)
        for name in ("max_multiplier", "switch_amplitude") + (("tol",) if self.tol is not None
                                                              else ()):
            _check_positive(name, getattr(self, name))
        check_count("transient", self.transient, 0)


#: ``locate_bifurcations``' continuation: steps of 0.02 that do not grow, at most 300
#: orbits on a branch, a branch abandoned beyond |mu| = 10 (no attractor is near)
LOCATE_CONTINUATION = ContinuationOptions(max_step=0.02, max_points=300, max_multiplier=10.0)


def continue_orbits(system: ImpactSystem, parameter: str, start: float, stop: float, *,
                    seed: float | None = None, guess=None, periods: int | None = None,
                    t0: float = 0.0, depth: int = 1,
                    continuation: ContinuationOptions | None = None, xtol: float = 1e-10,
                    progress: bool = False) -> xr.Dataset:
    """Branches of periodic orbits from ``start`` to ``stop`` with their bifurcations.

    The orbit at ``seed`` (default ``start``; ``periodic_orbit`` with ``guess``,
    ``periods`` and the ``transient`` of ``continuation``) is continued to both ends of
    the interval by pseudo-arclength continuation, stable and unstable parts alike. Every
    period doubling is located to ``xtol`` in the parameter and, up to ``depth`` levels
    (where one side of it is stable), the doubled branch (period 2k) is started from it
    and followed to the end of the interval. Folds, grazings and impulse-impact points
    are located along the branch (a fold where a doubled branch meets its parent is that
    parent's doubling); Neimark-Sacker points are interpolated. A branch ends at the
    interval's end, at ``max_points``, where a multiplier exceeds ``max_multiplier``,
    or where the map stops being smooth: an impact meeting an impulse time (marked
    ``impulse-impact``; if an orbit with the two events swapped exists just beyond, a new
    branch goes on from it) or a grazing.

    Parameters
    ----------
    system : the DMR or OPA system (its value of ``parameter`` is ignored).
    parameter : a model parameter name or ``sigma``.
    seed, guess, periods : where the first orbit is sought (``periodic_orbit``).
    t0 : the section time.
    depth : levels of period-doubled branches followed.
    continuation : the continuation's steps, limits and Newton tolerance
        (:class:`ContinuationOptions`; default ``ContinuationOptions()``).
    xtol : tolerance of the located parameter values.
    progress : print a line per branch.

    Returns
    -------
    xarray.Dataset (see ``branch_dataset``).

    Examples
    --------
    >>> from opa import preset
    >>> ds = continue_orbits(ImpactSystem(preset("3.1", F0=0.0)), "c", 0.1, 0.08)
    >>> int(ds.sizes["bifurcation"]) >= 1
    True
    """
    if parameter not in system.continuable:
        raise ValueError(f"parameter must be one of {', '.join(system.continuable)}, got "
                         f"{parameter!r}")
    for name, value in (("start", start), ("stop", stop)):
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value}")
    if start == stop:
        raise ValueError(f"start and stop must differ, got {start}")
    depth = check_count("depth", depth, 0)
    continuation = _check_continuation(continuation, ContinuationOptions())
    t0 = check_time("t0", t0, system.forcing_period)
    bounds = (min(start, stop), max(start, stop))
    tol = default_tolerance(system) if continuation.tol is None else continuation.tol
    seed = start if seed is None else float(seed)
    if not bounds[0] <= seed <= bounds[1]:
        raise ValueError(f"seed must lie between start and stop, got {seed}")
    sys0 = system.with_parameter(parameter, seed)
    orbit = periodic_orbit(sys0, guess, periods=periods, t0=t0,
                           transient=continuation.transient, tol=tol)
    tracer = _Tracer(system, parameter, bounds, depth=depth, continuation=continuation,
                     tol=tol, xtol=xtol, progress=progress)
    tracer.trace(sys0, orbit, ends=(stop, start))
    return branch_dataset(system, parameter, tracer.branches, tracer.bifurcations, t0=t0,
                          settings=dict(start=start, stop=stop, seed=seed, depth=depth,
                                        xtol=xtol, tol=tol))


def _check_continuation(continuation, default: ContinuationOptions) -> ContinuationOptions:
    return check_instance("continuation", continuation, ContinuationOptions, default)


class _Tracer:
    """The branches through a first orbit over ``bounds`` and their bifurcations.

    The work of ``continue_orbits`` once its first orbit is found (:meth:`trace`): follow
    it to each end in turn, locate every event between consecutive orbits, switch onto
    doubled branches up to ``depth`` and across impulse-impact borders. The lists of
    ``Branch`` and ``Bifurcation`` grow in ``branches`` and ``bifurcations``; a branch
    waits in ``queue`` as (system, orbit, end, tangent, parent branch, doubling level).
    """

    MAX_CROSSINGS = 20  # branches started across impulse-impact borders, per trace

    def __init__(self, system: ImpactSystem, parameter: str, bounds: tuple, *, depth: int,
                 continuation: ContinuationOptions, tol: float, xtol: float,
                 progress: bool = False):
        self.system, self.parameter, self.bounds = system, parameter, bounds
        self.depth, self.continuation = depth, continuation
        self.tol, self.xtol, self.progress = tol, xtol, progress
        self.branches: list[Branch] = []
        self.bifurcations: list[Bifurcation] = []
        self.queue: list[tuple] = []
        self.crossings = 0

    def trace(self, sys0: ImpactSystem, orbit: PeriodicOrbit, ends: tuple) -> None:
        """Follow ``orbit`` (at ``sys0``) to each of ``ends``, and every branch it leads
        to; the branches and bifurcations found are added to those found before."""
        seed = sys0.parameter(self.parameter)
        self.queue = [(sys0, orbit, end, None, -1, 0) for end in ends if end != seed]
        self.crossings = 0
        while self.queue:
            sys_b, orb, target, tangent, parent, level = self.queue.pop(0)
            b_id, branch, events = self._follow(sys_b, orb, target, tangent, parent)
            for kind, ia, ib in events:
                if kind == "period-doubling":
                    bif = self._period_doubling(branch, b_id, ia, ib, level)
                else:
                    bif = self._event(kind, branch, b_id, ia, ib)
                    if bif is None:
                        continue
                    if bif.kind == "impulse-impact":
                        self._cross(bif, branch, b_id, target, level)
                self.bifurcations.append(bif)

    def _room(self) -> bool:
        """Whether one more branch may be queued (MAX_BRANCHES bounds the trace)."""
        if len(self.branches) + len(self.queue) < MAX_BRANCHES:
            return True
        note = f"; no further branches (MAX_BRANCHES = {MAX_BRANCHES} reached)"
        if not self.branches[-1].end.endswith(note):
            self.branches[-1].end += note
        return False

    def _follow(self, sys_b, orbit, target, tangent, parent) -> tuple[int, Branch, list]:
        """One branch followed to ``target`` (``follow``) and recorded: (its index, the
        branch, its raw events)."""
        c = self.continuation
        branch, events = follow(sys_b, self.parameter, orbit, target, step=c.step,
                                max_step=c.max_step, max_points=c.max_points, tol=self.tol,
                                bounds=self.bounds, initial_tangent=tangent,
                                max_multiplier=c.max_multiplier)
        branch.parent = parent
        b_id = len(self.branches)
        self.branches.append(branch)
        if self.progress:
            print(f"  branch {b_id}: period {branch.periods}, {len(branch.orbits)} points, "
                  f"{self.parameter} in [{min(branch.values):.6g}, "
                  f"{max(branch.values):.6g}]; {branch.end}")
        return b_id, branch, events

    def _period_doubling(self, branch: Branch, b_id: int, ia: int, ib: int,
                         level: int) -> Bifurcation:
        """The doubling between orbits ``ia``, ``ib`` located (or interpolated, if it
        cannot be), and the doubled branch queued from it when it changes an attractor
        and ``level`` is below ``depth``."""
        parameter, oa, ob = self.parameter, branch.orbits[ia], branch.orbits[ib]
        a, b = (branch.values[ia], oa), (branch.values[ib], ob)
        try:
            o_pd = locate_period_doubling(self.system, parameter, a, b, xtol=self.xtol,
                                          tol=self.tol)
            located = True
            value = o_pd.system.parameter(parameter)
        except (ConvergenceError, SimulationError, ValueError):
            o_pd, located, value = None, False, 0.5 * (a[0] + b[0])
        bif = Bifurcation("period-doubling", value, b_id, located, o_pd,
                          attracting=oa.stable or ob.stable, between=(ia, ib))
        if o_pd is None:
            return bif
        bif.x, bif.v = float(o_pd.state[0]), float(o_pd.state[o_pd.system.order + 1])
        if level < self.depth and bif.attracting:
            doubled = (_doubled_seed(o_pd, parameter, self.continuation.switch_amplitude,
                                     self.tol) if self._room() else None)
            if doubled is not None:
                sys2, o2, ahead = doubled
                bif.child = len(self.branches) + len(self.queue)
                end = self.bounds[1] if ahead else self.bounds[0]
                self.queue.append((sys2, o2, end, None, b_id, level + 1))
        return bif

    def _event(self, kind: str, branch: Branch, b_id: int, ia: int,
               ib: int) -> Bifurcation | None:
        """Any other event between orbits ``ia``, ``ib`` (``ia == ib``: the branch's
        end) as a bifurcation, located where it can be; None where it is none (an end
        for no reason of the map, a branch of one orbit, a collapse onto an orbit that
        is not the parent's doubling)."""
        oa, ob = branch.orbits[ia], branch.orbits[ib]
        if kind == "end":
            kind = _end_kind(branch, ob)
            if kind is None:
                return None
        if ia == ib and len(branch.orbits) < 2 and kind != "collapse":
            return None  # ends at its first orbit: nothing to place the end by
        value, o, located = self._locate(kind, branch, ia, ib)
        if kind in ("fold", "collapse"):  # the parent's doubling (a doubled branch)?
            d = (max(abs(value - branch.values[ia]), abs(value - branch.values[ib]))
                 if kind == "fold" else abs(value - branch.values[max(ib - 1, 0)]))
            o_pd = _collapsed(self.system, self.parameter, ob, value, d, xtol=self.xtol,
                              tol=self.tol)
            if o_pd is None and kind == "collapse":
                return None
            if o_pd is not None:
                kind, o, located = "period-doubling", o_pd, True
                value = o_pd.system.parameter(self.parameter)
        return Bifurcation(kind, value, b_id, located, o if located else None,
                           x=float(o.state[0]), v=float(o.state[o.system.order + 1]),
                           attracting=oa.stable or ob.stable, between=(ia, ib))

    def _locate(self, kind: str, branch: Branch, ia: int, ib: int) -> tuple:
        """(value, orbit, located) of a fold (root-found), a grazing or the end of a
        branch (extrapolated, ``locate_edge``); where that fails or does not apply, the
        interpolated value and the orbit ``ia``."""
        system, parameter, tol, xtol = self.system, self.parameter, self.tol, self.xtol
        oa, ob = branch.orbits[ia], branch.orbits[ib]
        located, o = False, oa
        value = branch.values[ib] if kind == "collapse" else _interpolate(kind, branch, ia, ib)
        try:
            if kind == "fold":
                o = locate_fold(system, parameter, (branch.values[ia], oa),
                                (branch.values[ib], ob),
                                scale=self.bounds[1] - self.bounds[0], tol=tol)
                located, value = True, o.system.parameter(parameter)
            elif kind == "grazing" and ia != ib:
                # approach from the side without the grazing impact (smooth)
                i, j = (ia - 1, ia) if oa.impacts < ob.impacts else (ib + 1, ib)
                if 0 <= i < len(branch.orbits):
                    value, o = locate_edge(
                        system, parameter, (branch.values[i], branch.orbits[i]),
                        (branch.values[j], branch.orbits[j]), _gap, xtol=xtol, tol=tol)
                    located = True
            elif kind != "collapse" and ia == ib and len(branch.orbits) > 1:
                measure = (_separation if kind == "impulse-impact" else _graze_measure)
                value, o = locate_edge(
                    system, parameter, (branch.values[-2], branch.orbits[-2]),
                    (branch.values[-1], branch.orbits[-1]), measure, xtol=xtol, tol=tol)
                located = True
        except (ConvergenceError, SimulationError, ValueError):
            located, o = False, oa
        return value, o, located

    def _cross(self, bif: Bifurcation, branch: Branch, b_id: int, target: float,
               level: int) -> None:
        """Queue the branch beyond an impulse-impact border, if the orbit goes on there
        with the events swapped (at most MAX_CROSSINGS times per trace)."""
        if self.crossings < self.MAX_CROSSINGS and self._room():
            across = _cross_impulse(self.system, self.parameter, branch, bif.value,
                                    self.bounds, self.tol)
            if across is not None:
                self.crossings += 1
                bif.child = len(self.branches) + len(self.queue)
                self.queue.append((across[0], across[1], target, None, b_id, level))


def _end_kind(branch: Branch, last: PeriodicOrbit) -> str | None:
    """Why a branch ended at ``last``, as a bifurcation kind (its ``end`` told so), or
    None where the map gives no reason (the corrector failed, a non-smooth turn)."""
    if last.impulse_separation < NEAR:
        branch.end += "; an impact meets an impulse time (map discontinuous)"
        return "impulse-impact"
    if last.min_impact_velocity < NEAR or last.min_gap < NEAR:
        branch.end += "; grazing"
        return "grazing"
    return None


def _cross_impulse(system, parameter, branch, border, bounds, tol):
    """An orbit just beyond an impulse-impact discontinuity, with the events swapped.

    Newton shooting from the last orbit of ``branch`` at parameter values a little past
    the extrapolated border, in the direction of travel; accepted only with the same
    number of impacts and a different impact/impulse order. None if there is none (the
    branch then really ends: a gap in the parameter without this orbit).
    """
    last = branch.orbits[-1]
    lam_last = branch.values[-1]
    direction = np.sign(lam_last - branch.values[-2]) if len(branch.values) > 1 else 0.0
    if direction == 0.0:
        return None
    scale = bounds[1] - bounds[0]
    for step in (1e-5, 1e-4, 1e-3):
        lam = border + direction * step * scale
        if not bounds[0] <= lam <= bounds[1]:
            return None
        sys_ = system.with_parameter(parameter, lam)
        try:
            o = shoot(sys_, last.state, periods=last.periods, t0=last.t0, tol=tol,
                      max_iter=SHOOT_NEAR)
        except (ConvergenceError, SimulationError, ValueError):
            continue
        if o.impacts == last.impacts and o.impulse_order != last.impulse_order:
            return sys_, o
    return None


def _doubled_seed(o_pd: PeriodicOrbit, parameter: str, amplitude: float, tol: float):
    """First point of the doubled branch: Newton on P^{2k} from the PD orbit along v.

    Pseudo-arclength from the bifurcation point with the initial tangent (v, 0): for
    ``P^{2k}`` the period-doubling is a pitchfork, the doubled branch leaving the old
    one perpendicular to the parameter axis. Both the step and its sign are tried; a
    point counts only if it is a genuine 2k-orbit (``P^k(y) != y``).
    """
    system = o_pd.system
    k2 = 2 * o_pd.periods
    v = o_pd.eigenvector(-1.0)
    lam0 = system.parameter(parameter)
    L = max(abs(lam0), 1.0) * 0.05
    cont = _Continuation(system, parameter, lam0 - L, lam0 + L, k2, o_pd.t0, tol=tol, scale=L)
    u0 = np.concatenate([o_pd.state, [lam0 / L]])
    t = np.concatenate([v, [0.0]])
    for amp in (amplitude, 3 * amplitude, 10 * amplitude, 0.3 * amplitude):
        for sign in (1.0, -1.0):
            try:
                got = cont.correct(u0 + sign * amp * t, sign * t, max_iter=12)
            except (SimulationError, ValueError):
                got = None
            if got is None:
                continue
            y, lam, J, iters = got
            sys_ = system.with_parameter(parameter, lam)
            half = flow(sys_, y, [o_pd.t0, o_pd.t0 + o_pd.periods * sys_.forcing_period])
            if np.max(np.abs(half.states[-1] - y)) < 10 * amp * 1e-2:
                continue  # fell back onto the period-k orbit
            o2 = _orbit(sys_, y, k2, o_pd.t0, J, _residual(y, flow(
                sys_, y, [o_pd.t0, o_pd.t0 + k2 * sys_.forcing_period]).states[-1]), iters)
            return sys_, o2, lam > lam0  # continue away from the bifurcation
    return None


def _none_as_nan(values) -> np.ndarray:
    """An orbit's minimum over no event (inf inside, where comparisons need it) as NaN,
    the datasets' one word for "none"."""
    out = np.array(values, dtype=float)
    out[np.isinf(out)] = np.nan
    return out


def branch_dataset(system: ImpactSystem, parameter: str, branches: list, bifurcations: list,
                   *, t0: float = 0.0, settings: dict | None = None) -> xr.Dataset:
    """Labelled dataset of the branches (one ``point`` per orbit) and bifurcations.

    Variables over ``point``: the parameter (coordinate named after it), ``branch``,
    ``period`` (k), ``impacts`` (per period of the orbit), ``stable`` (1/0),
    ``spectral_radius``, ``min_impact_velocity``, ``min_gap``; over ``(point, strobe)``:
    ``section_x``, ``section_v`` (the mean coordinate at t0 + j T, NaN past the period);
    over ``(point, component)``: ``state``; over ``(point, multiplier)``:
    ``multiplier_real``, ``multiplier_imag``. Over ``bifurcation``:
    ``bifurcation_kind`` (flag values 0..4: period-doubling fold neimark-sacker
    grazing impulse-impact), ``bifurcation_<parameter>``, ``bifurcation_branch``, ``bifurcation_x``,
    ``bifurcation_v``, ``bifurcation_located`` (1: located to xtol), ``bifurcation_child``
    (the branch switched onto, -1 if none). Over ``branch_id``: ``branch_period``,
    ``branch_parent``.
    """
    D = system.dim
    n = system.order + 1
    rows = [(b, lam, o) for b, br in enumerate(branches) for lam, o in zip(br.values, br.orbits)]
    kmax = max([o.periods for _, _, o in rows] + [1])
    P = len(rows)
    sx = np.full((P, kmax), np.nan)
    sv = np.full((P, kmax), np.nan)
    state = np.empty((P, D))
    mr = np.empty((P, D))
    mi = np.empty((P, D))
    for i, (_, _, o) in enumerate(rows):
        sx[i, : o.periods] = o.points[:, 0]
        sv[i, : o.periods] = o.points[:, n]
        state[i] = o.state
        mr[i] = o.multipliers.real
        mi[i] = o.multipliers.imag
    one = {"units": "1"}
    kinds = np.array([BIFURCATION_KINDS.index(b.kind) for b in bifurcations], dtype=np.int8)
    ds = xr.Dataset(
        {
            "branch": ("point", np.array([b for b, _, _ in rows], dtype=np.int32),
                       {"long_name": "branch index", **one}),
            "period": ("point", np.array([o.periods for *_, o in rows], dtype=np.int32),
                       {"long_name": "period of the orbit in forcing periods 2 pi/omega", **one}),
            "impacts": ("point", np.array([o.impacts for *_, o in rows], dtype=np.int32),
                        {"long_name": "impacts per period of the orbit", **one}),
            "stable": ("point", np.array([o.stable for *_, o in rows], dtype=np.int8),
                       {"long_name": "1 if every Floquet multiplier is inside the unit circle",
                        **one}),
            "spectral_radius": ("point", np.array([o.spectral_radius for *_, o in rows]),
                                {"long_name": "largest Floquet multiplier modulus", **one}),
            "min_impact_velocity": ("point", _none_as_nan(
                                    [o.min_impact_velocity for *_, o in rows]),
                                    {"long_name": "smallest pre-impact velocity on the orbit "
                                                  "(NaN: no impact)", **one}),
            "min_gap": ("point", _none_as_nan([o.min_gap for *_, o in rows]),
                        {"long_name": "smallest distance of a free-flight maximum of x_0 "
                                      "below the wall, or of a minimum above a lower wall "
                                      "(NaN: no free-flight extremum, every flight ends at "
                                      "a wall)", **one}),
            "section_x": (("point", "strobe"), sx,
                          {"long_name": "x_0 at t0 + j 2 pi/omega (stroboscopic points)", **one}),
            "section_v": (("point", "strobe"), sv,
                          {"long_name": "v_0 at t0 + j 2 pi/omega (stroboscopic points)", **one}),
            "state": (("point", "component"), state,
                      {"long_name": "orbit state [x_0..x_N, v_0..v_N] at t0", **one}),
            "multiplier_real": (("point", "multiplier"), mr,
                                {"long_name": "Floquet multipliers, real part", **one}),
            "multiplier_imag": (("point", "multiplier"), mi,
                                {"long_name": "Floquet multipliers, imaginary part", **one}),
            "bifurcation_kind": ("bifurcation", kinds,
                                 {"long_name": "kind of bifurcation",
                                  "flag_values": np.arange(len(BIFURCATION_KINDS), dtype=np.int8),
                                  "flag_meanings": " ".join(k.replace("-", "_")
                                                            for k in BIFURCATION_KINDS)}),
            f"bifurcation_{parameter}": ("bifurcation",
                                         np.array([b.value for b in bifurcations], dtype=float),
                                         {"long_name": f"{parameter} at the bifurcation", **one}),
            "bifurcation_branch": ("bifurcation",
                                   np.array([b.branch for b in bifurcations], dtype=np.int32),
                                   {"long_name": "branch the bifurcation lies on", **one}),
            "bifurcation_x": ("bifurcation", np.array([b.x for b in bifurcations], dtype=float),
                              {"long_name": "x_0 at t0 of the orbit at the bifurcation", **one}),
            "bifurcation_v": ("bifurcation", np.array([b.v for b in bifurcations], dtype=float),
                              {"long_name": "v_0 at t0 of the orbit at the bifurcation", **one}),
            "bifurcation_located": ("bifurcation",
                                    np.array([b.located for b in bifurcations], dtype=np.int8),
                                    {"long_name": "1 if located by root finding to xtol, 0 if "
                                                  "interpolated", **one}),
            "bifurcation_child": ("bifurcation",
                                  np.array([b.child for b in bifurcations], dtype=np.int32),
                                  {"long_name": "branch started at this bifurcation (-1: none)",
                                   **one}),
            "branch_period": ("branch_id", np.array([b.periods for b in branches], dtype=np.int32),
                              {"long_name": "period of the branch's orbits", **one}),
            "branch_parent": ("branch_id", np.array([b.parent for b in branches], dtype=np.int32),
                              {"long_name": "branch this one was switched from (-1: none)", **one}),
        },
        coords={
            parameter: ("point", np.array([lam for _, lam, _ in rows], dtype=float),
                        {"long_name": f"continuation parameter {parameter}", **one}),
            "point": np.arange(P),
            "strobe": np.arange(kmax),
            "component": np.arange(D),
            "multiplier": np.arange(D),
            "bifurcation": np.arange(len(bifurcations)),
            "branch_id": np.arange(len(branches)),
        },
        attrs=system.attrs(),
    )
    ds.attrs.update(
        analysis="periodic-orbit continuation (pseudo-arclength, Newton shooting, saltation "
                 "matrices)",
        parameter=parameter,
        t0=float(t0),
        branch_end="; ".join(f"{i}: {b.end}" for i, b in enumerate(branches)),
    )
    for key, value in (settings or {}).items():
        ds.attrs[f"continuation_{key}"] = float(value)
    return ds


# --------------------------------------------------------------------------- located points
@dataclass(frozen=True)
class Located:
    """A bifurcation of a periodic attractor, located on its branch.

    Attributes
    ----------
    kind : one of ``BIFURCATION_KINDS``: ``period-doubling`` (a multiplier of ``P^k``
        through -1), ``fold`` (through +1: a stable and an unstable orbit meet),
        ``grazing`` (an impact with zero velocity), ``impulse-impact`` (an impact meets
        a Dirac impulse time or a pulse edge: the map is not smooth there),
        ``neimark-sacker`` (a complex pair leaves the unit circle).
    value : the parameter value.
    period : k, the period of the orbit in forcing periods (before the doubling).
    multiplier : the critical Floquet multiplier of ``P^k`` at the point: the one
        nearest -1 (period doubling), +1 (fold), the unit circle (Neimark-Sacker), or
        the largest in modulus (grazing, impulse-impact, where none need be critical).
    located : True when root-found or extrapolated to ``xtol``; False when only
        interpolated between two orbits of the branch.
    note : what happens there, in words.
    x, v : x_0 and v_0 of the orbit at the section time t0 at (or next to) the point.
    """

    kind: str
    value: float
    period: int
    multiplier: complex
    located: bool
    note: str
    x: float = math.nan
    v: float = math.nan


def _critical(kind: str, orbit: PeriodicOrbit) -> complex:
    mu = orbit.multipliers
    if kind == "period-doubling":
        return complex(mu[np.argmin(np.abs(mu + 1.0))])
    if kind == "fold":
        return complex(mu[np.argmin(np.abs(mu - 1.0))])
    if kind == "neimark-sacker":
        cplx = np.abs(mu.imag) > 1e-12
        if cplx.any():
            pick = np.flatnonzero(cplx)
            return complex(mu[pick[np.argmin(np.abs(np.abs(mu[pick]) - 1.0))]])
    return complex(mu[0])  # sorted by decreasing modulus


def _note(bif: Bifurcation, branch: Branch, parameter: str) -> str:
    """A one-line description of a bifurcation on ``branch``."""
    ia, ib = bif.between
    oa, ob = branch.orbits[ia], branch.orbits[ib]
    la, lb = branch.values[ia], branch.values[ib]
    k = (bif.orbit or oa).periods
    label = (bif.orbit or oa).label
    stable_at = lb if ob.stable else la if oa.stable else None

    def side(value):
        return f"{parameter} {'>' if value > bif.value else '<'} {bif.value:.7g}"

    if bif.kind == "period-doubling":
        text = f"period {k} -> {2 * k}: a multiplier of P^{k} crosses -1 (orbit {label}"
        if k != branch.periods:
            text += f"; found where the period-{branch.periods} branch turns back onto it"
        elif stable_at is not None:
            text += f", stable for {side(stable_at)}"
        text += ")"
    elif bif.kind == "fold":
        pair = ("a stable and an unstable period-{k} orbit" if (oa.stable or ob.stable)
                else "two unstable period-{k} orbits").format(k=k)
        text = f"{pair} ({label}) meet; none for {side(2 * bif.value - la)}"
    elif bif.kind == "grazing":
        if ia != ib:
            text = (f"an impact of the period-{k} orbit ({label}) grazes: {oa.impacts} -> "
                    f"{ob.impacts} impacts per {k} periods")
        else:
            text = f"the period-{k} orbit ({label}) grazes and its branch ends"
    elif bif.kind == "impulse-impact":
        what = ("an impulse time (the map is discontinuous)"
                if branch.orbits[0].system.impulse == "dirac" else
                "a pulse edge (the map is not smooth)")
        text = f"an impact of the period-{k} orbit ({label}) meets {what}; "
        text += ("the orbit goes on beyond with impact and impulse swapped" if bif.child >= 0
                 else f"no such orbit for {side(2 * bif.value - lb)}")
    else:
        text = f"a complex pair of multipliers of the period-{k} orbit ({label}) crosses |mu| = 1"
    return text + ("" if bif.located else " (interpolated)")


def _known(points: np.ndarray, value: float, branches: list) -> bool:
    """Whether the stroboscopic points ``points`` (k, 2) of a period-k orbit at
    ``value``, as (x_0, v_0), are those of an orbit on one of ``branches``: as a set
    (whatever the phase), close to the points interpolated between two orbits of a
    branch of period k that bracket ``value``."""
    k = len(points)
    scale = 1.0 + np.max(np.abs(points))
    for br in branches:
        if br.periods != k:
            continue
        n = br.orbits[0].system.order + 1
        for i in range(len(br.values) - 1):
            la, lb = br.values[i], br.values[i + 1]
            if not min(la, lb) <= value <= max(la, lb):
                continue
            frac = (value - la) / (lb - la) if lb != la else 0.0
            pa = br.orbits[i].points[:, [0, n]]
            pb = br.orbits[i + 1].points[:, [0, n]]
            ref = pa + frac * (pb - pa)
            near = max(1e-3 * scale, float(np.max(np.abs(pb - pa))))
            dist = np.max(np.abs(points[:, None, :] - ref[None, :, :]), axis=2)
            if np.max(np.min(dist, axis=1)) <= near:
                return True
    return False


def _seed_items(seeds, lo: float, hi: float) -> list:
    """Seeds as (value, state or None, time, points or None), in the order given."""
    if isinstance(seeds, (int, np.integer)) and not isinstance(seeds, bool):
        n = check_count("seeds", seeds, 1)
        values = [0.5 * (lo + hi)] if n == 1 else np.linspace(hi, lo, n).tolist()
        return [(float(v), None, 0.0, None) for v in values]
    items = []
    for item in seeds:
        if isinstance(item, (tuple, list)):
            if len(item) not in (2, 3, 4):
                raise ValueError("a seed is a value, (value, state), (value, state, time) or "
                                 f"(value, state, time, points); got {len(item)} items")
            value, state, time_, points = (*item, 0.0, None, None)[:4]
        else:
            value, state, time_, points = item, None, 0.0, None
        value = float(value)
        if not (math.isfinite(value) and lo <= value <= hi):
            raise ValueError(f"seed values must lie in [{lo:g}, {hi:g}], got {value!r}")
        if points is not None:
            points = np.asarray(points, dtype=float).reshape(-1, 2)
        items.append((value, state, float(time_), points))
    return items


def _seed_orbit(system: ImpactSystem, state, time_: float, transient: int, tol: float
                ) -> PeriodicOrbit:
    """The periodic orbit reached from x0, v0 (``state`` None) or from ``state`` at
    ``time_`` (advanced to the next start of the forcing cycle first)."""
    if state is None:
        return periodic_orbit(system, transient=transient, tol=tol)
    cycle = impulse_cycle(system.oscillator) * system.forcing_period
    start = math.ceil(time_ / cycle - 1e-9) * cycle
    y = np.asarray(state, dtype=float).ravel()
    if start > time_:
        y = flow(system, y, [time_, start]).states[-1]
    return periodic_orbit(system, guess=y, transient=0, tol=tol)


def check_locatable(system: ImpactSystem, parameter: str, lo: float, hi: float) -> int:
    """Refuse (``ValueError``, saying why) what ``locate_bifurcations`` cannot do: a
    parameter that is not continued (``x0``, ``v0`` only pick the attractor) or one
    that changes the forcing's common period (``impulse_cycle``) over ``[lo, hi]``.
    Returns that period k0 (in forcing periods)."""
    if parameter not in system.continuable:
        why = (f"{parameter} only selects the attractor, it moves no bifurcation"
               if parameter in ("x0", "v0") else f"choose from {', '.join(system.continuable)}")
        raise ValueError(f"bifurcations cannot be located in {parameter}: {why}")
    cycles = {impulse_cycle(system.with_parameter(parameter, v).oscillator)
              for v in (lo, 0.5 * (lo + hi), hi)}
    if len(cycles) > 1 or None in cycles:
        raise ValueError(
            f"the forcing's common period (impulse_cycle) changes with {parameter} over "
            f"[{lo:g}, {hi:g}] ({', '.join(str(c) for c in sorted(cycles, key=str))} forcing "
            "periods): there is no one stroboscopic map to continue (set F0 = 0 or sweep "
            "another parameter)")
    return cycles.pop()


def locate_bifurcations(oscillator: Oscillator | ImpactSystem, parameter: str, lo: float,
                        hi: float, *, options: SolverOptions | None = None, seeds=9,
                        depth: int = 2, continuation: ContinuationOptions | None = None,
                        xtol: float = 1e-10, unstable: bool = False,
                        progress: bool = False) -> list[Located]:
    """Bifurcations of the periodic attractors in ``lo <= parameter <= hi``, located.

    At each seed value the attractor is found (``periodic_orbit``); a stable orbit not
    already on a branch is continued to both ends of the interval (``continue_orbits``'
    machinery: pseudo-arclength continuation of the fixed points of ``P^k``, exact
    Jacobians with saltation matrices). Along the branches period doublings
    (``det(DP^k + I) = 0``), folds (``det(DP^k - I) = 0``) and grazings are root-found to
    ``xtol``, the ends of branches where an impact meets an impulse time are extrapolated
    to ``xtol`` (``locate_edge``); up to ``depth`` levels of doubled branches are
    followed from the doublings. With impulses (``F0 != 0``) the orbits are fixed points
    of ``P^k0`` (``impulse_cycle``), so a doubling there is ``k0 T -> 2 k0 T``.

    Parameters
    ----------
    oscillator : the model parameters (DMR, with ``options``), an ``opa.System`` (its
        DMR, with ``options``) or an ``ImpactSystem`` (DMR or OPA system) whose value of
        ``parameter`` is ignored.
    parameter : a model parameter name or ``sigma``; the forcing's common period
        (``impulse_cycle``) must not change over the interval.
    lo, hi : the interval.
    seeds : where to look for attractors: a number of evenly spaced values (from ``hi``
        down, ends included), or a sequence of values, ``(value, state)`` pairs (state at
        t = 0, or at a multiple of the forcing cycle), ``(value, state, time)`` (e.g. the
        final state of a sweep's run, at its end time) or ``(value, state, time,
        points)``, where ``points`` (p, 2) are the p stroboscopic (x_0, v_0) points of
        the period-p motion observed there: a seed whose points lie on a branch already
        followed is skipped without any integration. A value seeds the orbit reached
        after ``continuation.transient`` periods from x0, v0; a state, the orbit reached
        from it. Unstable and non-periodic seeds are skipped, and so are orbits on a
        branch already followed.
    depth : levels of period-doubled branches followed (2: periods k, 2k, 4k, so three
        doublings located).
    continuation : the continuation's steps, limits, Newton tolerance and transient
        (:class:`ContinuationOptions`; default ``LOCATE_CONTINUATION``: arclength steps
        of 0.02 that do not grow, at most 300 orbits on a branch, a branch abandoned once
        a multiplier exceeds 10 in modulus, far from an attractor, where nothing a
        diagram shows can happen).
    xtol : the tolerance of the located parameter values.
    unstable : also report bifurcations between two unstable orbits (default: only those
        next to a stable orbit, which change an attractor).
    progress : print a line per seed and per branch.

    Returns
    -------
    list of ``Located``, by increasing value.

    Performance: a few seconds for section 3.1 with F0 = 0 over c in [0.01, 0.1], and
    about 5-10 s with the default impulses (orbits of ``P^14``) on one core; most of it
    in the continuation of the doubled branches (``depth``).

    Examples
    --------
    >>> from opa import preset
    >>> pts = locate_bifurcations(preset("3.1", F0=0.0), "c", 0.08, 0.1, seeds=1)
    >>> [(p.kind, round(p.value, 7), p.period) for p in pts]
    [('period-doubling', 0.0891223, 1)]
    """
    system = _impact_system(oscillator, options)
    lo, hi = _check_interval(lo, hi)
    depth = check_count("depth", depth, 0)
    continuation = _check_continuation(continuation, LOCATE_CONTINUATION)
    _check_positive("xtol", xtol)
    check_locatable(system, parameter, lo, hi)
    tol = default_tolerance(system) if continuation.tol is None else continuation.tol
    branches: list[Branch] = []
    found: list[Located] = []
    for seed in _seed_items(seeds, lo, hi):
        start = _attractor_to_follow(system, parameter, seed, branches, continuation.transient,
                                     tol, progress)
        if start is None:
            continue
        tracer = _Tracer(system, parameter, (lo, hi), depth=depth, continuation=continuation,
                         tol=tol, xtol=xtol, progress=progress)
        tracer.trace(*start, ends=(lo, hi))
        branches += tracer.branches
        found += [_located(bif, tracer.branches[bif.branch], parameter)
                  for bif in tracer.bifurcations if bif.attracting or unstable]
    return _distinct(found, hi - lo)


def _impact_system(oscillator, options: SolverOptions | None) -> ImpactSystem:
    """The ImpactSystem of ``locate_bifurcations``' first argument."""
    if isinstance(oscillator, ImpactSystem):
        if options is not None:
            raise ValueError("options belong to the ImpactSystem: give them there")
        return oscillator
    if isinstance(oscillator, System):
        return ImpactSystem.of(oscillator, options=options)
    return ImpactSystem(oscillator, options=options or SolverOptions())


def _check_interval(lo, hi) -> tuple[float, float]:
    for name, value in (("lo", lo), ("hi", hi)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not (
                math.isfinite(value)):
            raise ValueError(f"{name} must be a finite number, got {value!r}")
    lo, hi = float(lo), float(hi)
    if not lo < hi:
        raise ValueError(f"lo must be < hi, got lo = {lo:g}, hi = {hi:g}")
    return lo, hi


def _attractor_to_follow(system: ImpactSystem, parameter: str, seed: tuple, branches: list,
                         transient: int, tol: float, progress: bool) -> tuple | None:
    """(system, orbit) of the attractor at a seed (``_seed_items``), or None where there is
    none to follow: its points or its orbit on one of ``branches`` already, no periodic
    orbit, or an unstable one."""
    value, state, time_, points = seed
    if points is not None and _known(points, value, branches):
        return None  # the motion seen there is on a branch already followed
    sys_v = system.with_parameter(parameter, value)
    try:
        orbit = _seed_orbit(sys_v, state, time_, transient, tol)
    except (ConvergenceError, SimulationError, ValueError) as err:
        if progress:
            print(f"  seed {parameter} = {value:.6g}: no periodic orbit ({err})")
        return None
    n = system.order + 1
    if not orbit.stable or _known(orbit.points[:, [0, n]], value, branches):
        if progress:
            why = "unstable" if not orbit.stable else "on a branch already followed"
            print(f"  seed {parameter} = {value:.6g}: {orbit.label} orbit {why}")
        return None
    if progress:
        print(f"  seed {parameter} = {value:.6g}: {orbit.label} orbit, following it")
    return sys_v, orbit


def _located(bif: Bifurcation, branch: Branch, parameter: str) -> Located:
    o = bif.orbit or branch.orbits[bif.between[0]]
    return Located(bif.kind, float(bif.value), o.periods, _critical(bif.kind, o),
                   bool(bif.located), _note(bif, branch, parameter), x=bif.x, v=bif.v)


def _distinct(found: list, length: float) -> list[Located]:
    """The points by increasing value, each once (the same point may be reached from two
    seeds: same kind and period within 1e-6 of the interval's ``length``)."""
    found = sorted(found, key=lambda p: p.value)
    out: list[Located] = []
    for p in found:
        if not any(q.kind == p.kind and q.period == p.period
                   and abs(q.value - p.value) <= 1e-6 * length for q in out):
            out.append(p)
    return out



def orbit_dataset(system: ImpactSystem, orbit: PeriodicOrbit, *, t0: float = 0.0):
    """One periodic orbit as a dataset of :func:`branch_dataset`'s layout: one branch of
    one orbit, in the parameter ``c`` at the system's value (``end = "single orbit"``),
    the form ``opa-mc stability`` writes without ``--sweep``.

    >>> import opa
    >>> system = opa.ImpactSystem.of(opa.System(opa.preset("3.1", F0=0.0)))
    >>> ds = orbit_dataset(system, opa.periodic_orbit(system))
    >>> ds.sizes["branch_id"], ds.sizes["point"], int(ds.period[0])
    (1, 1, 2)
    """
    branch = Branch(parameter="c", periods=orbit.periods, values=[system.oscillator.c],
                    orbits=[orbit], end="single orbit")
    return branch_dataset(system, "c", [branch], [], t0=t0)

__all__ = [
    "Bifurcation",
    "Branch",
    "BIFURCATION_KINDS",
    "ContinuationOptions",
    "LOCATE_CONTINUATION",
    "Located",
    "check_locatable",
    "follow",
    "locate_bifurcations",
    "locate_edge",
    "locate_period_doubling",
    "locate_fold",
    "continue_orbits",
    "branch_dataset",
    "orbit_dataset",
]
