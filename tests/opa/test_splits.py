"""The split detector against a grazing established with the scipy reference alone
(tests/reference_splits.py), and its classification on constructed event sequences; the
complete split list and its impact-count table against a brute scan of deterministic runs
(weighted by the semicircle law), the reported limit and the early stop short of it, and
an impact crossing an output time against the scipy reference (issue 24)."""

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opa import Oscillator, SolverOptions, preset
from opa._splits import (
    MAX_SPLITS,
    EventSequence,
    SampledRuns,
    ScanOptions,
    Split,
    SplitScanner,
    _classify,
    _crossing_brackets,
    _first_difference,
    _owed,
    _Rows,
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


def test_find_splits_every_horizon_shares_one_set_of_runs(monkeypatch):
    import opa._splits as S

    computed = []
    real = S.event_sequences

    def counting(osc, options, parameter, values, t_end):
        computed.extend(values)
        return real(osc, options, parameter, values, t_end)

    monkeypatch.setattr(S, "event_sequences", counting)
    runs = SampledRuns(_osc(0.8), OPTIONS, "mu", CASE["t_end"])
    long_ = find_splits(_osc(0.8), OPTIONS, "mu", 0.76, 0.80, CASE["t_end"], tol=1e-7,
                        runs=runs)[0]
    first = len(computed)
    short = find_splits(_osc(0.8), OPTIONS, "mu", 0.76, 0.80, 0.5 * CASE["t_end"], tol=1e-7,
                        runs=runs)[0]
    # the second horizon reruns none of the 129 scan values: only its own bisections
    assert first >= 129 and len(computed) - first < 129
    # the grazing is at t = 8.79 > t_end / 2: the short horizon sees no split there
    assert all(abs(s.value - CASE["mu_split"]) > 1e-4 or s.kind == "horizon" for s in short)
    assert any(s.kind == "grazing" for s in long_)
    with pytest.raises(ValueError, match="past the cached runs"):
        find_splits(_osc(0.8), OPTIONS, "mu", 0.76, 0.80, 2 * CASE["t_end"], runs=runs)
    with pytest.raises(ValueError, match="runs must be of the scan's system"):
        find_splits(_osc(0.81), OPTIONS, "mu", 0.76, 0.80, CASE["t_end"], runs=runs)


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
                       ScanOptions(tol=1e-8, center=0.8))


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
                      ScanOptions(tol=1e-8, center=0.8, max_splits=8))
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
                           ScanOptions(tol=1e-8, center=0.8, needed_within=needed))
        assert not scan.stopped_early and scan.needed_within == tuple(np.atleast_1d(needed))
        assert replace(scan, needed_within=()) == complete_398


def test_the_early_stop_gives_up_a_radius_the_limit_cannot_reach(brute_398, complete_398):
    """With a limit of 24 the 10-period list cannot reach sigma = 0.03 (it holds more than
    64 changes): the scan stops early, and where it says it is complete its counts are the
    brute scan's; a radius the scan without the early stop reaches is reached."""
    mu, counts, H = brute_398
    args = (_map_osc(3.98), MAP_OPTIONS, "mu", 0.8 - SIGMA, 0.8 + SIGMA, H)
    cut = scan_splits(*args, ScanOptions(tol=1e-8, center=0.8, max_splits=24))
    assert cut.truncated and not cut.stopped_early and 0 < cut.complete_within < SIGMA
    early = scan_splits(*args, ScanOptions(tol=1e-8, center=0.8, max_splits=24, min_splits=8,
                                           needed_within=(0.5 * cut.complete_within, SIGMA)))
    assert early.stopped_early and early.truncated
    assert 8 <= len(early.splits) < 24
    r = early.complete_within
    assert 0.5 * cut.complete_within <= r <= cut.complete_within
    assert _listed(early.splits, r) == _listed(complete_398.splits, r)
    inside = np.abs(mu - 0.8) < r
    np.testing.assert_array_equal(_predicted(early.splits, mu[inside]), counts[inside])
    # a radius it can reach: the same scan as without the early stop
    reach = scan_splits(*args, ScanOptions(tol=1e-8, center=0.8, max_splits=24, min_splits=8,
                                           needed_within=0.5 * cut.complete_within))
    assert not reach.stopped_early
    assert replace(reach, needed_within=()) == cut


