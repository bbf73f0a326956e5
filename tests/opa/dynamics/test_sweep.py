"""Tests for ``opa.dynamics._sweep`` (sweeps; their command line is tested in
``tests/opa/cli/test_bifurcation.py``).

The dataset contract of docs/datasets.md, labels and period doubling on sweeps whose
motions are known (section 3.1 without impulses: 4/4 at c = 0.035, 2/2 at c = 0.05;
section 3.3 without impulses: 1/1 -> 2/2 between omega = 4.9 and 5.0), parallel ==
serial, and crash safety: a sweep interrupted after k points and rerun computes only
the missing points and returns exactly the uninterrupted result.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import opa.dynamics._sweep as B
from opa import preset, sweep
from opa._model import PARAMETER_NAMES

QUICK = {"transient": 20, "record": 10, "per_period": 8, "workers": 1}
REPO = str(Path(__file__).resolve().parents[3])


def assert_same(a: xr.Dataset, b: xr.Dataset) -> None:
    drop = ["history", "points_resumed", "points_computed"]
    xr.testing.assert_identical(a.drop_attrs(), b.drop_attrs())  # values and coordinates
    assert {k: v for k, v in a.attrs.items() if k not in drop} == pytest.approx(
        {k: v for k, v in b.attrs.items() if k not in drop}, nan_ok=True)


# --------------------------------------------------------------------------- contract


def test_dataset_contract(tmp_path):
    osc = preset("3.1")
    values = [0.02, 0.05, 0.08]
    ds = sweep("dmr", "c", values, osc, out=tmp_path / "s.nc", **QUICK)
    assert ds.sizes["c"] == 3
    assert ds.sizes["point"] >= 10
    for name in ("section_x", "section_v", "impact_phase", "impact_v"):
        assert ds[name].dims == ("c", "point")
    for name in ("period", "impacts", "label", "residual", "impact_rate",
                 "min_impact_velocity", "min_gap", "grazing", "observed_doubling",
                 "period_doubling", "failed"):
        assert ds[name].dims == ("c",)
    np.testing.assert_array_equal(ds.period_doubling, ds.observed_doubling)  # former name
    for name in ("bifurcation_parameter", "bifurcation_kind", "bifurcation_period",
                 "bifurcation_multiplier_real", "bifurcation_multiplier_imag",
                 "bifurcation_located", "bifurcation_x", "bifurcation_v", "bifurcation_note"):
        assert ds[name].dims == ("bifurcation",)
    assert ds.attrs["bifurcation_method"].startswith("continuation")  # dmr: on by default
    assert ds.period.dtype.kind == "i" and ds.impacts.dtype.kind == "i"
    np.testing.assert_array_equal(ds.c.values, values)
    # the record's stroboscopic points, NaN padded beyond them
    assert np.all(np.isfinite(ds.section_x.values[:, :10]))
    assert np.all(np.isnan(ds.section_x.values[:, ds.sizes["point"] - 1 :])) or \
        ds.sizes["point"] == 10
    # every variable labelled, every parameter in the attributes, no bools
    for name, var in ds.variables.items():
        assert "long_name" in var.attrs, name
        if var.dtype.kind not in "UO":  # strings have no units
            assert "units" in var.attrs, name
    for name in PARAMETER_NAMES + ("sigma", "N", "impulse", "truncation", "impact_law", "rtol",
                                   "atol", "seed", "sampler", "Conventions", "history",
                                   "opa_mc_version", "sweep_parameter", "transient", "record",
                                   "continuation"):
        assert name in ds.attrs, name
    assert np.isnan(ds.attrs["c"])  # swept: the coordinate holds it
    assert not any(isinstance(v, (bool, dict, type(None))) for v in ds.attrs.values())
    # written atomically, parts removed, and what is on disk is what was returned
    assert not os.path.exists(str(tmp_path / "s.nc") + ".parts")
    with xr.open_dataset(tmp_path / "s.nc") as disk:
        assert_same(disk.load(), ds)


def test_labels_and_period_doubling_on_known_sweeps():
    ds = sweep("dmr", "c", [0.035, 0.05], preset("3.1", F0=0.0), transient=200, record=40,
               workers=1)
    assert ds.label.values.tolist() == ["4/4", "2/2"]
    assert ds.period.values.tolist() == [4, 2] and ds.impacts.values.tolist() == [4, 2]
    assert ds.observed_doubling.values.tolist() == [1, 0]  # 2 -> 4 going down in c
    ds = sweep("dmr", "omega", [4.9, 5.0], preset("3.3", F0=0.0), transient=200, record=40,
               workers=1)
    assert ds.label.values.tolist() == ["1/1", "2/2"]
    assert ds.observed_doubling.values.tolist() == [0, 1]


def test_opa_sigma_sweep_and_emr0_equals_dmr():
    osc = preset("3.1", c=0.05, F0=0.0)
    emr = sweep("opa", "sigma", [0.0, 0.05], osc, order=2, transient=100, record=20,
                workers=1)
    dmr = sweep("dmr", "x0", [osc.x0], osc, transient=100, record=20, workers=1)
    assert emr.label.values.tolist() == ["2/2", "2/2"]
    np.testing.assert_allclose(emr.section_x.values[0, :20], dmr.section_x.values[0, :20],
                               atol=1e-8)  # EMR_0 reduces to the DMR


def test_mc_sweep_has_phase_section_only():
    from mc import sweep_source
    from opa.dynamics import MonteCarlo

    ds = sweep("mc", "c", [0.05], preset("3.1", F0=0.0), sigma=0.01,
               mc=MonteCarlo(source=sweep_source, samples=8), **QUICK)
    assert np.all(np.isfinite(ds.section_x.values[0, :10]))
    assert np.all(np.isnan(ds.impact_v.values)) and ds.impacts.values.tolist() == [-1]
    assert ds.attrs["samples"] == 8 and ds.attrs["sampler"] == "sobol"


def test_parallel_equals_serial():
    osc = preset("3.1")
    values = np.linspace(0.03, 0.06, 4)
    serial = sweep("dmr", "c", values, osc, transient=30, record=10, workers=1)
    parallel = sweep("dmr", "c", values, osc, transient=30, record=10, workers=2)
    assert_same(serial, parallel)


def test_the_records_give_the_keywords_run_and_refuse_both_at_once(tmp_path):
    """``window=Window(...)`` and ``motion=MotionTolerances(...)`` are the keywords' run to
    the bit; a keyword beside its record is refused naming both; a checkpoint folder given
    in the execution record holds the parts and is kept after the write."""
    from opa import Execution
    from opa.dynamics._sections import MotionTolerances
    from opa.dynamics._sweep import Window

    osc = preset("3.1")
    values = [0.035, 0.05]
    by_keywords = sweep("dmr", "c", values, osc, transient=30, record=10, per_period=8,
                        period_tol=1e-3, workers=1)
    kept = tmp_path / "kept"
    by_records = sweep("dmr", "c", values, osc, window=Window(30, 10, 8),
                       motion=MotionTolerances(period_tol=1e-3), out=tmp_path / "d.nc",
                       execution=Execution(workers=1, checkpoint=str(kept)))
    assert_same(by_keywords, by_records)
    assert len(list(kept.glob("point-*"))) == 2  # kept: the user named it
    with pytest.raises(ValueError, match=r"sweep: give record inside window=Window"):
        sweep("dmr", "c", values, osc, window=Window(30, 10, 8), record=20)
    with pytest.raises(ValueError, match=r"window must be an opa.dynamics.Window"):
        sweep("dmr", "c", values, osc, window=(30, 10, 8))
    with pytest.raises(ValueError, match=r"per_period must be an integer >= 1, got 0"):
        Window(per_period=0)


def test_an_execution_record_runs_the_points_as_its_keywords_did():
    """``execution=Execution(workers=2)`` is the keywords' run; both at once is refused."""
    from opa import Execution

    osc = preset("3.1")
    values = np.linspace(0.03, 0.06, 3)
    by_keywords = sweep("dmr", "c", values, osc, transient=30, record=10, workers=2)
    by_record = sweep("dmr", "c", values, osc, transient=30, record=10,
                      execution=Execution(workers=2, progress=False))
    assert_same(by_keywords, by_record)
    with pytest.raises(ValueError, match=r"sweep: give workers inside execution="):
        sweep("dmr", "c", values, osc, workers=2, execution=Execution())
    with pytest.raises(ValueError, match=r"workers must be an integer >= 1, got 0"):
        sweep("dmr", "c", values, osc, workers=0)


