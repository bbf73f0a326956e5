"""Tests for opa._lock: an output folder or file that one process writes is refused to
every other process at once, naming the holder; a lock left by a dead process is taken
over; and the jobs that write folders take the lock (issue 45: a second ``opa-mc
validate`` on the same --outdir once overwrote the first's validate.nc without a word).

Every refusal here comes from a real second process holding the lock."""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import xarray as xr

from opa._dataset import Store, remove_store
from opa._lock import LOCK_NAME, OutputInUse, OutputLock, lock_file, process_ticks
from opa.cli._main import main

ROOT = Path(__file__).resolve().parent.parent.parent

# a process that takes the lock of argv[1] (a folder when argv[2] == "folder"), says
# "held", and keeps it until its stdin closes or says "release"
HOLDER = textwrap.dedent("""
    import sys
    from opa._lock import OutputLock
    with OutputLock(sys.argv[1], "test output", folder=sys.argv[2] == "folder"):
        print("held", flush=True)
        sys.stdin.readline()
    print("released", flush=True)
""")


class Holder:
    """A child process that holds the lock of ``path``."""

    def __init__(self, path, folder=True):
        self.proc = subprocess.Popen(
            [sys.executable, "-c", HOLDER, str(path), "folder" if folder else "file"],
            cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        assert line == "held\n", line
        self.pid = self.proc.pid

    def release(self):
        out, _ = self.proc.communicate("release\n", timeout=60)
        assert out == "released\n" and self.proc.returncode == 0

    def kill(self):
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()  # reaped: no zombie left to look alive
        self.proc.stdin.close()
        self.proc.stdout.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.proc.poll() is None:
            self.kill()


def read_lock(path) -> dict:
    with open(path, encoding="utf-8") as file:
        return json.load(file)


# --------------------------------------------------------------------------- the lock


@pytest.mark.parametrize("folder", [True, False])
def test_a_second_process_is_refused_naming_the_first_then_succeeds(tmp_path, folder):
    target = tmp_path / ("out" if folder else "out.nc")
    lockfile = target / LOCK_NAME if folder else tmp_path / "out.nc.lock"
    assert lock_file(target, folder) == str(lockfile)
    with Holder(target, folder) as holder:
        record = read_lock(lockfile)
        assert record["pid"] == holder.pid and record["host"] == socket.gethostname()
        assert "opa._lock" in record["command"]  # the holder's own command line
        with pytest.raises(OutputInUse) as refused:
            OutputLock(target, "test output", folder=folder).acquire()
        message = str(refused.value)
        assert isinstance(refused.value, ValueError) and "\n" not in message
        assert message.startswith(f"test output {str(target)!r} is in use by process "
                                  f"{holder.pid} (python -c ")
        assert str(lockfile) in message and "wait for it to finish" in message
        assert read_lock(lockfile) == record  # the holder's lock is untouched
        holder.release()
    assert not lockfile.exists()
    with OutputLock(target, "test output", folder=folder) as mine:
        assert mine.held and read_lock(lockfile)["pid"] == os.getpid()
    assert not lockfile.exists()


def test_the_lock_of_a_killed_process_is_taken_over_with_one_line(tmp_path):
    with Holder(tmp_path) as holder:
        holder.kill()  # SIGKILL: no cleanup runs
    lockfile = tmp_path / LOCK_NAME
    assert read_lock(lockfile)["pid"] == holder.pid  # left behind
    lines = []
    with OutputLock(tmp_path, "test output", folder=True, log=lines.append):
        assert read_lock(lockfile)["pid"] == os.getpid()
    assert len(lines) == 1 and "\n" not in lines[0]
    assert f"took over the lock of process {holder.pid} " in lines[0]
    assert "no longer running" in lines[0] and str(lockfile) in lines[0]
    assert not lockfile.exists()


def write_lock(path, **record):
    base = {"pid": os.getpid(), "host": socket.gethostname(), "command": "opa-mc test",
            "started": "2025-01-01T00:00:00+00:00", "ticks": None, "token": "t"}
    Path(path).write_text(json.dumps({**base, **record}))


@pytest.mark.parametrize(("record", "why"), [
    # a pid that now names another process (our parent runs, but started at another tick)
    ({"pid": os.getppid(), "ticks": -1}, "its pid now names another process"),
    # this process's pid, but not a lock this process took (an earlier container's)
    ({"pid": os.getpid()}, "left by an earlier process with this process's pid"),
])
def test_a_lock_whose_pid_names_another_process_is_stale(tmp_path, record, why):
    if process_ticks(os.getpid()) is None:
        pytest.skip("no /proc: a process's start time cannot be read")
    write_lock(tmp_path / LOCK_NAME, **record)
    lines = []
    with OutputLock(tmp_path, "test output", folder=True, log=lines.append):
        pass
    assert len(lines) == 1 and why in lines[0]


def test_a_live_holder_with_its_start_time_is_not_stale(tmp_path):
    write_lock(tmp_path / LOCK_NAME, pid=os.getppid(), ticks=process_ticks(os.getppid()))
    with pytest.raises(OutputInUse, match=f"in use by process {os.getppid()} "
                                          r"\(opa-mc test, started 2025"):
        OutputLock(tmp_path, "test output", folder=True).acquire()


def test_a_lock_of_another_host_is_refused_with_the_file_to_remove(tmp_path):
    write_lock(tmp_path / LOCK_NAME, pid=999999999, host="elsewhere.example")
    with pytest.raises(OutputInUse) as refused:
        OutputLock(tmp_path, "test output", folder=True).acquire()
    assert "process 999999999 on host elsewhere.example (opa-mc test" in str(refused.value)
    assert f"if that process has stopped, remove {tmp_path / LOCK_NAME}" in str(refused.value)
    assert (tmp_path / LOCK_NAME).exists()


def test_an_unreadable_lock_file_is_stale_only_once_its_writer_had_time(tmp_path):
    lockfile = tmp_path / LOCK_NAME
    lockfile.write_bytes(b"")  # a writer killed between creating and filling it
    os.utime(lockfile, (time.time() - 60, time.time() - 60))
    lines = []
    with OutputLock(tmp_path, "test output", folder=True, log=lines.append):
        pass
    assert len(lines) == 1 and "an unreadable lock file" in lines[0]


def test_the_lock_is_released_on_an_exception_and_on_keyboard_interrupt(tmp_path):
    lockfile = tmp_path / LOCK_NAME
    for error in (RuntimeError, KeyboardInterrupt):
        with pytest.raises(error):
            with OutputLock(tmp_path, "test output", folder=True):
                assert lockfile.exists()
                raise error()
        assert not lockfile.exists()


def test_this_process_may_take_its_own_lock_again(tmp_path):
    lockfile = tmp_path / LOCK_NAME
    with OutputLock(tmp_path, "test output", folder=True):
        token = read_lock(lockfile)["token"]
        with OutputLock(tmp_path, "test output", folder=True):
            assert read_lock(lockfile)["token"] == token
        assert lockfile.exists()  # the outer holder still holds it
    assert not lockfile.exists()


def test_threads_of_one_process_share_its_lock(tmp_path):
    """Eight threads take the lock of one folder at once: the process holds it (one lock
    file, never judged stale by a thread of its own) until the last lets go."""
    import threading

    barrier = threading.Barrier(8)
    tokens, lines = [], []

    def take():
        barrier.wait()
        with OutputLock(tmp_path, "test output", folder=True, log=lines.append):
            tokens.append(read_lock(tmp_path / LOCK_NAME)["token"])
            barrier.wait()

    threads = [threading.Thread(target=take) for _ in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    assert len(tokens) == 8 and len(set(tokens)) == 1 and lines == []
    assert not (tmp_path / LOCK_NAME).exists()


def _try_in_fork(path, queue):
    try:
        OutputLock(path, "test output", folder=True).acquire()
        queue.put("taken")
    except OutputInUse as err:
        queue.put(str(err))


def test_a_forked_child_does_not_inherit_the_lock(tmp_path):
    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork")
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    with OutputLock(tmp_path, "test output", folder=True):
        child = context.Process(target=_try_in_fork, args=(str(tmp_path), queue))
        child.start()
        said = queue.get(timeout=60)
        child.join(60)
        assert f"in use by process {os.getpid()} " in said
        assert (tmp_path / LOCK_NAME).exists()  # the child's exit left it alone


RACE = textwrap.dedent("""
    import sys, time
    from opa._lock import OutputInUse, OutputLock
    while time.time() < float(sys.argv[2]):
        pass
    try:
        with OutputLock(sys.argv[1], "test output", folder=True, log=lambda line: None):
            print("taken", flush=True)
            time.sleep(2)
    except OutputInUse:
        print("refused", flush=True)
""")


def test_processes_racing_for_a_stale_lock_take_it_one_at_a_time(tmp_path):
    """Four processes find the lock of a dead process at the same instant: one takes it
    over, the others are refused while it holds it (none removes the fresh lock)."""
    with Holder(tmp_path) as holder:
        holder.kill()
    start = time.time() + 3  # after every child has imported
    children = [subprocess.Popen([sys.executable, "-c", RACE, str(tmp_path), str(start)],
                                 cwd=ROOT, stdout=subprocess.PIPE, text=True)
                for _ in range(4)]
    said = sorted(child.communicate(timeout=120)[0].strip() for child in children)
    assert said == ["refused", "refused", "refused", "taken"]
    assert sorted(os.listdir(tmp_path)) == []


def test_a_path_that_cannot_hold_the_lock_is_one_line(tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match=r"test output '.*file': '.*file' is not a directory"):
        OutputLock(tmp_path / "file", "test output", folder=True).acquire()


# --------------------------------------------------------------------------- the store


def test_a_locked_store_is_refused_to_a_second_process_and_kept_from_removal(tmp_path):
    folder = tmp_path / "parts"
    with Holder(folder) as holder:
        with pytest.raises(OutputInUse, match=rf"sweep '.*parts' is in use by process "
                                              rf"{holder.pid} "):
            Store(folder, "sweep", settings={"a": 1}, lock=True)
        assert os.listdir(folder) == [LOCK_NAME]  # no marker written by the refused store
        remove_store(folder)  # another process writes it: left alone
        assert os.listdir(folder) == [LOCK_NAME]
        Store(folder, "sweep", settings={"a": 1})  # unlocked stores (the trust map's) do
        holder.release()
    with Store(folder, "sweep", settings={"a": 1}, lock=True) as store:
        store.save("p", {}, {"v": 1})
        assert read_lock(folder / LOCK_NAME)["pid"] == os.getpid()
    assert sorted(os.listdir(folder)) == ["p_" + store.key({})[:12] + ".npz", "store.json"]
    store = Store(folder, "sweep", settings={"a": 1}, lock=True)
    remove_store(folder)  # this process's own lock goes with the folder
    assert not folder.exists()
    store.close()  # nothing left to release


def test_a_store_releases_its_lock_when_collected_and_when_refused(tmp_path):
    folder = tmp_path / "parts"
    Store(folder, "sweep", settings={"a": 1}, lock=True)  # dropped at once
    assert not (folder / LOCK_NAME).exists()
    with pytest.raises(ValueError, match="belongs to another run"):
        Store(folder, "sweep", settings={"a": 2}, lock=True)
    assert sorted(os.listdir(folder)) == ["store.json"]


# --------------------------------------------------------------------------- the commands

@pytest.mark.parametrize("argv", [
    ["simulate", "mc", "--samples", "16", "--periods", "1"],
    ["bifurcation", "dmr", "--sweep", "c=0.02:0.03:2", "--transient", "5", "--record", "4"],
    ["stochastic", "--preset", "3.1", "--sweep", "c=0.04", "--samples", "0",
     "--transient", "50", "--workers", "1"],
])
def test_each_command_refuses_an_output_another_process_writes(tmp_path, capsys, argv):
    """``--out F.nc`` keeps F.nc.parts/: while another process holds its lock, the
    command exits 2 with one line naming the folder and that process, writes nothing;
    once it has gone, the same command runs."""
    out = tmp_path / "f.nc"
    parts = tmp_path / "f.nc.parts"
    with Holder(parts) as holder:
        assert main([*argv, "--out", str(out), "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("opa-mc: error: ")
        assert f"'{parts}' is in use by process {holder.pid} (python -c " in err[0]
        assert not out.exists() and os.listdir(parts) == [LOCK_NAME]
        holder.release()
    assert main([*argv, "--out", str(out), "--quiet"]) == 0
    assert out.exists() and not parts.exists()


VALIDATE = ["--values", "3.98", "--sigmas", "0.01", "--orders", "0,1", "--horizons", "4",
            "--samples", "64", "--max-samples", "128", "--per-period", "4", "--no-frontier",
            "--no-plots", "--quiet", "--workers", "1"]

# ``opa-mc validate`` whose map waits, once it has begun, until the file argv[1] exists
SLOW_VALIDATE = textwrap.dedent("""
    import os, sys, time
    import compare._trustmap as T
    from opa.cli._main import main
    run = T._Map.run
    def waiting(self, *args, **kwargs):
        print("mapping", flush=True)
        while not os.path.exists(sys.argv[1]):
            time.sleep(0.05)
        return run(self, *args, **kwargs)
    T._Map.run = waiting
    sys.exit(main(["validate", *sys.argv[2:]]))
""")


def test_two_validate_runs_on_one_outdir(tmp_path):
    """Issue 45: ``opa-mc validate`` with another --seed on the --outdir of a running
    one exits 2 naming it and writes nothing; the first run's map is kept; once it has
    finished, the second runs and writes its own."""
    outdir, go = tmp_path / "map", tmp_path / "go"
    env = dict(os.environ, MPLBACKEND="Agg")
    first = subprocess.Popen([sys.executable, "-c", SLOW_VALIDATE, str(go), *VALIDATE,
                              "--seed", "1", "--outdir", str(outdir)], cwd=ROOT, env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert first.stdout.readline() == "mapping\n"  # inside the lock
        assert read_lock(outdir / LOCK_NAME)["pid"] == first.pid
        second = subprocess.run([sys.executable, "-m", "opa.cli", "validate", *VALIDATE,
                                 "--seed", "2", "--outdir", str(outdir)], cwd=ROOT, env=env,
                                capture_output=True, text=True, timeout=300)
        assert second.returncode == 2, second.stderr
        lines = second.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(
            f"opa-mc: error: output folder {str(outdir)!r} is in use by process {first.pid} "
            f"(python -c ")
        # the end of its command line (a long one is shown as its first 120 and last 75
        # characters: the path's own length, e.g. under pytest-xdist, must not matter)
        assert f"{str(outdir)[-50:]}, started " in lines[0]
        assert "Traceback" not in second.stderr
        assert not (outdir / "validate.nc").exists()
        go.write_text("")
        out, err = first.communicate(timeout=300)
        assert first.returncode == 0, err
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    with xr.open_dataset(outdir / "validate.nc") as ds:
        assert ds.attrs["seed"] == 1
    assert not (outdir / LOCK_NAME).exists()
    again = subprocess.run([sys.executable, "-m", "opa.cli", "validate", *VALIDATE,
                            "--seed", "2", "--outdir", str(outdir)], cwd=ROOT, env=env,
                           capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    with xr.open_dataset(outdir / "validate.nc") as ds:
        assert ds.attrs["seed"] == 2


def test_a_validate_run_takes_over_the_lock_of_a_killed_one(tmp_path, capsys):
    outdir = tmp_path / "map"
    with Holder(outdir) as holder:
        holder.kill()
    assert main(["validate", *[a for a in VALIDATE if a != "--quiet"],
                 "--outdir", str(outdir)]) == 0
    err = capsys.readouterr().err
    assert f"took over the lock of process {holder.pid} " in err
    assert not (outdir / LOCK_NAME).exists() and (outdir / "validate.nc").exists()
