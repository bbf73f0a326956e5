"""Analyses of trajectories: Poincaré and constraint sections, brute-force sweeps,
periodic orbits with their Floquet multipliers, Lyapunov exponents, and continuation
with located bifurcations.

They serve the DMR, the OPA system and, through a trajectory *source*
(``sweep(..., mc=MonteCarlo(source=mc.sweep_source))``), the Monte Carlo mean; this package never
imports ``mc`` or ``compare``.
"""

from opa.dynamics._continuation import (
    BIFURCATION_KINDS,
    ContinuationOptions,
    Located,
    branch_dataset,
    continue_orbits,
    locate_bifurcations,
    orbit_dataset,
)
from opa.dynamics._orbits import (
    CONTINUABLE,
    STABILITY_LAWS,
    ImpactSystem,
    PeriodicOrbit,
    benettin_engine,
    impulse_cycle,
    lyapunov_benettin,
    lyapunov_exponent,
    periodic_orbit,
    poincare_map,
    transverse_lyapunov_exponent,
)
from opa.dynamics._sections import (
    MOTION_GRAZE_GAP,
    MOTION_GRAZE_VELOCITY,
    PERIOD_TOL,
    Motion,
    MotionTolerances,
    constraint_section,
    detect_period,
    identify_motion,
    phase_section,
)
from opa.dynamics._attractor import Settings
from opa.dynamics._stochastic import EMR, DiagramInputError, check_diagram, stochastic_diagram
from opa.dynamics._sweep import (
    CONTINUATIONS,
    DEFAULT_WORKERS,
    SWEEP_MODELS,
    MonteCarlo,
    Window,
    summary_lines,
    sweep,
)

__all__ = [
    "EMR",
    "MonteCarlo",
    "MotionTolerances",
    "Settings",
    "Window",
    "ContinuationOptions",
    "DiagramInputError",
    "ImpactSystem",
    "Located",
    "Motion",
    "PeriodicOrbit",
    "benettin_engine",
    "branch_dataset",
    "check_diagram",
    "constraint_section",
    "continue_orbits",
    "detect_period",
    "identify_motion",
    "impulse_cycle",
    "locate_bifurcations",
    "orbit_dataset",
    "lyapunov_benettin",
    "lyapunov_exponent",
    "periodic_orbit",
    "phase_section",
    "poincare_map",
    "stochastic_diagram",
    "summary_lines",
    "sweep",
    "transverse_lyapunov_exponent",
    # the vocabulary of the analyses' arguments and their defaults (``opa.cli``'s flags)
    "BIFURCATION_KINDS",
    "CONTINUABLE",
    "CONTINUATIONS",
    "DEFAULT_WORKERS",
    "MOTION_GRAZE_GAP",
    "MOTION_GRAZE_VELOCITY",
    "PERIOD_TOL",
    "STABILITY_LAWS",
    "SWEEP_MODELS",
]
