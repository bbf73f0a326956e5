"""Tables, figures and the Markdown summary of a validation dataset."""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402


def _fmt(x: float) -> str:
    if not np.isfinite(x):
        return "∞" if x > 0 else "–"
    return f"{x:.2e}"


def error_table(ds: xr.Dataset, *, markdown: bool = False) -> str:
    """One row per (sigma, N): RMS error of the mean over the window for each OPA
    variant, the MC standard error (the noise floor), the variance error and the time
    (in forcing periods) the OPA mean stays inside the 3-SE band."""
    variants = [str(v) for v in ds.variant.values]
    w = ds.attrs.get("window_periods", np.nan)
    head = (["σ", "N", "before 1st impact"] + [f"RMS err {v}" for v in variants]
            + ["MC SE (RMS)", "var err mean/galerkin", "in 3-SE band until [periods]"])
    rows = []
    sem = np.sqrt(np.nanmean(_window(ds, ds.mc_x_sem) ** 2, axis=-1))
    for s, sigma in enumerate(ds.sigma.values):
        for k, n in enumerate(ds.N.values):
            row = [f"{sigma:g}", f"{int(n)}", _fmt(float(ds.rms_error_pre[s, 0, k]))]
            row += [_fmt(float(ds.rms_error_window[s, v, k])) for v in range(len(variants))]
            row += [_fmt(float(sem[s])), _fmt(float(ds.var_rms_error_window[s, 0, k])),
                    f"{float(ds.agree_periods_window[s, 0, k]):.2f}"]
            rows.append(row)
    title = (f"RMS error of the OPA mean x_0 against the Monte Carlo mean: before the first "
             f"impact (mean/galerkin), and over the first {w:g} forcing periods per variant")
    if markdown:
        lines = [f"**{title}**", "", "| " + " | ".join(head) + " |",
                 "|" + "---|" * len(head)]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
        return "\n".join(lines)
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    out = [title, "  ".join(h.rjust(wd) for h, wd in zip(head, widths))]
    out += ["  ".join(c.rjust(wd) for c, wd in zip(r, widths)) for r in rows]
    return "\n".join(out)


def _window(ds, da):
    T = 2 * np.pi / ds.attrs["omega"]
    n = int(np.searchsorted(ds.time.values, ds.attrs["window_periods"] * T + 1e-9))
    return da.values[..., :n]


def cost_table(ds: xr.Dataset, *, markdown: bool = True) -> str:
    """Cost beside accuracy at the study sigma: OPA (both laws), collocation, MC, QMC."""
    s = int(np.argmin(np.abs(ds.sigma.values - ds.attrs.get("study_sigma", ds.sigma[0]))))
    rows = []
    for v, name in enumerate(ds.variant.values[:2]):
        for k, n in enumerate(ds.N.values):
            if int(n) in (0, 1, 2, 4, 8) or k == len(ds.N) - 1:
                rows.append([f"OPA {name}", f"N = {int(n)}",
                             _fmt(float(ds.rms_error_window[s, v, k])),
                             f"{float(ds.opa_seconds[s, v, k]):.3f}",
                             f"{int(ds.opa_rhs_evaluations[s, v, k]):,}"])
    for q, err, sec, rhs in zip(ds.Q.values, ds.study_gauss_error.values,
                                ds.study_gauss_seconds.values, ds.study_gauss_rhs.values):
        rows.append(["collocation", f"Q = {int(q)}", _fmt(float(err)), f"{sec:.3f}",
                     f"{int(rhs):,}"])
    for i, sampler in enumerate(ds.sampler.values):
        label = "MC" if sampler == "random" else "QMC (Sobol)"
        for j, m in enumerate(ds.M.values):
            rows.append([label, f"M = {int(m)}", _fmt(float(ds.study_mc_error[i, j])),
                         f"{float(ds.study_mc_seconds[i, j]):.3f}",
                         f"{int(ds.study_mc_rhs[i, j]):,}"])
    head = ["method", "size", "RMS error (window)", "wall [s]", "RHS evaluations"]
    note = (f"Reference: the main MC run ({ds.attrs.get('samples')} {ds.attrs.get('sampler')} "
            f"samples), its RMS standard error {float(ds.study_reference_sem):.1e}; "
            f"σ = {float(ds.sigma[s]):g}. OPA wall times are full-length runs "
            f"({ds.attrs.get('periods'):g} periods); the others cover the window only.")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return note + "\n\n" + "\n".join(lines)


