"""Every ``opa-mc`` subcommand on its happy path, run in process (``opa.cli.main``) at tiny
sizes: exit status 0, and what it wrote (netCDF, figure, text) checked against something
that shares no code with it: the scipy integrator of ``tests/reference.py`` (one
trajectory, or Gauss collocation over the semicircle law with ``tests/truths.py``'s rule),
the closed forms of ``tests/truths.py`` (the linear impact orbit, the impulse sizes), and
the parameter sets of the paper's section 3.2 and 3.3 written out here.

The subcommands are read from ``opa.cli._main.build_parser()``: each subcommand, and for
those whose positional ``model`` chooses the system (dmr, opa, mc), each model. A test
named ``test_<command>_<model>_...`` (or ``test_<command>_...``) covers it;
``test_every_subcommand_has_a_happy_path_test`` fails when one has none.
"""

from __future__ import annotations

import argparse
import math
import os

os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402
import xarray as xr  # noqa: E402

from opa.cli._main import build_parser, main  # noqa: E402
from tests.reference import reference_trajectory  # noqa: E402
from tests.truths import (  # noqa: E402
    impulse_size,
    linear_flow,
    linear_impact_orbit,
    semicircle_gauss_rule,
)

#: the paper's section 3.2 set, the CLI's defaults (README, "What is in the box")
SECTION_32 = dict(mu=0.8, a=0.5, c=0.05, f=1.5, omega=3.98, eta=0.8, delta=0.0, F0=0.1,
                  a1=1.0, omega1=1.0, n=2.0, x0=-1.0, v0=0.0)
#: section 3.3 without impulses: 1/1 at omega = 4.8, 2/2 at omega = 5.1
SECTION_33_NO_IMPULSES = {**SECTION_32, "a": 3.5, "f": 3.5, "F0": 0.0}
SWEEP_33 = ["--preset", "3.3", "--F0", "0", "--sweep", "omega=4.8,5.1", "--transient", "200",
            "--record", "40", "--workers", "1"]
#: the linear impact oscillator whose period-1 orbit is known in closed form
LINEAR = dict(a=1.0, f=1.0, omega=1.6, eta=0.8, delta=0.1)
LINEAR_FLAGS = ["--mu", "0", "--c", "0", "--a", "1", "--f", "1", "--omega", "1.6", "--eta",
                "0.8", "--delta", "0.1", "--F0", "0", "--x0", "-0.5"]


