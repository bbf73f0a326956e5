"""Peer solvers of the impact oscillator for ``bench_peers.py``: the loops a user would write.

Every peer solves the same problem as ``opa.simulate_dmr`` (see ``bench_peers.py``):
breakpoints at the Dirac kicks ``t_j = j 2 pi / omega1`` and at the stroboscopic output
times ``t_k = k 2 pi / omega``; at a kick the velocity jumps by
``F0 (1 + a1 sin(omega1 t_j / n))`` and, if then ``x >= delta`` and ``v > 0``, the impact
law ``v -> -eta v`` is applied at once; between breakpoints the ODE is integrated until
``x`` reaches ``delta`` from below, where ``x := delta, v := -eta v`` and the integration
restarts. Outputs are right-continuous (recorded after the kick). Chatter is ended as ours
ends it (``SolverOptions.chatter_velocity``, 1e-6): an impact slower than that with the
force at rest on the wall pointing into it starts sticking (x = delta, v = 0), released
when that force turns (closed form for the harmonic forcing: f cos(omega t) = a delta +
c delta^3). Without it a Zeno sequence (e.g. mu = 0.7971195805936405 at rtol 1e-8) costs
the dop853 loop ~10^5 impacts.

Nothing here imports a peer at module level: numbalsoda, jax and diffrax are imported by
the ``build_*`` functions, so that this module (and ``bench_peers.py``) imports cleanly
without them.

* ``numbalsoda_*(method="dop853")``: numbalsoda's ``dop853`` (Hairer's DOP853 in Fortran)
  called from a numba-jitted event loop with a ``numba.cfunc`` right-hand side.
  numbalsoda's plain ``dop853`` driver restarts the integrator at every requested time
  (``integrate(t_i, t_i+1)`` per interval, a new initial step each time, no dense
  output), so the loop advances in sub-windows of ``WINDOW_FRACTION`` forcing periods
  (1/4: 1/2 is as fast, a whole period misses an impact within 20 periods) and checks
  each window's end for ``x > delta`` and the window's cubic Hermite interpolant (x,
  x' = v at both ends) for a grazing excursion above ``delta`` inside it. A crossing is
  located by a safeguarded Newton iteration on ``x(t) - delta`` (``x' = v``), each
  iterate re-integrated from the last point known to be before the wall, down to
  ``|x - delta| <= 1e-14``. Intervals below 1e-9 |t| (which DOP853 refuses: "step size
  too small") are bridged by a Taylor step.
* ``method="ivp"``: numbalsoda's own event API, ``numbalsoda.solve_ivp`` (DOP853 with
  dense output and a Brent root finder on an event function, in Fortran), one call per
  segment between breakpoints and one more per impact. Its Brent tolerance is fixed at
  1e-8 in time, so the event is polished by one Newton (Taylor) step to ``x = delta``.
  Events fire on sign changes in either direction, tested at step ends only, so the event
  function is -1 at the start of each call (as in ``bench_dmr.scipy_dmr``) and a
  downward crossing is an error.
* ``diffrax_*``: ``diffrax.diffeqsolve`` (Dopri5 / Dopri8, ``PIDController``, ``dt0=None``)
  with an ``Event`` on ``x - delta`` (upward crossings, ``optimistix.Bisection`` on the
  dense interpolant of the step; see ``ROOT_FINDER`` for why not Newton) inside one
  jitted ``jax.lax.while_loop`` over segments and impacts; float64. The ensemble is
  ``jax.vmap`` of the same loop, in chunks of ``LANES`` samples dealt to 2 host devices
  (``--xla_force_host_platform_device_count=2``, set before jax is imported) from one
  thread each. RHS evaluations are counted from the steps (FSAL: 6 a step for Dopri5,
  13 for Dopri8, plus 2 a call for the initial step).
* ``scipy_opa``: the OPA system of order N in numpy (written from the Galerkin formula
  with a Gauss rule of the semicircle law) in the ``solve_ivp`` event loop of
  ``bench_dmr.scipy_dmr``.
"""

from __future__ import annotations

import math
import os
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np

TWO_PI = 2.0 * math.pi
# sub-window of the numbalsoda dop853 loop, in forcing periods 2 pi / omega
WINDOW_FRACTION = 0.25
# parameter vector layout shared by the numba and jax peers: the model, the chatter
# velocity, the start of the current integration (for numbalsoda's event function) and a
# counter of RHS calls (numbalsoda loops)
MU, A, C, F, OMEGA, DELTA, ETA, CHATTER, START, COUNT = range(10)
N_PARAMS = 10
MAX_STEPS = 100_000


def parameters(osc, mu: float | None = None, chatter_velocity: float = 1e-6) -> np.ndarray:
    p = np.zeros(N_PARAMS)
    p[:START] = (osc.mu if mu is None else mu, osc.a, osc.c, osc.f, osc.omega, osc.delta,
                 osc.eta, chatter_velocity)
    if osc.f <= 0.0:
        raise ValueError("the peers' sticking release assumes a forcing amplitude f > 0")
    return p


def wall_force(t, p):
    """Acceleration at rest on the wall (x = delta, v = 0: the mu term vanishes)."""
    d = p[DELTA]
    return -p[A] * d - p[C] * d * d * d + p[F] * math.cos(p[OMEGA] * t)


