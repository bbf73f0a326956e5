"""opa: the vibro-impact oscillator, its OPA equivalent system and the event-driven solver.

Public names are re-exported here; every other module is private. The analyses of
trajectories are ``opa.dynamics``' public names, re-exported as they are; the figures
(``opa.plots``) are imported only when drawn.

The vocabulary of the arguments (the parameter names, the System's fields, laws, methods,
presets, the default order and sigma, and their limits) is importable from here too, for
front ends such as ``opa.cli`` that list the choices; it is not in ``__all__``, which
holds what users call.
"""

# importing opa changes no process-wide state: numba's threads are told to sleep between
# parallel regions when opa first starts them (opa._run.quiet_threads)
from opa import dynamics as _dynamics  # noqa: E402
from opa.dynamics import *  # noqa: F403 -- exactly opa.dynamics.__all__
from opa._basis import chebyshev_u, cubic_projection, gauss_nodes, project, triple_product
from opa._dataset import write_netcdf
from opa._execution import Execution
from opa._model import Oscillator, SolverOptions, Uncertainty, preset, time_grid
from opa._model import (  # the vocabulary (module docstring)
    IMPACT_LAWS as IMPACT_LAWS,
    IMPULSE_MODELS as IMPULSE_MODELS,
    MAX_GRID as MAX_GRID,
    MAX_WHOLE as MAX_WHOLE,
    METHODS as METHODS,
    PARAMETER_DOCS as PARAMETER_DOCS,
    PARAMETER_NAMES as PARAMETER_NAMES,
    PRESETS as PRESETS,
    TRUNCATIONS as TRUNCATIONS,
    UNCERTAIN_PARAMETERS as UNCERTAIN_PARAMETERS,
)
from opa._run import SimulationError
from opa._simulate import simulate_dmr, simulate_opa
from opa._forcelaw import ForceLaw
from opa._problem import Problem
from opa._system import System
from opa._system import (  # the vocabulary (module docstring)
    DEFAULT_ORDER as DEFAULT_ORDER,
    DEFAULT_SIGMA as DEFAULT_SIGMA,
    IMPULSE_FIELDS as IMPULSE_FIELDS,
    SWEEPABLE as SWEEPABLE,
    SYSTEM_FIELDS as SYSTEM_FIELDS,
)


def __getattr__(name: str):
    """``opa.plot_branches`` without importing matplotlib with ``opa``."""
    if name == "plot_branches":
        from opa.plots import plot_branches

        return plot_branches
    raise AttributeError(f"module 'opa' has no attribute {name!r}")


__all__ = [
    "Execution",
    "Oscillator",
    "Problem",
    "ForceLaw",
    "System",
    "SolverOptions",
    "Uncertainty",
    "SimulationError",
    "preset",
    "time_grid",
    "simulate_dmr",
    "simulate_opa",
    "write_netcdf",
    "plot_branches",  # noqa: F405 -- module __getattr__
    "chebyshev_u",
    "cubic_projection",
    "gauss_nodes",
    "project",
    "triple_product",
    # opa.dynamics' functions and classes (its constants are its vocabulary, like ours)
    *(name for name in _dynamics.__all__ if not name.isupper()),
]
