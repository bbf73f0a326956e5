"""Tests for ``compare._figures`` (the paper's Figs. 2-11; the drawing blocks of
``opa.plots._diagrams`` are tested in ``tests/opa/plots/test_diagrams.py``).

Every figure is drawn once at tiny sizes (a few sweep values, 20 + 10 periods, 16 Monte
Carlo samples) and then inspected: the paper's panel count, the Monte Carlo mean line and
its ± 2 SE band wherever the EMR is drawn, captions that name what is drawn, no
bifurcation line from brute-force period labels, and measured numbers in the texts.
"""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import re  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import xarray as xr  # noqa: E402

import compare._figures as F  # noqa: E402
from tests.opa.plots.test_diagrams import flag_every_doubling, vertical_lines  # noqa: E402

TINY = F.Sizes(count=4, transient=10, record=6, portrait_transient=20, portrait_record=10,
               last=5, mc_samples=16, sweep_mc_samples=16, sweep_mc_stride=2)

#: panels of each figure in the paper (its captions: (a), (b), ...)
PAPER_PANELS = {"fig2": 2, "fig3": 2, "fig4": 4, "fig5": 2, "fig6": 4, "fig7": 2, "fig8": 2,
                "fig9": 4, "fig10": 4, "fig11": 4}
#: figures that draw the EMR (OPA with sigma > 0), and so the Monte Carlo mean
WITH_EMR = ("fig6", "fig7", "fig8", "fig9")
NUMBER = re.compile(r"\d+(\.\d+)?(e-?\d+)?")


def context(outdir) -> F._Context:
    return F._Context(outdir, TINY, workers=1, progress=False)


@pytest.fixture(scope="module")
def drawn(tmp_path_factory):
    ctx = context(tmp_path_factory.mktemp("figures"))
    figures = {name: F._MAKERS[name](ctx) for name in F.FIGURES}
    yield ctx, figures
    ctx.close()
    for d in figures.values():
        plt.close(d.fig)


def labels(ax) -> list[str]:
    return ([line.get_label() for line in ax.get_lines()]
            + [c.get_label() for c in ax.containers])


# --------------------------------------------------------------------------- layout


@pytest.mark.parametrize("name", F.FIGURES)
def test_panel_count_is_the_papers(drawn, name):
    _, figures = drawn
    assert len(figures[name].fig.axes) == PAPER_PANELS[name]


@pytest.mark.parametrize("name", ["fig6", "fig7", "fig8"])
def test_emr_panels_have_mc_mean_and_band(drawn, name):
    _, figures = drawn
    for ax in figures[name].fig.axes:
        names = labels(ax)
        assert any(n.startswith("EMR (OPA") for n in names)
        assert any(n.startswith("MC mean (16 Sobol") for n in names)  # the line
        assert "MC mean ± 2 SE" in names  # the band at the Poincaré points
        assert "MC ± 1 std (ensemble spread)" in names
        # no deterministic run is repeated in these panels
        assert not any(n in ("DMR", "EMR_0") for n in names)


def test_fig9_mc_mean_beside_every_emr_diagram(drawn):
    _, figures = drawn
    axes = figures["fig9"].fig.axes
    # sigma = 0: EMR_0, with its truth, the DMR, beside it and no Monte Carlo
    assert not any(n.startswith("MC mean") for n in labels(axes[0]))
    assert labels(axes[0]).count("DMR") == 1 and labels(axes[0]).count("EMR_0") == 1
    for ax in axes[1:]:
        assert any(n.startswith("MC mean (16 Sobol") for n in labels(ax))


def test_fig10_draws_the_dmr_beside_every_emr0_diagram(drawn):
    _, figures = drawn
    for ax in figures["fig10"].fig.axes:
        assert labels(ax).count("DMR") == 1 and labels(ax).count("EMR_0") == 1
    text = " ".join(figures["fig10"].differences)
    assert text.count("EMR_0 against the DMR: phase-plane points within 1e-6") == 2


def test_deterministic_figures_draw_each_run_once(drawn):
    _, figures = drawn
    for name in ("fig3", "fig5", "fig11"):
        for ax in figures[name].fig.axes:
            names = labels(ax)
            assert names.count("DMR") == 1
            assert sum(n.startswith("EMR_0") for n in names) == 1


# --------------------------------------------------------------------------- captions


@pytest.mark.parametrize("name", F.FIGURES)
def test_caption_is_the_suptitle_and_names_mc_iff_drawn(drawn, name):
    _, figures = drawn
    d = figures[name]
    assert d.fig._suptitle.get_text().replace("\n", " ") == d.caption
    has_mc = any(n.startswith("MC") for ax in d.fig.axes for n in labels(ax))
    assert has_mc == (name in WITH_EMR)
    assert ("Monte Carlo" in d.caption) == has_mc
    if has_mc:
        assert f"{TINY.mc_samples} scrambled Sobol" in d.caption or \
            f"{TINY.sweep_mc_samples} Sobol" in d.caption
        assert "2 standard errors" in d.caption or name == "fig9"


def test_caption_lists_no_lines_that_are_not_drawn(drawn):
    _, figures = drawn
    for name in ("fig3", "fig9", "fig10"):
        d = figures[name]
        assert "no bifurcation lines" in d.caption
        assert "doubling" not in d.caption and "grazing located" not in d.caption
        for ax in d.fig.axes:
            # only the purple guides at the parameter values of other figures
            assert all("Fig" in label for _, label in vertical_lines(ax) if label[0] != "_")