def release_time(t, p):
    """First time after t at which the acceleration at rest on the wall turns negative
    (closed form: f cos(omega t) = a delta + c delta^3), inf if it never does."""
    d = p[DELTA]
    K = (p[A] * d + p[C] * d * d * d) / p[F]
    if K <= -1.0:
        return math.inf
    alpha = math.acos(min(K, 1.0))
    phase = p[OMEGA] * t
    theta = phase - 2.0 * math.pi * math.floor(phase / (2.0 * math.pi))  # in [0, 2 pi)
    if theta > math.pi:
        theta -= 2.0 * math.pi
    dt = (alpha - theta) / p[OMEGA]
    if dt <= 0.0:
        dt += 2.0 * math.pi / p[OMEGA]
    return t + dt


def schedule(osc, periods: int):
    """Breakpoints (kicks and stroboscopic outputs), with per-breakpoint kick flag, velocity
    jump and output index (-1: none). Output times as ``bench_dmr.scipy_dmr``'s."""
    t_out = np.arange(periods + 1) * (TWO_PI / osc.omega)
    t_end = t_out[-1]
    T1 = TWO_PI / osc.omega1
    kicks = np.arange(math.floor(t_end / T1) + 1) * T1
    bounds = np.unique(np.concatenate([kicks, t_out]))
    is_kick = np.isin(bounds, kicks)
    kick_dv = np.where(is_kick, osc.F0 * (1.0 + osc.a1 * np.sin(osc.omega1 * bounds / osc.n)),
                       0.0)
    out_idx = np.full(len(bounds), -1, dtype=np.int64)
    where = np.searchsorted(bounds, t_out)
    out_idx[where] = np.arange(len(t_out))
    return t_out, bounds, is_kick, kick_dv, out_idx


# ============================================================================ numbalsoda

_NUMBALSODA: dict = {}


