"""Compiled event-driven integrator for the vibro-impact oscillator and its OPA system.

This is the one kernel chain of the project: the right-hand side, the Dormand-Prince
5(4) step with its quartic dense output, event location, the impact/impulse/sticking
driver and the Monte Carlo sample loop all live here, so numba's on-disk cache stays
consistent (it does not track edits to jitted functions in other modules).

State layout, for ``ncoef = N + 1`` polynomial coefficients::

    y = [x_0, ..., x_N, v_0, ..., v_N]

The first component ``x_0`` (the mean, eq. (20)) meets the wall at ``x_0 = delta``.
The deterministic model (eq. (29), the DMR) is the case ``N = 0`` with a one-node
quadrature at ``xi = 0``; a Monte Carlo sample is the DMR with its own parameter value.

Right-hand side (Galerkin projection, eqs. (9)-(13), pseudo-spectral form)::

    x_i' = v_i
    v_i' = sum_k w_k U_i(xi_k) g(x(xi_k), v(xi_k); p(xi_k)) + [i == 0] (f cos(omega t) + P(t))
    g(x, v; p) = mu (1 - v^2) v - a x - c x^3

which is exact for Q >= 2N + 1 Gauss nodes of the semicircle density. The ``paper``
truncation (eq. (27)) adds back ``sigma/2 * Y_{N+1}`` (or ``X_{N+1}`` for uncertain c) to
the last equation, i.e. drops that term from the exact projection.

Kernels are pure functions of arrays and floats and return status codes; the Python
layer (``opa._simulate``) validates input and turns codes into messages.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

# ---------------------------------------------------------------------------
# Indices into the float parameter vector ``p`` and the integer config ``cfg``.
P_MU, P_A, P_C, P_F, P_OMEGA, P_ETA, P_DELTA = 0, 1, 2, 3, 4, 5, 6
P_F0, P_A1, P_OMEGA1, P_N, P_TAU, P_SIGMA = 7, 8, 9, 10, 11, 12
P_CHATTER_V, P_HMAX = 13, 14
N_PARAMS = 15

C_NCOEF, C_UNCERTAIN, C_IMPULSE, C_AT_ZERO, C_TRUNC, C_LAW, C_MAXSTEPS = 0, 1, 2, 3, 4, 5, 6
N_CFG = 7

UNCERTAIN_MU, UNCERTAIN_A, UNCERTAIN_C = 0, 1, 2
IMPULSE_DIRAC, IMPULSE_PULSE = 0, 1
TRUNC_GALERKIN, TRUNC_PAPER = 0, 1
LAW_MEAN, LAW_ENSEMBLE, LAW_SALTATION = 0, 1, 2

# Escape bound: a state component |x_i| or |v_i| at or beyond
#
#     ESCAPE_FACTOR * (1 + max_j |y_j(t0)| + |delta|
#                      + (|f| + |F0| (1 + |a1|)) (1 + 1/omega + 1/omega^2 + 1/|a|))
#
# ends the run as escaped (``escape_bound``). The bracket is the problem's own scale: the
# start, the wall, and the largest force (harmonic amplitude plus the largest impulse or
# pulse height) together with the velocity (force / omega) and displacement
# (force / omega^2) it drives over a forcing period, and the static deflection force / |a|
# of a weak spring (a = 3e-5 holds |x| near 7e3 legitimately; with a = 0 there is no
# scale and the bound is infinite: only a non-finite state ends the run). The paper's motions stay more than
# 3000 times inside the bound (|x|, |v| < 11 over 300 periods of every preset, against
# bounds of 4e3 to 3.5e4; a Dirac kick F0 moves v by at most F0 (1 + |a1|)). The factor
# is 1e3, not larger, because a runaway with the van der Pol term is stiff: with c < 0
# the damping mu v^3 holds |v| near (|c| x^3 / mu)^(1/3) ~ |x| and the stable step falls
# like 1/x^2, so the steps needed to reach |x| = X grow like X^2 (about 6e6 steps to
# |x| = 3e3, 1e15 to the former fixed bound 1e8). With 1e3 such a DMR run stops in about
# a second (the OPA system of order 4 in about 15 s) instead of running to max_steps.
ESCAPE_FACTOR = 1e3

# Status codes returned by ``integrate``.
OK, MAX_STEPS, STEP_COLLAPSE, DIVERGED, ESCAPED, BAD_TIME, SKIPPED = 0, 1, 2, 3, 4, 5, 6
STATUS_MESSAGES = {
    OK: "ok",
    MAX_STEPS: "the maximum number of steps was reached",
    STEP_COLLAPSE: "the step size collapsed below round-off",
    DIVERGED: ("the trajectory diverged: the state became non-finite (NaN or inf), the "
               "vector field overflowing even at the smallest step or a jump (impact, "
               "impulse, release) giving a non-finite state"),
    ESCAPED: ("the trajectory diverged: the state escaped (|x| or |x'| beyond the escape "
              "bound 1000 (1 + max|y(t0)| + |delta| + (|f| + |F0| (1 + |a1|)) (1 + 1/omega "
              "+ 1/omega^2 + 1/|a|)))"),
    SKIPPED: "not integrated: another sample of the ensemble failed first",
    BAD_TIME: ("a time is not finite (NaN or inf), or too large for the impulse times to "
               "be resolved"),
}

# Kinds in the event log.
EV_IMPACT, EV_GRAZE, EV_STICK, EV_RELEASE = 0, 1, 2, 3

GRAZE_VELOCITY = 1e-6  # pre-impact velocity below which an impact is logged as a graze

# ---------------------------------------------------------------------------
# Dormand-Prince 5(4) tableau with Shampine's quartic continuous extension.
DP_C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0])
DP_A = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [1 / 5, 0.0, 0.0, 0.0, 0.0, 0.0],
        [3 / 40, 9 / 40, 0.0, 0.0, 0.0, 0.0],
        [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0, 0.0],
        [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0, 0.0],
        [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0.0],
    ]
)
DP_B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0])
# Error weights: 5th-order minus embedded 4th-order solution, per stage (7 with FSAL).
DP_E = np.array(
    [71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40]
)
# Dense output: y(t + theta h) = y + h * sum_s K_s * sum_j DP_P[s, j] theta^(j+1)
DP_P = np.array(
    [
        [1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799],
        [0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072],
        [0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632],
        [0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
        [0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423],
    ]
)
ERROR_EXPONENT = -1.0 / 5.0
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0


# ---------------------------------------------------------------------------
# Model
@njit(cache=True)
def impulse_strength(t, p):
    """Impulse magnitude F0 (1 + a1 sin(omega1 t / n)) at an impulse time t."""
    return p[P_F0] * (1.0 + p[P_A1] * np.sin(p[P_OMEGA1] * t / p[P_N]))


@njit(cache=True, inline="always")
def rhs(t, y, p, cfg, nodes, weights, U, pulse, sticking, out, xk, vk):
    """Right-hand side of the equivalent system (eqs. (24)-(27)); writes into ``out``.

    ``pulse`` is the current rectangular-pulse force (0 for Dirac impulses or between
    pulses). With ``sticking`` the mean coordinate is held at rest at the wall.
    Returns the unconstrained acceleration of the mean coordinate (the release function).
    """
    if cfg[C_NCOEF] == 1 and nodes.shape[0] == 1 and nodes[0] == 0.0:
        return rhs_deterministic(t, y, p, pulse, sticking, out)
    return rhs_galerkin(t, y, p, cfg, nodes, weights, U, pulse, sticking, out, xk, vk)


@njit(cache=True, inline="always")
def _f2(t, x, v, p, pulse, sticking):
    """Deterministic right-hand side on scalars: (x', v'), eq. (29)."""
    if sticking:
        return 0.0, 0.0
    return v, (p[P_MU] * (1.0 - v * v) * v - p[P_A] * x - p[P_C] * x * x * x
               + p[P_F] * np.cos(p[P_OMEGA] * t) + pulse)


@njit(cache=True, inline="always")
def rhs_deterministic(t, y, p, pulse, sticking, out):
    """The DMR (and one Monte Carlo sample): no quadrature needed."""
    dx, dv = _f2(t, y[0], y[1], p, pulse, False)
    out[0] = 0.0 if sticking else dx
    out[1] = 0.0 if sticking else dv
    return dv


@njit(cache=True)
def rhs_galerkin(t, y, p, cfg, nodes, weights, U, pulse, sticking, out, xk, vk):
    """Galerkin right-hand side for any N: evaluate x, v at the Q Gauss nodes, apply the
    sampled system's force there, project back on U_0..U_N (exact for Q >= 2N + 1)."""
    ncoef = cfg[C_NCOEF]
    q = nodes.shape[0]
    sigma = p[P_SIGMA]
    unc = cfg[C_UNCERTAIN]
    for k in range(q):
        xs = 0.0
        vs = 0.0
        for i in range(ncoef):
            xs += y[i] * U[k, i]
            vs += y[ncoef + i] * U[k, i]
        xk[k] = xs
        vk[k] = vs
    mu = p[P_MU]
    a = p[P_A]
    c = p[P_C]
    # Project the deviation g_k - g_0 from the force at the mean state; the constant g_0
    # goes to U_0 alone. Mathematically the same projection, but with sigma = 0 and zero
    # higher coefficients every g_k equals g_0 bit for bit, so the higher modes stay
    # exactly zero and EMR_0 is the DMR (sum_k w_k U_i(xi_k) is only ~1e-17 for i >= 1,
    # which the van der Pol term would otherwise amplify over long runs).
    x0 = y[0]
    v0 = y[ncoef]
    g0 = mu * (1.0 - v0 * v0) * v0 - a * x0 - c * x0 * x0 * x0
    for i in range(ncoef):
        out[i] = y[ncoef + i]
        out[ncoef + i] = 0.0
    out[ncoef] = g0
    for k in range(q):
        mu_k = mu
        a_k = a
        c_k = c
        if unc == UNCERTAIN_MU:
            mu_k = mu + sigma * nodes[k]
        elif unc == UNCERTAIN_A:
            a_k = a + sigma * nodes[k]
        else:
            c_k = c + sigma * nodes[k]
        x = xk[k]
        v = vk[k]
        g = weights[k] * (mu_k * (1.0 - v * v) * v - a_k * x - c_k * x * x * x - g0)
        if g == 0.0:
            continue
        for i in range(ncoef):
            out[ncoef + i] += g * U[k, i]
    if cfg[C_TRUNC] == TRUNC_PAPER and sigma != 0.0:
        # eq. (27) drops the xi * cubic term's projection on U_{N+1} from the last equation.
        extra = 0.0
        for k in range(q):
            if unc == UNCERTAIN_MU:
                extra += weights[k] * U[k, ncoef] * vk[k] ** 3
            elif unc == UNCERTAIN_C:
                extra += weights[k] * U[k, ncoef] * xk[k] ** 3
        out[2 * ncoef - 1] += 0.5 * sigma * extra
    out[ncoef] += p[P_F] * np.cos(p[P_OMEGA] * t) + pulse
    release = out[ncoef]
    if sticking:
        out[0] = 0.0
        out[ncoef] = 0.0
    return release


