"""The d-dimensional chaos basis (opa._chaos) against closed forms.

References that do not come from the code under test: moments of the uniform, semicircle
and Beta laws in exact fractions, scipy's Legendre polynomials, the semicircle
triple-product rule, binomial sizes of the index sets and a brute-force filter of the
tensor box, the Ishigami function's variance in closed form, and today's 1-D rules
(opa._run.quadrature, opa._elements.element_rule), which d = 1 must reproduce bit for bit.
"""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import numpy as np
import pytest
from scipy import integrate, special

from opa._basis import triple_product
from opa._chaos import (
    MAX_CHAOS_TERMS,
    MAX_RULE_NODES,
    ChaosBasis,
    multi_indices,
)
from opa._elements import element_rule
from opa._measure import beta, normal_trunc, semicircle, uniform
from opa._run import quadrature


# -- exact moments E[xi^k] of the laws on [-1, 1] --------------------------------------------
def uniform_moment(k: int) -> Fraction:
    return Fraction(1, k + 1) if k % 2 == 0 else Fraction(0)


def semicircle_moment(k: int) -> Fraction:
    # E[xi^(2m)] = Catalan(m) / 4^m for the density (2/pi) sqrt(1 - xi^2)
    if k % 2:
        return Fraction(0)
    m = k // 2
    return Fraction(math.comb(2 * m, m), (m + 1) * 4**m)


def beta_moment(a: int, b: int):
    """E[xi^k] for xi = 2y - 1, y ~ Beta(a, b), integer shapes."""
    def moment(k: int) -> Fraction:
        y = [math.prod(Fraction(a + r, a + b + r) for r in range(i)) for i in range(k + 1)]
        return sum(math.comb(k, i) * 2**i * (-1) ** (k - i) * y[i] for i in range(k + 1))
    return moment


LAWS = {"semicircle": (semicircle, semicircle_moment), "uniform": (uniform, uniform_moment),
        "beta:2,3": (lambda: beta(2, 3), beta_moment(2, 3))}
MIXED = {2: ("semicircle", "beta:2,3"), 3: ("semicircle", "uniform", "beta:2,3")}


def exact(names, k) -> float:
    """E[prod_j xi_j^k_j] under the product law."""
    return float(math.prod(LAWS[n][1](int(kj)) for n, kj in zip(names, k)))


def basis_of(names, order, kind="total") -> ChaosBasis:
    return ChaosBasis.from_order([LAWS[n][0]() for n in names], order, kind)


def integrate_monomial(rule, k) -> float:
    nodes, weights = rule
    return float(weights @ np.prod(nodes ** np.asarray(k), axis=1))


# -- multi-index sets ------------------------------------------------------------------------
@pytest.mark.parametrize("d, order", [(1, 5), (2, 4), (3, 3), (4, 2), (5, 0)])
def test_index_set_sizes_follow_the_closed_forms(d, order):
    total = multi_indices(d, order)
    tensor = multi_indices(d, order, "tensor")
    assert total.shape == (math.comb(order + d, d), d) and total.dtype == np.int64
    assert tensor.shape == ((order + 1) ** d, d)
    for rows in (total, tensor):
        assert len({tuple(r) for r in rows}) == len(rows)
        assert not rows[0].any()
        assert (np.diff(rows.sum(axis=1)) >= 0).all()  # graded by total degree


@pytest.mark.parametrize("d, order, q", [(2, 6, 0.5), (3, 5, 0.7), (4, 4, 0.4)])
def test_hyperbolic_set_is_the_brute_force_filter_and_inside_the_total_set(d, order, q):
    got = {tuple(r) for r in multi_indices(d, order, "hyperbolic", q)}
    box = itertools.product(range(order + 1), repeat=d)
    want = {k for k in box if sum(kj**q for kj in k) ** (1 / q) <= order + 1e-9}
    assert got == want
    assert got < {tuple(r) for r in multi_indices(d, order)}  # a strict subset
    assert np.array_equal(multi_indices(d, order, "hyperbolic", 1.0), multi_indices(d, order))


def test_hyperbolic_set_keeps_its_boundary_against_round_off():
    # (1, 1, 1, 1) has norm 4^3 = 64 exactly, but 64 ** (1/3) is 3.9999999999999996
    assert 64 ** (1 / 3) < 4
    rows = {tuple(r) for r in multi_indices(4, 64, "hyperbolic", 1 / 3)}
    assert (1, 1, 1, 1) in rows and (2, 1, 1, 1) not in rows


def test_graded_order_and_its_tie_break():
    assert multi_indices(1, 4).tolist() == [[0], [1], [2], [3], [4]]
    assert multi_indices(3, 2).tolist() == [
        [0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1],
        [2, 0, 0], [1, 1, 0], [1, 0, 1], [0, 2, 0], [0, 1, 1], [0, 0, 2]]


