"""Figures for single runs: time history and phase portrait with section points."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402


def _state(ds: xr.Dataset) -> tuple[np.ndarray, np.ndarray, str]:
    if "x" in ds:
        return ds.x.values, ds.v.values, "DMR"
    if "x_coef" in ds:
        return ds.x_coef.values[0], ds.v_coef.values[0], f"EMR (OPA N={ds.attrs['N']})"
    return ds.x_mean.values, ds.v_mean.values, f"MC mean ({ds.sizes['sample']} samples)"


def plot_run(ds: xr.Dataset, path: str, *, per_period: int | None = None) -> None:
    """Time history and phase portrait of a dmr/opa/mc dataset; stroboscopic points marked.

    ``per_period`` (outputs per forcing period) locates the stroboscopic samples; it is
    inferred from the time grid when omitted.
    """
    x, v, label = _state(ds)
    t = ds.time.values
    T = 2 * np.pi / ds.attrs["omega"]
    if per_period is None:
        per_period = max(1, int(round(T / (t[1] - t[0])))) if len(t) > 1 else 1
    fig, (ax_t, ax_p) = plt.subplots(1, 2, figsize=(11, 4.2))
    dense = per_period >= 8  # lines between outputs only when they resolve the motion
    style = dict(lw=0.8) if dense else dict(ls="none", marker=".", ms=3)
    ax_t.plot(t, x, label=label, **style)
    if "x_var" in ds and label != "DMR":
        sd = np.sqrt(np.maximum(ds.x_var.values, 0.0))
        ax_t.fill_between(t, x - sd, x + sd, alpha=0.25, label="± 1 std")
    ax_t.axhline(ds.attrs["delta"], color="k", lw=1, ls="--", label="wall x = Δ")
    ax_t.set_xlabel("t")
    ax_t.set_ylabel("x")
    ax_t.legend(loc="lower left", fontsize=8)
    ax_t.set_title("time history")
    half = len(t) // 2
    if dense:
        ax_p.plot(x[half:], v[half:], lw=0.6, label="trajectory (second half)")
    strobe = slice(half - half % per_period, None, per_period)
    ax_p.plot(x[strobe], v[strobe], "rs", ms=4, label="t = k 2π/ω")
    ax_p.axvline(ds.attrs["delta"], color="k", lw=1, ls="--")
    ax_p.set_xlabel("x")
    ax_p.set_ylabel("dx/dt")
    ax_p.legend(loc="lower left", fontsize=8)
    ax_p.set_title("phase portrait")
    fig.suptitle(
        f"{label}: ω = {ds.attrs['omega']:g}, c = {ds.attrs['c']:g}, σ = {ds.attrs['sigma']:g}, "
        f"F0 = {ds.attrs['F0']:g}, impulse = {ds.attrs['impulse']}"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
