"""The shared truths of ``tests/truths.py`` against references that share nothing with them:
``scipy.integrate.solve_ivp`` (DOP853, rtol = atol = 1e-12) written out here for each
problem, ``scipy.linalg.expm``, ``scipy.integrate.quad`` of the plain density and
``scipy.stats.beta``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, stats
from scipy.linalg import expm

from tests.truths import (
    accumulation_time,
    bouncing_sequence,
    chatter_time,
    impulse_size,
    kicked_linear_oscillator,
    linear_flow,
    linear_impact_orbit,
    linear_oscillator,
    pulsed_linear_oscillator,
    release_from_wall,
    semicircle_cdf,
    semicircle_cubic_projection,
    semicircle_density,
    semicircle_expectation,
    semicircle_gauss_rule,
    semicircle_golub_welsch_rule,
    semicircle_mass,
    semicircle_moment,
)

TIGHT = dict(method="DOP853", rtol=1e-12, atol=1e-12)


def forced(a, f, omega, force=lambda t: 0.0):
    return lambda t, y: [y[1], -a * y[0] + f * math.cos(omega * t) + force(t)]


def integrate_pieces(rhs, y0, t, breaks, jump=lambda t_b, y: y):
    """solve_ivp from break to break; ``jump`` maps the state at each break (t > 0), and an
    output at a break shows the state after the jump."""
    x, v = np.empty_like(t), np.empty_like(t)
    edges = sorted(set([0.0, *breaks, float(t[-1])]))
    y = np.array(y0, dtype=float)
    for lo, hi in zip(edges[:-1], edges[1:]):
        if lo in breaks:
            y = jump(lo, y)
        inside = (t >= lo) & ((t < hi) | (hi == t[-1]))
        sol = integrate.solve_ivp(rhs, (lo, hi), y, t_eval=t[inside], **TIGHT)
        x[inside], v[inside] = sol.y
        y = integrate.solve_ivp(rhs, (lo, hi), y, **TIGHT).y[:, -1]
    if t[-1] in breaks:  # outputs are right-continuous
        x[-1], v[-1] = jump(t[-1], np.array([x[-1], v[-1]]))
    return x, v


# --------------------------------------------------------------------------- linear oscillator


def test_linear_oscillator_against_solve_ivp():
    t = np.linspace(0.0, 20.0, 201)
    x, v = linear_oscillator(t, 1.3, 2.0, 2.8, -1.0, 0.4)
    sol = integrate.solve_ivp(forced(1.3, 2.0, 2.8), (0.0, 20.0), [-1.0, 0.4], t_eval=t,
                              **TIGHT)
    np.testing.assert_allclose(x, sol.y[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(v, sol.y[1], rtol=0, atol=1e-9)


def test_linear_flow_is_the_matrix_exponential():
    for a, s in [(1.0, 0.3), (0.7, 2.5), (5.0, 1.1)]:
        np.testing.assert_allclose(linear_flow(a, s), expm(s * np.array([[0.0, 1.0], [-a, 0.0]])),
                                   rtol=0, atol=1e-13)


def test_impulse_sizes():
    assert impulse_size(0.0, 0.3, 1.0, 1.0, 2) == 0.3
    assert impulse_size(math.pi, 0.3, 1.0, 1.0, 2) == pytest.approx(0.6, abs=1e-15)
    assert impulse_size(2 * math.pi, 0.3, 0.5, 1.0, 4) == pytest.approx(0.45, abs=1e-15)


@pytest.mark.parametrize("at_zero", [True, False])
def test_kicked_linear_oscillator_against_solve_ivp_with_velocity_jumps(at_zero):
    a, F0 = 0.7, 0.3
    t = np.linspace(0.0, 4 * 2 * math.pi, 201)
    times = [2 * math.pi * j for j in range(0 if at_zero else 1, 5)]
    kicks = [(t_j, impulse_size(t_j, F0, 1.0, 1.0, 2)) for t_j in times]
    x, v = kicked_linear_oscillator(t, a, 1.5, 2.0, -0.5, 0.0, kicks)
    y0 = [-0.5, kicks[0][1] if at_zero else 0.0]
    sizes = dict(kicks)
    rx, rv = integrate_pieces(forced(a, 1.5, 2.0), y0, t, [t_j for t_j in times if t_j > 0],
                              jump=lambda t_b, y: y + np.array([0.0, sizes[t_b]]))
    np.testing.assert_allclose(x, rx, rtol=0, atol=1e-9)
    np.testing.assert_allclose(v, rv, rtol=0, atol=1e-9)
    assert v[0] == (0.3 if at_zero else 0.0)  # right-continuous at a kick


def test_pulsed_linear_oscillator_against_solve_ivp_with_a_piecewise_force():
    a, tau = 0.7, 0.25
    t = np.linspace(0.0, 3 * 2 * math.pi, 151)
    pulses = [(2 * math.pi * j, impulse_size(2 * math.pi * j, 0.3, 1.0, 1.0, 2))
              for j in range(4)]
    x, v = pulsed_linear_oscillator(t, a, 0.8, 2.0, -0.2, 0.1, pulses, tau)

    def force(s):
        return sum(h for t_j, h in pulses if t_j <= s < t_j + tau)

    breaks = [b for t_j, _ in pulses for b in (t_j, t_j + tau) if 0 < b < t[-1]]
    rx, rv = integrate_pieces(forced(a, 0.8, 2.0, force), [-0.2, 0.1], t, breaks)
    np.testing.assert_allclose(x, rx, rtol=0, atol=1e-9)
    np.testing.assert_allclose(v, rv, rtol=0, atol=1e-9)


def _impact_map(a, f, omega, eta, delta, y0):
    """One forcing period of x'' + a x = f cos(omega t), x <= delta, by solve_ivp with a
    terminal wall event: (state at T, impact times, impact speeds)."""
    T = 2 * math.pi / omega
    wall = lambda t, y: y[0] - delta  # noqa: E731
    wall.terminal, wall.direction = True, 1.0
    t, y, times, speeds = 0.0, np.array(y0, dtype=float), [], []
    while True:
        sol = integrate.solve_ivp(forced(a, f, omega), (t, T), y, events=wall, max_step=0.05,
                                  **TIGHT)
        if sol.status == 0:
            return sol.y[:, -1], times, speeds
        t, y = sol.t_events[0][0], sol.y_events[0][0].copy()
        times.append(t)
        speeds.append(y[1])
        y = np.array([delta, -eta * y[1]])


@pytest.mark.parametrize("a, f, omega, eta, delta", [(1.0, 1.0, 1.6, 0.8, 0.1),
                                                     (1.0, 2.0, 2.8, 0.8, 0.1)])
def test_linear_impact_orbit_is_a_fixed_point_of_the_solve_ivp_impact_map(a, f, omega, eta,
                                                                         delta):
    y0, monodromy, phi, v = linear_impact_orbit(a, f, omega, eta, delta)
    y1, times, speeds = _impact_map(a, f, omega, eta, delta, y0)
    assert len(times) == 1
    assert times[0] == pytest.approx(phi / omega, abs=1e-9)
    assert speeds[0] == pytest.approx(v, rel=1e-9)
    np.testing.assert_allclose(y1, y0, rtol=0, atol=1e-9)
    h = 1e-6
    columns = [(_impact_map(a, f, omega, eta, delta, y0 + e)[0]
                - _impact_map(a, f, omega, eta, delta, y0 - e)[0]) / (2 * h)
               for e in (np.array([h, 0.0]), np.array([0.0, h]))]
    fd = np.array(columns).T
    np.testing.assert_allclose(monodromy, fd, rtol=0, atol=1e-6 * np.abs(fd).max())
    assert np.linalg.det(monodromy) == pytest.approx(eta**2, rel=1e-10)


# --------------------------------------------------------------------------- the wall


def test_bouncing_sequence_against_solve_ivp_with_a_wall_event():
    g, h, eta, delta = 2.0, 1.0, 0.6, 0.0
    wall = lambda t, y: y[0] - delta  # noqa: E731
    wall.terminal, wall.direction = True, 1.0
    t, y, times, speeds = 0.0, np.array([delta - h, 0.0]), [], []
    for _ in range(6):
        sol = integrate.solve_ivp(lambda t, y: [y[1], g], (t, t + 10.0), y, events=wall,
                                  **TIGHT)
        t, y = sol.t_events[0][0], sol.y_events[0][0].copy()
        times.append(t)
        speeds.append(y[1])
        y = np.array([delta, -eta * y[1]])
    expected_times, expected_speeds = bouncing_sequence(g, h, eta, 6)
    np.testing.assert_allclose(times, expected_times, rtol=0, atol=1e-10)
    np.testing.assert_allclose(speeds, expected_speeds, rtol=1e-10)


def test_accumulation_time_is_the_limit_of_the_impact_times():
    g, h, eta = 2.0, 1.0, 0.6
    times, speeds = bouncing_sequence(g, h, eta, 200)
    assert accumulation_time(g, h, eta) == pytest.approx(times[-1], rel=1e-14)
    assert chatter_time(speeds[3], g, eta) == pytest.approx(times[-1] - times[3], rel=1e-13)


def test_release_from_the_wall_against_solve_ivp():
    f, omega, delta = 1.5, 2.0, 0.2
    t_r, x_r, v_r = release_from_wall(math.pi / (2 * omega), f, omega, delta)
    assert t_r == math.pi / (2 * omega)
    assert (x_r, v_r) == (pytest.approx(delta, abs=1e-15), pytest.approx(0.0, abs=1e-15))
    # the force pushes into the wall before t_r and pulls away after it
    assert f * math.cos(omega * (t_r - 1e-6)) > 0 > f * math.cos(omega * (t_r + 1e-6))
    t = np.linspace(t_r, t_r + 3.0, 61)
    _, x, v = release_from_wall(t, f, omega, delta)
    sol = integrate.solve_ivp(forced(0.0, f, omega), (t_r, t[-1]), [delta, 0.0], t_eval=t,
                              **TIGHT)
    np.testing.assert_allclose(x, sol.y[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(v, sol.y[1], rtol=0, atol=1e-9)
    assert np.all(x[1:] < delta)


# --------------------------------------------------------------------------- semicircle law


def _quad_density(g, lo=-1.0, hi=1.0):
    """E[g 1(lo, hi)] by plain adaptive quad of 2/pi sqrt(1 - x^2) (no special weight)."""
    return integrate.quad(lambda x: g(x) * 2 / math.pi * math.sqrt(max(0.0, 1 - x * x)), lo,
                          hi, limit=200, epsabs=1e-13)[0]


def test_density_integrates_to_one_and_vanishes_outside():
    assert _quad_density(lambda x: 1.0) == pytest.approx(1.0, abs=1e-10)
    np.testing.assert_array_equal(semicircle_density([-1.5, -1.0, 1.0, 2.0]), 0.0)
    np.testing.assert_allclose(semicircle_density([-0.3, 0.5]),
                               stats.beta(1.5, 1.5, loc=-1, scale=2).pdf([-0.3, 0.5]),
                               rtol=1e-14)


def test_moments_are_catalan_over_4_to_the_k_by_quad_of_the_density():
    for k in range(13):
        assert semicircle_moment(k) == pytest.approx(_quad_density(lambda x: x**k), abs=1e-10)
    assert [semicircle_moment(2 * m) * 4**m for m in range(8)] == [1, 1, 2, 5, 14, 42, 132, 429]


def test_exact_moments_helper_matches_quadrature():
    """(Moved from tests/mc/test_sampling.py.) QAWS integrates against sqrt(1 - x^2)."""
    for k in range(9):
        # weight "alg" integrates against (1 + x)^1/2 (1 - x)^1/2 = sqrt(1 - x^2) exactly.
        moment, _ = integrate.quad(lambda x: 2 / np.pi * x**k, -1, 1, weight="alg", wvar=(0.5, 0.5))
        assert semicircle_moment(k) == pytest.approx(moment, abs=1e-14)
    assert semicircle_moment(2) == 0.25
    assert semicircle_moment(4) == 0.125


def test_expectation_against_the_moments_and_quad_of_the_density():
    for k in range(20):
        assert semicircle_expectation(lambda x: x**k) == pytest.approx(semicircle_moment(k),
                                                                       abs=1e-14)
    g = lambda x: math.exp(x) * math.cos(3 * x)  # noqa: E731
    assert semicircle_expectation(g) == pytest.approx(_quad_density(g), abs=1e-10)


def test_cdf_and_mass_against_scipy_beta_and_quad():
    x = np.linspace(-1.0, 1.0, 101)
    np.testing.assert_allclose(semicircle_cdf(x), stats.beta(1.5, 1.5, loc=-1, scale=2).cdf(x),
                               rtol=0, atol=1e-14)
    assert float(semicircle_cdf(-2.0)) == 0.0 and float(semicircle_cdf(2.0)) == 1.0
    for lo, hi in [(-1.0, -0.4), (-0.4, 0.2), (0.2, 1.0), (0.2, 0.7)]:
        assert semicircle_mass(lo, hi) == pytest.approx(_quad_density(lambda _: 1.0, lo, hi),
                                                        abs=1e-12)


@pytest.mark.parametrize("q", [1, 2, 3, 8, 25, 64])
def test_gauss_rule_closed_form_equals_golub_welsch_and_is_exact_to_degree_2q_minus_1(q):
    nodes, weights = semicircle_gauss_rule(q)
    ref_nodes, ref_weights = semicircle_golub_welsch_rule(q)
    np.testing.assert_allclose(nodes, ref_nodes, rtol=0, atol=1e-13)
    np.testing.assert_allclose(weights, ref_weights, rtol=0, atol=1e-13)
    assert np.all(np.diff(nodes) > 0)
    for d in range(min(2 * q, 40)):
        assert weights @ nodes**d == pytest.approx(semicircle_moment(d), abs=1e-13), d


def test_cubic_projection_against_quad():
    rng = np.random.default_rng(7)
    for n in (0, 1, 3, 6):
        coef = rng.normal(size=n + 1)
        got = semicircle_cubic_projection(coef, 3 * n + 2)

        def x(s):
            return sum(c * u for c, u in zip(coef, _chebyu(n, s)))

        for i in range(3 * n + 3):
            ref = semicircle_expectation(lambda s, i=i: x(s) ** 3 * _chebyu(i, s)[i])
            assert got[i] == pytest.approx(ref, abs=1e-11), (n, i)


def _chebyu(n, s):
    """U_0(s) .. U_n(s) by the three-term rule U_{i+1} = 2 s U_i - U_{i-1}."""
    u = [1.0, 2.0 * s]
    while len(u) < n + 1:
        u.append(2.0 * s * u[-1] - u[-2])
    return u[: n + 1]
