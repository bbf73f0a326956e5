"""Control variates on the OPA surrogate against plain scrambled Sobol, per true run.

Section 3.2, omega = 3.98, sigma = 0.05, 10 forcing periods, 8 outputs per period
(issue 25's target case): the 64-element adaptive ME-OPA (saltation law, N = 1) is the
control; ``compare.verify(run, samples=M, sequential=False)`` gives E_cv[x] from M true
systems, and a plain Sobol ensemble of the same M (``mc.simulate_mc``) gives E[x]. Both
against a 2^16-sample Sobol reference (seed 1; the runs use other seeds). The table of
RMS errors against M is printed (``-s``); the timing is of one certificate at M = 512.

    python -m pytest -s benchmarks/bench_verify.py

The smoke mode (CI) runs 2 periods, 16 elements, M = 64 and a 4096-sample reference.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from benchmarks.conftest import smoke_mode
from compare import verify
from mc import simulate_mc
from opa import Oscillator, simulate_opa
from opa._elements import ElementBudgetWarning
from opa._model import time_grid


@pytest.fixture(scope="module")
def case(request):
    smoke = smoke_mode(request.config)
    periods, budget, counts, reference = ((2, 16, (64,), 4096) if smoke else
                                          (10, 64, (128, 256, 512, 1024, 2048), 65536))
    osc = Oscillator(omega=3.98)
    times = time_grid(3.98, periods, 8)
    ref = simulate_mc(osc, sigma=0.05, samples=reference, sampler="sobol", seed=1, order=0,
                      times=times, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ElementBudgetWarning)
        control = simulate_opa(osc, sigma=0.05, order=1, elements="adaptive",
                               max_elements=budget, times=times)
    return dict(osc=osc, times=times, ref=ref, control=control, counts=counts)


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.asarray(a) ** 2)))


def test_error_against_true_runs(case):
    """The table: RMS error of E[x] against the reference, control variate and plain
    Sobol at the same number of true runs, with the reference's own noise."""
    ref = case["ref"].x_mean.values
    print(f"\nreference noise (RMS SE of the 2^16 run): {_rms(case['ref'].x_sem):.2g}")
    print("| true runs | control variate | its RMS SE | plain Sobol | its RMS SE |")
    print("|---|---|---|---|---|")
    for M in case["counts"]:
        cv = verify(case["control"], samples=M, sequential=False, seed=2)
        plain = simulate_mc(case["osc"], sigma=0.05, samples=M, sampler="sobol", seed=2,
                            order=0, times=case["times"], progress=False)
        print(f"| {M} | {_rms(cv.cv_x_mean - ref):.2e} | {_rms(cv.cv_x_mean_sem):.2e} | "
              f"{_rms(plain.x_mean - ref):.2e} | {_rms(plain.x_sem):.2e} |")
        # the control variate is the better estimate at every M
        assert _rms(cv.cv_x_mean_sem) < _rms(plain.x_sem)


def test_certificate_timing(benchmark, case):
    M = case["counts"][min(2, len(case["counts"]) - 1)]
    benchmark.group = "certificate of the 64-element run"
    benchmark.pedantic(lambda: verify(case["control"], samples=M, sequential=False, seed=2),
                       rounds=3, iterations=1, warmup_rounds=1)
