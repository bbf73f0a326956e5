"""Tests for mc._ensemble: the Monte Carlo ensemble of sampled impact systems (issue 5).

Ground truths, one per purpose:

* an independent scipy implementation (``tests/reference.py``: DOP853 with terminal wall
  events, no code shared with ``opa``) run sample by sample on the engine's own ``xi``;
* for the smooth regime (section 3.2 set, sigma = 0.05, 5 forcing periods: every sample
  has the same two impacts, so x(t, xi) is smooth in xi) a 32-node Gauss collocation at
  rtol 1e-11, which is converged to round-off (Q = 8 already agrees to 1e-13);
* for the Gauss path itself, the closed-form linear oscillator with uncertain stiffness,
  whose mean and Chebyshev coefficients are integrated over the semicircle by
  ``scipy.integrate.quad`` (both from ``tests/truths.py``).

Measured on the 2-core development container (printed with ``-s``): on the same 200 xi
the engine and the scipy reference differ by 6e-10 at most (sample means by 5e-11); the
random-sampling error slope is -0.49 for M = 2^4 .. 2^10 (8 seeds); Sobol' beats random at
M = 1024 by ~30x with the default 16 randomised replicates and by ~2700x with one
scrambling; Gauss collocation gains 2-3 orders of magnitude per node in the smooth regime;
section 3.2 at omega = 3.98 and sigma = 0.05 chatters for xi in about (-0.57682, -0.57660)
within 20 periods (mu ~ 0.77116: 40+ impacts at t ~ 25.1-25.3, stuck until the forcing
turns at t = 25.654); the window is narrow (2 samples in 8192), so the chatter test uses a
seed that draws two samples inside it.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
import tracemalloc

import numba
import numpy as np
import pytest

import mc
import opa
from opa._basis import chebyshev_u
from tests.reference import reference_trajectory
from tests.truths import linear_oscillator, semicircle_expectation

SECTION_32 = opa.preset("3.2", omega=3.98)
SIGMA = 0.05
MODEL_NAMES = ("a", "c", "f", "omega", "eta", "delta", "F0", "a1", "omega1", "n", "x0", "v0")

# The smooth regime: every sample has exactly two impacts over these 5 periods.
SMOOTH = dict(sigma=SIGMA, periods=5, per_period=4)
FAST = opa.SolverOptions(rtol=1e-9, atol=1e-9)
TIGHT = opa.SolverOptions(rtol=1e-11, atol=1e-11)
SEEDS = 8  # independent runs per sample size in the convergence tests


def rms(values) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


@pytest.fixture(scope="module")
def smooth_truth():
    """E[x(t)] in the smooth regime: 32-node Gauss collocation at rtol 1e-11."""
    return mc.simulate_mc(SECTION_32, samples=32, sampler="gauss", options=TIGHT, **SMOOTH)


@pytest.fixture(scope="module")
def random_errors(smooth_truth):
    """Errors of the random-sampling mean, x_mean - truth, for M = 2^4 .. 2^10 and 8
    seeds, with the engine's standard errors: {M: (errors (S, T), x_sem (S, T))}."""
    out = {}
    for M in 2 ** np.arange(4, 11):
        errors, sems = [], []
        for seed in range(SEEDS):
            ds = mc.simulate_mc(SECTION_32, samples=int(M), sampler="random", seed=seed,
                                options=FAST, **SMOOTH)  # fmt: skip
            errors.append(ds.x_mean.values - smooth_truth.x_mean.values)
            sems.append(ds.x_sem.values)
        out[int(M)] = (np.array(errors)[:, 1:], np.array(sems)[:, 1:])  # t = 0 has no spread
    return out


# --------------------------------------------------------------------------- scipy reference

REFERENCE_SAMPLES = 200
REFERENCE_PERIODS = 6  # samples have 2 or 3 impacts: the impact count varies with xi


@pytest.fixture(scope="module")
def reference_ensemble():
    """The engine's ensemble (paths kept) and the scipy reference on the same 200 xi."""
    ds = mc.simulate_mc(
        SECTION_32, sigma=SIGMA, samples=REFERENCE_SAMPLES, sampler="random", seed=11,
        periods=REFERENCE_PERIODS, per_period=2, options=TIGHT, keep_paths=True,
    )  # fmt: skip
    model = {name: getattr(SECTION_32, name) for name in MODEL_NAMES}
    paths, impacts = [], []
    for xi in ds.xi.values:
        ref = reference_trajectory(mu=SECTION_32.mu + SIGMA * xi, t_out=ds.time.values,
                                   rtol=1e-11, atol=1e-11, **model)  # fmt: skip
        paths.append(ref["x"])
        impacts.append(len(ref["impact_time"]))
    return ds, np.array(paths), np.array(impacts)


