"""The paper's Figs. 2-11, regenerated with the truth beside them: ``reproduce("fig6")``.

| figure | panels (as the paper) | drawn | parameter set |
|---|---|---|---|
| fig2 | (a) n = 2, (b) n = 4 | impulse train F(t) | F0 = 0.1 |
| fig3 | (a) phase plane, (b) constraint plane | DMR and EMR_0 vs c | 3.1 |
| fig4 | (a)/(c) portraits, (b)/(d) time histories | DMR, EMR_0 at c = 0.05, 0.035 | 3.1 |
| fig5 | (a) ω = 3.98, (b) ω = 4.2 | DMR, EMR_0 portraits | 3.2 |
| fig6 | (a)-(d) (ω, σ) = (3.98, 0.01) .. (4.2, 0.03) | EMR and MC mean portraits | 3.2 |
| fig7 | (a) σ = 0.1, (b) σ = 0.2 at ω = 4.00495 | EMR and MC mean portraits | 3.3 |
| fig8 | (a) σ = 0.1, (b) σ = 0.18 at ω = 3.98 | EMR and MC mean portraits | 3.3 |
| fig9 | (a)-(d) σ = 0, 0.1, 0.16, 0.18 | EMR (and MC mean) vs ω, phase plane | 3.3 |
| fig10 | (a)-(d) n = 2, 4 x both sections | EMR_0 vs c, F0 = 10 | 3.4 |
| fig11 | (a)-(d) F0 in {0.1, 10} x n in {2, 4} | EMR_0, DMR portraits at c = 0.0356 | 3.4 |

Wherever a figure shows the EMR (OPA with σ > 0) it also shows the mean of a Monte
Carlo ensemble of the true sampled systems (``mc.simulate_mc``, scrambled Sobol points)
with its ± 2 standard errors and its spread, so that OPA's "diffusion" can be told from
the stochastic oscillator's. Each figure writes beside ``figN.png``:

- ``figN.txt``: the caption (what is drawn, the sizes used), the paper's caption, and
  the differences from the paper measured on this run;
- netCDF data: the sweeps of the bifurcation figures (``figN_<run>.nc``, resumable
  while unfinished) or the drawn windows of the portrait figures (``figN.nc``), with
  the caption and the differences as attributes.

Bifurcation lines are drawn only at located bifurcations listed in the sweep dataset
(``opa.plots._diagrams.located_marks``); brute-force period labels are reported in the text,
never drawn as bifurcations. Panel titles carry the labels z = n/p measured on that run.

Default sizes: 61 sweep values, 300 + 60 periods; portraits 500 + 100 periods; Monte
Carlo 256 Sobol samples per portrait and 256 per sweep value at every 10th value.
``full=True``: 200 values, 500 + 100 periods, 1024 and 512 samples.

The sections shown: phase plane = the state (x, dx/dt) at t = k 2π/ω; constraint plane =
the pre-impact velocity at x = Δ (plotted against the parameter).
"""

from __future__ import annotations

import dataclasses
import math
import os
import textwrap
from collections import Counter
from dataclasses import dataclass, field

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

from opa.engine import (  # noqa: E402
    check_order, identify_motion, mean_state, phase_section, preset, SolverOptions, System,
)
from opa.plots import (  # noqa: E402
    COLORS,
    SECTION_LABELS,
    located_marks,
    describe_marks,
    diagram,
    draw_marks,
    history,
    PoincareMarks,
    plot_bifurcation,
    portrait,
    section_bars,
    window,
)

FIGURES = ("fig2", "fig3", "fig4", "fig5", "fig6", "fig7", "fig8", "fig9", "fig10", "fig11")

#: the paper's captions, for the text beside each figure
PAPER_CAPTIONS = {
    "fig2": "The periodic impulse force F(t) vs. t for F0 = 0.1. (a) n = 2; (b) n = 4",
    "fig3": "Bifurcation diagrams of DMR and EMR_0 vs. c, (a) the phase plane as Poincaré "
            "section, (b) the constraint plane as Poincaré section",
    "fig4": "(a) The phase portraits and Poincaré sections for c = 0.05, (b) the time "
            "histories for c = 0.05, the periodic 2/2 motion, (c) the phase portraits and "
            "Poincaré sections for c = 0.035, (d) the time histories for c = 0.035, the "
            "periodic 4/4 motion",
    "fig5": "The phase portraits (a) ω = 3.98, the periodic 6/2 motion, (b) ω = 4.2, the "
            "periodic 3/1 motion",
    "fig6": "EMR for different values of σ as (a) ω = 3.98, σ = 0.01, (b) ω = 3.98, "
            "σ = 0.014, (c) ω = 4.2, σ = 0.02, (d) ω = 4.2, σ = 0.03",
    "fig7": "EMR for different values of σ as ω = 4.00495, (a) σ = 0.1; (b) σ = 0.2",
    "fig8": "EMR for different values of σ as ω = 3.98, (a) σ = 0.1, (b) σ = 0.18",
    "fig9": "The bifurcation diagrams of EMR vs. ω for different values of σ, (a) σ = 0.0; "
            "(b) σ = 0.1; (c) σ = 0.16; (d) σ = 0.18",
    "fig10": "The bifurcation diagrams of EMR_0 vs. c with stronger impulse force, (a) the "
             "phase plane as Poincaré section with n = 2, (b) the constraint plane as "
             "Poincaré section with n = 2, (c) the phase plane as Poincaré section with "
             "n = 4, (d) the constraint plane as Poincaré section with n = 4",
    "fig11": "The phase portraits for c = 0.0356, (a) F0 = 0.1, n = 2; (b) F0 = 0.1, n = 4; "
             "(c) F0 = 10.0, n = 2; (d) F0 = 10.0, n = 4",
}


# --------------------------------------------------------------------------- sizes, context


@dataclass(frozen=True)
class Sizes:
    """How much each figure computes.

    ``count``, ``transient``, ``record``: sweep values and periods of the bifurcation
    diagrams; ``portrait_transient``, ``portrait_record``: periods of the portrait runs;
    ``last``: periods drawn in a portrait; ``mc_samples``: Sobol samples of a portrait's
    Monte Carlo run; ``sweep_mc_samples`` and ``sweep_mc_stride``: Sobol samples of the
    Monte Carlo mean at every ``sweep_mc_stride``-th sweep value.
    """

    count: int = 61
    transient: int = 300
    record: int = 60
    portrait_transient: int = 500
    portrait_record: int = 100
    last: int = 30
    mc_samples: int = 256
    sweep_mc_samples: int = 256
    sweep_mc_stride: int = 10


DEFAULT_SIZES = Sizes()
FULL_SIZES = Sizes(count=200, transient=500, record=100, mc_samples=1024,
                   sweep_mc_samples=512, sweep_mc_stride=10)