def build_numbalsoda():
    """Compile the cfunc RHS, the event function and the jitted loops (once a process)."""
    if _NUMBALSODA:
        return _NUMBALSODA
    import numba
    import numbalsoda
    from numba import carray, cfunc, njit, prange

    dop853 = numbalsoda.dop853
    nb_solve_ivp = numbalsoda.solve_ivp
    force_at_wall = njit(cache=False)(wall_force)
    release = njit(cache=False)(release_time)

    @cfunc(numbalsoda.lsoda_sig)
    def rhs(t, u, du, p_):
        p = carray(p_, (N_PARAMS,))
        x = u[0]
        v = u[1]
        du[0] = v
        du[1] = p[MU] * (1.0 - v * v) * v - p[A] * x - p[C] * x * x * x + p[F] * math.cos(
            p[OMEGA] * t)
        p[COUNT] += 1.0

    @cfunc(numbalsoda.lsoda_sig)
    def wall(t, u, e, p_):
        # -1 at the start: a restart from the wall (event value 0) must not be missed by
        # numbalsoda's sign-change test, nor re-detect its own impact
        p = carray(p_, (N_PARAMS,))
        e[0] = u[0] - p[DELTA] if t > p[START] else -1.0

    rhs_ptr, wall_ptr = rhs.address, wall.address

    @njit(cache=False)
    def tiny(t0, t1):
        return t1 - t0 <= 1e-9 * max(1.0, abs(t0))

    @njit(cache=False)
    def taylor(y, t0, t1, p):
        """DOP853 refuses intervals near rounding ("step size too small"; they arise in
        the Newton iteration and when an impact falls just before a breakpoint): one
        Taylor step, error O(dt^2) <= 1e-12 at t ~ 1e3 (in practice dt ~ 1e-13)."""
        dt = t1 - t0
        acc = (p[MU] * (1.0 - y[1] * y[1]) * y[1] - p[A] * y[0] - p[C] * y[0] ** 3
               + p[F] * math.cos(p[OMEGA] * t0))
        return np.array([y[0] + dt * y[1] + 0.5 * dt * dt * acc, y[1] + dt * acc])

    @njit(cache=False)
    def advance(y, t0, t1, p, rtol, atol, tt):
        """dop853 from (t0, y) to t1: (state, ok)."""
        if tiny(t0, t1):
            return taylor(y, t0, t1, p), True
        tt[0] = t0
        tt[1] = t1
        usol, ok = dop853(rhs_ptr, y, tt, p, rtol, atol, MAX_STEPS)
        return usol[1].copy(), ok

    @njit(cache=False)
    def locate(ta, ya, tb, yb, p, rtol, atol, tt):
        """Impact time in (ta, tb] (x(ta) <= delta < x(tb)): safeguarded Newton on
        x(t) - delta with x' = v, each iterate integrated from the last point before the
        wall. Returns (t, state, ok)."""
        delta = p[DELTA]
        tg = tb - (yb[0] - delta) / yb[1] if yb[1] > 0.0 else 0.5 * (ta + tb)
        if not (ta < tg < tb):
            tg = 0.5 * (ta + tb)
        t_best, y_best = tb, yb
        for _ in range(60):
            yg, ok = advance(ya, ta, tg, p, rtol, atol, tt)
            if not ok:
                return tg, yg, False
            g = yg[0] - delta
            if g < 0.0:
                ta, ya = tg, yg
            else:
                tb, yb = tg, yg
            t_best, y_best = tg, yg
            if abs(g) <= 1e-14 or tb - ta <= 4e-16 * max(1.0, abs(tb)):
                break
            tn = tg - g / yg[1] if yg[1] > 0.0 else 0.5 * (ta + tb)
            if not (ta < tn < tb):
                tn = 0.5 * (ta + tb)
            if tn == tg:
                break
            tg = tn
        return t_best, y_best, True

    @njit(cache=False)
    def hermite_peak(t0, y0, t1, y1):
        """Time of the largest interior maximum of the cubic Hermite interpolant of x on
        [t0, t1] and its value (t0, -inf when it has none)."""
        h = t1 - t0
        x0, x1 = y0[0], y1[0]
        d0, d1 = y0[1] * h, y1[1] * h
        # x(s) = h00 x0 + h10 d0 + h01 x1 + h11 d1, s in [0, 1]; dx/ds = qa s^2 + qb s + qc
        qa = 6.0 * x0 + 3.0 * d0 - 6.0 * x1 + 3.0 * d1
        qb = -6.0 * x0 - 4.0 * d0 + 6.0 * x1 - 2.0 * d1
        qc = d0
        best_t, best_x = t0, -np.inf
        roots = np.empty(2)
        nr = 0
        if abs(qa) < 1e-300:
            if qb != 0.0:
                roots[0] = -qc / qb
                nr = 1
        else:
            disc = qb * qb - 4.0 * qa * qc
            if disc >= 0.0:
                sq = math.sqrt(disc)
                roots[0] = (-qb - sq) / (2.0 * qa)
                roots[1] = (-qb + sq) / (2.0 * qa)
                nr = 2
        for k in range(nr):
            s = roots[k]
            if 0.0 < s < 1.0 and 2.0 * qa * s + qb < 0.0:  # a maximum
                s2, s3 = s * s, s * s * s
                xs = ((2 * s3 - 3 * s2 + 1) * x0 + (s3 - 2 * s2 + s) * d0
                      + (-2 * s3 + 3 * s2) * x1 + (s3 - s2) * d1)
                if xs > best_x:
                    best_t, best_x = t0 + s * h, xs
        return best_t, best_x

    @njit(cache=False)
    def kick_and_record(k, t, y, p, is_kick, kick_dv, out_idx, x_out, v_out, impacts, n_imp,
                        sticking):
        """At breakpoint k: the kick (and the impact it may cause), then the output.
        Returns (n_impacts, sticking)."""
        if is_kick[k]:
            y[1] += kick_dv[k]
            if y[0] >= p[DELTA] and y[1] > 0.0:
                if n_imp < len(impacts):
                    impacts[n_imp] = t
                n_imp += 1
                y[1] = -p[ETA] * y[1]
                sticking = False
        if out_idx[k] >= 0:
            x_out[out_idx[k]] = y[0]
            v_out[out_idx[k]] = y[1]
        return n_imp, sticking

    @njit(cache=False)
    def bounce(t, v_minus, p):
        """The impact law with ours' chatter rule: an impact slower than the chatter
        velocity with the force at rest pushing into the wall starts sticking.
        Returns (state after, sticking)."""
        if p[ETA] < 1.0 and v_minus < p[CHATTER] and force_at_wall(t, p) > 0.0:
            return np.array([p[DELTA], 0.0]), True
        return np.array([p[DELTA], -p[ETA] * v_minus]), False

    @njit(cache=False)
    def dop853_loop(y0, p, bounds, is_kick, kick_dv, out_idx, window, rtol, atol,
                    x_out, v_out, impacts):
        """Event loop around numbalsoda.dop853; returns (n_impacts, ok). Impact times are
        written to ``impacts`` while it has room."""
        delta = p[DELTA]
        tt = np.empty(2)
        y = y0.copy()
        n_imp = 0
        sticking = False
        nb = len(bounds)
        for k in range(nb):
            t = bounds[k]
            n_imp, sticking = kick_and_record(k, t, y, p, is_kick, kick_dv, out_idx, x_out,
                                              v_out, impacts, n_imp, sticking)
            if k == nb - 1:
                break
            t1 = bounds[k + 1]
            while t < t1:
                if sticking:
                    tr = release(t, p)
                    if tr >= t1:
                        t = t1
                        break
                    t = tr
                    sticking = False
                    continue
                tw = min(t + window, t1)
                yw, ok = advance(y, t, tw, p, rtol, atol, tt)
                if not ok:
                    return n_imp, False
                hit = yw[0] > delta
                tb, yb = tw, yw
                if not hit:
                    # grazing: an excursion above the wall inside the window?
                    tm, xm = hermite_peak(t, y, tw, yw)
                    if xm > delta - 1e-9:
                        ym, ok = advance(y, t, tm, p, rtol, atol, tt)
                        if not ok:
                            return n_imp, False
                        if ym[0] > delta:
                            hit = True
                            tb, yb = tm, ym
                if not hit:
                    t, y = tw, yw
                    continue
                ti, yi, ok = locate(t, y, tb, yb, p, rtol, atol, tt)
                if not ok:
                    return n_imp, False
                if n_imp < len(impacts):
                    impacts[n_imp] = ti
                n_imp += 1
                if n_imp > 10_000_000:
                    return n_imp, False
                t = ti
                y, sticking = bounce(ti, yi[1], p)
        return n_imp, True

    @njit(cache=False)
    def ivp_loop(y0, p, bounds, is_kick, kick_dv, out_idx, rtol, atol, x_out, v_out,
                 impacts):
        """Event loop around numbalsoda.solve_ivp (DOP853 + Brent events); returns
        (n_impacts, ok, rhs evaluations)."""
        delta = p[DELTA]
        y = y0.copy()
        n_imp = 0
        nfev = 0
        sticking = False
        nb = len(bounds)
        span = np.empty(2)
        teval = np.empty(0)
        pp = p.ctypes.data
        for k in range(nb):
            t = bounds[k]
            n_imp, sticking = kick_and_record(k, t, y, p, is_kick, kick_dv, out_idx, x_out,
                                              v_out, impacts, n_imp, sticking)
            if k == nb - 1:
                break
            t1 = bounds[k + 1]
            while t < t1:
                if sticking:
                    tr = release(t, p)
                    if tr >= t1:
                        t = t1
                        break
                    t = tr
                    sticking = False
                    continue
                if tiny(t, t1):
                    y = taylor(y, t, t1, p)
                    break
                span[0] = t
                span[1] = t1
                p[START] = t
                sol = nb_solve_ivp(rhs_ptr, span, y, teval, "DOP853", 1, wall_ptr, pp,
                                   0.0, 0.0, rtol, atol)
                nfev += sol.nfev
                if not sol.success:
                    return n_imp, False, nfev
                if not sol.event_found:
                    y = sol.y[-1].copy()
                    t = t1
                    continue
                te, ye = sol.t_event, sol.y_event
                if ye[1] <= 0.0:  # a downward crossing: the wall was passed unseen
                    return n_imp, False, nfev
                # polish Brent's 1e-8 event time with one Newton (Taylor) step
                acc = (p[MU] * (1.0 - ye[1] * ye[1]) * ye[1] - p[A] * ye[0]
                       - p[C] * ye[0] ** 3 + p[F] * math.cos(p[OMEGA] * te))
                dt = -(ye[0] - delta) / ye[1]
                te = te + dt
                ve = ye[1] + acc * dt
                if n_imp < len(impacts):
                    impacts[n_imp] = te
                n_imp += 1
                if n_imp > 10_000_000:
                    return n_imp, False, nfev
                t = te
                y, sticking = bounce(te, ve, p)
        return n_imp, True, nfev

    @njit(cache=False, parallel=True)
    def dop853_ensemble(y0, p, mus, bounds, is_kick, kick_dv, out_idx, window, rtol, atol,
                        x_out, v_out, n_impacts, nfev, ok):
        dummy = np.empty(0)
        for m in prange(len(mus)):
            q = p.copy()
            q[MU] = mus[m]
            q[COUNT] = 0.0
            n_impacts[m], ok[m] = dop853_loop(y0, q, bounds, is_kick, kick_dv, out_idx,
                                              window, rtol, atol, x_out[m], v_out[m], dummy)
            nfev[m] = q[COUNT]

    @njit(cache=False, parallel=True)
    def ivp_ensemble(y0, p, mus, bounds, is_kick, kick_dv, out_idx, rtol, atol, x_out,
                     v_out, n_impacts, nfev, ok):
        dummy = np.empty(0)
        for m in prange(len(mus)):
            q = p.copy()
            q[MU] = mus[m]
            n_impacts[m], ok[m], nfev[m] = ivp_loop(y0, q, bounds, is_kick, kick_dv,
                                                    out_idx, rtol, atol, x_out[m],
                                                    v_out[m], dummy)

    _NUMBALSODA.update(dop853_loop=dop853_loop, ivp_loop=ivp_loop,
                       dop853_ensemble=dop853_ensemble, ivp_ensemble=ivp_ensemble,
                       numba=numba)
    return _NUMBALSODA


