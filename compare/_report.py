"""summary.md and the figures of a trust-map dataset: :func:`write_report`, and the
process pool that draws the figures while this process writes the summary
(:func:`start_figures`).

Everything here is read off the dataset that :func:`compare.run_validation` wrote; nothing
is assumed about the model. The headline is the boundary table: sigma* per swept value and
horizon, beside the nearest split of the sampled systems' impact sequences. The sentences
come from :mod:`compare._findings`, the tables from :mod:`compare._tables`, the figures
from :mod:`compare._mapfigures`.
"""

from __future__ import annotations

import os

import xarray as xr

from compare._findings import cause, findings, first_screen, frontier_lines, run_failures
from compare._mapfigures import (
    _plot_frontier_of, plot_error_vs_order, plot_map, plot_mean, plot_phase, plot_variance,
)
from compare._mapread import (
    _element_variants, _g, _laws, _vals, check_map, frontier_dataset, nominal,
)
from compare._tables import boundary_table, count_table, verdict_grid


# -- summary.md -----------------------------------------------------------------------------
def wall_text(seconds: dict) -> str:
    """'12.4 s (map 10.1 s, report 2.3 s)': the wall times of one run, read off one clock."""
    parts = ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items() if k != "total")
    return f"{seconds['total']:.1f} s" + (f" ({parts})" if parts else "")


# -- the figures, drawn on a process pool while the summary is written ----------------------
#: the report's figures: file name and drawing function (:mod:`compare._mapfigures`)
REPORT_FIGURES = (("trust_map.png", plot_map), ("error_vs_N.png", plot_error_vs_order),
                  ("mean_vs_mc.png", plot_mean), ("variance.png", plot_variance),
                  ("phase.png", plot_phase))

#: CPU seconds of each figure of the default map on the 2-core machine (one process,
#: matplotlib imported first: ``python benchmarks/figure_times.py OUTDIR/validate.nc``):
#: the order in which start_figures hands them to its processes
FIGURE_COST = {"frontier.png": 2.11, "error_vs_N.png": 1.12, "trust_map.png": 0.95,
               "variance.png": 0.64, "mean_vs_mc.png": 0.55, "phase.png": 0.24}


def draw_figures(ds: xr.Dataset, outdir: str, *, workers: int = 1,
                 source: str | None = None) -> list[str]:
    """The report's figures (:data:`REPORT_FIGURES`, then the frontier's when the map has one),
    drawn in this process or, with ``workers`` > 1, side by side on that many processes
    of :func:`opa.engine.local_executor` (each figure depends on ``ds`` alone; the files
    are the same either way). ``source``: a netCDF file that holds ``ds`` (the map's
    validate.nc), which the processes open instead of each receiving a copy of ``ds``.
    Returns the written paths in the order of the figures."""
    return start_figures(ds, outdir, workers=workers, source=source)()


def start_figures(ds: xr.Dataset, outdir: str, *, workers: int = 1,
                  source: str | None = None):
    """:func:`draw_figures` in two steps: with ``workers`` > 1 the figures start on their
    processes now, and the function returned waits for them (and ends the processes)
    and returns the paths, so that this process can write the summary meanwhile; with
    one, they are drawn here when that function is called."""
    check_map(ds, "figures")
    jobs = [(fn, name) for name, fn in REPORT_FIGURES]
    if frontier_dataset(ds) is not None:
        jobs.append((_plot_frontier_of, "frontier.png"))
    if workers <= 1:
        return lambda: _paths([fn(ds, os.path.join(outdir, name)) for fn, name in jobs])
    from opa.engine import local_executor

    data = ds if source is None else source
    # the longest first, so that no long figure starts last (FIGURE_COST)
    order = sorted(range(len(jobs)), key=lambda k: -FIGURE_COST.get(jobs[k][1], 0.0))
    pool = local_executor(min(int(workers), len(jobs)))
    try:
        futures = {k: pool.submit(_draw, jobs[k][0], data, os.path.join(outdir, jobs[k][1]))
                   for k in order}
    except BaseException:
        pool.shutdown(cancel_futures=True)
        raise

    def finish() -> list[str]:
        try:
            return _paths([futures[k].result() for k in range(len(jobs))])
        finally:
            pool.shutdown(cancel_futures=True)

    return finish


def _paths(done) -> list[str]:
    """The written paths of the figures, in order (a figure may write several)."""
    paths = []
    for written in done:
        paths += [written] if isinstance(written, str) else list(written)
    return paths


def _draw(fn, data, path: str):
    """``fn(ds, path)`` on a worker: ``data`` is the map, or a netCDF file that holds it."""
    if isinstance(data, str):
        with xr.open_dataset(data) as ds:
            return fn(ds, path)
    return fn(data, path)


