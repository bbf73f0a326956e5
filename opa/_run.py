"""The only caller of the compiled kernel (``opa._kernel``): Gauss rules in the kernel's
layout, single and batched runs, status codes turned into :class:`SimulationError` with
advice, event-log decoding, and the checks on output times every run shares."""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import threading
from dataclasses import dataclass

import numpy as np

from opa import _kernel as kernel
from opa._basis import chebyshev_u, gauss_nodes, quadrature_order
from opa._forcefunction import check_addresses
from opa._memory import check_memory
from opa._model import check_span, time_grid


class SimulationError(RuntimeError):
    """A trajectory could not be completed (divergence, step collapse, step limit); its
    ``status`` is the kernel's code (None where no single run is to blame)."""

    def __init__(self, message: str, *, status: int | None = None):
        super().__init__(message)
        self.status = status


def quadrature(order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes, weights and basis values U_0..U_{N+1} at the nodes for an order-N system.

    The basis is degree-major, shape (N+2, Q): ``basis[i, k] = U_i(xi_k)``; the kernel
    takes it node-major (:func:`kernel_quadrature`).

    N = 0 uses the one-point rule at xi = 0, which makes EMR_0 the DMR exactly.
    """
    if order == 0:
        # exactly xi = 0 (cos(pi/2) is 6e-17 in floating point), so the kernel takes the
        # deterministic fast path
        nodes, weights = np.zeros(1), np.ones(1)
    else:
        nodes, weights = gauss_nodes(quadrature_order(order))
    basis = chebyshev_u(order + 1, nodes)  # (N+2, Q)
    return nodes, weights, np.ascontiguousarray(basis)


def kernel_quadrature(quad):
    """The kernel's layout of :func:`quadrature`'s rule: basis node-major (Q, N+2), so
    the kernel's inner loops over the degree run over contiguous memory."""
    nodes, weights, basis = quad
    return nodes, weights, np.ascontiguousarray(basis.T)


_ANNOUNCED = []
#: set (to the numba cache it names) by the process that said it compiles, so that the
#: workers it starts afterwards compile that cache in silence
ANNOUNCED_ENV = "OPA_MC_COMPILING_ANNOUNCED"


def _cold(dispatcher) -> bool:
    """Whether ``dispatcher`` is neither compiled here nor in numba's on-disk cache."""
    if dispatcher.signatures:
        return False
    try:  # numba's index of cached overloads, empty when the source changed
        return not dispatcher._cache._cache_file._load_index()
    except Exception:  # a numba without this layout: say nothing rather than guess
        return False


def announce_compilation() -> bool:
    """Say "compiling kernels (first run only)..." on stderr if the kernels are not in
    numba's on-disk cache, once for this process and the processes it starts afterwards
    (a map's pool workers compile the same cache): a command calls it before starting
    its workers. Returns whether it was said here."""
    from opa import _kernel as kernel

    cache = os.environ.get("NUMBA_CACHE_DIR", "")
    if _ANNOUNCED or os.environ.get(ANNOUNCED_ENV) == cache or not _cold(kernel.integrate):
        return False
    _ANNOUNCED.append(True)
    os.environ[ANNOUNCED_ENV] = cache
    print("compiling kernels (first run only)...", file=sys.stderr, flush=True)
    return True


#: the kernel entry points found compiled (here or in the cache): not looked at again
_WARM: set = set()


def prepare_kernels(dispatcher) -> None:
    """Before a kernel entry point that is neither compiled in this process nor in
    numba's on-disk cache: say so once (:func:`announce_compilation`: not again in the
    workers of a process that said it), to stderr, and compile the driver's callees on
    two cores (:func:`compile_callees`): a first run sits for several seconds compiling."""
    if _ANNOUNCED or dispatcher in _WARM:
        return
    if not _cold(dispatcher):
        _WARM.add(dispatcher)  # numba's list of signatures is rebuilt on every look
        return
    if os.environ.get(ANNOUNCED_ENV) != os.environ.get("NUMBA_CACHE_DIR", ""):
        os.environ[ANNOUNCED_ENV] = os.environ.get("NUMBA_CACHE_DIR", "")
        print("compiling kernels (first run only)...", file=sys.stderr, flush=True)
    _ANNOUNCED.append(True)
    compile_callees()


def callee_signatures() -> dict[str, dict[str, tuple]]:
    """The argument types with which ``integrate``, the one driver behind every entry
    point, calls each kernel function, in two groups ("main", "helper") of about equal
    compile time (3 to 4 s each when cold). A test compiles both groups and then
    ``integrate``, and checks that ``integrate`` compiled no callee of its own."""
    from numba import types as nt

    f8, i8, b1 = nt.float64, nt.int64, nt.boolean
    v, m, iv = nt.float64[::1], nt.float64[:, ::1], nt.int64[::1]
    table_v, table_m = nt.Array(f8, 1, "C", readonly=True), nt.Array(f8, 2, "C", readonly=True)
    system = (v, iv, m, v, m)  # p, cfg, table, weights, U
    column = nt.UniTuple(f8, 7)  # a component's dense-output coefficients
    stages = nt.UniTuple(f8, 12)  # one component's stages of a 2-D DOP853 step
    law = nt.UniTuple(f8, kernel.N_POLY + 1)  # a polynomial law (force_law's tuple)
    helper = {  # leaves and the 2-D stepper: nothing here calls the vector field; what
        # the main group calls first comes first (the main group's leaves give the
        # helper the time to finish the 2-D step before rk_step needs it)
        "is_deterministic": (i8, iv, m, v),
        "last_stage": (i8,),
        "_stages2_dop853": (f8,) * 14 + (b1,),
        "_stages2_dop853_poly": (f8,) * 6 + (law,) + (f8,) * 5 + (b1,),
        "_stages2_dop853_fn": (f8,) * 6 + (i8, i8) + (f8,) * 5 + (b1,),
        "register_step_poly": (f8,) * 6 + (law,) + (f8,) * 3 + (b1, f8, f8),
        "register_step_fn": (f8,) * 6 + (i8, i8) + (f8,) * 3 + (b1, f8, f8),
        "_error2": (f8,) * 7 + (stages, stages, f8, f8),
        "_dense_stages2_dop853": (f8, f8, m) + (f8,) * 10 + (b1,),
        "_dense_stages2_dop853_poly": (f8, f8, m, f8, f8, law) + (f8,) * 5 + (b1,),
        "_dense_stages2_dop853_fn": (f8, f8, m, f8, f8, i8, i8) + (f8,) * 5 + (b1,),
        "_dop853_coefficients": (v, v, f8, m, m),
        "store_stages2": (m, stages, stages),
        "dense_prepare2": (f8, v, v, f8, m, m, v, iv, f8, b1),
        "state_status": (v, i8, f8),
        "first_impulse": (f8, b1, f8, b1),
        "impulse_strength": (f8, v),
        "_log_event": (m, i8, f8, f8, i8),
        "_hold": (v, i8, i8, i8),
        "_reflect": (v, i8, i8, f8, b1),
        "dense_x": (i8, f8, f8, column),
        "dense_dx": (i8, f8, column),
        "dense_value": (i8, f8, v, m, i8),
        "_bisect_wall": (i8, f8, f8, f8, column, f8, f8, f8),
        "_bisect_maximum": (i8, f8, f8, column, f8),
        "wall_crossing": (i8, f8, column, f8, f8, f8),
        "dense_state": (i8, f8, v, m, v),
        "free_flight_maximum": (i8, f8, column, f8, f8),
        # the driver's phases that call no vector field (those that do are inlined)
        "start_run": (v, f8, f8, b1, v, iv, f8, f8, m, m),
        "impulses": (f8, v, i8, b1, i8, f8, f8, f8, i8, i8, i8, v, iv, m, v, m, f8, f8, m, m),
        "store_outputs": (f8, v, i8, i8, b1, v, m, m),
    }
    main = {  # the vector field, everything that calls it, and a few leaves
        "vector_field": (v, i8) + system + (f8, f8, b1, v, m),
        "_stage_forcing_long": (f8,) * 8,
        "stage_drive": (f8,) * 8,
        "_stage_rows": (f8, v, f8, m, v, table_m, table_v, i8, i8, i8) + system + (f8, b1, m),
        "_impact": (f8, v, i8) + system + (f8, v, v, m, f8),
        "_impact_at_nodes": (f8, v, i8) + system + (f8, v, v, m),
        "_reflect_at_nodes": (v, i8, i8, i8, m, v, m, m),
        "error_norm": (i8, v, v, m, f8, f8, f8),
        "wall_margin": (m, i8, i8, f8),
        "escape_bound": (v, v, iv),
        "rk_step": (i8, f8, v, f8, m, v, v, i8) + system + (f8, b1, m),
        "restep_to": (i8, i8, f8, v, f8, f8, m, m, v, v, i8) + system + (f8, m),
        "dense_prepare": (i8, f8, v, v, f8, m, m, v, i8) + system + (f8, b1, m),
        "step_dense": (b1, stages, stages, i8, f8, v, v, f8, m, m, v, i8) + system
        + (f8, b1, m),
    }
    return {"main": main, "helper": helper}


def compile_group(group: str, parent: int | None = None) -> None:
    """Compile one group of :func:`callee_signatures` (into numba's on-disk cache). A
    helper process passes its parent's pid and stops when that process is gone.

    Only a head start: an entry that no longer compiles (the table behind an edit of the
    kernel; the test of the table fails then) is skipped, and the driver's own
    compilation does what is needed."""
    for name, signature in callee_signatures()[group].items():
        if parent is not None and os.getppid() != parent:
            return
        try:
            getattr(kernel, name).compile(signature)
        except Exception:  # noqa: BLE001 - a head start must not fail the run
            continue


def compile_callees() -> None:
    """Compile ``integrate``'s callees on two cores: a helper process compiles the
    "helper" group into numba's on-disk cache while this process compiles the "main"
    group; ``integrate``, compiled next by its first call, then loads whatever the
    helper has finished from the cache (and compiles the rest itself).

    With one core, one numba thread (the sweep's and our Dask workers set one), a frozen
    application or no Python executable to start (an embedded interpreter), nothing is
    started here: the first call compiles everything in this process. The helper
    imports opa from this process's ``sys.path``. A helper that fails costs only time.
    It is reaped by a background thread when it ends; at exit this process waits for it
    at most 10 s, then stops it; if this process is killed, the helper notices between
    two functions (on POSIX) and stops."""
    global _HELPER
    if getattr(sys, "frozen", False) or not sys.executable or _threads() < 2:
        return
    if usable_cores() < 2:
        return
    import numba

    env = dict(os.environ)
    if numba.config.CACHE_DIR:
        env["NUMBA_CACHE_DIR"] = str(numba.config.CACHE_DIR)
    code = (f"import sys; sys.path[:] = {sys.path!r}; from opa._run import compile_group; "
            f"compile_group('helper', parent={os.getpid()})")
    try:
        _HELPER = subprocess.Popen([sys.executable, "-c", code], env=env,
                                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL,
                                   creationflags=getattr(subprocess, "CREATE_NO_WINDOW", 0))
    except OSError:
        _HELPER = None
    else:
        threading.Thread(target=_HELPER.wait, daemon=True).start()
        atexit.register(_end_helper, _HELPER)
    compile_group("main")


_HELPER: subprocess.Popen | None = None  # the last helper started (tests read it)


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity (``taskset``, a container's
    cpuset) where the system tells it, else every core of the machine."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


#: where the numba threads of the work running now come from, read before each parallel
#: batch (:func:`follow_thread_grant`); None: the calling thread's own count
_THREAD_GRANT = None


def follow_thread_grant(grant) -> None:
    """Read this process's numba thread count from ``grant()`` now and before each
    parallel batch of :func:`run_batch` (on the thread that calls it), so that work
    running on a pool can take the cores that other work left
    (``compare._scaleout.run_flow`` raises a task's grant as the tasks beside it end);
    None: stop. The batches' results do not depend on the count."""
    global _THREAD_GRANT
    _THREAD_GRANT = grant
    apply_thread_grant()


def quiet_threads() -> None:
    """Let numba's OpenMP threads sleep between parallel regions instead of spinning
    (``OMP_WAIT_POLICY=PASSIVE``, unless the user set it): the kernel runs many small
    batches (the levels of a split scan's or an ensemble's bisections), and spinning
    threads made one split scan 3.5x slower on a loaded 2-core machine (issue 29; a
    2048-sample ensemble took the same time either way). It must be set before numba
    starts its threads, so :func:`set_threads` and :func:`run_batch` call it, the only
    ways this package starts them; importing opa changes nothing."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def set_threads(threads: int) -> None:
    """numba's thread count for the calling thread (its threads started quiet:
    :func:`quiet_threads`)."""
    import numba

    quiet_threads()
    numba.set_num_threads(int(threads))


def thread_count() -> int:
    """numba's thread count for the calling thread, without starting its thread pool."""
    return _threads()


