"""The attractor of one run (opa.dynamics._attractor): each type against an independent
reference written here (scipy integrations of tests/reference.py, analytic facts about the
repeat distances), the early stop against the full horizon, the approach to a period
through a multiplier near -1 on both sides of a located doubling."""

import math

import numpy as np
import pytest

from opa import ForceLaw, Oscillator, SolverOptions, System, preset
from opa.dynamics._attractor import (
    CHAOS_THRESHOLD,
    Settings,
    _flip_fit,
    initial_states,
    row,
    same_attractor,
    sample_inputs,
    settle,
    settle_batch,
)
from tests.reference import reference_trajectory

SECTION_31 = preset("3.1", F0=0.0)
OPTIONS = SolverOptions()


def one(oscillator, mu=None, state=None, **settings):
    """The attractor of ``oscillator`` (mu replaced when given) from ``state``."""
    osc = oscillator if mu is None else oscillator.replace(mu=mu)
    system = System(osc, sigma=0.0, order=0)
    inputs = sample_inputs(system, OPTIONS, [osc.mu])
    start = (osc.x0, osc.v0) if state is None else state
    row = type(inputs)(*(np.asarray(a)[0] for a in (inputs.p, inputs.cfg, inputs.table,
                                                    inputs.weights, inputs.basis)))
    return settle(system, row, start, options=OPTIONS, settings=Settings(**settings))


def reference(osc, periods, *, state=None, rtol=1e-10, impulse_at_zero=True):
    """The scipy reference's stroboscopic points (x, v) at k T, k = 0 .. periods."""
    model = {k: getattr(osc, k) for k in ("mu", "a", "c", "f", "omega", "eta", "delta", "F0",
                                          "a1", "omega1", "n", "x0", "v0")}
    if state is not None:
        model["x0"], model["v0"] = state
    T = 2 * np.pi / osc.omega
    r = reference_trajectory(**model, t_out=np.arange(periods + 1) * T, rtol=rtol, atol=rtol,
                             impulse_at_zero=impulse_at_zero)
    return np.stack([r["x"], r["v"]], axis=1)


def test_a_period_two_orbit_settles_early_and_scipy_sees_the_same_period():
    """c = 0.05 (the paper's 2/2 of Fig. 4): settled well before the longest transient;
    scipy's stroboscopic points repeat every 2 periods, not every period."""
    osc = SECTION_31.replace(c=0.05)
    a = one(osc)
    assert (a.type, a.period, a.impacts, a.settled) == ("2/2", 2, 2, True)
    assert a.periods <= 160
    s = reference(osc, 160)[-20:]
    assert np.abs(s[2:] - s[:-2]).max() < 1e-6 < np.abs(s[1:] - s[:-1]).max()
    np.testing.assert_allclose(np.sort(a.points[:, 0]), np.sort(s[-2:, 0]), atol=1e-6)


def test_a_chaotic_run_and_the_exponent_of_two_scipy_trajectories():
    """c = 0.02, mu = 0.8 (the Lyapunov test case of docs/stability.md): chaotic, stopped
    after the early window with an exponent above the threshold; two scipy trajectories
    1e-9 apart separate at a rate above the threshold too (slope of log separation over
    25 periods, both started from scipy's own state after 60 periods)."""
    osc = SECTION_31.replace(c=0.02)
    a = one(osc)
    assert a.type == "chaotic" and a.settled
    assert a.lyapunov > CHAOS_THRESHOLD
    start = reference(osc, 60)[-1]
    u = np.array([1.0, 1.0]) / math.sqrt(2.0)
    if start[0] + 1e-9 > osc.delta:
        u = -u
    T = osc.forcing_period
    near = reference(osc.replace(), 25, state=start)
    far = reference(osc.replace(), 25, state=start + 1e-9 * u)
    growth = np.log(np.linalg.norm(far - near, axis=1)[1:])
    slope = np.polyfit(np.arange(1, 26) * T, growth, 1)[0]
    assert slope > 5 * CHAOS_THRESHOLD


def test_a_quasi_periodic_run_under_an_incommensurate_impulse_train():
    """Section 3.3 (F0 = 0.1) at omega = 4 + 0.1 sqrt(2): the impulses every 2 pi and the
    forcing period 2 pi / omega have no common period, and the forced motion is stable:
    quasi-periodic, decided early by a negative exponent. scipy: no repeat within 1e-4
    for any p <= 32 over 64 periods after 66, and a perturbation of 1e-7 at t = 0 shrinks
    (the slope of its log over the first 30 periods is below -threshold)."""
    osc = preset("3.3").replace(omega=4 + 0.1 * math.sqrt(2.0))
    a = one(osc, transient=300)
    assert a.type == "quasi-periodic" and a.settled and a.periods < 300
    assert a.lyapunov < -CHAOS_THRESHOLD
    s = reference(osc, 130)
    window = s[-64:]
    scale = np.abs(window).max()
    assert all(np.abs(window[p:] - window[:-p]).max() > 1e-4 * scale for p in range(1, 33))
    # the impulse train runs on absolute time: perturb at t = 0 (the reference starts there)
    far = reference(osc, 30, state=(osc.x0 - 1e-7, osc.v0))
    growth = np.log(np.linalg.norm(far - s[:31], axis=1)[1:])
    assert np.polyfit(np.arange(1, 31) * osc.forcing_period, growth, 1)[0] < -CHAOS_THRESHOLD


