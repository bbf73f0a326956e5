"""Tests for ``opa._basis`` against references that do not share its code.

References (the shared ones from ``tests/truths.py``): ``scipy.integrate.quad`` with the
algebraic weight ``sqrt(1 - xi^2)`` (QAWS), scipy's Gauss-Jacobi rule
``roots_jacobi(n, 1/2, 1/2)`` (Golub-Welsch, the semicircle up to the factor 2/pi), the
cubic projection by a 200-point such rule, ``scipy.special.eval_chebyu``, the exact
semicircle moments ``E[xi^(2m)] = Catalan(m) / 4^m``, chaospy's orthonormal expansion and
Gauss rule for ``Beta(3/2, 3/2)`` on [-1, 1], and the paper's printed formulas (14)-(19).
"""

from __future__ import annotations

import chaospy
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.special import eval_chebyu

from opa._basis import (
    chebyshev_u,
    cubic_projection,
    evaluate,
    gauss_nodes,
    project,
    quadrature_order,
    triple_product,
)
from tests.truths import (
    semicircle_cubic_projection,
    semicircle_density,
    semicircle_expectation,
    semicircle_golub_welsch_rule,
    semicircle_moment,
)

RNG_SEED = 20240611


# --------------------------------------------------------------------------- basis


def test_chebyshev_u_matches_scipy():
    xi = np.random.default_rng(RNG_SEED).uniform(-1.0, 1.0, size=(7, 5))
    u = chebyshev_u(30, xi)
    assert u.shape == (31, 7, 5)
    expected = np.array([eval_chebyu(i, xi) for i in range(31)])
    np.testing.assert_allclose(u, expected, rtol=1e-12, atol=1e-12)


def test_chebyshev_u_scalar_and_order_zero():
    assert chebyshev_u(0, 0.3).shape == (1,)
    np.testing.assert_array_equal(chebyshev_u(2, 1.0), [1.0, 2.0, 3.0])  # U_n(1) = n + 1


def test_orthonormality_by_quad():
    n = 30
    cache: dict[float, np.ndarray] = {}  # quad revisits the same abscissae for every pair

    def basis_at(x: float) -> np.ndarray:
        if x not in cache:
            cache[x] = chebyshev_u(n, x)
        return cache[x]

    gram = np.empty((n + 1, n + 1))
    for i in range(n + 1):
        for j in range(i, n + 1):
            gram[i, j] = gram[j, i] = semicircle_expectation(
                lambda x, i=i, j=j: basis_at(x)[i] * basis_at(x)[j]
            )
    np.testing.assert_allclose(gram, np.eye(n + 1), atol=1e-12)


def test_three_term_recurrence_eq5():
    xi = np.linspace(-1.0, 1.0, 11)
    u = chebyshev_u(10, xi)
    np.testing.assert_allclose(xi * u[1:-1], 0.5 * (u[2:] + u[:-2]), atol=1e-12)


# --------------------------------------------------------------------------- Gauss rule


@pytest.mark.parametrize("q", [1, 2, 3, 5, 9, 16, 40])
def test_gauss_nodes_basic_properties(q):
    nodes, weights = gauss_nodes(q)
    assert nodes.shape == weights.shape == (q,)
    assert np.all(np.diff(nodes) > 0)
    assert np.all(np.abs(nodes) < 1.0)
    assert np.all(weights > 0)
    assert weights.sum() == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(chebyshev_u(q, nodes)[q], 0.0, atol=1e-12)  # zeros of U_q


@pytest.mark.parametrize("q", range(1, 13))
def test_gauss_rule_exact_to_degree_2q_minus_1(q):
    nodes, weights = gauss_nodes(q)
    for d in range(2 * q):
        assert weights @ nodes**d == pytest.approx(semicircle_moment(d), abs=1e-14), d


@pytest.mark.parametrize("q", range(1, 13))
def test_gauss_rule_not_exact_at_degree_2q(q):
    # xi^(2q) = (U_q / 2^q)^2 + (degree <= 2q-1) and U_q vanishes at the nodes, so the
    # quadrature error is exactly E[(U_q / 2^q)^2] = 4^(-q).
    nodes, weights = gauss_nodes(q)
    error = semicircle_moment(2 * q) - weights @ nodes ** (2 * q)
    assert error == pytest.approx(4.0**-q, rel=1e-8)


def test_gauss_rule_matches_scipy_jacobi():
    nodes, weights = gauss_nodes(25)
    ref_nodes, ref_weights = semicircle_golub_welsch_rule(25)
    np.testing.assert_allclose(nodes, ref_nodes, atol=1e-13)
    np.testing.assert_allclose(weights, ref_weights, atol=1e-13)