def apply_thread_grant() -> int | None:
    """Set numba's thread count for this thread to the grant followed
    (:func:`follow_thread_grant`) and return it; None where none is followed."""
    grant = _THREAD_GRANT
    if grant is None:
        return None
    import numba

    threads = max(1, min(int(grant()), numba.config.NUMBA_NUM_THREADS))
    if threads != _threads():
        set_threads(threads)
    return threads


def _threads() -> int:
    """numba's thread count without starting its thread pool (a started pool makes a
    later fork of this process abort under OpenMP)."""
    import numba
    from numba.np.ufunc import parallel

    if getattr(parallel, "_is_initialized", False):
        return numba.get_num_threads()
    return numba.config.NUMBA_NUM_THREADS


def _end_helper(helper: subprocess.Popen, timeout: float = 10.0) -> None:
    """At exit: let the helper finish what it is writing to the cache (it is seconds
    from done), then stop it."""
    try:
        helper.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        helper.kill()
        helper.wait()


#: the default SolverOptions.max_steps; a run under it also has the runaway guard below
DEFAULT_MAX_STEPS = 50_000_000
# The runaway guard: a trajectory whose options keep the default max_steps may take at most
# max(GUARD_FLOOR, GUARD_PER_PERIOD x forcing periods, GUARD_PER_TIME x time units) steps.
# The paper's motions take 20 to 40 steps per forcing period (OPA of N = 8 and N = 20, the
# DMR); a state that runs away in finite time (c < 0) takes ever smaller steps and would
# otherwise use up the 50 million steps in silence (OPA of N = 8: about 200 s).
GUARD_FLOOR = 200_000
GUARD_PER_PERIOD = 20_000
GUARD_PER_TIME = 1_000