def test_the_early_stop_over_a_long_horizon():
    """50 forcing periods, |mu - 0.8| < 0.002: the changes are too dense for a limit of 48
    to reach 0.002. The early stop says so, and within its radius the list is that of the
    scan without it."""
    osc = _map_osc(3.98)
    args = (osc, MAP_OPTIONS, "mu", 0.798, 0.802, 50 * osc.forcing_period)
    full = scan_splits(*args, ScanOptions(tol=1e-8, center=0.8, max_splits=48))
    assert full.truncated and full.complete_within < 0.002 and len(full.splits) == 48
    early = scan_splits(*args, ScanOptions(tol=1e-8, center=0.8, max_splits=48, min_splits=8,
                                           needed_within=0.002))
    assert early.stopped_early and early.truncated and early.needed_within == (0.002,)
    assert 8 <= len(early.splits) < 48
    r = early.complete_within
    assert 0 < r <= full.complete_within
    assert _listed(early.splits, r) == _listed(full.splits, r) != []
    # without the floor it stops before the first wave: nothing located, complete within
    # the distance of the nearest bracket
    bare = scan_splits(*args, ScanOptions(tol=1e-8, center=0.8, max_splits=48, min_splits=0,
                                          needed_within=0.002))
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
    (dict(max_crossings=0), "max_crossings"), (dict(tol=float("inf")), "tol"),
    (dict(tol=True), "tol"), (dict(scan=1), "scan"), (dict(order="random"), "order"),
    (dict(needed_within=0.0), "needed_within"), (dict(needed_within=-0.01), "needed_within"),
    (dict(needed_within=float("nan")), "needed_within"),
    (dict(needed_within=[0.01, 0.0]), "needed_within"),
    (dict(needed_within=True), "needed_within"), (dict(needed_within="0.01"), "needed_within"),
    (dict(min_splits=-1), "min_splits"), (dict(min_splits=2.5), "min_splits"),
    (dict(min_splits=True), "min_splits"),
])
def test_scan_options_reject_bad_input(kwargs, needle):
    with pytest.raises(ValueError, match=needle):
        ScanOptions(**kwargs)