# --------------------------------------------------------------------------- triple products


def test_triple_product_rule_against_quad():
    for i in range(9):
        for j in range(9):
            for k in range(9):
                exact = triple_product(i, j, k)
                numeric = semicircle_expectation(
                    lambda x, i=i, j=j, k=k: (
                        eval_chebyu(i, x) * eval_chebyu(j, x) * eval_chebyu(k, x)
                    )
                )
                assert exact == pytest.approx(numeric, abs=1e-12), (i, j, k)


def test_triple_product_known_values():
    assert triple_product(0, 3, 3) == 1.0
    assert triple_product(1, 1, 2) == 1.0
    assert triple_product(1, 1, 1) == 0.0  # odd sum
    assert triple_product(1, 2, 4) == 0.0  # k > i + j
    assert triple_product(5, 1, 2) == 0.0  # k < |i - j|


# --------------------------------------------------------------------------- chaospy


SEMICIRCLE = chaospy.Beta(1.5, 1.5, lower=-1, upper=1)


def test_chaospy_distribution_is_the_semicircle():
    xi = np.linspace(-0.99, 0.99, 9)
    np.testing.assert_allclose(SEMICIRCLE.pdf(xi), semicircle_density(xi), rtol=1e-12)


@pytest.mark.parametrize("n", [0, 1, 2, 5, 10, 15])
def test_basis_matches_chaospy_expansion(n):
    expansion = chaospy.generate_expansion(n, SEMICIRCLE, normed=True)
    xi = np.random.default_rng(RNG_SEED + n).uniform(-1.0, 1.0, size=40)
    ref = np.asarray(expansion(xi)).reshape(n + 1, xi.size)
    ours = chebyshev_u(n, xi)
    # Orthonormal polynomials are unique up to a sign per degree.
    sign = np.sign(np.sum(ref * ours, axis=1))[:, None]
    np.testing.assert_allclose(sign * ref, ours, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("q", [1, 2, 3, 5, 8, 16])
def test_gauss_nodes_match_chaospy(q):
    ref_nodes, ref_weights = chaospy.generate_quadrature(q - 1, SEMICIRCLE, rule="gaussian")
    order = np.argsort(ref_nodes[0])
    nodes, weights = gauss_nodes(q)
    np.testing.assert_allclose(nodes, ref_nodes[0][order], atol=1e-12)
    np.testing.assert_allclose(weights, ref_weights[order], atol=1e-12)


# --------------------------------------------------------------------------- project / evaluate


def test_project_recovers_coefficients_and_evaluate_roundtrip():
    rng = np.random.default_rng(RNG_SEED)
    coef = rng.normal(size=(7, 3))  # degree 6, batch of 3
    nodes, weights = gauss_nodes(7)  # 6 + 6 <= 2*7 - 1
    values = evaluate(coef, nodes)
    assert values.shape == (3, 7)
    np.testing.assert_allclose(project(values, 6, nodes, weights), coef, atol=1e-12)
    xi = rng.uniform(-1, 1, size=4)
    ref = sum(coef[i][:, None] * eval_chebyu(i, xi)[None, :] for i in range(7))
    np.testing.assert_allclose(evaluate(coef, xi), ref, rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------- cubic projection


@pytest.mark.parametrize("n", [0, 1, 2, 4, 7, 12])
@settings(max_examples=20, deadline=None, database=None)
@given(data=st.data())
def test_cubic_projection_against_brute_force(n, data):
    coef = data.draw(arrays(np.float64, n + 1, elements=st.floats(-3.0, 3.0)), label="coef")
    # |x^3 U_i| <= (sum |c_j| (j + 1))^3 (i + 1) on [-1, 1]: rounding scale of both routes.
    scale = max(1.0, np.abs(coef) @ np.arange(1, n + 2)) ** 3 * (3 * n + 3)
    expected = semicircle_cubic_projection(coef, 3 * n + 2)
    got = cubic_projection(coef, n_out=3 * n + 2)
    assert got.shape == (3 * n + 3,)
    np.testing.assert_allclose(got, expected, atol=1e-14 * scale)
    np.testing.assert_allclose(got[3 * n + 1 :], 0.0, atol=1e-14 * scale)  # x^3 has degree 3N
    np.testing.assert_allclose(cubic_projection(coef), expected[: 3 * n + 1], atol=1e-14 * scale)


def test_cubic_projection_batched_and_from_quadruple_products():
    rng = np.random.default_rng(RNG_SEED)
    n = 4
    coef = rng.normal(size=(n + 1, 2, 3))
    got = cubic_projection(coef, n_out=n)
    assert got.shape == (n + 1, 2, 3)
    # O(N^4) route: E[U_a U_b U_c U_i] = sum_{m in U_a U_b} E[U_m U_c U_i].
    quad4 = np.zeros((n + 1,) * 4)
    for a in range(n + 1):
        for b in range(n + 1):
            for c in range(n + 1):
                for i in range(n + 1):
                    quad4[a, b, c, i] = sum(
                        triple_product(m, c, i) for m in range(abs(a - b), a + b + 1, 2)
                    )
    expected = np.einsum("abci,a...,b...,c...->i...", quad4, coef, coef, coef)
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_cubic_projection_with_larger_q_and_too_small_q():
    coef = np.random.default_rng(RNG_SEED).normal(size=5)
    np.testing.assert_allclose(
        cubic_projection(coef, n_out=4, q=20), cubic_projection(coef, n_out=4), atol=1e-12
    )
    with pytest.raises(ValueError, match="q must be >= 9"):
        cubic_projection(coef, n_out=4, q=8)


def test_quadrature_order_is_enough_for_the_opa_rhs():
    # E[xi x^3 U_i], i <= N, needs degree 4N + 1: exact with quadrature_order(N) nodes.
    rng = np.random.default_rng(RNG_SEED)
    for n in range(0, 9):
        q = quadrature_order(n)
        assert q == 2 * n + 1
        coef = rng.normal(size=n + 1)
        nodes, weights = gauss_nodes(q)
        got = project(nodes * evaluate(coef, nodes) ** 3, n, nodes, weights)
        ref_nodes, ref_weights = semicircle_golub_welsch_rule(64)
        ref = project(ref_nodes * evaluate(coef, ref_nodes) ** 3, n, ref_nodes, ref_weights)
        np.testing.assert_allclose(got, ref, atol=1e-11)


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: chebyshev_u(-1, 0.0), "n_max must be >= 0, got -1"),
        (lambda: chebyshev_u(2.5, 0.0), "n_max must be an integer"),
        (lambda: gauss_nodes(0), "q must be >= 1, got 0"),
        (lambda: gauss_nodes(True), "q must be an integer"),
        (lambda: triple_product(-1, 0, 1), "i must be >= 0, got -1"),
        (lambda: quadrature_order(-2), "order must be >= 0, got -2"),
        (lambda: cubic_projection([1.0], n_out=-1), "n_out must be >= 0, got -1"),
        (lambda: project(np.ones(3), 1, *gauss_nodes(4)), "last axis of length 4"),
    ],
)
def test_invalid_arguments_raise_value_error(call, message):
    with pytest.raises(ValueError, match=message):
        call()