_GUARD_LIMITS = (f"(at most {GUARD_PER_PERIOD} per forcing period, {GUARD_PER_TIME} per unit "
                 f"time, {GUARD_FLOOR} in all)")
_GUARD_ADVICE = ("The step size collapsed, as when the state runs away in finite time: check "
                 "the parameters (e.g. the signs of a and c); a run that truly needs more "
                 "steps can give SolverOptions(max_steps=...) explicitly.")


def step_guard(times, p) -> int:
    """Steps the runaway guard allows over ``times`` (module constants above)."""
    span = float(times[-1] - times[0]) if len(times) else 0.0
    periods = span * p[kernel.P_OMEGA] / (2.0 * np.pi)
    return int(min(DEFAULT_MAX_STEPS, max(GUARD_FLOOR, GUARD_PER_PERIOD * periods,
                                          GUARD_PER_TIME * span)))


def step_guards(times, P) -> np.ndarray:
    """:func:`step_guard` of each row of ``P`` (B, N_PARAMS) at once."""
    span = float(times[-1] - times[0]) if len(times) else 0.0
    periods = span * np.asarray(P)[:, kernel.P_OMEGA] / (2.0 * np.pi)
    steps = np.maximum(np.maximum(GUARD_FLOOR, GUARD_PER_PERIOD * periods),
                       GUARD_PER_TIME * span)
    return np.minimum(DEFAULT_MAX_STEPS, steps).astype(np.int64)


def _guarded_cfgs(inputs: Inputs, times, guard: bool):
    """(cfgs, guarded): a copy of the batch's configurations with the runaway guard as the
    step limit of every run that keeps the default one (with ``guard``), and those limits
    (0 for the runs not guarded)."""
    cfgs = np.array(inputs.cfg, dtype=np.int64)
    guarded = np.zeros(len(cfgs), np.int64)
    if guard:
        rows = np.flatnonzero(cfgs[:, kernel.C_MAXSTEPS] == DEFAULT_MAX_STEPS)
        guarded[rows] = cfgs[rows, kernel.C_MAXSTEPS] = step_guards(times, inputs.p[rows])
    return cfgs, guarded


def advice(status: int) -> str:
    """What to try after a kernel status: tolerances help a collapsed step, not an escape."""
    if status in (kernel.ESCAPED, kernel.DIVERGED):
        return ("The parameters drive the state out of every bound: check them (e.g. the "
                "signs of a and c, the sizes of f, F0 and mu).")
    if status == kernel.BAD_TIME:
        return "Check the output times: they must be finite, with impulse times resolvable."
    if status == kernel.MAX_STEPS:
        return ("The run needs more steps than max_steps (SolverOptions.max_steps): ask for "
                "fewer periods, looser tolerances or a larger --max-step, or check the "
                "parameters.")
    if status == kernel.STEP_COLLAPSE:
        return ("Near this time no step can be taken: check the parameters, and that "
                "--max-step and the tolerances are not below round-off.")
    return "Check the parameters."


