"""opa.System: one object for "which system", its checks, the impulse schedule, and every
entry point taking it or building it from the same keywords."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import mc
import opa
import opa.cli
from opa import ImpactSystem, Oscillator, SolverOptions, System, preset
from opa._system import DEFAULT_ORDER, DEFAULT_SIGMA, SYSTEM_FIELDS, as_system, impulse_schedule

FREE = dict(delta=1e6, x0=0.0, v0=0.0)  # a wall the motion never reaches


def test_defaults_are_one_set_everywhere():
    s = System()
    assert (s.sigma, s.order, s.uncertain, s.distribution, s.allow_negative) == (
        DEFAULT_SIGMA, DEFAULT_ORDER, "mu", None, False)
    assert (s.truncation, s.impact_law, s.impulse, s.pulse_width, s.impulse_at_zero) == (
        "galerkin", "mean", "dirac", 0.1, True)
    assert s.oscillator == Oscillator()
    # the command line's defaults are the System's
    from opa.cli._flags import system_from

    args = opa.cli.build_parser().parse_args(["simulate", "opa"])
    built = system_from(args)  # --sigma and --uncertain unset: the System's defaults
    assert (built.sigma, built.order, built.uncertain) == (DEFAULT_SIGMA, DEFAULT_ORDER, "mu")
    args = opa.cli.build_parser().parse_args(["stability", "opa"])
    assert (args.sigma, args.order) == (DEFAULT_SIGMA, DEFAULT_ORDER)


@pytest.mark.parametrize(("field", "value"), [
    ("sigma", -0.1), ("sigma", math.nan), ("uncertain", "a1"), ("order", -1), ("order", 1.5),
    ("truncation", "exact"), ("impact_law", "elastic"), ("impulse", "step"),
    ("pulse_width", 0.0), ("pulse_width", math.inf), ("impulse_at_zero", "yes"),
    ("allow_negative", "no"), ("distribution", "cauchy"),
])  # fmt: skip
def test_a_bad_field_is_refused_by_name(field, value):
    with pytest.raises(ValueError) as info:
        System(**{field: value})
    message = str(info.value)
    assert message.startswith(field) or f"the {field}" in message
    assert repr(value) in message or f"{value}" in message


def test_a_pulse_must_be_shorter_than_the_impulse_period():
    T1 = 2 * math.pi / 2.0
    with pytest.raises(ValueError, match=r"pulse_width must be shorter .* 3\.14159"):
        System(preset("3.1", omega1=2.0), impulse="pulse", pulse_width=T1)
    System(preset("3.1", omega1=2.0), impulse="dirac", pulse_width=T1)  # plays no role


# --------------------------------------------------------------------------- schedule
def test_the_impulse_schedule_is_j_times_the_impulse_period():
    s = System(preset("3.1", omega1=1.7))
    T1 = 2 * math.pi / 1.7
    expected = [j * T1 for j in range(100) if j * T1 <= 40.0]
    np.testing.assert_allclose(s.impulse_times(40.0), expected, rtol=0, atol=0)
    assert s.replace(impulse_at_zero=False).impulse_times(40.0)[0] == T1
    late = s.impulse_times(40.0, t_start=10.0)
    assert late[0] == min(t for t in expected if t >= 10.0) and late[-1] == expected[-1]
    assert System(preset("3.1", F0=0.0)).impulse_times(40.0).size == 0
    # the heights of eq. (1): F0 (1 + a1 sin(omega1 t_j / n))
    o = s.oscillator
    heights = [o.F0 * (1 + o.a1 * math.sin(o.omega1 * t / o.n)) for t in expected]
    np.testing.assert_allclose(s.impulse_heights(expected), heights, rtol=1e-15)
    pulses = s.replace(impulse="pulse", pulse_width=0.3).impulse_breaks(40.0)
    np.testing.assert_allclose(pulses, sorted(expected + [t + 0.3 for t in expected]))
    assert s.impulse_interval([0.0, T1 - 1e-9, T1, 2.5 * T1]).tolist() == [0, 0, 1, 2]
    snapped = s.snap_to_impulses([T1 * (1 + 1e-12), 0.5 * T1], 1e-9)
    assert snapped.tolist() == [T1, 0.5 * T1]


def test_the_kernel_kicks_at_the_scheduled_times_by_the_scheduled_heights():
    """A free linear oscillator: the velocity jumps by the schedule's height exactly at
    the schedule's times (no wall, no forcing, no damping)."""
    osc = Oscillator(mu=0.0, a=1.0, c=0.0, f=0.0, omega=1.0, F0=0.2, a1=0.5, omega1=3.0,
                     n=2.0, **FREE)
    s = System(osc)
    tj = s.impulse_times(10.0)[1:]
    eps = 1e-9
    times = np.sort(np.concatenate([[0.0], tj - eps, tj]))
    ds = opa.simulate_dmr(s, times=times, options=SolverOptions(rtol=1e-12, atol=1e-12))
    v = ds.v.values[1:].reshape(-1, 2)
    np.testing.assert_allclose(v[:, 1] - v[:, 0], s.impulse_heights(tj), atol=1e-8)
    assert impulse_schedule(10.0, 3.0).tolist() == s.impulse_times(10.0).tolist()