# --------------------------------------------------------------------------- paper (14)-(19)
# Transcribed term by term, in the printed order, from eqs. (14)-(19) for N = 4,
# where y_i are the velocity coefficients and Y_i = E[(sum_j y_j U_j)^3 U_i].


def paper_Y0(y):
    y0, y1, y2, y3, y4 = y
    return (
        3 * y0 * y1**2 + 3 * y0 * y2**2 + 3 * y0 * y3**2 + 3 * y0 * y4**2 + 3 * y2 * y3**2
        + y0**3 + y2**3 + y4**3
        + 3 * y2 * y4**2 + 3 * y2 * y1**2 + 3 * y4 * y2**2 + 3 * y4 * y3**2
        + 6 * y1 * y2 * y3 + 6 * y1 * y3 * y4
    )  # fmt: skip


def paper_Y1(y):
    y0, y1, y2, y3, y4 = y
    return (
        6 * y3 * y2**2 + 6 * y1 * y3**2 + 3 * y3 * y1**2 + 6 * y1 * y2**2 + 6 * y3 * y4**2
        + 2 * y1**3 + 2 * y3**3 + 3 * y1 * y0**2 + 6 * y1 * y4**2
        + 12 * y2 * y3 * y4 + 6 * y0 * y1 * y2 + 6 * y0 * y2 * y3 + 6 * y0 * y3 * y4
        + 6 * y1 * y2 * y4
    )  # fmt: skip


def paper_Y2(y):
    y0, y1, y2, y3, y4 = y
    return (
        3 * y2**3 + 3 * y4**3 + 3 * y0 * y1**2 + 3 * y4 * y1**2 + 3 * y2 * y0**2
        + 3 * y0 * y2**2 + 6 * y0 * y1 * y3 + 9 * y4 * y3**2 + 3 * y0 * y3**2
        + 3 * y0 * y4**2 + 6 * y4 * y2**2 + 6 * y0 * y2 * y4 + 6 * y2 * y1**2
        + 12 * y1 * y2 * y3 + 12 * y1 * y3 * y4 + 9 * y2 * y4**2 + 9 * y2 * y3**2
    )  # fmt: skip