def output_times(oscillator, periods, per_period, times, dim: int = 2):
    """The output times (the grid of ``periods`` and ``per_period`` unless ``times`` is
    given), refusing runs that cannot be resolved, finished or held in memory."""
    if times is None:
        times = time_grid(oscillator.omega, periods, per_period)
    else:
        try:
            times = np.asarray(times, dtype=float)
        except (TypeError, ValueError):
            raise ValueError("times must be a 1-D array of numbers") from None
        if times.ndim != 1 or len(times) < 1 or not np.all(np.isfinite(times)):
            raise ValueError("times must be a non-empty 1-D array of finite values")
        if np.any(np.diff(times) <= 0):
            raise ValueError("times must be strictly increasing")
    check_span(oscillator, float(times[-1]), t_start=float(times[0]))

    check_memory(f"{len(times)} outputs x {dim} states", len(times) * (dim + 1) * 8 * 2)
    return times


# ---------------------------------------------------------------------------- the inputs
#: the names of the kernel's float parameters, in the slots of its parameter vector
PARAMETER_SLOTS = {
    "mu": kernel.P_MU, "a": kernel.P_A, "c": kernel.P_C, "f": kernel.P_F,
    "omega": kernel.P_OMEGA, "eta": kernel.P_ETA, "delta": kernel.P_DELTA, "F0": kernel.P_F0,
    "a1": kernel.P_A1, "omega1": kernel.P_OMEGA1, "n": kernel.P_N,
    "pulse_width": kernel.P_TAU, "sigma": kernel.P_SIGMA, "chatter_velocity": kernel.P_CHATTER_V,
    "max_step": kernel.P_HMAX,
    # the optional lower wall (``pack`` puts -inf, no wall, and eta there when not given)
    "delta_minus": kernel.P_DELTA_MINUS, "eta_minus": kernel.P_ETA_MINUS,
}
#: the kernel's codes of each named choice
CHOICE_CODES = {
    "impulse": {"dirac": kernel.IMPULSE_DIRAC, "pulse": kernel.IMPULSE_PULSE},
    # the truncation's closure term: none (Galerkin), or the paper's on the velocities
    # (uncertain mu) or the positions (uncertain c)
    "closure": {"none": kernel.TRUNC_GALERKIN, "velocity": kernel.TRUNC_PAPER_V,
                "position": kernel.TRUNC_PAPER_X},
    "impact_law": {"mean": kernel.LAW_MEAN, "ensemble": kernel.LAW_ENSEMBLE,
                   "saltation": kernel.LAW_SALTATION},
    "method": {"dop853": kernel.METHOD_DOP853, "dp5": kernel.METHOD_DP5},
    # the force law: the paper's (mu, a, c) or a user's polynomial (its coefficients)
    "force": {"paper": kernel.FORCE_PAPER, "polynomial": kernel.FORCE_POLYNOMIAL,
              "function": kernel.FORCE_FUNCTION},
}
#: the parameter vector's slots of a polynomial force law's coefficients C[j, k]
POLY_SLOTS = slice(kernel.P_POLY, kernel.P_POLY + kernel.N_POLY)


@dataclass(frozen=True)
class Inputs:
    """What the kernel integrates: the parameter vector ``p``, the configuration ``cfg``,
    the parameter table (the coefficients mu, a, c at each node, shape (Q, N_TABLE)) and
    the rule's weights and basis node-major (Q, n + 1) of one system, or of B systems
    with a leading axis on each (:func:`stack`). Built by ``opa.System.kernel_inputs``
    and :func:`sampled`, read only here."""

    p: np.ndarray
    cfg: np.ndarray
    table: np.ndarray
    weights: np.ndarray
    basis: np.ndarray


def pack(values: dict, *, max_steps: int, impulse_at_zero: bool, rule, table,
         coefficients=None, wall_nodes: bool = False, drive_nodes: bool = False,
         function_address: int = 0, **choices) -> Inputs:
    """The kernel's inputs from named values (the keys of :data:`PARAMETER_SLOTS`), the
    step limit, the impulse train's start, the named choices of :data:`CHOICE_CODES`,
    ``rule`` (:func:`quadrature`'s nodes, weights and basis degree-major: its n + 1 rows
    are the n coefficients' basis functions and the closure's U_{N+1}) and ``table``, the
    coefficients of the force law at each of its nodes (Q, N_TABLE). ``coefficients``:
    a polynomial force law's nominal C[j, k] (N_POLY,), with ``force="polynomial"``.
    ``wall_nodes``: the restitution or the wall varies over the nodes (the table's T_ETA,
    T_DELTA); p then holds their means over the rule. ``drive_nodes``: f, omega or F0
    varies over the nodes (T_F, T_OMEGA, T_F0); p keeps the nominal drive.
    ``function_address``: a compiled force function's (``force="function"``; its
    constants take the coefficients' place), made in this process."""
    p = np.zeros(kernel.N_PARAMS)
    p[kernel.P_DELTA_MINUS] = -np.inf  # no lower wall unless ``values`` names one
    p[kernel.P_ETA_MINUS] = values.get("eta", 1.0)
    for name, value in values.items():
        p[PARAMETER_SLOTS[name]] = value
    if coefficients is not None:
        p[POLY_SLOTS] = coefficients
    cfg = np.zeros(kernel.N_CFG, dtype=np.int64)
    cfg[kernel.C_NCOEF] = len(rule[2]) - 1
    cfg[kernel.C_AT_ZERO] = int(impulse_at_zero)
    cfg[kernel.C_MAXSTEPS] = int(max_steps)
    cfg[kernel.C_FUNCTION] = int(function_address)
    slots = {"impulse": kernel.C_IMPULSE, "closure": kernel.C_TRUNC,
             "impact_law": kernel.C_LAW, "method": kernel.C_METHOD, "force": kernel.C_FORCE}
    for name, value in choices.items():
        cfg[slots[name]] = CHOICE_CODES[name][value]
    _, weights, basis = kernel_quadrature(rule)
    table = np.ascontiguousarray(table, dtype=float)
    if table.shape != (len(weights), kernel.N_TABLE):
        raise ValueError(f"the parameter table must have shape ({len(weights)}, "
                         f"{kernel.N_TABLE}), got {table.shape}")
    if wall_nodes:
        cfg[kernel.C_WALL_NODES] = 1
        for slot, col in ((kernel.P_ETA, kernel.T_ETA), (kernel.P_DELTA, kernel.T_DELTA)):
            p[slot] = float(weights @ table[:, col] / weights.sum())
    if drive_nodes:
        cfg[kernel.C_DRIVE_NODES] = 1
    return Inputs(p, cfg, table, weights, basis)


