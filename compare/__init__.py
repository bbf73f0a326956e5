"""compare: OPA against Monte Carlo — error metrics, the trust map, reports."""

#: where each public name lives: imported on first use, so that ``import compare`` (and
#: any ``compare._module``) stays light until a name is used; "module:name" where the
#: public name is not the module's own
_HOMES = {
    "ValidateConfig": "compare._config", "load_config": "compare._config",
    "compare_runs": "compare._metrics", "error_metrics": "compare._metrics",
    "boundary_table": "compare._tables", "findings": "compare._findings",
    "verdict_grid": "compare._tables", "write_report": "compare._report",
    "count_distribution": "compare._mapdata", "run_validation": "compare._mapflow",
    "verify": "compare._verify", "check_counts": "compare._verify",
    # the map's screen (what opa-mc validate prints) and its workers' preload
    "first_screen": "compare._findings", "cause": "compare._findings",
    "bullet": "compare._findings", "frontier_lines": "compare._findings",
    "wall_text": "compare._report", "map_preload": "compare._scaleout",
    # the convergence study of multi-element OPA (opa-mc converge)
    "ConvergenceConfig": "compare._convergence", "run_convergence": "compare._convergence",
    "convergence_lines": "compare._convergence:summary_lines",
    "write_convergence_report": "compare._convergence:write_report",
    "plot_frontier": "compare._mapfigures",
    # Sobol indices of the true systems, certified (opa-mc sobol)
    "certify_sobol": "compare._certify_sobol",
    # the trust line of several uncertain parameters (opa-mc validate --uncertain mu,c)
    "trust_line": "compare._trustline", "trust_scaled": "compare._trustline:scaled",
    # its map: trust lines over a model parameter's values and horizons, s* bisected
    "trust_map_several": "compare._trustmap_several",
    "check_map_several": "compare._trustmap_several",
    # the paper's figures: matplotlib only when they are asked for
    "reproduce": "compare._figures", "FIGURES": "compare._figures",
}


def __getattr__(name: str):
    """The public names, each from its module on first use."""
    if name in _HOMES:
        import importlib

        module, _, own = _HOMES[name].partition(":")
        value = getattr(importlib.import_module(module), own or name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'compare' has no attribute {name!r}")


__all__ = [
    "ConvergenceConfig",
    "FIGURES",
    "bullet",
    "cause",
    "certify_sobol",
    "check_counts",
    "convergence_lines",
    "first_screen",
    "frontier_lines",
    "map_preload",
    "plot_frontier",
    "run_convergence",
    "wall_text",
    "write_convergence_report",
    "reproduce",
    "trust_line",
    "trust_scaled",
    "trust_map_several",
    "check_map_several",
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