def numbalsoda_dmr(osc, periods: int, rtol: float, atol: float, method: str = "dop853",
                   chatter_velocity: float = 1e-6):
    """One trajectory: (t_out, x, v, impact_times, rhs_evaluations)."""
    nb = build_numbalsoda()
    t_out, bounds, is_kick, kick_dv, out_idx = schedule(osc, periods)
    p = parameters(osc, chatter_velocity=chatter_velocity)
    y0 = np.array([osc.x0, osc.v0])
    x, v = np.empty(len(t_out)), np.empty(len(t_out))
    impacts = np.empty(4 * periods + 64)
    if method == "dop853":
        window = WINDOW_FRACTION * TWO_PI / osc.omega
        n, ok = nb["dop853_loop"](y0, p, bounds, is_kick, kick_dv, out_idx, window, rtol,
                                  atol, x, v, impacts)
        nfev = int(p[COUNT])
    else:
        n, ok, nfev = nb["ivp_loop"](y0, p, bounds, is_kick, kick_dv, out_idx, rtol, atol,
                                     x, v, impacts)
    if not ok or n > len(impacts):
        raise RuntimeError(f"numbalsoda {method} loop failed ({n} impacts)")
    return t_out, x, v, impacts[:n].copy(), nfev


def numbalsoda_ensemble(osc, mus, periods: int, rtol: float, atol: float,
                        method: str = "dop853", chatter_velocity: float = 1e-6):
    """Stroboscopic paths of every sample mu (numba prange over samples):
    (x (M, P+1), v, n_impacts (M,), rhs evaluations)."""
    nb = build_numbalsoda()
    _, bounds, is_kick, kick_dv, out_idx = schedule(osc, periods)
    p = parameters(osc, chatter_velocity=chatter_velocity)
    y0 = np.array([osc.x0, osc.v0])
    mus = np.ascontiguousarray(mus, dtype=float)
    M = len(mus)
    x, v = np.empty((M, periods + 1)), np.empty((M, periods + 1))
    n_imp, nfev = np.zeros(M, np.int64), np.zeros(M, np.int64)
    ok = np.zeros(M, np.bool_)
    if method == "dop853":
        window = WINDOW_FRACTION * TWO_PI / osc.omega
        nb["dop853_ensemble"](y0, p, mus, bounds, is_kick, kick_dv, out_idx, window, rtol,
                              atol, x, v, n_imp, nfev, ok)
    else:
        nb["ivp_ensemble"](y0, p, mus, bounds, is_kick, kick_dv, out_idx, rtol, atol, x, v,
                           n_imp, nfev, ok)
    if not ok.all():
        raise RuntimeError(f"numbalsoda {method} ensemble: {int((~ok).sum())} samples failed")
    return x, v, n_imp, int(nfev.sum())