def commands() -> list[str]:
    """``opa-mc``'s subcommands, with each model of those that take one."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    found = []
    for name, command in sub.choices.items():
        model = next((a for a in command._actions if a.dest == "model"), None)
        found += [f"{name} {m}" for m in model.choices] if model else [name]
    return found


def assert_same_multipliers(got, expected, atol):
    """The same complex numbers, whatever their order (each matched once)."""
    left = list(np.asarray(expected, dtype=complex))
    assert len(got) == len(left)
    for mu in np.asarray(got, dtype=complex):
        k = int(np.argmin(np.abs(np.array(left) - mu)))
        assert abs(left[k] - mu) <= atol, (got, expected)
        left.pop(k)


def run(argv) -> None:
    assert main([str(a) for a in argv]) == 0, argv


def load(path) -> xr.Dataset:
    with xr.open_dataset(path) as ds:
        return ds.load()


def strobe_times(omega, periods, per_period):
    """t_j = j (2 pi / omega) / K, j = 0 .. P K (written out, not opa.time_grid)."""
    return np.arange(periods * per_period + 1) * (2 * math.pi / omega / per_period)


def collocation(model, sigma, times, nodes=12, tol=1e-12):
    """E[x], Var[x] over mu = mu_bar + sigma xi, xi semicircle: Gauss collocation of the
    scipy reference (exact to round-off for a response smooth in xi)."""
    xi, w = semicircle_gauss_rule(nodes)
    paths = np.array([reference_trajectory(**{**model, "mu": model["mu"] + sigma * x},
                                           t_out=times, rtol=tol, atol=tol)["x"] for x in xi])
    mean = w @ paths
    return mean, w @ paths**2 - mean**2


@pytest.fixture
def kept_figures(monkeypatch):
    """Figures that plt.close would have closed, to inspect what was drawn."""
    kept = []
    monkeypatch.setattr(plt, "close", kept.append)
    yield kept
    monkeypatch.undo()  # pyplot's own close, before closing
    for fig in kept:
        plt.close(fig)


@pytest.fixture(scope="module")
def sections_33():
    """The scipy reference's stroboscopic and impact sections of SECTION_33_NO_IMPULSES
    after 200 periods (a sweep records t = (200 + k) T, k = 1..40)."""
    out = {}
    for omega in (4.8, 5.1):
        T = 2 * math.pi / omega
        t = np.concatenate([[0.0], (201 + np.arange(40)) * T])
        ref = reference_trajectory(**{**SECTION_33_NO_IMPULSES, "omega": omega}, t_out=t,
                                   rtol=1e-10, atol=1e-10)
        after = ref["impact_time"] > 200 * T
        out[omega] = dict(x=ref["x"][1:], v=ref["v"][1:],
                          phase=np.mod(omega * ref["impact_time"][after], 2 * math.pi),
                          speed=ref["impact_velocity"][after])
    return out


# --------------------------------------------------------------------------- the list


def test_help_lists_every_subcommand(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    text = capsys.readouterr().out
    names = {c.split()[0] for c in commands()}
    assert names >= {"simulate", "validate", "converge", "bifurcation", "reproduce",
                     "stability"}
    assert all(f"    {name}" in text for name in names), text


def test_every_subcommand_has_a_happy_path_test():
    tests = [name for name, f in globals().items() if name.startswith("test_") and callable(f)]
    missing = [c for c in commands()
               if not any(t.startswith(f"test_{c.replace(' ', '_')}_") for t in tests)]
    assert missing == [], f"add a test_<command>_<model>_... here for {missing}"


# --------------------------------------------------------------------------- simulate


def test_simulate_dmr_is_the_scipy_reference(tmp_path, kept_figures):
    out, png = tmp_path / "dmr.nc", tmp_path / "dmr.png"
    run(["simulate", "dmr", "--periods", 5, "--per-period", 8, "--rtol", 1e-12, "--atol",
         1e-12, "--out", out, "--plot", png, "--quiet"])
    ds = load(out)
    assert {k: ds.attrs[k] for k in SECTION_32} == SECTION_32
    t = strobe_times(3.98, 5, 8)
    np.testing.assert_allclose(ds.time, t, rtol=1e-15, atol=0)
    ref = reference_trajectory(**SECTION_32, t_out=t)  # the dirac impulse at t = 0 included
    np.testing.assert_allclose(ds.x, ref["x"], rtol=0, atol=1e-8)
    np.testing.assert_allclose(ds.v, ref["v"], rtol=0, atol=1e-8)
    assert ds.sizes["impact"] == len(ref["impact_time"]) >= 2
    np.testing.assert_allclose(ds.impact_time, ref["impact_time"], rtol=0, atol=1e-8)
    np.testing.assert_allclose(ds.impact_velocity, ref["impact_velocity"], rtol=0, atol=1e-8)
    # the figure: the time history is x(t) of the file, the wall at delta = 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    (fig,) = kept_figures
    history = fig.axes[0].get_lines()[0]
    # the time axis is in forcing periods
    np.testing.assert_allclose(history.get_xdata(), ds.time.values * 3.98 / (2 * np.pi),
                               rtol=1e-14, atol=0)
    np.testing.assert_array_equal(history.get_ydata(), ds.x.values)


def test_simulate_opa_with_sigma_0_is_the_dmr_run(tmp_path):
    common = ["--periods", 5, "--per-period", 8, "--quiet"]
    run(["simulate", "dmr", *common, "--out", tmp_path / "dmr.nc"])
    run(["simulate", "opa", "--sigma", 0, "--order", 2, *common, "--out", tmp_path / "opa.nc"])
    dmr, emr = load(tmp_path / "dmr.nc"), load(tmp_path / "opa.nc")
    assert emr.attrs["sigma"] == 0.0 and emr.attrs["N"] == 2
    np.testing.assert_allclose(emr.x_mean, dmr.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(emr.v_mean, dmr.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(emr.x_var, 0.0, rtol=0, atol=1e-20)
    np.testing.assert_allclose(emr.impact_time, dmr.impact_time, rtol=0, atol=1e-12)


def test_simulate_opa_before_the_first_impact_is_the_collocation_of_the_reference(tmp_path):
    """sigma = 0.02 on mu over the first forcing period (no impact yet): the OPA mean and
    variance at N = 4 are those of the sampled systems to round-off (measured 5e-13)."""
    out = tmp_path / "opa.nc"
    run(["simulate", "opa", "--sigma", 0.02, "--order", 4, "--periods", 1, "--per-period", 8,
         "--rtol", 1e-12, "--atol", 1e-12, "--out", out, "--quiet"])
    ds = load(out)
    assert ds.sizes["impact"] == 0
    mean, var = collocation(SECTION_32, 0.02, strobe_times(3.98, 1, 8))
    np.testing.assert_allclose(ds.x_mean, mean, rtol=0, atol=1e-10)
    np.testing.assert_allclose(ds.x_var, var, rtol=0, atol=1e-12)


def test_simulate_mc_with_the_same_seed_writes_the_same_file(tmp_path):
    argv = ["simulate", "mc", "--sigma", 0.02, "--samples", 64, "--sampler", "random",
            "--periods", 5, "--per-period", 4, "--quiet"]
    run([*argv, "--seed", 3, "--out", tmp_path / "a.nc"])
    run([*argv, "--seed", 3, "--out", tmp_path / "b.nc"])
    run([*argv, "--seed", 4, "--out", tmp_path / "c.nc"])
    a, b, c = (load(tmp_path / f"{name}.nc") for name in "abc")
    assert not any(p.name.endswith(".parts") for p in tmp_path.iterdir())  # checkpoint gone
    # every variable and attribute but the history (a time stamp and the command line)
    for ds in (a, b, c):
        del ds.attrs["history"]
    xr.testing.assert_identical(a, b)
    assert a.sizes["sample"] == 64 and not np.array_equal(a.xi.values, c.xi.values)
    assert np.all(np.abs(a.xi.values) <= 1.0)
    # the history records the command main() ran, not the process's own argv
    history = load(tmp_path / "c.nc").attrs["history"]
    assert history.endswith(" ".join(["opa-mc", *map(str, argv), "--seed", "4", "--out",
                                      str(tmp_path / "c.nc")]))


def test_simulate_mc_gauss_is_the_collocation_of_the_reference(tmp_path):
    """8 Gauss nodes of the semicircle: the ensemble mean and variance are the weighted
    sampled systems, here integrated one by one by the scipy reference (impacts included)."""
    out = tmp_path / "mc.nc"
    run(["simulate", "mc", "--sigma", 0.02, "--samples", 8, "--sampler", "gauss", "--periods",
         5, "--per-period", 8, "--rtol", 1e-12, "--atol", 1e-12, "--out", out, "--quiet"])
    ds = load(out)
    xi, _ = semicircle_gauss_rule(8)
    np.testing.assert_allclose(np.sort(ds.xi.values), xi, rtol=0, atol=1e-14)
    mean, var = collocation(SECTION_32, 0.02, strobe_times(3.98, 5, 8), nodes=8)
    assert int(ds.n_impacts.min()) >= 2
    np.testing.assert_allclose(ds.x_mean, mean, rtol=0, atol=1e-8)
    np.testing.assert_allclose(ds.x_var, var, rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- validate, converge


def test_validate_against_collocation_of_the_reference(tmp_path):
    """A one-value map over 2 periods: its Monte Carlo reference lies within 4 standard
    errors of the sampled systems' exact mean and variance, its OPA mean (N = 2) is theirs
    before the first impact, and its impact counts are those of the scipy reference."""
    run(["validate", "--values", 3.98, "--sigmas", "0.01,0.03", "--orders", "0:2",
         "--horizons", 2, "--samples", 64, "--max-samples", 64, "--per-period", 4,
         "--no-plots", "--no-frontier", "--quiet", "--outdir", tmp_path])
    assert "# opa-mc validate" in (tmp_path / "summary.md").read_text(encoding="utf-8")
    ds = load(tmp_path / "validate.nc")
    t = ds.time.values * 2 * math.pi / 3.98  # validate.nc's time is in forcing periods
    np.testing.assert_allclose(t, strobe_times(3.98, 2, 4), rtol=1e-15)
    first_impact = reference_trajectory(**SECTION_32, t_out=[0.0, t[-1]])["impact_time"][0]
    for sigma in (0.01, 0.03):
        point = ds.sel(omega=3.98, sigma=sigma)
        mean, var = collocation(SECTION_32, sigma, t)
        assert np.all(np.abs(point.mc_x_mean - mean) <= 4 * point.mc_x_sem + 1e-8)
        assert np.all(np.abs(point.mc_x_var - var) <= 4 * point.mc_x_var_sem + 1e-10)
        opa = point.opa_x_mean.sel(variant="mean/galerkin", N=2).values
        np.testing.assert_allclose(opa[t < first_impact], mean[t < first_impact], rtol=0,
                                   atol=1e-7)
        counts = {reference_trajectory(**{**SECTION_32, "mu": 0.8 + s}, t_out=[0.0, t[-1]])[
            "impact_time"].size for s in (-sigma, 0.0, sigma)}
        assert len(counts) == 1  # no sampled system's impact count differs at the ends
        assert point.count_prob.sel(horizon=2.0, count=counts.pop()).item() == 1.0


@pytest.mark.long  # the quick loop keeps test_converge_uncertain_c and compare's own study tests
def test_converge_errors_against_the_collocation_of_the_reference(tmp_path):
    """The study's reference R (1024 Sobol samples) is within a few standard errors of the
    exact mean T (scipy collocation), so each reported error |X - R| is |X - T| to within
    |R - T|. With N = 0 the OPA system, and with one node the collocation, are the nominal
    system mu = 0.8, integrated here by the scipy reference."""
    out = tmp_path / "c"
    run(["converge", "--sigma", 0.05, "--periods", 2, "--order", 1, "--budgets", 4,
         "--uniform", "1,2", "--reference", 1024, "--outdir", out, "--quiet"])
    assert {p.name for p in out.iterdir()} >= {"convergence.nc", "convergence.md",
                                                "convergence.png"}
    ds = load(out / "convergence.nc")
    per_period = int(ds.attrs["per_period"])
    t = strobe_times(3.98, 2, per_period)
    truth, _ = collocation(SECTION_32, 0.05, t, nodes=16)
    nominal = reference_trajectory(**SECTION_32, t_out=t, rtol=1e-12, atol=1e-12)["x"]
    bound = 5 * ds.attrs["reference_sem"]  # |R - T| (RMS over the window)
    expected = math.sqrt(np.mean((nominal - truth) ** 2))
    rows = ds.to_dataframe()
    for method, order in (("OPA (one element), N", 0), ("collocation (one element), Q", 1)):
        (error,) = rows[(rows.method == method) & (rows.order == order)].error.unique()
        assert abs(error - expected) <= bound, (method, error, expected)
    converged = rows[(rows.method == "collocation (one element), Q") & (rows.order == 16)]
    assert converged.error.item() <= bound
    uniform = rows[(rows.method == "ME-OPA uniform") & (rows.law == "mean")]
    assert sorted(uniform["size"]) == [1, 2] and set(uniform.order) == {1}


# --------------------------------------------------------------------------- bifurcation


def _sweep_matches(ds, sections_33, atol):
    for omega in (4.8, 5.1):
        ref = sections_33[omega]
        np.testing.assert_allclose(ds.section_x.sel(omega=omega), ref["x"], rtol=0, atol=atol)
        np.testing.assert_allclose(ds.section_v.sel(omega=omega), ref["v"], rtol=0, atol=atol)


def test_bifurcation_dmr_labels_and_sections_of_section_33(tmp_path, sections_33,
                                                           kept_figures):
    """Section 3.3 without impulses: 1/1 at omega = 4.8, 2/2 at 5.1 (a period doubling in
    between); both sections are the scipy reference's."""
    out, png = tmp_path / "b.nc", tmp_path / "b.png"
    run(["bifurcation", "dmr", *SWEEP_33, "--out", out, "--plot", png, "--quiet"])
    ds = load(out)
    assert ds.label.values.tolist() == ["1/1", "2/2"]
    _sweep_matches(ds, sections_33, atol=1e-7)
    for omega in (4.8, 5.1):
        ref = sections_33[omega]
        k = len(ref["phase"]) // 2
        np.testing.assert_allclose(ds.impact_phase.sel(omega=omega)[:k], ref["phase"][:k],
                                   rtol=0, atol=1e-7)
        np.testing.assert_allclose(ds.impact_v.sel(omega=omega)[:k], ref["speed"][:k],
                                   rtol=0, atol=1e-7)
    meanings = ds.bifurcation_kind.attrs["flag_meanings"].split()
    kinds = [meanings[k] for k in ds.bifurcation_kind.values]
    (doubling,) = ds.bifurcation_parameter.values[[k == "period_doubling" for k in kinds]]
    assert 4.8 < doubling < 5.1
    # the figure draws the located doubling and nothing else as a vertical line
    assert png.stat().st_size > 10_000
    (fig,) = kept_figures
    for ax in fig.axes:
        xs = [line.get_xdata()[0] for line in ax.get_lines()
              if len(line.get_xdata()) == 2 and line.get_xdata()[0] == line.get_xdata()[1]]
        assert xs == pytest.approx([doubling])


