"""Tests for ``opa.dynamics._sections``: period detection, impacts per period, grazing, doubling.

References: constructed section sequences with a known repeat (rotations by 2 pi/p, an
irrational rotation that never repeats), closed-form free flights whose maximum and gap
to the wall are known, and periodic orbits of the DMR whose labels are stable (section
3.1 and 3.2 sets without impulses: 4/4, 2/2 and 6/2, as printed in the paper).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from opa import preset, simulate_dmr
from opa.dynamics._sections import (
    constraint_section,
    detect_period,
    free_flight_maxima,
    grazing_points,
    identify,
    identify_motion,
    impacts_per_period,
    period_doubling,
    period_label,
    phase_section,
    repeat_distance,
    stroboscopic_mask,
)

# --------------------------------------------------------------------------- period


@pytest.mark.parametrize("p", [1, 2, 3, 4, 6, 7, 14])
def test_rotation_by_2pi_over_p_has_period_p(p):
    k = np.arange(60)
    x, v = np.cos(2 * np.pi * k / p) - 1.2, np.sin(2 * np.pi * k / p)
    period, residual, nearest = detect_period(x, v)
    assert (period, nearest) == (p, p)
    assert residual < 1e-12


def test_irrational_rotation_has_no_period():
    k = np.arange(200)
    phase = 2 * np.pi * k * (math.sqrt(5) - 1) / 2
    period, residual, nearest = detect_period(np.cos(phase), np.sin(phase))
    assert period == 0
    assert residual > 1e-3  # the closest return is far above the tolerance
    assert 1 <= nearest <= 100


def test_period_is_the_smallest_repeat_within_the_tolerance():
    k = np.arange(40)
    base = np.cos(np.pi * k / 2)  # period 4
    wobble = 1e-3 * (-1.0) ** (k // 4)  # alternates every 4 samples: true period 8
    x, v = base + wobble, np.sin(np.pi * k / 2)
    assert detect_period(x, v)[0] == 8
    assert detect_period(x, v, tol=1e-2)[0] == 4  # a looser tolerance merges the two
    # a perturbation below the tolerance is not a different motion
    assert detect_period(base + 1e-7 * wobble, v)[0] == 4


def test_period_needs_two_repeats_and_finite_samples():
    x = np.array([0.0, 1.0, 2.0, 0.0, 1.0])
    assert detect_period(x, x)[0] == 0  # period 3 is seen only once and a bit
    assert detect_period(np.r_[x, 2.0, 0.0], np.r_[x, 2.0, 0.0])[0] == 3
    bad = np.array([0.0, np.nan, 0.0, np.nan])
    period, residual, _ = detect_period(bad, bad)
    assert period == 0 and math.isnan(residual)
    assert repeat_distance(np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0]]), 1) == 0.0


def test_period_label_and_doubling_flags():
    assert period_label(6, 2) == "6/2"
    assert period_label(4, -1) == "4/?"
    assert period_label(0, 3) == "none"
    flags = period_doubling(np.array([3, 3, 6, 6, 12, 0, 2, 4, 4, 2]))
    assert flags.tolist() == [0, 0, 1, 0, 1, 0, 0, 1, 1, 0]  # both directions


def test_impacts_per_period_counts_each_repeat():
    T = 2.0
    # period 3 motion with 2 impacts per repeat, the last window ends at t = 30
    times = np.concatenate([[3 * T * j + 0.5, 3 * T * j + 2.7] for j in range(5)])
    assert impacts_per_period(times, 30.0, T, 3, 5) == 2
    # an impact exactly on a window edge counts once, in the later window
    edge = np.array([6.0, 12.0, 18.0, 24.0, 30.0])
    assert impacts_per_period(edge, 30.0, T, 3, 4) == 1
    # not steady: one repeat has an extra impact
    assert impacts_per_period(np.r_[times, 7.0], 30.0, T, 3, 5) == -1
    assert impacts_per_period(times, 30.0, T, 0, 5) == -1


# --------------------------------------------------------------------------- grazing


def free_flight(gap, *, delta=0.0, omega=2.0, per_period=16, periods=20, phase=0.37):
    """x = delta - gap - A (1 - cos(omega t - phase)): maxima delta - gap, no impact."""
    T = 2 * np.pi / omega
    t = np.arange(periods * per_period + 1) * T / per_period
    A = 0.8
    x = delta - gap - A * (1 - np.cos(omega * t - phase))
    v = -A * omega * np.sin(omega * t - phase)
    return t, x, v, T


def test_hermite_maxima_of_a_free_flight_converge_at_fourth_order():
    errors = []
    for per_period in (8, 16, 32, 64):
        t, x, v, _T = free_flight(0.01, per_period=per_period)
        tm, xm = free_flight_maxima(t, x, v)
        assert len(xm) == 20
        errors.append(np.abs(xm + 0.01).max())
    slope = np.polyfit(np.log([8, 16, 32, 64]), np.log(errors), 1)[0]
    assert -4.3 < slope < -3.7  # cubic Hermite: error O(h^4)
    assert errors[1] < 5e-6  # 16 outputs per period resolve a graze of 1e-4
    np.testing.assert_allclose(np.mod(2.0 * tm - 0.37, 2 * np.pi), 0, atol=1e-3)
    # an interval that holds a break (impact, impulse) is not a free flight
    _, xb = free_flight_maxima(t, x, v, breaks=tm[:5] + 1e-3)
    assert len(xb) == 15


@pytest.mark.parametrize("gap, grazing", [(2e-5, 1), (5e-3, 0)])
def test_constructed_graze_without_impact(gap, grazing):
    t, x, v, T = free_flight(gap)
    m = identify(t, x, v, forcing_period=T, delta=0.0, start=5 * T,
                 impact_time=np.zeros(0), impact_velocity=np.zeros(0))
    assert m.grazing == grazing
    assert m.min_gap == pytest.approx(gap, abs=5e-6)
    assert (m.period, m.impacts, m.label) == (1, 0, "1/0")
    assert math.isnan(m.min_impact_velocity)


def test_constructed_graze_by_a_slow_impact():
    t, x, v, T = free_flight(0.3)
    fast = identify(t, x, v, forcing_period=T, delta=0.0, start=0.0,
                    impact_time=np.array([3.0, 9.0]), impact_velocity=np.array([0.9, 0.5]))
    slow = identify(t, x, v, forcing_period=T, delta=0.0, start=0.0,
                    impact_time=np.array([3.0, 9.0]), impact_velocity=np.array([0.9, 1e-3]))
    assert (fast.grazing, slow.grazing) == (0, 1)
    assert slow.min_impact_velocity == 1e-3


def test_the_tolerances_record_sets_the_grazing_threshold():
    """An impact at 5e-3 grazes under the default threshold (1e-2), not under 1e-3; the
    record refuses thresholds that cannot be one, naming them."""
    from opa.dynamics._sections import MotionTolerances

    t, x, v, T = free_flight(0.3)
    kw = dict(forcing_period=T, delta=0.0, start=0.0, impact_time=np.array([3.0, 9.0]),
              impact_velocity=np.array([0.9, 5e-3]))
    assert identify(t, x, v, **kw).grazing == 1
    strict = identify(t, x, v, tolerances=MotionTolerances(graze_velocity=1e-3), **kw)
    assert strict.grazing == 0
    for bad, message in ((dict(period_tol=0), "period_tol must be > 0, got 0"),
                         (dict(graze_gap=float("nan")), "graze_gap must be > 0"),
                         (dict(graze_velocity=True), "graze_velocity must be > 0"),
                         (dict(max_period=0), "max_period must be None or an integer >= 1")):
        with pytest.raises(ValueError, match=message):
            MotionTolerances(**bad)


def test_grazing_is_not_resolved_from_sparse_outputs():
    t, x, v, T = free_flight(2e-5, per_period=4)
    m = identify(t, x, v, forcing_period=T, delta=0.0, impact_time=np.zeros(0),
                 impact_velocity=np.zeros(0))
    assert math.isnan(m.min_gap) and m.grazing == 0


def test_grazing_located_between_periodic_branches_by_the_square_law():
    values = np.array([1.0, 2.0, 3.0, 4.0])
    period = np.array([2, 2, 2, 0])
    impacts = np.array([2, 2, 3, -1])
    vmin = np.array([0.5, 0.5, 0.2, 0.1])
    gap = np.array([0.3, 0.02, np.nan, np.nan])
    # g = +0.02 at 2, -0.2^2/2 = -0.02 at 3: the root is half way
    np.testing.assert_allclose(grazing_points(values, period, impacts, vmin, gap), [2.5])
    # no free-flight gap known: the midpoint
    np.testing.assert_allclose(
        grazing_points(values, period, impacts, vmin, np.full(4, np.nan)), [2.5])
    assert len(grazing_points(values, period, np.array([2, 2, 2, -1]), vmin, gap)) == 0


# --------------------------------------------------------------------------- real runs


@pytest.mark.parametrize(
    "name, changes, label",
    [("3.1", {"c": 0.035}, "4/4"), ("3.1", {"c": 0.05}, "2/2"), ("3.2", {"omega": 3.98},
                                                                   "6/2")],
)
def test_periodic_orbits_of_the_dmr_without_impulses(name, changes, label):
    osc = preset(name, F0=0.0, **changes)
    ds = simulate_dmr(osc, periods=300, per_period=16)
    m = identify_motion(ds, start=200 * osc.forcing_period)
    assert m.label == label
    assert m.residual < 1e-4
    assert m.grazing == 0 and m.min_impact_velocity > 0.1


def test_sections_of_a_run():
    osc = preset("3.1", c=0.05, F0=0.0)
    T = osc.forcing_period
    ds = simulate_dmr(osc, periods=60, per_period=8)
    sec = phase_section(ds, start=40 * T)
    assert sec.sizes["point"] == 20
    np.testing.assert_allclose(sec.section_time / T, np.arange(41, 61), atol=1e-9)
    np.testing.assert_array_equal(sec.section_x, ds.x.values[8 * 41 :: 8])
    hits = constraint_section(ds, start=40 * T)
    assert hits.sizes["point"] == 20  # a 2/2 motion: one impact per forcing period
    assert np.all((hits.impact_phase >= 0) & (hits.impact_phase < 2 * np.pi))
    assert np.all(hits.impact_v > 0)
    # the 2/2 motion alternates between two impact phases
    phases = np.unique(np.round(hits.impact_phase.values, 6))
    assert len(phases) == 2
    mask = stroboscopic_mask(ds.time.values, T, 40 * T, 50 * T)
    assert mask.sum() == 10


def test_mc_mean_has_no_constraint_section():
    from mc import simulate_mc

    osc = preset("3.1", c=0.05, F0=0.0)
    ds = simulate_mc(osc, sigma=0.01, samples=8, periods=20, per_period=8, progress=False)
    assert constraint_section(ds).sizes["point"] == 0
    m = identify_motion(ds, start=10 * osc.forcing_period)
    assert m.impacts == -1 and math.isnan(m.impact_rate)


def test_identify_motion_measures_the_lower_walls_gap_at_the_free_flight_minima():
    """A run's free-flight minima above the lower wall (``test_sweep``'s linear oscillator
    at f = 0.99 f_g: 1 - A = 0.01 in closed form, within 1e-6 by Hermite interpolation of
    64 outputs per period) make ``min_gap_lower``, and grazing with graze_gap = 0.02 but
    not with the default 1e-4; a one-wall run has none."""
    from tests.opa.dynamics.test_sweep import LOWER_DENOMINATOR, LOWER_GRAZE_F, \
        lower_wall_oscillator

    f = 0.99 * LOWER_GRAZE_F
    osc = lower_wall_oscillator(f=f)
    ds = simulate_dmr(osc, periods=160, per_period=64)
    start = 150 * osc.forcing_period
    motion = identify_motion(ds, start=start, graze_gap=0.02)
    assert motion.min_gap_lower == pytest.approx(1.0 - f / LOWER_DENOMINATOR, abs=1e-6)
    assert motion.nearest_gap == motion.min_gap_lower and motion.grazing == 1
    assert identify_motion(ds, start=start).grazing == 0
    one_wall = simulate_dmr(osc.replace(delta_minus=-math.inf), periods=160, per_period=64)
    assert math.isnan(identify_motion(one_wall, start=start, graze_gap=0.02).min_gap_lower)
