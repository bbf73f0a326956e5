"""The trust map's run (:func:`run_validation`): in one process, or as a flow of small
tasks on a local process pool or a Dask cluster.

One task per swept value leaves most workers idle past a handful of cores: the default
map has 5 values and the frontier. :class:`MapFlow` cuts the same work finer, into tasks
that share nothing but the parts folder (:class:`opa._dataset.Store`):

* first, all independent of each other: the split scan of every value
  (:func:`splits_task`) and the frontier's reference;
* as they finish, the tasks they make ready (:func:`compare._scaleout.run_flow` starts
  these ahead of the rest): a value whose split scan is done gets its grid points
  (value, sigma) with their OPA runs and Monte Carlo rounds (:func:`point_task`: the
  ensembles are stratified at the value's splits); a value whose grid points are all
  done gets the bisections of its sigma*, one task per horizon (:func:`bisect_task`: the
  horizons' bisections are independent); once these are done, its value task
  (:func:`value_task`) reads them back and assembles its datasets
  (:func:`compare._trustmap.value_work`); the frontier's runs once its reference
  is known (:class:`FrontierRuns`), and those that need the edges of earlier runs once
  these are known.

Each task writes what it computes as parts and returns it read back from its file, and
the value tasks and the frontier read those parts, so the map assembled here is the
one-process map to the bit, wherever the tasks ran.
"""

from __future__ import annotations

import os
import time
from dataclasses import replace

import numpy as np
import xarray as xr

from compare._config import ValidateConfig
from compare._mapdata import STREAMED_DIM
from compare._ledger import Ledger, Work
from compare._trustmap import (SLICES, _Map, boundary_at, clear_slices, details_part,
                               evaluate_point, frontier, frontier_part, frontier_runs,
                               grid_points, value_part, value_splits)
from opa.engine import Execution, OutputLock, Store, true_system_work, write_netcdf

def task_config(cfg: ValidateConfig) -> ValidateConfig:
    """The configuration a task runs with: in one process, no nested pool or cluster."""
    return replace(cfg, workers=1, scheduler=None)


def _task(cfg: ValidateConfig, phase: str, job, *, quiet_points: bool = False) -> dict:
    """``job(work)`` in a fresh :class:`compare._ledger.Work` with its time charged to
    ``phase``: its result, its ledger (counts, phases, the true systems integrated in
    this thread) and its log lines. ``quiet_points``: the points' own lines are left to
    the value task that reads them back."""
    lines: list[str] = []
    work = Work(cfg.outdir, log=lines.append)
    if quiet_points:
        work.point_log = lambda line: None
    before = true_system_work()
    with work.clock(phase):
        result = job(work)
    after = true_system_work()
    return {"result": result, "log": lines,
            "ledger": work.ledger((after[0] - before[0], after[1] - before[1]))}


def splits_task(cfg: ValidateConfig, value: float) -> dict:
    """The split scan at one swept value, kept as a part
    (:func:`compare._trustmap.value_splits`)."""
    def job(work):
        value_splits(cfg, work, value)

    return _task(cfg, "other", job)


def point_task(cfg: ValidateConfig, value: float, sigma: float) -> dict:
    """One grid point's OPA runs and Monte Carlo rounds, kept as parts
    (:func:`compare._trustmap.evaluate_point`)."""
    def job(work):
        evaluate_point(cfg, value, sigma, work=work)

    return _task(cfg, "other", job, quiet_points=True)


def bisect_task(cfg: ValidateConfig, value: float, h: int) -> dict:
    """The bisections of horizon ``h`` at one value
    (:func:`compare._trustmap.boundary_at`), after the :func:`point_task` of its grid,
    which it reads back."""
    def job(work):
        work.point_log = lambda line: None  # the value task says what the grid's say
        grid = grid_points(cfg, work, value)
        work.point_log = work.log
        return boundary_at(cfg, work, value, grid, h)

    return _task(cfg, "other", job)