@pytest.mark.parametrize("args, message", [
    ((0, 2), "d must be >= 1, got 0"),
    ((2, -1), "order must be >= 0, got -1"),
    ((2, 1.5), "order must be an integer >= 0, got 1.5"),
    ((2, 2, "sparse"), "kind must be one of total, tensor, hyperbolic, got 'sparse'"),
    ((2, 2, "hyperbolic", 0.0), r"q must be a number in \(0, 1\], got 0.0"),
    ((2, 2, "hyperbolic", 1.5), r"q must be a number in \(0, 1\], got 1.5"),
    ((30, 10), f"more than MAX_CHAOS_TERMS = {MAX_CHAOS_TERMS}"),
])
def test_bad_index_sets_are_refused_by_name(args, message):
    with pytest.raises(ValueError, match=message):
        multi_indices(*args)


# -- the basis -------------------------------------------------------------------------------
def test_evaluate_is_the_product_of_normalised_legendre_polynomials():
    basis = ChaosBasis.from_order([uniform(), uniform()], 4)
    xi = np.random.default_rng(0).uniform(-1, 1, (7, 2))
    want = np.stack([np.sqrt((2 * i + 1) * (2 * j + 1)) * special.eval_legendre(i, xi[:, 0])
                     * special.eval_legendre(j, xi[:, 1]) for i, j in basis.indices], axis=1)
    np.testing.assert_allclose(basis.evaluate(xi), want, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("kind", ["tensor", "smolyak", "auto"])
def test_the_basis_is_orthonormal_under_its_rules(d, kind):
    basis = basis_of(MIXED[d], 4)
    for nodes, weights in (basis.rule(8, kind), basis.exact_rule(2, kind)):
        assert math.isclose(weights.sum(), 1.0, rel_tol=1e-13)
        values = basis.evaluate(nodes)
        gram = values.T @ (weights[:, None] * values)
        np.testing.assert_allclose(gram, np.eye(basis.size), atol=1e-12)


# -- the rules -------------------------------------------------------------------------------
@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("kind", ["tensor", "smolyak"])
@pytest.mark.parametrize("degree", [3, 5, 7])
def test_rules_are_exact_to_their_degree_and_fail_above(d, kind, degree):
    names = MIXED[d]
    rule = basis_of(names, 1).rule(degree, kind)
    rng = np.random.default_rng(degree + 10 * d)
    for _ in range(12):
        k = rng.multinomial(rng.integers(0, degree + 1), np.ones(d) / d)
        assert integrate_monomial(rule, k) == pytest.approx(exact(names, k), abs=1e-13)
    # one past 2 floor(D/2) + 1 in one variable: a Gauss rule of D//2 + 1 points fails there
    k = [degree + 1 if degree % 2 else degree + 2] + [0] * (d - 1)
    assert abs(integrate_monomial(rule, k) - exact(names, k)) > 1e-6


def test_smolyak_fails_on_the_mixed_term_just_outside_its_space():
    names = MIXED[3]
    sparse = basis_of(names, 1).rule(5, "smolyak")  # sum_j floor(k_j/2) <= 2
    tensor = basis_of(names, 1).rule(5, "tensor")  # k_j <= 5 for all j
    k = (2, 2, 2)  # total degree 6, floor sum 3
    assert abs(integrate_monomial(sparse, k) - exact(names, k)) > 1e-6
    assert integrate_monomial(tensor, k) == pytest.approx(exact(names, k), abs=1e-14)


def test_smolyak_integrates_a_uniform_product_in_three_dimensions():
    basis = ChaosBasis.from_order([uniform()] * 3, 1)
    nodes, weights = basis.rule(7, "smolyak")
    assert (weights < 0).any()  # the combination technique
    # E[x^2 y^2 z^2] = 1/27, E[x^4 y^2] = 1/15, E[x^6] = 1/7, E[x^2 y^4 z] = 0
    for k, want in [((2, 2, 2), 1 / 27), ((4, 2, 0), 1 / 15), ((0, 0, 6), 1 / 7),
                    ((2, 4, 1), 0.0), ((7, 0, 0), 0.0)]:
        assert integrate_monomial((nodes, weights), k) == pytest.approx(want, abs=1e-13)


def test_smolyak_takes_fewer_nodes_than_the_tensor_rule_in_higher_dimension():
    # degree 3: the origin and two points on each axis (2d + 1) against 2^d
    for d in (3, 5):
        basis = ChaosBasis.from_order([uniform()] * d, 1)
        assert len(basis.rule(3, "smolyak")[0]) == 2 * d + 1 < 2**d
    basis = ChaosBasis.from_order([uniform()] * 5, 1)
    sparse, tensor = basis.rule(7, "smolyak"), basis.rule(7, "tensor")
    assert len(tensor[0]) == 4**5 and 4 * len(sparse[0]) < len(tensor[0])
    assert len(basis.rule(7)[0]) == len(sparse[0])  # auto takes it
    # in d = 3 the non-nested Gauss grids overlap too little past degree 5: auto keeps tensor
    basis3 = ChaosBasis.from_order([uniform()] * 3, 1)
    assert len(basis3.rule(9, "smolyak")[0]) > len(basis3.rule(9, "tensor")[0]) == 125
    assert len(basis3.rule(9)[0]) == 125


def test_anisotropic_rules_are_exact_on_their_documented_spaces():
    names = MIXED[3]
    basis = basis_of(names, 1)
    tensor = basis.rule((6, 4, 2), "tensor")  # 4 x 3 x 2 points, box k <= (7, 5, 3)
    assert len(tensor[0]) == 24
    assert integrate_monomial(tensor, (7, 5, 3)) == pytest.approx(exact(names, (7, 5, 3)),
                                                                   abs=1e-14)
    assert abs(integrate_monomial(tensor, (0, 0, 4)) - exact(names, (0, 0, 4))) > 1e-6
    sparse = basis.rule((8, 8, 4), "smolyak")  # floor(k1/2)/4 + floor(k2/2)/4 + floor(k3/2)/2
    for k in [(9, 0, 0), (0, 9, 0), (0, 0, 5), (4, 0, 3), (5, 5, 1), (2, 2, 2)]:
        assert integrate_monomial(sparse, k) == pytest.approx(exact(names, k), abs=1e-13)
    for k in [(0, 0, 6), (4, 4, 2)]:
        assert abs(integrate_monomial(sparse, k) - exact(names, k)) > 1e-6


@pytest.mark.parametrize("order", [0, 1, 2, 5, 12])
def test_one_dimension_reproduces_todays_semicircle_rule_bit_for_bit(order):
    nodes, weights, values = quadrature(order)
    basis = ChaosBasis.from_order([semicircle()], order + 1)
    for kind in ("tensor", "smolyak", "auto"):
        got_nodes, got_weights = basis.rule(4 * order + 1, kind)  # Q = 2N + 1 points
        assert np.array_equal(got_nodes[:, 0], nodes)
        assert np.array_equal(got_weights, weights)
        assert np.array_equal(basis.evaluate(got_nodes).T, values)


@pytest.mark.parametrize("law", [lambda: beta(2, 3), uniform, lambda: normal_trunc(2.0),
                                 lambda: semicircle().restrict(0.0, 0.5)])
@pytest.mark.parametrize("order", [0, 3, 8])
def test_one_dimension_reproduces_the_element_rule_of_other_laws_bit_for_bit(law, order):
    nodes, weights, values = element_rule(law(), order)
    basis = ChaosBasis.from_order([law()], order + 1)
    got_nodes, got_weights = basis.rule(4 * order + 1)
    assert np.array_equal(got_nodes[:, 0], nodes)
    assert np.array_equal(got_weights, weights)
    assert np.array_equal(basis.evaluate(got_nodes).T, values)


@pytest.mark.parametrize("args, message", [
    ((5, "gauss"), "kind must be one of auto, tensor, smolyak, got 'gauss'"),
    ((-1,), "degree must be >= 0, got -1"),
    (((3, 3),), r"degree must be an integer or one per dimension \(3\), got \(3, 3\)"),
    (((3, 3, -2),), r"degree\[2\] must be >= 0, got -2"),
    ((200, "tensor"), f"more than MAX_RULE_NODES = {MAX_RULE_NODES}"),
])
def test_bad_rules_are_refused_by_name(args, message):
    with pytest.raises(ValueError, match=message):
        basis_of(MIXED[3], 1).rule(*args)


def test_bad_bases_are_refused_by_name():
    with pytest.raises(ValueError, match=r"indices must have shape \(P, 2\)"):
        ChaosBasis((uniform(), uniform()), np.zeros((3, 3), int))
    with pytest.raises(ValueError, match=r"row 0 must be all zeros \(the mean\), got \[1, 0\]"):
        ChaosBasis(("uniform", "uniform"), [[1, 0], [0, 0]])
    with pytest.raises(ValueError, match="distinct"):
        ChaosBasis(("uniform", "uniform"), [[0, 0], [1, 0], [1, 0]])
    with pytest.raises(ValueError, match="integers >= 0"):
        ChaosBasis(("uniform",), [[0.0], [1.5]])
    with pytest.raises(ValueError, match=r"xi must have shape \(M, 2\), got shape \(4,\)"):
        ChaosBasis.from_order(("uniform", "uniform"), 2).evaluate(np.zeros(4))


# -- projection, moments, triple products ----------------------------------------------------
def test_projection_recovers_the_coefficients_of_a_polynomial():
    basis = ChaosBasis.from_order([uniform(), semicircle()], 3)
    # xi_1 xi_2 = (sqrt(3) xi_1)(2 xi_2) / (2 sqrt(3)); xi_2^2 = (U_0 + U_2) / 4
    coef, evaluations = basis.project_function(lambda x: x[:, 0] * x[:, 1] + x[:, 1] ** 2)
    want = np.zeros(basis.size)
    rows = [tuple(r) for r in basis.indices]
    want[rows.index((1, 1))] = 1 / (2 * np.sqrt(3))
    want[rows.index((0, 0))] = want[rows.index((0, 2))] = 0.25
    np.testing.assert_allclose(coef, want, atol=1e-14)
    assert evaluations == 16  # 4 x 4 Gauss points make every product of the basis exact
    # a random member of the span, batch axes kept
    basis3 = basis_of(MIXED[3], 3)
    c = np.random.default_rng(1).normal(size=(basis3.size, 2))
    got, _ = basis3.project_function(lambda x: basis3.evaluate(x) @ c)
    np.testing.assert_allclose(got, c, atol=1e-12)


def test_mean_and_variance_of_a_sum_of_independent_terms():
    names = MIXED[3]
    basis = basis_of(names, 3)
    coef, _ = basis.project_function(lambda x: x[:, 0] + x[:, 1] ** 2 + x[:, 2] ** 3)

    def var(name, k):
        moment = LAWS[name][1]
        return float(moment(2 * k) - moment(k) ** 2)

    mean = exact(names, (1, 0, 0)) + exact(names, (0, 2, 0)) + exact(names, (0, 0, 3))
    assert basis.mean(coef) == pytest.approx(mean, abs=1e-13)
    want = var(names[0], 1) + var(names[1], 2) + var(names[2], 3)
    assert basis.variance(coef) == pytest.approx(want, rel=1e-13)


def test_ishigami_variance_with_an_anisotropic_rule_takes_fewer_evaluations():
    a, b = 7.0, 0.1

    def ishigami(x):
        x = np.pi * x
        return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])

    variance = a**2 / 8 + b * np.pi**4 / 5 + b**2 * np.pi**8 / 18 + 0.5
    basis = ChaosBasis.from_order([uniform()] * 3, 12)
    full, n_full = basis.project_function(ishigami, 24, "tensor")
    # xi_3 enters as xi_3^4 times a degree-12 basis factor: degree 16 is exact in it
    lean, n_lean = basis.project_function(ishigami, (24, 24, 16), "tensor")
    assert n_lean < 0.75 * n_full
    for coef in (full, lean):
        assert basis.mean(coef) == pytest.approx(a / 2, abs=1e-12)
        assert basis.variance(coef) == pytest.approx(variance, rel=1e-6)


