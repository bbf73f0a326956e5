"""A second, lower wall x = delta_minus < delta (issue 43, item 2): the motion in
delta_minus < x < delta, a gear pair rattling in its backlash.

Independent reference: the scipy event integrator of ``tests/impact_truths.py``
(``two_wall_impacts``), with its own walls, restitutions and impact detection; sticking,
which it does not model, is checked against the physics of a mass pushed onto the wall
(it rests while the force pushes into the wall and leaves at the force's root).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import mc
import opa
from opa import _kernel as kernel
from opa._run import Events, Variational, run
from tests.impact_truths import two_wall_impacts

# The gear pair: x'' = -2 zeta x' - x + f cos(omega t) between walls -0.8 and 0.5 with
# restitutions 0.7 (lower) and 0.85 (upper): from rest at x = 0, 27 impacts in ten
# periods, both walls, twice in a row on the same wall too, pre-impact speeds >= 0.30.
ZETA, F, OMEGA = 0.05, 1.5, 1.0
WALLS, RESTITUTIONS = (-0.8, 0.5), (0.7, 0.85)
T = 2 * math.pi / OMEGA
TIGHT = opa.SolverOptions(rtol=1e-11, atol=1e-11)


def gear_pair(**changes) -> opa.Oscillator:
    fields = dict(force=opa.ForceLaw("-2*zeta*v - k*x", zeta=ZETA, k=1.0), a=1.0, f=F,
                  omega=OMEGA, eta=RESTITUTIONS[1], delta=WALLS[1], delta_minus=WALLS[0],
                  eta_minus=RESTITUTIONS[0], F0=0.0, omega1=OMEGA, x0=0.0, v0=0.0)
    return opa.Oscillator(**{**fields, **changes})


def truth(force, osc: opa.Oscillator, t_end: float) -> dict:
    return two_wall_impacts(force, osc.f, osc.omega, (osc.delta_minus, osc.delta),
                            (osc.lower_restitution, osc.eta), (osc.x0, osc.v0), t_end,
                            rtol=1e-12, atol=1e-13)


def test_the_gear_pair_rattles_between_its_walls_as_scipy_says():
    """Every impact time within 1e-8 of scipy's and the same sequence of walls over ten
    periods (measured: times within 6e-12, pre-impact velocities within 5e-12 at
    rtol = 1e-11)."""
    osc = gear_pair()
    want = truth(lambda x, v: -2 * ZETA * v - x, osc, 10 * T)
    ds = opa.simulate_dmr(osc, periods=10, options=TIGHT)
    walls = ds.impact_wall.values
    assert len(want["times"]) == 27 and set(want["wall"]) == {-1, 1}
    np.testing.assert_array_equal(walls, want["wall"])
    np.testing.assert_allclose(ds.impact_time.values, want["times"], rtol=0, atol=1e-8)
    np.testing.assert_allclose(ds.impact_velocity.values, want["velocities"], rtol=0, atol=1e-8)
    assert np.all(np.sign(ds.impact_velocity.values) == walls)  # v- < 0 at the lower wall
    assert ds.x.values[-1] == pytest.approx(want["state"][0], abs=1e-8)
    assert ds.attrs["delta_minus"] == -0.8 and ds.attrs["eta_minus"] == 0.7


def test_the_papers_law_with_a_lower_wall():
    """The paper's force law (section 3.2, no impulses) with a lower wall at -1.2 under
    the start x0 = -1: impacts on both walls, times within 1e-8 of scipy's over five
    periods."""
    osc = opa.preset("3.2", F0=0.0, delta_minus=-1.2, eta_minus=0.6, f=4.0)
    mu, a, c = osc.mu, osc.a, osc.c
    want = truth(lambda x, v: mu * (1 - v * v) * v - a * x - c * x ** 3, osc,
                 5 * osc.forcing_period)
    ds = opa.simulate_dmr(osc, periods=5, options=TIGHT)
    assert set(want["wall"]) == {-1, 1}
    np.testing.assert_array_equal(ds.impact_wall.values, want["wall"])
    np.testing.assert_allclose(ds.impact_time.values, want["times"], rtol=0, atol=1e-8)


def test_one_wall_datasets_have_no_lower_wall_variables():
    ds = opa.simulate_dmr(gear_pair(delta_minus=-math.inf, eta_minus=None), periods=2)
    assert "impact_wall" not in ds and "delta_minus" not in ds.attrs
    assert "eta_minus" not in ds.attrs


def test_order_zero_opa_is_the_dmr_bit_for_bit():
    """N = 0 (one node at xi = 0) and sigma = 0 with N = 3 (higher modes exactly 0): the
    OPA mean is the DMR's trajectory, bit for bit, with both walls."""
    osc = gear_pair()
    dmr = opa.simulate_dmr(osc, periods=5, per_period=4)
    for order, sigma in ((0, 0.05), (3, 0.0)):
        ds = opa.simulate_opa(opa.System(osc, uncertain="k", sigma=sigma, order=order),
                              periods=5, per_period=4)
        np.testing.assert_array_equal(ds.x_mean.values, dmr.x.values)
        np.testing.assert_array_equal(ds.impact_time.values, dmr.impact_time.values)
        np.testing.assert_array_equal(ds.impact_wall.values, dmr.impact_wall.values)


