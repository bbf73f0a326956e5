"""The map's paired estimates (compare._pairs): the same numbers as the surrogate evaluated
point by point (compare._verify.paired_estimates on opa.surrogate_values), unbiased errors
with calibrated standard errors on a closed-form response, and the choice of the
reference."""

import math

import numpy as np
import pytest
from scipy import special, stats

from compare._pairs import Control, pair_point
from compare._verify import paired_estimates
from mc import sample_xi
from opa._measure import parse
from opa._surrogate import surrogate_values


@pytest.mark.parametrize("law, edges, closed", [
    ("semicircle", [-1.0, 1.0], True),
    ("uniform", [-1.0, -0.3, 0.2, 1.0], False),
    ("beta:2,3", [-1.0, 1.0], False),
])
def test_the_estimates_are_those_of_the_surrogate_at_every_point(law, edges, closed):
    rng = np.random.default_rng(3)
    measure = parse(law)
    edges = np.array(edges)
    M, T = 256, 5
    xi = measure.ppf(rng.random(M))
    x = np.sin(3 * xi)[:, None] * np.arange(1, T + 1) + 0.1 * rng.normal(size=(M, T))
    K = len(edges) - 1
    controls = {(v, k): Control(rng.normal(size=(K, k + 1, T)), edges, closed)
                for v in range(2) for k in range(4)}
    prob = np.array([measure.restrict(a, b).probability() for a, b in zip(edges[:-1],
                                                                          edges[1:])])
    pairs = pair_point(x, xi, controls, measure, {key: prob for key in controls}, (2, 4))
    own = {}
    for (v, k), control in controls.items():
        x_hat = surrogate_values(control.coef, edges, measure, xi, closed_form=closed)
        mean, second = control.moments(prob)
        own[v, k] = paired_estimates(x, x_hat, 16, mean, second), mean, second - mean**2
        np.testing.assert_allclose(pairs.reduction[v, k], own[v, k][0]["variance_reduction"],
                                   rtol=1e-9)
    # the reference: the smallest RMS standard error of E[x] among the plain ensemble and
    # the controls at the highest N (in the order N, variant)
    zero = np.zeros(T)
    best = paired_estimates(x, np.zeros_like(x), 16, zero, zero)
    for v in range(2):
        est = own[v, 3][0]
        if np.sqrt(np.mean(est["mean_se"] ** 2)) < np.sqrt(np.mean(best["mean_se"] ** 2)):
            best = est
    np.testing.assert_allclose(pairs.reference["x_mean"], best["mean"], atol=1e-12)
    np.testing.assert_allclose(pairs.reference["x_sem"], best["mean_se"], atol=1e-12)
    for (v, k), (_, mean, var_hat) in own.items():
        np.testing.assert_allclose(pairs.err_mean[v, k], mean - best["mean"], atol=1e-12)
        np.testing.assert_allclose(pairs.err_mean_se[v, k], best["mean_se"], atol=1e-12)
        np.testing.assert_allclose(pairs.err_var[v, k], var_hat - best["var"], atol=1e-12)
        np.testing.assert_allclose(pairs.err_var_se[v, k], best["var_se"], atol=1e-12)


def test_errors_are_unbiased_and_their_intervals_cover_95_percent():
    """x(xi) = exp(xi) under the semicircle law (E[e^xi] = 2 I_1(1), E[e^2xi] = I_1(2)),
    against the control x_hat = 1 + 0.5 U_1(xi): 400 seeds of 128 scrambled Sobol'
    points in 16 replicates; the 95 % t-intervals of OPA's error of the mean and of the
    variance cover the exact errors in 93-97 % of the seeds."""
    mean_true = 2 * special.iv(1, 1.0)
    var_true = special.iv(1, 2.0) - mean_true**2
    coef = np.array([[[1.0], [0.5]]])  # (K=1, N+1=2, T=1)
    err_mean_true, err_var_true = 1.0 - mean_true, 0.25 - var_true
    measure = parse("semicircle")
    t = stats.t.ppf(0.975, 15)
    hits = {"mean": 0, "var": 0}
    seeds = 400
    for seed in range(seeds):
        xi, _ = sample_xi("sobol", 128, seed, 16)
        pairs = pair_point(np.exp(xi)[:, None], xi, {(0, 0): Control(coef, [-1.0, 1.0],
                                                                     True)},
                           measure, {(0, 0): np.ones(1)}, (1, 1))
        hits["mean"] += abs(pairs.err_mean[0, 0, 0] - err_mean_true) \
            <= t * pairs.err_mean_se[0, 0, 0]
        hits["var"] += abs(pairs.err_var[0, 0, 0] - err_var_true) \
            <= t * pairs.err_var_se[0, 0, 0]
    for name, count in hits.items():
        assert 0.93 <= count / seeds <= 0.97, (name, count / seeds)


def test_the_reference_is_the_best_finished_control_at_the_highest_order():
    rng = np.random.default_rng(0)
    measure = parse("semicircle")
    M, T = 128, 3
    xi, _ = sample_xi("sobol", M, 1, 16)
    x = (1 + 0.5 * xi + 0.1 * xi**2)[:, None] * np.ones(T)
    exact = np.zeros((1, 3, T))  # x = 1.0125 + 0.25 U_1 + 0.025 U_2 (U_2 = 4 xi^2 - 1)
    exact[0, 0], exact[0, 1], exact[0, 2] = 1 + 0.1 / 4, 0.25, 0.1 / 4
    stopped = exact.copy()
    stopped[:, :, 1:] = np.nan  # a run that stopped after the first output
    rough = exact + 0.01 * rng.normal(size=exact.shape)
    whole = np.array([-1.0, 1.0])
    controls = {(0, 1): Control(stopped, whole, True), (1, 1): Control(exact, whole, True),
                (2, 1): Control(rough, whole, True), (1, 0): Control(exact, whole, True)}
    pairs = pair_point(x, xi, controls, measure, {key: np.ones(1) for key in controls},
                       (3, 2))
    # the exact surrogate at N = Nmax: no noise left, and the truth to round-off
    assert pairs.reference["control"] == (1, 1)
    np.testing.assert_allclose(pairs.reference["x_mean"], exact[0, 0], atol=1e-14)
    np.testing.assert_allclose(pairs.reference["x_var"], 0.25**2 + 0.025**2, atol=1e-14)
    assert np.all(pairs.reference["x_sem"] < 1e-14)
    # the stopped run is NaN from where it stopped, and never the reference
    assert np.isfinite(pairs.err_mean[0, 1, 0]) and np.isnan(pairs.err_mean[0, 1, 1:]).all()
    assert np.isnan(pairs.err_mean[2, 0]).all()  # not run
    # without a usable control the reference is the plain ensemble
    plain = pair_point(x, xi, {(0, 1): Control(stopped, whole, True)}, measure,
                       {(0, 1): np.ones(1)}, (1, 2))
    assert plain.reference["control"] is None
    per = x.reshape(16, -1, T).mean(axis=1)
    np.testing.assert_allclose(plain.reference["x_mean"], per.mean(axis=0), atol=1e-14)
    np.testing.assert_allclose(plain.reference["x_sem"],
                               per.std(axis=0, ddof=1) / math.sqrt(16), atol=1e-14)


def test_points_that_cannot_form_the_replicates_are_refused():
    with pytest.raises(ValueError, match="replicates"):
        pair_point(np.zeros((100, 2)), np.zeros(100), {}, parse("semicircle"), {}, (1, 1))