# ============================================================================ jax / diffrax

# Capacities of the jitted loops' buffers: fixed, so that every size of run reuses one
# compiled program (shapes are part of a jax compilation).
DMR_CAPACITY = dict(bounds=2048, outputs=2048, impacts=2048)
MC_CAPACITY = dict(bounds=512, outputs=256, impacts=1)
# samples per jitted vmap call: 4000 = 8 chunks, 4 per device; smaller ensembles are padded
LANES = 500
_DIFFRAX: dict = {}


def import_jax():
    """Import jax with float64 and 2 host devices (the flag must precede the import)."""
    if "jax" not in sys.modules:
        flag = "--xla_force_host_platform_device_count=2"
        flags = os.environ.get("XLA_FLAGS", "")
        if flag.split("=")[0] not in flags:
            os.environ["XLA_FLAGS"] = (flags + " " + flag).strip()
    import jax

    jax.config.update("jax_enable_x64", True)
    return jax


def stages(solver_name: str) -> int:
    """RHS evaluations per diffrax step (FSAL: stages - 1)."""
    return {"Dopri5": 6, "Tsit5": 6, "Dopri8": 13}[solver_name]


# optimistix root finder of the event: (name, rtol, atol). Newton (the documented choice)
# stops with nonlinear_max_steps_reached on some impacts (e.g. mu = 0.8038669192114117,
# rtol 1e-8, the impact at t = 175.749; any Newton/Chord tolerance); Bisection on the
# step's bracket is robust. It stops when the bracket is below atol + rtol |t| and
# |x - delta| < atol.
ROOT_FINDER = ("Bisection", 1e-14, 1e-12)


def root_finder(optx):
    name, rtol, atol = ROOT_FINDER
    if name == "Bisection":
        # under vmap diffrax root-finds every lane when one has an event, the others on
        # (t_next - t), decreasing with its root at the bracket's end: "detect" would
        # refuse it; expand_if_necessary makes such brackets legal
        return optx.Bisection(rtol=rtol, atol=atol, flip="detect", expand_if_necessary=True)
    return getattr(optx, name)(rtol=rtol, atol=atol)


