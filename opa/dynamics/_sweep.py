"""Parameter sweeps: bifurcation diagrams in both Poincaré sections (paper Figs. 3, 9, 10).

``sweep`` runs one trajectory per parameter value (DMR, OPA equivalent system or a
Monte Carlo ensemble), drops a transient, records the phase-plane and constraint-plane
sections and identifies the motion (``opa.dynamics._sections.identify_motion``): period, impacts
per period, label ``z = n/p``, grazing. These are observations of one trajectory: a
period that is twice a neighbour's (``observed_doubling``) can be a slow transient or
another attractor. The bifurcations themselves are located by continuing the observed
periodic attractors (``opa.dynamics._continuation.locate_bifurcations``: Floquet multipliers,
root finding), one source for ``opa-mc bifurcation``, ``reproduce`` and ``stability``.

Parallel over parameter values with local processes (default, 2 workers, each with one
numba thread) or on a Dask distributed cluster (``scheduler``). Continuation sweeps
(``forward``: increasing values, ``backward``: decreasing) start each value from the
final state of the previous one and are sequential by nature.

Crash safety and resumption: with ``out`` set, every finished point is written at once
to ``<out>.parts/point-NNNNN_<key>.npz`` (temporary file, fsync, atomic rename), a store
(:class:`opa._dataset.Store`) whose ``store.json`` holds the sweep's settings. A rerun with
the same settings reads the finished points back and computes only the others (a
continuation resumes from the last finished point's final state); other settings, or a
folder of an older version, are refused naming the folder; a damaged point (unreadable,
or edited since it was written: each part carries the digest of its content) is set aside
with a warning and computed again. When all are done the dataset is written atomically to
``out`` and the parts are removed. The sweep holds the lock of ``<out>.parts`` from the
start to the final write (:mod:`opa._lock`): a second sweep to the same ``out`` is refused
at once, naming the first one's process. Each point starts at t = 0: continuation carries the
state over, not the clock (the forcing phase is the same at the handover, since runs end
at a multiple of 2 pi/omega, but the impulse train restarts).
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from opa._dataset import Store, provenance_attrs, remove_store, write_netcdf
from opa._execution import Execution, take_execution
from opa._lazy import lazy
from opa._model import (
    Oscillator,
    SolverOptions,
    _choice,
    check_instance,
)
from opa._system import SWEEPABLE, SYSTEM_FIELDS, System, as_system
from opa.dynamics._sections import (
    MotionTolerances,
    grazing_points,
    identify,
    period_doubling,
    sticking_mask,
    stroboscopic_mask,
)

xr = lazy("xarray")

SWEEP_MODELS = ("dmr", "opa", "mc")
CONTINUATIONS = ("fixed", "forward", "backward")
#: the System fields a sweep takes as keywords (its OPA system uses the semicircle law)
SWEEP_FIELDS = tuple(f for f in SYSTEM_FIELDS if f != "distribution")
DEFAULT_WORKERS = 2


# --------------------------------------------------------------------------- one point


def sweep_times(system: System, transient: int, record: int, per_period: int) -> np.ndarray:
    """Output times of one sweep point: stroboscopic through the transient, then
    ``per_period`` outputs per forcing period through the record.

    Output times within 1e-9 periods of an impulse are moved onto it exactly, so that a
    stroboscopic time that coincides with an impulse (e.g. omega = 2.8 = 14/5: every 14
    forcing periods) is always sampled just after it (outputs are right-continuous).
    Left to round-off, such a sample falls on either side of the velocity jump.
    """
    T = system.oscillator.forcing_period
    strobe = np.arange(transient + 1) * T
    dense = transient * T + np.arange(1, record * per_period + 1) * (T / per_period)
    return system.snap_to_impulses(np.concatenate([strobe, dense]), 1e-9 * T)


@dataclass(frozen=True)
class PointTask:
    """Everything one worker needs for one parameter value (picklable)."""

    index: int
    value: float
    model: str
    system: System  # the point's system (its deterministic part for the DMR)
    options: SolverOptions
    samples: int
    sampler: str
    seed: int
    transient: int
    record: int
    per_period: int
    period_tol: float
    graze_velocity: float
    graze_gap: float
    initial: np.ndarray | None = field(default=None, compare=False)
    single_thread: bool = False
    source: Callable[[PointTask, np.ndarray], dict] | None = None

    @property
    def oscillator(self) -> Oscillator:
        return self.system.oscillator


def _trajectory(task: PointTask, times: np.ndarray) -> dict:
    """Integrate one point; arrays only (the compiled kernel directly for dmr and opa,
    which saves building a dataset per point, about a fifth of a point's time)."""
    from opa._run import run

    if task.source is not None:
        return task.source(task, times)
    system, order = task.system, task.system.order
    ncoef = order + 1
    initial = None
    if task.initial is not None:
        initial = np.array(task.initial, dtype=float).reshape(2, ncoef)
        # round-off must not start the run beyond the wall
        initial[0, 0] = min(initial[0, 0], system.oscillator.delta)
    name = "DMR" if task.model == "dmr" else f"OPA (N={order})"
    rec = run(system.kernel_inputs(task.options), system.initial_state(initial), times,
              rtol=task.options.rtol, atol=task.options.atol, label=f"{name} trajectory")
    out, ev = rec.states, rec.events
    return {"x": out[:, 0], "v": out[:, ncoef], "impact_time": ev.time[ev.impacts],
            "impact_velocity": ev.velocity[ev.impacts],
            "stick_time": ev.time[ev.kind == ev.STICK],
            "release_time": ev.time[ev.kind == ev.RELEASE],
            "final": np.stack([out[-1, :ncoef], out[-1, ncoef:]])}


def compute_point(task: PointTask) -> dict:
    """Run one parameter value and reduce it to its sections and motion (a dict of arrays).

    A trajectory that cannot be completed (``SimulationError``) gives a failed point
    (NaN sections, ``failed = 1`` and the message) instead of stopping the sweep.
    """
    from opa._run import SimulationError

    if task.single_thread:
        from opa._run import set_threads

        set_threads(1)
    ncoef = task.system.order + 1
    osc = task.oscillator
    times = sweep_times(task.system, task.transient, task.record, task.per_period)
    try:
        run = _trajectory(task, times)
    except SimulationError as err:
        nan = math.nan
        return {
            "index": task.index, "value": task.value, "failed": 1, "message": str(err),
            "section_x": np.zeros(0), "section_v": np.zeros(0),
            "impact_phase": np.zeros(0), "impact_v": np.zeros(0),
            "period": 0, "impacts": -1, "label": "failed", "residual": nan,
            "nearest_period": 0, "impact_rate": nan, "min_impact_velocity": nan,
            "min_gap": nan, "grazing": 0, "min_gap_lower": nan,
            "final": np.full((2, ncoef), nan),
        }
    T = osc.forcing_period
    start = task.transient * T  # t = start itself belongs to the transient
    breaks = [run["stick_time"], run["release_time"]]
    if run["impact_time"] is not None:
        breaks.append(run["impact_time"])
    if osc.F0 != 0.0:
        breaks.append(task.system.impulse_breaks(times[-1]))
    sticking = (sticking_mask(times, run["stick_time"], run["release_time"])
                if len(run["stick_time"]) else None)
    motion = identify(times, run["x"], run["v"], forcing_period=T, delta=osc.delta,
                      delta_minus=osc.delta_minus, start=start, impact_time=run["impact_time"],
                      impact_velocity=run["impact_velocity"], breaks=np.concatenate(breaks),
                      sticking=sticking, tolerances=MotionTolerances(
                          period_tol=task.period_tol, graze_velocity=task.graze_velocity,
                          graze_gap=task.graze_gap))
    strobe = stroboscopic_mask(times, T, start)
    if run["impact_time"] is not None:
        hit = run["impact_time"] > start
        impact_phase = np.mod(osc.omega * run["impact_time"][hit], 2 * math.pi)
        impact_v = run["impact_velocity"][hit]
    else:
        impact_phase = impact_v = np.zeros(0)
    return {
        "index": task.index, "value": task.value, "failed": 0, "message": "",
        "section_x": run["x"][strobe], "section_v": run["v"][strobe],
        "impact_phase": impact_phase, "impact_v": impact_v,
        **motion.as_dict(), "final": run["final"],
    }


#: what the pool that made this worker process shares with it (``local_executor``'s
#: ``shared``), or None
_SHARED = None


def pool_shared():
    """The object shared by the pool this worker process belongs to (``shared`` of
    :func:`local_executor`), or None."""
    return _SHARED


def _init_worker(owner: int | None = None, shared=None) -> None:
    """Set up a pool worker: one numba thread, and no life beyond the pool's owner;
    ``shared``: what the pool shares with its workers (:func:`pool_shared`).

    The worker's parent is the fork server, not ``owner`` (the process that made the
    pool); the fork server ends when ``owner`` does (:func:`exit_with_parent`, started by
    the preload ``opa.dynamics._warm_worker``) and takes the worker with it through the kernel's
    parent-death signal. The watcher on ``owner`` is the fallback where that signal is not
    available; it can only act between two kernel calls, which hold the GIL.
    """
    from opa._run import set_threads

    global _SHARED
    _SHARED = shared
    set_threads(1)
    _kill_on_parent_death()
    if owner is not None:
        exit_with_parent(owner)


def _kill_on_parent_death() -> bool:
    """Ask Linux for SIGKILL when this process's parent ends (prctl PR_SET_PDEATHSIG).

    Only for processes forked by a single-threaded parent that forks from its main thread
    (the fork server): the signal follows the parent *thread*, not the parent process.
    """
    if not sys.platform.startswith("linux"):
        return False
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        if libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    return True


def exit_with_parent(owner: int | None = None, interval: float = 0.5) -> None:
    """End this process (``os._exit``) once its parent, or process ``owner``, has ended.

    A daemon thread looks every ``interval`` seconds: a process whose parent ends is
    handed to another (``os.getppid`` changes), which also holds for a parent that is a
    zombie nobody has reaped yet; ``owner`` counts as ended when it is gone or a zombie.
    """
    import threading
    import time

    parent = os.getppid()

    def watch():
        while os.getppid() == parent and (owner is None or _alive(owner)):
            time.sleep(interval)
        os._exit(1)

    threading.Thread(target=watch, name="opa-exit-with-parent", daemon=True).start()


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs; a zombie (ended, not yet reaped) does not."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            return fh.read().rsplit(b")", 1)[1].split()[0] not in (b"Z", b"X")
    except FileNotFoundError:
        if os.path.exists("/proc/self/stat"):
            return False  # /proc is there, the process is not
    except (OSError, IndexError):
        pass
    try:  # no /proc: signal 0 tells whether the pid exists (a zombie counts as alive)
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


