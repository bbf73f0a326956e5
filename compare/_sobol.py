"""Sobol indices certified by pick-freeze Monte Carlo, the surrogate as control variate.

Two independent samples ``A`` and ``B`` of the parameters, shape (M, d), and for each
parameter ``i`` the matrix ``A_B^(i)``: ``A`` with its column ``i`` taken from ``B``
(:func:`pick_freeze_design`). With the model's values ``f_A``, ``f_B``, ``f_ABi`` on the
rows (any trailing output shape: times, states),

    S_i  = mean(f_B (f_ABi - f_A)) / V                (Saltelli et al. 2010, table 2 (b))
    S_Ti = mean((f_A - f_ABi)^2) / (2 V)              (Jansen 1999; Saltelli 2010 (f))

with ``V`` the variance of the 2M values of ``A`` and ``B`` pooled. Both numerators are
unbiased; the ratios carry an O(1/M) bias, far below their noise.

**Standard errors: the delta method.** Each estimate is a ratio ``N / V`` of means over
the same M pairs, so each pair ``m`` has an influence value
``psi_m = (h_m - N - S (v_m - mean v)) / V``, with ``h_m`` the pair's term of the
numerator and ``v_m = ((f_A - mu)^2 + (f_B - mu)^2) / 2`` its term of the variance; the
standard error is ``std(psi) / sqrt(M)``. It costs nothing beyond the estimate, keeps the
correlation of the numerator and the variance (both move with the same samples), and
uses every pair as a degree of freedom; batch means would need a batch count and give a
noisier error for the same M. Its coverage is tested (``tests/compare/test_sobol.py``:
the 95 % intervals of 200 independent runs cover Ishigami's exact indices at the nominal
rate).

**Control variate.** A surrogate ``g`` (a polynomial chaos expansion) evaluated on the
same rows has exactly known indices (``opa.engine.sobol_indices`` of its coefficients),
hence exactly known numerators ``N_g = S(g) V(g)`` and variance ``V(g)``. Each numerator
and the variance are then estimated as

    N = mean(h(f) - beta h(g)) + beta N_g,     beta = cov(h(f), h(g)) / var(h(g)),

``beta`` fitted per index and per output on the same pairs. Fitting ``beta`` on the
sample costs a bias of order ``sigma_resid / M``, where the standard error is
``sigma_resid / sqrt(M)``: negligible for the M that pick-freeze needs. When the
surrogate is good the residual ``h(f) - beta h(g)`` is small and so is the error.

**Readings.** Each index's 95 % interval is ``estimate +- z SE`` (``z = 1.96`` by
default). It is *resolved* when the interval lies above 0 (``estimate - z SE > 0``);
*within noise* when it reaches 0 or below: then only the interval ``[0, max(upper, 0)]``
is reported (an index is never negative; a negative estimate is noise), never the
estimate; *undefined* where the output has no variance (a constant output) or the
standard error cannot be formed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the readings of an index, in the order of their codes
READINGS = ("resolved", "within noise", "undefined")


def pick_freeze_design(sample_a, sample_b) -> np.ndarray:
    """The pick-freeze matrices ``A_B^(i)``: ``A`` with its column ``i`` taken from ``B``.

    Parameters
    ----------
    sample_a, sample_b : array_like, shape (M, d)
        Two independent samples of the d parameters (of xi or of their values).

    Returns
    -------
    ndarray, shape (d, M, d)
        ``[i]`` is ``A_B^(i)``; evaluate the model on each to get ``f_ab`` (d, M, ...).

    Examples
    --------
    >>> import numpy as np
    >>> a, b = np.zeros((2, 3)), np.ones((2, 3))
    >>> pick_freeze_design(a, b)[1]
    array([[0., 1., 0.],
           [0., 1., 0.]])
    """
    a = np.asarray(sample_a, dtype=float)
    b = np.asarray(sample_b, dtype=float)
    if a.ndim != 2 or a.shape[0] < 2 or a.shape[1] < 1:
        raise ValueError(f"sample_a must have shape (M, d) with M >= 2, got shape {a.shape}")
    if b.shape != a.shape:
        raise ValueError(f"sample_b must have the shape of sample_a {a.shape}, got {b.shape}")
    d = a.shape[1]
    design = np.repeat(a[None], d, axis=0)
    columns = np.arange(d)
    design[columns, :, columns] = b.T
    return design


@dataclass(frozen=True)
class IndexEstimate:
    """Estimates of one kind of index (first order or total) with standard errors.

    Attributes
    ----------
    estimate : ndarray, shape (d, ...)
        The raw estimates; noise can make them negative, so read :attr:`value` and
        :attr:`interval` rather than this.
    standard_error : ndarray, shape (d, ...)
    z : float
        The interval's half-width in standard errors (1.96: 95 %).
    floor : float or ndarray (...)
        Added to both ends of the interval: the model's own numerical error of an index
        (its solver's tolerance), which no standard error sees; 0 for an exact model.
    """

    estimate: np.ndarray
    standard_error: np.ndarray
    z: float = 1.96
    floor: object = 0.0

    def __post_init__(self):
        if np.shape(self.estimate) != np.shape(self.standard_error):
            raise ValueError(f"estimate and standard_error must share a shape, got "
                             f"{np.shape(self.estimate)} and {np.shape(self.standard_error)}")
        if not (np.isfinite(self.z) and self.z > 0):
            raise ValueError(f"z must be a positive number, got {self.z}")

    @property
    def lower(self) -> np.ndarray:
        return self.estimate - self.z * self.standard_error - self.floor

    @property
    def upper(self) -> np.ndarray:
        return self.estimate + self.z * self.standard_error + self.floor

    @property
    def code(self) -> np.ndarray:
        """0 resolved, 1 within noise, 2 undefined (the index of :data:`READINGS`)."""
        undefined = ~(np.isfinite(self.estimate) & np.isfinite(self.standard_error))
        with np.errstate(invalid="ignore"):
            resolved = self.lower > 0
        return np.where(undefined, 2, np.where(resolved, 0, 1))

    @property
    def reading(self) -> np.ndarray:
        """"resolved", "within noise" or "undefined" for each index (the module's rule)."""
        return np.asarray(READINGS)[self.code]

    @property
    def value(self) -> np.ndarray:
        """The estimate where resolved (then positive), NaN elsewhere."""
        return np.where(self.code == 0, self.estimate, np.nan)

    @property
    def interval(self) -> tuple[np.ndarray, np.ndarray]:
        """The reported interval: ``[lower, upper]`` where resolved, ``[0, max(upper,
        0)]`` within noise, NaN where undefined; never below 0."""
        code = self.code
        low = np.where(code == 0, self.lower, np.where(code == 1, 0.0, np.nan))
        with np.errstate(invalid="ignore"):
            high = np.where(code == 2, np.nan, np.maximum(self.upper, 0.0))
        return low, high

    def contains(self, values) -> np.ndarray:
        """Whether each of ``values`` (shape (d, ...)) lies in the reported interval;
        False where either is NaN."""
        low, high = self.interval
        values = np.asarray(values, dtype=float)
        with np.errstate(invalid="ignore"):
            return (values >= low) & (values <= high)


@dataclass(frozen=True)
class SobolEstimate:
    """Pick-freeze Sobol indices of each of d parameters, for every output.

    Attributes
    ----------
    first, total : IndexEstimate
        ``S_i`` (Saltelli 2010) and ``S_Ti`` (Jansen 1999), shape (d, ...).
    variance, variance_se : ndarray, shape (...)
        The output's variance (A and B pooled) and its standard error.
    samples : int
        M, the rows of A (the model ran (d + 2) M times).
    control : bool
        Whether a surrogate served as control variate.
    """

    first: IndexEstimate
    total: IndexEstimate
    variance: np.ndarray
    variance_se: np.ndarray
    samples: int
    control: bool = False


def _checked_values(f_a, f_b, f_ab, role: str):
    a, b, ab = (np.asarray(x, dtype=float) for x in (f_a, f_b, f_ab))
    if a.ndim < 1 or a.shape[0] < 2:
        raise ValueError(f"{role}_a must have shape (M, ...) with M >= 2, got shape {a.shape}")
    if b.shape != a.shape:
        raise ValueError(f"{role}_b must have the shape of {role}_a {a.shape}, got {b.shape}")
    if ab.ndim != a.ndim + 1 or ab.shape[1:] != a.shape or ab.shape[0] < 1:
        raise ValueError(f"{role}_ab must have shape (d,) + {a.shape}, got {ab.shape}")
    for name, x in (("a", a), ("b", b), ("ab", ab)):
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{role}_{name} must be finite, got {np.sum(~np.isfinite(x))} "
                             f"non-finite values")
    return a, b, ab


def _terms(a, b, ab):
    """Per pair: the numerators' terms h (2, d, M, ...) and the variance's v (M, ...), and
    the pooled (unbiased) variance."""
    m = a.shape[0]
    mu = 0.5 * (a.mean(axis=0) + b.mean(axis=0))
    v = 0.5 * ((a - mu) ** 2 + (b - mu) ** 2)
    variance = v.sum(axis=0) * 2.0 / (2 * m - 1)
    first = b[None] * (ab - a[None])
    total = 0.5 * (a[None] - ab) ** 2
    return np.stack([first, total]), v, variance


def _beta(qf, qg, axis):
    """The control coefficient ``cov(qf, qg) / var(qg)`` along ``axis``; 0 where the
    surrogate's term does not vary."""
    dg = qg - qg.mean(axis=axis, keepdims=True)
    df = qf - qf.mean(axis=axis, keepdims=True)
    var = (dg ** 2).sum(axis=axis)
    cov = (df * dg).sum(axis=axis)
    return np.divide(cov, var, out=np.zeros_like(cov), where=var > 0)


def _controlled(h, v, variance, surrogate, exact):
    """The control-variate estimates of the numerators and the variance, with the
    per-pair terms whose spread gives their standard errors."""
    g_h, g_v, g_var = _terms(*surrogate)
    first, total, g_exact = (np.asarray(x, dtype=float) for x in exact)
    if first.shape != h.shape[1:2] + h.shape[3:] or total.shape != first.shape:
        raise ValueError(f"the surrogate's exact indices must have shape "
                         f"{h.shape[1:2] + h.shape[3:]}, got {first.shape} and {total.shape}")
    if g_exact.shape != variance.shape:
        raise ValueError(f"the surrogate's exact variance must have shape {variance.shape}, "
                         f"got {g_exact.shape}")
    # a surrogate with no variance has NaN indices and nothing to control
    g_numer = np.nan_to_num(np.stack([first, total]) * g_exact)
    beta_h = _beta(h, g_h, axis=2)
    beta_v = _beta(v, g_v, axis=0)
    numer = h.mean(axis=2) - beta_h * (g_h.mean(axis=2) - g_numer)
    variance = variance - beta_v * (g_var - g_exact)
    return numer, h - beta_h[:, :, None] * g_h, variance, v - beta_v * g_v


def _ratio(numer, h, variance, v):
    """Indices ``numer / variance`` and their delta-method standard errors; NaN where
    the variance is not positive."""
    m = h.shape[2]
    defined = variance > 0
    safe = np.where(defined, variance, 1.0)
    index = np.where(defined, numer / safe, np.nan)
    psi = ((h - h.mean(axis=2, keepdims=True))
           - np.nan_to_num(index)[:, :, None] * (v - v.mean(axis=0))) / safe
    se = np.sqrt((psi ** 2).sum(axis=2) / (m - 1) / m)
    return index, np.where(defined, se, np.nan)


def pick_freeze_indices(f_a, f_b, f_ab, *, surrogate=None, exact=None,
                        z: float = 1.96, floor=0.0) -> SobolEstimate:
    """First-order and total Sobol indices from paired pick-freeze runs, with standard
    errors, optionally with a surrogate as control variate.

    Parameters
    ----------
    f_a, f_b : array_like, shape (M, ...)
        The model on the rows of A and of B (trailing axes: outputs, e.g. times).
    f_ab : array_like, shape (d, M, ...)
        The model on the rows of each ``A_B^(i)`` (:func:`pick_freeze_design`).
    surrogate : tuple (g_a, g_b, g_ab), optional
        The surrogate's values on the same rows, shapes as ``f_a``, ``f_b``, ``f_ab``.
    exact : tuple (first, total, variance), optional
        The surrogate's exact indices, shapes (d, ...), (d, ...), (...): what
        ``sobol_indices(coefficients, indices)`` returns. Required with ``surrogate``.
    z : float
        Half-width of the intervals in standard errors (1.96: 95 %).
    floor : float or array_like (...)
        The model's own numerical error of an index, added to both ends of every
        interval (:class:`IndexEstimate`); with a control variate that matches the
        model to its solver's tolerance the standard errors alone shrink below it.

    Returns
    -------
    SobolEstimate

    Notes
    -----
    Estimators, standard errors (delta method), the control variate and the readings:
    see the module's docstring. Cost: (d + 2) M runs of the model.

    Examples
    --------
    ``f = xi_1 + 2 xi_2`` (xi uniform): S = ST = (0.2, 0.8), exact for every sample here
    since ``f`` is additive:

    >>> import numpy as np
    >>> rng = np.random.default_rng(1)
    >>> a, b = rng.uniform(-1, 1, (2, 4000, 2))
    >>> f = lambda x: x[..., 0] + 2 * x[..., 1]
    >>> est = pick_freeze_indices(f(a), f(b), f(pick_freeze_design(a, b)))
    >>> est.total.estimate.round(1).tolist(), est.first.reading.tolist()
    ([0.2, 0.8], ['resolved', 'resolved'])
    """
    a, b, ab = _checked_values(f_a, f_b, f_ab, "f")
    if (surrogate is None) != (exact is None):
        raise ValueError("a control variate needs both the surrogate's values (surrogate) "
                         "and its exact indices (exact)")
    h, v, variance = _terms(a, b, ab)
    numer = h.mean(axis=2)
    if surrogate is not None:
        if len(surrogate) != 3 or len(exact) != 3:
            raise ValueError("surrogate must be (g_a, g_b, g_ab) and exact "
                             "(first, total, variance)")
        g = _checked_values(*surrogate, role="g")
        if g[2].shape != ab.shape:
            raise ValueError(f"the surrogate's values must have the shapes of the model's, "
                             f"got g_ab {g[2].shape} for f_ab {ab.shape}")
        numer, h, variance, v = _controlled(h, v, variance, g, exact)
    index, se = _ratio(numer, h, variance, v)
    m = a.shape[0]
    var_se = np.sqrt(((v - v.mean(axis=0)) ** 2).sum(axis=0) / (m - 1) / m)
    return SobolEstimate(first=IndexEstimate(index[0], se[0], z, floor),
                         total=IndexEstimate(index[1], se[1], z, floor),
                         variance=variance, variance_se=var_se, samples=m,
                         control=surrogate is not None)


def surrogate_agreement(estimate: SobolEstimate, first, total) -> float:
    """The fraction of outputs at which every index of the surrogate lies in the Monte
    Carlo's reported interval.

    Parameters
    ----------
    estimate : SobolEstimate
        The pick-freeze indices (with or without control variate).
    first, total : array_like, shape (d, ...)
        The surrogate's indices (``sobol_indices(...).first`` and ``.total``).

    Returns
    -------
    float
        Over the outputs where the Monte Carlo variance is positive (NaN if none): the
        share where all 2d indices lie in their intervals (``[0, upper]`` for those
        within noise). Near the intervals' coverage (0.95 for 2d = 2; lower for more
        indices, as all must hold at once) when the surrogate's indices are the model's.

    Examples
    --------
    >>> import numpy as np
    >>> est = SobolEstimate(IndexEstimate(np.array([0.5, 0.0]), np.array([0.1, 0.1])),
    ...                     IndexEstimate(np.array([0.5, 0.5]), np.array([0.1, 0.1])),
    ...                     np.array(1.0), np.array(0.1), 100)
    >>> surrogate_agreement(est, [0.45, 0.1], [0.5, 0.55])
    1.0
    """
    first = np.asarray(first, dtype=float)
    total = np.asarray(total, dtype=float)
    shape = np.shape(estimate.first.estimate)
    if first.shape != shape or total.shape != shape:
        raise ValueError(f"first and total must have shape {shape}, got {first.shape} and "
                         f"{total.shape}")
    inside = estimate.first.contains(first).all(axis=0) & \
        estimate.total.contains(total).all(axis=0)
    compared = np.asarray(estimate.variance) > 0
    if not compared.any():
        return float("nan")
    return float(inside[compared].mean())