# ---------------------------------------------------------------------------
# Runge-Kutta step and dense output
@njit(cache=True)
def _rk_step_2d(t, y, h, K, y_new, p, pulse, sticking):
    """rk_step for the two-dimensional deterministic system, stages kept in registers."""
    x = y[0]
    v = y[1]
    k1x = K[0, 0]
    k1v = K[0, 1]
    k2x, k2v = _f2(t + h / 5, x + h * (k1x / 5), v + h * (k1v / 5), p, pulse, sticking)
    k3x, k3v = _f2(t + 3 * h / 10, x + h * (3 / 40 * k1x + 9 / 40 * k2x),
                   v + h * (3 / 40 * k1v + 9 / 40 * k2v), p, pulse, sticking)
    k4x, k4v = _f2(t + 4 * h / 5, x + h * (44 / 45 * k1x - 56 / 15 * k2x + 32 / 9 * k3x),
                   v + h * (44 / 45 * k1v - 56 / 15 * k2v + 32 / 9 * k3v), p, pulse, sticking)
    k5x, k5v = _f2(
        t + 8 * h / 9,
        x + h * (19372 / 6561 * k1x - 25360 / 2187 * k2x + 64448 / 6561 * k3x - 212 / 729 * k4x),
        v + h * (19372 / 6561 * k1v - 25360 / 2187 * k2v + 64448 / 6561 * k3v - 212 / 729 * k4v),
        p, pulse, sticking,
    )
    k6x, k6v = _f2(
        t + h,
        x + h * (9017 / 3168 * k1x - 355 / 33 * k2x + 46732 / 5247 * k3x + 49 / 176 * k4x
                 - 5103 / 18656 * k5x),
        v + h * (9017 / 3168 * k1v - 355 / 33 * k2v + 46732 / 5247 * k3v + 49 / 176 * k4v
                 - 5103 / 18656 * k5v),
        p, pulse, sticking,
    )
    xn = x + h * (35 / 384 * k1x + 500 / 1113 * k3x + 125 / 192 * k4x - 2187 / 6784 * k5x
                  + 11 / 84 * k6x)
    vn = v + h * (35 / 384 * k1v + 500 / 1113 * k3v + 125 / 192 * k4v - 2187 / 6784 * k5v
                  + 11 / 84 * k6v)
    k7x, k7v = _f2(t + h, xn, vn, p, pulse, sticking)
    y_new[0] = xn
    y_new[1] = vn
    K[1, 0] = k2x
    K[1, 1] = k2v
    K[2, 0] = k3x
    K[2, 1] = k3v
    K[3, 0] = k4x
    K[3, 1] = k4v
    K[4, 0] = k5x
    K[4, 1] = k5v
    K[5, 0] = k6x
    K[5, 1] = k6v
    K[6, 0] = k7x
    K[6, 1] = k7v


