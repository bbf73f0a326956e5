"""compare: OPA against Monte Carlo — error metrics, the trust map, reports."""

#: where each public name lives: imported on first use, so that ``import compare`` (and
#: any ``compare._module``) stays light until a name is used
_HOMES = {
    "ValidateConfig": "compare._config", "load_config": "compare._config",
    "compare_runs": "compare._metrics", "error_metrics": "compare._metrics",
    "boundary_table": "compare._tables", "findings": "compare._findings",
    "verdict_grid": "compare._tables", "write_report": "compare._report",
    "count_distribution": "compare._mapdata", "run_validation": "compare._mapflow",
    "verify": "compare._verify",
    # the paper's figures: matplotlib only when they are asked for
    "reproduce": "compare._figures", "FIGURES": "compare._figures",
}


def __getattr__(name: str):
    """The public names, each from its module on first use."""
    if name in _HOMES:
        import importlib

        value = getattr(importlib.import_module(_HOMES[name]), name)
        globals()[name] = value
        return value
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
