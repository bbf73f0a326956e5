"""The split detector against a grazing established with the scipy reference alone
(tests/reference_splits.py), and its classification on constructed event sequences; the
complete split list and its impact-count table against a brute scan of deterministic runs
(weighted by the semicircle law), the reported limit and the early stop short of it, and
an impact crossing an output time against the scipy reference (issue 24)."""

from dataclasses import replace

import numpy as np
import pytest

from opa import Oscillator, SolverOptions, preset
from opa._splits import (
    MAX_SPLITS,
    EventSequence,
    Split,
    _classify,
    count_probabilities,
    event_sequence,
    event_sequences,
    find_splits,
    scan_splits,
)
from tests.reference_splits import GRAZING_CASE, SAFE_OFFSET, impact_count
from tests.truths import semicircle_mass

CASE = GRAZING_CASE
OPTIONS = SolverOptions(rtol=1e-11, atol=1e-11, impulse="dirac", impulse_at_zero=True)


def _osc(mu):
    return Oscillator(mu=mu, **CASE["model"])


def test_reference_counts_on_both_sides_of_the_split():
    """The scipy reference itself: 3 impacts below mu_split, 2 above (its own claim)."""
    assert impact_count(CASE["mu_split"] - SAFE_OFFSET) == CASE["count_below"]
    assert impact_count(CASE["mu_split"] + SAFE_OFFSET) == CASE["count_above"]


@pytest.mark.parametrize("mu", [0.70, 0.74, 0.82, 0.9])
def test_event_counts_match_the_reference_away_from_the_split(mu):
    seq = event_sequence(_osc(mu), OPTIONS, CASE["t_end"])
    assert seq.count(CASE["t_end"]) == impact_count(mu)


def test_find_splits_locates_the_scipy_grazing():
    t_end = CASE["t_end"]
    splits, truncated = find_splits(_osc(0.8), OPTIONS, "mu", 0.76, 0.80, t_end, tol=1e-9)
    assert not truncated
    real = [s for s in splits if s.kind != "horizon"]
    assert len(real) == 1
    (s,) = real
    # the reference's bracket is +/- 5e-10; our solver's tolerance moves the split by less
    # than 1e-7 (the peak height changes by 0.315 per unit mu)
    assert abs(s.value - CASE["mu_split"]) < 1e-7
    assert s.tol <= 1e-9
    assert s.kind == "grazing"
    assert (s.left, s.right) == (CASE["count_below"], CASE["count_above"])
    assert abs(s.time - CASE["extra_impact_time"]) < 2e-3
    # velocity ~ 0.927 sqrt(mu_split - mu): at a bracket of 1e-9 it is below 1e-4
    assert s.speed < 1e-4


def test_find_splits_every_horizon_shares_one_cache(monkeypatch):
    import opa._splits as S

    computed = []
    real = S.event_sequences

    def counting(osc, options, parameter, values, t_end):
        computed.extend(values)
        return real(osc, options, parameter, values, t_end)

    monkeypatch.setattr(S, "event_sequences", counting)
    cache: dict = {}
    long_ = find_splits(_osc(0.8), OPTIONS, "mu", 0.76, 0.80, CASE["t_end"], tol=1e-7,
                        cache=cache)[0]
    first = len(computed)
    short = find_splits(_osc(0.8), OPTIONS, "mu", 0.76, 0.80, 0.5 * CASE["t_end"], tol=1e-7,
                        cache=cache)[0]
    # the second horizon reruns none of the 129 scan values: only its own bisections
    assert first >= 129 and len(computed) - first < 129
    # the grazing is at t = 8.79 > t_end / 2: the short horizon sees no split there
    assert all(abs(s.value - CASE["mu_split"]) > 1e-4 or s.kind == "horizon" for s in short)
    assert any(s.kind == "grazing" for s in long_)
    with pytest.raises(ValueError, match="past the cached runs"):
        find_splits(_osc(0.8), OPTIONS, "mu", 0.76, 0.80, 2 * CASE["t_end"], cache=cache)


def test_find_splits_rejects_bad_intervals():
    with pytest.raises(ValueError, match="lo < hi"):
        find_splits(_osc(0.8), OPTIONS, "mu", 0.8, 0.7, 1.0)
    with pytest.raises(ValueError, match="tol"):
        find_splits(_osc(0.8), OPTIONS, "mu", 0.7, 0.8, 1.0, tol=0.0)


# -- classification on constructed sequences ---------------------------------------------
def _seq(times, speeds, kinds=None, intervals=None):
    n = len(times)
    return EventSequence(np.array(times, float), np.array(speeds, float),
                         tuple(kinds or "I" * n), np.array(intervals or [0] * n))


