"""Orthonormal bases and Gauss rules for any law of xi, against closed forms and chaospy."""


import chaospy
import numpy as np
import pytest
from scipy import integrate, special, stats

from opa._basis import chebyshev_u, gauss_nodes
from opa._measure import beta, normal_trunc, parse, semicircle, uniform
from tests.truths import semicircle_density, semicircle_mass


def test_semicircle_recurrence_is_chebyshev_u_past_order_60():
    alpha, b = semicircle().recurrence(130)
    np.testing.assert_allclose(alpha, 0.0, atol=1e-14)
    np.testing.assert_allclose(b[1:], 0.5, atol=1e-13)


@pytest.mark.parametrize("q", [1, 2, 5, 17, 65])
def test_semicircle_gauss_rule_is_the_closed_form(q):
    x, w = semicircle().gauss(q)
    xr, wr = gauss_nodes(q)
    np.testing.assert_allclose(x, xr, atol=1e-14)
    np.testing.assert_allclose(w, wr, atol=1e-14)


def test_semicircle_basis_is_chebyshev_u_to_round_off():
    x = np.linspace(-1, 1, 41)
    got = semicircle().basis(70, x)
    # U_n(x) reaches n + 1 at the ends: compare relative to that size
    np.testing.assert_allclose(got / np.arange(1, 72)[:, None], chebyshev_u(70, x)
                               / np.arange(1, 72)[:, None], atol=1e-12)


def test_uniform_recurrence_is_legendre():
    _, b = uniform().recurrence(80)
    k = np.arange(1, 80)
    np.testing.assert_allclose(b[1:], k / np.sqrt(4 * k * k - 1), atol=1e-14)
    x, w = uniform().gauss(20)
    xr, wr = special.roots_legendre(20)
    np.testing.assert_allclose(x, xr, atol=1e-14)
    np.testing.assert_allclose(w, wr / 2, atol=1e-14)


@pytest.mark.parametrize("law, dist", [
    (beta(2.0, 3.0), chaospy.Beta(2.0, 3.0, -1.0, 1.0)),
    (normal_trunc(2.0), chaospy.TruncNormal(-1.0, 1.0, 0.0, 0.5)),
    (uniform(), chaospy.Uniform(-1.0, 1.0)),
])
def test_gauss_rules_match_chaospy_at_low_order(law, dist):
    nodes, weights = chaospy.generate_quadrature(5, dist, rule="gaussian")
    x, w = law.gauss(6)
    np.testing.assert_allclose(x, np.sort(nodes[0]), atol=1e-10)
    np.testing.assert_allclose(w, weights[np.argsort(nodes[0])], atol=1e-10)


@pytest.mark.parametrize("dist, pdf", [
    (chaospy.Beta(1.5, 1.5, -1, 1), stats.beta(1.5, 1.5, loc=-1, scale=2).pdf),
    (chaospy.Uniform(-1, 1), stats.uniform(loc=-1, scale=2).pdf),
    (chaospy.Beta(2, 3, -1, 1), stats.beta(2, 3, loc=-1, scale=2).pdf),
])
def test_a_chaospy_distribution_keeps_an_exact_discretisation(dist, pdf):
    law = parse(dist)
    # orthonormality of the computed polynomials under the law itself, to degree 60
    x, w = law.discretise(200)
    P = law.basis(60, x)
    np.testing.assert_allclose((P * w) @ P.T, np.eye(61), atol=1e-11)
    # and under an independent quadrature of its density (scipy quad, degree 4)
    def p(t):
        return law.basis(4, np.array([t]))[:, 0]

    for i in range(5):
        for j in range(i, 5):
            got = integrate.quad(lambda t: pdf(t) * p(t)[i] * p(t)[j], -1, 1, limit=100)[0]
            assert got == pytest.approx(float(i == j), abs=1e-8)


def test_restriction_is_the_conditional_law():
    law = semicircle().restrict(0.2, 0.7)
    assert law.probability() == pytest.approx(semicircle_mass(0.2, 0.7), abs=1e-13)
    x, w = law.gauss(6)
    assert 0.2 < x.min() and x.max() < 0.7
    # E[xi^k | element] by quad of the density
    for k in range(10):
        num = integrate.quad(lambda t: t**k * semicircle_density(t), 0.2, 0.7)[0]
        den = integrate.quad(semicircle_density, 0.2, 0.7)[0]
        assert w @ x**k == pytest.approx(num / den, rel=1e-12)
    # at the support's edge the end-point singularity is kept: beta(0.5, 0.5) (arcsine)
    edge = beta(0.5, 0.5).restrict(-1.0, -0.5)
    x, w = edge.gauss(8)
    f = lambda t: (1 + t) ** -0.5 * (1 - t) ** -0.5  # noqa: E731
    den = integrate.quad(f, -1, -0.5)[0]
    for k in range(12):
        assert w @ x**k == pytest.approx(integrate.quad(lambda t: t**k * f(t), -1, -0.5)[0]
                                         / den, rel=1e-10)


def test_ppf_inverts_the_cdf_on_an_element():
    law = beta(2, 3).restrict(-0.5, 0.4)
    u = np.linspace(0, 1, 11)
    x = law.ppf(u)
    fa, fb = law.cdf(-0.5), law.cdf(0.4)
    np.testing.assert_allclose((law.cdf(x) - fa) / (fb - fa), u, atol=1e-12)


@pytest.mark.parametrize("spec, message", [
    ("cauchy", "distribution must be one of"),
    ("beta:1", "distribution must be one of"),
    ("beta:0,1", "positive"),
    ("normal-trunc:-1", "positive"),
    ("beta:a,b", "must be numbers"),
    (chaospy.Normal(0, 1), "bounded support"),
    (3, "a name or a chaospy distribution"),
])
def test_bad_distributions_are_named(spec, message):
    with pytest.raises(ValueError, match=message):
        parse(spec)


def test_a_chaospy_law_whose_cdf_rounds_at_its_ends_is_bounded():
    """chaospy.Uniform(0.04, 0.06) has cdf(lower) = 1.7e-16 by roundoff, with its density
    at full height there: a bounded law (it was refused as unbounded), while a normal
    law cut by chaospy at 8 sd is still refused."""
    import chaospy
    from scipy import stats

    from opa._measure import from_chaospy

    law = from_chaospy(chaospy.Uniform(0.04, 0.06))
    x = np.linspace(0.041, 0.059, 7)
    np.testing.assert_allclose(law.cdf(x), stats.uniform(0.04, 0.02).cdf(x), atol=1e-12)
    with pytest.raises(ValueError, match="bounded support"):
        from_chaospy(chaospy.Normal(0, 1))


def test_a_chaospy_law_whose_density_does_not_integrate_to_one_is_refused_saying_so():
    """chaospy's Trunc of a normal law on [-0.5, 0.5]: its density integrates to 0.80
    (scipy quad here), so its cdf and quantiles cannot both be its law's; refused with
    the mass it has. A law on a sub-interval whose density is right is taken."""
    import chaospy
    from scipy import integrate

    bad = chaospy.Trunc(chaospy.Normal(0, 1), lower=-0.5, upper=0.5)
    mass = integrate.quad(lambda x: float(bad.pdf(x)), -0.5, 0.5)[0]
    assert abs(mass - 1) > 0.1
    with pytest.raises(ValueError, match=f"integrates to {mass:.6g} over its support"):
        parse(bad)
    good = parse(chaospy.Beta(2, 2, lower=-0.5, upper=0.5))
    assert (good.lo, good.hi) == (-0.5, 0.5)