def build_diffrax(solver_name: str, rtol: float, atol: float, capacity: dict):
    key = (solver_name, rtol, atol, tuple(sorted(capacity.items())), ROOT_FINDER)
    if key in _DIFFRAX:
        return _DIFFRAX[key]
    jax = import_jax()
    import diffrax
    import jax.numpy as jnp
    import optimistix as optx

    solver = getattr(diffrax, solver_name)()
    cap_o, cap_i = capacity["outputs"], capacity["impacts"]

    def field(t, y, p):
        x, v = y[0], y[1]
        return jnp.stack([v, p[MU] * (1.0 - v * v) * v - p[A] * x - p[C] * x * x * x
                          + p[F] * jnp.cos(p[OMEGA] * t)])

    term = diffrax.ODETerm(field)
    event = diffrax.Event(lambda t, y, args, **kwargs: y[0] - args[DELTA],
                          root_finder=root_finder(optx),
                          direction=True)
    controller = diffrax.PIDController(rtol=rtol, atol=atol)
    saveat = diffrax.SaveAt(t1=True)

    EVENT = int(diffrax.RESULTS.event_occurred._value)
    SUCCESS = int(diffrax.RESULTS.successful._value)

    def force_at_wall(t, p):
        d = p[DELTA]
        return -p[A] * d - p[C] * d * d * d + p[F] * jnp.cos(p[OMEGA] * t)

    def release(t, p):  # release_time in jax
        d = p[DELTA]
        K = (p[A] * d + p[C] * d * d * d) / p[F]
        alpha = jnp.arccos(jnp.minimum(K, 1.0))
        theta = jnp.fmod(p[OMEGA] * t, 2.0 * jnp.pi)
        theta = jnp.where(theta > jnp.pi, theta - 2.0 * jnp.pi, theta)
        dt = (alpha - theta) / p[OMEGA]
        dt = jnp.where(dt <= 0.0, dt + 2.0 * jnp.pi / p[OMEGA], dt)
        return jnp.where(K <= -1.0, jnp.inf, t + dt)

    def trajectory(p, y0, bounds, is_kick, kick_dv, out_idx, n_bounds):
        delta, eta = p[DELTA], p[ETA]
        zero = jnp.asarray(0, dtype=jnp.int64)
        at_rest = jnp.stack([delta, 0.0 * delta])

        def arrive(i, t, y, xo, vo, imp, n_imp):
            """Breakpoint i: the kick (and the impact it may cause), then the output."""
            v = y[1] + kick_dv[i]
            hit = is_kick[i] & (y[0] >= delta) & (v > 0.0)
            imp = imp.at[jnp.where(hit, n_imp, cap_i)].set(t, mode="drop")
            n_imp = n_imp + hit.astype(n_imp.dtype)
            v = jnp.where(hit, -eta * v, v)
            k = out_idx[i]
            xo = xo.at[jnp.where(k >= 0, k, cap_o)].set(y[0], mode="drop")
            vo = vo.at[jnp.where(k >= 0, k, cap_o)].set(v, mode="drop")
            return jnp.stack([y[0], v]), xo, vo, imp, n_imp, hit

        xo = jnp.full(cap_o, jnp.nan)
        vo = jnp.full(cap_o, jnp.nan)
        imp = jnp.full(cap_i, jnp.nan)
        y, xo, vo, imp, n_imp, _ = arrive(0, bounds[0], y0, xo, vo, imp, zero)
        state = (zero, bounds[0], y, xo, vo, imp, n_imp, zero, zero, zero, jnp.asarray(False))

        def cond(s):
            i, fail = s[0], s[9]
            return (i < n_bounds - 1) & (fail == 0)

        def body(s):
            i, t, y, xo, vo, imp, n_imp, steps, solves, _, stick = s
            t1 = bounds[i + 1]

            def solve(_):
                sol = diffrax.diffeqsolve(term, solver, t, t1, None, y, args=p,
                                          stepsize_controller=controller, event=event,
                                          saveat=saveat, max_steps=4096, throw=False)
                return (sol.ts[-1], sol.ys[-1], sol.result._value.astype(zero.dtype),
                        sol.stats["num_steps"].astype(zero.dtype))

            def skip(_):  # sticking: no integration
                return t, y, zero + SUCCESS, zero

            tf, yf, code, n_steps = jax.lax.cond(stick, skip, solve, None)
            hit = ~stick & (code == EVENT)
            good = stick | hit | (code == SUCCESS)
            # an impact: record it, restart from the wall in the same segment; ours'
            # chatter rule: too slow, with the force at rest into the wall: stick
            v_minus = yf[1]
            chatter = ((eta < 1.0) & (v_minus < p[CHATTER])
                       & (force_at_wall(tf, p) > 0.0))
            y_h = jnp.stack([delta, jnp.where(chatter, 0.0, -eta * v_minus)])
            imp_h = imp.at[jnp.where(hit, n_imp, cap_i)].set(tf, mode="drop")
            # sticking: released before the next breakpoint?
            tr = release(t, p)
            rel = stick & (tr < t1)
            # otherwise the next breakpoint is reached (in flight or at rest)
            y_a, xo_a, vo_a, imp_a, n_a, kicked = arrive(
                i + 1, t1, jnp.where(stick, at_rest, yf), xo, vo, imp, n_imp)
            stay = hit | rel
            return (jnp.where(stay, i, i + 1),
                    jnp.where(hit, tf, jnp.where(rel, tr, t1)),
                    jnp.where(hit, y_h, jnp.where(rel, at_rest, y_a)),
                    jnp.where(stay, xo, xo_a), jnp.where(stay, vo, vo_a),
                    jnp.where(hit, imp_h, jnp.where(rel, imp, imp_a)),
                    jnp.where(hit, n_imp + 1, jnp.where(rel, n_imp, n_a)),
                    steps + n_steps, solves + (~stick).astype(zero.dtype),
                    jnp.where(good, 0, 1 + code),
                    jnp.where(hit, chatter, jnp.where(rel, False, stick & ~kicked)))

        _, t, _, xo, vo, imp, n_imp, steps, solves, fail, _ = jax.lax.while_loop(
            cond, body, state)
        return xo, vo, imp, n_imp, steps, solves, fail, t

    single = jax.jit(trajectory)
    batched = jax.jit(jax.vmap(trajectory, in_axes=(0, None, None, None, None, None, None)))
    devices = jax.local_devices()
    # pmap and shard_map both fail here (optimistix/lineax closure conversion of the event
    # root find under SPMD mapping: "Closure-converted function called with different
    # dynamic arguments"), so the batch is split by hand: chunks of LANES samples (one
    # compiled shape for every ensemble size), dealt round-robin to one thread per host
    # device, each dispatching the jitted vmap on its own device (XLA releases the GIL).
    pool = ThreadPoolExecutor(len(devices))

    def ensemble(P, *rest):
        chunks = P.reshape(-1, LANES, P.shape[-1])

        def worker(k):
            done = []
            for c in range(k, len(chunks), len(devices)):
                args = jax.device_put((chunks[c], *rest), devices[k])
                done.append((c, jax.device_get(batched(*args))))
            return done

        parts = sorted((r for rs in pool.map(worker, range(len(devices))) for r in rs),
                       key=lambda r: r[0])
        return tuple(np.concatenate([np.asarray(r[1][j]) for r in parts])
                     for j in range(len(parts[0][1])))

    _DIFFRAX[key] = dict(single=single, ensemble=ensemble, devices=len(devices), jax=jax,
                         batched=batched)
    return _DIFFRAX[key]