class _Context:
    """Sizes and shared resources of one ``reproduce`` call."""

    def __init__(self, outdir, sizes: Sizes = DEFAULT_SIZES, *, options=None, order=4,
                 impulse="dirac", pulse_width=0.1, impulse_at_zero=True, workers=1,
                 scheduler=None, progress=False, log=None):
        self.outdir = os.fspath(outdir)
        self.sizes = sizes
        self.options = options or SolverOptions()
        # the impulse model of every figure (the System's fields)
        self.impulse_model = {"impulse": impulse, "pulse_width": pulse_width,
                              "impulse_at_zero": impulse_at_zero}
        self.impulse, self.pulse_width = impulse, pulse_width
        System(preset("3.1"), **self.impulse_model)  # checks the model before any figure
        self.order = order
        self.workers = workers
        self.scheduler = scheduler
        self.progress = progress
        self.log = log
        self.executor = None

    def sweep(self, name, model, param, values, osc, **kw):
        from opa.engine import local_executor, sweep

        if self.executor is None and self.scheduler is None and self.workers > 1:
            self.executor = local_executor(self.workers)
        s = self.sizes
        out = os.path.join(self.outdir, f"{name}.nc")
        if model == "mc":
            from mc import sweep_source

            kw = {"samples": s.sweep_mc_samples, "sampler": "sobol", "source": sweep_source,
                  **kw}
        kw = {"transient": s.transient, "record": s.record, **kw}
        ds = sweep(model, param, values, osc, options=self.options, order=self.order,
                   out=out, scheduler=self.scheduler, executor=self.executor,
                   workers=self.workers, progress=self.progress, **self.impulse_model, **kw)
        if self.log:
            from opa.engine import summary_lines

            self.log(f"  {name}:")
            for line in summary_lines(ds):
                self.log("  " + line)
        return ds, out

    def times(self, osc, record=None):
        from opa.engine import sweep_times

        # strong impulses (F0 = 10) kick the velocity far up, and the cubic damping brings
        # it back within a fraction of a period: resolve that in the drawn trajectory
        per_period = 512 if osc.F0 >= 1.0 else 64
        s = self.sizes
        return sweep_times(System(osc, **self.impulse_model), s.portrait_transient,
                           record or s.portrait_record, per_period)

    def run(self, model, osc, *, sigma=0.0, record=None):
        """One portrait run on a grid that is stroboscopic through the transient."""
        from opa.engine import simulate_dmr, simulate_opa

        times = self.times(osc, record)
        if model == "dmr":
            ds = simulate_dmr(osc, times=times, options=self.options, **self.impulse_model)
        else:
            ds = simulate_opa(osc, sigma=sigma, order=self.order, times=times,
                              options=self.options, **self.impulse_model)
        ds.attrs["transient"] = self.sizes.portrait_transient
        return ds

    def mc(self, osc, sigma):
        """The Monte Carlo ensemble on the portrait grid (scrambled Sobol, seed 0)."""
        from mc import simulate_mc

        ds = simulate_mc(osc, sigma=sigma, samples=self.sizes.mc_samples, sampler="sobol",
                         seed=0, order=self.order, times=self.times(osc),
                         options=self.options, scheduler=self.scheduler,
                         progress=self.progress, **self.impulse_model)
        ds.attrs["transient"] = self.sizes.portrait_transient
        return ds

    def start(self, ds) -> float:
        """End of a portrait run's transient (a time)."""
        return self.sizes.portrait_transient * 2 * math.pi / ds.attrs["omega"]

    def motion(self, ds):
        return identify_motion(ds, start=self.start(ds))

    def close(self):
        if self.executor is not None:
            self.executor.shutdown()


@dataclass
class Drawn:
    """A finished figure before it is written: the figure, its caption (also its
    suptitle), the measured differences from the paper, and data to keep beside it."""

    name: str
    fig: plt.Figure
    caption: str
    differences: list[str]
    data: xr.Dataset | None = None
    files: list[str] = field(default_factory=list)


def _drawn(ctx, name, fig, caption, differences, *, data=None, files=(), width=150):
    fig.suptitle(textwrap.fill(caption, width), fontsize=9)
    return Drawn(name, fig, caption, differences, data, list(files))


def _write(ctx, drawn: Drawn) -> list[str]:
    """PNG, text and data of a drawn figure; returns the paths written."""
    from opa.engine import atomic_write, write_netcdf

    png = os.path.join(ctx.outdir, f"{drawn.name}.png")
    drawn.fig.savefig(png, dpi=110)
    plt.close(drawn.fig)
    txt = os.path.join(ctx.outdir, f"{drawn.name}.txt")

    def write_text(path):
        with open(path, "w", encoding="utf-8") as f:
            f.write(_text(ctx, drawn))

    atomic_write(txt, write_text, suffix=".txt")
    paths = [png, txt]
    if drawn.data is not None:
        nc = os.path.join(ctx.outdir, f"{drawn.name}.nc")
        drawn.data.attrs.update(caption=drawn.caption,
                                differences="\n".join(drawn.differences))
        write_netcdf(drawn.data, nc)
        paths.append(nc)
    paths += drawn.files
    if ctx.log:
        for p in paths:
            ctx.log(f"  wrote {p}")
    return paths


def _text(ctx, drawn: Drawn) -> str:
    number = drawn.name[3:]
    s = ctx.sizes
    lines = [f"Fig. {number}: opa-mc reproduce {drawn.name} (impulse {ctx.impulse}, "
             f"OPA order N = {ctx.order}; sweeps {s.count} values, {s.transient} + "
             f"{s.record} periods; portraits {s.portrait_transient} + {s.portrait_record} "
             f"periods; Monte Carlo {s.mc_samples} Sobol samples per portrait, "
             f"{s.sweep_mc_samples} per sweep value)", "",
             "Caption (what is drawn):", textwrap.fill(drawn.caption, 92), "",
             "The paper's caption:", textwrap.fill(PAPER_CAPTIONS[drawn.name], 92), "",
             "Differences from the paper (measured on this run):"]
    for d in drawn.differences:
        lines.append(textwrap.fill(d, 92, initial_indent="- ", subsequent_indent="  "))
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- measurements


def _label_text(motion) -> str:
    if motion.period:
        return f"z = {motion.label}"
    return f"no period (nearest {motion.nearest_period}, res. {motion.residual:.1g})"


def _period_text(motion) -> str:
    """A Monte Carlo mean has no impacts of its own: its period only."""
    if motion.period:
        return f"period {motion.period}"
    return f"no period (nearest {motion.nearest_period}, res. {motion.residual:.1g})"


def _max_difference(a, b) -> float:
    """Largest |x_a - x_b| over two runs on the same grid."""
    xa, _, _ = mean_state(a)
    xb, _, _ = mean_state(b)
    return float(np.max(np.abs(xa - xb)))


def _difference_text(dmr, emr0, m_dmr) -> str:
    """EMR_0 against the DMR over a whole run (they are the same system when σ = 0)."""
    d = _max_difference(dmr, emr0)
    if d < 1e-6:
        return f"EMR_0 = DMR to {d:.2g} over the run"
    why = (": the motion has no period and round-off grows along it" if m_dmr.period == 0
           else "")
    return f"EMR_0 and DMR part by up to {d:.2g} over the run{why}"


