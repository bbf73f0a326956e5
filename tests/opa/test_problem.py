"""The problem object: names, scales and joint law of the uncertain parameters, and the
one map from xi to parameter values (``opa/_problem.py``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import opa
from opa._problem import Problem, split_list


def test_one_parameter_is_the_papers_uncertainty_bit_for_bit():
    """p_bar + sigma xi as numpy computes it, and the other columns the oscillator's."""
    osc = opa.preset("3.2")
    xi = opa.gauss_nodes(9)[0]
    for name, col in (("mu", 0), ("a", 1), ("c", 2)):
        table = Problem(name, 0.013).table(xi, osc)
        want = np.array([osc.mu, osc.a, osc.c])[None, :].repeat(len(xi), axis=0)
        want[:, col] = getattr(osc, name) + 0.013 * xi
        assert np.array_equal(table[:, :3], want), name
        assert not table[:, 3:-5].any(), name  # no user's force law: its columns are zero
        want = [[osc.eta, osc.delta, osc.f, osc.omega, osc.F0]] * len(xi)
        assert np.array_equal(table[:, -5:], np.array(want)), name


def test_several_parameters_each_get_their_own_scale_and_column():
    osc = opa.preset("3.2")
    problem = Problem(("c", "mu"), scales=(0.5, 0.25), laws="uniform")
    xi = np.array([[1.0, -1.0], [0.0, 0.5]])
    table = problem.table(xi, osc)
    np.testing.assert_array_equal(table[:, 0], [osc.mu - 0.25, osc.mu + 0.125])
    np.testing.assert_array_equal(table[:, 1], [osc.a, osc.a])
    np.testing.assert_array_equal(table[:, 2], [osc.c + 0.5, osc.c])
    np.testing.assert_array_equal(problem.support, [[-1, 1], [-1, 1]])


@pytest.mark.parametrize("text, want", [
    ("mu,c", ("mu", "c")), ("semicircle, uniform", ("semicircle", "uniform")),
    ("beta:2,3,uniform", ("beta:2,3", "uniform")), ("uniform,beta:2,3", ("uniform", "beta:2,3")),
    ("0.02,0.005", ("0.02", "0.005")),
])
def test_lists_split_where_a_law_keeps_its_arguments(text, want):
    assert split_list(text) == want


def test_one_scale_and_one_law_apply_to_all():
    problem = Problem("mu,a,c", scales=0.01, laws="beta:2,3")
    assert problem.scales == (0.01,) * 3
    assert [m.name for m in problem.measures] == [problem.measures[0].name] * 3
    with pytest.raises(ValueError, match="sigma must be a real number"):
        Problem("mu,c", scales="0.02,0.005")  # the CLI parses numbers; the API takes them


@pytest.mark.parametrize("kwargs, words", [
    (dict(names="mu,mu"), "twice"),
    (dict(names="x"), "uncertain must name"),
    (dict(names="x0"), "uncertain must name"),
    (dict(names="omega1"), "uncertain must name"),
    (dict(names="mu,c", scales=(0.1, 0.2, 0.3)), "one per uncertain parameter (2), got 3"),
    (dict(names="mu", scales=-1.0), "sigma must be >= 0"),
    (dict(names="mu", scales=float("nan")), "sigma must be finite"),
    (dict(names="mu,c", laws="cauchy"), "distribution"),
])
def test_bad_problems_get_one_line_naming_the_culprit(kwargs, words):
    with pytest.raises(ValueError, match=None) as err:
        Problem(**kwargs)
    assert words in str(err.value)


def test_negative_values_are_refused_per_parameter_unless_allowed():
    osc = opa.Oscillator(mu=0.01, c=1.0)
    with pytest.raises(ValueError, match="makes mu = 0.01"):
        Problem("c,mu", scales=(0.1, 0.02)).check(osc)
    Problem("c,mu", scales=(0.1, 0.02), allow_negative=True).check(osc)
    Problem("c,mu", scales=(0.1, 0.01)).check(osc)


