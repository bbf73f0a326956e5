"""The CPU seconds of each figure of a map's report, drawn one after the other in this
process (matplotlib imported first, so its import is not charged to the first figure):
the costs behind :data:`compare._report.FIGURE_COST`, the order in which
``draw_figures`` hands the figures to its processes (issue 29)::

    python benchmarks/figure_times.py OUTDIR/validate.nc [FOLDER for the figures]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time


def figure_times(source: str, outdir: str) -> list[tuple[str, float]]:
    """(figure, CPU seconds) for every figure of the map in ``source``."""
    import xarray as xr

    from compare._mapfigures import _plot_frontier_of, _pyplot
    from compare._mapread import frontier_dataset
    from compare._report import REPORT_FIGURES

    _pyplot()
    with xr.open_dataset(source) as ds:
        ds = ds.load()
    jobs = [(name, fn) for name, fn in REPORT_FIGURES]
    if frontier_dataset(ds) is not None:
        jobs.append(("frontier.png", _plot_frontier_of))
    rows = []
    for name, fn in jobs:
        start = time.process_time()
        fn(ds, os.path.join(outdir, name))
        rows.append((name, time.process_time() - start))
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source")
    parser.add_argument("outdir", nargs="?")
    args = parser.parse_args(argv)
    outdir = args.outdir or tempfile.mkdtemp(prefix="figures-")
    for name, cpu in sorted(figure_times(args.source, outdir), key=lambda r: -r[1]):
        print(f"{cpu:6.2f} s CPU  {name}")


if __name__ == "__main__":
    main()
