"""The stochastic diagram's figure: the samples' Poincaré points shaded by probability (a
law per control value: mass 1 per column, on the orbit's points), one line per attractor
type drawn from the dataset's probabilities, the boundaries in xi, the EMR beside them,
labelled axes, written to disk."""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from opa import preset  # noqa: E402
from opa.dynamics import stochastic_diagram  # noqa: E402
from opa.plots._stochastic import draw_stochastic, plot_stochastic, section_density  # noqa: E402


@pytest.fixture(scope="module")
def diagram():
    return stochastic_diagram(preset("3.1", F0=0.0), "c", [0.0396996668, 0.05], sigma=0.03,
                              samples=16, extra_states=0, emr=True)


def test_the_shaded_points_are_a_law_per_control_value(diagram):
    """Each column holds mass 1; at c = 0.05 (2/2 for every xi, a 2-point orbit whose
    points move little with xi) the mass sits on two narrow clusters of x."""
    c_edges, x_edges, mass = section_density(diagram)
    assert mass.shape == (2, len(x_edges) - 1) and len(c_edges) == 3
    np.testing.assert_allclose(mass.sum(axis=1), 1.0, atol=1e-12)
    x = diagram.mc_x.sel(c=0.05).values
    centres = 0.5 * (x_edges[1:] + x_edges[:-1])
    heavy = centres[mass[1] > 0]
    assert np.all(np.min(np.abs(heavy[:, None] - np.nanmean(x[:, :2], axis=0)[None]),
                         axis=1) < 0.05)


def test_the_figure_draws_the_probabilities_boundaries_and_emr(diagram, tmp_path):
    fig = draw_stochastic(diagram)
    try:
        ax_pts, ax_emr, ax_p, ax_b = fig.axes[:4]
        lines = {line.get_label(): line for line in ax_p.get_lines()
                 if not line.get_label().startswith("_")}
        assert set(lines) == {"2/2", "4/4"}
        for kind, line in lines.items():
            np.testing.assert_array_equal(line.get_ydata(), diagram.probability.sel(type=kind))
        marks = [line for line in ax_b.get_lines() if line.get_label() == "period-doubling"]
        assert len(marks) == 1 and abs(marks[0].get_ydata()[0]) < 1e-6
        drawn = ax_emr.get_lines()[0].get_ydata()
        finite = diagram.emr_x.values[np.isfinite(diagram.emr_x.values)]
        np.testing.assert_array_equal(np.sort(drawn), np.sort(finite))
        for ax in (ax_pts, ax_emr, ax_p, ax_b):
            assert ax.get_ylabel()
        assert ax_b.get_xlabel() == "control parameter c"
    finally:
        plt.close(fig)
    path = tmp_path / "s.png"
    plot_stochastic(diagram, str(path))
    assert path.stat().st_size > 10_000


def test_the_figure_without_samples_or_emr(tmp_path):
    ds = stochastic_diagram(preset("3.1", F0=0.0), "c", [0.05], sigma=0.03, samples=0,
                            extra_states=0)
    fig = draw_stochastic(ds)
    try:
        assert len(fig.axes) == 3
    finally:
        plt.close(fig)


def test_the_figure_of_several_uncertain_parameters_has_no_boundary_panel(tmp_path):
    """(mu, a) uncertain: no boundaries are located, so the figure is two panels, the
    points and the sampled probabilities, titled with both parameters."""
    from opa import System

    system = System(preset("3.1", F0=0.0), uncertain="mu,a", sigma=(0.03, 0.002),
                    distribution="semicircle,uniform")
    ds = stochastic_diagram(system, "c", [0.0396996668, 0.05], samples=16, extra_states=0)
    fig = draw_stochastic(ds)
    axes = fig.get_axes()
    titles = " ".join(ax.get_title() for ax in axes)
    assert "mu = 0.8 + 0.03 ξ1, a = 1 + 0.002 ξ2" in titles
    assert "no boundaries" in titles
    assert not any("boundary" in ax.get_ylabel() for ax in axes)
    plt.close(fig)
    plot_stochastic(ds, tmp_path / "several.png")
    assert (tmp_path / "several.png").stat().st_size > 10_000