P = 1.0  # forcing period of the constructed cases


def test_a_slow_extra_impact_is_a_grazing_and_a_fast_one_an_extra_impact():
    a = _seq([1.0, 2.0], [0.5, 0.6])
    assert _classify(a, _seq([1.0, 1.5, 2.0], [0.5, 1e-5, 0.6]), 10.0, P)[0] == "grazing"
    assert _classify(a, _seq([1.0, 1.5, 2.0], [0.5, 0.3, 0.6]), 10.0, P)[0] == "extra impact"
    kind, t, v = _classify(a, _seq([1.0, 2.0, 3.0], [0.5, 0.6, 0.2]), 10.0, P)
    assert (kind, t, v) == ("extra impact", 3.0, 0.2)


def test_an_event_at_the_horizon_is_a_horizon_crossing():
    a = _seq([1.0, 2.0], [0.5, 0.6])
    b = _seq([1.0, 2.0, 10.0 - 1e-6], [0.5, 0.6, 0.4])
    assert _classify(a, b, 10.0, P)[0] == "horizon"


def test_a_burst_of_impacts_or_a_stick_is_chatter():
    a = _seq([1.0, 2.0], [0.5, 0.6])
    burst = _seq([1.0, 2.0, 2.01, 2.015, 2.018], [0.5, 0.6, 0.1, 0.05, 0.02])
    assert _classify(a, burst, 10.0, P)[0] == "chatter"
    stick = _seq([1.0, 2.0, 2.5, 2.9], [0.5, 0.6, 0.0, 0.0], kinds="IISR")
    assert _classify(a, stick, 10.0, P)[0] == "chatter"


def test_an_impact_crossing_an_impulse_time_changes_the_order():
    a = _seq([1.0, 6.2], [0.5, 0.6], intervals=[0, 0])
    b = _seq([1.0, 6.3], [0.5, 0.6], intervals=[0, 1])
    assert _classify(a, b, 10.0, P)[0] == "impulse order"


# -- complete lists, exact counts, the limit (issue 24) -------------------------------------
# The validate default at omega = 3.98 (section 3.2 set, F0 = 0.1, dirac impulses, rtol =
# atol = 1e-9), 10 forcing periods, sigma = 0.03: a grazing, an impulse-driven cascade and
# a chatter cascade lie within the ensemble.

MAP_OPTIONS = SolverOptions(rtol=1e-9, atol=1e-9)
SIGMA = 0.03


def _map_osc(omega):
    return preset("3.2", omega=omega)


@pytest.fixture(scope="module")
def brute_398():
    """Independent of the split scan: the impact count of n deterministic runs at equally
    spaced values of mu over [0.8 - sigma, 0.8 + sigma] (cell midpoints)."""
    osc = _map_osc(3.98)
    H = 10 * osc.forcing_period
    n = 6000
    mu = 0.8 + SIGMA * (-1 + (2 * np.arange(n) + 1) / n)
    counts = np.array([s.count(H) for s in event_sequences(osc, MAP_OPTIONS, "mu", mu, H)])
    return mu, counts, H


@pytest.fixture(scope="module")
def complete_398(brute_398):
    _, _, H = brute_398
    return scan_splits(_map_osc(3.98), MAP_OPTIONS, "mu", 0.8 - SIGMA, 0.8 + SIGMA, H,
                       tol=1e-8, center=0.8)


def _predicted(splits, mu):
    """The count the split list gives at each mu (left of the next split above)."""
    values = np.array([s.value for s in splits])
    i = np.searchsorted(values, mu)
    return np.array([splits[k].left if k < len(splits) else splits[-1].right for k in i])


def test_the_complete_split_list_gives_every_brute_force_count(brute_398, complete_398):
    mu, counts, _ = brute_398
    scan = complete_398
    assert not scan.truncated and scan.complete_within == np.inf
    assert len(scan.splits) > 64  # more than the old silent cut
    assert {"grazing", "chatter"} <= {s.kind for s in scan.splits}
    for a, b in zip(scan.splits[:-1], scan.splits[1:]):  # a consistent chain of counts
        assert a.right == b.left
    # every one of the 6000 runs makes the count the list predicts
    np.testing.assert_array_equal(_predicted(scan.splits, mu), counts)