def stack(inputs) -> Inputs:
    """B systems' inputs as one batch (each must have the same rule size)."""
    return Inputs(*(np.ascontiguousarray(np.stack([getattr(i, f) for i in inputs]))
                    for f in ("p", "cfg", "table", "weights", "basis")))


#: the parameter vector's slots of the table's columns
TABLE_SLOTS = (kernel.P_MU, kernel.P_A, kernel.P_C,
               *range(kernel.P_POLY, kernel.P_POLY + kernel.N_POLY), kernel.P_ETA, kernel.P_DELTA,
               kernel.P_F, kernel.P_OMEGA, kernel.P_F0)


def sampled(inputs: Inputs, columns: dict, coefficients=None) -> Inputs:
    """B sampled deterministic systems (N = 0, a one-node table of their own
    coefficients) that are ``inputs`` (a deterministic system's) with each named
    parameter of ``columns`` at its B values (a user's force law's constants have no
    slot: their effect is ``coefficients``, the law's C[j, k] of each system, (B, N_POLY)
    or (1, N_POLY))."""
    columns = {name: np.asarray(values, dtype=float) for name, values in columns.items()}
    B = len(next(iter(columns.values())))
    P = np.repeat(np.asarray(inputs.p)[None, :], B, axis=0)
    for name, values in columns.items():
        if name in PARAMETER_SLOTS:
            P[:, PARAMETER_SLOTS[name]] = values
    if coefficients is not None:
        P[:, POLY_SLOTS] = coefficients
    cfgs = np.repeat(np.asarray(inputs.cfg)[None, :], B, axis=0)
    U = np.zeros((B, 1, 2))
    U[:, 0, 0] = 1.0
    table = np.ascontiguousarray(P[:, None, list(TABLE_SLOTS)])
    return Inputs(P, cfgs, table, np.ones((B, 1)), U)


# ---------------------------------------------------------------------------- the record
@dataclass(frozen=True)
class Events:
    """One run's event log, decoded: rows in time order with their time, velocity (the
    pre-impact velocity of x_0 for impacts and kicks, 0 for sticking and release), kind
    and wall (+1 the upper wall delta, -1 the lower wall delta_minus: the kernel logs a
    lower-wall event as its kind plus ``EV_LOWER``; ``kind`` here is the kind alone, and
    a lower-wall impact's velocity is negative)."""

    time: np.ndarray
    velocity: np.ndarray
    kind: np.ndarray
    wall: np.ndarray | None = None

    def __post_init__(self):
        if self.wall is None:
            object.__setattr__(self, "wall", np.ones(len(self.kind), dtype=np.int8))

    #: the kinds, by name
    IMPACT, GRAZE, STICK, RELEASE, KICK = (kernel.EV_IMPACT, kernel.EV_GRAZE, kernel.EV_STICK,
                                           kernel.EV_RELEASE, kernel.EV_KICK)

    @classmethod
    def of(cls, log: np.ndarray) -> Events:
        log = np.asarray(log, dtype=float).reshape(-1, 3)
        raw = log[:, 2].astype(np.int8)
        lower = raw >= kernel.EV_LOWER
        return cls(log[:, 0].copy(), log[:, 1].copy(),
                   np.where(lower, raw - kernel.EV_LOWER, raw).astype(np.int8),
                   np.where(lower, -1, 1).astype(np.int8))

    def __len__(self) -> int:
        return len(self.time)

    @property
    def impacts(self) -> np.ndarray:
        """Mask of the impacts: located ones (impact, graze) and kicks into the wall."""
        return np.isin(self.kind, (kernel.EV_IMPACT, kernel.EV_GRAZE, kernel.EV_KICK))

    @property
    def located(self) -> np.ndarray:
        """Mask of the impacts located on the dense output (not kicks)."""
        return np.isin(self.kind, (kernel.EV_IMPACT, kernel.EV_GRAZE))

    def first_impact(self) -> float:
        """The time of the first impact, inf when there is none."""
        hits = np.flatnonzero(self.impacts)
        return float(self.time[hits[0]]) if len(hits) else np.inf

    def names(self, impact: str, stick: str, release: str) -> list[str]:
        """Each event's name, impacts of every kind under ``impact``."""
        table = {kernel.EV_IMPACT: impact, kernel.EV_GRAZE: impact, kernel.EV_KICK: impact,
                 kernel.EV_STICK: stick, kernel.EV_RELEASE: release}
        return [table[int(k)] for k in self.kind]

    def dataset_vars(self, two_walls: bool = False) -> dict:
        """The event variables of a trajectory dataset (docs/datasets.md); ``two_walls``
        (the oscillator has a lower wall) adds ``impact_wall``, +1 or -1 per impact."""
        impact = self.impacts
        walls = {} if not two_walls else {"impact_wall": (
            "impact", self.wall[impact].astype(np.int8),
            {"long_name": "wall of the impact: +1 the upper wall delta, -1 the lower wall "
                          "delta_minus", "units": "1"})}
        return {
            "impact_time": ("impact", self.time[impact],
                            {"long_name": "time of impact with the wall", "units": "1"}),
            "impact_velocity": ("impact", self.velocity[impact],
                                {"long_name": "pre-impact velocity of the (mean) coordinate",
                                 "units": "1"}),
            "impact_graze": ("impact", (self.kind[impact] == kernel.EV_GRAZE).astype(np.int8),
                             {"long_name": f"1 where the impact velocity is below "
                                           f"{kernel.EVENT_GRAZE_VELOCITY} (graze)",
                              "units": "1"}),
            "stick_time": ("stick", self.time[self.kind == kernel.EV_STICK],
                           {"long_name": "chatter accumulation time, start of sticking",
                            "units": "1"}),
            "release_time": ("release", self.time[self.kind == kernel.EV_RELEASE],
                             {"long_name": "time of release from the wall after sticking",
                              "units": "1"}),
            **walls,
        }