def _without_impulses(ctx, osc) -> str:
    """The DMR label of the same run with F0 = 0: is the impulse train the difference?"""
    m = ctx.motion(ctx.run("dmr", dataclasses.replace(osc, F0=0.0)))
    return f"the same DMR run without impulses (F0 = 0) gives {m.label}"


def _row_max(a: np.ndarray) -> np.ndarray:
    """Largest finite value of each row, NaN for a row without one (a failed value)."""
    a = np.where(np.isfinite(a), a, -np.inf).max(axis=1)
    return np.where(np.isfinite(a), a, np.nan)


def _label_counts(ds) -> str:
    counts = Counter(str(v) for v in ds.label.values)
    return ", ".join(f"{k} x{n}" for k, n in counts.most_common())


def _nearest(ds, value):
    param = ds.attrs["sweep_parameter"]
    i = int(np.argmin(np.abs(ds[param].values - value)))
    return float(ds[param].values[i]), str(ds.label.values[i])


def _observed_period_changes(ds) -> int:
    """Neighbours that are both periodic with different periods (brute-force labels)."""
    p = ds.period.values
    return int(np.sum((p[1:] > 0) & (p[:-1] > 0) & (p[1:] != p[:-1])))


def _cycle(osc) -> int | None:
    from opa.engine import impulse_cycle

    return impulse_cycle(osc)


def _cycle_note(osc, record: int) -> str:
    """Why a label can or cannot come out: the forcing's own repeat (impulse train)."""
    from opa.engine import MAX_CYCLE

    k = _cycle(osc)
    if k is None:
        return (f"harmonic forcing and impulse train have no common cycle within {MAX_CYCLE} "
                f"forcing periods (ω/ω1 = {osc.omega / osc.omega1:g}), so no motion is "
                f"strictly periodic")
    text = (f"harmonic forcing and impulse train repeat together every {k} forcing periods, "
            f"so a periodic motion's period is a multiple of {k}")
    if k > record // 2:
        text += (f"; a record of {record} periods shows repeats up to {record // 2} only, so "
                 f"'none' is certain here whatever the motion")
    return text


def _emr0_dmr_text(dmr, emr0, record: int) -> str:
    """How closely EMR_0's sweep follows the DMR's (their truth at sigma = 0)."""
    gap = _row_max(np.abs(dmr.section_x.values[:, :record] - emr0.section_x.values[:, :record]))
    count = len(gap)
    close = int(np.sum(gap < 1e-6))
    same = int(np.sum(dmr.label.values == emr0.label.values))
    worst = float(np.max(gap, initial=0.0, where=np.isfinite(gap)))
    where = (f"all {count} values" if close == count else
             f"{close} of {count} values, and differ by up to {worst:.2g} at the others "
             f"(round-off grows along non-periodic motion)")
    return (f"EMR_0 against the DMR: phase-plane points within 1e-6 at {where}; the labels "
            f"agree at {same} of {count} values")


def _opa_not_located(ctx, osc, param, values, sigma) -> str:
    """Why a figure's OPA sweep has no located bifurcations: the reason the continuation
    cannot be done, or (EMR_0) where the DMR's, which are EMR_0's, are located."""
    from opa.engine import locate_setup

    system = System(osc, sigma=sigma, order=ctx.order, **ctx.impulse_model)
    try:
        locate_setup(True, "opa", param, np.asarray(values, dtype=float), system,
                      ctx.options)
    except ValueError as err:
        return "not located: " + str(err).removeprefix("locate=True: ")
    cycle = _cycle(osc)
    return ("not located here: the OPA system is continued only on request; EMR_0 equals "
            f"the DMR, whose bifurcations `opa-mc bifurcation dmr --locate` locates over "
            f"the same {param} (maps over the forcing's cycle of {cycle} periods)")


def _marks_text(marks, param, ds=None, why=None) -> str:
    """The located bifurcations for the text beside a figure, with the dataset's notes
    (``why``: the reason there are none, instead of the dataset's)."""
    if not marks:
        why = why or (ds.attrs.get("bifurcation_method", "") if ds is not None else "")
        why = f" ({why})" if why and not why.startswith("continuation") else ""
        return (f"no located bifurcations in the sweep dataset{why}, so no bifurcation lines "
                f"are drawn")
    text = describe_marks(marks, param)
    if ds is not None and {"bifurcation_parameter", "bifurcation_note"} <= set(ds.variables):
        notes = {round(float(v), 12): str(n) for v, n in
                 zip(ds.bifurcation_parameter.values, ds.bifurcation_note.values)}
        said = [f"{param} = {v:.8g}: {notes[round(v, 12)]}" for v, _, _ in marks
                if notes.get(round(v, 12))]
        if said:
            text += " (" + "; ".join(said) + ")"
    return text


def _merge_marks(*datasets):
    seen, out = set(), []
    for ds in datasets:
        for m in located_marks(ds):
            key = (round(m[0], 9), m[1])
            if key not in seen:
                seen.add(key)
                out.append(m)
    return sorted(out)


def _variance_summary(ctx, emr, mc) -> dict:
    """OPA's and the ensemble's Var[x] over the record: largest and at the end."""
    t = emr.time.values
    rec = t > ctx.start(emr) * (1 + 1e-12)
    i = int(np.argmax(np.where(rec, emr.x_var.values, -np.inf)))
    j = int(np.argmax(np.where(rec, mc.x_var.values, -np.inf)))
    return {"opa_end": float(emr.x_var.values[-1]), "opa_max": float(emr.x_var.values[i]),
            "opa_t": float(t[i]), "mc_end": float(mc.x_var.values[-1]),
            "mc_end_sem": float(mc.x_var_sem.values[-1]) if "x_var_sem" in mc else math.nan,
            "mc_max": float(mc.x_var.values[j]), "mc_t": float(t[j]),
            "mean_gap": float(np.max(np.abs(mean_state(emr)[0][rec] - mean_state(mc)[0][rec])))}


def _verdict(v) -> str:
    """The words that follow from the two variances (not from the paper)."""
    mc_top = v["mc_max"] + 2 * (v["mc_end_sem"] if math.isfinite(v["mc_end_sem"]) else 0)
    ratio = v["opa_max"] / max(mc_top, 1e-300)
    if max(v["opa_max"], v["mc_max"]) < 1e-3:
        return (f"neither spreads visibly (std of x at most "
                f"{math.sqrt(max(v['opa_max'], v['mc_max'])):.2g}; OPA/MC variance ratio "
                f"{ratio:.2g})")
    if ratio >= 10:
        return (f"OPA's spread is {ratio:.3g} x the true ensemble's: the diffusion is an "
                f"artefact of the equivalent system")
    if ratio >= 3:
        return f"OPA's spread is {ratio:.2g} x the true ensemble's"
    if ratio > 1 / 3:
        return (f"the two spreads are comparable (ratio {ratio:.2g}): the spread is the "
                f"stochastic system's own")
    return f"OPA's spread is {1 / ratio:.2g} x smaller than the true ensemble's"


