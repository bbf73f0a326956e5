"""Pick-freeze Sobol indices with standard errors and a surrogate control variate
(compare._sobol), calibrated on Ishigami's function: 200 independent runs at once (the
replicates ride along as an output axis), and the 95 % intervals must cover the exact
indices at the nominal rate, within binomial limits, with and without the control
variate."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import stats

from compare._sobol import (
    IndexEstimate, SobolEstimate, pick_freeze_design, pick_freeze_indices,
    surrogate_agreement,
)
from opa._sensitivity import sobol_indices
from tests.opa.test_sensitivity import (
    evaluate_expansion, ishigami, ishigami_truth, tensor_projection,
)

#: replicates and rows per replicate of the calibration runs
REPLICATES, ROWS = 200, 1000
#: the control variate's surrogate: a Gauss-Legendre tensor projection (8 x 9 x 5 points)
CONTROL_DEGREES = (7, 8, 4)


def binomial_limits(p: float, n: int = REPLICATES, level: float = 0.999) -> tuple[float, float]:
    """The central ``level`` range of the share of successes among ``n`` at rate ``p``."""
    low, high = stats.binom.interval(level, n, p)
    return low / n, high / n


class Surrogate:
    """An expansion of Ishigami's function: its values anywhere and its exact indices."""

    def __init__(self, degrees):
        self.degrees = degrees
        self.coefficients, self.indices = tensor_projection(ishigami, degrees)
        self.exact = sobol_indices(self.coefficients, self.indices)

    def __call__(self, xi):
        return evaluate_expansion(self.coefficients, self.indices, self.degrees, xi)

    def exact_for(self, shape):
        """The exact indices broadcast to outputs of ``shape``."""
        first, total, variance = self.exact
        extra = (None,) * len(shape)
        return (np.broadcast_to(first[(...,) + extra], first.shape + shape),
                np.broadcast_to(total[(...,) + extra], total.shape + shape),
                np.broadcast_to(variance, shape))


def pick_freeze_runs(f, rows, shape, seed, surrogate=None):
    """``f`` on A, B and the A_B^(i) of ``rows`` x ``shape`` uniform points of [-1, 1]^3
    (``shape``: the replicates), with the surrogate's values on the same points."""
    rng = np.random.default_rng(seed)
    a, b = rng.uniform(-1, 1, (2, rows) + shape + (3,))
    ab = np.stack([np.where(np.arange(3) == i, b, a) for i in range(3)])
    values = (f(a), f(b), f(ab))
    if surrogate is None:
        return values, None
    return values, (surrogate(a), surrogate(b), surrogate(ab))


@pytest.fixture(scope="module")
def calibration():
    """200 replicates of Ishigami's pick-freeze indices, plain and controlled."""
    control = Surrogate(CONTROL_DEGREES)
    values, controls = pick_freeze_runs(ishigami, ROWS, (REPLICATES,), 2024, control)
    plain = pick_freeze_indices(*values)
    controlled = pick_freeze_indices(*values, surrogate=controls,
                                     exact=control.exact_for((REPLICATES,)))
    return plain, controlled, control


def test_the_design_takes_one_column_from_b():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 5, 4))
    design = pick_freeze_design(a, b)
    assert design.shape == (4, 5, 4)
    for i in range(4):
        np.testing.assert_array_equal(design[i][:, i], b[:, i])
        others = [k for k in range(4) if k != i]
        np.testing.assert_array_equal(design[i][:, others], a[:, others])
    with pytest.raises(ValueError, match="sample_b must have the shape"):
        pick_freeze_design(a, b[:3])
    with pytest.raises(ValueError, match=r"shape \(M, d\)"):
        pick_freeze_design(a[0], b[0])


@pytest.mark.parametrize("controlled", [False, True], ids=["plain", "control variate"])
def test_the_intervals_cover_ishigami_at_the_nominal_rate(calibration, controlled):
    """Each of the six indices: the share of 200 runs whose 95 % interval holds the exact
    value lies within the 99.9 % binomial range of a 0.95 rate, [0.895, 0.99] (measured:
    0.925-0.975 plain, 0.935-0.98 controlled)."""
    first, total, _ = ishigami_truth()
    estimate = calibration[1] if controlled else calibration[0]
    low, high = binomial_limits(0.95)
    covered = np.concatenate([estimate.first.contains(first[:, None]).mean(axis=1),
                              estimate.total.contains(total[:, None]).mean(axis=1)])
    assert np.all((covered >= low) & (covered <= high)), covered
    # the same for the raw intervals estimate +- 1.96 SE: the standard errors are right
    for index, exact in ((estimate.first, first), (estimate.total, total)):
        raw = np.abs(index.estimate - exact[:, None]) <= 1.96 * index.standard_error
        assert np.all((raw.mean(axis=1) >= low) & (raw.mean(axis=1) <= high))


