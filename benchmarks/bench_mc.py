"""Throughput of the Monte Carlo engine in trajectory-periods per second, against scipy.

Problem (issue 5, item 7): section 3.2 parameters at omega = 3.98 with the default Dirac
impulse train, uncertain mu with sigma = 0.01, Sobol' samples (seed 0), stroboscopic output
(``per_period = 1``), rtol = atol = 1e-8. One trajectory-period is one sample advanced
over one forcing period 2 pi / omega.

- ``test_mc_throughput``: ``mc.simulate_mc`` on 2 numba threads, 2^14 samples x 100
  periods (2^8 x 10 in smoke mode), after a warm-up ensemble; best of 3 rounds.
- ``test_scipy_throughput[RK45|DOP853]``: a lean event-driven loop around ``solve_ivp``
  (``scipy_sample`` below: impulse times as breakpoints, a terminal event on x = delta,
  restart after each impact, no ``max_step``) on the first 4 samples of the same ensemble
  (1 in smoke mode), one core, extrapolated to trajectory-periods per second. Stores the
  engine/scipy ratio; the engine runs on 2 cores, scipy on one, so ``ratio_per_core`` is
  the ratio halved.
- ``test_million_samples_memory_is_bounded`` (slow): 10^6 samples x 100 periods without
  ``keep_paths``; checks the traced peak and the growth of the resident set against the
  1.6 GB that the paths alone would take.

Measured on the 2-core development container while other jobs ran (load ~3.5, so the
engine did not have both cores to itself): engine 4.9e4 trajectory-periods/s (187 rhs
evaluations per trajectory-period), scipy RK45 189 and DOP853 397 (169 and 151 rhs
evaluations): ratios 257x and 122x (129x and 61x per core). The issue's target of 1.5e5
is not reached: one DMR run at this tolerance takes ~780 ns per step, 4.3e4
trajectory-periods/s on one core. 10^6 samples x 10 periods (load ~4): 334 s, traced
peak 71 MiB, resident-set growth 75 MiB (~75 bytes a sample), against 168 MiB for the
paths; the 100-period run adds only one larger chunk of paths (6.6 MB).

Run ``pytest benchmarks/bench_mc.py -s`` for the numbers (``-m slow`` for the 10^6 run);
CI runs the smoke mode, ``pytest benchmarks -m "not slow" --benchmark-disable``.
"""

from __future__ import annotations

import os
import resource
import time
import tracemalloc

import numba
import numpy as np
import pytest

import mc
import opa
from benchmarks.bench_dmr import scipy_dmr

OSCILLATOR = opa.preset("3.2", omega=3.98)
SIGMA = 0.01
TOL = 1e-8
OPTIONS = opa.SolverOptions(rtol=TOL, atol=TOL)
THREADS = 2
SCIPY_METHODS = ("RK45", "DOP853")
# issue 5: at least 1.5e5 trajectory-periods/s on 2 cores, stretch 5e5
TARGET, STRETCH = 1.5e5, 5e5

_RESULTS: dict[str, dict] = {}  # the engine's measurement, for the scipy ratio


def is_smoke(config: pytest.Config) -> bool:
    """Smoke mode: ``--benchmark-disable`` or ``CI=true`` (as in ``conftest.py``)."""
    disabled = config.getoption("benchmark_disable") and not config.getoption("benchmark_enable")
    return bool(disabled) or os.environ.get("CI", "").lower() in ("1", "true", "yes")


@pytest.fixture(scope="module")
def sizes(request) -> dict:
    if is_smoke(request.config):
        return dict(samples=2**8, periods=10, scipy_samples=1, rounds=1)
    return dict(samples=2**14, periods=100, scipy_samples=4, rounds=3)


@pytest.fixture()
def two_threads():
    """Run the engine on 2 numba threads (fewer if numba has fewer); restore afterwards."""
    before = numba.get_num_threads()
    numba.set_num_threads(min(THREADS, numba.config.NUMBA_NUM_THREADS))
    yield numba.get_num_threads()
    numba.set_num_threads(before)