def test_mean_matches_scipy_reference_on_the_same_samples(reference_ensemble):
    """Same xi, two integrators: the sample means agree to integration accuracy.

    Checks that the engine gives sample m the parameter mu_bar + sigma xi[m], that it keeps
    every impact, and that the streamed mean is the plain mean of its paths.
    """
    ds, ref_paths, ref_impacts = reference_ensemble
    assert len(np.unique(ref_impacts)) > 1  # the horizon covers a change of impact count
    print(f"\nsame xi: max |path difference| {np.abs(ds.x.values - ref_paths).max():.1e}, "
          f"|mean difference| {np.abs(ds.x_mean.values - ref_paths.mean(axis=0)).max():.1e}")
    np.testing.assert_array_equal(ds.n_impacts.values, ref_impacts)
    np.testing.assert_allclose(ds.x.values, ref_paths, rtol=0, atol=1e-8)
    np.testing.assert_allclose(ds.x_mean.values, ref_paths.mean(axis=0), rtol=0, atol=1e-9)
    np.testing.assert_allclose(ds.x_mean.values, ds.x.values.mean(axis=0), rtol=0, atol=1e-14)
    np.testing.assert_allclose(ds.x_var.values, ds.x.values.var(axis=0, ddof=1), rtol=1e-10,
                               atol=1e-15)  # fmt: skip


def test_mean_matches_scipy_reference_within_four_standard_errors(reference_ensemble):
    """An independent draw (another seed, 4096 samples) against the reference's mean."""
    _, ref_paths, _ = reference_ensemble
    ref_mean = ref_paths.mean(axis=0)
    ref_sem = ref_paths.std(axis=0, ddof=1) / math.sqrt(len(ref_paths))
    ds = mc.simulate_mc(SECTION_32, sigma=SIGMA, samples=4096, sampler="random", seed=12,
                        periods=REFERENCE_PERIODS, per_period=2, options=FAST)  # fmt: skip
    both = np.hypot(ref_sem, ds.x_sem.values)
    z = np.abs(ds.x_mean.values - ref_mean)[1:] / both[1:]
    print(f"\nmax |MC - reference| / combined standard error: {z.max():.2f}")
    assert np.all(z < 4.0)
    np.testing.assert_array_equal(ds.x_mean.values[0], ref_mean[0])  # t = 0: x0 for all


# --------------------------------------------------------------------------- convergence


def test_random_error_decays_as_inverse_square_root(random_errors):
    """RMS error over 8 seeds and 20 output times vs M = 2^4 .. 2^10: fitted slope ~ -1/2.

    Also checks that x_sem is an honest standard error: the errors divided by it have
    mean square ~ 1 (56 independent runs per output time; the output times are correlated,
    hence the loose bounds).
    """
    sizes = np.array(sorted(random_errors))
    errors = np.array([rms(random_errors[M][0]) for M in sizes])
    slope = np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    z2 = np.mean([np.mean((e / s) ** 2) for e, s in random_errors.values()])
    print(f"\nrandom sampler: RMS error {dict(zip(sizes.tolist(), errors))}; slope {slope:.3f}; "
          f"mean (error/x_sem)^2 = {z2:.2f}")  # fmt: skip
    assert -0.7 < slope < -0.3
    assert 0.4 < z2 < 2.5


def test_sobol_beats_random_at_equal_samples(random_errors, smooth_truth):
    """M = 1024 in the smooth regime, RMS error over 8 seeds.

    Default (16 scrambled replicates of 64 points, for an error estimate) and a single
    scrambling of 1024 points. The replicate standard error must also be honest.
    """
    M = 1024
    truth = smooth_truth.x_mean.values
    random_rms = rms(random_errors[M][0])
    replicated, single, sems = [], [], []
    for seed in range(SEEDS):
        ds = mc.simulate_mc(SECTION_32, samples=M, sampler="sobol", seed=seed, options=FAST,
                            **SMOOTH)  # fmt: skip
        assert ds.attrs["replicates"] == 16
        replicated.append(ds.x_mean.values - truth)
        sems.append(ds.x_sem.values)
        ds = mc.simulate_mc(SECTION_32, samples=M, sampler="sobol", replicates=1, seed=seed,
                            options=FAST, **SMOOTH)  # fmt: skip
        single.append(ds.x_mean.values - truth)
    ratio_replicated = random_rms / rms(replicated)
    ratio_single = random_rms / rms(single)
    sem_honesty = rms(np.array(replicated)[:, 1:] / np.array(sems)[:, 1:])
    print(f"\nM = {M}: RMS error random {random_rms:.2e}, sobol (16 replicates) "
          f"{rms(replicated):.2e} (ratio {ratio_replicated:.0f}), sobol (1 scrambling) "
          f"{rms(single):.2e} (ratio {ratio_single:.0f}); RMS error/x_sem {sem_honesty:.2f}")
    assert ratio_replicated > 8.0
    assert ratio_single > 100.0
    assert 0.5 < sem_honesty < 2.0


