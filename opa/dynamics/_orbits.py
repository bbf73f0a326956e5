"""Stability of impacting orbits: the exact Jacobian of the stroboscopic Poincaré map,
periodic orbits by Newton shooting, Floquet multipliers and Lyapunov exponents.

The map is ``P: y(t0) -> y(t0 + k T)``, ``T = 2 pi / omega``, of the DMR (eq. (29)) or
of the OPA equivalent system of any order N (eqs. (24)-(28)); states are
right-continuous (just after an impulse or impact at that instant). Its Jacobian comes
from the variational equation carried through every impact with the saltation matrix
of the impact law (the kernel ``opa._kernel`` with m tangent columns), so it is exact
up to the integration tolerance; ``tests/opa/dynamics/test_orbits.py`` checks it against
finite differences of plain trajectories and against an independent scipy reference.

Impulses. With ``F0 = 0`` the system is T-periodic and every ``k >= 1`` gives an
autonomous map. With Dirac or pulse impulses at ``t_j = j 2 pi/omega1`` of amplitude
``F0 (1 + a1 sin(2 pi j / n))`` the forcing repeats only over the common period of the
harmonic forcing and of the impulse train: ``k0`` forcing periods, the smallest ``k``
with ``k T`` a multiple of the train's period (``impulse_cycle``; 14 for section 3.1,
where ``T1 = 2.8 T`` and the amplitude is constant for n = 2). Periodic orbits and
multipliers are then those of ``P^(k0)`` (``periods`` must be a multiple of ``k0``).
When ``omega1 / omega`` is irrational (or the common period is longer than
``MAX_CYCLE`` forcing periods) no stroboscopic map is autonomous and only Lyapunov
exponents are meaningful: ``lyapunov_exponent`` works for any forcing.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from opa._model import (
    _finite,
    IMPACT_LAWS,
    Oscillator,
    SolverOptions,
    _choice,
)
from opa._run import SimulationError, Variational, run
from opa._system import SWEEPABLE, SYSTEM_FIELDS, System

# The variational kernel implements the mean and ensemble laws (not saltation).
STABILITY_LAWS = IMPACT_LAWS[:2]

ORBIT_MODELS = ("dmr", "opa")
MAX_CYCLE = 1000  # longest common period (in forcing periods) accepted for a map
ORBIT_GRAZE_VELOCITY = 1e-3  # classification: impacts slower than this are (near) grazing
ORBIT_GRAZE_GAP = 1e-3  # classification: free-flight maxima closer than this to the wall
CRITICAL_TOL = 1e-3  # classification: |mu + 1|, |mu - 1|, ||mu| - 1| below this
# Times: the kernel cannot take a step shorter than STEP_FLOOR |t| (round-off of t), so a
# time is resolvable only while that floor is at most TIME_RESOLUTION of a forcing period,
# i.e. |t| <= 1e8 T (t + T == t long before that for t = 1e300).
STEP_FLOOR = 1e-14
TIME_RESOLUTION = 1e-6
LINE_SEARCH_HALVINGS = 20  # Newton's backtracking: step lengths 1, 1/2, ..., ~1e-6


class ConvergenceError(SimulationError):
    """Newton shooting (or a continuation corrector) did not converge."""


# --------------------------------------------------------------------------- the system
@dataclass(frozen=True)
class ImpactSystem(System):
    """The impact system whose stroboscopic map is studied: DMR or OPA of order N.

    An :class:`opa.System` (every field of it, with the same names and defaults) with the
    model and the solver options.

    Parameters
    ----------
    oscillator : model parameters (paper eq. (1)); x0, v0 only start transients.
    model : ``"dmr"`` (eq. (29), state (x, v); the uncertainty and the closures are not
        part of it: sigma, order are set to 0) or ``"opa"`` (eqs. (24)-(28), state
        ``[x_0..x_N, v_0..v_N]``, xi with the semicircle law, impact law ``mean`` or
        ``ensemble``).
    options : solver options; ``rtol``/``atol`` control the state and the variational
        matrix alike.

    Examples
    --------
    >>> from opa import preset
    >>> ImpactSystem(preset("3.1", F0=0.0)).dim
    2
    >>> ImpactSystem(preset("3.1"), model="opa", order=4, sigma=0.01).dim
    10
    """

    model: str = "dmr"
    options: SolverOptions = field(default_factory=SolverOptions)
    _packed: object = field(init=False, repr=False, compare=False, default=None)  # Inputs

    def __post_init__(self):
        _choice("model", self.model, ORBIT_MODELS)
        if not isinstance(self.options, SolverOptions):
            raise ValueError(f"options must be an opa.SolverOptions, got {self.options!r}")
        for name, value in self.options.legacy_impulse.items():  # deprecated spelling
            object.__setattr__(self, name, value)
        if self.model == "dmr":
            object.__setattr__(self, "sigma", 0.0)
            object.__setattr__(self, "order", 0)
        super().__post_init__()
        if self.model == "opa":
            _choice("impact_law", self.impact_law, STABILITY_LAWS)
            if self.distribution is not None:
                raise ValueError("the stability of the OPA system is implemented for the "
                                 "semicircle law of xi only (distribution=None)")
            self.check_samples()
        object.__setattr__(self, "_packed", self.kernel_inputs(self.options))

    @classmethod
    def of(cls, system: System, *, model: str = "dmr",
           options: SolverOptions | None = None) -> ImpactSystem:
        """The ImpactSystem of a :class:`opa.System` under ``model``."""
        return cls(**{name: getattr(system, name) for name in SYSTEM_FIELDS}, model=model,
                   options=SolverOptions() if options is None else options)

    @property
    def dim(self) -> int:
        """Dimension D = 2 (N + 1) of the state."""
        return 2 * (self.order + 1)

    @property
    def forcing_period(self) -> float:
        return self.oscillator.forcing_period

    @property
    def continuable(self) -> tuple[str, ...]:
        """The parameters a continuation may follow: ``CONTINUABLE`` and a user's force
        law's own constants."""
        law = self.oscillator.force
        return CONTINUABLE + (() if law is None else tuple(law.constants))

    def with_parameter(self, name: str, value: float) -> ImpactSystem:
        """A copy with one model parameter (or ``sigma``, or a constant of a user's force
        law) changed."""
        if name not in self.continuable:
            raise ValueError(f"parameter must be one of {', '.join(self.continuable)}, got "
                             f"{name!r}")
        return self.replace(**{name: float(value)})

    def parameter(self, name: str) -> float:
        return self.sigma if name == "sigma" else self.oscillator.value(name)

    def attrs(self) -> dict:
        """Dataset attributes (docs/datasets.md)."""
        from opa._dataset import provenance_attrs

        return provenance_attrs(self.model, self, self.options)