@pytest.mark.slow  # a local cluster's workers each import opa and load the kernel
def test_dask_scheduler_gives_the_local_result(tmp_path):
    """Points as Dask tasks on two worker processes, by Client and by address, fixed and
    continued: the same dataset as the local run (the dashboard takes a free port)."""
    distributed = pytest.importorskip("distributed")
    osc = preset("3.1")
    values = [0.03, 0.05, 0.07]
    kw = {"transient": 30, "record": 10, "per_period": 8}
    local = sweep("dmr", "c", values, osc, workers=1, **kw)
    local_cont = sweep("dmr", "c", values, osc, workers=1, continuation="forward", **kw)
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                 dashboard_address=":0") as cluster,
        distributed.Client(cluster) as client,
    ):
        by_client = sweep("dmr", "c", values, osc, scheduler=client, out=tmp_path / "d.nc",
                          **kw)
        by_address = sweep("dmr", "c", values, osc, scheduler=cluster.scheduler_address, **kw)
        continued = sweep("dmr", "c", values, osc, scheduler=client, continuation="forward",
                          **kw)
    assert_same(by_client, local)
    assert_same(by_address, local)
    assert_same(continued, local_cont)


# --------------------------------------------------------------------------- resumption


class Interrupt(Exception):
    pass


def interrupt_after(monkeypatch, k):
    """Make the k+1-th write of a finished point raise, as a crash at that moment would."""
    real = B._write_part
    written = []

    def write(parts, result):
        if len(written) == k:
            raise Interrupt
        written.append(result["index"])
        real(parts, result)

    monkeypatch.setattr(B, "_write_part", write)
    return written


