"""The figure of certified Sobol indices (``compare.certify_sobol``).

One column per parameter, two rows: the first-order index over time above, the total
below, of one state (x by default). The OPA surrogate's exact indices are a line; the
certified intervals of the true systems are a band with error bars at each output. An
index within the noise is drawn as its interval ``[0, upper]`` (a bar from 0, a hollow
marker at 0), never as a negative number; an undefined one (an output without variance,
the deterministic start) is left out.

matplotlib is imported when a figure is drawn (``opa.plots`` imports this module).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

#: the reading codes of the dataset (``compare._sobol.READINGS``): resolved, within noise
RESOLVED_CODE, NOISE_CODE = 0, 1
_KINDS = (("first", "first-order $S_i$"), ("total", "total $S_{T,i}$"))


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def draw_sensitivity(ds: xr.Dataset, state: str = "x"):
    """The figure of ``ds`` (a ``compare.certify_sobol`` dataset) for ``state`` (x or v).

    Each panel: the line ``surrogate`` (the OPA surrogate's index), the error bars
    ``certified`` (the estimate where resolved, bars to the interval) and ``within noise``
    (hollow markers at 0, bars to the upper end), and the band ``certified interval``.
    Returns the matplotlib figure.
    """
    plt = _pyplot()
    if state not in ("x", "v"):
        raise ValueError(f"state must be x or v, got {state!r:.20}")
    names = [str(p) for p in ds.parameter.values]
    t = ds.time.values / float(ds.time.attrs.get("forcing_period", 1.0))
    fig, axes = plt.subplots(2, len(names), figsize=(4.2 * len(names), 6.4), sharex=True,
                             squeeze=False)
    for row, (kind, label) in enumerate(_KINDS):
        name = f"{state}_sobol_{kind}"
        for col, parameter in enumerate(names):
            ax = axes[row, col]
            pick = dict(parameter=parameter)
            code = ds[f"{name}_reading"].sel(pick).values
            low = ds[f"{name}_lower"].sel(pick).values
            high = ds[f"{name}_upper"].sel(pick).values
            shown = (code == RESOLVED_CODE) | (code == NOISE_CODE)
            ax.fill_between(t, np.where(shown, low, np.nan), np.where(shown, high, np.nan),
                            color="tab:orange", alpha=0.25, linewidth=0,
                            label="certified interval")
            ax.plot(t, ds[f"{name}_surrogate"].sel(pick).values, color="tab:blue", lw=1.4,
                    label="surrogate")
            ok = code == RESOLVED_CODE
            mid = ds[name].sel(pick).values
            ax.errorbar(t[ok], mid[ok], yerr=[mid[ok] - low[ok], high[ok] - mid[ok]],
                        fmt="o", ms=3, color="tab:orange", ecolor="tab:orange",
                        capsize=2, lw=1, label="certified")
            noise = code == NOISE_CODE
            ax.errorbar(t[noise], np.zeros(noise.sum()), yerr=[np.zeros(noise.sum()),
                                                                 high[noise]],
                        fmt="o", ms=4, mfc="none", color="tab:grey", ecolor="tab:grey",
                        capsize=2, lw=1, label="within noise")
            ax.set_ylim(-0.05, 1.05)
            ax.grid(alpha=0.3)
            if row == 0:
                ax.set_title(f"{parameter}")
            if col == 0:
                ax.set_ylabel(f"{label} of {state}")
            if row == 1:
                ax.set_xlabel("t / forcing period")
    axes[0, 0].legend(fontsize=8, loc="best")
    fig.suptitle(f"Sobol indices of {state}: OPA surrogate and the true systems certified "
                 f"({ds.attrs.get('samples', '?')} pick-freeze samples)", fontsize=10)
    fig.tight_layout()
    return fig


def plot_sensitivity(ds: xr.Dataset, path: str, state: str = "x") -> None:
    """Write the figure of :func:`draw_sensitivity` to ``path``."""
    fig = draw_sensitivity(ds, state)
    plt = _pyplot()
    try:
        fig.savefig(path, dpi=120)
    finally:
        plt.close(fig)
