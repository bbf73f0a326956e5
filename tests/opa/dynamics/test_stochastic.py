"""The stochastic bifurcation diagram (opa.dynamics._stochastic): boundaries in xi against
the deterministic period doubling, against brute-force runs on both sides and (slow) the
scipy reference; probabilities against the law's CDF written out with scipy; Monte Carlo
agreement; the sampling fallback where continuation cannot follow."""

import numpy as np
import pytest
from scipy import stats

from opa import SolverOptions, preset
from opa.dynamics._stochastic import classify, stochastic_diagram
from tests.reference import reference_trajectory

SECTION_31 = preset("3.1", F0=0.0)
#: the deterministic first-but-one period doubling of section 3.1 (F0 = 0) at mu = 0.8,
#: c = 0.0396996668 (docs/stability.md; located in c with mu fixed)
C_PD = 0.0396996668


def test_the_doubling_curve_passes_through_the_deterministic_point():
    """At c = C_PD the boundary in xi is the doubling at mu = 0.8, i.e. xi = 0 (issue
    27's target: within 1e-6), and under the semicircle each side has probability 1/2."""
    ds = stochastic_diagram(SECTION_31, "c", [C_PD], sigma=0.03, samples=0)
    assert abs(float(ds.boundary_xi[0, 0])) < 1e-6
    assert str(ds.boundary_kind.values[0, 0]) == "period-doubling"
    assert list(ds.type.values) == ["2/2", "4/4"]
    np.testing.assert_allclose(ds.probability[0].values, [0.5, 0.5], atol=1e-6)


def test_probabilities_are_the_law_mass_between_the_boundaries():
    """beta:2,3: P(2/2) = F(xi*) with F the beta(2, 3) CDF on [-1, 1] (scipy, here)."""
    ds = stochastic_diagram(SECTION_31, "c", [0.04], sigma=0.03, samples=0,
                            distribution="beta:2,3")
    xi_b = float(ds.boundary_xi[0, 0])
    F = stats.beta(2, 3, loc=-1, scale=2).cdf
    np.testing.assert_allclose(ds.probability.sel(type="2/2").values, [F(xi_b)], atol=1e-12)
    np.testing.assert_allclose(ds.probability.sel(type="4/4").values, [1 - F(xi_b)],
                               atol=1e-12)


def test_the_boundary_separates_what_long_brute_force_runs_see():
    """Independent of the continuation: runs of 4000 periods just below and above the
    located boundary settle on the two types it separates."""
    ds = stochastic_diagram(SECTION_31, "c", [0.04], sigma=0.03, samples=0)
    mu_b = 0.8 + 0.03 * float(ds.boundary_xi[0, 0])
    osc = SECTION_31.replace(c=0.04)
    labels = classify(osc, "mu", [mu_b - 6e-4, mu_b + 6e-4], options=SolverOptions(),
                      transient=4000, record=64)
    assert labels == ["2/2", "4/4"]


def test_monte_carlo_agrees_on_a_smooth_case_and_near_a_doubling():
    ds = stochastic_diagram(SECTION_31, "c", [0.04, 0.07], sigma=0.03, samples=128,
                            transient=1000)
    assert list(ds.agree.values) == [1, 1] and list(ds.method.values) == [0, 0]
    assert float(ds.probability.sel(c=0.07, type="2/2")) == 1.0
    assert float(ds.mc_probability.sel(c=0.07, type="2/2")) == 1.0


def test_where_continuation_cannot_follow_monte_carlo_decides():
    """c = 0.01: most samples have no period within the record: the slice is sampled."""
    ds = stochastic_diagram(SECTION_31, "c", [0.01], sigma=0.03, samples=64)
    assert int(ds.method[0]) == 1
    np.testing.assert_array_equal(ds.probability.values, ds.mc_probability.values)
    assert float(ds.probability.sel(type="none").values[0]) > 0.5


@pytest.mark.parametrize("kw, message", [
    (dict(sigma=0.0), "sigma must be a positive number"),
    (dict(sigma=0.03, samples=1), "samples must be 0 or an integer >= 2"),
    (dict(sigma=0.03, uncertain="f"), "uncertain must be mu, a or c"),
])
def test_bad_arguments_are_named(kw, message):
    with pytest.raises(ValueError, match=message):
        stochastic_diagram(SECTION_31, "c", [0.04], **kw)
    with pytest.raises(ValueError, match="parameter must be a model parameter other"):
        stochastic_diagram(SECTION_31, "mu", [0.8], sigma=0.03)


@pytest.mark.slow
def test_the_boundary_against_the_scipy_reference():
    """The scipy integrator (tests/reference.py), 1500 periods on each side of the
    located boundary: period 2 below it (x(kT) repeats every 2 periods), 4 above."""
    ds = stochastic_diagram(SECTION_31, "c", [0.04], sigma=0.03, samples=0)
    mu_b = 0.8 + 0.03 * float(ds.boundary_xi[0, 0])
    model = {k: getattr(SECTION_31, k) for k in ("a", "f", "omega", "eta", "delta", "F0",
                                                  "a1", "omega1", "n", "x0", "v0")}
    T = 2 * np.pi / SECTION_31.omega
    t = np.arange(1501) * T
    for mu, repeat in ((mu_b - 3e-3, 2), (mu_b + 3e-3, 4)):
        x = reference_trajectory(mu=mu, c=0.04, t_out=t, **model)["x"][-16:]
        assert np.abs(x[repeat:] - x[:-repeat]).max() < 1e-6
        assert np.abs(x[repeat // 2:] - x[:-(repeat // 2)]).max() > 1e-3


def test_an_interrupted_diagram_resumes_from_its_parts(tmp_path, monkeypatch):
    """Each finished value is kept; a rerun computes only what is missing, and gives the
    same dataset. A damaged part is computed again."""
    import opa.dynamics._stochastic as S

    kw = dict(sigma=0.03, samples=8, transient=200, parts=str(tmp_path / "parts"))
    first = stochastic_diagram(SECTION_31, "c", [0.04], **kw)
    calls = []
    original = S.stochastic_slice
    monkeypatch.setattr(S, "stochastic_slice",
                        lambda *a, **k: calls.append(1) or original(*a, **k))
    both = stochastic_diagram(SECTION_31, "c", [0.04, 0.05], **kw)
    assert len(calls) == 1  # 0.04 was read back
    np.testing.assert_array_equal(both.probability.sel(c=0.04).values,
                                  first.probability.sel(c=0.04).values)
    slices = sorted((tmp_path / "parts").glob("slice-*.json"))
    assert len(slices) == 2
    for path in slices:
        path.write_text("{not json")
    with pytest.warns(RuntimeWarning, match="is damaged") as caught:
        again = stochastic_diagram(SECTION_31, "c", [0.04, 0.05], **kw)
    assert len(calls) == 3 and len(caught) == 2
    assert all(path.with_name(path.name + ".bad").exists() for path in slices)
    np.testing.assert_array_equal(again.probability.values, both.probability.values)