@njit(cache=True)
def rk_step(t, y, h, K, y_new, ytmp, p, cfg, nodes, weights, U, pulse, sticking, xk, vk):
    """One Dormand-Prince step from (t, y) of size h; K[0] must hold f(t, y).

    Fills K[1..6] (K[6] = f(t + h, y_new), first-same-as-last) and ``y_new``.
    """
    dim = y.shape[0]
    if dim == 2 and nodes.shape[0] == 1 and nodes[0] == 0.0:
        _rk_step_2d(t, y, h, K, y_new, p, pulse, sticking)
        return
    for s in range(1, 6):
        for j in range(dim):
            acc = 0.0
            for r in range(s):
                acc += DP_A[s, r] * K[r, j]
            ytmp[j] = y[j] + h * acc
        rhs(t + DP_C[s] * h, ytmp, p, cfg, nodes, weights, U, pulse, sticking, K[s], xk, vk)
    for j in range(dim):
        acc = 0.0
        for r in range(6):
            acc += DP_B[r] * K[r, j]
        y_new[j] = y[j] + h * acc
    rhs(t + h, y_new, p, cfg, nodes, weights, U, pulse, sticking, K[6], xk, vk)


@njit(cache=True)
def error_norm(y, y_new, K, h, rtol, atol):
    """Max-norm of the scaled local error estimate.

    The max-norm (rather than RMS) makes the step sequence independent of components
    that stay at zero, so EMR_0 (sigma = 0, N > 0) takes the DMR's steps exactly.
    """
    dim = y.shape[0]
    worst = 0.0
    for j in range(dim):
        e = 0.0
        for r in range(7):
            e += DP_E[r] * K[r, j]
        size = abs(y_new[j])
        scale = atol + rtol * max(abs(y[j]), size)
        r = abs(h * e) / scale
        # A non-finite trial state or stage is an infinite error, so the step is rejected
        # (written with comparisons that fail for NaN: numba's max drops a NaN argument).
        if not (r < np.inf and size < np.inf):
            return np.inf
        if r > worst:
            worst = r
    return worst


