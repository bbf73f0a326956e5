"""Speed of a bifurcation diagram: the paper's Fig. 3 sweep against scipy's ``solve_ivp``.

Problem (issue 7): the DMR of the section 3.1 set (Dirac impulses, F0 = 0.1) for 200
values of c in [0.01, 0.1]; per value 500 transient and 100 recorded forcing periods,
both Poincaré sections (stroboscopic points, and impacts with 16 outputs per period in
the record for grazing), period/label identification; rtol = atol = 1e-10; 2 worker
processes. Smoke mode (``--benchmark-disable`` or ``CI=true``): 10 values, 50 + 20
periods.

- ``test_fig3_sweep_warm``: ``opa.sweep`` on a process pool that is already started and
  has the kernel loaded (numba cache warm): the steady-state cost of a diagram.
- ``test_fig3_sweep_cold``: the same with a fresh pool (start-up of the fork server and
  loading the kernel from numba's cache included): what ``opa-mc bifurcation`` pays.
- ``test_fig3_sweep_cpu_seconds``: the sweep's CPU time (one process), divided by the 2
  workers: the warm-pool time on 2 idle cores, free of other load on a shared machine.
- ``test_fig3_scipy_extrapolated``: ``solve_ivp`` (DOP853 and RK45) on a few values of c
  with the event-driven loop of ``bench_dmr.scipy_dmr``, extrapolated to the whole
  sweep on 2 cores as ``(mean seconds per value) * values / 2`` (perfect parallelism,
  which favours scipy).
- ``test_fig3_report``: prints the table (ours warm/cold, scipy extrapolated, ratios,
  the 5 s target) and checks ours is faster.

Run ``pytest benchmarks/bench_bifurcation.py -s`` for the numbers.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import opa
from benchmarks.bench_dmr import scipy_dmr
from benchmarks.conftest import smoke_mode
from opa import sweep
from opa.dynamics._sweep import local_executor
from opa.dynamics._sections import detect_period

OSCILLATOR = opa.preset("3.1")
RTOL = ATOL = 1e-10
OPTIONS = opa.SolverOptions(rtol=RTOL, atol=ATOL)
WORKERS = 2
FULL = {"values": 200, "transient": 500, "record": 100}
SMOKE = {"values": 10, "transient": 50, "record": 20}
TARGET_S = 5.0
REPO = Path(__file__).resolve().parents[1]

_SECONDS: dict[str, float] = {}


@pytest.fixture(scope="module")
def size(request) -> dict:
    return SMOKE if smoke_mode(request.config) else FULL


@pytest.fixture(scope="module")
def warm_pool():
    """Two worker processes, started and with the kernel loaded, before any timing."""
    pool = local_executor(WORKERS)
    sweep("dmr", "c", [0.02, 0.05], OSCILLATOR, transient=2, record=2, executor=pool,
          options=OPTIONS)
    yield pool
    pool.shutdown()


def fig3(size, **kw):
    values = np.linspace(0.01, 0.1, size["values"])
    return sweep("dmr", "c", values, OSCILLATOR, transient=size["transient"],
                 record=size["record"], per_period=16, options=OPTIONS, **kw)


def test_fig3_sweep_warm(benchmark, size, warm_pool):
    def run():
        start = time.perf_counter()
        ds = fig3(size, executor=warm_pool)
        _SECONDS["warm"] = min(_SECONDS.get("warm", np.inf), time.perf_counter() - start)
        return ds

    rounds = 1 if size is SMOKE else 3
    ds = benchmark.pedantic(run, rounds=rounds, iterations=1)
    assert ds.sizes["c"] == size["values"] and not ds.failed.any()
    assert np.isfinite(ds.section_x.values[:, : size["record"]]).all()
    benchmark.extra_info.update(values=size["values"], transient=size["transient"],
                                record=size["record"], workers=WORKERS, rtol=RTOL,
                                labels=sorted(set(ds.label.values.tolist())))


_COLD = """
import json, sys, time
start = time.perf_counter()
import numpy as np
import opa
from opa import sweep
imported = time.perf_counter()
size = json.loads(sys.argv[1])
ds = sweep("dmr", "c", np.linspace(0.01, 0.1, size["values"]), opa.preset("3.1"),
           transient=size["transient"], record=size["record"], per_period=16, workers=2)