# --------------------------------------------------------------------------- parts on disk


def _parts_dir(out: str) -> str:
    return os.fspath(out) + ".parts"


def _part_name(index: int) -> str:
    return f"point-{index:05d}"


def _write_part(parts: Store, result: dict) -> None:
    index = int(result["index"])
    parts.save(_part_name(index), {"index": index},
               {k: np.asarray(v) for k, v in result.items()})


def _open_parts(folder: str | None, manifest: dict, count: int
                ) -> tuple[Store | None, dict]:
    """The store of this sweep's parts in ``folder`` (:class:`opa._dataset.Store`,
    refused when it holds another sweep) and the finished points it holds, by index."""
    if folder is None:
        return None, {}
    parts = Store(folder, "sweep", settings=manifest, lock=True)
    done = {}
    try:
        for index in range(count):
            result = parts.load(_part_name(index), {"index": index})
            if result is not None:
                done[index] = result
    except BaseException:
        parts.close()
        raise
    return parts, done


# --------------------------------------------------------------------------- the sweep


def _settings(model, param, values, base, options, kw) -> dict:
    """The sweep's settings as plain JSON values: the resume manifest."""
    return {
        "model": model,
        "param": param,
        "values": [float(v) for v in values],
        "oscillator": base.oscillator.as_dict(),
        "system": {k: v for k, v in base.dataset_attrs().items()},
        "options": {k: (float(v) if isinstance(v, float) else v)
                    for k, v in asdict(options).items()},
        **kw,
    }


