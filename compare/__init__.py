"""compare: OPA against Monte Carlo — error metrics, the trust map, reports."""

from compare._config import ValidateConfig, load_config
from compare._metrics import compare_runs, error_metrics
from compare._report import boundary_table, findings, verdict_grid, write_report
from compare._mapdata import count_distribution
from compare._mapflow import run_validation
from compare._verify import verify



def __getattr__(name: str):
    """``compare.reproduce`` (the paper's figures) without importing matplotlib with
    ``compare``."""
    if name in ("reproduce", "FIGURES"):
        from compare import _figures

        return getattr(_figures, name)
    raise AttributeError(f"module 'compare' has no attribute {name!r}")


__all__ = [
    "FIGURES",
    "reproduce",
    "ValidateConfig",
    "boundary_table",
    "compare_runs",
    "count_distribution",
    "error_metrics",
    "findings",
    "load_config",
    "run_validation",
    "verdict_grid",
    "verify",
    "write_report",
]
