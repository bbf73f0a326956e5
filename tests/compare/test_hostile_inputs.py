"""A hostile corpus for compare's entry points (issue 45, items 3 and 4).

Every public function of ``compare`` that takes a dataset a user may hand in
(``compare_runs``, ``error_metrics``, ``verify`` and the report's entry points on a
validate.nc read back) is fed broken inputs: NaN and inf in each variable it reads,
negative standard errors, nonsense keywords, missing attributes and variables, the old
``periods`` coordinate, and a dataset of the wrong kind. Each must be refused with one
ValueError whose message names the culprit and the dataset, never a KeyError, an
AttributeError or a result computed from NaN. The NaNs the data contracts document
(a Gauss quadrature's standard errors, a run that stopped, the trust map's curves after
a stop marked by ``opa_status``, the old ``periods`` name in the report) stay accepted.
The checks themselves live in ``compare._inputs``.

No ``opa-mc`` command reads a dataset file named on its command line (``simulate``,
``validate``, ``converge``, ``bifurcation``, ``reproduce``, ``stability`` and
``stochastic`` compute their own), so none of these cases is reachable from the CLI.
"""

import re

import numpy as np
import pytest
import xarray as xr

from compare import compare_runs, error_metrics, verify
from compare import _report as R
from mc import simulate_mc
from opa import Oscillator, simulate_opa

OSC = Oscillator()
KW = dict(sigma=0.01, order=2, periods=1, per_period=4)
TIMES = 5  # outputs of KW's runs: 1 period x 4 per period + t = 0


@pytest.fixture(scope="module")
def runs():
    """A one-element OPA run, a two-element one, a random ensemble and a Gauss
    quadrature of the same system, on the same five outputs."""
    one = simulate_opa(OSC, **KW)
    two = simulate_opa(OSC, elements=2, **KW)
    ens = simulate_mc(OSC, samples=16, sampler="random", seed=0, progress=False, **KW)
    quad = simulate_mc(OSC, samples=4, sampler="gauss", progress=False, **KW)
    assert one.sizes["time"] == ens.sizes["time"] == TIMES
    return {"opa": one, "opa2": two, "mc": ens, "gauss": quad}


@pytest.fixture(scope="module")
def trust_map(smallest_trust_map):
    """The smallest trust map (tests/compare/conftest.py), a copy of its own."""
    return smallest_trust_map.copy(deep=True)


def spoil(ds: xr.Dataset, name: str, value, index: int = 1) -> xr.Dataset:
    """A copy of ``ds`` with the flat element ``index`` of ``name`` set to ``value``."""
    out = ds.copy(deep=True)
    values = np.array(out[name].values, dtype=float)
    values.flat[index] = value
    out[name] = (out[name].dims, values, out[name].attrs)
    return out


def without_attr(ds: xr.Dataset, name: str) -> xr.Dataset:
    out = ds.copy()
    out.attrs = {k: v for k, v in ds.attrs.items() if k != name}
    return out


# ------------------------------------------------------------------ compare_runs: values
OPA_VALUES = [("opa", v) for v in ("x_mean", "x_var", "x_coef")] + \
             [("opa2", v) for v in ("x_mean", "element_x_coef", "element_edges",
                                    "element_probability")]
MC_VALUES = [("mc", v) for v in ("x_mean", "x_var", "x_coef", "x_sem", "x_var_sem",
                                 "x_coef_sem")] + [("gauss", "x_mean"), ("gauss", "x_coef")]


@pytest.mark.parametrize("bad", [np.nan, np.inf], ids=["nan", "inf"])
@pytest.mark.parametrize("run, name", OPA_VALUES + MC_VALUES,
                         ids=[f"{r}-{v}" for r, v in OPA_VALUES + MC_VALUES])
def test_compare_runs_refuses_non_finite_values(runs, run, name, bad):
    side = "mc" if run in ("mc", "gauss") else "opa"
    args = {"opa": runs["opa2" if run == "opa2" else "opa"],
            "mc": runs["gauss" if run == "gauss" else "mc"]}
    args[side] = spoil(args[side], name, bad)
    size = args[side][name].size
    with pytest.raises(ValueError, match=rf"the {side} dataset's {name} has 1 non-finite "
                                         rf"value of {size}\b"):
        compare_runs(args["opa"], args["mc"])


