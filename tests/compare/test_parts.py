"""The trust map's parts on disk (an opa._dataset.Store): a rerun reuses every finished
piece of work, a part that is damaged, foreign or half-written is named, set aside and
computed again, and a parts folder of a version before the store is refused."""

import os
import shutil
import subprocess
import time

import numpy as np
import pytest
import xarray as xr

import compare._convergence as convergence
import compare._trustmap as trustmap
from compare import load_config, run_validation
from compare._convergence import ConvergenceConfig, run_convergence
from opa._dataset import Store

# one swept value, two sigmas, N = 0 and 1, one horizon, no frontier: about a second
SMALL = dict(values=(3.98,), sigmas=(0.01, 0.03), orders=(0, 1), horizons=(4,), samples=64,
             max_samples=64, per_period=4, frontier=False)
# what differs between two runs by nature: when and how long this run took, what it did
RUN_ATTRS = ("history", "wall_seconds", "mc_runs_computed", "opa_runs_computed",
             "true_runs_computed", "true_periods_computed", "parts_computed",
             "parts_set_aside", "phase_names", "phase_wall_seconds", "phase_cpu_seconds",
             "phase_calls", "ran_on", "true_system_runs", "true_system_time")
INTEGRATORS = {
    trustmap: ("opa_variants", "simulate_mc", "simulate_opa", "simulate_dmr", "scan_splits",
               "_sequence", "element_variants", "adaptive_edges", "true_runs"),
    convergence: ("simulate_opa", "simulate_mc", "collocation", "true_runs"),
}


def _run(outdir):
    lines = []
    cfg = load_config(None, outdir=str(outdir), **SMALL)
    ds = run_validation(cfg, progress=False, log=lines.append)
    return ds, lines


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    out = tmp_path_factory.mktemp("clean")
    ds, _ = _run(out)
    return ds, out / "parts"


@pytest.fixture
def copy(clean, tmp_path):
    """A fresh output directory holding the clean run's parts."""
    shutil.copytree(clean[1], tmp_path / "parts")
    return tmp_path


