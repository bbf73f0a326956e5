"""Tests for ``compare._mapread``: what the report reads off a trust map.

The maps here are built by hand (two swept values, one horizon, six splits of known kind
and place), so every expected answer is read off the construction: the nearest split is
the one placed nearest to the nominal value, not one the code reported about itself.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from compare._mapread import (
    check_map, complete_within, frontier_dataset, nearest_horizon, nearest_split,
    star_phrase, star_text,
)

KINDS = "grazing extra_impact chatter impulse_order horizon output_crossing"
MU = 0.8


def hand_map(splits, *, complete=None) -> xr.Dataset:
    """A trust map of two omega values and one horizon whose split lists are ``splits``:
    per value a list of (kind index or -1, mu at the split, time); ``complete``: the
    variable split_complete_sigma per value (None: an older file's split_truncated)."""
    width = max(len(s) for s in splits)
    kind = np.full((2, 1, width), -1, np.int8)
    value = np.full((2, 1, width), np.nan)
    time = np.full((2, 1, width), np.nan)
    for q, row in enumerate(splits):
        for j, (k, mu, t) in enumerate(row):
            kind[q, 0, j], value[q, 0, j], time[q, 0, j] = k, mu, t
    dims = ("omega", "horizon", "split")
    ds = xr.Dataset(
        {"split_kind": (dims, kind, {"flag_values": np.arange(6, dtype=np.int8),
                                     "flag_meanings": KINDS}),
         "split_value": (dims, value), "split_time": (dims, time),
         "split_speed": (dims, np.full_like(value, 0.5)),
         "split_left": (dims, np.full(kind.shape, 3)),
         "split_right": (dims, np.full(kind.shape, 4)),
         "sigma_star": (("omega", "variant", "horizon", "criterion"), np.zeros((2, 1, 1, 2))),
         "sigma_star_upper": (("omega", "variant", "horizon", "criterion"),
                              np.full((2, 1, 1, 2), np.inf))},
        coords={"omega": [4.0, 4.1], "horizon": [10.0], "sigma": [0.01, 0.05],
                "variant": ["mean/galerkin"], "N": [0, 8], "criterion": ["mean", "variance"]},
        attrs={"model": "validate", "parameter": "omega", "uncertain": "mu", "mu": MU,
               "resolution": 1e-3})
    if complete is None:
        ds["split_truncated"] = (("omega", "horizon"), np.array([[0], [1]], np.int8))
    else:
        ds["split_complete_sigma"] = (("omega", "horizon"), np.array(complete)[:, None])
    return ds


#: value 0: a grazing split 0.03 above the nominal mu, a chatter split 0.02 below it, a
#: horizon split 0.001 away and an output crossing 0.005 away; value 1: horizons only
SPLITS = [[(0, MU + 0.03, 2.5), (2, MU - 0.02, 1.5), (4, MU + 0.001, 10.0),
           (5, MU - 0.005, 3.0), (-1, np.nan, np.nan)],
          [(4, MU + 0.04, 10.0), (4, MU - 0.01, 9.9)]]


def test_the_nearest_split_changes_the_impact_sequence():
    """Horizon crossings and output crossings are not splits, however near; unused slots
    (kind -1) are skipped; a value with none gives None."""
    ds = hand_map(SPLITS, complete=[np.inf, np.inf])
    sp = nearest_split(ds, 0, 0)
    assert sp["kind"] == "chatter"
    assert sp["value"] == MU - 0.02 and sp["time"] == 1.5
    assert sp["distance"] == pytest.approx(0.02, abs=1e-15)
    assert (sp["left"], sp["right"], sp["speed"]) == (3, 4, 0.5)
    assert nearest_split(ds, 1, 0) is None


def test_the_nearest_horizon_split():
    ds = hand_map(SPLITS, complete=[np.inf, np.inf])
    assert nearest_horizon(ds, 0, 0)["value"] == MU + 0.001
    assert nearest_horizon(ds, 1, 0)["value"] == MU - 0.01


def test_the_split_list_is_complete_within_the_reported_distance():
    """A map that reports split_complete_sigma is read as is; an older one (only
    split_truncated) is complete everywhere where the list was not cut, nowhere where
    it was."""
    assert [complete_within(hand_map(SPLITS, complete=[0.07, np.inf]), q, 0)
            for q in (0, 1)] == [0.07, np.inf]
    assert [complete_within(hand_map(SPLITS), q, 0) for q in (0, 1)] == [np.inf, 0.0]


@pytest.mark.parametrize("lo, hi, text, phrase", [
    (0.012, 0.0135, "0.012–0.0135", "σ* = 0.012–0.0135"),
    (0.0, 0.004, "< 0.004", "σ* < 0.004"),
    (0.05, np.inf, "≥ 0.05", "σ* ≥ 0.05"),
])
def test_sigma_star_is_said_from_its_bracket(lo, hi, text, phrase):
    """resolved: the bracket; below the smallest sigma probed: '<' its top; agreeing on
    the whole grid: '≥' the largest sigma (smax = 0.05)."""
    assert star_text(lo, hi, 0.05) == text
    assert star_phrase(lo, hi, 0.05) == phrase


def test_check_map_names_what_is_missing_or_wrong():
    ds = hand_map(SPLITS, complete=[np.inf, np.inf])
    check_map(ds, "boundary_table")  # everything boundary_table reads is there
    with pytest.raises(ValueError, match=r"lacks the variable sigma_star_upper"):
        check_map(ds.drop_vars("sigma_star_upper"), "boundary_table")
    unresolved = ds.copy()
    unresolved.attrs = {k: v for k, v in ds.attrs.items() if k != "resolution"}
    with pytest.raises(ValueError, match=r"lacks the attribute resolution"):
        check_map(unresolved, "boundary_table")
    with pytest.raises(ValueError, match=r"got model = 'opa'"):
        check_map(ds.assign_attrs(model="opa"), "boundary_table")
    with pytest.raises(ValueError, match=r"lacks its attribute flag_meanings"):
        bare = ds.copy()
        bare.split_kind.attrs.pop("flag_meanings")
        check_map(bare, "boundary_table")


def test_the_frontier_part_of_a_map():
    """frontier_* variables and attributes lose their prefix; a map without them has no
    frontier; one written before frontier_omega takes the map's omega."""
    ds = hand_map(SPLITS, complete=[np.inf, np.inf])
    assert frontier_dataset(ds) is None
    ds["frontier_error"] = ("frontier_run", [0.1, 0.01])
    ds["frontier_method"] = ("frontier_run", ["Sobol", "ME-OPA uniform"])
    ds.attrs.update(frontier_sigma=0.02, omega=4.0)
    conv = frontier_dataset(ds)
    assert list(conv.data_vars) == ["error", "method"]
    assert conv.sizes == {"run": 2}
    np.testing.assert_array_equal(conv.error.values, [0.1, 0.01])
    assert conv.attrs == {"sigma": 0.02, "omega": 4.0}
