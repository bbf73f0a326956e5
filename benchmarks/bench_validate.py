"""The main job's wall time: ``opa-mc validate`` in a fresh process, cold and warm.

Issue 11 targets the embedded default trust map (5 omegas x 8 sigmas, N = 0..8, four
variants, horizons 10 and 50, bisection of sigma*, split search) in at most 5 minutes on 2
cores with a cold numba cache and at most 2 minutes warm. *Cold*: an empty
``NUMBA_CACHE_DIR`` (every kernel compiles). *Warm*: the cache the cold run filled, and a
fresh output folder (every Monte Carlo run and OPA run is computed again; only the
compiled code is reused). *Resume*: a rerun into the same folder (every finished Monte Carlo
ensemble, OPA run, split scan and frontier run is read back from ``parts/``).

The full default is slow (minutes) and marked ``slow``; the smoke mode (CI) runs a tiny map
through the same path, cold then warm, to keep the harness honest.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from benchmarks.conftest import smoke_mode

TINY = ["--values", "3.98", "--sigmas", "0.01,0.03", "--orders", "0:2", "--horizons", "2,4",
        "--samples", "64", "--max-samples", "64", "--no-plots"]


def _validate(args, cache, outdir):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), MPLBACKEND="Agg")
    proc = subprocess.run(
        [sys.executable, "-m", "opa.cli", "validate", "--quiet", "--outdir", str(outdir),
         *args],
        env=env, capture_output=True, text=True,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert os.path.exists(os.path.join(outdir, "validate.nc"))
    return proc.stdout


@pytest.fixture(scope="module")
def shared(tmp_path_factory):
    """One numba cache and output folders shared by the cold, warm and resume runs of a
    configuration, in that order (each fills what the next needs if run alone)."""
    return tmp_path_factory.mktemp("validate-bench")


def _cold_warm_resume(benchmark, root, args, mode):
    cache = root / "numba-cache"
    out = root / f"results-{mode}"
    if mode == "warm" and not cache.exists():  # run alone: fill the cache (not timed)
        _validate(args, cache, root / "fill")
    if mode == "resume":
        out = root / "results-warm"
        if not (out / "validate.nc").exists():
            _validate(args, cache, out)

    def setup():
        if mode == "cold":
            shutil.rmtree(cache, ignore_errors=True)
        if mode != "resume":
            shutil.rmtree(out, ignore_errors=True)

    stdout = benchmark.pedantic(_validate, args=(args, cache, out), setup=setup, rounds=1,
                                iterations=1)
    assert "σ* mean" in stdout  # the first screen


@pytest.mark.parametrize("mode", ["cold", "warm", "resume"])
def test_validate_tiny(benchmark, shared, mode):
    """A tiny map in a fresh process (the smoke run of the harness)."""
    benchmark.group = "validate tiny"
    _cold_warm_resume(benchmark, shared / "tiny", TINY, mode)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["cold", "warm", "resume"])
def test_validate_default(benchmark, shared, request, mode):
    """The embedded default: the numbers for the issue's 5-minute (cold) and 2-minute
    (warm) targets."""
    if smoke_mode(request.config):
        pytest.skip("the full default map only outside smoke mode")
    benchmark.group = "validate default"
    _cold_warm_resume(benchmark, shared / "default", [], mode)
