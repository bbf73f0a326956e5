"""Drawing blocks: single runs (``plot_run``), bifurcation diagrams (``plot_bifurcation``)
and the panels of the paper's figures (``compare._figures``).

Colours name the model the same way in every figure: DMR black, EMR_0 orange, EMR blue,
Monte Carlo mean green; Poincaré points are red.

Bifurcation lines are drawn only from *located* bifurcations, the ones a sweep dataset
lists in its ``bifurcation_*`` variables (:func:`located_marks`); the brute-force period
labels of a sweep are never turned into lines.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

from opa.dynamics._sections import mean_state, stroboscopic_mask  # noqa: E402

COLORS = {"DMR": "black", "EMR_0": "tab:orange", "EMR": "tab:blue", "MC mean": "tab:green"}
SECTION_COLOR = "tab:red"


def _state(ds: xr.Dataset) -> tuple[np.ndarray, np.ndarray, str]:
    """x, x' and the label of what a dmr/opa/mc dataset's trajectory is: the DMR itself,
    or the mean state E[x], E[x'] of an OPA run (any number of elements, any law of xi)
    or of a Monte Carlo ensemble."""
    model = ds.attrs.get("model")
    if model == "dmr" or ("x" in ds and "x_mean" not in ds):
        return ds.x.values, ds.v.values, "DMR"
    law = ds.attrs.get("distribution", "semicircle")
    if model == "opa":
        K = ds.sizes.get("element", 1)
        parts = [f"N={ds.attrs['N']}"] + ([f"{K} elements"] if K > 1 else []) \
            + ([law] if law != "semicircle" else [])
        return ds.x_mean.values, ds.v_mean.values, f"EMR (OPA {', '.join(parts)})"
    if model == "mc":
        samples = int(ds.attrs.get("samples", ds.sizes.get("sample", 0)))
        where = "" if law == "semicircle" else f", {law}"
        return ds.x_mean.values, ds.v_mean.values, f"MC mean ({samples} samples{where})"
    raise ValueError(f"plot_run draws dmr, opa and mc datasets, got model = {model!r}")


def _extra_panel(ds: xr.Dataset) -> str | None:
    """The third panel a run deserves: the elements of a multi-element OPA run, the Sobol
    indices over time of an OPA run with several uncertain parameters, the impacts per
    sample of a Monte Carlo ensemble; None for the others."""
    if "x_sobol_first" in ds:  # several parameters (on one element or on boxes)
        return "sobol"
    if ds.attrs.get("model") == "opa" and ds.sizes.get("element", 1) > 1:
        return "elements"
    if ds.attrs.get("model") == "mc" and "n_impacts" in ds and ds.sizes.get("sample", 0):
        return "impacts"
    return None


def _draw_extra(ax, ds: xr.Dataset, kind: str) -> None:
    if kind == "elements":
        edges = ds.element_edges.values
        P = ds.element_probability.values
        ax.stairs(P / np.diff(edges), edges, fill=True, alpha=0.35, color="tab:blue",
                  label="element probability / width")
        ax.stairs(P / np.diff(edges), edges, color="tab:blue", lw=0.8)
        ax.set_xlabel("ξ (element edges)")
        ax.set_ylabel("probability density of ξ")
        ax.set_title(f"{len(P)} elements ({ds.attrs.get('element_mode', '')})")
        ax.legend(loc="upper right", fontsize=8)
        return
    if kind == "sobol":
        _draw_sobol(ax, ds)
        return
    counts = ds.n_impacts.values.astype(int)
    weights = ds.weight.values if "weight" in ds else np.ones(len(counts))
    values = np.arange(counts.min(), counts.max() + 1)
    share = np.array([weights[counts == k].sum() for k in values]) / weights.sum()
    ax.bar(values, share, width=0.8, color="tab:green", alpha=0.7)
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_xlabel("impacts of a sample over the run")
    ax.set_ylabel("share of the samples")
    ax.set_title("impacts per sample")


def _draw_sobol(ax, ds: xr.Dataset) -> None:
    """First-order (solid) and total (dashed) Sobol indices of x over time, one colour a
    parameter; gaps where x has no variance (the indices are undefined there)."""
    periods = ds.time.values * ds.attrs["omega"] / (2 * np.pi)
    for k, name in enumerate(ds.parameter.values):
        colour = f"C{k}"
        ax.plot(periods, ds.x_sobol_first.sel(parameter=name).values, color=colour, lw=1,
                label=f"{name}: first order")
        ax.plot(periods, ds.x_sobol_total.sel(parameter=name).values, color=colour, lw=1,
                ls="--", label=f"{name}: total")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("t [forcing periods]")
    ax.set_ylabel("Sobol index of x")
    ax.set_title("Sobol indices from the OPA coefficients")
    ax.legend(loc="best", fontsize=8)


#: colour of each verdict of a certificate (``compare.verify``); any other word is grey
VERDICT_COLORS = {"agrees": "tab:green", "disagrees": "tab:red", "undecided": "tab:orange"}
#: decades shown below the largest value of a log-scaled error panel
DECADES = 5


def _running_rms(values: np.ndarray) -> np.ndarray:
    """sqrt of the mean of values² over the outputs up to each one (the verdict's measure)."""
    return np.sqrt(np.cumsum(values ** 2) / np.arange(1, len(values) + 1))


def _draw_certificate(ax, ds: xr.Dataset, periods: np.ndarray) -> None:
    """The certificate of a verified run, as its verdict reads it: the running RMS of the
    paired error of E[x] with a ± 2 standard-error band, against the tolerance
    (``verify_tolerance`` × the running RMS standard deviation of x), and the verdict in
    the title, coloured by its word (agrees, disagrees, undecided)."""
    err = _running_rms(np.nan_to_num(ds.verify_err_mean.values))
    sem = _running_rms(np.nan_to_num(ds.verify_err_mean_sem.values))
    var = ds.cv_x_var.values if "cv_x_var" in ds else ds.x_var.values
    tol = float(ds.attrs.get("verify_tolerance", 0.1)) \
        * _running_rms(np.sqrt(np.maximum(np.nan_to_num(var), 0.0)))
    # at t = 0 every sample starts at x0: an error of exactly 0 says nothing and would set
    # a log axis by itself; so would one tiny error before the first impact: the axis
    # shows DECADES decades below the largest value drawn, smaller values sit on its floor
    shown = periods > 0
    top = np.nanmax(np.concatenate([(err + 2 * sem)[shown], tol[shown], [0.0]]))
    low = np.nanmin(np.concatenate([err[shown & (err > 0)], tol[shown & (tol > 0)],
                                    [np.inf]]))
    floor = max(low, top * 10.0 ** -DECADES) if top > 0 and np.isfinite(low) else 1e-16
    ax.fill_between(periods[shown], np.maximum(err - 2 * sem, floor)[shown],
                    (err + 2 * sem)[shown], color="tab:blue", alpha=0.3, lw=0,
                    label="± 2 standard errors")
    ax.plot(periods[shown], np.maximum(err, floor)[shown], color="tab:blue", lw=1.2,
            label="OPA − truth, E[x] (paired)")
    ax.plot(periods[shown], np.maximum(tol, floor)[shown], color="black", ls="--", lw=1,
            label=f"tolerance: {ds.attrs.get('verify_tolerance', 0.1):g} × std of x")
    first = float(ds.attrs.get("first_disagreement_mean", np.inf))
    if np.isfinite(first):
        ax.axvline(first, color=VERDICT_COLORS["disagrees"], lw=1, ls=":",
                   label=f"first disagreement, t = {first:.3g}")
    ax.set_yscale("log")
    ax.set_ylim(floor / 1.5, top * 1.5 if top > 0 else 1.0)
    ax.set_xlabel("t [forcing periods]")
    ax.set_ylabel("running RMS over the outputs up to t")
    verdict = str(ds.attrs.get("verdict", "?"))
    ax.set_title(f"certificate ({int(ds.attrs.get('verify_samples', 0))} true systems): "
                 f"{verdict.upper()}\n(mean {ds.attrs.get('verdict_mean', '?')}, variance "
                 f"{ds.attrs.get('verdict_var', '?')})",
                 color=VERDICT_COLORS.get(verdict, "tab:gray"), fontsize=10)
    ax.legend(loc="lower right", fontsize=8)


def plot_run(ds: xr.Dataset, path: str, *, per_period: int | None = None) -> None:
    """Time history and phase portrait of a dmr/opa/mc dataset; stroboscopic points marked.

    OPA runs (one element or several, any law of xi) and Monte Carlo ensembles draw their
    mean state with a band of ± 1 standard deviation; a multi-element run adds a panel of
    its elements, an ensemble one of the impacts per sample, and a run with a certificate
    (``compare.verify``, ``--verify``) one of the certificate: the paired error of E[x]
    with its ± 2 standard-error band against the tolerance, and the verdict.
    Times are in forcing periods 2π/ω.
    ``per_period`` (outputs per forcing period) locates the stroboscopic samples; it is
    inferred from the time grid when omitted.
    """
    fig = draw_run(ds, per_period=per_period)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def draw_run(ds: xr.Dataset, *, per_period: int | None = None):
    """The figure of :func:`plot_run`, not saved (the caller closes it)."""
    x, v, label = _state(ds)
    t = ds.time.values
    T = 2 * np.pi / ds.attrs["omega"]
    if per_period is None:
        per_period = max(1, int(round(T / (t[1] - t[0])))) if len(t) > 1 else 1
    extra = _extra_panel(ds)
    certified = "verify_err_mean" in ds and "verify_err_mean_sem" in ds
    panels = 2 + bool(extra) + certified
    fig, axes = plt.subplots(1, panels, figsize=(5.5 * panels, 4.4))
    ax_t, ax_p = axes[0], axes[1]
    periods = t / T
    dense = per_period >= 8  # lines between outputs only when they resolve the motion
    style = dict(lw=0.8) if dense else dict(ls="none", marker=".", ms=3)
    ax_t.plot(periods, x, label=label, **style)
    if "x_var" in ds and label != "DMR":
        sd = np.sqrt(np.maximum(ds.x_var.values, 0.0))
        ax_t.fill_between(periods, x - sd, x + sd, alpha=0.3, label="± 1 std")
    ax_t.axhline(ds.attrs["delta"], color="k", lw=1, ls="--", label="wall x = Δ")
    ax_t.set_xlabel("t [forcing periods]")
    ax_t.set_ylabel("x" if label == "DMR" else "E[x]")
    ax_t.legend(loc="lower left", fontsize=8)
    ax_t.set_title("time history")
    half = len(t) // 2
    if dense:
        ax_p.plot(x[half:], v[half:], lw=0.6, label="trajectory (second half)")
    strobe = slice(half - half % per_period, None, per_period)
    ax_p.plot(x[strobe], v[strobe], "rs", ms=4, label="t = k 2π/ω")
    ax_p.axvline(ds.attrs["delta"], color="k", lw=1, ls="--")
    ax_p.set_xlabel("x" if label == "DMR" else "E[x]")
    ax_p.set_ylabel("dx/dt" if label == "DMR" else "E[dx/dt]")
    ax_p.legend(loc="lower left", fontsize=8)
    ax_p.set_title("phase portrait" if label == "DMR" else "phase portrait of the mean")
    if extra:
        _draw_extra(axes[2], ds, extra)
    if certified:
        _draw_certificate(axes[-1], ds, periods)
    uncertain = ds.attrs.get("uncertain", "mu")
    sigma = ", ".join(f"{s:g}" for s in np.atleast_1d(ds.attrs["sigma"]))
    fig.suptitle(
        f"{label}: ω = {ds.attrs['omega']:g}, c = {ds.attrs['c']:g}, σ = {sigma}"
        f"{'' if label == 'DMR' else f' ({uncertain} uncertain)'}, F0 = {ds.attrs['F0']:g}, "
        f"impulse = {ds.attrs['impulse']}"
    )
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- located marks


#: names the bifurcation variables may carry (the sweep's, ``opa.dynamics._continuation``'s)
_VALUE_VARS = ("bifurcation_parameter", "bifurcation_value", "bifurcation_values",
               "located_parameter")
_KIND_VARS = ("bifurcation_kind", "bifurcation_type", "located_kind")
_LOCATED_VARS = ("bifurcation_located",)
_KIND_ALIASES = {"period-doubling": "period-doubling", "period doubling": "period-doubling",
                 "pd": "period-doubling", "doubling": "period-doubling",
                 "flip": "period-doubling", "fold": "fold", "saddle-node": "fold",
                 "limit-point": "fold", "neimark-sacker": "neimark-sacker",
                 "torus": "neimark-sacker", "grazing": "grazing", "graze": "grazing",
                 "impulse-impact": "impulse-impact"}
_MARK_STYLE = {
    "period-doubling": dict(color="tab:green", ls="--", name="period doubling"),
    "fold": dict(color="tab:red", ls="-.", name="fold"),
    "neimark-sacker": dict(color="tab:purple", ls="--", name="Neimark-Sacker"),
    "grazing": dict(color="tab:orange", ls=":", name="grazing"),
    "impulse-impact": dict(color="tab:gray", ls=":", name="impulse meets impact"),
    "bifurcation": dict(color="tab:brown", ls="--", name="bifurcation"),
}


def _kind_name(raw) -> str:
    text = str(raw).strip().lower().replace("_", "-")
    return _KIND_ALIASES.get(text, _KIND_ALIASES.get(text.replace("-", " "), text or
                                                      "bifurcation"))


def _kinds(ds: xr.Dataset, size: int) -> list[str]:
    var = next((ds[n] for n in _KIND_VARS if n in ds.variables), None)
    if var is None or var.size != size:
        return ["bifurcation"] * size
    raw = np.atleast_1d(var.values)
    if raw.dtype.kind in "USO":
        return [_kind_name(k) for k in raw]
    meanings = str(var.attrs.get("flag_meanings", "")).split()
    if not meanings:
        try:
            from opa.dynamics._continuation import BIFURCATION_KINDS as meanings
        except ImportError:  # the continuation module is optional here
            meanings = ()
    flags = var.attrs.get("flag_values")
    flags = list(np.atleast_1d(flags)) if flags is not None else list(range(len(meanings)))
    out = []
    for k in raw:
        try:
            out.append(_kind_name(meanings[flags.index(int(k))]))
        except (ValueError, IndexError, TypeError):
            out.append("bifurcation")
    return out


def located_marks(ds: xr.Dataset) -> list[tuple[float, str, bool]]:
    """Located bifurcations listed in a sweep (or branch) dataset, as drawn markers.

    Reads the parameter values from ``bifurcation_parameter`` (or ``bifurcation_value``,
    ``bifurcation_<swept parameter>``), their kinds from ``bifurcation_kind`` (strings,
    or flags decoded with the ``flag_meanings`` attribute) and, where present,
    ``bifurcation_located`` (0: an interpolated estimate). Values outside the swept
    range and non-finite ones are dropped. A dataset without such variables gives ``[]``:
    nothing is drawn.

    Returns
    -------
    ``[(value, kind, located), ...]`` sorted by value; ``kind`` is one of
    "period-doubling", "fold", "neimark-sacker", "grazing", "impulse-impact" or
    "bifurcation" (unknown).
    """
    param = ds.attrs.get("sweep_parameter")
    names = list(_VALUE_VARS) + ([f"bifurcation_{param}"] if param else [])
    var = next((ds[n] for n in names if n in ds.variables), None)
    if var is None:
        return []
    try:
        values = np.atleast_1d(np.asarray(var.values, dtype=float)).ravel()
    except (TypeError, ValueError):
        return []
    kinds = _kinds(ds, values.size)
    located = np.ones(values.size, dtype=bool)
    for name in _LOCATED_VARS:
        if name in ds.variables and ds[name].size == values.size:
            located = np.atleast_1d(ds[name].values).astype(bool).ravel()
    lo, hi = -math.inf, math.inf
    if param and param in ds.coords and ds[param].size:
        span = np.asarray(ds[param].values, dtype=float)
        lo, hi = float(np.nanmin(span)), float(np.nanmax(span))
    marks = [(float(v), k, bool(b)) for v, k, b in zip(values, kinds, located)
             if math.isfinite(v) and lo <= v <= hi]
    return sorted(marks)


def mark_name(kind: str, located: bool) -> str:
    name = _MARK_STYLE.get(kind, _MARK_STYLE["bifurcation"])["name"]
    return name if located else f"{name} (estimated)"


def draw_marks(ax, marks) -> None:
    """Vertical lines at located bifurcations, one legend entry per kind."""
    seen = {t.get_label() for t in ax.get_lines()}
    for value, kind, located in marks:
        style = _MARK_STYLE.get(kind, _MARK_STYLE["bifurcation"])
        name = mark_name(kind, located)
        ax.axvline(value, color=style["color"], ls=style["ls"], lw=1.0,
                   alpha=1.0 if located else 0.6, label=None if name in seen else name)
        seen.add(name)


def describe_marks(marks, param: str) -> str:
    """The caption's words for ``draw_marks``: exactly the lines drawn."""
    if not marks:
        return "no bifurcation lines: the sweep dataset lists no located bifurcations"
    parts = {}
    for value, kind, located in marks:
        parts.setdefault(mark_name(kind, located), []).append(f"{value:.5g}")
    return "located bifurcations (vertical lines): " + "; ".join(
        f"{name} at {param} = {', '.join(v)}" for name, v in parts.items())


# --------------------------------------------------------------------------- diagrams


SYMBOLS = {"omega": "ω", "sigma": "σ", "mu": "μ", "eta": "η", "delta": "Δ", "omega1": "ω1"}
SECTION_LABELS = {"phase": ("x at t = k 2π/ω", "phase plane"),
                  "constraint": ("impact velocity x'(t-) at x = Δ", "constraint plane")}


def diagram(ax, ds: xr.Dataset, section: str, *, color: str = "black",
            label: str | None = None, ms: float | None = None, marker: str = ".",
            zorder: float = 2) -> int:
    """Section points of a sweep against the swept parameter; returns how many drawn.

    ``section``: "phase" (stroboscopic x) or "constraint" (pre-impact velocity).
    """
    param = ds.attrs["sweep_parameter"]
    values = ds[param].values
    y = ds.section_x.values if section == "phase" else ds.impact_v.values
    xs = np.broadcast_to(values[:, None], y.shape)
    ok = np.isfinite(y)
    if ms is None:
        ms = 4.0 if len(values) <= 40 else 2.2
    hollow = marker in "x+1234|_"  # line markers: their edge is all there is
    ax.plot(xs[ok], y[ok], marker, ls="none", color=color, ms=ms, alpha=0.75,
            mec=color if hollow else "none", mew=1.2 if hollow else None, label=label,
            zorder=zorder)
    ylabel, _ = SECTION_LABELS[section]
    ax.set_xlabel(SYMBOLS.get(param, param))
    ax.set_ylabel(ylabel)
    if len(values) > 1:
        pad = 0.01 * (values[-1] - values[0])
        ax.set_xlim(values[0] - pad, values[-1] + pad)
    return int(ok.sum())


def plot_bifurcation(ds: xr.Dataset, path: str, *, section: str = "both",
                     title: str | None = None) -> None:
    """Bifurcation diagram of a ``sweep`` dataset in one or both Poincaré sections.

    Phase plane: stroboscopic x against the parameter; constraint plane: pre-impact
    velocity against the parameter. Vertical lines only at the located bifurcations the
    dataset lists (:func:`located_marks`); the title says which, or that there are none.
    """
    which = ["phase", "constraint"] if section == "both" else [section]
    fig, axes = plt.subplots(1, len(which), figsize=(5.5 * len(which) + 0.5, 4.2),
                             squeeze=False, layout="constrained")
    marks = located_marks(ds)
    for ax, kind in zip(axes[0], which):
        n = diagram(ax, ds, kind)
        ax.set_title(SECTION_LABELS[kind][1], fontsize=10)
        if n == 0:
            ax.text(0.5, 0.5, "no section points recorded", ha="center", va="center",
                    transform=ax.transAxes)
        draw_marks(ax, marks)
        if marks:
            ax.legend(fontsize=7, loc="best", framealpha=0.85)
    head = title or _sweep_title(ds)
    fig.suptitle(f"{head}\n{describe_marks(marks, ds.attrs['sweep_parameter'])}",
                 fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _sweep_title(ds) -> str:
    a = ds.attrs
    name = {"dmr": "DMR", "opa": "EMR_0" if a["sigma"] == 0 else f"EMR (σ = {a['sigma']:g})",
            "mc": f"MC mean ({a.get('samples', 0)} samples)"}[a["model"]]
    return (f"{name} vs {a['sweep_parameter']}: {a['transient']} transient + {a['record']} "
            f"recorded periods, impulse {a['impulse']}, F0 = {a['F0']:g}")


# --------------------------------------------------------------------------- portraits


def window(ds: xr.Dataset, last: int) -> np.ndarray:
    """Mask of the outputs in the last ``last`` forcing periods of a run."""
    t = ds.time.values
    T = 2 * math.pi / ds.attrs["omega"]
    return t >= t[-1] - last * T * (1 + 1e-9)


def strobe_window(ds: xr.Dataset, last: int) -> np.ndarray:
    """Mask of the stroboscopic outputs t = k 2π/ω in the last ``last`` periods."""
    t = ds.time.values
    T = 2 * math.pi / ds.attrs["omega"]
    return stroboscopic_mask(t, T, start=t[-1] - last * T * (1 + 1e-9))


@dataclass(frozen=True)
class PoincareMarks:
    """How a phase portrait marks its Poincaré points (the states at t = k 2π/ω).

    Attributes
    ----------
    marker : a matplotlib marker ("*", "s", "D", ...).
    color : their face colour (edged in black).
    label : their legend entry (None: none).
    size : marker size in points (None: 7 for "*", 4 for the others).

    Examples
    --------
    >>> PoincareMarks("s", size=6).color
    'tab:red'
    """

    marker: str = "*"
    color: str = SECTION_COLOR
    label: str | None = "Poincaré points t = k 2π/ω"
    size: float | None = None

    def __post_init__(self):
        if not isinstance(self.marker, str) or not self.marker:
            raise ValueError(f"marker must be a matplotlib marker such as '*', got "
                             f"{self.marker!r}")
        if self.size is not None and (
                isinstance(self.size, bool) or not isinstance(self.size, (int, float))
                or not (math.isfinite(self.size) and self.size > 0)):
            raise ValueError(f"size must be a finite number > 0 or None, got {self.size!r}")


def portrait(ax, ds: xr.Dataset, *, last: int = 30, color: str | None = None,
             label: str | None = None, ls: str = "-", lw: float = 0.8, alpha: float = 1.0,
             zorder: float = 2, points: PoincareMarks | None = PoincareMarks()) -> None:
    """Phase portrait of the last ``last`` periods: the line (``color``, default the
    run's colour in ``COLORS``; ``label``, default its name; ``ls``, ``lw``, ``alpha``,
    ``zorder``) with its Poincaré points marked as ``points`` says (None: not marked;
    drawn 3 above the line), and the wall."""
    x, v, name = mean_state(ds)
    keep = window(ds, last)
    ax.plot(x[keep], v[keep], ls, color=color or COLORS[name], lw=lw, label=label or name,
            alpha=alpha, zorder=zorder)
    if points is not None:
        s = strobe_window(ds, last)
        ax.plot(x[s], v[s], points.marker, ls="none", color=points.color,
                ms=points.size or (7 if points.marker == "*" else 4), mec="black", mew=0.4,
                label=points.label, zorder=zorder + 3)
    ax.axvline(ds.attrs["delta"], color="gray", lw=1.2)
    ax.set_xlabel("x")
    ax.set_ylabel("dx/dt")


def section_bars(ax, ds: xr.Dataset, *, last: int, scale: float, spread: str, color: str,
                 label: str, lw: float = 0.8, capsize: float = 0.0, zorder: float = 3
                 ) -> None:
    """Error bars at the Poincaré points of the last ``last`` periods.

    ``spread``: "std" (square root of ``x_var``/``v_var``) or "sem" (``x_sem``/``v_sem``
    of a Monte Carlo run); the bars reach ``scale`` times it in x and in dx/dt.
    """
    x, v, _ = mean_state(ds)
    s = strobe_window(ds, last)
    if spread == "std":
        ex = np.sqrt(np.maximum(ds.x_var.values[s], 0.0))
        ev = np.sqrt(np.maximum(ds.v_var.values[s], 0.0))
    else:
        ex, ev = ds.x_sem.values[s], ds.v_sem.values[s]
    ax.errorbar(x[s], v[s], xerr=scale * ex, yerr=scale * ev, fmt="none", ecolor=color,
                elinewidth=lw, capsize=capsize, label=label, zorder=zorder)


def history(ax, runs, *, last: int = 10) -> None:
    """Time histories of the last ``last`` periods of ``[(dataset, line style), ...]``,
    over time in forcing periods 2π/ω (as the captions count it)."""
    for ds, style in runs:
        x, _, name = mean_state(ds)
        keep = window(ds, last)
        period = 2 * math.pi / float(ds.attrs["omega"])
        ax.plot(ds.time.values[keep] / period, x[keep], style, color=COLORS[name],
                lw=1.3 if name == "DMR" else 0.9, label=name)
    ax.axhline(runs[0][0].attrs["delta"], color="gray", lw=1.2, label="wall x = Δ")
    ax.set_xlabel("t [forcing periods]")
    ax.set_ylabel("x")
    ax.legend(fontsize=7, loc="best", framealpha=0.85)


__all__ = ["COLORS", "plot_bifurcation", "plot_run"]
