"""Tests for ``opa.dynamics._continuation``: branches of periodic orbits
(``continue_orbits``, ``locate_period_doubling``) and ``locate_bifurcations``, with the
located bifurcations of ``opa.dynamics._sweep.sweep`` (one source of truth, issue 15;
``opa-mc bifurcation`` is tested in ``tests/opa/cli/test_bifurcation.py``).

References: the continuation values of docs/stability.md (finding A: section 3.1 with
F0 = 0; finding B: the default impulses), checked independently by the Floquet
multipliers of ``periodic_orbit`` just before and after each located point (a period
doubling is a multiplier through -1; a fold, where an orbit stops existing), and for
grazing by the free-flight maximum of the impact-free orbit; a period-doubling point
located at rtol 1e-9 and 1e-11; the doubled branch against a long brute-force simulation.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from mc import sweep_source
from opa import SolverOptions, preset, simulate_dmr, sweep
from opa.dynamics._continuation import (
    BIFURCATION_KINDS,
    ContinuationOptions,
    Located,
    continue_orbits,
    locate_bifurcations,
    locate_period_doubling,
)
from opa.dynamics._orbits import ConvergenceError, ImpactSystem, periodic_orbit, shoot
from opa.dynamics._sweep import add_located, summary_lines

# docs/stability.md, finding A (rtol = atol = 1e-10): 1/1 -> 2/2, 2/2 -> 4/4, 4/4 -> 8/8
F0_ZERO_DOUBLINGS = {1: 0.0891223469, 2: 0.0396996668, 4: 0.0316812257}
# finding B (default Dirac impulses, orbits of P^14)
IMPULSE_FOLD = 0.0735900439
IMPULSE_FIRST_DOUBLING = 0.0323090015
IMPULSE_END_OF_PERIOD_1_LIKE = 0.0743377  # rtol 1e-11; 0.0743384 at 1e-9 (extrapolated)


def _of(points, kind):
    return [p for p in points if p.kind == kind]


def _multiplier_near(orbit, target):
    mu = orbit.multipliers
    return complex(mu[np.argmin(np.abs(mu - target))])


@pytest.fixture(scope="module")
def cascade():
    return locate_bifurcations(preset("3.1", F0=0.0), "c", 0.025, 0.1, seeds=[0.1])


@pytest.fixture(scope="module")
def impulses():
    return locate_bifurcations(preset("3.1"), "c", 0.03, 0.08, seeds=[0.05], depth=0)


# --------------------------------------------------------------------------- F0 = 0
def test_f0_zero_cascade_located_to_1e6(cascade):
    pds = _of(cascade, "period-doubling")
    assert [p.period for p in pds] == [4, 2, 1]  # by increasing c
    for p in pds:
        assert abs(p.value - F0_ZERO_DOUBLINGS[p.period]) < 1e-6, p
        assert p.located and abs(p.multiplier + 1.0) < 1e-6
    assert len(cascade) == 3  # nothing else changes an attractor on these branches


@pytest.mark.parametrize("period", [1, 2, 4])
def test_f0_zero_doubling_is_a_multiplier_through_minus_one(cascade, period):
    """Independent check: the period-k orbit just above the located value has its
    multiplier -1 < mu, just below mu < -1 (``periodic_orbit`` from x0, v0)."""
    c = next(p.value for p in cascade if p.period == period)
    system = ImpactSystem(preset("3.1", F0=0.0))
    above = periodic_orbit(system.with_parameter("c", c + 1e-6), periods=period)
    below = periodic_orbit(system.with_parameter("c", c - 1e-6), periods=period)
    assert above.label == below.label == f"{period}/{period}"
    mu_a, mu_b = _multiplier_near(above, -1.0), _multiplier_near(below, -1.0)
    assert abs(mu_a.imag) < 1e-9 and abs(mu_b.imag) < 1e-9
    assert -1.0 < mu_a.real < -0.99 and -1.01 < mu_b.real < -1.0
    assert above.stable and not below.stable


def test_sweep_reports_located_doublings_and_observed_periods(tmp_path):
    import xarray as xr

    values = np.linspace(0.0314, 0.1, 14)
    ds = sweep("dmr", "c", values, preset("3.1", F0=0.0), transient=200, record=40,
               workers=1, out=tmp_path / "s.nc")
    kinds = [BIFURCATION_KINDS[k] for k in ds.bifurcation_kind.values]
    assert ds.bifurcation_kind.attrs["flag_meanings"].split()[0] == "period_doubling"
    located = {int(k): float(v) for k, v, kind in zip(
        ds.bifurcation_period.values, ds.bifurcation_parameter.values, kinds)
        if kind == "period-doubling"}
    for period, value in F0_ZERO_DOUBLINGS.items():
        assert abs(located[period] - value) < 1e-6
    assert np.all(ds.bifurcation_located.values == 1)
    with xr.open_dataset(tmp_path / "s.nc") as disk:  # strings and flags survive netCDF
        assert disk.bifurcation_note.values.tolist() == ds.bifurcation_note.values.tolist()
    text = "\n".join(summary_lines(ds))
    assert "observed periods" in text and "bifurcations located" in text
    assert "period-doubling  c = 0.08912234" in text
    assert "period doubling at" not in text  # the old brute-force wording


# --------------------------------------------------------------------------- impulses
def test_default_impulses_fold_and_first_doubling(impulses):
    folds, pds = _of(impulses, "fold"), _of(impulses, "period-doubling")
    assert len(folds) == 1 and abs(folds[0].value - IMPULSE_FOLD) < 1e-6
    assert folds[0].period == 14 and abs(folds[0].multiplier - 1.0) < 1e-6
    assert [p.period for p in pds] == [14]
    assert abs(pds[0].value - IMPULSE_FIRST_DOUBLING) < 1e-6
    # the brute force's "doubling at c = 0.073" is no doubling
    assert not [p for p in pds if 0.04 < p.value < 0.08]


def test_default_impulses_doubling_and_fold_checked_by_multipliers(impulses):
    system = ImpactSystem(preset("3.1"))
    pd = _of(impulses, "period-doubling")[0]
    above = periodic_orbit(system.with_parameter("c", pd.value + 1e-6), periods=14)
    below = periodic_orbit(system.with_parameter("c", pd.value - 1e-6), periods=14)
    assert -1.0 < _multiplier_near(above, -1.0).real < -0.99
    assert -1.01 < _multiplier_near(below, -1.0).real < -1.0
    # the fold: an orbit with a multiplier near +1 just below it, none just above
    fold = _of(impulses, "fold")[0]
    guess = [fold.x, fold.v]
    near = periodic_orbit(system.with_parameter("c", fold.value - 1e-6), guess=guess,
                          periods=14)
    assert abs(_multiplier_near(near, 1.0) - 1.0) < 0.05
    with pytest.raises(ConvergenceError):
        periodic_orbit(system.with_parameter("c", fold.value + 1e-6), guess=guess, periods=14)


def test_no_doubling_of_a_14_periodic_orbit_near_0073(impulses):
    """At c = 0.073 the 14T orbits of the folding branch have no multiplier near -1, and
    the 28/28 motion seen there is not a doubled 14T orbit: its halves are apart and its
    multipliers far from -1 and +1 (it lives in a window between two impulse-impact
    points, see the slow test)."""
    system = ImpactSystem(preset("3.1"))
    # the folding branch's stable orbit, in small steps from c = 0.066 (at c = 0.07 the
    # attractor reached from x0, v0 is another 14T orbit, which folds at c = 0.07118)
    stable = periodic_orbit(system.with_parameter("c", 0.066))
    for value in (0.068, 0.07, 0.071, 0.072, 0.0725, 0.073):
        stable = periodic_orbit(system.with_parameter("c", value), guess=stable.state,
                                periods=14)
    c = system.with_parameter("c", 0.073)
    fold = _of(impulses, "fold")[0]
    partner = periodic_orbit(c, guess=[fold.x, fold.v], periods=14)
    for orbit in (stable, partner):
        assert np.min(np.abs(orbit.multipliers + 1.0)) > 0.5
    assert stable.stable and not partner.stable
    seen = periodic_orbit(c)  # from x0, v0, as the sweep
    assert seen.label == "28/28" and seen.spectral_radius < 0.6  # far from any bifurcation
    assert np.max(np.abs(seen.points[14] - seen.points[0])) > 0.01


def test_end_of_the_period_1_like_orbit_located_independently_of_tolerance():
    """Where the orbit from c = 0.1 ends (an impact meets an impulse time) is
    extrapolated to 1e-10, not interpolated: rtol 1e-9 and 1e-11 agree to 1e-8."""
    values = []
    for tol in (1e-9, 1e-11):
        pts = locate_bifurcations(preset("3.1"), "c", 0.07, 0.1, seeds=[0.1], depth=0,
                                  options=SolverOptions(rtol=tol, atol=tol))
        assert [p.kind for p in pts] == ["impulse-impact"] and pts[0].located
        values.append(pts[0].value)
    assert abs(values[0] - values[1]) < 1e-8
    assert abs(values[1] - IMPULSE_END_OF_PERIOD_1_LIKE) < 1e-6


@pytest.mark.slow
def test_fig3_range_default_impulses_sweep_and_standalone_agree():
    """Fig. 3's DMR row (c in [0.01, 0.1], 61 values, 300 + 60 periods, the default
    impulses): the sweep's located points are the standalone function's (default seeds)
    where both find them, the fold and the first doubling are there, no doubling at
    0.073, and the 28/28 seen at 0.073 lies in a window bounded by two impulse-impact
    points."""
    values = np.linspace(0.01, 0.1, 61)
    ds = sweep("dmr", "c", values, preset("3.1"), transient=300, record=60, workers=2)
    kinds = [BIFURCATION_KINDS[k] for k in ds.bifurcation_kind.values]
    at = ds.bifurcation_parameter.values
    pd = [v for v, k in zip(at, kinds) if k == "period-doubling"]
    assert max(pd) == pytest.approx(IMPULSE_FIRST_DOUBLING, abs=1e-6)
    assert not [v for v in pd if v > 0.04]
    folds = [v for v, k in zip(at, kinds) if k == "fold"]
    assert pytest.approx(IMPULSE_FOLD, abs=1e-6) in folds
    window = [(v, p) for v, k, p in zip(at, kinds, ds.bifurcation_period.values)
              if k == "impulse-impact" and p == 28]
    assert len(window) == 2 and window[0][0] < 0.073 < window[1][0]
    ends = [v for v, k, p in zip(at, kinds, ds.bifurcation_period.values)
            if k == "impulse-impact" and p == 14 and v > 0.07]
    assert ends == [pytest.approx(IMPULSE_END_OF_PERIOD_1_LIKE, abs=1e-6)]
    assert "28/28" in ds.label.values.tolist()
    alone = locate_bifurcations(preset("3.1"), "c", 0.01, 0.1)
    for p in alone:
        same = [v for v, k in zip(at, kinds) if k == p.kind and abs(v - p.value) < 1e-6]
        assert same and abs(same[0] - p.value) < 1e-9, p


# --------------------------------------------------------------------------- grazing
def test_grazing_located_at_the_free_flight_maximum():
    """Moving the wall (delta) down onto the impact-free 3/0 orbit of section 3.1
    (F0 = 0, c = 0.05): it grazes where delta equals that orbit's largest x, taken from
    a simulation by the independent solver with the wall far away."""
    osc = preset("3.1", F0=0.0, c=0.05)
    far = osc.replace(delta=10.0)
    T = far.forcing_period
    per = 4000
    times = np.concatenate([[0.0], 597 * T + np.arange(1, 3 * per + 1) * (T / per)])
    run = simulate_dmr(far, times=times, options=SolverOptions(rtol=1e-11, atol=1e-11))
    x_max = float(run.x.values[-3 * per:].max())
    pts = locate_bifurcations(osc, "delta", x_max - 0.3, x_max + 0.3, seeds=[x_max + 0.3],
                              depth=0)
    assert [p.kind for p in pts] == ["grazing"]
    assert pts[0].located and pts[0].period == 3
    assert abs(pts[0].value - x_max) < 2e-6  # sampling error of x_max ~ 1e-6


# --------------------------------------------------------------------------- summary
def _small_sweep():
    return sweep("dmr", "c", [0.06, 0.07, 0.08, 0.09, 0.1], preset("3.1", F0=0.0),
                 transient=200, record=40, workers=1, locate=False)


def test_summary_reports_disagreements_in_words():
    ds = _small_sweep()
    assert ds.attrs["bifurcation_method"] == "not located: locate=False"
    assert "bifurcations not located: locate=False" in "\n".join(summary_lines(ds))
    points = [Located("period-doubling", 0.0891223, 1, -1.0 + 0j, True, "1 -> 2"),
              Located("fold", 0.0951, 2, 1.0 + 0j, True, "a fold")]
    ds = add_located(ds, points, method="continuation (test)")
    # observed: 4/4 at 0.06 (a change between 0.06 and 0.07 that nothing explains), then
    # 2/2 up to 0.1 (no change where the doubling and the fold were located)
    ds["label"] = ("c", np.array(["4/4"] + ["2/2"] * 4), ds.label.attrs)
    text = "\n".join(summary_lines(ds))
    assert "observed 4/4 -> 2/2 between c = 0.06 and 0.07: no located bifurcation" in text
    assert "nearest: period-doubling at c = 0.0891223" in text
    assert "located fold at c = 0.0951: the observed period does not change" in text
    assert "located period-doubling at c = 0.0891223: the observed period does not" in text
    assert "period-doubling  c = 0.0891223  period 1, multiplier -1.000000: 1 -> 2" in text


# --------------------------------------------------------------------------- refusals
def test_bad_requests_are_refused():
    osc = preset("3.1")
    with pytest.raises(ValueError, match="lo must be < hi"):
        locate_bifurcations(osc, "c", 0.1, 0.05)
    with pytest.raises(ValueError, match="only selects the attractor"):
        locate_bifurcations(osc, "x0", -1.0, 0.0)
    with pytest.raises(ValueError, match="common period"):
        locate_bifurcations(osc, "omega", 2.7, 2.9)
    with pytest.raises(ValueError, match="seed values must lie in"):
        locate_bifurcations(osc, "c", 0.05, 0.1, seeds=[0.2])
    with pytest.raises(ValueError, match="options belong to the ImpactSystem"):
        locate_bifurcations(ImpactSystem(osc), "c", 0.05, 0.1, options=SolverOptions())
    with pytest.raises(ValueError, match="locate=True: the Monte Carlo mean"):
        sweep("mc", "c", [0.05, 0.06], osc, sigma=0.01, samples=4, locate=True, workers=1,
              source=sweep_source)
    with pytest.raises(ValueError, match="locate must be"):
        sweep("dmr", "c", [0.05, 0.06], osc, locate="yes", workers=1)
    # by default a sweep that cannot be located says why instead of failing
    ds = sweep("dmr", "omega", [2.7, 2.9], osc, transient=5, record=4, workers=1)
    assert ds.attrs["bifurcation_method"].startswith("not located: the forcing's common")
    assert ds.sizes["bifurcation"] == 0


@pytest.mark.parametrize("field, value, rule", [
    ("step", 0.0, "a finite number > 0"), ("max_step", math.nan, "a finite number > 0"),
    ("max_points", 0, "an integer >= 1"), ("max_multiplier", -1.0, "a finite number > 0"),
    ("switch_amplitude", math.inf, "a finite number > 0"), ("tol", 0.0, "a finite number > 0"),
    ("transient", 2.5, "an integer >= 0")])
def test_continuation_options_name_the_field_and_the_value(field, value, rule):
    with pytest.raises(ValueError, match=re.escape(f"{field} must be {rule}, got {value!r}")):
        ContinuationOptions(**{field: value})


def test_the_continuation_options_reach_the_branch():
    """A branch from c = 0.095 towards 0.085 needs about 50 steps of 0.02 (in units of the
    interval): ``max_points`` = 5 stops it at 5 orbits and says so; steps twice as long
    need fewer orbits to the same end; a record that is not one is refused."""
    system = ImpactSystem(preset("3.1", F0=0.0))
    capped = continue_orbits(system, "c", 0.095, 0.085, depth=0,
                             continuation=ContinuationOptions(max_points=5))
    assert capped.sizes["point"] == 5 and "max_points (5) reached" in capped.branch_end
    short, long_ = (continue_orbits(system, "c", 0.095, 0.085, depth=0,
                                    continuation=ContinuationOptions(step=s, max_step=s))
                    for s in (0.05, 0.1))
    assert short.c.values[-1] == long_.c.values[-1] == 0.085
    assert long_.sizes["point"] < short.sizes["point"]
    with pytest.raises(ValueError, match="continuation must be a ContinuationOptions"):
        continue_orbits(system, "c", 0.095, 0.085, continuation={"max_points": 5})


# --------------------------------------------------------------------------- branches
def test_period_doubling_located_independently_of_tolerance():
    values = []
    for tol in (1e-9, 1e-11):
        system = ImpactSystem(preset("3.1", F0=0.0), options=SolverOptions(rtol=tol, atol=tol))
        ds = continue_orbits(system, "c", 0.095, 0.085, depth=0)
        pd = ds.bifurcation_kind.values == BIFURCATION_KINDS.index("period-doubling")
        assert pd.sum() == 1 and ds.bifurcation_located.values[pd][0] == 1
        values.append(float(ds.bifurcation_c.values[pd][0]))
    assert abs(values[0] - values[1]) < 1e-6
    assert 0.0891 < values[1] < 0.0892


def test_period_doubling_point_has_multiplier_minus_one_and_emr0_agrees():
    system = ImpactSystem(preset("3.1", F0=0.0))
    a = periodic_orbit(system.with_parameter("c", 0.092))
    b = shoot(system.with_parameter("c", 0.087), a.state, periods=1)
    orbit = locate_period_doubling(system, "c", (0.092, a), (0.087, b))
    assert np.min(np.abs(orbit.multipliers + 1.0)) < 1e-7
    assert "period-doubling" in orbit.classify()
    c_pd = orbit.system.oscillator.c
    emr0 = ImpactSystem(preset("3.1", F0=0.0), model="opa", order=3, sigma=0.0)
    y = np.zeros(8)
    y[0], y[4] = a.state
    ea = shoot(emr0.with_parameter("c", 0.092), y, periods=1)
    eb = shoot(emr0.with_parameter("c", 0.087), y, periods=1)
    e_pd = locate_period_doubling(emr0, "c", (0.092, ea), (0.087, eb))
    assert abs(e_pd.system.oscillator.c - c_pd) < 1e-8


def test_branch_switching_matches_brute_force():
    system = ImpactSystem(preset("3.1", F0=0.0))
    ds = continue_orbits(system, "c", 0.095, 0.08, depth=1)
    assert set(ds.branch_period.values) == {1, 2}
    pd = int(np.flatnonzero(ds.bifurcation_child.values >= 0)[0])
    c_pd = float(ds.bifurcation_c[pd])
    child = int(ds.bifurcation_child[pd])
    doubled = ds.where(ds.branch == child, drop=True)
    primary = ds.where(ds.branch == 0, drop=True)
    # supercritical: the doubled orbits lie below c_pd, stable; the period-1 orbit is
    # stable above c_pd and unstable below
    assert np.all(doubled.c.values <= c_pd + 1e-9)
    assert doubled.stable.values[-1] == 1
    assert np.all(primary.stable.values[primary.c.values > c_pd + 1e-6] == 1)
    assert np.all(primary.stable.values[primary.c.values < c_pd - 1e-6] == 0)
    # the doubled orbit at the end of the interval is the attractor of a long simulation
    end = int(np.argmin(doubled.c.values))
    osc = system.oscillator.replace(c=float(doubled.c.values[end]))
    sim = simulate_dmr(osc, periods=800, options=SolverOptions(rtol=1e-10, atol=1e-10))
    last = np.sort(sim.x.values[-2:])
    np.testing.assert_allclose(np.sort(doubled.section_x.values[end, :2]), last, atol=1e-6)


@pytest.mark.slow
def test_impulses_turn_the_first_period_doubling_into_a_fold():
    # with the default impulses the period-1-like orbit (a fixed point of P^14) meets an
    # impulse with an impact and ends; the period-2-like orbit folds instead of doubling
    system = ImpactSystem(preset("3.1"), options=SolverOptions(rtol=1e-10, atol=1e-10))
    ds = continue_orbits(system, "c", 0.1, 0.06, depth=0)
    kinds = [BIFURCATION_KINDS[k] for k in ds.bifurcation_kind.values]
    assert "impulse-impact" in kinds and "period-doubling" not in kinds
    ds2 = continue_orbits(system, "c", 0.06, 0.08, depth=0)
    folds = ds2.bifurcation_c.values[ds2.bifurcation_kind.values == BIFURCATION_KINDS.index(
        "fold")]
    assert len(folds) == 1 and 0.0735 < folds[0] < 0.0737