done = time.perf_counter()
print(json.dumps(dict(import_s=imported - start, sweep_s=done - imported)))
"""


@pytest.mark.slow  # a new interpreter: not part of the CI smoke run
def test_fig3_sweep_cold(benchmark, size, warm_pool):
    """In a new interpreter: the pool's fork server starts and loads the kernel from
    numba's (warm) cache, as for ``opa-mc bifurcation``."""

    def run():
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", _COLD, json.dumps(size)], cwd=REPO,
                              check=True, capture_output=True, text=True, timeout=600)
        result = json.loads(done.stdout.strip().splitlines()[-1])
        result["process_s"] = time.perf_counter() - start
        _SECONDS["cold"] = result["sweep_s"]
        _SECONDS["process"] = result["process_s"]
        return result

    result = benchmark.pedantic(run, rounds=1, iterations=1)
    benchmark.extra_info.update(result)


def test_fig3_sweep_cpu_seconds(benchmark, size, warm_pool):
    """The same sweep in this process, one value after the other: its CPU time divided by
    the 2 workers is what the warm sweep takes on 2 otherwise idle cores (on a shared
    machine the wall-clock numbers above also measure the other load)."""

    def run():
        start = time.process_time()
        fig3(size, workers=1)
        _SECONDS["cpu"] = time.process_time() - start
        return _SECONDS["cpu"]

    cpu = benchmark.pedantic(run, rounds=1, iterations=1)
    benchmark.extra_info.update(cpu_s=cpu, ideal_two_core_s=cpu / WORKERS)


def scipy_point(c: float, size: dict, method: str) -> float:
    """Seconds for one value of c: the whole trajectory plus both sections and the label."""
    osc = OSCILLATOR.replace(c=c)
    start = time.perf_counter()
    t, x, v, impacts, _ = scipy_dmr(osc, size["transient"] + size["record"], method, RTOL,
                                    ATOL)
    k0 = size["transient"] + 1
    detect_period(x[k0:], v[k0:])  # the sweep's own reduction, negligible
    np.mod(osc.omega * impacts[impacts > t[k0 - 1]], 2 * np.pi)
    return time.perf_counter() - start


@pytest.mark.parametrize("method", ["DOP853", "RK45"])
def test_fig3_scipy_extrapolated(benchmark, size, method):
    cs = [0.01, 0.055, 0.1] if size is FULL else [0.05]

    def run():
        per_value = np.mean([scipy_point(c, size, method) for c in cs])
        _SECONDS[method] = per_value * size["values"] / WORKERS
        return per_value

    per_value = benchmark.pedantic(run, rounds=1, iterations=1)
    benchmark.extra_info.update(method=method, sampled_values=cs, seconds_per_value=per_value,
                                extrapolated_sweep_s=_SECONDS[method])


def test_fig3_report(size, warm_pool, capsys):
    """A report: ours against the scipy extrapolation; only "ours is faster" is checked."""
    if "warm" not in _SECONDS:
        start = time.perf_counter()
        fig3(size, executor=warm_pool)
        _SECONDS["warm"] = time.perf_counter() - start
    for method in ("DOP853", "RK45"):
        if method not in _SECONDS:
            _SECONDS[method] = scipy_point(0.05, size, method) * size["values"] / WORKERS
    warm = _SECONDS["warm"]
    lines = [(f"Fig. 3 sweep: DMR, set 3.1, {size['values']} values of c, "
             f"{size['transient']} + {size['record']} periods, both sections, rtol = atol = "
             f"{RTOL:g}, {WORKERS} workers"),
             f"  opa sweep, warm pool        {warm:8.2f} s"
             + (f"   (target {TARGET_S:g} s: {'met' if warm <= TARGET_S else 'missed'})"
                if size is FULL else "")]
    if "cpu" in _SECONDS:
        lines.append(f"  opa sweep, CPU time / {WORKERS}     {_SECONDS['cpu'] / WORKERS:8.2f} s   "
                     f"(2 idle cores; CPU {_SECONDS['cpu']:.2f} s, "
                     f"{1e3 * _SECONDS['cpu'] / size['values']:.0f} ms per value)")
    if "cold" in _SECONDS:
        lines.append(f"  opa sweep, fresh pool       {_SECONDS['cold']:8.2f} s   (new process: "
                     f"{_SECONDS['process']:.2f} s with imports)")
    for method in ("DOP853", "RK45"):
        theirs = _SECONDS[method]
        lines.append(f"  scipy {method:<6} extrapolated {theirs:8.1f} s   ratio "
                     f"{theirs / warm:6.0f}x")
        assert warm < theirs
    with capsys.disabled():
        print("\n" + "\n".join(lines))
