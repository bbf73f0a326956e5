"""The stochastic bifurcation diagram's figure (``opa.dynamics.stochastic_diagram``).

Left column: the sampled systems' Poincaré points (stroboscopic x of each sample's
attractor) shaded by probability, each sample carrying 1/M of the mass spread over its
points, so that a column of the image is the law of the steady-state section at that
control value; below, the probability of each attractor type, continuation as lines and
Monte Carlo as points with 2 binomial standard errors. Right column, when the dataset
holds it (``emr=True``): the paper's diagram of the EMR (the OPA mean at the same sigma)
on the same axes; below it, the boundaries in xi where the type changes (the
two-parameter bifurcation curves xi*(control)), marked by the bifurcation there. A
diagram of several uncertain parameters has no boundaries (its attribute ``boundaries``
says why): the figure is the points and the sampled probabilities with 2 standard errors.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

_BOUNDARY_MARKERS = {"period-doubling": "o", "fold": "s", "grazing": "^",
                     "neimark-sacker": "D", "impulse-impact": "v"}
_STYLES = ["-", "--", "-.", ":"]
#: bins of x in the shaded panel
X_BINS = 240


def section_density(ds: xr.Dataset, bins: int = X_BINS):
    """The probability mass of the samples' stroboscopic x per bin at each control value:
    ``(edges of the control values, edges of x, mass (values, bins))``; each sample
    carries 1/M spread evenly over its points."""
    param = ds.attrs["sweep_parameter"]
    values = ds[param].values
    x = ds.mc_x.values.astype(float)  # (values, sample, point)
    finite = np.isfinite(x)
    lo, hi = (np.nanmin(x), np.nanmax(x)) if finite.any() else (-1.0, 1.0)
    pad = 0.02 * (hi - lo) if hi > lo else 0.5
    x_edges = np.linspace(lo - pad, hi + pad, bins + 1)
    mass = np.zeros((len(values), bins))
    for i in range(len(values)):
        count = finite[i].sum(axis=1)  # points per sample
        used = count > 0
        if not used.any():
            continue
        weight = np.where(finite[i], 1.0 / np.maximum(count, 1)[:, None], 0.0) / used.sum()
        mass[i] = np.histogram(x[i][finite[i]], bins=x_edges, weights=weight[finite[i]])[0]
    if len(values) > 1:
        mid = 0.5 * (values[1:] + values[:-1])
        c_edges = np.concatenate([[2 * values[0] - mid[0]], mid, [2 * values[-1] - mid[-1]]])
    else:
        c_edges = np.array([values[0] - 0.5, values[0] + 0.5])
    return c_edges, x_edges, mass


def _density_colours():
    """Light blue (rare, still visible on white) to dark blue (likely): the rarest bins of
    a log scale must not fade into the background."""
    from matplotlib.colors import LinearSegmentedColormap

    return LinearSegmentedColormap.from_list(
        "density", plt.get_cmap("Blues")(np.linspace(0.35, 1.0, 256)))


def _label_branches(ax, ds: xr.Dataset, c: np.ndarray) -> None:
    """Name each attractor type's branch once, on its uppermost point at the control
    value where the type is most likely (a type's points lie on several branches: the
    median could fall between them)."""
    types = ds.mc_type.values.astype(str)  # (value, sample)
    x = ds.mc_x.values.astype(float)  # (value, sample, point)
    for kind in ds.type.values:
        share = (types == str(kind)).mean(axis=1)
        if not share.any() or share.max() < 0.01:
            continue
        i = int(np.argmax(share))
        points = x[i][types[i] == str(kind)]
        points = points[np.isfinite(points)]
        if not len(points):
            continue
        ax.annotate(str(kind), (c[i], float(points.max())), xytext=(6, -14),
                    textcoords="offset points", fontsize=8, color="black",
                    bbox=dict(boxstyle="round,pad=0.15", facecolor="white", edgecolor="0.5",
                              alpha=0.85),
                    arrowprops=dict(arrowstyle="-", color="0.4", lw=0.6))


def draw_stochastic(ds: xr.Dataset):
    """The figure (not saved; the caller closes it). Axes in order: the shaded points,
    the probabilities, then (with the EMR) the EMR's diagram and the boundaries, or
    (without) the boundaries."""
    from opa.plots._diagrams import SYMBOLS

    param = ds.attrs["sweep_parameter"]
    c = ds[param].values
    emr = "emr_x" in ds
    bounded = "boundary_kind" in ds  # several uncertain parameters: none located
    if not bounded:
        fig, (ax_pts, ax_p) = plt.subplots(2, 1, figsize=(9, 7), sharex=True,
                                           gridspec_kw={"height_ratios": [3, 2]},
                                           layout="constrained")
        ax_b = ax_emr = None
    elif emr:
        fig, axes = plt.subplots(2, 2, figsize=(13, 8), sharex=True,
                                 gridspec_kw={"height_ratios": [3, 2]}, layout="constrained")
        ax_pts, ax_emr, ax_p, ax_b = axes[0, 0], axes[0, 1], axes[1, 0], axes[1, 1]
    else:
        fig, axes = plt.subplots(3, 1, figsize=(9, 10), sharex=True,
                                 gridspec_kw={"height_ratios": [3, 2, 2]},
                                 layout="constrained")
        ax_pts, ax_p, ax_b = axes
        ax_emr = None
    name = SYMBOLS.get(param, param)
    has_samples = ds.sizes.get("sample", 0) > 0 and np.isfinite(ds.mc_x.values).any()
    if has_samples:
        c_edges, x_edges, mass = section_density(ds)
        shown = np.where(mass > 0, mass, np.nan)
        top = max(float(np.nanmax(shown)), 1e-3) if np.isfinite(shown).any() else 1.0
        mesh = ax_pts.pcolormesh(c_edges, x_edges, shown.T, cmap=_density_colours(),
                                 norm=LogNorm(vmin=max(top * 1e-4, 1e-6), vmax=top),
                                 shading="flat")
        fig.colorbar(mesh, ax=ax_pts, label="probability per bin", pad=0.01)
        _label_branches(ax_pts, ds, c)
    else:
        ax_pts.text(0.5, 0.5, "no samples", ha="center", va="center",
                    transform=ax_pts.transAxes)
    ax_pts.set_ylabel("x at t = k 2π/ω (steady state)")
    ax_pts.set_title(f"sampled systems' Poincaré points, shaded by probability "
                     f"({ds.attrs['samples']} samples per value)", fontsize=9)
    if emr:
        ax_emr.plot(np.broadcast_to(c[:, None], ds.emr_x.shape)[np.isfinite(ds.emr_x.values)],
                    ds.emr_x.values[np.isfinite(ds.emr_x.values)], ".", color="black",
                    ms=2.2, alpha=0.75)
        ax_emr.set_ylim(ax_pts.get_ylim())
        ax_emr.set_ylabel("x_0 at t = k 2π/ω")
        ax_emr.set_title(f"EMR (OPA N = {ds.attrs['emr_order']}, σ = {ds.attrs['sigma']:g}): "
                         f"the paper's diagram", fontsize=9)
    colors = plt.get_cmap("tab10")
    for j, kind in enumerate(ds.type.values):
        style = dict(color=colors(j % 10), ls=_STYLES[(j // 10) % 4])
        p = ds.probability.sel(type=kind).values
        m = ds.mc_probability.sel(type=kind).values
        if np.all(p < 0.01) and np.all(m < 0.01):
            continue  # the figure's legend lists the types that matter somewhere
        ax_p.plot(c, p, lw=1.4 if bounded else 0.8, label=f"{kind}", **style)
        if ds.attrs.get("samples", 0):
            ax_p.errorbar(c, m, yerr=2 * np.nan_to_num(ds.mc_sem.sel(type=kind).values),
                          fmt="o", ms=2.5, color=style["color"], alpha=0.7, lw=0.8)
    sampled = (ds.method.values == 1) & bounded  # grey: where sampling decides
    for value in c[sampled]:
        ax_p.axvspan(value, value, color="0.6", lw=3, alpha=0.3)
    ax_p.set_ylim(-0.03, 1.03)
    ax_p.set_ylabel("probability of the attractor type")
    title = _uncertainty_title(ds) + ("; lines: continuation in ξ (grey: Monte Carlo "
                                      "decides)" if bounded else "")
    if ds.attrs.get("samples", 0):
        title += ("; points: Monte Carlo ± 2 SE" if bounded else
                  f";\npoints: {ds.attrs['samples']} scrambled Sobol' samples ± 2 SE (from "
                  f"{ds.attrs['scramblings']} scramblings); no boundaries: continuation "
                  f"in ξ is one-dimensional")
    ax_p.set_title(title, fontsize=8)
    ax_p.legend(title="type", fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    if not bounded:
        ax_p.set_xlabel(f"control parameter {name}")
        return fig
    kinds = sorted({str(k) for k in ds.boundary_kind.values.ravel() if str(k)})
    for kind in kinds:
        mask = ds.boundary_kind.values == kind
        rows, cols = np.nonzero(mask)
        ax_b.plot(c[rows], ds.boundary_xi.values[rows, cols], ls="none",
                  marker=_BOUNDARY_MARKERS.get(kind, "x"), ms=3.5, label=kind)
    ax_b.set_ylim(-1.05, 1.05)
    ax_b.set_ylabel("boundary ξ*")
    ax_b.set_title("boundaries in ξ where the type changes (located bifurcations)",
                   fontsize=8)
    if kinds:
        ax_b.legend(fontsize=7, loc="best")
    for ax in (ax_p, ax_b) if emr else (ax_b,):
        ax.set_xlabel(f"control parameter {name}")
    return fig


def _uncertainty_title(ds: xr.Dataset) -> str:
    """``mu = 0.8 + 0.03 ξ, ξ ~ semicircle``, or with several uncertain parameters one
    term each: ``mu = 0.8 + 0.03 ξ1, c = 0.05 + 0.005 ξ2, ξ ~ semicircle,uniform``."""
    names = str(ds.attrs["uncertain"]).split(",")
    sigma = np.atleast_1d(ds.attrs["sigma"])
    xi = ["ξ"] if len(names) == 1 else [f"ξ{j + 1}" for j in range(len(names))]
    terms = ", ".join(f"{n} = {float(ds.attrs[n]):g} + {float(s):g} {x}"
                      for n, s, x in zip(names, sigma, xi))
    return f"{terms}, ξ ~ {ds.attrs['distribution']}"


def plot_stochastic(ds: xr.Dataset, path: str) -> None:
    """Write the figure of :func:`draw_stochastic` to ``path``."""
    fig = draw_stochastic(ds)
    fig.savefig(path, dpi=120)
    plt.close(fig)


__all__ = ["draw_stochastic", "plot_stochastic", "section_density"]
