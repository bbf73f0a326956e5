"""The validate report's sentences of their own (``compare._findings``): the error before
OPA's first impact (``findings``) and the runs that did not finish (``run_failures``).

Each test takes the smallest trust map (validate.nc read back) and sets by hand what a
sentence reads: OPA's first impact, the MC standard errors, a run that stopped at a chosen
output. The expected numbers are computed here from the dataset's variables with plain
numpy (the pre-impact error from ``opa_x_mean`` and ``mc_x_mean``, the MC SE from
``mc_x_sem`` over the window, the stop from the first NaN of ``opa_x_mean``), never read
off the report, and the wording is checked where it changes: one value or a range, and
no sentence where there is nothing to say.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import xarray as xr

from compare import _findings as R
from compare._mapread import HEADLINE

HEAD = HEADLINE
BEFORE = "Before OPA's first impact"
#: a cell of the pre-impact sentence: error, sigma, MC SE
CELL = re.compile(r"(\S+) at σ = (\S+) \(MC SE (\S+)\)")


@pytest.fixture(scope="module")
def tiny_map(smallest_trust_map) -> xr.Dataset:
    """The smallest trust map (tests/compare/conftest.py): t = 0, 0.25, ..., 2."""
    ds = smallest_trust_map.copy(deep=True)
    assert np.allclose(ds.time.values, np.arange(9) / 4)
    return ds


@pytest.fixture
def ds(tiny_map) -> xr.Dataset:
    return tiny_map.copy(deep=True)


def with_sigmas(ds: xr.Dataset, sigmas) -> xr.Dataset:
    """The map on a grid of ``len(sigmas)`` sigmas: the existing points repeated in turn,
    relabelled (for the sentences' choice of sigmas; their numbers are set by hand)."""
    picks = [s % ds.sizes["sigma"] for s in range(len(sigmas))]
    return ds.isel(sigma=picks).assign_coords(sigma=np.asarray(sigmas, float)).copy(deep=True)


# ---------------------------------------------------------------- before the first impact


def pre_impact_sentence(ds) -> str | None:
    found = [f for f in R.findings(ds) if f.startswith(BEFORE)]
    assert len(found) <= 1
    return found[0] if found else None


#: pre-impact errors set by hand with a hand-set first impact, one per sigma
HAND_ERRORS = np.array([2.5e-9, 7.5e-8])


def set_first_impact(ds, first, sem=None) -> np.ndarray:
    """OPA's first impact (headline variant, N max, first value) at each sigma, with the
    error before it (``HAND_ERRORS``; the map's no longer fits the window), and the MC
    standard errors of the mean at each sigma and output; returns the errors."""
    ds.first_impact.values[0, :, HEAD, -1] = first
    ds.pre_impact_err.values[0, :, HEAD, -1] = HAND_ERRORS
    if sem is not None:
        ds.mc_x_sem.values[0] = sem
    return HAND_ERRORS


def expected_cells(ds, errors=None) -> dict[float, tuple[float, float]]:
    """sigma -> (the error: ``errors`` where given, else the RMS of x_0 - E_MC[x]; the RMS
    MC standard error), both over the outputs before OPA's first impact at that sigma,
    where there are outputs other than t = 0."""
    t = ds.time.values
    out = {}
    for s, sigma in enumerate(ds.sigma.values):
        before = t < ds.first_impact.values[0, s, HEAD, -1]
        if before.sum() < 2:
            continue
        gap = ds.opa_x_mean.values[0, s, HEAD, -1] - ds.mc_x_mean.values[0, s]
        err = np.sqrt(np.mean(gap[before] ** 2)) if errors is None else errors[s]
        out[float(sigma)] = (float(err),
                             float(np.sqrt(np.mean(ds.mc_x_sem.values[0, s][before] ** 2))))
    return out


def check_cells(sentence: str, ds, errors=None) -> list[float]:
    """The sentence's cells hold, each to its two printed digits, the error and the MC SE
    computed here (the errors: ``errors`` where given); returns the sigmas of the cells."""
    expected = expected_cells(ds, errors)
    cells = CELL.findall(sentence)
    assert cells, sentence
    for err, sigma, se in cells:
        want_err, want_se = expected[float(sigma)]
        assert float(err) == pytest.approx(want_err, rel=0.05), (sigma, sentence)
        assert float(se) == pytest.approx(want_se, rel=0.05), (sigma, sentence)
    return [float(sigma) for _, sigma, _ in cells]


def test_the_error_before_the_first_impact_is_the_rms_gap_over_that_window(ds):
    """On the map as run: OPA's first impact at 1.03 periods at both sigmas, so the window
    holds t = 0, 0.25, 0.5, 0.75, 1; the error is the RMS of x_0 - E_MC[x] there and the MC
    SE the RMS standard error there, at each sigma."""
    first = ds.first_impact.values[0, :, HEAD, -1]
    assert np.all((first > 1.0) & (first < 1.25))
    assert {f"{f:.2f}" for f in first} == {"1.03"}
    sentence = pre_impact_sentence(ds)
    nmax = int(ds.N.max())
    assert sentence.startswith(f"{BEFORE} (t < 1.03 periods at ω = 3.98) the error of x_0 at "
                               f"N = {nmax} is ")
    assert sentence.endswith(").")
    assert check_cells(sentence, ds) == [0.01, 0.03]
    # the numbers are those of the window, not of a longer one
    gap = ds.opa_x_mean.values[0, 0, HEAD, -1] - ds.mc_x_mean.values[0, 0]
    longer = np.sqrt(np.mean(gap[:7] ** 2))
    err = float(CELL.findall(sentence)[0][0])
    assert err != pytest.approx(longer, rel=0.05)


def test_one_window_is_written_as_one_value(ds):
    """First impacts at 1.1 and 1.104 periods: one window (t = 0 ... 1), written once as
    't < 1.10', with the MC SE over those five outputs, set by hand."""
    sem = 1e-4 * (1.0 + np.arange(ds.sizes["time"]))[None, :] * np.array([[1.0], [3.0]])
    errors = set_first_impact(ds, [1.1, 1.104], sem)
    sentence = pre_impact_sentence(ds)
    assert "(t < 1.10 periods at ω = 3.98)" in sentence
    assert "1.10–" not in sentence
    check_cells(sentence, ds, errors)
    se = float(CELL.findall(sentence)[1][2])
    assert se == pytest.approx(3e-4 * np.sqrt(np.mean(np.arange(1, 6) ** 2)), rel=0.05)


def test_windows_that_differ_by_sigma_are_written_as_a_range(ds):
    """First impacts at 1.1 (sigma = 0.01) and 1.6 periods (sigma = 0.03): the sentence
    gives the range, and each sigma's numbers are over its own window (five and seven
    outputs)."""
    sem = 1e-4 * (1.0 + np.arange(ds.sizes["time"]))[None, :] * np.ones((2, 1))
    errors = set_first_impact(ds, [1.1, 1.6], sem)
    sentence = pre_impact_sentence(ds)
    assert "(t < 1.10–1.60 periods at ω = 3.98)" in sentence
    assert check_cells(sentence, ds, errors) == [0.01, 0.03]
    se = [float(c[2]) for c in CELL.findall(sentence)]
    assert se == pytest.approx([1e-4 * np.sqrt(np.mean(np.arange(1, 6) ** 2)),
                                1e-4 * np.sqrt(np.mean(np.arange(1, 8) ** 2))], rel=0.05)


@pytest.mark.parametrize("first", [[0.2, 0.25], [0.0, 0.1], [np.nan, np.nan]])
def test_no_sentence_without_outputs_before_the_first_impact(ds, first):
    """An impact before the second output leaves t = 0 alone before it (where OPA and MC
    start from one state): nothing to report."""
    set_first_impact(ds, first)
    assert pre_impact_sentence(ds) is None


def test_only_the_sigmas_with_outputs_before_the_impact_are_reported(ds):
    """At sigma = 0.01 OPA impacts before the second output, at 0.03 at 1.6 periods: the
    sentence reports sigma = 0.03 alone, with its window."""
    errors = set_first_impact(ds, [0.2, 1.6])
    sentence = pre_impact_sentence(ds)
    assert "(t < 1.60 periods at ω = 3.98)" in sentence
    assert check_cells(sentence, ds, errors) == [0.03]


def test_no_impact_in_the_record(ds):
    """OPA does not impact in the record (first impact inf): the window is the whole
    record, and the sentence says so instead of 't < inf'."""
    errors = set_first_impact(ds, [np.inf, np.inf])
    sentence = pre_impact_sentence(ds)
    assert "inf" not in sentence
    assert sentence.startswith(f"{BEFORE} (no impact in the 2 periods recorded at ω = 3.98)")
    check_cells(sentence, ds, errors)


def test_no_impact_at_one_sigma(ds):
    errors = set_first_impact(ds, [1.1, np.inf])
    sentence = pre_impact_sentence(ds)
    assert "inf" not in sentence
    assert ("(t < 1.10 periods, or the 2 periods recorded where OPA does not impact, at "
            "ω = 3.98)") in sentence
    assert check_cells(sentence, ds, errors) == [0.01, 0.03]


def test_a_fine_grid_reports_a_few_sigmas_from_the_smallest(tiny_map):
    """Nine grid sigmas: a few of them are reported, the smallest first, in order, each
    with its own numbers."""
    sigmas = 0.005 * np.arange(1, 10)
    ds = with_sigmas(tiny_map, sigmas)
    sentence = pre_impact_sentence(ds)
    reported = check_cells(sentence, ds)
    assert 2 <= len(reported) <= 5
    assert reported[0] == pytest.approx(sigmas[0]) and reported == sorted(reported)


# ---------------------------------------------------------------- runs that did not finish


def stop(ds, s, at, reason="step_limit", v=HEAD, q=0):
    """The run (value q, sigma s, variant v, N max) stopped at output ``at``, as validate.nc
    records it: opa_status names the reason, the curves are NaN from there, the errors
    NaN."""
    names = ds.opa_status.attrs["flag_meanings"].split()
    ds.opa_status.values[q, s, v, -1] = ds.opa_status.attrs["flag_values"][names.index(reason)]
    ds.opa_x_mean.values[q, s, v, -1, at:] = np.nan
    ds.opa_x_var.values[q, s, v, -1, at:] = np.nan
    ds.err_mean.values[q, s, v, -1] = np.nan


def runs_of(ds, v) -> int:
    """Runs of variant v on the map: values x sigmas x the orders it ran at."""
    ran = int(ds.variant_ran.values[v].sum()) if "variant_ran" in ds else ds.sizes["N"]
    return ds.sizes["omega"] * ds.sizes["sigma"] * ran


def nan_from(sentence: str) -> str:
    found = re.search(r"x_0 is NaN from t = (\S+) periods on", sentence)
    assert found, sentence
    return found.group(1)


def test_a_finished_map_has_no_such_sentence(ds):
    assert R.run_failures(ds) == []


def test_one_stop_gives_its_time_its_count_and_its_reason(ds):
    stop(ds, 0, 3)
    (sentence,) = R.run_failures(ds)
    t = ds.time.values[np.flatnonzero(np.isnan(ds.opa_x_mean.values[0, 0, HEAD, -1]))[0]]
    assert t == 0.75
    assert nan_from(sentence) == "0.75"
    name = str(ds.variant.values[HEAD])
    assert sentence == (f"1 of {runs_of(ds, HEAD)} {name} runs over 2 periods did not finish: "
                        f"the OPA system's integration stopped before the horizon (x_0 is NaN "
                        f"from t = 0.75 periods on; step limit 1); counted as 'does not "
                        f"agree'")


def test_stops_at_one_time_are_one_value(ds):
    stop(ds, 0, 3)
    stop(ds, 1, 3)
    (sentence,) = R.run_failures(ds)
    assert sentence.startswith(f"2 of {runs_of(ds, HEAD)} ")
    assert nan_from(sentence) == "0.75"
    assert "step limit 2" in sentence


def test_stops_at_two_times_are_a_range(ds):
    stop(ds, 0, 3)
    stop(ds, 1, 6, reason="diverged")
    (sentence,) = R.run_failures(ds)
    assert ds.time.values[3] == 0.75 and ds.time.values[6] == 1.5
    assert nan_from(sentence) == "0.75–1.5"
    assert "step limit 1" in sentence and "diverged 1" in sentence


def test_stops_that_differ_below_the_digits_shown_are_one_value(ds):
    """Stops at t = 13.4 and 13.41 periods read '13.4', never the range '13.4–13.4'."""
    t = ds.time.values.copy()
    t[3], t[4] = 13.4, 13.41
    ds = ds.assign_coords(time=np.where(np.arange(len(t)) > 4, t + 20, t))
    stop(ds, 0, 3)
    stop(ds, 1, 4)
    (sentence,) = R.run_failures(ds)
    assert nan_from(sentence) == "13.4"
    assert "13.4–13.4" not in sentence
    t = ds.time.values.copy()
    ds = ds.assign_coords(time=np.where(np.arange(len(t)) == 4, 13.5, t))
    assert nan_from(R.run_failures(ds)[0]) == "13.4–13.5"


def test_each_variant_counts_its_own_stops(ds):
    ens = [str(v) for v in ds.variant.values].index("ensemble/galerkin")
    stop(ds, 1, 5, v=ens)
    (sentence,) = R.run_failures(ds)
    assert sentence.startswith(f"1 of {runs_of(ds, ens)} ensemble/galerkin runs ")
    assert nan_from(sentence) == f"{ds.time.values[5]:g}" == "1.25"


def test_orders_a_variant_did_not_run_are_not_counted(ds):
    """A variant not run at N = 0 (NaN there, opa_status -1) has no run that did not
    finish there; a stop at N max is one of the runs at the orders it ran."""
    v = [str(n) for n in ds.variant.values].index("saltation/galerkin")
    ds.variant_ran.values[v, 0] = 0
    ds.opa_status.values[:, :, v, 0] = -1
    ds.opa_x_mean.values[:, :, v, 0] = np.nan
    ds.opa_x_var.values[:, :, v, 0] = np.nan
    ds.err_mean.values[:, :, v, 0] = np.nan
    assert R.run_failures(ds) == []
    stop(ds, 0, 3, v=v)
    (sentence,) = R.run_failures(ds)
    assert sentence.startswith(f"1 of {ds.sizes['omega'] * ds.sizes['sigma']} "
                               f"saltation/galerkin runs ")


def test_the_impact_law_ratio_is_one_value_when_it_does_not_vary(ds):
    """"ranges over 3.2…3.2" read as a range of one value: it says the value."""
    ds.err_mean.values[..., 1, -1, 0] = 3.2 * ds.err_mean.values[..., 0, -1, 0]
    said = [line for line in R.findings(ds) if line.startswith("Ensemble against mean")]
    assert len(said) == 1 and "the ratio of their errors of x_0 is 3.2 wherever" in said[0]
    assert "…" not in said[0]