#: what continuation can follow: every SWEEPABLE name but x0 and v0, which only select
#: the attractor
CONTINUABLE = tuple(n for n in SWEEPABLE if n not in ("x0", "v0"))


def impulse_cycle(oscillator: Oscillator, *, max_cycle: int = MAX_CYCLE) -> int | None:
    """Forcing periods over which harmonic forcing and impulse train repeat together.

    1 when ``F0 = 0``. Otherwise the smallest ``k <= max_cycle`` such that ``k T`` is a
    whole number of periods of the impulse train (``J`` impulse intervals, where the
    amplitudes ``F0 (1 + a1 sin(2 pi j / n))`` repeat every ``J`` impulses), or None.

    Examples
    --------
    >>> from opa import preset
    >>> impulse_cycle(preset("3.1")), impulse_cycle(preset("3.1", F0=0.0))
    (14, 1)
    """
    if oscillator.F0 == 0.0:
        return 1
    amp = lambda j: math.sin(2.0 * math.pi * j / oscillator.n) * oscillator.a1  # noqa: E731
    J = None
    for cand in range(1, 65):
        if all(abs(amp(j + cand) - amp(j)) <= 1e-9 for j in range(2 * cand + 4)):
            J = cand
            break
    if J is None:
        return None
    ratio = oscillator.omega * J / oscillator.omega1  # forcing periods per train period
    for k in range(1, max_cycle + 1):
        m = k / ratio
        if abs(m - round(m)) <= 1e-9 * max(1.0, m) and round(m) >= 1:
            return k
    return None


def _cycle_or_raise(system: ImpactSystem, periods: int) -> int:
    k0 = impulse_cycle(system.oscillator)
    if k0 is None:
        osc = system.oscillator
        raise ValueError(
            f"with impulses (F0 = {osc.F0:g}, omega1 = {osc.omega1:g}, n = {osc.n:g}) and "
            f"omega = {osc.omega:g} the forcing has no common period of at most {MAX_CYCLE} "
            "forcing periods, so no stroboscopic map is autonomous; use F0 = 0 or the "
            "Lyapunov exponent"
        )
    if periods % k0:
        raise ValueError(
            f"with impulses the forcing repeats every {k0} forcing periods; periods must be a "
            f"multiple of {k0}, got {periods}"
        )
    return k0


