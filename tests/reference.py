"""Independent scipy reference for the deterministic vibro-impact oscillator (paper eq. 1).

    x'' = mu (1 - x'^2) x' - a x - c x^3 + f cos(omega t) + F(t),   x < delta
    x'(t+) = -eta x'(t-)                                             at x = delta

with impulses at ``t_j = j T1``, ``T1 = 2 pi / omega1``, of size
``I_j = F0 (1 + a1 sin(omega1 t_j / n))``: ``"dirac"`` adds ``I_j`` to the velocity,
``"pulse"`` applies a force ``I_j`` on ``[t_j, t_j + tau)``.

Deliberately simple and slow: ``solve_ivp(DOP853)`` between breakpoints (impulse times and
pulse ends), a terminal event on ``x - delta`` crossing upwards, restart after each impact.
It imports nothing from ``opa``, ``mc`` or ``compare`` so that it can check them.

Conventions: outputs are right-continuous, i.e. at an impulse or impact time they show the
state *after* the jump (``v(0) = v0 + I_0`` when the impulse at zero is included); the
recorded impact velocity is the pre-impact ``x'(-) > 0``. Chatter (impact velocities
shrinking to an accumulation point) and sticking are out of scope: more than
``max_impacts`` impacts raise ``RuntimeError``.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

# Bounds the step so that an excursion past the wall is not stepped over unseen.
_MAX_STEP = 0.05


def reference_trajectory(
    mu, a, c, f, omega, eta, delta, F0, a1, omega1, n, x0, v0, t_out,
    impulse="dirac", tau=0.1, impulse_at_zero=True, rtol=1e-12, atol=1e-12,
    max_impacts=100_000,
):  # fmt: skip
    """Integrate eq. (1) and return ``dict(x, v, impact_time, impact_velocity)``.

    ``t_out`` is an increasing array of output times starting at 0; ``x`` and ``v`` have
    its shape. See the module docstring for the conventions.
    """
    t_out = np.asarray(t_out, dtype=float)
    if t_out[0] != 0.0 or np.any(np.diff(t_out) < 0):
        raise ValueError("t_out must be increasing and start at 0")
    if impulse not in ("dirac", "pulse"):
        raise ValueError(f"impulse must be 'dirac' or 'pulse', got {impulse!r}")
    if x0 > delta:
        raise ValueError(f"x0 must be <= delta, got {x0!r}")
    t_end = t_out[-1]
    period = 2.0 * np.pi / omega1
    j = np.arange(0 if impulse_at_zero else 1, int(np.floor(t_end / period)) + 2)
    t_imp = j * period
    t_imp = t_imp[t_imp <= t_end]
    height = F0 * (1.0 + a1 * np.sin(omega1 * t_imp / n))
    breaks = t_imp if impulse == "dirac" else np.concatenate([t_imp, t_imp + tau])
    grid = np.unique(np.concatenate([[0.0, t_end], breaks[breaks <= t_end]]))

    starts, pieces = [], []  # piece: callable t -> state, valid from its start on
    impacts = []  # (time, pre-impact velocity)
    y = np.array([x0, v0], dtype=float)

    def wall_check(t, y):
        if y[0] >= delta and y[1] > 0.0:
            impacts.append((t, y[1]))
            y = np.array([delta, -eta * y[1]])
        return y

    for k, t0 in enumerate(grid):
        if impulse == "dirac":
            y = y + np.array([0.0, height[t_imp == t0].sum()])
        y = wall_check(t0, y)
        if k == len(grid) - 1:
            break
        t1 = grid[k + 1]
        mid = 0.5 * (t0 + t1)
        force = height[(t_imp <= mid) & (mid < t_imp + tau)].sum() if impulse == "pulse" else 0.0
        y = _integrate_interval(
            (mu, a, c, f, omega, force), delta, eta, t0, t1, y, rtol, atol,
            starts, pieces, impacts, max_impacts,
        )  # fmt: skip
    final = y.copy()
    starts.append(t_end)
    pieces.append(lambda t: np.broadcast_to(final[:, None], (2, np.size(t))))

    states = np.empty((2, t_out.size))
    which = np.searchsorted(np.asarray(starts), t_out, side="right") - 1
    for index in np.unique(which):
        mask = which == index
        states[:, mask] = pieces[index](t_out[mask])
    impacts = np.array(impacts, dtype=float).reshape(-1, 2)
    return dict(x=states[0], v=states[1], impact_time=impacts[:, 0], impact_velocity=impacts[:, 1])


def _integrate_interval(
    params, delta, eta, t0, t1, y, rtol, atol, starts, pieces, impacts, max_impacts
):
    """Integrate ``[t0, t1]`` with impacts; append dense pieces; return the state at t1."""
    mu, a, c, f, omega, force = params

    def rhs(t, y):
        x, v = y
        return [v, mu * (1.0 - v * v) * v - a * x - c * x**3 + f * np.cos(omega * t) + force]

    while t0 < t1:
        start = t0

        def hit_wall(t, y):
            # -1 at the start point: a restart from the wall must not re-detect that impact.
            return y[0] - delta if t > start else -1.0

        hit_wall.terminal, hit_wall.direction = True, 1.0
        sol = solve_ivp(
            rhs, (t0, t1), y, method="DOP853", dense_output=True, events=hit_wall,
            rtol=rtol, atol=atol, max_step=_MAX_STEP,
        )  # fmt: skip
        if not sol.success:
            raise RuntimeError(f"solve_ivp failed at t = {sol.t[-1]}: {sol.message}")
        starts.append(t0)
        pieces.append(sol.sol)
        if sol.status != 1:
            return sol.y[:, -1]
        t0, v_minus = sol.t_events[0][0], sol.y_events[0][0][1]
        impacts.append((t0, v_minus))
        if len(impacts) > max_impacts:
            raise RuntimeError(f"more than {max_impacts} impacts (chatter is out of scope)")
        y = np.array([delta, -eta * v_minus])
    return y


def reference_final_state(t_end, **model):
    """State ``(x, v)`` at ``t_end``; ``model`` holds the arguments of reference_trajectory."""
    out = reference_trajectory(t_out=np.array([0.0, t_end]), **model)
    return out["x"][-1], out["v"][-1]
