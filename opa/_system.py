"""Which system: the oscillator with its impulse model, the uncertainty and the OPA order
with its closures, and the one packer that turns them into the kernel's arguments."""

from __future__ import annotations

import math

import numpy as np

from opa import _kernel as K
from opa._model import IMPACT_LAWS, METHODS, TRUNCATIONS, Oscillator, SolverOptions


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
