"""Where the main job's time goes, and how much of it is serial (issue 29, item 1).

``opa-mc validate --workers 1`` runs in a fresh process at 1, 2 and all threads
(``NUMBA_NUM_THREADS``: the kernel's parallel batches; BLAS is held at one thread),
warm (numba's cache filled by a first run, a fresh output folder), and each run's phase
table is read from ``validate.nc`` (:class:`compare._phases.PhaseClock`: exclusive wall
and CPU seconds per phase; the figures and files after the dataset are the "report",
timed as the process's wall time minus the map's). Per phase it prints wall and CPU
seconds at each thread count, the speed-up, and the serial fraction f of Amdahl's law,
``T_n = T_1 (f + (1 - f) / n)``, fitted from T_1 and T_n:

    f = (T_n / T_1 - 1 / n) / (1 - 1 / n)

The default map is ``slow``; it is also run on n worker processes pinned to n cores
(``--workers n``, :mod:`compare._mapflow`; n: all the cores, or each of $PHASE_POOLS),
whose wall time gives the speed-up and the parallel efficiency ``T_1 / (n T_n)`` of the
whole map. The smoke run (CI) takes a tiny map through the same paths, on 2 workers.

    python -m pytest -s benchmarks/bench_phases.py -m slow     # the default map
    PHASE_COUNTS=1,16 PHASE_POOLS=8,16 python -m pytest -s benchmarks/bench_phases.py -m slow
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest
import xarray as xr

TINY = ["--values", "3.98", "--sigmas", "0.01,0.03", "--orders", "0:2", "--horizons", "2,4",
        "--samples", "64", "--max-samples", "128", "--no-frontier", "--no-plots"]


def _run(args, outdir, threads: int, workers: int = 1, cores: int | None = None) -> dict:
    """One map in a fresh process at ``threads`` numba threads on ``workers`` processes;
    with ``cores``, the process may run on the first ``cores`` cores only (its CPU
    affinity, which the map shares out among its workers)."""
    pin = None
    if cores is not None and hasattr(os, "sched_setaffinity"):
        allowed = sorted(os.sched_getaffinity(0))[:cores]

        def pin():
            os.sched_setaffinity(0, allowed)
    env = dict(os.environ, MPLBACKEND="Agg",
               NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "opa.cli", "validate", "--quiet",
                           "--outdir", str(outdir), "--workers", str(workers), *args],
                          env=env, capture_output=True, text=True, preexec_fn=pin)
    wall = time.perf_counter() - start
    assert proc.returncode == 0, proc.stderr[-2000:]
    with xr.open_dataset(os.path.join(outdir, "validate.nc")) as ds:
        attrs = dict(ds.attrs)
    names = attrs["phase_names"].split(",")
    table = {name: (float(w), float(c)) for name, w, c in zip(
        names, np.atleast_1d(attrs["phase_wall_seconds"]),
        np.atleast_1d(attrs["phase_cpu_seconds"]))}
    if workers == 1:  # the phases are exclusive: what they leave is the report and start-up
        mapped = sum(w for w, _ in table.values())
        table["report and start-up"] = (wall - mapped, float("nan"))
    return {"wall": wall, "phases": table, "map": float(attrs["wall_seconds"])}


def serial_fraction(t1: float, tn: float, n: int) -> float:
    """Amdahl's serial fraction from the times at 1 and n threads.

    >>> serial_fraction(10.0, 5.0, 2), serial_fraction(10.0, 10.0, 2)
    (0.0, 1.0)
    """
    return (tn / t1 - 1.0 / n) / (1.0 - 1.0 / n)


def _table(runs: dict[int, dict]) -> str:
    counts = sorted(runs)
    phases = sorted(runs[counts[0]]["phases"], key=lambda p: -runs[counts[0]]["phases"][p][0])
    head = "| phase | " + " | ".join(f"wall {n} thr (CPU)" for n in counts)
    head += " | speed-up | serial fraction |"
    lines = [head, "|" + "---|" * (len(counts) + 3)]
    for name in phases + ["total"]:
        if name == "total":
            cells = [(runs[n]["wall"], float("nan")) for n in counts]
        else:
            cells = [runs[n]["phases"].get(name, (0.0, 0.0)) for n in counts]
        t1, tn, n = cells[0][0], cells[-1][0], counts[-1]
        speed = t1 / tn if tn > 0 else float("nan")
        frac = serial_fraction(t1, tn, n) if t1 > 0 and n > 1 else float("nan")
        text = " | ".join(f"{w:.2f} ({c:.2f})" for w, c in cells)
        lines.append(f"| {name} | {text} | {speed:.2f} | {frac:.2f} |")
    return "\n".join(lines)


def _phases(tmp_path, args, counts, pools=()):
    """The table at ``counts`` threads in one process; for each n of ``pools`` also the
    map on n worker processes (``--workers n``) pinned to n cores, whose wall time is set
    against one thread: speed-up and parallel efficiency T_1 / (n T_n), with its own
    phase table (the phases' seconds summed over the workers)."""
    _run(args, tmp_path / "fill", max(counts))  # fill numba's cache: warm runs below
    runs = {n: _run(args, tmp_path / f"run-{n}", n) for n in counts}
    text = _table(runs)
    t1 = runs[min(counts)]["wall"]
    for n in pools:
        pooled = _run(args, tmp_path / f"pool-{n}", n, workers=n, cores=n)
        inside = f" (one process at {n} threads: {t1 / runs[n]['wall']:.2f}, " \
                 f"{t1 / (n * runs[n]['wall']):.2f})" if n in runs else ""
        phases = pooled["phases"]
        waiting = phases.pop("waiting for workers", (0.0, 0.0))[0]
        text += (f"\n\n--workers {n} on {n} cores: wall {pooled['wall']:.2f} s, "
                 f"speed-up {t1 / pooled['wall']:.2f} over one thread, parallel efficiency "
                 f"{t1 / (n * pooled['wall']):.2f}{inside}. Of its wall time: the map "
                 f"{pooled['map']:.2f} s ({waiting:.2f} s waiting for the workers), the "
                 f"report and start-up {pooled['wall'] - pooled['map']:.2f} s. The phases, "
                 f"wall seconds summed over the workers and this process (CPU): "
                 + ", ".join(f"{name} {w:.2f} ({c:.2f})" for name, (w, c) in
                             sorted(phases.items(), key=lambda item: -item[1][0])))
    print(f"\nload average {os.getloadavg()[0]:.2f} after the runs; "
          f"{os.cpu_count()} cores\n" + text)
    return runs


def _counts(name: str = "PHASE_COUNTS", default=None):
    """1, 2 and all cores, or the counts in $PHASE_COUNTS (e.g. "1,16": a short lease);
    ``name`` and ``default``: another variable (PHASE_POOLS) and its default."""
    if os.environ.get(name):
        return sorted({int(n) for n in os.environ[name].split(",")})
    cores = os.cpu_count() or 1
    return sorted({1, min(2, cores), cores}) if default is None else default


def test_phases_tiny(tmp_path):
    """The smoke run: a tiny map at 1 and 2 threads; every phase the map names is there,
    and the phases add up to the map's wall time."""
    runs = _phases(tmp_path, TINY, [1, 2], pools=[2])
    for run in runs.values():
        assert {"Monte Carlo runs", "OPA runs", "split scans", "pairs and verdicts"} \
            <= set(run["phases"])
        assert all(w >= 0 for w, _ in run["phases"].values())


@pytest.mark.slow
def test_phases_default(tmp_path):
    """The embedded default map at 1, 2 and all threads in one process, and on one
    worker process per core, on all the cores (or on each count of $PHASE_POOLS, e.g.
    "8,16", pinned to that many cores)."""
    cores = os.cpu_count() or 1
    _phases(tmp_path, [], _counts(), pools=_counts("PHASE_POOLS", [cores] if cores > 1
                                                   else []))


def test_timeline_tiny(tmp_path):
    """The smoke run of ``benchmarks/map_timeline.py``: every task of a tiny map's flow
    finishes once, each value's assembly after its bisections and its grid."""
    from benchmarks.map_timeline import timeline
    from compare._config import load_config

    cfg = load_config(None, outdir=str(tmp_path), values=(3.98,), sigmas=(0.01, 0.03),
                      orders=(0, 2), horizons=(2, 4), samples=64, max_samples=128,
                      frontier=False)
    rows = timeline(cfg, 2)
    keys = [key for key, _, _ in rows]
    assert sorted(keys) == sorted([("splits", 0), ("point", 0, 0), ("point", 0, 1),
                                   ("bisect", 0, 0), ("bisect", 0, 1), ("value", 0)])
    assert keys[-1] == ("value", 0)
    assert all(cpu > 0 for _, _, cpu in rows)


def test_figure_times_tiny(tmp_path):
    """The smoke run of ``benchmarks/figure_times.py``: every figure of a tiny map's
    report is drawn once and timed."""
    from benchmarks.figure_times import figure_times
    from compare._config import load_config
    from compare._mapflow import run_validation
    from compare._report import REPORT_FIGURES

    cfg = load_config(None, outdir=str(tmp_path), values=(3.98,), sigmas=(0.01, 0.03),
                      orders=(0, 2), horizons=(2, 4), samples=64, max_samples=128,
                      frontier=False)
    run_validation(cfg, progress=False, log=lambda *a: None)
    rows = figure_times(str(tmp_path / "validate.nc"), str(tmp_path))
    assert [name for name, _ in rows] == [name for name, _ in REPORT_FIGURES]
    assert all(cpu > 0 and (tmp_path / name).stat().st_size > 0 for name, cpu in rows)
