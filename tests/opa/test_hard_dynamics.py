"""Hard dynamics: a trajectory that is not finite is a failure, and every loop ends.

The kernel (``opa._kernel.integrate``, plain and variational runs) checks the state
after every accepted step and every jump (impact, impulse kick, saltation jump, release):
a NaN or inf component ends the run with ``DIVERGED``, a component beyond the escape
bound with ``ESCAPED``. The Python layer turns these into ``SimulationError``; a run never
returns NaN as a success. Time arguments of the stability tools that could never be
integrated (NaN, inf, t0 with t0 + T == t0) are refused with a ValueError naming them.

Every test is timed: a failure must be quick (a runaway with c < 0 used to take the whole
budget of 50 million steps), and a hang shows up as a failed time bound rather than a
stuck suite where the loop is in Python (``within`` arms SIGALRM; a compiled loop cannot
be interrupted, so the elapsed time is asserted as well).
"""

from __future__ import annotations

import math
import signal
import time
from contextlib import contextmanager

import numpy as np
import pytest

from opa import Oscillator, SolverOptions, preset, simulate_dmr, simulate_opa
from opa import _kernel as kernel
from opa.dynamics._continuation import ContinuationOptions, continue_orbits
from opa.dynamics._sections import impulse_times, stroboscopic_mask
from opa._run import SimulationError
from tests.conftest import kernel_inputs, rule
from opa.dynamics._orbits import (
    ImpactSystem,
    flow,
    lyapunov_exponent,
    periodic_orbit,
    poincare_map,
    shoot,
)
from tests.truths import accumulation_time

QUICK = 20.0  # seconds: generous on a loaded two-core machine, far below a hang


@contextmanager
def within(seconds: float):
    """Fail if the block takes longer than ``seconds`` (SIGALRM for Python loops, and the
    measured time for compiled ones, which a signal cannot interrupt)."""

    def expired(signum, frame):
        raise TimeoutError(f"still running after {seconds} s")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds + 5.0)
    start = time.perf_counter()
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
    elapsed = time.perf_counter() - start
    assert elapsed < seconds, f"took {elapsed:.1f} s, bound {seconds} s"


@pytest.fixture(scope="module", autouse=True)
def compiled():
    """Load (or compile) the kernels once, so the time bounds measure the runs only."""
    simulate_dmr(preset("3.1"), periods=1)
    simulate_opa(preset("3.1"), sigma=0.01, order=2, periods=1)
    simulate_opa(preset("3.1"), sigma=0.01, order=2, periods=1, impact_law="saltation")
    simulate_dmr(preset("3.1"), periods=1, options=SolverOptions(impulse="pulse"))
    flow(ImpactSystem(preset("3.1")), [-1.0, 0.0], [0.0, 1.0], tangent="identity")


def run_dmr_kernel(osc: Oscillator, times, options: SolverOptions | None = None):
    """The kernel's own status and counters for one DMR trajectory."""
    inputs = kernel_inputs(osc, options or SolverOptions())
    p, cfg = inputs.p, inputs.cfg
    out, log = np.empty((len(times), 2)), np.empty((64, 3))
    status, _, _, n_steps, _ = kernel.run_one(
        np.array([osc.x0, osc.v0]), np.asarray(times, dtype=float), p, cfg,
        *rule(inputs), 1e-10, 1e-10, out, log)
    return status, n_steps, out


def finishes_or_fails_cleanly(run):
    """Run ``run()``: either a dataset whose every state is finite, or SimulationError.
    Returns the dataset or the error."""
    try:
        ds = run()
    except SimulationError as err:
        return err
    for name in ("x", "v", "x_coef", "v_coef"):
        if name in ds:
            assert np.all(np.isfinite(ds[name].values)), f"{name} not finite in a success"
    return ds


# --------------------------------------------------------------------------- statuses