def sweep(
    model: str,
    param: str,
    values,
    system: System | Oscillator | None = None,
    *,
    window: Window | None = None,
    continuation: str = "fixed",
    mc: MonteCarlo | None = None,
    options: SolverOptions | None = None,
    motion: MotionTolerances | None = None,
    out: str | os.PathLike | None = None,
    locate: bool | None = None,
    execution: Execution | None = None,
    **fields,
) -> xr.Dataset:
    """Bifurcation diagram: sections and motion labels over values of one parameter.

    Parameters
    ----------
    model : "dmr" (eq. (29)), "opa" (the EMR; ``sigma = 0`` gives EMR_0) or "mc" (the
        Monte Carlo mean of sampled systems; needs ``mc``).
    param : the swept parameter, any of ``mu a c f omega eta delta F0 a1 omega1 n x0 v0``
        or ``sigma`` (opa, mc).
    values : (P,) distinct parameter values (stored in increasing order).
    system : an :class:`opa.System` (the other parameters, the uncertainty, N and the
        closures, the impulse model), or an :class:`opa.Oscillator` (paper defaults when
        omitted) with the System's fields as keywords (``sigma`` default 0.01, ``order``
        default 4, ``uncertain``, ``truncation``, ``impact_law``, ``allow_negative``,
        ``impulse``, ``pulse_width``, ``impulse_at_zero``; the DMR ignores the
        uncertainty; xi has the semicircle law).
    window : the run of each value (:class:`Window`): ``transient`` forcing periods 2
        pi/omega dropped, then ``record`` recorded, ``per_period`` outputs per forcing
        period in the record (>= 8 resolves free-flight maxima for grazing; the
        transient is sampled once per period). Default ``Window()``: 500, 100, 16.
    continuation : "fixed" (every value starts from ``x0, v0``), "forward" (increasing
        values, each from the final state of the previous) or "backward" (decreasing).
        A failed value hands ``x0, v0`` on to the next.
    mc : model "mc"'s settings (:class:`MonteCarlo`): its trajectory ``source`` (one
        point's Monte Carlo mean, ``source(task, times) -> dict`` of arrays, a
        module-level function so that workers can unpickle it: ``mc.sweep_source``;
        this module never imports ``mc``), ``samples``, ``sampler``, ``seed``.
    options : solver options.
    motion : the period and grazing thresholds (:class:`MotionTolerances`, see
        ``identify_motion``; ``max_period`` is not taken here).
    out : netCDF path. Finished points go to ``<out>.parts/`` (or ``execution``'s
        ``checkpoint``) as they come and a rerun with the same settings resumes; the
        dataset is written atomically at the end, and ``<out>.parts`` removed (a
        checkpoint folder given in ``execution`` is kept).
    locate : locate the bifurcations of the observed periodic attractors
        (``opa.dynamics._continuation.locate_bifurcations``, seeded with the final states of the
        values with a periodic motion, ``observed_seeds``). None (default): for "dmr" when the
        parameter allows it (not x0, v0, nor one that changes the forcing's common
        period), else not; True: required (ValueError before any point is computed if
        it cannot be done); False: not. Not for "mc". Adds a few seconds to tens of
        seconds (see ``locate_bifurcations``).

    execution : how the points run (:class:`opa.Execution`): ``workers`` local processes
        (default 2; 1 runs in this process; sequential for continuation sweeps), a Dask
        ``scheduler`` (points run there), an ``executor`` to reuse (e.g. a warm process
        pool), ``progress`` (a bar; default when stderr is a terminal), ``checkpoint``
        (the parts folder, kept after the write).

    The keywords of earlier releases are still taken: ``transient``, ``record``,
    ``per_period`` (the window), ``samples``, ``sampler``, ``seed``, ``source`` (mc),
    ``period_tol``, ``graze_velocity``, ``graze_gap`` (motion), ``keep_parts`` (the parts
    folder as the checkpoint), ``workers``, ``scheduler``, ``executor``, ``progress``
    (execution); a keyword beside the record it belongs to is refused.

    Returns
    -------
    xarray.Dataset with, over the dimension named ``param``: ``section_x, section_v
    (param, point)`` (stroboscopic points of the record, NaN padded), ``impact_phase,
    impact_v (param, point)`` (constraint plane), ``period`` (0: none), ``impacts`` (per
    period, -1: none), ``label`` ("n/p"), ``residual``, ``impact_rate``,
    ``min_impact_velocity``, ``min_gap``, ``grazing`` (at either wall), with a lower wall
    ``min_gap_lower`` (its free flights' gap), ``observed_doubling`` (the
    observed period is twice a neighbour's: an observation, not a located bifurcation;
    ``period_doubling`` is the same, its former name), ``failed``;
    ``grazing_parameter(graze)``: grazing locations estimated between neighbours; over
    ``bifurcation`` the located bifurcations (``bifurcation_parameter``,
    ``bifurcation_kind`` with ``flag_values``/``flag_meanings``, ``bifurcation_period``,
    ``bifurcation_multiplier_real/imag``, ``bifurcation_located``, ``bifurcation_x/v``,
    ``bifurcation_note``; empty when not located, attribute ``bifurcation_method`` says
    why); the attributes listed in docs/datasets.md (the swept parameter's is NaN).

    Performance: one trajectory of ``transient + record`` periods per value; about
    50 ms per value for the DMR at the default tolerances (600 periods, section 3.1),
    three times that for OPA N = 4.

    Examples
    --------
    >>> from opa import preset
    >>> ds = sweep("dmr", "c", [0.035, 0.05], preset("3.1", F0=0.0),
    ...            window=Window(transient=200, record=40), execution=Execution(workers=1))
    >>> ds.label.values.tolist()
    ['4/4', '2/2']
    """
    setup = _setup(model, param, values, system, window, continuation, mc, options, motion,
                   out, execution, fields)
    tasks = setup.tasks
    located, not_located = locate_setup(locate, model, param, setup.values, setup.base,
                                        setup.options)
    parts, done = _open_parts(setup.parts, setup.manifest, len(tasks))
    try:  # the lock of the parts folder is held to the final write
        results = _run_points(setup, done, parts)
        ds = assemble(model, param, setup.values, results, setup.base, setup.options,
                      setup.kw, continuation)
        ds.attrs.update(points_resumed=len(done), points_computed=len(tasks) - len(done))
        ds = _with_located(ds, located, not_located, setup, results)
        if setup.out is not None:
            write_netcdf(ds, setup.out)
            if not setup.keep_parts:
                remove_store(parts.directory)
        return ds
    finally:
        if parts is not None:
            parts.close()


