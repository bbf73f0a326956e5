"""Certificates of OPA runs with several uncertain parameters
(``compare/_verify_several.py``): how often their intervals and verdicts are wrong,
against truths computed independently (scipy at a tensor Gauss rule; a 2^14-sample
Monte Carlo of the true impact systems)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import stats

import compare
import mc
import opa
from opa._elements import ElementBudgetWarning
from tests.opa.test_galerkin import FREE, PER_PERIOD, PERIODS, SCALES, reference

IMPACTING = opa.preset("3.2", omega=3.98)


@pytest.fixture(scope="module")
def free_case():
    """A run of order 2 without impacts (its error is not small) and its true error."""
    system = opa.System(opa.Oscillator(**FREE), uncertain="mu,c", sigma=SCALES,
                        distribution="semicircle,uniform", order=2)
    run = opa.simulate_opa(system, periods=PERIODS, per_period=PER_PERIOD,
                           options=opa.SolverOptions(rtol=1e-11, atol=1e-11))
    mean, var, _, _ = reference(("semicircle", "uniform"))
    return run, run.x_mean.values - mean, run.x_var.values - var


def test_the_intervals_hold_the_true_error_at_the_nominal_rate(free_case):
    """95 % Student's t intervals of the error of E[x] and of Var[x] at the last output,
    over 40 seeds: the true error (OPA minus the scipy reference) inside at a rate
    consistent with 95 % (binomial, 99.9 % two-sided)."""
    run, err_mean, err_var = free_case
    t = stats.t.ppf(0.975, 15)
    inside_mean = inside_var = 0
    seeds = range(40)
    for seed in seeds:
        v = compare.verify(run, samples=128, max_samples=128, seed=seed, sequential=False)
        inside_mean += abs(v.verify_err_mean.values[-1] - err_mean[-1]) <= \
            t * v.verify_err_mean_sem.values[-1]
        inside_var += abs(v.verify_err_var.values[-1] - err_var[-1]) <= \
            t * v.verify_err_var_sem.values[-1]
    low, high = stats.binom.ppf([0.0005, 0.9995], len(seeds), 0.95)
    assert low <= inside_mean <= high and low <= inside_var <= high, (inside_mean,
                                                                        inside_var)


def test_the_verdicts_follow_the_independent_truth_on_the_impact_system():
    """Section 3.2 at omega = 3.98, (mu, c) uncertain: the single element's error of
    E[x] (against 2^14 true systems) is well above 0.1 of the spread, the adaptive boxes'
    far below; the certificate says disagrees and agrees, for every seed tried."""
    system = opa.System(IMPACTING, uncertain="mu,c", sigma=(0.016, 0.005), order=3,
                        impact_law="saltation")
    ref = mc.simulate_mc(system, samples=2**14, periods=10, per_period=8)
    single = opa.simulate_opa(system, periods=10, per_period=8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ElementBudgetWarning)
        boxes = opa.simulate_opa(system, periods=10, per_period=8, elements="adaptive")
    spread = np.sqrt(np.mean(ref.x_var.values))
    rms = [float(np.sqrt(np.mean((r.x_mean.values - ref.x_mean.values) ** 2)))
           for r in (single, boxes)]
    assert rms[0] > 0.15 * spread and rms[1] < 0.01 * spread, (rms, spread)  # tolerance 0.1
    for seed in range(3):
        assert compare.verify(single, samples=256, seed=seed).attrs["verdict"] == "disagrees"
        assert compare.verify(boxes, samples=256, seed=seed).attrs["verdict"] == "agrees"


def test_a_rare_change_of_the_impact_sequence_leaves_the_verdict_undecided():
    """Above the first split (about 3 % of the points make 3 or 5 impacts instead of 4):
    a few points in the rare region cannot bound its error, so no verdict is given."""
    system = opa.System(IMPACTING, uncertain="mu,c", sigma=(0.128, 0.04), order=2,
                        impact_law="saltation")
    run = opa.simulate_opa(system, periods=10, per_period=8, elements=2)
    v = compare.verify(run, samples=256, max_samples=256, seed=1)
    assert v.attrs["verdict"] == "undecided"
    assert "change of the impact sequence was seen at only" in \
        v.attrs["verify_undecided_because"]
    assert v.attrs["verify_unseen_probability"] == pytest.approx(3 / 256)


def test_the_certificate_refuses_what_it_cannot_take(free_case):
    run, _, _ = free_case
    broken = run.drop_vars("multi_index")
    with pytest.raises(ValueError, match="lacks multi_index"):
        compare.verify(broken, samples=64)
    unknown = run.copy()
    del unknown.attrs["distribution"]
    with pytest.raises(ValueError, match="lacks the attribute distribution"):
        compare.verify(unknown, samples=64)