def test_opa_of_an_uncertain_stiffness_agrees_with_monte_carlo():
    """The gear pair with an uncertain stiffness k = 1 + 0.05 xi (uniform) over three
    periods, impacts on both walls (Var[x] up to 4.3e-3), under the saltation law, against
    Monte Carlo on a 64-node Gauss-Legendre rule (64 and 128 nodes agree to 1e-6). The
    OPA error is the mean constraint's (an element's mean hits the wall where not all its
    samples do), falling with the element width. Measured max |E[x]| errors 1.3e-2, 9.4e-4,
    7.1e-5 on 1, 4, 16 elements (the mean law: 1.1e-2, 8.3e-4, 7.9e-5), Var[x] 2.3e-5 on
    16; adaptive elements (23) 2.9e-5 and 9.1e-6."""
    osc = gear_pair()
    times = np.linspace(0.0, 3 * T, 13)
    system = opa.System(osc, uncertain="k", sigma=0.05, distribution="uniform", order=3,
                        impact_law="saltation")
    ref = mc.simulate_mc(system, samples=64, sampler="gauss", times=times, progress=False)
    walls = set()
    for sample in (-0.9, 0.0, 0.9):
        dmr = opa.simulate_dmr(osc.replace(k=1.0 + 0.05 * sample), times=times)
        walls |= set(dmr.impact_wall.values)
    assert walls == {-1, 1}
    assert float(ref.x_var.max()) > 1e-3  # the uncertainty matters
    errors = {}
    for elements in (None, 4, 16):
        ds = opa.simulate_opa(system, times=times, elements=elements)
        errors[elements] = (float(np.abs(ds.x_mean.values - ref.x_mean.values).max()),
                            float(np.abs(ds.x_var.values - ref.x_var.values).max()))
    e1, e4, e16 = (errors[k][0] for k in (None, 4, 16))
    assert e1 > 10 * e4 > 100 * e16, errors
    assert e16 < 2e-4 and errors[16][1] < 5e-5, errors


