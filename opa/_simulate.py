"""Single runs of the DMR (eq. (29)) and of the OPA equivalent system (eqs. (24)-(28)).

This layer validates input, packs it into the flat vectors the compiled kernel takes,
turns the kernel's status codes into exceptions, and builds the ``dmr`` and ``opa``
datasets of docs/datasets.md.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from opa import _kernel as K
from opa._basis import chebyshev_u, gauss_nodes, quadrature_order
from opa._dataset import provenance_attrs, time_coord
from opa._lazy import lazy
from opa._model import (
    check_instance,
    check_order,
    check_span,
    IMPACT_LAWS,
    METHODS,
    TRUNCATIONS,
    Oscillator,
    SolverOptions,
    Uncertainty,
    _choice,
    time_grid,
)

xr = lazy("xarray")


class SimulationError(RuntimeError):
    """A trajectory could not be completed (divergence, step collapse, step limit)."""


def pack_parameters(
    oscillator: Oscillator,
    options: SolverOptions,
    *,
    sigma: float = 0.0,
    order: int = 0,
    uncertain: str = "mu",
    truncation: str = "galerkin",
    impact_law: str = "mean",
) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's float vector ``p`` and integer vector ``cfg``."""
    T1 = 2.0 * math.pi / oscillator.omega1
    if options.impulse == "pulse" and options.pulse_width >= T1:
        raise ValueError(
            f"pulse_width must be shorter than the impulse period 2 pi/omega1 = {T1:.6g}, "
            f"got {options.pulse_width}"
        )
    p = np.zeros(K.N_PARAMS)
    p[K.P_MU] = oscillator.mu
    p[K.P_A] = oscillator.a
    p[K.P_C] = oscillator.c
    p[K.P_F] = oscillator.f
    p[K.P_OMEGA] = oscillator.omega
    p[K.P_ETA] = oscillator.eta
    p[K.P_DELTA] = oscillator.delta
    p[K.P_F0] = oscillator.F0
    p[K.P_A1] = oscillator.a1
    p[K.P_OMEGA1] = oscillator.omega1
    p[K.P_N] = oscillator.n
    p[K.P_TAU] = options.pulse_width
    p[K.P_SIGMA] = sigma
    p[K.P_CHATTER_V] = options.chatter_velocity
    p[K.P_HMAX] = options.max_step
    cfg = np.zeros(K.N_CFG, dtype=np.int64)
    cfg[K.C_NCOEF] = order + 1
    cfg[K.C_UNCERTAIN] = ("mu", "a", "c").index(uncertain)
    cfg[K.C_IMPULSE] = ("dirac", "pulse").index(options.impulse)
    cfg[K.C_AT_ZERO] = int(bool(options.impulse_at_zero))
    cfg[K.C_TRUNC] = TRUNCATIONS.index(truncation)
    cfg[K.C_LAW] = IMPACT_LAWS.index(impact_law)
    cfg[K.C_MAXSTEPS] = int(options.max_steps)
    cfg[K.C_METHOD] = (K.METHOD_DOP853, K.METHOD_DP5)[METHODS.index(options.method)]
    return p, cfg


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


def announce_compilation(dispatcher) -> None:
    """Print "compiling kernels (first run only)..." once per process, to stderr, before
    a kernel entry point that is neither compiled in this process nor in numba's on-disk
    cache (a first run sits for several seconds compiling)."""
    if _ANNOUNCED or dispatcher.signatures:
        return
    try:  # numba's index of cached overloads, empty when the source changed
        cached = bool(dispatcher._cache._cache_file._load_index())
    except Exception:  # a numba without this layout: say nothing rather than guess
        cached = True
    if not cached:
        _ANNOUNCED.append(True)
        print("compiling kernels (first run only)...", file=sys.stderr, flush=True)


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
    announce_compilation(K.run_batch)
    K.run_batch(y0, np.ascontiguousarray(times, dtype=float), np.ascontiguousarray(P),
                np.ascontiguousarray(cfgs, dtype=np.int64), nodes, weights, U, rtol, atol, out,
                logs, counters, abort)
    return out, logs, counters


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
    while True:
        out = np.empty((len(times), len(y0)))
        log = np.empty((capacity, 3))
        z = np.array(y0, dtype=float)
        announce_compilation(K.integrate)
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
        if not partial:
            raise SimulationError(f"{message}. {advice(status)}")
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


