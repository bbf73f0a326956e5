"""The trust map's verdicts from paired runs: every OPA variant as its own control variate.

At a grid point the map runs M true sampled systems at scrambled Sobol' points xi_m in R
replicates (``mc.simulate_mc`` with ``keep_paths``). Every OPA run there -- each variant
(impact law x truncation, or multi-element law) at each N -- defines the surrogate
x_hat(t, xi) (:func:`opa._surrogate.surrogate_values`), whose mean E[x_hat] = x_0 and
second moment are exact. Paired with the same M true systems
(:func:`compare._verify.paired_estimates`), the differences ``x - x_hat`` give

* a control-variate estimate of E[x] and Var[x] per run, of which the map keeps the one
  whose E[x] has the smallest standard error, among the plain ensemble (no control) and
  every variant at the highest N whose run finished: the **reference** (the spread and
  variance the criterion scales with, and the curves the figures draw);
* every run's errors ``x_0 - E[x]`` and ``Var[x_hat] - Var[x]`` against that reference,
  with its standard errors (x_0 and Var[x_hat] are exact). A run's own pairing is not
  used for its errors: a run whose mean is right but whose higher modes are not pairs
  worse than no control at all (the paper's mean-law OPA at omega = 3.98, sigma = 0.005,
  N = 8: Var(x - x_hat) = 4.7 Var(x), ``pair_reduction`` 0.21), while the reference is
  never worse than the plain ensemble.

No model and no xarray: arrays in, arrays out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mc import cv_estimates
from opa.engine import Measure, surrogate_values

#: independent scramblings of the Sobol' points; the spread of their estimates is the
#: standard error (randomised QMC)
REPLICATES = 16


@dataclass(frozen=True)
class Control:
    """One OPA run as a control: its coefficients x_j (K, N+1, T) on K elements cut at
    ``edges``, in the closed-form Chebyshev U basis (``closed_form``, the paper's
    single-element semicircle OPA) or the orthonormal basis of the law conditioned on each
    element."""

    coef: np.ndarray
    edges: np.ndarray
    closed_form: bool = False

    def moments(self, probability: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The exact E[x_hat] and E[x_hat^2] (T,), with the elements' probabilities."""
        P = np.asarray(probability, float) / np.sum(probability)
        return P @ self.coef[:, 0], P @ (self.coef**2).sum(axis=1)


@dataclass
class Pairs:
    """The paired estimates of one grid point over (variant, N, output)."""

    err_mean: np.ndarray  # x_0 - E[x]
    err_mean_se: np.ndarray
    err_var: np.ndarray  # Var[x_hat] - Var_cv[x]
    err_var_se: np.ndarray
    reduction: np.ndarray  # (variant, N): Var(x) / Var(x - x_hat) summed over the outputs
    reference: dict  # x_mean, x_var, x_sem, x_var_sem (T,) and control (variant, N) or None


