"""Tables, plain-language findings, figures and summary.md of a trust-map dataset.

Everything here is read off the dataset that :func:`compare.run_validation` wrote; nothing
is assumed about the model. The headline is the boundary table: sigma* per swept value and
horizon, beside the nearest split of the sampled systems' impact sequences.
"""

from __future__ import annotations

import os

import numpy as np
import xarray as xr

# Variant shown where one must be picked: the paper's OPA (mean impact law) with the
# exact Galerkin truncation.
HEADLINE = 0
VARIANT_MARKERS = ("o", "s", "^", "v", "D")
# The impact laws drawn and summarised side by side (by name: under a law of xi other than
# the semicircle the paper-truncation variants are left out, and multi-element variants
# named "<law>/ME-<K8|adaptive64>" follow the single-element ones).
DRAWN_VARIANTS = ("mean/galerkin", "ensemble/galerkin", "saltation/galerkin")
KIND_COLOURS = {"grazing": "tab:red", "extra impact": "tab:orange", "chatter": "tab:purple",
                "impulse order": "tab:brown", "horizon": "0.6", "output crossing": "tab:cyan"}
# Kinds of the split arrays that do not change the impact sequence.
NOT_SPLITS = ("horizon", "output crossing")



def _pyplot():
    """matplotlib.pyplot on the Agg backend, imported only when a figure is drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt

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
        cut = (f"; the scan's limit of splits was reached, so splits and impact counts are "
               f"known only for |{unc} − {_g(nominal(ds))}| < {reach:.2g}")
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
    return (f"{head}, {star} comes before any split ({where}): below σ* every sample makes "
            f"the same impacts, so the error is OPA's own — the equivalent system's single "
            f"impact rule and its own dynamics between impacts — and not a discontinuity in "
            f"ξ; {first}.{slow}")


def _disagree(ds, q, h, v, c) -> tuple[float, float]:
    """First time of disagreement (N = Nmax) at the smallest grid sigma that fails over
    horizon h, and that sigma."""
    bad = np.flatnonzero(~ds.agrees.values[q, :, v, -1, h, c].astype(bool))
    s = int(bad[0]) if len(bad) else len(ds.sigma) - 1
    return float(ds.disagree_time.values[q, s, v, -1, c]), float(ds.sigma[s])


def boundary_table(ds: xr.Dataset, *, markdown: bool = False, criterion: int = 0) -> str:
    """sigma* (at N = Nmax, per variant) for every swept value and horizon, beside the
    nearest split of the impact sequence."""
    par, unc = _par(ds), _unc(ds)
    variants = [str(v) for v in ds.variant.values]
    smax = float(ds.sigma.max())
    drawn = _laws(ds) + _element_variants(ds)
    head = [par, "H [periods]"] + [f"σ* {v}" for v in variants] + [
        f"σ* variance {variants[v]}" for v in drawn] + [
        "first split at σ", "kind", "at t [periods]"]
    rows = []
    for q, value in enumerate(_vals(ds).values):
        for h, H in enumerate(ds.horizon.values):
            row = [_g(float(value)), f"{float(H):g}"]
            for v in range(len(variants)):
                row.append(star_text(float(ds.sigma_star.values[q, v, h, criterion]),
                                     float(ds.sigma_star_upper.values[q, v, h, criterion]),
                                     smax))
            for v in drawn:
                row.append(star_text(float(ds.sigma_star.values[q, v, h, 1]),
                                     float(ds.sigma_star_upper.values[q, v, h, 1]), smax))
            sp = nearest_split(ds, q, h)
            reach = complete_within(ds, q, h)
            if sp is not None and sp["distance"] >= reach:
                sp = None
            row += ([f"{sp['distance']:.6f}", sp["kind"], f"{sp['time']:.2f}"] if sp else
                    [f"none ≤ {_g(smax)}" if reach >= smax else
                     f"none < {reach:.2g} (limit reached)", "", ""])
            rows.append(row)
    title = (f"Trust boundary σ*: the largest σ at which OPA (N = {int(ds.N.max())}) agrees "
             f"with Monte Carlo in the mean, bisected to {ds.attrs['resolution']:g}; the first "
             f"split: the smallest σ whose ensemble {unc} ± σ contains a change of the "
             f"impact sequence")
    return _table(title, head, rows, markdown)


def verdict_grid(ds: xr.Dataset, h: int, *, v: int = HEADLINE, criterion: int = 0,
                 markdown: bool = False) -> str:
    """Rows: swept values; columns: sigma; cell: the smallest N from which OPA agrees
    at every larger N of the map, or '✗' where N = Nmax does not."""
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
            elif a.any():
                row.append("✗ (N = " + ", ".join(str(orders[k]) for k in np.flatnonzero(a))
                           + " agree)")
            else:
                row.append("✗")
        rows.append(row)
    title = (f"Verdict over {float(ds.horizon[h]):g} periods ({ds.variant.values[v]}, "
             f"{ds.criterion.values[criterion]}): N ≥ k: OPA agrees with Monte Carlo for "
             f"every N of the map from k to {orders[-1]}; ✗: N = {orders[-1]} does not "
             f"(the lower N that do are listed)")
    return _table(title, head, rows, markdown)


def count_table(ds: xr.Dataset, h: int, *, markdown: bool = True) -> str:
    """The distribution of impact counts up to the horizon at every grid point whose
    ensemble is not all alike."""
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
                             f"{complete_within(ds, q, h):.2g}, the split limit was reached)")
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
    se = ds.mc_x_sem.values[q, s, :n]
    return float(np.sqrt(np.mean(se**2)))


def findings(ds: xr.Dataset) -> list[str]:
    """Plain-language conclusions, each computed from the dataset."""
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
        out.append(
            f"Across σ* it jumps from {_e(err[s0])} (σ = {_g(float(sig[s0]))}) to "
            f"{_e(err[s1])} (σ = {_g(float(sig[s1]))}), a factor {err[s1] / err[s0]:.1f}"
            + (f", where the law fitted below σ* predicts "
               f"{(sig[s1] / sig[s0]) ** slope:.1f}." if below.sum() >= 3 else "."))
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
    # before the first impact
    pre = ds.pre_impact_err.values[q, :, HEADLINE, :]  # sigma, N
    first = ds.first_impact.values[q, 0, HEADLINE, -1]
    n_pre = int(np.sum(ds.periods.values < first))
    if n_pre > 1:
        floor = np.array([_window_sem(ds, q, s, n_pre) for s in range(len(sig))])
        ok = [f"σ = {_g(float(s))}: {_e(pre[i, -1])} (MC SE {_e(floor[i])})"
              for i, s in enumerate(sig)]
        out.append(f"Before OPA's first impact (t < {first:.2f} periods at "
                   f"{par} = {_g(float(_vals(ds)[q]))}) the error of x_0 at N = {nmax} is "
                   + "; ".join(ok[:: max(1, len(ok) // 4)]) + ".")
    # impact laws against each other, below sigma* of both
    e_mean = ds.err_mean.values[..., 0, -1, 0]
    e_ens = ds.err_mean.values[..., 1, -1, 0]
    ratio = e_ens / e_mean
    out.append(f"Ensemble against mean impact law (N = {nmax}, {float(ds.horizon[0]):g} "
               f"periods): the ratio of their errors of x_0 ranges over "
               f"{np.nanmin(ratio):.2g}…{np.nanmax(ratio):.2g} on the grid (median "
               f"{np.nanmedian(ratio):.2g}).")
    if "mean/paper" in variants:  # the paper's truncation exists under the semicircle only
        paper = variants.index("mean/paper")
        trunc = np.abs(ds.err_mean.values[..., paper, -1, 0] - e_mean) / np.maximum(e_mean,
                                                                                     1e-300)
        out.append(f"The paper's truncation (eq. (27)) against the Galerkin projection "
                   f"changes that error by at most {np.nanmax(trunc):.1e} relative on the grid.")
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
def plot_map(ds, path):
    """Per horizon: log10 of the relative error of x_0 at every grid point, the verdicts,
    sigma* (mean and ensemble law), every sigma probed, and the splits."""
    plt = _pyplot()
    H = len(ds.horizon)
    fig, axes = plt.subplots(1, H, figsize=(5.6 * H, 4.6), squeeze=False, sharey=True)
    x = _vals(ds).values
    y = ds.sigma.values
    kinds = _kinds(ds)
    smax = float(y.max())
    for h, ax in enumerate(axes[0]):
        rel = ds.err_mean_rel.values[:, :, HEADLINE, -1, h]
        mesh = ax.pcolormesh(*_edges(x, y), np.log10(np.maximum(rel.T, 1e-12)),
                             cmap="viridis", vmin=-4, vmax=1, shading="flat")
        a = ds.agrees.values[:, :, HEADLINE, -1, h, 0].astype(bool)
        X, Y = np.meshgrid(x, y, indexing="ij")
        ax.scatter(X[a], Y[a], marker="o", facecolor="white", edgecolor="k", s=30,
                   label="agrees", zorder=4)
        ax.scatter(X[~a], Y[~a], marker="x", color="red", s=30, label="does not", zorder=4)
        ps = ds.probe_sigma.values
        for q in range(len(x)):
            pr = ps[q][np.isfinite(ps[q])]
            ax.scatter(np.full(len(pr), x[q]), pr, marker="_", color="0.85", s=40, zorder=3,
                       label="σ probed" if q == 0 else None)
        for v, style, colour in zip(_laws(ds), ("-", "--", ":"), ("white", "gold", "cyan")):
            lo = ds.sigma_star.values[:, v, h, 0]
            hi = ds.sigma_star_upper.values[:, v, h, 0]
            top = np.where(np.isfinite(hi), lo, smax)
            ax.plot(x, top, style, color=colour, lw=2, zorder=5,
                    label=f"σ* {ds.variant.values[v]}")
        centre = nominal(ds)
        for q in range(len(x)):
            for j in range(ds.sizes["split"]):
                k = int(ds.split_kind.values[q, h, j])
                d = abs(float(ds.split_value.values[q, h, j]) - centre)
                if k < 0 or kinds[k] == "horizon" or d > smax:
                    continue
                ax.scatter(x[q] + 0.004 * (x[-1] - x[0] + 1e-9), d,
                           marker="v" if kinds[k] == "output crossing" else "D", s=22,
                           color=KIND_COLOURS[kinds[k]], edgecolor="k", lw=0.4, zorder=6,
                           label=f"split: {kinds[k]}")
        ax.set_xlabel(ds.attrs["parameter"])
        ax.set_title(f"H = {float(ds.horizon[h]):g} forcing periods")
        ax.set_ylim(0, smax * 1.04)
        if h == 0:
            ax.set_ylabel(f"σ (distance of the split from {_unc(ds)} = {_g(centre)})")
        fig.colorbar(mesh, ax=ax, label="log10 RMS error of x_0 / RMS spread")
    handles, labels = axes[0, -1].get_legend_handles_labels()
    for ax in axes[0][:-1]:
        hh, ll = ax.get_legend_handles_labels()
        handles, labels = handles + hh, labels + ll
    uniq = dict(zip(labels, handles))
    fig.legend(uniq.values(), uniq.keys(), loc="lower center", ncol=4, fontsize=8)
    fig.suptitle(f"Where OPA (N = {int(ds.N.max())}, {ds.variant.values[HEADLINE]}) agrees with "
                 f"Monte Carlo")
    fig.tight_layout(rect=(0, 0.12, 1, 1))
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


def plot_error_vs_order(ds, path, q=0):
    """RMS error of x_0 against N, before OPA's first impact and over each horizon, for
    every variant (distinct markers, offset in N), with the MC noise floor."""
    plt = _pyplot()
    picks = _pick_sigmas(ds, q)
    H = len(ds.horizon)
    fig, axes = plt.subplots(len(picks), 1 + H, figsize=(4.2 * (1 + H), 3.4 * len(picks)),
                             squeeze=False, sharex=True)
    N = ds.N.values.astype(float)
    for r, s in enumerate(picks):
        first = ds.first_impact.values[q, s, HEADLINE, -1]
        n_pre = max(2, int(np.sum(ds.periods.values < first)))
        windows = [("before OPA's first impact", ds.pre_impact_err.values[q, s], n_pre)]
        for h, Hh in enumerate(ds.horizon.values):
            windows.append((f"first {float(Hh):g} periods", ds.err_mean.values[q, s, :, :, h],
                            int(round(float(Hh) * ds.attrs["per_period"])) + 1))
        for c, (title, err, n) in enumerate(windows):
            ax = axes[r, c]
            for v, name in enumerate(ds.variant.values):
                ax.semilogy(N + 0.07 * (v - 2), np.maximum(err[v], 1e-16),
                            VARIANT_MARKERS[v % len(VARIANT_MARKERS)] + "-", ms=5, mfc="none" if v % 2 else None, lw=0.8,
                            label=str(name))
            ax.axhline(_window_sem(ds, q, s, n), color="k", ls="--", lw=1,
                       label="MC noise floor (RMS SE)")
            ax.set_title(f"σ = {float(ds.sigma[s]):g}: {title}", fontsize=9)
            if r == len(picks) - 1:
                ax.set_xlabel("N")
        axes[r, 0].set_ylabel("RMS error of x_0")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"{_par(ds)} = {_g(float(_vals(ds)[q]))}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def plot_mean(ds, path, q=0):
    """x_0 for several N beside the MC mean with its 2-SE band, and the error, at a sigma
    that agrees and one that does not, over the first horizon."""
    plt = _pyplot()
    picks = _pick_sigmas(ds, q)
    orders = [int(n) for n in ds.N.values]
    show = [k for k, n in enumerate(orders) if n in (0, 1, 2, 4, 8) or k == len(orders) - 1]
    n = int(round(float(ds.horizon[0]) * ds.attrs["per_period"])) + 1
    t = ds.periods.values[:n]
    fig, axes = plt.subplots(2, len(picks), figsize=(6.5 * len(picks), 6.4), squeeze=False,
                             sharex=True)
    for c, s in enumerate(picks):
        m = ds.mc_x_mean.values[q, s, :n]
        se = ds.mc_x_sem.values[q, s, :n]
        ax, ax2 = axes[0, c], axes[1, c]
        ax.fill_between(t, m - 2 * se, m + 2 * se, color="0.7", label="MC mean ± 2 SE")
        ax.plot(t, m, "k-", lw=1.6, label="MC mean")
        ax2.fill_between(t, -2 * se, 2 * se, color="0.7")
        for i, k in enumerate(show):
            x0 = ds.opa_x_mean.values[q, s, HEADLINE, k, :n]
            ax.plot(t, x0, lw=0.9, ls=("-", "--", ":", "-.")[i % 4], label=f"OPA N = {orders[k]}")
            ax2.plot(t, x0 - m, lw=0.9, ls=("-", "--", ":", "-.")[i % 4])
        ax.set_title(f"σ = {float(ds.sigma[s]):g}")
        ax2.set_xlabel("t [forcing periods]")
        ax2.set_yscale("symlog", linthresh=max(1e-8, float(np.nanmax(2 * se))))
    axes[0, 0].set_ylabel("E[x]")
    axes[1, 0].set_ylabel("x_0 − E_MC[x]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"{_par(ds)} = {_g(float(_vals(ds)[q]))}, {ds.variant.values[HEADLINE]}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def plot_variance(ds, path, q=0):
    plt = _pyplot()
    picks = _pick_sigmas(ds, q)
    n = int(round(float(ds.horizon[0]) * ds.attrs["per_period"])) + 1
    t = ds.periods.values[:n]
    fig, axes = plt.subplots(1, len(picks), figsize=(6 * len(picks), 3.8), squeeze=False)
    for c, s in enumerate(picks):
        ax = axes[0, c]
        var = ds.mc_x_var.values[q, s, :n]
        se = ds.mc_x_var_sem.values[q, s, :n]
        ax.fill_between(t, np.maximum(var - 2 * se, 1e-16), var + 2 * se, color="0.75")
        ax.semilogy(t, np.maximum(var, 1e-16), "k-", lw=1.6, label="MC Var[x] ± 2 SE")
        for j, v in enumerate(_laws(ds)):
            ax.semilogy(t, np.maximum(ds.opa_x_var.values[q, s, v, -1, :n], 1e-16),
                        ("-", "--", ":")[j], lw=1.2, label=f"OPA {ds.variant.values[v]}, N = "
                        f"{int(ds.N.max())}")
        positive = var[1:][var[1:] > 0]
        if len(positive):
            ax.set_ylim(bottom=0.1 * float(positive.min()))
        ax.set_title(f"σ = {float(ds.sigma[s]):g}")
        ax.set_xlabel("t [forcing periods]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Variance, {_par(ds)} = {_g(float(_vals(ds)[q]))}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def plot_phase(ds, path):
    """Dense-output phase portraits: OPA (both laws) against the MC mean and samples."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
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
    ax.legend(fontsize=7)
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
                 f"({ds.sizes['phase_time']} dense outputs)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


