"""The figure of certified Sobol indices: the surrogate's indices as lines, the certified
intervals as bands and error bars, an index within the noise at 0 with its upper end, an
undefined one left out; drawn from a dataset written out here (no computation)."""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import xarray as xr  # noqa: E402

from opa.plots import plot_sensitivity  # noqa: E402
from opa.plots._sensitivity import draw_sensitivity  # noqa: E402

PERIOD = 2.0
TIMES = np.arange(5) * PERIOD / 2  # 0, 0.5, ..., 2 forcing periods


def dataset() -> xr.Dataset:
    """Two parameters, five outputs: the start undefined, mu within the noise at t = 1.5,
    everything else resolved."""
    dims = ("parameter", "time")
    code = np.zeros((2, 5), dtype=np.int8)
    code[:, 0] = 2
    code[0, 3] = 1
    data = {}
    for state in "xv":
        for kind, base in (("first", 0.2), ("total", 0.3)):
            name = f"{state}_sobol_{kind}"
            value = np.array([[base] * 5, [1 - base] * 5])
            low, high = value - 0.05, value + 0.05
            value = np.where(code == 0, value, np.nan)
            low = np.where(code == 1, 0.0, np.where(code == 2, np.nan, low))
            high = np.where(code == 1, 0.12, np.where(code == 2, np.nan, high))
            data.update({name: (dims, value), f"{name}_lower": (dims, low),
                         f"{name}_upper": (dims, high), f"{name}_reading": (dims, code),
                         f"{name}_surrogate": (dims, np.full((2, 5), base + 0.01))})
    ds = xr.Dataset(data, coords={"time": ("time", TIMES, {"forcing_period": PERIOD}),
                                  "parameter": ["mu", "c"]})
    ds.attrs["samples"] = 64
    return ds


def test_each_panel_draws_the_surrogate_and_the_certified_intervals():
    ds = dataset()
    fig = draw_sensitivity(ds)
    try:
        axes = np.array(fig.axes).reshape(2, 2)
        for row, kind in enumerate(("first", "total")):
            for col, parameter in enumerate(("mu", "c")):
                ax = axes[row, col]
                name = f"x_sobol_{kind}"
                line = next(li for li in ax.get_lines() if li.get_label() == "surrogate")
                np.testing.assert_array_equal(line.get_xdata(), TIMES / PERIOD)
                np.testing.assert_array_equal(line.get_ydata(),
                                              ds[f"{name}_surrogate"].sel(parameter=parameter))
                bars = {c.get_label(): c for c in ax.containers}
                code = ds[f"{name}_reading"].sel(parameter=parameter).values
                certified = bars["certified"].lines[0]
                np.testing.assert_array_equal(certified.get_xdata(),
                                              TIMES[code == 0] / PERIOD)
                np.testing.assert_array_equal(
                    certified.get_ydata(), ds[name].sel(parameter=parameter).values[code == 0])
                noise = bars["within noise"].lines[0]
                np.testing.assert_array_equal(noise.get_xdata(), TIMES[code == 1] / PERIOD)
                assert (np.asarray(noise.get_ydata()) == 0).all()
                assert ax.get_ylim()[0] < 0 < ax.get_ylim()[1]
        # mu within the noise at t = 1.5 periods: a bar from 0 to its upper end 0.12
        ax = axes[0, 0]
        bars = [c for c in ax.containers if c.get_label() == "within noise"][0]
        segment = bars.lines[2][0].get_segments()[0]
        np.testing.assert_allclose(segment, [[1.5, 0.0], [1.5, 0.12]])
        assert axes[0, 0].get_ylabel().endswith("of x") and axes[1, 0].get_xlabel()
        assert axes[0, 1].get_title() == "c"
    finally:
        plt.close(fig)


def test_v_and_the_file(tmp_path):
    fig = draw_sensitivity(dataset(), "v")
    try:
        assert fig.axes[0].get_ylabel().endswith("of v")
    finally:
        plt.close(fig)
    path = tmp_path / "sobol.png"
    plot_sensitivity(dataset(), str(path))
    assert path.stat().st_size > 10_000
    with pytest.raises(ValueError, match="state must be x or v"):
        draw_sensitivity(dataset(), "y")
