"""Tables, plain-language findings, figures and summary.md of a trust-map dataset.

Everything here is read off the dataset that :func:`compare.run_validation` wrote; nothing
is assumed about the model. The headline is the boundary table: sigma* per swept value and
horizon, beside the nearest split of the sampled systems' impact sequences.
"""

from __future__ import annotations

import os

import numpy as np
import xarray as xr

from compare._inputs import (
    check_dataset, check_finite, check_standard_error, require_attributes, require_time,
    require_variables,
)

# Variant shown where one must be picked: the paper's OPA (mean impact law) with the
# exact Galerkin truncation.
HEADLINE = 0
VARIANT_MARKERS = ("o", "s", "^", "v", "D")
# The impact laws drawn and summarised side by side (by name: under a law of xi other than
# the semicircle the paper-truncation variants are left out, and multi-element variants
# named "<law>/ME-<K8|adaptive64>" follow the single-element ones).
DRAWN_VARIANTS = ("mean/galerkin", "ensemble/galerkin", "saltation/galerkin")
KIND_COLOURS = {"grazing": "tab:red", "extra impact": "gold", "chatter": "tab:cyan",
                "impulse order": "white", "horizon": "0.6", "output crossing": "tab:cyan"}
# Kinds of the split arrays that do not change the impact sequence.
NOT_SPLITS = ("horizon", "output crossing")



def _pyplot():
    """matplotlib.pyplot on the Agg backend, imported only when a figure is drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt

# -- what each entry point reads off the map (issue 45) -------------------------------------
# A map that lacks it (an older or partial validate.nc, or another kind of dataset) is
# refused by name, never with a KeyError. Read only when present, so not listed: the
# variables of newer maps that older ones lack (verdict, variant_ran, opa_status,
# count_unknown, variant_collocated, nominal_slowest_*, crossing_complete_sigma, the
# frontier); `time` may be called `periods` (files written before issue 26).
_MAP = "the trust-map dataset"
#: coordinates and attributes every entry point reads (and the swept parameter's
#: coordinate, named by the attribute `parameter`; the nominal value, by `uncertain`)
_MAP_COORDS = ("sigma", "variant", "N", "horizon", "criterion")
_MAP_ATTRS = ("parameter", "uncertain")
_STARS = ("sigma_star", "sigma_star_upper")
_SPLITS = ("split_value", "split_kind", "split_time", "split_speed", "split_left",
           "split_right", ("split_complete_sigma", "split_truncated"))
_CAUSE = _STARS + _SPLITS + ("agrees", "disagree_time")
_FAILURES = ("err_mean", "opa_x_mean")
#: entry point -> (variables, attributes, reads the time coordinate)
MAP_NEEDS = {
    "run_failures": (_FAILURES, ("per_period",), True),
    "cause": (_CAUSE, ("resolution", "per_period"), False),
    "first_screen": (_CAUSE + _FAILURES, ("tolerance", "var_tolerance", "resolution",
                                          "per_period"), True),
    "boundary_table": (_STARS + _SPLITS, ("resolution",), False),
    "verdict_grid": (("agrees",), (), False),
    "count_table": (("count_prob",) + _SPLITS[-1:], (), False),
    "findings": (_STARS + _SPLITS + ("err_mean", "agrees", "pre_impact_err", "first_impact",
                                     "mc_x_sem", "emr0_dmr_difference",
                                     "emr0_n0_dmr_difference"),
                 ("resolution", "var_tolerance"), True),
    "plot_map": (_STARS + ("agrees", "err_mean_rel", "err_var_rel", "probe_sigma",
                           "split_kind", "split_value"), ("tolerance", "var_tolerance"), False),
    "plot_error_vs_order": (("agrees", "err_mean", "first_impact", "pre_impact_err",
                             "mc_x_sem", "mc_x_var"),
                            ("per_period", "rtol", "atol", "tolerance"), True),
    "plot_mean": (("agrees", "mc_x_mean", "mc_x_sem", "opa_x_mean"), ("per_period",), True),
    "plot_variance": (("agrees", "mc_x_var", "mc_x_var_sem", "opa_x_var"), ("per_period",),
                      True),
    "plot_phase": (("law", "phase_time", "phase_opa_x", "phase_opa_v", "phase_mc_x",
                    "phase_mc_v", "phase_sample_x", "phase_sample_v"),
                   ("delta", "phase_value", "phase_sigma"), False),
}


def _union(*entries: str) -> tuple:
    """The needs of several entry points together."""
    variables, attributes = [], []
    for entry in entries:
        v, a, _ = MAP_NEEDS[entry]
        variables += [x for x in v if x not in variables]
        attributes += [x for x in a if x not in attributes]
    return tuple(variables), tuple(attributes), any(MAP_NEEDS[e][2] for e in entries)


MAP_NEEDS["figures"] = _union("plot_map", "plot_error_vs_order", "plot_mean",
                              "plot_variance", "plot_phase")
MAP_NEEDS["write_report"] = _union("first_screen", "boundary_table", "verdict_grid",
                                   "count_table", "findings")
MAP_NEEDS["write_report"] = (MAP_NEEDS["write_report"][0], MAP_NEEDS["write_report"][1] + (
    "wall_seconds", "mc_runs_computed", "opa_runs_computed", "parts_computed", "preset",
    "impulse", "rtol", "atol", "samples", "max_samples", "seed", "criterion_text", "alpha"),
    True)


def check_map(ds, entry: str) -> None:
    """Refuse, with one ValueError naming the culprit, a dataset that is not a trust map
    (``opa-mc validate``'s validate.nc, docs/datasets.md) or lacks what ``entry`` (a key
    of :data:`MAP_NEEDS`) reads, or whose Monte Carlo estimates or standard errors are not
    finite, or whose standard errors are negative, or whose OPA curves are not finite
    where ``opa_status`` says the run finished (after a stop they are NaN, as
    documented)."""
    check_dataset(ds, _MAP, "a trust map (opa-mc validate's validate.nc)")
    model = ds.attrs.get("model", "validate")
    if model != "validate":
        raise ValueError(f"{_MAP} must be a trust map (opa-mc validate's validate.nc, "
                         f"attribute model = 'validate'), got model = {model!r}")
    variables, attributes, time = MAP_NEEDS[entry]
    require_attributes(ds, _MAP, _MAP_ATTRS + attributes)
    require_attributes(ds, _MAP, (str(ds.attrs["uncertain"]),),
                       hint=" (the nominal value of the uncertain parameter)")
    require_variables(ds, _MAP, _MAP_COORDS + (str(ds.attrs["parameter"]),) + variables)
    if time:
        require_time(ds, _MAP, old_name=True)
    if "split_kind" in variables and "flag_meanings" not in ds.split_kind.attrs:
        raise ValueError(f"{_MAP}'s split_kind lacks its attribute flag_meanings")
    for name in ("mc_x_mean", "mc_x_var"):
        if name in variables:
            check_finite(ds, _MAP, name)
    for name in ("mc_x_sem", "mc_x_var_sem"):
        if name in variables:
            check_standard_error(ds, _MAP, name)
    for name in ("opa_x_mean", "opa_x_var"):
        if name in variables and "opa_status" in ds:
            finished = ds.opa_status == 0
            stopped = ~finished.broadcast_like(ds[name]).transpose(*ds[name].dims).values
            check_finite(ds, _MAP, name, allowed=stopped,
                         where=" where opa_status says the run finished")


def _kinds(ds) -> list[str]:
    return [k.replace("_", " ") for k in ds.split_kind.attrs["flag_meanings"].split()]


def _g(x: float, digits: int = 4) -> str:
    return f"{x:.{digits}g}"


def _e(x: float) -> str:
    if not np.isfinite(x):
        return "∞" if x > 0 else "–"
    return f"{x:.1e}"


def star_text(lo: float, hi: float, smax: float) -> str:
    """sigma* as read from its bisection bracket."""
    if not np.isfinite(hi):
        return f"≥ {_g(smax)}"
    if lo == 0:
        return f"< {_g(hi, 3)}"
    return f"{_g(lo, 3)}–{_g(hi, 3)}"


def star_phrase(lo: float, hi: float, smax: float) -> str:
    """'σ* = a–b', 'σ* < b' or 'σ* ≥ a' from the bisection bracket."""
    text = star_text(lo, hi, smax)
    return f"σ* {text}" if text[0] in "<≥" else f"σ* = {text}"


def _laws(ds) -> list[int]:
    """Indices of the variants compared across impact laws (those in the dataset)."""
    names = [str(v) for v in ds.variant.values]
    return [names.index(n) for n in DRAWN_VARIANTS if n in names]


def _element_variants(ds) -> list[int]:
    """Indices of the multi-element variants (run at N = Nmax only)."""
    return [v for v, name in enumerate(ds.variant.values) if "/ME-" in str(name)]


def _single_of(ds, v: int) -> int | None:
    """The single-element Galerkin variant of the same impact law as variant v."""
    names = [str(n) for n in ds.variant.values]
    name = names[v].split("/")[0] + "/galerkin"
    return names.index(name) if name in names else None


def _time(ds):
    """Output times in forcing periods: the coordinate ``time`` (``periods`` in files
    written before issue 26, still read)."""
    return ds["time"] if "time" in ds.dims else ds["periods"]


def _vals(ds):
    """The swept parameter's coordinate (named after the parameter, docs/datasets.md)."""
    return ds[ds.attrs["parameter"]]


