"""Tests for ``opa.plots._branches``: the branches of ``continue_orbits`` (section 3.1
without impulses, through the period doubling at c = 0.0891) survive a netCDF round trip
and are drawn."""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

from opa import preset  # noqa: E402
from opa._dataset import write_netcdf  # noqa: E402
from opa.dynamics._continuation import ContinuationOptions, continue_orbits  # noqa: E402
from opa.dynamics._orbits import ImpactSystem  # noqa: E402
from opa.plots import plot_branches  # noqa: E402


def test_dataset_netcdf_and_plot(tmp_path):
    system = ImpactSystem(preset("3.1", F0=0.0))
    ds = continue_orbits(system, "c", 0.095, 0.085, depth=1,
                         continuation=ContinuationOptions(max_points=30))
    for name in ("section_x", "section_v", "multiplier_real", "multiplier_imag", "stable",
                 "bifurcation_kind", "bifurcation_c", "state", "period", "impacts"):
        assert name in ds
    assert ds.attrs["parameter"] == "c" and ds.attrs["model"] == "dmr"
    path = tmp_path / "branches.nc"
    write_netcdf(ds, path)
    with xr.open_dataset(path) as back:
        np.testing.assert_array_equal(back.stable.values, ds.stable.values)
    png = tmp_path / "branches.png"
    plot_branches(ds, str(png))
    assert png.stat().st_size > 1000
