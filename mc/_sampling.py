"""Samplers for the uncertain variable ``xi`` with the semicircle density.

The uncertain parameter of the model is ``mu = mu_bar + sigma * xi`` (paper eq. 1) where
``xi`` lives on ``[-1, 1]`` with the Wigner semicircle density

.. math::

    p(\\xi) = \\frac{2}{\\pi} \\sqrt{1 - \\xi^2}, \\qquad
    F(\\xi) = \\frac{1}{2} + \\frac{\\xi \\sqrt{1 - \\xi^2} + \\arcsin \\xi}{\\pi},

i.e. ``Beta(3/2, 3/2)`` mapped from ``[0, 1]`` to ``[-1, 1]`` (chaospy ``Wigner(1)``).
Three samplers give points ``xi_k`` and weights ``w_k`` (summing to one) such that
``E[g(xi)] ~ sum_k w_k g(xi_k)``:

``random``
    independent draws, weights ``1/M``; error ``O(M^-1/2)``.
``sobol``
    scrambled Sobol' points pushed through the inverse CDF, weights ``1/M``; error close
    to ``O(M^-1)`` for smooth integrands.
``gauss``
    the ``Q``-point Gauss rule of ``p`` (Chebyshev of the second kind), exact for
    polynomials of degree ``<= 2Q - 1``; deterministic, the seed is ignored.
"""

from __future__ import annotations

import numbers

import numpy as np

from opa.engine import gauss_nodes
from scipy import special
from scipy.stats import qmc

__all__ = ["SAMPLERS", "gauss_nodes", "sample_xi", "semicircle_cdf", "semicircle_ppf"]

SAMPLERS = ("random", "sobol", "gauss")

# Beta(3/2, 3/2) on [0, 1]: the semicircle law after y = (1 + xi) / 2.
_BETA_SHAPE = 1.5
_BETA_NORM = 8.0 / np.pi  # 1 / B(3/2, 3/2)


def semicircle_cdf(x: np.ndarray | float) -> np.ndarray | float:
    """Cumulative distribution function of the semicircle law on ``[-1, 1]``.

    Parameters
    ----------
    x : float or array_like, any shape
        Points; values outside ``[-1, 1]`` give 0 or 1.

    Returns
    -------
    float or ndarray, same shape as `x`
        ``F(x) = 1/2 + (x sqrt(1 - x^2) + arcsin x) / pi``.

    Examples
    --------
    >>> float(semicircle_cdf(0.0))
    0.5
    >>> float(semicircle_cdf(1.0))
    1.0
    """
    x = np.clip(np.asarray(x, dtype=float), -1.0, 1.0)
    return 0.5 + (x * np.sqrt(1.0 - x * x) + np.arcsin(x)) / np.pi


def semicircle_ppf(u: np.ndarray | float) -> np.ndarray | float:
    """Inverse CDF (quantile function) of the semicircle law.

    Starts from ``scipy.special.betaincinv`` on ``Beta(3/2, 3/2)`` and polishes with one
    Newton step on the regularised incomplete beta function. The lower half ``u <= 1/2``
    is computed directly and the upper half by the symmetry ``ppf(u) = -ppf(1 - u)``
    (``1 - u`` is exact there), so both tails keep full relative accuracy in the
    distance to the nearest end point and the result is odd about ``u = 1/2``.

    Parameters
    ----------
    u : float or array_like, any shape
        Probabilities in ``[0, 1]``.

    Returns
    -------
    float or ndarray, same shape as `u`
        ``xi`` in ``[-1, 1]`` with ``semicircle_cdf(xi) = u``; ``ppf(0) = -1``,
        ``ppf(1) = 1``. Monotone non-decreasing, absolute error about ``1e-15``.

    Raises
    ------
    ValueError
        If any `u` lies outside ``[0, 1]`` or is not finite.

    Examples
    --------
    >>> float(semicircle_ppf(0.5))
    0.0
    >>> float(semicircle_ppf(semicircle_cdf(0.3)))  # doctest: +ELLIPSIS
    0.3...
    """
    u = np.asarray(u, dtype=float)
    if not np.all((u >= 0.0) & (u <= 1.0)):
        bad = u[~((u >= 0.0) & (u <= 1.0))].flat[0]
        raise ValueError(f"u must be in [0, 1], got {bad!r}")
    upper = u > 0.5
    tail = np.where(upper, 1.0 - u, u)  # in [0, 1/2]
    y = special.betaincinv(_BETA_SHAPE, _BETA_SHAPE, tail)
    density = _BETA_NORM * np.sqrt(y * (1.0 - y))
    inside = density > 0.0
    residual = special.betainc(_BETA_SHAPE, _BETA_SHAPE, y) - tail
    y = np.where(inside, y - residual / np.where(inside, density, 1.0), y)
    y = np.clip(y, 0.0, 0.5)
    xi = 2.0 * y - 1.0
    xi = np.where(upper, -xi, xi)
    return xi[()] if xi.ndim == 0 else xi


