"""The phase table of one or more trust maps, side by side: CPU seconds per phase (summed
over the workers), the map's wall time and the true impact systems it integrated.

    python benchmarks/map_phases.py OUTDIR/validate.nc [OTHER/validate.nc ...]

Each file's attributes are read as written by ``opa-mc validate`` (``phase_names``,
``phase_cpu_seconds``, ``wall_seconds``, ``true_system_runs``); nothing is recomputed.
"""

from __future__ import annotations

import sys

import xarray as xr


def phases(path: str) -> tuple[dict[str, float], float, int]:
    """({phase: CPU seconds}, wall seconds, true-system runs) of one validate.nc."""
    with xr.open_dataset(path) as ds:
        a = ds.attrs
        names = str(a["phase_names"]).split(",")
        cpu = {name: float(s) for name, s in zip(names, a["phase_cpu_seconds"])}
        return cpu, float(a["wall_seconds"]), int(a["true_system_runs"])


def main(paths: list[str]) -> None:
    tables = [phases(p) for p in paths]
    names = sorted({n for cpu, _, _ in tables for n in cpu},
                   key=lambda n: -max(cpu.get(n, 0.0) for cpu, _, _ in tables))
    print("| phase | " + " | ".join(paths) + " |")
    print("|---" * (len(paths) + 1) + "|")
    for name in names:
        print(f"| {name} | " + " | ".join(f"{cpu.get(name, 0.0):.1f}" for cpu, _, _ in tables)
              + " |")
    work = [sum(v for k, v in cpu.items() if k != "waiting for workers") for cpu, _, _ in tables]
    print("| CPU of the phases (not the wait) | " + " | ".join(f"{w:.1f}" for w in work) + " |")
    print("| map wall seconds | " + " | ".join(f"{w:.1f}" for _, w, _ in tables) + " |")
    print("| true-system runs | " + " | ".join(f"{r:,}" for _, _, r in tables) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
