"""Sobol indices from a chaos expansion's coefficients (opa._sensitivity), against
independent truths: expansions whose indices are written by hand, a brute-force ANOVA by
quadrature, and the Ishigami function's closed-form indices.

The Ishigami function and its truths live here (``tests/compare/test_sobol.py`` imports
them): f = sin x1 + a sin^2 x2 + b x3^4 sin x1, x_i ~ U(-pi, pi), a = 7, b = 0.1.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from numpy.polynomial.legendre import leggauss, legvander
from scipy.integrate import quad

from opa._chaos import ChaosBasis, multi_indices
from opa._sensitivity import sobol_indices

ISHIGAMI_A, ISHIGAMI_B = 7.0, 0.1


def ishigami(xi):
    """Ishigami's function of xi in [-1, 1]^3 (x = pi xi), shape (..., 3) -> (...)."""
    x = np.pi * np.asarray(xi)
    return (np.sin(x[..., 0]) + ISHIGAMI_A * np.sin(x[..., 1]) ** 2
            + ISHIGAMI_B * x[..., 2] ** 4 * np.sin(x[..., 0]))


def uniform_moment(k: int) -> float:
    """E[x^k] for x ~ U(-pi, pi) (k even)."""
    return math.pi ** k / (k + 1)


def ishigami_truth() -> tuple[np.ndarray, np.ndarray, float]:
    """(first, total, variance) of Ishigami's function, from its ANOVA terms.

    With E[sin^2] = 1/2, E[sin^4] = 3/8 and m_k = E[x^k]:
    ``f_1 = sin x1 (1 + b m_4)``, so V_1 = (1 + b m_4)^2 / 2; ``f_2 = a (sin^2 x2 - 1/2)``,
    V_2 = a^2 (3/8 - 1/4) = a^2 / 8; ``f_13 = b sin x1 (x3^4 - m_4)``,
    V_13 = b^2 (m_8 - m_4^2) / 2; V_3 = V_12 = V_23 = V_123 = 0.
    """
    a, b = ISHIGAMI_A, ISHIGAMI_B
    m4, m8 = uniform_moment(4), uniform_moment(8)
    v1 = (1 + b * m4) ** 2 / 2
    v2 = a ** 2 / 8
    v13 = b ** 2 * (m8 - m4 ** 2) / 2
    variance = v1 + v2 + v13
    first = np.array([v1, v2, 0.0]) / variance
    total = np.array([v1 + v13, v2, v13]) / variance
    return first, total, variance


def legendre(x, degree: int) -> np.ndarray:
    """Orthonormal Legendre polynomials under U(-1, 1): shape (..., degree + 1)."""
    return legvander(np.asarray(x, dtype=float), degree) * np.sqrt(2 * np.arange(degree + 1) + 1)