def check_time(name: str, value, period: float) -> float:
    """``value`` as a finite time the integrator can resolve, else ValueError naming it.

    A NaN or infinite time never ends an integration, and near a huge time the round-off
    of t exceeds the steps the motion needs (t + T == t for t = 1e300): refuse both.
    """
    value = _finite(name, value)
    floor = STEP_FLOOR * abs(value)
    if floor > TIME_RESOLUTION * period or value + period == value:
        limit = TIME_RESOLUTION * period / STEP_FLOOR
        raise ValueError(
            f"{name} = {value:g} is too large to resolve the motion: near it no step can be "
            f"shorter than {STEP_FLOOR:g} |{name}| = {floor:.3g}, more than {TIME_RESOLUTION:g} "
            f"of the forcing period {period:.6g}; use |{name}| <= {limit:.3g} (the forcing "
            f"repeats, so a section time can be taken modulo its period)"
        )
    return value


def _as_state(system: ImpactSystem, state) -> np.ndarray:
    y = np.asarray(state, dtype=float)
    if y.shape == (2, system.order + 1):
        y = y.ravel()
    if y.shape != (system.dim,) or not np.all(np.isfinite(y)):
        raise ValueError(f"state must be a finite array of shape ({system.dim},) or "
                         f"(2, {system.order + 1}), got shape {np.shape(state)}")
    return y.copy()


# --------------------------------------------------------------------------- flow
@dataclass(frozen=True, eq=False)
class Flow:
    """Result of ``flow``: states at the requested times and the tangent map.

    ``states`` (len(times), D); ``tangent`` (D, m): W(t_end) for W(t_start) given;
    ``impact_time``, ``impact_velocity``: impacts of the mean coordinate (pre-impact
    velocity); ``min_gap``: smallest distance of a free-flight maximum of x_0 below the
    wall, or of a minimum above a lower wall (the nearer); ``sticks``: sticking episodes.
    """

    times: np.ndarray
    states: np.ndarray
    tangent: np.ndarray | None
    impact_time: np.ndarray
    impact_velocity: np.ndarray
    min_gap: float
    sticks: int
    steps: int


def flow(system: ImpactSystem, state, times, *, tangent=None, include_start: bool = False
         ) -> Flow:
    """Integrate the state (and tangent vectors) through ``times``.

    Parameters
    ----------
    state : (D,) or (2, N+1) state at ``times[0]`` (right-continuous).
    times : increasing times; the state is returned at each. They must be finite and
        resolvable (``check_time``: |t| <= 1e8 T), else ValueError.
    tangent : None, ``"identity"`` (the Jacobian of the flow map) or an array (D, m) of
        tangent vectors carried with the variational equation and the saltation matrices.
    include_start : apply an impulse that falls on ``times[0]`` (for a transient started
        at t = 0 with ``impulse_at_zero``); otherwise it belongs to the previous interval.
    """
    y = _as_state(system, state)
    times = np.ascontiguousarray(times, dtype=float)
    if times.ndim != 1 or len(times) < 2:
        raise ValueError(f"times must be a 1-D array of length >= 2, got shape {times.shape}")
    for name, value in (("the start time", times[0]), ("the end time", times[-1])):
        check_time(name, value, system.forcing_period)
    if not np.all(np.diff(times) > 0):  # false for NaN as well
        raise ValueError("times must be finite and strictly increasing")
    if y[0] > system.oscillator.delta:
        raise ValueError(f"state x_0 = {y[0]:.10g} is beyond the wall delta = "
                         f"{system.oscillator.delta:g}")
    D = system.dim
    if tangent is None:
        W = np.zeros((D, 0))
    elif isinstance(tangent, str) and tangent == "identity":
        W = np.eye(D)
    else:
        W = np.asarray(tangent, dtype=float)
        if W.ndim == 1:
            W = W[:, None]
        if W.shape[0] != D:
            raise ValueError(f"tangent must have {D} rows, got shape {W.shape}")
    rec = run(system._packed, y, times, rtol=system.options.rtol, atol=system.options.atol,
              label=f"{system.model} variational flow", variational=Variational(W),
              statistics=True, include_start=include_start, guard=False)
    located = rec.events.located  # located impacts, not kicks
    return Flow(
        times=times,
        states=rec.states,
        tangent=rec.tangent,
        impact_time=rec.events.time[located],
        impact_velocity=rec.events.velocity[located],
        min_gap=float(rec.statistics.nearest_gap.min()),
        sticks=int(rec.statistics.sticks.sum()),
        steps=int(rec.statistics.steps.sum()),
    )