@dataclass(frozen=True)
class Window:
    """The run of each swept value: ``transient`` forcing periods dropped, ``record``
    recorded, ``per_period`` outputs per forcing period in the record."""

    transient: int = 500
    record: int = 100
    per_period: int = 16

    def __post_init__(self):
        for name, low in (("transient", 0), ("record", 2), ("per_period", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer,
                                                                 np.floating)) \
                    or int(value) != value or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value}")
            object.__setattr__(self, name, int(value))


@dataclass(frozen=True)
class MonteCarlo:
    """Model "mc" of a sweep: the Monte Carlo mean of ``samples`` sampled systems drawn
    by ``sampler`` with ``seed``, each point's trajectory from ``source``
    (``mc.sweep_source``)."""

    source: Callable | None = None
    samples: int = 256
    sampler: str = "sobol"
    seed: int = 0

    def __post_init__(self):
        if self.source is not None and not callable(self.source):
            raise ValueError(f"source must be a function (task, times) -> arrays, got "
                             f"{self.source!r}")


#: the keywords of earlier releases, by the record that now holds them
_RECORD_KEYWORDS = {
    "window": ("transient", "record", "per_period"),
    "mc": ("samples", "sampler", "seed", "source"),
    "motion": ("period_tol", "graze_velocity", "graze_gap"),
}


def _record(name: str, given, cls, fields: dict):
    """The record ``name`` of a sweep: ``given``, or one of its keywords found among
    ``fields`` (removed from them); both at once is refused."""
    taken = {k: fields.pop(k) for k in _RECORD_KEYWORDS[name] if k in fields}
    if taken and given is not None:
        raise ValueError(f"sweep: give {', '.join(sorted(taken))} inside {name}="
                         f"{cls.__name__}(...), not beside it")
    if given is not None and not isinstance(given, cls):
        raise ValueError(f"{name} must be an opa.dynamics.{cls.__name__} or None, got "
                         f"{given!r:.60}")
    return given if given is not None else cls(**taken)


@dataclass(frozen=True)
class _Setup:
    """A sweep's inputs, checked: its points and where they are kept."""

    model: str
    param: str
    values: np.ndarray
    base: System
    options: SolverOptions
    kw: dict
    tasks: list
    continuation: str
    run: Execution
    manifest: dict
    out: str | None
    parts: str | None
    keep_parts: bool


def _setup(model, param, values, system, window, continuation, mc, options, motion, out,
           execution, fields) -> _Setup:
    """Check every input of :func:`sweep` before any work, and make its points."""
    keep_parts = fields.pop("keep_parts", False)
    run = take_execution(execution, fields, "sweep",
                         {"workers": DEFAULT_WORKERS} if execution is None else {}).only(
        "sweep", "workers", "scheduler", "executor", "checkpoint", "connect_timeout",
        "worker_timeout")
    window = _record("window", window, Window, fields)
    mc = _record("mc", mc, MonteCarlo, fields)
    motion = _record("motion", motion, MotionTolerances, fields)
    _choice("model", model, SWEEP_MODELS)
    _choice("continuation", continuation, CONTINUATIONS)
    options = check_instance("options", options, SolverOptions, SolverOptions())
    base = as_system(system, options, allowed=SWEEP_FIELDS, where="sweep", **fields)
    # the model's parameters, a user's force law's own constants, and sigma
    _choice("parameter", param, base.oscillator.sweepable_names + ("sigma",))
    base = (base.deterministic() if model == "dmr" else
            base.replace(order=0) if model == "mc" else base)
    if model == "mc" and "omega" in base.problem.names:
        raise ValueError("an uncertain omega cannot be swept with model 'mc': each sample has "
                         "its own forcing period, and its motion is classified at the nominal "
                         "period's stroboscopic times; sweep omega instead")
    if param == "sigma" and model == "dmr":
        raise ValueError("the DMR has no uncertainty: sweep sigma with model 'opa' or 'mc'")
    if continuation != "fixed" and model == "mc":
        raise ValueError("continuation is not defined for 'mc' (every sample has its own "
                         "state); use continuation='fixed'")
    if model == "mc" and mc.source is None:
        raise ValueError("model 'mc' needs its trajectory source: pass mc=MonteCarlo("
                         "source=mc.sweep_source) (the CLI does)")
    values = _swept_values(param, values)
    _check_sweep_work(model, values, window, mc)
    kw = {
        "samples": int(mc.samples), "sampler": mc.sampler, "seed": int(mc.seed),
        "transient": window.transient, "record": window.record,
        "per_period": window.per_period, "period_tol": float(motion.period_tol),
        "graze_velocity": float(motion.graze_velocity), "graze_gap": float(motion.graze_gap),
    }
    tasks = []
    for i, value in enumerate(values):
        point = base.replace(**{param: float(value)})  # validates, names the value
        if model != "dmr":
            point.check_samples()
        tasks.append(PointTask(index=i, value=float(value), model=model, system=point,
                               options=options, source=mc.source, **kw))
    manifest = _settings(model, param, values, base, options,
                         {**kw, "continuation": continuation})
    out = None if out is None else os.fspath(out)
    parts = (os.fspath(run.checkpoint) if run.checkpoint is not None
             else None if out is None else _parts_dir(out))
    return _Setup(model, param, values, base, options, kw, tasks, continuation, run,
                  manifest, out, parts, bool(keep_parts) or run.checkpoint is not None)


