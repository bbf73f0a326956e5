"""Sobol indices from the coefficients of a polynomial chaos expansion (Sudret 2008).

In an orthonormal product basis ``Psi_alpha(xi) = prod_k p_{alpha_k}(xi_k)`` of
independent parameters, a surrogate ``g(xi) = sum_alpha c_alpha Psi_alpha(xi)`` has the
variance ``V = sum_{alpha != 0} c_alpha^2``, and its ANOVA decomposition groups the same
squares by the parameters each multi-index involves:

    S_i  = sum_{alpha_i > 0, alpha_k = 0 (k != i)} c_alpha^2 / V     (first order)
    S_Ti = sum_{alpha_i > 0} c_alpha^2 / V                            (total)

(B. Sudret, Global sensitivity analysis using polynomial chaos expansions, Reliab. Eng.
Syst. Saf. 93, 2008, eqs. 33 and 36). The indices are exact for the surrogate; how close
they are to the model's is the surrogate's error, which ``compare._sobol`` certifies by
pick-freeze Monte Carlo (using the surrogate as its control variate).

Pure numpy: the kernels of the labelled results elsewhere, never xarray.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class SobolIndices(NamedTuple):
    """First-order and total Sobol indices of every parameter, and the variance.

    Attributes
    ----------
    first : ndarray, shape (d, ...)
        ``S_i`` for each parameter ``i`` and each output.
    total : ndarray, shape (d, ...)
        ``S_Ti``; ``total >= first`` and ``sum(first) <= 1 <= sum(total)`` (up to rounding).
    variance : ndarray, shape (...)
        ``V = sum_{alpha != 0} c_alpha^2``. Where it is 0 the indices are NaN.
    """

    first: np.ndarray
    total: np.ndarray
    variance: np.ndarray


def _checked_indices(indices, rows: int) -> np.ndarray:
    table = np.asarray(indices)
    if table.ndim != 2 or table.shape[1] < 1:
        raise ValueError(f"indices must have shape (P, d) with d >= 1, got shape "
                         f"{table.shape}")
    if table.shape[0] != rows:
        raise ValueError(f"indices must have one row per coefficient ({rows}), got "
                         f"{table.shape[0]} rows")
    if not np.issubdtype(table.dtype, np.integer):
        if not np.issubdtype(table.dtype, np.floating) or not np.all(table == np.round(table)):
            raise ValueError(f"indices must be whole numbers, got dtype {table.dtype}")
        table = table.astype(np.int64)
    if np.any(table < 0):
        raise ValueError(f"indices must be non-negative, got the row "
                         f"{table[np.any(table < 0, axis=1)][0].tolist()}")
    if np.any(table[0] != 0):
        raise ValueError(f"indices[0] must be the constant (all zeros), got "
                         f"{table[0].tolist()}")
    if len(np.unique(table, axis=0)) != rows:
        raise ValueError("indices must not repeat a multi-index (its coefficient would be "
                         "counted twice)")
    return table


def sobol_indices(coefficients, indices) -> SobolIndices:
    """First-order and total Sobol indices of a polynomial chaos expansion.

    Parameters
    ----------
    coefficients : array_like, shape (P, ...)
        The expansion's coefficients in an orthonormal product basis: row ``p`` goes with
        the multi-index ``indices[p]``; the trailing axes are outputs (times, states).
    indices : array_like of int, shape (P, d)
        The multi-indices, one per row, without repetition; row 0 is the constant
        (all zeros). Any set works (total degree, tensor, hyperbolic, Smolyak's).

    Returns
    -------
    SobolIndices
        ``first`` and ``total``, shape (d, ...), and ``variance``, shape (...).

    Notes
    -----
    With ``d_alpha = c_alpha^2`` and ``V = sum_{alpha != 0} d_alpha``,

    .. math::

        S_i = \\frac{1}{V} \\sum_{\\alpha_i > 0,\\ \\alpha_k = 0\\ (k \\neq i)} c_\\alpha^2,
        \\qquad
        S_{T i} = \\frac{1}{V} \\sum_{\\alpha_i > 0} c_\\alpha^2

    (Sudret 2008, eqs. 33 and 36). An output whose variance is exactly 0 (a constant
    output, e.g. the initial state at t = 0) has no variance to share out: its indices
    are undefined and returned as NaN, without a division warning. The orthonormality of
    the basis is the caller's promise: in any other basis the squares are not the
    partial variances.

    Examples
    --------
    ``g = 1 + 2 xi_1 + xi_2 + xi_1 xi_2`` in orthonormal polynomials (d = 2):

    >>> import numpy as np
    >>> idx = np.array([[0, 0], [1, 0], [0, 1], [1, 1]])
    >>> s = sobol_indices(np.array([1.0, 2.0, 1.0, 1.0]), idx)
    >>> s.variance.item(), s.first.round(4).tolist(), s.total.round(4).tolist()
    (6.0, [0.6667, 0.1667], [0.8333, 0.3333])
    """
    values = np.asarray(coefficients, dtype=float)
    if values.ndim < 1 or values.shape[0] < 1:
        raise ValueError(f"coefficients must have shape (P, ...) with P >= 1, got shape "
                         f"{values.shape}")
    table = _checked_indices(indices, values.shape[0])
    squares = values ** 2
    involved = table > 0                                   # (P, d)
    alone = involved & (involved.sum(axis=1) == 1)[:, None]
    variance = squares[1:].sum(axis=0)
    total = np.tensordot(involved.T.astype(float), squares, axes=1)
    first = np.tensordot(alone.T.astype(float), squares, axes=1)
    defined = variance > 0
    safe = np.where(defined, variance, 1.0)
    first = np.where(defined, first / safe, np.nan)
    total = np.where(defined, total / safe, np.nan)
    return SobolIndices(first=first, total=total, variance=variance)