def run_engine(samples: int, periods: int) -> tuple[float, object]:
    start = time.perf_counter()
    ds = mc.simulate_mc(OSCILLATOR, sigma=SIGMA, samples=samples, sampler="sobol", seed=0,
                        periods=periods, per_period=1, options=OPTIONS, progress=False)
    return time.perf_counter() - start, ds


def record_engine(sizes: dict, runs: list) -> dict:
    """Best-of-rounds throughput from ``[(seconds, dataset), ...]``, kept for the session."""
    seconds = min(s for s, _ in runs)
    ds = runs[0][1]
    work = sizes["samples"] * sizes["periods"]
    _RESULTS["mc"] = dict(
        seconds=seconds, xi=ds.xi.values, throughput=work / seconds,
        rhs_per_period=ds.attrs["rhs_evaluations"] / work,
        finite=bool(np.isfinite(ds.x_mean.values).all()),
    )  # fmt: skip
    return _RESULTS["mc"]


def engine_throughput(sizes: dict) -> dict:
    """The engine's measurement of this session (run now if its benchmark did not run)."""
    if "mc" not in _RESULTS:
        run_engine(64, 2)  # load the compiled kernel and start the thread pool
        record_engine(sizes, [run_engine(sizes["samples"], sizes["periods"])
                              for _ in range(sizes["rounds"])])  # fmt: skip
    return _RESULTS["mc"]


# --------------------------------------------------------------------------- scipy loop


def scipy_sample(osc: opa.Oscillator, mu: float, periods: int, method: str, rtol: float,
                 atol: float):  # fmt: skip
    """Stroboscopic x of eq. (1) for one value of mu with ``solve_ivp`` (the lean loop of
    ``bench_dmr.scipy_dmr``). Returns ``(x at t_j = j 2 pi / omega, rhs evaluations)``."""
    _, x, _, _, nfev = scipy_dmr(osc.replace(mu=mu), periods, method, rtol, atol)
    return x, nfev


# --------------------------------------------------------------------------- benchmarks


def test_mc_throughput(benchmark, sizes, two_threads, capsys):
    """Trajectory-periods per second of ``mc.simulate_mc`` on 2 threads (a report: the
    issue's targets are stored, not asserted, since they depend on the machine)."""
    benchmark.group = "mc throughput"
    run_engine(64, 2)  # load the compiled kernel and start the thread pool
    runs = []

    def run():
        runs.append(run_engine(sizes["samples"], sizes["periods"]))

    benchmark.pedantic(run, rounds=sizes["rounds"], iterations=1)
    measured = record_engine(sizes, runs)
    throughput = measured["throughput"]
    assert measured["finite"]
    benchmark.extra_info.update(
        samples=sizes["samples"], periods=sizes["periods"], threads=two_threads, rtol=TOL,
        sigma=SIGMA, trajectory_periods_per_s=throughput,
        rhs_evaluations_per_trajectory_period=measured["rhs_per_period"],
        target=TARGET, stretch_target=STRETCH, meets_target=throughput >= TARGET,
    )  # fmt: skip
    with capsys.disabled():
        print(f"\nmc engine, {sizes['samples']} samples x {sizes['periods']} periods, "
              f"{two_threads} threads, rtol = atol = {TOL:g}: {throughput:.3g} "
              f"trajectory-periods/s ({measured['rhs_per_period']:.0f} rhs evaluations per "
              f"trajectory-period; target {TARGET:.1e}, stretch {STRETCH:.1e})")


