"""Tests for the checkpoint of mc.simulate_mc (mc._checkpoint): nothing is lost, nothing
is computed twice, nothing is left behind, and the resumed result is the uninterrupted
one bit for bit (README, 'Errors, limits and resuming')."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import mc
import opa
from mc import _ensemble

OSC = opa.preset("3.2", omega=3.98)
# 6 chunks of 16 samples, 16 randomised-QMC replicates, paths kept
RUN = dict(sigma=0.05, samples=96, sampler="sobol", seed=3, periods=3, per_period=4,
           chunk_size=16, order=3, options=opa.SolverOptions(rtol=1e-8, atol=1e-8),
           progress=False)  # fmt: skip
VARIABLES = ("x_mean", "v_mean", "x_var", "v_var", "x_sem", "v_sem", "x_var_sem", "x_coef",
             "x_coef_sem", "n_impacts", "xi", "weight", "x", "v")  # fmt: skip


@pytest.fixture(scope="module")
def fresh():
    """The uninterrupted run, without a checkpoint."""
    return mc.simulate_mc(OSC, keep_paths=True, **RUN)


def assert_identical(ds, reference):
    for name in VARIABLES:
        np.testing.assert_array_equal(ds[name].values, reference[name].values, err_msg=name)
    differing = {k for k in reference.attrs
                 if not np.array_equal(ds.attrs.get(k), reference.attrs[k])}
    assert differing <= {"history"}  # history holds a time stamp


def chunk_files(directory) -> list[str]:
    return sorted(n for n in os.listdir(directory) if n.startswith("chunk-"))


def forge_chunk(directory, name, arrays) -> None:
    """Write ``arrays`` as chunk file ``name`` the way the checkpoint itself writes a
    chunk (its key, the digest of its content): a chunk that passes the store's checks
    and only the checkpoint's own can find wrong."""
    from opa._dataset import Store

    settings = json.loads((directory / "store.json").read_text())["settings"]
    stem = name.rsplit("_", 1)[0]  # chunk-IIIIII-LO-HI
    lo, hi = (int(v) for v in stem.split("-")[2:])
    store = Store(directory, "Monte Carlo checkpoint", settings=settings)
    assert store.path(stem, [lo, hi]) == str(directory / name)
    store.save(stem, [lo, hi], arrays)


@pytest.fixture
def counted(monkeypatch):
    """The chunks computed (not loaded), by their first sample."""
    computed = []
    original = _ensemble.integrate_chunk

    def integrate_chunk(y0, xi, *args, **kwargs):
        computed.append(len(xi))
        return original(y0, xi, *args, **kwargs)

    monkeypatch.setattr(_ensemble, "integrate_chunk", integrate_chunk)
    return computed


def test_rerun_loads_every_finished_chunk_and_is_bit_identical(tmp_path, fresh, counted):
    parts = tmp_path / "run.nc.parts"
    first = mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    assert len(counted) == 6
    names = chunk_files(parts)
    assert [n.rsplit("_", 1)[0] for n in names] == \
        [f"chunk-{i:06d}-{16 * i}-{16 * i + 16}" for i in range(6)]
    assert all(len(n.rsplit("_", 1)[1]) == len("0123456789ab.npz") for n in names)
    assert json.loads((parts / "store.json").read_text())["settings"]["seed"] == 3
    again = mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    assert len(counted) == 6  # nothing computed twice
    assert_identical(first, fresh)
    assert_identical(again, fresh)


