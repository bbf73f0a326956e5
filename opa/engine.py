"""The building blocks that the packages above ``opa`` (``mc``, ``compare``) build on:
runs of the compiled kernel, the system and its law of xi, multi-element OPA, the splits
of the sampled systems, the OPA surrogate, datasets and the one resume store, and the
brute-force sweep. Users want ``opa``'s own public names; this module is the one door
through which ``mc`` and ``compare`` reach ``opa``'s private modules (the architecture
test forbids them ``from opa._x import``), so each name here is a commitment.
"""

from opa._basis import chebyshev_u, gauss_nodes, orthonormal, quadrature_order
from opa._boxes import MAX_BOXES
from opa._chaos import MAX_CHAOS_TERMS, ChaosBasis
from opa._forcelaw import OSCILLATOR_COEFFICIENTS
from opa._modelfile import read_model, uncertain_problem
from opa._problem import split_list
from opa._dataset import (
    COMMAND,
    Store,
    atomic_write,
    check_opa_layout,
    digest,
    first_non_finite,
    package_version,
    provenance_attrs,
    read_toml,
    remove_store,
    time_coord,
    write_netcdf,
)
from opa._elements import (
    MAX_ELEMENTS,
    ElementBudgetWarning,
    adaptive_edges,
    collocate_element,
    collocation,
    global_coefficients,
    run_elements,
    true_runs,
    uniform_edges,
)
from opa._execution import (
    DaskError,
    Execution,
    connect_scheduler,
    take_execution,
)
from opa._gpu import require as require_gpu
from opa._lock import OutputLock
from opa._measure import Measure, parse
from opa._memory import check_memory
from opa._model import (
    MAX_GRID,
    PARAMETER_NAMES,
    Oscillator,
    SolverOptions,
    check_count,
    check_instance,
    check_scheduler_address,
    check_order,
    check_span,
    preset,
    time_grid,
)
from opa._sensitivity import SobolIndices, sobol_indices
from opa._run import STATUS_NAMES, SimulationError, add_true_system_work, \
    announce_compilation, \
    follow_thread_grant, output_times, run_batch, set_threads, thread_count, \
    true_system_work, usable_cores
from opa._simulate import default_impact_law, opa_variants, simulate_dmr, simulate_opa
from opa._splits import (
    CHATTER_WINDOW,
    MAX_CROSSINGS,
    MAX_SPLITS,
    MIN_SPLITS,
    SPLIT_KINDS,
    SampledRuns,
    ScanOptions,
    Split,
    count_probabilities,
    event_sequence,
    scan_splits,
)
from opa._surrogate import (
    run_measure,
    surrogate,
    surrogate_moments,
    surrogate_several,
    surrogate_values,
)
from opa._system import IMPULSE_FIELDS, System, as_system
from opa._work import (
    WorkBudgetError,
    budget,
    check_steps,
    check_work,
    parse_duration,
    process_started,
)
from opa.dynamics._orbits import MAX_CYCLE, impulse_cycle
from opa.dynamics._sections import identify_motion, mean_state, phase_section
from opa.dynamics._sweep import local_executor, locate_setup, pool_shared, summary_lines, sweep, \
    start_fork_server, sweep_times

__all__ = [
    # what opa.cli takes besides (the command line's provenance, the work budget, the
    # compilation notice, the map's fork server, the rule of a failed run's numbers)
    "COMMAND", "WorkBudgetError", "announce_compilation",
    "budget", "first_non_finite", "parse_duration", "process_started", "start_fork_server",
    "DaskError", "Execution", "connect_scheduler",
    "take_execution", "set_threads", "thread_count",
    "ChaosBasis", "MAX_CHAOS_TERMS", "SobolIndices", "sobol_indices",
    "CHATTER_WINDOW", "ElementBudgetWarning", "IMPULSE_FIELDS", "MAX_CROSSINGS", "MAX_CYCLE",
    "add_true_system_work",
    "MAX_BOXES", "MAX_ELEMENTS", "MAX_GRID", "MAX_SPLITS", "MIN_SPLITS", "Measure", "Oscillator",
    "OutputLock", "check_steps", "check_work", "check_scheduler_address",
    "PARAMETER_NAMES", "SPLIT_KINDS", "STATUS_NAMES",
    "SampledRuns", "ScanOptions",
    "SimulationError", "SolverOptions", "Split", "Store", "System", "adaptive_edges",
    "as_system", "atomic_write", "chebyshev_u", "check_count", "check_instance",
    "check_memory", "check_opa_layout", "check_order", "check_span", "collocate_element",
    "collocation", "count_probabilities", "default_impact_law", "digest", "event_sequence",
    "gauss_nodes",
    "follow_thread_grant", "global_coefficients", "identify_motion", "impulse_cycle",
    "local_executor",
    "locate_setup", "mean_state", "opa_variants", "orthonormal", "output_times",
    "package_version", "parse", "phase_section", "pool_shared", "preset", "provenance_attrs",
    "quadrature_order", "read_toml", "remove_store", "require_gpu", "run_batch",
    "split_list", "OSCILLATOR_COEFFICIENTS", "read_model", "uncertain_problem",
    "run_elements", "run_measure",
    "true_system_work",
    "usable_cores",
    "scan_splits", "simulate_dmr", "simulate_opa", "summary_lines", "surrogate",
    "surrogate_moments", "surrogate_several", "surrogate_values", "sweep", "sweep_times",
    "time_coord",
    "time_grid", "true_runs", "uniform_edges", "write_netcdf",
]