def test_count_probabilities_agree_with_the_brute_scan_weighted_by_the_law(brute_398,
                                                                          complete_398):
    """P(k) from the splits against the runs weighted by the semicircle mass of their
    cells: each end of a segment of count k misplaces at most the mass of one cell."""
    mu, counts, _ = brute_398
    n = len(mu)
    xi_edges = -1 + 2 * np.arange(n + 1) / n
    w = np.array([semicircle_mass(a, b) for a, b in zip(xi_edges[:-1], xi_edges[1:])])
    probs, unknown = count_probabilities(complete_398.splits, 0.8, SIGMA, 4,
                                         _semicircle_cdf, complete_398.complete_within)
    assert unknown == 0.0
    assert sum(probs.values()) == pytest.approx(1.0, abs=1e-12)
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    for k in set(probs) | set(counts.tolist()):
        brute = float(w[counts == k].sum())
        ends = sum(k in (s.left, s.right) for s in complete_398.splits if s.left != s.right)
        assert abs(probs.get(k, 0.0) - brute) <= ends * w.max() + 1e-12, k
    # the shares the independent scan gives: 92.74 % / 7.20 % / 0.064 % (6-56)
    assert probs[4] == pytest.approx(0.9274, abs=1e-4)
    assert probs[5] == pytest.approx(0.0720, abs=3e-4)


def _semicircle_cdf(x):
    return semicircle_mass(-1.0, x)


def test_a_limit_reached_is_reported_and_the_counts_marked_incomplete(brute_398,
                                                                      complete_398):
    mu, counts, H = brute_398
    cut = scan_splits(_map_osc(3.98), MAP_OPTIONS, "mu", 0.8 - SIGMA, 0.8 + SIGMA, H,
                      tol=1e-8, center=0.8, max_splits=8)
    assert cut.truncated and cut.limit == 8
    r = cut.complete_within
    assert 0 < r < SIGMA
    # within the radius the cut list is the complete one, and its counts are the runs'
    full = [s for s in complete_398.splits if abs(s.value - 0.8) < r]
    mine = [s for s in cut.splits if abs(s.value - 0.8) < r]
    assert [(s.left, s.right) for s in mine] == [(s.left, s.right) for s in full]
    np.testing.assert_allclose([s.value for s in mine], [s.value for s in full], atol=2e-8)
    inside = np.abs(mu - 0.8) < r
    np.testing.assert_array_equal(_predicted(cut.splits, mu[inside]), counts[inside])
    probs, unknown = count_probabilities(cut.splits, 0.8, SIGMA, 4, _semicircle_cdf, r)
    assert unknown == pytest.approx(1 - semicircle_mass(-r / SIGMA, r / SIGMA), abs=1e-12)
    assert unknown > 0
    assert sum(probs.values()) + unknown == pytest.approx(1.0, abs=1e-12)
    # a sigma within the radius is complete and exact
    probs, unknown = count_probabilities(cut.splits, 0.8, 0.9 * r, 4, _semicircle_cdf, r)
    assert unknown == 0.0 and sum(probs.values()) == pytest.approx(1.0, abs=1e-12)


def test_the_default_limit_is_documented_and_find_splits_reports_it():
    assert MAX_SPLITS >= 1024
    osc = _map_osc(3.98)
    splits, truncated = find_splits(osc, MAP_OPTIONS, "mu", 0.77, 0.83,
                                    10 * osc.forcing_period, tol=1e-7, max_splits=4,
                                    center=0.8)
    assert truncated and len(splits) >= 4


# -- the early stop (needed_within) --------------------------------------------------------
def _listed(splits, r):
    """What the count tables and the causes read off a list within r of mu = 0.8."""
    return [(s.value, s.tol, s.kind, s.left, s.right) for s in splits if abs(s.value - 0.8) < r]


def test_the_early_stop_keeps_a_list_that_can_be_completed_whole(complete_398):
    """Where the scan can become complete within the radii asked it does not stop early:
    it is the same scan, whichever radii (the limit reaches the whole ensemble)."""
    H = 10 * _map_osc(3.98).forcing_period
    for needed in (SIGMA, (0.005, 0.01, SIGMA)):
        scan = scan_splits(_map_osc(3.98), MAP_OPTIONS, "mu", 0.8 - SIGMA, 0.8 + SIGMA, H,
                           tol=1e-8, center=0.8, needed_within=needed)
        assert not scan.stopped_early and scan.needed_within == tuple(np.atleast_1d(needed))
        assert replace(scan, needed_within=()) == complete_398


