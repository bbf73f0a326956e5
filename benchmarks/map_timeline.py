"""The trust map's tasks as they finish: which task holds the map up (issue 29).

Runs the map's flow (:class:`compare._mapflow.MapFlow`) on ``--workers`` local processes
and prints, for every task in the order it finished, the seconds from the flow's start
to its end and the CPU seconds of its phases, then the longest tasks. Warm (numba's
cache filled) and with a fresh output folder, the CPU seconds are each task's own cost::

    python benchmarks/map_timeline.py OUTDIR [--workers 2] [validate's TOML file]
"""

from __future__ import annotations

import argparse
import time


def timeline(cfg, workers: int) -> list[tuple]:
    """(key, seconds from the start to the task's end, its CPU seconds) per task, in the
    order they finished."""
    from compare._mapflow import MapFlow
    from compare._scaleout import run_flow
    from compare._scaleout import MAP_PRELOAD
    from opa.engine import Execution, Store

    flow = MapFlow(cfg, Store(f"{cfg.outdir}/parts", "trust map"))
    start = time.perf_counter()
    rows = []
    for key, result in run_flow(flow.first(), flow.follow, preload=MAP_PRELOAD,
                                execution=Execution(workers=workers)):
        # each task returns its ledger: phase -> (wall s, CPU s, calls)
        cpu = sum(row[1] for row in result["ledger"].phases.values())
        rows.append((key, time.perf_counter() - start, cpu))
    return rows


def main(argv=None) -> None:
    from compare._config import load_config

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("outdir")
    parser.add_argument("config", nargs="?")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    cfg = load_config(args.config, outdir=args.outdir, workers=args.workers)
    rows = timeline(cfg, args.workers)
    for key, end, cpu in rows:
        print(f"{end:8.2f} s  {cpu:6.2f} s CPU  {key}")
    print(f"\n{len(rows)} tasks in {rows[-1][1]:.2f} s on {args.workers} processes, "
          f"{sum(r[2] for r in rows):.2f} s CPU; the longest:")
    for key, _, cpu in sorted(rows, key=lambda r: -r[2])[:8]:
        print(f"  {cpu:6.2f} s  {key}")


if __name__ == "__main__":
    main()