@pytest.mark.parametrize("impact_law", ["mean", "ensemble", "saltation"])
def test_every_impact_law_at_the_lower_wall_against_monte_carlo(impact_law):
    """N = 1, one element, k = 1 + sigma xi (uniform) over three periods (impacts at
    t = 0.89 upper, 2.69 and 4.50 lower, 5.99 upper, ...): every law's E[x] is right to
    O(sigma^2) (measured 4e-6 at sigma = 1e-3, 4e-4 at 1e-2: a wrong sign at the lower
    wall would be O(1)); the saltation law's Var[x] is first-order exact (relative error
    5.7e-5 and 5.7e-3, falling as sigma^2: the gain (a+ + eta a-) / v- with the signed
    v- < 0), the mean and ensemble laws' are O(1) off (0.57, 0.97), as at one wall."""
    osc = gear_pair()
    times = np.linspace(0.0, 3 * T, 13)
    errors = []
    for sigma in (1e-3, 1e-2):
        system = opa.System(osc, uncertain="k", sigma=sigma, distribution="uniform", order=1,
                            impact_law=impact_law)
        ref = mc.simulate_mc(system, samples=32, sampler="gauss", times=times,
                             progress=False)
        ds = opa.simulate_opa(system, times=times)
        errors.append((float(np.abs(ds.x_mean.values - ref.x_mean.values).max()),
                       float(np.abs(ds.x_var.values - ref.x_var.values).max()
                             / ref.x_var.values.max())))
    (mean3, var3), (mean2, var2) = errors
    assert mean3 < 1e-5 and mean2 < 1e-3, errors
    if impact_law == "saltation":
        assert var3 < 2e-4 and 50 * var3 < var2 < 2e-2, errors
    else:
        assert var3 > 0.3, errors


def test_the_tangent_map_through_lower_wall_impacts_is_the_flow_maps_derivative():
    """The Jacobian of the flow map over two periods (W through the saltation matrices
    of three lower-wall and three upper-wall impacts) against central differences of the
    end state in the start state (steps 1e-6; measured difference 2.2e-9)."""
    osc = gear_pair()
    system = opa.System(osc, order=0)
    inputs = system.kernel_inputs(TIGHT)
    times = np.array([0.0, 2 * T])
    y0 = system.initial_state()
    rec = run(inputs, y0, times, rtol=1e-12, atol=1e-12, variational=Variational(np.eye(2)))
    assert set(rec.events.wall[rec.events.impacts]) == {-1, 1}
    fd = np.empty((2, 2))
    for j in range(2):
        step = np.zeros(2)
        step[j] = 1e-6
        plus = run(inputs, y0 + step, times, rtol=1e-12, atol=1e-12).states[-1]
        minus = run(inputs, y0 - step, times, rtol=1e-12, atol=1e-12).states[-1]
        fd[:, j] = (plus - minus) / 2e-6
    np.testing.assert_allclose(rec.tangent, fd, rtol=0, atol=1e-7)


def scipy_gaps(want: dict, times, delta_minus, delta):
    """Per interval of ``times``: the smallest x - delta_minus at scipy's free-flight minima
    and delta - x at its maxima (inf where there is none)."""
    lower, upper = np.full(len(times) - 1, np.inf), np.full(len(times) - 1, np.inf)
    seg = np.searchsorted(times, want["turn_times"], side="right") - 1
    for j, x, kind in zip(seg, want["turn_x"], want["turn_kind"]):
        if kind == 1:
            lower[j] = min(lower[j], x - delta_minus)
        else:
            upper[j] = min(upper[j], delta - x)
    return lower, upper


@pytest.mark.parametrize("delta_minus", [-0.8, -1.2])
def test_the_lower_walls_gap_is_the_lowest_free_flight_minimum_as_scipy_says(delta_minus):
    """Statistics.gap_lower (kernel S_GAP_LOWER) per quarter period over ten: x_0 -
    delta_minus at the lowest free-flight minimum, inf where the interval has none, as
    scipy's turning points say (measured within 7e-12); the upper wall's gap as well."""
    osc = gear_pair(delta_minus=delta_minus)
    system = opa.System(osc, order=0)
    times = np.linspace(0.0, 10 * T, 41)
    rec = run(system.kernel_inputs(TIGHT), system.initial_state(), times, rtol=1e-12,
              atol=1e-12, statistics=True)
    want = truth(lambda x, v: -2 * ZETA * v - x, osc, 10 * T)
    lower, upper = scipy_gaps(want, times, delta_minus, osc.delta)
    stats = rec.statistics
    assert np.isfinite(lower).sum() >= 9
    for got, expected in ((stats.gap_lower, lower), (stats.gap, upper)):
        np.testing.assert_array_equal(np.isfinite(got), np.isfinite(expected))
        finite = np.isfinite(expected)
        np.testing.assert_allclose(got[finite], expected[finite], rtol=0, atol=1e-9)
    np.testing.assert_allclose(stats.nearest_gap, np.minimum(lower, upper), rtol=0, atol=1e-9)
    one_wall = run(system.replace(oscillator=osc.replace(delta_minus=-math.inf))
                   .kernel_inputs(TIGHT), system.initial_state(), times, rtol=1e-12,
                   atol=1e-12, statistics=True).statistics
    assert np.all(one_wall.gap_lower == np.inf)


