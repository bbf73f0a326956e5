"""Tests for ``opa.plots._diagrams``: bifurcation lines come only from located
bifurcations (``located_marks``, ``plot_bifurcation``), never from brute-force period
labels. The paper's figures, built from these blocks, are tested in
``tests/compare/test_figures.py``, which shares the helpers of this module.
"""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
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
    assert P.located_marks(sweep_like()) == []
    ds = sweep_like(bifurcation_parameter=("bifurcation", [0.06, 0.03, 0.5, np.nan]),
                    bifurcation_kind=("bifurcation", ["fold", "period-doubling", "fold",
                                                      "grazing"]))
    assert P.located_marks(ds) == [(0.03, "period-doubling", True), (0.06, "fold", True)]
    ds = sweep_like(bifurcation_c=("bifurcation", [0.04]),
                    bifurcation_kind=("bifurcation", np.array([3], dtype=np.int8)),
                    bifurcation_located=("bifurcation", np.array([0], dtype=np.int8)))
    assert P.located_marks(ds) == [(0.04, "grazing", False)]
    assert P.mark_name("grazing", False) == "grazing (estimated)"
    # values without kinds still come out, as plain bifurcations
    ds = sweep_like(bifurcation_value=("bifurcation", [0.05]))
    assert P.located_marks(ds) == [(0.05, "bifurcation", True)]
    # and a brute-force flag alone gives nothing
    ds = sweep_like(period_doubling=("c", [0, 1, 1]))
    assert P.located_marks(ds) == []


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


# --------------------------------------------------------------------------- plot_run