def value_task(cfg: ValidateConfig, value: float, found: list, spill: bool = True) -> dict:
    """:func:`compare._trustmap.value_part` as a task, after :func:`splits_task`, the
    :func:`point_task` of its grid and the :func:`bisect_task` of every horizon
    (``found``, in horizon order): it reads those back and assembles the value's slice
    of the map, its bulk written to OUTDIR with ``spill`` (else the slice is returned
    whole, for a machine that cannot read OUTDIR's disk). At the first value it also
    computes the phase portraits, kept as a part
    (:func:`compare._trustmap.details_part`), which the map would otherwise compute
    after the flow."""
    def job(work):
        result = value_part(cfg, work, value, found, spill=spill)
        if value == cfg.values[0]:
            details_part(cfg, work, result["phase_sigma"])
        return result

    return _task(cfg, "other", job)


def frontier_run_task(cfg: ValidateConfig, run) -> dict:
    """One run of the frontier (a :class:`compare._convergence.StudyRun` that
    :func:`compare._trustmap.frontier_runs` listed), kept as a part; its result is
    ``{name: result}``."""
    def job(work):
        return {run.name: work.parts.get(frontier_part(run.name), run.spec, run.compute)}

    return _task(cfg, "frontier", job)


class FrontierRuns:
    """The frontier's runs as tasks: which are known (read back from the parts, or
    returned by a task), which are running, and the study assembled once all are known.

    The runs are those :func:`compare._trustmap.frontier_runs` lists given the runs
    known: first the reference alone (every row's error depends on it), then every run
    of the rows and ladders, then the adaptive collocation rows, which need the edges of
    the adaptive runs."""

    def __init__(self, cfg: ValidateConfig, parts: Store):
        self.cfg = cfg
        self.parts = parts
        self.known: dict = {}
        self.tried: set[str] = set()  # looked for in the parts
        self.running: set[str] = set()

    def _needed(self) -> list:
        """The runs listed and not known, after reading back the parts an earlier run
        left (which may name more runs: the reference, an adaptive run's edges)."""
        while True:
            needed, found = [], False
            for run in frontier_runs(self.cfg, self.known):
                if run.name in self.known:
                    continue
                if run.name not in self.tried:
                    self.tried.add(run.name)
                    part = self.parts.load(frontier_part(run.name), run.spec)
                    if part is not None:
                        self.known[run.name], found = part, True
                        continue
                needed.append(run)
            if not found:
                return needed

    def ready(self) -> list[tuple]:
        """The tasks of the runs needed and not yet running."""
        tasks = []
        for run in self._needed():
            if run.name not in self.running:
                self.running.add(run.name)
                tasks.append((("frontier", run.name), frontier_run_task,
                              (task_config(self.cfg), run)))
        return tasks

    def done(self, runs: dict) -> list[tuple]:
        """A task's runs are known; the tasks that made ready."""
        self.known.update(runs)
        self.running.difference_update(runs)
        return self.ready()

    @property
    def complete(self) -> bool:
        return not self.running and not self._needed()

    def dataset(self) -> xr.Dataset:
        """The frontier assembled from the known runs (:func:`compare._trustmap.frontier`)."""
        return frontier(self.cfg, known=self.known)


