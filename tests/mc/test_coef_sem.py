"""Standard errors of the Monte Carlo coefficient estimates, x_coef_sem (issue 15).

Is the reported standard error the actual spread of the estimate? Checked against truths
that owe nothing to the code under test:

* at t = 0 every sample sits at x0, so E[x U_i(xi)] = x0 E[U_i] = x0 [i == 0] exactly;
* along a trajectory, in the smooth regime of section 3.2 (sigma = 0.05, 5 periods: every
  sample has the same two impacts), a 32-node Gauss collocation at rtol 1e-11 (converged
  to round-off, see tests/mc/test_ensemble.py).

Over many independent seeds the z-score (estimate - truth) / x_coef_sem must have RMS ~ 1:
for ``random`` a t-statistic with M - 1 = 255 degrees of freedom (E z^2 = 1.008), for
``sobol`` with R = 16 replicates one with R - 1 = 15 (E z^2 = 15/13, RMS 1.074, and heavier
tails). Measured on the 2-core development container (printed with ``-s``), RMS z per
order i = 1..4 over 200 seeds at t = 0: random 1.02-1.04 (|z| > 3 in 0.3 %), random
with a uniform law 0.95-1.06, sobol 1.00-1.07; along the trajectory (i = 0..4) random
1.02-1.04, sobol 1.00-1.07. The SD of an RMS over 200 seeds is ~0.05 (random) and ~0.06
(t_15), so the bands [0.8, 1.2] and [0.75, 1.4] leave about 4 of them. In this regime
x(t, xi) is nearly x_mean(t), so the trajectory's z-scores follow those at t = 0; they
check the SE against an independent truth at every output time.
"""

from __future__ import annotations

import numpy as np
import pytest

import mc
import opa

SECTION_32 = opa.preset("3.2", omega=3.98)
SIGMA = 0.05
M = 256
ORDER = 4
START = dict(sigma=SIGMA, samples=M, order=ORDER, periods=0.1, per_period=10, progress=False)
SMOOTH = dict(sigma=SIGMA, samples=M, order=ORDER, periods=5, per_period=4, progress=False,
              options=opa.SolverOptions(rtol=1e-9, atol=1e-9))  # fmt: skip


def rms(values, axis=None):
    return np.sqrt(np.mean(np.square(values), axis=axis))


def start_z_scores(sampler: str, seeds: int, **kwargs) -> np.ndarray:
    """(seeds, ORDER) z-scores of x_coef[i](0) for i = 1..ORDER, whose truth is 0."""
    z = []
    for seed in range(seeds):
        ds = mc.simulate_mc(SECTION_32, sampler=sampler, seed=seed, **START, **kwargs)
        coef, sem = ds.x_coef.values[:, 0], ds.x_coef_sem.values[:, 0]
        assert coef[0] == pytest.approx(SECTION_32.x0, rel=1e-14) and sem[0] < 1e-14
        z.append(coef[1:] / sem[1:])
    return np.array(z)


def test_coefficient_sem_matches_the_spread_at_t0_random():
    """200 seeds of 256 random samples: x_coef[i](0) = x0 mean(U_i(xi)) against the truth
    0, per order i = 1..4; RMS z-score in [0.8, 1.2] (expected 1.004, sd ~0.05)."""
    z = start_z_scores("random", 200)
    per_order = rms(z, axis=0)
    print(f"\nrandom, t = 0: RMS z per order {np.round(per_order, 3)}, "
          f"|z| > 3 in {np.mean(np.abs(z) > 3):.3f} of the estimates")
    assert np.all((0.8 < per_order) & (per_order < 1.2)), per_order
    assert np.mean(np.abs(z) > 3) < 0.02  # 0.003 for a normal, 0.003 for t_255


def test_coefficient_sem_matches_the_spread_at_t0_for_another_law():
    """xi uniform on [-1, 1]: the coefficients are E[x p_i(xi)] with the law's orthonormal
    (Legendre) polynomials, p_0 = 1; the same check, 200 seeds of 256 random samples."""
    per_order = rms(start_z_scores("random", 200, distribution="uniform"), axis=0)
    print(f"\nrandom, uniform law, t = 0: RMS z per order {np.round(per_order, 3)}")
    assert np.all((0.8 < per_order) & (per_order < 1.2)), per_order