@pytest.mark.parametrize("name", ["x_sem", "x_var_sem", "x_coef_sem"])
@pytest.mark.parametrize("run", ["mc", "gauss"])
def test_compare_runs_refuses_negative_standard_errors(runs, run, name):
    with pytest.raises(ValueError, match=rf"the mc dataset's {name} is negative at 1 "
                                         rf"output\b"):
        compare_runs(runs["opa"], spoil(runs[run], name, -1e-3))


def test_a_quadratures_nan_standard_errors_are_accepted(runs):
    """docs/datasets.md: a Gauss quadrature has no sampling error, its *_sem are NaN; the
    band is then the floor alone."""
    quad = runs["gauss"]
    assert np.isnan(quad.x_sem.values).all()
    cmp = compare_runs(runs["opa"], quad, floor=1e-7)
    assert np.isnan(cmp.mc_sem.values).all()
    within = (np.abs(cmp.err_mean.values) <= 1e-7).astype(np.int8)
    np.testing.assert_array_equal(cmp.within_noise.values, within)


def _stopped(run: xr.Dataset, at: int) -> xr.Dataset:
    """``run`` as ``simulate_opa(partial=True)`` returns one that stopped before output
    ``at``: NaN from there on, the reason in ``attrs["failure"]``."""
    out = run.copy(deep=True)
    for name, var in out.data_vars.items():
        if "time" in var.dims and var.dtype.kind == "f":
            var.values[..., at:] = np.nan
    out.attrs["failure"] = "the OPA system's mean grazes the wall (test)"
    return out


def test_a_run_that_stopped_is_compared_up_to_its_stop(runs):
    """simulate_opa(partial=True) documents NaN after the stop: compared where it ran."""
    cmp = compare_runs(_stopped(runs["opa"], 3), runs["mc"])
    assert np.isfinite(cmp.err_mean.values[:3]).all()
    assert np.isnan(cmp.err_mean.values[3:]).all()
    np.testing.assert_allclose(cmp.err_mean.values[:3], runs["opa"].x_mean.values[:3]
                               - runs["mc"].x_mean.values[:3], rtol=0, atol=1e-15)


def test_a_nan_before_the_stop_is_refused(runs):
    """Only the tail after the stop is documented NaN: a hole before it is not."""
    broken = spoil(_stopped(runs["opa"], 3), "x_var", np.nan, index=1)
    with pytest.raises(ValueError, match=r"the opa dataset's x_var has 1 non-finite value "
                                         r"of 5 before the run stopped"):
        compare_runs(broken, runs["mc"])


# ------------------------------------------------------------------ keywords
@pytest.mark.parametrize("keyword, value", [
    ("z", float("nan")), ("z", -1.0), ("z", float("inf")), ("z", "3"), ("z", True),
    ("floor", float("nan")), ("floor", -1e-9), ("floor", float("inf")), ("floor", None),
])
def test_compare_runs_refuses_nonsense_keywords(runs, keyword, value):
    with pytest.raises(ValueError, match=rf"^{keyword} must be a finite number >= 0, got "
                                         rf"{re.escape(repr(value))}$"):
        compare_runs(runs["opa"], runs["mc"], **{keyword: value})


@pytest.mark.parametrize("keyword, value", [
    ("window_periods", float("nan")), ("window_periods", -1.0), ("window_periods", 0.0),
    ("window_periods", "2"), ("until", float("nan")), ("until", "1"),
])
def test_error_metrics_refuses_nonsense_keywords(runs, keyword, value):
    cmp = compare_runs(runs["opa"], runs["mc"])
    with pytest.raises(ValueError, match=rf"^{keyword} must be .*got "
                                         rf"{re.escape(repr(value))}$"):
        error_metrics(cmp, **{keyword: value})


@pytest.mark.parametrize("keyword, value", [
    ("tolerance", float("nan")), ("var_tolerance", float("nan")), ("var_tolerance", -0.1),
    ("tolerance", float("inf")), ("alpha", float("nan")), ("alpha", 0.9),
])
def test_verify_refuses_nonsense_keywords(runs, keyword, value):
    with pytest.raises(ValueError, match=rf"^{keyword} must be a finite number in .*got "
                                         rf"{re.escape(repr(value))}$"):
        verify(runs["opa"], samples=64, **{keyword: value})