def test_bifurcation_opa_with_sigma_0_is_the_reference(tmp_path, sections_33):
    out = tmp_path / "b.nc"
    run(["bifurcation", "opa", "--sigma", 0, "--order", 1, *SWEEP_33, "--out", out, "--quiet"])
    ds = load(out)
    assert ds.label.values.tolist() == ["1/1", "2/2"]
    _sweep_matches(ds, sections_33, atol=1e-7)


def test_bifurcation_mc_mean_of_a_narrow_ensemble_is_the_reference(tmp_path, sections_33):
    """sigma = 0.001: every sample falls on the same stable orbit, within 1e-5 of the
    nominal one (measured 2e-7); the Monte Carlo mean has no constraint section."""
    out = tmp_path / "b.nc"
    run(["bifurcation", "mc", "--sigma", 0.001, "--samples", 8, *SWEEP_33, "--out", out,
         "--quiet"])
    ds = load(out)
    assert ds.label.values.tolist() == ["1/?", "2/?"]
    _sweep_matches(ds, sections_33, atol=1e-5)


# --------------------------------------------------------------------------- reproduce


def test_reproduce_fig2_draws_the_impulse_sizes(tmp_path, kept_figures):
    run(["reproduce", "fig2", "--outdir", tmp_path, "--quiet"])
    assert (tmp_path / "fig2.png").stat().st_size > 10_000
    text = " ".join((tmp_path / "fig2.txt").read_text(encoding="utf-8").split())
    (fig,) = kept_figures
    t_j = 2 * math.pi * np.arange(int(64 / (2 * math.pi)) + 1)  # 0 <= t <= 64, omega1 = 1
    for ax, n in zip(fig.axes, (2, 4)):
        heights = impulse_size(t_j, 0.1, 1.0, 1.0, n)
        (stems,) = [line for line in ax.get_lines() if line.get_marker() == "o"]
        np.testing.assert_allclose(stems.get_xdata(), t_j, rtol=1e-14)
        np.testing.assert_allclose(stems.get_ydata(), heights, rtol=0, atol=1e-15)
    cycle = ", ".join(f"{h:.3g}" for h in impulse_size(t_j[:4], 0.1, 1.0, 1.0, 4))
    assert f"4 cycles through {cycle}," in text and cycle == "0.1, 0.2, 0.1, 0"


# --------------------------------------------------------------------------- stability