def _times(oscillator, periods, per_period, times, dim: int = 2):
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
    from opa._dataset import check_memory

    check_memory(f"{len(times)} outputs x {dim} states", len(times) * (dim + 1) * 8 * 2)
    return times


def _event_vars(log: np.ndarray) -> dict:
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
            {"long_name": f"1 where the impact velocity is below {K.GRAZE_VELOCITY} (graze)",
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


def simulate_dmr(
    oscillator: Oscillator | None = None,
    *,
    periods: float = 100,
    per_period: int = 1,
    options: SolverOptions | None = None,
    times: np.ndarray | None = None,
) -> xr.Dataset:
    """One deterministic trajectory of the impact oscillator (the DMR, eq. (29)).

    Parameters
    ----------
    oscillator : model parameters (paper defaults when omitted).
    periods, per_period : output times t_j = j (2 pi/omega)/K, j = 0..P K; K = 1 gives
        the stroboscopic samples. ``times`` overrides this grid.
    options : solver options (impulse model, tolerances, ...).

    Returns
    -------
    xarray.Dataset with ``x(time)``, ``v(time)``, ``impact_time(impact)``,
    ``impact_velocity(impact)`` and the provenance attributes of docs/datasets.md.
    States at an impulse time are recorded just after the impulse (right-continuous).

    Examples
    --------
    >>> ds = simulate_dmr(Oscillator(), periods=10)
    >>> ds.x.sizes["time"]
    11
    """
    oscillator = check_instance("oscillator", oscillator, Oscillator, Oscillator())
    options = check_instance("options", options, SolverOptions, SolverOptions())
    times = _times(oscillator, periods, per_period, times)
    p, cfg = pack_parameters(oscillator, options)
    out, log, stats = run_kernel(
        [oscillator.x0, oscillator.v0], times, p, cfg, quadrature(0),
        rtol=options.rtol, atol=options.atol, label="DMR trajectory",
    )
    ds = xr.Dataset(
        {
            "x": ("time", out[:, 0], {"long_name": "displacement x", "units": "1"}),
            "v": ("time", out[:, 1], {"long_name": "velocity dx/dt", "units": "1"}),
            **_event_vars(log),
        },
        coords=time_coord(times, oscillator.omega),
        attrs=provenance_attrs("dmr", oscillator, options),
    )
    ds.attrs.update(steps=stats["steps"], rhs_evaluations=stats["rhs_evaluations"])
    return ds


def check_support(oscillator: Oscillator, unc: Uncertainty, measure) -> None:
    """Refuse samples p_bar + sigma xi < 0 over xi's support unless allowed."""
    mean = getattr(oscillator, unc.parameter)
    lowest = mean + unc.sigma * measure.lo
    if not unc.allow_negative and lowest < 0.0 <= mean:
        raise ValueError(
            f"sigma = {unc.sigma} with xi down to {measure.lo:g} makes {unc.parameter} = "
            f"{lowest:.6g} negative for some samples; pass allow_negative=True "
            f"(--allow-negative) if that is intended")


def simulate_opa(
    oscillator: Oscillator | None = None,
    *,
    sigma: float = 0.0,
    order: int = 4,
    uncertain: str = "mu",
    truncation: str = "galerkin",
    impact_law: str = "mean",
    allow_negative: bool = False,
    periods: float = 100,
    per_period: int = 1,
    options: SolverOptions | None = None,
    times: np.ndarray | None = None,
    initial: np.ndarray | None = None,
    distribution=None,
    elements=None,
    tolerance: float = 1e-6,
    max_elements: int = 64,
    partial: bool = False,
) -> xr.Dataset:
    """The OPA equivalent system of order N (the EMR, eqs. (24)-(28)).

    ``x(t, xi) ~ sum_i x_i(t) U_i(xi)`` with the uncertain parameter
    ``p = p_bar + sigma xi``; impacts use the mean constraint ``x_0 = delta``
    (eq. (21)) and the impact law ``mean`` (eq. (28): only x_0' jumps) or ``ensemble``
    (every velocity coefficient is multiplied by -eta). ``truncation="paper"`` drops
    the ``sigma/2 Y_{N+1}`` term of the last equation as eq. (27) does; ``galerkin``
    keeps the exact projection. Initial coefficients: x_0 = x0, v_0 = v0, others 0,
    unless ``initial`` (shape (2, N+1): rows x_coef, v_coef) is given, e.g. to continue
    from the end of an earlier run.

    Multi-element OPA (:mod:`opa._elements`): ``distribution`` is the law of xi (a name
    of :data:`opa._measure.DISTRIBUTIONS`, a chaospy distribution with bounded support,
    or a :class:`opa._measure.Measure`; default the semicircle) and ``elements`` cuts
    its support: ``K`` equal-probability elements, an increasing array of edges, or
    ``"adaptive"`` (edges at the splits of the sampled systems' impact sequences, then
    halving of the element with the largest variance share until it is below
    ``tolerance`` or ``max_elements`` is reached). Each element runs its own OPA system
    of order N; the result holds the assembled ``x_mean, x_var, v_mean, v_var`` and the
    per-element coefficients, edges and probabilities.

    ``partial``: a trajectory that cannot be completed (e.g. the OPA system diverges)
    returns the outputs reached, NaN after, with the reason in ``attrs["failure"]``,
    instead of raising :class:`SimulationError`.

    Returns
    -------
    xarray.Dataset with ``x_coef(order, time)``, ``v_coef(order, time)``,
    ``x_mean`` (= x_coef[0], the EMR), ``x_var`` (= sum_{i>=1} x_coef^2), ``v_mean``,
    ``v_var`` and the impacts of the mean coordinate.

    Examples
    --------
    >>> ds = simulate_opa(Oscillator(), sigma=0.01, order=4, periods=10)
    >>> ds.x_coef.shape
    (5, 11)
    """
    oscillator = check_instance("oscillator", oscillator, Oscillator, Oscillator())
    options = check_instance("options", options, SolverOptions, SolverOptions())
    order = check_order(order)
    _choice("truncation", truncation, TRUNCATIONS)
    _choice("impact_law", impact_law, IMPACT_LAWS)
    unc = Uncertainty(sigma, uncertain, allow_negative)
    if distribution is not None or elements is not None:
        from opa._elements import simulate_elements
        from opa._measure import parse

        if initial is not None or partial:
            raise ValueError("initial and partial are not supported with elements or a "
                             "distribution")
        measure = parse(distribution)
        check_support(oscillator, unc, measure)
        return simulate_elements(
            oscillator, sigma=unc.sigma, order=order, uncertain=uncertain,
            impact_law=impact_law, truncation=truncation, options=options,
            times=_times(oscillator, periods, per_period, times), unc=unc, measure=measure,
            elements=1 if elements is None else elements, tolerance=tolerance,
            max_elements=max_elements, allow_negative=allow_negative)
    unc.check(oscillator)
    times = _times(oscillator, periods, per_period, times, dim=2 * (order + 1))
    p, cfg = pack_parameters(
        oscillator, options, sigma=unc.sigma, order=order, uncertain=uncertain,
        truncation=truncation, impact_law=impact_law,
    )
    y0 = np.zeros(2 * (order + 1))
    if initial is None:
        y0[0] = oscillator.x0
        y0[order + 1] = oscillator.v0
    else:
        initial = np.asarray(initial, dtype=float)
        if initial.shape != (2, order + 1) or not np.all(np.isfinite(initial)):
            raise ValueError(
                f"initial must be a finite array of shape (2, {order + 1}), got shape "
                f"{initial.shape}"
            )
        if initial[0, 0] > oscillator.delta:
            raise ValueError(f"initial x_0 must not be beyond the wall, got {initial[0, 0]}")
        y0[:] = initial.ravel()
    out, log, stats = run_kernel(
        y0, times, p, cfg, quadrature(order), rtol=options.rtol, atol=options.atol,
        label=f"OPA (N={order}) trajectory", partial=partial,
    )
    xc = out[:, : order + 1].T
    vc = out[:, order + 1 :].T
    ds = xr.Dataset(
        {
            "x_coef": (("order", "time"), xc,
                       {"long_name": "OPA coefficient x_i = E[x U_i(xi)]", "units": "1"}),
            "v_coef": (("order", "time"), vc,
                       {"long_name": "OPA coefficient v_i = E[x' U_i(xi)]", "units": "1"}),
            "x_mean": ("time", xc[0], {"long_name": "OPA mean E[x] = x_0 (EMR)", "units": "1"}),
            "x_var": ("time", (xc[1:] ** 2).sum(axis=0),
                      {"long_name": "OPA variance sum_{i>=1} x_i^2", "units": "1"}),
            "v_mean": ("time", vc[0], {"long_name": "OPA mean velocity v_0", "units": "1"}),
            "v_var": ("time", (vc[1:] ** 2).sum(axis=0),
                      {"long_name": "OPA velocity variance sum_{i>=1} v_i^2", "units": "1"}),
            **_event_vars(log),
        },
        coords={**time_coord(times, oscillator.omega), "order": ("order", np.arange(order + 1))},
        attrs=provenance_attrs(
            "opa", oscillator, options, sigma=unc.sigma, order=order, uncertain=uncertain,
            truncation=truncation, impact_law=impact_law,
        ),
    )
    ds.attrs.update(steps=stats["steps"], rhs_evaluations=stats["rhs_evaluations"],
                    allow_negative=int(allow_negative))
    if "failure" in stats:
        ds.attrs["failure"] = stats["failure"]
    return ds


def opa_variants(oscillator: Oscillator, *, sigma: float, order: int, uncertain: str,
                 variants, times: np.ndarray, options: SolverOptions):
    """The OPA system of order N under several (impact law, truncation) variants, in
    parallel: mean and variance of x over ``times`` (NaN after a trajectory that could not
    be completed) and the time of each variant's first impact (inf: none).

    Returns (x_mean (V, T), x_var (V, T), first_impact (V,))."""
    order = check_order(order)
    cfgs = []
    for law, trunc in variants:
        _choice("impact_law", law, IMPACT_LAWS)
        _choice("truncation", trunc, TRUNCATIONS)
        p, cfg = pack_parameters(oscillator, options, sigma=sigma, order=order,
                                 uncertain=uncertain, truncation=trunc, impact_law=law)
        cfgs.append(cfg)
    nodes, weights, basis = kernel_quadrature(quadrature(order))
    dim = 2 * (order + 1)
    y0 = np.zeros(dim)
    y0[0] = oscillator.x0
    y0[order + 1] = oscillator.v0
    V = len(cfgs)
    cap = max(64, 4 * len(times))
    rule = tuple(np.repeat(a[None], V, axis=0) for a in (nodes, weights, basis))
    out, logs, counters = run_batch(y0, times, np.repeat(p[None, :], V, axis=0),
                                    np.stack(cfgs), rule, rtol=options.rtol, atol=options.atol,
                                    capacity=cap)
    first = np.full(V, np.inf)
    for v in range(V):
        if counters[v, 0] != K.OK:
            out[v][~np.isfinite(out[v]).all(axis=1)] = np.nan
        n = min(int(counters[v, 1]), cap)
        hits = np.flatnonzero(np.isin(logs[v, :n, 2], (K.EV_IMPACT, K.EV_GRAZE, K.EV_KICK)))
        if len(hits):
            first[v] = logs[v, hits[0], 0]
    x = out[:, :, : order + 1]
    return x[:, :, 0], (x[:, :, 1:] ** 2).sum(axis=2), first