# ------------------------------------------------------------------ missing attributes
def test_compare_runs_needs_the_forcing_frequency(runs):
    with pytest.raises(ValueError, match=r"the opa dataset lacks the attribute omega"):
        compare_runs(without_attr(runs["opa"], "omega"), without_attr(runs["mc"], "omega"))


@pytest.mark.parametrize("side, name", [("mc", "sigma"), ("opa", "uncertain"),
                                        ("mc", "impulse_at_zero")])
def test_compare_runs_names_an_attribute_one_run_lacks(runs, side, name):
    args = dict(opa=runs["opa"], mc=runs["mc"])
    args[side] = without_attr(args[side], name)
    other = "opa" if side == "mc" else "mc"
    with pytest.raises(ValueError, match=rf"the {side} dataset lacks the attribute {name} "
                                         rf"\(.* in the {other} dataset\)"):
        compare_runs(args["opa"], args["mc"])


def test_compare_runs_names_an_attribute_that_is_not_a_number(runs):
    with pytest.raises(ValueError, match=r"the mc dataset's attribute omega = 'fast' is "
                                         r"not a finite number"):
        compare_runs(runs["opa"], runs["mc"].assign_attrs(omega="fast"))


def test_error_metrics_needs_the_forcing_frequency(runs):
    cmp = compare_runs(runs["opa"], runs["mc"])
    with pytest.raises(ValueError, match=r"cmp lacks the attribute omega"):
        error_metrics(without_attr(cmp, "omega"))


@pytest.mark.parametrize("name", ["sigma", "omega", "uncertain", "rtol", "impulse",
                                  "impulse_at_zero"])
def test_verify_names_a_missing_attribute(runs, name):
    with pytest.raises(ValueError, match=rf"the run lacks the attribute {name}\b"):
        verify(without_attr(runs["opa"], name), samples=64)


@pytest.mark.parametrize("name, value", [("sigma", float("nan")), ("omega", float("inf")),
                                         ("rtol", float("nan"))])
def test_verify_names_a_non_finite_attribute(runs, name, value):
    with pytest.raises(ValueError, match=rf"\b{name}\b.*{value!r}"):
        verify(runs["opa"].assign_attrs({name: value}), samples=64)


# the trust map: (entry point, attribute); each entry point is called as in CALL
MAP_ATTRS = [("write_report", "wall_seconds"), ("write_report", "criterion_text"),
             ("write_report", "per_period"), ("findings", "resolution"),
             ("findings", "parameter"), ("boundary_table", "uncertain"),
             ("boundary_table", "mu"), ("first_screen", "tolerance"),
             ("plot_mean", "per_period"), ("plot_phase", "delta"),
             ("plot_map", "var_tolerance")]


def call(entry: str, ds, tmp_path):
    """Call the report's entry point ``entry`` on ``ds`` as a user would."""
    if entry.startswith("write_report"):
        return R.write_report(ds, str(tmp_path), plots=entry.endswith("_plots"))
    if entry == "draw_figures":
        return R.draw_figures(ds, str(tmp_path))
    if entry in ("verdict_grid", "count_table"):
        return getattr(R, entry)(ds, 0)
    if entry.startswith("plot_"):
        return getattr(R, entry)(ds, str(tmp_path / f"{entry}.png"))
    return getattr(R, entry)(ds)


@pytest.mark.parametrize("entry, name", MAP_ATTRS, ids=[f"{e}-{n}" for e, n in MAP_ATTRS])
def test_the_report_names_a_missing_attribute(trust_map, tmp_path, entry, name):
    with pytest.raises(ValueError, match=rf"the trust-map dataset lacks the attribute "
                                         rf"{name}\b"):
        call(entry, without_attr(trust_map, name), tmp_path)