def test_lost_and_damaged_chunks_are_recomputed_and_the_result_is_bit_identical(
        tmp_path, fresh, counted):
    parts = tmp_path / "parts"
    mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    names = chunk_files(parts)
    os.remove(parts / names[1])  # lost
    data = (parts / names[3]).read_bytes()
    (parts / names[3]).write_bytes(data[: len(data) // 2])  # truncated
    (parts / names[4]).write_bytes(b"")  # zero bytes
    counted.clear()
    lines = []
    resumed = mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, log=lines.append, **RUN)
    assert_identical(resumed, fresh)
    assert len(counted) == 3
    damaged = [line for line in lines if " is damaged " in line]
    assert len(damaged) == 2
    for name, line in zip((names[3], names[4]), damaged):
        assert str(parts / name) in line and "\n" not in line
        assert (parts / (name + ".bad")).exists()
    assert chunk_files(parts) == sorted([*names, names[3] + ".bad", names[4] + ".bad"])
    assert any("3 of 6 chunks already finished" in line for line in lines)


def test_a_damaged_chunk_warns_by_default(tmp_path, fresh):
    parts = tmp_path / "parts"
    mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    name = chunk_files(parts)[0]
    (parts / name).write_bytes(b"not a zip file")
    with pytest.warns(RuntimeWarning, match=rf"checkpoint part .*{name} is damaged"):
        resumed = mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    assert_identical(resumed, fresh)


@pytest.mark.parametrize(("entry", "edit"), [
    ("x_mean", lambda a: a * 1.5),  # a value scaled
    ("x_mean", lambda a: np.where(np.arange(a.size).reshape(a.shape) == 3, np.nan, a)),
    ("n_impacts", lambda a: a + 1),
])  # fmt: skip
def test_a_chunk_edited_on_disk_is_set_aside_and_recomputed(tmp_path, fresh, counted, entry,
                                                           edit):
    """Issue 45: a chunk whose numbers were changed after it was written (its key and
    its digest left as they were) is named, moved aside and computed again; the other
    chunks are read back, and the result is the uninterrupted run's, bit for bit."""
    parts = tmp_path / "run.nc.parts"
    mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    name = chunk_files(parts)[2]
    with np.load(parts / name) as data:
        arrays = {k: data[k] for k in data.files}
    assert entry in arrays and "store_digest" in arrays
    arrays[entry] = edit(arrays[entry])
    with open(parts / name, "wb") as file:
        np.savez(file, **arrays)
    counted.clear()
    lines = []
    resumed = mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, log=lines.append, **RUN)
    damaged = [line for line in lines if " is damaged " in line]
    assert len(damaged) == 1 and str(parts / name) in damaged[0]
    assert "differs from the digest it was written with" in damaged[0]
    assert counted == [16]  # that chunk alone
    assert (parts / (name + ".bad")).exists()
    assert_identical(resumed, fresh)


def test_a_second_process_is_refused_the_checkpoint_while_the_first_writes_it(tmp_path,
                                                                             fresh):
    """A run of the checkpoint in another process (SIGSTOPped while it holds the
    directory: it writes no more) makes a run here fail at once naming its pid; once it
    is killed, its lock is taken over (one line) and the run resumes from its chunks."""
    parts = tmp_path / "parts"
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    script = textwrap.dedent(KILLED_RUN).replace("samples=1024", "samples=96").replace(
        "chunk_size=8", "chunk_size=16")
    child = subprocess.Popen([sys.executable, "-c", script, str(parts)], cwd=root)
    try:
        deadline = time.monotonic() + 120
        while (not parts.exists() or not chunk_files(parts)) and child.poll() is None:
            assert time.monotonic() < deadline, "no chunk file within 120 s"
            time.sleep(0.01)
        child.send_signal(signal.SIGSTOP)
        assert child.poll() is None, "the run finished before it could be stopped"
        with pytest.raises(ValueError, match=rf"Monte Carlo checkpoint '.*parts' is in use "
                                             rf"by process {child.pid} \(python -c ") as err:
            mc.simulate_mc(OSC, checkpoint=parts, **KILLED_KW)
        assert "\n" not in str(err.value)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    kept = len(chunk_files(parts))
    lines = []
    resumed = mc.simulate_mc(OSC, checkpoint=parts, log=lines.append, **KILLED_KW)
    taken = [line for line in lines if "took over the lock" in line]
    assert len(taken) == 1 and f"process {child.pid} " in taken[0]
    assert any(f"{kept} of 6 chunks already finished" in line for line in lines), lines
    np.testing.assert_array_equal(resumed.x_mean.values,
                                  mc.simulate_mc(OSC, **KILLED_KW).x_mean.values)


