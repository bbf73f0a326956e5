"""Control variates on the OPA surrogate against plain scrambled Sobol, per true run.

Section 3.2, omega = 3.98, sigma = 0.05, 10 forcing periods, 8 outputs per period
(issue 25's target case): the 64-element adaptive ME-OPA (saltation law, N = 1) is the
control; ``compare.verify(run, samples=M, sequential=False)`` gives E_cv[x] from M true
systems (stratified by element: the 65 edges, then jittered groups of 4), and a plain
Sobol ensemble of the same M (``mc.simulate_mc``) gives E[x].

The reference is the same control-variate estimate from 2^16 true systems at other
points (seed 1); a plain 2^16-sample Sobol ensemble (seed 1) must agree with it within
4 joint standard errors at every output, so the reference does not lean on the control.

    python -m pytest -s benchmarks/bench_verify.py

prints the table of RMS errors against M (one seed), then the calibration at M = 512
over 100 seeds: the RMS error, the RMS standard error and the coverage of the 95 %
Student-t intervals; the timing is of one certificate at M = 512.

The smoke mode (CI) runs 2 periods, 16 elements, M = 128, a 4096-sample reference and
5 seeds.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from benchmarks.conftest import smoke_mode
from compare import verify
from compare._verify import interval_halfwidth
from mc import simulate_mc
from opa import Oscillator, simulate_opa
from opa._elements import ElementBudgetWarning
from opa._model import time_grid


@pytest.fixture(scope="module")
def case(request):
    smoke = smoke_mode(request.config)
    periods, budget, counts, reference, seeds = (
        (2, 16, (128,), 4096, 5) if smoke else
        (10, 64, (128, 256, 512, 1024, 2048), 65536, 100))
    osc = Oscillator(omega=3.98)
    times = time_grid(3.98, periods, 8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ElementBudgetWarning)
        control = simulate_opa(osc, sigma=0.05, order=1, elements="adaptive",
                               max_elements=budget, times=times)
    ref = verify(control, samples=reference, max_samples=reference, seed=1,
                 sequential=False)
    plain = simulate_mc(osc, sigma=0.05, samples=reference, sampler="sobol", seed=1,
                        order=0, times=times, progress=False)
    return dict(osc=osc, times=times, ref=ref, plain=plain, control=control, counts=counts,
                seeds=seeds, calibrate=counts[min(2, len(counts) - 1)])


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.asarray(a) ** 2)))


def test_the_reference_agrees_with_plain_sobol(case):
    ref, plain = case["ref"], case["plain"]
    print(f"\nreference: RMS SE {_rms(ref.cv_x_mean_sem):.2g} (control variate, "
          f"{ref.attrs['verify_samples']} runs); plain Sobol of as many: RMS SE "
          f"{_rms(plain.x_sem):.2g}, RMS difference {_rms(plain.x_mean - ref.cv_x_mean):.2g}")
    gap = np.abs(plain.x_mean.values - ref.cv_x_mean.values)
    assert np.all(gap <= 4 * np.hypot(plain.x_sem.values, ref.cv_x_mean_sem.values) + 1e-12)


def test_the_edge_misfit_follows_the_spread_inside(case):
    """The allocation's premise: each element's misfit at its ends (edge_indicator) against
    the spread of x - x_hat over the element at 2^15 points of equal probability (2^12
    in smoke mode); the correlation of the logarithms is printed."""
    from compare._verify import edge_indicator, system_of
    from opa.engine import run_measure, surrogate, true_runs

    run = case["control"]
    system, options = system_of(run)
    measure = run_measure(run)
    edges = run.element_edges.values
    n = 4096 if len(case["counts"]) == 1 else 32768
    xi = measure.ppf((np.arange(n) + 0.5) / n)
    paths, _ = true_runs(system, options, xi, case["times"], what="grid point")
    d = paths[:, :, 0] - surrogate(run, xi, measure=measure)[0]
    which = np.clip(np.searchsorted(edges, xi, side="right") - 1, 0, len(edges) - 2)
    spread = np.array([np.sqrt(np.mean(np.var(d[which == k], axis=0)))
                       if np.sum(which == k) > 1 else np.nan for k in range(len(edges) - 1)])
    ends, _ = true_runs(system, options, edges, case["times"], what="element edge")
    misfit = edge_indicator(run.element_x_coef.values, edges, measure, ends[:, :, 0])
    ok = np.isfinite(spread) & (spread > 0) & (misfit > 0)
    r = float(np.corrcoef(np.log(spread[ok]), np.log(misfit[ok]))[0, 1])
    print(f"\nlog misfit at the ends against log spread inside, {ok.sum()} elements with "
          f"points: correlation {r:.3f}")
    assert r > 0.5


def test_error_against_true_runs(case):
    """The table: RMS error of E[x] against the reference, control variate and plain
    Sobol at the same number of true runs (one seed)."""
    ref = case["ref"].cv_x_mean.values
    print("\n| true runs | control variate | its RMS SE | plain Sobol | its RMS SE |")
    print("|---|---|---|---|---|")
    for M in case["counts"]:
        cv = verify(case["control"], samples=M, sequential=False, seed=2)
        plain = simulate_mc(case["osc"], sigma=0.05, samples=M, sampler="sobol", seed=2,
                            order=0, times=case["times"], progress=False)
        print(f"| {M} | {_rms(cv.cv_x_mean - ref):.2e} | {_rms(cv.cv_x_mean_sem):.2e} | "
              f"{_rms(plain.x_mean - ref):.2e} | {_rms(plain.x_sem):.2e} |")
        # the control variate is the better estimate at every M
        assert _rms(cv.cv_x_mean_sem) < _rms(plain.x_sem)


def test_calibration_over_seeds(case):
    """At M = 512 over many seeds: the RMS error (over seeds and outputs), the RMS
    standard error, and how often the 95 % t-interval holds the reference."""
    ref, M = case["ref"], case["calibrate"]
    errors, ses, hits = [], [], []
    for seed in range(100, 100 + case["seeds"]):
        cv = verify(case["control"], samples=M, sequential=False, seed=seed)
        err = cv.cv_x_mean.values - ref.cv_x_mean.values
        se = np.hypot(cv.cv_x_mean_sem.values, ref.cv_x_mean_sem.values)
        half = interval_halfwidth(se, cv.cv_x_mean_dof.values)
        errors.append(err)
        ses.append(cv.cv_x_mean_sem.values)
        hits.append(np.abs(err[1:]) <= half[1:])  # t = 0: every sample at x0, no noise
    errors, hits = np.array(errors), np.array(hits)
    per_seed = np.sqrt(np.mean(errors**2, axis=1))
    print(f"\n{case['seeds']} seeds at {M} true runs: RMS error {_rms(errors):.2e} "
          f"(per seed: median {np.median(per_seed):.2e}, largest {per_seed.max():.2e}), "
          f"RMS SE {_rms(ses):.2e}, coverage of the 95 % t-intervals {hits.mean():.3f} "
          f"(lowest output {hits.mean(axis=0).min():.2f})")
    assert _rms(errors) <= 3 * _rms(ses)  # the standard errors are of the right size


def test_certificate_timing(benchmark, case):
    M = case["calibrate"]
    benchmark.group = "certificate of the 64-element run"
    benchmark.pedantic(lambda: verify(case["control"], samples=M, sequential=False, seed=2),
                       rounds=3, iterations=1, warmup_rounds=1)