def _par(ds) -> str:
    return {"omega": "ω", "mu": "μ"}.get(ds.attrs["parameter"], ds.attrs["parameter"])


def _unc(ds) -> str:
    return {"mu": "μ"}.get(ds.attrs["uncertain"], ds.attrs["uncertain"])


def nominal(ds) -> float:
    return float(ds.attrs[ds.attrs["uncertain"]])


# -- the boundary and what sits there ------------------------------------------------------
def _nearest(ds, q: int, h: int, wanted):
    kinds = _kinds(ds)
    vals = ds.split_value.values[q, h]
    kind = ds.split_kind.values[q, h]
    ok = np.array([k >= 0 and wanted(kinds[k]) for k in kind], dtype=bool)
    if not ok.any():
        return None
    centre = nominal(ds)
    j = np.flatnonzero(ok)[np.argmin(np.abs(vals[ok] - centre))]
    return dict(value=float(vals[j]), distance=abs(float(vals[j]) - centre),
                kind=kinds[int(kind[j])], time=float(ds.split_time.values[q, h, j]),
                speed=float(ds.split_speed.values[q, h, j]),
                left=int(ds.split_left.values[q, h, j]),
                right=int(ds.split_right.values[q, h, j]))


def nearest_split(ds, q: int, h: int):
    """The split (not a horizon crossing, not an output crossing) nearest to the nominal
    value, as a dict, or None."""
    return _nearest(ds, q, h, lambda kind: kind not in NOT_SPLITS)


def nearest_crossing(ds, q: int, h: int):
    """The output crossing (an impact time crossing an output time) nearest to the
    nominal value, as a dict (``time``: the output time, ``speed``: the impact's), or
    None."""
    return _nearest(ds, q, h, lambda kind: kind == "output crossing")


def nearest_horizon(ds, q: int, h: int):
    """The 'horizon' split nearest to the nominal value (an impact that crosses the end of
    the horizon: it changes the impact count up to H but no output within H), or None."""
    return _nearest(ds, q, h, lambda kind: kind == "horizon")


def complete_within(ds, q: int, h: int) -> float:
    """The distance from the nominal value within which the split list is complete (inf:
    the whole scan; datasets written before the limit was reported: inf where the list
    was not cut, 0 where it was)."""
    if "split_complete_sigma" in ds:
        return float(ds.split_complete_sigma.values[q, h])
    return 0.0 if int(ds.split_truncated.values[q, h]) else float("inf")


def _crossing_cause(ds, q: int, h: int, at: float, sigma: float):
    """The output crossing inside the ensemble at ``sigma`` whose output is the output
    ``at`` (forcing periods) where OPA first leaves the tolerance, or None."""
    if "crossing_complete_sigma" not in ds:
        return None
    half = 0.5 / float(ds.attrs["per_period"])
    kinds = _kinds(ds)
    best = None
    for j in range(ds.sizes["split"]):
        k = int(ds.split_kind.values[q, h, j])
        if k < 0 or kinds[k] != "output crossing":
            continue
        d = abs(float(ds.split_value.values[q, h, j]) - nominal(ds))
        t = float(ds.split_time.values[q, h, j])
        if d < sigma and abs(t - at) < half and (best is None or d < best["distance"]):
            best = dict(value=float(ds.split_value.values[q, h, j]), distance=d, time=t,
                        speed=float(ds.split_speed.values[q, h, j]))
    return best


