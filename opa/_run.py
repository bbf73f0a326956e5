"""The only caller of the compiled kernel (``opa._kernel``): Gauss rules in the kernel's
layout, single and batched runs, status codes turned into :class:`SimulationError` with
advice, event-log decoding, and the checks on output times every run shares."""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import threading

import numpy as np

from opa import _kernel as K
from opa._basis import chebyshev_u, gauss_nodes, quadrature_order
from opa._memory import check_memory
from opa._model import check_span, time_grid


class SimulationError(RuntimeError):
    """A trajectory could not be completed (divergence, step collapse, step limit)."""


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


def prepare_kernels(dispatcher) -> None:
    """Before a kernel entry point that is neither compiled in this process nor in
    numba's on-disk cache: print "compiling kernels (first run only)..." once per
    process, to stderr, and compile the driver's callees on two cores
    (:func:`compile_callees`): a first run sits for several seconds compiling."""
    if _ANNOUNCED or dispatcher.signatures:
        return
    try:  # numba's index of cached overloads, empty when the source changed
        cached = bool(dispatcher._cache._cache_file._load_index())
    except Exception:  # a numba without this layout: say nothing rather than guess
        cached = True
    if not cached:
        _ANNOUNCED.append(True)
        print("compiling kernels (first run only)...", file=sys.stderr, flush=True)
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
    system = (v, iv, v, v, m)  # p, cfg, nodes, weights, U
    column = nt.UniTuple(f8, 7)  # a component's dense-output coefficients
    stages = nt.UniTuple(f8, 12)  # one component's stages of a 2-D DOP853 step
    helper = {  # leaves and the 2-D stepper: nothing here calls the vector field; what
        # the main group calls first comes first (the main group's leaves give the
        # helper the time to finish the 2-D step before rk_step needs it)
        "is_deterministic": (i8, iv, v),
        "last_stage": (i8,),
        "_stages2_dop853": (f8,) * 14 + (b1,),
        "_error2": (f8,) * 7 + (stages, stages, f8, f8),
        "_dense_stages2_dop853": (f8, f8, m) + (f8,) * 10 + (b1,),
        "_dop853_coefficients": (v, v, f8, m, m),
        "store_stages2": (m, stages, stages),
        "dense_prepare2": (f8, v, v, f8, m, m, v, f8, b1),
        "state_status": (v, i8, f8),
        "first_impulse": (f8, b1, f8, b1),
        "impulse_strength": (f8, v),
        "_log_event": (m, i8, f8, f8, i8),
        "_hold": (v, i8, i8, i8),
        "_reflect": (v, i8, i8, f8, b1),
        "dense_x": (i8, f8, f8, column),
        "dense_dx": (i8, f8, column),
        "dense_value": (i8, f8, v, m, i8),
        "_bisect_wall": (i8, f8, f8, f8, column, f8, f8),
        "_bisect_maximum": (i8, f8, f8, column),
        "wall_crossing": (i8, f8, column, f8, f8),
        "dense_state": (i8, f8, v, m, v),
        "free_flight_maximum": (i8, f8, column, f8),
        # the driver's phases that call no vector field (those that do are inlined)
        "start_run": (v, f8, f8, b1, v, iv, f8, f8, m, m),
        "impulses": (f8, v, i8, b1, i8, f8, f8, f8, i8, i8, i8, v, iv, f8, f8, m, m),
        "store_outputs": (f8, v, i8, i8, b1, v, m, m),
    }
    main = {  # the vector field, everything that calls it, and a few leaves
        "vector_field": (v, i8) + system + (f8, b1, v, m),
        "_stage_forcing_long": (f8,) * 8,
        "stage_drive": (f8,) * 8,
        "_stage_rows": (f8, v, f8, m, v, table_m, table_v, i8, i8, i8) + system + (f8, b1, m),
        "_impact": (f8, v, i8) + system + (f8, v, v, m),
        "error_norm": (i8, v, v, m, f8, f8, f8),
        "wall_margin": (m, i8, i8, f8),
        "escape_bound": (v, v),
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
            getattr(K, name).compile(signature)
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
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if (cores or 1) < 2:
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


def sampled_batch(p: np.ndarray, cfg: np.ndarray, *, xi=None, values=None):
    """Kernel inputs of M sampled deterministic systems (N = 0) for :func:`run_batch`.

    System m has the uncertain parameter (``cfg``'s) at ``values[m]`` (absolute) or at
    ``p_bar + sigma xi[m]`` (computed as the kernel always has, so the results are the
    same bit for bit). Returns (P (M, N_PARAMS), cfgs (M, N_CFG), rule) with the one-node
    rule at xi = 0 for every system."""
    idx = (K.P_MU, K.P_A, K.P_C)[int(cfg[K.C_UNCERTAIN])]
    if values is None:
        values = p[idx] + p[K.P_SIGMA] * np.asarray(xi, dtype=float)
    values = np.asarray(values, dtype=float)
    M = len(values)
    P = np.repeat(p[None, :], M, axis=0)
    P[:, idx] = values
    P[:, K.P_SIGMA] = 0.0
    one = cfg.copy()
    one[K.C_NCOEF] = 1
    one[K.C_TRUNC] = K.TRUNC_GALERKIN
    one[K.C_LAW] = K.LAW_MEAN
    cfgs = np.repeat(one[None, :], M, axis=0)
    U = np.zeros((M, 1, 2))
    U[:, 0, 0] = 1.0
    return P, cfgs, (np.zeros((M, 1)), np.ones((M, 1)), U)


def run_batch(y0, times, P, cfgs, rule, *, rtol, atol, capacity=0, stop_on_failure=False):
    """B independent plain runs in parallel (``opa._kernel.run_batch``).

    Run b starts from ``y0`` with parameters ``P[b]``, configuration ``cfgs[b]`` and
    the node-major rule ``(nodes[b], weights[b], U[b])`` of ``rule``. Returns (out
    (B, n_out, dim), logs (B, capacity, 3), counters (B, 5): status, events, impacts,
    steps, right-hand sides). With ``stop_on_failure`` the runs not started after the
    first failure are marked ``SKIPPED``."""
    nodes, weights, U = (np.ascontiguousarray(a, dtype=float) for a in rule)
    y0 = np.ascontiguousarray(y0, dtype=float)
    B = len(P)
    out = np.empty((B, len(times), len(y0)))
    logs = np.empty((B, capacity, 3))
    counters = np.zeros((B, 5), dtype=np.int64)
    abort = np.array([0 if stop_on_failure else -1], dtype=np.int64)
    prepare_kernels(K.run_batch)
    K.run_batch(y0, np.ascontiguousarray(times, dtype=float), np.ascontiguousarray(P),
                np.ascontiguousarray(cfgs, dtype=np.int64), nodes, weights, U, rtol, atol, out,
                logs, counters, abort)
    return out, logs, counters


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


def step_guard(times, p) -> int:
    """Steps the runaway guard allows over ``times`` (module constants above)."""
    span = float(times[-1] - times[0]) if len(times) else 0.0
    periods = span * p[K.P_OMEGA] / (2.0 * np.pi)
    return int(min(DEFAULT_MAX_STEPS, max(GUARD_FLOOR, GUARD_PER_PERIOD * periods,
                                          GUARD_PER_TIME * span)))


def run_kernel(y0, times, p, cfg, quad, *, rtol, atol, label="trajectory", partial=False,
               include_start=True):
    """Integrate and return (states (n_out, dim), event log (n, 3), counters dict).

    ``quad`` is :func:`quadrature`'s (nodes, weights, basis (N+2, Q)). With
    ``include_start`` an impulse at ``times[0]`` is applied (a run from the start of the
    train); without, it belongs to the previous interval (a run resumed mid-way). A trajectory that
    cannot be completed raises :class:`SimulationError`, or with ``partial`` returns the
    outputs reached (NaN after) and the reason in ``counters["failure"]``."""
    nodes, weights, basis = kernel_quadrature(quad)
    capacity = max(64, 4 * len(times))
    guard = step_guard(times, p) if cfg[K.C_MAXSTEPS] == DEFAULT_MAX_STEPS else None
    if guard is not None:
        cfg = cfg.copy()
        cfg[K.C_MAXSTEPS] = guard
    while True:
        out = np.empty((len(times), len(y0)))
        log = np.empty((capacity, 3))
        z = np.array(y0, dtype=float)
        prepare_kernels(K.integrate)
        status, n_events, n_impacts, n_steps, n_rhs = K.integrate(
            z, 0, np.ascontiguousarray(times, dtype=float), include_start, False, p, cfg, nodes,
            weights, basis, rtol, atol, out, np.empty((0, K.N_STATS)), np.empty(0), log
        )
        if n_events <= capacity:
            break
        capacity = int(n_events * 1.2) + 16
    counters = {"steps": n_steps, "rhs_evaluations": n_rhs, "impacts": n_impacts}
    if status != K.OK:
        reached = np.isfinite(out[:, 0])
        t_last = times[reached][-1] if reached.any() else times[0]
        message = (f"{label} stopped: {K.STATUS_MESSAGES[status]} (last output time reached "
                   f"t = {t_last:.6g} of {times[-1]:.6g}; {n_steps} steps, {n_impacts} "
                   f"impacts)")
        hint = advice(status)
        if status == K.MAX_STEPS and guard is not None:
            size = float(np.max(np.abs(z))) if np.isfinite(z).all() else float("inf")
            message = (f"{label} stopped by the runaway guard: {n_steps} steps by t = "
                       f"{t_last:.6g} of {times[-1]:.6g} (at most {GUARD_PER_PERIOD} per "
                       f"forcing period, {GUARD_PER_TIME} per unit time, {GUARD_FLOOR} in "
                       f"all), the state's largest component {size:.3g}, {n_impacts} impacts")
            hint = ("The step size collapsed, as when the state runs away in finite time: "
                    "check the parameters (e.g. the signs of a and c); a run that truly "
                    "needs more steps can give SolverOptions(max_steps=...) explicitly.")
        if not partial:
            raise SimulationError(f"{message}. {hint}")
        out[~np.isfinite(out).all(axis=1)] = np.nan
        counters["failure"] = message
    return out, log[:min(n_events, len(log))], counters


def advice(status: int) -> str:
    """What to try after a kernel status: tolerances help a collapsed step, not an escape."""
    if status in (K.ESCAPED, K.DIVERGED):
        return ("The parameters drive the state out of every bound: check them (e.g. the "
                "signs of a and c, the sizes of f, F0 and mu).")
    if status == K.BAD_TIME:
        return "Check the output times: they must be finite, with impulse times resolvable."
    if status == K.MAX_STEPS:
        return ("The run needs more steps than max_steps (SolverOptions.max_steps): ask for "
                "fewer periods, looser tolerances or a larger --max-step, or check the "
                "parameters.")
    if status == K.STEP_COLLAPSE:
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


def event_vars(log: np.ndarray) -> dict:
    kinds = log[:, 2].astype(np.int8) if len(log) else np.zeros(0, np.int8)
    impact = np.isin(kinds, (K.EV_IMPACT, K.EV_GRAZE, K.EV_KICK))
    return {
        "impact_time": (
            "impact",
            log[impact, 0],
            {"long_name": "time of impact with the wall", "units": "1"},
        ),
        "impact_velocity": (
            "impact",
            log[impact, 1],
            {"long_name": "pre-impact velocity of the (mean) coordinate", "units": "1"},
        ),
        "impact_graze": (
            "impact",
            (kinds[impact] == K.EV_GRAZE).astype(np.int8),
            {"long_name": f"1 where the impact velocity is below {K.EVENT_GRAZE_VELOCITY} (graze)",
             "units": "1"},
        ),
        "stick_time": (
            "stick",
            log[kinds == K.EV_STICK, 0],
            {"long_name": "chatter accumulation time, start of sticking", "units": "1"},
        ),
        "release_time": (
            "release",
            log[kinds == K.EV_RELEASE, 0],
            {"long_name": "time of release from the wall after sticking", "units": "1"},
        ),
    }