def count_computed(monkeypatch):
    real = B.compute_point
    computed = []

    def compute(task):
        computed.append(task.index)
        return real(task)

    monkeypatch.setattr(B, "compute_point", compute)
    return computed


@pytest.mark.parametrize("continuation", ["fixed", "forward", "backward"])
def test_interrupted_sweep_resumes_without_loss_or_rework(tmp_path, monkeypatch,
                                                          continuation):
    osc = preset("3.1")
    values = np.linspace(0.02, 0.08, 6)
    kw = {"transient": 30, "record": 10, "per_period": 8, "workers": 1,
          "continuation": continuation}
    reference = sweep("dmr", "c", values, osc, **kw)
    out = tmp_path / "sweep.nc"

    with monkeypatch.context() as m:
        written = interrupt_after(m, 3)
        with pytest.raises(Interrupt):
            sweep("dmr", "c", values, osc, out=out, **kw)
    parts = str(out) + ".parts"
    assert len(written) == 3 and not out.exists()
    assert sorted(f.rsplit("_", 1)[0] for f in os.listdir(parts) if f.startswith("point-")) \
        == [f"point-{i:05d}" for i in sorted(written)]
    before = {f: os.stat(os.path.join(parts, f)).st_mtime_ns for f in os.listdir(parts)}

    with monkeypatch.context() as m:
        computed = count_computed(m)
        resumed = sweep("dmr", "c", values, osc, out=out, keep_parts=True, **kw)
    assert sorted(computed) == sorted(set(range(6)) - set(written))  # nothing redone
    assert resumed.attrs["points_resumed"] == 3 and resumed.attrs["points_computed"] == 3
    for f, mtime in before.items():  # finished points untouched
        assert os.stat(os.path.join(parts, f)).st_mtime_ns == mtime
    assert_same(resumed, reference)  # nothing lost
    if continuation == "forward":
        assert written == [0, 1, 2]
    elif continuation == "backward":
        assert written == [5, 4, 3]