def test_status_codes_are_distinct_and_say_where_and_why():
    codes = [kernel.OK, kernel.MAX_STEPS, kernel.STEP_COLLAPSE, kernel.DIVERGED, kernel.ESCAPED,
             kernel.BAD_TIME, kernel.SKIPPED]
    assert len(set(codes)) == len(codes)
    assert set(kernel.STATUS_MESSAGES) == set(codes)
    assert "escaped" in kernel.STATUS_MESSAGES[kernel.ESCAPED]
    assert "non-finite" in kernel.STATUS_MESSAGES[kernel.DIVERGED]
    assert "not finite" in kernel.STATUS_MESSAGES[kernel.BAD_TIME]


def test_state_check_catches_nan_that_max_would_drop():
    bound = 10.0
    assert kernel.state_status(np.array([1.0, -2.0]), 2, bound) == kernel.OK
    assert kernel.state_status(np.array([1.0, np.nan]), 2, bound) == kernel.DIVERGED
    assert kernel.state_status(np.array([np.nan, 1.0]), 2, bound) == kernel.DIVERGED
    assert kernel.state_status(np.array([-np.inf, 1.0]), 2, bound) == kernel.DIVERGED
    assert kernel.state_status(np.array([1.0, -10.0]), 2, bound) == kernel.ESCAPED
    assert kernel.state_status(np.array([11.0, np.nan]), 2, bound) == kernel.DIVERGED
    # the variational check: the state escapes; the tangent may be large but finite
    z = np.array([1.0, 2.0, 1e200, -1e200])
    assert kernel.state_status(z, 2, bound) == kernel.OK
    z[3] = np.nan
    assert kernel.state_status(z, 2, bound) == kernel.DIVERGED
    assert kernel.state_status(np.array([1.0, 20.0, 0.0, 0.0]), 2, bound) == kernel.ESCAPED


@pytest.mark.parametrize("method", [kernel.METHOD_DP5, kernel.METHOD_DOP853])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_error_norm_rejects_a_non_finite_trial_step(bad, method):
    y = np.array([0.5, -0.5])
    stages = np.zeros((kernel.K_ROWS, 2))
    y_new = np.array([0.5, bad])
    assert kernel.error_norm(method, y, y_new, stages, 0.1, 1e-10, 1e-10) == np.inf
    stages[kernel.last_stage(method), 0] = bad
    assert kernel.error_norm(method, y, y, stages, 0.1, 1e-10, 1e-10) == np.inf


def test_escape_bound_follows_the_documented_formula():
    osc = Oscillator(f=2.0, omega=2.8, F0=10.0, a1=0.5, delta=0.3, x0=-1.5, v0=0.7)
    inputs = kernel_inputs(osc, SolverOptions())
    p, cfg = inputs.p, inputs.cfg
    y0 = np.array([osc.x0, osc.v0])
    force = 2.0 + 10.0 * 1.5
    a = osc.a
    expected = 1e3 * (1.0 + 1.5 + 0.3 + force * (1.0 + 1.0 / 2.8 + 1.0 / 2.8**2 + 1.0 / a))
    assert kernel.escape_bound(y0, p, cfg) == pytest.approx(expected, rel=1e-14)
    p[kernel.P_A] = 0.0  # no restoring force, no scale: nothing escapes
    assert kernel.escape_bound(y0, p, cfg) == np.inf


def test_a_weak_spring_is_not_an_escape():
    """a = 3e-5, c = 0 under the paper's forcing: a bounded motion near |x| ~ 1e4 (the
    static deflection f/a = 5e4 sets its scale) finishes; it is not an escape."""
    osc = Oscillator(a=3e-5, c=0.0)
    ds = simulate_dmr(osc, periods=300)
    assert np.isfinite(ds.x).all() and float(abs(ds.x).max()) > 100.0


def test_an_ensemble_stops_at_its_first_failed_sample():
    """c < 0: the first sample that runs away fails the chunk (the runaway guard ends it
    before its state escapes); the rest are skipped, so the ensemble fails in about the
    time of one sample, not of all of them."""
    from mc import simulate_mc
    from opa._run import SimulationError

    start = time.perf_counter()
    with pytest.raises(SimulationError, match="runaway guard"):
        simulate_mc(Oscillator(c=-1.0), sigma=0.01, samples=256, periods=10, progress=False)
    assert time.perf_counter() - start < 30


