"""Nordmark's square-root law near grazing, on a user's force law.

Truth (Nordmark 1991, "Non-periodic motion caused by grazing incidence in an impact
oscillator", J. Sound Vib. 145): let the free flow (no wall) of x'' = g(x, v) + f cos(omega t)
from y0 at t0 reach its maximum x_max at t* with acceleration A = x''(t*) < 0. Put the
wall at delta = x_max - d. For small d the trajectory with the wall hits it once, near t*,
with velocity ~ sqrt(2 |A| d), and the restitution law changes v by -(1 + eta) times that,
so the stroboscopic map with the wall differs from the free one by

    y_wall(t0 + T) - y_free(t0 + T) = -(1 + eta) sqrt(2 |A| d) Phi(t0 + T, t*) e_v + O(d)

(Phi the free flow's fundamental matrix, e_v = (0, 1)): the correction scales as d^(1/2).

Independent references: the force laws written again in Python here; scipy's
``solve_ivp`` for the free flight, its maximum (located to ~1e-13 on the grazing time, where
v = 0, by Brent's method and a re-integration to it) and the velocity column of Phi (the
variational equation). opa supplies only the runs with and without the wall.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import opa

SCIPY = dict(method="DOP853", rtol=1e-13, atol=1e-13)
OPTIONS = opa.SolverOptions(rtol=1e-12, atol=1e-12)
DEPTHS = np.geomspace(1e-8, 1e-4, 9)  # penetration depths d of the free flight
FAR = 100.0  # the wall out of reach: the free flow

# A damped, hardening Duffing oscillator (not the paper's law), and the paper's own law
# (van der Pol - Duffing, section 3.2) written as a user's law.
DUFFING = dict(
    expression="-2*zeta*v - k*x - k3*x^3", constants=dict(zeta=0.05, k=1.0, k3=0.1),
    oscillator=dict(f=0.4, omega=1.3, eta=0.8), transient=80,
    g=lambda x, v: -2 * 0.05 * v - 1.0 * x - 0.1 * x**3,
    dg=lambda x, v: (-1.0 - 0.3 * x**2, -0.1),
)
_P = opa.preset("3.2")
PAPER = dict(
    expression="mu*(1 - v^2)*v - a*x - c*x^3", constants={},
    oscillator=dict(mu=_P.mu, a=_P.a, c=_P.c, f=_P.f, omega=_P.omega, eta=_P.eta),
    transient=None,  # the first stroboscopic state after 20 periods with an interior maximum
    g=lambda x, v: _P.mu * (1 - v**2) * v - _P.a * x - _P.c * x**3,
    dg=lambda x, v: (-_P.a - 3 * _P.c * x**2, _P.mu * (1 - 3 * v**2)),
)


def free_rhs(case):
    g, f, omega = case["g"], case["oscillator"]["f"], case["oscillator"]["omega"]

    def rhs(t, y):
        return [y[1], g(y[0], y[1]) + f * math.cos(omega * t)]
    return rhs


def variational_rhs(case):
    rhs, dg = free_rhs(case), case["dg"]

    def var(t, z):
        gx, gv = dg(z[0], z[1])
        return [*rhs(t, z[:2]), z[3], gx * z[2] + gv * z[3]]
    return var


def maximum_of_period(rhs, y0, T, margin=1e-3):
    """The free flight's maximum over [0, T] from y0 (scipy): (t*, x_max), or None when
    it is not interior or x comes within ``margin`` of it again elsewhere in the period
    (so a wall at x_max - d with d <= 1e-4 is met once, near t*)."""
    sol = solve_ivp(rhs, (0.0, T), y0, dense_output=True, **SCIPY)
    grid = np.linspace(0.0, T, 4001)
    x, v = sol.sol(grid)
    i = int(np.argmax(x))
    if not 0 < i < len(grid) - 1 or not v[i - 1] > 0 > v[i + 1]:
        return None
    high = np.flatnonzero(x > x[i] - margin)  # one run of grid points, not at an end
    if high[0] == 0 or high[-1] == len(grid) - 1 or len(high) != high[-1] - high[0] + 1:
        return None
    t_star = brentq(lambda t: sol.sol(t)[1], grid[i - 1], grid[i + 1], xtol=1e-15, rtol=1e-15)
    # x at t*: a fresh integration ending there (not the interpolant); the error of t*
    # enters x_max only at second order since v(t*) = 0.
    x_max = solve_ivp(rhs, (0.0, t_star), y0, **SCIPY).y[0, -1]
    return t_star, x_max


def grazing_start(case, T):
    """y0 (at t0 = 0) and its flight's maximum (t*, x_max)."""
    rhs = free_rhs(case)
    if case["transient"] is not None:
        y0 = solve_ivp(rhs, (0.0, case["transient"] * T), [0.0, 0.0], **SCIPY).y[:, -1]
        found = maximum_of_period(rhs, y0, T)
        assert found is not None
        return y0, found
    y = solve_ivp(rhs, (0.0, 20 * T), [-1.0, 0.0], **SCIPY).y[:, -1]
    for _ in range(40):  # t = 0 mod T: the forcing repeats, so each start is at t0 = 0
        found = maximum_of_period(rhs, y, T)
        if found is not None:
            return y, found
        y = solve_ivp(rhs, (0.0, T), y, **SCIPY).y[:, -1]
    raise AssertionError("no period of the flight has an isolated interior maximum")