class MapFlow:
    """The map's tasks (:func:`compare._scaleout.run_flow`): :meth:`first` are the
    independent ones, :meth:`follow` gives those each finished task makes ready."""

    def __init__(self, cfg: ValidateConfig, parts: Store):
        self.cfg = cfg
        self.inner = task_config(cfg)
        values = range(len(cfg.values))
        # per value: its grid points not yet done, its split scan done, its bisections
        self.points = {i: len(cfg.sigmas) for i in values}
        self.split = {i: False for i in values}
        self.found: dict[int, dict[int, tuple]] = {i: {} for i in values}
        self.frontier = FrontierRuns(cfg, parts) if cfg.frontier else None

    def first(self) -> list[tuple]:
        cfg, inner = self.cfg, self.inner
        tasks = self.frontier.ready() if self.frontier is not None else []
        # a value's grid points follow its split scan: their ensembles are cut at its splits
        tasks += [(("splits", i), splits_task, (inner, value))
                  for i, value in enumerate(cfg.values)]
        return tasks

    def follow(self, key, result: dict) -> list[tuple]:
        """A value's grid points once its split scan is done (their ensembles are cut at
        its splits); its bisections, the longest horizon first, once its grid points are;
        its value task once these are."""
        kind, cfg = key[0], self.cfg
        if kind == "frontier":
            return self.frontier.done(result["result"])
        i = key[1]
        if kind == "point":
            self.points[i] -= 1
            if not self.points[i]:
                order = sorted(range(len(cfg.horizons)), key=lambda h: -cfg.horizons[h])
                return [(("bisect", i, h), bisect_task, (self.inner, cfg.values[i], h))
                        for h in order]
        elif kind == "bisect":
            self.found[i][key[2]] = result["result"]
        elif kind == "splits":
            self.split[i] = True
            return [(("point", i, j), point_task, (self.inner, cfg.values[i], float(sigma)))
                    for j, sigma in enumerate(cfg.sigmas)]
        if kind == "bisect" and self.split[i] and len(self.found[i]) == len(cfg.horizons):
            found = [self.found[i][h] for h in range(len(cfg.horizons))]
            # on a Dask cluster the slice travels whole: its workers may not share OUTDIR
            return [(("value", i), value_task, (self.inner, cfg.values[i], found,
                                                cfg.scheduler is None))]
        return []


def run_map_tasks(cfg: ValidateConfig, work: Work, bar) -> tuple[dict, Ledger]:
    """The map as a flow of small tasks (:class:`MapFlow`, run by
    :func:`compare._scaleout.run_flow`) on ``cfg.workers`` local processes or the Dask
    cluster ``cfg.scheduler``; ``work``: this process's (its parts, its log, its clock:
    its wait is the phase "waiting for workers"). Returns the values' results and the
    frontier, and the sum of the ledgers the tasks returned (counts, phase seconds
    summed over the workers)."""
    from compare._scaleout import map_preload, run_flow

    flow = MapFlow(cfg, work.parts)
    first = flow.first()
    where = (f"the Dask cluster at {cfg.scheduler}" if cfg.scheduler is not None
             else f"{cfg.processes} local processes")
    work.log(f"{len(cfg.values)} split scans{', the frontier' if cfg.frontier else ''}, "
             f"then each value's {len(cfg.sigmas)} grid points, then its bisections, on "
             f"{where} ...")
    results, ledgers = {}, []
    with work.clock("waiting for workers"):
        for key, result in run_flow(first, flow.follow, preload=map_preload(cfg.plots),
                                    execution=cfg.execution):
            for line in result["log"]:
                work.log(line)
            ledgers.append(result["ledger"])
            if key[0] == "point":
                bar.update(1)
            elif key[0] == "value":
                results[key[1]] = result["result"]
    if flow.frontier is not None:
        if not flow.frontier.complete:
            raise RuntimeError("the frontier's runs did not all finish")
        with work.clock("frontier"):
            results["frontier"] = flow.frontier.dataset()
    return results, sum(ledgers, Ledger())


