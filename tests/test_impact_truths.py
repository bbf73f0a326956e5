"""The impact truths of ``tests/impact_truths.py`` against each other, against closed forms
and against ``scipy``: the Shaw & Holmes period-1 orbits (closed form) against the
independent event integrator ``two_wall_impacts`` (``solve_ivp``, DOP853); their Floquet
multipliers from the differentiated impact map against the flow's monodromy matrix with its
saltation matrix and against finite differences of the scipy impact map; the two-wall
integrator against the closed-form bouncing of ``x'' = -x`` between walls."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from tests.impact_truths import (
    SHAW_HOLMES_CASES,
    linear_flow_matrix,
    shaw_holmes_flight,
    shaw_holmes_flow_multipliers,
    shaw_holmes_map_jacobian,
    shaw_holmes_monodromy,
    shaw_holmes_orbits,
    sort_multipliers,
    two_wall_impacts,
)


def _period(case):
    return 2.0 * math.pi / case["omega"]


def _force(case):
    zeta = case["zeta"]
    return lambda x, v: -2.0 * zeta * v - x


def _orbits():
    """(case id, case, orbit) for every period-1 orbit of every case."""
    out = []
    for k, case in enumerate(SHAW_HOLMES_CASES):
        for j, orbit in enumerate(shaw_holmes_orbits(**case)):
            out.append(pytest.param(case, orbit, id=f"case{k}-orbit{j}"))
    return out


ORBITS = _orbits()


def _from_orbit(case, t_star, velocity, t_end, max_impacts=None):
    """``two_wall_impacts`` from the post-impact state of the wall ``x = delta`` at ``t_star``."""
    delta, r = case["delta"], case["r"]
    return two_wall_impacts(_force(case), 1.0, case["omega"], (None, delta), (None, r),
                            (delta, -r * velocity), t_end, t0=t_star, max_impacts=max_impacts)


def _impact_map(case, t_star, velocity):
    """The scipy impact-to-impact map ``(t_n, V_n) -> (t_{n+1}, V_{n+1})``."""
    out = _from_orbit(case, t_star, velocity, t_star + 2.0 * _period(case), max_impacts=1)
    return np.array([out["times"][0], out["velocities"][0]])


def _same_multipliers(a, b, tol):
    """Every multiplier of ``a`` within ``tol`` of one of ``b`` and vice versa."""
    a, b = np.asarray(a), np.asarray(b)
    return (max(np.min(np.abs(b - x)) for x in a) < tol
            and max(np.min(np.abs(a - x)) for x in b) < tol)


# ----------------------------------------------------------------- the closed-form pieces


def test_the_flow_matrix_is_the_matrix_exponential():
    zeta = 0.05
    A = np.array([[0.0, 1.0], [-1.0, -2.0 * zeta]])
    for s in (0.0, 0.3, 2.0, 7.5):
        assert np.allclose(linear_flow_matrix(zeta, s), expm(A * s), rtol=0, atol=1e-13)


def test_the_closed_form_flight_matches_solve_ivp():
    zeta, omega, delta, r, t_star, velocity = 0.05, 2.5, 0.0, 0.8, 0.4, 1.1
    s = np.linspace(0.0, 3.0, 7)

    def rhs(t, y):
        return [y[1], -2.0 * zeta * y[1] - y[0] + math.cos(omega * t)]

    sol = solve_ivp(rhs, (t_star, t_star + 3.0), [delta, -r * velocity], method="DOP853",
                    rtol=1e-12, atol=1e-12, t_eval=t_star + s)
    closed = shaw_holmes_flight(zeta, omega, delta, r, t_star, velocity, s)
    assert np.allclose(closed, sol.y, rtol=0, atol=1e-10)


def test_the_cases_hold_a_stable_and_an_unstable_orbit():
    assert all(len(shaw_holmes_orbits(**case)) >= 1 for case in SHAW_HOLMES_CASES)
    moduli = [abs(p.values[1]["multipliers"][0]) for p in ORBITS]
    assert any(m < 1.0 for m in moduli) and any(m > 1.0 for m in moduli)


# ------------------------------------------------------- orbits against the integrator


@pytest.mark.parametrize("case, orbit", ORBITS)
def test_the_orbit_returns_to_the_wall_once_a_period(case, orbit):
    T, t_star, velocity = _period(case), orbit["phase"], orbit["velocity"]
    assert 0.0 <= t_star < T and velocity > 0.0
    out = _from_orbit(case, t_star, velocity, t_star + 3.5 * T)
    assert out["times"].size == 3 and set(out["wall"]) == {1}
    assert np.allclose(out["times"], t_star + T * np.arange(1, 4), rtol=0, atol=1e-8)
    assert np.allclose(out["velocities"], velocity, rtol=0, atol=1e-8)


@pytest.mark.parametrize("case, orbit", ORBITS)
def test_the_orbit_flight_stays_below_the_wall(case, orbit):
    s = np.linspace(0.0, _period(case), 2001)[1:-1]
    x = shaw_holmes_flight(case["zeta"], case["omega"], case["delta"], case["r"],
                           orbit["phase"], orbit["velocity"], s)[0]
    assert np.max(x) < case["delta"]


# ------------------------------------------------------------------------- multipliers


@pytest.mark.parametrize("case, orbit", ORBITS)
def test_the_two_derivations_of_the_multipliers_agree(case, orbit):
    args = (case["zeta"], case["omega"], case["delta"], case["r"], orbit["phase"],
            orbit["velocity"])
    flow = shaw_holmes_flow_multipliers(*args)
    assert _same_multipliers(orbit["multipliers"], flow, 1e-8)
    det = case["r"] ** 2 * math.exp(-2.0 * case["zeta"] * _period(case))
    assert np.linalg.det(shaw_holmes_map_jacobian(*args)) == pytest.approx(det, rel=1e-9)
    assert np.linalg.det(shaw_holmes_monodromy(*args)) == pytest.approx(det, rel=1e-9)


@pytest.mark.parametrize("case, orbit", ORBITS)
def test_the_multipliers_match_finite_differences_of_the_scipy_map(case, orbit):
    t_star, velocity, h = orbit["phase"], orbit["velocity"], 1e-4
    d_t = (_impact_map(case, t_star + h, velocity) - _impact_map(case, t_star - h, velocity))
    d_v = (_impact_map(case, t_star, velocity + h) - _impact_map(case, t_star, velocity - h))
    jac = np.column_stack([d_t, d_v]) / (2.0 * h)
    numeric = sort_multipliers(np.linalg.eigvals(jac))
    assert _same_multipliers(orbit["multipliers"], numeric, 1e-5)


@pytest.mark.parametrize("case, orbit", ORBITS)
def test_a_stable_orbit_attracts_and_an_unstable_one_repels(case, orbit):
    T, t_star, velocity = _period(case), orbit["phase"], orbit["velocity"]
    out = _from_orbit(case, t_star + 1e-3, velocity + 1e-3, t_star + 50.25 * T)
    phase_gap = (out["times"][-1] - t_star + T / 2) % T - T / 2
    gap = math.hypot(phase_gap, out["velocities"][-1] - velocity)
    if np.max(np.abs(orbit["multipliers"])) < 1.0:
        assert gap < 1e-6
    else:
        assert gap > 1e-2


# ------------------------------------------------------------------ two-wall integrator


def test_elastic_bouncing_between_two_walls_matches_the_closed_form():
    """``x'' = -x`` from ``x = 0`` with speed ``V`` between walls at ``+-d`` (``r = 1``): the
    orbit is ``V sin t`` folded between the walls, the first impact at ``t1 = arcsin(d / V)``
    on the upper wall and each flight between the walls lasts ``2 t1``."""
    V, d, n = 1.5, 0.7, 20
    t1 = math.asin(d / V)
    out = two_wall_impacts(lambda x, v: -x, 0.0, 1.0, (-d, d), (1.0, 1.0), (0.0, V),
                           (2 * n) * t1)
    k = np.arange(1, n + 1)
    assert np.allclose(out["times"], (2 * k - 1) * t1, rtol=0, atol=1e-9)
    assert np.array_equal(out["wall"], np.where(k % 2 == 1, 1, -1))
    assert np.allclose(out["velocities"], out["wall"] * math.sqrt(V**2 - d**2), rtol=0,
                       atol=1e-9)


def test_restitution_takes_its_share_at_each_wall():
    """With ``r_minus = 0.6`` and ``r_plus = 0.8`` each pre-impact speed is the last one times
    the last wall's ``r`` (the energy ``(x^2 + v^2) / 2`` is kept in flight and ``|x| = d`` at
    both walls); a flight leaving a wall with speed ``s`` lasts ``2 arcsin(d / A)``,
    ``A = sqrt(d^2 + s^2)``. The late flights barely reach the far wall (``A`` close to ``d``):
    they poke through it within one solver step, where the plain events of ``solve_ivp`` see
    no sign change and the turning-point guard of ``two_wall_impacts`` must catch them."""
    V, d, n, rest = 1.5, 0.7, 12, {-1: 0.6, 1: 0.8}
    out = two_wall_impacts(lambda x, v: -x, 0.0, 1.0, (-d, d), (rest[-1], rest[1]), (0.0, V),
                           100.0, max_impacts=n)
    assert out["times"].size == n
    assert np.array_equal(out["wall"], np.where(np.arange(n) % 2 == 0, 1, -1))
    t, speed = math.asin(d / V), math.sqrt(V**2 - d**2)
    for k in range(n):
        assert out["times"][k] == pytest.approx(t, abs=1e-9)
        assert abs(out["velocities"][k]) == pytest.approx(speed, abs=1e-9)
        energy_before = 0.5 * (d**2 + out["velocities"][k] ** 2)
        speed *= rest[int(out["wall"][k])]
        energy_after = 0.5 * (d**2 + speed**2)
        assert energy_after < energy_before
        t += 2.0 * math.asin(d / math.hypot(d, speed))
    assert np.allclose(out["state"], [d * out["wall"][-1], -rest[int(out["wall"][-1])]
                                      * out["velocities"][-1]], rtol=0, atol=1e-12)


def test_the_lower_wall_mirrors_the_upper_one():
    """``x -> -x`` maps the Shaw & Holmes oscillator onto ``x'' + 2 zeta x' + x = -cos(omega t)``
    with a lower wall at ``-delta``: the same impact times, the velocities negated."""
    case = SHAW_HOLMES_CASES[0]
    orbit = shaw_holmes_orbits(**case)[0]
    T, t_star, velocity = _period(case), orbit["phase"], orbit["velocity"]
    delta, r = case["delta"], case["r"]
    up = _from_orbit(case, t_star, velocity, t_star + 2.5 * T)
    down = two_wall_impacts(_force(case), -1.0, case["omega"], (-delta, None), (r, None),
                            (-delta, r * velocity), t_star + 2.5 * T, t0=t_star)
    assert np.array_equal(down["wall"], [-1, -1])
    assert np.allclose(down["times"], up["times"], rtol=0, atol=1e-10)
    assert np.allclose(down["velocities"], -up["velocities"], rtol=0, atol=1e-10)


def test_far_walls_leave_a_nonlinear_flow_alone():
    """A damped Duffing oscillator that never reaches the walls: no impact, and the final state
    of a plain ``solve_ivp`` run."""
    def force(x, v):
        return -0.1 * v - x - 0.5 * x**3

    out = two_wall_impacts(force, 0.3, 1.2, (-5.0, 5.0), (0.7, 0.7), (0.5, 0.0), 20.0)
    sol = solve_ivp(lambda t, y: [y[1], force(*y) + 0.3 * math.cos(1.2 * t)], (0.0, 20.0),
                    [0.5, 0.0], method="DOP853", rtol=1e-11, atol=1e-12)
    assert out["times"].size == 0 and out["t"] == 20.0
    assert np.allclose(out["state"], sol.y[:, -1], rtol=0, atol=1e-10)


def test_the_turning_points_of_a_free_flight_are_the_closed_forms():
    """``x'' = -x`` from ``(0, 1)`` is ``sin t``: maxima x = 1 at pi/2 + 2 pi k, minima x = -1
    at 3 pi/2 + 2 pi k; with an elastic wall at x = 0.5 the flights' maxima are gone (each
    rise ends at the wall) and the minima x = -1 stay, one per flight."""
    out = two_wall_impacts(lambda x, v: -x, 0.0, 1.0, (-5.0, 5.0), (1.0, 1.0), (0.0, 1.0), 20.0)
    k = np.arange(1, 7)
    assert np.allclose(out["turn_times"], k * math.pi - math.pi / 2, rtol=0, atol=1e-10)
    assert np.allclose(out["turn_x"], np.where(k % 2, 1.0, -1.0), rtol=0, atol=1e-10)
    assert np.array_equal(out["turn_kind"], np.where(k % 2, -1, 1))
    walled = two_wall_impacts(lambda x, v: -x, 0.0, 1.0, (None, 0.5), (None, 1.0), (0.0, 1.0),
                              10.0)
    assert walled["times"].size >= 2 and np.all(walled["turn_kind"] == 1)
    assert np.allclose(walled["turn_x"], -1.0, rtol=0, atol=1e-10)


def test_chatter_is_refused():
    """A ball bouncing on the floor under gravity with ``r = 0.5`` accumulates infinitely many
    impacts in finite time: without a sticking model that is an error."""
    with pytest.raises(ValueError, match="chatter"):
        two_wall_impacts(lambda x, v: -1.0, 0.0, 1.0, (0.0, None), (0.5, None), (1.0, 0.0),
                         10.0)


def test_a_start_outside_the_walls_is_refused():
    with pytest.raises(ValueError, match="outside"):
        two_wall_impacts(lambda x, v: -x, 0.0, 1.0, (-1.0, 1.0), (1.0, 1.0), (2.0, 0.0), 1.0)
