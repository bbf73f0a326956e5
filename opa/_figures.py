"""The paper's Figs. 2-11, regenerated: ``reproduce("fig3", "figures/")``.

| figure | content | parameter set |
|---|---|---|
| fig2 | impulse train F(t), n = 2 and n = 4 | F0 = 0.1 |
| fig3 | bifurcation diagrams vs c, both sections, DMR and EMR_0 | 3.1 |
| fig4 | phase portraits + sections, time histories: c = 0.05, 0.035 | 3.1 |
| fig5 | phase portraits: omega = 3.98, 4.2 (sigma = 0) | 3.2 |
| fig6 | EMR: (3.98, 0.01), (3.98, 0.014), (4.2, 0.02), (4.2, 0.03) | 3.2 |
| fig7 | EMR at omega = 4.00495: sigma = 0.1, 0.2 | 3.3 |
| fig8 | EMR at omega = 3.98: sigma = 0.1, 0.18 | 3.3 |
| fig9 | EMR bifurcation diagrams vs omega, sigma = 0, 0.1, 0.16, 0.18 | 3.3 |
| fig10 | EMR_0 bifurcation diagrams vs c, F0 = 10, n = 2 and 4 | 3.4 |
| fig11 | phase portraits at c = 0.0356: F0 in {0.1, 10} x n in {2, 4} | 3.4 |

Every panel title carries the label z = n/p measured on that run (``identify_motion``),
not the paper's. Bifurcation figures keep their sweep datasets as ``<fig>_<run>.nc``
beside the PNG (resumable while unfinished). Default sizes (61 sweep values, 300 + 60
periods) run in a few minutes on 2 cores; ``full=True`` uses 200 values and 500 + 100.

The sections shown: phase plane = the state (x, dx/dt) at t = k 2 pi/omega; constraint
plane = the pre-impact velocity at x = delta (the diagrams plot it against the
parameter, the portraits mark the stroboscopic points on the trajectory).
"""

from __future__ import annotations

import math
import os
import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from opa._model import SolverOptions, check_order, preset
from opa._poincare import identify_motion, mean_state, phase_section

FIGURES = ("fig2", "fig3", "fig4", "fig5", "fig6", "fig7", "fig8", "fig9", "fig10", "fig11")

COLORS = {"DMR": "black", "EMR_0": "tab:orange", "EMR": "tab:blue"}


# --------------------------------------------------------------------------- building blocks


def _label_text(motion) -> str:
    if motion.period:
        return f"z = {motion.label}"
    return f"no period (nearest {motion.nearest_period}, res. {motion.residual:.1g})"


