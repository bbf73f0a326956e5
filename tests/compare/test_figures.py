"""Tests for ``compare._figures`` (the paper's Figs. 2-11; the drawing blocks of
``opa.plots._diagrams`` are tested in ``tests/opa/plots/test_diagrams.py``) and for the
trust map report's figures (``compare._mapfigures``).

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


# --------------------------------------------------------------------------- read at a glance
# Reading aids every figure of the project keeps (the paper's figures above, the trust map's
# report, a run with its certificate, the stochastic diagram): a legend lists only what is
# drawn, two differently named lines of one panel never share colour, dash and marker, a
# band is opaque enough to be seen, a log axis is not stretched by the exact zero of t = 0,
# and a time axis is in forcing periods, as the text counts time.

#: the least opacity of a band (fill_between) that reads on paper and on screen
MIN_BAND_ALPHA = 0.2
#: decades a log axis may reach below its lowest value at t > 0
SLACK_DECADES = 2


def _drawn_labels(fig) -> set[str]:
    """Labels of the artists that draw something."""
    from matplotlib.collections import PathCollection

    out = set()
    for ax in fig.axes:
        for line in ax.get_lines():
            if len(line.get_xdata()) and line.get_visible():
                out.add(line.get_label())
        for coll in ax.collections:  # a scatter draws its offsets, a band its paths
            if isinstance(coll, PathCollection):
                if len(coll.get_offsets()):
                    out.add(coll.get_label())
            elif len(coll.get_paths()):
                out.add(coll.get_label())
        for cont in ax.containers:
            out.add(cont.get_label())
        for patch in ax.patches:
            out.add(patch.get_label())
    return out


def _legends(fig):
    return [ax.get_legend() for ax in fig.axes if ax.get_legend()] + list(fig.legends)


def legend_entries_without_artist(fig) -> list[str]:
    drawn = _drawn_labels(fig)
    return [text.get_text() for legend in _legends(fig) for text in legend.get_texts()
            if text.get_text() not in drawn]


def shared_styles(fig) -> list[tuple[str, str]]:
    """Pairs of differently named lines of one panel with the same colour, dash and marker."""
    from matplotlib.colors import to_rgba

    clashes = []
    for ax in fig.axes:
        seen = {}
        for line in ax.get_lines():
            label = line.get_label()
            if label.startswith("_") or not len(line.get_xdata()):
                continue
            key = (to_rgba(line.get_color()), str(line.get_linestyle()), str(line.get_marker()))
            if key in seen and seen[key] != label:
                clashes.append((seen[key], label))
            seen.setdefault(key, label)
    return clashes


def _colour(c):
    """A colour as an RGBA tuple rounded to what an eye can tell, None if invisible."""
    from matplotlib.colors import to_rgba

    if c is None or (isinstance(c, str) and c.lower() == "none"):
        return None
    rgba = np.asarray(to_rgba(c) if isinstance(c, str) or np.ndim(c) == 1 else c[0], float)
    return None if rgba[3] == 0 else tuple(np.round(rgba, 2))


def _shape(path) -> tuple:
    """A marker's outline, whatever its size."""
    v = np.asarray(path.vertices, float)
    v = v / max(float(np.abs(v).max()), 1e-12)
    codes = () if path.codes is None else tuple(path.codes)
    return tuple(np.round(v, 2).ravel()), codes


def _dash(offset, dashes, width=1.0) -> tuple | None:
    """A dash pattern at line width 1 (None: solid)."""
    return None if dashes is None else tuple(np.round(np.asarray(dashes, float) / width, 2))


