"""Figures: matplotlib only, no computation. Import it only where a figure is drawn
(``import opa`` does not import matplotlib)."""

from opa.plots._branches import plot_branches
from opa.plots._sensitivity import plot_sensitivity
from opa.plots._stochastic import plot_stochastic
from opa.plots._diagrams import (
    COLORS,
    PoincareMarks,
    SECTION_LABELS,
    describe_marks,
    diagram,
    draw_marks,
    history,
    located_marks,
    plot_bifurcation,
    plot_run,
    portrait,
    section_bars,
    window,
)

__all__ = [
    "plot_bifurcation", "plot_branches", "plot_run", "plot_sensitivity", "plot_stochastic",
    # the drawing blocks of the paper's figures (``compare._figures``)
    "COLORS", "PoincareMarks", "SECTION_LABELS", "describe_marks", "diagram", "draw_marks",
    "history", "located_marks", "portrait", "section_bars", "window",
]