def test_scan_splits_rejects_bad_input():
    with pytest.raises(ValueError, match="horizon"):
        scan_splits(_osc(0.8), OPTIONS, "mu", 0.7, 0.8, -1.0)
    with pytest.raises(ValueError, match="outputs"):
        scan_splits(_osc(0.8), OPTIONS, "mu", 0.7, 0.8, 1.0, outputs=[1.0, float("nan")])
    with pytest.raises(ValueError, match="tol = 1e-300"):
        scan_splits(_osc(0.8), OPTIONS, "mu", 0.7, 0.8, 1.0, ScanOptions(tol=1e-300))
    with pytest.raises(TypeError, match="ScanOptions"):
        scan_splits(_osc(0.8), OPTIONS, "mu", 0.7, 0.8, 1.0, dict(tol=1e-6))
    with pytest.raises(ValueError, match="t_end"):
        SampledRuns(_osc(0.8), OPTIONS, "mu", 0.0)


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
    scan = scan_splits(osc, MAP_OPTIONS, "mu", 0.75, 0.85, H, ScanOptions(tol=1e-9, center=0.8),
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


# -- the vectorised steps against plain loops written here (random sequences) -------------
SLACK = 0.05


@st.composite
def _families(draw):
    """Event sequences at increasing values: a common pattern of kinds and intervals, each
    sequence with its own jitter of the times, and some with an event dropped, a kind or an
    interval changed, or a time jumped; a horizon that cuts some of them short."""
    n = draw(st.integers(0, 7))
    kinds = draw(st.lists(st.sampled_from("IIISR"), min_size=n, max_size=n))
    base = np.cumsum(draw(st.lists(st.floats(0.05, 1.0), min_size=n, max_size=n)))
    count = draw(st.integers(1, 9))
    seqs = []
    for _ in range(count):
        jitter = draw(st.lists(st.floats(-0.04, 0.04), min_size=n, max_size=n))
        times = np.sort(base + np.array(jitter))
        k, iv = list(kinds), [int(t // 1.5) for t in base]
        change = draw(st.sampled_from(["none", "none", "drop", "kind", "interval", "jump"]))
        if n and change == "drop":
            at = draw(st.integers(0, n - 1))
            times, k, iv = np.delete(times, at), k[:at] + k[at + 1:], iv[:at] + iv[at + 1:]
        elif n and change == "kind":
            at = draw(st.integers(0, n - 1))
            k[at] = "S" if k[at] != "S" else "I"
        elif n and change == "interval":
            iv[draw(st.integers(0, n - 1))] += 1
        elif n and change == "jump":
            at = draw(st.integers(0, n - 1))
            times = times.copy()
            times[at:] += 2 * SLACK
        seqs.append(EventSequence(np.asarray(times, float), np.linspace(0.1, 1.0, len(k)),
                                  tuple(k), np.array(iv, dtype=np.int64)))
    values = np.cumsum(draw(st.lists(st.floats(0.01, 1.0), min_size=count, max_size=count)))
    horizon = draw(st.floats(0.5, float(base[-1]) + 1.0 if n else 2.0))
    return dict(zip(values.tolist(), seqs)), horizon


def _plain_differ(x: EventSequence, y: EventSequence, horizon: float, times: bool) -> bool:
    ex = [i for i in range(len(x.time)) if x.time[i] <= horizon]
    ey = [i for i in range(len(y.time)) if y.time[i] <= horizon]
    if [(x.kind[i], int(x.interval[i])) for i in ex] != [(y.kind[i], int(y.interval[i]))
                                                        for i in ey]:
        return True
    return times and any(not abs(x.time[i] - y.time[i]) <= SLACK for i in ex)


@settings(max_examples=200, deadline=None)
@given(_families(), st.data())
def test_the_table_compares_pairs_as_a_plain_loop(family, data):
    """_Rows.differ / certain / neighbours against the signatures compared event by
    event, and against EventSequence.same_as."""
    runs, horizon = family
    values = list(runs)
    rows = _Rows(runs, horizon, SLACK)
    xs = data.draw(st.lists(st.sampled_from(values), max_size=12))
    ys = data.draw(st.lists(st.sampled_from(values), min_size=len(xs), max_size=len(xs)))
    differ, certain = rows.differ(xs, ys), rows.certain(xs, ys)
    assert differ.tolist() == [_plain_differ(runs[x], runs[y], horizon, True)
                               for x, y in zip(xs, ys)]
    assert certain.tolist() == [_plain_differ(runs[x], runs[y], horizon, False)
                                for x, y in zip(xs, ys)]
    assert differ.tolist() == [not runs[x].same_as(runs[y], horizon, SLACK)
                               for x, y in zip(xs, ys)]
    assert rows.neighbours(values).tolist() == [
        _plain_differ(runs[x], runs[y], horizon, True) for x, y in zip(values, values[1:])]


@settings(max_examples=200, deadline=None)
@given(_families(), st.data())
def test_the_first_difference_is_that_of_a_plain_loop(family, data):
    """Where _classify starts reading two runs: the first event that differs in kind,
    interval or (beyond the slack) time, or the shorter run's end."""
    runs, horizon = family
    a, b = (runs[data.draw(st.sampled_from(list(runs)))] for _ in range(2))
    n = min(len(a.time), len(b.time))
    i = 0
    while i < n and a.kind[i] == b.kind[i] and a.interval[i] == b.interval[i] \
            and abs(a.time[i] - b.time[i]) <= SLACK:
        i += 1
    assert _first_difference(a, b, n, SLACK) == i


@settings(max_examples=200, deadline=None)
@given(_families(), st.lists(st.floats(0.01, 12.0), max_size=30), st.floats(0.005, 0.5),
       st.floats(0.0, 10.0), st.data())
def test_the_crossing_search_is_a_plain_loop(family, outputs, step, center, data):
    """Which impact of which pair of neighbours crosses which output time, in which
    order: the vectorised search against one written with loops (output times among the
    event times too: an impact at an output time crosses nothing)."""
    runs, horizon = family
    points = list(runs)
    times = np.concatenate([runs[x].time for x in points])
    exact = data.draw(st.lists(st.sampled_from(times.tolist()), max_size=4)) if len(times) \
        else []
    outputs = np.unique(np.concatenate([np.arange(step / 3, 12.0, step), outputs, exact]))
    found = _crossing_brackets(_Rows(runs, horizon, SLACK), points, outputs, center)
    plain = []
    for x, y in zip(points, points[1:]):
        if _plain_differ(runs[x], runs[y], horizon, True):
            continue
        d = 0.0 if x <= center <= y else min(abs(x - center), abs(y - center))
        for i in range(len(runs[x].time)):
            if runs[x].time[i] > horizon:
                break
            tx, ty = runs[x].time[i], runs[y].time[i]
            if runs[x].kind[i] != "I":
                continue
            for tj in outputs:
                if min(tx, ty) < tj < max(tx, ty):
                    plain.append((d, x, y, i, float(tj), math.copysign(1.0, tx - tj)))
    plain.sort(key=lambda task: task[0])
    assert list(zip(*(a.tolist() for a in found))) == [task[1:] for task in plain]


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_the_brackets_owed_are_those_of_a_plain_loop(data):
    """The look-ahead's bookkeeping (_owed) against the loop it replaced: nodes grouped by
    the bracket left over that holds them, bare brackets where certain."""
    edges = sorted(set(data.draw(st.lists(st.integers(0, 40), min_size=1, max_size=16))))
    pending = [(0, float(a), float(b)) for a, b in zip(edges, edges[1:])
               if data.draw(st.booleans())]
    pending = data.draw(st.permutations(pending))
    nodes = []
    for _, a, b in pending:
        for _ in range(data.draw(st.integers(0, 2))):
            lo = data.draw(st.floats(a, b))
            nodes.append((lo, data.draw(st.floats(lo, b + 2.0))))
    nodes = data.draw(st.permutations(nodes))
    center, r = data.draw(st.floats(0.0, 40.0)), data.draw(st.floats(0.0, 30.0))

    def sure(x, y):
        return int(x + 3 * y) % 3 != 0

    ahead = (np.array([n[0] for n in nodes], float), np.array([n[1] for n in nodes], float))
    got = _owed(pending, ahead, center, r,
                lambda xs, ys: np.array([sure(x, y) for x, y in zip(xs, ys)], bool))

    def distance(x, y):
        return 0.0 if x <= center <= y else min(abs(x - center), abs(y - center))

    spans = sorted((a, b) for _, a, b in pending if distance(a, b) < r)
    held = {span: [] for span in spans}
    for x, y in nodes:
        inside = [span for span in spans if span[0] <= x]
        if inside and y <= inside[-1][1]:
            held[inside[-1]].append((x, y))
    plain = [node for span, own in held.items()
             for node in (own or ([span] if sure(*span) else []))]
    assert list(zip(*(a.tolist() for a in got))) == plain


class _Model:
    """Runs of a made-up system, in the place of SampledRuns: impact k (1..4) at time
    k + 0.3 p, an extra impact at 4.5 once p passes each of ``extra`` (one per value
    passed), all in impulse interval 0. Its splits are at ``extra``, its output crossings
    where k + 0.3 p is an output time."""

    def __init__(self, extra, t_end):
        self.extra, self.t_end = sorted(extra), t_end
        self.system = SimpleNamespace(oscillator=SimpleNamespace(forcing_period=1.0))
        self._kept = {}

    def _run(self, p):
        times = [k + 0.3 * p for k in range(1, 5)]
        times += [4.5 + 0.01 * m for m, e in enumerate(self.extra) if p > e]
        times = np.sort(times)
        return EventSequence(times, np.full(len(times), 0.5), ("I",) * len(times),
                             np.zeros(len(times), np.int64))

    def ensure(self, values):
        for v in values:
            self._kept.setdefault(float(v), self._run(float(v)))

    def __getitem__(self, value):
        return self._kept[value]

    def values(self, lo, hi):
        return [v for v in self._kept if lo <= v <= hi]


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(0.05, 0.95), min_size=1, max_size=3, unique=True),
       st.sampled_from([17, 33]), st.sampled_from(["nearest", "generation"]))
def test_the_scanner_finds_a_made_up_systems_splits_and_crossings(extra, scan, order):
    """The scanner's steps on a system whose answer is known: each extra impact's
    threshold is a split of kind "extra impact" within tol (where thresholds are further
    apart than the scan's spacing), with the counts on its two sides; each output crossing
    away from the splits is located within tol at (t_j - k) / 0.3."""
    spacing = 1.0 / (scan - 1)
    extra = [e for e in extra if all(e == f or abs(e - f) > 2 * spacing for f in extra)]
    tol, outputs = 1e-9, (np.arange(1, 80) + 0.37) / 16  # none at a scan point
    found = SplitScanner(_Model(extra, 6.0), 0.0, 1.0, 6.0,
                         ScanOptions(scan=scan, tol=tol, order=order, max_crossings=1000),
                         outputs).run()
    assert not found.truncated and found.complete_within == math.inf
    assert [s.kind for s in found.splits] == ["extra impact"] * len(extra)
    for s, e in zip(found.splits, sorted(extra)):
        assert abs(s.value - e) <= tol and s.tol <= tol
        assert s.right == s.left + 1
    truth = sorted((tj - k) / 0.3 for k in range(1, 5) for tj in outputs
                   if 0.0 < (tj - k) / 0.3 < 1.0)
    located = [c.value for c in found.crossings]
    assert all(min(abs(v - t) for t in truth) <= tol for v in located)
    far = [t for t in truth if all(abs(t - e) > spacing for e in extra)]
    assert all(min(abs(v - t) for v in located) <= tol for t in far)
    assert all(abs(c.time - (c.value * 0.3 + round(c.time - 0.3 * c.value))) < 1e-6
               for c in found.crossings)


def test_runs_are_shared_by_a_view_to_another_end(monkeypatch):
    """SampledRuns.until: the same runs, new ones to the view's end; a run kept serves a
    view whose end it reaches, a shorter one is run again."""
    import opa._splits as S

    made = []
    monkeypatch.setattr(S, "event_sequences", lambda system, options, parameter, values,
                        t_end: [made.append((v, t_end)) or EventSequence(
                            np.array([t_end]), np.array([0.0]), ("I",), np.array([0]))
                            for v in values])
    runs = SampledRuns(_osc(0.8), OPTIONS, "mu", 2.0)
    runs.ensure([0.1, 0.2])
    short = runs.until(1.0)
    short.ensure([0.2, 0.3])
    assert made == [(0.1, 2.0), (0.2, 2.0), (0.3, 1.0)]
    assert short.values(0.0, 1.0) == [0.1, 0.2, 0.3] and runs.values(0.0, 1.0) == [0.1, 0.2]
    assert runs.get(0.3) is None and short.get(0.3).time[0] == 1.0
    runs.ensure([0.3])  # too short for the longer view: run again, the longer run kept
    assert made[-1] == (0.3, 2.0) and short.get(0.3).time[0] == 2.0


def test_a_free_flight_minimum_reaching_the_lower_wall_is_a_grazing_split():
    """``x'' = -2 zeta x' - x + f cos(omega t)`` from rest is f times the unit response
    x_1(t) until its first impact, so the first lower-wall impact appears at f_s =
    delta_minus / min x_1 over the horizon: scipy's turning points of x_1 (walls out of
    reach) give it. The scan over f finds there a grazing split (within its tol), one more
    impact on the right, at the time of that minimum, at the lower wall (v- < 0), and
    none without the lower wall (the impacts counted are Events.impacts, either wall)."""
    from tests.impact_truths import two_wall_impacts
    from tests.opa.dynamics.test_sweep import (
        LOWER_OMEGA,
        LOWER_WALL,
        LOWER_ZETA,
        lower_wall_oscillator,
    )

    osc = lower_wall_oscillator()
    horizon = 6.3 * osc.forcing_period
    unit = two_wall_impacts(lambda x, v: -2 * LOWER_ZETA * v - x, 1.0, LOWER_OMEGA,
                            (None, None), (None, None), (0.0, 0.0), horizon, rtol=1e-12,
                            atol=1e-13)
    minima = unit["turn_kind"] == 1
    lowest = int(np.argmin(np.where(minima, unit["turn_x"], np.inf)))
    f_s = LOWER_WALL / unit["turn_x"][lowest]
    options = SolverOptions(rtol=1e-10, atol=1e-10)
    splits, truncated = find_splits(osc, options, "f", 0.8 * f_s, 1.2 * f_s, horizon,
                                    scan=9, tol=1e-9)
    first = min(splits, key=lambda s: s.value)
    assert not truncated and first.kind == "grazing"
    assert abs(first.value - f_s) <= 2e-9
    assert (first.left, first.right) == (0, 1) and first.speed < 0
    assert first.time == pytest.approx(unit["turn_times"][lowest], abs=1e-4)
    one_wall, _ = find_splits(osc.replace(delta_minus=-np.inf), options, "f", 0.8 * f_s,
                              1.2 * f_s, horizon, scan=9, tol=1e-9)
    assert one_wall == []