def _glyph(handle) -> frozenset:
    """What a legend handle draws, in parts a reader tells apart at a glance: its line
    (colour, dash), its marker (outline, face, edge) and its fill (colour). Widths and
    sizes are left out: a thicker line of one colour and dash reads as the same line."""
    from matplotlib.collections import LineCollection, PathCollection
    from matplotlib.lines import Line2D
    from matplotlib.markers import MarkerStyle
    from matplotlib.patches import Patch

    parts = set()
    if isinstance(handle, Line2D):
        if handle.get_linestyle() not in ("None", "none", "", " ") and handle.get_linewidth():
            parts.add(("line", _colour(handle.get_color()),
                       _dash(*handle._unscaled_dash_pattern)))
        if handle.get_marker() not in (None, "None", "none", "", " "):
            style = MarkerStyle(handle.get_marker(), handle.get_fillstyle())
            face = _colour(handle.get_markerfacecolor()) if style.is_filled() else None
            parts.add(("marker", _shape(style.get_path().transformed(style.get_transform())),
                       face, _colour(handle.get_markeredgecolor())))
    elif isinstance(handle, PathCollection):
        edge = (_colour(handle.get_edgecolor()) if len(handle.get_edgecolor())
                and np.max(handle.get_linewidth()) > 0 else None)
        face = _colour(handle.get_facecolor()) if len(handle.get_facecolor()) else None
        parts.add(("marker", _shape(handle.get_paths()[0]), face, edge))
    elif isinstance(handle, LineCollection):  # error bars: a line in the legend
        offset, dashes = handle.get_linestyle()[0]  # scaled by the width, unlike a line's
        width = float(np.atleast_1d(handle.get_linewidth())[0]) or 1.0
        parts.add(("line", _colour(handle.get_color()), _dash(offset, dashes, width)))
    elif isinstance(handle, Patch):
        parts.add(("fill", _colour(handle.get_facecolor())))
    return frozenset(parts)


def shared_glyphs(fig) -> list[tuple[str, str]]:
    """Pairs of entries of one legend whose glyphs a reader cannot tell apart: the same
    glyph, or one entry's glyph a part of the other's (an open circle alone and a line
    with open circles on it; a black line alone and a black line with squares). One glyph,
    one meaning. An entry whose glyph the check cannot read is reported with None."""
    clashes = []
    for legend in _legends(fig):
        entries = [(text.get_text(), _glyph(handle))
                   for text, handle in zip(legend.get_texts(), legend.legend_handles)]
        clashes += [(a, None) for a, ga in entries if not ga]
        for i, (a, ga) in enumerate(entries):
            for b, gb in entries[i + 1:]:
                if a != b and ga and gb and (ga <= gb or gb <= ga):
                    clashes.append((a, b))
    return clashes


def faint_bands(fig) -> list[str]:
    from matplotlib.collections import FillBetweenPolyCollection, PolyCollection

    kinds = (FillBetweenPolyCollection, PolyCollection)
    return [f"{ax.get_title()}: {coll.get_label()} alpha {coll.get_alpha()}"
            for ax in fig.axes for coll in ax.collections
            if isinstance(coll, kinds) and coll.get_alpha() is not None
            and coll.get_alpha() < MIN_BAND_ALPHA]


def _is_time_axis(label: str) -> bool:
    return label == "t" or label.startswith("t ") or label.startswith("t [")


def log_axes_stretched_by_t0(fig) -> list[str]:
    """Log y axes over time whose lower limit lies far below every value drawn at t > 0."""
    bad = []
    for ax in fig.axes:
        if ax.get_yscale() != "log" or not _is_time_axis(ax.get_xlabel()):
            continue
        later = []
        for line in ax.get_lines():
            x = np.asarray(line.get_xdata(), float)
            y = np.asarray(line.get_ydata(), float)
            keep = (x > 0) & np.isfinite(y) & (y > 0)
            later.extend(y[keep])
        if later and ax.get_ylim()[0] < min(later) * 10.0 ** -SLACK_DECADES:
            bad.append(f"{ax.get_title()}: bottom {ax.get_ylim()[0]:.1e}, "
                       f"lowest at t > 0 {min(later):.1e}")
    return bad


