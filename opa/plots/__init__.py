"""Figures: matplotlib only, no computation. Import it only where a figure is drawn
(``import opa`` does not import matplotlib)."""

from opa.plots._branches import plot_branches
from opa.plots._diagrams import plot_bifurcation, plot_run

__all__ = ["plot_bifurcation", "plot_branches", "plot_run"]
