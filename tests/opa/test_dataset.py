"""Tests for opa._dataset: atomic netCDF files with the umask's mode, the cleaning of
temporaries that crashed writes left behind, and the one resume store (README, 'Errors,
limits and resuming')."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from opa._dataset import (Store, atomic_write, clean_stale_temporaries, current_umask, digest,
                          remove_store, write_netcdf)


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


# --------------------------------------------------------------------------- the store


def test_digest_hashes_values_arrays_and_dataclasses():
    from opa import SolverOptions, System, preset

    assert digest({"a": 1, "b": (2.5, "x")}) == digest({"b": [2.5, "x"], "a": 1})
    assert digest(0.1 + 0.2) != digest(0.3)  # floats exactly
    a = np.arange(6.0)
    assert digest(a) == digest(a.copy()) == digest(np.float64(0) + a)
    assert len({digest(a), digest(a.reshape(2, 3)), digest(a.astype(np.float32)),
                digest(np.arange(6))}) == 4  # dtype and shape count
    assert digest(a[::2]) == digest(np.array([0.0, 2.0, 4.0]))  # by value, not by layout
    assert digest(np.int64(3)) == digest(3)
    s = System(preset("3.2"), sigma=0.02)
    assert digest(s) == digest(System(preset("3.2"), sigma=0.02))
    assert digest(s) != digest(s.replace(sigma=0.03))
    assert digest(SolverOptions()) != digest(SolverOptions(rtol=1e-9))
    with pytest.raises(TypeError, match="cannot hash a object"):
        digest({"x": object()})
    with pytest.raises(TypeError, match="keys must be strings"):
        digest({1: 2})


@pytest.mark.parametrize(("suffix", "content"), [
    (".npz", {"a": np.arange(3.0), "s": "text", "n": 7, "x": 0.1 + 0.2,
              "e": np.array([], dtype=str)}),
    (".json", {"a": [1.5, None], "s": "text"}),
    (".nc", xr.Dataset({"x": ("t", np.arange(3.0))}, attrs={"model": "m"})),
])
def test_store_parts_round_trip_and_are_computed_once(tmp_path, umask, suffix, content):
    umask(0o022)
    store = Store(tmp_path, "test job")
    got = store.get("thing", {"k": 1}, lambda: content, suffix)
    again = store.get("thing", {"k": 1}, lambda: pytest.fail("recomputed"), suffix)
    other = store.get("thing", {"k": 2}, lambda: content, suffix)
    assert store.computed == 2
    for out in (got, again, other):
        _same(out, content, suffix)
    names = sorted(os.listdir(tmp_path))
    parts = [n for n in names if n != "store.json"]
    assert len(parts) == 2 and len(names) == 3  # no temporaries left
    assert all(n.startswith("thing_") and n.endswith(suffix) for n in parts)
    assert stat.S_IMODE(os.stat(tmp_path / parts[0]).st_mode) == 0o644  # not mkstemp's
    # a new store of the same folder reads them back
    assert Store(tmp_path, "test job").load("thing", {"k": 1}, suffix) is not None


def test_store_refuses_a_reserved_name(tmp_path):
    with pytest.raises(ValueError, match="reserved"):
        Store(tmp_path, "job").save("x", {}, {"store_key": 1})


def test_damaged_and_foreign_parts_are_set_aside_named_and_recomputed(tmp_path):
    lines = []
    store = Store(tmp_path, "job", log=lines.append)
    for k in range(3):
        store.get("p", {"k": k}, lambda k=k: {"v": k})
    path = [store.path("p", {"k": k}) for k in range(3)]
    with open(path[0], "wb") as fh:
        fh.write(b"half")
    os.replace(path[1], path[2])  # k = 2's file holds k = 1
    for k in range(3):
        assert store.get("p", {"k": k}, lambda k=k: {"v": 10 + k})["v"] == 10 + k
    assert store.set_aside == 2 and len(lines) == 2
    assert path[0] in lines[0] and "is damaged (cannot be read" in lines[0]
    assert path[2] in lines[1] and "stores the key" in lines[1]
    assert all(os.path.exists(p + ".bad") for p in (path[0], path[2]))
    with open(path[0], "wb") as fh:
        fh.write(b"")
    with pytest.warns(RuntimeWarning, match=r"job part .* is damaged"):  # default: a warning
        assert Store(tmp_path, "job").load("p", {"k": 0}) is None


def test_a_folder_of_an_older_version_or_of_another_run_is_refused(tmp_path):
    old = tmp_path / "old"
    old.mkdir()
    (old / "manifest.json").write_text("{}")
    with pytest.raises(ValueError, match=r"job '.*old' holds files but no store.json "
                                         r"\(manifest.json\).*remove it"):
        Store(old, "job")
    assert os.listdir(old) == ["manifest.json"]

    folder = tmp_path / "run"
    Store(folder, "job", settings={"a": 1, "b": {"c": [1, 2]}})
    Store(folder, "job", settings={"a": 1, "b": {"c": (1, 2)}})  # the same settings
    with pytest.raises(ValueError, match=r"belongs to another run: b.c is 2 entries there, "
                                         r"3 entries here"):
        Store(folder, "job", settings={"a": 1, "b": {"c": [1, 2, 3]}})
    with pytest.raises(ValueError, match=r"holds the parts of a job, not of a sweep"):
        Store(folder, "sweep", settings={"a": 1, "b": {"c": [1, 2]}})
    marker = json.loads((folder / "store.json").read_text())
    marker["format"] = "opa-mc store 0"
    (folder / "store.json").write_text(json.dumps(marker))
    with pytest.raises(ValueError, match=r"another format \('opa-mc store 0'; this version "
                                         r"reads 'opa-mc store 2'\)"):
        Store(folder, "job", settings={"a": 1, "b": {"c": [1, 2]}})
    # the previous format: its parts carry no digest of their contents
    marker["format"] = "opa-mc store 1"
    (folder / "store.json").write_text(json.dumps(marker))
    with pytest.raises(ValueError, match=r"holds parts of format 'opa-mc store 1', written "
                                         r"without the digests .*remove it") as err:
        Store(folder, "job", settings={"a": 1, "b": {"c": [1, 2]}})
    assert "\n" not in str(err.value)
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="is not a directory"):
        Store(tmp_path / "file", "job")


def test_remove_store_removes_only_what_a_store_holds(tmp_path):
    store = Store(tmp_path / "s", "job")
    store.get("p", {}, lambda: {"v": 1})
    (tmp_path / "s" / "p_0123456789ab.npz.bad").write_bytes(b"")
    remove_store(tmp_path / "s")
    assert not (tmp_path / "s").exists()
    remove_store(tmp_path / "s")  # gone already: fine
    store = Store(tmp_path / "s", "job")
    (tmp_path / "s" / "notes.txt").write_text("mine")
    remove_store(tmp_path / "s")
    assert os.listdir(tmp_path / "s") == ["notes.txt"]


def test_a_write_that_fails_names_the_file_asked_for_and_leaves_nothing(tmp_path):
    """A full disk (ENOSPC from the writer) or netCDF's own RuntimeError: one OSError
    that names the path asked for (not the temporary), and no file left behind."""
    import errno

    from opa._dataset import atomic_write

    target = tmp_path / "out.nc"

    def full(tmp):
        with open(tmp, "wb") as f:
            f.write(b"partial")
        raise OSError(errno.ENOSPC, "No space left on device", tmp)

    def hdf(tmp):
        raise RuntimeError("NetCDF: HDF error")

    for write, code, text in ((full, errno.ENOSPC, "No space left"), (hdf, errno.EIO, "HDF")):
        with pytest.raises(OSError) as raised:
            atomic_write(target, write)
        assert raised.value.filename == str(target) and raised.value.errno == code
        assert text in raised.value.strerror
        assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- edited parts


def _edit_one_number(path: str, suffix: str) -> None:
    """Change one number of a part on disk, leaving its key and digest as they were."""
    if suffix == ".npz":
        with np.load(path) as stored:
            arrays = {name: stored[name] for name in stored.files}
        assert {"store_key", "store_digest"} <= set(arrays)
        arrays["a"] = arrays["a"].copy()
        arrays["a"][1] += 1e-12
        with open(path, "wb") as file:
            np.savez(file, **arrays)
    elif suffix == ".nc":
        import netCDF4

        with netCDF4.Dataset(path, "a") as nc:
            assert "store_digest" in nc.ncattrs()
            nc["x"][1] = np.nan
    else:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
        assert "store_digest" in data
        data["content"]["a"][0] = 2.5
        with open(path, "w", encoding="utf-8") as file:
            json.dump(data, file)


PARTS = [
    (".npz", {"a": np.arange(3.0), "s": "text", "n": 7}),
    (".json", {"a": [1.5, None], "s": "text"}),
    (".nc", xr.Dataset({"x": ("t", np.arange(3.0), {"units": "1"})},
                       coords={"t": np.arange(3)}, attrs={"model": "m", "level": 2})),
]


def _same(out, content, suffix):
    if suffix == ".nc":
        xr.testing.assert_identical(out, content)
    else:
        assert set(out) == set(content)
        for name in content:
            np.testing.assert_array_equal(out[name], content[name])


@pytest.mark.parametrize(("suffix", "content"), PARTS)
def test_a_part_edited_on_disk_is_set_aside_named_and_recomputed(tmp_path, suffix, content):
    """Issue 45: a part whose content was changed after it was written (key and digest
    left as they were) is found out on reading, moved aside to .bad, named in one line
    and computed again; an untouched part beside it is read back."""
    store = Store(tmp_path, "job")
    for k in (1, 2):
        store.get("thing", {"k": k}, lambda: content, suffix)
    edited = store.path("thing", {"k": 1}, suffix)
    _edit_one_number(edited, suffix)

    lines = []
    again = Store(tmp_path, "job", log=lines.append)
    got = again.get("thing", {"k": 1}, lambda: content, suffix)
    kept = again.get("thing", {"k": 2}, lambda: pytest.fail("recomputed"), suffix)
    assert again.computed == 1 and again.set_aside == 1
    assert len(lines) == 1 and "\n" not in lines[0]
    assert lines[0].startswith(f"job part {edited} is damaged (its content differs from the "
                               f"digest it was written with")
    assert os.path.exists(edited + ".bad")
    _same(got, content, suffix)
    _same(kept, content, suffix)
    assert again.load("thing", {"k": 1}, suffix) is not None  # the recomputed one is whole


def test_the_digest_is_of_the_content_not_of_the_bytes(tmp_path):
    """A JSON part written out again with other spacing holds the same content: kept."""
    store = Store(tmp_path, "job")
    store.get("p", {}, lambda: {"a": [0.1, 2], "b": "x"}, ".json")
    path = store.path("p", {}, ".json")
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    with open(path, "w", encoding="utf-8") as file:
        json.dump(data, file, indent=4, sort_keys=True)
    assert Store(tmp_path, "job", log=pytest.fail).load("p", {}, ".json") == \
        {"a": [0.1, 2], "b": "x"}


def test_a_part_without_its_digest_is_set_aside(tmp_path):
    lines = []
    store = Store(tmp_path, "job", log=lines.append)
    store.get("p", {}, lambda: {"v": np.arange(3)})
    path = store.path("p", {})
    with np.load(path) as stored:
        arrays = {name: stored[name] for name in stored.files if name != "store_digest"}
    with open(path, "wb") as file:
        np.savez(file, **arrays)
    assert store.get("p", {}, lambda: {"v": np.arange(3)})["v"].tolist() == [0, 1, 2]
    assert len(lines) == 1 and "stores no digest of its content" in lines[0]
    with pytest.raises(ValueError, match="reserved"):
        store.save("q", {}, {"store_digest": 1})


def test_an_edited_slice_of_a_stochastic_diagram_is_recomputed(tmp_path):
    """Issue 45's case end to end: the parts of a stochastic diagram, one slice's
    probability scaled and another's Monte Carlo type changed on disk between two runs:
    the rerun names both, computes them again and gives the clean run's diagram (it
    wrote NaN probabilities and exited 0 before)."""
    from opa import preset
    from opa.dynamics._stochastic import stochastic_diagram

    kw = dict(sigma=0.03, samples=8, transient=200, extra_states=1, coexist=4,
              parts=str(tmp_path / "parts"))
    values = [0.04, 0.05]
    clean = stochastic_diagram(preset("3.1"), "c", values, **kw)
    slices = sorted((tmp_path / "parts").glob("slice-*.npz"))
    assert len(slices) == 2
    for path, (entry, edit) in zip(slices, [("prob_value", lambda a: a * 0.5),
                                            ("mc_type", lambda a: np.full_like(a, "2/2"))]):
        with np.load(path) as stored:
            arrays = {name: stored[name] for name in stored.files}
        arrays[entry] = edit(arrays[entry])
        with open(path, "wb") as file:
            np.savez(file, **arrays)
    lines = []
    again = stochastic_diagram(preset("3.1"), "c", values, **kw, log=lines.append)
    damaged = [line for line in lines if " is damaged " in line]
    assert len(damaged) == 2 and all(str(p) in line for p, line in zip(slices, damaged))
    assert all(p.with_name(p.name + ".bad").exists() for p in slices)
    assert np.isfinite(again.probability.values).all()
    for name in ("probability", "mc_probability", "mc_type", "mc_xi", "boundary_xi"):
        np.testing.assert_array_equal(again[name].values, clean[name].values, err_msg=name)


def test_a_force_law_keys_a_part_and_the_paper_law_keeps_the_old_keys():
    """Fields added later (the oscillator's ``force`` and lower wall) count in a digest only
    when set:
    the paper's law hashes as before the field existed (no ``force`` entry), two user's
    laws, or two values of one constant, hash apart."""
    import opa
    from opa._dataset import _canonical, digest

    canonical = _canonical(opa.Oscillator())
    assert not {"force", "delta_minus", "eta_minus"} & set(canonical)  # added later, unset
    assert "delta_minus" in _canonical(opa.Oscillator(delta_minus=-2.0))
    law = opa.ForceLaw("-2*zeta*v - x", zeta=0.05)
    a, b = opa.Oscillator(force=law), opa.Oscillator(force=law.__class__("-2*zeta*v - x",
                                                                         zeta=0.06))
    assert digest(a) == digest(opa.Oscillator(force=opa.ForceLaw("-2*zeta*v - x", zeta=0.05)))
    assert len({digest(a), digest(b), digest(opa.Oscillator())}) == 3