# --------------------------------------------------------------------------- Gauss collocation
# No non-trivial trajectory of eq. (1) is polynomial in xi (even x'' + (a + sigma xi) x = f
# cos(omega t) is not), so "exact for a quantity polynomial in xi" is checked where it holds
# exactly, at t = 0 where x_coef[i] = x0 E[U_i]; the dynamics are covered by the weighted
# sum of single runs at the nodes, spectral convergence, and a closed-form expectation.


@pytest.mark.parametrize("nodes", [1, 2, 3, 5, 8])
def test_gauss_sampler_exact_to_degree_2q_minus_1(nodes):
    """At t = 0 every sample is at x0, so x_coef[i](0) = x0 sum_k w_k U_i(xi_k): the Q-node
    rule must return x0 [i == 0] exactly for every polynomial U_i of degree <= 2Q - 1, and
    fail at degree 2Q (the rule is exact to degree 2Q - 1 and no further)."""
    order = 2 * nodes
    ds = mc.simulate_mc(SECTION_32, sigma=SIGMA, samples=nodes, sampler="gauss", order=order,
                        periods=1)  # fmt: skip
    coef = ds.x_coef.values[:, 0]
    expected = np.zeros(order + 1)
    expected[0] = SECTION_32.x0
    np.testing.assert_allclose(coef[:order], expected[:order], rtol=0, atol=1e-14)
    assert abs(coef[order]) > 0.1  # degree 2Q: sum_k w_k U_2Q(xi_k) = -1
    assert ds.x_var.values[0] == 0.0 and np.isnan(ds.x_sem.values).all()
    assert math.isclose(ds.weight.values.sum(), 1.0, rel_tol=1e-15)


def test_gauss_ensemble_is_the_weighted_sum_of_dmr_runs_at_the_nodes():
    """The Gauss ensemble of Q = 6 nodes equals sum_k w_k x_DMR(t; mu_bar + sigma xi_k)
    computed one run at a time with simulate_dmr (same kernel, same parameter values)."""
    ds = mc.simulate_mc(SECTION_32, samples=6, sampler="gauss", order=3, keep_paths=True,
                        **SMOOTH)  # fmt: skip
    xi, w = ds.xi.values, ds.weight.values
    runs = np.array([
        opa.simulate_dmr(SECTION_32.replace(mu=SECTION_32.mu + SIGMA * k), periods=5,
                         per_period=4).x.values
        for k in xi
    ])  # fmt: skip
    np.testing.assert_array_equal(ds.x.values, runs)
    mean = w @ runs
    np.testing.assert_allclose(ds.x_mean.values, mean, rtol=0, atol=1e-14)
    np.testing.assert_allclose(ds.x_var.values, w @ (runs - mean) ** 2, rtol=0, atol=1e-14)
    np.testing.assert_allclose(ds.x_coef.values, (chebyshev_u(3, xi) * w) @ runs, rtol=0,
                               atol=1e-14)  # fmt: skip


def test_gauss_converges_spectrally_in_the_smooth_regime(smooth_truth):
    """Q = 1, 2, 3, 4 nodes against the 32-node truth: each node gains orders of
    magnitude (x(t, xi) is analytic in xi here), where MC would gain a factor sqrt(2)."""
    truth = smooth_truth.x_mean.values
    errors = [
        np.abs(mc.simulate_mc(SECTION_32, samples=q, sampler="gauss", options=TIGHT, **SMOOTH)
               .x_mean.values - truth).max()
        for q in (1, 2, 3, 4)
    ]  # fmt: skip
    print("\nGauss error, Q = 1..4: " + ", ".join(f"{e:.1e}" for e in errors))
    assert errors[-1] < 1e-10
    for coarse, fine in zip(errors, errors[1:]):
        assert fine < 1e-2 * coarse or fine < 1e-12


