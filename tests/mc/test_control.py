"""simulate_mc(control=run): control-variate estimates formed from the streamed replicate
sums, against the same estimates written out from the kept paths and the surrogate, and
against an independent large ensemble; refusals name what differs."""

import math

import numpy as np
import pytest

import mc
import opa

from mc import simulate_mc
from opa import Oscillator, simulate_opa
from opa._surrogate import surrogate

OSC = Oscillator(omega=3.98)


@pytest.fixture(scope="module")
def controlled():
    run = simulate_opa(OSC, sigma=0.02, order=4, periods=3, per_period=8, elements=4)
    ens = simulate_mc(OSC, sigma=0.02, samples=256, seed=4, control=run, keep_paths=True,
                      chunk_size=48, progress=False)
    return run, ens


def test_the_estimates_are_the_paired_replicate_estimates(controlled):
    """Written out here from the kept paths: per replicate r, E[x_hat] + mean_r(x - x_hat)
    and E[x_hat^2] + mean_r(x^2 - x_hat^2) - (that mean)^2; the spread over sqrt(16)."""
    run, ens = controlled
    x = ens.x.values
    x_hat = surrogate(run, ens.xi.values)[0]
    mean_hat = run.x_mean.values
    second_hat = run.x_var.values + mean_hat**2
    R, n = 16, len(x) // 16
    mean_r = mean_hat + (x - x_hat).reshape(R, n, -1).mean(axis=1)
    var_r = second_hat + (x**2 - x_hat**2).reshape(R, n, -1).mean(axis=1) - mean_r**2
    np.testing.assert_allclose(ens.cv_x_mean.values, mean_r.mean(axis=0), rtol=0,
                               atol=1e-13)
    np.testing.assert_allclose(ens.cv_x_mean_sem.values,
                               mean_r.std(axis=0, ddof=1) / math.sqrt(R), rtol=1e-9,
                               atol=1e-15)
    np.testing.assert_allclose(ens.cv_x_var.values, var_r.mean(axis=0), rtol=0, atol=1e-13)
    np.testing.assert_allclose(ens.cv_x_var_sem.values,
                               var_r.std(axis=0, ddof=1) / math.sqrt(R), rtol=1e-9,
                               atol=1e-15)
    want = np.sum(ens.x_sem.values**2) / np.sum(ens.cv_x_mean_sem.values**2)
    assert ens.attrs["variance_reduction"] == pytest.approx(want)


def test_a_good_control_gives_the_truth_with_far_fewer_runs(controlled):
    """Against 8192 independent Sobol' points (another seed, no control): within 4 joint
    standard errors at every output, and with a variance reduction over 100. (The plain
    variance carries the factor M / (M - 1), which under Sobol' points is a bias of
    Var / (M - 1), larger than its randomised-QMC standard error while the spread is
    tiny: it is allowed for.)"""
    _, ens = controlled
    M = 8192
    big = simulate_mc(OSC, sigma=0.02, samples=M, seed=11, times=ens.time.values,
                      progress=False)
    gap = np.abs(ens.cv_x_mean.values - big.x_mean.values)
    assert np.all(gap <= 4 * np.hypot(ens.cv_x_mean_sem.values, big.x_sem.values) + 1e-15)
    gap = np.abs(ens.cv_x_var.values - big.x_var.values)
    allowed = 4 * np.hypot(ens.cv_x_var_sem.values, big.x_var_sem.values) \
        + big.x_var.values / (M - 1)
    assert np.all(gap <= allowed + 1e-15)
    assert ens.attrs["variance_reduction"] > 100


@pytest.mark.parametrize("kw, needle", [
    (dict(sigma=0.03), "sigma = 0.02 in the run, 0.03"),
    (dict(uncertain="c"), "uncertain = 'mu' in the run, 'c'"),
    (dict(distribution="uniform"), "distribution = 'semicircle' in the run, 'uniform'"),
    (dict(sampler="random"), "replicates >= 2"),
    (dict(times=np.linspace(0, 1, 5)), "output times differ"),
])
def test_a_control_of_another_system_is_refused(controlled, kw, needle):
    run, _ = controlled
    args = dict(sigma=0.02, samples=64, progress=False) | kw
    with pytest.raises(ValueError, match=needle):
        simulate_mc(OSC, control=run, **args)


def test_a_control_must_be_an_opa_run():
    with pytest.raises(ValueError, match="control must be an OPA run"):
        simulate_mc(OSC, sigma=0.02, samples=64, control="run.nc", progress=False)


def test_a_run_of_several_parameters_controls_their_ensemble():
    """(mu, c) on the impact system of section 3.2: the controlled estimate of E[x] from
    1024 samples controlled by the adaptive boxes agrees with a plain 2^14-sample
    ensemble within 4 of their combined standard errors at every output, with a
    standard error several times smaller; a
    control of other scales is refused by name."""
    osc = opa.preset("3.2", omega=3.98)
    system = opa.System(osc, uncertain="mu,c", sigma=(0.016, 0.005), order=3,
                        impact_law="saltation")
    run = opa.simulate_opa(system, periods=10, per_period=8, elements="adaptive")
    ds = mc.simulate_mc(system, samples=1024, periods=10, per_period=8, control=run)
    ref = mc.simulate_mc(system, samples=2**14, periods=10, per_period=8, seed=5)
    combined = np.hypot(ds.cv_x_mean_sem.values, ref.x_sem.values)
    assert np.all(np.abs(ds.cv_x_mean.values - ref.x_mean.values) <= 4 * combined)
    assert ds.attrs["variance_reduction"] > 10  # measured 28
    other = opa.System(osc, uncertain="mu,c", sigma=(0.016, 0.004), order=3)
    with pytest.raises(ValueError, match=r"control: sigma = \[0.016, 0.005\] in the run"):
        mc.simulate_mc(other, samples=64, periods=10, per_period=8, control=run)
