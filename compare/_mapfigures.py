"""The trust map's figures, drawn with matplotlib (imported when a figure is drawn):
the map itself, the error against N, the mean and the variance beside Monte Carlo, the
phase portraits and the cost-accuracy frontier. Each reads the trust-map dataset alone
(:mod:`compare._mapread`) and writes one PNG file."""

from __future__ import annotations

import numpy as np
import xarray as xr

from compare._mapread import (
    HEADLINE, _element_variants, _g, _kinds, _laws, _par, _time, _vals, _window_sem,
    _window_tolerance, check_map, frontier_dataset, nominal,
)

#: the markers of the variants (error_vs_N.png) and of the orders (mean_vs_mc.png)
VARIANT_MARKERS = ("o", "s", "^", "v", "D")
KIND_COLOURS = {"grazing": "tab:red", "extra impact": "gold", "chatter": "tab:cyan",
                "impulse order": "white", "horizon": "0.6", "output crossing": "tab:cyan"}


def _pyplot():
    """matplotlib.pyplot on the Agg backend, imported only when a figure is drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# -- the trust map -------------------------------------------------------------------------
# sigma* of each variant: colour, dash, marker. The markers are none of the verdicts' (o, x)
# nor the splits' (KIND_MARKERS), so that one glyph has one meaning in the trust map.
STAR_STYLES = (("k", "-", "s"), ("tab:green", "--", "D"), ("tab:purple", ":", "^"),
               ("tab:orange", "-.", "p"), ("tab:brown", (0, (5, 1, 1, 1)), "h"),
               ("tab:pink", (0, (1, 1)), "8"))
#: the marker of a sigma* below the smallest sigma probed, drawn on the axis at sigma = 0
BELOW_MARKER = "$\\downarrow$"
#: the marker of each kind of split (and of an output crossing), distinct in shape
KIND_MARKERS = {"grazing": "*", "extra impact": "P", "chatter": "X", "impulse order": "d",
                "output crossing": "v", "horizon": "."}
#: the fewest sigma-axis heights (a fraction of the axis) between two probes drawn
PROBE_GAP = 0.012


def _xlim(ax, x):
    """Limits of the swept axis: the grid with a margin, or +-2 % around a single value."""
    x = np.asarray(x, float)
    if len(x) == 1:
        half = 0.02 * max(abs(float(x[0])), 1e-3)
        ax.set_xlim(x[0] - half, x[0] + half)
        ax.set_xticks([float(x[0])])
    else:
        pad = 0.06 * (x[-1] - x[0])
        ax.set_xlim(x[0] - pad, x[-1] + pad)


def _fig_legend(fig, handles, labels, ncol):
    """One legend below the panels, inside the figure."""
    uniq = dict(zip(labels, handles))
    renderer = fig.canvas.get_renderer()
    for n in range(min(ncol, len(uniq)) or 1, 0, -1):  # as many columns as the width holds
        legend = fig.legend(uniq.values(), uniq.keys(), loc="outside lower center", ncol=n,
                            fontsize=7, frameon=False)
        if n == 1 or legend.get_window_extent(renderer).width <= 0.98 * fig.bbox.width:
            return legend
        legend.remove()
    return legend


def _axes_legend(fig, axes, ncol):
    """:func:`_fig_legend` of every entry of ``axes``."""
    handles, labels = [], []
    for ax in axes:
        hh, ll = ax.get_legend_handles_labels()
        handles, labels = handles + hh, labels + ll
    return _fig_legend(fig, handles, labels, ncol)


def _thinned(values, gap):
    """The finite values sorted, without those closer than gap to one kept before."""
    kept = []
    for v in np.sort(values[np.isfinite(values)]):
        if not kept or v - kept[-1] >= gap:
            kept.append(v)
    return np.array(kept)


def plot_map(ds, path, *, size=None):
    """Per horizon (rows) the mean and the variance (columns): the error at every grid point
    against the tolerance (diverging colours centred on it), the verdicts of the paper's
    OPA, sigma* of every impact law drawn (lines), the sigma probed, the runs that did not
    finish, and for each kind of split the smallest sigma at which one enters the ensemble
    (with the count of the others of that kind in the panel).

    Reading aids: one glyph has one meaning (verdicts o and x, sigma* markers, split
    markers and the below-resolution arrow are all different), probes closer than
    ``PROBE_GAP`` of the axis are drawn once, and the legend lists only what is drawn."""
    check_map(ds, "plot_map")
    plt = _pyplot()

    H = len(ds.horizon)
    fig, axes = plt.subplots(H, 2, figsize=size or (11, 3.9 * H + 1.4), squeeze=False,
                             sharex=True, sharey=True, layout="constrained")
    handles, labels = [], []
    for h in range(H):
        for c, (what, rel, tol) in enumerate((
                ("mean", ds.err_mean_rel, float(ds.attrs["tolerance"])),
                ("variance", ds.err_var_rel, float(ds.attrs["var_tolerance"])))):
            ax = axes[h, c]
            _map_panel(fig, ax, ds, h, c, rel.values[:, :, HEADLINE, -1, h] / tol, what)
            hh, ll = ax.get_legend_handles_labels()
            handles, labels = handles + hh, labels + ll
    _fig_legend(fig, handles, labels, 3)
    import textwrap

    # one line at the default size; wrapped only where a smaller figure cannot hold it
    width = int(fig.get_size_inches()[0] * 72 / (9 * 0.6))  # characters of 9 pt that fit
    fig.suptitle("\n".join(textwrap.wrap(
        f"Where OPA (N = {int(ds.N.max())}) agrees with Monte Carlo: marks "
        f"{ds.variant.values[HEADLINE]}, lines σ* per variant", width)), fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def _map_panel(fig, ax, ds, h: int, c: int, r, what: str) -> None:
    """One panel of :func:`plot_map`: horizon h, criterion c (``what``: mean or variance),
    ``r`` the error over its tolerance per swept value and sigma."""
    from matplotlib.colors import TwoSlopeNorm

    x = _vals(ds).values.astype(float)
    y = ds.sigma.values
    smax = float(y.max())
    span = (x[-1] - x[0]) / max(1, len(x) - 1) if len(x) > 1 else 0.02 * abs(x[0])
    norm = TwoSlopeNorm(vcenter=0.0, vmin=-3.0, vmax=2.0)
    mesh = ax.pcolormesh(*_edges(x, y), np.log10(np.maximum(r.T, 1e-12)),
                         cmap="RdBu_r", norm=norm, shading="flat")
    _map_verdicts(ax, ds, h, c, x, y, r)
    _map_probes(ax, ds, x, smax, span)
    _map_stars(ax, ds, h, c, x, smax, span)
    _map_splits(ax, ds, h, x, smax, span)
    ax.set_ylim(-0.04 * smax, smax * 1.04)
    _xlim(ax, x)
    ax.set_title(f"{what}, H = {float(ds.horizon[h]):g} forcing periods", fontsize=9)
    if h == len(ds.horizon) - 1:
        ax.set_xlabel(_par(ds))
    if c == 0:
        ax.set_ylabel("σ")
    cb = fig.colorbar(mesh, ax=ax, extend="both")
    cb.set_label(f"RMS error of the {what} / its tolerance", fontsize=8)
    cb.set_ticks([-3, -2, -1, 0, 1, 2],
                 labels=["0.001", "0.01", "0.1", "1 = tol", "10", "100"])
    cb.ax.tick_params(labelsize=7)
    cb.ax.axhline(0.0, color="k", lw=2)


def _map_verdicts(ax, ds, h: int, c: int, x, y, r) -> None:
    """The headline variant's verdict at every grid point: agrees (o), does not (x),
    undecided (grey o), did not finish (?)."""
    head = str(ds.variant.values[HEADLINE])
    X, Y = np.meshgrid(x, y, indexing="ij")
    a = ds.agrees.values[:, :, HEADLINE, -1, h, c].astype(bool)
    bad = ~np.isfinite(r)
    if a.any():
        ax.scatter(X[a], Y[a], marker="o", facecolor="white", edgecolor="k", s=26,
                   label=f"{head} agrees", zorder=4)
    undecided = (ds.verdict.values[:, :, HEADLINE, -1, h, c] == 0 if "verdict" in ds
                 else np.zeros_like(a))
    if (~a & ~bad & ~undecided).any():
        ax.scatter(X[~a & ~bad & ~undecided], Y[~a & ~bad & ~undecided], marker="x",
                   color="k", s=26, label=f"{head} does not", zorder=4)
    if (undecided & ~bad).any():  # grey: between agrees (white) and does not
        ax.scatter(X[undecided & ~bad], Y[undecided & ~bad], marker="o",
                   facecolor="0.6", edgecolor="k", s=26, zorder=4,
                   label=f"{head} undecided (counts as does not)")
    if bad.any():
        ax.scatter(X[bad], Y[bad], marker="$?$", color="k", s=40, zorder=4,
                   label="run did not finish (NaN)")


def _map_probes(ax, ds, x, smax: float, span: float) -> None:
    """The sigma probed, drawn left of their column, thinned to ``PROBE_GAP``."""
    ps = ds.probe_sigma.values
    for q in range(len(x)):
        kept = _thinned(ps[q], PROBE_GAP * smax)
        if len(kept):
            ax.scatter(np.full(len(kept), x[q] - 0.2 * span), kept, marker="_",
                       color="0.25", s=30, lw=0.8, zorder=3, label="σ probed")


def _map_stars(ax, ds, h: int, c: int, x, smax: float, span: float) -> None:
    """sigma* of every variant drawn (:data:`STAR_STYLES`), side by side where they
    coincide; one below the smallest sigma probed is an arrow on the axis."""
    drawn = _laws(ds) + _element_variants(ds)
    for j, (v, (colour, style, mark)) in enumerate(zip(drawn, STAR_STYLES)):
        lo = ds.sigma_star.values[:, v, h, c]
        hi = ds.sigma_star_upper.values[:, v, h, c]
        top = np.where(np.isfinite(hi), lo, smax)
        shift = (j - (len(drawn) - 1) / 2) * 0.04 * span  # coinciding lines show
        below = np.isfinite(top) & (top <= 0)
        line = np.where(below, 0.0, top)
        ax.plot(x + shift, line, color=colour, ls=style, lw=1.6, zorder=5,
                marker=mark, markevery=[int(i) for i in np.flatnonzero(~below)],
                ms=5.5, mfc="white", label=f"σ* {ds.variant.values[v]}")
        if below.any():
            ax.plot((x + shift)[below], line[below], color=colour, ls="none",
                    marker=BELOW_MARKER, ms=9, zorder=5,
                    label=f"below the smallest σ probed: σ* {ds.variant.values[v]}")


def _map_splits(ax, ds, h: int, x, smax: float, span: float) -> None:
    """For each kind of split but 'horizon' (each in its own lane right of its column) the
    smallest sigma at which one enters the ensemble, and a count of the others."""
    kinds = _kinds(ds)
    kind = ds.split_kind.values[:, h]
    dist = np.abs(ds.split_value.values[:, h] - nominal(ds))
    shown = [k for k, name in enumerate(kinds) if name != "horizon"]
    more = np.zeros(len(x), dtype=int)  # splits beyond the first of each kind
    lowest = np.full(len(x), np.inf)
    for rank, k in enumerate(shown):
        name = kinds[k]
        crossing = name == "output crossing"
        at = 0.12 * span + 0.07 * span * rank  # each kind its own lane, right
        for q in range(len(x)):  # the first of each kind per column, and a count
            sel = (kind[q] == k) & (dist[q] <= smax)
            if not sel.any():
                continue
            first = float(dist[q][sel].min())
            ax.scatter([x[q] + at], [first], marker=KIND_MARKERS[name],
                       s=60 if name == "grazing" else 34, color=KIND_COLOURS[name],
                       edgecolor="k", lw=0.5, zorder=6,
                       label=f"first {name} at this σ" if crossing
                       else f"first split ({name}) at this σ")
            more[q] += int(sel.sum()) - 1
            lowest[q] = min(lowest[q], first)
    for q in np.flatnonzero(more):  # one count per column, right of its lanes
        ax.annotate(f"+{int(more[q])}", (x[q] + 0.12 * span + 0.07 * span
                                         * (len(shown) - 1), lowest[q]),
                    xytext=(4, -8), textcoords="offset points", fontsize=6,
                    zorder=6)


def _edges(x, y):
    def e(a):
        a = np.asarray(a, float)
        if len(a) == 1:
            return np.array([a[0] * 0.9, a[0] * 1.1])
        mid = 0.5 * (a[1:] + a[:-1])
        return np.concatenate([[a[0] - (mid[0] - a[0])], mid, [a[-1] + (a[-1] - mid[-1])]])
    return e(x), e(y)


def _pick_sigmas(ds, q=0, h=0):
    """A grid sigma that agrees and the first that does not (headline variant)."""
    a = ds.agrees.values[q, :, HEADLINE, -1, h, 0].astype(bool)
    good = np.flatnonzero(a)
    bad = np.flatnonzero(~a)
    picks = []
    if len(good):
        picks.append(int(good[-1] if not len(bad) else good[good < bad[0]][-1]
                          if (good < bad[0]).any() else good[0]))
    if len(bad):
        picks.append(int(bad[0]))
    return picks or [0]


LINE_STYLES = ("-", "--", ":", "-.", (0, (5, 1, 1, 1)), (0, (1, 1)), (0, (3, 1, 1, 1, 1, 1)))
#: colours of the variants in error_vs_N.png: neither red (the verdict's tolerance) nor
#: black (the MC noise floor)
VARIANT_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown",
                   "tab:pink", "tab:olive", "tab:cyan")


def plot_error_vs_order(ds, path, q=0, *, size=None):
    """RMS error of x_0 against N, before OPA's first impact and over each horizon, for
    every variant (distinct markers, offset in N), with the MC noise floor."""
    check_map(ds, "plot_error_vs_order")
    plt = _pyplot()
    picks = _pick_sigmas(ds, q)
    H = len(ds.horizon)
    fig, axes = plt.subplots(len(picks), 1 + H, figsize=size or (4.2 * (1 + H),
                                                                  3.4 * len(picks) + 1),
                             squeeze=False, sharex=True, layout="constrained")
    N = ds.N.values.astype(float)
    for r, s in enumerate(picks):
        first = ds.first_impact.values[q, s, HEADLINE, -1]
        n_pre = max(2, int(np.sum(_time(ds).values < first)))
        windows = [("before OPA's first impact", ds.pre_impact_err.values[q, s], n_pre)]
        for h, Hh in enumerate(ds.horizon.values):
            windows.append((f"first {float(Hh):g} periods", ds.err_mean.values[q, s, :, :, h],
                            int(round(float(Hh) * ds.attrs["per_period"])) + 1))
        for c, (title, err, n) in enumerate(windows):
            ax = axes[r, c]
            for v, name in enumerate(ds.variant.values):
                xs = N + 0.07 * (v - 2)
                line, = ax.semilogy(xs, np.maximum(err[v], 1e-16),
                                    color=VARIANT_COLOURS[v % len(VARIANT_COLOURS)],
                                    marker=VARIANT_MARKERS[v % len(VARIANT_MARKERS)],
                                    ls=LINE_STYLES[v % len(LINE_STYLES)], ms=5,
                                    mfc="none" if v % 2 else None, lw=0.8, label=str(name))
                ran = ds.variant_ran.values[v].astype(bool) if "variant_ran" in ds else True
                nan = ~np.isfinite(err[v]) & ran
                if nan.any():  # a run that did not finish: marked at the top, not a gap
                    ax.scatter(xs[nan], np.full(nan.sum(), 0.93), marker="$?$", s=30,
                               color=line.get_color(), transform=ax.get_xaxis_transform(),
                               label="run did not finish (NaN)")
            noise = _window_sem(ds, q, s, n)
            ax.axhline(noise, color="k", ls="--", lw=1, label="MC noise floor (RMS SE)")
            ax.axhline(_window_tolerance(ds, q, s, n), color="tab:red", ls="-", lw=1.2,
                       label="the verdict's tolerance (mean)")
            finite = err[np.isfinite(err)]
            if len(finite) and noise > float(finite.max()):
                ax.text(0.5, 0.5, "MC noise floor above every curve:\nthese errors are "
                        "not resolved", transform=ax.transAxes, ha="center", va="center",
                        fontsize=8, color="0.25",
                        bbox=dict(facecolor="white", edgecolor="0.6", alpha=0.9))
            ax.set_title(f"σ = {float(ds.sigma[s]):g}: {title}", fontsize=9)
            if r == len(picks) - 1:
                ax.set_xlabel("N")
        axes[r, 0].set_ylabel("RMS error of x_0")
    _axes_legend(fig, axes.flat, 4)
    fig.suptitle(f"{_par(ds)} = {_g(float(_vals(ds)[q]))}: RMS error of x_0 against N "
                 f"(variants offset in N)", fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


#: colours of the orders N in one figure: distinct hues, none black (the Monte Carlo truth)
ORDER_COLOURS = ("tab:purple", "tab:blue", "tab:green", "tab:orange", "tab:red", "tab:brown",
                 "tab:pink", "tab:olive", "tab:cyan")


def plot_mean(ds, path, q=0, *, size=None):
    """x_0 for several N beside the MC mean, and |x_0 - E_MC[x]| against the band of 2 MC
    standard errors, at a sigma that agrees and one that does not, over the first horizon.
    (The 2-SE band of the mean is far thinner than a line at the scale of E[x], so it is
    drawn where it can be seen: below, as the noise the errors are held against.)"""
    check_map(ds, "plot_mean")
    plt = _pyplot()
    picks = _pick_sigmas(ds, q)
    orders = [int(n) for n in ds.N.values]
    show = [k for k, n in enumerate(orders) if n in (0, 1, 2, 4, 8) or k == len(orders) - 1]
    n = int(round(float(ds.horizon[0]) * ds.attrs["per_period"])) + 1
    t = _time(ds).values[:n]
    fig, axes = plt.subplots(2, len(picks), figsize=size or (6.5 * len(picks), 7.0),
                             squeeze=False, sharex=True, layout="constrained")
    every = max(1, n // 12)
    later = t > 0  # at t = 0 every sample is at x0: no error to draw on a log axis
    for c, s in enumerate(picks):
        m = ds.mc_x_mean.values[q, s, :n]
        se = ds.mc_x_sem.values[q, s, :n]
        ax, ax2 = axes[0, c], axes[1, c]
        ax.plot(t, m, "k-", lw=2.2, label="MC mean")
        shown = [2 * se[later]]
        for i, k in enumerate(show):
            x0 = ds.opa_x_mean.values[q, s, HEADLINE, k, :n]
            style = dict(color=ORDER_COLOURS[i % len(ORDER_COLOURS)],
                         ls=LINE_STYLES[i % len(LINE_STYLES)], lw=1.1,
                         marker=VARIANT_MARKERS[i % len(VARIANT_MARKERS)], ms=3.5,
                         markevery=(i * every // max(1, len(show)), every))
            ax.plot(t, x0, label=f"OPA N = {orders[k]}", **style)
            gap = np.abs(x0 - m)[later]
            ax2.semilogy(t[later], np.maximum(gap, 1e-300), **style)
            shown.append(gap)
        values = np.concatenate(shown)
        values = values[np.isfinite(values) & (values > 0)]
        top = float(values.max()) if len(values) else 1.0
        bottom = max(float(values.min()) if len(values) else top * 1e-6, top * 1e-8)
        ax2.fill_between(t[later], bottom / 10, np.maximum(2 * se[later], bottom / 10),
                         color="0.55", alpha=0.35, lw=0, label="within 2 MC SE (noise)")
        # dashed: the solid black line is the MC mean, in the same legend
        ax2.semilogy(t[later], np.maximum(2 * se[later], bottom / 10), "k--", lw=1.4,
                     label="2 MC SE")
        ax2.set_ylim(bottom / 2, top * 2)
        ax.set_title(f"σ = {float(ds.sigma[s]):g}", fontsize=9)
        ax2.set_xlabel("t [forcing periods]")
    axes[0, 0].set_ylabel("E[x]")
    axes[1, 0].set_ylabel("|x_0 − E_MC[x]|")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    hh, ll = axes[1, 0].get_legend_handles_labels()
    _fig_legend(fig, handles + hh, labels + ll, 4)
    fig.suptitle(f"{_par(ds)} = {_g(float(_vals(ds)[q]))}, {ds.variant.values[HEADLINE]}",
                 fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def plot_variance(ds, path, q=0, *, size=None):
    check_map(ds, "plot_variance")
    plt = _pyplot()
    picks = _pick_sigmas(ds, q)
    n = int(round(float(ds.horizon[0]) * ds.attrs["per_period"])) + 1
    t = _time(ds).values[:n]
    fig, axes = plt.subplots(1, len(picks), figsize=size or (6 * len(picks), 4.6),
                             squeeze=False, layout="constrained")
    for c, s in enumerate(picks):
        ax = axes[0, c]
        var = ds.mc_x_var.values[q, s, :n]
        se = ds.mc_x_var_sem.values[q, s, :n]
        ax.fill_between(t, np.maximum(var - 2 * se, 1e-16), var + 2 * se, color="0.75")
        ax.semilogy(t, np.maximum(var, 1e-16), "k-", lw=2.2, label="MC Var[x] ± 2 SE")
        # the verdict's tolerance, drawn pointwise (the criterion reads its running RMS)
        tol = float(ds.attrs.get("var_tolerance", 0.25))
        for sign in (-1.0, 1.0):
            ax.semilogy(t, np.maximum(var * (1.0 + sign * tol), 1e-16), color="0.35",
                        ls=":", lw=1.0, label=(f"tolerance: MC Var × (1 ± {tol:g})"
                                               if sign > 0 else None))
        for j, v in enumerate(_laws(ds) + _element_variants(ds)):
            colour, style, mark = STAR_STYLES[(j + 1) % len(STAR_STYLES)]
            ax.semilogy(t, np.maximum(ds.opa_x_var.values[q, s, v, -1, :n], 1e-16),
                        color=colour, ls=style, marker=mark, ms=3, markevery=max(1, n // 10),
                        lw=1.2, label=f"OPA {ds.variant.values[v]}, N = {int(ds.N.max())}")
        positive = var[1:][var[1:] > 0]
        if len(positive):
            ax.set_ylim(bottom=0.1 * float(positive.min()))
        ax.set_title(f"σ = {float(ds.sigma[s]):g}", fontsize=9)
        ax.set_xlabel("t [forcing periods]")
    axes[0, 0].set_ylabel("Var[x]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    _fig_legend(fig, handles, labels, 3)
    fig.suptitle(f"Variance of x, {_par(ds)} = {_g(float(_vals(ds)[q]))}", fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def plot_phase(ds, path, *, size=None):
    """Dense-output phase portraits: OPA (both laws) against the MC mean and samples."""
    check_map(ds, "plot_phase")
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=size or (11, 5.0), layout="constrained")
    ax = axes[0]
    for j in range(ds.sizes["phase_sample"]):
        ax.plot(ds.phase_sample_x[j], ds.phase_sample_v[j], lw=0.5, color="0.7",
                label="sample paths" if j == 0 else None)
    ax.plot(ds.phase_mc_x, ds.phase_mc_v, "k-", lw=1.5, label="MC mean")
    for i, law in enumerate(ds.law.values):
        ax.plot(ds.phase_opa_x[i], ds.phase_opa_v[i], ("-", "--")[i], lw=1,
                label=f"OPA ({law} law)")
    ax.axvline(float(ds.attrs["delta"]), color="r", lw=1, label="wall")
    ax.set_xlabel("x")
    ax.set_ylabel("x'")
    _fig_legend(fig, *ax.get_legend_handles_labels(), 5)
    ax = axes[1]
    t = ds.phase_time.values
    for j in range(ds.sizes["phase_sample"]):
        ax.plot(t, ds.phase_sample_x[j], lw=0.5, color="0.7")
    ax.plot(t, ds.phase_mc_x, "k-", lw=1.5)
    for i in range(ds.sizes["law"]):
        ax.plot(t, ds.phase_opa_x[i], ("-", "--")[i], lw=1)
    ax.set_xlabel("t [forcing periods]")
    ax.set_ylabel("x")
    fig.suptitle(f"{_par(ds)} = {_g(ds.attrs['phase_value'])}, σ = "
                 f"{_g(ds.attrs['phase_sigma'])}, N = {int(ds.N.max())} "
                 f"({ds.sizes['phase_time']} dense outputs)", fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


# -- the cost-accuracy frontier -------------------------------------------------------------
#: markers of the frontier's methods, paired with the colours so that no two methods share
#: a colour and a marker
FRONTIER_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "h", "<", ">")


def plot_frontier(conv, path, *, size=None):
    """The cost-accuracy study of the map (``frontier_dataset``): error against elements K,
    against N (one line per element count, so that K and N are never joined) and against
    cost. A method (with its impact law) has one colour and one marker in every panel;
    in the N panel the element counts of one method differ by the dash. Each panel has a
    legend of its own lines."""
    plt = _pyplot()
    from compare._convergence import STUDY_LAWS, _select

    fig, axes = plt.subplots(1, 3, figsize=size or (17, 6.8), layout="constrained")
    colours = [c for c in plt.rcParams["axes.prop_cycle"].by_key()["color"]]
    keys: dict = {}

    def style(method, law, dash=0):
        key = (method.removesuffix(", N"), law)
        if key not in keys:
            k = len(keys)
            keys[key] = dict(color=colours[k % len(colours)],
                             marker=FRONTIER_MARKERS[k % len(FRONTIER_MARKERS)])
        return dict(keys[key], ls=LINE_STYLES[dash % len(LINE_STYLES)], ms=4.5, lw=1.2,
                    mfc="none" if dash % 2 else None)

    ax = axes[0]
    for method in ("ME-OPA uniform", "ME-OPA adaptive", "ME-collocation uniform",
                   "ME-collocation adaptive"):
        for law in (*STUDY_LAWS, "true system"):
            idx = _select(conv, method, law)
            if len(idx):
                ax.loglog(conv["size"].values[idx], conv.error.values[idx],
                          label=f"{method} ({law})", **style(method, law))
    ax.set_xlabel("elements K")
    ax.set_ylabel("RMS error of E[x]")
    ax.set_title("against the number of elements", fontsize=9)
    ax = axes[1]
    for method in ("ME-OPA adaptive, N", "OPA (one element), N"):
        for law in STUDY_LAWS:
            idx = _select(conv, method, law)
            for dash, K in enumerate(np.unique(conv["size"].values[idx])):
                sub = idx[conv["size"].values[idx] == K]
                ax.semilogy(conv.order.values[sub], conv.error.values[sub],
                            label=f"{method.removesuffix(', N')} ({law}), K = {int(K)}",
                            **style(method, law, dash))
    ax.set_xlabel("N")
    ax.set_ylabel("RMS error of E[x]")
    ax.set_title("against the order N", fontsize=9)
    ax = axes[2]
    for method in np.unique(conv.method.values):
        if method.endswith(", N"):
            continue
        for law in np.unique(conv.law.values):
            idx = _select(conv, method, law)
            if len(idx):
                ax.loglog(conv.rhs_evaluations.values[idx], conv.error.values[idx],
                          label=f"{method} ({law})", **style(method, law))
    ax.set_xlabel("right-hand-side evaluations")
    ax.set_ylabel("RMS error of E[x]")
    ax.set_title("against the cost", fontsize=9)
    for ax in axes:
        ax.axhline(conv.attrs["reference_sem"], color="k", ls=":", lw=1,
                   label="reference's standard error")
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=1,
                  frameon=False)
    # several uncertain parameters: one sigma each (uncertain "mu,c", sigma [s1, s2])
    sigma = ", ".join(f"{s:g}" for s in np.atleast_1d(conv.attrs["sigma"]))
    if np.ndim(conv.attrs["sigma"]):
        sigma = f"({sigma}) of {conv.attrs.get('uncertain', '')}"
    fig.suptitle(f"σ = {sigma}, ω = {conv.attrs['omega']:g}, "
                 f"{conv.attrs['periods']:g} periods: error against K, N and cost", fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _plot_frontier_of(ds: xr.Dataset, path: str):
    """The frontier's figure of a map (:func:`frontier_dataset`)."""
    return plot_frontier(frontier_dataset(ds), path)


__all__ = ["BELOW_MARKER", "KIND_COLOURS", "KIND_MARKERS", "STAR_STYLES", "plot_error_vs_order",
           "plot_frontier", "plot_map", "plot_mean", "plot_phase", "plot_variance"]