def time_axes_not_in_periods(fig) -> list[str]:
    """Time axes that do not say their unit: forcing periods, as the texts count time, or
    time units where a caption counts in them (the paper's Fig. 2)."""
    return [label for ax in fig.axes for label in (ax.get_xlabel(),)
            if _is_time_axis(label) and label not in ("t [forcing periods]", "t [time units]")]


def check_reads_at_a_glance(fig, name):
    assert legend_entries_without_artist(fig) == [], name
    assert shared_styles(fig) == [], name
    assert shared_glyphs(fig) == [], name
    assert faint_bands(fig) == [], name
    assert log_axes_stretched_by_t0(fig) == [], name
    assert time_axes_not_in_periods(fig) == [], name


# the checks themselves fail on the defects they guard against


def test_the_checks_catch_each_defect():
    fig, ax = plt.subplots()
    t = np.linspace(0, 10, 50)
    ax.plot(t, t + 1, color="k", label="OPA N = 2")
    ax.plot(t, t + 2, color="k", label="OPA N = 4")  # one style, two methods
    ax.fill_between(t, t, t + 1, alpha=0.05, label="± 2 SE")  # invisible band
    ax.scatter([], [], label="split")  # a legend entry for nothing
    ax.legend()
    ax.set_xlabel("t")  # time units
    assert legend_entries_without_artist(fig) == ["split"]
    assert shared_styles(fig) == [("OPA N = 2", "OPA N = 4")]
    assert len(faint_bands(fig)) == 1
    assert time_axes_not_in_periods(fig) == ["t"]
    fig2, ax2 = plt.subplots()
    ax2.semilogy(t, np.where(t == 0, 1e-16, 1e-3 + t * 1e-4))  # the exact zero at t = 0
    ax2.set_xlabel("t [forcing periods]")
    assert len(log_axes_stretched_by_t0(fig2)) == 1
    plt.close(fig)
    plt.close(fig2)


def test_the_glyph_check_catches_one_glyph_with_two_meanings():
    """Two entries of one legend clash when their glyphs are alike or one is a part of the
    other, widths and sizes aside; a different shape, fill or dash tells them apart."""
    fig, (ax, ax2) = plt.subplots(1, 2)
    t = np.linspace(0, 10, 5)
    ax.scatter(t, t, marker="o", facecolor="white", edgecolor="k", s=26, label="agrees")
    ax.plot(t, t + 1, "k-", marker="o", mfc="white", ms=5, label="σ* (circles)")
    ax.plot(t, t + 2, "k-", lw=2.2, label="MC mean")
    ax.plot(t, t + 3, "k-", lw=1.0, label="2 MC SE")
    ax.legend()
    assert {frozenset(pair) for pair in shared_glyphs(fig)} == {
        frozenset(pair) for pair in (("agrees", "σ* (circles)"), ("MC mean", "2 MC SE"),
                                     ("MC mean", "σ* (circles)"), ("2 MC SE", "σ* (circles)"))}
    ax2.scatter(t, t, marker="o", facecolor="white", edgecolor="k", label="agrees")
    ax2.scatter(t, t, marker="o", facecolor="0.6", edgecolor="k", label="undecided")
    ax2.scatter(t, t, marker="x", color="k", label="does not")
    ax2.plot(t, t, "k-", marker="s", mfc="white", label="σ*")
    ax2.plot(t, t, "k--", label="2 MC SE")
    ax2.plot(t, t, color="tab:red", ls=(0, (5, 1, 1, 1)), label="tolerance")
    ax2.plot(t, t, color="tab:red", ls=(0, (1, 1)), label="other")
    ax2.vlines(t, t, t + 1, color="darkgreen", lw=1.6, label="MC mean ± 2 SE")
    ax2.fill_between(t, t, t + 1, color="0.55", alpha=0.35, label="within 2 SE")
    ax.get_legend().remove()
    ax2.legend()
    assert shared_glyphs(fig) == []
    # error bars read as a line of their colour and dash, whatever their width
    ax2.plot(t, t, color="darkgreen", lw=0.8, label="MC mean")
    ax2.vlines(t, t, t + 1, color="tab:red", ls=(0, (1, 1)), lw=2.5, label="red bars")
    ax2.legend()
    assert {frozenset(pair) for pair in shared_glyphs(fig)} == {
        frozenset(("MC mean ± 2 SE", "MC mean")), frozenset(("other", "red bars"))}
    plt.close(fig)