# --------------------------------------------------------------------------- entry points
def test_as_system_takes_a_system_or_its_fields_not_both():
    s = System(order=3)
    assert as_system(s) is s
    assert as_system(None, order=3) == s
    assert as_system(None, oscillator=Oscillator(c=0.04)).oscillator.c == 0.04
    with pytest.raises(ValueError, match=r"either a System or its fields \(order\)"):
        as_system(s, order=2)
    with pytest.raises(TypeError, match="sigmaa"):
        as_system(None, sigmaa=0.1)
    with pytest.raises(TypeError, match="simulate_dmr.* order"):
        opa.simulate_dmr(order=3)
    with pytest.raises(ValueError, match="oscillator must be an opa.Oscillator"):
        as_system("3.1")
    assert set(SYSTEM_FIELDS) == {"oscillator", "sigma", "uncertain", "distribution",
                                  "allow_negative", "order", "truncation", "impact_law",
                                  "impulse", "pulse_width", "impulse_at_zero"}


def test_the_deprecated_impulse_keywords_of_solver_options_still_work_and_warn():
    osc = preset("3.1")
    with pytest.warns(DeprecationWarning, match=r"belongs to the system, opa.System\(impulse="):
        legacy = SolverOptions(impulse="pulse", pulse_width=0.2)
    new = opa.simulate_dmr(osc, periods=3, impulse="pulse", pulse_width=0.2)
    old = opa.simulate_dmr(osc, periods=3, options=legacy)
    np.testing.assert_array_equal(old.x.values, new.x.values)
    assert old.attrs["impulse"] == "pulse" and old.attrs["pulse_width"] == 0.2
    with pytest.raises(ValueError, match="disagree on impulse"):
        opa.simulate_dmr(System(osc), periods=1, options=legacy)


def test_every_entry_point_gives_the_same_run_from_a_system_or_from_keywords():
    osc = preset("3.1")
    fields = dict(sigma=0.02, order=3, impulse="pulse", pulse_width=0.2, impulse_at_zero=False)
    s = System(osc, **fields)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pairs = [
            (opa.simulate_dmr(s, periods=3).x,
             opa.simulate_dmr(osc, periods=3, impulse="pulse", pulse_width=0.2,
                              impulse_at_zero=False).x),
            (opa.simulate_opa(s, periods=3).x_coef, opa.simulate_opa(osc, periods=3, **fields)
             .x_coef),
            (mc.simulate_mc(s, samples=16, periods=3, progress=False).x_mean,
             mc.simulate_mc(osc, samples=16, periods=3, progress=False, **fields).x_mean),
            (opa.sweep("opa", "c", [0.04, 0.05], s, transient=3, record=2, workers=1,
                       locate=False).section_x,
             opa.sweep("opa", "c", [0.04, 0.05], osc, transient=3, record=2, workers=1,
                       locate=False, **fields).section_x),
        ]
    for a, b in pairs:
        np.testing.assert_array_equal(a.values, b.values)
    # the DMR of a System is its deterministic part, whatever the uncertainty
    np.testing.assert_array_equal(opa.simulate_dmr(s, periods=3).x.values,
                                  opa.simulate_opa(s.replace(sigma=0.0, order=0), periods=3)
                                  .x_mean.values)
    orbit = ImpactSystem.of(s, model="opa")
    assert (orbit.sigma, orbit.order, orbit.impulse) == (0.02, 3, "pulse")
    assert ImpactSystem.of(s).order == 0


def test_negative_samples_need_consent_and_the_message_names_the_mean():
    s = System(Oscillator(mu=0.8), sigma=0.9)
    with pytest.raises(ValueError, match=r"sigma = 0\.9 .* makes mu = 0\.8 \+ sigma xi = "
                                         r"-0\.1 negative"):
        s.check_samples()
    s.replace(allow_negative=True).check_samples()
    s.replace(sigma=0.8).check_samples()  # mu_bar - sigma = 0 is allowed
    # on another law of xi the support decides: uniform on [-1, 1] reaches -1 too
    with pytest.raises(ValueError, match="xi down to -1"):
        s.replace(distribution="uniform").check_samples()


def test_replace_takes_the_oscillators_parameters_by_name():
    s = System(preset("3.1"), sigma=0.02)
    t = s.replace(c=0.07, sigma=0.03)
    assert (t.oscillator.c, t.sigma, t.oscillator.omega) == (0.07, 0.03, 2.8)
    with pytest.raises(ValueError, match="eta"):
        s.replace(eta=2.0)
    d = s.deterministic()
    assert (d.sigma, d.order, d.impulse) == (0.0, 0, s.impulse)


def test_analyses_of_one_parameter_refuse_several_in_one_line():
    """Sweeps take one uncertain parameter for now: a system of several is refused by
    name; the runs that take several (simulate_opa, simulate_mc, the DMR, the
    deterministic split scans) accept it."""
    two = System(uncertain="mu,c", sigma=0.01, order=1)
    with pytest.raises(ValueError, match=r"sweep\(\) takes one uncertain parameter; this "
                                         r"system has 2 \(mu,c\)"):
        opa.sweep("opa", "omega", [3.9, 4.0], two)
    assert as_system(two, several=True) is two
    assert opa.simulate_dmr(two, periods=1).sizes["time"] == 2