@njit(cache=True)
def dense_component(theta, y_old, h, K, j):
    """Dense output of component j at t_old + theta h (quartic in theta)."""
    acc = 0.0
    for s in range(7):
        ks = K[s, j]
        if ks != 0.0:
            acc += ks * theta * (DP_P[s, 0] + theta * (DP_P[s, 1] + theta * (DP_P[s, 2] + theta * DP_P[s, 3])))
    return y_old[j] + h * acc


@njit(cache=True)
def dense_slope(theta, h, K, j):
    """d/dtheta of the dense output of component j."""
    acc = 0.0
    for s in range(7):
        ks = K[s, j]
        if ks != 0.0:
            acc += ks * (DP_P[s, 0] + theta * (2.0 * DP_P[s, 1] + theta * (3.0 * DP_P[s, 2] + theta * 4.0 * DP_P[s, 3])))
    return h * acc


@njit(cache=True)
def dense_state(theta, y_old, h, K, out):
    for j in range(y_old.shape[0]):
        out[j] = dense_component(theta, y_old, h, K, j)


# ---------------------------------------------------------------------------
# Event location on the dense output
N_SCAN = 8


@njit(cache=True)
def _bisect_wall(lo, hi, y_old, h, K, delta):
    """Root of x_0(theta) = delta in [lo, hi] with g(lo) <= 0 < g(hi)."""
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if dense_component(mid, y_old, h, K, 0) - delta > 0.0:
            hi = mid
        else:
            lo = mid
        if (hi - lo) * abs(h) < 1e-15:
            break
    return hi


@njit(cache=True)
def _bisect_slope_max(lo, hi, h, K):
    """Location of a maximum of x_0(theta) in [lo, hi] where the slope goes + to -."""
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if dense_slope(mid, h, K, 0) > 0.0:
            lo = mid
        else:
            hi = mid
        if (hi - lo) < 1e-13:
            break
    return 0.5 * (lo + hi)


@njit(cache=True)
def find_wall_crossing(y_old, h, K, delta):
    """First theta in (0, 1] where the dense output of x_0 reaches delta, or -1.

    The caller skips steps that cannot reach the wall (a cheap bound on the quartic).
    Scans the quartic on N_SCAN sub-intervals and inspects every local maximum, so a
    step whose interpolant touches the wall and comes back is not missed.
    """
    prev_t = 0.0
    prev_g = dense_component(0.0, y_old, h, K, 0) - delta
    prev_s = dense_slope(0.0, h, K, 0)
    for m in range(1, N_SCAN + 1):
        th = m / N_SCAN
        g = dense_component(th, y_old, h, K, 0) - delta
        s = dense_slope(th, h, K, 0)
        lo_t = prev_t
        lo_g = prev_g
        hit = g > 0.0
        hi_t = th
        if not hit and prev_s > 0.0 and s < 0.0:
            tm = _bisect_slope_max(prev_t, th, h, K)
            gm = dense_component(tm, y_old, h, K, 0) - delta
            if gm > 0.0:
                hit = True
                hi_t = tm
        if hit:
            if lo_g >= 0.0:
                # Starting on the wall (just after an impact): walk towards 0 for g < 0.
                found = False
                tt = hi_t
                for _ in range(60):
                    tt *= 0.5
                    if tt <= lo_t:
                        break
                    if dense_component(tt, y_old, h, K, 0) - delta < 0.0:
                        found = True
                        break
                if not found:
                    return -1.0
                lo_t = tt
                # the crossing lies between lo_t and hi_t
                return _bisect_wall(lo_t, hi_t, y_old, h, K, delta)
            return _bisect_wall(lo_t, hi_t, y_old, h, K, delta)
        prev_t = th
        prev_g = g
        prev_s = s
    return -1.0


# ---------------------------------------------------------------------------
# Driver
@njit(cache=True)
def _next_impulse_time(j, T1):
    return j * T1


@njit(cache=True)
def _apply_impact(y, ncoef, eta, law):
    if law == LAW_ENSEMBLE:
        for i in range(ncoef):
            y[ncoef + i] = -eta * y[ncoef + i]
    else:
        y[ncoef] = -eta * y[ncoef]