def _grazing_text(m_emr, m_dmr) -> str:
    """What the runs say about grazing (the thresholds of ``identify_motion``)."""
    speeds = (f"the slowest impact in the record has speed {m_emr.min_impact_velocity:.4g} "
              f"(EMR; DMR {m_dmr.min_impact_velocity:.4g})")
    if math.isfinite(m_emr.min_gap) or math.isfinite(m_dmr.min_gap):
        gaps = (f"the highest free-flight maximum stays {m_emr.min_gap:.3g} (EMR; DMR "
                f"{m_dmr.min_gap:.3g}) below the wall")
    else:
        gaps = "every free flight ends in an impact (no maximum below the wall)"
    if m_emr.grazing or m_dmr.grazing:
        return (f"Grazing flagged (EMR {m_emr.grazing}, DMR {m_dmr.grazing}): {speeds}; "
                f"{gaps}.")
    return (f"No grazing (an impact slower than 0.01 or a maximum within 1e-4 of the wall "
            f"would count): {speeds}; {gaps}.")


# --------------------------------------------------------------------------- Fig. 2


def fig2(ctx):
    fig, axes = plt.subplots(2, 1, figsize=(9, 5.8), sharex=True, layout="constrained")
    t_end = 64.0
    heights = {}
    for ax, n, tag in zip(axes, (2, 4), "ab"):
        osc = preset("3.1", n=float(n))
        system = System(osc, **ctx.impulse_model)
        T1 = system.impulse_period
        tj = system.impulse_times(t_end)
        height = system.impulse_heights(tj)
        heights[n] = height
        tt = np.linspace(0, t_end, 2000)
        ax.plot(tt, system.impulse_heights(tt), ":",
                color="gray", lw=1, label="F0 (1 + a1 sin(ω1 t / n)) (switched signal)")
        if ctx.impulse == "dirac":
            ax.vlines(tj, 0, height, color="black", lw=1.5)
            ax.plot(tj, height, "o", color="black", ms=4, label="impulse strength (Dirac)")
        else:
            tau = ctx.pulse_width
            for tk, hk in zip(tj, height):
                ax.fill_between([tk, tk + tau], 0, hk, color="black", step="pre")
            ax.plot([], [], "s", color="black", label=f"rectangular pulse, width {tau:g}")
        ax.set_ylabel("F(t)")
        ax.set_title(f"({tag}) n = {n}: impulses every 2π/ω1 = {T1:.4g}, F0 = {osc.F0:g}, "
                     f"a1 = {osc.a1:g}", fontsize=10)
        ax.set_ylim(-0.005, 2.8 * osc.F0)
        ax.legend(fontsize=7, loc="upper center", ncol=2)
    axes[-1].set_xlabel("t [time units]")  # the paper's axis: its caption counts 0..64
    shape = ("stems: the strengths of the Dirac impulses" if ctx.impulse == "dirac"
             else f"black: rectangular pulses of width {ctx.pulse_width:g}")
    caption = (f"Fig. 2: the impulse force F(t) for F0 = 0.1, a1 = 1, ω1 = 1, 0 ≤ t ≤ "
               f"{t_end:g}: (a) n = 2, (b) n = 4; {shape} at t_j = j 2π/ω1 (j from "
               f"{0 if ctx.impulse_model['impulse_at_zero'] else 1}); dotted: the switched "
               "signal "
               f"F0 (1 + a1 sin(ω1 t/n)).")

    def cycle(h):
        return ", ".join(f"{x:.3g}" for x in h[:4])

    diffs = [f"None in the force: (a) n = 2 gives every impulse the strength "
             f"{np.unique(np.round(heights[2], 12))[0]:.3g} (sin(π j) = 0), (b) n = 4 "
             f"cycles through {cycle(heights[4])}, as the paper's text describes. The "
             f"paper's plot of a delta train is schematic; here each impulse is drawn at "
             f"its strength."]
    return _drawn(ctx, "fig2", fig, caption, diffs, width=110)


# --------------------------------------------------------------------------- bifurcation figures


def _guide_lines(ax, values, label):
    for k, v in enumerate(values):
        ax.axvline(v, color="tab:purple", lw=0.7, alpha=0.6, label=label if k == 0 else None)


def _finish_section_panel(ax, title: str, points: int) -> None:
    """Title and legend of a section panel; says so when no point was recorded."""
    ax.set_title(title, fontsize=10)
    if points == 0:
        ax.text(0.5, 0.5, "no section points recorded", ha="center", va="center",
                transform=ax.transAxes)
    ax.legend(fontsize=7, loc="best", framealpha=0.85, markerscale=2)


def fig3(ctx):
    s = ctx.sizes
    values = np.linspace(0.01, 0.1, s.count)
    osc = preset("3.1")
    dmr, p_dmr = ctx.sweep("fig3_dmr", "dmr", "c", values, osc)
    emr0, p_emr0 = ctx.sweep("fig3_emr0", "opa", "c", values, osc, sigma=0.0)
    marks = _merge_marks(dmr, emr0)
    guide = (0.035, 0.05)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), layout="constrained")
    for ax, section, tag in zip(axes, ("phase", "constraint"), "ab"):
        n = diagram(ax, dmr, section, color=COLORS["DMR"], label="DMR", ms=4.0, marker="o")
        diagram(ax, emr0, section, color=COLORS["EMR_0"], label=f"EMR_0 (N = {ctx.order})",
                ms=2.2, zorder=3)
        _guide_lines(ax, guide, "c = 0.035, 0.05 (Fig. 4)")
        draw_marks(ax, marks)
        _finish_section_panel(ax, f"({tag}) {SECTION_LABELS[section][1]}", n)
    caption = (f"Fig. 3: bifurcation diagrams vs c, set 3.1 (F0 = 0.1, {ctx.impulse} "
               f"impulses), {s.count} values of c, {s.record} recorded periods after "
               f"{s.transient}: (a) phase plane (x at t = k 2π/ω), (b) constraint plane "
               f"(pre-impact velocity); DMR black circles, EMR_0 orange dots on top; purple: "
               f"c = 0.035 and 0.05 of Fig. 4; {describe_marks(marks, 'c')}.")
    c35, l35 = _nearest(dmr, 0.035)
    c50, l50 = _nearest(dmr, 0.05)
    r = s.record
    per_value = _row_max(np.abs(dmr.section_x.values[:, :r] - emr0.section_x.values[:, :r]))
    close = per_value < 1e-6
    worst = float(np.max(per_value, initial=0.0, where=np.isfinite(per_value)))
    same = int(np.sum(dmr.label.values == emr0.label.values))
    diffs = [
        f"The paper reads a 4/4 motion at c = 0.035 turning into 2/2 at c = 0.05. Measured "
        f"DMR labels: {l35} at c = {c35:.4g} and {l50} at c = {c50:.4g} (the nearest sweep "
        f"values); over all {s.count} values: {_label_counts(dmr)}. Why: "
        f"{_cycle_note(osc, s.record)}.",
        f"Brute-force period changes between periodic neighbours: "
        f"{_observed_period_changes(dmr)} (reported, not drawn as bifurcations); "
        f"{_marks_text(marks, 'c', dmr)}.",
        f"EMR_0 against DMR: phase-plane points within 1e-6 at {int(close.sum())} of "
        f"{s.count} values; at the other {int((~close).sum())} (of which "
        f"{int(np.sum(~close & (dmr.period.values == 0)))} without a period) they differ by "
        f"up to {worst:.2g}: round-off grows along non-periodic motion. The "
        f"labels agree at {same} of {s.count} values.",
    ]
    return _drawn(ctx, "fig3", fig, caption, diffs, files=[p_dmr, p_emr0])


