"""The kernel's caller on a cold numba cache: the first-run message, the callees compiled
on two cores, and the table of callee signatures that makes that possible."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numba
import numpy as np
import pytest

import opa
from opa import _run

REPO = Path(__file__).resolve().parents[2]
MESSAGE = "compiling kernels (first run only)"


def _python(script: str, cache_dir: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(script)], env=env, cwd=REPO,
                          capture_output=True, text=True, timeout=300, check=True)


@pytest.mark.long  # a fresh process lists integrate's callees (CI runs it)
def test_callee_table_is_what_integrate_calls(tmp_path):
    """With both groups of the table compiled, ``integrate``'s own compilation compiles
    no kernel function but itself: every callee it needs was in the table, with the
    argument types it calls it with (a drifted entry would be compiled again)."""
    done = _python(
        """
        import json
        from numba.core import event
        import opa
        from opa import _kernel as kernel, _run
        _run.compile_group("helper")
        _run.compile_group("main")
        _run._ANNOUNCED.append(True)  # the table is compiled: no helper process
        with event.install_recorder("numba:compile") as record:
            opa.simulate_dmr(periods=1)
        compiled = [e.data["dispatcher"].py_func.__name__ for _, e in record.buffer
                    if e.is_start and e.data["dispatcher"].py_func.__module__ == kernel.__name__]
        counts = {name: len(getattr(kernel, name).signatures)
                  for group in _run.callee_signatures().values() for name in group}
        print(json.dumps([compiled, counts]))
        """, tmp_path)
    compiled, counts = json.loads(done.stdout.strip().splitlines()[-1])
    assert compiled == ["integrate"]
    assert set(counts.values()) == {1}


@pytest.mark.long  # a cold compile; the quick loop keeps the once-per-command message test
def test_cold_first_call_says_so_once_and_matches_the_cached_run(tmp_path):
    """The cold run prints the message once, starts the helper (which compiles its group
    and exits cleanly), and computes what the cached run and this process compute."""
    script = """
        import json, opa
        from opa import _run
        first = opa.simulate_dmr(periods=2)
        again = opa.simulate_dmr(periods=2)
        helper = None if _run._HELPER is None else _run._HELPER.wait(timeout=120)
        print(json.dumps([helper, first["x"].values.tolist(), again["x"].values.tolist()]))
        """
    cold = _python(script, tmp_path)
    warm = _python(script, tmp_path)
    assert cold.stderr.count(MESSAGE) == 1, cold.stderr
    assert MESSAGE not in warm.stderr, warm.stderr
    helper_cold = json.loads(cold.stdout.strip().splitlines()[-1])[0]
    helper_warm = json.loads(warm.stdout.strip().splitlines()[-1])[0]
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if cores >= 2 and numba.config.NUMBA_NUM_THREADS >= 2:
        assert helper_cold == 0  # started, and exited without an error
    assert helper_warm is None  # a warm cache starts nothing
    here = opa.simulate_dmr(periods=2)["x"].values
    for run in (cold, warm):
        for x in json.loads(run.stdout.strip().splitlines()[-1])[1:]:
            np.testing.assert_array_equal(np.array(x), here)


def test_the_two_groups_do_not_overlap():
    groups = _run.callee_signatures()
    assert not set(groups["main"]) & set(groups["helper"])
    assert "integrate" not in set(groups["main"]) | set(groups["helper"])


def test_a_stale_table_entry_is_skipped_not_raised(monkeypatch):
    """The table is a head start: an entry that no longer types (here one argument too
    few, as after an edit of the kernel) must not fail the user's run, nor stop the
    entries after it from compiling (a float method code: a signature nothing else
    compiles)."""
    from numba import types as nt

    monkeypatch.setattr(_run, "callee_signatures", lambda: {"main": {
        "is_deterministic": (nt.int64,), "last_stage": (nt.float64,)}})
    assert (nt.float64,) not in _run.kernel.last_stage.signatures
    _run.compile_group("main")
    assert all(len(sig) == 4 for sig in _run.kernel.is_deterministic.signatures)
    assert (nt.float64,) in _run.kernel.last_stage.signatures


def test_no_helper_without_a_python_to_start(monkeypatch):
    """An embedded interpreter has no ``sys.executable``: nothing is started and the
    main group still compiles (here emptied, so the call is instant)."""
    started = []
    monkeypatch.setattr(_run, "_threads", lambda: 2)  # where a helper would start
    monkeypatch.setattr(_run.os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setattr(_run.sys, "executable", "")
    monkeypatch.setattr(_run.subprocess, "Popen", lambda *a, **k: started.append(a))
    monkeypatch.setattr(_run, "callee_signatures", lambda: {"main": {}, "helper": {}})
    _run.compile_callees()
    assert started == []


def test_the_kernel_threads_sleep_unless_told_otherwise_and_importing_changes_nothing():
    """Importing opa leaves OMP_WAIT_POLICY alone (no process-wide state changed at
    import); the first parallel batch sets it to PASSIVE before numba starts its OpenMP
    threads, and keeps a value the user set (a fresh process each)."""
    import os
    import subprocess
    import sys

    code = ("import os, opa, mc; before = os.environ.get('OMP_WAIT_POLICY', 'unset'); "
            "mc.simulate_mc(samples=16, periods=1); "
            "print(before, os.environ['OMP_WAIT_POLICY'])")
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout.strip()
    assert out == "unset PASSIVE"
    out = subprocess.run([sys.executable, "-c", code], env=env | {"OMP_WAIT_POLICY": "ACTIVE"},
                         capture_output=True, text=True, check=True).stdout.strip()
    assert out == "ACTIVE ACTIVE"


def test_a_command_says_it_compiles_once_for_the_workers_it_starts(tmp_path, monkeypatch):
    """announce_compilation on a cold cache says so and marks the environment; a second
    call, and a process started afterwards with the same cache (a pool worker), stay
    silent; a process with another cache says it again. Nothing is compiled here."""
    script = """
        import os, subprocess, sys
        from opa._run import announce_compilation
        said = [announce_compilation(), announce_compilation()]
        child = "from opa._run import announce_compilation; print(announce_compilation())"
        same = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True)
        other = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True,
                               env={**os.environ, "NUMBA_CACHE_DIR": os.environ["OTHER"]})
        print(said, same.stdout.strip(), other.stdout.strip(), same.stderr.count("compiling"),
              other.stderr.count("compiling"))
        """
    monkeypatch.setenv("OTHER", str(tmp_path / "other"))
    done = _python(script, tmp_path / "cache")
    assert done.stdout.strip().splitlines()[-1] == "[True, False] False True 0 1"
    assert done.stderr.count(MESSAGE) == 1


@pytest.mark.slow
def test_a_cold_map_on_two_processes_says_it_compiles_once(tmp_path):
    """The first map on a cold numba cache, with 2 worker processes: one line, not one
    per process (issue 44). About 3 minutes on 2 cores: every process compiles."""
    done = subprocess.run(
        [sys.executable, "-c", "import sys; from opa.cli._main import main; sys.exit(main())",
         "validate", "--omega", "3.98", "--sigmas", "0.01", "--orders", "0,1",
         "--horizons", "2", "--samples", "64", "--max-samples", "64", "--no-frontier",
         "--no-plots", "--workers", "2", "--quiet", "--outdir", str(tmp_path / "map")],
        env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}, cwd=REPO,
        capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr
    assert done.stderr.count(MESSAGE) == 1, done.stderr


def test_tangents_ride_along_and_renormalising_only_rescales_them():
    """Tangent vectors (``Variational``) carried through a run of the DMR with its wall far
    away: W at the end is the flow's derivative, checked against central differences of
    plain runs; one renormalised vector's log growths add up to the log of the norm the
    same vector reaches unrenormalised; a tangent that is not (D, m) is refused by name."""
    system = opa.System(opa.preset("3.1", F0=0.0).replace(delta=10.0)).deterministic()
    inputs = system.kernel_inputs(opa.SolverOptions(rtol=1e-12, atol=1e-12))
    y0 = system.initial_state()
    times = np.linspace(0.0, 3 * system.oscillator.forcing_period, 7)
    kw = dict(rtol=1e-12, atol=1e-12)
    W = _run.run(inputs, y0, times, variational=_run.Variational(np.eye(2)), **kw).tangent
    eps = 1e-6
    for j in range(2):
        step = eps * np.eye(2)[j]
        ahead = _run.run(inputs, y0 + step, times, **kw).states[-1]
        behind = _run.run(inputs, y0 - step, times, **kw).states[-1]
        np.testing.assert_allclose(W[:, j], (ahead - behind) / (2 * eps), rtol=1e-6,
                                   atol=1e-8)
    w0 = np.array([[0.6], [0.8]])
    plain = _run.run(inputs, y0, times, variational=_run.Variational(w0), **kw)
    scaled = _run.run(inputs, y0, times, variational=_run.Variational(w0, renormalise=True),
                      **kw)
    assert plain.log_growth is None and len(scaled.log_growth) == len(times) - 1
    assert scaled.log_growth.sum() == pytest.approx(np.log(np.linalg.norm(plain.tangent)),
                                                    rel=1e-10)
    np.testing.assert_allclose(scaled.tangent, plain.tangent / np.linalg.norm(plain.tangent),
                               rtol=1e-10)
    with pytest.raises(ValueError, match=r"tangent must be a \(D, m\) array, got shape \(2,\)"):
        _run.Variational(np.ones(2))
    with pytest.raises(ValueError, match="renormalise must be True or False, got 'yes'"):
        _run.Variational(np.eye(2), renormalise="yes")
    with pytest.raises(ValueError, match=r"tangent must have 2 rows, got shape \(3, 1\)"):
        _run.run(inputs, y0, times, variational=_run.Variational(np.ones((3, 1))), **kw)