def plot_bifurcation(ds: xr.Dataset, path: str, *, section: str = "both",
                     title: str | None = None) -> None:
    """Bifurcation diagram of a ``sweep`` dataset in one or both Poincaré sections.

    Phase plane: stroboscopic x against the parameter; constraint plane: pre-impact
    velocity against the parameter. Grazing estimates and period doublings are marked.
    """
    which = ["phase", "constraint"] if section == "both" else [section]
    fig, axes = plt.subplots(1, len(which), figsize=(5.5 * len(which) + 0.5, 4.2),
                             squeeze=False, layout="constrained")
    for ax, kind in zip(axes[0], which):
        _diagram(ax, ds, kind)
    fig.suptitle(title or _sweep_title(ds), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _sweep_title(ds) -> str:
    a = ds.attrs
    name = {"dmr": "DMR", "opa": "EMR_0" if a["sigma"] == 0 else f"EMR (σ = {a['sigma']:g})",
            "mc": "MC mean"}[a["model"]]
    return (f"{name} vs {a['sweep_parameter']}: {a['transient']} transient + {a['record']} "
            f"recorded periods, impulse {a['impulse']}, F0 = {a['F0']:g}")


def _diagram(ax, ds: xr.Dataset, kind: str, color: str = "black") -> None:
    param = ds.attrs["sweep_parameter"]
    values = ds[param].values
    if kind == "phase":
        y = ds.section_x.values
        ylabel = "x at t = k 2π/ω"
        title = "phase plane"
    else:
        y = ds.impact_v.values
        ylabel = "impact velocity x'(t-) at x = Δ"
        title = "constraint plane"
    xs = np.broadcast_to(values[:, None], y.shape)
    ok = np.isfinite(y)
    ms = 4.0 if len(values) <= 40 else 2.2
    ax.plot(xs[ok], y[ok], ".", color=color, ms=ms, alpha=0.7, mec="none")
    for g in ds.grazing_parameter.values:
        ax.axvline(g, color="tab:orange", lw=0.8, ls=":")
    for v in values[ds.period_doubling.values == 1]:
        ax.axvline(v, color="tab:green", lw=0.8, ls="--")
    if kind == "constraint" and not ok.any():
        ax.text(0.5, 0.5, "no impacts recorded", ha="center", va="center",
                transform=ax.transAxes)
    ax.set_xlabel(param)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.set_xlim(values[0], values[-1])


def _run(model, osc, *, sigma=0.0, order=4, options, transient, record, per_period=64):
    """One run on the sweep's time grid (stroboscopic times aligned with impulses)."""
    from opa._bifurcation import sweep_times
    from opa._simulate import simulate_dmr, simulate_opa

    times = sweep_times(osc, options, transient, record, per_period)
    if model == "dmr":
        ds = simulate_dmr(osc, times=times, options=options)
    else:
        ds = simulate_opa(osc, sigma=sigma, order=order, times=times, options=options)
    ds.attrs["transient"] = transient
    return ds


def _portrait(ax, ds, *, color, marker="*", last=30, label=None, ls="-", strobe=True):
    """Phase portrait of the last ``last`` periods, with the stroboscopic points."""
    x, v, name = mean_state(ds)
    t = ds.time.values
    T = 2 * math.pi / ds.attrs["omega"]
    keep = t >= t[-1] - last * T
    lw = 1.3 if ls == "-" and color == COLORS["DMR"] else 0.7
    ax.plot(x[keep], v[keep], ls, color=color, lw=lw, label=label or name)
    if strobe:
        sec = phase_section(ds, start=ds.attrs["transient"] * T)
        ax.plot(sec.section_x, sec.section_v, marker, color="tab:red", ms=7 if marker == "*"
                else 4, mec="darkred", mew=0.6, label="t = k 2π/ω" if label is None else None,
                zorder=5)
    ax.axvline(ds.attrs["delta"], color="gray", lw=1.2)
    ax.set_xlabel("x")
    ax.set_ylabel("dx/dt")


def _history(ax, runs, *, last=10):
    """Time histories of the last ``last`` periods; EMR with a ± 1 std band."""
    for ds, style in runs:
        x, _, name = mean_state(ds)
        t = ds.time.values
        T = 2 * math.pi / ds.attrs["omega"]
        keep = t >= t[-1] - last * T
        ax.plot(t[keep], x[keep], style, color=COLORS[name], lw=0.9, label=name)
        if name == "EMR" and "x_var" in ds:
            sd = np.sqrt(np.maximum(ds.x_var.values[keep], 0))
            ax.fill_between(t[keep], x[keep] - sd, x[keep] + sd, color=COLORS[name],
                            alpha=0.2, lw=0, label="EMR ± 1 std")
    ax.axhline(runs[0][0].attrs["delta"], color="gray", lw=1.2)
    ax.set_xlabel("t")
    ax.set_ylabel("x")
    ax.legend(fontsize=7, loc="best", framealpha=0.85)


def _suptitle(fig, text: str, width: int) -> None:
    fig.suptitle(textwrap.fill(text, width), fontsize=10)


def _save(fig, outdir, name, log) -> str:
    path = os.path.join(outdir, f"{name}.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    if log:
        log(f"  wrote {path}")
    return path


# --------------------------------------------------------------------------- the figures


class _Context:
    """Sizes and shared resources of one ``reproduce`` call."""

    def __init__(self, outdir, full, impulse, pulse_width, order, workers, scheduler,
                 progress, log):
        self.outdir = outdir
        self.full = full
        self.options = SolverOptions(impulse=impulse, pulse_width=pulse_width)
        self.order = order
        self.workers = workers
        self.scheduler = scheduler
        self.progress = progress
        self.log = log
        self.count = 200 if full else 61
        self.transient = 500 if full else 300
        self.record = 100 if full else 60
        self.executor = None

    def sweep(self, name, model, param, values, osc, **kw):
        from opa._bifurcation import local_executor, sweep

        if self.executor is None and self.scheduler is None and self.workers > 1:
            self.executor = local_executor(self.workers)
        out = os.path.join(self.outdir, f"{name}.nc")
        return sweep(model, param, values, osc, transient=self.transient, record=self.record,
                     options=self.options, order=self.order, out=out,
                     scheduler=self.scheduler, executor=self.executor,
                     progress=self.progress, **kw)

    def run(self, model, osc, **kw):
        # strong impulses (F0 = 10) kick the velocity far up, and the cubic damping brings
        # it back within a fraction of a period: resolve that in the drawn trajectory
        per_period = 512 if osc.F0 >= 1.0 else 64
        return _run(model, osc, order=self.order, options=self.options, transient=500,
                    record=100, per_period=per_period, **kw)

    def close(self):
        if self.executor is not None:
            self.executor.shutdown()


def fig2(ctx):
    fig, axes = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True, layout="constrained")
    t_end = 64.0
    for ax, n, tag in zip(axes, (2, 4), "ab"):
        osc = preset("3.1", n=float(n))
        T1 = 2 * math.pi / osc.omega1
        tj = np.arange(0 if ctx.options.impulse_at_zero else 1, int(t_end / T1) + 1) * T1
        height = osc.F0 * (1 + osc.a1 * np.sin(osc.omega1 * tj / osc.n))
        tt = np.linspace(0, t_end, 2000)
        ax.plot(tt, osc.F0 * (1 + osc.a1 * np.sin(osc.omega1 * tt / osc.n)), ":",
                color="gray", lw=1, label="F0 (1 + a1 sin(ω1 t / n)) (switched signal)")
        if ctx.options.impulse == "dirac":
            ax.vlines(tj, 0, height, color="black", lw=1.5)
            ax.plot(tj, height, "o", color="black", ms=4, label="impulse strength (Dirac)")
        else:
            tau = ctx.options.pulse_width
            for tk, hk in zip(tj, height):
                ax.fill_between([tk, tk + tau], 0, hk, color="black", step="pre")
            ax.plot([], [], "s", color="black", label=f"rectangular pulse, width {tau:g}")
        ax.set_ylabel("F(t)")
        ax.set_title(f"({tag}) n = {n}: impulses every 2π/ω1 = {T1:.4g}, F0 = {osc.F0:g}, "
                     f"a1 = {osc.a1:g}", fontsize=10)
        ax.set_ylim(-0.005, 2.8 * osc.F0)
        ax.legend(fontsize=7, loc="upper center", ncol=2)
    axes[-1].set_xlabel("t")
    fig.suptitle("Fig. 2: the periodic impulse force F(t)")
    return [_save(fig, ctx.outdir, "fig2", ctx.log)]


def _bifurcation_grid(ctx, name, rows, param, values, *, title, marks=()):
    """Rows of (row label, model, oscillator, sweep kwargs): both sections side by side."""
    fig, axes = plt.subplots(len(rows), 2, figsize=(11, 3.1 * len(rows)), squeeze=False,
                             layout="constrained")
    paths = []
    for (row_label, tag, model, osc, kw), ax_row in zip(rows, axes):
        ds = ctx.sweep(f"{name}_{tag}", model, param, values, osc, **kw)
        paths.append(os.path.join(ctx.outdir, f"{name}_{tag}.nc"))
        color = COLORS["DMR"] if model == "dmr" else (
            COLORS["EMR_0"] if kw.get("sigma", 0) == 0 else COLORS["EMR"])
        for ax, kind in zip(ax_row, ("phase", "constraint")):
            _diagram(ax, ds, kind, color=color)
            ax.set_title(f"{row_label}: {ax.get_title()}", fontsize=9)
            for m in marks:
                ax.axvline(m, color="tab:purple", lw=0.6, alpha=0.6)
        if ctx.log:
            from opa._bifurcation_cli import _summary

            ctx.log(f"  {name} {row_label}:")
            for line in _summary(ds):
                ctx.log("  " + line)
    _suptitle(fig, title, 120)
    return [_save(fig, ctx.outdir, name, ctx.log)] + paths


def fig3(ctx):
    values = np.linspace(0.01, 0.1, ctx.count)
    osc = preset("3.1")
    rows = [("DMR", "dmr", "dmr", osc, {}),
            ("EMR_0", "emr0", "opa", osc, {"sigma": 0.0})]
    return _bifurcation_grid(
        ctx, "fig3", rows, "c", values, marks=(0.035, 0.05),
        title=f"Fig. 3: bifurcation diagrams vs c (set 3.1, F0 = 0.1, impulse "
              f"{ctx.options.impulse}); purple lines: c = 0.035, 0.05 of Fig. 4",
    )


def _portrait_grid(ctx, name, cases, *, title, marker="*", history=True):
    """Rows of (row title, oscillator, sigma): DMR + EMR_0 | EMR (if sigma) | history."""
    has_emr = any(sigma > 0 for _, _, sigma in cases)
    ncol = 1 + has_emr + history
    fig, axes = plt.subplots(len(cases), ncol, figsize=(4.3 * ncol, 3.5 * len(cases)),
                             squeeze=False, layout="constrained")
    for (row, osc, sigma), ax_row in zip(cases, axes):
        T = osc.forcing_period
        dmr = ctx.run("dmr", osc)
        emr0 = ctx.run("opa", osc, sigma=0.0)
        m_dmr = identify_motion(dmr, start=500 * T)
        m_emr0 = identify_motion(emr0, start=500 * T)
        ax = ax_row[0]
        _portrait(ax, dmr, color=COLORS["DMR"], marker=marker)
        _portrait(ax, emr0, color=COLORS["EMR_0"], ls="--", strobe=False, label="EMR_0")
        ax.set_title(f"{row}\nDMR: {_label_text(m_dmr)}; EMR_0: {_label_text(m_emr0)}",
                     fontsize=8)
        ax.legend(fontsize=7, loc="best", framealpha=0.85)
        runs = [(dmr, "-"), (emr0, "--")]
        col = 1
        if has_emr:
            ax = ax_row[col]
            col += 1
            if sigma > 0:
                emr = ctx.run("opa", osc, sigma=sigma)
                m_emr = identify_motion(emr, start=500 * T)
                _portrait(ax, dmr, color="lightgray", strobe=False, label="DMR")
                _portrait(ax, emr, color=COLORS["EMR"], marker=marker)
                ax.set_title(f"{row}\nEMR σ = {sigma:g} (N = {ctx.order}): "
                             f"{_label_text(m_emr)}", fontsize=8)
                ax.legend(fontsize=7, loc="best", framealpha=0.85)
                runs.append((emr, "-"))
            else:
                ax.axis("off")
        if history:
            _history(ax_row[col], runs)
            ax_row[col].set_title(f"{row}: time history (last 10 periods)", fontsize=8)
    _suptitle(fig, title, int(40 * ncol))
    return [_save(fig, ctx.outdir, name, ctx.log)]


def fig4(ctx):
    cases = [(f"c = {c:g}", preset("3.1", c=c), 0.0) for c in (0.05, 0.035)]
    return _portrait_grid(ctx, "fig4", cases, title="Fig. 4: set 3.1; the paper labels "
                          "c = 0.05 a 2/2 and c = 0.035 a 4/4 motion (measured labels in "
                          "the panel titles; * = Poincaré points)")


def fig5(ctx):
    cases = [(f"ω = {w:g}", preset("3.2", omega=w), 0.0) for w in (3.98, 4.2)]
    return _portrait_grid(ctx, "fig5", cases, marker="s", title="Fig. 5: set 3.2, σ = 0; "
                          "the paper labels ω = 3.98 a 6/2 and ω = 4.2 a 3/1 motion "
                          "(measured labels in the panel titles; ■ = Poincaré points)")


def fig6(ctx):
    cases = [(f"ω = {w:g}", preset("3.2", omega=w), s)
             for w, s in ((3.98, 0.01), (3.98, 0.014), (4.2, 0.02), (4.2, 0.03))]
    return _portrait_grid(ctx, "fig6", cases, marker="s",
                          title="Fig. 6: EMR of set 3.2 for growing σ (uncertain μ)")


def fig7(ctx):
    cases = [("ω = 4.00495", preset("3.3", omega=4.00495), s) for s in (0.1, 0.2)]
    return _portrait_grid(ctx, "fig7", cases, marker="s",
                          title="Fig. 7: EMR of set 3.3 (c = 0.05) at ω = 4.00495")


def fig8(ctx):
    cases = [("ω = 3.98", preset("3.3", omega=3.98), s) for s in (0.1, 0.18)]
    return _portrait_grid(ctx, "fig8", cases, marker="s",
                          title="Fig. 8: EMR of set 3.3 (c = 0.05) at ω = 3.98")


def fig9(ctx):
    values = np.linspace(3.9, 5.9, ctx.count)
    osc = preset("3.3")
    rows = [(f"σ = {s:g}", f"sigma{s:g}", "opa", osc, {"sigma": s})
            for s in (0.0, 0.1, 0.16, 0.18)]
    return _bifurcation_grid(
        ctx, "fig9", rows, "omega", values, marks=(3.98, 4.00495),
        title="Fig. 9: EMR bifurcation diagrams vs ω (set 3.3, c = 0.05); purple: the "
              "paper's ω = 3.98 and 4.00495; orange dotted: grazing located between "
              "periodic neighbours; green dashed: period doubling",
    )


def fig10(ctx):
    values = np.linspace(0.01, 0.1, ctx.count)
    rows = [(f"F0 = 10, n = {n}", f"n{n}", "opa", preset("3.4", n=float(n)), {"sigma": 0.0})
            for n in (2, 4)]
    return _bifurcation_grid(ctx, "fig10", rows, "c", values, marks=(0.0356,),
                             title="Fig. 10: EMR_0 bifurcation diagrams vs c with the "
                                   "stronger impulse F0 = 10 (set 3.4)")


def fig11(ctx):
    cases = [(f"F0 = {F0:g}, n = {n}", preset("3.4", F0=F0, n=float(n)), 0.0)
             for F0 in (0.1, 10.0) for n in (2, 4)]
    fig, axes = plt.subplots(2, 2, figsize=(10, 8), layout="constrained")
    for (row, osc, _), ax, tag in zip(cases, axes.ravel(), "abcd"):
        T = osc.forcing_period
        emr0 = ctx.run("opa", osc, sigma=0.0)
        dmr = ctx.run("dmr", osc)
        _portrait(ax, emr0, color=COLORS["EMR_0"], marker="s", last=60)
        _portrait(ax, dmr, color="black", ls=":", strobe=False, label="DMR (dotted)", last=60)
        m = identify_motion(emr0, start=500 * T)
        ax.set_title(f"({tag}) c = 0.0356, {row}\nEMR_0: {_label_text(m)}", fontsize=9)
        ax.legend(fontsize=7, loc="best", framealpha=0.85)
    fig.suptitle("Fig. 11: phase portraits (last 60 periods) and Poincaré points (last 100)"
                 " for c = 0.0356", fontsize=10)
    return [_save(fig, ctx.outdir, "fig11", ctx.log)]


_MAKERS = {"fig2": fig2, "fig3": fig3, "fig4": fig4, "fig5": fig5, "fig6": fig6,
           "fig7": fig7, "fig8": fig8, "fig9": fig9, "fig10": fig10, "fig11": fig11}


def reproduce(figure: str, outdir: str | os.PathLike = "figures", *, full: bool = False,
              impulse: str = "dirac", pulse_width: float = 0.1, order: int = 4,
              workers: int = 2, scheduler=None, progress: bool | None = None,
              log=None) -> list[str]:
    """Regenerate one of the paper's figures (``"fig2"`` .. ``"fig11"``) or ``"all"``.

    Parameters
    ----------
    outdir : folder for the PNG files (and the sweeps' netCDF files).
    full : the paper's resolution for the bifurcation diagrams (200 values of the
        parameter, 500 transient + 100 recorded periods) instead of 61 and 300 + 60.
    impulse, pulse_width : impulse model for every figure (SPEC section 3).
    order : OPA order N of EMR_0 and EMR.
    workers, scheduler : parallel sweeps (local processes or a Dask scheduler).
    log : callable for progress lines (e.g. ``print``), or None.

    Returns
    -------
    The paths written.
    """
    names = list(FIGURES) if figure == "all" else [figure]
    for name in names:
        if name not in _MAKERS:
            raise ValueError(f"figure must be one of {', '.join(FIGURES)} or 'all', "
                             f"got {figure!r}")
    order = check_order(order)
    os.makedirs(outdir, exist_ok=True)
    ctx = _Context(os.fspath(outdir), full, impulse, pulse_width, int(order), int(workers),
                   scheduler, progress, log)
    paths = []
    try:
        for name in names:
            if log:
                log(f"{name}:")
            paths += _MAKERS[name](ctx)
    finally:
        ctx.close()
    return paths


__all__ = ["FIGURES", "plot_bifurcation", "reproduce"]