def fig9(ctx):
    s = ctx.sizes
    values = np.linspace(3.9, 5.9, s.count)
    mc_values = values[:: s.sweep_mc_stride]
    osc = preset("3.3")
    sigmas = (0.0, 0.1, 0.16, 0.18)
    fig, axes = plt.subplots(2, 2, figsize=(12, 8), sharey=True, layout="constrained")
    files, diffs, all_marks, firsts = [], [], [], []
    for ax, sigma, tag in zip(axes.ravel(), sigmas, "abcd"):
        emr, path = ctx.sweep(f"fig9_sigma{sigma:g}", "opa", "omega", values, osc,
                              sigma=sigma)
        files.append(path)
        name = "EMR_0" if sigma == 0 else "EMR"
        line = f"({tag}) σ = {sigma:g}: "
        if sigma == 0:  # the truth at sigma = 0 is the DMR
            dmr, path = ctx.sweep("fig9_dmr", "dmr", "omega", values, osc, locate=False)
            files.append(path)
            diagram(ax, dmr, "phase", color=COLORS["DMR"], label="DMR", ms=4.0, marker="o")
            line += f"{_emr0_dmr_text(dmr, emr, s.record)}; "
        diagram(ax, emr, "phase", color=COLORS[name], label=name,
                **({"ms": 2.2, "zorder": 3} if sigma == 0 else {}))
        if sigma > 0:
            mc, path = ctx.sweep(f"fig9_mc_sigma{sigma:g}", "mc", "omega", mc_values, osc,
                                 sigma=sigma)
            files.append(path)
            diagram(ax, mc, "phase", color=COLORS["MC mean"], marker="x", ms=4,
                    label=f"MC mean ({s.sweep_mc_samples} Sobol samples)", zorder=4)
            sub = emr.sel(omega=mc_values, method="nearest")
            r = s.record
            gap = np.abs(sub.section_x.values[:, :r] - mc.section_x.values[:, :r])
            rows = _row_max(gap)
            k = int(np.argmax(np.where(np.isfinite(rows), rows, -np.inf)))
            finite = gap[np.isfinite(gap)]
            line += (f"EMR against the MC mean at {len(mc_values)} values of ω: largest "
                     f"phase-plane difference {rows[k]:.2g} (at ω = {mc_values[k]:.4g}), "
                     f"median {np.median(finite) if finite.size else math.nan:.2g}; ")
        marks = located_marks(emr)
        all_marks.append(marks)
        _guide_lines(ax, (3.98, 4.00495), "ω = 3.98, 4.00495 (Figs. 7, 8)")
        draw_marks(ax, marks)
        ax.set_title(f"({tag}) σ = {sigma:g}" + (" (EMR_0)" if sigma == 0 else ""),
                     fontsize=10)
        ax.legend(fontsize=7, loc="upper left", framealpha=0.85, markerscale=2)
        graze = emr.omega.values[emr.grazing.values == 1]
        first = float(graze[0]) if len(graze) else math.nan
        firsts.append(first)
        slow = int(np.nanargmin(np.where(np.isfinite(emr.min_impact_velocity.values),
                                         emr.min_impact_velocity.values, np.inf)))
        why = None if marks else _opa_not_located(ctx, osc, "omega", values, sigma)
        line += (f"first grazing flag (impact slower than {emr.attrs['graze_velocity']:g} or "
                 f"free flight within {emr.attrs['graze_gap']:g} of the wall) at ω = "
                 f"{_first_text(first)}; slowest impact "
                 f"{emr.min_impact_velocity.values[slow]:.3g} at "
                 f"ω = {emr.omega.values[slow]:.4g}; periodic at "
                 f"{int(np.sum(emr.period.values > 0))} of {s.count} values; "
                 f"{_marks_text(marks, 'ω', emr, why)}.")
        diffs.append(line)
    for ax in axes[:, 1]:
        ax.set_ylabel("")
    drawn_marks = "; ".join(f"({t}) {describe_marks(m, 'ω')}" for t, m in
                            zip("abcd", all_marks)) if any(all_marks) else \
        describe_marks([], "ω")
    caption = (f"Fig. 9: bifurcation diagrams vs ω in the phase plane (x at t = k 2π/ω), set "
               f"3.3 (a = f = 3.5, c = 0.05, F0 = 0.1), {s.count} values of ω, {s.record} "
               f"recorded periods after {s.transient}: (a) EMR_0 (σ = 0, orange dots) on the DMR "
               f"(black circles, its "
               f"truth), (b)-(d) "
               f"EMR for σ = 0.1, 0.16, 0.18 (blue) with the Monte Carlo mean (green x, "
               f"{s.sweep_mc_samples} Sobol samples, at every {s.sweep_mc_stride}th ω); "
               f"purple: ω = 3.98 and 4.00495 of Figs. 7-8; {drawn_marks}.")
    ok = [f for f in firsts if math.isfinite(f)]
    if len(ok) < 2:
        trend = "cannot be compared: too few diagrams have a grazing flag"
    elif len(ok) == len(firsts) and all(b < a for a, b in zip(ok, ok[1:])):
        trend = "moves earlier with every increase of σ"
    else:
        trend = "does not move earlier with every increase of σ"
    fits = sum(1 for w in values if (k := _cycle(preset("3.3", omega=float(w)))) is not None
               and k <= s.record // 2)
    diffs.insert(0, f"Periodic labels can only come out where harmonic forcing and impulse "
                    f"train repeat together within {s.record // 2} forcing periods (half the "
                    f"record): at {fits} of the {s.count} values of ω.")
    diffs.insert(0, f"The paper: grazing appears in advance as σ grows. Measured first "
                    f"grazing flag at ω = {', '.join(_first_text(f) for f in firsts)} for "
                    f"σ = 0, 0.1, 0.16, 0.18: it {trend} (sweep step "
                    f"{values[1] - values[0]:.3g}).")
    return _drawn(ctx, "fig9", fig, caption, diffs, files=files)


def _record_for(osc, record: int, longest: int = 100) -> int:
    """A record long enough to see the forcing's own cycle twice (if it is not too long)."""
    k = _cycle(osc)
    return max(record, 2 * k) if k is not None and k <= longest else record


def _records_text(records, ns) -> str:
    if len(set(records)) == 1:
        return f"{records[0]} recorded periods"
    return ", ".join(f"{r} recorded periods for n = {n}" for r, n in zip(records, ns))


def _first_text(value: float) -> str:
    return f"{value:.4g}" if math.isfinite(value) else "none"


def fig10(ctx):
    s = ctx.sizes
    values = np.linspace(0.01, 0.1, s.count)
    fig, axes = plt.subplots(2, 2, figsize=(12, 8), layout="constrained")
    files, diffs, all_marks, records = [], [], [], []
    for row, n, tags in zip(axes, (2, 4), ("ab", "cd")):
        osc = preset("3.4", n=float(n))
        record = _record_for(osc, s.record)
        emr0, path = ctx.sweep(f"fig10_n{n}", "opa", "c", values, osc, sigma=0.0,
                               record=record)
        # the truth at sigma = 0 is the DMR (not located here: see _opa_not_located)
        dmr, p_dmr = ctx.sweep(f"fig10_dmr_n{n}", "dmr", "c", values, osc, record=record,
                               locate=False)
        files += [path, p_dmr]
        marks = located_marks(emr0)
        all_marks.append(marks)
        for ax, section, tag in zip(row, ("phase", "constraint"), tags):
            diagram(ax, dmr, section, color=COLORS["DMR"], label="DMR", ms=4.0, marker="o")
            cnt = diagram(ax, emr0, section, color=COLORS["EMR_0"], label="EMR_0", ms=2.2,
                          zorder=3)
            _guide_lines(ax, (0.0356,), "c = 0.0356 (Fig. 11)")
            draw_marks(ax, marks)
            _finish_section_panel(ax, f"({tag}) n = {n}: {SECTION_LABELS[section][1]}", cnt)
        why = None if marks else _opa_not_located(ctx, osc, "c", values, 0.0)
        diffs.append(f"n = {n}: {_emr0_dmr_text(dmr, emr0, record)}.")
        diffs.append(f"n = {n}: periodic at {int(np.sum(emr0.period.values > 0))} of "
                     f"{s.count} values of c ({_label_counts(emr0)}) in a record of {record} "
                     f"periods; {_cycle_note(osc, record)}; "
                     f"{_marks_text(marks, 'c', emr0, why)}.")
        records.append(record)
    marks_text = ("; ".join(f"n = {n}: {describe_marks(m, 'c')}" for n, m in
                            zip((2, 4), all_marks)) if any(all_marks)
                  else describe_marks([], "c"))
    caption = (f"Fig. 10: EMR_0 (σ = 0, N = {ctx.order}) and DMR bifurcation diagrams vs c, "
               f"set 3.4 "
               f"with the stronger impulse F0 = 10, {s.count} values of c, "
               f"{_records_text(records, (2, 4))} after {s.transient}: (a) phase plane and "
               f"(b) constraint "
               f"plane for n = 2, (c), (d) the same for n = 4; DMR black circles, EMR_0 "
               f"orange dots on top (σ = 0: the DMR is the truth); purple: c = 0.0356 of "
               f"Fig. 11;"
               f" {marks_text}.")
    diffs.insert(0, "The paper sees stronger 'diffusion' with F0 = 10 and more with n = 4. "
                    "EMR_0 has σ = 0, so what spreads here is the deterministic motion: a "
                    "value of c without a period shows as a vertical cloud, and a long period "
                    "as many points. With n = 4 the impulse strengths repeat only every 4 "
                    "impulses, which lengthens the forcing's own cycle (the records are "
                    "lengthened to show it).")
    return _drawn(ctx, "fig10", fig, caption, diffs, files=files)


# --------------------------------------------------------------------------- portraits


def _window_data(panels, keys, last) -> xr.Dataset:
    """The drawn windows of a portrait figure: ``(panel, k)`` arrays per run."""
    n = max(int(window(runs[k], last).sum()) for _, runs in panels for k in runs)
    data = {}

    def put(name, tag_values, long_name):
        arr = np.full((len(panels), n), np.nan)
        for i, v in enumerate(tag_values):
            if v is not None:
                arr[i, : len(v)] = v
        data[name] = (("panel", "k"), arr, {"long_name": long_name, "units": "1"})

    first = keys[0]
    put("time", [runs[first].time.values[window(runs[first], last)] for _, runs in panels],
        "time t of the drawn window")
    for key in keys:
        def pick(fn, key=key):
            out = []
            for _, runs in panels:
                ds = runs.get(key)
                out.append(None if ds is None else fn(ds)[window(ds, last)])
            return out

        put(f"{key}_x", pick(lambda ds: mean_state(ds)[0]), f"{key}: x (mean coordinate)")
        put(f"{key}_v", pick(lambda ds: mean_state(ds)[1]), f"{key}: dx/dt")
        if key in ("emr", "mc"):
            put(f"{key}_x_var", pick(lambda ds: ds.x_var.values), f"{key}: Var[x]")
        if key == "mc":
            put("mc_x_sem", pick(lambda ds: ds.x_sem.values), "mc: standard error of x_mean")
    return xr.Dataset(data, coords={"panel": [t for t, _ in panels]})


def _deterministic_panel(ctx, ax, osc, marker, tag, head):
    """DMR (black) and EMR_0 (orange dashed) with the DMR's Poincaré points."""
    last = ctx.sizes.last
    dmr = ctx.run("dmr", osc)
    emr0 = ctx.run("opa", osc, sigma=0.0)
    m_dmr, m_emr0 = ctx.motion(dmr), ctx.motion(emr0)
    portrait(ax, dmr, last=last, lw=1.3, points=PoincareMarks(marker))
    portrait(ax, emr0, last=last, ls="--", points=None, label=f"EMR_0 (N = {ctx.order})",
             zorder=3)
    ax.set_title(f"({tag}) {head}\nDMR: {_label_text(m_dmr)}; EMR_0: {_label_text(m_emr0)}",
                 fontsize=9)
    ax.legend(fontsize=7, loc="best", framealpha=0.85)
    return dmr, emr0, m_dmr, m_emr0


def fig4(ctx):
    s = ctx.sizes
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), layout="constrained")
    panels, diffs = [], []
    for row, c, paper, tags in zip(axes, (0.05, 0.035), ("2/2", "4/4"), ("ab", "cd")):
        osc = preset("3.1", c=c)
        dmr, emr0, m_dmr, m_emr0 = _deterministic_panel(ctx, row[0], osc, "*", tags[0],
                                                        f"c = {c:g}: phase portrait")
        history(row[1], [(dmr, "-"), (emr0, "--")])
        row[1].set_title(f"({tags[1]}) c = {c:g}: time history, last 10 periods", fontsize=9)
        panels.append((f"c={c:g}", {"dmr": dmr, "emr0": emr0}))
        diffs.append(f"c = {c:g}: the paper's {paper}; measured DMR {m_dmr.label}, EMR_0 "
                     f"{m_emr0.label} (stroboscopic repeat within 1e-4 over "
                     f"{s.portrait_record} periods); "
                     f"{_difference_text(dmr, emr0, m_dmr)}; "
                     f"{_cycle_note(osc, s.portrait_record)}; {_without_impulses(ctx, osc)}.")
    caption = (f"Fig. 4: set 3.1 (F0 = 0.1, {ctx.impulse} impulses), {s.last} of "
               f"{s.portrait_record} recorded forcing periods after {s.portrait_transient}: "
               f"(a), (c) phase portraits for c = 0.05 and 0.035, DMR (black) and EMR_0 "
               f"(orange dashed), red *: the DMR's Poincaré points t = k 2π/ω; (b), (d) time "
               f"histories x(t) of the last 10 periods; panel titles: the labels z = n/p "
               f"measured on these runs.")
    return _drawn(ctx, "fig4", fig, caption, diffs,
                  data=_window_data(panels, ["dmr", "emr0"], s.last), width=130)