@dataclass(frozen=True)
class Statistics:
    """Per output interval: impacts, smallest pre-impact speed |v-| (at either wall),
    sticking episodes, steps, sticking at its end (0/1), smallest free-flight gap
    delta - x_0 to the upper wall (at the maxima of x_0) and ``gap_lower``, the smallest
    x_0 - delta_minus to the lower wall (at the minima; inf without a lower wall)."""

    impacts: np.ndarray
    min_velocity: np.ndarray
    sticks: np.ndarray
    steps: np.ndarray
    sticking: np.ndarray
    gap: np.ndarray
    gap_lower: np.ndarray

    @property
    def nearest_gap(self) -> np.ndarray:
        """The smaller of the two walls' gaps, per interval (``gap`` with one wall)."""
        return np.minimum(self.gap, self.gap_lower)

    @classmethod
    def of(cls, stats: np.ndarray) -> Statistics:
        columns = (kernel.S_IMPACTS, kernel.S_MIN_VELOCITY, kernel.S_STICKS, kernel.S_STEPS,
                   kernel.S_STICKING, kernel.S_GAP, kernel.S_GAP_LOWER)
        return cls(*(stats[:, j].copy() for j in columns))


@dataclass(frozen=True)
class Record:
    """One run, decoded: the states at the output times (rows not reached are NaN), the
    events, the counters, the status and, when asked for, the tangent matrix W at the end,
    the per-interval statistics and the log growth of W per interval."""

    states: np.ndarray
    events: Events
    steps: int
    rhs_evaluations: int
    impacts: int
    status: int = kernel.OK
    failure: str | None = None
    tangent: np.ndarray | None = None
    statistics: Statistics | None = None
    log_growth: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.status == kernel.OK


class Batch:
    """B runs made together (:func:`run_batch`): states (B, n_out, dim), each run's
    events, counters and status."""

    def __init__(self, states, logs, counters, guarded=None):
        self.states = states
        self._guarded = guarded
        self._logs = logs
        self._counters = counters
        self.status = counters[:, 0].copy()
        self.steps = counters[:, 3].copy()
        self.rhs_evaluations = counters[:, 4].copy()
        self.impacts = counters[:, 2].copy()

    def __len__(self) -> int:
        return len(self.status)

    def events(self, b: int) -> Events:
        """Run b's events (as many as the log's capacity holds)."""
        return Events.of(self._logs[b, :min(int(self._counters[b, 1]), self._logs.shape[1])])

    def log(self, b: int) -> np.ndarray:
        """Run b's raw event log (as many rows as the capacity holds; :meth:`Events.of`
        decodes it), a copy."""
        return self._logs[b, :min(int(self._counters[b, 1]), self._logs.shape[1])].copy()

    def log_complete(self, b: int) -> bool:
        """Whether run b's events all fit in the log."""
        return int(self._counters[b, 1]) <= self._logs.shape[1]

    @property
    def ok(self) -> np.ndarray:
        return self.status == kernel.OK

    @property
    def failed(self) -> np.ndarray:
        """Runs that failed themselves (not the ones skipped after a failure)."""
        return (self.status != kernel.OK) & (self.status != kernel.SKIPPED)

    def message(self, b: int) -> str:
        """What became of run b, in words ("ok" when it finished)."""
        status = int(self.status[b])
        if status == kernel.MAX_STEPS and self._guarded is not None and \
                0 < self._guarded[b] < DEFAULT_MAX_STEPS:  # at the cap: the plain limit
            return (f"the runaway guard ended it after {int(self.steps[b])} steps "
                    f"{_GUARD_LIMITS}. {_GUARD_ADVICE}")
        return status_message(status)

    def blank_failures(self) -> None:
        """Rows of a failed run that are not finite become NaN throughout."""
        for b in np.flatnonzero(~self.ok):
            rows = self.states[b]
            rows[~np.isfinite(rows).all(axis=1)] = np.nan


def status_message(status: int) -> str:
    """What a kernel status means, in words ("ok" when the run finished)."""
    return kernel.STATUS_MESSAGES[int(status)]


#: a short name of each kernel status, indexed by its code (``Batch.status``); datasets
#: store the codes with these names as their flag meanings
STATUS_NAMES = tuple(dict(sorted({
    kernel.OK: "finished", kernel.MAX_STEPS: "step_limit", kernel.STEP_COLLAPSE: "step_collapse",
    kernel.DIVERGED: "diverged", kernel.ESCAPED: "escaped", kernel.BAD_TIME: "bad_time",
    kernel.SKIPPED: "skipped"}.items())).values())