# ---------------------------------------------------------------- sticking on the lower wall
def pushed(**changes) -> opa.Oscillator:
    """x'' = -1 + 2 cos t with the lower wall at -1 (the upper at 5, out of reach): from
    rest at 0 the mass rises, falls onto the lower wall at t ~ 3.15 with the force
    -1 + 2 cos t ~ -3 into it, chatters (restitution 0.3) and sticks, and leaves where the
    force turns upwards, at t = 5 pi / 3."""
    fields = dict(force=opa.ForceLaw("-g", g=1.0), a=1.0, f=2.0, omega=1.0, eta=0.8,
                  delta=5.0, delta_minus=-1.0, eta_minus=0.3, F0=0.0, omega1=1.0, x0=0.0,
                  v0=0.0)
    return opa.Oscillator(**{**fields, **changes})


def test_chatter_sticks_on_the_lower_wall_and_releases_at_the_forces_root():
    """The mass rests at delta_minus (x = -1, v = 0 at every output) from the chatter's
    end until the force -1 + 2 cos t changes sign at 5 pi / 3 (the root, independently:
    cos t = 1/2), and the release is there to 1e-9; the first impact is where the free
    flight x = 2 - 2 cos t - t^2 / 2 reaches -1 (brentq)."""
    from scipy.optimize import brentq

    osc = pushed()
    times = np.linspace(0.0, 2 * math.pi, 241)
    ds = opa.simulate_dmr(osc, times=times, options=TIGHT)
    first = brentq(lambda t: 2 - 2 * math.cos(t) - t * t / 2 + 1, 2.5, 4.0, xtol=1e-14)
    release = 5 * math.pi / 3
    assert ds.impact_time.values[0] == pytest.approx(first, abs=1e-9)
    assert np.all(ds.impact_wall.values == -1) and len(ds.impact_time) > 5
    assert len(ds.stick_time) == 1 and len(ds.release_time) == 1
    t_stick, t_release = float(ds.stick_time[0]), float(ds.release_time[0])
    assert first < t_stick < 4.5
    assert t_release == pytest.approx(release, abs=1e-9)
    resting = (times > t_stick + 1e-9) & (times < t_release)
    assert resting.sum() > 10
    np.testing.assert_array_equal(ds.x.values[resting], -1.0)
    np.testing.assert_array_equal(ds.v.values[resting], 0.0)
    after = times > t_release
    assert np.all(ds.x.values[after] > -1.0)  # it leaves upwards
    system = opa.System(osc, order=0)
    rec = run(system.kernel_inputs(TIGHT), system.initial_state(), times, rtol=TIGHT.rtol,
              atol=TIGHT.atol)
    kinds = rec.events.kind[~rec.events.located]  # the last bounces may be grazes
    assert list(kinds) == [Events.STICK, Events.RELEASE]
    assert np.all(rec.events.wall == -1)


def test_at_rest_on_the_lower_wall_it_stays_while_pushed_into_it():
    """Started at rest on the lower wall with the force -1 + 0.5 cos t < 0 always into it:
    sticking from the start, held exactly there."""
    ds = opa.simulate_dmr(pushed(f=0.5, x0=-1.0), periods=3, per_period=8)
    np.testing.assert_array_equal(ds.x.values, -1.0)
    np.testing.assert_array_equal(ds.v.values, 0.0)
    assert len(ds.stick_time) == 1 and len(ds.release_time) == 0


