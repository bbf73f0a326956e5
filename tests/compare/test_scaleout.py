"""The trust map's tasks on a local process pool and on a Dask cluster (compare._scaleout):
the map they assemble equals the one computed in one process, bit for bit."""

import numba
import numpy as np
import pytest
import xarray as xr

from compare._config import load_config
from compare._scaleout import auto_workers, run_flow, run_tasks, share_cores
from opa.engine import usable_cores
from compare._mapflow import run_validation
from tests.compare.test_parts import RUN_ATTRS

# two swept values and the frontier off: three sigmas, N = 0 and 2, two horizons
SMALL = dict(values=(3.98, 4.09), sigmas=(0.01, 0.02, 0.03), orders=(0, 2), horizons=(4, 8),
             samples=64, max_samples=256, per_period=4, frontier=False)
TIMING_VARS = ("mc_seconds", "point_seconds", "frontier_seconds")
TIMING_ATTRS = RUN_ATTRS + ("frontier_wall_seconds",)


def _draw(seed: int, n: int) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal(n)


def assert_same_variables(a: xr.Dataset, b: xr.Dataset, skip=()) -> None:
    """The same variables with the same values to the bit (NaN equal to NaN), but
    ``skip``."""
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.data_vars:
        if name in skip:
            continue
        x, y = a[name].values, b[name].values
        assert np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"), name


def assert_same_map(a: xr.Dataset, b: xr.Dataset) -> None:
    """Every variable and attribute the same, but the wall times and what the run did."""
    assert_same_variables(a, b, skip=TIMING_VARS)
    keep = [k for k in a.attrs if k not in TIMING_ATTRS]
    assert keep == [k for k in b.attrs if k not in TIMING_ATTRS]
    for k in keep:
        assert str(a.attrs[k]) == str(b.attrs[k]), k


def test_run_tasks_gives_every_result_under_its_key():
    tasks = [(i, _draw, (i, 5)) for i in range(4)]
    serial = dict(run_tasks(tasks))
    pooled = dict(run_tasks(tasks, workers=2))
    assert sorted(pooled) == [0, 1, 2, 3]
    for i in range(4):
        np.testing.assert_array_equal(pooled[i], serial[i])


def test_a_task_failure_reaches_the_caller():
    with pytest.raises(ValueError, match="math domain"):
        dict(run_tasks([(0, _fail, ()), (1, _draw, (1, 2))], workers=2))


def _fail():
    import math

    return math.sqrt(-1.0)


def test_the_default_shares_the_cores_out():
    assert auto_workers(6, cores=2) == 2 and auto_workers(6, cores=16) == 6
    assert auto_workers(2, cores=16) == 1 and auto_workers(6, cores=1) == 1
    assert share_cores(16, 16) == [1] * 16 and share_cores(16, 2) == [8, 8]
    assert share_cores(16, 3) == [6, 5, 5]  # every core, the spare one to the oldest
    assert share_cores(2, 5) == [1] * 5  # never none


def _numba_threads(hold: float):
    """numba's thread count as the task starts, then ``hold`` seconds doing nothing (so
    that tasks started together run together)."""
    import time

    threads = numba.get_num_threads()
    time.sleep(hold)
    return threads


def _threads_seen(seconds: float) -> list[int]:
    """The thread counts this task is granted, in the order seen, until it has the two
    cores or ``seconds`` pass."""
    import time

    from opa._run import apply_thread_grant

    seen, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        threads = apply_thread_grant()
        if not seen or seen[-1] != threads:
            seen.append(threads)
        if threads == 2:
            break
        time.sleep(0.01)
    return seen


def _sleep(seconds: float) -> float:
    import time

    time.sleep(seconds)
    return seconds


TWO_THREADS = pytest.mark.skipif(usable_cores() < 2 or numba.config.NUMBA_NUM_THREADS < 2,
                                 reason="needs 2 cores")


@TWO_THREADS
def test_a_pool_gives_the_last_task_the_cores_the_others_left():
    """Two tasks on 2 processes: one thread each; one task alone: both cores."""
    two = dict(run_flow([(i, _numba_threads, (2.0,)) for i in range(2)], workers=2))
    assert two == {0: 1, 1: 1}
    alone = dict(run_flow([(0, _numba_threads, (0.0,))], workers=2))
    assert alone == {0: 2}