@njit(cache=True)
def _apply_saltation(y, ncoef, eta, v_minus, a_minus, a_plus):
    """The saltation matrix of the impact applied to the deviation coefficients
    (i >= 1): a sample that reaches the wall later or earlier than the mean leaves it
    with x_i -> -eta x_i and v_i -> -eta v_i + (a+ + eta a-) / v- x_i, where a-, a+ are
    the mean's accelerations just before and after the impact and v- its impact speed.
    The mean's own jump (x_0 = delta, v_0 -> -eta v_0) is applied by the caller."""
    k = (a_plus + eta * a_minus) / v_minus
    for i in range(1, ncoef):
        xi_ = y[i]
        y[i] = -eta * xi_
        y[ncoef + i] = -eta * y[ncoef + i] + k * xi_


@njit(cache=True)
def escape_bound(y0, p):
    """The |x_i|, |v_i| beyond which the state counts as escaped (see ESCAPE_FACTOR)."""
    start = 0.0
    for j in range(y0.shape[0]):
        a = abs(y0[j])
        if not (a <= start):  # NaN propagates
            start = a
    w = p[P_OMEGA]
    drive = abs(p[P_F]) + abs(p[P_F0]) * (1.0 + abs(p[P_A1]))
    stiffness = abs(p[P_A])
    if stiffness == 0.0:
        return np.inf  # no linear restoring force: no scale to escape from
    return ESCAPE_FACTOR * (1.0 + start + abs(p[P_DELTA])
                            + drive * (1.0 + 1.0 / w + 1.0 / (w * w) + 1.0 / stiffness))


@njit(cache=True, inline="always")
def state_status(y, escape):
    """OK, ESCAPED (some |y_j| >= escape) or DIVERGED (some y_j NaN or inf).

    Every comparison is false for NaN, so a NaN component cannot pass."""
    status = OK
    for j in range(y.shape[0]):
        a = abs(y[j])
        if not (a < escape):
            if not (a < np.inf):
                return DIVERGED
            status = ESCAPED
    return status


@njit(cache=True)
def _fill_nan(out_y, start):
    for kk in range(start, out_y.shape[0]):
        for jj in range(out_y.shape[1]):
            out_y[kk, jj] = np.nan


@njit(cache=True)
def _log_event(log, count, t, v, kind):
    if count < log.shape[0]:
        log[count, 0] = t
        log[count, 1] = v
        log[count, 2] = kind
    return count + 1