def result_name(code: int) -> str:
    """The diffrax RESULTS message of a loop's failure code (code = RESULTS value + 1)."""
    import diffrax

    for name, item in diffrax.RESULTS._name_to_item.items():
        if item._value == code - 1:
            return name
    return f"result {code - 1}"


def _padded_schedule(osc, periods, capacity):
    t_out, bounds, is_kick, kick_dv, out_idx = schedule(osc, periods)
    nb = len(bounds)
    if nb > capacity["bounds"] or len(t_out) > capacity["outputs"]:
        raise ValueError(f"{periods} periods exceed the diffrax loop's capacity {capacity}")
    pad = capacity["bounds"] - nb
    bounds = np.concatenate([bounds, np.full(pad, bounds[-1])])
    is_kick = np.concatenate([is_kick, np.zeros(pad, bool)])
    kick_dv = np.concatenate([kick_dv, np.zeros(pad)])
    out_idx = np.concatenate([out_idx, np.full(pad, -1, np.int64)])
    return t_out, (bounds, is_kick, kick_dv, out_idx, np.int64(nb))


def diffrax_dmr(osc, periods: int, rtol: float, atol: float, solver: str = "Dopri5"):
    """One trajectory: (t_out, x, v, impact_times, rhs_evaluations (from the step count))."""
    d = build_diffrax(solver, rtol, atol, DMR_CAPACITY)
    t_out, sched = _padded_schedule(osc, periods, DMR_CAPACITY)
    y0 = np.array([osc.x0, osc.v0])
    xo, vo, imp, n_imp, steps, solves, fail, t = d["single"](parameters(osc), y0, *sched)
    xo, vo, imp = (np.asarray(a) for a in (xo, vo, imp))  # blocks until done
    n_imp = int(n_imp)
    if int(fail) or n_imp > DMR_CAPACITY["impacts"]:
        raise RuntimeError(f"diffrax {solver} loop failed at t = {float(t)} ({n_imp} impacts, "
                           f"{result_name(int(fail))})")
    n = len(t_out)
    nfev = int(steps) * stages(solver) + 2 * int(solves)
    return t_out, xo[:n], vo[:n], imp[:n_imp], nfev


def diffrax_ensemble(osc, mus, periods: int, rtol: float, atol: float,
                     solver: str = "Dopri5"):
    """vmap over samples (split over the host devices): (x, v, n_impacts, rhs evaluations)."""
    d = build_diffrax(solver, rtol, atol, MC_CAPACITY)
    t_out, sched = _padded_schedule(osc, periods, MC_CAPACITY)
    y0 = np.array([osc.x0, osc.v0])
    mus = np.asarray(mus, dtype=float)
    M = len(mus)
    P = np.tile(parameters(osc), (M, 1))
    P[:, MU] = mus
    pad = -M % LANES  # whole chunks: the padding lanes repeat the last sample
    P = np.concatenate([P, np.tile(P[-1:], (pad, 1))])
    xo, vo, _, n_imp, steps, solves, fail, t = d["ensemble"](P, y0, *sched)
    n = len(t_out)
    xo = np.asarray(xo).reshape(-1, xo.shape[-1])[:M, :n]
    vo = np.asarray(vo).reshape(-1, vo.shape[-1])[:M, :n]
    n_imp = np.asarray(n_imp).reshape(-1)[:M]
    fail = np.asarray(fail).reshape(-1)[:M]
    if fail.any():
        m = int(np.flatnonzero(fail)[0])
        t_fail = float(np.asarray(t).reshape(-1)[m])
        raise RuntimeError(f"diffrax {solver} ensemble: {int((fail > 0).sum())} samples "
                           f"failed, the first (mu = {mus[m]!r}) at t = {t_fail} "
                           f"({result_name(int(fail[m]))})")
    nfev = (np.asarray(steps).reshape(-1)[:M].sum() * stages(solver)
            + 2 * np.asarray(solves).reshape(-1)[:M].sum())
    return xo, vo, n_imp, int(nfev)