# --------------------------------------------------------------------------- bifurcation lines


def test_no_line_from_brute_force_period_doubling(tmp_path, monkeypatch):
    original = F._Context.sweep

    def sweep(self, *args, **kw):
        ds, path = original(self, *args, **kw)
        return flag_every_doubling(ds), path

    monkeypatch.setattr(F._Context, "sweep", sweep)
    ctx = context(tmp_path)
    for maker, guides in ((F.fig3, {0.035, 0.05}), (F.fig10, {0.0356})):
        d = maker(ctx)
        for ax in d.fig.axes:
            xs = {round(x, 9) for x, _ in vertical_lines(ax)}
            assert xs <= guides  # the flagged values would add lines here
            assert not any("doubling" in n for n in labels(ax))
        assert "Brute-force" in d.differences[1] or maker is F.fig10
        plt.close(d.fig)


def test_located_bifurcations_are_drawn_and_captioned(tmp_path, monkeypatch):
    original = F._Context.sweep

    def sweep(self, name, model, param, values, osc, **kw):
        ds, path = original(self, name, model, param, values, osc, **kw)
        ds = ds.drop_dims("bifurcation", errors="ignore").assign(
            bifurcation_kind=("bifurcation", np.array([1, 0], dtype=np.int8),
                              {"flag_values": np.arange(5, dtype=np.int8),
                               "flag_meanings": "period_doubling fold neimark_sacker "
                                                "grazing impulse_impact"}),
            bifurcation_c=("bifurcation", [0.0735900439, 0.0323090015]),
        )
        return ds, path

    monkeypatch.setattr(F._Context, "sweep", sweep)
    d = F.fig3(context(tmp_path))
    for ax in d.fig.axes:
        lines = dict((round(x, 6), label) for x, label in vertical_lines(ax))
        assert lines[0.07359] == "fold"
        assert lines[0.032309] == "period doubling"
    assert "fold at c = 0.07359" in d.caption
    assert "period doubling at c = 0.032309" in d.caption
    assert "located bifurcations (vertical lines)" in " ".join(d.differences)
    plt.close(d.fig)


# --------------------------------------------------------------------------- measured texts


@pytest.mark.parametrize("name", F.FIGURES)
def test_differences_are_measured(drawn, name):
    _, figures = drawn
    d = figures[name]
    assert d.differences
    for line in d.differences:
        assert NUMBER.search(line), line


def test_fig6_text_compares_opa_and_mc_variances(drawn):
    _, figures = drawn
    text = " ".join(figures["fig6"].differences)
    for tag in "abcd":
        assert f"({tag})" in text
    assert text.count("OPA's Var[x] grows to") == 4
    assert text.count("Monte Carlo Var[x] is at most") == 4


def test_fig7_fig8_texts_say_whether_grazing_occurs(drawn):
    _, figures = drawn
    for name in ("fig7", "fig8"):
        for line in figures[name].differences:
            assert "razing" in line and "slowest impact" in line


def test_verdict_follows_the_numbers():
    base = {"mc_end_sem": 1e-9}
    assert "artefact of the equivalent system" in F._verdict(
        {**base, "opa_max": 0.5, "mc_max": 1e-5})
    assert "comparable" in F._verdict({**base, "opa_max": 0.3, "mc_max": 0.2})
    assert "smaller than the true ensemble" in F._verdict(
        {**base, "opa_max": 0.01, "mc_max": 0.2})
    assert "neither spreads visibly" in F._verdict({**base, "opa_max": 5e-5, "mc_max": 2e-4})


def test_cycle_note_explains_missing_periods():
    from opa import preset

    assert "every 14 forcing periods" in F._cycle_note(preset("3.1"), 100)
    note = F._cycle_note(preset("3.2", omega=3.98), 100)
    assert "199" in note and "certain" in note
    assert "no common cycle" in F._cycle_note(preset("3.3"), 100)


def test_write_puts_text_and_data_beside_the_png(tmp_path):
    ctx = context(tmp_path)
    paths = F._write(ctx, F.fig5(ctx))
    names = sorted(os.path.basename(p) for p in paths)
    assert names == ["fig5.nc", "fig5.png", "fig5.txt"]
    text = (tmp_path / "fig5.txt").read_text(encoding="utf-8")
    assert "Caption (what is drawn):" in text and "The paper's caption:" in text
    assert "Differences from the paper (measured on this run):" in text
    with xr.open_dataset(tmp_path / "fig5.nc") as ds:
        assert ds.sizes["panel"] == 2
        assert "DMR" in ds.attrs["caption"] and ds.attrs["differences"]
        assert np.isfinite(ds.dmr_x.values[:, 0]).all()


def test_reproduce_fig2_writes_png_and_text(tmp_path):
    paths = F.reproduce("fig2", tmp_path, workers=1)
    assert sorted(os.path.basename(p) for p in paths) == ["fig2.png", "fig2.txt"]
    text = " ".join((tmp_path / "fig2.txt").read_text(encoding="utf-8").split())
    assert "n = 4 cycles through 0.1, 0.2, 0.1, 0" in text
