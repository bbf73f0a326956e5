"""The stochastic diagram's figure: one line per attractor type that occurs, drawn from
the dataset's probabilities, the boundaries in xi below, labelled axes, written to disk."""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from opa import preset  # noqa: E402
from opa.dynamics import stochastic_diagram  # noqa: E402
from opa.plots._stochastic import draw_stochastic, plot_stochastic  # noqa: E402


def test_the_figure_draws_the_probabilities_and_boundaries(tmp_path):
    ds = stochastic_diagram(preset("3.1", F0=0.0), "c", [0.0396996668, 0.05], sigma=0.03,
                            samples=16, transient=500)
    fig = draw_stochastic(ds)
    try:
        ax_p, ax_b = fig.axes[:2]
        lines = {line.get_label(): line for line in ax_p.get_lines()
                 if not line.get_label().startswith("_")}
        assert set(lines) == {"2/2", "4/4"}
        for kind, line in lines.items():
            np.testing.assert_array_equal(line.get_ydata(), ds.probability.sel(type=kind))
        marks = [line for line in ax_b.get_lines() if line.get_label() == "period-doubling"]
        assert len(marks) == 1 and abs(marks[0].get_ydata()[0]) < 1e-6
        for ax in (ax_p, ax_b):
            assert ax.get_ylabel()
        assert ax_b.get_xlabel() == "control parameter c"
    finally:
        plt.close(fig)
    path = tmp_path / "s.png"
    plot_stochastic(ds, str(path))
    assert path.stat().st_size > 10_000
