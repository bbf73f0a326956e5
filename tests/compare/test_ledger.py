"""The ledger of work (compare._ledger): what each task of the map returns, added up by the
main process, against counts taken independently at the kernel's entry points and at the
Monte Carlo runs."""

import threading

import numpy as np
import pytest

import compare._trustmap as trustmap
from compare import load_config, run_validation
from compare._ledger import COUNTS, Ledger, Work
from compare._mapflow import MapFlow
from compare._scaleout import run_flow
from opa import _kernel as kernel

# one swept value, two sigmas, N = 0 and 1, one horizon, no frontier: a few seconds
SMALL = dict(values=(3.98,), sigmas=(0.01, 0.03), orders=(0, 1), horizons=(4,), samples=64,
             max_samples=128, per_period=4, frontier=False)


def test_ledgers_add_count_by_count_and_phase_by_phase():
    a = Ledger(mc_runs=1, true_runs=64, true_periods=2.5, system_runs=70,
               phases={"split scans": (1.0, 2.0, 1), "bisection": (0.5, 0.5, 3)})
    b = Ledger(mc_runs=2, true_runs=128, parts_computed=4,
               phases={"split scans": (0.25, 0.5, 2)})
    total = sum([a, b], Ledger())
    assert (total.mc_runs, total.true_runs, total.true_periods, total.system_runs,
            total.parts_computed) == (3, 192, 2.5, 70, 4)
    assert total.phases == {"split scans": (1.25, 2.5, 3), "bisection": (0.5, 0.5, 3)}
    assert a.phases == {"split scans": (1.0, 2.0, 1), "bisection": (0.5, 0.5, 3)}  # unchanged
    attrs = total.attrs()
    assert attrs["phase_names"] == "split scans,bisection"  # the longest first
    assert attrs["mc_runs_computed"] == 3 and attrs["true_system_runs"] == 70
    assert set(COUNTS) | {"phases"} == set(Ledger.__dataclass_fields__)


class _Counted:
    """A kernel entry point that counts the true impact systems it starts: state
    dimension 2 (x, x'), sigma = 0 in the parameter row (OPA at N = 0 has sigma > 0),
    started from the initial state (not resumed)."""

    def __init__(self, real, counts, lock, kind):
        self.real, self.counts, self.lock, self.kind = real, counts, lock, kind

    def __getattr__(self, name):  # signatures, the cache: the dispatcher's own
        return getattr(self.real, name)

    def __call__(self, *args):
        if self.kind == "integrate":  # (z, m, times, include_start, renormalise, p, ...)
            z, m, times, fresh, _, p = args[:6]
            dim, rows = len(z) // (1 + m), np.atleast_2d(p)
        elif self.kind == "run_batch":  # (y0, times, p, ...): always from y0
            y0, times, p = args[:3]
            dim, rows, fresh = np.shape(y0)[-1], np.atleast_2d(p), True
        else:  # run_batch_from (y0, include_start, times, p, ...)
            y0, fresh, times, p = args[:4]
            dim, rows = np.shape(y0)[-1], np.atleast_2d(p)
        if dim == 2 and fresh and len(times):
            with self.lock:
                self.counts["systems"] += int(np.count_nonzero(rows[:, kernel.P_SIGMA] == 0))
        return self.real(*args)


@pytest.fixture
def counted(monkeypatch):
    """Counts of the true systems the kernel starts (every thread) and of the map's Monte
    Carlo ensembles and their samples."""
    counts = {"systems": 0, "ensembles": 0, "samples": 0, "periods": 0.0}
    lock = threading.Lock()
    for name in ("integrate", "run_batch", "run_batch_from"):
        monkeypatch.setattr(kernel, name, _Counted(getattr(kernel, name), counts, lock, name))
    real = trustmap.true_runs

    def true_runs(system, options, xi, times, *, what, **kw):
        if what == "Monte Carlo sample":
            counts["ensembles"] += 1
            counts["samples"] += len(xi)
            counts["periods"] += len(xi) * times[-1] / system.oscillator.forcing_period
        return real(system, options, xi, times, what=what, **kw)

    monkeypatch.setattr(trustmap, "true_runs", true_runs)
    return counts


def test_the_tasks_ledgers_are_the_work_counted_at_the_kernel(tmp_path, counted):
    """The map's flow of tasks, run here one after the other (compare._scaleout.run_flow
    with one worker): the sum of the ledgers the tasks return equals the true systems the
    kernel was asked to start and the Monte Carlo ensembles and samples run, counted
    independently; every task's ledger is its own (a fresh Work), and a rerun, which
    reads every part back, returns ledgers with no runs."""
    cfg = load_config(None, outdir=str(tmp_path), workers=1, **SMALL)
    flow = MapFlow(cfg, Work(cfg.outdir).parts)
    ledgers = [result["ledger"] for _, result in run_flow(flow.first(), flow.follow)]
    total = sum(ledgers, Ledger())
    assert counted["systems"] > counted["samples"] > 0  # the split scans' runs too
    assert total.system_runs == counted["systems"]
    assert (total.mc_runs, total.true_runs) == (counted["ensembles"], counted["samples"])
    assert total.true_periods == pytest.approx(counted["periods"], rel=1e-12)
    assert total.parts_computed == len([p for p in (tmp_path / "parts").iterdir()
                                        if p.name != "store.json"])
    # the split scan, the grid points, the bisections of the horizon, the value: the
    # points and the bisections' probes run ensembles, the scan and the value read back
    assert len(ledgers) == 1 + len(cfg.sigmas) + len(cfg.horizons) + 1
    assert [ledger.mc_runs > 0 for ledger in ledgers] == [False, True, True, True, False]
    for name in counted:
        counted[name] = 0
    flow = MapFlow(cfg, Work(cfg.outdir).parts)
    again = sum((r["ledger"] for _, r in run_flow(flow.first(), flow.follow)), Ledger())
    assert (again.mc_runs, again.true_runs, again.system_runs, again.parts_computed) == (
        0, 0, 0, 0) and counted["systems"] == 0


@pytest.mark.parametrize("workers", [1, 2])
def test_the_maps_counts_are_the_work_counted_at_the_kernel(tmp_path, counted, workers):
    """The map's attributes are the sum of the ledgers: in one process, every true
    system the kernel started here; on 2 processes (whose kernels this process cannot
    count), the same counts, from the tasks' ledgers."""
    one = run_validation(load_config(None, outdir=str(tmp_path / "one"), workers=1, **SMALL),
                         progress=False, log=lambda *a: None)
    assert one.attrs["true_system_runs"] == counted["systems"]
    assert one.attrs["mc_runs_computed"] == counted["ensembles"]
    assert one.attrs["true_runs_computed"] == counted["samples"]
    assert one.attrs["true_periods_computed"] == pytest.approx(counted["periods"], rel=1e-12)
    if workers == 1:
        return
    pooled = run_validation(load_config(None, outdir=str(tmp_path / "two"), workers=2,
                                        **SMALL), progress=False, log=lambda *a: None)
    assert pooled.attrs["ran_on"] == "2 local processes"
    for name in ("true_system_runs", "mc_runs_computed", "true_runs_computed",
                 "parts_computed"):
        assert pooled.attrs[name] == one.attrs[name], name