def test_a_chunk_with_wrong_contents_is_recomputed(tmp_path, fresh):
    """A readable file whose arrays do not fit (here: a chunk of the statistics without
    paths, copied over) is damage too."""
    parts = tmp_path / "parts"
    mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    name = chunk_files(parts)[2]
    with np.load(parts / name) as data:
        arrays = {k: data[k] for k in data.files if k not in ("paths", "store_key",
                                                              "store_digest")}
    forge_chunk(parts, name, arrays)
    lines = []
    resumed = mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, log=lines.append, **RUN)
    assert any("missing or unexpected" in line for line in lines)
    assert_identical(resumed, fresh)


def test_a_chunk_without_the_coefficient_sums_of_squares_is_recomputed(tmp_path, fresh):
    """A chunk as the previous format wrote it (no x_moment_m2, x_moment_rep), under this
    run's own id, is damage: recomputed, and the result (x_coef_sem included) is the
    uninterrupted one bit for bit."""
    parts = tmp_path / "parts"
    mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    name = chunk_files(parts)[1]
    with np.load(parts / name) as data:
        arrays = {k: data[k] for k in data.files if k not in ("x_moment_m2", "x_moment_rep",
                                                              "store_key", "store_digest")}
    forge_chunk(parts, name, arrays)
    lines = []
    resumed = mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, log=lines.append, **RUN)
    damaged = [line for line in lines if " is damaged " in line]
    assert len(damaged) == 1 and "x_moment_m2" in damaged[0] and "x_moment_rep" in damaged[0]
    assert_identical(resumed, fresh)


def test_a_checkpoint_of_the_previous_format_is_refused_naming_it(tmp_path):
    """Format 1 chunks lack the coefficients' SE sums: the directory is another run's,
    refused in one line that names both formats, and left untouched."""
    parts = tmp_path / "parts"
    mc.simulate_mc(OSC, checkpoint=parts, **RUN)
    marker = json.loads((parts / "store.json").read_text())
    assert marker["settings"]["format"] == "opa-mc monte-carlo checkpoint 2"
    marker["settings"]["format"] = "opa-mc monte-carlo checkpoint 1"
    (parts / "store.json").write_text(json.dumps(marker))
    before = {n: (parts / n).read_bytes() for n in os.listdir(parts)}
    with pytest.raises(ValueError, match=r"belongs to another run: format is opa-mc monte-"
                                         r"carlo checkpoint 1 there, opa-mc monte-carlo "
                                         r"checkpoint 2 here") as err:
        mc.simulate_mc(OSC, checkpoint=parts, **RUN)
    assert "\n" not in str(err.value)
    assert {n: (parts / n).read_bytes() for n in os.listdir(parts)} == before


@pytest.mark.parametrize(
    ("change", "key"),
    [
        (dict(seed=4), r"seed is 3 there, 4 here"),
        (dict(sigma=0.04), r"sigma is 0.05 there, 0.04 here"),
        (dict(chunk_size=32), r"chunks is 6 entries there, 3 entries here"),
        (dict(keep_paths=False), r"keep_paths is true there, false here"),
        (dict(options=opa.SolverOptions(rtol=1e-9, atol=1e-8)), r"options.rtol is 1e-08 there"),
        (dict(oscillator=opa.preset("3.2", omega=3.9)), r"oscillator.omega is 3.98 there"),
        (dict(per_period=5), r"times.count is 13 there, 16 here"),
    ],
)  # fmt: skip
def test_a_checkpoint_of_another_run_is_refused(tmp_path, change, key):
    parts = tmp_path / "parts"
    first = {"oscillator": OSC, "keep_paths": True, **RUN}
    mc.simulate_mc(checkpoint=parts, **first)
    before = {n: (parts / n).read_bytes() for n in os.listdir(parts)}
    with pytest.raises(ValueError, match=rf"checkpoint '.*parts' belongs to another run: "
                                         rf"{key}") as err:  # fmt: skip
        mc.simulate_mc(checkpoint=parts, **{**first, **change})
    assert "\n" not in str(err.value)
    assert {n: (parts / n).read_bytes() for n in os.listdir(parts)} == before  # untouched


