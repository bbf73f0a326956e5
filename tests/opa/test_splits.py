"""The split detector against a grazing established with the scipy reference alone
(tests/reference_splits.py), and its classification on constructed event sequences."""

import numpy as np
import pytest

from opa import Oscillator, SolverOptions
from opa._splits import EventSequence, _classify, event_sequence, find_splits
from tests.reference_splits import GRAZING_CASE, SAFE_OFFSET, impact_count

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
