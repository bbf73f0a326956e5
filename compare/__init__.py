"""compare: OPA against Monte Carlo — errors, convergence studies, reports, validate."""

from compare._metrics import compare_runs, error_metrics
from compare._report import error_table, write_report
from compare._validate import ValidateConfig, load_config, run_validation

__all__ = [
    "compare_runs",
    "error_metrics",
    "error_table",
    "write_report",
    "ValidateConfig",
    "load_config",
    "run_validation",
]