# ------------------------------------------------------------------ missing variables
@pytest.mark.parametrize("run, names, culprit", [
    ("opa", ["x_mean"], "the opa dataset lacks the variable x_mean"),
    ("opa", ["x_var"], "the opa dataset lacks the variable x_var"),
    ("opa", ["x_coef", "element_x_coef"], "the opa dataset lacks the variable x_coef"),
    ("opa2", ["element_edges"], "the opa dataset lacks the variable element_edges"),
    ("mc", ["x_mean"], "the mc dataset lacks the variable x_mean"),
    ("mc", ["x_var"], "the mc dataset lacks the variable x_var"),
    ("mc", ["x_coef", "x_coef_sem"], "the mc dataset lacks the variable x_coef"),
    ("mc", ["x_sem"], r"the mc dataset lacks the standard errors \['x_sem'\]"),
])
def test_compare_runs_names_a_missing_variable(runs, run, names, culprit):
    args = {"opa": runs["opa2" if run == "opa2" else "opa"], "mc": runs["mc"]}
    side = "mc" if run == "mc" else "opa"
    args[side] = args[side].drop_vars(names)
    with pytest.raises(ValueError, match=culprit):
        compare_runs(args["opa"], args["mc"])


@pytest.mark.parametrize("name", ["err_mean", "mc_sem", "within_noise", "err_var"])
def test_error_metrics_names_a_missing_variable(runs, name):
    cmp = compare_runs(runs["opa"], runs["mc"])
    with pytest.raises(ValueError, match=rf"cmp lacks the variable {name}\b"):
        error_metrics(cmp.drop_vars(name))


@pytest.mark.parametrize("name", ["x_mean", "x_var", "element_x_coef", "element_edges",
                                  "element_probability"])
def test_verify_names_a_missing_variable(runs, name):
    with pytest.raises(ValueError, match=rf"the run lacks .*\b{name}\b"):
        verify(runs["opa"].drop_vars(name), samples=64)


MAP_VARIABLES = [("boundary_table", "sigma_star"), ("boundary_table", "split_kind"),
                 ("verdict_grid", "agrees"), ("verdict_grid", "sigma"),
                 ("findings", "mc_x_sem"), ("findings", "err_mean"),
                 ("findings", "emr0_dmr_difference"), ("write_report", "count_prob"),
                 ("first_screen", "sigma_star_upper"), ("plot_map", "probe_sigma"),
                 ("plot_map", "err_var_rel"), ("draw_figures", "phase_sample_v"),
                 ("plot_mean", "opa_x_mean"), ("plot_mean", "mc_x_sem"),
                 ("plot_variance", "mc_x_var_sem"), ("plot_phase", "phase_mc_x"),
                 ("plot_error_vs_order", "pre_impact_err")]


@pytest.mark.parametrize("entry, name", MAP_VARIABLES,
                         ids=[f"{e}-{n}" for e, n in MAP_VARIABLES])
def test_the_report_names_a_missing_variable(trust_map, tmp_path, entry, name):
    with pytest.raises(ValueError, match=rf"the trust-map dataset lacks the variable "
                                         rf"{name}\b"):
        call(entry, trust_map.drop_vars(name), tmp_path)


# ------------------------------------------------------------------ the old name `periods`
@pytest.mark.parametrize("side", ["opa", "mc"])
def test_compare_runs_names_the_old_periods_coordinate(runs, side):
    args = dict(opa=runs["opa"], mc=runs["mc"])
    args[side] = args[side].rename(time="periods")
    with pytest.raises(ValueError, match=rf"the {side} dataset has no coordinate time "
                                         rf"\(it has periods"):
        compare_runs(args["opa"], args["mc"])


def test_error_metrics_names_the_old_periods_coordinate(runs):
    cmp = compare_runs(runs["opa"], runs["mc"])
    with pytest.raises(ValueError, match=r"cmp has no coordinate time \(it has periods"):
        error_metrics(cmp.rename(time="periods"))


def test_verify_names_the_old_periods_coordinate(runs):
    with pytest.raises(ValueError, match=r"the run has no coordinate time \(it has periods"):
        verify(runs["opa"].rename(time="periods"), samples=64)


def test_the_report_reads_the_old_periods_coordinate(trust_map, tmp_path):
    """docs/datasets.md: files written before issue 26 called ``time`` ``periods``, and
    the report still reads them: the same findings and tables."""
    old = trust_map.rename(time="periods")
    assert R.findings(old) == R.findings(trust_map)
    assert R.boundary_table(old) == R.boundary_table(trust_map)
    assert R.run_failures(old) == R.run_failures(trust_map)