def test_a_checkpoint_of_an_older_version_is_refused(tmp_path):
    """A directory as versions before the one store wrote it (manifest.json and chunk
    files, no store.json) is refused in one line naming it, and left untouched."""
    parts = tmp_path / "parts"
    parts.mkdir()
    (parts / "manifest.json").write_text("{}")
    (parts / "chunk-000000-0-16.npz").write_bytes(b"")
    with pytest.raises(ValueError, match=r"checkpoint '.*parts' holds files but no "
                                         r"store.json \(chunk-000000-0-16.npz, ...\).*"
                                         r"remove it") as err:
        mc.simulate_mc(OSC, checkpoint=parts, **RUN)
    assert "\n" not in str(err.value)
    assert sorted(os.listdir(parts)) == ["chunk-000000-0-16.npz", "manifest.json"]
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match=r"checkpoint '.*file' is not a directory"):
        mc.simulate_mc(OSC, checkpoint=tmp_path / "file", **RUN)


def dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_temporaries_of_a_killed_writer_are_removed_and_remove_checkpoint_cleans_up(
        tmp_path, fresh):
    parts = tmp_path / "parts"
    mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    stale = parts / f".tmp-opa-mc-{dead_pid()}-abc.npz"
    stale.write_bytes(b"half a chunk")
    resumed = mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    assert not stale.exists()
    assert_identical(resumed, fresh)
    (parts / (chunk_files(parts)[0] + ".bad")).write_bytes(b"")
    mc.remove_checkpoint(parts)
    assert not parts.exists()
    mc.remove_checkpoint(parts)  # already gone: fine
    # a directory holding other files keeps them (and itself)
    mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **RUN)
    (parts / "notes.txt").write_text("mine")
    mc.remove_checkpoint(parts)
    assert os.listdir(parts) == ["notes.txt"]


def test_progress_counts_loaded_chunks_as_done(tmp_path, capsys):
    parts = tmp_path / "parts"
    mc.simulate_mc(OSC, checkpoint=parts, **RUN)
    capsys.readouterr()
    mc.simulate_mc(OSC, checkpoint=parts, **{**RUN, "progress": True})
    err = capsys.readouterr().err
    assert "96/96" in err and " 0/96" not in err


KILLED_RUN = """
import sys
import mc, opa
mc.simulate_mc(opa.preset("3.2", omega=3.98), sigma=0.05, samples=1024, sampler="sobol",
               seed=5, periods=40, per_period=2, chunk_size=8, order=2,
               options=opa.SolverOptions(rtol=1e-9, atol=1e-9), progress=False,
               checkpoint=sys.argv[1])
"""


KILLED_KW = dict(sigma=0.05, samples=96, sampler="sobol", seed=5, periods=40, per_period=2,
                 chunk_size=16, order=2, options=opa.SolverOptions(rtol=1e-9, atol=1e-9),
                 progress=False)  # fmt: skip


def test_a_run_killed_mid_way_resumes_bit_identical(tmp_path):
    """SIGKILL after the first chunk files appear (no chance to clean up), then resume."""
    parts = tmp_path / "parts"
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    child = subprocess.Popen([sys.executable, "-c", textwrap.dedent(KILLED_RUN), str(parts)],
                             cwd=root)  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while (not parts.exists() or len(chunk_files(parts)) < 3) and child.poll() is None:
            assert time.monotonic() < deadline, "no chunk file within 120 s"
            time.sleep(0.02)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    kept = len(chunk_files(parts))
    assert 3 <= kept < 128, kept  # killed mid-run
    kwargs = dict(sigma=0.05, samples=1024, sampler="sobol", seed=5, periods=40, per_period=2,
                  chunk_size=8, order=2, options=opa.SolverOptions(rtol=1e-9, atol=1e-9),
                  progress=False)  # fmt: skip
    lines = []
    resumed = mc.simulate_mc(OSC, checkpoint=parts, log=lines.append, **kwargs)
    assert not any(" is damaged " in line for line in lines)
    assert len(chunk_files(parts)) == 128
    assert not [n for n in os.listdir(parts) if n.startswith(".tmp")]
    fresh = mc.simulate_mc(OSC, **kwargs)
    for name in VARIABLES[:-2]:
        np.testing.assert_array_equal(resumed[name].values, fresh[name].values, err_msg=name)