def test_gauss_matches_closed_form_linear_oscillator():
    """x'' + a x = f cos(omega t), no wall, no damping, no impulses, a = 1 + 0.3 xi:
    E[x], E[x U_1], E[x U_2] and Var[x] from 12 Gauss nodes against scipy quad of the
    closed-form solution over the semicircle density."""
    a_bar, sigma, f, omega, x0 = 1.0, 0.3, 1.0, 2.8, -1.0
    osc = opa.Oscillator(mu=0.0, a=a_bar, c=0.0, f=f, omega=omega, delta=1e6, F0=0.0,
                         x0=x0, v0=0.0)  # fmt: skip
    ds = mc.simulate_mc(osc, sigma=sigma, uncertain="a", samples=12, sampler="gauss", order=2,
                        periods=3, per_period=2, options=TIGHT)  # fmt: skip

    def x_exact(t, xi):
        return float(linear_oscillator(t, a_bar + sigma * xi, f, omega, x0, 0.0)[0])

    def expectation(g):
        return semicircle_expectation(g, epsabs=1e-14, epsrel=1e-14)

    for j, t in enumerate(ds.time.values):
        mean = expectation(lambda xi: x_exact(t, xi))
        assert ds.x_mean.values[j] == pytest.approx(mean, abs=1e-9)
        assert ds.x_coef.values[1, j] == pytest.approx(
            expectation(lambda xi: x_exact(t, xi) * 2 * xi), abs=1e-9)
        assert ds.x_coef.values[2, j] == pytest.approx(
            expectation(lambda xi: x_exact(t, xi) * (4 * xi * xi - 1)), abs=1e-9)
        assert ds.x_var.values[j] == pytest.approx(
            expectation(lambda xi: (x_exact(t, xi) - mean) ** 2), abs=1e-9)


# --------------------------------------------------------------------------- chatter

CHATTER_SEED = 68  # draws xi = -0.57677 and -0.57665, inside the chatter window
CHATTER_SAMPLES = 512


def test_section_32_ensemble_with_chattering_samples_finishes():
    """Section 3.2 at omega = 3.98, Dirac impulses, sigma = 0.05, 20 periods.

    Samples near xi = -0.5767 (mu ~ 0.77116) chatter: after an impact at t ~ 25.13 the
    impact velocities shrink geometrically (ratio -> eta) to an accumulation point where
    the mass sticks on the wall until the forcing f cos(omega t) turns (t = 25.654). The
    ensemble must finish with finite statistics, those samples sitting exactly on the wall
    at the output times while stuck, and no path beyond the wall.
    """
    osc = SECTION_32
    ds = mc.simulate_mc(osc, sigma=SIGMA, samples=CHATTER_SAMPLES, sampler="random",
                        seed=CHATTER_SEED, periods=20, per_period=8, keep_paths=True)  # fmt: skip
    for name in ("x_mean", "v_mean", "x_var", "v_var", "x_sem", "x_coef"):
        assert np.all(np.isfinite(ds[name].values)), name
    assert ds.x.values.max() <= osc.delta and ds.x_mean.values.max() <= osc.delta

    typical = np.median(ds.n_impacts.values)
    chattering = np.flatnonzero(ds.n_impacts.values > 3 * typical)
    print(f"\n{len(chattering)} of {CHATTER_SAMPLES} samples chatter: xi = "
          f"{ds.xi.values[chattering]}, impacts {ds.n_impacts.values[chattering]} "
          f"(median {typical:.0f})")
    assert len(chattering) >= 1
    times = ds.time.values
    for m in chattering:
        run = opa.simulate_dmr(osc.replace(mu=osc.mu + SIGMA * ds.xi.values[m]), periods=20,
                               per_period=8)  # fmt: skip
        assert run.impact_time.size == ds.n_impacts.values[m]
        np.testing.assert_array_equal(run.x.values, ds.x.values[m])
        assert run.stick_time.size >= 1 and run.stick_time.values[0] < times[-1]
        speeds = run.impact_velocity.values
        before = run.impact_time.values < run.stick_time.values[0]
        tail = speeds[before][-10:]
        np.testing.assert_allclose(tail[1:] / tail[:-1], osc.eta, rtol=0.02)  # Zeno sequence
        stuck = (times > run.stick_time.values[0]) & (times < run.release_time.values[0])
        assert stuck.any()
        np.testing.assert_array_equal(ds.x.values[m, stuck], osc.delta)
        np.testing.assert_array_equal(ds.v.values[m, stuck], 0.0)