@pytest.mark.parametrize("name", F.FIGURES)
def test_paper_figures_read_at_a_glance(drawn, name):
    _, figures = drawn
    check_reads_at_a_glance(figures[name].fig, name)


REPORT_FIGURES = ("trust_map.png", "error_vs_N.png", "mean_vs_mc.png", "variance.png",
                  "phase.png", "frontier.png")


def draw_report(ds, out) -> dict:
    """Every figure of the trust map's report of ``ds``, drawn into ``out`` and kept open
    for inspection, by file name."""
    from matplotlib.figure import Figure

    from compare import _mapfigures as M

    kept = {}
    save = Figure.savefig

    def keep(fig, path, *args, **kw):
        kept[os.path.basename(str(path))] = fig
        return save(fig, path, *args, **kw)

    Figure.savefig = keep
    try:
        for name, draw in zip(REPORT_FIGURES, (M.plot_map, M.plot_error_vs_order, M.plot_mean,
                                               M.plot_variance, M.plot_phase,
                                               M._plot_frontier_of)):
            draw(ds, str(out / name))
    finally:
        Figure.savefig = save
    return kept


@pytest.fixture(scope="module")
def report_figures(tmp_path_factory):
    """Every figure of the trust map's report, drawn from a tiny map's validate.nc, kept
    open for inspection."""
    from compare import load_config, run_validation

    out = tmp_path_factory.mktemp("map")
    cfg = load_config(None, outdir=str(out), values=(3.98, 4.035), sigmas=(0.01, 0.03),
                      orders=(0, 1, 3), horizons=(4, 8), samples=64, max_samples=128,
                      per_period=4)
    run_validation(cfg, progress=False, log=lambda *a: None)
    ds = xr.open_dataset(out / "validate.nc")
    kept = draw_report(ds, out)
    yield ds, kept
    ds.close()


def with_every_entry(ds) -> xr.Dataset:
    """The tiny map changed so that each report figure draws every kind of legend entry it
    has: the three verdicts of the paper's OPA, a run that did not finish (the headline run
    at the first grid point, stopped after output 3, as validate.nc records a stop), sigma*
    resolved at the first value and below the smallest probe at the second, and a split of
    every kind in every column."""
    from compare import _mapread as R

    ds = ds.load().copy(deep=True)
    v, n = R.HEADLINE, -1
    # verdicts (value, sigma): does not at (0, 1), agrees at (1, 0), undecided at (1, 1)
    for (q, s), verdict in {(0, 1): -1, (1, 0): 1, (1, 1): 0}.items():
        ds.verdict.values[q, s, v, n] = verdict
        ds.agrees.values[q, s, v, n] = verdict == 1
    names = ds.opa_status.attrs["flag_meanings"].split()
    ds.opa_status.values[0, 0, v, n] = ds.opa_status.attrs["flag_values"][
        names.index("step_limit")]
    for name in ("opa_x_mean", "opa_x_var"):
        ds[name].values[0, 0, v, n, 3:] = np.nan
    for name in ("err_mean", "err_mean_rel", "err_var", "err_var_rel"):
        ds[name].values[0, 0, v, n] = np.nan
    ds.verdict.values[0, 0, v, n] = -1
    ds.agrees.values[0, 0, v, n] = False
    smax = float(ds.sigma.max())
    ds.sigma_star.values[0] = 0.5 * smax
    ds.sigma_star_upper.values[0] = 0.6 * smax
    ds.sigma_star.values[1] = 0.0
    ds.sigma_star_upper.values[1] = 0.5 * float(ds.sigma.min())
    kinds = ds.split_kind.attrs["flag_meanings"].split()
    for k in range(len(kinds)):
        ds.split_kind.values[:, :, k] = ds.split_kind.attrs["flag_values"][k]
        ds.split_value.values[:, :, k] = R.nominal(ds) + (k + 1) * smax / (len(kinds) + 1)
    return ds