def test_the_control_variate_shrinks_the_standard_errors(calibration):
    """With an 8 x 9 x 5-point surrogate (indices 2e-3 off) the standard errors shrink
    more than twentyfold (measured 32-97 fold) for every index, the variance's 43 fold."""
    plain, controlled, control = calibration
    assert np.abs(control.exact.total - ishigami_truth()[1]).max() < 3e-3
    for kind in ("first", "total"):
        ratio = (getattr(plain, kind).standard_error.mean(axis=1)
                 / getattr(controlled, kind).standard_error.mean(axis=1))
        assert np.all(ratio > 20), (kind, ratio)
    assert np.all(controlled.variance_se < plain.variance_se / 5)
    assert controlled.control and not plain.control and plain.samples == ROWS


@pytest.mark.parametrize("controlled", [False, True], ids=["plain", "control variate"])
def test_a_zero_index_is_within_noise_and_never_negative(calibration, controlled):
    """S3 = 0: "within noise" in all but the one-sided 2.5 % of runs (binomial range),
    its reported interval [0, upper] never below 0, its value never a negative number;
    the half of the raw estimates that are negative are reported as intervals."""
    estimate = (calibration[1] if controlled else calibration[0]).first
    reading = estimate.reading[2]
    assert np.mean(reading == "within noise") >= binomial_limits(0.975)[0]
    assert set(reading) <= {"within noise", "resolved"}
    assert np.any(estimate.estimate[2] < 0)
    low, high = estimate.interval
    assert np.all(low >= 0) and np.all(high >= 0)
    noise = reading == "within noise"
    assert np.all(np.isnan(estimate.value[2][noise]))
    assert np.all(low[2][noise] == 0) and np.all(estimate.value[2][~noise] > 0)
    # S1, S2 and every total index are resolved in every run
    assert np.all(estimate.reading[:2] == "resolved")


def test_a_pure_interaction_has_no_first_order_index():
    """f = xi1 xi2 on U(-1, 1)^2: S1 = S2 = 0 and ST1 = ST2 = 1. The first-order
    indices are within noise (binomial range of 0.975), the totals resolved, in 200
    runs of 500 rows."""
    rng = np.random.default_rng(7)
    a, b = rng.uniform(-1, 1, (2, 500, REPLICATES, 2))
    ab = np.stack([np.where(np.arange(2) == i, b, a) for i in range(2)])
    est = pick_freeze_indices(a[..., 0] * a[..., 1], b[..., 0] * b[..., 1],
                              ab[..., 0] * ab[..., 1])
    assert np.all(np.mean(est.first.reading == "within noise", axis=1)
                  >= binomial_limits(0.975)[0])
    assert np.all(est.total.reading == "resolved")
    low, high = binomial_limits(0.95)
    covered = est.total.contains(np.ones((2, 1))).mean(axis=1)
    assert np.all((covered >= low) & (covered <= high)), covered
    assert np.all(est.first.interval[0] >= 0)


def test_outputs_over_time_and_a_constant_output():
    """f(t) = t xi1 + t^2 xi2 + t xi1 xi3 over t = 0, ..., 1: at t = 0 the output is
    constant and every index is undefined (NaN, no warning); elsewhere the indices follow
    V_1 = t^2/3, V_2 = t^4/3, V_13 = t^2/9 within their intervals."""
    t = np.linspace(0.0, 1.0, 6)
    rng = np.random.default_rng(5)
    a, b = rng.uniform(-1, 1, (2, 4000, 3))
    ab = pick_freeze_design(a, b)

    def f(xi):
        xi = xi[..., None]
        return t * xi[..., 0, :] + t ** 2 * xi[..., 1, :] + t * xi[..., 0, :] * xi[..., 2, :]

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        est = pick_freeze_indices(f(a), f(b), f(ab))
    assert est.first.estimate.shape == (3, 6) and est.variance.shape == (6,)
    assert np.all(est.first.reading[:, 0] == "undefined")
    assert np.all(np.isnan(est.first.estimate[:, 0]))
    assert np.all(np.isnan(est.total.interval[0][:, 0]))
    v1, v2, v13 = t[1:] ** 2 / 3, t[1:] ** 4 / 3, t[1:] ** 2 / 9
    variance = v1 + v2 + v13
    unknown = np.full((3, 1), np.nan)  # t = 0
    first = np.hstack([unknown, np.stack([v1, v2, 0 * v1]) / variance])
    total = np.hstack([unknown, np.stack([v1 + v13, v2, v13]) / variance])
    # 30 intervals: allow the one or two misses of a 95 % rate
    inside = np.concatenate([est.first.contains(first)[:, 1:],
                             est.total.contains(total)[:, 1:]])
    assert inside.mean() >= 0.85
    assert surrogate_agreement(est, first, total) >= 0.6