def test_stability_dmr_finds_the_closed_form_linear_impact_orbit(tmp_path):
    out = tmp_path / "s.nc"
    run(["stability", "dmr", *LINEAR_FLAGS, "--out", out, "--quiet"])
    ds = load(out)
    state, monodromy, _, speed = linear_impact_orbit(**LINEAR)
    np.testing.assert_allclose(ds.state.values[0], state, rtol=0, atol=1e-9)
    assert ds.period.item() == 1 and ds.impacts.item() == 1 and ds.stable.item() == 1
    assert ds.min_impact_velocity.item() == pytest.approx(speed, rel=1e-9)
    got = ds.multiplier_real.values[0] + 1j * ds.multiplier_imag.values[0]
    assert_same_multipliers(got, np.linalg.eigvals(monodromy), atol=1e-8)


def test_stability_opa_with_sigma_0_is_the_dmr_orbit_and_free_higher_modes(tmp_path):
    """At sigma = 0 (mean impact law) the OPA orbit is the DMR orbit in x_0, v_0 with zero
    higher coefficients, and each higher mode is the free flow x_i'' + a x_i = 0 over a
    period: multipliers exp(+-i sqrt(a) T) besides the DMR's."""
    out = tmp_path / "s.nc"
    run(["stability", "opa", "--sigma", 0, "--order", 2, *LINEAR_FLAGS, "--out", out,
         "--quiet"])
    ds = load(out)
    state, monodromy, _, _ = linear_impact_orbit(**LINEAR)
    np.testing.assert_allclose(ds.state.values[0], [state[0], 0, 0, state[1], 0, 0], rtol=0,
                               atol=1e-9)
    free = np.linalg.eigvals(linear_flow(LINEAR["a"], 2 * math.pi / LINEAR["omega"]))
    expected = np.concatenate([np.linalg.eigvals(monodromy), free, free])
    got = ds.multiplier_real.values[0] + 1j * ds.multiplier_imag.values[0]
    assert_same_multipliers(got, expected, atol=1e-8)


def test_validate_uniform_law_with_elements(tmp_path, capsys):
    """``validate --distribution uniform --elements 2``: the Monte Carlo reference samples
    the uniform law (within 4 standard errors of Gauss-Legendre collocation of the scipy
    reference, whose variance differs from the semicircle's), the paper truncation is left
    out, and the multi-element variants have sigma* beside the single-element ones."""
    run(["validate", "--values", 3.98, "--sigmas", "0.01,0.03", "--orders", "0:1",
         "--horizons", 2, "--samples", 64, "--max-samples", 64, "--per-period", 4,
         "--distribution", "uniform", "--elements", 2, "--no-plots", "--no-frontier",
         "--quiet", "--outdir", tmp_path])
    out = capsys.readouterr().out
    assert "variants left out: mean/paper, ensemble/paper" in out
    assert "σ* saltation/ME-K2" in (tmp_path / "summary.md").read_text()
    ds = load(tmp_path / "validate.nc")
    assert ds.attrs["distribution"] == "uniform"
    assert list(ds.variant.values) == ["mean/galerkin", "ensemble/galerkin",
                                       "saltation/galerkin", "mean/ME-K2", "ensemble/ME-K2",
                                       "saltation/ME-K2"]
    assert np.isfinite(ds.sigma_star.values).all()
    t = ds.time.values * 2 * math.pi / 3.98  # validate.nc's time is in forcing periods
    xi, w = np.polynomial.legendre.leggauss(12)
    w = w / 2
    for sigma in (0.01, 0.03):
        paths = np.array([reference_trajectory(**{**SECTION_32, "mu": 0.8 + sigma * x},
                                               t_out=t, rtol=1e-12, atol=1e-12)["x"]
                          for x in xi])
        mean = w @ paths
        var = w @ paths**2 - mean**2
        point = ds.sel(omega=3.98, sigma=sigma)
        assert np.all(np.abs(point.mc_x_mean - mean) <= 4 * point.mc_x_sem + 1e-8)
        assert np.all(np.abs(point.mc_x_var - var) <= 4 * point.mc_x_var_sem + 1e-10)


def test_converge_uncertain_c(tmp_path):
    """``converge --uncertain c`` at tiny sizes: the study's dataset says c is uncertain,
    and with one collocation node (the nominal system) its error is that of the scipy
    reference's nominal trajectory against the reference ensemble's mean."""
    out = tmp_path / "c"
    run(["converge", "--uncertain", "c", "--sigma", 0.02, "--periods", 2, "--order", 1,
         "--budgets", 2, "--uniform", "1,2", "--reference", 1024, "--outdir", out,
         "--quiet"])
    ds = load(out / "convergence.nc")
    assert ds.attrs["uncertain"] == "c" and ds.attrs["c"] == 0.05
    rows = ds.to_dataframe()
    assert set(rows.method) >= {"ME-OPA uniform", "ME-OPA adaptive", "QMC (Sobol)"}
    assert np.isfinite(rows.error).all()