@pytest.mark.parametrize("impact_law", ["mean", "ensemble", "saltation"])
def test_a_kick_into_the_lower_wall_reflects_with_its_restitution(impact_law):
    """A Dirac kick of -0.5 at t = 0 on the mass at rest on the lower wall is an impact
    at once: v = 0.5 eta_minus right after it (the state at t = 0), logged as a kick at
    the lower wall with the kicked velocity -0.5."""
    osc = pushed(x0=-1.0, f=0.5, F0=-0.5, a1=0.0)
    system = opa.System(osc, order=0, impact_law=impact_law)
    times = np.array([0.0, 0.1])
    rec = run(system.kernel_inputs(TIGHT), system.initial_state(), times, rtol=1e-11,
              atol=1e-11)
    assert rec.states[0, 1] == 0.5 * 0.3
    ev = rec.events
    assert ev.kind[0] == Events.KICK and ev.wall[0] == -1 and ev.velocity[0] == -0.5


def test_the_kernel_logs_lower_wall_events_with_their_own_kinds():
    """The raw log's kinds at the lower wall are the upper wall's plus EV_LOWER; Events
    decodes them into kind and wall."""
    log = np.array([[1.0, -2.0, kernel.EV_IMPACT + kernel.EV_LOWER],
                    [2.0, 3.0, kernel.EV_IMPACT],
                    [3.0, 0.0, kernel.EV_STICK + kernel.EV_LOWER]])
    ev = Events.of(log)
    np.testing.assert_array_equal(ev.kind, [Events.IMPACT, Events.IMPACT, Events.STICK])
    np.testing.assert_array_equal(ev.wall, [-1, 1, -1])
    assert ev.impacts.sum() == 2


def test_a_two_wall_run_names_its_lower_wall_to_whoever_reads_it_back():
    """Manifests (``as_dict``) and dataset attributes carry delta_minus and eta_minus
    only with a lower wall; ``compare.verify`` rebuilds the true systems with it."""
    from compare._verify import system_of

    osc = opa.preset("3.2", F0=0.0, delta_minus=-1.2)
    assert opa.Oscillator(**osc.as_dict()) == osc.replace(eta_minus=osc.eta)
    assert set(opa.Oscillator().as_dict()) == set(opa.PARAMETER_NAMES)
    ds = opa.simulate_opa(opa.System(osc, uncertain="mu", sigma=0.02, order=2), periods=1)
    assert (ds.attrs["delta_minus"], ds.attrs["eta_minus"]) == (-1.2, 0.8)
    system, _ = system_of(ds)
    assert system.oscillator == osc.replace(eta_minus=0.8)


# ---------------------------------------------------------------- refused input
@pytest.mark.parametrize("fields, words", [
    (dict(delta_minus=0.5), "delta_minus must be below the wall delta"),
    (dict(delta_minus=1.0), "delta_minus must be below the wall delta"),
    (dict(x0=-0.9), "x0 must not be below the lower wall"),
    (dict(x0=-0.8, v0=-0.1), "v0 must be >= 0 when x0 is at the lower wall"),
    (dict(eta_minus=0.0), "eta_minus must be in (0, 1]"),
    (dict(eta_minus=1.5), "eta_minus must be in (0, 1]"),
    (dict(eta_minus=float("nan")), "eta_minus must be finite"),
    (dict(delta_minus=float("nan")), "delta_minus must be a real number or -inf"),
    (dict(delta_minus="low"), "delta_minus must be a real number or -inf"),
])
def test_bad_lower_walls_are_refused_in_one_line(fields, words):
    with pytest.raises(ValueError) as err:
        gear_pair(**fields)
    assert words in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("name, sigma, errors", [
    ("delta", 0.02, (4.1e-3, 2.6e-4, 1.6e-5)), ("eta", 0.05, (3.5e-2, 1.2e-2, 2.9e-4))])