def poincare_map(system: ImpactSystem, state, *, periods: int = 1, t0: float = 0.0,
                 jacobian: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """The stroboscopic map ``P^k: y(t0) -> y(t0 + k T)`` and its exact Jacobian.

    ``periods`` (k) must be a multiple of ``impulse_cycle`` when ``F0 != 0``; ``t0`` must
    be finite and resolvable (``check_time``).

    Returns
    -------
    state (D,), Jacobian (D, D) or None

    Examples
    --------
    >>> from opa import preset
    >>> system = ImpactSystem(preset("3.1", F0=0.0, c=0.05))
    >>> y, J = poincare_map(system, [-1.5, 0.6], periods=2)
    >>> J.shape
    (2, 2)
    """
    periods = _periods(periods)
    _cycle_or_raise(system, periods)
    t0 = check_time("t0", t0, system.forcing_period)
    times = t0 + np.array([0.0, periods]) * system.forcing_period
    res = flow(system, state, times, tangent="identity" if jacobian else None)
    return res.states[-1].copy(), res.tangent


def check_count(name: str, value, minimum: int) -> int:
    """``value`` as an int >= minimum (a whole float is accepted), else ValueError."""
    if (isinstance(value, bool) or not isinstance(value, (int, float, np.number))
            or not math.isfinite(value) or int(value) != value or value < minimum):
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _periods(periods) -> int:
    return check_count("periods", periods, 1)


# --------------------------------------------------------------------------- periodic orbits
@dataclass(frozen=True, eq=False)
class PeriodicOrbit:
    """A periodic orbit of the stroboscopic map and its Floquet multipliers.

    Attributes
    ----------
    system : the system it belongs to.
    state : (D,) the state at t0.
    periods : k, the orbit's period in forcing periods T = 2 pi/omega.
    t0 : section time.
    points : (k, D) the stroboscopic states at t0 + j T, j = 0..k-1.
    jacobian : (D, D) the Jacobian of P^k at ``state`` (monodromy matrix).
    multipliers : (D,) complex eigenvalues of ``jacobian``, by decreasing modulus.
    eigenvectors : (D, D) the matching eigenvectors (columns).
    impact_time, impact_velocity : impacts over one period of the orbit.
    min_gap : smallest distance below the wall of a free-flight maximum of x_0 (or above
        a lower wall of a minimum, the nearer: ``Statistics.nearest_gap``).
    residual : max |P^k(y) - y| / (1 + max |y|) at convergence; iterations: Newton steps.
    """

    system: ImpactSystem
    state: np.ndarray
    periods: int
    t0: float
    points: np.ndarray
    jacobian: np.ndarray
    multipliers: np.ndarray
    eigenvectors: np.ndarray
    impact_time: np.ndarray
    impact_velocity: np.ndarray
    min_gap: float
    sticks: int
    residual: float
    iterations: int

    @property
    def impulse_separation(self) -> float:
        """Smallest time between an impact and an impulse time (or a pulse edge).

        With Dirac impulses the map is discontinuous where an impact meets an impulse
        (kick then impact, or impact then kick, differ by (1 + eta) F0 in velocity), so
        a branch ends where this separation goes to zero. inf when F0 = 0.
        """
        if not self.system.impulsive or not self.impacts:
            return math.inf
        T1 = self.system.impulse_period
        edges = [0.0]
        if self.system.impulse == "pulse":
            edges.append(self.system.pulse_width)
        sep = math.inf
        for e in edges:
            ph = np.mod(self.impact_time - e, T1)
            sep = min(sep, float(np.min(np.minimum(ph, T1 - ph))))
        return sep

    @property
    def impulse_order(self) -> tuple:
        """For each impact, the number of impulse times (and pulse ends) before it.

        Two orbits of one branch with the same impacts but a different order have had an
        impact cross an impulse time between them (a discontinuity of the map).
        """
        if not self.system.impulsive:
            return ()
        count = self.system.impulse_interval(self.impact_time)
        if self.system.impulse == "pulse":
            count = count + self.system.impulse_interval(self.impact_time
                                                         - self.system.pulse_width)
        return tuple(int(c) for c in count)

    @property
    def impacts(self) -> int:
        """Impacts per period of the orbit (the p of the paper's label z = n/p)."""
        return len(self.impact_time)

    @property
    def label(self) -> str:
        """The paper's period label z = n/p (n forcing periods, p impacts)."""
        return f"{self.periods}/{self.impacts}"

    @property
    def min_impact_velocity(self) -> float:
        return float(self.impact_velocity.min()) if self.impacts else math.inf

    @property
    def spectral_radius(self) -> float:
        return float(np.abs(self.multipliers).max())

    @property
    def stable(self) -> bool:
        """All Floquet multipliers strictly inside the unit circle."""
        return self.spectral_radius < 1.0

    def classify(self, *, tol: float = CRITICAL_TOL, graze_velocity: float = ORBIT_GRAZE_VELOCITY,
                 graze_gap: float = ORBIT_GRAZE_GAP) -> list[str]:
        """Labels of the orbit: ``stable``/``unstable`` and any critical multiplier.

        ``period-doubling``: a real multiplier within ``tol`` of -1; ``fold``: within
        ``tol`` of +1; ``neimark-sacker``: a complex pair within ``tol`` of the unit
        circle; ``grazing``: an impact slower than ``graze_velocity`` or a free-flight
        maximum within ``graze_gap`` of the wall (a minimum of a lower wall); ``sticking``:
        the orbit sticks.
        """
        labels = ["stable" if self.stable else "unstable"]
        mu = self.multipliers
        real = np.abs(mu.imag) <= tol
        if np.any(real & (np.abs(mu.real + 1.0) < tol)):
            labels.append("period-doubling")
        if np.any(real & (np.abs(mu.real - 1.0) < tol)):
            labels.append("fold")
        if np.any(~real & (np.abs(np.abs(mu) - 1.0) < tol)):
            labels.append("neimark-sacker")
        if self.min_impact_velocity < graze_velocity or self.min_gap < graze_gap:
            labels.append("grazing")
        if self.sticks:
            labels.append("sticking")
        return labels

    def eigenvector(self, target: float = -1.0) -> np.ndarray:
        """The real eigenvector of the multiplier closest to ``target``, unit length."""
        i = int(np.argmin(np.abs(self.multipliers - target)))
        v = np.real(self.eigenvectors[:, i])
        return v / np.linalg.norm(v)


def _residual(y, y1):
    return float(np.max(np.abs(y1 - y)) / (1.0 + np.max(np.abs(y))))


def default_tolerance(system: ImpactSystem) -> float:
    """Newton tolerance matched to the integrator: 10 max(rtol, atol), at least 1e-13.

    The residual of the map cannot fall much below the integration error, so a tighter
    tolerance only stalls.
    """
    return max(10.0 * max(system.options.rtol, system.options.atol), 1e-13)


def shoot(system: ImpactSystem, guess, *, periods: int = 1, t0: float = 0.0,
          tol: float | None = None, max_iter: int = 40) -> PeriodicOrbit:
    """Newton shooting for a fixed point of ``P^k`` from ``guess`` (no transient).

    Solves ``P^k(y) - y = 0`` with the exact Jacobian ``DP^k - I`` and a backtracking line
    search that keeps x_0 behind the wall. Unstable orbits converge as well as stable
    ones. ``tol`` bounds max |P^k(y) - y| / (1 + max |y|) (default
    ``default_tolerance``); a residual that stops decreasing within 100 tol is accepted
    (the integration-noise floor). Raises ``ConvergenceError`` otherwise.
    """
    periods = _periods(periods)
    _cycle_or_raise(system, periods)
    t0 = check_time("t0", t0, system.forcing_period)
    tol = default_tolerance(system) if tol is None else float(tol)
    if not tol > 0.0:
        raise ValueError(f"tol must be > 0, got {tol}")
    max_iter = check_count("max_iter", max_iter, 0)
    y = _as_state(system, guess)
    T = system.forcing_period
    end = np.array([t0, t0 + periods * T])
    delta = system.oscillator.delta
    eye = np.eye(system.dim)
    res = math.inf
    for it in range(max_iter + 1):
        y1, J = poincare_map(system, y, periods=periods, t0=t0)
        G = y1 - y
        res_prev, res = res, _residual(y, y1)
        if res < tol or (res < 100.0 * tol and res > 0.5 * res_prev):
            return _orbit(system, y, periods, t0, J, res, it)
        if it == max_iter:
            break
        try:
            dy = np.linalg.solve(J - eye, -G)
        except np.linalg.LinAlgError:
            dy = np.linalg.lstsq(J - eye, -G, rcond=None)[0]
        lam = 1.0
        for _ in range(LINE_SEARCH_HALVINGS):
            y_try = y + lam * dy
            if y_try[0] <= delta:
                try:
                    r_try = _residual(y_try, flow(system, y_try, end).states[-1])
                except (SimulationError, ValueError):
                    r_try = math.inf
                if r_try < res or lam < 1e-3:
                    break
            lam *= 0.5
        y = y_try if y_try[0] <= delta and np.all(np.isfinite(y_try)) else y
    raise ConvergenceError(
        f"Newton shooting for a period-{periods} orbit did not converge: residual {res:.3g} "
        f"after {max_iter} iterations (tolerance {tol:g})"
    )


def _orbit(system, y, periods, t0, J, residual, iterations) -> PeriodicOrbit:
    T = system.forcing_period
    times = t0 + np.arange(periods + 1) * T
    tr = flow(system, y, times)
    mu, vec = np.linalg.eig(J)
    order = np.argsort(-np.abs(mu), kind="stable")
    return PeriodicOrbit(
        system=system, state=y.copy(), periods=periods, t0=t0, points=tr.states[:-1].copy(),
        jacobian=J, multipliers=mu[order], eigenvectors=vec[:, order],
        impact_time=tr.impact_time, impact_velocity=tr.impact_velocity, min_gap=tr.min_gap,
        sticks=tr.sticks, residual=residual, iterations=iterations,
    )


def _minimal_period(points: np.ndarray, k: int, k0: int, tol: float) -> int:
    """Smallest divisor d of k (multiple of k0) with points[d] == points[0]."""
    scale = 1.0 + np.max(np.abs(points))
    for d in range(k0, k, k0):
        if k % d == 0 and np.max(np.abs(points[d] - points[0])) <= tol * scale:
            return d
    return k


def periodic_orbit(system: ImpactSystem, guess=None, *, periods: int | None = None,
                   t0: float = 0.0, transient: int = 300, max_period: int = 32,
                   tol: float | None = None, max_iter: int = 40) -> PeriodicOrbit:
    """A periodic orbit of the stroboscopic map with its Floquet multipliers.

    Parameters
    ----------
    system : the DMR or the OPA system.
    guess : starting state (D,) or (2, N+1). Default: run ``transient`` forcing periods
        from the oscillator's x0, v0 (higher OPA coefficients 0) and start from there.
        With ``periods`` as well, Newton starts from ``guess`` at once; without, the
        transient and the period detection run from ``guess`` (taken as the state at
        t = 0, or at any multiple of ``impulse_cycle`` forcing periods).
    periods : k, the period in forcing periods; default: the smallest stroboscopic
        repeat (up to ``max_period``) seen after the transient, else ``impulse_cycle``.
    t0 : section time (the orbit is sampled at t0 + j T). The transient runs from 0 to
        ``(t0 mod k0 T) + transient T`` (the forcing repeats every k0 T, ``impulse_cycle``).
    tol : Newton tolerance on max |P^k(y) - y| / (1 + max |y|) (``shoot``).

    Returns
    -------
    PeriodicOrbit (the period is reduced to the minimal one if Newton lands on an orbit
    of a smaller period).

    Examples
    --------
    >>> from opa import preset
    >>> orbit = periodic_orbit(ImpactSystem(preset("3.1", F0=0.0, c=0.05)))
    >>> orbit.label, orbit.stable
    ('2/2', True)
    """
    k0 = impulse_cycle(system.oscillator)
    if k0 is None:
        _cycle_or_raise(system, 1)
    T = system.forcing_period
    t0 = check_time("t0", t0, T)
    hint = ""
    if guess is None or periods is None:
        transient = check_count("transient", transient, 0)
        n_tr = int(math.ceil(transient / k0)) * k0
        # a guess is a right-continuous state: a kick at t = 0 is already in it
        kick = system.impulse_at_zero and guess is None
        y0 = system.initial_state() if guess is None else _as_state(system, guess)
        # the phase of t0 in the forcing's period: the same motion, without integrating
        # from 0 up to a large t0
        phase = math.fmod(t0, k0 * T)
        if phase < 0.0:
            phase += k0 * T
        start = 0.0
        if phase != 0.0 or n_tr > 0:
            tr = flow(system, y0, [0.0, phase + n_tr * T], include_start=kick)
            y0 = tr.states[-1]
            start = phase + n_tr * T
        if periods is None:
            n_rec = 2 * max_period
            n_rec = int(math.ceil(n_rec / k0)) * k0
            rec = flow(system, y0, start + np.arange(n_rec + 1) * T).states
            scale = 1.0 + np.max(np.abs(rec))
            dist = {k: np.max(np.abs(rec[-1] - rec[-1 - k])) / scale
                    for k in range(k0, min(max_period, n_rec) + 1, k0)}
            close = [k for k, d in dist.items() if d < 1e-4]
            periods = min(close) if close else k0
            y0 = rec[-1]
            if not close:
                hint = (f"; no stroboscopic repeat up to {max_period} periods after "
                        f"{n_tr} periods of transient: the motion may not be periodic (give "
                        "periods, a longer transient, or use the Lyapunov exponent)")
        guess = y0
    periods = _periods(periods)
    try:
        orbit = shoot(system, guess, periods=periods, t0=t0, tol=tol, max_iter=max_iter)
    except ConvergenceError as err:
        raise ConvergenceError(f"{err}{hint}") from None
    d = _minimal_period(orbit.points, orbit.periods, k0, 1e-7)
    if d < orbit.periods:
        orbit = shoot(system, orbit.state, periods=d, t0=t0, tol=tol, max_iter=max_iter)
    return orbit


# --------------------------------------------------------------------------- Lyapunov
@dataclass(frozen=True, eq=False)
class LyapunovEstimate:
    """Largest Lyapunov exponent (per unit time) and its convergence record.

    ``log_growth[k]`` is the log growth of the renormalised perturbation over forcing
    period k; the exponent is their mean divided by T. ``standard_error`` is a
    batch-means estimate (20 batches) of the statistical error of the exponent.
    """

    exponent: float
    log_growth: np.ndarray
    forcing_period: float
    method: str
    impacts: int
    min_impact_velocity: float
    min_gap: float
    sticks: int

    @property
    def periods(self) -> int:
        return len(self.log_growth)

    @property
    def running(self) -> np.ndarray:
        """The running estimate after 1, 2, ... periods."""
        return np.cumsum(self.log_growth) / (np.arange(1, self.periods + 1) * self.forcing_period)

    @property
    def standard_error(self) -> float:
        g = self.log_growth
        if not np.all(np.isfinite(g)) or len(g) < 40:
            return math.nan
        batches = np.array_split(g, 20)
        means = np.array([b.mean() for b in batches]) / self.forcing_period
        return float(means.std(ddof=1) / math.sqrt(len(means)))


def lyapunov_exponent(system: ImpactSystem, *, periods: int = 2000, transient: int = 500,
                      t0: float = 0.0, initial=None) -> LyapunovEstimate:
    """Largest Lyapunov exponent of the non-smooth flow from the variational equation.

    One tangent vector is carried with the flow, through every impact with the saltation
    matrix of the impact law (and unchanged through impulses), and renormalised every
    forcing period T; the exponent is the mean log growth per unit time. Works with any
    forcing, periodic or not. Sticking collapses the tangent vector (growth ``-inf``).

    Parameters
    ----------
    periods : forcing periods averaged over; transient : forcing periods dropped first.
    t0 : start time of the transient; initial : start state (default x0, v0, zeros).
    """
    periods, transient = _periods(periods), check_count("transient", transient, 0)
    T = system.forcing_period
    t0 = check_time("t0", t0, T)
    check_time("the end time t0 + (transient + periods) T", t0 + (transient + periods) * T, T)
    D = system.dim
    y = system.initial_state() if initial is None else _as_state(system, initial)
    start = bool(system.impulse_at_zero) and t0 == 0.0
    t_rec = t0
    if transient > 0:
        t_rec = t0 + transient * T
        y = flow(system, y, [t0, t_rec], include_start=start).states[-1]
        start = False
    rec = run(system._packed, y, t_rec + np.arange(periods + 1) * T, rtol=system.options.rtol,
              atol=system.options.atol, label="Lyapunov run",
              variational=Variational(np.full((D, 1), 1.0 / math.sqrt(D)), renormalise=True),
              statistics=True, events=False, include_start=start, guard=False)
    stats = rec.statistics
    return LyapunovEstimate(
        exponent=float(np.mean(rec.log_growth) / T), log_growth=rec.log_growth,
        forcing_period=T, method="variational (saltation)", impacts=int(stats.impacts.sum()),
        min_impact_velocity=float(stats.min_velocity.min()), min_gap=float(stats.nearest_gap.min()),
        sticks=int(stats.sticks.sum()),
    )


def transverse_lyapunov_exponent(system: ImpactSystem, *, periods: int = 2000,
                                 transient: int = 500) -> LyapunovEstimate:
    """Exponent of perturbations of the higher OPA coefficients along EMR_0 = DMR.

    At sigma = 0 the subspace x_i = v_i = 0 (i >= 1) is invariant and carries the DMR.
    Its transverse stability decides whether round-off (or a small sigma) in the higher
    coefficients dies out or grows until the OPA trajectory leaves the DMR. The linearised
    dynamics of every higher mode is the same (orthonormality), so order 1 suffices: a
    tangent vector in (x_1, v_1) is carried along the trajectory, whose higher
    coefficients are reset to exactly 0 every period so that it stays the DMR. With the
    ``mean`` law the transverse mode crosses impacts unchanged (the saltation matrix is
    the identity on it); with ``ensemble`` its velocity is multiplied by -eta.
    """
    if system.model != "opa" or system.sigma != 0.0 or system.order < 1:
        raise ValueError("transverse_lyapunov_exponent needs model 'opa', sigma = 0 and "
                         f"order >= 1, got model {system.model!r}, sigma = {system.sigma}, "
                         f"order {system.order}")
    periods, transient = _periods(periods), check_count("transient", transient, 0)
    one = dataclasses.replace(system, order=1)
    T = one.forcing_period
    y = one.initial_state()
    if transient > 0:
        y = flow(one, y, [0.0, transient * T], include_start=one.impulse_at_zero
                 ).states[-1]
    w = np.array([0.0, 1.0, 0.0, 1.0]) / math.sqrt(2.0)
    growth = np.empty(periods)
    impacts, vmin = 0, math.inf
    for k in range(periods):
        y[[1, 3]] = 0.0
        res = flow(one, y, [(transient + k) * T, (transient + k + 1) * T], tangent=w,
                   include_start=transient == 0 and k == 0 and one.impulse_at_zero)
        y, w = res.states[-1], res.tangent[:, 0]
        norm = float(np.linalg.norm(w))
        growth[k] = math.log(norm) if norm > 0 else -math.inf
        w = w / norm if norm > 0 else np.array([0.0, 1.0, 0.0, 1.0]) / math.sqrt(2.0)
        impacts += len(res.impact_time)
        if len(res.impact_velocity):
            vmin = min(vmin, float(res.impact_velocity.min()))
    return LyapunovEstimate(
        exponent=float(np.mean(growth) / T), log_growth=growth, forcing_period=T,
        method=f"transverse (higher OPA coefficients along the DMR, {system.impact_law} law)",
        impacts=impacts, min_impact_velocity=vmin, min_gap=math.nan, sticks=0,
    )


def lyapunov_benettin(system: ImpactSystem, *, periods: int = 2000, transient: int = 500,
                      initial=None, d0: float = 1e-8, engine: str = "solver") -> LyapunovEstimate:
    """Largest Lyapunov exponent by two nearby trajectories (Benettin et al. 1980).

    An independent check of ``lyapunov_exponent``: a reference and a perturbed
    trajectory, with no variational equation and no saltation matrix, the separation
    renormalised to ``d0`` every forcing period.

    Parameters
    ----------
    engine : ``"solver"``: both trajectories as plain runs of the kernel
        (``opa._run.run``, the DMR/OPA path, resumed under the impulse train);
        ``"plain"``: through :func:`flow` without tangent vectors. Both share the event
        code, not the saltation matrices.
    """
    _choice("engine", engine, ("solver", "plain"))
    periods, transient = _periods(periods), check_count("transient", transient, 0)
    T = system.forcing_period
    delta = system.oscillator.delta
    impacts, vmin = 0, math.inf
    at_zero = bool(system.impulse_at_zero)
    if engine == "solver":
        opts = system.options

        def step(y, ta, tb, first=False):
            rec = run(system._packed, y, np.array([ta, tb]), rtol=opts.rtol, atol=opts.atol,
                      label="Benettin trajectory", include_start=first and at_zero)
            return rec.states[-1], rec.events.velocity[rec.events.located]
    else:
        def step(y, ta, tb, first=False):
            res = flow(system, y, [ta, tb], include_start=first and at_zero)
            return res.states[-1], res.impact_velocity

    y = system.initial_state() if initial is None else _as_state(system, initial)
    if transient > 0:
        y, _ = step(y, 0.0, transient * T, first=True)
    u = np.ones(system.dim) / math.sqrt(system.dim)
    growth = np.empty(periods)
    for k in range(periods):
        ta, tb = (transient + k) * T, (transient + k + 1) * T
        if y[0] + d0 * u[0] > delta:
            u = -u
        first = transient == 0 and k == 0
        y_next, v_imp = step(y, ta, tb, first)
        y_pert, _ = step(y + d0 * u, ta, tb, first)
        diff = y_pert - y_next
        dist = float(np.linalg.norm(diff))
        growth[k] = math.log(dist / d0) if dist > 0 else -math.inf
        u = diff / dist if dist > 0 else np.ones(system.dim) / math.sqrt(system.dim)
        y = y_next
        impacts += len(v_imp)
        if len(v_imp):
            vmin = min(vmin, float(np.min(v_imp)))
    where = "plain kernel runs" if engine == "solver" else "the flow without tangents"
    return LyapunovEstimate(
        exponent=float(np.mean(growth) / T), log_growth=growth, forcing_period=T,
        method=f"Benettin two-trajectory ({where}, d0 = {d0:g})", impacts=impacts,
        min_impact_velocity=vmin, min_gap=math.nan, sticks=0,
    )



def benettin_engine(system: ImpactSystem) -> str:
    """The engine of :func:`lyapunov_benettin` as the check of :func:`lyapunov_exponent`
    (``opa-mc stability --lyapunov --benettin``): the kernel's own runs (``"solver"``)
    without impulses, this module's plain flow (``"plain"``) with them (F0 != 0).

    >>> import opa
    >>> [benettin_engine(opa.ImpactSystem.of(opa.System(opa.preset("3.1", F0=F0))))
    ...  for F0 in (0.0, 0.1)]
    ['solver', 'plain']
    """
    return "solver" if system.oscillator.F0 == 0.0 else "plain"

__all__ = [
    "ImpactSystem",
    "PeriodicOrbit",
    "LyapunovEstimate",
    "ConvergenceError",
    "impulse_cycle",
    "flow",
    "poincare_map",
    "shoot",
    "default_tolerance",
    "periodic_orbit",
    "lyapunov_exponent",
    "transverse_lyapunov_exponent",
    "lyapunov_benettin",
    "benettin_engine",
]