def run_validation(cfg: ValidateConfig, *, started: float | None = None,
                   execution: Execution | None = None, **legacy) -> xr.Dataset:
    """Run the trust map and return its dataset (also written to OUTDIR/validate.nc):
    in this process, or as a flow of tasks on local processes or a Dask cluster
    (:func:`run_map_tasks`), to the same bits. The dataset returned reads its time
    series (``STREAMED_DIM``) from validate.nc when they are used (:func:`open_map`).

    ``execution``: how the map runs (:class:`opa.Execution`: ``workers``, ``scheduler``,
    ``progress``, ``log``); default: the configuration's ``workers`` (0: auto) and
    ``scheduler`` (the TOML's keys), a progress bar and ``print``, or the keywords
    ``progress`` and ``log`` of earlier releases. An execution with workers or a
    scheduler set in the configuration too is refused (one place says where the map runs).

    ``started``: the ``time.perf_counter()`` reading at which the command started (the
    one clock of a run); the attribute ``wall_seconds`` is the time from it to the
    finished dataset (default: from the call).

    OUTDIR is locked (``OUTDIR/.opa-mc.lock``, :class:`opa.engine.OutputLock`) from the
    start to the write of validate.nc: while one run holds it, another run with the same
    OUTDIR raises ValueError at once, naming the path and the holder's pid and command
    line (the CLI: exit status 2); the lock of a killed run is taken over (one ``log``
    line)."""
    started = time.perf_counter() if started is None else started
    cfg, progress, log = _validation_run(cfg, execution, legacy)
    # OUTDIR is locked from before the first part to validate.nc: a second run there is
    # refused at once, naming this one (its tasks share OUTDIR/parts, unlocked)
    with OutputLock(cfg.outdir, "output folder", folder=True, log=log):
        pooled = cfg.processes > 1 or cfg.scheduler is not None
        ds = _Map(cfg, progress=progress, log=log).run(run_map_tasks if pooled else None)
        for dim in ds.dims:  # every dimension has a coordinate (the frontier's run has none)
            if dim not in ds.coords:
                ds = ds.assign_coords({dim: (dim, np.arange(ds.sizes[dim]),
                                             {"long_name": f"index along {dim}", "units": "1"})})
        if "frontier_run" in ds.dims:
            ds["frontier_run"].attrs.update(long_name="index of a run of the cost-accuracy study",
                                            units="1")
            for name, text in (("frontier_method", "method of the run"),
                               ("frontier_law", "impact law of the run (true system: none)")):
                if name in ds and "long_name" not in ds[name].attrs:
                    ds[name].attrs["long_name"] = text
        ds.attrs["wall_seconds"] = time.perf_counter() - started
        path = os.path.join(cfg.outdir, "validate.nc")
        import dask

        try:
            # the bulk of the values' slices, one at a time, from their files to validate.nc,
            # in this process
            with dask.config.set(scheduler="synchronous"):
                write_netcdf(ds, path)
        finally:
            clear_slices(os.path.join(cfg.outdir, SLICES))
        return open_map(path)


def _validation_run(cfg: ValidateConfig, execution, legacy: dict):
    """(the configuration to run, progress, log) of :func:`run_validation`'s inputs."""
    unknown = sorted(set(legacy) - {"progress", "log"})
    if unknown:
        raise TypeError(f"run_validation() got an unexpected keyword argument "
                        f"{unknown[0]!r}")
    if execution is None:
        return cfg, legacy.get("progress", True), legacy.get("log", print)
    if not isinstance(execution, Execution):
        raise ValueError(f"execution must be an opa.Execution, got {execution!r:.60}")
    if legacy:
        raise ValueError(f"run_validation: give {', '.join(sorted(legacy))} inside "
                         f"execution=Execution(...), not beside it")
    execution.only("run_validation", "workers", "scheduler")
    if cfg.workers or cfg.scheduler is not None:
        raise ValueError("run_validation: the configuration's workers or scheduler beside "
                         "execution=: say where the map runs in one place")
    cfg = replace(cfg, workers=execution.workers, scheduler=execution.scheduler)
    return cfg, execution.shows_progress, execution.log or (lambda line: None)


def open_map(path: str) -> xr.Dataset:
    """validate.nc as the report reads it: every variable in memory but those along
    ``STREAMED_DIM`` (the OPA and Monte Carlo moments, most of the map's bytes), of
    which each use reads what it indexes from the file (``ds.opa_x_mean[q, s]``: that
    point's), and nothing is kept."""
    ds = xr.open_dataset(path, engine="netcdf4", decode_times=False, decode_timedelta=False,
                         cache=False)
    for variable in ds.variables.values():
        if STREAMED_DIM not in variable.dims:
            variable.load()
    return ds


__all__ = ["FrontierRuns", "MapFlow", "bisect_task", "frontier_run_task",
           "point_task", "run_map_tasks", "run_validation", "splits_task", "task_config",
           "value_task"]