@pytest.fixture(scope="module")
def every_entry_figures(report_figures, tmp_path_factory):
    """The report's figures of :func:`with_every_entry`'s map, kept open."""
    ds = with_every_entry(report_figures[0])
    yield ds, draw_report(ds, tmp_path_factory.mktemp("every_entry"))


@pytest.mark.parametrize("name", REPORT_FIGURES)
def test_report_figures_read_at_a_glance(report_figures, name):
    _, kept = report_figures
    check_reads_at_a_glance(kept[name], name)


@pytest.mark.parametrize("name", REPORT_FIGURES)
def test_report_figures_read_at_a_glance_with_every_entry(every_entry_figures, name):
    """Every report figure, with every kind of legend entry it can draw present, gives
    each entry a glyph of its own (and passes the other checks)."""
    _, kept = every_entry_figures
    check_reads_at_a_glance(kept[name], name)


def test_every_entry_map_draws_every_entry(every_entry_figures):
    """The map of the test above does draw each kind of entry (else its check is void)."""
    ds, kept = every_entry_figures
    head = str(ds.variant.values[0])
    entries = {t.get_text() for legend in _legends(kept["trust_map.png"])
               for t in legend.get_texts()}
    kinds = [k.replace("_", " ") for k in ds.split_kind.attrs["flag_meanings"].split()]
    wanted = {f"{head} agrees", f"{head} does not", f"{head} undecided (counts as does not)",
              "run did not finish (NaN)", "σ probed",
              *(f"σ* {name}" for name in ("mean/galerkin", "ensemble/galerkin",
                                           "saltation/galerkin")),
              *(f"below the smallest σ probed: σ* {name}"
                for name in ("mean/galerkin", "ensemble/galerkin", "saltation/galerkin")),
              "first output crossing at this σ",
              *(f"first split ({k}) at this σ" for k in kinds
                if k not in ("horizon", "output crossing"))}
    assert wanted <= entries, wanted - entries
    entries = {t.get_text() for legend in _legends(kept["error_vs_N.png"])
               for t in legend.get_texts()}
    assert "run did not finish (NaN)" in entries


def test_trust_map_glyphs_have_one_meaning(report_figures):
    """Verdicts, sigma* markers and split markers never share a glyph; sigma* below the
    smallest probe has its own arrow; the swept parameter is named by its symbol."""
    from compare import _mapfigures as M

    _, kept = report_figures
    fig = kept["trust_map.png"]
    verdicts = {"o", "x"}
    stars = {mark for _, _, mark in M.STAR_STYLES}
    splits = set(M.KIND_MARKERS.values())
    assert not (verdicts & stars) and not (verdicts & splits) and not (stars & splits)
    assert M.BELOW_MARKER not in stars | splits | verdicts
    assert all(ax.get_xlabel() in ("", "ω") for ax in fig.axes[:4])
    assert "\n" not in fig._suptitle.get_text()


def test_error_vs_n_draws_the_tolerance(report_figures):
    """The tolerance and the noise floor are drawn in every panel, each in a colour that no
    variant's line has (one colour, one meaning)."""
    from matplotlib.colors import to_rgba

    ds, kept = report_figures
    variants = {str(v) for v in ds.variant.values}
    for ax in kept["error_vs_N.png"].axes:
        colours = {line.get_label(): to_rgba(line.get_color()) for line in ax.get_lines()}
        assert "the verdict's tolerance (mean)" in colours
        assert "MC noise floor (RMS SE)" in colours
        used = {colours[v] for v in variants}
        assert len(used) == len(variants)
        assert colours["the verdict's tolerance (mean)"] not in used
        assert colours["MC noise floor (RMS SE)"] not in used