def paper_Y3(y):
    y0, y1, y2, y3, y4 = y
    return (
        y1**3 + 4 * y3**3 + 3 * y3 * y0**2 + 6 * y1 * y3**2 + 6 * y1 * y2**2
        + 6 * y1 * y4**2 + 9 * y3 * y2**2 + 12 * y1 * y2 * y4 + 6 * y0 * y1 * y4
        + 6 * y0 * y1 * y2 + 6 * y0 * y3 * y4 + 6 * y0 * y2 * y3 + 18 * y2 * y3 * y4
    )  # fmt: skip


def paper_Y4(y):
    y0, y1, y2, y3, y4 = y
    return (
        2 * y2**3 + 5 * y4**3 + 3 * y2 * y1**2 + 3 * y0 * y2**2 + 3 * y0 * y3**2
        + 3 * y0 * y4**2 + 12 * y1 * y2 * y3 + 12 * y1 * y3 * y4 + 3 * y4 * y0**2
        + 6 * y0 * y2 * y4 + 6 * y0 * y1 * y3 + 6 * y4 * y1**2 + 9 * y2 * y3**2
        + 9 * y4 * y2**2 + 9 * y2 * y4**2 + 12 * y4 * y3**2
    )  # fmt: skip


def paper_Y5(y):
    y0, y1, y2, y3, y4 = y
    return (
        3 * y3**3 + 3 * y1 * y2**2 + 3 * y3 * y1**2 + 6 * y1 * y4**2 + 6 * y1 * y3**2
        + 12 * y3 * y4**2 + 12 * y1 * y2 * y4 + 6 * y3 * y2**2 + 6 * y0 * y2 * y3
        + 6 * y0 * y3 * y4 + 6 * y0 * y1 * y4 + 18 * y2 * y3 * y4
    )  # fmt: skip


def corrected_Y3(y):
    """Eq. (17) with the two terms the printed formula omits: 6 y1^2 y3 and 12 y3 y4^2."""
    y1, y3, y4 = y[1], y[3], y[4]
    return paper_Y3(y) + 6 * y1**2 * y3 + 12 * y3 * y4**2


PAPER_CORRECT = {0: paper_Y0, 1: paper_Y1, 2: paper_Y2, 4: paper_Y4, 5: paper_Y5}


def _random_velocity_coefficients(count: int) -> np.ndarray:
    return np.random.default_rng(RNG_SEED).uniform(-2.0, 2.0, size=(count, 5))


@pytest.mark.parametrize("i", sorted(PAPER_CORRECT))
def test_paper_printed_formula_is_exact(i):
    for y in _random_velocity_coefficients(50):
        assert PAPER_CORRECT[i](y) == pytest.approx(cubic_projection(y, n_out=5)[i], abs=1e-10)


def test_paper_eq17_is_wrong_and_corrected_formula_is_exact():
    # Printed eq. (17) for Y_3 lacks the monomials 6 y1^2 y3 (E[U1 U1 U3 U3] = 2, times the
    # 3 orderings) and 12 y3 y4^2 (E[U3 U4 U4 U3] = 4, times 3 orderings).
    for y in _random_velocity_coefficients(50):
        exact = cubic_projection(y, n_out=5)[3]
        missing = 6 * y[1] ** 2 * y[3] + 12 * y[3] * y[4] ** 2
        assert abs(paper_Y3(y) - exact) > 1e-6
        assert exact - paper_Y3(y) == pytest.approx(missing, abs=1e-10)
        assert corrected_Y3(y) == pytest.approx(exact, abs=1e-10)


def test_paper_eq17_missing_terms_on_unit_vectors():
    # Deterministic witnesses: y = (0, 1, 0, 1, 0) and y = (0, 0, 0, 1, 1).
    y = np.array([0.0, 1.0, 0.0, 1.0, 0.0])
    assert paper_Y3(y) == pytest.approx(11.0)  # 1 + 4 + 6
    assert cubic_projection(y, n_out=5)[3] == pytest.approx(17.0)
    y = np.array([0.0, 0.0, 0.0, 1.0, 1.0])
    assert paper_Y3(y) == pytest.approx(4.0)
    assert cubic_projection(y, n_out=5)[3] == pytest.approx(16.0)