@pytest.mark.parametrize("section", ["3.1", "3.2", "3.3", "3.4"])
def test_paper_cases_stay_far_inside_the_escape_bound(section):
    """The bound never fires on the paper's cases: they stay 100 times below it."""
    osc = preset(section)
    inputs = kernel_inputs(osc, SolverOptions())
    bound = kernel.escape_bound(np.array([osc.x0, osc.v0]), inputs.p, inputs.cfg)
    ds = simulate_dmr(osc, periods=100, per_period=16)
    assert 100.0 * max(np.abs(ds.x).max(), np.abs(ds.v).max()) < bound


# --------------------------------------------------------------------------- overflow


@pytest.mark.parametrize(
    "changes",
    [dict(mu=1e300), dict(v0=1e200), dict(f=1e300), dict(c=1e300), dict(a=-1e300)],
    ids=["mu=1e300", "v0=1e200", "f=1e300", "c=1e300", "a=-1e300"],
)
def test_overflowing_parameters_stop_with_a_status_not_nan(changes):
    osc = Oscillator(**changes)
    with within(QUICK), pytest.raises(SimulationError, match="non-finite|escaped"):
        simulate_dmr(osc, periods=2)


def test_a_kick_that_overflows_stops_at_the_jump():
    """F0 (1 + a1 sin(omega1 t / n)) = 1e300 * 1e300 at the second impulse: the kick
    itself makes v infinite, and the check after the jump reports it."""
    osc = Oscillator(F0=1e300, a1=1e300)
    with within(QUICK), pytest.raises(SimulationError, match="non-finite"):
        simulate_dmr(osc, periods=5)
    options = SolverOptions(impulse="pulse")
    with within(QUICK), pytest.raises(SimulationError, match="non-finite"):
        simulate_dmr(osc, periods=5, options=options)


def test_overflow_in_the_opa_system_stops_with_a_status():
    with within(QUICK), pytest.raises(SimulationError, match="non-finite|escaped"):
        simulate_opa(Oscillator(mu=1e300), sigma=0.1, order=2, periods=2)


def test_huge_impulse_on_section_3_1_fails_cleanly():
    osc = preset("3.1", F0=1e12)
    with within(QUICK):
        got = finishes_or_fails_cleanly(lambda: simulate_dmr(osc, periods=5))
    assert isinstance(got, SimulationError)  # v jumps to 1e12: mu v^3 cannot be resolved
    status, _, out = run_dmr_kernel(osc, np.linspace(0.0, 5 * osc.forcing_period, 6))
    assert status in (kernel.DIVERGED, kernel.STEP_COLLAPSE, kernel.ESCAPED)
    assert np.isnan(out[-1]).all()


def test_impulses_of_a_million_finish_or_fail_cleanly():
    with within(QUICK):
        finishes_or_fails_cleanly(lambda: simulate_dmr(Oscillator(F0=1e6), periods=5))
        finishes_or_fails_cleanly(lambda: simulate_dmr(preset("3.4", F0=1e6), periods=5))


def test_pulses_of_height_1e8_finish_with_finite_states():
    options = SolverOptions(impulse="pulse", pulse_width=0.1)
    with within(QUICK):
        got = finishes_or_fails_cleanly(
            lambda: simulate_dmr(Oscillator(F0=1e8), periods=5, options=options))
    assert not isinstance(got, SimulationError), got
    assert len(got.impact_time) > 0


# --------------------------------------------------------------------------- escape


def test_runaway_with_negative_cubic_stiffness_escapes_quickly():
    """c = -1: the van der Pol damping makes the runaway stiff (steps ~ |x|^2); it used
    to run the whole 50 million steps before 'maximum number of steps'."""
    osc = Oscillator(c=-1.0)
    times = np.linspace(0.0, 50 * osc.forcing_period, 51)
    with within(QUICK):
        status, n_steps, out = run_dmr_kernel(osc, times)
    assert status == kernel.ESCAPED
    assert n_steps < 3e7  # well under SolverOptions().max_steps = 5e7
    assert np.isnan(out[-1]).all()
    # through the Python layer the runaway guard (1e6 steps over 50 periods) ends it first
    with within(QUICK), pytest.raises(SimulationError, match="runaway guard"):
        simulate_dmr(osc, periods=50)