def legendre_triples(n: int) -> np.ndarray:
    """E[P_i P_j P_k] of the normalised Legendre polynomials by scipy's adaptive quadrature."""
    def p(i, x):
        return np.sqrt(2 * i + 1) * special.eval_legendre(i, x)
    out = np.empty((n + 1,) * 3)
    for i, j, k in itertools.product(range(n + 1), repeat=3):
        out[i, j, k] = integrate.quad(lambda x: p(i, x) * p(j, x) * p(k, x) / 2, -1, 1)[0]
    return out


def test_triple_products_are_products_of_one_dimensional_ones():
    basis = ChaosBasis.from_order([semicircle(), uniform()], 3)
    semi = np.array([[[triple_product(i, j, k) for k in range(4)] for j in range(4)]
                     for i in range(4)])
    legendre = legendre_triples(3)
    i = basis.indices
    want = (semi[i[:, None, None, 0], i[None, :, None, 0], i[None, None, :, 0]]
            * legendre[i[:, None, None, 1], i[None, :, None, 1], i[None, None, :, 1]])
    np.testing.assert_allclose(basis.triple_products(), want, atol=1e-12)


def test_semicircle_triple_products_follow_the_closed_rule():
    t = ChaosBasis.from_order([semicircle()], 6).triple_products()
    for i, j, k in itertools.product(range(7), repeat=3):
        want = 1.0 if (i + j + k) % 2 == 0 and abs(i - j) <= k <= i + j else 0.0
        assert t[i, j, k] == pytest.approx(want, abs=1e-12)


def test_triple_products_refuse_a_dense_tensor_past_the_bound():
    with pytest.raises(ValueError, match=r"P = 455 terms \(order 12 in d = 3 dimensions\)"):
        ChaosBasis.from_order([uniform()] * 3, 12).triple_products()