def _swept_values(param: str, values) -> np.ndarray:
    values = np.asarray(values, dtype=float).ravel()
    if len(values) < 1 or not np.all(np.isfinite(values)):
        raise ValueError(f"sweep values of {param} must be finite, got {values.tolist()}")
    values = np.sort(values)
    if np.any(np.diff(values) == 0):
        raise ValueError(f"sweep values of {param} must be distinct, got {values.tolist()}")
    return values


def _check_sweep_work(model: str, values, window: Window, mc: MonteCarlo) -> None:
    """The work budget (:mod:`opa._work`): one run of transient + record periods per
    value; "mc" runs ``samples`` of them."""
    from opa._work import check_work

    samples = mc.samples
    runs = samples if model == "mc" and isinstance(samples, int) and samples > 0 else 1
    transient, record = window.transient, window.record
    drivers = [("values", len(values)), ("transient + record", f"({transient} + {record})")]
    check_work("this bifurcation sweep", len(values) * runs * float(transient + record),
               drivers + ([("samples", runs)] if runs > 1 else []))


def _run_points(setup: _Setup, done: dict, parts) -> list[dict]:
    """Every point's result, in order: those in ``done`` and the others computed (each
    kept in ``parts`` as it finishes)."""
    results = dict(done)
    tasks, run = setup.tasks, setup.run
    with run.bar(len(tasks), initial=len(done), unit="point",
                 desc=f"{setup.model} sweep over {setup.param}") as bar:

        def finish(result):
            if parts is not None:
                _write_part(parts, result)
            results[int(result["index"])] = result
            bar.update(1)

        if setup.continuation == "fixed":
            _run_parallel([t for t in tasks if t.index not in done], finish, run)
        else:
            ordered = tasks if setup.continuation == "forward" else tasks[::-1]
            _run_continuation(ordered, done, finish, run)
    return [results[i] for i in range(len(tasks))]


def _with_located(ds, located, not_located, setup: _Setup, results):
    """``ds`` with the located bifurcations of its observed periodic attractors (or the
    reason they were not located)."""
    if located is None:
        return add_located(ds, [], method=f"not located: {not_located}")
    from opa.dynamics._continuation import locate_bifurcations

    values = setup.values
    seeds = observed_seeds(setup.param, values, results, setup.base, setup.kw)
    points = locate_bifurcations(located, setup.param, float(values[0]), float(values[-1]),
                                 seeds=seeds)
    return add_located(ds, points, method=(
        "continuation of the observed periodic attractors (locate_bifurcations, "
        f"{len(seeds)} seeds)"))


# --------------------------------------------------------------------------- located points


def locate_setup(locate, model, param, values, base, options):
    """(ImpactSystem, None) when the sweep's bifurcations are to be located, else
    (None, why not). ``locate=True`` turns a reason into a ValueError."""
    from opa.dynamics._continuation import check_locatable
    from opa.dynamics._orbits import ImpactSystem

    if locate is not None and not isinstance(locate, bool):
        raise ValueError(f"locate must be True, False or None, got {locate!r}")
    if locate is False or (locate is None and model != "dmr"):
        return None, ("locate=False" if locate is False else
                      f"not by default for model '{model}' (locate=True to ask)")
    try:
        if model == "mc":
            raise ValueError("the Monte Carlo mean has no periodic orbits to continue")
        if len(values) < 2:
            raise ValueError("one value: no interval to locate bifurcations in")
        system = ImpactSystem.of(base, model=model, options=options)
        check_locatable(system, param, float(values[0]), float(values[-1]))
    except ValueError as err:
        if locate:
            raise ValueError(f"locate=True: {err}") from None
        return None, str(err)
    return system, None