@njit(cache=True)
def integrate(y0, t_out, p, cfg, nodes, weights, U, rtol, atol, out_y, log):
    """Integrate the impact system from t_out[0] and record the state at each t_out.

    Parameters
    ----------
    y0 : (dim,) initial state ``[x_0..x_N, v_0..v_N]`` at ``t_out[0]``.
    t_out : (n_out,) increasing output times, hit exactly as breakpoints.
    p, cfg : parameter and configuration vectors (see the ``P_*`` and ``C_*`` indices).
    nodes, weights : (Q,) semicircle Gauss rule; U : (Q, N+2) basis values at the nodes,
        ``U[k, i] = U_i(xi_k)`` (node-major, so the loops over i run over contiguous memory).
    out_y : (n_out, dim) output buffer.
    log : (cap, 3) event log rows ``(time, velocity, kind)``; kind is EV_*.
        Impacts record the pre-impact velocity of x_0.

    Returns
    -------
    status, n_events, n_impacts, n_steps, n_rhs

    The state is checked after every accepted step and every jump (impact, impulse
    kick, sticking, release): a NaN or inf component ends the run with DIVERGED, a
    component beyond ``escape_bound`` with ESCAPED; outputs not reached are NaN.
    """
    dim = y0.shape[0]
    ncoef = cfg[C_NCOEF]
    q = nodes.shape[0]
    delta = p[P_DELTA]
    eta = p[P_ETA]
    law = cfg[C_LAW]
    max_steps = cfg[C_MAXSTEPS]
    chatter_v = p[P_CHATTER_V]
    hmax = p[P_HMAX]
    pulse_model = cfg[C_IMPULSE] == IMPULSE_PULSE
    tau = p[P_TAU]
    use_impulses = p[P_F0] != 0.0
    T1 = 2.0 * np.pi / p[P_OMEGA1]
    stick_hmax = 2.0 * np.pi / p[P_OMEGA] / 32.0

    K = np.empty((7, dim))
    K2 = np.empty((7, dim))
    y = y0.copy()
    y_new = np.empty(dim)
    ytmp = np.empty(dim)
    xk = np.empty(q)
    vk = np.empty(q)

    n_out = t_out.shape[0]
    t = t_out[0]
    escape = escape_bound(y0, p)
    # first impulse at or after the start (t_0 = 0 only when the impulse at zero is on)
    j_first = np.ceil(t / T1 - 1e-12)
    status = OK
    if not (abs(t) < np.inf and abs(t_out[n_out - 1]) < np.inf):
        status = BAD_TIME  # a NaN end time would never be reached
    elif use_impulses and not (abs(j_first) < 2.0**53):
        status = BAD_TIME  # impulse index beyond exact integers: times not resolvable
    elif state_status(y, escape) != OK:
        status = DIVERGED
    if status != OK:
        _fill_nan(out_y, 0)
        return status, 0, 0, 0, 0
    j_imp = max(0 if cfg[C_AT_ZERO] != 0 else 1, int(j_first) if use_impulses else 0)
    pulse = 0.0
    pulse_end = np.inf
    sticking = False
    n_events = 0
    n_impacts = 0
    n_steps = 0
    n_rhs = 0
    t_imp = _next_impulse_time(j_imp, T1) if use_impulses else np.inf
    h = 0.0
    k_out = 0
    # Every pass of the outer loop takes a step or passes a breakpoint (output, impulse,
    # pulse end) closer than round-off; the cap only matters for the latter, e.g. impulse
    # times denser than the resolution of t, which would otherwise loop without a step.
    n_passes = 0
    while True:
        n_passes += 1
        if n_passes > 2 * (max_steps + n_out):
            status = MAX_STEPS
            break
        # ---- breakpoint handling at time t
        if use_impulses:
            if pulse_model and t >= pulse_end:
                pulse = 0.0
                pulse_end = np.inf
            while t_imp <= t:
                strength = impulse_strength(t_imp, p)
                if pulse_model:
                    pulse = strength
                    pulse_end = t_imp + tau
                else:
                    y[ncoef] += strength
                    if y[0] >= delta and y[ncoef] > 0.0:
                        v_minus = y[ncoef]
                        # a kick into the wall at a fixed time: the reset's Jacobian is
                        # diag(1, -eta), so the saltation law reflects every v_i
                        _apply_impact(y, ncoef, eta,
                                      LAW_ENSEMBLE if law == LAW_SALTATION else law)
                        n_events = _log_event(log, n_events, t, v_minus, EV_IMPACT)
                        n_impacts += 1
                    if sticking and y[ncoef] != 0.0:
                        sticking = False
                        n_events = _log_event(log, n_events, t, 0.0, EV_RELEASE)
                    status = state_status(y, escape)
                    if status != OK:
                        break
                j_imp += 1
                t_imp = _next_impulse_time(j_imp, T1)
            if status != OK:
                break
        while k_out < n_out and t_out[k_out] <= t:
            for jj in range(dim):
                out_y[k_out, jj] = y[jj]
            k_out += 1
        if k_out >= n_out:
            break
        t_break = t_out[k_out]
        if t_imp < t_break:
            t_break = t_imp
        if pulse_end < t_break:
            t_break = pulse_end

        release = rhs(t, y, p, cfg, nodes, weights, U, pulse, sticking, K[0], xk, vk)
        n_rhs += 1
        if sticking and release < 0.0:
            sticking = False
            n_events = _log_event(log, n_events, t, 0.0, EV_RELEASE)
            rhs(t, y, p, cfg, nodes, weights, U, pulse, sticking, K[0], xk, vk)
            n_rhs += 1
        elif not sticking and y[0] >= delta and y[ncoef] == 0.0 and release > 0.0:
            # at rest on the wall with the net force into it (e.g. x0 = delta, v0 = 0):
            # no impact will be detected from here, so start sticking now
            y[0] = delta
            if law != LAW_MEAN:
                for i in range(ncoef):
                    y[ncoef + i] = 0.0
            sticking = True
            n_events = _log_event(log, n_events, t, 0.0, EV_STICK)
            rhs(t, y, p, cfg, nodes, weights, U, pulse, sticking, K[0], xk, vk)
            n_rhs += 1
        if h == 0.0:
            # Initial step: a fraction of the forcing period, then let the controller adapt.
            h = min(1e-3, 0.01 * (t_break - t) + 1e-12)

        # ---- integrate up to t_break
        while t < t_break:
            if n_steps >= max_steps:
                status = MAX_STEPS
                break
            h_lim = min(h, hmax)
            if sticking:
                h_lim = min(h_lim, stick_hmax)
            last = False
            if t + h_lim >= t_break:
                h_try = t_break - t
                last = True
            else:
                h_try = h_lim
            if h_try <= 1e-14 * max(1.0, abs(t)):
                if last:
                    t = t_break
                    break
                status = STEP_COLLAPSE
                break
            rk_step(t, y, h_try, K, y_new, ytmp, p, cfg, nodes, weights, U, pulse, sticking, xk, vk)
            n_rhs += 6
            n_steps += 1
            err = error_norm(y, y_new, K, h_try, rtol, atol)
            if not np.isfinite(err):
                h = 0.25 * h_try
                if h < 1e-14 * max(1.0, abs(t)):
                    status = DIVERGED
                    break
                continue
            if err > 1.0:
                factor = max(MIN_FACTOR, SAFETY * err**ERROR_EXPONENT)
                h = h_try * factor
                continue
            # accepted
            if err == 0.0:
                factor = MAX_FACTOR
            else:
                factor = min(MAX_FACTOR, SAFETY * err**ERROR_EXPONENT)
            h_next = max(h_try * factor, h if last else 0.0)

            # Cheap exclusion before the full scan: the quartic cannot rise more than
            # |h| max|stage slope| above the higher endpoint (x2 for interpolant overshoot).
            near_wall = False
            if not sticking:
                vmax = 0.0
                for s in range(7):
                    vmax = max(vmax, abs(K[s, 0]))
                near_wall = max(y[0], y_new[0]) + 2.0 * h_try * vmax >= delta
            if near_wall:
                theta = find_wall_crossing(y, h_try, K, delta)
                if theta > 0.0:
                    t_hit, v_minus = _locate_impact(t, y, h_try, theta, K, K2, y_new, ytmp, p, cfg, nodes, weights, U, pulse, xk, vk)
                    n_rhs += 18
                    # y_new now holds the state at the wall
                    t = t_hit
                    for jj in range(dim):
                        y[jj] = y_new[jj]
                    y[0] = delta
                    n_impacts += 1
                    kind = EV_GRAZE if v_minus < GRAZE_VELOCITY else EV_IMPACT
                    n_events = _log_event(log, n_events, t, v_minus, kind)
                    if law == LAW_SALTATION and v_minus > GRAZE_VELOCITY:
                        a_minus = rhs(t, y, p, cfg, nodes, weights, U, pulse, False, ytmp, xk, vk)
                        y[ncoef] = -eta * y[ncoef]
                        a_plus = rhs(t, y, p, cfg, nodes, weights, U, pulse, False, ytmp, xk, vk)
                        n_rhs += 2
                        _apply_saltation(y, ncoef, eta, v_minus, a_minus, a_plus)
                    elif law == LAW_SALTATION:  # grazing: no finite saltation; reflect v
                        _apply_impact(y, ncoef, eta, LAW_ENSEMBLE)
                    else:
                        _apply_impact(y, ncoef, eta, law)
                    # chatter: impacts too slow to resolve with a net force into the wall
                    if eta < 1.0 and v_minus < chatter_v:
                        y[ncoef] = 0.0
                        acc = rhs(t, y, p, cfg, nodes, weights, U, pulse, False, K[0], xk, vk)
                        n_rhs += 1
                        if acc > 0.0:
                            t_acc = t + 2.0 * eta * v_minus / (acc * (1.0 - eta))
                            if law != LAW_MEAN:
                                for i in range(ncoef):
                                    y[ncoef + i] = 0.0
                            sticking = True
                            n_events = _log_event(log, n_events, t_acc, 0.0, EV_STICK)
                        else:
                            y[ncoef] = -eta * v_minus
                    status = state_status(y, escape)
                    if status != OK:
                        break
                    rhs(t, y, p, cfg, nodes, weights, U, pulse, sticking, K[0], xk, vk)
                    n_rhs += 1
                    h = max(h_next * 0.5, 1e-10)
                    if t >= t_break:
                        t = t_break
                        break
                    continue
            elif sticking:
                # sticking: release when the unconstrained acceleration turns away from the wall
                rel_end = rhs(t + h_try, y_new, p, cfg, nodes, weights, U, pulse, False, ytmp, xk, vk)
                n_rhs += 1
                if rel_end < 0.0:
                    lo = 0.0
                    hi = 1.0
                    for _ in range(60):
                        mid = 0.5 * (lo + hi)
                        dense_state(mid, y, h_try, K, ytmp)
                        ytmp[0] = delta
                        ytmp[ncoef] = 0.0
                        r = rhs(t + mid * h_try, ytmp, p, cfg, nodes, weights, U, pulse, False, y_new, xk, vk)
                        n_rhs += 1
                        if r < 0.0:
                            hi = mid
                        else:
                            lo = mid
                        if (hi - lo) * h_try < 1e-13:
                            break
                    dense_state(hi, y, h_try, K, ytmp)
                    t = t + hi * h_try
                    for jj in range(dim):
                        y[jj] = ytmp[jj]
                    y[0] = delta
                    y[ncoef] = 0.0
                    sticking = False
                    n_events = _log_event(log, n_events, t, 0.0, EV_RELEASE)
                    status = state_status(y, escape)
                    if status != OK:
                        break
                    rhs(t, y, p, cfg, nodes, weights, U, pulse, sticking, K[0], xk, vk)
                    n_rhs += 1
                    h = h_next
                    if t >= t_break:
                        t = t_break
                        break
                    continue

            t = t_break if last else t + h_try
            for jj in range(dim):
                y[jj] = y_new[jj]
                K[0, jj] = K[6, jj]
            if sticking:
                y[0] = delta
                y[ncoef] = 0.0
            h = h_next
            status = state_status(y, escape)
            if status != OK:
                break
        if status != OK:
            break
    _fill_nan(out_y, k_out)  # what was not reached
    return status, n_events, n_impacts, n_steps, n_rhs