def oscillator(case, y0, delta):
    law = opa.ForceLaw(case["expression"], **case["constants"])
    o = case["oscillator"]
    return opa.Oscillator(force=law, **o, delta=delta, F0=0.0, omega1=o["omega"],
                          x0=float(y0[0]), v0=float(y0[1]))


def one_period(osc):
    """opa's DMR over one forcing period: the end state, impact times and velocities.
    (``sigma=0``: the deterministic system, for a law without the default uncertain mu.)"""
    ds = opa.simulate_dmr(opa.System(osc, sigma=0.0), periods=1, per_period=1,
                          options=OPTIONS)
    end = np.array([float(ds.x[-1]), float(ds.v[-1])])
    return end, ds.impact_time.values, ds.impact_velocity.values


@pytest.mark.parametrize("case", [DUFFING, PAPER], ids=["duffing", "paper-law-3.2"])
def test_the_correction_to_the_map_grows_as_the_square_root_of_the_penetration(case):
    """Nine depths d from 1e-8 to 1e-4: one impact near t* at sqrt(2 |A| d), a correction
    |y_wall(T) - y_free(T)| of log-log slope 1/2 (+- 0.02) and of Nordmark's leading term
    (1 + eta) sqrt(2 |A| d) Phi(T, t*) e_v to 10 %."""
    eta, omega = case["oscillator"]["eta"], case["oscillator"]["omega"]
    T = 2 * math.pi / omega
    y0, (t_star, x_max) = grazing_start(case, T)
    accel = free_rhs(case)(t_star, [x_max, 0.0])[1]
    assert accel < -1e-2  # a quadratic maximum: the grazing is generic
    column = solve_ivp(variational_rhs(case), (t_star, T), [x_max, 0.0, 0.0, 1.0],
                       **SCIPY).y[2:, -1]

    free, impacts, _ = one_period(oscillator(case, y0, FAR))
    assert len(impacts) == 0
    want_free = solve_ivp(free_rhs(case), (0.0, T), y0, **SCIPY).y[:, -1]
    np.testing.assert_allclose(free, want_free, rtol=0, atol=1e-9)

    corrections = []
    for d in DEPTHS:
        wall, times, velocities = one_period(oscillator(case, y0, x_max - d))
        speed = math.sqrt(2 * abs(accel) * d)
        assert len(times) == 1, (d, times)
        # the free flight crosses x_max - d at t* - sqrt(2 d / |A|) (to O(d))
        assert times[0] == pytest.approx(t_star - math.sqrt(2 * d / abs(accel)),
                                         abs=0.1 * math.sqrt(2 * d / abs(accel)))
        assert abs(velocities[0]) == pytest.approx(speed, rel=0.05)
        leading = -(1 + eta) * speed * column
        corrections.append(np.linalg.norm(wall - free))
        assert np.linalg.norm(wall - free - leading) <= 0.1 * np.linalg.norm(leading), d
    slope = np.polyfit(np.log(DEPTHS), np.log(corrections), 1)[0]
    assert slope == pytest.approx(0.5, abs=0.02), (slope, corrections)
