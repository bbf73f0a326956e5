"""End to end on a tiny map: verdicts against direct comparisons computed here, the
netCDF round trip, resume from parts/, the report, the configuration and the CLI."""

import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from scipy import stats

from compare import load_config, run_validation, write_report
from compare._config import VARIANTS
from compare._ledger import Work
from opa import simulate_opa
from opa._surrogate import surrogate
from opa.cli._main import main
from opa._model import time_grid
from tests.compare.test_parts import _forbid_integration, _same

TINY = dict(values=(3.98, 4.035), sigmas=(0.01, 0.03), orders=(0, 1, 3), horizons=(4, 8),
            samples=64, max_samples=128, per_period=4)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("validate")
    cfg = load_config(None, outdir=str(out), **TINY)
    ds = run_validation(cfg, progress=False, log=lambda *a: None)
    return cfg, ds, out


def _running_rms(a):
    out, acc = [], 0.0
    for k, x in enumerate(a, start=1):
        acc += x * x
        out.append(math.sqrt(acc / k))
    return np.array(out)


def _verdict(err, sem, var, var_sem, n, tol, floor, *, spread, alpha, rounds):
    """The documented three-valued verdict, written out: the band's half-width is the
    Student's t quantile (R - 1 degrees of freedom) at two-sided level alpha / 2^rounds
    split over 2 n intervals, times each standard error; the scale (the spread when
    ``spread``, else the variance) runs from the band's low to its high end. 1 when the
    running RMS of |err| + band is within tol running RMS low scale + floor at every output
    of the first n, -1 when that of max(|err| - band, 0) exceeds tol running RMS high scale
    + floor at one (a stopped run, NaN, from where it stopped), else 0."""
    q = stats.t.ppf(1 - alpha / 2**rounds / (2 * n) / 2, R - 1)
    low = np.maximum(var[:n] - q * var_sem[:n], 0)
    high = np.maximum(var[:n] + q * var_sem[:n], 0)
    if spread:
        low, high = np.sqrt(low), np.sqrt(high)
    e, b = np.abs(err[:n]), q * sem[:n]
    upper = _running_rms(e + b) - tol * _running_rms(low) - floor
    lower = _running_rms(np.maximum(e - b, 0)) - tol * _running_rms(high) - floor
    if not np.isfinite(e).all():
        stop = int(np.argmax(~np.isfinite(e)))
        return -1 if stop == 0 or (lower[:stop] > 0).any() or np.isfinite(lower[:stop]).all() \
            else 0
    return 1 if (upper <= 0).all() else -1 if (lower > 0).any() else 0


R = 16  # the replicates of the map's scrambled Sobol' points


