"""Tests for opa._dataset: atomic netCDF files with the umask's mode and the cleaning of
temporaries that crashed writes left behind (README, 'Errors, limits and resuming')."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import time

import numpy as np
import pytest
import xarray as xr

from opa._dataset import atomic_write, clean_stale_temporaries, current_umask, write_netcdf


@pytest.fixture
def ds():
    return xr.Dataset({"x": ("time", np.arange(5.0))}, attrs={"model": "test"})


@pytest.fixture
def umask():
    """Set the umask for a test; restored afterwards."""
    old = os.umask(0o022)
    yield os.umask
    os.umask(old)


def dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


# --------------------------------------------------------------------------- files


@pytest.mark.parametrize(("mask", "mode"), [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_written_file_gets_the_mode_of_the_umask(tmp_path, ds, umask, mask, mode):
    umask(mask)
    assert current_umask() == mask
    write_netcdf(ds, tmp_path / "out.nc")
    assert stat.S_IMODE(os.stat(tmp_path / "out.nc").st_mode) == mode
    assert os.listdir(tmp_path) == ["out.nc"]
    with xr.open_dataset(tmp_path / "out.nc") as back:
        np.testing.assert_array_equal(back.x.values, ds.x.values)


def test_stale_temporaries_are_removed_and_live_ones_kept(tmp_path, ds):
    dead = dead_pid()
    stale = tmp_path / f".tmp-opa-mc-{dead}-k3j2.nc"
    stale_chunk = tmp_path / f".tmp-opa-mc-{dead}-x.npz"
    live = tmp_path / f".tmp-opa-mc-{os.getppid()}-abcd.nc"  # our parent is running
    own = tmp_path / f".tmp-opa-mc-{os.getpid()}-efgh.nc"
    legacy_old = tmp_path / ".tmp-a1b2c3.nc"  # an old version's empty temporary
    legacy_new = tmp_path / ".tmp-d4e5f6.nc"  # too recent: its writer may be starting
    legacy_full = tmp_path / ".tmp-g7h8i9.nc"  # holds data: not ours to judge
    other = tmp_path / "results.nc"
    for path in (stale, stale_chunk, live, own, legacy_old, legacy_new, other):
        path.write_bytes(b"" if path.name.startswith(".tmp-") and "opa-mc" not in path.name
                         else b"data")  # fmt: skip
    legacy_full.write_bytes(b"data")
    long_ago = time.time() - 3600
    for path in (legacy_old, legacy_full):
        os.utime(path, (long_ago, long_ago))
    removed = clean_stale_temporaries(tmp_path)
    assert sorted(removed) == sorted(str(p) for p in (stale, stale_chunk, legacy_old))
    assert sorted(os.listdir(tmp_path)) == sorted(
        p.name for p in (live, own, legacy_new, legacy_full, other))
    # write_netcdf cleans the directory it writes to
    stale.write_bytes(b"data")
    write_netcdf(ds, tmp_path / "out.nc")
    assert not stale.exists() and live.exists()
    assert clean_stale_temporaries(tmp_path / "missing") == []


def test_a_failed_write_leaves_nothing_behind(tmp_path, ds):
    (tmp_path / "out.nc").write_bytes(b"previous result")

    def fail(tmp):
        with open(tmp, "wb") as file:
            file.write(b"half a file")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_write(tmp_path / "out.nc", fail, suffix=".nc")
    assert os.listdir(tmp_path) == ["out.nc"]
    assert (tmp_path / "out.nc").read_bytes() == b"previous result"


def test_a_killed_writer_leaves_a_temporary_the_next_write_removes(tmp_path, ds):
    """A writer killed between creating its temporary and the rename (SIGKILL: no
    cleanup runs) leaves .tmp-opa-mc-<pid>-*.nc; the next write in the directory removes
    it, and the target is never a partial file."""
    script = (
        "import os, sys, time\n"
        "from opa._dataset import atomic_write\n"
        "def hang(tmp):\n"
        "    open(tmp, 'wb').write(b'partial')\n"
        "    print('writing', flush=True)\n"
        "    time.sleep(60)\n"
        "atomic_write(sys.argv[1], hang, suffix='.nc')\n"
    )
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    child = subprocess.Popen([sys.executable, "-c", script, str(tmp_path / "out.nc")],
                             cwd=root, stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert child.stdout.readline() == "writing\n"
    finally:
        child.kill()
        child.wait()
        child.stdout.close()
    left = os.listdir(tmp_path)
    assert len(left) == 1 and left[0].startswith(f".tmp-opa-mc-{child.pid}-")
    write_netcdf(ds, tmp_path / "out.nc")
    assert os.listdir(tmp_path) == ["out.nc"]