def fig5(ctx):
    s = ctx.sizes
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), layout="constrained")
    panels, diffs = [], []
    for ax, w, paper, tag in zip(axes, (3.98, 4.2), ("6/2", "3/1"), "ab"):
        osc = preset("3.2", omega=w)
        dmr, emr0, m_dmr, m_emr0 = _deterministic_panel(ctx, ax, osc, "s", tag, f"ω = {w:g}")
        panels.append((f"omega={w:g}", {"dmr": dmr, "emr0": emr0}))
        diffs.append(f"ω = {w:g}: the paper's {paper}; measured DMR {m_dmr.label}, EMR_0 "
                     f"{m_emr0.label} (nearest repeat {m_dmr.nearest_period}, residual "
                     f"{m_dmr.residual:.2g}); "
                     f"{_difference_text(dmr, emr0, m_dmr)}; "
                     f"{_cycle_note(osc, s.portrait_record)}; {_without_impulses(ctx, osc)}.")
    caption = (f"Fig. 5: set 3.2 (σ = 0, F0 = 0.1, {ctx.impulse} impulses), phase "
               f"portraits of the last {s.last} of {s.portrait_record} recorded periods "
               f"after {s.portrait_transient}: (a) ω = 3.98, (b) ω = 4.2; DMR (black), EMR_0 "
               f"(orange dashed), red ■: the DMR's Poincaré points t = k 2π/ω; panel "
               f"titles: the labels z = n/p measured on these runs.")
    return _drawn(ctx, "fig5", fig, caption, diffs,
                  data=_window_data(panels, ["dmr", "emr0"], s.last), width=120)