def test_the_report_names_a_missing_time_coordinate(trust_map, tmp_path):
    with pytest.raises(ValueError, match=r"the trust-map dataset has no coordinate time"):
        R.findings(trust_map.drop_vars("time"))


# ------------------------------------------------------------------ the wrong kind
@pytest.mark.parametrize("opa_arg, mc_arg, message", [
    ("mc", "mc", r"opa_ds must be an opa run, got model = 'mc'"),
    ("opa", "opa", r"mc_ds must be an mc run, got model = 'opa'"),
    ("map", "mc", r"opa_ds must be an opa run, got model = 'validate'"),
    ("opa", "map", r"mc_ds must be an mc run, got model = 'validate'"),
    ("path", "mc", r"opa_ds must be an xarray.Dataset of an opa run, got str"),
])
def test_compare_runs_refuses_a_dataset_of_the_wrong_kind(runs, trust_map, opa_arg, mc_arg,
                                                          message):
    pick = {**runs, "map": trust_map, "path": "validate.nc"}
    with pytest.raises(ValueError, match=message):
        compare_runs(pick[opa_arg], pick[mc_arg])


@pytest.mark.parametrize("arg", ["opa", "mc", "path"])
def test_error_metrics_refuses_what_is_not_a_comparison(runs, arg):
    with pytest.raises(ValueError, match=r"cmp (lacks the variables? err_mean|must be an "
                                         r"xarray.Dataset)"):
        error_metrics({**runs, "path": "cmp.nc"}[arg])


@pytest.mark.parametrize("arg, message", [
    ("mc", r"run must be an OPA run \(attribute model = 'opa'\), got model = 'mc'"),
    ("map", r"run must be an OPA run \(attribute model = 'opa'\), got model = 'validate'"),
    ("path", r"run must be an xarray.Dataset of an OPA run, got str"),
])
def test_verify_refuses_a_dataset_of_the_wrong_kind(runs, trust_map, arg, message):
    with pytest.raises(ValueError, match=message):
        verify({**runs, "map": trust_map, "path": "run.nc"}[arg], samples=64)


REPORT_ENTRIES = ["write_report", "findings", "boundary_table", "verdict_grid",
                  "first_screen", "count_table", "plot_map", "plot_mean", "plot_variance",
                  "plot_phase", "plot_error_vs_order"]


@pytest.mark.parametrize("entry", REPORT_ENTRIES)
@pytest.mark.parametrize("arg", ["opa", "mc"])
def test_the_report_refuses_a_dataset_of_the_wrong_kind(runs, tmp_path, entry, arg):
    with pytest.raises(ValueError, match=rf"the trust-map dataset must be a trust map "
                                         rf"\(.*\), got model = '{arg}'"):
        call(entry, runs[arg], tmp_path)


@pytest.mark.parametrize("entry", ["write_report", "findings", "plot_mean"])
def test_the_report_refuses_what_is_not_a_dataset(tmp_path, entry):
    with pytest.raises(ValueError, match=r"the trust-map dataset must be an xarray.Dataset"
                                         r".*got str"):
        call(entry, "validate.nc", tmp_path)


# ------------------------------------------------------------------ the trust map's values
MAP_VALUES = [("plot_mean", "mc_x_mean", np.inf, "non-finite"),
              ("plot_mean", "mc_x_sem", np.nan, "non-finite"),
              ("findings", "mc_x_sem", np.nan, "non-finite"),
              ("write_report", "mc_x_sem", np.inf, "non-finite"),
              ("plot_variance", "mc_x_var", np.nan, "non-finite"),
              ("plot_variance", "mc_x_var_sem", np.inf, "non-finite"),
              ("plot_error_vs_order", "mc_x_var", np.nan, "non-finite"),
              ("plot_mean", "opa_x_mean", np.nan, "non-finite"),
              ("plot_variance", "opa_x_var", np.inf, "non-finite"),
              ("plot_mean", "mc_x_sem", -1e-3, "negative"),
              ("findings", "mc_x_sem", -1e-3, "negative"),
              ("write_report", "mc_x_sem", -1e-3, "negative"),
              ("write_report_plots", "mc_x_var_sem", -1e-3, "negative"),
              ("plot_variance", "mc_x_var_sem", -1e-3, "negative")]