def findings(ds: xr.Dataset) -> list[str]:
    """Plain-language conclusions read off the dataset (nothing assumed)."""
    out = []
    variants = [str(v) for v in ds.variant.values]
    T = 2 * np.pi / ds.attrs["omega"]
    sem = np.sqrt(np.nanmean(_window(ds, ds.mc_x_sem) ** 2, axis=-1))
    orders = [int(n) for n in ds.N.values]
    for s, sigma in enumerate(ds.sigma.values):
        pre = ds.rms_error_pre.values[s, 0]
        t1 = float(np.nanmin(ds.first_impact_time.values[s])) / T
        floor_n = [n for n, e in zip(orders, pre) if e <= 2 * sem[s]]
        text = (f"σ = {sigma:g}: before the first impact (t < {t1:.2f} periods) the OPA mean "
                f"error falls from {pre[0]:.1e} (N = {orders[0]}) to {np.nanmin(pre):.1e} "
                f"(N = {orders[int(np.nanargmin(pre))]})")
        text += (f" and is within 2 MC standard errors ({sem[s]:.1e}) from N = {floor_n[0]}"
                 if floor_n else f", above the MC noise floor {sem[s]:.1e}")
        win = ds.rms_error_window.values[s]
        text += (f". Over the first {ds.attrs['window_periods']:g} periods, which include "
                 f"impacts, the error stays at {win[0, -1]:.1e} (mean law) / {win[1, -1]:.1e} "
                 f"(ensemble law) at N = {orders[-1]}, whatever N: the floor is set at the "
                 f"impacts by the impact law, not by the truncation.")
        best_v, best_k = np.unravel_index(np.nanargmin(win), win.shape)
        text += f" Best variant: {variants[best_v]}, N = {orders[best_k]}."
        out.append(text)
    if len(ds.sigma) > 1:
        sig = ds.sigma.values
        win = ds.rms_error_window.values[:, 0, -1]
        slope = np.polyfit(np.log(sig), np.log(win), 1)[0]
        out.append(f"The post-impact error grows like σ^{slope:.2f} (mean law, N = "
                   f"{orders[-1]}, fitted over σ = {', '.join(f'{x:g}' for x in sig)}).")
    return out


def write_report(ds: xr.Dataset, outdir: str, *, plots: bool = True) -> list[str]:
    """Write summary.md and the figures; returns the written paths."""
    os.makedirs(outdir, exist_ok=True)
    paths = []
    if plots:
        paths += plot_error_vs_order(ds, os.path.join(outdir, "error_vs_N.png"))
        paths += plot_mean_band(ds, os.path.join(outdir, "mean_vs_mc.png"))
        paths += plot_variance(ds, os.path.join(outdir, "variance.png"))
        paths += plot_phase(ds, os.path.join(outdir, "phase.png"))
        paths += plot_cost(ds, os.path.join(outdir, "cost.png"))
    md = os.path.join(outdir, "summary.md")
    a = ds.attrs
    with open(md, "w") as fh:
        fh.write("# opa-mc validate\n\n")
        fh.write(
            f"Model: mu = {a['mu']:g}, a = {a['a']:g}, c = {a['c']:g}, f = {a['f']:g}, "
            f"omega = {a['omega']:g}, eta = {a['eta']:g}, delta = {a['delta']:g}, "
            f"F0 = {a['F0']:g} ({a['impulse']} impulses), uncertain {a['uncertain']}; "
            f"{a['periods']:g} periods, {a['per_period']} outputs per period, "
            f"rtol = {a['rtol']:g}; MC: {a['samples']} {a['sampler']} samples, seed {a['seed']}."
            "\n\n"
        )
        fh.write("## Findings\n\n" + "\n".join(f"- {f}" for f in findings(ds)) + "\n\n")
        fh.write(error_table(ds, markdown=True) + "\n\n")
        fh.write("## Cost and accuracy\n\n" + cost_table(ds) + "\n\n")
        if plots:
            fh.write("## Figures\n\n" + "\n".join(
                f"![{os.path.basename(p)}]({os.path.basename(p)})" for p in paths) + "\n")
    return [md] + paths