def check_sampler(sampler: str, samples: int, seed: int | None) -> None:
    if sampler not in SAMPLERS:
        allowed = ", ".join(repr(s) for s in SAMPLERS)
        raise ValueError(f"sampler must be one of {allowed}, got {sampler!r}")
    from opa.engine import check_count

    if isinstance(samples, float) or not isinstance(samples, (numbers.Integral, np.ndarray,
                                                              np.generic)):
        raise ValueError(f"samples must be a positive integer, got {samples!r}")
    try:
        check_count("samples", samples, 1)
    except ValueError as err:
        raise ValueError(f"samples must be a positive integer, got {samples!r}"
                         + (" (at most 2^53)" if "most" in str(err) else "")) from None
    if seed is not None:
        if isinstance(seed, float):
            raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
        try:
            check_count("seed", seed, 0)
        except ValueError as err:
            raise ValueError(str(err) if "at most" in str(err) else
                             f"seed must be a non-negative integer or None, got "
                             f"{seed!r}") from None


def sample_xi(
    sampler: str, samples: int, seed: int | None = None, replicates: int = 1,
    distribution=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Points and weights for expectations over the semicircle law (or ``distribution``).

    Parameters
    ----------
    sampler : {"random", "sobol", "gauss"}
        ``random``: ``numpy.random.default_rng(seed).beta(1.5, 1.5)`` mapped to
        ``[-1, 1]``. ``sobol``: ``scipy.stats.qmc.Sobol(d=1, scramble=True, seed=seed)``
        through :func:`semicircle_ppf`. ``gauss``: the rule of :func:`gauss_nodes`.
    samples : int
        Number of points ``M >= 1`` (the number of nodes ``Q`` for ``gauss``). Sobol'
        points keep their balance properties only when ``M`` is a power of two; other
        ``M`` give the first ``M`` points of the next power-of-two set (the same points
        as ``Sobol.random(M)``, without its warning).
    seed : int or None
        Non-negative seed; the same seed gives identical output. Ignored by ``gauss``.
    replicates : int
        ``sobol`` only: R independent scramblings of ``M / R`` points each, concatenated
        (replicate r holds points ``r M/R .. (r+1) M/R - 1``). The spread of the R
        replicate means is the honest error estimate of randomised QMC; the naive
        ``sqrt(Var/M)`` overstates a Sobol' estimate's error by orders of magnitude.
        ``M`` must be a multiple of ``R``.
    distribution : None, name, chaospy distribution or opa._measure.Measure
        Another law of xi (:func:`opa._measure.parse`): the same uniforms go through its
        quantile function, and ``gauss`` uses its Gauss rule. None: the semicircle, by
        the closed forms above.

    Returns
    -------
    xi : ndarray, shape (M,)
        Points in ``[-1, 1]`` (ascending for ``gauss``).
    weights : ndarray, shape (M,)
        Quadrature weights summing to one (``1/M`` for ``random`` and ``sobol``).

    Raises
    ------
    ValueError
        Unknown `sampler`, `samples` not a positive integer, or `seed` negative.

    Examples
    --------
    >>> xi, w = sample_xi("gauss", 4)
    >>> round(float(w @ xi**4), 15)  # E[xi^4] = 1/8
    0.125
    >>> xi, w = sample_xi("sobol", 1024, seed=1)
    >>> abs(float(w @ xi**2) - 0.25) < 1e-4
    True
    """
    check_sampler(sampler, samples, seed)
    samples = int(samples)
    measure = None
    if distribution is not None:
        from opa.engine import parse

        measure = parse(distribution)
        if measure.name == "semicircle" and measure.is_whole:
            measure = None  # the closed forms below
    if sampler == "gauss":
        return gauss_nodes(samples) if measure is None else measure.gauss(samples)
    ppf = semicircle_ppf if measure is None else measure.ppf
    weights = np.full(samples, 1.0 / samples)
    if sampler == "random":
        rng = np.random.default_rng(seed)
        if measure is not None:
            return ppf(rng.random(samples)), weights
        xi = 2.0 * rng.beta(_BETA_SHAPE, _BETA_SHAPE, size=samples) - 1.0
        return xi, weights
    if isinstance(replicates, bool) or int(replicates) != replicates or replicates < 1:
        raise ValueError(f"replicates must be a positive integer, got {replicates!r}")
    replicates = int(replicates)
    if replicates == 1:
        return ppf(_sobol_uniform(samples, seed)), weights
    if samples % replicates:
        raise ValueError(
            f"samples must be a multiple of replicates = {replicates}, got {samples}"
        )
    children = np.random.SeedSequence(seed).spawn(replicates)
    per = samples // replicates
    u = np.concatenate([_sobol_uniform(per, np.random.default_rng(c)) for c in children])
    return ppf(u), weights


def _sobol_uniform(samples: int, seed) -> np.ndarray:
    engine = qmc.Sobol(d=1, scramble=True, seed=seed)
    power = int(np.ceil(np.log2(samples)))
    return engine.random_base2(power)[:samples, 0]
