"""Branch diagrams of continuation datasets (``opa.continue_orbits``): stable orbits
solid, unstable dashed, located bifurcations marked."""

from __future__ import annotations

import numpy as np
import xarray as xr

from opa.dynamics._continuation import BIFURCATION_KINDS

BIFURCATION_MARKERS = {"period-doubling": ("o", "tab:red"), "fold": ("s", "k"),
           "neimark-sacker": ("D", "tab:purple"), "grazing": ("^", "tab:green"),
           "impulse-impact": ("x", "tab:brown")}


def plot_branches(ds: xr.Dataset, path: str | None = None, *, ax=None, coordinate: str = "x"):
    """Branch diagram: stable orbits solid, unstable dashed, bifurcations marked.

    ``coordinate``: ``"x"`` (x_0 at the stroboscopic times) or ``"v"``. Draws on ``ax``
    if given (e.g. over a brute-force bifurcation diagram), writes ``path`` if given.
    Returns the matplotlib axes.
    """
    import matplotlib

    if ax is None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    parameter = ds.attrs["parameter"]
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(8, 5))
    sec = ds[f"section_{coordinate}"]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    periods = sorted(set(int(k) for k in ds.branch_period.values))
    labelled = set()
    for b in np.unique(ds.branch.values):
        sel = ds.branch.values == b
        lam = ds[parameter].values[sel]
        stable = ds.stable.values[sel].astype(bool)
        k = int(ds.period.values[sel][0])
        colour = colours[periods.index(k) % len(colours)]  # one colour per period
        for j in range(k):
            y = sec.values[sel, j]
            for flag, style in ((True, "-"), (False, "--")):
                yy = np.where(stable == flag, y, np.nan)
                # join a run to its neighbour so stable and unstable parts meet
                edge = np.zeros_like(stable)
                edge[:-1] |= (stable[:-1] != stable[1:]) & (stable[1:] == flag)
                yy = np.where(edge, y, yy)
                label = None
                if (k, flag) not in labelled:
                    label = f"period {k}, {'stable' if flag else 'unstable'}"
                    labelled.add((k, flag))
                ax.plot(lam, yy, style, color=colour, lw=1.2, label=label)
    for kind, (marker, colour) in BIFURCATION_MARKERS.items():
        sel = ds.bifurcation_kind.values == BIFURCATION_KINDS.index(kind)
        if sel.any():
            ax.plot(ds[f"bifurcation_{parameter}"].values[sel],
                    ds[f"bifurcation_{coordinate}"].values[sel], marker, color=colour,
                    ms=7, mfc="none", mew=1.5, ls="none", label=kind)
    ax.set_xlabel(parameter)
    ax.set_ylabel(f"{coordinate}_0 at t0 + j 2π/ω")
    ax.set_title(f"{ds.attrs['model'].upper()} (N = {ds.attrs['N']}, σ = {ds.attrs['sigma']:g}): "
                 "stable solid, unstable dashed")
    ax.legend(fontsize=8, loc="best")
    if own:
        fig.tight_layout()
        if path:
            fig.savefig(path, dpi=120)
        plt.close(fig)
    return ax