def plot_error_vs_order(ds, path):
    fig, axes = plt.subplots(1, len(ds.sigma), figsize=(4.2 * len(ds.sigma), 3.8),
                             squeeze=False, sharey=True)
    sem = np.sqrt(np.nanmean(_window(ds, ds.mc_x_sem) ** 2, axis=-1))
    for s, ax in enumerate(axes[0]):
        for v, name in enumerate(ds.variant.values):
            ax.semilogy(ds.N, ds.rms_error_window[s, v], "o-", label=f"OPA {name}")
        ax.axhline(sem[s], color="k", ls="--", label="MC noise floor (RMS SE)")
        ax.set_title(f"σ = {float(ds.sigma[s]):g}")
        ax.set_xlabel("N")
        ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].set_ylabel(f"RMS |x_0 - E_MC[x]|, first {ds.attrs['window_periods']:g} periods")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def plot_mean_band(ds, path):
    T = 2 * np.pi / ds.attrs["omega"]
    n = int(np.searchsorted(ds.time.values, 2 * ds.attrs["window_periods"] * T + 1e-9))
    t = ds.time.values[:n] / T
    fig, axes = plt.subplots(2, len(ds.sigma), figsize=(4.6 * len(ds.sigma), 6.5),
                             squeeze=False, sharex=True)
    for s in range(len(ds.sigma)):
        mean = ds.mc_x_mean.values[s, :n]
        se = ds.mc_x_sem.values[s, :n]
        ax = axes[0, s]
        ax.fill_between(t, mean - 2 * se, mean + 2 * se, color="0.6", alpha=0.6,
                        label="MC mean ± 2 SE")
        ax.plot(t, mean, "k", lw=0.8)
        ax.plot(t, ds.opa_x_mean.values[s, 0, -1, :n], "C0--", lw=1,
                label=f"OPA x_0, N = {int(ds.N[-1])}, mean law")
        ax.set_title(f"σ = {float(ds.sigma[s]):g}")
        ax.axhline(ds.attrs["delta"], color="r", lw=0.6)
        ax = axes[1, s]
        for v, name in enumerate(ds.variant.values[:2]):
            ax.semilogy(t, np.abs(ds.opa_x_mean.values[s, v, -1, :n] - mean) + 1e-16,
                        lw=0.8, label=f"|error| OPA {name}")
        ax.semilogy(t, 2 * se + 1e-16, "k--", lw=0.8, label="2 SE")
        ax.set_xlabel("t / (2π/ω)")
    axes[0, 0].set_ylabel("E[x]")
    axes[1, 0].set_ylabel("|x_0 - E_MC[x]|")
    axes[0, 0].legend(fontsize=7, loc="lower left")
    axes[1, 0].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def plot_variance(ds, path):
    T = 2 * np.pi / ds.attrs["omega"]
    n = int(np.searchsorted(ds.time.values, 2 * ds.attrs["window_periods"] * T + 1e-9))
    t = ds.time.values[:n] / T
    fig, axes = plt.subplots(1, len(ds.sigma), figsize=(4.4 * len(ds.sigma), 3.6),
                             squeeze=False)
    for s, ax in enumerate(axes[0]):
        ax.semilogy(t, ds.mc_x_var.values[s, :n] + 1e-20, "k", lw=1.2, label="MC variance")
        for v, name in enumerate(ds.variant.values[:2]):
            ax.semilogy(t, ds.opa_x_var.values[s, v, -1, :n] + 1e-20, "--", lw=1,
                        label=f"OPA {name}, N = {int(ds.N[-1])}")
        ax.set_title(f"σ = {float(ds.sigma[s]):g}")
        ax.set_xlabel("t / (2π/ω)")
    axes[0, 0].set_ylabel("Var[x]")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def plot_phase(ds, path):
    T = 2 * np.pi / ds.attrs["omega"]
    n = int(np.searchsorted(ds.time.values, 2 * ds.attrs["window_periods"] * T + 1e-9))
    fig, axes = plt.subplots(1, len(ds.sigma), figsize=(4.4 * len(ds.sigma), 4),
                             squeeze=False, sharey=True)
    for s, ax in enumerate(axes[0]):
        ax.plot(ds.mc_x_mean.values[s, :n], ds.mc_v_mean.values[s, :n], "k", lw=0.8,
                label="MC mean")
        ax.plot(ds.opa_x_mean.values[s, 0, -1, :n], ds.opa_v_mean.values[s, 0, :n], "C0--",
                lw=0.8, label=f"EMR (OPA N = {int(ds.N[-1])})")
        ax.axvline(ds.attrs["delta"], color="r", lw=0.6)
        ax.set_title(f"σ = {float(ds.sigma[s]):g}, first {2 * ds.attrs['window_periods']:g} "
                     "periods")
        ax.set_xlabel("E[x]")
    axes[0, 0].set_ylabel("E[x']")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]


def plot_cost(ds, path):
    s = int(np.argmin(np.abs(ds.sigma.values - ds.attrs.get("study_sigma", ds.sigma[0]))))
    fig, (ax_m, ax_c) = plt.subplots(1, 2, figsize=(10, 4))
    for i, sampler in enumerate(ds.sampler.values):
        ax_m.loglog(ds.M, ds.study_mc_error[i], "o-", label="MC" if sampler == "random"
                    else "QMC (Sobol)")
    M = ds.M.values.astype(float)
    e0 = float(ds.study_mc_error[0, 0])
    ax_m.loglog(M, e0 * (M / M[0]) ** -0.5, "k:", label="M^-1/2")
    ax_m.loglog(ds.Q, ds.study_gauss_error, "s-", label="Gauss collocation (M = Q)")
    ax_m.axhline(float(ds.study_reference_sem), color="0.5", ls="--",
                 label="reference SE")
    ax_m.set_xlabel("samples M (or nodes Q)")
    ax_m.set_ylabel("RMS error of E[x] over the window")
    ax_m.legend(fontsize=8)
    ax_m.grid(True, which="both", alpha=0.3)
    for v, name in enumerate(ds.variant.values[:2]):
        ax_c.loglog(ds.opa_rhs_evaluations[s, v], ds.rms_error_window[s, v], "o-",
                    label=f"OPA {name} (N = 0..{int(ds.N[-1])})")
    ax_c.loglog(ds.study_gauss_rhs, ds.study_gauss_error, "s-", label="collocation")
    for i, sampler in enumerate(ds.sampler.values):
        ax_c.loglog(ds.study_mc_rhs[i], ds.study_mc_error[i], "^-",
                    label="MC" if sampler == "random" else "QMC")
    ax_c.set_xlabel("right-hand-side evaluations")
    ax_c.set_ylabel("RMS error")
    ax_c.legend(fontsize=8)
    ax_c.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"cost and accuracy, σ = {float(ds.sigma[s]):g}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]