@njit(cache=True)
def _locate_impact(t, y, h, theta, K, K2, y_new, ytmp, p, cfg, nodes, weights, U, pulse, xk, vk):
    """Refine the impact time found on the dense output by re-stepping exactly to it.

    Newton iterations on x_0(t_hit) = delta, each a fresh Runge-Kutta step from
    (t, y), so the impact state is a full-order step result, not an interpolant.
    Returns (t_hit, v_minus) and leaves the impact state in ``y_new``.
    """
    ncoef = cfg[C_NCOEF]
    delta = p[P_DELTA]
    dim = y.shape[0]
    for jj in range(dim):
        K2[0, jj] = K[0, jj]
    hh = theta * h
    for _ in range(3):
        rk_step(t, y, hh, K2, y_new, ytmp, p, cfg, nodes, weights, U, pulse, False, xk, vk)
        g = y_new[0] - delta
        v = y_new[ncoef]
        if v <= 0.0 or abs(g) <= 1e-14 * (1.0 + abs(delta)):
            break
        dh = -g / v
        if hh + dh <= 0.0 or hh + dh > h:
            break
        hh += dh
    return t + hh, y_new[ncoef]


# ---------------------------------------------------------------------------
# Monte Carlo: many sampled deterministic systems, parallel over samples
@njit(cache=True)
def _sampled_system(cfg):
    """The one-point rule of a sampled deterministic system (N = 0) and the index in ``p``
    of its uncertain parameter."""
    nodes = np.zeros(1)
    weights = np.ones(1)
    U = np.zeros((1, 2))
    U[0, 0] = 1.0
    unc = cfg[C_UNCERTAIN]
    idx = P_MU
    if unc == UNCERTAIN_A:
        idx = P_A
    elif unc == UNCERTAIN_C:
        idx = P_C
    return nodes, weights, U, idx