def test_damaged_parts_are_set_aside_and_recomputed(tmp_path, monkeypatch):
    """A truncated, an empty and a part holding another point, plus a killed writer's
    temporary: the rerun names each, moves it to .bad, recomputes exactly those points
    (and the one whose file went elsewhere) and loses nothing."""
    osc = preset("3.1")
    values = np.linspace(0.02, 0.08, 5)
    kw = {"transient": 30, "record": 10, "per_period": 8, "workers": 1}
    reference = sweep("dmr", "c", values, osc, **kw)
    out = tmp_path / "sweep.nc"
    with monkeypatch.context() as m:
        interrupt_after(m, 4)
        with pytest.raises(Interrupt):
            sweep("dmr", "c", values, osc, out=out, **kw)
    parts = str(out) + ".parts"
    point = {int(f[6:11]): os.path.join(parts, f) for f in os.listdir(parts)
             if f.startswith("point-")}
    assert sorted(point) == [0, 1, 2, 3]
    data = Path(point[0]).read_bytes()
    Path(point[0]).write_bytes(data[: len(data) // 2])  # truncated
    Path(point[1]).write_bytes(b"")  # empty
    os.replace(point[2], point[3])  # point 3's file holds point 2
    stale = os.path.join(parts, ".tmp-opa-mc-999999999-x.npz")
    Path(stale).write_bytes(b"")  # a temporary of a writer that is gone
    with monkeypatch.context() as m:
        computed = count_computed(m)
        with pytest.warns(RuntimeWarning, match="moved aside") as caught:
            resumed = sweep("dmr", "c", values, osc, out=out, keep_parts=True, **kw)
    assert sorted(computed) == [0, 1, 2, 3, 4]
    assert len(caught) == 3
    assert "other inputs" in str(caught[2].message)
    assert all(os.path.exists(point[i] + ".bad") for i in (0, 1, 3))
    assert not os.path.exists(stale)
    assert_same(resumed, reference)


def test_resume_refuses_different_settings(tmp_path, monkeypatch):
    osc = preset("3.1")
    out = tmp_path / "sweep.nc"
    with monkeypatch.context() as m:
        interrupt_after(m, 1)
        with pytest.raises(Interrupt):
            sweep("dmr", "c", [0.02, 0.05], osc, out=out, **QUICK)
    with pytest.raises(ValueError, match="belongs to another run: record is 10 there, 12 here"):
        sweep("dmr", "c", [0.02, 0.05], osc, out=out, **{**QUICK, "record": 12})


def test_killed_sweep_process_resumes(tmp_path, monkeypatch):
    """SIGKILL a sweep in another process half way, then finish it here.

    The other process pauses 0.2 s after each finished point, so that the kill lands
    while points are still missing whatever the speed of the machine."""
    out = tmp_path / "killed.nc"
    parts = str(out) + ".parts"
    script = (
        "import time\n"
        "import numpy as np\n"
        "import opa.dynamics._sweep as B\n"
        "from opa import preset\n"
        "from opa.dynamics._sweep import sweep\n"
        "write = B._write_part\n"
        "B._write_part = lambda *a: (write(*a), time.sleep(0.2))\n"
        f"sweep('dmr', 'c', np.linspace(0.02, 0.08, 12), preset('3.1'), transient=100, "
        f"record=10, workers=1, out={str(out)!r})\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=REPO)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            done = [f for f in os.listdir(parts)] if os.path.isdir(parts) else []
            if sum(f.startswith("point-") for f in done) >= 4:
                break
            assert proc.poll() is None, "the sweep finished before it could be killed"
            time.sleep(0.01)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
    finished = sorted(f for f in os.listdir(parts) if f.startswith("point-"))
    assert 4 <= len(finished) < 12 and not out.exists()
    computed = count_computed(monkeypatch)
    ds = sweep("dmr", "c", np.linspace(0.02, 0.08, 12), preset("3.1"), transient=100,
               record=10, workers=1, out=out)
    assert len(computed) == 12 - len(finished)
    reference = sweep("dmr", "c", np.linspace(0.02, 0.08, 12), preset("3.1"), transient=100,
                      record=10, workers=1)
    assert_same(ds, reference)


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    "args, kwargs, match",
    [
        (("dmr", "cc", [0.1]), {}, "parameter must be one of"),
        (("dmr", "c", [0.1, 0.1]), {}, "distinct"),
        (("dmr", "c", [0.1, np.nan]), {}, "finite"),
        (("dmr", "sigma", [0.1]), {}, "no uncertainty"),
        (("mc", "c", [0.1]), {"continuation": "forward"}, "continuation"),
        (("dmr", "eta", [0.5, 1.5]), {}, r"eta must be in \(0, 1\], got 1.5"),
        (("opa", "sigma", [0.1, 0.9]), {}, "sigma = 0.9"),
        (("dmr", "c", [0.1]), {"record": 1}, "record must be an integer >= 2"),
        (("dmr", "c", [0.1]), {"continuation": "sideways"}, "continuation must be one of"),
    ],
)
def test_bad_input_is_refused_with_the_value(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        sweep(*args, preset("3.1"), **{**QUICK, **kwargs})



# ----------------------------------------------------------- a lower wall's free flights
# x'' = -2 zeta x' - x + f cos(omega t) with the upper wall far away (delta = 5) and a
# lower wall at -1: without impacts the steady state is A cos(omega t - phi) with the
# closed-form amplitude A = f / |1 - omega^2 + 2 i zeta omega|, so its free-flight minima
# lie 1 - A above the lower wall, and they graze it at f_g = |1 - omega^2 + 2i zeta omega|.
LOWER_ZETA, LOWER_OMEGA, LOWER_WALL = 0.1, 0.8, -1.0
LOWER_DENOMINATOR = abs(complex(1 - LOWER_OMEGA ** 2, 2 * LOWER_ZETA * LOWER_OMEGA))
LOWER_GRAZE_F = -LOWER_WALL * LOWER_DENOMINATOR


def lower_wall_oscillator(**changes):
    import opa

    fields = dict(force=opa.ForceLaw("-2*zeta*v - x", zeta=LOWER_ZETA), f=0.3,
                  omega=LOWER_OMEGA, delta=5.0, delta_minus=LOWER_WALL, eta_minus=0.8, F0=0.0,
                  omega1=LOWER_OMEGA, x0=0.0, v0=0.0)
    return opa.Oscillator(**{**fields, **changes})


def test_a_sweep_sees_free_flights_graze_the_lower_wall():
    """Values of f below and above the grazing f_g: below, ``min_gap_lower`` is the closed
    form 1 - A (within 1e-6; measured 1.4e-7 from the Hermite interpolation of 64 outputs
    per period) and ``grazing`` flags the value within graze_gap = 0.02 of the wall
    only; above, the motion impacts the lower wall; the grazing is located between the
    two within 1e-3 f_g (measured 1e-4) from the lower wall's gap (the upper wall's
    would put it near 1.01 f_g)."""
    import opa

    values = LOWER_GRAZE_F * np.array([0.9, 0.99, 1.01, 1.1])
    ds = sweep("dmr", "f", values, lower_wall_oscillator(),
               window=B.Window(transient=150, record=10, per_period=64), locate=False,
               motion=B.MotionTolerances(graze_gap=0.02), execution=opa.Execution(workers=1),
               options=opa.SolverOptions(rtol=1e-10, atol=1e-10))
    free = slice(0, 2)
    np.testing.assert_allclose(ds.min_gap_lower.values[free],
                               1.0 - values[free] / LOWER_DENOMINATOR, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(ds.grazing.values[free], [0, 1])
    np.testing.assert_array_equal(ds.impacts.values[free], [0, 0])
    assert np.all(ds.impacts.values[2:] > 0) and np.all(ds.min_gap.values > 3.9)
    assert ds.grazing_parameter.values == pytest.approx([LOWER_GRAZE_F],
                                                        abs=1e-3 * LOWER_GRAZE_F)
    assert any("closest free flight to the lower wall" in line
               for line in B.summary_lines(ds))
    one_wall = sweep("dmr", "f", values[:1], lower_wall_oscillator(delta_minus=-np.inf),
                     window=B.Window(transient=2, record=2, per_period=16), locate=False,
                     execution=opa.Execution(workers=1))
    assert "min_gap_lower" not in one_wall


def test_a_user_laws_constant_is_swept_onto_shaw_holmes_closed_form_orbits():
    """Shaw & Holmes' damping zeta swept (a constant of the user's law): at each value the
    settled motion is the closed-form period-1 orbit, its impact velocity and phase
    (omega t) to 1e-6 (``tests/impact_truths.py``)."""
    import opa
    from tests.impact_truths import shaw_holmes_orbits

    osc = opa.Oscillator(force=opa.ForceLaw("-2*zeta*v - x", zeta=0.05), f=1.0, omega=2.5,
                         eta=0.8, delta=0.0, F0=0.0, omega1=2.5, x0=-0.5)
    zetas = [0.04, 0.05, 0.07]
    ds = sweep("dmr", "zeta", zetas, osc, transient=300, record=8, workers=1)
    assert list(ds.label.values) == ["1/1"] * 3
    for zeta in zetas:
        (orbit,) = [o for o in shaw_holmes_orbits(zeta, 2.5, 0.0, 0.8)
                    if max(abs(np.asarray(o["multipliers"]))) < 1]
        at = ds.sel(zeta=zeta)
        np.testing.assert_allclose(at.impact_v.values, orbit["velocity"], atol=1e-6)
        np.testing.assert_allclose(at.impact_phase.values, 2.5 * orbit["phase"], atol=1e-6)
    with pytest.raises(ValueError, match="parameter"):
        sweep("dmr", "kappa", zetas, osc, transient=10, record=8, workers=1)


def test_an_uncertain_omega_is_not_swept_with_monte_carlo():
    """Each sample would have its own period, classified at the nominal one's times."""
    with pytest.raises(ValueError, match="its own forcing period"):
        sweep("mc", "c", [0.03, 0.04], preset("3.1"), uncertain="omega", sigma=0.001,
              transient=10, record=8, workers=1)