def test_negative_damping_escapes_in_the_opa_system_and_the_variational_flow():
    """mu < 0 with |v| > 1: the van der Pol term pumps energy, |v| blows up in finite
    time; c < 0 in the variational flow: the stiff runaway of the DMR test."""
    osc = Oscillator(mu=-0.5, v0=-2.0)
    with within(QUICK), pytest.raises(SimulationError, match="escaped"):
        simulate_opa(osc, sigma=0.1, order=2, periods=200, allow_negative=True)
    system = ImpactSystem(Oscillator(c=-1.0))
    with within(QUICK), pytest.raises(SimulationError, match="escaped"):
        flow(system, [-1.0, 0.0], [0.0, 50 * system.forcing_period])
    with within(QUICK), pytest.raises(SimulationError, match="escaped"):
        periodic_orbit(system, transient=50)


# --------------------------------------------------------------------------- grazing, chatter


@pytest.mark.parametrize("law", ["mean", "ensemble", "saltation"])
@pytest.mark.parametrize("v0", [1e-8, 2e-6])
def test_grazing_start_finishes_with_finite_states(law, v0):
    """Start just below the wall, moving into it at 1e-8 (a graze) or 2e-6 (just above
    the graze threshold: the saltation factor 1/v- is 5e5)."""
    osc = preset("3.1", x0=-1e-12, v0=v0)
    with within(QUICK):
        dmr = finishes_or_fails_cleanly(lambda: simulate_dmr(osc, periods=5, per_period=8))
        opa = finishes_or_fails_cleanly(lambda: simulate_opa(
            osc, sigma=0.02, order=3, impact_law=law, periods=5, per_period=8))
    assert not isinstance(dmr, SimulationError), dmr
    assert dmr.impact_time.size > 0
    if not isinstance(opa, SimulationError):
        assert opa.impact_time.size > 0


def test_grazing_at_1e_8_finishes_with_the_closed_form_impacts():
    """x = -A cos t against a wall just inside the amplitude, delta = A (1 - eps): the
    first impact comes at v1 = A sqrt(1 - (1 - eps)^2) = 1e-8 (a graze), and each later
    one at eta times the previous (the free linear oscillator returns to the wall with
    its rebound speed). The saltation matrix of the variational flow holds 1/v1 = 1e8."""
    A, v1, eta = 1e-6, 1e-8, 0.8
    osc = Oscillator(mu=0.0, a=1.0, c=0.0, f=0.0, F0=0.0, eta=eta, omega=1.0,
                     delta=A * (1.0 - 0.5 * (v1 / A) ** 2), x0=-A, v0=0.0)
    options = SolverOptions(rtol=1e-12, atol=1e-15)
    with within(QUICK):
        ds = simulate_dmr(osc, periods=3, per_period=64, options=options)
    assert np.all(np.isfinite(ds.x)) and np.all(np.isfinite(ds.v))
    v = ds.impact_velocity.values
    assert len(v) == 3 and ds.impact_graze.values.all()
    assert v[0] == pytest.approx(v1, rel=1e-3)
    np.testing.assert_allclose(v[1:] / v[:-1], eta, rtol=1e-3)
    with within(QUICK):
        res = flow(ImpactSystem(osc, options=options), [-A, 0.0], [0.0, 2 * math.pi],
                   tangent="identity")
    assert len(res.impact_velocity) == 1
    assert np.all(np.isfinite(res.states)) and np.all(np.isfinite(res.tangent))


def test_chatter_then_sticking_finishes():
    """A mass pushed into the wall by an almost constant force (omega small) bounces
    ever lower, sticks after finitely many impacts and stays at the wall."""
    osc = Oscillator(mu=0.0, a=0.0, c=0.0, f=1.0, omega=0.01, F0=0.0, eta=0.5, delta=0.0,
                     x0=-1.0, v0=0.0)
    times = np.linspace(0.0, 30.0, 61)
    with within(QUICK):
        ds = simulate_dmr(osc, times=times)
    assert ds.stick_time.size >= 1
    assert np.all(np.isfinite(ds.x)) and np.all(np.isfinite(ds.v))
    assert float(ds.x[-1]) == 0.0 and float(ds.v[-1]) == 0.0
    # the chatter accumulation time: t1 = sqrt(2), t_inf = t1 + 2 eta v1 / (g (1 - eta))
    assert float(ds.stick_time[0]) == pytest.approx(accumulation_time(1.0, 1.0, 0.5), rel=1e-3)


