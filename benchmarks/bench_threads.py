"""The Monte Carlo kernel's rate per thread as threads are added (issue 29, item 2).

Problem: ``bench_peers.py``'s Monte Carlo case (section 3.2 at omega = 3.98, uncertain mu,
sigma = 0.01, random samples, 200 periods, one output a period, rtol = atol = 1e-8), with
2000 samples per thread, so each count of threads does the same work per thread. Two
ways of using n cores:

- ``threads``: one process, ``numba.set_num_threads(n)``, one ``mc.simulate_mc`` of 2000 n
  samples (the kernel's ``prange`` over each chunk's samples);
- ``processes``: n processes at one numba thread each, started together, each with its
  own 2000 samples (nothing shared: no chunking, no common cache lines, no scheduler).

If the rate per core falls as much with processes as with threads, the loss is the
machine's (clock under load, shared caches and memory, hyperthreads), not the kernel's
parallel loop. The table gives both rates, per core, and the efficiency against one
core. ``lscpu``'s cores per socket and threads per core are printed with it.

    python -m pytest -s benchmarks/bench_threads.py -m slow

The smoke run (CI) takes 64 samples per thread x 4 periods at 1 and 2.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

PER_THREAD, PERIODS = 2000, 200
SMOKE = (64, 4)

CHILD = """
import json, sys, time
import numba
numba.set_num_threads(1)
import mc, opa
osc = opa.preset("3.2", omega=3.98)
opts = opa.SolverOptions(rtol=1e-8, atol=1e-8)
samples, periods, seed, start_at = (int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]),
                                    float(sys.argv[4]))
mc.simulate_mc(osc, sigma=0.01, samples=64, sampler="random", seed=seed, periods=2,
               options=opts, progress=False)
while time.time() < start_at:
    time.sleep(0.001)
t = time.perf_counter()
mc.simulate_mc(osc, sigma=0.01, samples=samples, sampler="random", seed=seed,
               periods=periods, options=opts, progress=False)
print(json.dumps(time.perf_counter() - t))
"""


def _threads(n: int, per: int, periods: int) -> float:
    """Wall seconds of one process at n numba threads over n * per samples."""
    import numba

    import mc
    import opa

    osc = opa.preset("3.2", omega=3.98)
    opts = opa.SolverOptions(rtol=1e-8, atol=1e-8)
    numba.set_num_threads(n)
    mc.simulate_mc(osc, sigma=0.01, samples=64, sampler="random", seed=1, periods=2,
                   options=opts, progress=False)
    start = time.perf_counter()
    mc.simulate_mc(osc, sigma=0.01, samples=n * per, sampler="random", seed=0,
                   periods=periods, options=opts, progress=False)
    return time.perf_counter() - start


def _processes(n: int, per: int, periods: int) -> float:
    """The slowest of n single-thread processes, each over its own ``per`` samples, all
    started at the same moment after their warm-up."""
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1")
    start_at = time.time() + 8.0 + 0.5 * n
    procs = [subprocess.Popen([sys.executable, "-c", CHILD, str(per), str(periods), str(k),
                               str(start_at)], env=env, stdout=subprocess.PIPE, text=True)
             for k in range(n)]
    times = []
    for p in procs:
        out, _ = p.communicate(timeout=600)
        assert p.returncode == 0
        times.append(json.loads(out.strip().splitlines()[-1]))
    return max(times)


def _rates(counts, per, periods) -> dict:
    """{(mode, n): trajectory-periods per second} for both ways of using n cores."""
    return {(mode, n): n * per * periods / fn(n, per, periods)
            for n in counts for mode, fn in (("threads", _threads), ("processes", _processes))}


def _table(rates: dict) -> str:
    lines = ["| cores | threads: traj-periods/s | per core | efficiency | processes: "
             "traj-periods/s | per core | efficiency |", "|---|---|---|---|---|---|---|"]
    counts = sorted({n for _, n in rates})
    for n in counts:
        cells = []
        for mode in ("threads", "processes"):
            rate, base = rates[(mode, n)], rates[(mode, counts[0])] / counts[0]
            cells.append(f"{rate:.3g} | {rate / n:.3g} | {rate / n / base:.2f}")
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _lscpu() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
    except OSError:
        return "lscpu not found"
    keep = ("Model name", "Thread(s) per core", "Core(s) per socket", "Socket(s)", "CPU(s)")
    return "; ".join(line.strip() for line in out.splitlines()
                     if line.split(":")[0].strip() in keep)


def _counts(cores: int) -> list[int]:
    """1, 2, 4, ... up to the cores, or the counts in $THREAD_COUNTS (e.g. "1,16")."""
    if os.environ.get("THREAD_COUNTS"):
        return sorted({int(n) for n in os.environ["THREAD_COUNTS"].split(",")})
    return sorted({n for n in (1, 2, 4, 8, 16, 32, 64) if n <= cores} | {cores})


def test_threads_smoke():
    per, periods = SMOKE
    rates = _rates([1, 2], per, periods)
    print("\n" + _table(rates))
    assert set(rates) == {(m, n) for m in ("threads", "processes") for n in (1, 2)}
    assert all(0.0 < r < float("inf") for r in rates.values())


@pytest.mark.slow
def test_threads_scaling():
    from opa.engine import usable_cores

    cores = usable_cores()
    text = _table(_rates(_counts(cores), PER_THREAD, PERIODS))
    print(f"\n{_lscpu()}\nload average {os.getloadavg()[0]:.2f} after the runs\n{text}")
