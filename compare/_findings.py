"""The report's plain-language text, each sentence computed from the trust-map dataset:
why sigma* is where it is (:func:`cause`, in a few words :func:`short_cause`), the first
screen, the runs that did not finish, the findings and the frontier's lines.

Nothing is assumed about the model: every number is read off the dataset that
:func:`compare.run_validation` wrote (:mod:`compare._mapread`).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from compare._mapread import (
    HEADLINE, _e, _element_variants, _g, _kinds, _laws, _par, _single_of, _star, _time, _unc,
    _vals, _window_sem, check_map, complete_within, frontier_dataset, nearest_horizon,
    nearest_split, nominal, star_phrase, star_text,
)


# -- why sigma* is where it is --------------------------------------------------------------
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


# -- the first screen -----------------------------------------------------------------------
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


# -- findings -------------------------------------------------------------------------------
def findings(ds: xr.Dataset) -> list[str]:
    """Plain-language conclusions, each computed from the dataset: sigma* per horizon
    (:func:`_boundary_findings`), how the error grows across it (:func:`_growth_findings`),
    whether N changes the verdict (:func:`_order_findings`), the error before OPA's first
    impact (:func:`_before_impact_findings`), the impact laws and truncations against each
    other (:func:`_law_findings`), the variance (:func:`_variance_findings`) and OPA at
    sigma = 0 against the DMR (:func:`_dmr_findings`)."""
    check_map(ds, "findings")
    out = []
    for h in range(len(ds.horizon)):
        out += _boundary_findings(ds, h)
    for part in (_growth_findings, _order_findings, _before_impact_findings, _law_findings,
                 _variance_findings, _dmr_findings):
        out += part(ds)
    return out


def _names(ds):
    """The swept parameter's symbol, the orders N, the largest N, the sigma grid and the
    variants' names."""
    orders = [int(n) for n in ds.N.values]
    return _par(ds), orders, orders[-1], ds.sigma.values, [str(v) for v in ds.variant.values]


def _boundary_findings(ds, h: int) -> list[str]:
    """sigma* of the headline variant over horizon h at every swept value, that of each
    multi-element variant beside the single element's, and the values where the boundary
    coincides with the first split."""
    par, _, nmax, sig, variants = _names(ds)
    out = []
    H = ds.horizon.values[h]
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
    return out


def _growth_findings(ds) -> list[str]:
    """How the error grows below sigma* and across it (first value, first horizon)."""
    par, _, nmax, sig, variants = _names(ds)
    out = []
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
    return out


def _order_findings(ds) -> list[str]:
    """Whether N matters for the verdict, per horizon."""
    _, orders, nmax, _, variants = _names(ds)
    out = []
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
    return out


def _before_impact_findings(ds) -> list[str]:
    """The error of x_0 before OPA's first impact (first value)."""
    par, _, nmax, sig, _ = _names(ds)
    out = []
    q = 0
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
    return out


def _law_findings(ds) -> list[str]:
    """The ensemble impact law against the mean law, and the paper's truncation against
    the Galerkin projection."""
    _, _, nmax, _, variants = _names(ds)
    out = []
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
    return out


def _variance_findings(ds) -> list[str]:
    """Where the variance agrees, per impact law drawn."""
    _, _, nmax, _, variants = _names(ds)
    out = []
    for v in _laws(ds):
        frac = ds.agrees.values[:, :, v, -1, :, 1].mean(axis=(0, 1))
        out.append(f"The variance ({variants[v]}, N = {nmax}) agrees within "
                   f"{ds.attrs['var_tolerance']:g} of the MC variance at "
                   + ", ".join(f"{100 * f:.0f}% of the grid over {float(H):g} periods"
                               for f, H in zip(frac, ds.horizon.values)) + ".")
    return out


def _dmr_findings(ds) -> list[str]:
    """OPA with sigma = 0 against the DMR."""
    nmax = int(ds.N.values[-1])
    out = []
    d = ds.emr0_dmr_difference.values
    out.append(f"With σ = 0, OPA at N = {nmax} and the DMR differ by at most "
               + ", ".join(f"{_e(x)} over {float(H):g} periods"
                           for x, H in zip(d, ds.horizon.values))
               + f" (round-off amplified by the flow); at N = 0 by "
               f"{float(ds.emr0_n0_dmr_difference):.1e}.")
    return out


# -- the frontier ---------------------------------------------------------------------------
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


__all__ = ["SCREEN_WIDTH", "best_variant", "bullet", "cause", "findings", "first_screen",
           "frontier_lines", "run_failures", "short_cause"]