# ---------------------------------------------------------------------------- the runs
_WORK = threading.local()


def true_system_work() -> tuple[int, float]:
    """(runs, time) of the true impact systems (state dimension 2, sigma = 0: sampled or
    deterministic, not OPA at N = 0) that this thread has integrated so far: runs
    started from their initial state, and the time units integrated by every run
    (resumed ones too). A caller takes the difference of two readings; the kernel's own
    threads are not separate callers."""
    return getattr(_WORK, "runs", 0), getattr(_WORK, "time", 0.0)


def add_true_system_work(runs: int, time: float) -> None:
    """Count in this thread true-system work done for it in another (a helper thread that
    integrates ahead: ``mc``'s chunk pipeline)."""
    _WORK.runs = getattr(_WORK, "runs", 0) + int(runs)
    _WORK.time = getattr(_WORK, "time", 0.0) + float(time)


def _count(dim: int, p: np.ndarray, times, fresh: bool) -> None:
    if dim != 2 or not len(times):
        return
    count = int(np.count_nonzero(np.atleast_2d(p)[:, kernel.P_SIGMA] == 0.0))
    _WORK.runs = getattr(_WORK, "runs", 0) + (count if fresh else 0)
    _WORK.time = getattr(_WORK, "time", 0.0) + count * float(times[-1] - times[0])


@dataclass(frozen=True, eq=False)
class Variational:
    """Tangent vectors carried with a run (:func:`run`): the variational equation between
    events and the saltation matrices at them.

    Attributes
    ----------
    tangent : (D, m) the tangent vectors W at the start (the record's ``tangent`` is W at
        the end).
    renormalise : scale W to unit norm at every output time and record its log growth
        per interval (Benettin's loop; the record's ``log_growth``).

    Examples
    --------
    >>> Variational(np.eye(2)).tangent.shape
    (2, 2)
    >>> Variational(np.ones(2))
    Traceback (most recent call last):
    ...
    ValueError: tangent must be a (D, m) array, got shape (2,)
    """

    tangent: np.ndarray
    renormalise: bool = False

    def __post_init__(self):
        W = np.asarray(self.tangent, dtype=float)
        if W.ndim != 2:
            raise ValueError(f"tangent must be a (D, m) array, got shape {W.shape}")
        if not isinstance(self.renormalise, (bool, np.bool_)):
            raise ValueError(f"renormalise must be True or False, got {self.renormalise!r}")
        object.__setattr__(self, "tangent", W)


def run(inputs: Inputs, y0, times, *, rtol: float, atol: float, label: str = "trajectory",
        variational: Variational | None = None, statistics: bool = False,
        events: bool = True, include_start: bool = True, partial: bool = False,
        guard: bool = True) -> Record:
    """Integrate one system from ``y0`` through ``times`` and return its :class:`Record`.

    ``variational``: tangent vectors carried with the run, renormalised or not
    (:class:`Variational`); ``statistics`` records the per-interval :class:`Statistics`;
    without ``events`` no event log is kept. With ``include_start`` an impulse at
    ``times[0]`` is applied (a run from the start of the train); without, it belongs to
    the previous interval (a run resumed mid-way). ``guard``: the runaway guard
    (:func:`step_guard`) when the step limit is the default one.

    A run that cannot be completed raises :class:`SimulationError` (with its status), or
    with ``partial`` returns the outputs reached (NaN after) and the reason in
    ``failure``."""
    y0 = np.asarray(y0, dtype=float)
    times = np.ascontiguousarray(times, dtype=float)
    _count(y0.shape[-1], inputs.p, times, include_start)
    cfg = inputs.cfg
    check_addresses(cfg)
    limit = (step_guard(times, inputs.p)
             if guard and cfg[kernel.C_MAXSTEPS] == DEFAULT_MAX_STEPS else None)
    if limit is not None:
        cfg = cfg.copy()
        cfg[kernel.C_MAXSTEPS] = limit
    if (variational is not None and cfg[kernel.C_WALL_NODES] and cfg[kernel.C_NCOEF] > 1
            and cfg[kernel.C_LAW] == kernel.LAW_SALTATION):
        raise ValueError("tangents (Floquet multipliers, Lyapunov exponents) of an OPA system "
                         "with an uncertain eta or delta take the impact law mean or "
                         "ensemble; the saltation law's has no saltation matrix here yet")
    W = np.zeros((len(y0), 0)) if variational is None else variational.tangent
    if W.shape[0] != len(y0):
        raise ValueError(f"tangent must have {len(y0)} rows, got shape {W.shape}")
    renormalise = variational is not None and variational.renormalise
    m = W.shape[1]
    capacity = max(64, 4 * len(times)) if events else 0
    stats = np.empty((len(times) - 1 if statistics else 0, kernel.N_STATS))
    growth = np.empty(len(times) - 1 if renormalise else 0)
    for _ in range(2):  # a log cut at its capacity is rerun once, large enough
        out = np.empty((len(times), len(y0)))
        log = np.empty((capacity, 3))
        z = np.concatenate([y0, W.ravel()])
        prepare_kernels(kernel.integrate)
        status, n_events, n_impacts, n_steps, n_rhs = kernel.integrate(
            z, m, times, include_start, renormalise, inputs.p, cfg, inputs.table,
            inputs.weights, inputs.basis, rtol, atol, out, stats, growth, log)
        if not events or n_events <= capacity:
            break
        capacity = int(n_events * 1.2) + 16
    else:
        raise SimulationError(f"{label}: the event count changed between two identical runs "
                              f"({n_events} events)", status=status)
    failure = None
    if status != kernel.OK:
        failure = _failure(label, status, out, times, z, n_steps, n_impacts, limit)
        if not partial:
            raise SimulationError(failure, status=status)
        out[~np.isfinite(out).all(axis=1)] = np.nan
    D = len(y0)
    return Record(
        states=out, events=Events.of(log[:min(n_events, capacity)]), steps=int(n_steps),
        rhs_evaluations=int(n_rhs), impacts=int(n_impacts), status=int(status),
        failure=failure, tangent=z[D:].reshape(D, m).copy() if m else None,
        statistics=Statistics.of(stats) if statistics else None,
        log_growth=growth if renormalise else None)


