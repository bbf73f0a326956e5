"""opa: the vibro-impact oscillator, its OPA equivalent system and the event-driven solver.

Public names are re-exported here; every other module is private.
"""

from opa._basis import chebyshev_u, cubic_projection, gauss_nodes, project, triple_product
from opa._dataset import write_netcdf
from opa._model import Oscillator, SolverOptions, Uncertainty, preset, time_grid
from opa._simulate import SimulationError, simulate_dmr, simulate_opa

__all__ = [
    "Oscillator",
    "SolverOptions",
    "Uncertainty",
    "SimulationError",
    "preset",
    "time_grid",
    "simulate_dmr",
    "simulate_opa",
    "write_netcdf",
    "chebyshev_u",
    "cubic_projection",
    "gauss_nodes",
    "project",
    "triple_product",
]
