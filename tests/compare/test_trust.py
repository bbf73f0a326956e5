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
)
from compare._trustmap import count_distribution
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
