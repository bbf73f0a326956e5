"""opa: the vibro-impact oscillator, its OPA equivalent system and the event-driven solver.

Public names are re-exported here; every other module is private.
"""

from opa._basis import chebyshev_u, cubic_projection, gauss_nodes, project, triple_product
from opa._dataset import write_netcdf
from opa._model import Oscillator, SolverOptions, Uncertainty, preset, time_grid
from opa._bifurcation import sweep
from opa._continuation import Located, continue_orbits, locate_bifurcations, plot_branches
from opa._poincare import Motion, constraint_section, detect_period, identify_motion, phase_section
from opa._simulate import SimulationError, simulate_dmr, simulate_opa
from opa._stability import (
    ImpactSystem,
    PeriodicOrbit,
    impulse_cycle,
    lyapunov_benettin,
    lyapunov_exponent,
    periodic_orbit,
    poincare_map,
    transverse_lyapunov_exponent,
)


def reproduce(figure: str, outdir: str = "figures", **kwargs):
    """Regenerate a figure of the paper (``fig2`` .. ``fig11`` or ``all``); see
    :func:`opa._figures.reproduce`. Imported lazily: it pulls in matplotlib."""
    from opa._figures import reproduce as _reproduce

    return _reproduce(figure, outdir, **kwargs)


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
