"""The stochastic bifurcation diagram's figure (``opa.dynamics.stochastic_diagram``): the
probability of each attractor type along the control parameter, continuation as lines and
Monte Carlo as points with 2 binomial standard errors, and below it the boundaries in xi
where the type changes, marked by the bifurcation there."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

_BOUNDARY_MARKERS = {"period-doubling": "o", "fold": "s", "grazing": "^",
                     "neimark-sacker": "D", "impulse-impact": "v"}
_STYLES = ["-", "--", "-.", ":"]


def draw_stochastic(ds: xr.Dataset):
    """The figure (not saved; the caller closes it)."""
    param = ds.attrs["sweep_parameter"]
    c = ds[param].values
    fig, (ax_p, ax_b) = plt.subplots(2, 1, figsize=(9, 7.5), sharex=True,
                                     gridspec_kw={"height_ratios": [3, 2]})
    colors = plt.get_cmap("tab10")
    for j, kind in enumerate(ds.type.values):
        style = dict(color=colors(j % 10), ls=_STYLES[(j // 10) % 4])
        p = ds.probability.sel(type=kind).values
        if np.all(p == 0) and np.all(ds.mc_probability.sel(type=kind).values == 0):
            continue
        ax_p.plot(c, p, lw=1.4, label=f"{kind}", **style)
        if ds.attrs.get("samples", 0):
            ax_p.errorbar(c, ds.mc_probability.sel(type=kind).values,
                          yerr=2 * np.nan_to_num(ds.mc_sem.sel(type=kind).values),
                          fmt="o", ms=3, color=style["color"], alpha=0.7, lw=0.8)
    sampled = ds.method.values == 1
    for value in c[sampled]:
        ax_p.axvspan(value, value, color="0.6", lw=3, alpha=0.3)
    ax_p.set_ylim(-0.03, 1.03)
    ax_p.set_ylabel("probability of the attractor type")
    title = (f"{ds.attrs['uncertain']} = {ds.attrs[ds.attrs['uncertain']]:g} + "
             f"{ds.attrs['sigma']:g} ξ, ξ ~ {ds.attrs['distribution']}; lines: "
             f"continuation in ξ")
    if ds.attrs.get("samples", 0):
        title += f"; points: Monte Carlo ({ds.attrs['samples']} samples) ± 2 SE"
    ax_p.set_title(title, fontsize=9)
    ax_p.legend(title="type z = n/p", fontsize=8, loc="center left",
                bbox_to_anchor=(1.01, 0.5))
    kinds = sorted({str(k) for k in ds.boundary_kind.values.ravel() if str(k)})
    for kind in kinds:
        mask = ds.boundary_kind.values == kind
        rows, cols = np.nonzero(mask)
        ax_b.plot(c[rows], ds.boundary_xi.values[rows, cols], ls="none",
                  marker=_BOUNDARY_MARKERS.get(kind, "x"), ms=4, label=kind)
    ax_b.set_ylim(-1.05, 1.05)
    ax_b.set_ylabel("boundary in ξ")
    ax_b.set_xlabel(f"control parameter {param}")
    if kinds:
        ax_b.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
    if sampled.any():
        ax_b.set_title("grey: values where continuation cannot follow (Monte Carlo decides)",
                       fontsize=8)
    fig.tight_layout()
    return fig


def plot_stochastic(ds: xr.Dataset, path: str) -> None:
    """Write the figure of :func:`draw_stochastic` to ``path``."""
    fig = draw_stochastic(ds)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


__all__ = ["draw_stochastic", "plot_stochastic"]