@pytest.mark.parametrize("method", SCIPY_METHODS)
def test_scipy_throughput(benchmark, sizes, two_threads, method, capsys):
    """The lean scipy loop on the first samples of the engine's ensemble, extrapolated;
    checks both solve the same problem (10 periods, before the motion is sensitive)."""
    engine = engine_throughput(sizes)
    periods, count = sizes["periods"], sizes["scipy_samples"]
    mus = OSCILLATOR.mu + SIGMA * engine["xi"][:count]

    def run():
        start = time.perf_counter()
        results = [scipy_sample(OSCILLATOR, mu, periods, method, TOL, TOL) for mu in mus]
        return time.perf_counter() - start, results

    benchmark.group = "mc throughput"
    seconds, results = benchmark.pedantic(run, rounds=1, iterations=1)
    throughput = count * periods / seconds
    ratio = engine["throughput"] / throughput
    nfev = sum(n for _, n in results) / (count * periods)
    early = 10 + 1
    worst = 0.0
    for mu, (x, _) in zip(mus, results):
        ours = opa.simulate_dmr(OSCILLATOR.replace(mu=mu), periods=periods, options=OPTIONS)
        worst = max(worst, float(np.abs(ours.x.values[:early] - x[:early]).max()))
    benchmark.extra_info.update(
        solver=f"scipy solve_ivp {method}", samples=count, periods=periods, rtol=TOL,
        trajectory_periods_per_s=throughput, rhs_evaluations_per_trajectory_period=nfev,
        engine_trajectory_periods_per_s=engine["throughput"], engine_threads=two_threads,
        ratio=ratio, ratio_per_core=ratio / two_threads, x_difference_first_10_periods=worst,
    )  # fmt: skip
    with capsys.disabled():
        print(f"\nscipy {method}, {count} samples x {periods} periods: {throughput:.3g} "
              f"trajectory-periods/s ({nfev:.0f} rhs evaluations per trajectory-period); "
              f"engine/scipy {ratio:.0f}x ({ratio / two_threads:.0f}x per core); "
              f"max |x difference| over the first 10 periods {worst:.1e}")
    assert worst < 1e-5
    assert ratio > 1.0


@pytest.mark.slow
def test_million_samples_memory_is_bounded(benchmark, request, two_threads, capsys):
    """10^6 samples x 100 periods (2^14 x 100 in smoke mode), statistics only.

    The paths would take M (P + 1) 2 8 bytes = 1.6 GB. The engine keeps one chunk of
    paths (by default 4096 samples at 101 output times: 6.6 MB) and O(M) vectors (xi,
    weights, replicate labels, impact counts). Asserted: the traced peak (numpy) and the
    growth of the resident set stay within 3 chunks of paths + 256 bytes a sample
    (+ 64 MiB allocator slack for the resident set): 276 MB at M = 10^6.
    """
    samples, periods = (2**14, 100) if is_smoke(request.config) else (10**6, 100)
    all_paths = samples * (periods + 1) * 2 * 8
    run_engine(64, 2)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # KiB on Linux
    tracemalloc.start()
    try:
        seconds, ds = benchmark.pedantic(run_engine, args=(samples, periods), rounds=1,
                                         iterations=1)  # fmt: skip
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    rss_growth = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - rss_before
    throughput = samples * periods / seconds
    benchmark.extra_info.update(
        samples=samples, periods=periods, threads=two_threads, seconds=seconds,
        trajectory_periods_per_s=throughput, traced_peak_bytes=peak,
        max_rss_growth_bytes=rss_growth, all_paths_bytes=all_paths,
        rhs_evaluations_per_trajectory_period=ds.attrs["rhs_evaluations"] / (samples * periods),
    )  # fmt: skip
    with capsys.disabled():
        print(f"\n{samples} samples x {periods} periods: {seconds:.0f} s ({throughput:.3g} "
              f"trajectory-periods/s), traced peak {peak / 2**20:.1f} MiB, max RSS growth "
              f"{rss_growth / 2**20:.1f} MiB (all paths: {all_paths / 2**20:.0f} MiB)")
    for name in ("x_mean", "v_mean", "x_var", "x_sem", "x_coef"):
        assert np.isfinite(ds[name].values).all(), name
    assert "x" not in ds
    budget = 3 * min(samples, 4096) * (periods + 1) * 2 * 8 + 256 * samples
    assert peak < budget
    assert rss_growth < budget + 64 * 2**20