@TWO_THREADS
def test_a_running_task_takes_the_core_a_finished_one_left():
    """A task beside a short one has one thread, then both cores once the short one has
    ended, without starting again."""
    done = dict(run_flow([("long", _threads_seen, (60.0,)), ("short", _sleep, (0.5,))],
                         workers=2))
    assert done["long"] == [1, 2]


@pytest.fixture(scope="module")
def one_process(tmp_path_factory):
    cfg = load_config(None, outdir=str(tmp_path_factory.mktemp("one")), workers=1, **SMALL)
    return run_validation(cfg, progress=False, log=lambda *a: None)


def test_a_pool_of_processes_gives_the_same_map(one_process, tmp_path):
    cfg = load_config(None, outdir=str(tmp_path), workers=2, **SMALL)
    lines = []
    pooled = run_validation(cfg, progress=False, log=lines.append)
    assert pooled.attrs["ran_on"] == "2 local processes"
    assert any("2 split scans, then each value's 3 grid points, then its bisections, on 2 "
               "local processes" in line for line in lines)
    assert_same_map(one_process, pooled)
    # the work done is counted wherever it ran
    for name in ("true_runs_computed", "mc_runs_computed", "opa_runs_computed"):
        assert pooled.attrs[name] == one_process.attrs[name], name


def test_a_dask_cluster_gives_the_same_map(one_process, tmp_path):
    """The values as tasks on a LocalCluster of 2 worker processes (one thread each)."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        cfg = load_config(None, outdir=str(tmp_path), scheduler=cluster.scheduler_address,
                          **SMALL)
        clustered = run_validation(cfg, progress=False, log=lambda *a: None)
    assert clustered.attrs["ran_on"].startswith("Dask cluster at tcp://")
    assert_same_map(one_process, clustered)
    assert clustered.attrs["true_runs_computed"] == one_process.attrs["true_runs_computed"]


def test_a_scheduler_that_does_not_answer_is_named(tmp_path):
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg = load_config(None, outdir=str(tmp_path), scheduler=f"tcp://127.0.0.1:{port}",
                      **SMALL)
    with pytest.raises(ValueError, match=f"scheduler 'tcp://127.0.0.1:{port}' did not "
                                         f"answer"):
        run_validation(cfg, progress=False, log=lambda *a: None)


def test_a_silent_endpoint_is_refused_within_the_connect_timeout(tmp_path):
    """An endpoint that accepts the connection and never speaks Dask (it hung the map for
    120 s): one line naming it, within the map's CONNECT_TIMEOUT."""
    import socket
    import time

    from opa._execution import CONNECT_TIMEOUT

    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
        cfg = load_config(None, outdir=str(tmp_path), scheduler=address, **SMALL)
        start = time.perf_counter()
        with pytest.raises(ValueError, match=f"scheduler '{address}' did not answer"):
            run_validation(cfg, progress=False, log=lambda *a: None)
    assert time.perf_counter() - start < CONNECT_TIMEOUT + 10


