"""Independent reference solutions ("truths") for impact oscillators, written with numpy and
scipy only: nothing here imports ``opa``, ``mc`` or ``compare``. They are checked against
each other, against scipy and against closed forms in ``tests/test_impact_truths.py``, and
serve later as references for user-defined force laws and two-wall impacts.

1. The linear impact oscillator of Shaw & Holmes (S. W. Shaw and P. J. Holmes, "A periodically
   forced piecewise linear oscillator", J. Sound Vib. 90 (1983) 129-155)::

       x'' + 2 zeta x' + x = cos(omega t),      x < delta
       x'(t+) = -r x'(t-)                       at x = delta

   Its period-1 single-impact orbits (one impact per forcing period ``T = 2 pi / omega``)
   come in closed form from the linear flight between impacts
   (:func:`shaw_holmes_orbits`), with their Floquet multipliers derived twice: by
   differentiating the closed-form impact-to-impact map (:func:`shaw_holmes_map_jacobian`)
   and from the monodromy matrix of the flow with the saltation matrix of the impact
   (:func:`shaw_holmes_flow_multipliers`).

2. An event-driven integrator for one or two rigid walls with Newton restitution and any
   force law ``x'' = g(x, x') + f cos(omega t)`` (:func:`two_wall_impacts`), built on
   ``scipy.integrate.solve_ivp`` (DOP853) with terminal events. It has no sticking model and
   refuses chatter.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

# Shaw & Holmes cases with period-1 single-impact orbits (phase t*, pre-impact velocity V,
# Floquet multipliers by modulus):
#   omega 2.5, delta 0.0, r 0.8: one orbit, t* = 1.15797, V = 0.63636, |m| = 0.706 (x2): stable
#   omega 3.0, delta -0.5, r 0.5: two orbits, t* = 0.25206, V = 0.95182, m = 1.852, 0.110:
#       unstable (a saddle), and t* = 0.62837, V = 1.25333, |m| = 0.450 (x2): stable
#   omega 1.8, delta 0.6, r 0.8: two orbits, t* = 0.75783, V = 4.21580, |m| = 0.672 (x2):
#       stable, and t* = 1.55642, V = 1.09190, m = 1.726, 0.262: unstable (a saddle)
SHAW_HOLMES_CASES = [
    dict(zeta=0.05, omega=2.5, delta=0.0, r=0.8),
    dict(zeta=0.05, omega=3.0, delta=-0.5, r=0.5),
    dict(zeta=0.05, omega=1.8, delta=0.6, r=0.8),
]

# ----------------------------------------------------------------------- the linear flight


def _check_underdamped(zeta, omega):
    if not 0.0 <= zeta < 1.0:
        raise ValueError(f"zeta = {zeta} is not underdamped (0 <= zeta < 1 is required)")
    if omega <= 0.0:
        raise ValueError(f"omega = {omega} must be positive")


def linear_flow_matrix(zeta, s):
    """The fundamental matrix ``Phi(s)`` of ``x'' + 2 zeta x' + x = 0`` (``0 <= zeta < 1``).

    ``[x(s), v(s)] = Phi(s) [x(0), v(0)]`` with, for ``wd = sqrt(1 - zeta^2)``, ``c = cos(wd s)``
    and ``n = sin(wd s)``::

        Phi(s) = exp(-zeta s) [[c + zeta n / wd,  n / wd],
                               [-n / wd,          c - zeta n / wd]]

    (the homogeneous solution ``exp(-zeta s) (A cos(wd s) + B sin(wd s))`` fitted to the
    initial state). It solves ``Phi' = A Phi``, ``A = [[0, 1], [-1, -2 zeta]]``.
    """
    wd = math.sqrt(1.0 - zeta**2)
    c, n = math.cos(wd * s), math.sin(wd * s)
    e = math.exp(-zeta * s)
    return e * np.array([[c + zeta * n / wd, n / wd], [-n / wd, c - zeta * n / wd]])


def _system_matrix(zeta):
    return np.array([[0.0, 1.0], [-1.0, -2.0 * zeta]])


def particular_state(zeta, omega, t):
    """The harmonic (T-periodic) solution of ``x'' + 2 zeta x' + x = cos(omega t)``.

    ``x_p = P cos(omega t) + Q sin(omega t)`` with ``D = (1 - omega^2)^2 + (2 zeta omega)^2``,
    ``P = (1 - omega^2) / D`` and ``Q = 2 zeta omega / D`` (undetermined coefficients).
    Returns the state ``(x_p, x_p')`` and its time derivative ``(x_p', x_p'')`` as arrays.
    """
    d = (1.0 - omega**2) ** 2 + (2.0 * zeta * omega) ** 2
    p, q = (1.0 - omega**2) / d, 2.0 * zeta * omega / d
    c, s = math.cos(omega * t), math.sin(omega * t)
    x = p * c + q * s
    v = omega * (q * c - p * s)
    return np.array([x, v]), np.array([v, -omega**2 * x])


def shaw_holmes_flight(zeta, omega, delta, r, t_star, velocity, s):
    """The closed-form state ``(x, v)`` at ``t_star + s`` of the flight that leaves the wall
    ``x = delta`` at ``t_star`` with the post-impact velocity ``-r * velocity``.

    ``y(t_star + s) = y_p(t_star + s) + Phi(s) (y(t_star+) - y_p(t_star))`` with the harmonic
    solution ``y_p`` (:func:`particular_state`) and the fundamental matrix ``Phi``
    (:func:`linear_flow_matrix`). ``s`` may be an array; the result then has shape
    ``(2, len(s))``.
    """
    _check_underdamped(zeta, omega)
    yp0, _ = particular_state(zeta, omega, t_star)
    h0 = np.array([delta, -r * velocity]) - yp0
    s = np.atleast_1d(np.asarray(s, dtype=float))
    out = np.empty((2, s.size))
    for k, sk in enumerate(s):
        harmonic = particular_state(zeta, omega, t_star + sk)[0]
        out[:, k] = harmonic + linear_flow_matrix(zeta, sk) @ h0
    return out


# ------------------------------------------------------------------ Shaw & Holmes orbits


def _fixed_point_pieces(zeta, omega, r, delta, t_star):
    """``(M - I) u`` and ``w`` of the fixed-point equations ``(M - I) u = V w``."""
    T = 2.0 * math.pi / omega
    M = linear_flow_matrix(zeta, T)
    yp, _ = particular_state(zeta, omega, t_star)
    u = np.array([delta - yp[0], -yp[1]])
    w = np.array([r * M[0, 1], 1.0 + r * M[1, 1]])
    return (M - np.eye(2)) @ u, w


def shaw_holmes_residual(zeta, omega, delta, r, t_star):
    """The scalar closed-form residual whose zeros in ``t_star`` are period-1 impact phases.

    Over one period the harmonic part returns to itself, so the homogeneous part
    ``h(s) = y(t_star + s) - y_p(t_star + s)`` must map ``h(0) = u + V (0, -r)`` onto
    ``h(T) = u + V (0, 1)``, ``u = (delta - x_p(t_star), -x_p'(t_star))``, through
    ``h(T) = M h(0)``, ``M = Phi(T)``. That is ``(M - I) u = V w``, ``w = (r M12, 1 + r M22)``:
    two linear equations in the pre-impact velocity ``V``, solvable iff the 2D cross product
    ``(M - I) u x w`` vanishes. Returns that cross product.
    """
    a, w = _fixed_point_pieces(zeta, omega, r, delta, t_star)
    return a[0] * w[1] - a[1] * w[0]


def shaw_holmes_velocity(zeta, omega, delta, r, t_star):
    """The pre-impact velocity ``V`` that solves ``(M - I) u = V w`` in least squares (exactly
    where :func:`shaw_holmes_residual` vanishes)."""
    a, w = _fixed_point_pieces(zeta, omega, r, delta, t_star)
    return float(a @ w / (w @ w))


def _flight_stays_below(zeta, omega, delta, r, t_star, velocity, samples=4001):
    T = 2.0 * math.pi / omega
    s = np.linspace(0.0, T, samples)[1:-1]
    x = shaw_holmes_flight(zeta, omega, delta, r, t_star, velocity, s)[0]
    return bool(np.max(x) <= delta + 1e-10)


def shaw_holmes_orbits(zeta, omega, delta, r, scan=2000):
    """The period-1 single-impact orbits of the Shaw & Holmes (1983) impact oscillator.

    ``x'' + 2 zeta x' + x = cos(omega t)`` for ``x < delta`` (``0 <= zeta < 1``), the wall at
    ``x = delta`` approached from below, impact law ``x'(t+) = -r x'(t-)``. A period-1 orbit
    leaves the wall at the phase ``t*`` with ``-r V`` and is back at ``t* + T``,
    ``T = 2 pi / omega``, with the pre-impact velocity ``V > 0``.

    The phase solves the closed-form equation of :func:`shaw_holmes_residual` (no ODE is
    integrated): the residual is scanned on ``scan`` points of ``[0, T)`` and each sign change
    refined by ``scipy.optimize.brentq``; ``V`` then follows from
    :func:`shaw_holmes_velocity`. Solutions with ``V <= 0``, or whose closed-form flight rises
    above ``delta`` anywhere on a dense grid of ``(t*, t* + T)``, are rejected.

    Returns a list of dicts: ``phase`` (``t*`` in ``[0, T)``), ``velocity`` (``V``) and
    ``multipliers`` (the two Floquet multipliers from the derivative of the closed-form
    impact map, :func:`shaw_holmes_map_jacobian`; complex, by modulus descending).
    """
    _check_underdamped(zeta, omega)
    T = 2.0 * math.pi / omega
    grid = np.linspace(0.0, T, scan + 1)
    res = np.array([shaw_holmes_residual(zeta, omega, delta, r, t) for t in grid])
    orbits = []
    for k in range(scan):
        if res[k] == 0.0 or res[k] * res[k + 1] < 0.0:
            t_star = grid[k] if res[k] == 0.0 else brentq(
                lambda t: shaw_holmes_residual(zeta, omega, delta, r, t),
                grid[k], grid[k + 1], xtol=1e-15, rtol=4 * np.finfo(float).eps)
            t_star = float(t_star % T)
            velocity = shaw_holmes_velocity(zeta, omega, delta, r, t_star)
            if velocity <= 0.0:
                continue
            if not _flight_stays_below(zeta, omega, delta, r, t_star, velocity):
                continue
            jac = shaw_holmes_map_jacobian(zeta, omega, delta, r, t_star, velocity)
            orbits.append(dict(phase=t_star, velocity=velocity,
                               multipliers=sort_multipliers(np.linalg.eigvals(jac))))
    return orbits


def sort_multipliers(values):
    """Complex multipliers sorted by modulus descending (ties: imaginary part descending)."""
    values = np.asarray(values, dtype=complex)
    order = sorted(range(values.size),
                   key=lambda k: (-round(abs(values[k]), 12), -values[k].imag))
    return values[order]


def shaw_holmes_map_jacobian(zeta, omega, delta, r, t_star, velocity):
    """The Jacobian of the impact-to-impact map ``(t_n, V_n) -> (t_{n+1}, V_{n+1})`` at a
    period-1 orbit, by differentiating the closed-form map analytically.

    With ``h0 = (delta, -r V_n) - y_p(t_n)`` and ``s = t_{n+1} - t_n`` the flight is
    ``y(t_{n+1}) = y_p(t_{n+1}) + Phi(s) h0``; the map is ``x(t_{n+1}) = delta`` (implicit in
    ``t_{n+1}``) and ``V_{n+1} = v(t_{n+1})``. At fixed ``t_{n+1}``,
    ``dy/dt_n = G = -A Phi(s) h0 - Phi(s) y_p'(t_n)`` and ``dy/dV_n = H = Phi(s) (0, -r)``;
    ``dy/dt_{n+1} = (V_{n+1}, a_{n+1})``, ``a_{n+1}`` the pre-impact acceleration. Then
    ``dt_{n+1} = -(G_1 dt_n + H_1 dV_n) / V_{n+1}`` and
    ``dV_{n+1} = a_{n+1} dt_{n+1} + G_2 dt_n + H_2 dV_n``. Its eigenvalues are the Floquet
    multipliers; its determinant is ``r^2 exp(-2 zeta T)``.
    """
    T = 2.0 * math.pi / omega
    phi = linear_flow_matrix(zeta, T)
    yp0, dyp0 = particular_state(zeta, omega, t_star)
    h0 = np.array([delta, -r * velocity]) - yp0
    g = -_system_matrix(zeta) @ phi @ h0 - phi @ dyp0
    h = phi @ np.array([0.0, -r])
    arrival = particular_state(zeta, omega, t_star + T)[0] + phi @ h0
    v1 = arrival[1]
    a1 = -2.0 * zeta * v1 - arrival[0] + math.cos(omega * (t_star + T))
    return np.array([[-g[0] / v1, -h[0] / v1],
                     [g[1] - a1 * g[0] / v1, h[1] - a1 * h[0] / v1]])


def shaw_holmes_saltation(zeta, omega, delta, r, t_star, velocity):
    """The saltation matrix of the impact at ``(t*, x = delta, x' = V)``.

    For the event surface ``x = delta`` (normal ``e0 = (1, 0)``) and the reset
    ``R(x, v) = (x, -r v)``: ``S = dR + (f+ - dR f-) e0^T / (e0^T f-)`` with the vector fields
    ``f- = (V, a-)`` just before and ``f+ = (-r V, a+)`` just after the impact,
    ``a-+ = -2 zeta v -+ delta + cos(omega t*)``. This gives
    ``S = [[-r, 0], [(a+ + r a-) / V, -r]]``.
    """
    drive = -delta + math.cos(omega * t_star)
    a_minus = -2.0 * zeta * velocity + drive
    a_plus = 2.0 * zeta * r * velocity + drive
    f_minus = np.array([velocity, a_minus])
    f_plus = np.array([-r * velocity, a_plus])
    dR = np.diag([1.0, -r])
    e0 = np.array([1.0, 0.0])
    return dR + np.outer(f_plus - dR @ f_minus, e0) / (e0 @ f_minus)


def shaw_holmes_monodromy(zeta, omega, delta, r, t_star, velocity):
    """The monodromy matrix of the flow over one period, from just after the impact at ``t*``
    to just after the next: ``S Phi(T)`` (the variational equation of the linear flow is
    ``dy' = A dy`` whatever the phase, so the flight contributes ``Phi(T)``; the impact
    contributes the saltation matrix ``S``, :func:`shaw_holmes_saltation`)."""
    T = 2.0 * math.pi / omega
    S = shaw_holmes_saltation(zeta, omega, delta, r, t_star, velocity)
    return S @ linear_flow_matrix(zeta, T)


def shaw_holmes_flow_multipliers(zeta, omega, delta, r, t_star, velocity):
    """The Floquet multipliers as eigenvalues of the 2x2 monodromy matrix of the flow
    (:func:`shaw_holmes_monodromy`), by modulus descending. The non-autonomous flow's
    stroboscopic map over one period has these as its nontrivial multipliers."""
    return sort_multipliers(
        np.linalg.eigvals(shaw_holmes_monodromy(zeta, omega, delta, r, t_star, velocity)))


# ------------------------------------------------------------------ two-wall integrator


def _wall_events(walls):
    """The terminal wall events (upper: ``x - delta_plus`` rising, lower: ``x - delta_minus``
    falling) with their sides, then the non-terminal turning-point event ``v = 0``."""
    events, sides = [], []
    lower, upper = walls
    if upper is not None:
        def hit_upper(t, y):
            return y[0] - upper
        hit_upper.terminal, hit_upper.direction = True, 1
        events.append(hit_upper)
        sides.append(1)
    if lower is not None:
        def hit_lower(t, y):
            return y[0] - lower
        hit_lower.terminal, hit_lower.direction = True, -1
        events.append(hit_lower)
        sides.append(-1)

    def turning(t, y):
        return y[1]
    turning.terminal, turning.direction = False, 0
    return events + [turning], sides


def _missed_crossing(sol, walls, t_start, t_stop):
    """A wall crossing that the sign test of ``solve_ivp`` missed, as ``(t, v, side)``.

    ``solve_ivp`` looks for events at step ends only, so a flight that pokes through a wall
    and comes back within one step goes unseen. Its turning point (``v = 0``, recorded as a
    non-terminal event) then lies beyond the wall: the crossing is found by ``brentq`` on the
    dense output between that turning point and the previous one (or the start), where ``x``
    is monotone and on the right side of the wall. Returns ``None`` if there is none.
    """
    lower, upper = walls
    turns = [t for t in sol.t_events[-1] if t_start < t <= t_stop]
    for k, t_turn in enumerate(turns):
        x_turn = sol.sol(t_turn)[0]
        for side, wall in ((1, upper), (-1, lower)):
            if wall is None or side * (x_turn - wall) <= 0.0:
                continue
            t_prev = turns[k - 1] if k else t_start
            t_hit = brentq(lambda t: sol.sol(t)[0] - wall, t_prev, t_turn,
                           xtol=1e-15, rtol=4 * np.finfo(float).eps)
            return t_hit, float(sol.sol(t_hit)[1]), side
    return None


def _flight(rhs, t, y, t_end, walls, rtol, atol):
    """One flight from ``(t, y)``: ``(t_hit, v_hit, side)`` of its impact, or ``None`` and
    the state at ``t_end`` if it reaches ``t_end`` first; and its turning points before
    the impact as ``(t, x, +1 a minimum / -1 a maximum)`` (the sign of x'' there)."""
    events, sides = _wall_events(walls)
    sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", events=events, rtol=rtol, atol=atol,
                    dense_output=True)
    if sol.status == -1:
        raise RuntimeError(f"solve_ivp failed at t = {t}: {sol.message}")
    hit = None
    if sol.status == 1:
        k = next(i for i, te in enumerate(sol.t_events[:-1]) if te.size)
        hit = float(sol.t_events[k][0]), float(sol.y_events[k][0][1]), sides[k]
    missed = _missed_crossing(sol, walls, t, hit[0] if hit else sol.t[-1])
    if missed is not None and (hit is None or missed[0] < hit[0]):
        hit = missed
    stop = hit[0] if hit else float(sol.t[-1])
    turns = [(float(tt), float(yy[0]), math.copysign(1.0, rhs(tt, yy)[1]))
             for tt, yy in zip(sol.t_events[-1], sol.y_events[-1]) if t < tt < stop]
    return hit, (float(sol.t[-1]), sol.y[:, -1].copy()), turns


def two_wall_impacts(force, f, omega, walls, restitutions, y0, t_end, t0=0.0,
                     rtol=1e-11, atol=1e-12, max_impacts=None):
    """Integrate ``x'' = force(x, x') + f cos(omega t)`` between rigid walls with restitution.

    ``walls = (delta_minus, delta_plus)`` (either may be ``None``: one wall), the motion in
    ``delta_minus < x < delta_plus``; ``restitutions = (r_minus, r_plus)``. An impact at a wall
    resets ``x' -> -r x'`` there, with ``x`` put exactly on the wall. The flights are
    ``scipy.integrate.solve_ivp`` (DOP853, ``rtol``, ``atol``) runs from ``(t0, y0)`` to
    ``t_end``, stopped by terminal events ``x - delta_plus`` (direction +1) and
    ``x - delta_minus`` (direction -1) and restarted after each impact; a crossing within one
    step, which the events miss, is caught at the turning point beyond the wall
    (:func:`_missed_crossing`). It stops early after ``max_impacts`` impacts if given.

    There is no sticking model: a ``ValueError`` is raised for chatter, i.e. more than 1000
    impacts within one forcing period ``2 pi / omega`` (``omega > 0``), a pre-impact speed
    below ``1e-8``, or an impact at the instant of the previous one.

    Returns a dict: ``times``, ``velocities`` (pre-impact) and ``wall`` (+1 upper, -1 lower)
    of every impact as arrays, the final time ``t`` and state ``state = (x, v)``, and the
    free flights' turning points (``v = 0`` events): ``turn_times``, ``turn_x`` and
    ``turn_kind`` (+1 a minimum of x, -1 a maximum).
    """
    if omega <= 0.0:
        raise ValueError("omega must be positive (it sets the chatter window 2 pi / omega)")
    lower, upper = walls
    x_start = float(y0[0])
    if (upper is not None and x_start > upper) or (lower is not None and x_start < lower):
        raise ValueError(f"the start x = {x_start} lies outside the walls {walls}")
    period = 2.0 * math.pi / omega

    def rhs(t, y):
        return [y[1], force(y[0], y[1]) + f * math.cos(omega * t)]

    t, y = float(t0), np.array(y0, dtype=float)
    times, velocities, wall, turns = [], [], [], []
    while t < t_end:
        hit, (t, y), flight_turns = _flight(rhs, t, y, t_end, walls, rtol, atol)
        turns += flight_turns
        if hit is None:
            break
        t_hit, v_hit, side = hit
        _refuse_chatter(times, times[-1] if times else t0, t_hit, v_hit, side, period)
        times.append(t_hit)
        velocities.append(v_hit)
        wall.append(side)
        r = restitutions[1] if side == 1 else restitutions[0]
        t, y = t_hit, np.array([upper if side == 1 else lower, -r * v_hit])
        if max_impacts is not None and len(times) >= max_impacts:
            break
    turns = np.array(turns).reshape(-1, 3)
    return dict(times=np.array(times), velocities=np.array(velocities),
                wall=np.array(wall, dtype=int), t=t, state=y, turn_times=turns[:, 0],
                turn_x=turns[:, 1], turn_kind=turns[:, 2].astype(int))


def _refuse_chatter(times, t_start, t_hit, v_hit, side, period, per_period=1000,
                    min_speed=1e-8):
    """Raise ``ValueError`` for an impact that signals chatter (see :func:`two_wall_impacts`)."""
    if abs(v_hit) < min_speed or side * v_hit <= 0.0:
        raise ValueError(f"chatter at t = {t_hit}: pre-impact velocity {v_hit} at the "
                         f"{'upper' if side == 1 else 'lower'} wall (no sticking model)")
    if times and t_hit <= t_start:
        raise ValueError(f"chatter at t = {t_hit}: an impact at the instant of the last one")
    recent = sum(1 for tk in times[-per_period:] if tk > t_hit - period)
    if recent >= per_period:
        raise ValueError(f"chatter at t = {t_hit}: more than {per_period} impacts within "
                         f"one forcing period (no sticking model)")