@pytest.mark.long  # the quick loop keeps the d = 2 study of tests/compare/test_convergence.py
def test_converge_two_uncertain_parameters(tmp_path, capsys):
    """``converge --uncertain mu,c --sigma 0.016,0.005 --distribution semicircle,uniform``
    at tiny sizes: boxes and ladders, the parts of one parameter said to be left out, the
    report and figure written; a --sigma of the wrong count exits 2 naming --sigma."""
    out = tmp_path / "two"
    run(["converge", "--uncertain", "mu,c", "--sigma", "0.016,0.005", "--distribution",
         "semicircle,uniform", "--periods", 2, "--order", 1, "--budgets", 4, "--uniform",
         "1,2", "--reference", 1024, "--outdir", out])
    printed = capsys.readouterr()
    assert "collocation (multi-element and one element) skipped" in printed.err
    assert "Control-variate ladder skipped" in printed.out
    ds = load(out / "convergence.nc")
    assert ds.attrs["uncertain"] == "mu,c" and list(ds.attrs["sigma"]) == [0.016, 0.005]
    assert set(ds.method.values) >= {"ME-OPA uniform", "ME-OPA adaptive", "QMC (Sobol)"}
    assert not any("collocation" in m for m in ds.method.values)
    assert (out / "convergence.png").exists() and (out / "convergence.md").exists()
    assert main(["converge", "--uncertain", "mu,c", "--sigma", "0.1,0.2,0.3", "--outdir",
                 str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "--sigma must give one value, or one per uncertain parameter (2), got 3" in err
    assert "Traceback" not in err


def test_simulate_opa_elements_say_what_cannot_be_trusted(tmp_path, capsys):
    """Issue 24: ``simulate opa --sigma 0.05 --elements 16 --distribution beta:2,3`` (100
    periods) printed E[x] = -0.633 without a word where the true ensemble gives -0.846.
    Every element then contains a change of the impact sequence: the scipy reference at
    the support's two ends (mu = 0.75 and 0.85) makes its impacts in other impulse
    intervals [2 pi j, 2 pi (j + 1)), and the summary must say so, besides the elements
    computed by collocation."""
    t_end = 100 * 2 * math.pi / 3.98
    intervals = [tuple(np.floor(reference_trajectory(
        **{**SECTION_32, "mu": mu}, t_out=np.array([0.0, t_end]))["impact_time"]
        / (2 * math.pi)).astype(int)) for mu in (0.75, 0.85)]
    assert intervals[0] != intervals[1]
    run(["simulate", "opa", "--sigma", 0.05, "--elements", 16, "--distribution", "beta:2,3",
         "--out", tmp_path / "b.nc"])
    out = capsys.readouterr().out
    assert "16 elements (uniform), beta:2,3 law, impact law saltation" in out
    assert "warning: 16 of 16 elements (probability 1) contain a change of the impact " \
           "sequence" in out
    ds = load(tmp_path / "b.nc")
    assert "elements computed by collocation" in out and ds.attrs["collocation_elements"] > 0


def test_simulate_opa_verify_strict_catches_the_beta_case(tmp_path, capsys):
    """Issue 25: the beta:2,3 run of 16 elements over 100 periods prints E[x] = -0.725
    where the true ensemble gives -0.846; --verify 256 doubles (over 100 periods the
    paired differences are noisy) and --strict exits 4: over 100 periods the split scan
    hits its limit, so the certificate certifies nothing (UNDECIDED, with the reason) --
    its estimates stand: a control-variate E[x] at the end within 4 joint standard
    errors of a separate Monte Carlo ensemble of 4096 true systems (simulate mc, other
    points)."""
    out = tmp_path / "v.nc"
    argv = ["simulate", "opa", "--sigma", "0.05", "--elements", "16", "--distribution",
            "beta:2,3", "--verify", "256", "--strict", "--out", str(out)]
    assert main(argv) == 4
    text = capsys.readouterr()
    assert "UNDECIDED" in text.out and "split scan hit its limit" in text.out
    assert "is not certified by" in text.err and "--strict" in text.err
    ds = load(out)
    assert ds.attrs["verdict"] == "undecided" and ds.attrs["verify_splits_complete"] == 0
    run(["simulate", "mc", "--sigma", "0.05", "--distribution", "beta:2,3", "--samples",
         "4096", "--seed", "3", "--out", tmp_path / "m.nc", "--quiet"])
    ens = load(tmp_path / "m.nc")
    noise = 4 * math.hypot(float(ds.cv_x_mean_sem[-1]), float(ens.x_sem[-1]))
    assert abs(float(ds.cv_x_mean[-1]) - float(ens.x_mean[-1])) <= noise
    assert abs(float(ds.x_mean[-1]) - float(ens.x_mean[-1])) > 0.08  # the OPA run is off


def test_stochastic_diagram_through_the_deterministic_doubling(tmp_path, capsys):
    """``opa-mc stochastic`` at c = 0.0396996668 (section 3.1, F0 = 0), where the
    deterministic doubling 2/2 -> 4/4 sits at mu = 0.8: the boundary is at xi = 0 and
    each type has half the semicircle's mass; the Monte Carlo samples agree
    (tests/opa/dynamics/test_stochastic.py checks boundaries against long brute-force runs
    and the scipy reference)."""
    out, fig = tmp_path / "s.nc", tmp_path / "s.png"
    run(["stochastic", "--preset", "3.1", "--F0", "0", "--sweep", "c=0.0396996668,0.05",
         "--samples", "32", "--transient", "800", "--out", out, "--plot", fig])
    text = capsys.readouterr().out
    assert "c = 0.0396997: 2/2 0.500, 4/4 0.500 (continuation)" in text
    assert "c = 0.05: 2/2 1.000 (continuation)" in text
    ds = load(out)
    assert abs(float(ds.boundary_xi.sel(c=0.0396996668, boundary=0))) < 1e-6
    assert list(ds.agree.values) == [1, 1]
    assert fig.stat().st_size > 10_000
    assert not (tmp_path / "s.nc.parts").exists()  # kept only until the final write
    assert main(["stochastic", "--preset", "3.1", "--sweep", "c=0.04", "--keep-parts"]) == 2
    assert "--keep-parts has no effect without --out" in capsys.readouterr().err


def test_stochastic_diagram_of_two_uncertain_parameters(tmp_path, capsys):
    """``opa-mc stochastic --uncertain mu,a --sigma 0.03,0.002 --distribution
    semicircle,uniform``: no boundaries (said in one line), the probabilities sampled with
    their standard errors from the scramblings (tests/opa/dynamics/test_stochastic.py
    checks them against the one-parameter boundaries); the refusals name the flag."""
    out, fig = tmp_path / "two.nc", tmp_path / "two.png"
    flags = ["stochastic", "--preset", "3.1", "--F0", "0", "--uncertain", "mu,a", "--sigma",
             "0.03,0.002", "--distribution", "semicircle,uniform"]
    run([*flags, "--sweep", "c=0.0396996668,0.05", "--samples", "64", "--extra-states", "0",
         "--out", out, "--plot", fig])
    text = capsys.readouterr().out
    assert "mu = 0.8 + 0.03 xi_1, a = 1 + 0.002 xi_2, 64 samples each (scrambled Sobol'" in text
    assert "boundaries not located: continuation in xi is one-dimensional by nature" in text
    assert "c = 0.05: 2/2 1.000 ± 0.000 (sampled)" in text
    ds = load(out)
    assert ds.attrs["uncertain"] == "mu,a" and list(ds.attrs["sigma"]) == [0.03, 0.002]
    assert ds.mc_xi.dims == ("sample", "parameter") and "boundary_xi" not in ds
    assert fig.stat().st_size > 10_000 and not (tmp_path / "two.nc.parts").exists()
    for extra, flag in ((["--emr"], "--emr: the EMR's sweep takes one uncertain parameter"),
                        (["--samples", "100"], "--samples must be a multiple of 8"),
                        (["--sigma", "0.03,0.002,0.1"], "--sigma must give one value"),
                        (["--uncertain", "mu,x"], "--uncertain must name parameters among")):
        argv = [*flags, "--sweep", "c=0.05", *extra]
        if extra[0] in ("--sigma", "--uncertain"):  # replaces the flag given above
            i = argv.index(extra[0])
            argv[i:i + 2] = []
        try:  # argparse's own refusals exit
            code = main(argv)
        except SystemExit as stop:
            code = stop.code
        assert code == 2, extra
        err = capsys.readouterr().err
        assert flag in err and "Traceback" not in err, err


class _Started(Exception):
    pass


def test_validate_starts_its_workers_fork_server_before_the_maps_imports(monkeypatch,
                                                                        tmp_path):
    """``opa-mc validate`` on worker processes starts their fork server (with the map's
    modules to import) once its input is checked, before it imports the map's modules
    itself; a map in one process starts none, and building the parser imports no
    matplotlib (the figure names of ``reproduce`` are read when asked for)."""
    import subprocess
    import sys

    import opa.engine
    from compare._scaleout import FIGURE_PRELOAD, MAP_PRELOAD

    started = []

    def start(preload):
        started.append(preload)
        raise _Started

    monkeypatch.setattr(opa.engine, "start_fork_server", start)  # the CLI's door to it
    tiny = ["--values", "3.98", "--sigmas", "0.01,0.03", "--orders", "0:2", "--horizons",
            "2,4", "--samples", "64", "--max-samples", "128", "--no-frontier",
            "--no-plots", "--quiet"]
    assert main(["validate", *tiny, "--workers", "2", "--outdir", str(tmp_path / "a")]) == 1
    assert started == [MAP_PRELOAD]  # --no-plots: no matplotlib for the server
    assert main(["validate", *tiny, "--workers", "1", "--outdir", str(tmp_path / "b")]) == 0
    assert started == [MAP_PRELOAD]
    drawn = [a for a in tiny if a != "--no-plots"]
    assert main(["validate", *drawn, "--workers", "2", "--outdir", str(tmp_path / "c")]) == 1
    assert started == [MAP_PRELOAD, MAP_PRELOAD + FIGURE_PRELOAD]
    code = ("import sys; from opa.cli._main import build_parser; build_parser(); "
            "print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"


@pytest.mark.parametrize("argv", [
    # a rare change of the impact sequence: xi < -0.90 (2 % of the law) makes an extra
    # impact; the true errors are 1.30x (mean) and 3.60x (variance) the tolerance
    ["--impact-law", "saltation", "--order", "4", "--sigma", "0.025", "--verify", "256",
     "--seed", "5016"],
    # 8 elements at sigma = 0.03, true errors 1.24x and 8.3x the tolerance, the smallest M
    ["--sigma", "0.03", "--elements", "8", "--verify", "64", "--seed", "3"],
])
def test_simulate_opa_strict_never_certifies_the_issues_wrong_answers(argv, capsys):
    """The two commands that used to print AGREES and exit 0 under --strict (their true
    errors from tests/certificate_cases.py): neither agrees now, and --strict exits 4."""
    code = main(["simulate", "opa", "--periods", "10", "--per-period", "8", "--strict"]
                + argv)
    text = capsys.readouterr()
    assert code == 4 and ": AGREES" not in text.out
    assert ("DISAGREES" in text.out or "UNDECIDED" in text.out) and "--strict" in text.err


def test_a_variance_reduction_below_one_is_explained():
    """The certificate's summary says why a variance reduction below 1 can happen."""
    from compare import verify
    from opa import Oscillator, simulate_opa
    from opa.cli._main import _verify_lines

    ds = verify(simulate_opa(Oscillator(), sigma=0.01, order=1, periods=1), samples=64)
    assert not any("below 1" in line for line in _verify_lines(ds))
    ds.attrs["variance_reduction"] = 0.6
    assert any("below 1: x - x_hat varies more than x itself" in line
               for line in _verify_lines(ds))


# --- the rules the CLI takes from the library (issue 41, item 4): the API gets them too ---


def test_the_default_impact_law_is_the_librarys_for_the_api_and_the_cli(tmp_path):
    """docs/elements.md: with elements the default law is saltation (the law whose
    elements converge), without them the paper's mean law (eq. 28); ``simulate opa`` and
    ``opa.simulate_opa`` both take it from ``default_impact_law``."""
    import opa
    from opa.engine import default_impact_law

    assert [default_impact_law(k) for k in (None, 1, 3, "adaptive")] == \
        ["mean", "saltation", "saltation", "saltation"]
    common = ["--sigma", 0.02, "--order", 2, "--periods", 2, "--quiet"]
    for elements, law in ((None, "mean"), (2, "saltation")):
        out = tmp_path / f"{elements}.nc"
        run(["simulate", "opa", *common, *(["--elements", elements] if elements else []),
             "--out", out])
        api = opa.simulate_opa(sigma=0.02, order=2, periods=2, elements=elements)
        explicit = opa.simulate_opa(sigma=0.02, order=2, periods=2, elements=elements,
                                    impact_law=law)
        cli = load(out)
        assert cli.attrs["impact_law"] == api.attrs["impact_law"] == law
        np.testing.assert_array_equal(cli.x_mean, explicit.x_mean)
        np.testing.assert_array_equal(api.x_mean, explicit.x_mean)


def test_a_run_is_failed_by_its_non_finite_numbers_except_the_documented_ones():
    """docs/datasets.md: a Gauss quadrature's standard errors are NaN (it has no sampling
    error) and the refinement history may hold NaN and inf; any other NaN or inf makes a
    run that could not be completed (``first_non_finite``, what ``simulate`` refuses)."""
    import mc
    from opa.engine import first_non_finite

    ds = xr.Dataset({"x_mean": ("time", [0.5, 1.0]), "x_sem": ("time", [np.nan, np.nan]),
                     "refinement_share": ("step", [np.inf]),
                     "refinement_mean_change": ("step", [np.nan]),
                     "n_impacts": ("sample", [1, 2])})
    assert first_non_finite(ds) == ("x_sem", 2)  # a sampler's standard error: a failure
    ds.attrs["sampler"] = "gauss"
    assert first_non_finite(ds) is None
    ds["x_var"] = ("time", [0.1, np.inf])
    assert first_non_finite(ds) == ("x_var", 1)
    gauss = mc.simulate_mc(sigma=0.02, samples=8, sampler="gauss", periods=2, progress=False)
    assert np.isnan(gauss.x_sem).all() and first_non_finite(gauss) is None


def test_the_api_sweeps_the_monte_carlo_mean_with_mcs_source(sections_33):
    """``opa.sweep`` is ``opa.dynamics.sweep``: the Monte Carlo mean needs its trajectory
    source from the layer above, ``mc.sweep_source`` (what ``bifurcation mc`` passes), and
    is then the section 3.3 reference, as in the CLI's test above."""
    import mc
    import opa

    system = opa.System(opa.preset("3.3", F0=0.0), sigma=0.001)
    kwargs = dict(samples=8, transient=200, record=40, per_period=16, workers=1)
    with pytest.raises(ValueError, match=r"source=mc\.sweep_source"):
        opa.sweep("mc", "omega", [4.8, 5.1], system, **kwargs)
    ds = opa.sweep("mc", "omega", [4.8, 5.1], system, source=mc.sweep_source, **kwargs)
    assert ds.label.values.tolist() == ["1/?", "2/?"]
    _sweep_matches(ds, sections_33, atol=1e-5)


# --------------------------------------------------------------------------- several parameters

FREE_FLAGS = ["--mu", 0.3, "--a", 1.0, "--c", 0.5, "--f", 0.4, "--omega", 1.3, "--delta", 50.0,
              "--F0", 0.0, "--x0", 0.5, "--v0", 0.0, "--periods", 3, "--per-period", 8,
              "--rtol", 1e-12, "--atol", 1e-12, "--quiet"]


def test_simulate_opa_with_two_uncertain_parameters_is_the_tensor_reference(tmp_path):
    """--uncertain mu,c on a case without impacts: the moments and Sobol indices of the
    scipy runs at a 14 x 14 tensor Gauss rule (tests/opa/test_galerkin.py)."""
    from tests.opa.test_galerkin import reference

    out = tmp_path / "two.nc"
    run(["simulate", "opa", "--uncertain", "mu,c", "--sigma", "0.06,0.2", "--distribution",
         "semicircle,uniform", "--order", 6, *FREE_FLAGS, "--out", out])
    ds = load(out)
    mean, var, first, total = reference(("semicircle", "uniform"))
    np.testing.assert_allclose(ds.x_mean, mean, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ds.x_var, var, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ds.x_sobol_first[:, 1:], first[:, 1:], rtol=0, atol=1e-6)
    np.testing.assert_allclose(ds.x_sobol_total[:, 1:], total[:, 1:], rtol=0, atol=1e-6)
    assert ds.attrs["uncertain"] == "mu,c" and ds.multi_index.shape == (28, 2)


def test_simulate_opa_with_two_uncertain_parameters_on_boxes(tmp_path, capsys):
    """--elements 2 with two parameters: four boxes, the same moments as the tensor
    reference, and the summary says so."""
    from tests.opa.test_galerkin import reference

    out = tmp_path / "boxes.nc"
    run(["simulate", "opa", "--uncertain", "mu,c", "--sigma", "0.06,0.2", "--distribution",
         "semicircle,uniform", "--order", 4, "--elements", 2,
         *[f for f in FREE_FLAGS if f != "--quiet"], "--out", out])
    ds = load(out)
    mean, var, _, _ = reference(("semicircle", "uniform"))
    np.testing.assert_allclose(ds.x_mean, mean, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ds.x_var, var, rtol=0, atol=1e-7)
    assert ds.sizes["element"] == 4
    assert "4 boxes (uniform)" in capsys.readouterr().out


def test_simulate_mc_with_three_uncertain_parameters_is_the_mean_of_its_samples(tmp_path):
    """The ensemble's mean and variance are those of scipy runs at the points it wrote
    (sample, parameter), with each parameter at p_bar + sigma xi."""
    out = tmp_path / "mc3.nc"
    run(["simulate", "mc", "--uncertain", "mu,a,c", "--sigma", "0.06,0.1,0.2",
         "--distribution", "uniform", "--samples", 32, "--sampler", "random", *FREE_FLAGS,
         "--out", out])
    ds = load(out)
    assert ds.xi.dims == ("sample", "parameter") and ds.sizes["parameter"] == 3
    assert np.all(np.abs(ds.xi.values) <= 1.0)
    t = ds.time.values
    paths = []
    for mu, a, c in np.array([0.3, 1.0, 0.5]) + np.array([0.06, 0.1, 0.2]) * ds.xi.values:
        def rhs(s, y, mu=mu, a=a, c=c):
            return [y[1], mu * (1 - y[1] ** 2) * y[1] - a * y[0] - c * y[0] ** 3
                    + 0.4 * np.cos(1.3 * s)]
        paths.append(solve_ivp(rhs, (0, t[-1]), [0.5, 0.0], method="DOP853", t_eval=t,
                               rtol=1e-12, atol=1e-12).y[0])
    paths = np.array(paths)
    np.testing.assert_allclose(ds.x_mean, paths.mean(axis=0), rtol=0, atol=1e-8)
    np.testing.assert_allclose(ds.x_var, paths.var(axis=0, ddof=1), rtol=0, atol=1e-8)


@pytest.mark.parametrize("argv, words", [
    (["--uncertain", "mu,x"], "--uncertain must name parameters among"),
    (["--uncertain", "mu,mu"], "argument --uncertain: a parameter is named twice"),
    (["--uncertain", "mu,c", "--sigma", "0.1,0.2,0.3"], "--sigma must give one value, or one"),
    (["--uncertain", "mu,c", "--distribution", "uniform,uniform,beta:2,3"],
     "--distribution must give one value, or one"),
    (["--uncertain", "mu,c", "--basis", "sparse"], "--basis must be one of"),
    (["--uncertain", "mu,a,c", "--order", "40"], "--order 40 with 3 uncertain parameters"),
    (["--uncertain", "mu,c", "--elements", "adaptive", "--max-elements", "100000"],
     "--max-elements must be 2 to 4096 boxes"),
    (["--uncertain", "mu,a,c", "--elements", "20"], "elements = 20 makes 20^3 boxes"),
    (["--uncertain", "mu,1x"], "argument --uncertain: each uncertain parameter must be a name"),
])
def test_several_parameters_refused_in_one_line_naming_the_flag(argv, words, capsys):
    argv = ["simulate", "opa", *argv, "--periods", "1", "--quiet"]
    if words.startswith("argument"):  # refused by the parser
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        assert exit_.value.code == 2
    else:
        assert main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


# --------------------------------------------------------------------------- sobol


def test_sobol_certifies_the_indices_of_scipy_s_tensor_rule(tmp_path, capsys):
    """The no-impact case of tests/opa/cli/test_sobol.py: the certified intervals of x at
    the last output hold the indices scipy gives at a 10 x 10 Gauss rule."""
    from tests.opa.cli.test_sobol import flags, truth_at_the_end

    out = tmp_path / "sobol.nc"
    run(["sobol", *flags(), "--out", out, "--quiet"])
    assert "S_i certified" in capsys.readouterr().out
    ds = load(out)
    for kind, exact in zip(("first", "total"), truth_at_the_end()):
        low = ds[f"x_sobol_{kind}_lower"].values[:, -1]
        high = ds[f"x_sobol_{kind}_upper"].values[:, -1]
        assert np.all((low <= exact) & (exact <= high)), (kind, low, exact, high)


def test_a_problem_file_is_the_same_as_its_flags(tmp_path, capsys):
    """--problem FILE.toml gives the run the flags --uncertain/--sigma/--distribution
    give; mixing them is refused naming the flags."""
    problem = tmp_path / "problem.toml"
    problem.write_text('[mu]\nsigma = 0.06\n[c]\nsigma = 0.2\ndistribution = "uniform"\n')
    run(["simulate", "opa", "--problem", problem, "--order", 2, *FREE_FLAGS,
         "--out", tmp_path / "a.nc"])
    run(["simulate", "opa", "--uncertain", "mu,c", "--sigma", "0.06,0.2", "--distribution",
         "semicircle,uniform", "--order", 2, *FREE_FLAGS, "--out", tmp_path / "b.nc"])
    a, b = load(tmp_path / "a.nc"), load(tmp_path / "b.nc")
    for ds in (a, b):
        del ds.attrs["history"]
    xr.testing.assert_identical(a, b)
    assert main(["simulate", "opa", "--problem", str(problem), "--sigma", "0.1",
                 "--quiet"]) == 2
    assert "--sigma may not be given with it" in capsys.readouterr().err


def test_simulate_opa_with_two_uncertain_parameters_certified(tmp_path, capsys):
    """--verify with two parameters: a converged run (N = 6, no impacts) agrees with its
    certificate and --strict exits 0; the single element on the impact system of section
    3.2 (its error of E[x] is 0.2 of the spread, tests/compare/test_verify_several.py)
    disagrees and exits 4."""
    argv = ["simulate", "opa", "--uncertain", "mu,c", "--verify", 64, "--strict"]
    assert main([str(a) for a in [*argv, "--sigma", "0.06,0.2", *FREE_FLAGS, "--order", 6]]) == 0
    assert main([str(a) for a in [*argv, "--sigma", "0.016,0.005", "--omega", 3.98, "--periods",
                                  10, "--per-period", 8, "--impact-law", "saltation",
                                  "--quiet"]]) == 4
    assert "disagrees with its Monte Carlo certificate" in capsys.readouterr().err


# --- issue 43: --model FILE.toml on every command that takes an oscillator --------------

EXAMPLES = os.path.join(os.path.dirname(__file__), "..", "..", "..", "docs", "examples")
SHAW_MODEL = os.path.join(EXAMPLES, "shaw-holmes.toml")
DUFFING_MODEL = os.path.join(EXAMPLES, "duffing-impact.toml")
VDP_MODEL = os.path.join(EXAMPLES, "van-der-pol-x2v.toml")


def test_simulate_takes_a_model_file_and_the_flags_override_it(tmp_path):
    """``simulate dmr|opa|mc --model shaw-holmes.toml``: the file's law, constants,
    parameters and uncertain constant reach the dataset; dmr is the API's run of the same
    oscillator bit for bit; an explicit flag overrides the file's value."""
    import opa
    from opa._modelfile import read_model

    model = read_model(SHAW_MODEL)
    for name, extra in (("dmr", []), ("opa", ["--order", 2]), ("mc", ["--samples", 16])):
        run(["simulate", name, "--model", SHAW_MODEL, "--periods", 3, "--out",
             tmp_path / f"{name}.nc", "--quiet", *extra])
        ds = load(tmp_path / f"{name}.nc")
        assert ds.attrs["force_law"] == "-2*zeta*v - x" and ds.attrs["omega"] == 2.5
        assert ds.attrs["force_constants"] == "zeta=0.05" and ds.attrs["x0"] == -0.5
        if name != "dmr":
            assert (ds.attrs["uncertain"], ds.attrs["sigma"]) == ("zeta", 0.01)
            assert ds.attrs["distribution"] == "uniform"
    api = opa.simulate_dmr(opa.System(model.oscillator, sigma=0.0), periods=3)
    np.testing.assert_array_equal(load(tmp_path / "dmr.nc").x.values, api.x.values)
    run(["simulate", "opa", "--model", SHAW_MODEL, "--periods", 3, "--omega", 2.6,
         "--sigma", 0.02, "--order", 2, "--out", tmp_path / "over.nc", "--quiet"])
    ds = load(tmp_path / "over.nc")
    assert (ds.attrs["omega"], ds.attrs["sigma"], ds.attrs["uncertain"]) == (2.6, 0.02, "zeta")
    assert ds.attrs["distribution"] == "uniform"  # not overridden: the file's


def test_sweeps_and_orbits_take_a_model_file(tmp_path):
    """bifurcation, stability and sobol with a user's force law from a model file."""
    run(["bifurcation", "dmr", "--model", SHAW_MODEL, "--sweep", "omega=2.4,2.6",
         "--transient", 3, "--record", 2, "--workers", 1, "--no-locate", "--out",
         tmp_path / "b.nc", "--quiet"])
    assert load(tmp_path / "b.nc").attrs["force_law"] == "-2*zeta*v - x"
    run(["stability", "dmr", "--model", SHAW_MODEL, "--transient", 20, "--out",
         tmp_path / "s.nc", "--quiet"])
    assert load(tmp_path / "s.nc").attrs["force_law"] == "-2*zeta*v - x"
    run(["sobol", "--model", DUFFING_MODEL, "--periods", 1, "--samples", 8, "--order", 1,
         "--out", tmp_path / "sobol.nc", "--quiet"])
    ds = load(tmp_path / "sobol.nc")
    assert ds.attrs["force_law"] == "-d*v - k*x - b*x^3" and ds.attrs["uncertain"] == "k,b"


def test_stochastic_converge_and_validate_take_a_model_file(tmp_path, capsys):
    """stochastic with a user's law that names mu; converge and validate with a model file
    of the paper's law (they refuse a user's law: tests/opa/cli/test_bad_inputs.py)."""
    run(["stochastic", "--model", VDP_MODEL, "--sweep", "omega=1.2", "--samples", 8,
         "--transient", 10, "--record", 4, "--extra-states", 0, "--workers", 1, "--out",
         tmp_path / "st.nc", "--quiet"])
    ds = load(tmp_path / "st.nc")
    assert ds.attrs["force_law"] == "mu*(1 - x^2)*v - x" and ds.attrs["uncertain"] == "mu"
    paper = tmp_path / "paper.toml"
    paper.write_text("[oscillator]\nomega = 4.0\n[uncertain.c]\nsigma = 0.02\n")
    run(["converge", "--model", paper, "--periods", 2, "--order", 1, "--budgets", 2,
         "--uniform", "1,2", "--reference", 1024, "--outdir", tmp_path / "c", "--quiet"])
    ds = load(tmp_path / "c" / "convergence.nc")
    assert (ds.attrs["uncertain"], ds.attrs["sigma"], ds.attrs["omega"]) == ("c", 0.02, 4.0)
    paper.write_text("[oscillator]\nomega = 4.0\nF0 = 0.0\n")
    run(["validate", "--model", paper, "--omega", 4.1, "--sigmas", 0.01, "--orders", "0:1",
         "--horizons", 2, "--samples", 64, "--max-samples", 64, "--no-plots",
         "--no-frontier", "--outdir", tmp_path / "v", "--quiet"])
    ds = load(tmp_path / "v" / "validate.nc")
    assert float(ds.omega.values[0]) == 4.1 and ds.attrs["F0"] == 0.0
