"""The convergence study on a tiny configuration: its dataset against direct runs, the
slope and cost helpers on synthetic data, and the CLI."""

import numpy as np
import pytest
import xarray as xr

from compare._convergence import (
    ConvergenceConfig,
    cheapest_reaching,
    run_convergence,
    skipped_parts,
    slope,
    summary_lines,
    uniform_counts,
    write_report,
)
from mc import simulate_mc
from opa import simulate_opa
from opa.cli._main import main
from opa._model import time_grid

TINY = dict(sigma=0.02, periods=2, per_period=4, orders=(0, 1), uniform=(1, 2),
            budgets=(2, 4), order_budget=4, single_nodes=(1, 2), mc_samples=(64, 128),
            reference=1024)


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("conv")
    cfg = ConvergenceConfig(outdir=str(out), **TINY)
    return cfg, run_convergence(cfg, log=lambda *a: None), out


def test_rows_match_direct_runs(study):
    cfg, ds, _ = study
    times = time_grid(cfg.oscillator.omega, cfg.periods, cfg.per_period)
    ref = simulate_mc(cfg.oscillator, sigma=cfg.sigma, samples=cfg.reference,
                      sampler="sobol", seed=cfg.seed, order=0, times=times,
                      options=cfg.options, progress=False)
    i = int(np.flatnonzero((ds.method.values == "ME-OPA uniform") & (ds.law.values == "mean")
                           & (ds["size"].values == 2))[0])
    emr = simulate_opa(cfg.oscillator, sigma=cfg.sigma, order=cfg.order, elements=2,
                       impact_law="mean", times=times, options=cfg.options)
    err = float(np.sqrt(np.mean((emr.x_mean.values - ref.x_mean.values) ** 2)))
    assert ds.error.values[i] == pytest.approx(err, rel=1e-12)
    assert ds.rhs_evaluations.values[i] == emr.attrs["rhs_evaluations"]
    assert ds.node_rhs_evaluations.values[i] == 3 * emr.attrs["rhs_evaluations"]  # Q = 3
    assert ds.attrs["reference_sem"] == pytest.approx(
        float(np.sqrt(np.mean(ref.x_sem.values ** 2))))
    assert set(ds.method.values) >= {"ME-OPA uniform", "ME-OPA adaptive", "QMC (Sobol)", "MC",
                                     "ME-collocation uniform", "ME-collocation adaptive",
                                     "OPA (one element), N", "collocation (one element), Q"}


def _rms_errors(ref, mean, var):
    return (float(np.sqrt(np.mean((mean - ref.x_mean.values) ** 2))),
            float(np.sqrt(np.mean((np.sqrt(np.maximum(var, 0)) - np.sqrt(ref.x_var.values))
                                  ** 2))))


def test_ladder_rows_match_separate_ensembles(study):
    """The nested ladders: each rung of MC and Sobol' equals a separate simulate_mc run of
    that size at the ladder's seed (random; scrambled Sobol' with 16 replicates), its
    right-hand sides those of that run."""
    cfg, ds, _ = study
    times = time_grid(cfg.oscillator.omega, cfg.periods, cfg.per_period)
    ref = simulate_mc(cfg.oscillator, sigma=cfg.sigma, samples=cfg.reference,
                      sampler="sobol", seed=cfg.seed, order=0, times=times,
                      options=cfg.options, progress=False)
    for method, sampler in (("MC", "random"), ("QMC (Sobol)", "sobol")):
        rows = np.flatnonzero(ds.method.values == method)
        assert list(ds["size"].values[rows]) == list(cfg.mc_samples), method
        for i in rows:
            alone = simulate_mc(cfg.oscillator, sigma=cfg.sigma, samples=int(ds["size"][i]),
                                sampler=sampler, seed=cfg.seed + 1, order=0, times=times,
                                options=cfg.options, progress=False)
            err, sd = _rms_errors(ref, alone.x_mean.values, alone.x_var.values)
            assert ds.error.values[i] == pytest.approx(err, rel=1e-9), method
            assert ds.sd_error.values[i] == pytest.approx(sd, rel=1e-9), method
            assert ds.rhs_evaluations.values[i] == alone.attrs["rhs_evaluations"], method


