"""Analyses of trajectories: Poincaré and constraint sections, brute-force sweeps,
periodic orbits with their Floquet multipliers, Lyapunov exponents, and continuation
with located bifurcations.

They serve the DMR, the OPA system and, through a trajectory *source*
(``sweep(..., source=mc.sweep_source)``), the Monte Carlo mean; this package never
imports ``mc`` or ``compare``.
"""

from opa.dynamics._continuation import (
    ContinuationOptions,
    Located,
    branch_dataset,
    continue_orbits,
    locate_bifurcations,
)
from opa.dynamics._orbits import (
    ImpactSystem,
    PeriodicOrbit,
    impulse_cycle,
    lyapunov_benettin,
    lyapunov_exponent,
    periodic_orbit,
    poincare_map,
    transverse_lyapunov_exponent,
)
from opa.dynamics._sections import (
    Motion,
    constraint_section,
    detect_period,
    identify_motion,
    phase_section,
)
from opa.dynamics._stochastic import stochastic_diagram
from opa.dynamics._sweep import summary_lines, sweep

__all__ = [
    "ContinuationOptions",
    "ImpactSystem",
    "Located",
    "Motion",
    "PeriodicOrbit",
    "branch_dataset",
    "constraint_section",
    "continue_orbits",
    "detect_period",
    "identify_motion",
    "impulse_cycle",
    "locate_bifurcations",
    "lyapunov_benettin",
    "lyapunov_exponent",
    "periodic_orbit",
    "phase_section",
    "poincare_map",
    "stochastic_diagram",
    "summary_lines",
    "sweep",
    "transverse_lyapunov_exponent",
]