def cause(ds, q: int, h: int, v: int = HEADLINE, c: int = 0) -> str:
    """One sentence: why sigma* is where it is, for value q and horizon h."""
    par, unc = _par(ds), _unc(ds)
    value = float(_vals(ds)[q])
    H = float(ds.horizon[h])
    lo, hi = (float(ds.sigma_star.values[q, v, h, c]),
              float(ds.sigma_star_upper.values[q, v, h, c]))
    res = float(ds.attrs["resolution"])
    sp = nearest_split(ds, q, h)
    law, _, kind = str(ds.variant.values[v]).partition("/")
    law = f"{law} law, {kind}" if kind.startswith("ME-") else law
    head = f"At {par} = {_g(value)} over {H:g} periods"
    smax = float(ds.sigma.max())
    reach = complete_within(ds, q, h)
    cut = ""
    if reach < smax:
        cut = (f"; the scan's limit of splits cut the list short, so splits and impact counts "
               f"are known only for |{unc} − {_g(nominal(ds))}| < {reach:.2g}")
    if sp is not None and sp["distance"] >= reach:
        sp = None
    if sp is None:
        where = f"no sampled system's impact sequence changes for |{unc} − {_g(nominal(ds))}| " \
                + (f"≤ {_g(smax)}" if reach >= smax else f"< {reach:.2g}") + cut
    else:
        more = "above" if sp["right"] > sp["left"] else "below"
        side = (f"{unc} > {sp['value']:.7g}" if more == "above"
                else f"{unc} < {sp['value']:.7g}")
        extra = {"grazing": "an extra, grazing impact",
                 "extra impact": "an extra impact",
                 "chatter": "a different chatter/sticking sequence",
                 "impulse order": "an impact on the other side of an impulse"}[sp["kind"]]
        where = (f"samples with {side} (σ ≥ {sp['distance']:.5f}) make {extra} at "
                 f"t ≈ {sp['time']:.2f} periods (speed {sp['speed']:.1e}), "
                 f"{min(sp['left'], sp['right'])} → {max(sp['left'], sp['right'])} impacts"
                 f"{cut}")
        shape = ("x(t, ξ) is continuous in ξ there but not smooth: the new impact's speed, "
                 "and with it the change of x after it, grows like the square root of the "
                 "distance from the split" if sp["kind"] == "grazing" else
                 "x(t, ξ) is not smooth in ξ there")
    if not np.isfinite(hi):
        return f"{head}, OPA ({law}{'' if ', ME-' in law else ' law'}) agrees at every σ up " \
               f"to {_g(lo)}; {where}."
    if kind.startswith("ME-"):
        head += f" ({law})"
    star = star_phrase(lo, hi, float(ds.sigma.max()))
    first = "OPA first leaves the tolerance at t ≈ {:.2f} periods at σ = {:g}, the " \
            "smallest grid σ where it fails".format(*_disagree(ds, q, h, v, c))
    if sp is not None and lo == 0 and sp["distance"] <= hi:
        return (f"{head}, {star}, below the bisection's resolution, and so is the first "
                f"split: {where}. Over this horizon x(t, ξ) is not smooth in ξ for any σ "
                f"above {sp['distance']:.2g}; {first}.")
    if sp is not None and lo > 0 and lo - 2 * res <= sp["distance"] <= hi + 2 * res:
        return (f"{head}, {star} sits at the first split: {where}; {shape}, which no "
                f"polynomial in ξ and no single impact rule for the whole ensemble can "
                f"represent.")
    if sp is not None and sp["distance"] < lo:
        return (f"{head}, {star} lies past the first split ({where}): the samples "
                f"beyond it carry too little probability to move the error past the "
                f"tolerance before σ*.")
    at, sigma_fail = _disagree(ds, q, h, v, c)
    cross = _crossing_cause(ds, q, h, at, sigma_fail)
    if cross is not None and (sp is None or cross["distance"] < sp["distance"]):
        return (f"{head}, {star} comes before any split ({where}), but an impact crosses "
                f"an output time: at {unc} = {cross['value']:.7g} an impact (speed "
                f"{cross['speed']:.2g}) falls exactly on the output at t = "
                f"{cross['time']:.2f} periods, so for σ ≥ {cross['distance']:.2g} that output "
                f"sees some samples just before the impact and the others just after it, and "
                f"x({cross['time']:.2f} periods, ξ) has a kink in ξ there, which a polynomial "
                f"in ξ smooths over; {first}: "
                f"that very output.")
    slow = ""
    if "nominal_slowest_speed" in ds and np.isfinite(ds.nominal_slowest_speed.values[q, h]):
        slow = (f" The nominal system's slowest impact in the horizon hits the wall at speed "
                f"{float(ds.nominal_slowest_speed.values[q, h]):.2g} at t ≈ "
                f"{float(ds.nominal_slowest_time.values[q, h]):.2f} periods.")
    edge = nearest_horizon(ds, q, h)
    # a horizon split inside the grid is named even where sigma* lies below it: the count
    # table shows its extra impact (omega = 4.035, 10 periods, sigma = 0.005)
    if edge is not None and edge["distance"] < min(float(ds.sigma.max()), reach):
        same = (f"the samples make the same impacts within the horizon, except that "
                f"for σ ≥ {edge['distance']:.2g} some of them ({unc} "
                f"{'>' if edge['right'] > edge['left'] else '<'} {edge['value']:.7g}) make "
                f"one more impact within 1e-4 time units of the horizon's end (t = "
                f"{edge['time']:.2f} periods; {min(edge['left'], edge['right'])} → "
                f"{max(edge['left'], edge['right'])} impacts in the count table), which "
                f"moves x at the last output by at most its speed ({abs(edge['speed']):.2g}) "
                f"× 1e-4")
    else:
        same = "below σ* every sample makes the same impacts"
    return (f"{head}, {star} comes before any split ({where}): {same}, so the error is OPA's "
            f"own — the equivalent system's single "
            f"impact rule and its own dynamics between impacts — and not a discontinuity in "
            f"ξ; {first}.{slow}")


def short_cause(ds, q: int, h: int, v: int = HEADLINE, c: int = 0) -> str:
    """The cause of :func:`cause` in a few words (the first screen)."""
    check_map(ds, "cause")
    lo, hi = (float(ds.sigma_star.values[q, v, h, c]),
              float(ds.sigma_star_upper.values[q, v, h, c]))
    res = float(ds.attrs["resolution"])
    sp = nearest_split(ds, q, h)
    reach = complete_within(ds, q, h)
    if sp is not None and sp["distance"] >= reach:
        sp = None
    split = "" if sp is None else f"{sp['kind']} at σ {sp['distance']:.2g}, t ≈ {sp['time']:.1f}"
    if not np.isfinite(hi):
        return "agrees at every σ of the grid" + (f"; first split: {split}" if split else "")
    if sp is not None and lo == 0 and sp["distance"] <= hi:
        return f"a split at once: {split}"
    if sp is not None and lo > 0 and lo - 2 * res <= sp["distance"] <= hi + 2 * res:
        return f"the first split: {split}"
    if sp is not None and sp["distance"] < lo:
        return f"past the first split ({split}), which carries too little probability"
    at, sigma_fail = _disagree(ds, q, h, v, c)
    cross = _crossing_cause(ds, q, h, at, sigma_fail)
    if cross is not None and (sp is None or cross["distance"] < sp["distance"]):
        return (f"an impact crosses the output at t = {cross['time']:.2f} "
                f"(σ ≥ {cross['distance']:.2g}): a kink in ξ")
    return f"OPA's own error, no split below σ* (fails first at t ≈ {at:.1f})"


def _star(ds, q, v, h, c) -> str:
    return star_text(float(ds.sigma_star.values[q, v, h, c]),
                     float(ds.sigma_star_upper.values[q, v, h, c]), float(ds.sigma.max()))


def best_variant(ds, q: int, h: int) -> int:
    """The variant with the largest sigma* of the mean (ties: of the variance, then the
    first listed)."""
    def key(v):
        out = []
        for c in (0, 1):
            lo, hi = ds.sigma_star.values[q, v, h, c], ds.sigma_star_upper.values[q, v, h, c]
            out.append(np.inf if not np.isfinite(hi) else float(lo))
        return tuple(out)
    return max(range(ds.sizes["variant"]), key=lambda v: (key(v), -v))