def write_report(ds: xr.Dataset, outdir: str, *, plots: bool = True,
                 command: str = "opa-mc validate", started: float | None = None,
                 timing: dict | None = None, workers: int = 1,
                 source: str | None = None) -> list[str]:
    """Write summary.md and the figures; returns the written paths.

    ``workers``: processes that draw the figures side by side, ``source``: the netCDF
    file of ``ds`` they read it from (:func:`draw_figures`).

    ``started``: the ``time.perf_counter()`` reading at which the command started, the
    same clock as ``run_validation(started=...)``: summary.md then gives the time from it
    to the finished report, split into the map (the dataset's ``wall_seconds``) and the
    report. Without it summary.md gives the map's time only. ``timing``, a dict, receives
    those times (keys total, map, report), for the caller to print the same numbers."""
    import time

    check_map(ds, "write_report")
    os.makedirs(outdir, exist_ok=True)
    # the figures' processes draw while this one writes the summary
    figures = (start_figures(ds, outdir, workers=workers, source=source) if plots
               else (lambda: []))
    try:
        lines = _summary_lines(ds, command)
    finally:
        paths = figures()
    a = ds.attrs
    seconds = {"total": float(a["wall_seconds"])}
    if started is not None:
        seconds = {"total": time.perf_counter() - started, "map": float(a["wall_seconds"])}
        seconds["report"] = seconds["total"] - seconds["map"]
    lines = [line.replace(_WALL_TIME, wall_text(seconds)) for line in lines]
    if plots:
        lines += ["## Figures", ""] + [f"![{os.path.basename(p)}]({os.path.basename(p)})"
                                       for p in paths] + [""]
    md = os.path.join(outdir, "summary.md")
    with open(md, "w") as fh:
        fh.write("\n".join(lines))
    if timing is not None:
        timing.update(seconds)
    return [md] + paths


#: where summary.md's wall time goes, once the figures are drawn
_WALL_TIME = "\x00wall time\x00"


def _summary_lines(ds: xr.Dataset, command: str) -> list[str]:
    """summary.md's lines but its figures, the wall time a placeholder (``_WALL_TIME``)."""
    a = ds.attrs
    value_text = ", ".join(_g(float(v)) for v in _vals(ds).values)
    lines = [
        "# opa-mc validate: where OPA agrees with Monte Carlo", "",
        "```text", *first_screen(ds), "```", "",
        f"Command: `{command}` (wall time {_WALL_TIME}; computed: "
        f"{a['mc_runs_computed']} Monte Carlo runs, {a['opa_runs_computed']} OPA runs, "
        f"{a['parts_computed']} parts in all (splits and the frontier included); the rest "
        f"reused from parts/).", "",
        f"Model: preset {a['preset']} (" + ", ".join(
            f"{k} = {a[k]:g}" for k in ("mu", "a", "c", "f", "omega", "eta", "delta", "F0")
            if k in a) + f", {a['impulse']} impulses), {a['parameter']} swept over "
        f"{value_text}, uncertain {a['uncertain']} "
        f"= {_g(nominal(ds))} + σ ξ, ξ ~ {a.get('distribution', 'semicircle')}, σ in "
        f"{', '.join(_g(float(s)) for s in ds.sigma.values)}; "
        f"N = {int(ds.N.min())}..{int(ds.N.max())}; rtol = {a['rtol']:g}, atol = "
        f"{a['atol']:g}; Monte "
        f"Carlo: scrambled Sobol, {a['samples']} samples, doubled up to {a['max_samples']} "
        f"while a verdict is undecided, seed {a['seed']}.", "",
        f"Criterion: {a['criterion_text']}; tol = {a['tolerance']:g} (mean), "
        f"{a['var_tolerance']:g} (variance), alpha = {a['alpha']:g}.", "",
    ]
    if a.get("variants_dropped", "none") != "none":
        lines += [f"Variants left out: {a['variants_dropped']}.", ""]
    if _element_variants(ds):
        lines += [f"Multi-element variants ({a.get('elements')} elements"
                  + (f", budget {a['max_elements']}" if "max_elements" in a else "")
                  + f"): {a.get('element_text', '')}.", ""]
    fails = run_failures(ds)
    if fails:
        lines += ["## Runs that did not finish", ""] + [f"- {f}." for f in fails] + [""]
    lines += [
        "## Trust boundary", "", boundary_table(ds, markdown=True), "",
        boundary_table(ds, markdown=True, criterion=1), "",
        "## Why it breaks", "",
    ]
    for q in range(len(_vals(ds))):
        for h in range(len(ds.horizon)):
            lines.append(f"- {cause(ds, q, h)}")
            for v in _element_variants(ds):
                lines.append(f"- {cause(ds, q, h, v)}")
    lines += ["", "## Findings", ""] + [f"- {f}" for f in findings(ds)] + [""]
    front = frontier_lines(ds)
    if front:
        from compare._convergence import table as frontier_table

        lines += ["## Cost and accuracy", "", front[0], ""] + [f"- {f}" for f in front[1:]]
        lines += ["", frontier_table(frontier_dataset(ds)), ""]
    lines += ["## Verdicts", ""]
    for h in range(len(ds.horizon)):
        lines += [verdict_grid(ds, h, markdown=True), ""]
        for v in _laws(ds)[1:]:
            lines += [verdict_grid(ds, h, v=v, markdown=True), ""]
        for v in _laws(ds):
            lines += [verdict_grid(ds, h, v=v, criterion=1, markdown=True), ""]
    lines += ["## Impact counts", ""]
    for h in range(len(ds.horizon)):
        lines += [count_table(ds, h), ""]
    return lines


__all__ = ["FIGURE_COST", "REPORT_FIGURES", "draw_figures", "start_figures", "wall_text",
           "write_report"]