def _runs_of_every_kind():
    """Tiny runs of every kind --plot draws: DMR, OPA (one element, K elements, adaptive,
    laws of xi) and Monte Carlo (laws of xi)."""
    import warnings

    import mc
    from opa import Oscillator, simulate_dmr, simulate_opa

    osc = Oscillator(omega=3.98)
    kw = dict(sigma=0.03, order=2, periods=2, per_period=8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # an adaptive budget of 4 is meant to run out
        return {
            "dmr": simulate_dmr(osc, periods=2, per_period=8),
            "opa": simulate_opa(osc, **kw),
            "opa K=3 beta": simulate_opa(osc, elements=3, distribution="beta:2,3", **kw),
            "opa adaptive uniform c": simulate_opa(
                osc, elements="adaptive", max_elements=4, distribution="uniform",
                uncertain="c", **{**kw, "sigma": 0.01}),
            "mc": mc.simulate_mc(osc, samples=32, progress=False, **kw),
            "mc beta": mc.simulate_mc(osc, samples=32, distribution="beta:2,3",
                                      progress=False, **kw),
        }


def test_plot_run_draws_every_kind_of_run(tmp_path):
    """Every run kind is drawn (issue 24: MC and multi-element plots crashed): the time
    panel's line is the run's x (DMR) or E[x], the axes are labelled, the legends lie
    inside their axes, multi-element runs show their elements and ensembles the impacts
    per sample."""
    for name, ds in _runs_of_every_kind().items():
        fig = P.draw_run(ds)
        try:
            axes = fig.axes
            want = ds.x.values if name == "dmr" else ds.x_mean.values
            np.testing.assert_array_equal(axes[0].lines[0].get_ydata(), want)
            extra = ("elements" if "K=" in name or "adaptive" in name else
                     "impacts" if name.startswith("mc") else None)
            assert len(axes) == (3 if extra else 2), name
            if extra == "elements":
                edges = ds.element_edges.values
                assert axes[2].get_xlim()[0] <= edges[0] and axes[2].get_xlim()[1] >= edges[-1]
            for ax in axes:
                assert ax.get_xlabel() and ax.get_ylabel(), (name, ax.get_title())
                legend = ax.get_legend()
                if legend is not None:
                    fig.canvas.draw()
                    box, frame = legend.get_window_extent(), ax.get_window_extent()
                    assert frame.x0 - 1 <= box.x0 and box.x1 <= frame.x1 + 1, name
            law = ds.attrs.get("distribution", "semicircle")
            if law != "semicircle":  # the title names any other law of xi
                assert law in fig._suptitle.get_text(), name
        finally:
            plt.close(fig)
        path = tmp_path / f"{name.replace(' ', '_')}.png"
        P.plot_run(ds, str(path))
        assert path.stat().st_size > 10_000


def test_a_portrait_marks_its_poincare_points_as_asked():
    """The marks are the run's states at t = k 2π/ω (found here from the time grid, not by
    the module's masks), drawn with the record's marker, colour, size and label 3 above
    the line; the default star is 7 points; ``points=None`` draws the line and the wall
    only; a record with no marker or a size <= 0 is refused by name."""
    from opa import simulate_dmr

    osc = preset("3.1", F0=0.0, c=0.05)
    ds = simulate_dmr(osc, periods=40, per_period=8)
    T = 2 * np.pi / osc.omega
    k = ds.time.values / T
    strobe = (np.abs(k - np.round(k)) < 1e-9) & (ds.time.values >= ds.time.values[-1] - 10 * T
                                                  * (1 + 1e-9))
    fig, ax = plt.subplots()
    try:
        P.portrait(ax, ds, last=10, zorder=2,
                   points=P.PoincareMarks("D", color="tab:green", label="marks", size=3.5))
        line, marks = ax.lines[0], ax.lines[1]
        np.testing.assert_array_equal(marks.get_xdata(), ds.x.values[strobe])
        np.testing.assert_array_equal(marks.get_ydata(), ds.v.values[strobe])
        assert (marks.get_marker(), marks.get_color(), marks.get_markersize(),
                marks.get_label(), marks.get_zorder()) == ("D", "tab:green", 3.5, "marks", 5)
        assert line.get_label() == "DMR" and marks.get_linestyle() == "None"
        ax.clear()
        P.portrait(ax, ds, last=10)
        assert ax.lines[1].get_marker() == "*" and ax.lines[1].get_markersize() == 7
        ax.clear()
        P.portrait(ax, ds, last=10, points=None)
        assert len(ax.lines) == 2  # the line and the wall
        assert ax.lines[1].get_xdata()[0] == osc.delta
    finally:
        plt.close(fig)
    with pytest.raises(ValueError, match="marker must be a matplotlib marker.*got ''"):
        P.PoincareMarks("")
    with pytest.raises(ValueError, match="size must be a finite number > 0 or None, got 0"):
        P.PoincareMarks(size=0)


def test_a_run_of_several_parameters_draws_its_sobol_indices_over_time():
    """The third panel holds each parameter's first-order and total index of x, the
    dataset's own values (NaN at the deterministic start left as a gap), on [0, 1]."""
    import opa

    system = opa.System(preset("3.2"), uncertain="mu,c", sigma=(0.016, 0.005), order=2)
    boxes = P.draw_run(opa.simulate_opa(system, periods=2, per_period=8, elements=2),
                       per_period=8)  # on boxes too (it drew the 1-D elements' panel)
    assert boxes.axes[2].get_title() == "Sobol indices from the OPA coefficients"
    plt.close(boxes)
    ds = opa.simulate_opa(system, periods=2, per_period=8)
    fig = P.draw_run(ds, per_period=8)
    try:
        panel = fig.axes[2]
        lines = {line.get_label(): line.get_ydata() for line in panel.get_lines()}
        for name in ("mu", "c"):
            np.testing.assert_array_equal(lines[f"{name}: first order"],
                                          ds.x_sobol_first.sel(parameter=name).values)
            np.testing.assert_array_equal(lines[f"{name}: total"],
                                          ds.x_sobol_total.sel(parameter=name).values)
        assert panel.get_ylim() == (-0.02, 1.02)
        assert "0.016, 0.005" in fig._suptitle.get_text()
    finally:
        plt.close(fig)
