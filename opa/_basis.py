r"""Orthonormal Chebyshev-U basis of the semicircle law, its Gauss rule, and cubic projections.

The uncertain parameter :math:`\xi` of the OPA method has the semicircle density

.. math::

    p(\xi) = \frac{2}{\pi}\sqrt{1 - \xi^2}, \qquad |\xi| \le 1,

and the basis :math:`H_i = U_i` are the Chebyshev polynomials of the second kind,

.. math::

    U_0 = 1, \quad U_1 = 2\xi, \quad U_{i+1} = 2\xi U_i - U_{i-1},

which are orthonormal under :math:`p` (paper eq. (4)) and obey the three-term rule
:math:`\xi U_i = (U_{i+1} + U_{i-1})/2` (eq. (5)). A response is expanded as
:math:`x(t, \xi) = \sum_{i=0}^N x_i(t) U_i(\xi)` (eq. (3)) with
:math:`x_i = E[x U_i]`, and the cubic terms of the equation of motion are projected as

.. math::

    \Big(\sum_{j=0}^N x_j U_j\Big)^3 = \sum_{i=0}^{3N} X_i U_i, \qquad
    X_i = E\Big[\Big(\sum_j x_j U_j\Big)^3 U_i\Big]

(eqs. (7)-(8); the paper's :math:`Y_i` are the same map applied to the velocities).

Instead of the O(N^4) tensor of quadruple products :math:`E[U_a U_b U_c U_i]` this module
computes :math:`X_i` exactly with the Gauss rule of :math:`p` (Gauss-Chebyshev of the second
kind): with :math:`q` nodes :math:`\xi_k = \cos(k\pi/(q+1))` and weights
:math:`w_k = \tfrac{2}{q+1}\sin^2(k\pi/(q+1))`, :math:`\sum_k w_k f(\xi_k) = E[f]` for every
polynomial :math:`f` of degree at most :math:`2q - 1`. Evaluating :math:`x` at the nodes,
cubing pointwise and projecting back is therefore exact as soon as
:math:`3N + n_{out} \le 2q - 1`, at O(N q) cost.

Products of basis functions follow the linearisation
:math:`U_i U_j = \sum_{k = |i-j|,\ \mathrm{step}\ 2}^{i+j} U_k`, hence the triple-product
rule :math:`E[U_i U_j U_k] = 1` iff :math:`i+j+k` is even and
:math:`|i-j| \le k \le i+j`, else 0 (see :func:`triple_product`).

Notes
-----
The printed N = 4 formula eq. (17) for :math:`Y_3` omits the terms
:math:`6 y_1^2 y_3` and :math:`12 y_3 y_4^2`; eqs. (14)-(16), (18), (19) agree with
:func:`cubic_projection`. ``tests/opa/test_basis.py`` pins this.
"""

from __future__ import annotations

from numbers import Integral

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "chebyshev_u",
    "cubic_projection",
    "evaluate",
    "gauss_nodes",
    "project",
    "quadrature_order",
    "triple_product",
]


def _check_int(name: str, value: object, minimum: int) -> int:
    """Return ``value`` as an int, or raise ValueError naming ``name`` and the value."""
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def chebyshev_u(n_max: int, xi: ArrayLike) -> np.ndarray:
    r"""Chebyshev polynomials of the second kind :math:`U_0, \dots, U_{n_{max}}` at ``xi``.

    .. math::

        U_0 = 1, \quad U_1 = 2\xi, \quad U_{i+1} = 2\xi U_i - U_{i-1}.

    They are orthonormal under the semicircle density, paper eq. (4).

    Parameters
    ----------
    n_max : int
        Highest degree, ``n_max >= 0``.
    xi : array_like, shape S
        Evaluation points (any shape; normally in [-1, 1]).

    Returns
    -------
    numpy.ndarray, shape (n_max + 1, *S)
        ``out[i] = U_i(xi)``.

    Examples
    --------
    >>> chebyshev_u(3, 0.5)
    array([ 1.,  1.,  0., -1.])
    """
    n_max = _check_int("n_max", n_max, 0)
    xi = np.asarray(xi, dtype=float)
    out = np.empty((n_max + 1, *xi.shape))
    out[0] = 1.0
    if n_max >= 1:
        out[1] = 2.0 * xi
    for i in range(1, n_max):
        out[i + 1] = 2.0 * xi * out[i] - out[i - 1]
    return out