@pytest.mark.parametrize("xi, kind", [(-0.45, "2/2"), (-0.33, "1/1")])
def test_the_approach_through_a_multiplier_near_minus_one(xi, kind):
    """Section 3.1 at c = 0.0895, sigma = 0.05: the period-1 orbit doubles at
    xi = -0.39213 (docs/stochastic.md). On its stable side the runs approach it through a
    multiplier near -1 and look period-2 to 1e-4 for hundreds of periods; they are
    classified 1/1, and the runs beside the 2-cycle 2/2. Reference: the Floquet
    multipliers of the period-1 orbit by Newton shooting (opa.periodic_orbit, another
    algorithm): inside the unit circle on the 1/1 side, one beyond -1 on the other."""
    from opa.dynamics import ImpactSystem, periodic_orbit

    osc = SECTION_31.replace(c=0.0895, mu=0.8 + 0.05 * xi)
    a = one(osc)
    assert a.type == kind
    orbit = periodic_orbit(ImpactSystem(osc, options=OPTIONS), periods=1, transient=0,
                           guess=np.array([*_period_one_guess(osc)]))
    assert (np.abs(orbit.multipliers).max() < 1) == (kind == "1/1")
    assert np.min(orbit.multipliers.real) < -0.9  # near the doubling: a multiplier near -1


def _period_one_guess(osc):
    """A point near the period-1 orbit: the run's mean over two periods after 600 (the
    alternating deviation cancels)."""
    from opa._run import run

    inputs = System(osc, sigma=0.0, order=0).deterministic().kernel_inputs(OPTIONS)
    s = run(inputs, np.array([osc.x0, osc.v0]), np.arange(602) * osc.forcing_period,
            rtol=1e-10, atol=1e-10).states
    return 0.5 * (s[-1] + s[-2])


@pytest.mark.parametrize("eps", [0.002, -0.002, 0.0005, -0.0005])
def test_the_flip_fit_reads_eps_off_the_normal_form(eps):
    """x -> -(1 - eps) x + x^3 (the supercritical flip's normal form) from x = 0.3, 300
    steps, the second half still in the algebraic decay: the fit's intercept is eps to
    5 % (eps > 0: approach to the fixed point; eps < 0: to the 2-cycle)."""
    x, pts = 0.3, []
    for _ in range(300):
        pts.append((x, 0.5 * x))
        x = -(1 - eps) * x + x ** 3
    fit = _flip_fit(np.array(pts) + np.array([1.0, 0.0]), 1, 1.3)
    assert fit is not None
    assert abs(fit[0] - eps) < 0.05 * abs(eps)


def test_early_stop_agrees_with_the_full_horizon():
    """The runs that settled early keep their type when run to the full horizon and
    classified from the last 64 periods at 1e-4 (a sweep's rule, scipy-free but a
    different algorithm): 24 values of mu across the 2/2 -> 4/4 doubling at c = 0.04."""
    from opa.dynamics._sections import detect_period

    osc = SECTION_31.replace(c=0.04)
    mus = 0.8 + 0.03 * np.linspace(-0.9, 0.9, 24)
    system = System(osc, sigma=0.0, order=0)
    found = settle_batch(system, sample_inputs(system, OPTIONS, mus),
                         np.tile([osc.x0, osc.v0], (len(mus), 1)), options=OPTIONS)
    from opa._run import run

    for mu, a in zip(mus, found):
        if not a.settled:
            continue
        inputs = System(osc.replace(mu=mu), sigma=0.0, order=0).deterministic() \
            .kernel_inputs(OPTIONS)
        s = run(inputs, np.array([osc.x0, osc.v0]), np.arange(2065) * osc.forcing_period,
                rtol=1e-10, atol=1e-10).states[-64:]
        assert detect_period(s[:, 0], s[:, 1])[0] == a.period


