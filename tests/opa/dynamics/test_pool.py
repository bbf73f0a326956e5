"""The sweep's process pool cannot outlive the process that made it, even when that
process is killed outright (SIGKILL: no handler, no shutdown, no atexit): the workers of
``opa.dynamics._sweep.local_executor`` and its fork server, which preloads
``opa.dynamics._warm_worker``."""

import os
import signal
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="reads the process table from /proc")

# A sweep long enough that both workers are deep in a kernel (holding the GIL) when the
# parent is killed.
SWEEP = """
import numpy as np
from opa import sweep
sweep("dmr", "c", np.linspace(0.01, 0.1, 400), transient=20000, record=2000, workers=2,
      progress=False)
"""


def _processes() -> dict[int, tuple[str, int, int]]:
    """pid -> (state, parent pid, session id) of every process, from /proc/PID/stat."""
    table = {}
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as fh:
                stat = fh.read()
        except OSError:  # ended while we read
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        table[int(name)] = (fields[0], int(fields[1]), int(fields[3]))
    return table


def _alive_in_session(sid: int) -> list[int]:
    return [pid for pid, (state, _, session) in _processes().items()
            if session == sid and state not in ("Z", "X")]


def _children(pid: int) -> list[int]:
    return [p for p, (state, ppid, _) in _processes().items()
            if ppid == pid and state not in ("Z", "X")]


def test_sigkill_of_the_parent_takes_the_pool_with_it():
    proc = subprocess.Popen([sys.executable, "-c", SWEEP], start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    sid = proc.pid  # a new session: every descendant carries this id
    try:
        # the fork server is the child of ours whose own children are the two workers
        deadline = time.monotonic() + 60
        workers: list[int] = []
        while len(workers) < 2:
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the pool never started"
            time.sleep(0.2)
            workers = [w for child in _children(proc.pid) for w in _children(child)]
        time.sleep(1.0)  # into the kernels
        assert len(_alive_in_session(sid)) >= 5  # us, resource tracker, fork server, workers

        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 5
        left = _alive_in_session(sid)
        while left and time.monotonic() < deadline:
            time.sleep(0.1)
            left = _alive_in_session(sid)
        assert left == [], f"still alive 5 s after the parent was killed: {left}"
    finally:
        for pid in _alive_in_session(sid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()


WATCHER = """
import sys, time
from opa.dynamics._sweep import exit_with_parent
exit_with_parent(int(sys.argv[1]), interval=0.1)
print("watching", flush=True)
time.sleep(60)
"""


@pytest.mark.parametrize("reap", [True, False], ids=["reaped", "zombie"])
def test_the_fallback_watcher_ends_a_process_with_its_owner(reap):
    """Where the kernel's parent-death signal is not available, a worker ends by itself
    once the pool's owner is gone, also while the owner is an unreaped zombie."""
    owner = subprocess.Popen(["sleep", "60"])
    watcher = subprocess.Popen([sys.executable, "-c", WATCHER, str(owner.pid)],
                               stdout=subprocess.PIPE)
    try:
        assert watcher.stdout.readline() == b"watching\n"
        assert watcher.poll() is None
        owner.kill()
        if reap:
            owner.wait()
        assert watcher.wait(timeout=5) == 1
    finally:
        for p in (owner, watcher):
            if p.poll() is None:
                p.kill()
            p.wait()
        watcher.stdout.close()