def test_the_early_stop_gives_up_a_radius_the_limit_cannot_reach(brute_398, complete_398):
    """With a limit of 24 the 10-period list cannot reach sigma = 0.03 (it holds more than
    64 changes): the scan stops early, and where it says it is complete its counts are the
    brute scan's; a radius the scan without the early stop reaches is reached."""
    mu, counts, H = brute_398
    args = (_map_osc(3.98), MAP_OPTIONS, "mu", 0.8 - SIGMA, 0.8 + SIGMA, H)
    cut = scan_splits(*args, tol=1e-8, center=0.8, max_splits=24)
    assert cut.truncated and not cut.stopped_early and 0 < cut.complete_within < SIGMA
    early = scan_splits(*args, tol=1e-8, center=0.8, max_splits=24, min_splits=8,
                        needed_within=(0.5 * cut.complete_within, SIGMA))
    assert early.stopped_early and early.truncated
    assert 8 <= len(early.splits) < 24
    r = early.complete_within
    assert 0.5 * cut.complete_within <= r <= cut.complete_within
    assert _listed(early.splits, r) == _listed(complete_398.splits, r)
    inside = np.abs(mu - 0.8) < r
    np.testing.assert_array_equal(_predicted(early.splits, mu[inside]), counts[inside])
    # a radius it can reach: the same scan as without the early stop
    reach = scan_splits(*args, tol=1e-8, center=0.8, max_splits=24, min_splits=8,
                        needed_within=0.5 * cut.complete_within)
    assert not reach.stopped_early
    assert replace(reach, needed_within=()) == cut


def test_the_early_stop_over_a_long_horizon():
    """50 forcing periods, |mu - 0.8| < 0.002: the changes are too dense for a limit of 48
    to reach 0.002. The early stop says so, and within its radius the list is that of the
    scan without it."""
    osc = _map_osc(3.98)
    args = (osc, MAP_OPTIONS, "mu", 0.798, 0.802, 50 * osc.forcing_period)
    full = scan_splits(*args, tol=1e-8, center=0.8, max_splits=48)
    assert full.truncated and full.complete_within < 0.002 and len(full.splits) == 48
    early = scan_splits(*args, tol=1e-8, center=0.8, max_splits=48, min_splits=8,
                        needed_within=0.002)
    assert early.stopped_early and early.truncated and early.needed_within == (0.002,)
    assert 8 <= len(early.splits) < 48
    r = early.complete_within
    assert 0 < r <= full.complete_within
    assert _listed(early.splits, r) == _listed(full.splits, r) != []
    # without the floor it stops before the first wave: nothing located, complete within
    # the distance of the nearest bracket
    bare = scan_splits(*args, tol=1e-8, center=0.8, max_splits=48, min_splits=0,
                       needed_within=0.002)
    assert bare.stopped_early and bare.splits == [] and bare.complete_within < r


def test_count_probabilities_by_hand():
    splits = [Split(0.78, 1e-9, "grazing", 5.0, 1e-5, 4, 3),
              Split(0.79, 1e-9, "output crossing", 6.0, 0.5, 3, 3),
              Split(0.81, 1e-9, "extra impact", 7.0, 0.2, 3, 5)]
    probs, unknown = count_probabilities(splits, 0.8, 0.05, 3, _semicircle_cdf)
    assert unknown == 0.0
    assert probs[4] == pytest.approx(semicircle_mass(-1, -0.4), abs=1e-12)
    assert probs[3] == pytest.approx(semicircle_mass(-0.4, 0.2), abs=1e-12)
    assert probs[5] == pytest.approx(semicircle_mass(0.2, 1), abs=1e-12)
    # complete only within 0.015: the split at 0.78 is beyond, and so is its mass
    probs, unknown = count_probabilities(splits, 0.8, 0.05, 3, _semicircle_cdf, 0.015)
    assert probs == {3: pytest.approx(semicircle_mass(-0.3, 0.2), abs=1e-12),
                     5: pytest.approx(semicircle_mass(0.2, 0.3), abs=1e-12)}
    assert unknown == pytest.approx(1 - semicircle_mass(-0.3, 0.3), abs=1e-12)
    assert count_probabilities(splits, 0.8, 0.05, 3, _semicircle_cdf, 0.0) == ({}, 1.0)


@pytest.mark.parametrize("kwargs, needle", [
    (dict(sigma=0.0), "sigma"), (dict(sigma=float("nan")), "sigma"),
    (dict(center=float("inf")), "center"), (dict(complete_within=-1.0), "complete_within"),
])
def test_count_probabilities_rejects_bad_input(kwargs, needle):
    args = dict(center=0.8, sigma=0.05, count_at_center=3, cdf=_semicircle_cdf) | kwargs
    with pytest.raises(ValueError, match=needle):
        count_probabilities([], **args)