def diffrax_gpu_ensemble(osc, mus, periods: int, rtol: float, atol: float, lanes: int,
                         solver: str = "Dopri5"):
    """The same loop's ``vmap`` on the first GPU, ``lanes`` samples a launch, each chunk
    reduced there: only the moments cross back, as ours (``opa._run.gpu_moments``).
    Returns (mean x, var x (ddof 1), mean v, var v at the outputs, impacts in all, rhs
    evaluations)."""
    d = build_diffrax(solver, rtol, atol, MC_CAPACITY)
    jax = d["jax"]
    gpu = jax.devices("gpu")[0]
    t_out, sched = _padded_schedule(osc, periods, MC_CAPACITY)
    n = len(t_out)
    key = ("gpu", solver, rtol, atol, n)
    if key not in _DIFFRAX:
        def reduced(P, *rest):
            xo, vo, _, n_imp, steps, solves, fail, _ = d["batched"](P, *rest)
            xo, vo = xo[:, :n], vo[:, :n]
            return (xo.sum(0), (xo * xo).sum(0), vo.sum(0), (vo * vo).sum(0), n_imp.sum(),
                    steps.sum(), solves.sum(), (fail > 0).sum())
        _DIFFRAX[key] = jax.jit(reduced)
    reduced = _DIFFRAX[key]
    mus = np.asarray(mus, dtype=float)
    M = len(mus)
    if M % lanes:
        raise ValueError(f"{M} samples are not whole chunks of {lanes} lanes")
    P = np.tile(parameters(osc), (M, 1))
    P[:, MU] = mus
    y0 = np.array([osc.x0, osc.v0])
    rest = jax.device_put((y0, *sched), gpu)
    parts = [reduced(jax.device_put(P[c:c + lanes], gpu), *rest) for c in range(0, M, lanes)]
    sx, sxx, sv, svv, imp, steps, solves, failed = (
        sum(np.asarray(jax.device_get(p[j])) for p in parts) for j in range(8))
    if int(failed):
        raise RuntimeError(f"diffrax {solver} GPU ensemble: {int(failed)} samples failed")
    mx, mv = sx / M, sv / M
    vx, vv = (sxx - M * mx * mx) / (M - 1), (svv - M * mv * mv) / (M - 1)
    nfev = int(steps) * stages(solver) + 2 * int(solves)
    return mx, vx, mv, vv, int(imp), nfev


# ============================================================================ scipy OPA


def opa_quadrature(order: int):
    """Gauss rule of the semicircle law with Q = 2N + 2 nodes and the orthonormal
    Chebyshev-U basis at the nodes, shape (N + 1, Q)."""
    Q = 2 * order + 2
    k = np.arange(1, Q + 1)
    xi = np.cos(k * math.pi / (Q + 1))
    w = 2.0 / (Q + 1) * np.sin(k * math.pi / (Q + 1)) ** 2
    U = np.empty((order + 1, Q))
    U[0] = 1.0
    if order >= 1:
        U[1] = 2.0 * xi
    for i in range(1, order):
        U[i + 1] = 2.0 * xi * U[i] - U[i - 1]
    return xi, w, U


def scipy_opa(osc, sigma: float, order: int, periods: int, rtol: float, atol: float,
              method: str = "DOP853"):
    """The Galerkin OPA system (uncertain mu, impacts on x_0 with the ``mean`` law) by
    ``solve_ivp`` in the event loop of ``bench_dmr.scipy_dmr``.
    Returns (t, x_coef (N+1, T), v_coef (N+1, T), impact_times, rhs_evaluations)."""
    from scipy.integrate import solve_ivp

    n = order + 1
    xi, w, U = opa_quadrature(order)
    mu_k = osc.mu + sigma * xi
    WU = U * w  # (N+1, Q): projection
    a, c, f, omega, delta, eta = osc.a, osc.c, osc.f, osc.omega, osc.delta, osc.eta

    def rhs(t, y):
        xk = y[:n] @ U
        vk = y[n:] @ U
        dv = WU @ (mu_k * (1.0 - vk * vk) * vk - a * xk - c * xk * xk * xk)
        dv[0] += f * math.cos(omega * t)
        return np.concatenate((y[n:], dv))

    t_out, bounds, is_kick, kick_dv, out_idx = schedule(osc, periods)
    out = np.empty((len(t_out), 2 * n))
    impacts = []
    nfev = 0
    y = np.zeros(2 * n)
    y[0], y[n] = osc.x0, osc.v0
    for k, t0 in enumerate(bounds):
        if is_kick[k]:
            y[n] += kick_dv[k]
            if y[0] >= delta and y[n] > 0.0:
                impacts.append(t0)
                y[n] = -eta * y[n]
        if out_idx[k] >= 0:
            out[out_idx[k]] = y
        if k == len(bounds) - 1:
            break
        t1 = bounds[k + 1]
        while True:
            start = t0

            def hit_wall(t, s, start=start):
                return s[0] - delta if t > start else -1.0

            hit_wall.terminal, hit_wall.direction = True, 1.0
            sol = solve_ivp(rhs, (t0, t1), y, method=method, rtol=rtol, atol=atol,
                            events=hit_wall)
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed at t = {sol.t[-1]}: {sol.message}")
            nfev += sol.nfev
            if sol.status == 0:
                y = sol.y[:, -1].copy()
                break
            t0 = sol.t_events[0][0]
            impacts.append(t0)
            y = sol.y_events[0][0].copy()
            y[0] = delta
            y[n] = -eta * y[n]
    return t_out, out[:, :n].T, out[:, n:].T, np.array(impacts), nfev