def test_control_variate_rows_match_separate_stratified_ensembles(study):
    """Each control-variate rung equals a separate stratified ensemble of its size (the
    law cut at the splits, 16 replicates, compare._strata.replicate_points at the rung's
    scale) paired with the adaptive ME-OPA control, the estimate written out here: per
    replicate E_cv = E[x_hat] + sum w (x - x_hat), Var_cv = E[x_hat^2] + sum w (x^2 -
    x_hat^2) - E_cv^2, averaged over the replicates."""
    from compare._strata import build_strata, replicate_allocation, replicate_points, \
        split_values
    from opa.engine import surrogate, surrogate_moments, true_runs

    cfg, ds, _ = study
    times = time_grid(cfg.oscillator.omega, cfg.periods, cfg.per_period)
    ref = simulate_mc(cfg.oscillator, sigma=cfg.sigma, samples=cfg.reference,
                      sampler="sobol", seed=cfg.seed, order=0, times=times,
                      options=cfg.options, progress=False)
    with pytest.warns(UserWarning):  # tolerance 1e-14: the element budget stops it
        control = simulate_opa(cfg.oscillator, sigma=cfg.sigma, order=cfg.order,
                               elements="adaptive", tolerance=1e-14,
                               max_elements=cfg.order_budget, impact_law="saltation",
                               times=times, options=cfg.options)
    moments = surrogate_moments(control)
    system = cfg.system.replace(order=0)
    measure = cfg.system.measure
    first = min(cfg.mc_samples)
    split_xi, complete = split_values(system, cfg.options, measure, times[-1])
    strata = build_strata(measure, [measure.lo, measure.hi], split_xi, complete=complete,
                          max_strata=max(1, first // 16 // 2))
    allocation = replicate_allocation(first // 16, strata.probability)
    rows = np.flatnonzero(ds.method.values == f"control variate (ME-OPA K={cfg.order_budget})")
    assert list(ds["size"].values[rows]) == list(cfg.mc_samples)
    for i in rows:
        m = int(ds["size"].values[i])
        xi, w, _ = replicate_points(measure, strata, allocation, 16, cfg.seed + 1, m // first)
        x = true_runs(system, cfg.options, xi, times, what="test")[0][:, :, 0]
        h = surrogate(control, xi)[0]
        w, x, h = w.reshape(16, -1, 1), x.reshape(16, -1, len(times)), \
            h.reshape(16, -1, len(times))
        mean_r = moments["x_mean"] + (w * (x - h)).sum(1)
        var_r = moments["x_second"] + (w * (x**2 - h**2)).sum(1) - mean_r**2
        err, sd = _rms_errors(ref, mean_r.mean(0), var_r.mean(0))
        assert ds.error.values[i] == pytest.approx(err, rel=1e-9)
        assert ds.sd_error.values[i] == pytest.approx(sd, rel=1e-9)


def test_the_run_list_is_what_the_study_runs(study, monkeypatch):
    """study_runs lists exactly the runs the study performs (each once), and the two
    ladders run max(mc_samples) true systems each: the true systems the kernel is asked
    for, counted here, are the reference's, the collocation rows' and the ladders'."""
    import compare._convergence as C

    cfg, ds, _ = study
    performed, true_systems = [], {}
    real_runs = C.true_runs

    def counted(system, options, xi, times, *, what, **kw):
        true_systems[what] = true_systems.get(what, 0) + len(xi)
        return real_runs(system, options, xi, times, what=what, **kw)

    def memo(name, spec, compute):
        performed.append(name)
        results[name] = compute()
        return results[name]

    results = {}
    monkeypatch.setattr(C, "true_runs", counted)
    again = run_convergence(cfg, log=lambda *a: None, write=False, memo=memo)
    listed = [run.name for run in C.study_runs(cfg, results)]
    assert sorted(performed) == sorted(listed) and len(set(performed)) == len(performed)
    assert sum(name.startswith("ME-collocation-adaptive") for name in listed) == len(
        cfg.budgets)  # named once the adaptive runs' edges were known
    most = max(cfg.mc_samples)
    assert true_systems == {"random ladder sample": most, "sobol ladder sample": most,
                            "control-variate sample": most}
    np.testing.assert_array_equal(again.error.values, ds.error.values)


def test_a_control_variate_reference_agrees_with_plain_sobol(tmp_path):
    """reference_method="control": the reference is compare.verify of the adaptive
    ME-OPA control at the reference's seed; it agrees with an independent 2^14-sample
    Sobol ensemble within 4 joint standard errors at every output, with a smaller
    standard error from 1024 true systems."""
    cfg = ConvergenceConfig(outdir=str(tmp_path), reference_method="control",
                            **{**TINY, "budgets": (4,), "uniform": (1,), "orders": (1,)})
    ds = run_convergence(cfg, log=lambda *a: None, write=False)
    times = time_grid(cfg.oscillator.omega, cfg.periods, cfg.per_period)
    plain = simulate_mc(cfg.oscillator, sigma=cfg.sigma, samples=2**14, sampler="sobol",
                        seed=99, order=0, times=times, options=cfg.options, progress=False)
    i = int(np.flatnonzero((ds.method.values == "ME-OPA uniform") & (ds.law.values == "mean")
                           & (ds["size"].values == 1))[0])
    emr = simulate_opa(cfg.oscillator, sigma=cfg.sigma, order=cfg.order, elements=1,
                       impact_law="mean", times=times, options=cfg.options)
    # the row's error against the reference and against the plain ensemble differ by
    # at most the two references' difference, within their noise
    direct = float(np.sqrt(np.mean((emr.x_mean.values - plain.x_mean.values) ** 2)))
    assert abs(ds.error.values[i] - direct) <= 4 * float(np.sqrt(np.mean(
        plain.x_sem.values**2))) + 4 * ds.attrs["reference_sem"]
    assert ds.attrs["reference_sem"] < float(np.sqrt(np.mean(plain.x_sem.values**2)))
    assert ds.attrs["reference_method"] == "control"
    assert summary_lines(ds)[0].startswith("Reference: the control-variate estimate from "
                                           "1024 true systems")
    with pytest.raises(ValueError, match="power of two"):
        ConvergenceConfig(reference_method="control", reference=3000)
    with pytest.raises(ValueError, match="reference_method"):
        ConvergenceConfig(reference_method="quad")


def test_without_a_control_the_reference_is_plain_sobol(tmp_path, monkeypatch):
    """A control run that cannot serve (here: its certificate refused) leaves the plain
    Sobol reference of PLAIN_REFERENCE samples, said in the log and the attributes."""
    import compare._convergence as C

    real = C.verify

    def refuse_the_reference(run, *, samples, **kw):
        if samples == 1024:
            raise ValueError("refused for the test")
        return real(run, samples=samples, **kw)

    monkeypatch.setattr(C, "verify", refuse_the_reference)
    monkeypatch.setattr(C, "PLAIN_REFERENCE", 2048)
    cfg = ConvergenceConfig(outdir=str(tmp_path), reference_method="control",
                            **{**TINY, "budgets": (4,), "uniform": (1,), "orders": (1,)})
    lines = []
    ds = run_convergence(cfg, log=lines.append, write=False)
    assert any("refused for the test" in line and "2048 Sobol samples" in line
               for line in lines)
    assert ds.attrs["reference_method"] == "sobol" and ds.attrs["reference_samples"] == 2048
    times = time_grid(cfg.oscillator.omega, cfg.periods, cfg.per_period)
    ref = simulate_mc(cfg.oscillator, sigma=cfg.sigma, samples=2048, sampler="sobol",
                      seed=cfg.seed, order=0, times=times, options=cfg.options,
                      progress=False)
    assert ds.attrs["reference_sem"] == pytest.approx(
        float(np.sqrt(np.mean(ref.x_sem.values ** 2))))


def test_round_trip_and_report(study):
    _, ds, out = study
    with xr.open_dataset(out / "convergence.nc") as back:
        np.testing.assert_array_equal(back.error.values, ds.error.values)
        assert list(back.method.values) == list(ds.method.values)
    from compare._mapfigures import plot_frontier

    written = write_report(ds, str(out), draw=plot_frontier, command="opa-mc converge (test)")
    assert all((out / p.split("/")[-1]).exists() for p in written)
    assert summary_lines(ds)[0].startswith("Reference: 1024 Sobol samples")


def _synthetic(errors, sizes, rhs):
    n = len(errors)
    return xr.Dataset({
        "method": ("run", np.array(["ME-OPA adaptive"] * n, dtype=object)),
        "law": ("run", np.array(["saltation"] * n, dtype=object)),
        "size": ("run", np.array(sizes)), "error": ("run", np.array(errors)),
        "rhs_evaluations": ("run", np.array(rhs)),
    })


def test_slope_and_cheapest_on_synthetic_data():
    k = np.array([2, 4, 8, 16, 32])
    ds = _synthetic(3.0 * k ** -1.5, k, 1000 * k)
    assert slope(ds, "ME-OPA adaptive", "saltation") == pytest.approx(-1.5, abs=1e-12)
    i = cheapest_reaching(ds, "ME-OPA adaptive", 0.1, "saltation")
    assert ds["size"].values[i] == 16  # 3 * 8^-1.5 = 0.133 > 0.1 >= 3 * 16^-1.5 = 0.047
    assert cheapest_reaching(ds, "ME-OPA adaptive", 1e-9, "saltation") is None


def test_converge_cli_refuses_bad_input(tmp_path, capsys):
    assert main(["converge", "--sigma", "-1", "--outdir", str(tmp_path / "c")]) == 2
    assert "sigma" in capsys.readouterr().err
    target = tmp_path / "f"
    target.write_text("")
    assert main(["converge", "--outdir", str(target)]) == 2
    assert "--outdir" in capsys.readouterr().err


def test_uncertain_c_rows_match_direct_runs(tmp_path):
    """The study with the uncertainty on c (c = 0.05 + sigma xi): its reference and its
    two-element OPA row against simulate_mc and simulate_opa run here with uncertain='c'."""
    cfg = ConvergenceConfig(outdir=str(tmp_path), uncertain="c",
                            **{**TINY, "budgets": (2,), "orders": (1,), "mc_samples": (64,),
                               "single_nodes": (1,)})
    ds = run_convergence(cfg, log=lambda *a: None, write=False)
    assert ds.attrs["uncertain"] == "c"
    times = time_grid(cfg.oscillator.omega, cfg.periods, cfg.per_period)
    ref = simulate_mc(cfg.oscillator, sigma=cfg.sigma, uncertain="c", samples=cfg.reference,
                      sampler="sobol", seed=cfg.seed, order=0, times=times,
                      options=cfg.options, progress=False)
    mu = simulate_mc(cfg.oscillator, sigma=cfg.sigma, samples=cfg.reference,
                     sampler="sobol", seed=cfg.seed, order=0, times=times,
                     options=cfg.options, progress=False)
    assert np.abs(ref.x_var.values - mu.x_var.values).max() > 0  # c, not mu, is uncertain
    for law in ("mean", "saltation"):
        i = int(np.flatnonzero((ds.method.values == "ME-OPA uniform") & (ds.law.values == law)
                               & (ds["size"].values == 2))[0])
        emr = simulate_opa(cfg.oscillator, sigma=cfg.sigma, order=cfg.order, uncertain="c",
                           elements=2, impact_law=law, times=times, options=cfg.options)
        err = float(np.sqrt(np.mean((emr.x_mean.values - ref.x_mean.values) ** 2)))
        assert ds.error.values[i] == pytest.approx(err, rel=1e-12)


def test_the_study_on_worker_processes_has_the_same_rows(study):
    """workers=2: the study's runs as tasks (compare._scaleout), the adaptive collocation
    rows after the adaptive runs whose edges they take; every row as in one process."""
    cfg, ds, _ = study
    lines = []
    pooled = run_convergence(cfg, log=lines.append, write=False, workers=2)
    assert any("runs of the study as tasks" in line for line in lines)
    assert list(pooled.method.values) == list(ds.method.values)
    assert list(pooled.law.values) == list(ds.law.values)
    for name in ("size", "order", "error", "sd_error", "rhs_evaluations",
                 "node_rhs_evaluations"):
        np.testing.assert_array_equal(pooled[name].values, ds[name].values, err_msg=name)
    assert pooled.attrs["reference_sem"] == ds.attrs["reference_sem"]


def test_the_study_on_a_dask_cluster_has_the_same_rows(study):
    distributed = pytest.importorskip("distributed")
    cfg, ds, _ = study
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        there = run_convergence(cfg, log=lambda *a: None, write=False,
                                scheduler=cluster.scheduler_address)
    assert list(there.method.values) == list(ds.method.values)
    for name in ("size", "error", "sd_error", "rhs_evaluations"):
        np.testing.assert_array_equal(there[name].values, ds[name].values, err_msg=name)


def test_the_log_goes_inside_the_execution_record(tmp_path):
    """run_convergence takes where it runs and its log as one opa.Execution; the keyword
    ``log`` beside it, or one it never took, is refused before any run."""
    from opa import Execution

    cfg = ConvergenceConfig(outdir=str(tmp_path))
    with pytest.raises(ValueError, match=r"give log inside execution="):
        run_convergence(cfg, execution=Execution(), log=print)
    with pytest.raises(ValueError, match=r"give workers inside execution="):
        run_convergence(cfg, execution=Execution(), workers=2)
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'progress'"):
        run_convergence(cfg, progress=False)


# --------------------------------------------------------------- several uncertain parameters
TWO = dict(uncertain="mu,c", sigma=(0.016, 0.005), distribution="semicircle,uniform",
           periods=4, per_period=8, orders=(0, 1, 2), uniform=(1, 2), budgets=(4, 8),
           order_budget=8, mc_samples=(256, 1024), reference=4096)
#: the rows a study of several parameters has (docs/several.md, "Convergence")
SEVERAL_METHODS = {"ME-OPA uniform", "ME-OPA adaptive", "ME-OPA adaptive, N",
                   "OPA (one element), N", "MC", "QMC (Sobol)"}


@pytest.fixture(scope="module")
def study_two(tmp_path_factory):
    cfg = ConvergenceConfig(outdir=str(tmp_path_factory.mktemp("conv2")), **TWO)
    lines = []
    return cfg, run_convergence(cfg, log=lines.append, write=False), lines


def test_two_parameters_rows_names_and_costs(study_two):
    """d = 2 (mu semicircle, c uniform): the rows are those documented, collocation and
    the control-variate ladder are left out and said so (log, dataset, report); the
    costs grow with K, the budget, N (node right-hand sides) and M; an OPA row's node
    right-hand sides are its right-hand sides times its cubature's nodes."""
    cfg, ds, lines = study_two
    assert set(ds.method.values) == SEVERAL_METHODS
    assert ds.attrs["uncertain"] == "mu,c" and ds.attrs["distribution"] == "semicircle,uniform"
    for said in (ds.attrs["skipped"], "\n".join(lines), "\n".join(summary_lines(ds))):
        said = said.lower()
        assert "collocation" in said and "control-variate ladder" in said
        assert "one uncertain parameter" in said
    assert np.isfinite(ds.error.values).all() and ds.attrs["failures"] == 0
    for method in ("ME-OPA uniform", "ME-OPA adaptive", "MC", "QMC (Sobol)"):
        for law in ("mean", "saltation", "true system"):
            idx = np.flatnonzero((ds.method.values == method) & (ds.law.values == law))
            assert np.all(np.diff(ds["size"].values[idx]) > 0)
            assert np.all(np.diff(ds.rhs_evaluations.values[idx]) > 0), (method, law)
    one = np.flatnonzero(ds.method.values == "OPA (one element), N")
    assert np.all(np.diff(ds.node_rhs_evaluations.values[one][:3]) > 0)  # N = 0, 1, 2
    times = time_grid(cfg.oscillator.omega, cfg.periods, cfg.per_period)
    i = int(np.flatnonzero((ds.method.values == "ME-OPA uniform")
                           & (ds.law.values == "saltation") & (ds["size"].values == 2))[0])
    boxes = simulate_opa(cfg.system.replace(impact_law="saltation"), elements=2, times=times,
                         options=cfg.options)
    assert boxes.attrs["elements"] == 4  # K = 2 per parameter: 2^2 boxes
    assert ds.rhs_evaluations.values[i] == boxes.attrs["rhs_evaluations"]
    assert ds.node_rhs_evaluations.values[i] == (boxes.attrs["rhs_evaluations"]
                                                 * boxes.attrs["nodes"])


def test_two_parameters_box_errors_fall_with_k(study_two):
    """The uniform boxes' errors fall from K = 1 to K = 2 against the study's reference,
    and so do those computed here against an independent plain simulate_mc (2^14 Sobol
    samples, another seed); both references give the rows' errors within their
    difference."""
    cfg, ds, _ = study_two
    times = time_grid(cfg.oscillator.omega, cfg.periods, cfg.per_period)
    alone = simulate_mc(cfg.system.replace(order=0), samples=2**14, sampler="sobol",
                        seed=7, times=times, options=cfg.options, progress=False)
    for law in ("mean", "saltation"):
        idx = np.flatnonzero((ds.method.values == "ME-OPA uniform") & (ds.law.values == law))
        assert list(ds["size"].values[idx]) == [1, 2]
        assert ds.error.values[idx[1]] < 0.7 * ds.error.values[idx[0]], law
        mine = []
        for k in (1, 2):
            run = simulate_opa(cfg.system.replace(impact_law=law), elements=k, times=times,
                               options=cfg.options)
            mine.append(float(np.sqrt(np.mean((run.x_mean.values - alone.x_mean.values)
                                              ** 2))))
        assert mine[1] < 0.7 * mine[0], law
        np.testing.assert_allclose(ds.error.values[idx], mine, atol=2e-5)


def test_two_parameters_refusals_and_the_boxes_left_out():
    """The System's checks refuse sigma or laws of the wrong count; a K whose K^d boxes
    pass MAX_BOXES (4096) is left out and said, without running anything."""
    with pytest.raises(ValueError, match=r"sigma must give one value, or one per uncertain "
                                         r"parameter \(2\), got 3"):
        ConvergenceConfig(uncertain="mu,c", sigma=(0.1, 0.2, 0.3))
    with pytest.raises(ValueError, match=r"distribution must give one value"):
        ConvergenceConfig(uncertain="mu,c", sigma=(0.01, 0.005),
                          distribution="semicircle,uniform,uniform")
    with pytest.raises(ValueError, match=r"sigma must be > 0"):
        ConvergenceConfig(uncertain="mu,c", sigma=(0.01, 0.0))
    cfg = ConvergenceConfig(uncertain="mu,c", sigma=(0.016, 0.005), uniform=(1, 64, 65))
    assert uniform_counts(cfg) == [1, 64]
    assert any("K = 65 skipped: K^2 boxes is more than 4096" in line
               for line in skipped_parts(cfg))
    assert skipped_parts(ConvergenceConfig()) == []  # one parameter: the whole study
