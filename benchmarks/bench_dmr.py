"""Speed of one DMR trajectory: the compiled solver against scipy's ``solve_ivp``.

Problem: section 3.2 parameters at omega = 3.98 with the default Dirac impulse train,
x0 = -1, v0 = 0, stroboscopic output (one point per forcing period), rtol = atol = 1e-10,
1000 forcing periods (50 in smoke mode, see ``conftest.py``).

- ``test_dmr_opa``: ``opa.simulate_dmr`` with the numba kernel already compiled and
  loaded (compile time is measured separately in ``test_numba_compile_time``).
- ``test_dmr_scipy[RK45|DOP853]``: a lean event-driven loop around ``solve_ivp`` written
  for this benchmark (``scipy_dmr`` below): the same breakpoints (impulse times), a
  terminal event on ``x = delta``, restart after each impact, no ``max_step``. RK45 is
  the same Dormand-Prince 5(4) pair as ours; DOP853 is scipy's best choice at 1e-10.
- ``test_speed_ratio``: prints ours against each scipy method and checks ours is faster.

Run ``pytest benchmarks`` for the numbers, ``pytest benchmarks -s`` to see the printed
report; CI runs ``pytest benchmarks -m "not slow" --benchmark-disable``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import opa

OSCILLATOR = opa.preset("3.2", omega=3.98)
RTOL = ATOL = 1e-10
OPTIONS = opa.SolverOptions(rtol=RTOL, atol=ATOL)
SCIPY_METHODS = ("RK45", "DOP853")
REPO = Path(__file__).resolve().parents[1]

# Wall-clock seconds of the scipy runs of this session, keyed by (method, periods), so
# that test_speed_ratio need not run them again.
_SCIPY_SECONDS: dict[tuple[str, int], float] = {}


# --------------------------------------------------------------------------- scipy loop


def scipy_dmr(osc: opa.Oscillator, periods: int, method: str, rtol: float, atol: float):
    """Stroboscopic states and impacts of eq. (1) with Dirac kicks, by ``solve_ivp``.

    Kicks at ``t_j = j 2 pi / omega1`` (j = 0, 1, ...) add ``F0 (1 + a1 sin(omega1 t_j / n))``
    to the velocity; outputs are right-continuous like ``opa.simulate_dmr``'s. Returns
    ``(t, x, v, impact_times, rhs_evaluations)``.
    """
    mu, a, c, f, omega = osc.mu, osc.a, osc.c, osc.f, osc.omega
    delta, eta = osc.delta, osc.eta
    t_out = np.arange(periods + 1) * (2 * math.pi / omega)
    t_end = t_out[-1]
    T1 = 2 * math.pi / osc.omega1
    kicks = np.arange(math.floor(t_end / T1) + 1) * T1
    bounds = np.unique(np.concatenate([kicks, [t_end]]))
    x_out, v_out = np.empty_like(t_out), np.empty_like(t_out)
    impacts = []
    nfev = 0

    def rhs(t, y):
        x, v = y
        return [v, mu * (1.0 - v * v) * v - a * x - c * x * x * x + f * math.cos(omega * t)]

    y = np.array([osc.x0, osc.v0])
    for k, t0 in enumerate(bounds):
        if t0 in kicks:
            y[1] += osc.F0 * (1.0 + osc.a1 * math.sin(osc.omega1 * t0 / osc.n))
            if y[0] >= delta and y[1] > 0.0:
                impacts.append(t0)
                y[1] = -eta * y[1]
        here = t_out == t0
        x_out[here], v_out[here] = y
        if k == len(bounds) - 1:
            break
        t1 = bounds[k + 1]
        while True:
            inside = np.flatnonzero((t_out > t0) & (t_out < t1))
            start = t0

            def hit_wall(t, y, start=start):
                # -1 at the start: a restart from the wall must not see that impact again
                return y[0] - delta if t > start else -1.0

            hit_wall.terminal, hit_wall.direction = True, 1.0
            # t1 is appended to the outputs so that the end state comes back too
            sol = solve_ivp(rhs, (t0, t1), y, method=method, rtol=rtol, atol=atol,
                            events=hit_wall, t_eval=np.append(t_out[inside], t1))
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed at t = {sol.t[-1]}: {sol.message}")
            nfev += sol.nfev
            reached = inside[: len(sol.t)]
            if reached.size:
                x_out[reached], v_out[reached] = np.asarray(sol.y)[:, : reached.size]
            if sol.status == 0:
                y = sol.y[:, -1].copy()
                break
            t0 = sol.t_events[0][0]
            impacts.append(t0)
            y = np.array([delta, -eta * sol.y_events[0][0][1]])
    return t_out, x_out, v_out, np.array(impacts), nfev


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def warm_kernel():
    """Compile (or load from numba's cache) before anything is timed."""
    opa.simulate_dmr(OSCILLATOR, periods=1, options=OPTIONS)


# --------------------------------------------------------------------------- benchmarks


def test_dmr_opa(benchmark, periods, warm_kernel):
    ds = benchmark(opa.simulate_dmr, OSCILLATOR, periods=periods, options=OPTIONS)
    assert ds.x.sizes["time"] == periods + 1 and np.isfinite(ds.x).all()
    benchmark.extra_info.update(
        solver="opa (numba, Dormand-Prince 5(4))", periods=periods, rtol=RTOL, atol=ATOL,
        steps=int(ds.attrs["steps"]), rhs_evaluations=int(ds.attrs["rhs_evaluations"]),
        impacts=int(ds.impact_time.size),
    )


@pytest.mark.parametrize("method", SCIPY_METHODS)
def test_dmr_scipy(benchmark, periods, method):
    def run():
        start = time.perf_counter()
        result = scipy_dmr(OSCILLATOR, periods, method, RTOL, ATOL)
        _SCIPY_SECONDS[method, periods] = time.perf_counter() - start
        return result

    t, x, v, impacts, nfev = benchmark.pedantic(run, rounds=1, iterations=1)
    assert np.isfinite(x).all() and x.max() <= OSCILLATOR.delta
    benchmark.extra_info.update(
        solver=f"scipy solve_ivp {method}", periods=periods, rtol=RTOL, atol=ATOL,
        rhs_evaluations=int(nfev), impacts=int(impacts.size),
    )


def test_scipy_loop_solves_the_same_problem(warm_kernel):
    """Guards the comparison: over 20 periods (motion not yet sensitive, amplification
    ~15) both scipy methods agree with ours to the tolerance level."""
    ours = opa.simulate_dmr(OSCILLATOR, periods=20, options=OPTIONS)
    for method in SCIPY_METHODS:
        t, x, v, impacts, _ = scipy_dmr(OSCILLATOR, 20, method, RTOL, ATOL)
        np.testing.assert_allclose(t, ours.time, rtol=1e-15)
        np.testing.assert_allclose(x, ours.x, rtol=0, atol=1e-6)
        np.testing.assert_allclose(v, ours.v, rtol=0, atol=1e-6)
        np.testing.assert_allclose(impacts, ours.impact_time, rtol=0, atol=1e-6)


def best_of(repeats: int, fn) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def test_speed_ratio(periods, warm_kernel, capsys):
    """A report, not a threshold: ours (best of 3) against one run of each scipy method.

    Only "ours is faster" is asserted; the ratio itself depends on the machine.
    """
    ours = best_of(3, lambda: opa.simulate_dmr(OSCILLATOR, periods=periods, options=OPTIONS))
    lines = [f"DMR, section 3.2, omega = 3.98, Dirac impulses, {periods} periods, "
             f"rtol = atol = {RTOL:g}", f"  opa (numba DP5(4)) {ours:9.4f} s"]
    for method in SCIPY_METHODS:
        if (method, periods) not in _SCIPY_SECONDS:
            start = time.perf_counter()
            scipy_dmr(OSCILLATOR, periods, method, RTOL, ATOL)
            _SCIPY_SECONDS[method, periods] = time.perf_counter() - start
        theirs = _SCIPY_SECONDS[method, periods]
        lines.append(f"  scipy {method:<12} {theirs:9.4f} s   ratio {theirs / ours:7.1f}x")
        assert ours < theirs, f"opa {ours:.3g} s is not faster than {method} {theirs:.3g} s"
    with capsys.disabled():
        print("\n" + "\n".join(lines))


# --------------------------------------------------------------------------- compile time

_STARTUP = textwrap.dedent(
    """
    import json, time
    start = time.perf_counter()
    import opa
    imported = time.perf_counter()
    opa.simulate_dmr(periods=1)
    first = time.perf_counter()
    opa.simulate_dmr(periods=1)
    second = time.perf_counter()
    print(json.dumps(dict(import_s=imported - start, first_call_s=first - imported,
                          warm_call_s=second - first)))
    """
)


def fresh_process_startup(cache_dir: Path) -> dict:
    """Time ``import opa`` and the first ``simulate_dmr`` in a new interpreter."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _STARTUP], env=env, cwd=REPO, check=True,
                          capture_output=True, text=True, timeout=600)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    result["process_s"] = time.perf_counter() - start
    return result


@pytest.mark.slow
def test_numba_compile_time(benchmark, tmp_path, capsys):
    """Cold compile (empty NUMBA_CACHE_DIR) against a cache hit (same directory again).

    The compile time is the first call minus a warm call; the benchmark table shows the
    whole cached start-up (new interpreter, import, first call).
    """
    cold = fresh_process_startup(tmp_path)
    cached = benchmark.pedantic(fresh_process_startup, args=(tmp_path,), rounds=1,
                                iterations=1)
    compile_cold = cold["first_call_s"] - cold["warm_call_s"]
    compile_cached = cached["first_call_s"] - cached["warm_call_s"]
    benchmark.extra_info.update(
        compile_cold_s=compile_cold, compile_cached_s=compile_cached,
        import_cold_s=cold["import_s"], import_cached_s=cached["import_s"],
        process_cold_s=cold["process_s"], process_cached_s=cached["process_s"],
    )
    with capsys.disabled():
        print(f"\nnumba compile of the DMR kernel chain: cold {compile_cold:.2f} s, from cache "
              f"{compile_cached:.2f} s (import opa {cold['import_s']:.2f} / "
              f"{cached['import_s']:.2f} s; whole process {cold['process_s']:.2f} / "
              f"{cached['process_s']:.2f} s)")
    assert compile_cached < compile_cold
