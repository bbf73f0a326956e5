"""The rates behind the work budget's time term (:data:`opa._work.TIME_UNITS_PER_SECOND`,
:data:`opa._work.STEPS_PER_TIME_UNIT`): time units of slow forcing one core integrates per
second, and the solver's steps per time unit there.

    NUMBA_NUM_THREADS=1 python -m benchmarks.bench_time_rate

runs the paper's section 3.2 set (``preset("3.2")``, rtol = atol = 1e-9) at omega = 1e-5
and 1e-6, where one forcing period is 6.3e5 and 6.3e6 time units, over the first
``SPAN`` time units of the period, after one warm-up: the DMR and the OPA system of order
N = 4 (sigma = 0.01). The forcing there is quasi-static: it holds the mass on the wall and
every impulse (each 2 pi / omega1) starts a chatter, about 9 impacts per time unit. It
prints the time units per second of each, the OPA's per pair of states (times N + 1, the
budget's count), the steps per time unit, and the slowest rate and fewest steps: the
budget's constants are those, rounded down.
"""

from __future__ import annotations

import time

import numpy as np

from opa import SolverOptions, preset, simulate_dmr, simulate_opa

SPAN = 1.0e4
ORDER = 4


def rates() -> dict[tuple[str, float], tuple[float, float]]:
    """(model, omega): (time units per second per pair of states, steps per time unit)."""
    options = SolverOptions(rtol=1e-9, atol=1e-9)
    times = np.linspace(0.0, SPAN, 3)
    out = {}
    for omega in (1e-5, 1e-6):
        oscillator = preset("3.2", omega=omega)
        for model, pairs, run in (
                ("dmr", 1, lambda t: simulate_dmr(oscillator, times=t, options=options)),
                ("opa", ORDER + 1, lambda t: simulate_opa(oscillator, times=t, options=options,
                                                          sigma=0.01, order=ORDER))):
            run(times[:2] / 100)  # warm-up
            start = time.perf_counter()
            ds = run(times)
            seconds = time.perf_counter() - start
            out[model, omega] = (pairs * SPAN / seconds, ds.attrs["steps"] / SPAN)
    return out


def test_smoke_rate_is_positive():
    """The harness runs; no rate is read off it."""
    import benchmarks.bench_time_rate as b

    b.SPAN = 20.0
    try:
        assert all(r > 0 and s > 0 for r, s in rates().values())
    finally:
        b.SPAN = 1.0e4


if __name__ == "__main__":
    found = rates()
    for (model, omega), (rate, steps) in found.items():
        print(f"{model} omega = {omega:g}: {rate:.3g} time units per second per pair of "
              f"states, {steps:.3g} steps per time unit")
    print(f"slowest: {min(r for r, _ in found.values()):.3g} time units per second; fewest: "
          f"{min(s for _, s in found.values()):.3g} steps per time unit")
