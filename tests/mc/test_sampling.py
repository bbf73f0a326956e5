"""Tests for mc._sampling: the semicircle law, its samplers and its Gauss rule (against
the semicircle truths of ``tests/truths.py``, moments and the closed-form Gauss rule)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from mc._sampling import SAMPLERS, gauss_nodes, sample_xi, semicircle_cdf, semicircle_ppf
from tests.truths import semicircle_density, semicircle_gauss_rule, semicircle_moment

SEEDS = (0, 1, 2, 3, 4, 5, 6, 7)


# --- CDF and inverse CDF --------------------------------------------------------------------


def test_cdf_matches_scipy_beta_and_end_points():
    x = np.linspace(-1.0, 1.0, 2001)
    expected = stats.beta(1.5, 1.5, loc=-1.0, scale=2.0).cdf(x)
    np.testing.assert_allclose(semicircle_cdf(x), expected, rtol=0, atol=1e-14)
    assert semicircle_cdf(-1.0) == 0.0
    assert semicircle_cdf(1.0) == 1.0
    assert semicircle_cdf(0.0) == 0.5
    np.testing.assert_array_equal(semicircle_cdf([-3.0, 2.0]), [0.0, 1.0])


def test_cdf_derivative_is_the_density():
    x = np.linspace(-0.95, 0.95, 39)
    h = 1e-6
    slope = (semicircle_cdf(x + h) - semicircle_cdf(x - h)) / (2 * h)
    np.testing.assert_allclose(slope, semicircle_density(x), rtol=1e-8)


def test_ppf_inverts_cdf():
    x = np.linspace(-0.999, 0.999, 20001)
    np.testing.assert_allclose(semicircle_ppf(semicircle_cdf(x)), x, rtol=0, atol=1e-13)
    u = np.linspace(0.0, 1.0, 20001)
    np.testing.assert_allclose(semicircle_cdf(semicircle_ppf(u)), u, rtol=0, atol=1e-15)


def test_ppf_end_points_symmetry_and_monotonicity():
    assert semicircle_ppf(0.0) == -1.0
    assert semicircle_ppf(1.0) == 1.0
    assert semicircle_ppf(0.5) == 0.0
    u = np.linspace(0.0, 1.0, 100001)
    assert np.all(np.diff(semicircle_ppf(u)) >= 0.0)
    lower = np.arange(2**16 + 1) / 2.0**17  # dyadic, so 1 - lower is exact
    np.testing.assert_array_equal(semicircle_ppf(1.0 - lower), -semicircle_ppf(lower))
    tails = semicircle_ppf(np.array([1e-300, 1e-12, 1 - 1e-12]))
    assert -1.0 <= tails[0] < tails[1] < -0.99 and 0.99 < tails[2] < 1.0


@pytest.mark.parametrize("bad", [-0.1, 1.5, np.nan])
def test_ppf_rejects_probabilities_outside_unit_interval(bad):
    with pytest.raises(ValueError, match=r"u must be in \[0, 1\], got"):
        semicircle_ppf([0.2, bad])


# --- Monte Carlo and quasi-Monte Carlo samplers ---------------------------------------------


@pytest.mark.parametrize("seed", SEEDS[:4])
@pytest.mark.parametrize("k", [1, 2, 3, 4])
def test_random_moments_within_four_standard_errors(seed, k):
    samples = 20_000
    xi, weights = sample_xi("random", samples, seed)
    estimate = weights @ xi**k
    std = np.sqrt(semicircle_moment(2 * k) - semicircle_moment(k) ** 2)
    assert abs(estimate - semicircle_moment(k)) < 4 * std / np.sqrt(samples)


@pytest.mark.parametrize("sampler", ["random", "sobol"])
def test_kolmogorov_smirnov_against_semicircle(sampler):
    xi, weights = sample_xi(sampler, 4096, seed=11)
    assert np.all((xi >= -1.0) & (xi <= 1.0))
    np.testing.assert_array_equal(weights, np.full(4096, 1 / 4096))
    assert stats.kstest(xi, semicircle_cdf).pvalue > 1e-3


def _rms_moment_error(sampler: str, samples: int, k: int) -> float:
    errors = []
    for seed in SEEDS:
        xi, weights = sample_xi(sampler, samples, seed)
        errors.append(weights @ xi**k - semicircle_moment(k))
    return float(np.sqrt(np.mean(np.square(errors))))


@pytest.mark.parametrize("k", [2, 4])
def test_sobol_beats_random_at_equal_samples(k):
    random_error = _rms_moment_error("random", 1024, k)
    sobol_error = _rms_moment_error("sobol", 1024, k)
    assert sobol_error < random_error / 20


def test_random_error_decays_like_inverse_square_root():
    sizes = 2 ** np.arange(6, 15, 2)
    errors = [_rms_moment_error("random", int(m), 2) for m in sizes]
    slope = np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    assert -0.8 < slope < -0.3


def test_sobol_error_decays_faster_than_random():
    sizes = 2 ** np.arange(6, 15, 2)
    errors = [_rms_moment_error("sobol", int(m), 2) for m in sizes]
    slope = np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    assert slope < -0.8


def test_sobol_accepts_sizes_that_are_not_powers_of_two():
    xi, weights = sample_xi("sobol", 1000, seed=5)
    assert xi.shape == weights.shape == (1000,)
    reference, _ = sample_xi("sobol", 1024, seed=5)
    np.testing.assert_array_equal(xi, reference[:1000])


@pytest.mark.parametrize("sampler", ["random", "sobol"])
def test_same_seed_same_points(sampler):
    first = sample_xi(sampler, 257, seed=42)
    second = sample_xi(sampler, 257, seed=42)
    np.testing.assert_array_equal(first[0], second[0])
    np.testing.assert_array_equal(first[1], second[1])
    assert not np.array_equal(first[0], sample_xi(sampler, 257, seed=43)[0])


def test_seed_none_draws_fresh_points():
    xi, weights = sample_xi("random", 16, None)
    assert xi.shape == weights.shape == (16,)


# --- Gauss rule -----------------------------------------------------------------------------


@pytest.mark.parametrize("order", range(1, 13))
def test_gauss_exact_up_to_degree_2q_minus_1(order):
    xi, weights = sample_xi("gauss", order, seed=None)
    assert np.all(np.diff(xi) > 0)
    assert weights.sum() == pytest.approx(1.0, abs=1e-15)
    for degree in range(2 * order):
        assert abs(weights @ xi**degree - semicircle_moment(degree)) < 1e-13
    # xi^(2Q) = pi_Q^2 + lower degree, pi_Q = U_Q / 2^Q monic and zero at the nodes,
    # so the rule misses exactly E[pi_Q^2] = 4^-Q.
    miss = semicircle_moment(2 * order) - weights @ xi ** (2 * order)
    assert miss == pytest.approx(4.0**-order, rel=1e-10)


def test_gauss_nodes_formula_and_symmetry():
    order = 7
    xi, weights = gauss_nodes(order)
    nodes, expected = semicircle_gauss_rule(order)
    np.testing.assert_allclose(xi, nodes, atol=1e-15)
    np.testing.assert_allclose(weights, expected, atol=1e-15)
    np.testing.assert_array_equal(xi, -xi[::-1])
    assert xi[order // 2] == 0.0
    assert sample_xi("gauss", order, seed=1)[0].tolist() == xi.tolist()


def test_gauss_orthonormalises_chebyshev_u():
    order = 6
    xi, weights = gauss_nodes(order)
    # U_0..U_5 by the three-term rule xi U_i = (U_{i+1} + U_{i-1}) / 2.
    basis = [np.ones_like(xi), 2 * xi]
    while len(basis) < order:
        basis.append(2 * xi * basis[-1] - basis[-2])
    gram = np.array(basis) * weights @ np.array(basis).T
    np.testing.assert_allclose(gram, np.eye(order), atol=1e-13)


# --- Validation -----------------------------------------------------------------------------


def test_sampler_names():
    assert SAMPLERS == ("random", "sobol", "gauss")


def test_unknown_sampler():
    with pytest.raises(
        ValueError, match="sampler must be one of 'random', 'sobol', 'gauss', got 'xyz'"
    ):
        sample_xi("xyz", 10, 0)


@pytest.mark.parametrize("samples", [0, -3, 2.5, "10", True, None])
def test_bad_samples(samples):
    with pytest.raises(ValueError, match=f"samples must be a positive integer, got {samples!r}"):
        sample_xi("random", samples, 0)


@pytest.mark.parametrize("seed", [-1, 1.5, "7", False])
def test_bad_seed(seed):
    with pytest.raises(
        ValueError, match=f"seed must be a non-negative integer or None, got {seed!r}"
    ):
        sample_xi("sobol", 8, seed)


def test_numpy_integers_are_accepted():
    xi, _ = sample_xi("sobol", np.int64(8), np.uint32(3))
    np.testing.assert_array_equal(xi, sample_xi("sobol", 8, 3)[0])
