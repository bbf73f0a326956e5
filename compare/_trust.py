"""Verdicts: does an OPA curve agree with the Monte Carlo truth, and until when?

Plain numpy on arrays over time; no model, no xarray. The criterion, for the mean
(``e = x_0 - E_MC[x]``, spread ``s = sqrt(Var_MC[x])``, MC standard error ``se``)::

    R_e(t) <= tol * R_s(t) + z * R_se(t) + floor        for every output t <= H

where ``R_a(t) = sqrt(mean of a^2 over the outputs in [0, t])`` is a running root mean
square. In words: the OPA mean stays within ``tol`` of the ensemble's own spread, after
allowing ``z`` MC standard errors for the reference's noise. The running RMS makes the
verdict robust to the instants where the spread or the error crosses zero, and monotone
in the horizon: the *first time of disagreement* is the first t where the inequality
fails, and OPA agrees over H exactly when that time is past H. The variance uses the
same form with ``e = Var_OPA - Var_MC``, scale ``Var_MC`` and the variance's SE.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def running_rms(a: np.ndarray) -> np.ndarray:
    """sqrt(cumulative mean of a^2) along the last axis."""
    a = np.asarray(a, dtype=float)
    k = np.arange(1, a.shape[-1] + 1)
    return np.sqrt(np.cumsum(a * a, axis=-1) / k)


def excess(err: np.ndarray, scale: np.ndarray, sem: np.ndarray, *, tol: float,
           z: float = 0.0, floor: float = 0.0) -> np.ndarray:
    """``R_e - tol R_scale - z R_se - floor`` at every output (> 0: disagreement)."""
    sem = np.where(np.isfinite(sem), sem, 0.0)
    return running_rms(err) - tol * running_rms(scale) - z * running_rms(sem) - floor


def first_disagreement(t: np.ndarray, err: np.ndarray, scale: np.ndarray, sem: np.ndarray,
                       *, tol: float, z: float, floor: float) -> float:
    """The first output time at which the criterion fails (inf if it never does)."""
    # not <= 0 rather than > 0: a diverged OPA run (NaN) disagrees from where it stopped
    bad = np.flatnonzero(~(excess(err, scale, sem, tol=tol, z=z, floor=floor) <= 0))
    return float(t[bad[0]]) if len(bad) else float("inf")


def marginal(err, scale, sem, *, tol: float, z: float, floor: float, upto: int,
             upper: float | None = None) -> bool:
    """Whether the verdict over the first ``upto`` outputs hangs on the MC noise: it
    differs between no allowance for the noise and an allowance of ``upper`` standard
    errors (default ``2 z``). So a verdict is decided when OPA agrees even without the
    allowance, or disagrees even with ``upper`` standard errors allowed.

    >>> scale, sem = np.ones(4), np.full(4, 0.01)
    >>> marginal(np.full(4, 0.155), scale, sem, tol=0.1, z=3.0, floor=0.0, upto=4)
    True
    >>> marginal(np.full(4, 0.155), scale, sem, tol=0.1, z=3.0, floor=0.0, upto=4, upper=5.0)
    False
    """
    upper = 2 * z if upper is None else upper
    strict = excess(err[:upto], scale[:upto], sem[:upto], tol=tol, z=0.0, floor=floor)
    loose = excess(err[:upto], scale[:upto], sem[:upto], tol=tol, z=upper, floor=floor)
    return bool((strict <= 0).all()) != bool((loose <= 0).all())  # NaN: never marginal


def bound_excess(err, width, scale_low, scale_high, *, tol: float,
                 floor: float) -> tuple[np.ndarray, np.ndarray]:
    """The upper and lower bounds of the criterion's excess at every output (> 0: over
    the tolerance), for many curves at once (..., T): ``R(|err| + width) - tol
    R(scale_low) - floor`` and ``R(max(|err| - width, 0)) - tol R(scale_high) - floor``
    (:func:`bounded_verdict`; NaN where an estimate is not finite)."""
    err, width = np.asarray(err, dtype=float), np.asarray(width, dtype=float)
    with np.errstate(invalid="ignore"):
        upper = running_rms(np.abs(err) + width) - tol * running_rms(
            np.maximum(np.asarray(scale_low, dtype=float), 0.0)) - floor
        lower = running_rms(np.maximum(np.abs(err) - width, 0.0)) - tol * running_rms(
            np.asarray(scale_high, dtype=float)) - floor
    return upper, lower


def bounded_verdict(err, width, scale_low, scale_high, *, tol: float,
                    floor: float) -> tuple[str, int, int]:
    """A verdict that holds whenever the true error and scale lie in their bands.

    ``err`` (T,): the estimated error, whose true value lies within ``width`` of it at
    every output; the true scale the tolerance multiplies (the spread, or the variance)
    lies in ``[scale_low, scale_high]``. Inside the band ``|e_t| <= |err_t| + width_t``
    and ``|e_t| >= max(|err_t| - width_t, 0)``, so, with ``R`` the running RMS:

    * ``agrees`` when ``R(|err| + width) <= tol R(scale_low) + floor`` at every output:
      an upper bound of the criterion's error is below the tolerance;
    * ``disagrees`` when ``R(max(|err| - width, 0)) > tol R(scale_high) + floor`` at some
      output: a lower bound is above it;
    * ``undecided`` otherwise (or where an estimate is not finite).

    Returns the verdict, the first output index where the lower bound exceeds the
    tolerance (-1: none) and the first where the upper bound does (-1: none).

    >>> ones = np.ones(4)
    >>> bounded_verdict(0.05 * ones, 0.004 * ones, ones, ones, tol=0.1, floor=0.0)
    ('agrees', -1, -1)
    >>> bounded_verdict(0.2 * ones, 0.04 * ones, ones, ones, tol=0.1, floor=0.0)
    ('disagrees', 0, 0)
    >>> bounded_verdict(0.09 * ones, 0.04 * ones, ones, ones, tol=0.1, floor=0.0)
    ('undecided', -1, 0)
    """
    upper, lower = bound_excess(err, width, scale_low, scale_high, tol=tol, floor=floor)
    finite = np.isfinite(upper) & np.isfinite(lower)
    above = np.flatnonzero(finite & (lower > 0))
    over = np.flatnonzero(~(upper <= 0))
    first_above = int(above[0]) if len(above) else -1
    first_over = int(over[0]) if len(over) else -1
    if first_above >= 0 and finite[:first_above + 1].all():
        return "disagrees", first_above, first_over
    if first_over < 0:
        return "agrees", -1, -1
    return "undecided", first_above, first_over


def band_multiplier(alpha: float, outputs: int, dof, *, quantities: int = 2):
    """The multiplier c of a band of Student's t intervals that holds at all ``outputs``
    times ``quantities`` estimates at once with probability >= 1 - ``alpha`` (Bonferroni:
    each two-sided interval misses with probability ``alpha / (outputs quantities)``),
    per output from its degrees of freedom ``dof`` (inf: normal).

    >>> round(float(band_multiplier(0.05, 1, np.inf, quantities=1)), 3)
    1.96
    """
    from scipy import stats

    each = alpha / (outputs * quantities)
    return stats.t.ppf(1.0 - each / 2.0, np.asarray(dof, dtype=float))


def window_errors(err: np.ndarray, scale: np.ndarray, sem: np.ndarray,
                  upto: int) -> tuple[float, float, float]:
    """RMS error over the first ``upto`` outputs: absolute, in MC standard errors, and
    relative to the RMS of ``scale`` (the response's spread, or the variance)."""
    rms = float(np.sqrt(np.mean(err[:upto] ** 2)))
    se = sem[:upto]
    se_rms = float(np.sqrt(np.mean(se**2))) if np.isfinite(se).all() else float("nan")
    sc = float(np.sqrt(np.mean(scale[:upto] ** 2)))
    in_se = rms / se_rms if se_rms > 0 else float("inf")
    rel = rms / sc if sc > 0 else (0.0 if rms == 0 else float("inf"))
    return rms, in_se, rel


def window_errors_all(err: np.ndarray, scale: np.ndarray, sem: np.ndarray,
                      upto: int) -> np.ndarray:
    """:func:`window_errors` for many curves at once: ``err``, ``sem`` (..., T), ``scale``
    (T,); returns (..., 3)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.mean(err[..., :upto] ** 2, axis=-1))
        se = sem[..., :upto]
        se_rms = np.where(np.isfinite(se).all(-1), np.sqrt(np.mean(se**2, axis=-1)), np.nan)
        sc = float(np.sqrt(np.mean(scale[:upto] ** 2)))
        in_se = np.where(se_rms > 0, rms / np.where(se_rms > 0, se_rms, 1.0), np.inf)
        rel = rms / sc if sc > 0 else np.where(rms == 0, 0.0, np.inf)
    return np.stack(np.broadcast_arrays(rms, in_se, rel), axis=-1)


def bisect_boundary(agrees: Callable[[float], bool], lo: float, hi: float,
                    resolution: float, *, max_steps: int = 60) -> tuple[float, float, int]:
    """Locate the change from "agrees" (at ``lo``) to "does not" (at ``hi``) by bisection.

    ``agrees(lo)`` is taken as True and ``agrees(hi)`` as False (the caller knows them).
    Returns the final bracket ``(lo, hi)``, ``hi - lo <= resolution``, and the number of
    evaluations. When the verdict is not monotone inside the bracket, this finds *a*
    boundary inside it, not necessarily the smallest.
    """
    if not lo < hi:
        raise ValueError(f"need lo < hi, got [{lo}, {hi}]")
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0, got {resolution}")
    steps = 0
    while hi - lo > resolution and steps < max_steps:
        mid = 0.5 * (lo + hi)
        if agrees(mid):
            lo = mid
        else:
            hi = mid
        steps += 1
    return lo, hi, steps


__all__ = ["band_multiplier", "bisect_boundary", "bound_excess", "bounded_verdict", "excess",
           "first_disagreement", "marginal", "running_rms", "window_errors",
           "window_errors_all"]
