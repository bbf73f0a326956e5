"""opa: the vibro-impact oscillator, its OPA equivalent system and the event-driven solver.

Public names are re-exported here; every other module is private.
"""

from opa._basis import chebyshev_u, cubic_projection, gauss_nodes, project, triple_product
from opa._dataset import write_netcdf
from opa._model import Oscillator, SolverOptions, Uncertainty, preset, time_grid
from opa._system import System
from opa._shims import reproduce, sweep
from opa.dynamics._continuation import Located, continue_orbits, locate_bifurcations
from opa.dynamics._sections import Motion, constraint_section, detect_period, identify_motion, phase_section
from opa._simulate import simulate_dmr, simulate_opa
from opa._run import SimulationError
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


def __getattr__(name: str):
    """``opa.plot_branches`` without importing matplotlib with ``opa``."""
    if name == "plot_branches":
        from opa.plots import plot_branches

        return plot_branches
    raise AttributeError(f"module 'opa' has no attribute {name!r}")


__all__ = [
    "Oscillator",
    "System",
    "SolverOptions",
    "Uncertainty",
    "SimulationError",
    "preset",
    "time_grid",
    "simulate_dmr",
    "simulate_opa",
    "write_netcdf",
    "sweep",
    "reproduce",
    "Motion",
    "identify_motion",
    "phase_section",
    "constraint_section",
    "detect_period",
    "ImpactSystem",
    "PeriodicOrbit",
    "periodic_orbit",
    "poincare_map",
    "lyapunov_exponent",
    "lyapunov_benettin",
    "transverse_lyapunov_exponent",
    "impulse_cycle",
    "continue_orbits",
    "locate_bifurcations",
    "Located",
    "plot_branches",
    "chebyshev_u",
    "cubic_projection",
    "gauss_nodes",
    "project",
    "triple_product",
]
