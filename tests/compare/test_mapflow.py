"""The trust map as a flow of small tasks (compare._mapflow): which tasks come first,
which each one makes ready, and that the map they give is the one-process map."""

import pytest

from compare._config import load_config
from compare._mapflow import FrontierRuns, MapFlow, run_validation
from opa.engine import Store
from tests.compare.test_scaleout import assert_same_map

# one swept value, two sigmas, the frontier on, short horizons
WITH_FRONTIER = dict(values=(3.98,), sigmas=(0.01, 0.03), orders=(0, 2), horizons=(2, 4),
                     samples=64, max_samples=128, per_period=4, frontier=True)


def _store(tmp_path) -> Store:
    return Store(str(tmp_path / "parts"), "trust map")


def test_the_first_tasks_are_independent_and_each_value_waits_for_its_grid(tmp_path):
    cfg = load_config(None, outdir=str(tmp_path), values=(3.98, 4.09), sigmas=(0.01, 0.02),
                      frontier=False)
    flow = MapFlow(cfg, _store(tmp_path))
    first = flow.first()
    assert [key for key, _, _ in first] == [("splits", 0), ("splits", 1)]
    # a value's grid points once its split scan is done (they are stratified at its
    # splits); its bisections once both its points are done, the longest horizon first;
    # its value task once they are
    points = flow.follow(("splits", 1), {}) + flow.follow(("splits", 0), {})
    assert [key for key, _, _ in points] == [
        ("point", 1, 0), ("point", 1, 1), ("point", 0, 0), ("point", 0, 1)]
    assert len(first) + len(points) == cfg.first_tasks
    assert flow.follow(("point", 1, 0), {}) == []
    assert flow.follow(("point", 0, 0), {}) == []
    bisect = flow.follow(("point", 1, 1), {})
    assert [key for key, _, _ in bisect] == [("bisect", 1, 1), ("bisect", 1, 0)]
    assert cfg.horizons[1] > cfg.horizons[0]
    _, _, args = bisect[0]
    assert args[1:] == (4.09, 1)
    assert args[0].workers == 1 and args[0].scheduler is None  # no pool inside a task
    assert flow.follow(("bisect", 1, 1), {"result": "long"}) == []
    (key, _, args), = flow.follow(("bisect", 1, 0), {"result": "short"})
    # its slice's time series go to OUTDIR (spill): a local pool shares its disk
    assert key == ("value", 1) and args[1:] == (4.09, ["short", "long"], True)


def test_on_a_dask_cluster_a_value_task_returns_its_slice_whole(tmp_path):
    """The cluster's workers may not share OUTDIR's disk: no spilled time series."""
    cfg = load_config(None, outdir=str(tmp_path), values=(3.98,), sigmas=(0.01,),
                      frontier=False, scheduler="tcp://127.0.0.1:8786")
    flow = MapFlow(cfg, _store(tmp_path))
    flow.follow(("splits", 0), {})
    flow.follow(("point", 0, 0), {})
    flow.follow(("bisect", 0, 1), {"result": 1})
    (key, _, args), = flow.follow(("bisect", 0, 0), {"result": 0})
    assert key == ("value", 0) and args[-1] is False


def test_the_frontier_asks_for_its_reference_alone_first(tmp_path):
    cfg = load_config(None, outdir=str(tmp_path), **WITH_FRONTIER)
    runs = FrontierRuns(cfg, _store(tmp_path))
    (key, _, args), = runs.ready()
    assert key == ("frontier", "reference") and args[1].name == "reference"
    assert runs.ready() == []  # running: not asked for twice
    assert not runs.complete


