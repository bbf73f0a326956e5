"""Tests for the periodic orbits, Poincare maps and Lyapunov exponents of
``opa.dynamics._orbits`` (their continuation is tested in ``test_continuation.py``, the
branch plot in ``tests/opa/plots/test_branches.py``, ``opa-mc stability`` in
``tests/opa/cli/test_stability.py``).

Independent references:

- central finite differences of the stroboscopic map computed with the project's
  event-driven solver (``opa.simulate_dmr`` / ``opa.simulate_opa``), which shares no
  code with the variational kernel, for the DMR, the OPA system (both impact laws, both
  truncations, uncertain mu and c) and with Dirac and pulse impulses;
- the closed form of the period-1 single-impact orbit of the linear impact oscillator
  (mu = c = 0, ``tests.truths.linear_impact_orbit``): impact phase and velocity from the
  fixed-point equations of the impact map, and the monodromy matrix composed of the
  explicit linear flow and the saltation matrix (whose determinant is eta^2);
- two Lyapunov estimates: tangent vector with saltation matrices vs two trajectories
  of ``opa._solver`` (Benettin), in a chaotic impacting regime;
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from opa import Oscillator, SolverOptions, preset, simulate_dmr, simulate_opa
from opa.dynamics._continuation import continue_orbits
from opa.dynamics._orbits import (
    ImpactSystem,
    impulse_cycle,
    lyapunov_benettin,
    lyapunov_exponent,
    periodic_orbit,
    poincare_map,
    shoot,
    transverse_lyapunov_exponent,
)
from tests.truths import linear_impact_orbit

TIGHT = SolverOptions(rtol=1e-12, atol=1e-12)
H = 1e-6  # finite-difference step


def _fd_jacobian(fun, y, h=H):
    cols = []
    for j in range(len(y)):
        e = np.zeros(len(y))
        e[j] = h
        cols.append((fun(y + e) - fun(y - e)) / (2 * h))
    return np.array(cols).T


def _solver_map_dmr(osc, options, t0, t1):
    def fun(y):
        ds = simulate_dmr(osc.replace(x0=y[0], v0=y[1]), times=np.array([t0, t1]),
                          options=options)
        return np.array([ds.x.values[-1], ds.v.values[-1]])
    return fun


# --------------------------------------------------------------------------- Jacobian
def test_monodromy_matches_finite_differences_dmr():
    system = ImpactSystem(preset("3.1", F0=0.0, c=0.05), options=TIGHT)
    orbit = periodic_orbit(system)
    assert orbit.label == "2/2" and orbit.stable
    T = system.forcing_period
    fd = _fd_jacobian(_solver_map_dmr(system.oscillator, TIGHT, 0.0, 2 * T), orbit.state)
    np.testing.assert_allclose(orbit.jacobian, fd, atol=1e-6 * np.abs(fd).max())
    np.testing.assert_allclose(np.sort_complex(orbit.multipliers),
                               np.sort_complex(np.linalg.eigvals(fd)), atol=1e-6)


@pytest.mark.parametrize(
    "law, truncation, uncertain",
    [("mean", "galerkin", "mu"), ("ensemble", "paper", "mu"), ("mean", "paper", "c"),
     ("ensemble", "galerkin", "a")],
)
def test_map_jacobian_matches_finite_differences_opa(law, truncation, uncertain):
    osc = preset("3.1", F0=0.0, c=0.05)
    system = ImpactSystem(osc, model="opa", order=3, sigma=0.05, uncertain=uncertain,
                          truncation=truncation, impact_law=law, options=TIGHT)
    y0 = np.array([-1.5, 0.1, -0.02, 0.01, 0.6, 0.02, -0.01, 0.0])
    T = system.forcing_period
    y1, J = poincare_map(system, y0, periods=2)

    def fun(y):
        ds = simulate_opa(osc, sigma=0.05, order=3, uncertain=uncertain, truncation=truncation,
                          impact_law=law, times=np.array([0.0, 2 * T]), options=TIGHT,
                          initial=y.reshape(2, 4))
        return np.concatenate([ds.x_coef.values[:, -1], ds.v_coef.values[:, -1]])

    ds_imp = simulate_opa(osc, sigma=0.05, order=3, uncertain=uncertain, truncation=truncation,
                          impact_law=law, times=np.array([0.0, 2 * T]), options=TIGHT,
                          initial=y0.reshape(2, 4))
    assert ds_imp.sizes["impact"] >= 2  # the map crosses impacts
    np.testing.assert_allclose(y1, fun(y0), atol=1e-9)
    fd = _fd_jacobian(fun, y0)
    np.testing.assert_allclose(J, fd, atol=2e-6 * np.abs(fd).max())


@pytest.mark.parametrize("impulse", ["dirac", "pulse"])
def test_flow_jacobian_through_impulses(impulse):
    from opa.dynamics._orbits import flow

    options = SolverOptions(rtol=1e-12, atol=1e-12, impulse=impulse, impulse_at_zero=False)
    system = ImpactSystem(preset("3.1", c=0.05, F0=0.3), options=options)
    T = system.forcing_period
    t0, t1 = 0.7, 0.7 + 3 * T  # contains the impulse (or pulse) at t = 2 pi
    y0 = np.array([-1.2, 0.4])
    res = flow(system, y0, [t0, t1], tangent="identity")
    assert len(res.impact_time) >= 1
    fun = _solver_map_dmr(system.oscillator, options, t0, t1)
    np.testing.assert_allclose(res.states[-1], fun(y0), atol=1e-9)
    fd = _fd_jacobian(fun, y0)
    np.testing.assert_allclose(res.tangent, fd, atol=2e-6 * np.abs(fd).max())


# --------------------------------------------------------------------------- closed form


@pytest.mark.parametrize(
    "a, f, omega, eta, delta, stable",
    [(1.0, 1.0, 1.6, 0.8, 0.1, True), (1.0, 2.0, 2.8, 0.8, 0.1, False)],
)
def test_linear_impact_oscillator_closed_form(a, f, omega, eta, delta, stable):
    y_ref, M_ref, phi, v = linear_impact_orbit(a, f, omega, eta, delta)
    osc = Oscillator(mu=0.0, c=0.0, a=a, f=f, omega=omega, eta=eta, delta=delta, F0=0.0,
                     x0=min(delta, -0.5))
    system = ImpactSystem(osc, options=TIGHT)
    orbit = shoot(system, y_ref + np.array([0.02, -0.03]), periods=1)
    np.testing.assert_allclose(orbit.state, y_ref, atol=1e-9)
    assert orbit.impacts == 1 and orbit.label == "1/1"
    T = system.forcing_period
    assert math.isclose(orbit.impact_time[0] % T, phi / omega, abs_tol=1e-9)
    assert math.isclose(orbit.impact_velocity[0], v, rel_tol=1e-9)
    np.testing.assert_allclose(orbit.jacobian, M_ref, atol=1e-8 * np.abs(M_ref).max())
    np.testing.assert_allclose(np.sort_complex(orbit.multipliers),
                               np.sort_complex(np.linalg.eigvals(M_ref)), atol=1e-8)
    assert math.isclose(np.prod(orbit.multipliers).real, eta**2, rel_tol=1e-8)
    assert orbit.stable is stable


def test_grazing_gap_of_free_oscillation():
    # x'' + x = 0 from (-A, 0): x = -A cos t reaches A at t = pi, 1e-4 below the wall;
    # every state is 2 pi-periodic (multipliers 1, 1) and the orbit grazes
    A = 0.5
    osc = Oscillator(mu=0.0, c=0.0, a=1.0, f=0.0, omega=1.0, eta=0.8, delta=A + 1e-4, F0=0.0)
    orbit = shoot(ImpactSystem(osc, options=TIGHT), [-A, 0.0], periods=1)
    assert orbit.impacts == 0
    assert math.isclose(orbit.min_gap, 1e-4, rel_tol=1e-6)
    np.testing.assert_allclose(orbit.multipliers, [1.0, 1.0], atol=1e-8)
    assert {"grazing", "fold"} <= set(orbit.classify())


# --------------------------------------------------------------------------- Lyapunov
def test_lyapunov_two_independent_estimates_agree_in_chaos():
    # section 3.1, F0 = 0, c = 0.02: beyond the period-doubling cascade, one impact per
    # forcing period, no sticking
    system = ImpactSystem(preset("3.1", F0=0.0, c=0.02), options=SolverOptions(rtol=1e-10,
                                                                                 atol=1e-10))
    # 15000 periods: each estimate's batch-means standard error is ~1%, so 5% is a
    # ~4-sigma bound for two estimates along different (chaotic) trajectories
    var = lyapunov_exponent(system, periods=15000, transient=200)
    ben = lyapunov_benettin(system, periods=15000, transient=200)
    assert var.exponent > 0.05 and var.impacts >= 15000 and var.sticks == 0
    assert abs(var.exponent - ben.exponent) < 0.05 * abs(ben.exponent)


def test_lyapunov_of_periodic_orbit_is_log_multiplier():
    system = ImpactSystem(preset("3.1", F0=0.0, c=0.05))
    orbit = periodic_orbit(system)
    expected = math.log(orbit.spectral_radius) / (orbit.periods * system.forcing_period)
    est = lyapunov_exponent(system, periods=400, transient=300)
    assert math.isclose(est.exponent, expected, rel_tol=1e-2)
    # once the tangent vector has aligned with the leading Floquet vector
    tail = est.log_growth[100:].mean() / system.forcing_period
    assert math.isclose(tail, expected, rel_tol=1e-5)


def test_transverse_exponent_matches_growth_of_a_seed():
    # EMR_0 = DMR is invariant in the OPA system at sigma = 0; with the ensemble law its
    # section 3.2 (omega = 4.2, F0 = 0) orbit is transversally unstable: a 1e-14 seed in
    # x_1, integrated by the independent solver, grows at the transverse exponent
    options = SolverOptions(rtol=1e-11, atol=1e-11)
    osc = preset("3.2", omega=4.2, F0=0.0)
    dmr = simulate_dmr(osc, periods=300, options=options)
    est = transverse_lyapunov_exponent(
        ImpactSystem(osc, model="opa", sigma=0.0, order=1, impact_law="ensemble",
                     options=options),
        periods=1000, transient=300)
    ds = simulate_opa(osc, sigma=0.0, order=1, impact_law="ensemble", periods=200,
                      options=options,
                      initial=np.array([[float(dmr.x[-1]), 1e-14], [float(dmr.v[-1]), 0.0]]))
    amp = np.hypot(ds.x_coef.values[1], ds.v_coef.values[1])
    t = ds.time.values
    sel = (t > 20 * osc.forcing_period) & (amp < 1e-6)
    slope = np.polyfit(t[sel], np.log(amp[sel]), 1)[0]
    assert est.exponent > 0.05
    assert math.isclose(slope, est.exponent, rel_tol=0.02)


@pytest.mark.slow
def test_lyapunov_two_estimates_agree_opa():
    system = ImpactSystem(preset("3.1", F0=0.0, c=0.02), model="opa", order=4, sigma=0.02,
                          options=SolverOptions(rtol=1e-10, atol=1e-10))
    var = lyapunov_exponent(system, periods=8000, transient=200)
    ben = lyapunov_benettin(system, periods=8000, transient=200)
    assert var.exponent > 0.05
    assert abs(var.exponent - ben.exponent) < 0.05 * abs(ben.exponent)


# --------------------------------------------------------------------------- impulses
def test_impulse_cycle():
    assert impulse_cycle(preset("3.1", F0=0.0)) == 1
    assert impulse_cycle(preset("3.1")) == 14  # T1 = 2.8 T, constant amplitudes (n = 2)
    assert impulse_cycle(preset("3.1", n=4.0)) == 56  # amplitudes repeat every 4 impulses
    assert impulse_cycle(preset("3.2")) == 199  # omega = 3.98 = 199/50
    assert impulse_cycle(preset("3.1", omega=math.sqrt(8.0))) is None


def test_map_with_impulses_needs_the_common_period():
    system = ImpactSystem(preset("3.1"))
    with pytest.raises(ValueError, match="multiple of 14"):
        poincare_map(system, [-1.0, 0.0], periods=2)
    with pytest.raises(ValueError, match="no common period"):
        poincare_map(ImpactSystem(preset("3.1", omega=math.sqrt(8.0))), [-1.0, 0.0])


# --------------------------------------------------------------------------- validation
def test_bad_input_is_reported():
    with pytest.raises(ValueError, match="model"):
        ImpactSystem(model="mc")
    # the DMR has no uncertainty: the System's sigma and N are not part of it
    assert (ImpactSystem(sigma=0.1).sigma, ImpactSystem(order=6).order) == (0.0, 0)
    with pytest.raises(ValueError, match="periods"):
        poincare_map(ImpactSystem(preset("3.1", F0=0.0)), [-1.0, 0.0], periods=0)
    with pytest.raises(ValueError, match="beyond the wall"):
        poincare_map(ImpactSystem(preset("3.1", F0=0.0)), [0.5, 0.0])
    with pytest.raises(ValueError, match="parameter"):
        continue_orbits(ImpactSystem(preset("3.1", F0=0.0)), "x0", 0.0, 1.0)


def test_an_orbits_gap_is_the_nearer_walls_and_grazes_at_the_lower_wall():
    """The linear oscillator of ``test_sweep``'s lower-wall cases at f = 0.9995 f_g: its
    period-1 orbit has no impact and its minimum lies 1 - A = 5e-4 above the lower wall
    (closed form), far below the upper wall (4 + ...): ``min_gap`` is the lower wall's,
    and the orbit is classified grazing (ORBIT_GRAZE_GAP 1e-3)."""
    from tests.opa.dynamics.test_sweep import (
        LOWER_DENOMINATOR,
        LOWER_GRAZE_F,
        lower_wall_oscillator,
    )

    f = 0.9995 * LOWER_GRAZE_F
    system = ImpactSystem(lower_wall_oscillator(f=f), options=TIGHT)
    orbit = periodic_orbit(system)
    assert orbit.periods == 1 and len(orbit.impact_time) == 0
    assert orbit.min_gap == pytest.approx(1.0 - f / LOWER_DENOMINATOR, abs=1e-9)
    assert "grazing" in orbit.classify() and orbit.stable