def pair_point(x: np.ndarray, xi: np.ndarray, controls: dict, measure: Measure,
               probabilities: dict, shape: tuple[int, int],
               replicates: int = REPLICATES, weights=None) -> Pairs:
    """Paired estimates for every control at one grid point.

    ``x`` (M, T): the true systems at ``xi`` (M,), replicate r holding rows
    ``r M/R .. (r+1) M/R - 1``, weighted by ``weights`` (M,: each replicate's sum to 1;
    default equal, the plain randomised QMC; a stratified design gives P_j / n_j,
    :func:`compare._strata.replicate_points`); ``controls``: (variant, N index) -> :class:`Control`
    (missing: not run, NaN); ``probabilities``: (variant, N index) -> element
    probabilities (K,); ``shape``: (variants, Ns). A control with NaN coefficients (a run
    that stopped) gives NaN estimates from where it stopped: it disagrees there.

    The estimates are those of :func:`compare._verify.paired_estimates` (per replicate
    r: ``d_r = mean_r(x - x_hat)``, ``q_r = mean_r(x^2 - x_hat^2)``), formed without the
    (M, T) surrogate: x_hat is linear in the coefficients, so ``mean_r(x_hat)`` and
    ``mean_r(x_hat^2)`` follow from the replicate means of the basis values and of their
    products, computed once per basis (:class:`_Moments`) and shared by every N.
    """
    V, N = shape
    M, T = x.shape
    n = M // replicates
    if M % replicates or replicates < 2:
        raise ValueError(f"{M} points cannot form {replicates} replicates of equal size")
    # each replicate's weights sum to 1 (plain: 1/n each; stratified: P_j / n_j)
    w = np.full(M, 1.0 / n) if weights is None else np.asarray(weights, dtype=float)
    out = {name: np.full((V, N, T), np.nan)
           for name in ("err_mean", "err_mean_se", "err_var", "err_var_se")}
    reduction = np.full((V, N), np.nan)
    x_r, w_r = x.reshape(replicates, n, T), w.reshape(replicates, n, 1)
    x1, x2 = (w_r * x_r).sum(axis=1), (w_r * x_r**2).sum(axis=1)  # (R, T)
    plain = cv_estimates(x1, x2, np.zeros(T), np.zeros(T), np.zeros_like(x1),
                       np.zeros_like(x1))
    best, best_se, best_key = plain, _rms(plain["mean_se"]), None
    total = float((x2.mean(axis=0) - x1.mean(axis=0) ** 2).sum())  # Var(x), all points
    cache: dict = {}
    exact = {}  # (v, k) -> the run's exact E[x_hat] and Var[x_hat]
    for (v, k), control in controls.items():
        key = (control.closed_form, tuple(np.asarray(control.edges, float)))
        if key not in cache:
            cache[key] = _Moments(x, xi, control, measure, replicates,
                                  max(c.coef.shape[1] for c in controls.values()), w)
        moments = cache[key]
        mean, second = control.moments(probabilities[(v, k)])
        h1, h2, cross = moments.of(control.coef)
        with np.errstate(invalid="ignore"):
            est = cv_estimates(x1, x2, mean, second, h1, h2)
        exact[v, k] = mean, second - mean**2
        # Var(x - x_hat) over the M points, summed over the outputs
        d_all = x1.mean(axis=0) - h1.mean(axis=0)
        spread = float((x2.mean(axis=0) - 2 * cross + h2.mean(axis=0) - d_all**2).sum())
        reduction[v, k] = total / spread if spread > 0 else (np.nan if np.isnan(spread)
                                                             else np.inf)
        if k == N - 1 and np.isfinite(est["mean"]).all() and np.isfinite(est["var"]).all():
            se = _rms(est["mean_se"])
            if se < best_se:
                best, best_se, best_key = est, se, (v, k)
    # every run's errors against the one best estimate: its own pairing can be worse than
    # none (a run whose mean is right but whose higher modes are not, as the paper's
    # mean-law OPA at sigma = 0.005: Var(x - x_hat) = 4.7 Var(x)), the best never is
    for (v, k), (mean, var_hat) in exact.items():
        out["err_mean"][v, k] = mean - best["mean"]
        out["err_mean_se"][v, k] = best["mean_se"]
        out["err_var"][v, k] = var_hat - best["var"]
        out["err_var_se"][v, k] = best["var_se"]
    reference = {"x_mean": best["mean"], "x_var": np.maximum(best["var"], 0.0),
                 "x_sem": best["mean_se"], "x_var_sem": best["var_se"], "control": best_key}
    return Pairs(out["err_mean"], out["err_mean_se"], out["err_var"], out["err_var_se"],
                 reduction, reference)


class _Moments:
    """The replicate means of one basis at the points: ``b1[r, k, j] = mean_r(1_k phi_j)``,
    ``b2[r, k, j, l] = mean_r(1_k phi_j phi_l)`` (element k's indicator 1_k) and
    ``g[k, j, t] = mean(1_k phi_j x(t))`` over all M points, up to degree ``J - 1``; each
    mean weighted by ``w`` (a replicate's weights sum to 1)."""

    def __init__(self, x, xi, control: Control, measure: Measure, replicates: int, J: int,
                 w: np.ndarray):
        M = len(xi)
        edges = np.asarray(control.edges, float)
        K = len(edges) - 1
        # each point's element (the last edge closes the last element) and basis values
        which = np.clip(np.searchsorted(edges, xi, side="right") - 1, 0, K - 1)
        phi = np.zeros((M, K, J))
        for k in np.unique(which):
            here = which == k
            phi[here, k] = _basis(edges[k], edges[k + 1], measure, xi[here], J,
                                  control.closed_form)
        n = M // replicates
        phi_r = phi.reshape(replicates, n, K, J)
        w_r = w.reshape(replicates, n)
        self.b1 = np.einsum("rm,rmkj->rkj", w_r, phi_r)
        self.b2 = np.einsum("rm,rmkj,rmkl->rkjl", w_r, phi_r, phi_r)
        # as (T, M) @ (M, KJ): the fast order of the product on this machine's BLAS
        self.g = (x.T @ (w[:, None] * phi.reshape(M, K * J))).T.reshape(K, J, -1) / replicates

    def of(self, coef: np.ndarray):
        """Replicate means of x_hat and x_hat^2 (R, T) and mean(x x_hat) (T,) for the
        coefficients (K, N+1, T)."""
        J = coef.shape[1]
        h1 = np.einsum("rkj,kjt->rt", self.b1[:, :, :J], coef)
        h2 = np.einsum("rkjl,kjt,klt->rt", self.b2[:, :, :J, :J], coef, coef,
                       optimize=True)
        cross = np.einsum("kjt,kjt->t", self.g[:, :J], coef)
        return h1, h2, cross


def _basis(a: float, b: float, measure: Measure, xi: np.ndarray, J: int,
           closed_form: bool) -> np.ndarray:
    """phi_0 .. phi_{J-1} at ``xi`` (len(xi), J): the orthonormal basis of ``measure`` on
    [a, b] (or the Chebyshev U_j)."""
    unit = np.eye(J)[None, :, :]  # coefficients picking each phi_j: (1, J, J as "time")
    return surrogate_values(unit, [a, b], measure, xi, closed_form=closed_form)


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


__all__ = ["Control", "Pairs", "REPLICATES", "pair_point"]
