"""Compiled variational integrator: the flow of the impact system and its Jacobian.

This is the kernel chain of the stability tools (``opa._stability``). It is separate
from ``opa._solver`` on purpose: numba's on-disk cache does not notice edits to jitted
functions in other modules, so this module imports no jitted code and has its own
right-hand side, Dormand-Prince step, dense output and event location.

Augmented state, for ``n = N + 1`` coefficients, ``D = 2 n`` and ``m`` tangent columns::

    z = [y_0 .. y_{D-1},  W[0, 0..m-1], W[1, 0..m-1], ..., W[D-1, 0..m-1]]
    y = [x_0 .. x_N, v_0 .. v_N]           (state; x_0 meets the wall x_0 = delta)
    y' = f(t, y),   W' = J(t, y) W          (variational equation, J = df/dy)

``m = D`` with ``W(t0) = I`` gives the Jacobian of the flow map; ``m = 1`` carries one
tangent vector (Lyapunov exponents); ``m = 0`` is the plain trajectory.

Right-hand side (Galerkin projection on Q Gauss nodes, eqs. (24)-(27)) and Jacobian::

    v_i' = sum_k w_k U_i(xi_k) g(x_k, v_k; p_k) + [i = 0] (f cos(omega t) + pulse)
    g = mu_k (1 - v^2) v - a_k x - c_k x^3,   x_k = sum_j x_j U_j(xi_k)
    d v_i' / d x_j = sum_k w_k U_i U_j (-a_k - 3 c_k x_k^2)
    d v_i' / d v_j = sum_k w_k U_i U_j mu_k (1 - 3 v_k^2)

The DMR (eq. (29)) is N = 0 with the one-node rule xi = 0.

Non-smooth events and what they do to W:

- impact (x_0 reaches delta, event surface h(y) = x_0 - delta, normal n = e_0): the
  reset R multiplies v_0 (law ``mean``, eq. (28)) or every v_i (law ``ensemble``) by
  -eta, and W jumps by the saltation matrix
  ``S = dR + (f(t*, R y-) - dR f(t*, y-)) e_0^T / v_0-`` (Aizerman-Gantmacher);
- Dirac impulse at a fixed time t_j: y jumps by a constant, W is unchanged;
  rectangular pulses switch the force at fixed times: W is continuous;
- chatter ending in sticking (as in ``opa._solver``): the held rows (x_0, v_0; for the
  ensemble law all velocities) of W are zeroed; at release f is continuous, S = I.

Kernels are pure functions of arrays and floats and return status codes.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# The tableau and status codes are plain constants shared with the solver (no jitted code
# is imported across modules, so numba's per-module cache stays consistent).
from opa._solver import (  # noqa: E402
    BAD_TIME,
    DIVERGED,
    DP_A,
    DP_B,
    DP_C,
    DP_E,
    DP_P,
    ERROR_EXPONENT,
    ESCAPE_FACTOR,
    ESCAPED,
    MAX_FACTOR,
    MAX_STEPS,
    MIN_FACTOR,
    OK,
    SAFETY,
    STATUS_MESSAGES,
    STEP_COLLAPSE,
)

# ---------------------------------------------------------------------------
# Parameter vector ``p`` and integer configuration ``cfg`` of this kernel chain.
V_MU, V_A, V_C, V_F, V_OMEGA, V_ETA, V_DELTA = 0, 1, 2, 3, 4, 5, 6
V_F0, V_A1, V_OMEGA1, V_N, V_TAU, V_SIGMA = 7, 8, 9, 10, 11, 12
V_CHATTER_V, V_HMAX = 13, 14
N_PARAMS = 15

G_NCOEF, G_UNCERTAIN, G_IMPULSE, G_AT_ZERO, G_TRUNC, G_LAW, G_MAXSTEPS = 0, 1, 2, 3, 4, 5, 6
N_CFG = 7

UNCERTAIN_MU, UNCERTAIN_A, UNCERTAIN_C = 0, 1, 2
IMPULSE_DIRAC, IMPULSE_PULSE = 0, 1
TRUNC_GALERKIN, TRUNC_PAPER = 0, 1
LAW_MEAN, LAW_ENSEMBLE = 0, 1

# Slots of the ``stats`` output of ``advance``.
S_IMPACTS, S_MIN_VELOCITY, S_STICKS, S_STEPS, S_STICKING, S_GAP = 0, 1, 2, 3, 4, 5
N_STATS = 6

# Impulse times within this (relative) distance of the end of an interval belong to it.
SNAP = 1e-10

N_SCAN = 8


# ---------------------------------------------------------------------------
# Vector field and its Jacobian
@njit(cache=True)
def impulse_strength(t, p):
    """F0 (1 + a1 sin(omega1 t / n)) at an impulse time t (paper eq. (1))."""
    return p[V_F0] * (1.0 + p[V_A1] * np.sin(p[V_OMEGA1] * t / p[V_N]))


@njit(cache=True)
def vector_field(t, z, m, p, cfg, nodes, weights, U, force, sticking, out, work):
    """Write f(t, y) and, for m > 0, J(t, y) W into ``out`` (layout of ``z``).

    ``force`` is the current rectangular-pulse force (0 otherwise). ``work`` is a
    (6, Q) scratch array. Returns the unconstrained acceleration of x_0 (the release
    function of sticking).
    """
    n = cfg[G_NCOEF]
    dim = 2 * n
    q = nodes.shape[0]
    unc = cfg[G_UNCERTAIN]
    sigma = p[V_SIGMA]
    xk = work[0]
    vk = work[1]
    gx = work[2]
    gv = work[3]
    dxk = work[4]
    dvk = work[5]
    for k in range(q):
        xs = 0.0
        vs = 0.0
        for i in range(n):
            xs += z[i] * U[i, k]
            vs += z[n + i] * U[i, k]
        xk[k] = xs
        vk[k] = vs
    # The force at the mean state, g_0, goes to U_0 alone and only g_k - g_0 is projected:
    # the same projection (sum_k w_k U_i(xi_k) = [i = 0]), but with sigma = 0 and zero
    # higher coefficients every g_k - g_0 is exactly 0, so the higher modes stay exactly
    # 0 and EMR_0 is the DMR bit for bit; otherwise the ~1e-17 round-off of that sum is
    # amplified by the transverse instability (``transverse_lyapunov_exponent``).
    x0 = z[0]
    v0 = z[n]
    g0 = p[V_MU] * (1.0 - v0 * v0) * v0 - p[V_A] * x0 - p[V_C] * x0 * x0 * x0
    for i in range(n):
        out[i] = z[n + i]
        out[n + i] = 0.0
    out[n] = g0
    for k in range(q):
        mu_k = p[V_MU]
        a_k = p[V_A]
        c_k = p[V_C]
        if unc == UNCERTAIN_MU:
            mu_k += sigma * nodes[k]
        elif unc == UNCERTAIN_A:
            a_k += sigma * nodes[k]
        else:
            c_k += sigma * nodes[k]
        x = xk[k]
        v = vk[k]
        w = weights[k]
        g = w * (mu_k * (1.0 - v * v) * v - a_k * x - c_k * x * x * x - g0)
        gx[k] = w * (-a_k - 3.0 * c_k * x * x)
        gv[k] = w * mu_k * (1.0 - 3.0 * v * v)
        if g != 0.0:
            for i in range(n):
                out[n + i] += g * U[i, k]
    paper = cfg[G_TRUNC] == TRUNC_PAPER and sigma != 0.0 and unc != UNCERTAIN_A
    if paper:
        # eq. (27) drops the projection of the xi * cubic term on U_{N+1}: add it back
        extra = 0.0
        for k in range(q):
            if unc == UNCERTAIN_MU:
                extra += weights[k] * U[n, k] * vk[k] ** 3
            else:
                extra += weights[k] * U[n, k] * xk[k] ** 3
        out[dim - 1] += 0.5 * sigma * extra
    out[n] += p[V_F] * np.cos(p[V_OMEGA] * t) + force
    release = out[n]
    if sticking:
        out[0] = 0.0
        out[n] = 0.0
    for c in range(m):
        for k in range(q):
            dx = 0.0
            dv = 0.0
            for j in range(n):
                dx += U[j, k] * z[dim + j * m + c]
                dv += U[j, k] * z[dim + (n + j) * m + c]
            dxk[k] = dx
            dvk[k] = dv
        for i in range(n):
            out[dim + i * m + c] = z[dim + (n + i) * m + c]
            acc = 0.0
            for k in range(q):
                acc += U[i, k] * (gx[k] * dxk[k] + gv[k] * dvk[k])
            out[dim + (n + i) * m + c] = acc
        if paper:
            extra = 0.0
            for k in range(q):
                if unc == UNCERTAIN_MU:
                    extra += weights[k] * U[n, k] * 3.0 * vk[k] ** 2 * dvk[k]
                else:
                    extra += weights[k] * U[n, k] * 3.0 * xk[k] ** 2 * dxk[k]
            out[dim + (dim - 1) * m + c] += 0.5 * sigma * extra
        if sticking:
            out[dim + c] = 0.0
            out[dim + n * m + c] = 0.0
    return release


# ---------------------------------------------------------------------------
# Runge-Kutta step, error estimate and dense output
@njit(cache=True)
def rk_step(t, z, h, K, z_new, ztmp, m, p, cfg, nodes, weights, U, force, sticking, work):
    """One Dormand-Prince step of the augmented system; K[0] must hold f(t, z)."""
    size = z.shape[0]
    for s in range(1, 6):
        for j in range(size):
            acc = 0.0
            for r in range(s):
                acc += DP_A[s, r] * K[r, j]
            ztmp[j] = z[j] + h * acc
        vector_field(t + DP_C[s] * h, ztmp, m, p, cfg, nodes, weights, U, force, sticking,
                     K[s], work)
    for j in range(size):
        acc = 0.0
        for r in range(6):
            acc += DP_B[r] * K[r, j]
        z_new[j] = z[j] + h * acc
    vector_field(t + h, z_new, m, p, cfg, nodes, weights, U, force, sticking, K[6], work)


@njit(cache=True)
def error_norm(z, z_new, K, h, rtol, atol):
    """Max-norm of the scaled local error over state and tangent components."""
    worst = 0.0
    for j in range(z.shape[0]):
        e = 0.0
        for r in range(7):
            e += DP_E[r] * K[r, j]
        size = abs(z_new[j])
        scale = atol + rtol * max(abs(z[j]), size)
        r = abs(h * e) / scale
        # non-finite trial state or stage: infinite error, the step is rejected (tests that
        # fail for NaN; numba's max drops a NaN argument)
        if not (r < np.inf and size < np.inf):
            return np.inf
        if r > worst:
            worst = r
    return worst


@njit(cache=True)
def escape_bound(y0, p):
    """|x_i|, |v_i| beyond which the state counts as escaped: the formula of
    ``opa._solver.escape_bound`` (see ``opa._solver.ESCAPE_FACTOR`` for the reasoning)."""
    start = 0.0
    for j in range(y0.shape[0]):
        a = abs(y0[j])
        if not (a <= start):  # NaN propagates
            start = a
    w = p[V_OMEGA]
    drive = abs(p[V_F]) + abs(p[V_F0]) * (1.0 + abs(p[V_A1]))
    stiffness = abs(p[V_A])
    if stiffness == 0.0:
        return np.inf  # no linear restoring force: no scale to escape from
    return ESCAPE_FACTOR * (1.0 + start + abs(p[V_DELTA])
                            + drive * (1.0 + 1.0 / w + 1.0 / (w * w) + 1.0 / stiffness))


@njit(cache=True)
def augmented_status(z, dim, escape):
    """OK; ESCAPED when a state component |y_j| >= escape; DIVERGED when a state or
    tangent component is NaN or inf (comparisons are false for NaN, so it cannot pass).
    The tangent W may grow large (it is only renormalised by the caller), so only its
    finiteness is checked."""
    status = OK
    for j in range(z.shape[0]):
        a = abs(z[j])
        if not (a < np.inf):
            return DIVERGED
        if j < dim and not (a < escape):
            status = ESCAPED
    return status


@njit(cache=True)
def dense_value(theta, z_old, h, K, j):
    acc = 0.0
    for s in range(7):
        ks = K[s, j]
        if ks != 0.0:
            acc += ks * theta * (DP_P[s, 0] + theta * (
                DP_P[s, 1] + theta * (DP_P[s, 2] + theta * DP_P[s, 3])))
    return z_old[j] + h * acc


@njit(cache=True)
def dense_slope(theta, h, K, j):
    acc = 0.0
    for s in range(7):
        ks = K[s, j]
        if ks != 0.0:
            acc += ks * (DP_P[s, 0] + theta * (2.0 * DP_P[s, 1] + theta * (
                3.0 * DP_P[s, 2] + theta * 4.0 * DP_P[s, 3])))
    return h * acc


# ---------------------------------------------------------------------------
# Wall crossings on the dense output of x_0
@njit(cache=True)
def _bisect_crossing(lo, hi, z_old, h, K, delta):
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if dense_value(mid, z_old, h, K, 0) - delta > 0.0:
            hi = mid
        else:
            lo = mid
        if (hi - lo) * abs(h) < 1e-15:
            break
    return hi


@njit(cache=True)
def _bisect_maximum(lo, hi, h, K):
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if dense_slope(mid, h, K, 0) > 0.0:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-13:
            break
    return 0.5 * (lo + hi)


@njit(cache=True)
def wall_crossing(z_old, x_end, h, K, delta):
    """First theta in (0, 1] where the dense x_0 reaches delta, or -1.

    The quartic is scanned on N_SCAN sub-intervals, and every interior maximum is
    inspected, so a step whose interpolant touches the wall and comes back is caught.
    """
    vmax = 0.0
    for s in range(7):
        vmax = max(vmax, abs(K[s, 0]))
    if max(z_old[0], x_end) + 2.0 * abs(h) * vmax < delta:
        return -1.0
    prev_t = 0.0
    prev_g = dense_value(0.0, z_old, h, K, 0) - delta
    prev_s = dense_slope(0.0, h, K, 0)
    for i in range(1, N_SCAN + 1):
        th = i / N_SCAN
        g = dense_value(th, z_old, h, K, 0) - delta
        s = dense_slope(th, h, K, 0)
        hit = g > 0.0
        hi_t = th
        if not hit and prev_s > 0.0 and s < 0.0:
            tm = _bisect_maximum(prev_t, th, h, K)
            if dense_value(tm, z_old, h, K, 0) - delta > 0.0:
                hit = True
                hi_t = tm
        if hit:
            lo_t = prev_t
            if prev_g >= 0.0:
                # leaving the wall just after an impact: find a point strictly inside
                found = False
                tt = hi_t
                for _ in range(60):
                    tt *= 0.5
                    if tt <= lo_t:
                        break
                    if dense_value(tt, z_old, h, K, 0) - delta < 0.0:
                        found = True
                        break
                if not found:
                    return -1.0
                lo_t = tt
            return _bisect_crossing(lo_t, hi_t, z_old, h, K, delta)
        prev_t = th
        prev_g = g
        prev_s = s
    return -1.0


@njit(cache=True)
def free_flight_gap(z_old, h, K, delta):
    """Smallest distance delta - x_0 at the interior maxima of the dense x_0 in a step.

    A maximum that approaches the wall from below is the signature of a grazing
    bifurcation; returns inf when x_0 has no interior maximum in the step.
    """
    gap = np.inf
    prev_t = 0.0
    prev_s = dense_slope(0.0, h, K, 0)
    for i in range(1, N_SCAN + 1):
        th = i / N_SCAN
        s = dense_slope(th, h, K, 0)
        if prev_s > 0.0 and s <= 0.0:
            tm = _bisect_maximum(prev_t, th, h, K)
            gap = min(gap, delta - dense_value(tm, z_old, h, K, 0))
        prev_t = th
        prev_s = s
    return gap


@njit(cache=True)
def locate_impact(t, z, h, theta, K, K2, z_new, ztmp, m, p, cfg, nodes, weights, U, force, work):
    """Re-step exactly to the impact: Newton on x_0(t + hh) = delta, full RK steps.

    Leaves the augmented state at the impact in ``z_new`` and returns its time.
    """
    n = cfg[G_NCOEF]
    delta = p[V_DELTA]
    for j in range(z.shape[0]):
        K2[0, j] = K[0, j]
    hh = theta * h
    for _ in range(4):
        rk_step(t, z, hh, K2, z_new, ztmp, m, p, cfg, nodes, weights, U, force, False, work)
        g = z_new[0] - delta
        v = z_new[n]
        if v <= 0.0 or abs(g) <= 1e-14 * (1.0 + abs(delta)):
            break
        dh = -g / v
        if hh + dh <= 0.0 or hh + dh > h:
            break
        hh += dh
    return t + hh


# ---------------------------------------------------------------------------
# Events
@njit(cache=True)
def _impact(t, z, m, p, cfg, nodes, weights, U, force, f_minus, f_plus, work):
    """Apply the impact law to y and the saltation matrix to W, at x_0 = delta.

    Returns the pre-impact velocity v_0-.
    """
    n = cfg[G_NCOEF]
    dim = 2 * n
    eta = p[V_ETA]
    ensemble = cfg[G_LAW] == LAW_ENSEMBLE
    z[0] = p[V_DELTA]
    v_minus = z[n]
    vector_field(t, z, 0, p, cfg, nodes, weights, U, force, False, f_minus, work)
    if ensemble:
        for i in range(n):
            z[n + i] = -eta * z[n + i]
    else:
        z[n] = -eta * z[n]
    if m > 0:
        vector_field(t, z, 0, p, cfg, nodes, weights, U, force, False, f_plus, work)
        for c in range(m):
            w0 = z[dim + c] / v_minus  # e_0^T W / (e_0^T f-)
            for r in range(dim):
                d = -eta if (r == n or (ensemble and r > n)) else 1.0
                z[dim + r * m + c] = d * z[dim + r * m + c] + (f_plus[r] - d * f_minus[r]) * w0
    return v_minus


@njit(cache=True)
def _hold(z, m, n, ensemble):
    """Zero the rows of W of the coordinates held by sticking."""
    dim = 2 * n
    for c in range(m):
        z[dim + c] = 0.0
        z[dim + n * m + c] = 0.0
        if ensemble:
            for i in range(1, n):
                z[dim + (n + i) * m + c] = 0.0


@njit(cache=True)
def _first_impulse(t0, include_start, T1, at_zero):
    """Index j of the first impulse t_j = j T1 of the interval starting at t0, or -1
    when t0 / T1 is beyond exact integers (impulse times not resolvable).

    The loops fix the rounding of floor(t0 / T1) and the snap window; a few passes
    suffice unless impulses are denser than the snap window (then j is approximate)."""
    snap = SNAP * max(1.0, abs(t0))
    jf = np.floor(t0 / T1) - 1.0
    if not (abs(jf) < 2.0**53):
        return -1
    j = int(jf)
    for _ in range(8):
        if j * T1 >= t0 - snap:
            break
        j += 1
    if not include_start:
        for _ in range(8):
            if j * T1 > t0 + snap:
                break
            j += 1
    if j < 0:
        j = 0
    if j == 0 and not at_zero:
        j = 1
    return j


# ---------------------------------------------------------------------------
# Driver
@njit(cache=True)
def advance(z, m, t0, t1, include_start, p, cfg, nodes, weights, U, rtol, atol, escape, stats,
            log):
    """Integrate the augmented state ``z`` in place from t0 to t1 (t1 > t0).

    Parameters
    ----------
    z : (D + D m,) state and row-major tangent matrix W (D, m).
    include_start : apply an impulse that falls on t0 (otherwise it is taken to belong
        to the previous interval: states are right-continuous, impulses at t1 are applied).
    escape : the escape bound of the state (``escape_bound``); the augmented state is
        checked after every accepted step and every jump (``augmented_status``).
    stats : (N_STATS,) output: impacts, smallest pre-impact velocity, sticking episodes,
        steps, 1 if sticking at t1, smallest gap delta - x_0 at free-flight maxima.
    log : (cap, 2) rows (time, pre-impact velocity) of the impacts; rows beyond cap are
        counted, not written.

    Returns
    -------
    status, number of impacts
    """
    n = cfg[G_NCOEF]
    dim = 2 * n
    size = z.shape[0]
    q = nodes.shape[0]
    delta = p[V_DELTA]
    eta = p[V_ETA]
    ensemble = cfg[G_LAW] == LAW_ENSEMBLE
    max_steps = cfg[G_MAXSTEPS]
    chatter_v = p[V_CHATTER_V]
    hmax = p[V_HMAX]
    pulse_model = cfg[G_IMPULSE] == IMPULSE_PULSE
    tau = p[V_TAU]
    use_impulses = p[V_F0] != 0.0
    T1 = 2.0 * np.pi / p[V_OMEGA1]
    stick_hmax = 2.0 * np.pi / p[V_OMEGA] / 32.0
    snap = SNAP * max(1.0, abs(t1))

    K = np.empty((7, size))
    K2 = np.empty((7, size))
    z_new = np.empty(size)
    ztmp = np.empty(size)
    f_minus = np.empty(dim)
    f_plus = np.empty(dim)
    work = np.empty((6, q))

    stats[S_IMPACTS] = 0.0
    stats[S_MIN_VELOCITY] = np.inf
    stats[S_STICKS] = 0.0
    stats[S_STEPS] = 0.0
    stats[S_STICKING] = 0.0
    stats[S_GAP] = np.inf
    n_log = 0

    t = t0
    if not (abs(t0) < np.inf and abs(t1) < np.inf):
        return BAD_TIME, 0  # a NaN end would never be reached
    at_zero = cfg[G_AT_ZERO] != 0
    j_imp = _first_impulse(t0, include_start, T1, at_zero) if use_impulses else 0
    if j_imp < 0:
        return BAD_TIME, 0
    t_imp = j_imp * T1 if use_impulses else np.inf
    force = 0.0
    force_end = np.inf
    if use_impulses and pulse_model and j_imp >= 1:
        # a pulse that started before t0 may still be on
        j_prev = j_imp - 1
        if j_prev >= (0 if at_zero else 1) and t0 < j_prev * T1 + tau - snap:
            force = impulse_strength(j_prev * T1, p)
            force_end = j_prev * T1 + tau
    # a state resting on the wall with the force into it starts sticking
    sticking = False
    if z[0] >= delta and z[n] == 0.0:
        acc = vector_field(t, z, 0, p, cfg, nodes, weights, U, force, False, f_minus, work)
        if acc > 0.0:
            sticking = True
    n_steps = 0
    status = OK
    h = 0.0
    # each pass takes a step or passes a breakpoint; the cap only matters for breakpoints
    # closer than round-off (see opa._solver.integrate)
    n_passes = 0
    while True:
        n_passes += 1
        if n_passes > 2 * max_steps + 2:
            status = MAX_STEPS
            break
        # ---- fixed-time events at t
        if use_impulses:
            if pulse_model and t >= force_end - snap:
                force = 0.0
                force_end = np.inf
            while t_imp <= t + snap:
                strength = impulse_strength(t_imp, p)
                if pulse_model:
                    force = strength
                    force_end = t_imp + tau
                else:
                    z[n] += strength
                    if z[0] >= delta and z[n] > 0.0:
                        # kicked into the wall while on it: the impact law at once
                        if ensemble:
                            for i in range(n):
                                z[n + i] = -eta * z[n + i]
                        else:
                            z[n] = -eta * z[n]
                        for c in range(m):
                            z[dim + n * m + c] *= -eta
                            if ensemble:
                                for i in range(1, n):
                                    z[dim + (n + i) * m + c] *= -eta
                        stats[S_IMPACTS] += 1.0
                    if sticking and z[n] != 0.0:
                        sticking = False
                    status = augmented_status(z, dim, escape)
                    if status != OK:
                        break
                j_imp += 1
                t_imp = j_imp * T1
            if status != OK:
                break
        if t >= t1:
            break
        t_break = t1
        if t_imp < t_break:
            t_break = t_imp
        if force_end < t_break:
            t_break = force_end
        if t1 - t_break <= snap:
            t_break = t1

        release = vector_field(t, z, m, p, cfg, nodes, weights, U, force, sticking, K[0], work)
        if sticking and release < 0.0:
            sticking = False
            vector_field(t, z, m, p, cfg, nodes, weights, U, force, sticking, K[0], work)
        if h == 0.0:
            h = min(1e-3, 0.01 * (t_break - t) + 1e-12)

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
            rk_step(t, z, h_try, K, z_new, ztmp, m, p, cfg, nodes, weights, U, force, sticking,
                    work)
            n_steps += 1
            err = error_norm(z, z_new, K, h_try, rtol, atol)
            if not np.isfinite(err):
                h = 0.25 * h_try
                if h < 1e-14 * max(1.0, abs(t)):
                    status = DIVERGED
                    break
                continue
            if err > 1.0:
                h = h_try * max(MIN_FACTOR, SAFETY * err**ERROR_EXPONENT)
                continue
            factor = MAX_FACTOR if err == 0.0 else min(MAX_FACTOR, SAFETY * err**ERROR_EXPONENT)
            h_next = max(h_try * factor, h if last else 0.0)

            if not sticking:
                theta = wall_crossing(z, z_new[0], h_try, K, delta)
                if theta > 0.0:
                    t = locate_impact(t, z, h_try, theta, K, K2, z_new, ztmp, m, p, cfg, nodes,
                                      weights, U, force, work)
                    for j in range(size):
                        z[j] = z_new[j]
                    v_minus = _impact(t, z, m, p, cfg, nodes, weights, U, force, f_minus,
                                      f_plus, work)
                    stats[S_IMPACTS] += 1.0
                    stats[S_MIN_VELOCITY] = min(stats[S_MIN_VELOCITY], v_minus)
                    if n_log < log.shape[0]:
                        log[n_log, 0] = t
                        log[n_log, 1] = v_minus
                    n_log += 1
                    if eta < 1.0 and v_minus < chatter_v:
                        # chatter: rest on the wall if the net force pushes into it
                        z[n] = 0.0
                        acc = vector_field(t, z, 0, p, cfg, nodes, weights, U, force, False,
                                           f_minus, work)
                        if acc > 0.0:
                            if ensemble:
                                for i in range(n):
                                    z[n + i] = 0.0
                            _hold(z, m, n, ensemble)
                            sticking = True
                            stats[S_STICKS] += 1.0
                        else:
                            z[n] = -eta * v_minus
                    # the saltation matrix divides by v_0-: near grazing W can overflow
                    status = augmented_status(z, dim, escape)
                    if status != OK:
                        break
                    vector_field(t, z, m, p, cfg, nodes, weights, U, force, sticking, K[0], work)
                    h = max(h_next * 0.5, 1e-10)
                    if t >= t_break:
                        t = t_break
                        break
                    continue
            else:
                rel_end = vector_field(t + h_try, z_new, 0, p, cfg, nodes, weights, U, force,
                                       False, f_plus, work)
                if rel_end < 0.0:
                    lo = 0.0
                    hi = 1.0
                    for _ in range(60):
                        mid = 0.5 * (lo + hi)
                        for j in range(size):
                            ztmp[j] = dense_value(mid, z, h_try, K, j)
                        ztmp[0] = delta
                        ztmp[n] = 0.0
                        r = vector_field(t + mid * h_try, ztmp, 0, p, cfg, nodes, weights, U,
                                         force, False, f_plus, work)
                        if r < 0.0:
                            hi = mid
                        else:
                            lo = mid
                        if (hi - lo) * h_try < 1e-13:
                            break
                    for j in range(size):
                        z[j] = dense_value(hi, z, h_try, K, j)
                    t = t + hi * h_try
                    z[0] = delta
                    z[n] = 0.0
                    sticking = False
                    status = augmented_status(z, dim, escape)
                    if status != OK:
                        break
                    vector_field(t, z, m, p, cfg, nodes, weights, U, force, sticking, K[0], work)
                    h = h_next
                    if t >= t_break:
                        t = t_break
                        break
                    continue

            if not sticking:
                stats[S_GAP] = min(stats[S_GAP], free_flight_gap(z, h_try, K, delta))
            t = t_break if last else t + h_try
            for j in range(size):
                z[j] = z_new[j]
                K[0, j] = K[6, j]
            if sticking:
                z[0] = delta
                z[n] = 0.0
            h = h_next
            status = augmented_status(z, dim, escape)
            if status != OK:
                break
        if status != OK:
            break
    stats[S_STEPS] = n_steps
    stats[S_STICKING] = 1.0 if sticking else 0.0
    return status, n_log


@njit(cache=True)
def flow_points(z, m, times, include_start, renormalise, p, cfg, nodes, weights, U, rtol, atol,
                out, stats, log_growth, log):
    """Advance ``z`` through ``times`` (increasing), storing the state at each time.

    ``out`` (len(times), D) receives the state (W is not stored); ``stats`` (len(times)
    - 1, N_STATS) the statistics of each interval; the impacts of all intervals go to
    ``log``. With ``renormalise`` the tangent matrix W is scaled to unit Frobenius norm
    at every time and ``log_growth[i]`` (len(times) - 1) receives the log of its growth
    over interval i (``-inf`` when sticking collapsed it; W then restarts from equal
    entries). This is the Lyapunov loop (Benettin's renormalisation with the exact
    tangent map). ``z`` ends as the augmented state at times[-1].

    Returns
    -------
    status, number of impacts logged (or counted beyond the log's capacity)
    """
    dim = 2 * cfg[G_NCOEF]
    size = z.shape[0]
    for j in range(dim):
        out[0, j] = z[j]
    # one bound for the whole call, from the state at times[0]
    escape = escape_bound(z[:dim], p)
    if augmented_status(z, dim, escape) != OK:
        return DIVERGED, 0
    n_log = 0
    for i in range(times.shape[0] - 1):
        sub = log[min(n_log, log.shape[0]):]
        status, count = advance(z, m, times[i], times[i + 1], include_start and i == 0, p, cfg,
                                nodes, weights, U, rtol, atol, escape, stats[i], sub)
        n_log += count
        if status != OK:
            return status, n_log
        for j in range(dim):
            out[i + 1, j] = z[j]
        if renormalise and m > 0:
            norm = 0.0
            for j in range(dim, size):
                norm += z[j] * z[j]
            norm = np.sqrt(norm)
            if norm > 0.0 and np.isfinite(norm):
                log_growth[i] = np.log(norm)
                for j in range(dim, size):
                    z[j] /= norm
            else:
                log_growth[i] = -np.inf
                for j in range(dim, size):
                    z[j] = 1.0 / np.sqrt(size - dim)
    return OK, n_log