def run_failures(ds) -> list[str]:
    """Runs whose error is NaN (the OPA trajectory stopped before the horizon): counted per
    variant and horizon, with the times at which they stop. They count as 'does not
    agree'."""
    check_map(ds, "run_failures")
    out = []
    ran = ds.variant_ran.values.astype(bool) if "variant_ran" in ds else \
        np.ones((ds.sizes["variant"], ds.sizes["N"]), bool)
    t = _time(ds).values
    for v, name in enumerate(ds.variant.values):
        for h, H in enumerate(ds.horizon.values):
            err = ds.err_mean.values[:, :, v, :, h][:, :, ran[v]]
            bad = ~np.isfinite(err)
            if not bad.any():
                continue
            n = int(round(float(H) * ds.attrs["per_period"])) + 1
            x = ds.opa_x_mean[:, :, v, :, :n].values[:, :, ran[v]][bad]  # v's only
            stops = [t[np.flatnonzero(~np.isfinite(row))[0]] for row in x
                     if (~np.isfinite(row)).any()]
            span = (f"{min(stops):.3g}" if f"{min(stops):.3g}" == f"{max(stops):.3g}"
                    else f"{min(stops):.3g}–{max(stops):.3g}") if stops else ""
            when = f"x_0 is NaN from t = {span} periods on" if stops else "no finite error"
            why = ""
            if "opa_status" in ds:  # the kernel's reasons, counted
                codes = ds.opa_status.values[:, :, v, :][:, :, ran[v]][bad]
                names = dict(zip(ds.opa_status.attrs["flag_values"].tolist(),
                                 ds.opa_status.attrs["flag_meanings"].split()))
                tally = {}
                for c in codes.tolist():
                    tally[names.get(c, str(c))] = tally.get(names.get(c, str(c)), 0) + 1
                why = "; " + ", ".join(f"{k.replace('_', ' ')} {n}" for k, n in
                                       sorted(tally.items(), key=lambda kv: -kv[1]))
            out.append(f"{int(bad.sum())} of {bad.size} {name} runs over {float(H):g} periods "
                       f"did not finish: the OPA system's integration stopped before the "
                       f"horizon ({when}{why}); counted as 'does not agree'")
    return out


SCREEN_WIDTH = 100


def bullet(text: str, mark: str = "* ") -> str:
    """A paragraph wrapped to SCREEN_WIDTH characters, with a hanging indent."""
    import textwrap

    return "\n".join(textwrap.wrap(text, SCREEN_WIDTH, initial_indent=mark,
                                    subsequent_indent=" " * len(mark),
                                    break_on_hyphens=False)) or mark.rstrip()


def process_started() -> float:
    """The ``time.perf_counter()`` reading at which this process started (Linux: from
    /proc; elsewhere: now), so that a command's wall time includes its imports."""
    import time

    now = time.perf_counter()
    try:
        with open("/proc/self/stat") as fh:
            ticks = int(fh.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as fh:
            uptime = float(fh.read().split()[0])
        age = uptime - ticks / os.sysconf("SC_CLK_TCK")
        return now - age if 0 <= age < 1e6 else now
    except (OSError, ValueError, IndexError):
        return now


def first_screen(ds) -> list[str]:
    """The answer at a glance, lines of at most 100 characters: per swept value and horizon,
    sigma* of the mean and of the variance (the paper's OPA), the best variant with its
    sigma*, and the cause in one line; then the runs that did not finish."""
    check_map(ds, "first_screen")
    par, unc = _par(ds), _unc(ds)
    smax = float(ds.sigma.max())
    head = str(ds.variant.values[HEADLINE])
    lines = [f"Where OPA (N = {int(ds.N.max())}) agrees with Monte Carlo: {unc} = "
             f"{_g(nominal(ds))} + σ ξ, ξ ~ {ds.attrs.get('distribution', 'semicircle')}, "
             f"σ ≤ {_g(smax)}",
             f"σ*: largest σ at which {head} agrees; mean: error ≤ "
             f"{ds.attrs['tolerance']:g} spread, variance: ≤ {ds.attrs['var_tolerance']:g} Var",
             ""]
    rows = []
    for q, value in enumerate(_vals(ds).values):
        for h, H in enumerate(ds.horizon.values):
            b = best_variant(ds, q, h)
            rows.append(([_g(float(value)), f"{float(H):g}", _star(ds, q, HEADLINE, h, 0),
                          _star(ds, q, HEADLINE, h, 1),
                          f"{ds.variant.values[b]}: {_star(ds, q, b, h, 0)} / "
                          f"{_star(ds, q, b, h, 1)}"], short_cause(ds, q, h)))
    cols = [par, "H", "σ* mean", "σ* variance", "best variant: σ* mean / variance"]
    widths = [max(len(cols[i]), *(len(r[0][i]) for r in rows)) for i in range(len(cols))]
    lines.append("  ".join(c.ljust(w) for c, w in zip(cols, widths)).rstrip())
    for cells, why in rows:
        lines.append("  ".join(c.ljust(w) for c, w in zip(cells, widths)).rstrip())
        lines += bullet(why, mark="    why: ").split("\n")
    fails = run_failures(ds)
    if fails:
        lines.append("")
        for f in fails:
            lines += bullet(f, mark="! ").split("\n")
    return [out for line in lines for out in (bullet(line, mark="").split("\n")
                                              if len(line) > SCREEN_WIDTH else [line])]


def _disagree(ds, q, h, v, c) -> tuple[float, float]:
    """First time of disagreement (N = Nmax) at the smallest grid sigma that fails over
    horizon h, and that sigma."""
    bad = np.flatnonzero(~ds.agrees.values[q, :, v, -1, h, c].astype(bool))
    s = int(bad[0]) if len(bad) else len(ds.sigma) - 1
    return float(ds.disagree_time.values[q, s, v, -1, c]), float(ds.sigma[s])


def boundary_table(ds: xr.Dataset, *, markdown: bool = False, criterion: int = 0) -> str:
    """sigma* (at N = Nmax, per variant) of the mean (``criterion=0``, beside the nearest
    split of the impact sequence) or of the variance (``criterion=1``) for every swept
    value and horizon."""
    check_map(ds, "boundary_table")
    par, unc = _par(ds), _unc(ds)
    variants = [str(v) for v in ds.variant.values]
    smax = float(ds.sigma.max())
    head = [par, "H [periods]"] + [f"σ* {v}" for v in variants]
    if criterion == 0:
        head += ["first split at σ", "kind", "at t [periods]"]
    rows = []
    for q, value in enumerate(_vals(ds).values):
        for h, H in enumerate(ds.horizon.values):
            row = [_g(float(value)), f"{float(H):g}"]
            for v in range(len(variants)):
                row.append(_star(ds, q, v, h, criterion))
            if criterion == 0:
                sp = nearest_split(ds, q, h)
                reach = complete_within(ds, q, h)
                if sp is not None and sp["distance"] >= reach:
                    sp = None
                row += ([f"{sp['distance']:.6f}", sp["kind"], f"{sp['time']:.2f}"] if sp else
                        [f"none ≤ {_g(smax)}" if reach >= smax else
                         f"none < {reach:.2g} (list cut by the limit)", "", ""])
            rows.append(row)
    if criterion == 0:
        title = (f"Trust boundary σ*: the largest σ at which OPA (N = {int(ds.N.max())}) agrees "
                 f"with Monte Carlo in the mean, bisected to {ds.attrs['resolution']:g}; the "
                 f"first split: the smallest σ whose ensemble {unc} ± σ contains a change of "
                 f"the impact sequence")
    else:
        title = (f"σ* of the variance: the largest σ at which the OPA variance (N = "
                 f"{int(ds.N.max())}) agrees with the Monte Carlo variance, bisected to "
                 f"{ds.attrs['resolution']:g}")
    return _table(title, head, rows, markdown)


def verdict_grid(ds: xr.Dataset, h: int, *, v: int = HEADLINE, criterion: int = 0,
                 markdown: bool = False, compact: bool = False) -> str:
    """Rows: swept values; columns: sigma; cell: the smallest N from which OPA agrees
    at every larger N of the map, or '✗' where N = Nmax does not."""
    check_map(ds, "verdict_grid")
    par = _par(ds)
    agrees = ds.agrees.values[:, :, v, :, h, criterion]  # value, sigma, N
    orders = [int(n) for n in ds.N.values]
    head = [f"{par} \\ σ"] + [_g(float(s)) for s in ds.sigma.values]
    rows = []
    for q, value in enumerate(_vals(ds).values):
        row = [_g(float(value))]
        for s in range(len(ds.sigma)):
            a = agrees[q, s].astype(bool)
            tail = np.flatnonzero(~a)
            first = 0 if not len(tail) else tail[-1] + 1
            if first < len(orders):
                row.append(f"N ≥ {orders[first]}")
            elif a.any() and not compact:
                row.append("✗ (N = " + ", ".join(str(orders[k]) for k in np.flatnonzero(a))
                           + " agree)")
            else:
                row.append("✗")
        rows.append(row)
    title = (f"Verdict over {float(ds.horizon[h]):g} periods ({ds.variant.values[v]}, "
             f"{ds.criterion.values[criterion]}): N ≥ k: OPA agrees with Monte Carlo for "
             f"every N of the map from k to {orders[-1]}; ✗: N = {orders[-1]} does not"
             + ("" if compact else " (the lower N that do are listed)"))
    if compact:
        title = bullet(title, mark="")
    return _table(title, head, rows, markdown)


def count_table(ds: xr.Dataset, h: int, *, markdown: bool = True) -> str:
    """The distribution of impact counts up to the horizon at every grid point whose
    ensemble is not all alike."""
    check_map(ds, "count_table")
    head = [_par(ds), "σ", "impacts: probability"]
    rows = []
    for q, value in enumerate(_vals(ds).values):
        for s, sigma in enumerate(ds.sigma.values):
            p = ds.count_prob.values[q, s, h]
            unknown = float(ds.count_unknown.values[q, s, h]) if "count_unknown" in ds \
                else 0.0
            nz = np.flatnonzero(p > 0)
            if len(nz) > 1 or unknown > 0:
                big = [k for k in nz if p[k] >= 1e-3]
                rest = [k for k in nz if p[k] < 1e-3]
                cell = ", ".join(f"{k}: {p[k]:.3f}" for k in big)
                if rest:
                    cell += (f", {len(rest)} other counts ({rest[0]}–{rest[-1]}) "
                             f"together: {p[rest].sum():.1e}")
                if unknown > 0:
                    cell += (f"; INCOMPLETE: {unknown:.3g} of the samples lie beyond the "
                             f"located splits (|{_unc(ds)} − {_g(nominal(ds))}| ≥ "
                             f"{complete_within(ds, q, h):.2g}: the split limit cut the list "
                             f"short)")
                rows.append([_g(float(value)), _g(float(sigma)), cell])
    title = (f"Impact counts up to {float(ds.horizon[h]):g} periods (exact where the split "
             f"list is complete, else marked INCOMPLETE; points where every sample makes the "
             f"same count are left out)")
    if not rows:
        return f"{title}: every grid point's samples make the same number of impacts."
    return _table(title, head, rows, markdown)


def _table(title, head, rows, markdown):
    if markdown:
        lines = [f"**{title}**", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h)
              for i, h in enumerate(head)]
    out = [title, "  ".join(h.rjust(w) for h, w in zip(head, widths))]
    return "\n".join(out + ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in rows])


