"""The report's tables, read off the trust-map dataset: the trust boundary (sigma* per
swept value and horizon beside the first split of the impact sequence), the verdict grids
and the impact counts; plain text or markdown."""

from __future__ import annotations

import numpy as np
import xarray as xr

from compare._findings import bullet
from compare._mapread import (
    HEADLINE, _g, _par, _star, _unc, _vals, check_map, complete_within, nearest_split,
    nominal,
)


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


__all__ = ["boundary_table", "count_table", "verdict_grid"]