@pytest.mark.parametrize("sampler", ["sobol", "lhs", "random"])
def test_samples_follow_each_marginal(sampler):
    """Each column's empirical law against its marginal (Kolmogorov-Smirnov), for a
    semicircle and a Beta(2, 3) column; the same seed gives the same points."""
    problem = Problem("mu,c", laws=(None, "beta:2,3"))
    xi = problem.sample(2048, sampler, seed=3)
    assert xi.shape == (2048, 2)
    semicircle = stats.beta(1.5, 1.5, loc=-1, scale=2)
    beta = stats.beta(2, 3, loc=-1, scale=2)
    assert stats.kstest(xi[:, 0], semicircle.cdf).pvalue > 1e-3
    assert stats.kstest(xi[:, 1], beta.cdf).pvalue > 1e-3
    assert np.array_equal(xi, problem.sample(2048, sampler, seed=3))
    assert not np.array_equal(xi, problem.sample(2048, sampler, seed=4))


def test_latin_hypercube_puts_one_point_in_each_stratum():
    problem = Problem("mu,a,c", laws="uniform")
    xi = problem.sample(64, "lhs", seed=1)
    strata = np.floor((xi + 1.0) / 2.0 * 64).astype(int)
    for j in range(3):
        assert sorted(strata[:, j]) == list(range(64))


def test_a_system_of_several_parameters():
    system = opa.System(uncertain="mu,c", sigma=(0.02, 0.005),
                        distribution="semicircle,uniform", order=2)
    assert system.dimension == 2
    assert system.uncertain == ("mu", "c") and system.sigma == (0.02, 0.005)
    assert system.problem.dimension == 2
    attrs = system.dataset_attrs()
    assert attrs["uncertain"] == "mu,c"
    np.testing.assert_array_equal(attrs["sigma"], [0.02, 0.005])
    with pytest.raises(ValueError, match="takes one uncertain parameter; this system has 2"):
        system.one_dimensional("the split scan")
    with pytest.raises(ValueError, match="truncation 'paper'"):
        opa.System(uncertain="mu,c", sigma=0.01, truncation="paper")
    one = opa.System(uncertain=Problem("c", 0.03))
    assert (one.uncertain, one.sigma, one.dimension) == ("c", 0.03, 1)


def test_a_toml_table_names_the_parameters_in_order(tmp_path):
    path = tmp_path / "problem.toml"
    path.write_text('allow_negative = true\n[c]\nsigma = 0.005\ndistribution = "beta:2,3"\n'
                    '[mu]\nsigma = 0.016\n')
    problem = Problem.from_toml(path)
    assert problem == Problem(("c", "mu"), (0.005, 0.016), ("beta:2,3", None), True)


@pytest.mark.parametrize("text, words", [
    ("[mu]\nsigma = 0.01\nlaw = 'uniform'\n", "[mu] has unknown key(s) 'law'"),
    ("[mu]\ndistribution = 'uniform'\n", "[mu] needs sigma"),
    ("mu = 0.01\n", "'mu' must be a table [mu]"),
    ("allow_negative = true\n", "names no uncertain parameter"),
    ("[mu]\nsigma = 'big'\n", "sigma must be a real number"),
    ("[x]\nsigma = 0.1\n", "uncertain must name parameters"),
    ("[mu\n", "is not valid TOML"),
])
def test_a_bad_problem_file_gets_one_line_naming_it(tmp_path, text, words):
    path = tmp_path / "problem.toml"
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        Problem.from_toml(path)
    assert words in str(err.value)
    with pytest.raises(ValueError, match="problem file .*: not a regular file"):
        Problem.from_toml(tmp_path)


def test_a_problem_and_its_fields_are_not_given_together():
    with pytest.raises(ValueError, match="as a Problem or as sigma"):
        opa.System(uncertain=Problem("mu,c", 0.01), sigma=0.02)


def test_the_names_a_law_allows_count_in_a_digest_only_when_given():
    """``coefficients`` came after parts keyed by a Problem were written: left at None it
    is not in the digest (those keys still match), given it is."""
    from opa._dataset import _canonical

    assert "coefficients" not in _canonical(Problem("mu,c", (0.02, 0.005)))
    assert "coefficients" in _canonical(Problem("zeta", 0.01, coefficients=("zeta",)))