# --------------------------------------------------------------------------- reproducibility

REPRO = dict(sigma=SIGMA, samples=200, sampler="random", seed=5, periods=8, per_period=2,
             options=FAST, order=3)  # fmt: skip
STAT_NAMES = ("x_mean", "v_mean", "x_var", "v_var", "x_sem", "v_sem", "x_var_sem", "x_coef",
              "x_coef_sem", "n_impacts", "xi", "weight")  # fmt: skip
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run_with_blas_threads(threads: int, script: str, out) -> dict:
    """Run ``script`` (which saves arrays to sys.argv[1]) in a fresh interpreter whose
    OpenBLAS has ``threads`` threads; its arrays."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": str(threads), "OMP_NUM_THREADS": str(threads)}
    subprocess.run([sys.executable, "-c", textwrap.dedent(script), str(out)], cwd=ROOT,
                   env=env, check=True)  # fmt: skip
    with np.load(out) as data:
        return {name: data[name] for name in data.files}


CHUNK_STATS = """
import sys
import numpy as np
from mc._ensemble import ChunkStats
rng = np.random.default_rng(0)
M, T = 1024, 1501  # 1500 or 1501 outputs split unevenly between two BLAS threads
x, v = rng.standard_normal((2, M, T))
xi = rng.uniform(-1, 1, M)
w = rng.uniform(0.5, 1.5, M) / M
s = ChunkStats.of(x, v, xi, w, 6, np.arange(M) // (M // 16), 16)
np.savez(sys.argv[1], **{k: np.asarray(getattr(s, k)) for k in s.__dataclass_fields__})
"""


def test_chunk_statistics_do_not_depend_on_the_blas_thread_count(tmp_path):
    """Matrix products (``w @ x``) sum in an order that depends on the BLAS thread count:
    one against two OpenBLAS threads changed x_mean, x_m2, v_mean and v_m2 (hence x_var,
    x_sem) in the last bit at 4 of these 1501 outputs. The statistics now never go
    through BLAS, the coefficients' sums of squares and replicate sums (x_coef_sem)
    included. (On a one-core machine OpenBLAS may run one thread either way; the test
    then passes trivially.)"""
    one = run_with_blas_threads(1, CHUNK_STATS, tmp_path / "one.npz")
    two = run_with_blas_threads(2, CHUNK_STATS, tmp_path / "two.npz")
    assert set(one) == set(two)
    assert {"x_moment", "x_moment_m2", "x_moment_rep"} <= set(one)
    assert one["x_moment_rep"].shape == (16, 7, 1501)
    for name in one:
        np.testing.assert_array_equal(one[name], two[name], err_msg=name)


ENSEMBLE = """
import sys
import numpy as np
import mc, opa
ds = mc.simulate_mc(opa.preset("3.2", omega=3.98), sigma=0.05, samples=1024, seed=3,
                    periods=15, per_period=100, chunk_size=1024, order=6, progress=False,
                    options=opa.SolverOptions(rtol=1e-7, atol=1e-7))
np.savez(sys.argv[1], **{k: ds[k].values for k in ds.data_vars})
"""


@pytest.mark.slow
def test_ensemble_does_not_depend_on_the_blas_thread_count(tmp_path):
    """The whole ensemble, 1024 samples of 1501 outputs, under one and two OpenBLAS
    threads: every statistic equal bit for bit, x_coef_sem included (before, x_mean,
    v_mean, x_var, v_var, x_sem and v_sem were not)."""
    one = run_with_blas_threads(1, ENSEMBLE, tmp_path / "one.npz")
    two = run_with_blas_threads(2, ENSEMBLE, tmp_path / "two.npz")
    assert set(STAT_NAMES) <= set(one)
    for name in one:
        np.testing.assert_array_equal(one[name], two[name], err_msg=name)


def test_same_seed_same_result_whatever_the_thread_count():
    before = numba.get_num_threads()
    results = {}
    try:
        for threads in sorted({1, min(2, numba.config.NUMBA_NUM_THREADS)}):
            numba.set_num_threads(threads)
            results[threads] = mc.simulate_mc(SECTION_32, keep_paths=True, chunk_size=64,
                                              **REPRO)  # fmt: skip
    finally:
        numba.set_num_threads(before)
    if len(results) < 2:
        pytest.skip("numba has a single thread here")
    one, two = results[1], results[2]
    for name in (*STAT_NAMES, "x", "v"):
        np.testing.assert_array_equal(one[name].values, two[name].values, err_msg=name)


def test_chunk_size_changes_only_the_round_off_of_the_statistics():
    runs = [mc.simulate_mc(SECTION_32, keep_paths=True, chunk_size=size, **REPRO)
            for size in (200, 64, 7)]  # fmt: skip
    for ds in runs[1:]:
        for name in ("x", "v", "n_impacts", "xi", "weight"):
            np.testing.assert_array_equal(ds[name].values, runs[0][name].values, err_msg=name)
        for name in ("x_mean", "v_mean", "x_var", "v_var", "x_sem", "v_sem", "x_coef",
                     "x_coef_sem"):
            np.testing.assert_allclose(ds[name].values, runs[0][name].values, rtol=1e-13,
                                       atol=1e-14, err_msg=name)  # fmt: skip


# --------------------------------------------------------------------------- memory


def test_without_keep_paths_only_streamed_statistics_are_returned():
    """No (sample, time) array unless paths are asked for; chunking (7 samples per chunk)
    gives the one-chunk statistics to round-off."""
    whole = mc.simulate_mc(SECTION_32, chunk_size=200, **REPRO)
    chunked = mc.simulate_mc(SECTION_32, chunk_size=7, **REPRO)
    for ds in (whole, chunked):
        assert "x" not in ds and "v" not in ds
        for name, var in ds.data_vars.items():
            assert not {"sample", "time"} <= set(var.dims), name
            assert var.size <= max(ds.sizes["sample"], ds.sizes["order"] * ds.sizes["time"])
    for name in ("x_mean", "v_mean", "x_var", "v_var", "x_sem", "v_sem", "x_coef", "x_coef_sem"):
        np.testing.assert_allclose(chunked[name].values, whole[name].values, rtol=1e-13,
                                   atol=1e-14, err_msg=name)  # fmt: skip
    np.testing.assert_array_equal(chunked.n_impacts.values, whole.n_impacts.values)


def test_peak_memory_does_not_grow_with_the_number_of_samples():
    """tracemalloc peak (numpy allocations) without keep_paths, 32-sample chunks of 101
    output times, Sobol' with 16 replicates: 16x the samples may add O(M) vectors (xi,
    weights, impact counts: ~40 bytes a sample) but nothing of size O(M T).

    Fails today: each finished chunk's statistics (x_mean, x_m2, v_mean, v_m2, the N + 1
    moments and 2 R replicate sums: 41 T floats) stay in the list ``_run_chunks``
    returns until the merge, i.e. memory O((M / chunk) T (N + 2 R)), here ~1000 bytes a
    sample; with a lazy ``_run_chunks`` (merge as chunks arrive) the growth measured
    37 bytes a sample.
    """
    kwargs = dict(sigma=SIGMA, sampler="sobol", seed=0, periods=1, per_period=100,
                  options=opa.SolverOptions(rtol=1e-6, atol=1e-6), chunk_size=32)  # fmt: skip
    mc.simulate_mc(SECTION_32, samples=64, **kwargs)  # compile and import outside the trace
    peaks = {}
    for M in (128, 2048):
        tracemalloc.start()
        try:
            ds = mc.simulate_mc(SECTION_32, samples=M, **kwargs)
            peaks[M] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert ds.attrs["replicates"] == 16 and np.isfinite(ds.x_mean.values).all()
    per_sample = (peaks[2048] - peaks[128]) / (2048 - 128)
    all_paths = 2048 * 101 * 2 * 8
    print(f"\npeak traced memory {peaks}: {per_sample:.0f} bytes per extra sample; all "
          f"paths of M = 2048 would take {all_paths} bytes")  # fmt: skip
    assert peaks[2048] < all_paths / 4
    assert per_sample < 128


# --------------------------------------------------------------------------- Dask


@pytest.mark.long  # the quick suite's equivalent: tests/mc/test_dask.py's resumed run
def test_dask_local_cluster_gives_exactly_the_local_result():
    """Two worker processes, chunks as tasks, merged in submission order: bit-identical to
    the local engine for the same seed and chunk size (by Client and by address). The
    dashboard gets a free port (":0"): a busy 8787 would raise a warning, an error here."""
    distributed = pytest.importorskip("distributed")
    kwargs = dict(sigma=SIGMA, samples=96, sampler="sobol", seed=3, periods=5, chunk_size=16,
                  order=3, options=FAST)  # fmt: skip
    local = mc.simulate_mc(SECTION_32, **kwargs)
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                 dashboard_address=":0") as cluster,
        distributed.Client(cluster) as client,
    ):  # fmt: skip
        by_client = mc.simulate_mc(SECTION_32, scheduler=client, **kwargs)
        by_address = mc.simulate_mc(SECTION_32, scheduler=cluster.scheduler_address, **kwargs)
    for remote in (by_client, by_address):
        for name in STAT_NAMES:
            np.testing.assert_array_equal(remote[name].values, local[name].values, err_msg=name)
        differing = {k for k in local.attrs if remote.attrs.get(k) != local.attrs[k]}
        assert differing <= {"history"}  # history holds a time stamp


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(sampler="latin"), r"sampler must be one of .*got 'latin'"),
        (dict(samples=0), r"samples must be a positive integer, got 0"),
        (dict(samples=-3), r"samples must be a positive integer, got -3"),
        (dict(samples=2.5), r"samples must be a positive integer, got 2.5"),
        (dict(seed=-1), r"seed must be a non-negative integer or None, got -1"),
        (dict(sigma=-0.01), r"sigma must be >= 0, got -0.01"),
        (dict(sigma=math.nan), r"sigma must be finite, got nan"),
        (dict(sampler="sobol", samples=100, replicates=8),
         r"samples must be a multiple of replicates = 8, got 100"),
        (dict(sampler="sobol", replicates=0), r"replicates must be a positive integer, got 0"),
        (dict(order=-1), r"order \(N\) must be an integer >= 0, got -1"),
        (dict(uncertain="a1"), r"uncertain must name parameters among .*, got 'a1'"),
        (dict(sigma=0.9), r"makes mu = 0.8 \+ sigma xi = -0.1 negative"),
        (dict(chunk_size=0), r"chunk_size must be a positive integer, got 0"),
        (dict(samples=True), r"samples must be a positive integer, got True"),
        (dict(samples="64"), r"samples must be a positive integer, got '64'"),
        (dict(samples=1e12), r"samples must be a positive integer, got 1000000000000.0"),
        (dict(samples=10**15), r"^sampling needs 85.3 PiB \(samples 1000000000000000 x 96 "
                               r"bytes\), more than the memory budget of .* \(set "
                               r"OPA_MC_MEMORY_BUDGET to change it\)$"),
        (dict(checkpoint=3), r"checkpoint must be a directory path, got 3"),
    ],
)  # fmt: skip
def test_bad_input_names_the_parameter_and_the_value(kwargs, message):
    arguments = dict(sigma=SIGMA, samples=16, sampler="random", seed=0, periods=1)
    with pytest.raises(ValueError, match=message):
        mc.simulate_mc(SECTION_32, **{**arguments, **kwargs})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(samples=1024, keep_paths=True),
         r"^keep_paths needs 1.6 MiB \(samples 1024 x 101 outputs x 2 states\), more than "
         r"the memory budget of 1 MiB \(set OPA_MC_MEMORY_BUDGET to change it\)$"),
        (dict(samples=16, order=500),
         r"^x_coef needs 790.6 KiB \(order \+ 1 = 501 coefficients x 101 outputs, running "
         r"sum and a chunk's\), more than the memory budget of 512 KiB"),
        (dict(samples=4096, chunk_size=4096),
         r"^a chunk of paths needs 18.9 MiB \(chunk_size 4096 x 101 outputs"),
        (dict(samples=256, sampler="sobol", order=40, chunk_size=64),
         r"^x_coef_sem needs 1.1 MiB \(\(replicates 16 \+ 1\) x order \+ 1 = 41 "
         r"coefficients x 101 outputs, running sums and a chunk's\), more than the memory "
         r"budget of 512 KiB"),
    ],
)  # fmt: skip
def test_sizes_beyond_the_memory_budget_are_refused_up_front(monkeypatch, kwargs, message):
    """OPA_MC_MEMORY_BUDGET (here 1 MiB or 512 KiB) bounds what a run may allocate."""
    budget = "512K" if "order" in kwargs else "1M"
    monkeypatch.setenv("OPA_MC_MEMORY_BUDGET", budget)
    arguments = dict(sigma=SIGMA, sampler="random", seed=0, periods=1, per_period=100)
    with pytest.raises(ValueError, match=message):
        mc.simulate_mc(SECTION_32, **{**arguments, **kwargs})


def test_pipelined_chunks_count_their_runs_in_the_calling_thread():
    """The chunks are integrated on a helper thread while the last is reduced; every
    sample's run is still counted in the thread that asked (``true_system_work``), and
    the result equals the same chunks run one after the other in this thread."""
    from opa.engine import true_system_work

    osc = opa.Oscillator(omega=3.98)
    kw = dict(sigma=0.02, samples=64, sampler="random", seed=5, periods=3, per_period=2,
              chunk_size=16, progress=False)
    runs, time_units = true_system_work()
    ds = mc.simulate_mc(osc, **kw)
    after = true_system_work()
    assert after[0] - runs == 64
    assert after[1] - time_units == pytest.approx(64 * 3 * 2 * np.pi / 3.98, rel=1e-12)
    from mc import _ensemble

    chunks = [_ensemble._run_chunk(np.array([osc.x0, osc.v0]), ds.xi.values[lo:lo + 16],
                                  ds.weight.values[lo:lo + 16], np.zeros(16, int), 1,
                                  ds.time.values, opa.System(osc, sigma=0.02),
                                  opa.SolverOptions(), ds.attrs.get("order", 4), False)[0]
              for lo in range(0, 64, 16)]
    total = chunks[0]
    for c in chunks[1:]:
        total = total.merge(c)
    np.testing.assert_array_equal(total.x_mean, ds.x_mean.values)


def test_the_pipeline_integrates_with_the_callers_numba_thread_count(monkeypatch):
    """numba's thread count is per thread: the helper that integrates the chunks takes the
    caller's (a map's worker process runs on its share of the cores)."""
    import numba

    from mc import _ensemble

    seen = []
    original = _ensemble.integrate_chunk

    def integrate_chunk(*args, **kwargs):
        seen.append(numba.get_num_threads())
        return original(*args, **kwargs)

    monkeypatch.setattr(_ensemble, "integrate_chunk", integrate_chunk)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        mc.simulate_mc(opa.Oscillator(), sigma=0.01, samples=32, periods=1, chunk_size=8,
                       progress=False)
    finally:
        numba.set_num_threads(before)
    assert seen == [1, 1, 1, 1]


def test_the_sobol_variance_has_no_bessel_bias():
    """Scrambled Sobol' points: the variance estimate averages to the truth (scipy quad
    over the closed-form linear oscillator, no wall, no impulses, ``a`` uncertain), where
    Bessel's M / (M - 1) added a bias of Var / M (1.6 % at M = 64, many times the
    estimate's own spread over 200 seeds)."""
    from scipy import integrate, stats

    osc = opa.Oscillator(mu=0.0, c=0.0, a=1.3, f=2.0, omega=2.8, delta=100.0, F0=0.0,
                     x0=-1.0, v0=0.4)
    sigma, t_end = 0.3, 3.0
    density = stats.beta(1.5, 1.5, loc=-1, scale=2).pdf

    def moment(p):
        return integrate.quad(lambda xi: linear_oscillator(t_end, 1.3 + sigma * xi, 2.0, 2.8,
                                                           -1.0, 0.4)[0] ** p * density(xi),
                              -1, 1, epsabs=1e-14)[0]

    truth = moment(2) - moment(1) ** 2
    estimates = []
    for seed in range(200):
        ds = mc.simulate_mc(osc, sigma=sigma, uncertain="a", samples=64, sampler="sobol",
                            replicates=4,
                         seed=seed, times=np.array([0.0, t_end]), progress=False)
        estimates.append(float(ds.x_var[-1]))
    estimates = np.array(estimates)
    spread = estimates.std(ddof=1) / np.sqrt(len(estimates))
    assert abs(estimates.mean() - truth) <= 4 * spread + 1e-12 * truth
    assert truth / 64 > 4 * spread  # the old bias would have shown


def test_an_ensemble_of_several_parameters_bounds_its_coefficients_up_front():
    """C(N + d, d) coefficients E[x Psi_alpha] counted before any sample is drawn."""
    system = opa.System(uncertain="mu,a,c", sigma=0.01, order=100)
    with pytest.raises(ValueError, match="order 100 with 3 uncertain parameters makes 176851 "
                                         "coefficients"):
        mc.simulate_mc(system, samples=64, periods=1)
    with pytest.raises(ValueError, match="sampler 'gauss' .* takes one uncertain parameter"):
        mc.simulate_mc(system.replace(order=2), samples=8, sampler="gauss", periods=1)