def _emr_mc_figure(ctx, name, cases, shape, set_name, paper_notes, grazing=False):
    """Panels of EMR (OPA, σ > 0) with the Monte Carlo mean of the true systems beside.

    ``cases``: ``[(tag, oscillator, sigma, head)]``; ``paper_notes``: what the paper says
    of each panel, for the differences.
    """
    s = ctx.sizes
    rows, cols = shape
    fig, axes = plt.subplots(rows, cols, figsize=(5.6 * cols, 4.9 * rows + 0.7),
                             squeeze=False, layout="constrained")
    panels, diffs = [], []
    for ax, (tag, osc, sigma, head), note in zip(axes.ravel(), cases, paper_notes):
        emr = ctx.run("opa", osc, sigma=sigma)
        mc = ctx.mc(osc, sigma)
        m_emr, m_mc = ctx.motion(emr), ctx.motion(mc)
        portrait(ax, emr, last=s.last, color=COLORS["EMR"], lw=2.6, alpha=0.45,
                 points=PoincareMarks("s", size=6, label="EMR at t = k 2π/ω"),
                 label=f"EMR (OPA, N = {ctx.order})")
        section_bars(ax, emr, last=s.last, scale=1.0, spread="std", color="lightsteelblue",
                     label="EMR ± 1 std (OPA variance)", lw=0.8, zorder=1)
        portrait(ax, mc, last=s.last, color=COLORS["MC mean"], lw=1.0,
                 points=PoincareMarks("D", color=COLORS["MC mean"], size=3.5,
                                      label="MC mean at t = k 2π/ω"),
                 label=f"MC mean ({s.mc_samples} Sobol)", zorder=4)
        section_bars(ax, mc, last=s.last, scale=1.0, spread="std", color="yellowgreen",
                     label="MC ± 1 std (ensemble spread)", lw=1.0, zorder=2)
        section_bars(ax, mc, last=s.last, scale=2.0, spread="sem", color="darkgreen",
                     label="MC mean ± 2 SE", lw=1.6, capsize=2.5, zorder=8)
        v = _variance_summary(ctx, emr, mc)
        title = (f"({tag}) {head}, σ = {sigma:g}\nEMR: {_label_text(m_emr)}; MC mean: "
                 f"{_period_text(m_mc)}\nVar[x] at the end: OPA {v['opa_end']:.2g}, "
                 f"MC {v['mc_end']:.2g}")
        panels.append((f"({tag}) {head}, sigma={sigma:g}", {"emr": emr, "mc": mc}))
        text = (f"({tag}) {head}, σ = {sigma:g}: the paper: {note}. Measured: OPA's Var[x] "
                f"grows to {v['opa_max']:.3g} (at t = {v['opa_t']:.1f}; {v['opa_end']:.3g} at "
                f"the end, t = {emr.time.values[-1]:.1f}) while the Monte Carlo Var[x] is at "
                f"most {v['mc_max']:.3g} (at t = {v['mc_t']:.1f}; {v['mc_end']:.3g} ± "
                f"{v['mc_end_sem']:.2g} at the end): {_verdict(v)}. EMR mean and MC mean "
                f"differ by up to {v['mean_gap']:.3g} in x over the record; labels: EMR "
                f"{m_emr.label}, MC mean {_period_text(m_mc)}.")
        if grazing:
            m_dmr = ctx.motion(ctx.run("dmr", osc))
            text += " " + _grazing_text(m_emr, m_dmr)
            title += (f"; slowest impact {m_emr.min_impact_velocity:.3g}: "
                      f"{'grazing' if m_emr.grazing else 'no grazing'}")
        ax.set_title(title, fontsize=8.5)
        diffs.append(text)
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize=8,
               framealpha=0.9)
    caption = (f"Fig. {name[3:]}: set {set_name}, phase portraits of the last {s.last} of "
               f"{s.portrait_record} recorded forcing periods after {s.portrait_transient}: "
               f"the EMR (OPA mean x_0, N = {ctx.order}, wide light blue, red ■ at t = k 2π/ω) "
               f"with its "
               f"± 1 std (light blue bars) and, beside it, the mean of a Monte Carlo ensemble "
               f"of the true sampled systems (MC, {s.mc_samples} scrambled Sobol samples of "
               f"μ = 0.8 + σ ξ, green, ◆ at t = k 2π/ω) with ± 2 standard errors (dark green "
               f"bars) and ± 1 std of the ensemble (yellow-green bars); titles: measured "
               f"labels and Var[x] at the end of the run"
               + ("; the slowest impact of the EMR in the record." if grazing else "."))
    keys = ["emr", "mc"]
    return _drawn(ctx, name, fig, caption, diffs, data=_window_data(panels, keys, s.last),
                  width=int(62 * cols))