# --------------------------------------------------------------------------- times


def test_kernels_refuse_non_finite_times_at_once():
    osc = preset("3.1")
    for bad in (np.nan, np.inf):
        with within(QUICK):
            status, _, out = run_dmr_kernel(osc, np.array([0.0, 1.0, bad]))
        assert status == kernel.BAD_TIME and np.isnan(out).all()
    system = ImpactSystem(osc)
    p, cfg, (nodes, weights, U) = system._packed.p, system._packed.cfg, rule(system._packed)
    for times in (np.array([0.0, np.nan]), np.array([np.nan, 1.0]), np.array([0.0, np.inf])):
        z = np.array([-1.0, 0.0])
        out, stats, log = np.empty((2, 2)), np.empty((1, kernel.N_STATS)), np.empty((4, 3))
        with within(QUICK):
            status = kernel.integrate(z, 0, times, False, False, p, cfg, nodes, weights, U,
                                      1e-10, 1e-10, out, stats, np.empty(0), log)[0]
        assert status == kernel.BAD_TIME


@pytest.mark.parametrize("t0", [math.nan, math.inf, -math.inf, 1e300])
def test_stability_tools_refuse_unresolvable_section_times(t0):
    system = ImpactSystem(preset("3.1", F0=0.0, c=0.05))
    pattern = "t0 must be finite" if not math.isfinite(t0) else "t0 = 1e.300 is too large"
    with within(QUICK):
        with pytest.raises(ValueError, match=pattern):
            periodic_orbit(system, t0=t0)
        with pytest.raises(ValueError, match=pattern):
            poincare_map(system, [-1.5, 0.6], t0=t0)
        with pytest.raises(ValueError, match=pattern):
            shoot(system, [-1.5, 0.6], periods=2, t0=t0)
        with pytest.raises(ValueError, match=pattern):
            lyapunov_exponent(system, t0=t0, periods=10, transient=0)
        with pytest.raises(ValueError, match=pattern):
            continue_orbits(system, "c", 0.1, 0.08, t0=t0)
        with pytest.raises(ValueError, match="finite|too large"):
            flow(system, [-1.5, 0.6], [0.0, t0])


def test_large_but_resolvable_section_time_is_reduced_to_its_phase():
    """periodic_orbit runs its transient to the phase of t0, not from 0 up to t0."""
    system = ImpactSystem(preset("3.1", F0=0.0, c=0.05))
    T = system.forcing_period
    with within(QUICK):
        near = periodic_orbit(system, t0=0.3)
        far = periodic_orbit(system, t0=0.3 + 1e6 * T)
    assert far.label == near.label
    np.testing.assert_allclose(far.state, near.state, atol=1e-6)


def test_continuation_refuses_steps_that_would_never_end():
    system = ImpactSystem(preset("3.1", F0=0.0, c=0.05))
    for kwargs in (dict(step=0.0), dict(step=math.nan), dict(max_step=-1.0),
                   dict(max_points=0), dict(depth=math.inf)):
        with within(QUICK), pytest.raises(ValueError):
            depth = kwargs.pop("depth", 1)  # the rest: the continuation's record
            continue_orbits(system, "c", 0.1, 0.08, depth=depth,
                            continuation=ContinuationOptions(**kwargs))


def test_section_helpers_refuse_non_finite_bounds():
    with pytest.raises(ValueError, match="start must be finite"):
        stroboscopic_mask(np.arange(5.0), 1.0, start=math.nan)
    with pytest.raises(ValueError, match="t_end must be finite"):
        impulse_times(math.inf, 1.0)
    with within(QUICK), pytest.raises(ValueError, match="impulse times"):
        impulse_times(1e300, 1.0)
