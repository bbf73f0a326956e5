"""The verdict criterion and the sigma* bisection on synthetic error models with known
answers."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from compare._trust import (
    bisect_boundary,
    excess,
    first_disagreement,
    marginal,
    running_rms,
    window_errors,
    window_errors_all,
)
from compare._mapdata import count_distribution
from opa._splits import Split
from tests.truths import semicircle_mass


def test_running_rms_by_hand():
    np.testing.assert_allclose(running_rms([3.0, 4.0, 0.0]),
                               [3.0, math.sqrt(12.5), math.sqrt(25 / 3)])
    np.testing.assert_allclose(running_rms(np.full(5, -2.0)), 2.0)


def test_first_disagreement_of_a_linear_drift():
    """err = 0.01 t against a constant spread 1 and tol 0.1: the running RMS of a ramp on
    t = 0, dt, ..., is 0.01 sqrt(mean of t^2); it passes 0.1 where mean(t^2) = 100."""
    t = np.arange(0, 40.0, 0.25)
    err = 0.01 * t
    got = first_disagreement(t, err, np.ones_like(t), np.zeros_like(t), tol=0.1, z=0.0,
                             floor=0.0)
    k = np.arange(1, len(t) + 1)
    expected = t[np.flatnonzero(np.cumsum(t**2) / k > 100.0)[0]]
    assert got == expected
    assert 17.25 <= got <= 17.5  # continuous version: t^2 / 3 = 100, t = 17.32
    assert first_disagreement(t, 0 * t, np.ones_like(t), np.zeros_like(t), tol=0.1, z=0,
                              floor=0) == math.inf


def test_standard_errors_and_floor_widen_the_band():
    err = np.full(10, 1.0)
    scale = np.full(10, 5.0)
    sem = np.full(10, 0.2)
    np.testing.assert_allclose(excess(err, scale, sem, tol=0.1, z=0.0), 0.5)  # 1 - 0.5
    np.testing.assert_allclose(excess(err, scale, sem, tol=0.1, z=3.0), -0.1)  # - 0.6
    np.testing.assert_allclose(excess(err, scale, sem, tol=0.1, z=0.0, floor=0.6), -0.1)
    # NaN standard errors (Gauss collocation) count as zero
    assert np.isfinite(excess(err, scale, np.full(10, np.nan), tol=0.1)).all()


def test_marginal_means_the_verdict_hangs_on_the_noise():
    scale = np.ones(8)
    sem = np.full(8, 0.01)
    # error 0.12: fails without noise allowance (0.1), passes with 2 x 3 SE (0.16)
    assert marginal(np.full(8, 0.12), scale, sem, tol=0.1, z=3.0, floor=0.0, upto=8)
    assert not marginal(np.full(8, 0.5), scale, sem, tol=0.1, z=3.0, floor=0.0, upto=8)
    assert not marginal(np.full(8, 0.05), scale, sem, tol=0.1, z=3.0, floor=0.0, upto=8)


def test_window_errors_are_absolute_in_se_and_relative():
    err = np.array([0.0, 3.0, 4.0, 100.0])
    scale = np.array([1.0, 1.0, 1.0, 1.0])
    sem = np.array([0.5, 0.5, 0.5, 0.5])
    rms, in_se, rel = window_errors(err, scale, sem, upto=3)
    assert rms == pytest.approx(math.sqrt(25 / 3))
    assert in_se == pytest.approx(rms / 0.5)
    assert rel == pytest.approx(rms)


# -- the sigma* bisection on an error model with a known boundary ------------------------
def _model(boundary, tol=0.1):
    """Relative error growing like (s / s_b)^2 tol below a jump at s_b; above, 10 tol."""
    def agrees(s):
        return (s / boundary) ** 2 * tol * 0.99 <= tol if s < boundary else False
    return agrees


@pytest.mark.parametrize("boundary", [0.0123, 0.02244, 0.0399])
def test_bisection_converges_on_a_known_boundary(boundary):
    calls = []
    agrees = _model(boundary)

    def probe(s):
        calls.append(s)
        return agrees(s)

    lo, hi, steps = bisect_boundary(probe, 0.005, 0.05, 1e-4)
    assert lo < boundary <= hi
    assert hi - lo <= 1e-4
    assert steps == len(calls) == math.ceil(math.log2(0.045 / 1e-4))


@settings(max_examples=60, deadline=None)
@given(boundary=st.floats(0.0011, 0.0499), res=st.floats(1e-6, 1e-3))
def test_bisection_brackets_any_boundary(boundary, res):
    lo, hi, _ = bisect_boundary(lambda s: s < boundary, 0.001, 0.05, res)
    assert lo < boundary <= hi and hi - lo <= res


def test_bisection_rejects_bad_brackets():
    with pytest.raises(ValueError, match="lo < hi"):
        bisect_boundary(lambda s: True, 0.02, 0.01, 1e-3)
    with pytest.raises(ValueError, match="resolution"):
        bisect_boundary(lambda s: True, 0.01, 0.02, 0.0)


# -- impact-count distributions from located splits --------------------------------------
def test_count_distribution_is_the_semicircle_mass_between_splits():
    centre, sigma = 0.8, 0.05
    splits = [Split(0.78, 1e-9, "grazing", 5.0, 1e-5, 4, 3),
              Split(0.81, 1e-9, "extra impact", 7.0, 0.2, 3, 5)]
    got = count_distribution(centre, sigma, splits, count_at_centre=3)
    assert got[4] == pytest.approx(semicircle_mass(-1, -0.4), abs=1e-12)
    assert got[3] == pytest.approx(semicircle_mass(-0.4, 0.2), abs=1e-12)
    assert got[5] == pytest.approx(semicircle_mass(0.2, 1), abs=1e-12)
    assert sum(got.values()) == pytest.approx(1.0, abs=1e-14)
    # a sigma that does not reach either split: every sample makes the centre's count
    assert count_distribution(centre, 0.01, splits, count_at_centre=3) == {3: 1.0}


# -- the causes in words: output crossings, the split limit (issue 24) --------------------
def _map(kinds, values, times, *, star=(0.0215, 0.0219), disagree=9.75, complete=np.inf,
         unknown=0.0):
    """A one-point map dataset (omega = 4.09, 10 periods, N = 8, mean/galerkin) with the
    given split arrays; OPA fails first at sigma = 0.025 at t = ``disagree`` periods."""
    import xarray as xr

    from opa._splits import SPLIT_KINDS

    n = max(1, len(kinds))
    sigma = np.array([0.005, 0.01, 0.014, 0.02, 0.025, 0.03, 0.04, 0.05])
    agrees = np.zeros((1, 8, 1, 1, 1, 2), np.int8)
    agrees[0, :4] = 1
    disagree_time = np.full((1, 8, 1, 1, 2), np.inf)
    disagree_time[0, 4:] = disagree
    kind = np.full((1, 1, n), -1, np.int8)
    kind[0, 0, : len(kinds)] = [SPLIT_KINDS.index(k) for k in kinds]
    pad = lambda a, fill: np.array(list(a) + [fill] * (n - len(a)), float)[None, None]  # noqa: E731
    count_prob = np.zeros((1, 8, 1, 6))
    count_prob[0, :, 0, 4] = 1.0 - unknown
    flags = {"flag_values": np.arange(len(SPLIT_KINDS), dtype=np.int8),
             "flag_meanings": " ".join(k.replace(" ", "_") for k in SPLIT_KINDS)}
    return xr.Dataset(
        {"sigma_star": (("omega", "variant", "horizon", "criterion"),
                        np.full((1, 1, 1, 2), star[0])),
         "sigma_star_upper": (("omega", "variant", "horizon", "criterion"),
                              np.full((1, 1, 1, 2), star[1])),
         "agrees": (("omega", "sigma", "variant", "N", "horizon", "criterion"), agrees),
         "disagree_time": (("omega", "sigma", "variant", "N", "criterion"), disagree_time),
         "split_value": (("omega", "horizon", "split"), pad(values, np.nan)),
         "split_kind": (("omega", "horizon", "split"), kind, flags),
         "split_time": (("omega", "horizon", "split"), pad(times, np.nan)),
         "split_speed": (("omega", "horizon", "split"), pad([0.64] * len(kinds), np.nan)),
         "split_left": (("omega", "horizon", "split"), pad([4] * len(kinds), -1).astype(int)),
         "split_right": (("omega", "horizon", "split"), pad([4] * len(kinds), -1).astype(int)),
         "split_truncated": (("omega", "horizon"), np.array([[int(complete < np.inf)]])),
         "split_complete_sigma": (("omega", "horizon"), np.array([[complete]])),
         "crossing_complete_sigma": (("omega", "horizon"), np.array([[complete]])),
         "count_prob": (("omega", "sigma", "horizon", "count"), count_prob),
         "count_unknown": (("omega", "sigma", "horizon"), np.full((1, 8, 1), unknown))},
        coords={"omega": [4.09], "sigma": sigma, "variant": ["mean/galerkin"],
                "N": [8], "horizon": [10.0], "criterion": ["mean", "variance"]},
        attrs={"parameter": "omega", "uncertain": "mu", "mu": 0.8, "resolution": 1e-3,
               "per_period": 8})


def test_the_cause_at_4_09_is_an_impact_crossing_the_output_where_opa_fails():
    from compare._findings import cause

    ds = _map(["output crossing", "output crossing"], [0.8019001, 0.8346],
              [9.75, 7.0])
    text = cause(ds, 0, 0)
    assert "comes before any split" in text and "an impact crosses an output time" in text
    assert "μ = 0.8019001" in text and "t = 9.75 periods" in text
    assert "σ ≥ 0.0019" in text and "kink in ξ" in text
    # OPA failing at another output: the crossing is not named as the cause
    other = cause(_map(["output crossing"], [0.8019001], [9.75], disagree=8.5), 0, 0)
    assert "crosses an output" not in other and "OPA's own" in other
    # a crossing outside the failing ensemble (sigma = 0.025) is not the cause either
    far = cause(_map(["output crossing"], [0.8346], [9.75]), 0, 0)
    assert "crosses an output" not in far


def test_a_grazing_at_the_boundary_is_continuous_with_a_square_root():
    from compare._findings import cause

    ds = _map(["grazing"], [0.777563], [5.57], star=(0.0225, 0.0231))
    ds["split_left"][:] = 5
    text = cause(ds, 0, 0)
    assert "sits at the first split" in text and "jumps" not in text
    assert "continuous in ξ" in text and "square root" in text


def test_a_reached_split_limit_is_said_and_the_counts_marked_incomplete():
    from compare._findings import cause
    from compare._tables import boundary_table, count_table

    ds = _map([], [], [], complete=0.0042, unknown=0.3)
    text = cause(ds, 0, 0)
    assert "limit of splits cut the list short" in text and "< 0.0042" in text
    assert "≤ 0.05" not in text
    assert "cut by the limit" in boundary_table(ds)
    table = count_table(ds, 0)
    assert "INCOMPLETE: 0.3 of the samples" in table


def test_a_horizon_split_in_the_grid_is_named_even_below_sigma_star():
    """omega = 4.035 (10 periods): sigma* < 0.000625, yet the count table at sigma = 0.005
    shows an extra impact: a "horizon" split (an impact sliding across the end) at
    sigma >= 0.0045. The cause must name it, not say every sample makes the same impacts."""
    from compare._findings import cause

    ds = _map(["horizon"], [0.7955337], [10.0], star=(0.0, 0.000625), disagree=7.38)
    ds["split_right"][:] = 5
    text = cause(ds, 0, 0)
    assert "every sample makes the same impacts" not in text
    assert "one more impact within 1e-4 time units of the horizon's end" in text
    assert "σ ≥ 0.0045" in text and "4 → 5 impacts" in text


def test_window_errors_of_many_curves_are_those_of_each_curve():
    rng = np.random.default_rng(2)
    err = rng.normal(size=(3, 4, 20))
    sem = np.abs(rng.normal(size=(3, 4, 20)))
    err[0, 1, 5:] = np.nan  # a run that stopped
    sem[1, 2, 3] = np.nan  # an unknown standard error
    sem[2, 3] = 0.0  # no noise at all
    err[2, 0] = 0.0
    for scale in (np.abs(rng.normal(size=20)), np.zeros(20)):
        for upto in (1, 7, 20):
            got = window_errors_all(err, scale, sem, upto)
            for idx in np.ndindex(3, 4):
                np.testing.assert_allclose(got[idx], window_errors(err[idx], scale, sem[idx],
                                                                   upto), rtol=1e-12)