# -- findings -------------------------------------------------------------------------------
def _window_sem(ds, q, s, n):
    se = ds.mc_x_sem[q, s, :n].values
    return float(np.sqrt(np.mean(se**2)))


def _window_tolerance(ds, q, s, n):
    """The mean's tolerance over the first n outputs, as the RMS error of the window is
    held against it: tol x RMS spread + the solver floor (the verdict certifies the
    error below it, or above it, at error rate alpha)."""
    spread = np.sqrt(np.maximum(ds.mc_x_var[q, s, :n].values, 0.0))
    floor = 10 * (float(ds.attrs["rtol"]) + float(ds.attrs["atol"]))
    return float(float(ds.attrs["tolerance"]) * np.sqrt(np.mean(spread**2)) + floor)


def findings(ds: xr.Dataset) -> list[str]:
    """Plain-language conclusions, each computed from the dataset."""
    check_map(ds, "findings")
    out = []
    par = _par(ds)
    orders = [int(n) for n in ds.N.values]
    nmax = orders[-1]
    sig = ds.sigma.values
    variants = [str(v) for v in ds.variant.values]
    for h, H in enumerate(ds.horizon.values):
        lo = ds.sigma_star.values[:, HEADLINE, h, 0]
        hi = ds.sigma_star_upper.values[:, HEADLINE, h, 0]
        txt = ", ".join(f"{par} = {_g(float(v))}: {star_text(a, b, float(sig.max()))}"
                        for v, a, b in zip(_vals(ds).values, lo, hi))
        out.append(f"Over {float(H):g} periods, σ* ({variants[HEADLINE]}, N = {nmax}) is {txt}.")
        for v in _element_variants(ds):  # multi-element sigma* beside the single element's
            one = _single_of(ds, v)
            cells = []
            for q, value in enumerate(_vals(ds).values):
                cell = star_text(float(ds.sigma_star.values[q, v, h, 0]),
                                 float(ds.sigma_star_upper.values[q, v, h, 0]), float(sig.max()))
                if one is not None:
                    cell += " (one element: " + star_text(
                        float(ds.sigma_star.values[q, one, h, 0]),
                        float(ds.sigma_star_upper.values[q, one, h, 0]), float(sig.max())) + ")"
                cells.append(f"{par} = {_g(float(value))}: {cell}")
            text = (f"Over {float(H):g} periods, σ* of multi-element OPA {variants[v]} "
                    f"(N = {nmax}) is {', '.join(cells)}.")
            if "variant_collocated" in ds:
                hit = ds.variant_collocated.values[:, :, v]
                if hit.any():
                    text += (f" At {int((hit > 0).sum())} of the {hit.size} grid points some "
                             f"elements' OPA systems diverged and were computed by collocation "
                             f"of the true systems (at most {int(hit.max())} elements).")
            out.append(text)
        res = float(ds.attrs["resolution"])
        at_split = []
        for q in range(len(_vals(ds))):
            sp = nearest_split(ds, q, h)
            if (sp and np.isfinite(hi[q]) and lo[q] > 0
                    and lo[q] - 2 * res <= sp["distance"] <= hi[q] + 2 * res):
                at_split.append(_g(float(_vals(ds)[q])))
        if at_split:
            out.append(f"Over {float(H):g} periods the boundary coincides (within "
                       f"{2 * res:g}) with the first split of the impact sequence at "
                       f"{par} = {', '.join(at_split)}.")
    # how the error grows below and past the boundary (first value, first horizon)
    q, h = 0, 0
    err = ds.err_mean.values[q, :, HEADLINE, -1, h]
    lo = float(ds.sigma_star.values[q, HEADLINE, h, 0])
    below = sig <= lo
    if below.sum() >= 3:
        slope = np.polyfit(np.log(sig[below]), np.log(err[below]), 1)[0]
        out.append(
            f"At {par} = {_g(float(_vals(ds)[q]))}, over {float(ds.horizon[h]):g} periods, "
            f"the RMS error of x_0 ({variants[HEADLINE]}, N = {nmax}) grows like "
            f"σ^{slope:.2f} for σ = {_g(float(sig[below][0]))}…{_g(float(sig[below][-1]))} "
            f"(below σ*), from {_e(err[below][0])} to {_e(err[below][-1])}.")
    above = np.flatnonzero(sig > lo)
    if below.any() and len(above):
        s0, s1 = np.flatnonzero(below)[-1], above[0]
        factor, ratio = err[s1] / err[s0], sig[s1] / sig[s0]
        if below.sum() >= 3:
            law = f"the law fitted below σ* predicts {ratio ** slope:.1f}"
            expected = ratio ** slope
        else:  # too few points below sigma* to fit: compare with the sigma^1 and sigma^2 laws
            law = (f"an error ∝ σ would grow by {ratio:.1f} and one ∝ σ² by {ratio ** 2:.1f} "
                   f"(too few grid σ below σ* to fit a law)")
            expected = ratio ** 2
        verb = "jumps" if factor > 1.5 * expected else "grows, without a jump,"
        out.append(
            f"Across σ* it {verb} from {_e(err[s0])} (σ = {_g(float(sig[s0]))}) to "
            f"{_e(err[s1])} (σ = {_g(float(sig[s1]))}), a factor {factor:.1f}, where {law}.")
    # does N matter for the verdict?
    for h, H in enumerate(ds.horizon.values):
        a = ds.agrees.values[:, :, HEADLINE, :, h, 0].astype(bool)  # value, sigma, N
        some = a.any(axis=-1)
        if some.any():
            n0 = a[..., 0][some].sum()
            text = (f"Over {float(H):g} periods ({variants[HEADLINE]}), N = {orders[0]} "
                    f"already agrees at {n0} of the {some.sum()} grid points where some "
                    f"N ≤ {nmax} agrees")
            if n0 >= 0.9 * some.sum():
                text += ": N hardly changes the verdict"
            out.append(text + ".")
    # before the first impact: each sigma's window ends at OPA's first impact there (the
    # window of pre_impact_err), inf where OPA does not impact in the record
    pre = ds.pre_impact_err.values[q, :, HEADLINE, :]  # sigma, N
    first = ds.first_impact.values[q, :, HEADLINE, -1]  # sigma
    t = _time(ds).values
    n_pre = np.array([int(np.sum(t < f)) for f in first])
    shown = np.flatnonzero(n_pre > 1)  # more than t = 0, where OPA and MC start as one
    if len(shown):
        ok = [f"{_e(pre[s, -1])} at σ = {_g(float(sig[s]))} (MC SE "
              f"{_e(_window_sem(ds, q, s, n_pre[s]))})" for s in shown]
        ends = sorted({f"{f:.2f}" for f in first[shown] if np.isfinite(f)}, key=float)
        when = f"t < {'–'.join(dict.fromkeys(ends[:1] + ends[-1:]))} periods"  # or a range
        if not np.isfinite(first[shown]).all():
            whole = f"the {float(t[-1]):g} periods recorded"
            when = (f"{when}, or {whole} where OPA does not impact," if ends
                    else f"no impact in {whole}")
        out.append(f"Before OPA's first impact ({when} at {par} = "
                   f"{_g(float(_vals(ds)[q]))}) the error of x_0 at N = {nmax} is "
                   + "; ".join(ok[:: max(1, len(ok) // 4)]) + ".")
    # impact laws against each other, below sigma* of both
    e_mean = ds.err_mean.values[..., 0, -1, 0]
    e_ens = ds.err_mean.values[..., 1, -1, 0]
    ratio = e_ens / e_mean
    head = (f"Ensemble against mean impact law (N = {nmax}, {float(ds.horizon[0]):g} "
            f"periods): the ratio of their errors of x_0 ")
    lo, hi = (f"{np.nanmin(ratio):.2g}", f"{np.nanmax(ratio):.2g}") \
        if np.isfinite(ratio).any() else ("", "")
    if lo and lo == hi:  # one value to the digits shown: not a range
        out.append(head + f"is {lo} wherever it is known on the grid.")
    elif lo:
        out.append(head + f"ranges over {lo}…{hi} on the grid (median "
                          f"{np.nanmedian(ratio):.2g}).")
    else:
        out.append(head + "is known nowhere on the grid: a run of one of them stopped at "
                          "every point (see the runs that did not finish).")
    if "mean/paper" in variants:  # the paper's truncation exists under the semicircle only
        paper = variants.index("mean/paper")
        trunc = np.abs(ds.err_mean.values[..., paper, -1, 0] - e_mean) / np.maximum(e_mean,
                                                                                     1e-300)
        head = "The paper's truncation (eq. (27)) against the Galerkin projection "
        out.append(head + (f"changes that error by at most {np.nanmax(trunc):.1e} relative on "
                           f"the grid." if np.isfinite(trunc).any() else
                           "cannot be compared anywhere on the grid: the runs of one of them "
                           "stopped at every point."))
    # variance
    for v in _laws(ds):
        frac = ds.agrees.values[:, :, v, -1, :, 1].mean(axis=(0, 1))
        out.append(f"The variance ({variants[v]}, N = {nmax}) agrees within "
                   f"{ds.attrs['var_tolerance']:g} of the MC variance at "
                   + ", ".join(f"{100 * f:.0f}% of the grid over {float(H):g} periods"
                               for f, H in zip(frac, ds.horizon.values)) + ".")
    # EMR_0 against DMR
    d = ds.emr0_dmr_difference.values
    out.append(f"With σ = 0, OPA at N = {nmax} and the DMR differ by at most "
               + ", ".join(f"{_e(x)} over {float(H):g} periods"
                           for x, H in zip(d, ds.horizon.values))
               + f" (round-off amplified by the flow); at N = 0 by "
               f"{float(ds.emr0_n0_dmr_difference):.1e}.")
    return out


# -- figures --------------------------------------------------------------------------------
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
    from matplotlib.colors import TwoSlopeNorm

    H = len(ds.horizon)
    fig, axes = plt.subplots(H, 2, figsize=size or (11, 3.9 * H + 1.4), squeeze=False,
                             sharex=True, sharey=True, layout="constrained")
    x = _vals(ds).values.astype(float)
    y = ds.sigma.values
    kinds = _kinds(ds)
    smax = float(y.max())
    drawn = _laws(ds) + _element_variants(ds)
    head = str(ds.variant.values[HEADLINE])
    centre = nominal(ds)
    X, Y = np.meshgrid(x, y, indexing="ij")
    norm = TwoSlopeNorm(vcenter=0.0, vmin=-3.0, vmax=2.0)
    span = (x[-1] - x[0]) / max(1, len(x) - 1) if len(x) > 1 else 0.02 * abs(x[0])
    handles, labels = [], []
    for h in range(H):
        for c, (what, rel, tol) in enumerate((
                ("mean", ds.err_mean_rel, float(ds.attrs["tolerance"])),
                ("variance", ds.err_var_rel, float(ds.attrs["var_tolerance"])))):
            ax = axes[h, c]
            r = rel.values[:, :, HEADLINE, -1, h] / tol
            mesh = ax.pcolormesh(*_edges(x, y), np.log10(np.maximum(r.T, 1e-12)),
                                 cmap="RdBu_r", norm=norm, shading="flat")
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
            ps = ds.probe_sigma.values
            for q in range(len(x)):  # probes drawn left of their column, thinned
                kept = _thinned(ps[q], PROBE_GAP * smax)
                if len(kept):
                    ax.scatter(np.full(len(kept), x[q] - 0.2 * span), kept, marker="_",
                               color="0.25", s=30, lw=0.8, zorder=3, label="σ probed")
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
            kind = ds.split_kind.values[:, h]
            dist = np.abs(ds.split_value.values[:, h] - centre)
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
            ax.set_ylim(-0.04 * smax, smax * 1.04)
            _xlim(ax, x)
            ax.set_title(f"{what}, H = {float(ds.horizon[h]):g} forcing periods", fontsize=9)
            if h == H - 1:
                ax.set_xlabel(_par(ds))
            if c == 0:
                ax.set_ylabel("σ")
            cb = fig.colorbar(mesh, ax=ax, extend="both")
            cb.set_label(f"RMS error of the {what} / its tolerance", fontsize=8)
            cb.set_ticks([-3, -2, -1, 0, 1, 2],
                         labels=["0.001", "0.01", "0.1", "1 = tol", "10", "100"])
            cb.ax.tick_params(labelsize=7)
            cb.ax.axhline(0.0, color="k", lw=2)
            hh, ll = ax.get_legend_handles_labels()
            handles, labels = handles + hh, labels + ll
    _fig_legend(fig, handles, labels, 3)
    import textwrap

    # one line at the default size; wrapped only where a smaller figure cannot hold it
    width = int(fig.get_size_inches()[0] * 72 / (9 * 0.6))  # characters of 9 pt that fit
    fig.suptitle("\n".join(textwrap.wrap(
        f"Where OPA (N = {int(ds.N.max())}) agrees with Monte Carlo: marks {head}, "
        f"lines σ* per variant", width)), fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


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
    fig.suptitle(f"σ = {conv.attrs['sigma']:g}, ω = {conv.attrs['omega']:g}, "
                 f"{conv.attrs['periods']:g} periods: error against K, N and cost", fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def frontier_dataset(ds):
    """The frontier part of a trust-map dataset in the shape of an ``opa-mc converge``
    dataset (None if the map was run without it)."""
    names = [n for n in ds.data_vars if n.startswith("frontier_")]
    if not names:
        return None
    out = ds[names].rename({n: n[len("frontier_"):] for n in names}
                           | {"frontier_run": "run"})
    out.attrs = {k[len("frontier_"):]: v for k, v in ds.attrs.items()
                 if k.startswith("frontier_")}
    if "omega" in ds.attrs:  # files written before frontier_omega
        out.attrs.setdefault("omega", ds.attrs["omega"])
    return out


def frontier_lines(ds) -> list[str]:
    from compare._convergence import summary_lines

    conv = frontier_dataset(ds)
    if conv is None:
        return []
    reference = conv.attrs.get("reference_text",
                               f"{conv.attrs['reference_samples']} Sobol samples")
    head = (f"Cost against accuracy at {_par(ds)} = {_g(conv.attrs['value'])}, σ = "
            f"{_g(conv.attrs['sigma'])}, over {conv.attrs['periods']:g} periods (RMS error of "
            f"E[x] against {reference}):")
    return [head] + summary_lines(conv)


# -- summary.md -----------------------------------------------------------------------------
def wall_text(seconds: dict) -> str:
    """'12.4 s (map 10.1 s, report 2.3 s)': the wall times of one run, read off one clock."""
    parts = ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items() if k != "total")
    return f"{seconds['total']:.1f} s" + (f" ({parts})" if parts else "")


REPORT_FIGURES = (("trust_map.png", plot_map), ("error_vs_N.png", plot_error_vs_order),
           ("mean_vs_mc.png", plot_mean), ("variance.png", plot_variance),
           ("phase.png", plot_phase))

#: CPU seconds of each figure of the default map on the 2-core machine (one process,
#: matplotlib imported first: ``python benchmarks/figure_times.py OUTDIR/validate.nc``):
#: the order in which start_figures hands them to its processes
FIGURE_COST = {"frontier.png": 2.11, "error_vs_N.png": 1.12, "trust_map.png": 0.95,
               "variance.png": 0.64, "mean_vs_mc.png": 0.55, "phase.png": 0.24}


def draw_figures(ds: xr.Dataset, outdir: str, *, workers: int = 1,
                 source: str | None = None) -> list[str]:
    """The report's figures (:data:`REPORT_FIGURES`, then the frontier's when the map has one),
    drawn in this process or, with ``workers`` > 1, side by side on that many processes
    of :func:`opa.engine.local_executor` (each figure depends on ``ds`` alone; the files
    are the same either way). ``source``: a netCDF file that holds ``ds`` (the map's
    validate.nc), which the processes open instead of each receiving a copy of ``ds``.
    Returns the written paths in the order of the figures."""
    return start_figures(ds, outdir, workers=workers, source=source)()


def start_figures(ds: xr.Dataset, outdir: str, *, workers: int = 1,
                  source: str | None = None):
    """:func:`draw_figures` in two steps: with ``workers`` > 1 the figures start on their
    processes now, and the function returned waits for them (and ends the processes)
    and returns the paths, so that this process can write the summary meanwhile; with
    one, they are drawn here when that function is called."""
    check_map(ds, "figures")
    jobs = [(fn, name) for name, fn in REPORT_FIGURES]
    if frontier_dataset(ds) is not None:
        jobs.append((_plot_frontier_of, "frontier.png"))
    if workers <= 1:
        return lambda: _paths([fn(ds, os.path.join(outdir, name)) for fn, name in jobs])
    from opa.engine import local_executor

    data = ds if source is None else source
    # the longest first, so that no long figure starts last (FIGURE_COST)
    order = sorted(range(len(jobs)), key=lambda k: -FIGURE_COST.get(jobs[k][1], 0.0))
    pool = local_executor(min(int(workers), len(jobs)))
    try:
        futures = {k: pool.submit(_draw, jobs[k][0], data, os.path.join(outdir, jobs[k][1]))
                   for k in order}
    except BaseException:
        pool.shutdown(cancel_futures=True)
        raise

    def finish() -> list[str]:
        try:
            return _paths([futures[k].result() for k in range(len(jobs))])
        finally:
            pool.shutdown(cancel_futures=True)

    return finish


def _paths(done) -> list[str]:
    """The written paths of the figures, in order (a figure may write several)."""
    paths = []
    for written in done:
        paths += [written] if isinstance(written, str) else list(written)
    return paths


def _plot_frontier_of(ds: xr.Dataset, path: str):
    """The frontier's figure of a map (:func:`frontier_dataset`)."""
    return plot_frontier(frontier_dataset(ds), path)


def _draw(fn, data, path: str):
    """``fn(ds, path)`` on a worker: ``data`` is the map, or a netCDF file that holds it."""
    if isinstance(data, str):
        with xr.open_dataset(data) as ds:
            return fn(ds, path)
    return fn(data, path)


def write_report(ds: xr.Dataset, outdir: str, *, plots: bool = True,
                 command: str = "opa-mc validate", started: float | None = None,
                 timing: dict | None = None, workers: int = 1,
                 source: str | None = None) -> list[str]:
    """Write summary.md and the figures; returns the written paths.

    ``workers``: processes that draw the figures side by side, ``source``: the netCDF
    file of ``ds`` they read it from (:func:`draw_figures`).

    ``started``: the ``time.perf_counter()`` reading at which the command started, the
    same clock as ``run_validation(started=...)``: summary.md then gives the time from it
    to the finished report, split into the map (the dataset's ``wall_seconds``) and the
    report. Without it summary.md gives the map's time only. ``timing``, a dict, receives
    those times (keys total, map, report), for the caller to print the same numbers."""
    import time

    check_map(ds, "write_report")
    os.makedirs(outdir, exist_ok=True)
    # the figures' processes draw while this one writes the summary
    figures = (start_figures(ds, outdir, workers=workers, source=source) if plots
               else (lambda: []))
    try:
        lines = _summary_lines(ds, command)
    finally:
        paths = figures()
    a = ds.attrs
    seconds = {"total": float(a["wall_seconds"])}
    if started is not None:
        seconds = {"total": time.perf_counter() - started, "map": float(a["wall_seconds"])}
        seconds["report"] = seconds["total"] - seconds["map"]
    lines = [line.replace(_WALL_TIME, wall_text(seconds)) for line in lines]
    if plots:
        lines += ["## Figures", ""] + [f"![{os.path.basename(p)}]({os.path.basename(p)})"
                                       for p in paths] + [""]
    md = os.path.join(outdir, "summary.md")
    with open(md, "w") as fh:
        fh.write("\n".join(lines))
    if timing is not None:
        timing.update(seconds)
    return [md] + paths


#: where summary.md's wall time goes, once the figures are drawn
_WALL_TIME = "\x00wall time\x00"


def _summary_lines(ds: xr.Dataset, command: str) -> list[str]:
    """summary.md's lines but its figures, the wall time a placeholder (``_WALL_TIME``)."""
    a = ds.attrs
    value_text = ", ".join(_g(float(v)) for v in _vals(ds).values)
    lines = [
        "# opa-mc validate: where OPA agrees with Monte Carlo", "",
        "```text", *first_screen(ds), "```", "",
        f"Command: `{command}` (wall time {_WALL_TIME}; computed: "
        f"{a['mc_runs_computed']} Monte Carlo runs, {a['opa_runs_computed']} OPA runs, "
        f"{a['parts_computed']} parts in all (splits and the frontier included); the rest "
        f"reused from parts/).", "",
        f"Model: preset {a['preset']} (" + ", ".join(
            f"{k} = {a[k]:g}" for k in ("mu", "a", "c", "f", "omega", "eta", "delta", "F0")
            if k in a) + f", {a['impulse']} impulses), {a['parameter']} swept over "
        f"{value_text}, uncertain {a['uncertain']} "
        f"= {_g(nominal(ds))} + σ ξ, ξ ~ {a.get('distribution', 'semicircle')}, σ in "
        f"{', '.join(_g(float(s)) for s in ds.sigma.values)}; "
        f"N = {int(ds.N.min())}..{int(ds.N.max())}; rtol = {a['rtol']:g}, atol = "
        f"{a['atol']:g}; Monte "
        f"Carlo: scrambled Sobol, {a['samples']} samples, doubled up to {a['max_samples']} "
        f"while a verdict is undecided, seed {a['seed']}.", "",
        f"Criterion: {a['criterion_text']}; tol = {a['tolerance']:g} (mean), "
        f"{a['var_tolerance']:g} (variance), alpha = {a['alpha']:g}.", "",
    ]
    if a.get("variants_dropped", "none") != "none":
        lines += [f"Variants left out: {a['variants_dropped']}.", ""]
    if _element_variants(ds):
        lines += [f"Multi-element variants ({a.get('elements')} elements"
                  + (f", budget {a['max_elements']}" if "max_elements" in a else "")
                  + f"): {a.get('element_text', '')}.", ""]
    fails = run_failures(ds)
    if fails:
        lines += ["## Runs that did not finish", ""] + [f"- {f}." for f in fails] + [""]
    lines += [
        "## Trust boundary", "", boundary_table(ds, markdown=True), "",
        boundary_table(ds, markdown=True, criterion=1), "",
        "## Why it breaks", "",
    ]
    for q in range(len(_vals(ds))):
        for h in range(len(ds.horizon)):
            lines.append(f"- {cause(ds, q, h)}")
            for v in _element_variants(ds):
                lines.append(f"- {cause(ds, q, h, v)}")
    lines += ["", "## Findings", ""] + [f"- {f}" for f in findings(ds)] + [""]
    front = frontier_lines(ds)
    if front:
        from compare._convergence import table as frontier_table

        lines += ["## Cost and accuracy", "", front[0], ""] + [f"- {f}" for f in front[1:]]
        lines += ["", frontier_table(frontier_dataset(ds)), ""]
    lines += ["## Verdicts", ""]
    for h in range(len(ds.horizon)):
        lines += [verdict_grid(ds, h, markdown=True), ""]
        for v in _laws(ds)[1:]:
            lines += [verdict_grid(ds, h, v=v, markdown=True), ""]
        for v in _laws(ds):
            lines += [verdict_grid(ds, h, v=v, criterion=1, markdown=True), ""]
    lines += ["## Impact counts", ""]
    for h in range(len(ds.horizon)):
        lines += [count_table(ds, h), ""]
    return lines


__all__ = ["best_variant", "boundary_table", "cause", "draw_figures", "first_screen",
           "start_figures",
           "run_failures",
           "short_cause", "wall_text", "bullet", "process_started", "complete_within",
           "count_table", "findings",
           "frontier_dataset", "frontier_lines", "nearest_crossing", "nearest_split",
           "star_text", "verdict_grid", "write_report"]