def test_a_surrogate_is_certified_or_refused(calibration):
    """The agreement helper: Ishigami's exact indices (a 20^3-point surrogate) lie in
    every interval of most controlled runs; a coarse 4 x 5 x 5-point surrogate (indices
    0.12 off), used as its own control variate, lies in none."""
    plain, controlled, _ = calibration
    first, total, _ = ishigami_truth()
    fine = Surrogate((19, 19, 19))
    np.testing.assert_allclose(fine.exact.total, total, atol=1e-10)
    shape = (REPLICATES,)
    for estimate in (plain, controlled):
        share = surrogate_agreement(estimate, *fine.exact_for(shape)[:2])
        assert share >= 0.6, share  # all six at once: ~0.95^6 if they were independent
    coarse = Surrogate((3, 4, 4))
    values, controls = pick_freeze_runs(ishigami, ROWS, (20,), 99, coarse)
    refused = pick_freeze_indices(*values, surrogate=controls, exact=coarse.exact_for((20,)))
    assert surrogate_agreement(refused, *coarse.exact_for((20,))[:2]) == 0.0
    assert surrogate_agreement(refused, *fine.exact_for((20,))[:2]) >= 0.5


def test_the_readings_follow_the_rule():
    index = IndexEstimate(np.array([0.5, 0.05, -0.02, np.nan, -0.5]),
                          np.array([0.1, 0.05, 0.05, 0.1, 0.1]))
    assert index.reading.tolist() == ["resolved", "within noise", "within noise",
                                      "undefined", "within noise"]
    low, high = index.interval
    np.testing.assert_allclose(low, [0.5 - 0.196, 0, 0, np.nan, 0])
    np.testing.assert_allclose(high, [0.5 + 0.196, 0.148, 0.078, np.nan, 0])
    np.testing.assert_allclose(index.value, [0.5, np.nan, np.nan, np.nan, np.nan])
    wide = IndexEstimate(index.estimate, index.standard_error, z=3.0)
    assert wide.reading[0] == "resolved" and wide.reading[1] == "within noise"
    with pytest.raises(ValueError, match="z must be"):
        IndexEstimate(index.estimate, index.standard_error, z=-1.0)
    with pytest.raises(ValueError, match="share a shape"):
        IndexEstimate(index.estimate, index.standard_error[:2])


def test_bad_inputs_are_refused_by_name():
    rng = np.random.default_rng(1)
    f_a, f_b, f_ab = rng.normal(size=(10, 4)), rng.normal(size=(10, 4)), rng.normal(size=(2, 10, 4))
    exact = (np.zeros((2, 4)), np.zeros((2, 4)), np.ones(4))
    with pytest.raises(ValueError, match="f_ab must have shape"):
        pick_freeze_indices(f_a, f_b, f_ab[:, :5])
    with pytest.raises(ValueError, match="f_b must have the shape"):
        pick_freeze_indices(f_a, f_b[:, :3], f_ab)
    with pytest.raises(ValueError, match="finite"):
        pick_freeze_indices(np.where(f_a > 1, np.nan, f_a), f_b, f_ab)
    with pytest.raises(ValueError, match="needs both"):
        pick_freeze_indices(f_a, f_b, f_ab, surrogate=(f_a, f_b, f_ab))
    with pytest.raises(ValueError, match="exact indices must have shape"):
        pick_freeze_indices(f_a, f_b, f_ab, surrogate=(f_a, f_b, f_ab),
                            exact=(np.zeros(2), np.zeros(2), np.ones(4)))
    with pytest.raises(ValueError, match="g_ab must have shape"):
        pick_freeze_indices(f_a, f_b, f_ab, surrogate=(f_a, f_b, f_ab[:1, :5]), exact=exact)
    est = pick_freeze_indices(f_a, f_b, f_ab)
    with pytest.raises(ValueError, match="first and total must have shape"):
        surrogate_agreement(est, np.zeros(2), np.zeros(2))
    assert isinstance(est, SobolEstimate)