def _failure(label, status, out, times, z, n_steps, n_impacts, limit) -> str:
    """The message of a run that stopped: what happened, where, and what to try."""
    reached = np.isfinite(out[:, 0])
    t_last = times[reached][-1] if reached.any() else times[0]
    # a guard at the default cap did not end the run early: it needed more than max_steps
    if status == kernel.MAX_STEPS and limit is not None and limit < DEFAULT_MAX_STEPS:
        size = float(np.max(np.abs(z))) if np.isfinite(z).all() else float("inf")
        return (f"{label} stopped by the runaway guard: {n_steps} steps by t = {t_last:.6g} "
                f"of {times[-1]:.6g} {_GUARD_LIMITS}, the state's largest component "
                f"{size:.3g}, {n_impacts} impacts. {_GUARD_ADVICE}")
    return (f"{label} stopped: {kernel.STATUS_MESSAGES[status]} (last output time reached "
            f"t = {t_last:.6g} of {times[-1]:.6g}; {n_steps} steps, {n_impacts} impacts). "
            f"{advice(status)}")


def _cpu_only(cfgs) -> None:
    if (np.asarray(cfgs)[..., kernel.C_FORCE] == kernel.FORCE_FUNCTION).any():
        raise ValueError("a compiled force function runs on the CPU only: leave out "
                         "--device cuda")


def run_batch(inputs: Inputs, y0, times, *, rtol: float, atol: float, capacity: int = 0,
              stop_on_failure: bool = False, guard: bool = True,
              include_start: bool = True, device: str = "cpu") -> Batch:
    """B independent plain runs in parallel: run b starts from ``y0`` (or ``y0[b]`` when
    it has shape (B, dim)) with the b-th system of ``inputs`` (:func:`stack`,
    :func:`sampled`). Each log keeps ``capacity`` events. With ``stop_on_failure`` the
    runs not started after the first failure are marked skipped (not with states of
    their own). ``guard``: the runaway guard (:func:`step_guard`) for each run whose step
    limit is the default one. ``include_start``: as for :func:`run` (False: runs resumed
    mid-way; not with ``stop_on_failure``). Each run depends on nothing but its own
    inputs, so the results do not depend on the threads. ``device="cuda"``: the runs on a
    GPU, one thread each (:mod:`opa._gpu`; the true 2-D systems only, every run made)."""
    y0 = np.ascontiguousarray(y0, dtype=float)
    times = np.ascontiguousarray(times, dtype=float)
    B = len(inputs.p)
    own_states = y0.ndim == 2 or not include_start
    if own_states and stop_on_failure:
        raise ValueError("stop_on_failure needs one start state and include_start")
    cfgs, guarded = _guarded_cfgs(inputs, times, guard)
    check_addresses(cfgs)
    dim = y0.shape[-1]
    _count(dim, inputs.p, times, include_start)
    out = np.empty((B, len(times), dim))
    logs = np.empty((B, capacity, 3))
    counters = np.zeros((B, 5), dtype=np.int64)
    if device == "cuda":
        from . import _gpu

        _cpu_only(cfgs)
        out, logs, counters = _gpu.run_batch(
            np.broadcast_to(y0, (B, dim)), include_start, times, inputs.p, cfgs,
            inputs.table, inputs.weights, inputs.basis, rtol, atol, capacity)
        return Batch(out, logs, counters, guarded)
    quiet_threads()
    apply_thread_grant()
    if own_states:
        prepare_kernels(kernel.run_batch_from)
        kernel.run_batch_from(np.ascontiguousarray(np.broadcast_to(y0, (B, dim))),
                              bool(include_start), times, np.ascontiguousarray(inputs.p), cfgs,
                              *(np.ascontiguousarray(a, dtype=float)
                                for a in (inputs.table, inputs.weights, inputs.basis)),
                              rtol, atol, out, logs, counters)
        return Batch(out, logs, counters, guarded)
    abort = np.array([0 if stop_on_failure else -1], dtype=np.int64)
    prepare_kernels(kernel.run_batch)
    kernel.run_batch(y0, times, np.ascontiguousarray(inputs.p), cfgs,
                     *(np.ascontiguousarray(a, dtype=float)
                       for a in (inputs.table, inputs.weights, inputs.basis)),
                     rtol, atol, out, logs, counters, abort)
    return Batch(out, logs, counters, guarded)


def gpu_moments(inputs: Inputs, y0, times, *, rtol: float, atol: float,
                guard: bool = True):
    """The B runs of ``inputs`` (the true 2-D systems, :func:`sampled`) from ``y0`` on a
    CUDA GPU, reduced there (:func:`opa._gpu.moments`): only the moments and the counters
    cross back. Returns (mean (n_out, 2), var (n_out, 2), finite counts, counters (B, 5)).
    ``guard``: as for :func:`run_batch`."""
    from . import _gpu

    times = np.ascontiguousarray(times, dtype=float)
    cfgs, _ = _guarded_cfgs(inputs, times, guard)
    _cpu_only(cfgs)
    y0 = np.ascontiguousarray(y0, dtype=float)
    B = len(inputs.p)
    _count(y0.shape[-1], inputs.p, times, True)
    return _gpu.moments(np.broadcast_to(y0, (B, y0.shape[-1])), True, times, inputs.p, cfgs,
                        inputs.table, inputs.weights, inputs.basis, rtol, atol)