# -- the cost-accuracy frontier -------------------------------------------------------------
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
    out.attrs.setdefault("omega", ds.attrs["omega"])
    return out


def frontier_lines(ds) -> list[str]:
    from compare._convergence import summary_lines

    conv = frontier_dataset(ds)
    if conv is None:
        return []
    head = (f"Cost against accuracy at {_par(ds)} = {_g(conv.attrs['value'])}, σ = "
            f"{_g(conv.attrs['sigma'])}, over {conv.attrs['periods']:g} periods (RMS error of "
            f"E[x] against {conv.attrs['reference_samples']} Sobol samples):")
    return [head] + summary_lines(conv)


# -- summary.md -----------------------------------------------------------------------------
def write_report(ds: xr.Dataset, outdir: str, *, plots: bool = True,
                 command: str = "opa-mc validate") -> list[str]:
    """Write summary.md and the figures; returns the written paths."""
    os.makedirs(outdir, exist_ok=True)
    paths = []
    if plots:
        paths += plot_map(ds, os.path.join(outdir, "trust_map.png"))
        paths += plot_error_vs_order(ds, os.path.join(outdir, "error_vs_N.png"))
        paths += plot_mean(ds, os.path.join(outdir, "mean_vs_mc.png"))
        paths += plot_variance(ds, os.path.join(outdir, "variance.png"))
        paths += plot_phase(ds, os.path.join(outdir, "phase.png"))
        conv = frontier_dataset(ds)
        if conv is not None:
            from compare._convergence import plot as plot_frontier

            paths.append(plot_frontier(conv, os.path.join(outdir, "frontier.png")))
    a = ds.attrs
    md = os.path.join(outdir, "summary.md")
    lines = [
        "# opa-mc validate: where OPA agrees with Monte Carlo", "",
        f"Command: `{command}` ({a['wall_seconds']:.0f} s; computed: "
        f"{a['mc_runs_computed']} Monte Carlo runs, {a['opa_runs_computed']} OPA runs, "
        f"{a['parts_computed']} parts in all (splits and the frontier included); the rest "
        f"reused from parts/).", "",
        f"Model: preset {a['preset']} (mu = {a['mu']:g}, a = {a['a']:g}, c = {a['c']:g}, "
        f"f = {a['f']:g}, eta = {a['eta']:g}, delta = {a['delta']:g}, F0 = {a['F0']:g}, "
        f"{a['impulse']} impulses), {a['parameter']} swept over "
        f"{', '.join(_g(float(v)) for v in _vals(ds).values)}, uncertain {a['uncertain']} "
        f"= {_g(nominal(ds))} + σ ξ, ξ ~ {a.get('distribution', 'semicircle')}, σ in "
        f"{', '.join(_g(float(s)) for s in ds.sigma.values)}; "
        f"N = {int(ds.N.min())}..{int(ds.N.max())}; rtol = {a['rtol']:g}, atol = "
        f"{a['atol']:g}; Monte "
        f"Carlo: scrambled Sobol, {a['samples']} samples, doubled up to {a['max_samples']} "
        f"where the verdict hangs on the MC noise, seed {a['seed']}.", "",
        f"Criterion: {a['criterion_text']}; tol = {a['tolerance']:g} (mean), "
        f"{a['var_tolerance']:g} (variance), z = {a['z']:g}.", "",
    ]
    if a.get("variants_dropped", "none") != "none":
        lines += [f"Variants left out: {a['variants_dropped']}.", ""]
    if _element_variants(ds):
        lines += [f"Multi-element variants ({a.get('elements')} elements"
                  + (f", budget {a['max_elements']}" if "max_elements" in a else "")
                  + f"): {a.get('element_text', '')}.", ""]
    lines += [
        "## Trust boundary", "", boundary_table(ds, markdown=True), "",
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
    if plots:
        lines += ["## Figures", ""] + [f"![{os.path.basename(p)}]({os.path.basename(p)})"
                                       for p in paths] + [""]
    with open(md, "w") as fh:
        fh.write("\n".join(lines))
    return [md] + paths


__all__ = ["boundary_table", "cause", "complete_within", "count_table", "findings",
           "frontier_dataset", "frontier_lines", "nearest_crossing", "nearest_split",
           "star_text", "verdict_grid", "write_report"]
