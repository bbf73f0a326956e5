"""Start-up: ``import opa``, and numba's cold compilation of the kernel entry points.

Each measurement runs in a new interpreter with its own empty ``NUMBA_CACHE_DIR`` (cold)
and then again with the same directory (cached):

- ``import opa`` alone (numba's own import measured beside it: ``import numba``);
- the DMR path: the first ``opa.simulate_dmr(periods=1)`` (``opa._kernel.integrate``);
- the DMR path with one numba thread (no helper process compiles beside it);
- everything ``opa-mc validate`` compiles: the DMR path, then one small Monte Carlo
  ensemble (``opa._kernel.run_batch``, which also serves OPA variants, elements and
  split scans), then one variational flow with tangents (the same ``integrate``).

The cold run must print "compiling kernels (first run only)..." once, the cached run
never. Targets (issue 14): cold DMR <= 10 s, cold validate kernels <= 20 s, import
<= 0.5 s plus numba's import. Smoke mode (CI) measures only the cached import.

    python -m pytest benchmarks/bench_startup.py -s
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
MESSAGE = "compiling kernels (first run only)"

_SCRIPT = textwrap.dedent(
    """
    import json, sys, time
    marks = {}
    start = time.perf_counter()
    import numba
    marks["numba_import_s"] = time.perf_counter() - start
    start = time.perf_counter()
    import opa
    marks["opa_import_s"] = time.perf_counter() - start
    marks["heavy"] = [m for m in ("xarray", "pandas", "scipy.optimize", "scipy.stats",
                                  "matplotlib", "dask", "distributed") if m in sys.modules]
    if "import" not in sys.argv[1:]:
        start = time.perf_counter()
        opa.simulate_dmr(periods=1)
        marks["dmr_s"] = time.perf_counter() - start
    if "validate" in sys.argv[1:]:
        import mc
        start = time.perf_counter()
        mc.simulate_mc(sigma=0.01, samples=8, periods=1, progress=False)
        marks["batch_s"] = time.perf_counter() - start
        start = time.perf_counter()
        system = opa.ImpactSystem(opa.preset("3.1"))
        opa.poincare_map(system, [-1.0, 0.0], periods=14, jacobian=True)
        marks["tangent_s"] = time.perf_counter() - start
    print(json.dumps(marks))
    """
)


def fresh_process(cache_dir: Path, *what: str, threads: int | None = None) -> tuple[dict, str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    if threads is not None:
        env["NUMBA_NUM_THREADS"] = str(threads)
    done = subprocess.run([sys.executable, "-c", _SCRIPT, *what], env=env, cwd=REPO,
                          check=True, capture_output=True, text=True, timeout=600)
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stderr


def test_import_time(benchmark, tmp_path, capsys):
    """``import opa`` in a new interpreter (importing compiles nothing), against
    ``import numba`` alone; the heavy libraries stay unimported until used."""
    marks, _ = benchmark.pedantic(fresh_process, args=(tmp_path, "import"), rounds=3,
                                  iterations=1)
    benchmark.extra_info.update(marks)
    with capsys.disabled():
        print(f"\nimport opa {marks['opa_import_s']:.3f} s after import numba "
              f"{marks['numba_import_s']:.3f} s (load {os.getloadavg()[0]:.2f})")
    assert marks["heavy"] == []


@pytest.mark.slow
@pytest.mark.parametrize("what", ["dmr", "validate", "dmr, one thread"])
def test_cold_compilation(benchmark, tmp_path, what, capsys):
    """"dmr, one thread": NUMBA_NUM_THREADS=1, so no helper process compiles beside."""
    args = ("validate",) if what == "validate" else ()
    threads = 1 if what.endswith("one thread") else None
    start = time.perf_counter()
    cold, cold_err = fresh_process(tmp_path, *args, threads=threads)
    cold_total = time.perf_counter() - start
    cached, cached_err = benchmark.pedantic(fresh_process, args=(tmp_path, *args),
                                            kwargs={"threads": threads}, rounds=1,
                                            iterations=1)
    calls = ("dmr_s", "batch_s", "tangent_s")
    compile_s = sum(v for k, v in cold.items() if k in calls)
    cached_s = sum(v for k, v in cached.items() if k in calls)
    benchmark.extra_info.update(cold=cold, cached=cached, compile_s=compile_s)
    with capsys.disabled():
        print(f"\n{what}: cold first calls {compile_s:.2f} s ({cold}), cached {cached_s:.3f} s, "
              f"cold process {cold_total:.1f} s, load {os.getloadavg()[0]:.2f}")
    assert cold_err.count(MESSAGE) == 1, cold_err
    assert MESSAGE not in cached_err, cached_err
    assert cached_s < compile_s