@pytest.mark.parametrize("address", ["garbage", "tcp://host", "tcp://:8786", "", "  "])
def test_an_address_that_is_not_one_is_refused_before_anything_runs(address, tmp_path):
    with pytest.raises(ValueError, match="scheduler must be a Dask scheduler address"):
        load_config(None, outdir=str(tmp_path), scheduler=address, **SMALL)
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
def test_the_default_map_on_a_4_process_local_cluster(tmp_path):
    """Issue 29's target: the embedded default map on a LocalCluster of 4 worker
    processes equals the one-process map bit for bit."""
    distributed = pytest.importorskip("distributed")
    one = run_validation(load_config(None, outdir=str(tmp_path / "one"), workers=1),
                         progress=False, log=lambda *a: None)
    with distributed.LocalCluster(n_workers=4, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        cfg = load_config(None, outdir=str(tmp_path / "four"),
                          scheduler=cluster.scheduler_address)
        four = run_validation(cfg, progress=False, log=lambda *a: None)
    assert_same_map(one, four)


def test_every_true_system_run_is_counted_wherever_it_ran(one_process, tmp_path):
    """true_system_runs / true_system_time: the Monte Carlo samples, split scans and
    phase portraits of the map, the same whether the values ran here or in workers; at
    least the Monte Carlo runs the map counts itself, and the time at least theirs."""
    cfg = load_config(None, outdir=str(tmp_path), workers=2, **SMALL)
    pooled = run_validation(cfg, progress=False, log=lambda *a: None)
    assert pooled.attrs["true_system_runs"] == one_process.attrs["true_system_runs"]
    assert pooled.attrs["true_system_time"] == pytest.approx(
        one_process.attrs["true_system_time"], rel=1e-12)
    assert one_process.attrs["true_system_runs"] > one_process.attrs["true_runs_computed"]
    T = 2 * np.pi / np.array(SMALL["values"])
    assert one_process.attrs["true_system_time"] >= \
        one_process.attrs["true_periods_computed"] * T.min()


def test_a_map_killed_on_its_pool_leaves_nothing_and_resumes(one_process, tmp_path):
    """SIGKILL of ``opa-mc validate --workers 2`` once some parts are written: no worker
    or fork server is left, and the rerun computes only what is missing and gives the
    one-process map."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from tests.opa.dynamics.test_pool import _alive_in_session

    flags = ["--values", "3.98,4.09", "--sigmas", "0.01,0.02,0.03", "--orders", "0,2",
             "--horizons", "4,8", "--samples", "64", "--max-samples", "256",
             "--per-period", "4", "--no-frontier", "--no-plots", "--quiet",
             "--outdir", str(tmp_path)]
    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.Popen([sys.executable, "-m", "opa.cli", "validate", "--workers", "2",
                             *flags], start_new_session=True, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    parts = tmp_path / "parts"
    try:
        deadline = time.monotonic() + 120
        while not (parts.exists() and len(list(parts.glob("mc_*.npz"))) >= 2):
            assert proc.poll() is None, "the map finished before it could be killed"
            assert time.monotonic() < deadline, "no parts written"
            time.sleep(0.1)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 5
        while _alive_in_session(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _alive_in_session(proc.pid) == []
    finally:
        for pid in _alive_in_session(proc.pid):
            os.kill(pid, signal.SIGKILL)
    cfg = load_config(None, outdir=str(tmp_path), workers=2, **SMALL)
    resumed = run_validation(cfg, progress=False, log=lambda *a: None)
    assert 0 < resumed.attrs["parts_computed"] < one_process.attrs["parts_computed"]
    assert_same_map(one_process, resumed)


def _negate(x):
    return -x


def _follow_chain(key, result):
    """a -> b: each finished "a" task makes a "b" task ready."""
    return [(("b", key[1]), _negate, (result,))] if key[0] == "a" else []


@pytest.mark.parametrize("workers", [1, 2])
def test_run_flow_runs_what_each_task_makes_ready(workers):
    tasks = [(("a", i), abs, (-i,)) for i in range(4)]
    got = dict(run_flow(tasks, _follow_chain, workers=workers))
    assert got == {**{("a", i): i for i in range(4)}, **{("b", i): -i for i in range(4)}}


def test_run_flow_starts_what_a_task_made_ready_ahead_of_the_rest():
    """In one process the order is fixed: b 0 runs right after a 0, before a 1."""
    tasks = [(("a", i), abs, (-i,)) for i in range(3)]
    order = [key for key, _ in run_flow(tasks, _follow_chain)]
    assert order == [("a", 0), ("b", 0), ("a", 1), ("b", 1), ("a", 2), ("b", 2)]


def test_run_flow_on_a_dask_cluster_runs_the_followers():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=":0") as cluster:
        tasks = [(("a", i), abs, (-i,)) for i in range(3)]
        got = dict(run_flow(tasks, _follow_chain, scheduler=cluster.scheduler_address))
    assert got == {**{("a", i): i for i in range(3)}, **{("b", i): -i for i in range(3)}}


def test_a_failed_follower_reaches_the_caller():
    def follow(key, result):
        return [("bad", _fail, ())] if key == "a" else []

    with pytest.raises(ValueError, match="math domain"):
        dict(run_flow([("a", abs, (1,)), ("c", abs, (2,))], follow, workers=2))
