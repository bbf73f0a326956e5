"""The rate behind the work budget (:data:`opa._work.PERIODS_PER_SECOND`): forcing periods
of deterministic impact systems one core integrates per second.

    NUMBA_NUM_THREADS=1 python -m benchmarks.bench_work_rate

runs 256 sampled systems of the default map's model (preset 3.2 at omega = 3.98, 4.09 and
4.2, mu = 0.8 + 0.02 xi, rtol = atol = 1e-9) over 100 forcing periods, 8 outputs per
period, after one warm-up, and prints the periods per second of each omega and the
slowest. The budget's rate is the slowest, rounded down.
"""

from __future__ import annotations

import time

import numpy as np

from compare._config import load_config
from opa.engine import SolverOptions, time_grid, true_runs

PERIODS = 100
SAMPLES = 256


def rates() -> dict[float, float]:
    cfg = load_config(None)
    options = SolverOptions(rtol=1e-9, atol=1e-9)
    xi = np.linspace(-0.99, 0.99, SAMPLES)
    out = {}
    for omega in (3.98, 4.09, 4.2):
        system = cfg.system_at(omega, sigma=0.02, order=0)
        times = time_grid(omega, PERIODS, 8)
        true_runs(system, options, xi[:4], times[:9], what="warm-up")
        start = time.perf_counter()
        true_runs(system, options, xi, times, what="rate")
        out[omega] = SAMPLES * PERIODS / (time.perf_counter() - start)
    return out


def test_smoke_rate_is_positive():
    """The harness runs; no rate is read off it."""
    import benchmarks.bench_work_rate as b

    b.PERIODS, b.SAMPLES = 2, 8
    try:
        assert all(r > 0 for r in rates().values())
    finally:
        b.PERIODS, b.SAMPLES = 100, 256


if __name__ == "__main__":
    found = rates()
    for omega, rate in found.items():
        print(f"omega = {omega:g}: {rate:.3g} periods per second")
    print(f"slowest: {min(found.values()):.3g} periods per second")
