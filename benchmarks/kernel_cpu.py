"""CPU seconds of the kernel's three kinds of runs, to hold its speed between two trees.

    NUMBA_NUM_THREADS=1 PYTHONPATH=TREE python benchmarks/kernel_cpu.py LABEL

Section 3.2 at omega = 3.98: one DMR trajectory of 1000 forcing periods, the OPA system of
N = 8 over 200 periods, and a Monte Carlo ensemble of 1000 random samples over 100
periods, each timed by ``time.process_time()`` after a warm-up call (compilation
excluded). Alternate two trees' runs under the same load (``benchmarks/alternate.sh``
does so for the map) and compare the medians.
"""

from __future__ import annotations

import sys
import time


def main(label: str) -> None:
    import mc
    from opa import preset, simulate_dmr, simulate_opa

    osc = preset("3.2", omega=3.98)
    simulate_dmr(osc, periods=5)
    simulate_opa(osc, sigma=0.01, order=8, periods=5)
    mc.simulate_mc(osc, samples=64, periods=2, sampler="random", seed=0)
    cases = {
        "dmr 1000 periods": lambda: simulate_dmr(osc, periods=1000),
        "opa N=8 200 periods": lambda: simulate_opa(osc, sigma=0.01, order=8, periods=200),
        "mc 1000 x 100 periods": lambda: mc.simulate_mc(osc, samples=1000, periods=100,
                                                        sampler="random", seed=0),
    }
    seconds = {}
    for name, run in cases.items():
        start = time.process_time()
        run()
        seconds[name] = time.process_time() - start
    print(label, "  ".join(f"{name}: {s:.3f} s" for name, s in seconds.items()))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "this tree")
