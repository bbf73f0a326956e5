"""compare: OPA against Monte Carlo — error metrics, the trust map, reports."""

from compare._metrics import compare_runs, error_metrics
from compare._report import boundary_table, findings, verdict_grid, write_report
from compare._trustmap import ValidateConfig, count_distribution, load_config, run_validation

__all__ = [
    "ValidateConfig",
    "boundary_table",
    "compare_runs",
    "count_distribution",
    "error_metrics",
    "findings",
    "load_config",
    "run_validation",
    "verdict_grid",
    "write_report",
]
