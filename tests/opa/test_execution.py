"""opa._execution: the one record of how batch work runs, its checks, its one Dask
connection rule and its one lost-worker policy."""

from __future__ import annotations

import socket
import time

import pytest

from benchmarks.silent_scheduler import silent_endpoint
from opa import Execution
from opa._execution import (
    DaskError,
    Watchdog,
    as_execution,
    connect_scheduler,
    take_execution,
)


@pytest.mark.parametrize("field, value, message", [
    ("workers", 0, r"workers"),
    ("workers", 1.5, r"workers"),
    ("workers", True, r"workers"),
    ("scheduler", 8786, r"scheduler must be an address"),
    ("scheduler", "not an address", r"scheduler must be a Dask scheduler address"),
    ("device", "gpu", r"device must be one of 'cpu', 'cuda', got 'gpu'"),
    ("progress", "yes", r"progress must be True, False or None, got 'yes'"),
    ("log", "stderr", r"log must be a callable"),
    ("checkpoint", 3, r"checkpoint must be a directory path, got 3"),
    ("chunk_size", 0, r"chunk_size"),
    ("connect_timeout", None, r"connect_timeout must be a number of seconds in \(0, 86400\]"),
    ("connect_timeout", float("nan"), r"connect_timeout"),
    ("worker_timeout", 0, r"worker_timeout must be a number of seconds in \(0, 86400\] or "
                          r"None, got 0"),
    ("worker_timeout", 1e9, r"worker_timeout"),
    ("executor", "pool", r"executor must be a concurrent.futures executor"),
])
def test_each_bad_field_is_refused_by_name(field, value, message):
    with pytest.raises(ValueError, match=message):
        Execution(**{field: value})


def test_the_gpu_runs_in_this_process_not_on_a_cluster():
    with pytest.raises(ValueError, match="not with scheduler"):
        Execution(device="cuda", scheduler="tcp://127.0.0.1:8786")


def test_defaults_run_here_and_numbers_are_normalised():
    run = Execution(workers=2.0, connect_timeout=3, chunk_size=64.0)
    assert (run.workers, run.chunk_size, run.connect_timeout) == (2, 64, 3.0)
    assert isinstance(run.workers, int) and isinstance(run.chunk_size, int)
    here = as_execution(None)
    assert (here.workers, here.scheduler, here.device, here.checkpoint) == (1, None, "cpu",
                                                                          None)
    with pytest.raises(ValueError, match="execution must be an opa.Execution"):
        as_execution({"workers": 2})


def test_replace_checks_like_a_new_record():
    assert Execution().replace(workers=3).workers == 3
    with pytest.raises(ValueError, match="workers"):
        Execution().replace(workers=-1)


def test_progress_follows_the_terminal_only_when_not_said(monkeypatch):
    import sys

    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    assert Execution().shows_progress
    assert not Execution(progress=False).shows_progress
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False, raising=False)
    assert not Execution().shows_progress
    assert Execution(progress=True).shows_progress


def test_say_goes_to_the_log_or_nowhere():
    lines = []
    Execution(log=lines.append).say("one")
    Execution().say("lost")
    assert lines == ["one"]


def test_the_keywords_of_earlier_releases_make_the_same_record():
    keywords = {"scheduler": "tcp://127.0.0.1:1", "chunk_size": 8, "sigma": 0.1}
    run = take_execution(None, keywords, "simulate_mc")
    assert run == Execution(scheduler="tcp://127.0.0.1:1", chunk_size=8)
    assert keywords == {"sigma": 0.1}  # the science keywords are left for the caller
    with pytest.raises(ValueError, match=r"simulate_mc: give progress inside execution="):
        take_execution(Execution(), {"progress": False}, "simulate_mc")
    assert take_execution(None, {}, "x") == Execution()


def test_an_endpoint_that_says_nothing_is_refused_within_the_timeout():
    with silent_endpoint() as address:  # the benchmark's: accepts, never speaks
        start = time.monotonic()
        with pytest.raises(ValueError, match=r"did not answer within 0.5 s \(connect_timeout\)"):
            with Execution(scheduler=address, connect_timeout=0.5).client():
                pass
        assert time.monotonic() - start < 3


def test_a_closed_port_is_refused_naming_it():
    probe = socket.socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()  # nothing listens there now
    with pytest.raises(ValueError, match=rf"scheduler 'tcp://127.0.0.1:{port}' did not answer"):
        connect_scheduler(f"tcp://127.0.0.1:{port}", 1.0)


def test_no_scheduler_gives_no_client():
    with Execution().client() as client:
        assert client is None


class _Cluster:
    """A stand-in for a distributed.Client whose worker count is set by the test."""

    def __init__(self, workers):
        self.workers = workers

    def nthreads(self):
        if self.workers is None:
            raise OSError("connection closed")
        return {f"w{i}": 1 for i in range(self.workers)}


def test_the_watchdog_fails_a_cluster_left_without_workers_only_after_the_timeout():
    cluster = _Cluster(0)
    dog = Watchdog(cluster, 0.2, lambda: 3, unit="chunks")
    dog.check()  # first seen empty: the clock starts
    time.sleep(0.05)
    dog.check()  # within the timeout
    cluster.workers = 1
    time.sleep(0.25)
    dog.check()  # a worker came back: the clock stops
    cluster.workers = 0
    dog.check()
    time.sleep(0.25)
    with pytest.raises(DaskError, match=r"no workers for 0.2 s .* with 3 chunks unfinished"):
        dog.check()
    assert dog.poll == pytest.approx(0.05)


def test_the_watchdog_reports_a_lost_scheduler_and_never_gives_up_without_a_timeout():
    with pytest.raises(DaskError, match="lost the Dask scheduler"):
        Watchdog(_Cluster(None), 1.0, lambda: 0).check()
    patient = Watchdog(_Cluster(0), None, lambda: 0)
    patient.check()
    time.sleep(0.01)
    patient.check()  # None waits forever: never raises
    assert patient.poll == 0.5


@pytest.mark.parametrize("cls", [DaskError])
def test_dask_errors_are_failed_runs(cls):
    import opa

    assert issubclass(cls, opa.SimulationError)


def test_a_field_the_function_does_not_use_is_refused_by_name():
    """A record set away from its defaults where the function has no use for it (a GPU
    for a sweep, a chunk size for the stochastic diagram, a checkpoint for the map) is
    refused naming the field and the function, never silently ignored."""
    import mc
    from compare import load_config, run_validation
    from opa import preset, sweep
    from opa.dynamics import stochastic_diagram

    osc = preset("3.1", F0=0.0)
    with pytest.raises(ValueError, match=r"sweep does not use the execution's device"):
        sweep("dmr", "c", [0.05], osc, execution=Execution(device="cuda"))
    with pytest.raises(ValueError, match=r"stochastic_diagram does not use the execution's "
                                         r"chunk_size"):
        stochastic_diagram(osc, "c", [0.05], sigma=0.03, execution=Execution(chunk_size=8))
    with pytest.raises(ValueError, match=r"simulate_mc does not use the execution's workers"):
        mc.simulate_mc(osc, samples=16, periods=1, execution=Execution(workers=2))
    with pytest.raises(ValueError, match=r"run_validation does not use the execution's "
                                         r"checkpoint"):
        run_validation(load_config(None, values=(3.98,), sigmas=(0.01,), orders=(0,),
                                   horizons=(2,), samples=64, max_samples=64),
                       execution=Execution(checkpoint="elsewhere"))
    # display fields are always taken, and an unused field at its default passes
    assert Execution(progress=False, log=print).only("f", "workers").workers == 1