def test_an_uncertain_upper_wall_beside_a_lower_wall_converges_with_elements(name, sigma,
                                                                             errors):
    """The upper wall delta = 0.5 + sigma xi, or its restitution eta = 0.85 + sigma xi
    (uniform), with the lower wall deterministic: saltation law, N = 3, over three
    periods with impacts on both walls, against Monte Carlo on a 128-node Gauss-Legendre
    rule of the true systems (one node checked against scipy's two-wall integrator). The
    max |E[x]| error on 1, 4 and 16 elements measured ``errors``; it must fall 10-fold
    from 1 to 16 elements and more, and Var[x] with it."""
    osc = gear_pair()
    times = np.linspace(0.0, 3 * T, 13)
    system = opa.System(osc, uncertain=name, sigma=sigma, distribution="uniform", order=3,
                        impact_law="saltation")
    ref = mc.simulate_mc(system, samples=128, sampler="gauss", times=times, progress=False)
    node = osc.replace(**{name: getattr(osc, name) + 0.9 * sigma})
    dmr = opa.simulate_dmr(node, times=times, options=TIGHT)
    want = truth(lambda x, v: -2 * ZETA * v - x, node, 3 * T)
    assert abs(float(dmr.x[-1]) - want["state"][0]) < 1e-9
    assert set(dmr.impact_wall.values) == {-1, 1}
    got = []
    for elements in (None, 4, 16):
        ds = opa.simulate_opa(system, times=times, elements=elements)
        got.append((float(np.abs(ds.x_mean - ref.x_mean).max()),
                    float(np.abs(ds.x_var - ref.x_var).max())))
    assert got[0][0] > 10 * got[2][0] and got[0][1] > 10 * got[2][1], got
    assert got[2][0] < 2 * errors[2], got


def test_an_uncertain_wall_beside_a_lower_wall_is_checked_in_one_line():
    """An uncertain eta needs the lower wall's own eta_minus (left out, it is eta); an
    uncertain delta may not reach delta_minus anywhere on its support."""
    for osc, name, sigma, words in (
            (gear_pair(eta_minus=None), "eta", 0.05, "give the lower wall's own eta_minus"),
            (gear_pair(), "delta", 1.5, "at or below the lower wall")):
        with pytest.raises(ValueError) as err:  # the support is checked before any run
            opa.System(osc, uncertain=name, sigma=sigma, distribution="uniform").check_samples()
        assert words in str(err.value) and "\n" not in str(err.value)


def test_the_simulated_gpu_runs_the_two_wall_ensemble_as_the_cpu():
    """The CUDA simulator (``tests/opa/test_gpu.py``) on the gear pair's sampled
    stiffnesses: the same states and event logs (walls included) as the CPU kernel."""
    from tests.opa.test_gpu import _simulated

    got = _simulated("""
        import json
        import numpy as np
        import opa
        from opa import _run
        from tests.opa.test_two_walls import gear_pair, T
        system = opa.System(gear_pair(), uncertain="k", sigma=0.05, distribution="uniform")
        inputs = system.sampled_inputs(opa.SolverOptions(), xi=np.linspace(-1.0, 1.0, 5))
        times = np.linspace(0.0, 3 * T, 7)
        y0 = system.deterministic().initial_state()
        kw = dict(rtol=1e-9, atol=1e-9, capacity=64)
        cpu = _run.run_batch(inputs, y0, times, **kw)
        gpu = _run.run_batch(inputs, y0, times, **kw, device="cuda")
        same = all(np.array_equal(cpu.log(b), gpu.log(b)) for b in range(5))
        walls = sorted({int(w) for b in range(5) for w in cpu.events(b).wall})
        print(json.dumps(dict(states=bool(np.array_equal(cpu.states, gpu.states)),
                              logs=bool(same), walls=walls)))
        """)
    assert got == dict(states=True, logs=True, walls=[-1, 1])