def test_coefficient_sem_matches_the_spread_at_t0_sobol_replicates():
    """The same with scrambled Sobol' points in 16 replicates of 16: the SE is the spread
    of the 16 replicate estimates / 4, a t-statistic with 15 degrees of freedom (RMS z
    1.074); the randomised-QMC error is far below the random one."""
    z = start_z_scores("sobol", 200)
    per_order = rms(z, axis=0)
    ds = mc.simulate_mc(SECTION_32, sampler="sobol", seed=0, **START)
    assert ds.attrs["replicates"] == 16
    print(f"\nsobol (16 replicates), t = 0: RMS z per order {np.round(per_order, 3)}")
    assert np.all((0.75 < per_order) & (per_order < 1.4)), per_order


@pytest.fixture(scope="module")
def smooth_truth():
    """E[x U_i(xi)](t) in the smooth regime: 32-node Gauss collocation at rtol 1e-11."""
    tight = opa.SolverOptions(rtol=1e-11, atol=1e-11)
    return mc.simulate_mc(SECTION_32, sampler="gauss", **{**SMOOTH, "samples": 32,
                                                          "options": tight})


@pytest.mark.parametrize(("sampler", "low", "high"), [("random", 0.8, 1.2),
                                                       ("sobol", 0.75, 1.4)])
def test_coefficient_sem_matches_the_spread_along_the_trajectory(smooth_truth, sampler, low,
                                                                 high):
    """200 seeds, 5 periods through two impacts: (x_coef - truth) / x_coef_sem over the
    seeds, pooled over the 20 output times after t = 0 (correlated, so the band is that
    of the t = 0 tests), per order i = 0..4."""
    truth = smooth_truth.x_coef.values[:, 1:]
    z = []
    for seed in range(200):
        ds = mc.simulate_mc(SECTION_32, sampler=sampler, seed=seed, **SMOOTH)
        z.append((ds.x_coef.values[:, 1:] - truth) / ds.x_coef_sem.values[:, 1:])
    per_order = rms(np.array(z), axis=(0, 2))
    print(f"\n{sampler}, t > 0: RMS z per order {np.round(per_order, 3)}")
    assert np.all((low < per_order) & (per_order < high)), per_order


@pytest.mark.parametrize("sampler", ["random", "sobol"])
def test_order_zero_is_the_mean_and_its_sem_is_x_sem(sampler):
    """U_0 = 1: x_coef[0] estimates E[x] and x_coef_sem[0] is x_sem (bit for bit with
    replicates, where both are spreads of the same replicate sums; to round-off without,
    where the coefficient's centred sum of squares is merged from its own means)."""
    ds = mc.simulate_mc(SECTION_32, sampler=sampler, seed=1, chunk_size=48, **SMOOTH)
    np.testing.assert_allclose(ds.x_coef.values[0], ds.x_mean.values, rtol=1e-13, atol=1e-15)
    if sampler == "sobol":
        np.testing.assert_array_equal(ds.x_coef_sem.values[0], ds.x_sem.values)
    else:
        np.testing.assert_allclose(ds.x_coef_sem.values[0], ds.x_sem.values, rtol=1e-10,
                                   atol=1e-15)  # fmt: skip


def test_random_sem_is_the_sample_standard_deviation_over_sqrt_m():
    """From the kept paths, by numpy: std(x U_i(xi), ddof=1) / sqrt(M); with sobol
    replicates the spread of the per-replicate estimates / sqrt(R)."""
    ds = mc.simulate_mc(SECTION_32, sampler="random", seed=2, keep_paths=True, chunk_size=100,
                        **SMOOTH)  # fmt: skip
    y = opa.chebyshev_u(ORDER, ds.xi.values)[:, :, None] * ds.x.values[None]
    np.testing.assert_allclose(ds.x_coef_sem.values, y.std(axis=1, ddof=1) / np.sqrt(M),
                               rtol=1e-9, atol=1e-15)  # fmt: skip
    ds = mc.simulate_mc(SECTION_32, sampler="sobol", seed=2, keep_paths=True, chunk_size=100,
                        **SMOOTH)  # fmt: skip
    y = opa.chebyshev_u(ORDER, ds.xi.values)[:, :, None] * ds.x.values[None]
    per_replicate = y.reshape(ORDER + 1, 16, M // 16, -1).mean(axis=2)
    np.testing.assert_allclose(ds.x_coef_sem.values,
                               per_replicate.std(axis=1, ddof=1) / 4, rtol=1e-9, atol=1e-15)


def test_gauss_quadrature_has_no_sampling_error():
    ds = mc.simulate_mc(SECTION_32, sampler="gauss", **{**SMOOTH, "samples": 8})
    assert ds.x_coef_sem.dims == ("order", "time")
    assert np.isnan(ds.x_coef_sem.values).all()