def test_frontier_has_a_legend_per_panel_and_one_style_per_method(report_figures):
    _, kept = report_figures
    fig = kept["frontier.png"]
    assert all(ax.get_legend() is not None for ax in fig.axes)
    style = {}
    for ax in fig.axes:
        for line in ax.get_lines():
            label = line.get_label()
            if label.startswith("_") or "standard error" in label:
                continue
            method = label.split(", K =")[0]
            key = (line.get_color(), line.get_marker())
            assert style.setdefault(method, key) == key, method  # the same in every panel
    assert len(set(style.values())) == len(style)  # and no two methods alike


@pytest.mark.parametrize("verdict", ["agrees", "disagrees", "undecided"])
def test_a_certified_run_draws_its_certificate(verdict):
    """``plot_run`` of a run with a certificate draws it, in the verdict's colour, for each
    of the three verdicts."""
    import opa
    from opa.plots._diagrams import VERDICT_COLORS, draw_run

    run = opa.simulate_opa(opa.Oscillator(omega=3.98), sigma=0.01, order=2, periods=2,
                           per_period=8)
    n = run.sizes["time"]
    ramp = np.linspace(0.0, 1e-4, n)
    run = run.assign(verify_err_mean=("time", ramp), verify_err_mean_sem=("time", ramp / 5),
                     cv_x_var=run.x_var)
    run.attrs.update(verdict=verdict, verdict_mean=verdict, verdict_var="agrees",
                     verify_samples=64, verify_tolerance=0.1)
    fig = draw_run(run)
    try:
        cert = fig.axes[-1]
        assert verdict.upper() in cert.get_title()
        assert cert.title.get_color() == VERDICT_COLORS[verdict]
        check_reads_at_a_glance(fig, f"certificate, {verdict}")
    finally:
        plt.close(fig)


def test_stochastic_figure_names_its_branches_and_shows_rare_bins():
    """The shaded panel's rarest colour is not near white, and each attractor type that
    occurs is named on it."""
    from matplotlib.colors import to_rgba

    from opa import preset
    from opa.dynamics import stochastic_diagram
    from opa.plots._stochastic import _density_colours, draw_stochastic

    rare = np.array(to_rgba(_density_colours()(0.0))[:3])
    assert rare.min() < 0.8  # visible on a white background
    ds = stochastic_diagram(preset("3.1", F0=0.0), "c", [0.0396996668, 0.05], sigma=0.03,
                            samples=16, extra_states=0)
    fig = draw_stochastic(ds)
    try:
        names = {text.get_text() for text in fig.axes[0].texts}
        occurring = {str(t) for t in np.unique(ds.mc_type.values.astype(str)) if str(t)}
        assert occurring and occurring <= names
        check_reads_at_a_glance(fig, "stochastic")
    finally:
        plt.close(fig)


def test_the_variance_figure_draws_the_verdicts_tolerance(report_figures):
    """variance.png draws MC Var x (1 +- var_tolerance) in every panel: the lines lie at
    exactly those multiples of the drawn MC variance."""
    ds, kept = report_figures
    tol = float(ds.attrs["var_tolerance"])
    fig = kept["variance.png"]
    labels = [t.get_text() for legend in fig.legends for t in legend.get_texts()]
    assert f"tolerance: MC Var × (1 ± {tol:g})" in labels
    for ax in fig.axes:
        lines = ax.get_lines()
        var = lines[0].get_ydata()  # the MC variance, drawn first
        bounds = [line.get_ydata() for line in lines[1:3]]
        keep = var * (1 - tol) > 1e-16
        np.testing.assert_allclose(bounds[0][keep], var[keep] * (1 - tol), rtol=1e-12)
        np.testing.assert_allclose(bounds[1][keep], var[keep] * (1 + tol), rtol=1e-12)
