r"""Polynomial chaos in d dimensions: multi-index sets, product bases, tensor and Smolyak rules.

Several uncertain parameters are driven by independent variables
:math:`\xi = (\xi_1, \dots, \xi_d)` with a product law :math:`\mu_1 \otimes \dots \otimes
\mu_d` (each :math:`\mu_j` a bounded :class:`~opa._measure.Measure`). With
:math:`p^{(j)}_k` the orthonormal polynomials of :math:`\mu_j`, the product polynomials

.. math::

    \Psi_\alpha(\xi) = \prod_{j=1}^d p^{(j)}_{\alpha_j}(\xi_j), \qquad
    E[\Psi_\alpha \Psi_\beta] = \delta_{\alpha\beta},

over a multi-index set :math:`\mathcal A \subset \mathbb N^d` span the expansion
:math:`x(\xi) = \sum_{\alpha \in \mathcal A} x_\alpha \Psi_\alpha(\xi)` with
:math:`x_\alpha = E[x \Psi_\alpha]`, mean :math:`x_0` and variance
:math:`\sum_{\alpha \ne 0} x_\alpha^2` (the d-dimensional paper eqs. (3)-(4)).

Multi-index sets (:func:`multi_indices`): total degree :math:`|\alpha|_1 \le N` (the
default), tensor :math:`\max_j \alpha_j \le N`, hyperbolic cross
:math:`(\sum_j \alpha_j^q)^{1/q} \le N` with :math:`0 < q \le 1`.

Rules (:meth:`ChaosBasis.rule`) are built from the marginals' Gauss rules: the
:math:`m`-point Gauss rule of :math:`\mu_j` integrates :math:`\xi_j^k` exactly for
:math:`k \le 2m - 1`. With :math:`Q^{(j)}_l` the rule of :math:`l + 1` points (exact to
degree :math:`2l + 1`):

* **tensor**: :math:`Q^{(1)}_{l_1} \otimes \dots \otimes Q^{(d)}_{l_d}` is exact for every
  monomial :math:`\xi^k` with :math:`k_j \le 2 l_j + 1` for all j (a box), at
  :math:`\prod_j (l_j + 1)` nodes;
* **smolyak** (the combination technique): for a downward-closed set :math:`\Lambda` of
  levels,

  .. math::

      A_\Lambda = \sum_{l \in \Lambda} c_l\, Q^{(1)}_{l_1} \otimes \dots \otimes
      Q^{(d)}_{l_d}, \qquad
      c_l = \sum_{e \in \{0, 1\}^d,\ l + e \in \Lambda} (-1)^{|e|},

  is exact on the sum of the boxes of its levels, every :math:`\xi^k` with
  :math:`(\lfloor k_j / 2 \rfloor)_j \in \Lambda` (Gerstner & Griebel 1998; it holds for
  non-nested rules because the exact spaces of the 1-D rules are nested). Nodes shared by
  several grids are merged; weights may be negative.

A degree D asks for :math:`\Lambda = \{l : \sum_j l_j \le \lfloor D/2 \rfloor\}`, exact for
every monomial of total degree at most :math:`2\lfloor D/2 \rfloor + 1 \ge D`; per-dimension
degrees :math:`(D_1, \dots, D_d)` ask for the anisotropic
:math:`\Lambda = \{l : \sum_j l_j / \lfloor D_j/2 \rfloor \le 1\}` (see
:meth:`ChaosBasis.rule` for the exact space).

In one dimension with the paper's semicircle law the factors are exactly today's
:func:`~opa._basis.chebyshev_u` and :func:`~opa._basis.gauss_nodes` (so ``d = 1`` reproduces
:func:`opa._run.quadrature` bit for bit); other laws use the recurrence of
:class:`~opa._measure.Measure` as :func:`opa._elements.element_rule` does.

Examples
--------
>>> from opa._measure import semicircle, uniform
>>> basis = ChaosBasis.from_order((semicircle(), uniform()), 2)
>>> basis.size  # C(2 + 2, 2)
6
>>> coef, evaluations = basis.project_function(lambda x: x[:, 0] + x[:, 1] ** 2)
>>> float(basis.mean(coef)).__round__(12)  # E[xi_1] + E[xi_2^2] = 0 + 1/3
0.333333333333
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import reduce
from numbers import Real

import numpy as np
from numpy.typing import ArrayLike

from opa._basis import _check_int, chebyshev_u, gauss_nodes
from opa._measure import Measure, parse

__all__ = [
    "INDEX_KINDS",
    "MAX_CHAOS_TERMS",
    "MAX_RULE_NODES",
    "MAX_TRIPLE_BYTES",
    "RULE_KINDS",
    "ChaosBasis",
    "multi_indices",
]

#: the multi-index sets :func:`multi_indices` builds
INDEX_KINDS = ("total", "tensor", "hyperbolic")
#: the rules :meth:`ChaosBasis.rule` builds
RULE_KINDS = ("auto", "tensor", "smolyak")
#: most basis functions P: the (Q, P) matrix of basis values is the largest array here, and
#: at 50 000 terms a 10 000-node rule already takes 4 GB
MAX_CHAOS_TERMS = 50_000
#: most nodes Q of a rule (for Smolyak: summed over its grids before duplicates merge)
MAX_RULE_NODES = 1_000_000
#: largest dense triple-product tensor, P^3 doubles: 256 MiB, about P = 322
MAX_TRIPLE_BYTES = 2**28
#: relative slack on a set's norm bound: (1^q + 1^q)^(1/q) = 2^(1/q) must not fall out of a
#: hyperbolic set by round-off, nor l = (1, 1, 1) out of an anisotropic level set with 1/3's
NORM_SLACK = 1e-10
#: nodes of Smolyak grids closer than this (relative to the support) are one node: distinct
#: Gauss nodes of up to MAX_GAUSS points are 1e-6 apart, copies of one node 1e-16
MERGE_TOL = 1e-12


# -- multi-index sets ------------------------------------------------------------------------
def _lower_set(costs: Sequence[np.ndarray], budget: float, what: str) -> np.ndarray:
    """Every alpha with ``alpha_j < len(costs[j])`` and ``sum_j costs[j][alpha_j] <= budget``.

    Built one dimension at a time; each partial set is the projection of the final one
    (costs are >= 0 with ``costs[j][0] == 0``), so a partial set past
    :data:`MAX_CHAOS_TERMS` already proves the final one too large."""
    rows = np.zeros((1, 0), dtype=np.int64)
    spent = np.zeros(1)
    limit = budget * (1.0 + NORM_SLACK) + NORM_SLACK
    for cost in costs:
        total = spent[:, None] + np.asarray(cost, dtype=float)[None, :]
        keep_row, keep_k = np.nonzero(total <= limit)
        if keep_row.size > MAX_CHAOS_TERMS:
            raise ValueError(f"{what} has more than MAX_CHAOS_TERMS = {MAX_CHAOS_TERMS} "
                             f"multi-indices; lower the order or use a sparser set")
        rows = np.column_stack([rows[keep_row], keep_k]).astype(np.int64)
        spent = total[keep_row, keep_k]
    return rows


def _graded(rows: np.ndarray) -> np.ndarray:
    """Rows sorted by total degree, ties by the first exponent descending, then the second..."""
    d = rows.shape[1]
    keys = [-rows[:, j] for j in reversed(range(d))] + [rows.sum(axis=1)]
    return np.ascontiguousarray(rows[np.lexsort(keys)])


def multi_indices(d: int, order: int, kind: str = "total", q: float = 1.0) -> np.ndarray:
    r"""The multi-index set of a d-dimensional polynomial chaos, in graded order.

    .. math::

        \text{total: } \sum_j \alpha_j \le N, \qquad
        \text{tensor: } \max_j \alpha_j \le N, \qquad
        \text{hyperbolic: } \Big(\sum_j \alpha_j^q\Big)^{1/q} \le N.

    Parameters
    ----------
    d : int
        Number of variables, ``d >= 1``.
    order : int
        The bound N, ``order >= 0``.
    kind : {"total", "tensor", "hyperbolic"}
        Which set. ``"hyperbolic"`` with ``q = 1`` is ``"total"``.
    q : float
        The quasi-norm's exponent, ``0 < q <= 1`` (used by ``"hyperbolic"``; smaller q
        keeps fewer interactions). The bound has a relative slack of
        :data:`NORM_SLACK` against round-off.

    Returns
    -------
    numpy.ndarray of int64, shape (P, d)
        One multi-index per row, sorted by total degree, ties broken by the first
        exponent descending, then the second, and so on (``(2, 0), (1, 1), (0, 2)``). Row
        0 is all zeros; for ``d = 1`` the rows are ``[0], [1], ..., [order]``.

    Raises
    ------
    ValueError
        Bad arguments, or more than :data:`MAX_CHAOS_TERMS` rows. Sizes: total
        ``C(order + d, d)``, tensor ``(order + 1)^d``.

    Examples
    --------
    >>> multi_indices(2, 2).tolist()
    [[0, 0], [1, 0], [0, 1], [2, 0], [1, 1], [0, 2]]
    >>> len(multi_indices(3, 4, "hyperbolic", q=0.5)), len(multi_indices(3, 4))
    (16, 35)
    """
    d = _check_int("d", d, 1)
    order = _check_int("order", order, 0)
    if kind not in INDEX_KINDS:
        raise ValueError(f"kind must be one of {', '.join(INDEX_KINDS)}, got {kind!r}")
    if isinstance(q, bool) or not isinstance(q, Real) or not 0.0 < float(q) <= 1.0:
        raise ValueError(f"q must be a number in (0, 1], got {q!r}")
    k = np.arange(order + 1, dtype=float)
    what = f"the {kind} set of order {order} in d = {d} dimensions"
    if kind == "tensor":
        rows = _lower_set([np.zeros(order + 1)] * d, 0.0, what)
    elif kind == "total" or float(q) == 1.0:
        rows = _lower_set([k] * d, float(order), what)
    else:
        rows = _lower_set([k ** float(q)] * d, float(order) ** float(q), what)
    return _graded(rows)


# -- one-dimensional factors -----------------------------------------------------------------
def _is_paper_law(measure: Measure) -> bool:
    """The whole semicircle law: its closed forms are today's 1-D basis and rule (the test
    :func:`opa._elements.element_rule` makes)."""
    return measure.name == "semicircle" and measure.is_whole


def _gauss_1d(measure: Measure, points: int) -> tuple[np.ndarray, np.ndarray]:
    if _is_paper_law(measure):
        return gauss_nodes(points)
    return measure.gauss(points)


def _basis_1d(measure: Measure, n_max: int, x: np.ndarray) -> np.ndarray:
    """p_0..p_{n_max} at x, shape (n_max + 1, M)."""
    if _is_paper_law(measure):
        return chebyshev_u(n_max, x)
    return measure.basis(n_max, x)


# -- rules -----------------------------------------------------------------------------------
def _tensor_grid(rules: Sequence[tuple[np.ndarray, np.ndarray]]):
    """Nodes (Q, d), first dimension slowest, and product weights (Q,)."""
    grids = np.meshgrid(*[nodes for nodes, _ in rules], indexing="ij")
    nodes = np.stack([g.ravel() for g in grids], axis=1)
    weights = reduce(np.multiply.outer, [w for _, w in rules]).ravel()
    return nodes, weights


def _signed_subsets(steps: np.ndarray, start: int, slack: float) -> int:
    """Sum of (-1)^|E| over subsets E of ``steps[start:]`` (ascending) whose sum <= slack."""
    total = 1
    for i in range(start, steps.size):
        if steps[i] > slack:
            break
        total -= _signed_subsets(steps, i + 1, slack - steps[i])
    return total


def _smolyak_plan(levels: Sequence[int]) -> list[tuple[np.ndarray, int]]:
    """The levels l with a non-zero combination coefficient c_l, for the level set
    ``sum_j l_j / levels[j] <= 1`` (l_j = 0 where levels[j] = 0)."""
    costs = [np.arange(n + 1) / n if n > 0 else np.zeros(1) for n in levels]
    lam = _lower_set(costs, 1.0, f"the Smolyak level set of levels {tuple(levels)}")
    inverse = np.array([1.0 / n for n in levels if n > 0])
    steps = np.sort(inverse)
    spent = lam[:, np.asarray(levels) > 0] @ inverse if steps.size else np.zeros(len(lam))
    limit = 1.0 + 2 * NORM_SLACK  # the bound of _lower_set
    plan = []
    for row, used in zip(lam, spent):
        # l + e is in the set iff its cost stays below 1; only the cost matters
        c = _signed_subsets(steps, 0, limit - used)
        if c:
            plan.append((row, c))
    return plan


def _merge(nodes: np.ndarray, weights: np.ndarray, widths: Sequence[float]):
    """Nodes equal to ``MERGE_TOL`` times the support's width made one, weights summed.

    Grids of different levels share nodes (the middle node of every odd Gauss rule of a
    symmetric law), but Golub-Welsch puts that node at 1e-17 rather than 0: equal nodes
    are found per coordinate, by gaps in the sorted values, and keep the first value."""
    labels = np.empty(nodes.shape, dtype=np.int64)
    for j, width in enumerate(widths):
        order = np.argsort(nodes[:, j], kind="stable")
        step = np.diff(nodes[order, j]) > MERGE_TOL * width
        labels[order, j] = np.concatenate([[0], np.cumsum(step)])
    _, first, inverse = np.unique(labels, axis=0, return_index=True, return_inverse=True)
    return nodes[first], np.bincount(inverse.ravel(), weights=weights)


def _smolyak(measures: Sequence[Measure], levels: Sequence[int]):
    plan = _smolyak_plan(levels)
    count = sum(int(np.prod(row + 1)) for row, _ in plan)
    if count > MAX_RULE_NODES:
        raise ValueError(f"the Smolyak rule of levels {tuple(levels)} has {count} nodes "
                         f"before merging, more than MAX_RULE_NODES = {MAX_RULE_NODES}")
    found: dict = {}

    def rule_1d(j, points):
        if (j, points) not in found:
            found[j, points] = _gauss_1d(measures[j], points)
        return found[j, points]

    if len(plan) == 1 and plan[0][1] == 1:  # one grid (d = 1): today's rule, untouched
        return _tensor_grid([rule_1d(j, int(n) + 1) for j, n in enumerate(plan[0][0])])
    parts = [_tensor_grid([rule_1d(j, int(n) + 1) for j, n in enumerate(row)])
             for row, _ in plan]
    nodes = np.concatenate([p[0] for p in parts])
    weights = np.concatenate([c * p[1] for p, (_, c) in zip(parts, plan)])
    nodes, weights = _merge(nodes, weights, [m.hi - m.lo for m in measures])
    # nodes whose weights cancel to round-off are not worth an evaluation
    keep = np.abs(weights) > 8 * np.finfo(float).eps * np.abs(weights).sum()
    return np.ascontiguousarray(nodes[keep]), weights[keep]


def _degrees(degree, d: int) -> tuple[int, ...]:
    if isinstance(degree, (tuple, list, np.ndarray)):
        if len(degree) != d:
            raise ValueError(f"degree must be an integer or one per dimension ({d}), got "
                             f"{tuple(degree)!r}")
        return tuple(_check_int(f"degree[{j}]", v, 0) for j, v in enumerate(degree))
    return (_check_int("degree", degree, 0),) * d


# -- the basis -------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ChaosBasis:
    r"""Orthonormal product polynomials :math:`\Psi_\alpha` of a product law, and its rules.

    Parameters
    ----------
    measures : sequence of Measure or str, length d
        The law of each :math:`\xi_j` (anything :func:`opa._measure.parse` takes); the
        joint law is their product.
    indices : array_like of int, shape (P, d)
        The multi-index set, row 0 all zeros (the mean), rows distinct; see
        :func:`multi_indices` and :meth:`from_order`.

    Examples
    --------
    >>> basis = ChaosBasis.from_order(("semicircle", "uniform", "beta:2,3"), 3)
    >>> nodes, weights = basis.rule(6)
    >>> gram = basis.evaluate(nodes).T @ (weights[:, None] * basis.evaluate(nodes))
    >>> bool(np.allclose(gram, np.eye(basis.size)))
    True
    """

    measures: tuple
    indices: np.ndarray

    def __post_init__(self):
        measures = tuple(parse(m) for m in self.measures)
        if not measures:
            raise ValueError("measures must name at least one law, got none")
        indices = np.asarray(self.indices)
        if indices.ndim != 2 or indices.shape[1] != len(measures) or not indices.shape[0]:
            raise ValueError(f"indices must have shape (P, {len(measures)}) with P >= 1, got "
                             f"shape {indices.shape}")
        if not np.issubdtype(indices.dtype, np.integer) or (indices < 0).any():
            raise ValueError(f"indices must be integers >= 0, got {indices.dtype} with "
                             f"minimum {indices.min()}")
        if indices.shape[0] > MAX_CHAOS_TERMS:
            raise ValueError(f"indices has {indices.shape[0]} rows, more than "
                             f"MAX_CHAOS_TERMS = {MAX_CHAOS_TERMS}")
        if indices[0].any():
            raise ValueError(f"indices row 0 must be all zeros (the mean), got "
                             f"{indices[0].tolist()}")
        if len(np.unique(indices, axis=0)) != len(indices):
            raise ValueError("indices must be distinct rows, got repeated multi-indices")
        indices = np.array(indices, dtype=np.int64)
        indices.flags.writeable = False
        object.__setattr__(self, "measures", measures)
        object.__setattr__(self, "indices", indices)

    @classmethod
    def from_order(cls, measures, order: int, kind: str = "total",
                   q: float = 1.0) -> "ChaosBasis":
        """The basis of :func:`multi_indices` ``(len(measures), order, kind, q)``."""
        return cls(tuple(measures), multi_indices(len(measures), order, kind, q))

    @property
    def dimension(self) -> int:
        """d, the number of variables."""
        return len(self.measures)

    @property
    def size(self) -> int:
        """P, the number of basis functions."""
        return self.indices.shape[0]

    @property
    def order(self) -> int:
        """The highest total degree of the set."""
        return int(self.indices.sum(axis=1).max())

    @property
    def degrees(self) -> tuple[int, ...]:
        """The highest degree in each variable."""
        return tuple(int(n) for n in self.indices.max(axis=0))

    def evaluate(self, xi: ArrayLike) -> np.ndarray:
        r"""Values :math:`\Psi_\alpha(\xi_m)` at M points.

        Parameters
        ----------
        xi : array_like, shape (M, d)
            Points, one per row.

        Returns
        -------
        numpy.ndarray, shape (M, P)
            Node-major: ``out[m, a] = Psi_{indices[a]}(xi[m])``.
        """
        xi = np.asarray(xi, dtype=float)
        if xi.ndim != 2 or xi.shape[1] != self.dimension:
            raise ValueError(f"xi must have shape (M, {self.dimension}), got shape {xi.shape}")
        values = None
        for j, (measure, n_max) in enumerate(zip(self.measures, self.degrees)):
            factor = _basis_1d(measure, n_max, xi[:, j])[self.indices[:, j]]  # (P, M)
            values = factor if values is None else values * factor
        return np.ascontiguousarray(values.T)

    def rule(self, degree, kind: str = "auto") -> tuple[np.ndarray, np.ndarray]:
        r"""A cubature rule of the product law built from the marginals' Gauss rules.

        Parameters
        ----------
        degree : int or sequence of d ints
            An int D: exact for every polynomial of total degree <= D (both kinds). Per
            dimension :math:`(D_1, \dots, D_d)`, with :math:`L_j = \lfloor D_j/2 \rfloor`:

            * ``"tensor"``: :math:`L_j + 1` Gauss points in dimension j, exact for every
              :math:`\xi^k` with :math:`k_j \le 2L_j + 1` for all j at once;
            * ``"smolyak"``: exact for every :math:`\xi^k` with
              :math:`\sum_{j: L_j > 0} \lfloor k_j/2 \rfloor / L_j \le 1` and
              :math:`k_j \le 1` where :math:`L_j = 0`, so for each :math:`\xi_j^{k}`,
              :math:`k \le D_j`, and the mixed terms in that anisotropic simplex.
        kind : {"auto", "tensor", "smolyak"}
            ``"auto"``: tensor for d <= 2; Smolyak for d >= 3, unless the tensor rule has
            no more nodes (its exact space contains the Smolyak one).

        Returns
        -------
        nodes : numpy.ndarray, shape (Q, d)
        weights : numpy.ndarray, shape (Q,)
            Summing to 1; Smolyak weights may be negative.

        Raises
        ------
        ValueError
            Bad arguments, or more than :data:`MAX_RULE_NODES` nodes.

        Notes
        -----
        Gauss rules are not nested, so the Smolyak grids share few nodes (only the middle
        node of the odd rules of a symmetric law). For total degree 7 in uniform laws:
        d = 3, 69 nodes against the tensor rule's 64; d = 4, 137 against 256; d = 5, 241
        against 1024; degree 3 takes 2d + 1 nodes against 2^d. Hence ``"auto"`` compares
        the two counts. The combination's coefficients grow with d, and so does the
        round-off of its sums (weights sum to 1 within 1e-11 at d = 10, degree 11).

        Examples
        --------
        Ishigami-like functions are smooth in xi_1, xi_2 but need only degree 4 in xi_3:

        >>> basis = ChaosBasis.from_order(["uniform"] * 3, 4)
        >>> len(basis.rule(12, "tensor")[0]), len(basis.rule((12, 12, 4), "tensor")[0])
        (343, 147)
        """
        if kind not in RULE_KINDS:
            raise ValueError(f"kind must be one of {', '.join(RULE_KINDS)}, got {kind!r}")
        levels = [n // 2 for n in _degrees(degree, self.dimension)]
        tensor_count = math.prod(n + 1 for n in levels)
        if kind == "smolyak" or (kind == "auto" and self.dimension >= 3):
            try:
                nodes, weights = _smolyak(self.measures, levels)
            except ValueError:
                if kind == "smolyak" or tensor_count > MAX_RULE_NODES:
                    raise
            else:
                if kind == "smolyak" or len(nodes) < tensor_count:
                    return nodes, weights
        if tensor_count > MAX_RULE_NODES:
            raise ValueError(f"the tensor rule of degree {degree!r} has {tensor_count} nodes, "
                             f"more than MAX_RULE_NODES = {MAX_RULE_NODES}")
        return _tensor_grid([_gauss_1d(m, n + 1) for m, n in zip(self.measures, levels)])

    def exact_rule(self, factors: int = 2, kind: str = "auto"):
        """A rule exact for every product of ``factors`` basis functions (2: the Gram
        matrix and projections of the span; 3: triple products).

        Tensor: degree ``factors * n_j`` in each dimension; Smolyak: total degree
        ``factors * order``; ``"auto"`` takes whichever has fewer nodes (tensor for
        d <= 2)."""
        factors = _check_int("factors", factors, 1)
        if kind not in RULE_KINDS:
            raise ValueError(f"kind must be one of {', '.join(RULE_KINDS)}, got {kind!r}")
        if kind == "smolyak":
            return self.rule(factors * self.order, "smolyak")
        box = self.rule(tuple(factors * n for n in self.degrees), "tensor")
        if kind == "tensor" or self.dimension <= 2:
            return box
        try:
            sparse = self.rule(factors * self.order, "smolyak")
        except ValueError:
            return box
        return sparse if len(sparse[0]) < len(box[0]) else box

    def project(self, values: ArrayLike, nodes: ArrayLike, weights: ArrayLike) -> np.ndarray:
        r"""Coefficients :math:`c_\alpha = \sum_k w_k v(\xi_k) \Psi_\alpha(\xi_k)
        \approx E[v \Psi_\alpha]`.

        Parameters
        ----------
        values : array_like, shape (Q, ...)
            Values at the nodes, node-major.
        nodes : array_like, shape (Q, d)
        weights : array_like, shape (Q,)
            A rule, e.g. from :meth:`rule`; exact when it integrates every
            :math:`v \Psi_\alpha`.

        Returns
        -------
        numpy.ndarray, shape (P, ...)
        """
        nodes = np.asarray(nodes, dtype=float)
        weights = np.asarray(weights, dtype=float)
        values = np.asarray(values, dtype=float)
        if weights.ndim != 1 or nodes.shape != (weights.size, self.dimension):
            raise ValueError(f"nodes and weights must have shapes (Q, {self.dimension}) and "
                             f"(Q,), got {nodes.shape} and {weights.shape}")
        if values.ndim == 0 or values.shape[0] != weights.size:
            raise ValueError(f"values must have first axis of length {weights.size} (the "
                             f"nodes), got shape {values.shape}")
        weighted = self.evaluate(nodes) * weights[:, None]  # (Q, P)
        flat = weighted.T @ values.reshape(weights.size, -1)
        return flat.reshape(self.size, *values.shape[1:])

    def project_function(self, f: Callable, degree=None,
                         kind: str = "auto") -> tuple[np.ndarray, int]:
        """Project ``f`` on the basis with a rule of ``degree`` (see :meth:`rule`).

        Parameters
        ----------
        f : callable
            ``f(nodes)`` with nodes of shape (Q, d) returns values of shape (Q, ...).
        degree : int or sequence of d ints, optional
            Default: :meth:`exact_rule` ``(2)``, exact for every f in the span.
        kind : {"auto", "tensor", "smolyak"}

        Returns
        -------
        coef : numpy.ndarray, shape (P, ...)
        evaluations : int
            Q, the number of points f was evaluated at.
        """
        if degree is None:
            nodes, weights = self.exact_rule(2, kind)
        else:
            nodes, weights = self.rule(degree, kind)
        values = np.asarray(f(nodes), dtype=float)
        if values.ndim == 0 or values.shape[0] != len(nodes):
            raise ValueError(f"f must return values of shape ({len(nodes)}, ...) for nodes "
                             f"of shape {nodes.shape}, got shape {values.shape}")
        return self.project(values, nodes, weights), len(nodes)

    def _coefficients(self, coef: ArrayLike) -> np.ndarray:
        coef = np.asarray(coef, dtype=float)
        if coef.ndim == 0 or coef.shape[0] != self.size:
            raise ValueError(f"coef must have first axis of length P = {self.size}, got "
                             f"shape {coef.shape}")
        return coef

    def mean(self, coef: ArrayLike) -> np.ndarray:
        """E[x] = c_0 (row 0 is the constant), shape ``coef.shape[1:]``."""
        return self._coefficients(coef)[0]

    def variance(self, coef: ArrayLike) -> np.ndarray:
        r"""Var[x] = :math:`\sum_{\alpha \ne 0} c_\alpha^2`, shape ``coef.shape[1:]``."""
        return (self._coefficients(coef)[1:] ** 2).sum(axis=0)

    def triple_products(self) -> np.ndarray:
        r"""Dense :math:`T_{abc} = E[\Psi_a \Psi_b \Psi_c]`, shape (P, P, P).

        Computed with :meth:`exact_rule` ``(3)``, exact to rounding.

        Raises
        ------
        ValueError
            When ``8 P^3`` bytes exceed :data:`MAX_TRIPLE_BYTES` (about P = 322).

        Examples
        --------
        >>> t = ChaosBasis.from_order(["semicircle"], 3).triple_products()
        >>> round(float(t[1, 1, 2]), 12) + 0.0, round(float(t[1, 1, 1]), 12) + 0.0  # U1U1U2, U1^3
        (1.0, 0.0)
        """
        p = self.size
        if 8 * p**3 > MAX_TRIPLE_BYTES:
            raise ValueError(
                f"the triple products of P = {p} terms (order {self.order} in d = "
                f"{self.dimension} dimensions) take {8 * p**3 / 2**20:.0f} MiB, more than "
                f"MAX_TRIPLE_BYTES = {MAX_TRIPLE_BYTES // 2**20} MiB; lower the order")
        nodes, weights = self.exact_rule(3)
        values = self.evaluate(nodes)
        out = np.zeros((p, p * p))
        # the (chunk, P^2) pair products stay within the bound too
        chunk = max(1, MAX_TRIPLE_BYTES // (8 * p * p))
        for s in range(0, len(weights), chunk):
            v = values[s:s + chunk]
            pairs = (v[:, :, None] * v[:, None, :]).reshape(len(v), p * p)
            out += (v * weights[s:s + chunk, None]).T @ pairs
        return out.reshape(p, p, p)