def _design_ensemble(cfg, ds, q, s, times):
    """The map's point (q, s) ensemble rebuilt: the points of its stratified design
    (compare._strata.replicate_points, whose strata are checked here against the split
    values the dataset lists within sigma) and the true systems there (opa.engine's
    true_runs). Returns x (M, T), xi, and the weights (each replicate's summing to 1)."""
    from types import SimpleNamespace

    from compare._ledger import Work
    from compare._strata import replicate_points
    from compare._trustmap import design
    from opa.engine import true_runs

    value, sigma = cfg.values[q], cfg.sigmas[s]
    strata, allocation = design(cfg, Work(cfg.outdir), value, sigma, times)
    samples = int(ds.mc_samples[q, s])
    xi, w, rep = replicate_points(cfg.measure(), strata, allocation, R, cfg.seed,
                                  samples // cfg.samples)
    assert len(xi) == samples and np.allclose(np.bincount(rep, weights=w), 1.0)
    # the strata cut the law of xi at every change of the impact sequence the dataset
    # lists within sigma (a cascade merged into one stratum: its ends are cuts)
    listed = ds.split_value.values[q, -1]
    kinds = [str(k) for k in ds.split_kind.attrs["flag_meanings"].split()]
    kind = ds.split_kind.values[q, -1]
    centre = getattr(cfg.oscillator_at(value), cfg.uncertain)
    jumps = [(v - centre) / sigma for v, k in zip(listed, kind)
             if k >= 0 and kinds[k] not in ("horizon", "output_crossing")
             and abs(v - centre) < sigma]
    def listed_jump(c):
        return any(abs(c - j) < 1e-9 for j in jumps)

    for x in jumps:  # on a cut, or inside a zone: a stratum from one jump to another
        assert listed_jump(x) and (np.min(np.abs(strata.cuts - x)) < 1e-9 or any(
            a < x < b and listed_jump(a) and listed_jump(b)
            for a, b in zip(strata.cuts[:-1], strata.cuts[1:])))
    system = cfg.system_at(value, sigma=sigma, order=0)
    paths = true_runs(system, cfg.options, xi, times, what="test")[0][:, :, 0]
    return SimpleNamespace(x=SimpleNamespace(values=paths), xi=SimpleNamespace(values=xi),
                           w=w)


def _paired(x, x_hat, mean_hat, second_hat, w):
    """The paired estimates written out from the paths: per replicate r the weighted
    means (weights w, summing to 1 in each replicate) of d = x - x_hat and q = x^2 -
    x_hat^2; E_cv[x] = E[x_hat] + d_r, Var_cv[x] = E[x_hat^2] + q_r - E_cv[x]^2;
    estimates are the replicate averages, standard errors their spread over sqrt(R).
    Returns OPA's errors of the mean and the variance with their standard errors, and
    the control-variate E[x], Var[x] with theirs."""
    M, T = x.shape
    w = w.reshape(R, M // R, 1)
    d = (w * (x - x_hat).reshape(R, M // R, T)).sum(axis=1)
    q = (w * (x**2 - x_hat**2).reshape(R, M // R, T)).sum(axis=1)
    mean_r = mean_hat + d
    var_r = second_hat + q - mean_r**2

    def avg_se(a):
        return a.mean(axis=0), a.std(axis=0, ddof=1) / math.sqrt(R)

    (d_avg, d_se), (m, m_se), (v, v_se) = avg_se(d), avg_se(mean_r), avg_se(var_r)
    return {"err_mean": -d_avg, "err_mean_se": d_se,
            "err_var": (second_hat - mean_hat**2) - v, "err_var_se": v_se,
            "mean": m, "mean_se": m_se, "var": v, "var_se": v_se}


def _check_point(cfg, ds, q, s, ens, runs):
    """The map's verdicts at grid point (q, s) from ``runs`` ((variant, N index) -> an OPA
    dataset) and the ensemble's paths: the reference E[x], Var[x] is the control-variate
    estimate of the control (the plain ensemble, or a run at the highest N, paired here
    with the ensemble) whose E[x] has the smallest RMS standard error; every run's errors
    are against it, with its standard errors."""
    x, xi = ens.x.values, ens.xi.values
    zero = np.zeros(x.shape[1])
    best = _paired(x, np.zeros_like(x), zero, zero, ens.w)
    pairs = {}
    for (v, k), run in runs.items():
        x_hat = surrogate(run, xi)[0]
        mean_hat = run.x_mean.values
        pairs[v, k] = _paired(x, x_hat, mean_hat, run.x_var.values + mean_hat**2, ens.w)
        np.testing.assert_allclose(ds.opa_x_mean.values[q, s, v, k], mean_hat, rtol=0,
                                   atol=1e-12)
    K = len(cfg.orders) - 1

    def rms(a):
        return float(np.sqrt(np.mean(a**2)))

    for (v, k), p in sorted(pairs.items(), key=lambda item: item[0][::-1]):  # N, variant
        if k == K and np.isfinite(p["mean"]).all() and np.isfinite(p["var"]).all() \
                and rms(p["mean_se"]) < rms(best["mean_se"]):
            best = p
    np.testing.assert_allclose(ds.mc_x_mean.values[q, s], best["mean"], rtol=0, atol=1e-12)
    var = np.maximum(best["var"], 0.0)
    floor = 10 * (cfg.options.rtol + cfg.options.atol)
    # the variance's floor: the solvers' squared plus 16 roundoffs of E[x^2]
    var_floor = floor**2 + 16 * np.finfo(float).eps * np.max(var + best["mean"] ** 2)
    rounds = 1 + int(round(math.log2(x.shape[0] / cfg.samples)))
    for (v, k), run in runs.items():
        # every run against the reference, whose standard errors are the errors' own
        err = run.x_mean.values - best["mean"]
        verr = run.x_var.values - best["var"]
        for h, H in enumerate(cfg.horizons):
            n = int(round(H * cfg.per_period)) + 1
            # a horizon whose split list is incomplete within sigma certifies nothing
            complete = ds.split_complete_sigma.values[q, h] >= cfg.sigmas[s]
            for c, (e, se, tol, fl) in enumerate(((err, best["mean_se"], cfg.tolerance, floor),
                                                  (verr, best["var_se"], cfg.var_tolerance,
                                                   var_floor))):
                verdict = _verdict(e, se, best["var"], best["var_se"], n, tol, fl,
                                   spread=c == 0, alpha=cfg.alpha, rounds=rounds)
                if not complete:
                    verdict = -1 if not np.isfinite(e[:n]).all() else 0
                assert ds.verdict.values[q, s, v, k, h, c] == verdict, (v, k, h, c)
                assert ds.agrees.values[q, s, v, k, h, c] == (verdict == 1), (v, k, h, c)
            np.testing.assert_allclose(ds.err_mean.values[q, s, v, k, h],
                                       rms(err[:n]), rtol=1e-7)
            np.testing.assert_allclose(ds.err_mean_rel.values[q, s, v, k, h],
                                       rms(err[:n]) / rms(np.sqrt(var[:n])), rtol=1e-7)


@pytest.mark.parametrize("q", [0, 1])
@pytest.mark.parametrize("s", [0, 1])
def test_verdicts_match_direct_comparisons(tiny, q, s):
    """Every verdict of a grid point against the paired estimates formed here from an
    independent ensemble (simulate_mc with the map's samples) and simulate_opa runs."""
    cfg, ds, _ = tiny
    value, sigma = cfg.values[q], cfg.sigmas[s]
    osc = cfg.oscillator.replace(omega=value)
    times = time_grid(value, max(cfg.horizons), cfg.per_period)
    ens = _design_ensemble(cfg, ds, q, s, times)
    runs = {(v, k): simulate_opa(osc, sigma=sigma, order=order, uncertain="mu",
                                 truncation=trunc, impact_law=law, times=times,
                                 options=cfg.options, partial=True)
            for v, (law, trunc) in enumerate(VARIANTS) for k, order in enumerate(cfg.orders)}
    _check_point(cfg, ds, q, s, ens, runs)


def test_the_tiny_map_has_all_three_verdicts(tiny):
    """So that the comparison above can fail every way."""
    _, ds, _ = tiny
    for c in range(2):
        a = ds.agrees.values[..., c]
        assert a.any() or c == 1
        assert not a.all()
    assert set(np.unique(ds.verdict.values[..., 0])) == {-1, 0, 1}


def test_sigma_star_brackets_the_verdicts_it_probed(tiny):
    cfg, ds, _ = tiny
    for q in range(len(cfg.values)):
        sig = ds.probe_sigma.values[q]
        ok = np.isfinite(sig)
        for v in range(len(VARIANTS)):
            for h in range(len(cfg.horizons)):
                lo = ds.sigma_star.values[q, v, h, 0]
                hi = ds.sigma_star_upper.values[q, v, h, 0]
                verdict = ds.probe_agrees.values[q, ok, v, h, 0]
                three = ds.probe_verdict.values[q, ok, v, h, 0]
                np.testing.assert_array_equal(verdict, np.where(three == -2, -1, three == 1))
                probed = sig[ok]
                if np.isfinite(hi):
                    assert hi - lo <= cfg.resolution + 1e-15
                    assert not verdict[probed == hi].any()
                    assert lo == 0 or verdict[probed == lo].all()
                else:  # agrees at every sigma tried
                    assert verdict.all() and lo == probed.max()


def test_netcdf_round_trip(tiny):
    _, ds, out = tiny
    with xr.open_dataset(out / "validate.nc") as back:
        back = back.load()
    assert set(back.data_vars) == set(ds.data_vars)
    for name in ds.data_vars:
        a, b = ds[name].values, back[name].values
        assert a.shape == b.shape, name
        if a.dtype.kind in "fc":
            np.testing.assert_array_equal(a, b, err_msg=name)
        else:
            assert (a == b).all(), name
    for name in ("parameter", "uncertain", "tolerance", "alpha", "resolution", "floor", "mu",
                 "rtol", "seed", "criterion_text"):
        assert back.attrs[name] == ds.attrs[name], name
    assert list(back.variant.values) == [f"{a}/{b}" for a, b in VARIANTS]


def test_the_map_dataset_explains_itself(tiny):
    """A grid dataset: no global sigma, N or swept-parameter value (they are coordinates);
    every dimension has a coordinate with a long_name, the time coordinate is called `time`
    as in the simulate datasets, and its values are the output times in forcing periods."""
    cfg, _, out = tiny
    with xr.open_dataset(out / "validate.nc") as back:
        back = back.load()
    for name in ("sigma", "N", "omega"):
        assert name not in back.attrs, name
    assert "periods" not in back.dims and "time" in back.dims
    for dim in back.dims:
        assert dim in back.coords, dim
        assert back[dim].attrs.get("long_name"), dim
    for name in ("sigma", "N", "omega", "time", "count", "probe", "split"):
        assert "units" in back[name].attrs, name
    np.testing.assert_allclose(back.time.values,
                               np.arange(back.sizes["time"]) / cfg.per_period)
    assert back.time.size == int(max(cfg.horizons) * cfg.per_period) + 1


def test_rerun_resumes_from_parts(tiny, monkeypatch):
    """A rerun of a finished map, frontier included, integrates nothing and gives the
    same dataset to the bit (apart from what describes the run itself)."""
    cfg, ds, out = tiny
    _forbid_integration(monkeypatch)
    again = run_validation(cfg, progress=False, log=lambda *a: None)
    assert again.attrs["mc_runs_computed"] == again.attrs["parts_computed"] == 0
    parts = [p for p in os.listdir(out / "parts") if p != "store.json"]
    assert ds.attrs["mc_runs_computed"] == len([p for p in parts if p.startswith("mc_")])
    assert ds.attrs["parts_computed"] == len(parts)
    assert any(p.startswith("frontier_") for p in parts)
    _same(again, ds)


def test_count_distribution_sums_to_one_and_matches_the_ensemble_range(tiny):
    _, ds, _ = tiny
    p = ds.count_prob.values
    np.testing.assert_allclose(p.sum(axis=-1), 1.0, atol=1e-12)
    # the fewest and the most impacts a Monte Carlo sample made up to the longest horizon
    # are counts the located splits give a positive probability (the samples need not
    # reach every count: a few have probabilities below 1 / samples)
    for q in range(ds.sizes[cfg_parameter(ds)]):
        for s in range(ds.sizes["sigma"]):
            assert p[q, s, -1, ds.mc_impacts_min.values[q, s]] > 0
            assert p[q, s, -1, ds.mc_impacts_max.values[q, s]] > 0
    assert (p[..., -1, :] > 0).sum(axis=-1).max() > 1  # some ensemble is split


def cfg_parameter(ds):
    return ds.attrs["parameter"]


def test_the_longer_horizons_locate_at_most_long_splits(tmp_path, monkeypatch):
    """The shortest horizon's scan may locate MAX_SPLITS, each longer one long_splits."""
    import compare._trustmap as trustmap
    from opa._splits import MAX_SPLITS

    cfg = load_config(None, outdir=str(tmp_path), **{**TINY, "horizons": (4, 8, 12)},
                      long_splits=5)
    limits = {}
    real_scan = trustmap.scan_splits

    def scan(*args, **kw):
        limits[round(args[5] / cfg.oscillator_at(3.98).forcing_period, 9)] = args[6].max_splits
        return real_scan(*args, **kw)

    monkeypatch.setattr(trustmap, "scan_splits", scan)
    trustmap.value_splits(cfg, Work(cfg.outdir), 3.98)
    assert limits == {12: 5, 8: 5, 4: MAX_SPLITS}


def test_each_horizon_bisects_with_runs_to_its_own_horizon(tmp_path, monkeypatch):
    """The split scans of one value: the longest horizon first, then the shorter one with
    runs to its own horizon (and the chatter window past it), not to the longest; each
    asked to be complete within every sigma. The longest horizon's scan is cut here (a
    limit of 8), so the shorter one bisects runs of its own: its splits are those of its
    scan alone, and the counts at the centre those of one run to the longest horizon."""
    import dataclasses

    import compare._trustmap as trustmap
    import opa._splits as splits

    cfg = load_config(None, outdir=str(tmp_path), **{**TINY, "horizons": (8, 12)})
    T = cfg.oscillator_at(3.98).forcing_period
    calls, ends = [], []
    real_scan, real_runs = trustmap.scan_splits, splits.event_sequences

    def scan(*args, **kw):
        calls.append((round(args[5] / T, 9), round(kw["runs"].t_end / T, 9),
                      args[6].needed_within))
        cut = dataclasses.replace(args[6], max_splits=8) if len(calls) == 1 else args[6]
        return real_scan(*args[:6], cut, *args[7:], **kw)

    def runs(system, options, parameter, values, t_end):
        ends.append((calls[-1][0], round(t_end / T, 9)))
        return real_runs(system, options, parameter, values, t_end)

    monkeypatch.setattr(trustmap, "scan_splits", scan)
    monkeypatch.setattr(splits, "event_sequences", runs)
    centre, scans = trustmap.value_splits(cfg, Work(cfg.outdir), 3.98)
    monkeypatch.undo()
    short = 8 + splits.CHATTER_WINDOW
    assert calls == [(12, 12, cfg.sigmas), (8, short, cfg.sigmas)]
    assert scans[1].truncated and not scans[0].truncated
    assert {end for h, end in ends if h == 12} == {12}
    assert {end for h, end in ends if h == 8} == {short}
    alone = splits.scan_splits(cfg.system_at(3.98), cfg.options, "mu", centre - 0.03,
                               centre + 0.03, 8 * T,
                               splits.ScanOptions(center=centre, tol=cfg.split_resolution * 0.01),
                               runs=splits.SampledRuns(cfg.system_at(3.98), cfg.options, "mu",
                                                       short * T))
    assert alone.splits
    assert ([(s.value, s.kind, s.left, s.right) for s in scans[0].splits
             if s.kind != "output crossing"]
            == [(s.value, s.kind, s.left, s.right) for s in alone.splits])
    run = splits.event_sequence(cfg.system_at(3.98), cfg.options, 12 * T)
    assert [scan.count for scan in scans] == [run.count(8 * T), run.count(12 * T)]


def test_sweep_dimension_is_named_after_the_parameter(tiny):
    _, ds, _ = tiny
    assert "omega" in ds.dims and "value" not in ds.dims
    np.testing.assert_array_equal(ds.omega.values, TINY["values"])


def test_report_files_and_tables(tiny):
    _, ds, out = tiny
    written = write_report(ds, str(out), plots=True, command="opa-mc validate (test)")
    for name in ("summary.md", "trust_map.png", "error_vs_N.png", "mean_vs_mc.png",
                 "variance.png", "phase.png"):
        assert str(out / name) in written
        assert os.path.getsize(out / name) > 0
    text = (out / "summary.md").read_text()
    assert "Trust boundary" in text and "opa-mc validate (test)" in text
    # the first line counts every kind of part the run computed, not only Monte Carlo
    a = ds.attrs
    assert (f"computed: {a['mc_runs_computed']} Monte Carlo runs, {a['opa_runs_computed']} "
            f"OPA runs, {a['parts_computed']} parts in all") in text
    assert a["parts_computed"] > a["mc_runs_computed"] > 0 and a["opa_runs_computed"] > 0


@pytest.mark.long  # the quick loop draws every figure in one process
def test_figures_drawn_on_two_processes_are_the_same_files(tiny, tmp_path):
    """``write_report(workers=2)`` draws the figures side by side on worker processes:
    the same PNG bytes as drawn in this process, in the same order, whether the workers
    receive the map or read it from its validate.nc (``source``)."""
    import hashlib

    from compare._report import draw_figures

    _, ds, out = tiny
    for name in ("one", "two", "file"):
        (tmp_path / name).mkdir()
    one = draw_figures(ds, str(tmp_path / "one"))
    two = draw_figures(ds, str(tmp_path / "two"), workers=2)
    read = draw_figures(ds, str(tmp_path / "file"), workers=2,
                        source=str(out / "validate.nc"))
    assert [os.path.basename(p) for p in one] == [os.path.basename(p) for p in two] \
        == [os.path.basename(p) for p in read]
    assert len(one) >= 5
    for a, b, c in zip(one, two, read):
        digest = hashlib.sha256(Path(a).read_bytes()).digest()
        assert digest == hashlib.sha256(Path(b).read_bytes()).digest(), a
        assert digest == hashlib.sha256(Path(c).read_bytes()).digest(), c


def test_config_errors_name_the_key(tmp_path):
    with pytest.raises(ValueError, match="sigmas must be strictly increasing"):
        load_config(None, sigmas=(0.02, 0.01))
    with pytest.raises(ValueError, match="samples must be a multiple of 16"):
        load_config(None, samples=100)
    with pytest.raises(ValueError, match="preset must be one of"):
        load_config(None, preset="3.4")
    with pytest.raises(ValueError, match="values are needed"):
        load_config(None, parameter="f")
    with pytest.raises(ValueError, match="long_splits must be >= 1, got 0"):
        load_config(None, long_splits=0)
    for key, value, message in (("alpha", "3", "alpha must be a number"),
                                ("alpha", 0.9, r"alpha \(the error rate of a verdict\) must "
                                 r"be in \[1e-9, 0.5\], got 0.9"),
                                ("z", 3.0, "config key z is gone"),
                                ("max_samples", "x", "max_samples must be an integer"),
                                ("outdir", 3, "outdir must be a non-empty string")):
        with pytest.raises(ValueError, match=message):
            load_config(None, **{key: value})
    bad = tmp_path / "bad.toml"
    bad.write_text("sigmas = [0.01,\n")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_config(str(bad))
    good = tmp_path / "good.toml"
    good.write_text('preset = "3.1"\nsigmas = [0.01, 0.02]\n[model]\nF0 = 0\n')
    cfg = load_config(str(good))
    assert cfg.parameter == "c" and cfg.oscillator.F0 == 0 and len(cfg.values) == 7


@pytest.mark.parametrize("argv, needle", [
    (["--sigmas", "0.02,0.01"], "sigmas"),
    (["--horizons", "0"], "horizons"),
    (["--sweep", "omega=4:3.9:0"], None),  # argparse: exits 2 on its own
    (["--tolerance", "-1"], "tolerance"),
    (["--long-splits", "0"], "--long-splits"),
])
def test_cli_bad_input_exits_2_with_one_line(argv, needle, tmp_path, capsys):
    if needle is None or needle.startswith("--"):  # argparse's own check
        with pytest.raises(SystemExit) as excinfo:
            main(["validate", "--outdir", str(tmp_path / "r"), *argv])
        assert excinfo.value.code == 2
    else:
        assert main(["validate", "--outdir", str(tmp_path / "r"), *argv]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if needle:
        assert needle in err and err.count("\n") == 1


def test_cli_refuses_an_unwritable_outdir_before_computing(tmp_path, capsys):
    target = tmp_path / "file"
    target.write_text("x")
    assert main(["validate", "--outdir", str(target)]) == 2
    assert "--outdir" in capsys.readouterr().err


# --------------------------------------------------------------------------- another law of
# xi and multi-element variants

LAW_TINY = dict(values=(3.98,), sigmas=(0.01, 0.03), orders=(0, 2), horizons=(4, 8),
                samples=64, max_samples=128, per_period=4, frontier=False,
                distribution="uniform", elements="adaptive", max_elements=8)


@pytest.fixture(scope="module")
def tiny_law(tmp_path_factory):
    out = tmp_path_factory.mktemp("validate_law")
    cfg = load_config(None, outdir=str(out), **LAW_TINY)
    ds = run_validation(cfg, progress=False, log=lambda *a: None)
    return cfg, ds, out


def test_law_and_element_variants_are_named_and_the_paper_truncation_dropped(tiny_law):
    cfg, ds, _ = tiny_law
    assert list(ds.variant.values) == [
        "mean/galerkin", "ensemble/galerkin", "saltation/galerkin", "mean/ME-adaptive8",
        "ensemble/ME-adaptive8", "saltation/ME-adaptive8"]
    assert ds.attrs["distribution"] == "uniform" and ds.attrs["elements"] == "adaptive"
    assert ds.attrs["variants_dropped"].startswith("mean/paper, ensemble/paper")
    assert ds.attrs["max_elements"] == 8 and ds.attrs["truncation"] == "galerkin"
    # multi-element variants run at N = Nmax only
    np.testing.assert_array_equal(ds.variant_ran.values, [[1, 1]] * 3 + [[0, 1]] * 3)
    assert np.isnan(ds.err_mean.values[:, :, 3:, 0]).all()
    assert not ds.agrees.values[:, :, 3:, 0].any()
    n = ds.variant_elements.values
    assert (n[..., :3] == 1).all() and ((n[..., 3:] >= 1) & (n[..., 3:] <= 8)).all()
    assert (n[..., 3:] > 1).any()
    # sigma* for every variant, the multi-element ones included
    assert np.isfinite(ds.sigma_star.values[:, 3:]).all()


def _opa_law(cfg, sigma, order, law, times, elements=None):
    import warnings

    osc = cfg.oscillator.replace(omega=cfg.values[0])
    kw = {} if elements is None else dict(elements=elements, max_elements=cfg.max_elements)
    with warnings.catch_warnings():  # the element budget may run out, as in the map
        warnings.simplefilter("ignore")
        return simulate_opa(osc, sigma=sigma, order=order, uncertain="mu",
                            distribution=cfg.distribution, impact_law=law,
                            allow_negative=True, times=times, options=cfg.options, **kw)


@pytest.mark.parametrize("s", [0, 1])
def test_law_and_element_verdicts_match_direct_comparisons(tiny_law, s):
    """The uniform law's Monte Carlo ensemble, its single-element OPA (in the Legendre
    basis) at every N and its adaptive multi-element OPA at N = Nmax, each judged here
    from simulate_opa and simulate_mc with the documented criterion."""
    cfg, ds, _ = tiny_law
    value, sigma = cfg.values[0], cfg.sigmas[s]
    times = time_grid(value, max(cfg.horizons), cfg.per_period)
    ens = _design_ensemble(cfg, ds, 0, s, times)
    cases = [(v, k, law, None) for v, law in enumerate(("mean", "ensemble", "saltation"))
             for k in range(len(cfg.orders))]
    cases += [(3 + v, len(cfg.orders) - 1, law, "adaptive")
              for v, law in enumerate(("mean", "ensemble", "saltation"))]
    runs = {}
    for v, k, law, elements in cases:
        runs[v, k] = _opa_law(cfg, sigma, cfg.orders[k], law, times, elements)
        if elements is not None:
            assert ds.variant_elements.values[0, s, v] == runs[v, k].attrs["elements"]
    _check_point(cfg, ds, 0, s, ens, runs)


def test_the_law_map_has_both_verdicts(tiny_law):
    _, ds, _ = tiny_law
    a = ds.agrees.values[:, :, :, -1, :, 0]
    assert a.any() and not a.all()


def test_law_map_counts_use_the_law_of_xi(tiny_law):
    """The impact-count distribution integrates the uniform law between the splits."""
    from compare._mapdata import count_distribution
    from opa._splits import Split

    _, ds, _ = tiny_law
    np.testing.assert_allclose(ds.count_prob.values.sum(axis=-1), 1.0, atol=1e-12)
    split = Split(value=0.8 + 0.5 * 0.02, tol=1e-9, kind="grazing", time=1.0, speed=1e-3,
                  left=3, right=4)
    uniform = count_distribution(0.8, 0.02, [split], 3, cdf=lambda x: (np.asarray(x) + 1) / 2)
    assert uniform == pytest.approx({3: 0.75, 4: 0.25})
    semicircle = count_distribution(0.8, 0.02, [split], 3)
    assert semicircle[4] == pytest.approx(1 / 3 - math.sqrt(3) / (4 * math.pi))


def test_semicircle_map_with_k_elements(tmp_path):
    """K equal-probability elements beside the paper's five variants; the K-element
    variant's mean is simulate_opa's."""
    cfg = load_config(None, outdir=str(tmp_path), values=(3.98,), sigmas=(0.02,),
                      orders=(1,), horizons=(4,), samples=64, max_samples=64, per_period=4,
                      frontier=False, elements=3)
    ds = run_validation(cfg, progress=False, log=lambda *a: None)
    names = [f"{a}/{b}" for a, b in VARIANTS] + [f"{law}/ME-K3" for law in
                                                 ("mean", "ensemble", "saltation")]
    assert list(ds.variant.values) == names and ds.attrs["variants_dropped"] == "none"
    times = time_grid(3.98, 4, 4)
    for v, law in enumerate(("mean", "ensemble", "saltation")):
        emr = simulate_opa(cfg.oscillator, sigma=0.02, order=1, impact_law=law, elements=3,
                           times=times, options=cfg.options)
        np.testing.assert_allclose(ds.opa_x_mean.values[0, 0, 5 + v, 0], emr.x_mean.values,
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(ds.opa_x_var.values[0, 0, 5 + v, 0], emr.x_var.values,
                                   rtol=0, atol=1e-12)
    assert (ds.variant_elements.values[..., 5:] == 3).all()


@pytest.mark.parametrize("kw, message", [
    (dict(distribution="triangle"), "distribution must be one of"),
    (dict(distribution="beta:0,1"), "distribution 'beta:0,1'"),
    (dict(distribution=3), "distribution must be a name"),
    (dict(elements=1), "elements must be an integer in 2..1024"),
    (dict(elements="many"), "elements must be an integer"),
    (dict(elements=True), "elements must be an integer"),
    (dict(max_elements=8), "max_elements = 8 .* no effect"),
    (dict(elements=4, max_elements=8), "no effect"),
    (dict(elements="adaptive", max_elements=1025), "max_elements must be an integer"),
])
def test_law_and_element_settings_are_checked(kw, message):
    with pytest.raises(ValueError, match=message):
        load_config(None, **kw)


def test_law_settings_from_toml(tmp_path):
    path = tmp_path / "law.toml"
    path.write_text('distribution = "beta:2,3"\nelements = "adaptive"\nmax_elements = 16\n')
    cfg = load_config(str(path))
    assert (cfg.distribution, cfg.elements, cfg.budget) == ("beta:2,3", "adaptive", 16)
    assert cfg.variants[-1] == "saltation/ME-adaptive16"
    assert load_config(None, distribution="beta:2.0,3").distribution == "beta:2,3"


def test_failed_elements_fall_back_to_collocation_as_in_simulate_opa():
    """At N = 8, saltation law, 4 uniform-law elements over 20 periods (sigma = 0.05) one
    element's OPA system diverges: the map's multi-element runs compute it by collocation
    of the true systems, as simulate_opa does, and say so; without the fallback it is NaN."""
    import warnings

    from compare._trustmap import element_variants
    from opa._elements import uniform_edges
    from opa._measure import parse
    from opa._model import SolverOptions, preset
    from opa._system import System

    osc, opts, law = preset("3.2"), SolverOptions(rtol=1e-9, atol=1e-9), parse("uniform")
    times = time_grid(osc.omega, 20, 4)
    system = System(osc, sigma=0.05, distribution="uniform", order=8, allow_negative=True)
    edges = [uniform_edges(law, 4)]
    run = element_variants(system, opts, law, ["saltation"], edges, times, fallback=True)
    assert run["collocated"][0] == 1 and run["elements"][0] == 4
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        emr = simulate_opa(osc, sigma=0.05, distribution="uniform", order=8,
                           impact_law="saltation", allow_negative=True, elements=4,
                           times=times, options=opts)
    np.testing.assert_allclose(run["x_mean"][0], emr.x_mean.values, rtol=0, atol=1e-14)
    np.testing.assert_allclose(run["x_var"][0], emr.x_var.values, rtol=0, atol=1e-14)
    bare = element_variants(system, opts, law, ["saltation"], edges, times)
    assert bare["collocated"][0] == 0 and np.isnan(bare["x_mean"][0, -1])


def test_report_of_a_law_map_with_elements(tiny_law):
    """The report names variants, not indices: the law map has no paper truncation, and
    its multi-element variants get variance columns, sigma* beside the single element's
    and causes of their own."""
    _, ds, out = tiny_law
    written = write_report(ds, str(out), plots=True, command="opa-mc validate (law test)")
    assert str(out / "error_vs_N.png") in written
    text = (out / "summary.md").read_text()
    assert "ξ ~ uniform" in text and "Variants left out: mean/paper, ensemble/paper" in text
    assert "σ* of the variance" in text and "| σ* saltation/ME-adaptive8 |" in text
    assert "σ* of multi-element OPA saltation/ME-adaptive8 (N = 2) is ω = 3.98:" in text
    assert "(one element: " in text and "paper's truncation (eq. (27))" not in text
    assert "(saltation law, ME-adaptive8)" in text


# -- figures: checked by their text extents, not by eye alone ------------------------------
def _drawn(monkeypatch, draw):
    """The figures a drawing function makes (pyplot.close held back), rendered."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.close("all")
    monkeypatch.setattr(plt, "close", lambda *a, **k: None)
    draw()
    figs = [plt.figure(n) for n in plt.get_fignums()]
    for fig in figs:
        fig.canvas.draw()
    monkeypatch.undo()
    return figs


def _boxes(texts, renderer):
    return [(t.get_text(), t.get_window_extent(renderer)) for t in texts
            if t.get_visible() and t.get_text().strip()]


def _overlaps(boxes):
    return [(a, b) for i, (a, ba) in enumerate(boxes) for b, bb in boxes[i + 1:]
            if ba.overlaps(bb) and ba.intersection(ba, bb).width > 0.5
            and ba.intersection(ba, bb).height > 0.5]


def _check_figure(fig, name):
    renderer = fig.canvas.get_renderer()
    page = fig.bbox
    plots = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            ticks = _boxes(axis.get_ticklabels(), renderer)
            assert not _overlaps(ticks), f"{name}: tick labels overlap: {_overlaps(ticks)}"
    for legend in fig.legends + [ax.get_legend() for ax in fig.axes if ax.get_legend()]:
        box = legend.get_window_extent(renderer)
        assert (box.x0 >= page.x0 - 1 and box.x1 <= page.x1 + 1 and box.y0 >= page.y0 - 1
                and box.y1 <= page.y1 + 1), f"{name}: a legend leaves the figure"
        for ax in plots:  # no legend covers a panel
            inter = box.intersection(box, ax.get_window_extent(renderer))
            assert inter is None or inter.width * inter.height < 1, \
                f"{name}: a legend covers the panel {ax.get_title()!r}"
    # every row of panels has a y label, every column an x label
    rows, cols = {}, {}
    for ax in plots:
        spec = ax.get_subplotspec()
        rows.setdefault(spec.rowspan.start, []).append(ax.get_ylabel())
        cols.setdefault(spec.colspan.start, []).append(ax.get_xlabel())
    assert all(any(labels) for labels in rows.values()), f"{name}: a row has no y label"
    assert all(any(labels) for labels in cols.values()), f"{name}: a column has no x label"
    # lines told apart by more than colour: (colour, dash, marker) differ per label
    for ax in plots:
        seen = {}
        for line in ax.get_lines():
            label = line.get_label()
            if label.startswith("_"):
                continue
            key = (str(line.get_color()), str(line.get_linestyle()), str(line.get_marker()),
                   str(line.get_dashes() if hasattr(line, "get_dashes") else ""))
            seen.setdefault(key, set()).add(label)
        same = [labels for labels in seen.values() if len(labels) > 1]
        assert not same, f"{name}: lines drawn alike: {same}"
        # and different labels are not drawn the same line style and marker in black
    # the panels' texts (titles, suptitle) do not run into each other
    titles = _boxes([ax.title for ax in plots] + ([fig._suptitle] if fig._suptitle else []),
                    renderer)
    assert not _overlaps(titles), f"{name}: titles overlap: {_overlaps(titles)}"
    texts = titles + _boxes([ax.xaxis.label for ax in fig.axes]
                            + [ax.yaxis.label for ax in fig.axes], renderer)
    for text, box in texts:  # nothing is cut off at the figure's edge
        assert (box.x0 >= page.x0 - 1 and box.x1 <= page.x1 + 1 and box.y0 >= page.y0 - 1
                and box.y1 <= page.y1 + 1), f"{name}: {text!r} leaves the figure"


FIGURES = ("plot_map", "plot_error_vs_order", "plot_mean", "plot_variance", "plot_phase")


@pytest.mark.parametrize("scale", [1.0, 0.6])
@pytest.mark.parametrize("name", FIGURES)
def test_figures_read_at_any_size(tiny, tmp_path, monkeypatch, name, scale):
    """Each figure, at its size and at 60 % of it: no tick labels overprint, legends stay in
    the figure and off the panels, every panel row and column is labelled, and no two
    labelled lines share colour, dash and marker."""
    from compare import _report

    _, ds, _ = tiny
    draw = getattr(_report, name)
    figs = _drawn(monkeypatch, lambda: draw(ds, str(tmp_path / f"{name}.png")))
    assert len(figs) == 1
    fig = figs[0]
    if scale != 1.0:
        w, h = fig.get_size_inches()
        figs = _drawn(monkeypatch, lambda: draw(ds, str(tmp_path / f"{name}.png"),
                                                size=(w * scale, h * scale)))
        fig = figs[0]
    _check_figure(fig, f"{name} at {scale:g}")


def test_trust_map_draws_both_verdicts_and_every_sigma_star(tiny, tmp_path, monkeypatch):
    """The map has a mean and a variance panel per horizon; each draws sigma* of every impact
    law as a visible (not white) line, and its colour bar marks the tolerance at 0."""
    from compare._mapfigures import plot_map

    _, ds, _ = tiny
    fig, = _drawn(monkeypatch, lambda: plot_map(ds, str(tmp_path / "m.png")))
    plots = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    assert len(plots) == 2 * ds.sizes["horizon"]
    titles = [ax.get_title() for ax in plots]
    assert sum(t.startswith("mean") for t in titles) == ds.sizes["horizon"]
    assert sum(t.startswith("variance") for t in titles) == ds.sizes["horizon"]
    from matplotlib.colors import to_rgb

    for ax in plots:
        stars = [ln for ln in ax.get_lines() if ln.get_label().startswith("σ* ")]
        assert {ln.get_label() for ln in stars} == {
            f"σ* {v}" for v in ("mean/galerkin", "ensemble/galerkin", "saltation/galerkin")}
        assert all(to_rgb(ln.get_color()) != (1.0, 1.0, 1.0) for ln in stars)
        assert ax.get_ylabel() in ("σ", "")
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert bars and all(any(np.allclose(ln.get_ydata(), 0) for ln in ax.get_lines())
                        for ax in bars)


def test_trust_map_marks_an_undecided_verdict_apart(tiny, tmp_path, monkeypatch):
    """Every undecided verdict at N = Nmax gets its own glyph at its grid point, in its
    panel only (one made undecided here besides those of the tiny map's capped ensembles);
    the certain ones keep theirs."""
    from compare._mapfigures import plot_map
    from compare._mapread import HEADLINE

    _, ds, _ = tiny
    ds = ds.copy(deep=True)
    ds.verdict.values[0, 0, HEADLINE, -1, 0, 0] = 0
    ds.agrees.values[0, 0, HEADLINE, -1, 0, 0] = 0
    fig, = _drawn(monkeypatch, lambda: plot_map(ds, str(tmp_path / "m.png")))
    values = ds[ds.attrs["parameter"]].values
    panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    for h in range(ds.sizes["horizon"]):
        for c, what in enumerate(("mean", "variance")):
            ax, = [a for a in panels
                   if a.get_title().startswith(f"{what}, H = {float(ds.horizon[h]):g} ")]
            want = {(float(values[q]), float(ds.sigma[s])) for q, s in
                    zip(*np.nonzero(ds.verdict.values[:, :, HEADLINE, -1, h, c] == 0))}
            got = {tuple(map(float, xy)) for col in ax.collections
                   if "undecided" in col.get_label() for xy in col.get_offsets()}
            crosses = {tuple(map(float, xy)) for col in ax.collections
                       if col.get_label().endswith("does not") for xy in col.get_offsets()}
            assert got == want and not got & crosses, (h, c)
    assert (3.98, 0.01) in {tuple(map(float, xy)) for col in panels[0].collections
                            if "undecided" in col.get_label() for xy in col.get_offsets()}


def test_trust_map_counts_further_splits_once_per_column(tiny, tmp_path, monkeypatch):
    """The splits beyond the first of each kind are one "+n" per column (they crowded the
    50-period rows as one count per kind), n their number within the largest sigma."""
    from compare._mapfigures import plot_map

    _, ds, _ = tiny
    fig, = _drawn(monkeypatch, lambda: plot_map(ds, str(tmp_path / "m.png")))
    values = ds[ds.attrs["parameter"]].values
    smax = float(ds.sigma.max())
    centre = float(ds.attrs[ds.attrs["uncertain"]])  # mu, not swept here
    seen = 0
    for h in range(ds.sizes["horizon"]):
        ax = [a for a in fig.axes if a.get_title().startswith(
            f"mean, H = {float(ds.horizon[h]):g} ")][0]
        counts = [t for t in ax.texts if t.get_text().startswith("+")]
        columns = [int(np.argmin(np.abs(values - t.xy[0]))) for t in counts]
        assert len(columns) == len(set(columns)), h
        kinds = ds.split_kind.attrs["flag_meanings"].split()
        for t, q in zip(counts, columns):
            kind = ds.split_kind.values[q, h]
            near = np.abs(ds.split_value.values[q, h] - centre) <= smax
            shown = (kind >= 0) & near & np.isin(kind, [k for k, n in enumerate(kinds)
                                                        if n != "horizon"])
            firsts = len(set(kind[shown].tolist()))
            assert t.get_text() == f"+{int(shown.sum()) - firsts}", (h, q)
            seen += 1
    assert seen  # the tiny map has columns with more splits than kinds

def test_single_value_map_has_sensible_limits(tiny, tmp_path, monkeypatch):
    """With one value of the swept parameter the x axis spans a few per cent around it and
    sigma* is still drawn (as a marker)."""
    from compare._mapfigures import plot_map

    _, ds, _ = tiny
    one = ds.isel(omega=[0])
    fig, = _drawn(monkeypatch, lambda: plot_map(one, str(tmp_path / "m.png")))
    value = float(one.omega[0])
    for ax in [a for a in fig.axes if a.get_label() != "<colorbar>"]:
        lo, hi = ax.get_xlim()
        assert lo < value < hi and hi - lo < 0.05 * value
        stars = [ln for ln in ax.get_lines() if ln.get_label().startswith("σ* ")]
        assert stars and all(ln.get_marker() not in ("", "None", None) for ln in stars)
    _check_figure(fig, "single-value map")


def test_runs_that_stop_carry_their_reason(tmp_path):
    """At sigma = 5 the paper's OPA runs escape: the map keeps going, opa_status names the
    kernel's reason exactly where the OPA curves turn NaN, the same reason a single
    simulate_opa run gives, and the first screen counts the runs by that reason."""
    from compare._findings import first_screen

    cfg = load_config(None, outdir=str(tmp_path), values=(3.98,), sigmas=(5.0,), orders=(2,),
                      horizons=(4,), samples=64, max_samples=64, per_period=4, plots=False,
                      frontier=False)
    ds = run_validation(cfg, progress=False, log=lambda *a: None)
    status = ds.opa_status
    names = dict(zip(status.attrs["flag_values"].tolist(), status.attrs["flag_meanings"].split()))
    stopped = np.isnan(ds.opa_x_mean.values).any(axis=-1)
    ran = status.values >= 0
    assert ((status.values > 0) == stopped)[ran].all()
    assert stopped.any() and (~stopped & ran).any()
    v = list(ds.variant.values).index("mean/galerkin")
    code = int(status.values[0, 0, v, 0])
    assert names[code] == "escaped"
    single = simulate_opa(cfg.system_at(3.98, sigma=5.0, order=2),
                          times=time_grid(3.98, 4, 4), options=cfg.options, partial=True)
    assert "escaped" in single.attrs["failure"]
    screen = "\n".join(first_screen(ds))
    assert "did not finish" in screen and "escaped" in screen


@pytest.mark.parametrize("distribution", ["semicircle", "uniform"])
def test_a_doubled_ensemble_equals_one_run_whole(tmp_path, distribution):
    """A round that doubles runs only the new Sobol' points (each replicate's sequence goes
    on) and gives, bit for bit, the ensemble run whole at that size."""
    import compare._trustmap as trustmap

    cfg = load_config(None, outdir=str(tmp_path), distribution=distribution, **TINY)
    work = Work(cfg.outdir)
    times = time_grid(3.98, max(cfg.horizons), cfg.per_period)
    design = trustmap.design(cfg, work, 3.98, 0.03, times)
    half = trustmap.ensemble(cfg, work, 3.98, 0.03, 64, times, design)
    grown = trustmap.ensemble(cfg, work, 3.98, 0.03, 128, times, design, previous=half)
    whole = trustmap.ensemble(cfg, work, 3.98, 0.03, 128, times, design)
    ledger = work.ledger()
    assert ledger.true_runs == 64 + 64 + 128  # the doubling ran only its new half
    assert ledger.mc_runs == 3
    for name in ("x", "xi", "weights", "impacts"):
        np.testing.assert_array_equal(grown[name], whole[name])
    assert grown["rhs"] == whole["rhs"]


def test_the_map_is_written_from_its_slices_without_holding_its_bulk(tmp_path, monkeypatch):
    """Each value's slice waits with its time series on disk (compare._mapdata.spill):
    the validate.nc written from them holds the map that the points' datasets joined in
    memory give (compare._mapdata.combine, one step over the whole grid), the scratch
    files are gone after it, and the dataset returned reads the time series from
    validate.nc as they are used instead of holding them."""
    import compare._trustmap as trustmap
    from compare._mapdata import STREAMED_DIM, combine

    got = []
    value_work = trustmap.value_work

    def keep(cfg, work, value, found=None):
        result = value_work(cfg, work, value, found)
        got.append(result)
        return result

    monkeypatch.setattr(trustmap, "value_work", keep)
    cfg = load_config(None, outdir=str(tmp_path),
                      **{**TINY, "frontier": False, "values": (3.98, 4.09)})
    ds = run_validation(cfg, progress=False, log=lambda *a: None)
    assert not (tmp_path / trustmap.SLICES).exists()
    whole = combine(cfg, [r["points"] for r in got], [r["value"] for r in got])
    with xr.open_dataset(tmp_path / "validate.nc") as back:
        back = back.rename({cfg.parameter: "value"})
        for name, variable in whole.variables.items():
            if variable.dtype.kind not in "OU":  # text: object in memory, <U from a file
                assert variable.dtype == back[name].dtype, name
            if variable.dtype.kind in "fc":
                assert np.array_equal(variable.values, back[name].values,
                                      equal_nan=True), name
            else:
                assert np.array_equal(variable.values, back[name].values), name
            attrs = back[name].attrs
            assert list(variable.attrs) == list(attrs), name
            assert all(np.array_equal(np.asarray(v), np.asarray(attrs[k]))
                       for k, v in variable.attrs.items()), name
    streamed = [n for n, v in ds.data_vars.items() if STREAMED_DIM in v.dims]
    assert "opa_x_mean" in streamed and "mc_x_mean" in streamed
    assert not any(ds[n].variable._in_memory for n in streamed)
    assert all(ds[n].variable._in_memory for n in ds.data_vars if n not in streamed)
    np.testing.assert_array_equal(ds.opa_x_mean[0, 1].values,
                                  whole.opa_x_mean[0, 1].values)


def test_spill_keeps_values_dtypes_and_attributes(tmp_path):
    """A slice's time series written to .npy files and read back lazily: the same
    dataset, its bulk no longer in memory; ``clear_slices`` removes the files."""
    from compare._mapdata import spill
    from compare._trustmap import clear_slices

    ds = xr.Dataset({"x": (("value", "time"), np.arange(6.0).reshape(1, 6), {"units": "1"}),
                     "n": (("value", "time"), np.arange(6).reshape(1, 6)),
                     "k": (("value",), np.array([7], np.int8), {"long_name": "k"})},
                    attrs={"slice_failures": ""})
    lazy = spill(ds, str(tmp_path / "slices"), "omega3.98")
    assert sorted(os.listdir(tmp_path / "slices")) == ["omega3.98_n.npy", "omega3.98_x.npy"]
    assert not lazy.x.variable._in_memory and lazy.k.variable._in_memory
    assert lazy.identical(ds) and lazy.n.dtype == ds.n.dtype
    assert clear_slices(str(tmp_path / "slices")) == ["omega3.98_n.npy", "omega3.98_x.npy"]
    assert not (tmp_path / "slices").exists()


def test_a_rerun_removes_the_slices_a_killed_map_left(tiny):
    """OUTDIR/slices is the map's scratch: what a killed run left there goes at the next
    start, and the folder once the map is written."""
    import compare._trustmap as trustmap

    cfg, _, out = tiny
    folder = out / trustmap.SLICES
    folder.mkdir(exist_ok=True)
    np.save(folder / "omega9_opa_x_mean.npy", np.zeros(3))
    lines = []
    run_validation(cfg, progress=False, log=lines.append)
    assert "slices: removed 1 file(s) an interrupted run left behind" in lines
    assert not folder.exists()


def test_bisection_probes_are_counted_beside_the_bar_not_in_its_total():
    """The bar's total is the grid's points, known up front; probes found by the
    bisections are a count beside it (the total used to grow from 3/3 to 6/6)."""
    import io

    from tqdm import tqdm

    from compare._ledger import Work

    with tqdm(total=4, file=io.StringIO()) as bar, tempfile.TemporaryDirectory() as tmp:
        job = Work(tmp, bar=bar)
        job.tick()
        job.tick()
        assert bar.total == 4 and bar.n == 0
        assert "probes=2" in bar.postfix