def observed_seeds(param, values, results, base: System, kw) -> list:
    """Seeds for ``locate_bifurcations`` from a sweep's points: ``(value, final state,
    end time, stroboscopic points)`` of every value with a periodic motion. First the
    middle value of every run of equal labels, shorter periods and longer runs first (a
    branch of a short period, followed first, often holds the others); then every other
    periodic value, which costs nothing when its points lie on a branch already
    followed (a run of equal labels can hold several coexisting orbits)."""
    runs = []
    start = 0
    for i in range(1, len(values) + 1):
        if i == len(values) or results[i]["label"] != results[start]["label"]:
            runs.append((int(results[start]["period"]), -(i - start), (start + i - 1) // 2))
            start = i
    middles = [m for _, _, m in sorted(runs)]
    rest = sorted((int(r["period"]), i) for i, r in enumerate(results) if i not in middles)
    seeds = []
    for m in middles + [i for _, i in rest]:
        r = results[m]
        p = int(r["period"])
        final = np.asarray(r["final"], dtype=float)
        if p <= 0 or int(r["failed"]) or not np.all(np.isfinite(final)):
            continue
        points = np.stack([np.asarray(r["section_x"])[:p], np.asarray(r["section_v"])[:p]], 1)
        end = sweep_times(base.replace(**{param: float(values[m])}), kw["transient"],
                          kw["record"], kw["per_period"])[-1]
        seeds.append((float(values[m]), final.ravel(), float(end), points))
    return seeds


def add_located(ds: xr.Dataset, points: list, *, method: str) -> xr.Dataset:
    """``ds`` with the located bifurcations ``points`` (``Located``) over ``bifurcation``."""
    from opa.dynamics._continuation import BIFURCATION_KINDS

    param = ds.attrs["sweep_parameter"]
    one = {"units": "1"}
    dim = "bifurcation"
    mu = np.array([p.multiplier for p in points], dtype=complex)
    data = {
        "bifurcation_parameter": (dim, np.array([p.value for p in points], dtype=float),
                                  {"long_name": f"{param} at the located bifurcation", **one}),
        "bifurcation_kind": (dim, np.array([BIFURCATION_KINDS.index(p.kind) for p in points],
                                           dtype=np.int8),
                             {"long_name": "kind of the located bifurcation", **one,
                              "flag_values": np.arange(len(BIFURCATION_KINDS), dtype=np.int8),
                              "flag_meanings": " ".join(k.replace("-", "_")
                                                        for k in BIFURCATION_KINDS)}),
        "bifurcation_period": (dim, np.array([p.period for p in points], dtype=np.int32),
                               {"long_name": "period of the orbit in forcing periods (before "
                                             "a doubling)", **one}),
        "bifurcation_multiplier_real": (dim, mu.real.copy(), {
            "long_name": "critical Floquet multiplier, real part", **one}),
        "bifurcation_multiplier_imag": (dim, mu.imag.copy(), {
            "long_name": "critical Floquet multiplier, imaginary part", **one}),
        "bifurcation_located": (dim, np.array([p.located for p in points], dtype=np.int8),
                                {"long_name": "1 if located to xtol, 0 if interpolated", **one}),
        "bifurcation_x": (dim, np.array([p.x for p in points], dtype=float),
                          {"long_name": "x at t = 0 of the orbit at the bifurcation", **one}),
        "bifurcation_v": (dim, np.array([p.v for p in points], dtype=float),
                          {"long_name": "dx/dt at t = 0 of the orbit at the bifurcation",
                           **one}),
        "bifurcation_note": (dim, np.array([p.note for p in points], dtype=str),
                             {"long_name": "what happens at the located bifurcation"}),
    }
    out = ds.assign(data)
    out.attrs["bifurcation_method"] = method
    return out


def _run_parallel(tasks, finish, run: Execution) -> None:
    """The points here, on ``run``'s local processes (or its executor) or its cluster."""
    if not tasks:
        return
    if run.scheduler is not None:
        _run_dask(tasks, finish, run)
        return
    executor, workers = run.executor, run.workers
    if executor is None and (workers <= 1 or len(tasks) == 1):
        for task in tasks:
            finish(compute_point(task))
        return
    from concurrent.futures import FIRST_COMPLETED, wait

    own = executor is None
    if own:
        executor = local_executor(min(workers, len(tasks)))
    pending = set()
    try:
        pending = {executor.submit(compute_point, t) for t in tasks}
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                finish(fut.result())
    except BaseException:
        for fut in pending:
            fut.cancel()
        raise
    finally:
        if own:
            executor.shutdown(wait=True, cancel_futures=True)


def local_executor(workers: int = DEFAULT_WORKERS, preload: tuple[str, ...] = (),
                   shared=None):
    """A process pool for sweeps: ``workers`` processes with one numba thread each.

    ``preload``: more modules for the fork server to import before it forks the first
    worker, so that no worker imports them again (this process's first pool starts the
    server; the ones after it share that server and its modules). ``shared``: an object
    the workers get when they start (:func:`pool_shared`), e.g. a ``RawArray`` this
    process writes to while they run.

    Processes come from a fork server (not a plain fork, which is unsafe once numba's
    thread pool has started in this process). Reuse it across sweeps with
    ``sweep(..., executor=pool)`` to pay the start-up (imports and loading the compiled
    kernel, about 2-3 s) once. The fork server and the workers end within about a second
    when this process ends, also when it is killed without a chance to shut them down.
    """
    from concurrent.futures import ProcessPoolExecutor

    ctx = _forkserver(preload)
    # the workers must not outlive this process, even when it is killed (SIGKILL leaves
    # no chance to shut the pool down): see _init_worker and opa.dynamics._warm_worker
    return ProcessPoolExecutor(max_workers=int(workers), mp_context=ctx,
                               initializer=_init_worker, initargs=(os.getpid(), shared))


def _forkserver(preload: tuple[str, ...]):
    """The fork server's context, with what it imports before its first fork (used when
    it starts: this process's first pool, or :func:`start_fork_server`)."""
    import multiprocessing

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["opa.dynamics._sweep", "opa.dynamics._warm_worker",
                                *preload])
    return ctx


def start_fork_server(preload: tuple[str, ...] = ()) -> None:
    """Start the fork server of :func:`local_executor` now, importing ``preload``: it
    imports them while this process goes on with its own work (its own imports), so the
    first pool's workers start sooner. A no-op where the server runs already."""
    from multiprocessing import forkserver

    _forkserver(preload)
    forkserver.ensure_running()


def _run_dask(tasks, finish, run: Execution) -> None:
    """The points as tasks on ``run``'s Dask cluster, each with one numba thread,
    connected and watched as every batch of opa-mc is (:class:`opa.Execution`)."""
    with run.client() as client:
        single = [PointTask(**{**_task_fields(t), "single_thread": True}) for t in tasks]
        futures = {client.submit(compute_point, t, pure=False): t for t in single}
        watchdog = run.watchdog(client, lambda: len(futures), "points")
        try:
            for fut in watchdog.finished(list(futures)):
                task = futures.pop(fut)
                finish(watchdog.result(fut, f"point {task.index} (value {task.value:g})"))
        finally:
            client.cancel(list(futures))


def _task_fields(task: PointTask) -> dict:
    return {f: getattr(task, f) for f in PointTask.__dataclass_fields__}


def _run_continuation(ordered, done, finish, run: Execution) -> None:
    """Sequential sweep, each value from the final state of the previous one (each a
    task on ``run``'s cluster where it has one)."""
    with run.client() as client:
        _continue(ordered, done, finish, client, run)


def _continue(ordered, done, finish, client, run: Execution) -> None:
    initial = None
    watchdog = None if client is None else run.watchdog(client, lambda: 1, "points")
    for task in ordered:
        if task.index in done:
            final = np.asarray(done[task.index]["final"], dtype=float)
            initial = final if np.all(np.isfinite(final)) else None
            continue
        task = PointTask(**{**_task_fields(task), "initial": initial})
        if client is None:
            result = compute_point(task)
        else:
            future = client.submit(compute_point, task, pure=False)
            result = watchdog.result(future, f"point {task.index} (value {task.value:g})")
        finish(result)
        final = np.asarray(result["final"], dtype=float)
        initial = final if np.all(np.isfinite(final)) else None


# --------------------------------------------------------------------------- assembly


_SCALARS = {
    "period": ("int32", "smallest stroboscopic repeat in forcing periods (0: none)"),
    "impacts": ("int32", "impacts per period (-1: no period or not steady)"),
    "residual": ("float64", ("relative stroboscopic repeat distance at the period "
                            "(or at nearest_period)")),
    "nearest_period": ("int32", "repeat with the smallest stroboscopic distance"),
    "impact_rate": ("float64", "impacts per forcing period in the record (NaN: no impact "
                               "record, the Monte Carlo mean's)"),
    "min_impact_velocity": ("float64", "slowest impact velocity in the record (NaN: no "
                                       "impact)"),
    "min_gap": ("float64", "delta minus the highest free-flight maximum of x (NaN: no "
                           "free-flight maximum, every flight ends at the wall, or too few "
                           "outputs to see one)"),
    "grazing": ("int8", ("1 where an impact is slower than graze_velocity or a free "
                        "flight comes within graze_gap of the wall (of either wall, "
                        "with a lower wall)")),
    "failed": ("int8", "1 where the trajectory could not be completed"),
}


_LOWER_GAP = ("the lowest free-flight minimum of x minus delta_minus, the lower wall's gap "
              "(NaN: none, or too few outputs to see one)")


def _padded(rows, width):
    out = np.full((len(rows), width), np.nan)
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


def assemble(model, param, values, results, base, options, kw, continuation
             ) -> xr.Dataset:
    """The sweep dataset (docs/datasets.md) from per-point results in value order."""
    width = max([kw["record"]] + [len(r["impact_v"]) for r in results])
    dim = param
    data = {
        "section_x": ((dim, "point"), _padded([r["section_x"] for r in results], width),
                      {"long_name": "phase-plane section: x at t = k 2 pi/omega",
                       "units": "1"}),
        "section_v": ((dim, "point"), _padded([r["section_v"] for r in results], width),
                      {"long_name": "phase-plane section: dx/dt at t = k 2 pi/omega",
                       "units": "1"}),
        "impact_phase": ((dim, "point"), _padded([r["impact_phase"] for r in results], width),
                         {"long_name": "constraint-plane section: forcing phase "
                                       "omega t mod 2 pi at impact", "units": "rad"}),
        "impact_v": ((dim, "point"), _padded([r["impact_v"] for r in results], width),
                     {"long_name": "constraint-plane section: pre-impact velocity",
                      "units": "1"}),
        "label": (dim, np.array([str(r["label"]) for r in results], dtype=str),
                  {"long_name": "period label z = n/p (n forcing periods, p impacts)"}),
    }
    for name, (dtype, long_name) in _SCALARS.items():
        data[name] = (dim, np.array([r[name] for r in results], dtype=dtype),
                      {"long_name": long_name, "units": "1"})
    nearest = data["min_gap"][1]
    if base.oscillator.two_walls:  # parts written before it lack it: NaN
        lower = np.array([r.get("min_gap_lower", math.nan) for r in results], dtype=float)
        data["min_gap_lower"] = (dim, lower, {"long_name": _LOWER_GAP, "units": "1"})
        nearest = np.fmin(nearest, lower)
    periods = data["period"][1]
    doubled = period_doubling(periods)
    data["observed_doubling"] = (dim, doubled,
                                 {"long_name": "1 where the observed period is twice a "
                                               "neighbour's (not a located bifurcation)",
                                  "units": "1"})
    data["period_doubling"] = (dim, doubled.copy(),
                               {"long_name": "former name of observed_doubling", "units": "1"})
    graze_at = grazing_points(values, periods, data["impacts"][1],
                              data["min_impact_velocity"][1], nearest)
    data["grazing_parameter"] = ("graze", graze_at,
                                 {"long_name": f"estimated {param} of grazing bifurcations",
                                  "units": "1"})
    attrs = provenance_attrs(model, base, options, seed=kw["seed"] if model == "mc" else -1,
                             sampler=kw["sampler"] if model == "mc" else "none")
    attrs[param] = math.nan  # swept: see the coordinate
    attrs.update(
        sweep_parameter=param, continuation=continuation, transient=kw["transient"],
        record=kw["record"], per_period=kw["per_period"], period_tol=kw["period_tol"],
        graze_velocity=kw["graze_velocity"], graze_gap=kw["graze_gap"],
        samples=kw["samples"] if model == "mc" else 0,
        failures="; ".join(f"{param}={r['value']:.6g}: {r['message']}" for r in results
                           if r["failed"]) or "none",
    )
    coords = {
        dim: (dim, np.asarray(values, dtype=float), {"long_name": f"swept parameter {param}",
                                                     "units": "1"}),
        "point": ("point", np.arange(width), {"long_name": "index of the section point in "
                                             "the record (time order)", "units": "1"}),
    }
    return xr.Dataset(data, coords=coords, attrs=attrs)



def summary_lines(ds) -> list[str]:
    """The observed periods (runs of equal labels), impacts and grazing, the located
    bifurcations, and where the two disagree."""
    param = ds.attrs["sweep_parameter"]
    values = ds[param].values
    labels = ds.label.values
    lines = ["  observed periods (one trajectory per value, after the transient):"]
    start = 0
    for i in range(1, len(values) + 1):
        if i == len(values) or labels[i] != labels[start]:
            lo, hi = values[start], values[i - 1]
            where = f"{param} = {lo:.6g}" if i - 1 == start else f"{param} in [{lo:.6g}, {hi:.6g}]"
            lab = str(labels[start])
            if lab == "none":
                near = ds.nearest_period.values[start:i]
                res = ds.residual.values[start:i]
                lab = (f"no period within tol (nearest repeat {int(near[np.argmin(res)])}, "
                       f"residual >= {np.nanmin(res):.2g})")
            else:
                lab = f"{lab}  (period {ds.period.values[start]}, impacts "
                lab += f"{ds.impacts.values[start]})"
            lines.append(f"    {where}: {lab}")
            start = i
    rate = ds.impact_rate.values
    if np.isfinite(rate).any():
        first = np.flatnonzero(np.abs(rate - rate[0]) > 0.01)
        if len(first):
            i = first[0]
            lines.append(f"  impacts per forcing period {rate[0]:.3g} from {param} = "
                         f"{values[0]:.6g}, first different at {param} = {values[i]:.6g} "
                         f"({rate[i]:.3g})")
        vmin = ds.min_impact_velocity.values
        if np.isfinite(vmin).any():
            j = int(np.nanargmin(vmin))
            lines.append(f"  slowest impact velocity {vmin[j]:.3g} at {param} = {values[j]:.6g}")
    gap = ds.min_gap.values
    if np.isfinite(gap).any():
        j = int(np.nanargmin(gap))
        lines.append(f"  closest free flight to the wall: gap {gap[j]:.3g} at {param} = "
                     f"{values[j]:.6g}")
    lower = ds.min_gap_lower.values if "min_gap_lower" in ds else np.zeros(0)
    if np.isfinite(lower).any():
        j = int(np.nanargmin(lower))
        lines.append(f"  closest free flight to the lower wall: gap {lower[j]:.3g} at {param} "
                     f"= {values[j]:.6g}")
    graze = ds.grazing_parameter.values
    if len(graze):
        lines.append(f"  grazing between periodic branches near {param} = "
                     + ", ".join(f"{g:.6g}" for g in graze))
    flagged = values[ds.grazing.values == 1]
    if len(flagged):
        lines.append(f"  grazing flagged (slow impact or near-touching free flight) at "
                     f"{len(flagged)} values, first {param} = {flagged[0]:.6g}")
    if ds.failed.values.any():
        lines.append(f"  {int(ds.failed.sum())} values failed: {ds.attrs['failures']}")
    return lines + _located_lines(ds)


def _located_lines(ds) -> list[str]:
    """The located bifurcations and their disagreements with the observed periods."""
    from opa.dynamics._continuation import BIFURCATION_KINDS

    param = ds.attrs["sweep_parameter"]
    values = ds[param].values
    labels = ds.label.values
    doubled = values[ds.observed_doubling.values == 1]
    method = str(ds.attrs.get("bifurcation_method", "not located"))
    if "bifurcation_parameter" not in ds or method.startswith("not located"):
        lines = [f"  bifurcations {method}"]
        if len(doubled):
            lines.append(f"  observed period twice a neighbour's at {param} = "
                         + ", ".join(f"{v:.6g}" for v in doubled)
                         + " (an observation, not a located bifurcation)")
        return lines
    located = ds.bifurcation_parameter.values
    kinds = [BIFURCATION_KINDS[int(k)] for k in ds.bifurcation_kind.values]
    lines = [("  bifurcations located by continuation of the observed periodic orbits "
              "(Floquet multipliers):")]
    if not len(located):
        lines.append(f"    none in [{values[0]:.6g}, {values[-1]:.6g}]")
    for i, (value, kind) in enumerate(zip(located, kinds)):
        mu = complex(float(ds.bifurcation_multiplier_real[i]),
                     float(ds.bifurcation_multiplier_imag[i]))
        mu_text = f"{mu.real:+.6f}" if mu.imag == 0 else f"|{abs(mu):.6f}|"
        lines.append(f"    {kind:16s} {param} = {value:.10g}  period "
                     f"{int(ds.bifurcation_period[i])}, multiplier {mu_text}: "
                     f"{ds.bifurcation_note.values[i]}")
    disagree = []
    step = np.diff(values)
    changes = [i for i in range(len(values) - 1) if labels[i] != labels[i + 1]
               and not (ds.failed.values[i] or ds.failed.values[i + 1])]

    def window(i):  # an observed change between values i and i+1, give or take a step
        return values[i] - step[i], values[i + 1] + step[i]

    for i in changes:
        lo, hi = window(i)
        if not np.any((located >= lo) & (located <= hi)):
            text = (f"    observed {labels[i]} -> {labels[i + 1]} between {param} = "
                    f"{values[i]:.6g} and {values[i + 1]:.6g}: no located bifurcation within "
                    f"a sweep step")
            if len(located):
                j = int(np.argmin(np.abs(located - 0.5 * (values[i] + values[i + 1]))))
                text += f" (nearest: {kinds[j]} at {param} = {located[j]:.7g})"
            disagree.append(text + "; a slow transient, another attractor or non-periodic "
                                   "motion, not a bifurcation of the continued orbits")
    for value, kind in zip(located, kinds):
        if not any(window(i)[0] <= value <= window(i)[1] for i in changes):
            j = int(np.clip(np.searchsorted(values, value), 1, len(values) - 1))
            disagree.append(f"    located {kind} at {param} = {value:.7g}: the observed "
                            f"period does not change within a sweep step ({labels[j - 1]} "
                            f"at {values[j - 1]:.6g}, {labels[j]} at {values[j]:.6g})")
    if disagree:
        lines.append("  where the observed periods and the located bifurcations disagree:")
        lines += disagree
    return lines


__all__ = [
    "CONTINUATIONS",
    "SWEEP_MODELS",
    "SWEEPABLE",
    "PointTask",
    "add_located",
    "assemble",
    "compute_point",
    "local_executor",
    "observed_seeds",
    "start_fork_server",
    "sweep",
    "sweep_times",
]
