"""Which sigma* of a trust map moved between two runs, and the verdict at the new bracket.

    python -m benchmarks.map_sigma_moves BEFORE/validate.nc AFTER/validate.nc

Prints a markdown table of every (value, variant, horizon, criterion) whose sigma*
bracket differs, with the AFTER run's three-valued verdict at its bracket's upper end
(``probe_verdict``; "?" where the BEFORE run has no such variable), then the Monte Carlo
work of both runs and AFTER's verdict counts.
"""

from __future__ import annotations

import sys

import numpy as np
import xarray as xr

VERDICTS = {-2: "not formed", -1: "disagrees", 0: "undecided", 1: "agrees"}
HEAD = ("ω", "H", "variant", "criterion", "σ* before", "σ* after",
        "verdict after at the bracket's upper end")


def bracket(lo: float, hi: float) -> str:
    return f"{lo:.3g}–{hi:.3g}" if np.isfinite(hi) else f"≥ {lo:.3g}"


def moves(before: xr.Dataset, after: xr.Dataset) -> list[tuple]:
    rows = []
    values = before[before.attrs["parameter"]].values
    for q, value in enumerate(values):
        for v, name in enumerate(before.variant.values):
            for h, H in enumerate(before.horizon.values):
                for c, criterion in enumerate(("mean", "variance")):
                    old = (float(before.sigma_star[q, v, h, c]),
                           float(before.sigma_star_upper[q, v, h, c]))
                    new = (float(after.sigma_star[q, v, h, c]),
                           float(after.sigma_star_upper[q, v, h, c]))
                    if np.allclose(old, new, equal_nan=True):
                        continue
                    at = np.flatnonzero(np.isclose(after.probe_sigma.values[q], new[1]))
                    verdict = ("?" if "probe_verdict" not in after or not len(at) else
                               VERDICTS[int(after.probe_verdict.values[q, at[0], v, h, c])])
                    rows.append((f"{value:g}", f"{H:g}", str(name), criterion, bracket(*old),
                                 bracket(*new), verdict))
    return rows


def main(argv: list[str]) -> None:
    before, after = (xr.open_dataset(path) for path in argv[:2])
    print("| " + " | ".join(HEAD) + " |")
    print("|" + "---|" * len(HEAD))
    for row in moves(before, after):
        print("| " + " | ".join(row) + " |")
    print()
    for key in ("mc_runs_computed", "true_runs_computed"):
        print(f"{key}: before {before.attrs.get(key)}, after {after.attrs.get(key)}")
    print(f"grid samples summed over the points: before {int(before.mc_samples.sum())}, "
          f"after {int(after.mc_samples.sum())}")
    if "verdict" in after:
        grid = after.verdict.values
        probes = after.probe_verdict.values
        for label, counts in (("grid, mean", grid[..., 0]), ("grid, variance", grid[..., 1]),
                              ("probes", probes)):
            print(f"after, {label}: " + ", ".join(
                f"{VERDICTS[k]} {int((counts == k).sum())}" for k in (-1, 0, 1)))


if __name__ == "__main__":
    main(sys.argv[1:])