# --- the folder's name and lifetime (mc.checkpoint_for, mc.checkpoint_lifetime) ----------


def test_the_checkpoint_of_an_output_is_the_folder_beside_it(tmp_path):
    assert mc.checkpoint_for("runs/mc.nc") == "runs/mc.nc.parts"
    assert mc.checkpoint_for(tmp_path / "a.nc") == f"{tmp_path}/a.nc.parts"
    assert mc.checkpoint_for(None) is None and mc.checkpoint_for("") is None


@pytest.fixture
def finished(tmp_path):
    """The checkpoint of a finished run: 6 chunk files."""
    parts = tmp_path / "run.nc.parts"
    mc.simulate_mc(OSC, checkpoint=parts, **RUN)
    assert len(chunk_files(parts)) == 6
    return parts


@pytest.mark.parametrize(("error", "kept"), [
    (opa.SimulationError("Monte Carlo sample 3 stopped"), False),  # fails every rerun
    (mc.DaskError("the Dask cluster has had no worker for 60 s"), True),  # resumable
    (ValueError("checkpoint belongs to another run"), True),  # not ours to delete
    (OSError(28, "No space left on device"), True),  # the write failed: rerun resumes
    (KeyboardInterrupt(), True),
])  # fmt: skip
def test_after_a_failure_the_checkpoint_goes_only_when_a_rerun_would_fail_again(
        finished, counted, error, kept):
    with pytest.raises(type(error)):
        with mc.checkpoint_lifetime(finished):
            raise error
    assert finished.exists() is kept
    if kept:  # every chunk is still there and loaded by a rerun, none computed again
        mc.simulate_mc(OSC, checkpoint=finished, **RUN)
        assert counted == []


def test_after_the_write_the_checkpoint_goes_unless_it_is_kept(finished):
    with mc.checkpoint_lifetime(finished, keep=True):
        pass
    assert len(chunk_files(finished)) == 6
    with mc.checkpoint_lifetime(finished):
        pass
    assert not finished.exists()
    with mc.checkpoint_lifetime(None):  # no checkpoint: nothing to do
        pass


def test_a_sample_that_cannot_be_integrated_leaves_no_checkpoint(tmp_path):
    """c < 0 blows up (the runaway guard stops the first sample): the run's folder, made
    before its first chunk, is left behind by simulate_mc alone and removed under the
    lifetime rules."""
    runaway = dict(sigma=0.01, samples=16, periods=50, progress=False)
    alone, ruled = tmp_path / "alone.parts", tmp_path / "ruled.parts"
    with pytest.raises(opa.SimulationError, match="runaway guard"):
        mc.simulate_mc(opa.Oscillator(c=-1.0), checkpoint=alone, **runaway)
    assert os.listdir(alone) == ["store.json"]
    with pytest.raises(opa.SimulationError, match="runaway guard"):
        with mc.checkpoint_lifetime(ruled):
            mc.simulate_mc(opa.Oscillator(c=-1.0), checkpoint=ruled, **runaway)
    assert not ruled.exists()


def test_an_ensemble_of_several_parameters_resumes_bit_identical(tmp_path, counted):
    """(mu, c): a lost chunk is recomputed and the resumed ensemble is the uninterrupted
    one bit for bit; a checkpoint of other scales is refused."""
    run = dict(RUN, sigma=(0.05, 0.01), uncertain="mu,c", order=2)
    fresh = mc.simulate_mc(OSC, keep_paths=True, **run)
    parts = tmp_path / "parts"
    mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **run)
    os.remove(parts / chunk_files(parts)[2])
    counted.clear()
    resumed = mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **run)
    assert len(counted) == 1
    assert_identical(resumed, fresh)
    assert resumed.xi.dims == ("sample", "parameter")
    with pytest.raises(ValueError, match="checkpoint"):
        mc.simulate_mc(OSC, keep_paths=True, checkpoint=parts, **dict(run, sigma=(0.05, 0.02)))