def tensor_projection(f, degrees) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients and multi-indices of ``f`` on U(-1, 1)^3 by a Gauss-Legendre tensor
    rule of ``degree + 1`` points per dimension (numpy only, independent of opa._chaos);
    coefficients below 1e-10 dropped, the constant first."""
    rules = [leggauss(n + 1) for n in degrees]
    points = np.stack(np.meshgrid(*[r[0] for r in rules], indexing="ij"), axis=-1)
    weights = np.einsum("i,j,k->ijk", *[r[1] / 2 for r in rules])
    basis = [legendre(r[0], n) for r, n in zip(rules, degrees)]
    table = np.einsum("ijk,ia,jb,kc->abc", f(points) * weights, *basis)
    kept = np.argwhere(np.abs(table) > 1e-10)
    kept = kept[np.any(kept > 0, axis=1)]
    indices = np.vstack([np.zeros((1, 3), dtype=int), kept])
    return table[tuple(indices.T)], indices


def evaluate_expansion(coefficients, indices, degrees, xi) -> np.ndarray:
    """The expansion at xi, shape (..., 3) -> (...)."""
    basis = [legendre(xi[..., k], degrees[k]) for k in range(3)]
    out = np.zeros(xi.shape[:-1])
    for c, (i, j, k) in zip(coefficients, indices):
        out += c * basis[0][..., i] * basis[1][..., j] * basis[2][..., k]
    return out


def test_the_ishigami_truth_is_the_published_one():
    """The closed forms of ``ishigami_truth`` against the moments by quadrature and the
    values printed in the literature (Sudret 2008, table 1)."""
    for k in (4, 8):
        got = quad(lambda x: x ** k / (2 * np.pi), -np.pi, np.pi)[0]
        assert got == pytest.approx(uniform_moment(k), rel=1e-12)
    first, total, variance = ishigami_truth()
    pi = math.pi
    assert variance == pytest.approx(ISHIGAMI_A ** 2 / 8 + ISHIGAMI_B * pi ** 4 / 5
                                     + ISHIGAMI_B ** 2 * pi ** 8 / 18 + 0.5, rel=1e-14)
    np.testing.assert_allclose(first, [0.3139, 0.4424, 0.0], atol=1e-4)
    np.testing.assert_allclose(total, [0.5576, 0.4424, 0.2437], atol=1e-4)


def test_a_hand_built_expansion():
    """d = 3, multi-indices in a deliberately shuffled order: the squares grouped by hand.
    c^2: (1,0,0) 4, (2,0,0) 1, (0,1,0) 9, (1,1,0) 1, (0,1,2) 4, (0,0,3) 1; V = 20."""
    indices = np.array([[0, 0, 0], [0, 1, 2], [1, 0, 0], [0, 0, 3], [1, 1, 0], [2, 0, 0],
                        [0, 1, 0]])
    coefficients = np.array([5.0, -2.0, 2.0, 1.0, -1.0, 1.0, 3.0])
    s = sobol_indices(coefficients, indices)
    assert s.variance == pytest.approx(20.0)
    np.testing.assert_allclose(s.first, [5 / 20, 9 / 20, 1 / 20], rtol=1e-14)
    np.testing.assert_allclose(s.total, [6 / 20, 14 / 20, 5 / 20], rtol=1e-14)


def test_outputs_ride_along_and_scale_out():
    """Trailing axes are outputs, each its own expansion; a scale and the constant
    change no index."""
    rng = np.random.default_rng(3)
    indices = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [2, 1], [0, 3]])
    coefficients = rng.normal(size=(6, 4, 5))
    s = sobol_indices(coefficients, indices)
    assert s.first.shape == s.total.shape == (2, 4, 5) and s.variance.shape == (4, 5)
    one = sobol_indices(coefficients[:, 2, 3], indices)
    np.testing.assert_allclose(s.first[:, 2, 3], one.first, rtol=1e-14)
    np.testing.assert_allclose(s.total[:, 2, 3], one.total, rtol=1e-14)
    moved = coefficients * 3.0
    moved[0] += 100.0
    np.testing.assert_allclose(sobol_indices(moved, indices).total, s.total, rtol=1e-12)
    # the identities of any ANOVA: S_i <= S_Ti, sum S_i <= 1 <= sum S_Ti
    assert np.all(s.first <= s.total + 1e-15)
    assert np.all(s.first.sum(axis=0) <= 1 + 1e-12)
    assert np.all(s.total.sum(axis=0) >= 1 - 1e-12)


def test_a_brute_force_anova_by_quadrature():
    """An expansion in orthonormal Legendre polynomials, its indices against the
    variances of its conditional expectations computed on a Gauss grid."""
    rng = np.random.default_rng(11)
    degrees = (3, 2, 2)
    indices = np.argwhere(np.ones(tuple(n + 1 for n in degrees)))
    coefficients = rng.normal(size=len(indices))
    nodes, weights = leggauss(8)
    weights = weights / 2
    grid = np.stack(np.meshgrid(nodes, nodes, nodes, indexing="ij"), axis=-1)
    values = evaluate_expansion(coefficients, indices, degrees, grid)
    w3 = np.einsum("i,j,k->ijk", weights, weights, weights)
    mean = np.sum(values * w3)
    variance = np.sum((values - mean) ** 2 * w3)
    first, total = [], []
    for i in range(3):
        others = tuple(k for k in range(3) if k != i)
        # E[f | x_i]: average out the others; E[f | x_~i]: average out x_i
        given_i = np.tensordot(values, np.einsum("j,k->jk", weights, weights),
                               axes=(others, (0, 1)))
        first.append(np.sum(weights * (given_i - mean) ** 2) / variance)
        given_rest = np.tensordot(values, weights, axes=(i, 0))
        total.append(1 - np.sum(np.einsum("j,k->jk", weights, weights)
                                * (given_rest - mean) ** 2) / variance)
    s = sobol_indices(coefficients, indices)
    assert s.variance == pytest.approx(variance, rel=1e-12)
    np.testing.assert_allclose(s.first, first, rtol=1e-10)
    np.testing.assert_allclose(s.total, total, rtol=1e-10)


def test_ishigami_by_a_fine_tensor_projection():
    """A 20^3-point Gauss-Legendre projection (numpy only): every index to 1e-10."""
    first, total, variance = ishigami_truth()
    coefficients, indices = tensor_projection(ishigami, (19, 19, 19))
    s = sobol_indices(coefficients, indices)
    assert s.variance == pytest.approx(variance, rel=1e-10)
    np.testing.assert_allclose(s.first, first, atol=1e-10)
    np.testing.assert_allclose(s.total, total, atol=1e-10)


def ishigami_surrogate(degrees) -> tuple[np.ndarray, np.ndarray, int]:
    """Ishigami's expansion by opa._chaos: the tensor set of per-dimension degrees
    ``degrees`` projected with the Gauss-Legendre tensor rule of ``degree + 1`` points per
    dimension (as many nodes as coefficients). Returns (coefficients, indices,
    evaluations)."""
    indices = multi_indices(3, max(degrees), "tensor")
    indices = indices[np.all(indices <= np.array(degrees), axis=1)]
    basis = ChaosBasis(("uniform",) * 3, indices)
    coefficients, evaluations = basis.project_function(
        ishigami, tuple(2 * n for n in degrees), "tensor")
    return coefficients, basis.indices, evaluations


def test_ishigami_by_a_chaos_surrogate_of_200_evaluations():
    """opa._chaos with at most 200 evaluations of Ishigami's function: 5 x 8 x 5 Gauss
    points (x3 enters as x3^4, x2 as sin^2 of twice the frequency), every index within
    0.01 of the truth (measured: at most 0.0064, on S2 and ST1); the error is the
    surrogate's: 8 x 10 x 5 points take it below 3e-4, 9 x 12 x 5 below 1e-5."""
    first, total, variance = ishigami_truth()
    errors = []
    for degrees, evaluations_at_most, tolerance in (((4, 7, 4), 200, 0.01),
                                                    ((6, 9, 4), 400, 3e-4),
                                                    ((8, 11, 4), 540, 1e-5)):
        coefficients, indices, evaluations = ishigami_surrogate(degrees)
        assert evaluations <= evaluations_at_most
        s = sobol_indices(coefficients, indices)
        error = max(np.abs(s.first - first).max(), np.abs(s.total - total).max())
        assert error < tolerance, (degrees, error)
        errors.append(error)
    assert errors[0] > errors[1] > errors[2]
    assert s.variance == pytest.approx(variance, rel=1e-5)


def test_a_constant_output_has_nan_indices_without_a_warning():
    indices = np.array([[0, 0], [1, 0], [0, 1]])
    coefficients = np.array([[1.0, 2.0], [0.0, 1.0], [0.0, 1.0]])  # output 0 is constant
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = sobol_indices(coefficients, indices)
    assert np.all(np.isnan(s.first[:, 0])) and np.all(np.isnan(s.total[:, 0]))
    np.testing.assert_allclose(s.first[:, 1], [0.5, 0.5])
    assert s.variance[0] == 0.0


@pytest.mark.parametrize("indices, message", [
    (np.array([[0, 0], [1, 0]]), "one row per coefficient"),
    (np.array([[0, 0], [1, 0], [-1, 1]]), "non-negative"),
    (np.array([[1, 0], [0, 0], [0, 1]]), "constant"),
    (np.array([[0, 0], [1, 0], [1, 0]]), "repeat"),
    (np.array([[0.0, 0], [0.5, 0], [0, 1]]), "whole numbers"),
    (np.array([0, 1, 2]), "shape"),
])
def test_bad_indices_are_refused_by_name(indices, message):
    with pytest.raises(ValueError, match=message):
        sobol_indices(np.ones(3), indices)