def fig6(ctx):
    cases = [(tag, preset("3.2", omega=w), sig, f"ω = {w:g}")
             for tag, (w, sig) in zip("abcd", ((3.98, 0.01), (3.98, 0.014), (4.2, 0.02),
                                               (4.2, 0.03)))]
    notes = ["some diffusion, the period is still 6T", "no longer periodic in the strict "
             "sense, differs greatly from the DMR", "the same diffusion phenomenon",
             "strong diffusion changes the topology of the response"]
    return _emr_mc_figure(ctx, "fig6", cases, (2, 2), "3.2 (a = 0.5, c = 0.05, f = 1.5, "
                          "F0 = 0.1, μ uncertain)", notes)


def fig7(ctx):
    cases = [(tag, preset("3.3", omega=4.00495), sig, "ω = 4.00495")
             for tag, sig in zip("ab", (0.1, 0.2))]
    notes = ["grazing (a trajectory tangent to the wall with zero speed); the portrait "
             "changes little with σ", "the motion is kept quite well even at σ = 0.2"]
    return _emr_mc_figure(ctx, "fig7", cases, (1, 2), "3.3 (a = f = 3.5, c = 0.05, "
                          "F0 = 0.1, μ uncertain)", notes, grazing=True)


def fig8(ctx):
    cases = [(tag, preset("3.3", omega=3.98), sig, "ω = 3.98")
             for tag, sig in zip("ab", (0.1, 0.18))]
    notes = ["grazing, with certain diffusion of the trajectories",
             "serious diffusion"]
    return _emr_mc_figure(ctx, "fig8", cases, (1, 2), "3.3 (a = f = 3.5, c = 0.05, "
                          "F0 = 0.1, μ uncertain)", notes, grazing=True)


def fig11(ctx):
    last = 2 * ctx.sizes.last
    s = ctx.sizes
    cases = [(tag, F0, n) for tag, (F0, n) in zip("abcd", ((0.1, 2), (0.1, 4), (10.0, 2),
                                                            (10.0, 4)))]
    fig, axes = plt.subplots(2, 2, figsize=(11, 8.6), layout="constrained")
    panels, diffs, records = [], [], []
    for (tag, F0, n), ax in zip(cases, axes.ravel()):
        osc = preset("3.4", F0=F0, n=float(n))
        record = _record_for(osc, s.portrait_record)
        records.append(record)
        emr0 = ctx.run("opa", osc, sigma=0.0, record=record)
        dmr = ctx.run("dmr", osc, record=record)
        portrait(ax, dmr, last=last, lw=1.3, points=None)
        portrait(ax, emr0, last=last, ls="--", points=PoincareMarks("s"),
                 label=f"EMR_0 (N = {ctx.order})", zorder=3)
        m, m_dmr = ctx.motion(emr0), ctx.motion(dmr)
        ax.set_title(f"({tag}) c = 0.0356, F0 = {F0:g}, n = {n}\nEMR_0: {_label_text(m)}",
                     fontsize=9)
        ax.legend(fontsize=7, loc="best", framealpha=0.85)
        panels.append((f"F0={F0:g}, n={n}", {"emr0": emr0, "dmr": dmr}))
        strobe = phase_section(emr0, start=ctx.start(emr0)).section_x.values
        diffs.append(f"({tag}) F0 = {F0:g}, n = {n}: EMR_0 {_label_text(m)}, DMR "
                     f"{m_dmr.label} in a record of {record} periods; the stroboscopic x "
                     f"spans {np.ptp(strobe):.3g}; "
                     f"{_difference_text(dmr, emr0, m_dmr)}; {_cycle_note(osc, record)}.")
    rec = (f"{records[0]} recorded forcing periods" if len(set(records)) == 1 else
           f"{' / '.join(str(r) for r in records)} recorded forcing periods for (a)-(d)")
    caption = (f"Fig. 11: phase portraits for c = 0.0356 (set 3.4), the last {last} of "
               f"{rec} after {s.portrait_transient}: (a) F0 = 0.1, n = 2; (b) F0 = 0.1, "
               f"n = 4; (c) F0 = 10, n = 2; (d) F0 = 10, n = 4; DMR (black) and EMR_0 "
               f"(orange dashed) with the EMR_0's Poincaré points t = k 2π/ω in the drawn "
               f"window (red ■).")
    diffs.insert(0, "The paper: little difference between n = 2 and 4 at F0 = 0.1, some "
                    "diffusion at F0 = 10 with n = 2, serious diffusion with n = 4. With "
                    "σ = 0 there is no randomness in these runs: the spread of the "
                    "Poincaré points measures how far the deterministic motion is from "
                    "periodic, and with n = 4 the forcing's own cycle is 4 times longer.")
    return _drawn(ctx, "fig11", fig, caption, diffs,
                  data=_window_data(panels, ["emr0", "dmr"], last), width=120)


_MAKERS = {"fig2": fig2, "fig3": fig3, "fig4": fig4, "fig5": fig5, "fig6": fig6,
           "fig7": fig7, "fig8": fig8, "fig9": fig9, "fig10": fig10, "fig11": fig11}


def reproduce(figure: str, outdir: str | os.PathLike = "figures", *, full: bool = False,
              impulse: str = "dirac", pulse_width: float = 0.1,
              impulse_at_zero: bool = True, order: int = 4,
              workers: int = 2, scheduler=None, progress: bool | None = None,
              log=None, sizes: Sizes | None = None) -> list[str]:
    """Regenerate one of the paper's figures (``"fig2"`` .. ``"fig11"``) or ``"all"``.

    Parameters
    ----------
    outdir : folder for the PNG, text and netCDF files.
    full : the paper's resolution for the bifurcation diagrams (200 values of the
        parameter, 500 transient + 100 recorded periods) and larger Monte Carlo
        ensembles (:data:`FULL_SIZES`) instead of :data:`DEFAULT_SIZES`.
    impulse, pulse_width, impulse_at_zero : the impulse model of every figure
        (``opa.System``'s fields; README, 'Choices the paper leaves open').
    order : OPA order N of EMR_0 and EMR.
    workers, scheduler : parallel sweeps (local processes or a Dask scheduler).
    log : callable for progress lines (e.g. ``print``), or None.
    sizes : explicit :class:`Sizes` (overrides ``full``).

    Returns
    -------
    The paths written: per figure ``figN.png``, ``figN.txt`` (caption and the measured
    differences from the paper) and its netCDF data.
    """
    names = list(FIGURES) if figure == "all" else [figure]
    for name in names:
        if name not in _MAKERS:
            raise ValueError(f"figure must be one of {', '.join(FIGURES)} or 'all', "
                             f"got {figure!r}")
    order = check_order(order)
    os.makedirs(outdir, exist_ok=True)
    ctx = _Context(outdir, sizes or (FULL_SIZES if full else DEFAULT_SIZES),
                   impulse=impulse, pulse_width=pulse_width,
                   impulse_at_zero=impulse_at_zero, order=int(order), workers=int(workers),
                   scheduler=scheduler,
                   progress=progress, log=log)
    paths = []
    try:
        for name in names:
            if log:
                log(f"{name}:")
            paths += _write(ctx, _MAKERS[name](ctx))
    finally:
        ctx.close()
    return paths


__all__ = ["DEFAULT_SIZES", "FIGURES", "FULL_SIZES", "Sizes", "plot_bifurcation",
           "reproduce"]