@njit(cache=True, parallel=True)
def run_samples(y0, xi, t_out, p, cfg, rtol, atol, paths, n_impacts, n_rhs, status, abort):
    """Integrate the true impact system for each sample value ``xi[m]``.

    ``abort`` (int64 array of one element): set to 1 by the first sample that fails; the
    samples not yet started are then marked ``SKIPPED`` (their paths are not filled).

    The uncertain parameter of sample m is ``p[uncertain] + p[P_SIGMA] * xi[m]``; each
    sample is the deterministic system (N = 0), so its results do not depend on the
    thread that ran it. paths: (M, n_out, 2); n_impacts, n_rhs, status: (M,).
    """
    M = xi.shape[0]
    nodes, weights, U, idx = _sampled_system(cfg)
    for m in prange(M):
        if abort[0] != 0:  # another sample failed: the chunk fails, do not integrate on
            status[m] = SKIPPED
            continue
        pm = p.copy()
        pm[idx] = p[idx] + p[P_SIGMA] * xi[m]
        pm[P_SIGMA] = 0.0
        cm = cfg.copy()
        cm[C_NCOEF] = 1
        cm[C_TRUNC] = TRUNC_GALERKIN
        cm[C_LAW] = LAW_MEAN
        log = np.empty((0, 3))
        res = integrate(y0, t_out, pm, cm, nodes, weights, U, rtol, atol, paths[m], log)
        status[m] = res[0]
        n_impacts[m] = res[2]
        n_rhs[m] = res[4]
        if res[0] != OK:
            abort[0] = 1


@njit(cache=True, parallel=True)
def run_elements(y0, t_out, p, cfg, nodes, weights, U, rtol, atol, out, counters):
    """Integrate E independent OPA systems (the elements of a multi-element system) in
    parallel: element e has its own rule ``nodes[e], weights[e]`` and basis ``U[e]``
    (node-major, (Q, N+2)). out: (E, n_out, dim); counters: (E, 5) with the status,
    events, impacts, steps and right-hand sides of each."""
    E = nodes.shape[0]
    for e in prange(E):
        log = np.empty((0, 3))
        res = integrate(y0, t_out, p, cfg, nodes[e], weights[e], U[e], rtol, atol, out[e], log)
        for j in range(5):
            counters[e, j] = res[j]


@njit(cache=True, parallel=True)
def run_event_logs(y0, values, t_out, p, cfg, rtol, atol, logs, n_events, status):
    """The event logs of M sampled deterministic systems, in parallel: sample m has the
    uncertain parameter ``values[m]`` (absolute, not p_bar + sigma xi). logs: (M, cap, 3);
    n_events (M,) may exceed cap, in which case the log was cut and must be rerun."""
    M = values.shape[0]
    nodes, weights, U, idx = _sampled_system(cfg)
    for m in prange(M):
        pm = p.copy()
        pm[idx] = values[m]
        pm[P_SIGMA] = 0.0
        cm = cfg.copy()
        cm[C_NCOEF] = 1
        out = np.empty((t_out.shape[0], 2))
        res = integrate(y0, t_out, pm, cm, nodes, weights, U, rtol, atol, out, logs[m])
        status[m] = res[0]
        n_events[m] = res[1]


@njit(cache=True, parallel=True)
def run_configs(y0, t_out, p, cfgs, nodes, weights, U, rtol, atol, out, logs, counters):
    """Integrate one OPA system of one order under B configurations (impact law,
    truncation: rows of ``cfgs``) in parallel. out: (B, n_out, dim); logs: (B, cap, 3);
    counters: (B, 5) with the status, events, impacts, steps and right-hand sides."""
    B = cfgs.shape[0]
    for b in prange(B):
        res = integrate(y0, t_out, p, cfgs[b], nodes, weights, U, rtol, atol, out[b], logs[b])
        for j in range(5):
            counters[b, j] = res[j]