def _forbid_integration(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("integrated although every part was on disk")

    for module, names in INTEGRATORS.items():
        for name in names:
            monkeypatch.setattr(module, name, refuse)


def _same(a: xr.Dataset, b: xr.Dataset, *, timings: bool = True):
    """Identical data, coordinates and attributes, apart from what describes the run
    itself; without ``timings``, also apart from the wall times (a recomputed part took
    its own time)."""
    a, b = a.copy(), b.copy()
    for ds in (a, b):
        for name in RUN_ATTRS:
            ds.attrs.pop(name, None)
    if not timings:
        seconds = [name for name in a.data_vars if a[name].attrs.get("units") == "s"]
        assert seconds  # the comparison below leaves something out
        a, b = a.drop_vars(seconds), b.drop_vars(seconds)
    xr.testing.assert_identical(a, b)


def _store_lines(lines):
    """What the store said: damaged parts, removed temporaries."""
    return [line for line in lines if " is damaged " in line or line.startswith("parts:")]


def _part(outdir, prefix, index=0):
    names = sorted(p for p in os.listdir(outdir / "parts") if p.startswith(prefix + "_")
                   and not p.endswith(".bad"))
    return outdir / "parts" / names[index]


def test_a_finished_map_is_reassembled_without_integrating(clean, copy, monkeypatch):
    _forbid_integration(monkeypatch)
    ds, lines = _run(copy)
    assert ds.attrs["parts_computed"] == 0 and ds.attrs["mc_runs_computed"] == 0
    assert not _store_lines(lines)
    _same(ds, clean[0])
    with xr.open_dataset(copy / "validate.nc") as back:
        _same(back.load(), clean[0])


@pytest.mark.parametrize("prefix", ["mc", "opa", "splits", "details"])
@pytest.mark.parametrize("length", ["half", "empty"])
def test_a_damaged_part_is_named_set_aside_and_recomputed(clean, copy, prefix, length):
    path = _part(copy, prefix)
    data = path.read_bytes()
    damaged = data[: len(data) // 2] if length == "half" else b""
    path.write_bytes(damaged)
    bad = path.with_name(path.name + ".bad")
    bad.write_bytes(b"an older part set aside")

    ds, lines = _run(copy)

    named = [line for line in lines if path.name in line]
    assert len(named) == 1 and "cannot be read" in named[0], lines
    assert bad.read_bytes() == damaged  # the older one replaced
    assert ds.attrs["parts_computed"] == 1 and ds.attrs["parts_set_aside"] == 1
    assert ds.attrs["mc_runs_computed"] == (prefix == "mc")
    assert ds.attrs["opa_runs_computed"] == (prefix == "opa")
    _same(ds, clean[0], timings=False)
    _, again = _run(copy)  # the recomputed part is whole
    assert not _store_lines(again)


@pytest.mark.parametrize("prefix", ["mc", "opa"])
def test_a_part_of_other_settings_is_found_by_its_stored_key(clean, copy, prefix):
    """The sigma = 0.03 part copied under the name of the sigma = 0.01 one."""
    target = _part(copy, f"{prefix}_omega3.98_sigma0.01")
    shutil.copyfile(_part(copy, f"{prefix}_omega3.98_sigma0.03"), target)

    ds, lines = _run(copy)

    named = [line for line in lines if target.name in line]
    assert len(named) == 1 and "stores the key" in named[0], lines
    assert target.with_name(target.name + ".bad").exists()
    assert ds.attrs["parts_set_aside"] == 1
    _same(ds, clean[0], timings=False)


def test_a_part_without_its_key_is_set_aside(clean, copy):
    """No exception for parts that store no key: such a part is damage."""
    path = _part(copy, "mc_omega3.98_sigma0.01")
    with np.load(path) as stored:
        content = {name: stored[name] for name in stored.files if name != "store_key"}
    with open(path, "wb") as file:
        np.savez(file, **content)
    ds, lines = _run(copy)
    named = [line for line in lines if path.name in line]
    assert len(named) == 1 and "stores no key" in named[0], lines
    assert ds.attrs["mc_runs_computed"] == 1 and ds.attrs["parts_set_aside"] == 1
    _same(ds, clean[0], timings=False)


def test_a_parts_folder_of_an_older_version_is_refused(tmp_path):
    """A folder of parts written before the one store (no store.json) is refused in one
    line naming it, before anything is computed, and left as it was."""
    parts = tmp_path / "parts"
    parts.mkdir()
    (parts / "mc_omega3.98_sigma0.01_M64_0123456789ab.nc").write_bytes(b"old")
    with pytest.raises(ValueError, match=r"trust map '.*parts' holds files but no "
                                         r"store.json .*remove it") as err:
        _run(tmp_path)
    assert "\n" not in str(err.value)
    assert os.listdir(parts) == ["mc_omega3.98_sigma0.01_M64_0123456789ab.nc"]


def test_the_keys_are_the_inputs(clean, copy):
    """Another seed changes the inputs of the Monte Carlo ensembles and the phase
    portraits' (computed again), not those of OPA or of the split scans (reused)."""
    import re

    def stems(names, prefix):
        return {n.rsplit("_", 1)[0] for n in names if n.startswith(prefix + "_")}

    old = set(os.listdir(clean[1]))
    cfg = load_config(None, outdir=str(copy), seed=1, **SMALL)
    ds = run_validation(cfg, progress=False, log=lambda *a: None)
    new = set(os.listdir(copy / "parts")) - old
    assert stems(old, "mc") <= stems(new, "mc")  # every ensemble again, under a new key
    assert stems(new, "details")
    assert not stems(new, "splits")
    # OPA only at the sigmas the new bisections probe (the verdicts may move)
    probed = {re.search(r"_sigma([0-9.e-]+)_", n)[1] for n in stems(old, "opa")}
    assert not {re.search(r"_sigma([0-9.e-]+)_", n)[1] for n in stems(new, "opa")} & probed
    assert ds.attrs["parts_set_aside"] == 0


def _dead_pid() -> int:
    child = subprocess.Popen(["true"])
    child.wait()
    return child.pid


def test_temporaries_of_killed_writers_are_removed(clean, copy):
    parts = copy / "parts"
    dead = parts / f".tmp-opa-mc-{_dead_pid()}-x1y2.nc"
    dead.write_bytes(b"half a netCDF file")
    empty = parts / ".tmp-a8b7c6.nc"  # an older version's name, no pid: removed when empty
    empty.write_bytes(b"")  # and untouched for a minute (a writer of that version is gone)
    os.utime(empty, (time.time() - 120, time.time() - 120))
    live = parts / f".tmp-opa-mc-{os.getpid()}-z9.npz"  # a writer still running
    live.write_bytes(b"")
    young = parts / ".tmp-d5e4f3.nc"  # no pid, written to a moment ago
    young.write_bytes(b"data")

    ds, lines = _run(copy)

    assert not dead.exists() and not empty.exists()
    assert live.exists() and young.exists()
    named = [line for line in lines if dead.name in line]
    assert len(named) == 1 and empty.name in named[0]
    assert ds.attrs["parts_computed"] == 0
    _same(ds, clean[0])


CONVERGENCE = dict(sigma=0.02, periods=2, per_period=4, orders=(0, 1), uniform=(1, 2),
                   budgets=(2, 4), order_budget=4, single_nodes=(1, 2), mc_samples=(64, 128),
                   reference=1024)


def test_the_convergence_study_runs_each_run_once(tmp_path, monkeypatch):
    cfg = ConvergenceConfig(outdir=str(tmp_path), **CONVERGENCE)
    parts = Store(str(tmp_path), "trust map", log=lambda *a: None)

    def memo(run, spec, compute):
        return parts.get(f"frontier_{run}", spec, compute)

    first = run_convergence(cfg, log=lambda *a: None, write=False, memo=memo)
    # every run the study lists (the reference, each OPA and collocation row, the three
    # ladders), beside store.json
    runs = {}
    while todo := convergence.pending_runs(cfg, runs):
        runs.update((run.name, run.compute()) for run in todo)
    assert parts.computed == len(os.listdir(tmp_path)) - 1 == len(runs)
    # the MC, Sobol' and control-variate rows at each rung come from three ladder runs
    ladder_rows = 3 * len(cfg.mc_samples)
    assert len(runs) == 1 + first.sizes["run"] - ladder_rows + 3
    plain = run_convergence(cfg, log=lambda *a: None, write=False)
    # the same rows as without parts, apart from the wall times
    _same(first.drop_vars("seconds").drop_attrs(deep=False),
          plain.drop_vars("seconds").drop_attrs(deep=False))

    _forbid_integration(monkeypatch)
    again = run_convergence(cfg, log=lambda *a: None, write=False, memo=memo)
    _same(again, first)
    assert again.attrs["wall_seconds"] == first.attrs["wall_seconds"]
    singles = first.seconds.values[first.law.values != "true system"].sum()
    assert first.attrs["wall_seconds"] > singles + first.attrs["reference_seconds"]


def test_adding_elements_to_a_finished_map_reuses_its_parts(clean, copy, monkeypatch):
    """The same map with elements = 2 computes the multi-element parts, and single-element
    OPA only at the sigmas its own bisections probe: every OPA part and the split scans of
    the finished map are reused. The Monte Carlo rounds are paired with the new variants
    too, so they are run again (they keep verdicts, not paths)."""
    import re

    def sigmas(names):
        return {m.group(1) for n in names if (m := re.search(r"_sigma([0-9.e-]+)_", n))}

    old = os.listdir(clean[1])
    monkeypatch.setattr(trustmap, "scan_splits", _refuse)
    monkeypatch.setattr(trustmap, "_sequence", _refuse)
    cfg = load_config(None, outdir=str(copy), elements=2, **SMALL)
    ds = run_validation(cfg, progress=False, log=lambda *a: None)
    new = [p for p in os.listdir(copy / "parts") if p not in old]
    assert any(p.startswith("elements_") for p in new)
    assert not sigmas(p for p in new if p.startswith("opa_")) & sigmas(old), new
    assert ds.attrs["parts_computed"] == len(new) and ds.attrs["parts_set_aside"] == 0
    single = ds.isel(variant=slice(0, 5))
    np.testing.assert_array_equal(single.opa_x_mean.values[..., -1, :],
                                  clean[0].opa_x_mean.values[..., -1, :])


def _refuse(*args, **kwargs):
    raise AssertionError("integrated although the part was on disk")