def orthonormal(n_max: int, xi: ArrayLike, alpha: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Orthonormal polynomials p_0..p_{n_max} at ``xi`` from the recurrence
    ``b_{k+1} p_{k+1} = (xi - alpha_k) p_k - b_k p_{k-1}``, ``p_0 = 1`` (any law of xi;
    :mod:`opa._measure` computes ``alpha``, ``b``). Shape ``(n_max + 1, *xi.shape)``."""
    xi = np.asarray(xi, dtype=float)
    out = np.empty((n_max + 1, *xi.shape))
    out[0] = 1.0
    if n_max >= 1:
        out[1] = (xi - alpha[0]) / b[1]
    for k in range(1, n_max):
        out[k + 1] = ((xi - alpha[k]) * out[k] - b[k] * out[k - 1]) / b[k + 1]
    return out


def gauss_nodes(q: int) -> tuple[np.ndarray, np.ndarray]:
    r"""Gauss rule of the semicircle density (Gauss-Chebyshev of the second kind).

    .. math::

        \xi_k = \cos\frac{k\pi}{q+1}, \qquad
        w_k = \frac{2}{q+1}\sin^2\frac{k\pi}{q+1}, \qquad k = 1, \dots, q,

    so that :math:`\sum_k w_k f(\xi_k) = \int_{-1}^{1} p(\xi) f(\xi)\,d\xi` for every
    polynomial of degree at most ``2q - 1``. The weights sum to 1 (``p`` is a density).

    Parameters
    ----------
    q : int
        Number of nodes, ``q >= 1``.

    Returns
    -------
    nodes : numpy.ndarray, shape (q,)
        The zeros of :math:`U_q`, sorted ascending, inside (-1, 1).
    weights : numpy.ndarray, shape (q,)
        Positive weights matching ``nodes``.

    Examples
    --------
    >>> nodes, weights = gauss_nodes(3)
    >>> round(float(weights @ nodes**2), 12)  # E[xi^2] = 1/4
    0.25
    """
    q = _check_int("q", q, 1)
    theta = np.arange(q, 0, -1) * np.pi / (q + 1)  # k = q..1 gives ascending nodes
    # cos(k pi/(Q+1)) = sin((Q+1-2k) pi/(2(Q+1))): the sine form is exactly antisymmetric,
    # and the middle node of an odd rule is exactly 0 (cos(pi/2) is 6e-17).
    nodes = np.sin((2 * np.arange(1, q + 1) - q - 1) * np.pi / (2 * (q + 1)))
    weights = 2.0 / (q + 1) * np.sin(theta) ** 2
    return nodes, weights


def project(values: ArrayLike, order: int, nodes: ArrayLike, weights: ArrayLike) -> np.ndarray:
    r"""Project values sampled at quadrature nodes onto :math:`U_0, \dots, U_{order}`.

    .. math::

        c_i = \sum_k w_k\, v(\xi_k)\, U_i(\xi_k) \approx E[v\, U_i],

    exact when :math:`v` is a polynomial and ``deg v + order <= 2q - 1`` for the
    :func:`gauss_nodes` rule with ``q`` nodes.

    Parameters
    ----------
    values : array_like, shape (*B, q)
        Function values; the last axis runs over the nodes.
    order : int
        Highest degree of the projection, ``order >= 0``.
    nodes, weights : array_like, shape (q,)
        Quadrature rule, e.g. from :func:`gauss_nodes`.

    Returns
    -------
    numpy.ndarray, shape (order + 1, *B)
        Coefficients, degree on the first axis (the layout :func:`evaluate` takes).

    Examples
    --------
    >>> nodes, weights = gauss_nodes(4)
    >>> project(nodes**2, 2, nodes, weights).round(12) + 0.0  # xi^2 = (U_0 + U_2) / 4
    array([0.25, 0.  , 0.25])
    """
    order = _check_int("order", order, 0)
    values = np.asarray(values, dtype=float)
    nodes = np.asarray(nodes, dtype=float)
    weights = np.asarray(weights, dtype=float)
    if nodes.ndim != 1 or nodes.shape != weights.shape:
        raise ValueError(
            f"nodes and weights must be 1-d of equal length, got shapes "
            f"{nodes.shape} and {weights.shape}"
        )
    if values.ndim == 0 or values.shape[-1] != nodes.size:
        raise ValueError(
            f"values must have last axis of length {nodes.size} (the nodes), "
            f"got shape {values.shape}"
        )
    basis_w = chebyshev_u(order, nodes) * weights  # (order + 1, q)
    return np.moveaxis(values @ basis_w.T, -1, 0)


def evaluate(coef: ArrayLike, xi: ArrayLike) -> np.ndarray:
    r"""Evaluate the expansion :math:`\sum_{i=0}^{N} c_i U_i(\xi)` (paper eq. (3)).

    Parameters
    ----------
    coef : array_like, shape (N + 1, *B)
        Coefficients, degree on the first axis; ``*B`` are batch axes.
    xi : array_like, shape S
        Evaluation points.

    Returns
    -------
    numpy.ndarray, shape (*B, *S)
        The expansion at ``xi`` for every batch entry.

    Examples
    --------
    >>> evaluate([1.0, 0.5], [-1.0, 0.0, 1.0])  # 1 + 0.5 * 2 xi
    array([0., 1., 2.])
    """
    coef = np.asarray(coef, dtype=float)
    if coef.ndim == 0:
        raise ValueError(f"coef must have at least one axis (the degree), got shape {coef.shape}")
    basis = chebyshev_u(coef.shape[0] - 1, xi)
    return np.tensordot(coef, basis, axes=(0, 0))


def cubic_projection(coef: ArrayLike, n_out: int | None = None, q: int | None = None) -> np.ndarray:
    r"""Exact projection of the cube of an expansion, :math:`X_i = E[x^3 U_i]`.

    .. math::

        x = \sum_{j=0}^{N} c_j U_j, \qquad
        x^3 = \sum_{i=0}^{3N} X_i U_i, \qquad X_i = E[x^3 U_i],

    paper eqs. (7)-(8) (:math:`X_i` for displacements, :math:`Y_i` for velocities). Computed
    by evaluating :math:`x` at ``q`` Gauss nodes, cubing pointwise and projecting back; the
    result is exact (to rounding) because :math:`\deg(x^3 U_i) = 3N + i \le 2q - 1`.

    Parameters
    ----------
    coef : array_like, shape (N + 1, *B)
        Expansion coefficients, degree on the first axis; ``*B`` are batch axes.
    n_out : int, optional
        Highest output index, ``n_out >= 0``. Default ``3N`` (the full cube;
        :math:`X_i = 0` for ``i > 3N``).
    q : int, optional
        Number of Gauss nodes. Default and minimum: the smallest exact one,
        ``ceil((3N + n_out + 1) / 2)``.

    Returns
    -------
    numpy.ndarray, shape (n_out + 1, *B)
        :math:`X_0, \dots, X_{n_{out}}`.

    Notes
    -----
    Cost O((N + n_out) q) per batch entry, instead of O(N^3 n_out) for the quadruple-product
    tensor :math:`E[U_a U_b U_c U_i]`.

    Examples
    --------
    >>> cubic_projection([0.0, 1.0]).round(12) + 0.0  # (2 xi)^3 = 2 U_1 + U_3
    array([0., 2., 0., 1.])
    """
    coef = np.asarray(coef, dtype=float)
    if coef.ndim == 0 or coef.shape[0] == 0:
        raise ValueError(
            f"coef must have a non-empty first axis (the degree), got shape {coef.shape}"
        )
    n = coef.shape[0] - 1
    n_out = 3 * n if n_out is None else _check_int("n_out", n_out, 0)
    q_min = max(1, (3 * n + n_out + 2) // 2)  # smallest q with 3N + n_out <= 2q - 1
    if q is None:
        q = q_min
    else:
        q = _check_int("q", q, 1)
        if q < q_min:
            raise ValueError(
                f"q must be >= {q_min} for an exact projection with N={n}, n_out={n_out}, "
                f"got {q}"
            )
    nodes, weights = gauss_nodes(q)
    return project(evaluate(coef, nodes) ** 3, n_out, nodes, weights)


def triple_product(i: int, j: int, k: int) -> float:
    r"""Closed-form triple product :math:`E[U_i U_j U_k]` under the semicircle density.

    From the linearisation :math:`U_i U_j = \sum_{m=|i-j|,\ \mathrm{step}\ 2}^{i+j} U_m` and
    orthonormality (eqs. (4)-(5)):

    .. math::

        E[U_i U_j U_k] = \begin{cases} 1, & i+j+k \text{ even and } |i-j| \le k \le i+j,\\
        0, & \text{otherwise.}\end{cases}

    Parameters
    ----------
    i, j, k : int
        Degrees, each ``>= 0``.

    Returns
    -------
    float
        1.0 or 0.0.

    Examples
    --------
    >>> triple_product(1, 1, 2), triple_product(1, 1, 1)
    (1.0, 0.0)
    """
    i = _check_int("i", i, 0)
    j = _check_int("j", j, 0)
    k = _check_int("k", k, 0)
    return 1.0 if (i + j + k) % 2 == 0 and abs(i - j) <= k <= i + j else 0.0


def quadrature_order(order: int) -> int:
    r"""Number of Gauss nodes the OPA right-hand side of order ``N`` needs: ``Q = 2N + 1``.

    The equivalent system (eqs. (10)-(13)) needs :math:`E[x^3 U_i]` and
    :math:`E[\xi (\dot x)^3 U_i]` for :math:`i \le N`; the integrand has degree at most
    :math:`3N + 1 + N = 4N + 1 \le 2Q - 1`.

    Parameters
    ----------
    order : int
        Expansion order ``N >= 0``.

    Returns
    -------
    int
        ``2 * order + 1``.

    Examples
    --------
    >>> quadrature_order(4)
    9
    """
    order = _check_int("order", order, 0)
    return 2 * order + 1