@pytest.mark.parametrize("entry, name, bad, what", MAP_VALUES,
                         ids=[f"{e}-{n}-{b}" for e, n, b, _ in MAP_VALUES])
def test_the_report_refuses_broken_values(trust_map, tmp_path, entry, name, bad, what):
    size = trust_map[name].size
    message = (rf"the trust-map dataset's {name} has 1 non-finite value of {size}\b"
               if what == "non-finite" else
               rf"the trust-map dataset's {name} is negative at 1 output\b")
    with pytest.raises(ValueError, match=message):
        call(entry, spoil(trust_map, name, bad), tmp_path)
    assert not list(tmp_path.iterdir())  # refused before anything was written


def test_a_map_written_before_the_three_valued_verdicts_is_drawn(trust_map, tmp_path):
    """``verdict`` is read only where present (older maps have ``agrees`` alone)."""
    assert R.plot_map(trust_map.drop_vars("verdict"), str(tmp_path / "map.png"))


def _map_with_a_stop(trust_map) -> xr.Dataset:
    """The map with the headline run at the first grid point stopped after output 3, as
    validate.nc records it: opa_status names the kernel's reason, the curves are NaN
    after it and its errors NaN."""
    ds = trust_map.copy(deep=True)
    names = ds.opa_status.attrs["flag_meanings"].split()
    code = int(ds.opa_status.attrs["flag_values"][names.index("not_run") + 2])
    ds.opa_status.values[0, 0, 0, -1] = code
    ds.opa_x_mean.values[0, 0, 0, -1, 3:] = np.nan
    ds.opa_x_var.values[0, 0, 0, -1, 3:] = np.nan
    ds.err_mean.values[0, 0, 0, -1] = np.nan
    return ds


def test_the_maps_curves_after_a_stop_are_accepted(trust_map, tmp_path):
    """docs/datasets.md: opa_status > 0 marks a run that stopped, its curves NaN after:
    the report counts it among the runs that did not finish, and draws."""
    stopped = _map_with_a_stop(trust_map)
    failures = R.run_failures(stopped)
    assert len(failures) == 1 and "x_0 is NaN from t = 0.75 periods on" in failures[0]
    R.write_report(stopped, str(tmp_path), plots=False)
    assert "did not finish" in (tmp_path / "summary.md").read_text()
    assert R.plot_mean(stopped, str(tmp_path / "mean.png"))


def test_a_nan_in_a_finished_maps_curve_is_refused(trust_map, tmp_path):
    """A NaN where opa_status says the run finished is not the documented one."""
    ds = _map_with_a_stop(trust_map)
    ds.opa_x_mean.values[0, 1, 0, -1, 2] = np.nan  # another point, which finished
    with pytest.raises(ValueError, match=r"the trust-map dataset's opa_x_mean has 1 "
                                         r"non-finite value of \d+ where opa_status says "
                                         r"the run finished"):
        R.plot_mean(ds, str(tmp_path / "mean.png"))


# ------------------------------------------------------------------ verify's own estimates
def test_verify_refuses_non_finite_values_in_the_run(runs):
    for name in ("x_mean", "x_var"):
        with pytest.raises(ValueError, match=rf"the run's {name} holds 1 non-finite "
                                             rf"values? of {TIMES}\b"):
            verify(spoil(runs["opa"], name, np.nan), samples=64)


def test_verify_gives_no_verdict_from_non_finite_estimates(runs, monkeypatch):
    """If an estimate verify forms is not finite (a true system that went far), the
    verdict is 'undecided', with the reason, never one read off NaN."""
    import compare._verify as V

    real = V.stratified_estimates

    def nan_at_one_output(*args, **kw):
        est = real(*args, **kw)
        est["d"] = np.array(est["d"], dtype=float)
        est["d"][2] = np.nan
        return est

    monkeypatch.setattr(V, "stratified_estimates", nan_at_one_output)
    out = verify(runs["opa"], samples=64, sequential=False)
    assert out.attrs["verdict"] == "undecided"
    assert out.attrs["verdict_mean"] == out.attrs["verdict_var"] == "undecided"
    assert out.attrs["first_disagreement_mean"] == np.inf
    assert re.search(r"verify_err_mean has 1 non-finite value of 5",
                     out.attrs["verify_undecided_because"])
