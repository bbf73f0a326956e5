"""Tests for ``opa.plots._diagrams``: bifurcation lines come only from located
bifurcations (``_located_marks``, ``plot_bifurcation``), never from brute-force period
labels. The paper's figures, built from these blocks, are tested in
``tests/compare/test_figures.py``, which shares the helpers of this module.
"""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

import opa.plots._diagrams as P  # noqa: E402
from opa import preset, sweep  # noqa: E402


def vertical_lines(ax) -> list[tuple[float, str]]:
    """(x, label) of every axvline of an axis."""
    out = []
    for line in ax.get_lines():
        x = np.asarray(line.get_xdata(), dtype=float)
        y = np.asarray(line.get_ydata(), dtype=float)
        if len(x) == 2 and x[0] == x[1] and tuple(y) == (0.0, 1.0):
            out.append((float(x[0]), line.get_label()))
    return out


def flag_every_doubling(ds: xr.Dataset) -> xr.Dataset:
    """What the brute-force labels would say at their loudest."""
    ds = ds.drop_dims("bifurcation", errors="ignore")
    for name in ("period_doubling", "observed_doubling"):
        if name in ds:
            ds[name] = ds[name] * 0 + 1
    return ds


def sweep_like(values=(0.02, 0.05, 0.08), **variables) -> xr.Dataset:
    return xr.Dataset(variables, coords={"c": list(values)},
                      attrs={"sweep_parameter": "c"})


def test_located_marks_adapter():
    assert P._located_marks(sweep_like()) == []
    ds = sweep_like(bifurcation_parameter=("bifurcation", [0.06, 0.03, 0.5, np.nan]),
                    bifurcation_kind=("bifurcation", ["fold", "period-doubling", "fold",
                                                      "grazing"]))
    assert P._located_marks(ds) == [(0.03, "period-doubling", True), (0.06, "fold", True)]
    ds = sweep_like(bifurcation_c=("bifurcation", [0.04]),
                    bifurcation_kind=("bifurcation", np.array([3], dtype=np.int8)),
                    bifurcation_located=("bifurcation", np.array([0], dtype=np.int8)))
    assert P._located_marks(ds) == [(0.04, "grazing", False)]
    assert P.mark_name("grazing", False) == "grazing (estimated)"
    # values without kinds still come out, as plain bifurcations
    ds = sweep_like(bifurcation_value=("bifurcation", [0.05]))
    assert P._located_marks(ds) == [(0.05, "bifurcation", True)]
    # and a brute-force flag alone gives nothing
    ds = sweep_like(period_doubling=("c", [0, 1, 1]))
    assert P._located_marks(ds) == []


def test_plot_bifurcation_draws_only_located_marks(tmp_path, monkeypatch):
    ds = sweep("dmr", "c", [0.03, 0.05, 0.07], preset("3.1"), transient=10, record=6,
               workers=1, progress=False)
    ds = flag_every_doubling(ds)
    kept = []
    monkeypatch.setattr(P.plt, "close", kept.append)
    P.plot_bifurcation(ds, str(tmp_path / "b.png"))
    fig = kept[0]
    assert all(vertical_lines(ax) == [] for ax in fig.axes)
    assert "no bifurcation lines" in fig._suptitle.get_text()
    ds = ds.drop_dims("bifurcation", errors="ignore").assign(
                   bifurcation_c=("bifurcation", [0.04]),
                   bifurcation_kind=("bifurcation", ["period-doubling"]))
    P.plot_bifurcation(ds, str(tmp_path / "b2.png"))
    assert all(vertical_lines(ax) == [(0.04, "period doubling")] for ax in kept[1].axes)
    monkeypatch.undo()  # plt.close is pyplot's own: restore it before closing
    for f in kept:
        plt.close(f)