def test_coexisting_orbits_of_one_type_are_told_apart_and_scipy_keeps_each():
    """Section 3.1 with the paper's impulses (F0 = 0.1), c = 0.07, mu = 0.8: two stable
    14T orbits coexist (docs/stability.md: one folds at c = 0.0711811408, the other at
    0.0735900439). From (x0, v0) and from (-0.5, -1) the runs settle on different orbits
    of the same label; ``same_attractor`` tells them apart. scipy, from each run's final
    state (a multiple of the 14-period cycle: the clock restarts in phase), stays on its
    orbit for 28 periods (repeat every 14 to 1e-6), the two orbits are 1e-2 apart, and a
    kick of 1e-4 off each is smaller after two cycles than after one (each attracts; slowly,
    near its fold)."""
    osc = preset("3.1").replace(c=0.07)
    system = System(osc, sigma=0.0, order=0)
    starts = np.array([[osc.x0, osc.v0], [-0.5, -1.0]])
    a, b = settle_batch(system, sample_inputs(system, OPTIONS, [0.8, 0.8]), starts,
                        options=OPTIONS)
    assert a.type == b.type == "14/14"
    assert not same_attractor(a, b) and same_attractor(a, a)
    orbits = []
    for found in (a, b):
        assert found.periods % 14 == 0
        s = reference(osc, 28, state=found.state, impulse_at_zero=False)
        assert np.abs(s[14:] - s[:-14]).max() < 1e-6
        orbits.append(s[:14])
        kicked = reference(osc, 28, state=found.state + np.array([-1e-4, 0.0]),
                           impulse_at_zero=False)
        off = np.abs(kicked - s).max(axis=1)
        assert off[28] < off[14]  # the kick dies down from one cycle to the next
    gap = np.abs(orbits[0][:, None] - orbits[1][None]).max(axis=2).min(axis=1).max()
    assert gap > 1e-2


def test_initial_states_are_inside_the_wall():
    states = initial_states(SECTION_31, 3)
    assert states.shape == (4, 2)
    assert tuple(states[0]) == (SECTION_31.x0, SECTION_31.v0)
    assert np.all(states[:, 0] <= SECTION_31.delta)


def test_bad_settings_are_named():
    with pytest.raises(ValueError, match="record must be >= 4"):
        Settings(record=2)
    with pytest.raises(ValueError, match="settle_tol must be a finite number > 0"):
        Settings(settle_tol=0.0)


# ------------------------------------------------------------------------ a lower wall
def settled_with(osc, name: str, value: float, state):
    """The attractor of ``osc`` with its parameter ``name`` (a force law's constant) at
    ``value``, from ``state``."""
    system = System(osc, sigma=0.0, order=0, uncertain=name)
    inputs = sample_inputs(system, OPTIONS, [value])
    return settle(system, row(inputs, 0), state, options=OPTIONS)


def test_impacts_on_the_lower_wall_count_in_the_label():
    """``test_sweep``'s linear oscillator at f = 1.1 f_g hits only the lower wall: scipy's
    event integrator sees 50 impacts, all at the lower wall, over periods 200..300, one
    every two periods; the classification says 2/1 (period 2, one impact)."""
    from tests.impact_truths import two_wall_impacts
    from tests.opa.dynamics.test_sweep import (
        LOWER_GRAZE_F,
        LOWER_OMEGA,
        LOWER_WALL,
        LOWER_ZETA,
        lower_wall_oscillator,
    )

    osc = lower_wall_oscillator(f=1.1 * LOWER_GRAZE_F)
    T = osc.forcing_period
    truth = two_wall_impacts(lambda x, v: -2 * LOWER_ZETA * v - x, osc.f, LOWER_OMEGA,
                             (LOWER_WALL, osc.delta), (osc.lower_restitution, osc.eta),
                             (osc.x0, osc.v0), 300 * T, rtol=1e-10, atol=1e-11)
    late = truth["times"] > 200 * T
    assert set(truth["wall"][late]) == {-1}
    got = settled_with(osc, "zeta", LOWER_ZETA, (osc.x0, osc.v0))
    assert got.period * late.sum() == 100 * got.impacts
    assert (got.type, got.period, got.impacts) == ("2/1", 2, 1)


def test_resting_on_the_lower_wall_is_sticking():
    """x'' = -1 + 0.5 cos t pushes the mass onto the lower wall x = -1 at all times: from
    rest there it never leaves (the force never turns away from the wall); it was
    labelled 1/0 when only the upper wall could hold it."""
    osc = Oscillator(force=ForceLaw("-g", g=1.0), f=0.5, omega=1.0, delta=5.0,
                     delta_minus=-1.0, F0=0.0, omega1=1.0, x0=-1.0, v0=0.0)
    assert settled_with(osc, "g", 1.0, (-1.0, 0.0)).type == "sticking"


def test_other_initial_states_lie_between_the_walls():
    osc = Oscillator(delta=0.2, delta_minus=-0.2, x0=0.0)
    states = initial_states(osc, 6)
    assert np.all((states[:, 0] > -0.2) & (states[:, 0] < 0.2))
    assert np.array_equal(states[1:, 1], initial_states(Oscillator(), 6)[1:, 1])
    one_wall = initial_states(Oscillator(delta=0.2), 6)  # as it was: 0.5 below the wall
    assert np.isclose(one_wall[:, 0].max(), -0.3) and one_wall[:, 0].min() < -0.8