def test_the_frontier_rows_come_once_the_reference_is_known(tmp_path):
    """After the reference, every row that needs no other run is ready at once, one
    task each; the nested ladders are one run each (MC, Sobol', control variates)."""
    cfg = load_config(None, outdir=str(tmp_path), **WITH_FRONTIER)
    runs = FrontierRuns(cfg, _store(tmp_path))
    runs.ready()
    tasks = runs.done({"reference": {"x_mean": 0.0, "x_var": 1.0, "x_sem": 0.0,
                                     "seconds": 0.0, "rhs": 0}})
    names = [args[1].name for _, _, args in tasks]
    assert [key for key, _, _ in tasks] == [("frontier", name) for name in names]
    assert len(names) == len(set(names)) and "reference" not in names
    assert any(name.startswith("ME-OPA-adaptive") for name in names)
    ladders = [name for name in names if "ladder" in name]
    assert ladders == ["MC-ladder-M8192", "QMC-Sobol-ladder-M8192", "CV-K64-ladder-M8192"]
    # the collocation rows on the adaptive runs' edges wait for those runs
    assert not any(name.startswith("ME-collocation-adaptive") for name in names)
    assert runs.ready() == []  # running: not asked for twice


@pytest.fixture(scope="module")
def one_process_with_frontier(tmp_path_factory):
    cfg = load_config(None, outdir=str(tmp_path_factory.mktemp("one")), workers=1,
                      **WITH_FRONTIER)
    return run_validation(cfg, progress=False, log=lambda *a: None)


def test_the_frontier_as_tasks_gives_the_one_process_map(one_process_with_frontier,
                                                          tmp_path):
    cfg = load_config(None, outdir=str(tmp_path), workers=2, **WITH_FRONTIER)
    pooled = run_validation(cfg, progress=False, log=lambda *a: None)
    assert pooled.attrs["ran_on"] == "2 local processes"
    assert "frontier_error" in pooled
    assert_same_map(one_process_with_frontier, pooled)
    for name in ("true_runs_computed", "mc_runs_computed", "opa_runs_computed"):
        assert pooled.attrs[name] == one_process_with_frontier.attrs[name], name
    # a rerun finds every task's parts, the frontier's runs among them
    again = run_validation(cfg, progress=False, log=lambda *a: None)
    assert again.attrs["parts_computed"] == 0
    assert_same_map(one_process_with_frontier, again)


def test_element_variants_under_another_law_as_tasks_give_the_one_process_map(tmp_path):
    """The flow composes with the map's other options: a uniform law of xi and adaptive
    multi-element variants, with the frontier, on 2 processes equal one process."""
    kw = dict(WITH_FRONTIER, distribution="uniform", elements="adaptive", max_elements=8)
    one = run_validation(load_config(None, outdir=str(tmp_path / "one"), workers=1, **kw),
                         progress=False, log=lambda *a: None)
    two = run_validation(load_config(None, outdir=str(tmp_path / "two"), workers=2, **kw),
                         progress=False, log=lambda *a: None)
    assert any("ME-adaptive" in str(v) for v in two.variant.values)
    assert two.attrs["distribution"] == "uniform"
    assert_same_map(one, two)


def test_an_execution_record_says_where_the_map_runs(tmp_path):
    """``execution=Execution(workers=2, log=...)`` runs the flow on 2 processes and gives
    the one-process map of the configuration's own workers = 1; workers in both places,
    or the keywords beside the record, are refused by name."""
    from opa import Execution

    kw = dict(values=(3.98,), sigmas=(0.01, 0.03), orders=(0, 2), horizons=(2,),
              samples=64, max_samples=128, per_period=4, frontier=False, plots=False)
    lines = []
    one = run_validation(load_config(None, outdir=str(tmp_path / "one"), workers=1, **kw),
                         progress=False, log=lambda *a: None)
    two = run_validation(load_config(None, outdir=str(tmp_path / "two"), **kw),
                         execution=Execution(workers=2, progress=False, log=lines.append))
    assert two.attrs["ran_on"] == "2 local processes" and lines
    assert_same_map(one, two)
    with pytest.raises(ValueError, match=r"workers or scheduler beside execution="):
        run_validation(load_config(None, outdir=str(tmp_path / "x"), workers=2, **kw),
                       execution=Execution(workers=2))
    with pytest.raises(ValueError, match=r"give progress inside execution="):
        run_validation(load_config(None, outdir=str(tmp_path / "y"), **kw),
                       execution=Execution(), progress=False)