@pytest.mark.parametrize("kwargs, needle", [
    (dict(max_splits=0), "max_splits"), (dict(max_splits=2.5), "max_splits"),
    (dict(scan=1), "scan"), (dict(outputs=[1.0, float("nan")]), "outputs"),
    (dict(order="random"), "order"),
    (dict(needed_within=0.0), "needed_within"), (dict(needed_within=-0.01), "needed_within"),
    (dict(needed_within=float("nan")), "needed_within"),
    (dict(needed_within=[0.01, 0.0]), "needed_within"),
    (dict(needed_within=True), "needed_within"), (dict(needed_within="0.01"), "needed_within"),
    (dict(min_splits=-1), "min_splits"), (dict(min_splits=2.5), "min_splits"),
    (dict(min_splits=True), "min_splits"),
])
def test_scan_splits_rejects_bad_input(kwargs, needle):
    with pytest.raises(ValueError, match=needle):
        scan_splits(_osc(0.8), OPTIONS, "mu", 0.7, 0.8, 1.0, **kwargs)
    with pytest.raises(ValueError, match="horizon"):
        scan_splits(_osc(0.8), OPTIONS, "mu", 0.7, 0.8, -1.0)


# -- an impact crossing an output time (issue 24: the cause at omega = 4.09) ----------------
def _scipy(mu, omega, t_out):
    from tests.reference import reference_trajectory

    osc = _map_osc(omega)
    model = {k: getattr(osc, k) for k in ("a", "c", "f", "omega", "eta", "delta", "F0", "a1",
                                          "omega1", "n", "x0", "v0")}
    return reference_trajectory(mu=mu, t_out=np.asarray(t_out, float), rtol=1e-11,
                                atol=1e-11, **model)


def test_an_impact_crossing_an_output_time_at_4_09_matches_scipy():
    """The validate default at omega = 4.09 over 10 periods, outputs every 1/8 period: no
    split for |mu - 0.8| <= 0.05, but the 4th impact crosses the output at t = 9.75
    periods. Where, how many and the kink of x(t_j, mu) there are computed with the scipy
    reference alone."""
    from scipy.optimize import brentq

    osc = _map_osc(4.09)
    T = osc.forcing_period
    H = 10 * T
    outputs = np.arange(81) * T / 8
    scan = scan_splits(osc, MAP_OPTIONS, "mu", 0.75, 0.85, H, tol=1e-9, center=0.8,
                       outputs=outputs)
    assert scan.splits == [] and not scan.truncated
    # scipy at the two ends: the same impacts; which impact times straddle an output
    ends = [_scipy(mu, 4.09, [0.0, H]) for mu in (0.75, 0.85)]
    assert len(ends[0]["impact_time"]) == len(ends[1]["impact_time"]) == 4
    straddle = [(i, tj) for i, (t0, t1) in enumerate(zip(*(e["impact_time"] for e in ends)))
                for tj in outputs if min(t0, t1) < tj < max(t0, t1)]
    assert len(scan.crossings) == len(straddle) == 1
    (i, tj), (c,) = straddle[0], scan.crossings
    assert i == 3 and tj / T == pytest.approx(9.75)
    assert c.kind == "output crossing" and c.time == pytest.approx(tj, abs=1e-12)
    assert (c.left, c.right) == (4, 4)

    def impact_minus_output(mu):
        return _scipy(mu, 4.09, [0.0, H])["impact_time"][i] - tj

    mu_ref = brentq(impact_minus_output, 0.75, 0.85, xtol=1e-12)
    assert abs(c.value - mu_ref) < 1e-7
    assert 0.0015 < abs(mu_ref - 0.8) < 0.0025  # sigma ~ 0.002: the estimate
    v = _scipy(mu_ref, 4.09, [0.0, H])["impact_velocity"][i]
    assert c.speed == pytest.approx(v, rel=1e-4)
    # the kink of x(t_j, mu): one-sided slopes (scipy) differ by (1 + eta) v |dt_i/dmu|
    h = 2e-5
    rate = (impact_minus_output(mu_ref + h) - impact_minus_output(mu_ref - h)) / (2 * h)
    x = {k: _scipy(mu_ref + k * h, 4.09, [0.0, tj])["x"][-1] for k in (-2, -1, 1, 2)}
    left, right = (x[-1] - x[-2]) / h, (x[2] - x[1]) / h
    expected = (1 + osc.eta) * v * abs(rate)
    assert abs(right - left) == pytest.approx(expected, rel=0.05)
    assert expected > 1.0
