"""Paired Monte Carlo certificates of OPA runs, and control-variate estimates.

An OPA run of any K and any law of xi defines the surrogate x_hat(t, xi)
(:mod:`opa._surrogate`) whose moments E[x_hat], E[x_hat^2] are exact. At M points xi_m
drawn from the run's own law the true sampled systems give x(t, xi_m), and the paired
differences ``d_m = x(t, xi_m) - x_hat(t, xi_m)`` estimate, without bias,

    E[x] - E[x_hat] = E[d],      E[x^2] - E[x_hat^2] = E[x^2 - x_hat^2],

with a variance Var(d) that shrinks as OPA gets better: the surrogate is a control
variate (Glasserman 2004, ch. 4; multi-fidelity Monte Carlo: Peherstorfer, Willcox &
Gunzburger 2016). So the same runs give

* the **error of the run**: ``err_mean = E[x_hat] - (E[x_hat] + mean d) = -mean d`` and
  ``err_var = Var[x_hat] - Var_cv[x]``, with standard errors, and a verdict under the trust
  map's criterion (:mod:`compare._trust`: running RMS error <= tol x running RMS spread +
  z x running RMS SE + floor);
* **control-variate estimates** ``E_cv[x] = E[x_hat] + mean d`` and ``Var_cv[x] =
  E[x_hat^2] + mean(x^2 - x_hat^2) - E_cv[x]^2`` with standard errors, and the variance
  reduction factor Var(x) / Var(d).

Where are the points? For a run of one element (or too few points for the strata below):
scrambled Sobol' in R independent replicates (``mc.sample_xi``); every estimate is formed
per replicate and its standard error is the spread of the R replicate estimates over
sqrt(R), the honest error of randomised QMC. For a multi-element run of K elements with
M >= 5K + 1: stratified by element (the elements are the strata, of known probability).
First the true systems at the K + 1 edges: element k's indicator is the misfit of its own
polynomial at its two ends (:func:`edge_indicator`), which follows the spread of d inside
the element (correlation 0.978 of the logarithms in the case below), so no random pilot
is spent or discarded. The other M - K - 1 points come in jittered groups of
``GROUP`` = 4: element k gets n_k groups (one each, then half the rest in proportion to
P_k times its indicator, half to P_k), cuts its law into n_k slices of equal probability
and draws 4 independent points in each. The estimate sums the slices, its standard error
comes from the within-slice variances, with Welch-Satterthwaite degrees of freedom for
Student's t intervals (``cv_x_mean_dof``). The paired differences are large only in the
few elements whose polynomial cannot follow a split, and the strata spend the points
there (section 3.2, omega = 3.98, sigma = 0.05, 10 periods, 8 outputs per period, 64
elements, 512 true runs, 100 seeds: RMS error of E_cv[x] 8.7e-6, 95 % t-intervals
covering 93.4 %; benchmarks/bench_verify.py). A later round adds an independent batch;
the batches are summed with fixed weights (their groups), so the sum stays unbiased.
Sequential: start at
``samples`` points and double while a verdict hangs on the noise (it differs between no
allowance and twice the allowance for the standard errors), up to ``max_samples``.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import xarray as xr

from compare._trust import first_disagreement, marginal
from mc import cv_estimates, sample_xi
from opa.engine import (
    PARAMETER_NAMES, check_memory, check_opa_layout, Oscillator, run_measure, SolverOptions,
    surrogate, surrogate_moments, surrogate_values, System, true_runs,
)

#: points in each jittered group of a stratified certificate: 4 give each slice 3 degrees
#: of freedom, and the t-intervals of the strata cover 93-97 % on the closed-form kink of
#: tests/compare/test_verify.py (pairs fall outside, 0.98 with t, 0.92 with normal
#: intervals); section 3.2 at 512 true runs over 100 seeds: RMS error 8.7e-6, 93.4 %
#: coverage (benchmarks/bench_verify.py)
GROUP = 4

#: the trust map's criterion (README, "The main job")
MEAN_TOLERANCE = 0.1
VAR_TOLERANCE = 0.25
Z = 3.0


def system_of(run: xr.Dataset) -> tuple[System, SolverOptions]:
    """The System and solver options an OPA run was computed with, from its attributes."""
    attrs = run.attrs
    oscillator = Oscillator(**{name: float(attrs[name]) for name in PARAMETER_NAMES})
    distribution = attrs.get("distribution", "semicircle")
    system = System(oscillator, sigma=float(attrs["sigma"]), order=0,
                    uncertain=str(attrs["uncertain"]),
                    distribution=None if distribution == "semicircle" else distribution,
                    allow_negative=bool(attrs.get("allow_negative", 0)),
                    impulse=str(attrs["impulse"]), pulse_width=float(attrs["pulse_width"]),
                    impulse_at_zero=bool(attrs["impulse_at_zero"]))
    options = SolverOptions(rtol=float(attrs["rtol"]), atol=float(attrs["atol"]),
                            method=str(attrs.get("method", "dop853")),
                            chatter_velocity=float(attrs.get("chatter_velocity", 1e-6)))
    return system, options


def _check_count(name: str, value, least: int) -> int:
    if not (isinstance(value, numbers.Integral) and not isinstance(value, bool)
            and value >= least and value & (value - 1) == 0):
        raise ValueError(f"{name} must be a power of two >= {least} (scrambled Sobol' "
                         f"points in up to 16 replicates), got {value!r}")
    return int(value)


def check_counts(samples, max_samples, *, flags: bool = False) -> tuple[int, int]:
    """``samples`` and ``max_samples`` checked (``flags``: named as the CLI's flags)."""
    first, most = ("--verify", "--verify-max") if flags else ("samples", "max_samples")
    samples = _check_count(first, samples, 8)
    return samples, _check_count(most, max_samples, samples)


def paired_estimates(x: np.ndarray, x_hat: np.ndarray, replicates: int,
                     surrogate_mean: np.ndarray, surrogate_second: np.ndarray) -> dict:
    """Control-variate estimates from paired values, formed per replicate.

    ``x``, ``x_hat``: (M, T) true and surrogate values at M points, replicate r holding
    rows ``r M/R .. (r+1) M/R - 1``; ``surrogate_mean``, ``surrogate_second``: the exact
    E[x_hat], E[x_hat^2] (T,). Returns the estimates and their standard errors (the
    spread of the R replicate estimates over sqrt(R)): ``d`` = E[x - x_hat],
    ``mean`` = E_cv[x], ``var`` = Var_cv[x]; and ``variance_reduction`` =
    sum_t Var(x) / sum_t Var(x - x_hat) over the points.

    Examples
    --------
    A perfect surrogate leaves no error and no noise:

    >>> x = np.linspace(-1, 1, 16)[:, None] ** 2
    >>> est = paired_estimates(x, x, 4, np.array([x.mean()]), np.array([(x**2).mean()]))
    >>> float(est["d"][0]), float(est["d_se"][0])
    (0.0, 0.0)
    """
    M, T = x.shape
    if M % replicates or replicates < 2:
        raise ValueError(f"{M} points cannot form {replicates} replicates of equal size")
    d = (x - x_hat).reshape(replicates, -1, T).mean(axis=1)
    q = (x**2 - x_hat**2).reshape(replicates, -1, T).mean(axis=1)
    zero = np.zeros_like(d)  # d and q are already the paired replicate means
    out = cv_estimates(d, q, surrogate_mean, surrogate_second, zero, zero)
    var_d = float(np.var(x - x_hat, axis=0).sum())
    out["variance_reduction"] = float(np.var(x, axis=0).sum()) / var_d if var_d > 0 \
        else math.inf
    return out


def stratified_estimates(x: list, x_hat: list, probability, surrogate_mean: np.ndarray,
                         surrogate_second: np.ndarray) -> dict:
    """Control-variate estimates from paired values drawn independently within strata.

    ``x[k]``, ``x_hat[k]``: (n_k, T) true and surrogate values at n_k >= 2 points drawn
    from the law of xi restricted to element k of probability ``probability[k]``.
    ``E[x - x_hat] = sum_k P_k mean_k(x - x_hat)`` with the variance
    ``sum_k P_k^2 s_k^2 / n_k`` (s_k: the element's sample standard deviation), and
    likewise for ``E[x^2 - x_hat^2]``; the variance estimate's standard error by the
    delta method (``q - 2 E_cv[x] d`` per element). Returns the keys of
    :func:`paired_estimates` (``variance_reduction``: the strata-weighted Var(x) over
    Var(x - x_hat)) and ``mean_dof``, ``var_dof``: the Welch-Satterthwaite degrees of
    freedom of each standard error, ``(sum v_k)^2 / sum v_k^2 / (n_k - 1)`` with
    ``v_k = P_k^2 s_k^2 / n_k``, for Student's t intervals (:func:`interval_halfwidth`).

    Examples
    --------
    >>> x = [np.array([[1.0], [3.0]]), np.array([[5.0], [7.0]])]
    >>> est = stratified_estimates(x, [0 * a for a in x], [0.5, 0.5], np.zeros(1),
    ...                            np.zeros(1))
    >>> float(est["mean"][0]), round(float(est["mean_se"][0]) ** 2, 12)  # 2 x 0.25 x 2 / 2
    (4.0, 0.5)
    """
    P = np.asarray(probability, dtype=float)
    if any(len(a) < 2 for a in x):
        raise ValueError("every stratum needs at least 2 points for its variance")
    d = [a - b for a, b in zip(x, x_hat)]
    q = [a**2 - b**2 for a, b in zip(x, x_hat)]
    D = sum(p * dk.mean(axis=0) for p, dk in zip(P, d))
    Q = sum(p * qk.mean(axis=0) for p, qk in zip(P, q))
    mean = surrogate_mean + D
    var = surrogate_second + Q - mean**2

    def se(parts):
        """The standard error and its Welch-Satterthwaite degrees of freedom."""
        v = [p**2 * np.var(y, axis=0, ddof=1) / len(y) for p, y in zip(P, parts)]
        total = sum(v)
        spread = sum(vk**2 / (len(y) - 1) for vk, y in zip(v, parts))
        with np.errstate(invalid="ignore", divide="ignore"):
            dof = np.where(spread > 0, total**2 / np.where(spread > 0, spread, 1.0),
                           sum(len(y) - 1 for y in parts))
        return np.sqrt(total), dof

    d_se, d_dof = se(d)
    var_se, var_dof = se([qk - 2 * mean * dk for qk, dk in zip(q, d)])

    def weighted_var(parts):
        m = sum(p * y.mean(axis=0) for p, y in zip(P, parts))
        return float(sum(p * ((y - m) ** 2).mean(axis=0) for p, y in zip(P, parts)).sum())

    var_d = weighted_var(d)
    return {"d": D, "d_se": d_se, "mean": mean, "mean_se": d_se, "var": var,
            "var_se": var_se, "mean_dof": d_dof, "var_dof": var_dof,
            "variance_reduction": weighted_var(x) / var_d if var_d > 0 else math.inf}


def neyman_allocation(total: int, probability, spread) -> np.ndarray:
    """Points per stratum for ``total`` more points: proportional to P_k s_k (Neyman),
    rounded so that they sum to ``total``; where every s_k is 0, proportional to P_k."""
    weight = np.asarray(probability, float) * np.asarray(spread, float)
    if not weight.sum() > 0:
        weight = np.asarray(probability, float)
    share = total * weight / weight.sum()
    n = np.floor(share).astype(int)
    n[np.argsort(n - share)[: total - int(n.sum())]] += 1  # largest remainders
    return n


def edge_indicator(x_coef: np.ndarray, edges, measure, x_edges: np.ndarray) -> np.ndarray:
    """How far each element's polynomial is from the truth at its ends.

    ``x_coef`` (K, N+1, T): the run's element coefficients; ``edges`` (K + 1); ``x_edges``
    (K + 1, T): the true systems at the edges. Element k's indicator is the larger over
    its two ends of the RMS over time of ``x(t, e) - x_hat_k(t, e)``, with x_hat_k the
    element's own polynomial (at an inner edge the two neighbours' polynomials differ).
    It follows the spread of x - x_hat inside the element closely (section 3.2,
    omega = 3.98, sigma = 0.05, 10 periods, 64 adaptive elements: correlation 0.978 of
    the logarithms against 2^15 points; benchmarks/bench_verify.py), so it sets the
    allocation without a pilot.

    >>> coef = np.array([[[0.0], [1.0]], [[0.0], [0.0]]])  # x_hat = phi_1 on [-1, 0], 0 on [0, 1]
    >>> from opa._measure import uniform
    >>> edge_indicator(coef, [-1.0, 0.0, 1.0], uniform(), np.zeros((3, 1))).round(3)
    array([1.732, 0.   ])
    """
    edges = np.asarray(edges, dtype=float)
    out = np.empty(len(edges) - 1)
    for k in range(len(out)):
        ends = surrogate_values(x_coef[k:k + 1], edges[k:k + 2], measure, edges[k:k + 2])
        out[k] = np.sqrt(np.mean((x_edges[k:k + 2] - ends) ** 2, axis=1)).max()
    return out


def group_allocation(groups: int, probability, indicator) -> np.ndarray:
    """Jittered groups per element for ``groups`` in all: one each, then half the rest in
    proportion to P_k times the indicator (Neyman with the indicator for the spread) and
    half in proportion to P_k (defensive, for what the ends do not show).

    >>> group_allocation(10, [0.5, 0.25, 0.25], [0.0, 1.0, 3.0]).tolist()
    [3, 3, 4]
    """
    K = len(probability)
    if groups < K:
        raise ValueError(f"{groups} groups cannot give each of {K} elements one")
    rest = groups - K
    return 1 + neyman_allocation(rest // 2, probability, indicator) \
        + neyman_allocation(rest - rest // 2, probability, np.ones(K))


def interval_halfwidth(se, dof, level: float = 0.95):
    """Half-width of a two-sided ``level`` confidence interval: Student's t with ``dof``
    degrees of freedom (scalar or per time) times the standard error; R replicates give
    R - 1 (16: 2.13 SE), strata their ``*_dof`` (the dataset's ``cv_x_mean_dof``)."""
    from scipy import stats

    return stats.t.ppf(0.5 + level / 2, np.asarray(dof, dtype=float)) * np.asarray(se)


def verify(run: xr.Dataset, *, samples: int = 256, max_samples: int = 4096, seed: int = 0,
           tolerance: float = MEAN_TOLERANCE, var_tolerance: float = VAR_TOLERANCE,
           z: float = Z, sequential: bool = True, log=None) -> xr.Dataset:
    """The run with its paired Monte Carlo certificate and control-variate estimates.

    Parameters
    ----------
    run : an OPA dataset (any number of elements, any law of xi, any uncertain parameter).
    samples : true systems of the first round (a power of two >= 8).
    max_samples : the most a sequential certificate doubles to (a power of two).
    seed : seed of the points (scrambled Sobol', or the random points of the strata).
    tolerance, var_tolerance, z : the verdict's criterion for the mean and the variance
        (the trust map's defaults 0.1, 0.25 and 3).
    sequential : double the samples while a verdict hangs on the noise; False: one round.
    log : callable taking a line of progress, or None.

    Returns
    -------
    A copy of ``run`` with ``verify_err_mean``, ``verify_err_var`` (OPA minus truth) and
    their standard errors, the control-variate estimates ``cv_x_mean``, ``cv_x_var`` and
    their standard errors and degrees of freedom (``cv_x_mean_dof``, ``cv_x_var_dof``)
    over time, and the attributes ``verdict`` (``agrees`` | ``disagrees``),
    ``verdict_mean``, ``verdict_var``, ``first_disagreement_mean`` and ``_var`` (forcing
    periods; inf: none), ``verify_samples`` (the true runs of the estimate: the last
    round's replicates, or with strata the edges and every round's batch),
    ``verify_replicates`` (0 when stratified), ``verify_sampling``
    (in words), ``verify_rounds``, ``variance_reduction`` and ``verify_rhs_evaluations``.
    """
    check_opa_layout(run, "run")
    samples, max_samples = check_counts(samples, max_samples)
    for name, value in (("tolerance", tolerance), ("var_tolerance", var_tolerance), ("z", z)):
        if isinstance(value, bool) or not isinstance(value, numbers.Real) \
                or not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    if "failure" in run.attrs:
        raise ValueError(f"the run did not complete ({run.attrs['failure']}): nothing to "
                         f"verify")
    system, options = system_of(run)
    measure = run_measure(run)
    times = run.time.values
    # at t = 0 every sample is at x0 (x' may have jumped by an impulse at t = 0, by the
    # same amount for every sample): x_0 = x0 and no higher coefficient
    start = np.zeros(run.sizes["order"])
    start[0] = system.oscillator.x0
    first_x = run.element_x_coef.values[:, :, 0]
    first_v = run.element_v_coef.values[:, 1:, 0]
    if times[0] == 0.0 and not (np.allclose(first_x, start, rtol=0.0, atol=1e-12)
                                and np.allclose(first_v, 0.0, rtol=0.0, atol=1e-12)):
        raise ValueError("the run does not start from the x0, v0 of its attributes (an "
                         "OPA run continued with initial=...): the true systems it "
                         "describes are not known, so it cannot be verified")
    check_memory("verification paths", max_samples * len(times) * 8 * 5,
                 f"max_samples {max_samples} x {len(times)} outputs x 5 arrays")
    moments = surrogate_moments(run)
    floor = 10 * (options.rtol + options.atol)
    T = 2 * math.pi / system.oscillator.omega
    M, rounds, rhs = samples, 0, 0
    P = run.element_probability.values / run.element_probability.values.sum()
    edges = run.element_edges.values
    stratify = len(P) >= 2 and samples >= len(P) + 1 + GROUP * len(P)
    if stratify:
        rng = np.random.default_rng(seed)
        elements = [measure.restrict(float(a), float(b)) for a, b in zip(edges[:-1],
                                                                         edges[1:])]
        # the true systems at the K + 1 edges tell, before any random point, how far each
        # element's polynomial is from the truth at its two ends
        edge_paths, rhs = true_runs(system, options, edges, times, what="element edge")
        indicator = edge_indicator(run.element_x_coef.values, edges, measure,
                                   edge_paths[:, :, 0])
        batches = []  # (x, x_hat, stratum probability) of each round's groups

        def draw(total):
            """A batch of ``total`` true runs in jittered groups, allocated by the
            indicator: element k's n_k groups cut its law into n_k slices of equal
            probability, with GROUP independent points in each (the last total % GROUP
            points join the first group of the element with the most groups)."""
            groups = group_allocation(total // GROUP, P, indicator)
            size = [np.full(n, GROUP) for n in groups]
            size[int(np.argmax(groups))][0] += total % GROUP
            u = [(np.repeat(np.arange(n), m) + rng.random(m.sum())) / n
                 for n, m in zip(groups, size)]
            xi = np.concatenate([e.ppf(v) for e, v in zip(elements, u)])
            paths, n_rhs = true_runs(system, options, xi, times, what="verification sample")
            x_hat = surrogate(run, xi, measure=measure)[0]
            cut = np.cumsum(np.concatenate(size))[:-1]
            return (np.split(paths[:, :, 0], cut), np.split(x_hat, cut),
                    np.repeat(P / groups, groups)), n_rhs

    drawn = len(edges) if stratify else 0  # true runs so far
    while True:
        rounds += 1
        if stratify:
            batch, n_rhs = draw(M - drawn)
            rhs += n_rhs
            drawn = M
            batches.append(batch)
            # the rounds' batches are independent stratified estimates, weighted by their
            # groups (fixed weights: the sum stays unbiased, its variance the weighted sum)
            weight = np.concatenate([np.full(len(b[2]), len(b[2])) for b in batches])
            est = stratified_estimates(
                [s for b in batches for s in b[0]], [s for b in batches for s in b[1]],
                np.concatenate([b[2] for b in batches]) * weight / len(weight),
                moments["x_mean"], moments["x_second"])
            replicates = 0
        else:
            replicates = min(16, M // 4)
            xi, _ = sample_xi("sobol", M, seed, replicates, distribution=measure)
            paths, n_rhs = true_runs(system, options, xi, times, what="verification sample")
            rhs += n_rhs
            drawn = M
            est = paired_estimates(paths[:, :, 0], surrogate(run, xi, measure=measure)[0],
                                   replicates, moments["x_mean"], moments["x_second"])
        d_se = est["d_se"]
        cv_mean, cv_mean_se, cv_var, cv_var_se = (est["mean"], est["mean_se"], est["var"],
                                                  est["var_se"])
        err_mean, err_var = -est["d"], run.x_var.values - cv_var
        spread = np.sqrt(np.maximum(cv_var, 0.0))
        hangs = [marginal(err_mean, spread, d_se, tol=tolerance, z=z, floor=floor,
                          upto=len(times)),
                 marginal(err_var, cv_var, cv_var_se, tol=var_tolerance, z=z, floor=floor,
                          upto=len(times))]
        if log is not None:
            log(f"verify: {M} true systems, error of E[x] RMS "
                f"{float(np.sqrt(np.mean(err_mean**2))):.3g} ± "
                f"{float(np.sqrt(np.mean(d_se**2))):.2g}"
                + (" (verdict hangs on the noise: doubling)" if any(hangs)
                   and sequential and M < max_samples else ""))
        if not (sequential and any(hangs) and M < max_samples):
            break
        M *= 2
    first_mean = first_disagreement(times, err_mean, spread, d_se, tol=tolerance, z=z,
                                    floor=floor)
    first_var = first_disagreement(times, err_var, cv_var, cv_var_se, tol=var_tolerance,
                                   z=z, floor=floor)
    one = {"units": "1"}
    out = run.copy()
    out["verify_err_mean"] = ("time", err_mean, {
        "long_name": "paired estimate of the error of E[x]: E[x_hat] - E[x]", **one})
    out["verify_err_mean_sem"] = ("time", d_se, {
        "long_name": "standard error of verify_err_mean", **one})
    out["verify_err_var"] = ("time", err_var, {
        "long_name": "paired estimate of the error of Var[x]: Var[x_hat] - Var[x]", **one})
    out["verify_err_var_sem"] = ("time", cv_var_se, {
        "long_name": "standard error of verify_err_var", **one})
    out["cv_x_mean"] = ("time", cv_mean, {
        "long_name": "control-variate estimate of E[x] (surrogate + paired differences)",
        **one})
    out["cv_x_mean_sem"] = ("time", cv_mean_se, {"long_name": "standard error of cv_x_mean",
                                                 **one})
    out["cv_x_var"] = ("time", cv_var, {"long_name": "control-variate estimate of Var[x]",
                                        **one})
    out["cv_x_var_sem"] = ("time", cv_var_se, {"long_name": "standard error of cv_x_var",
                                               **one})
    for name in ("mean", "var"):
        dof = est.get(f"{name}_dof", np.full(len(times), replicates - 1.0))
        out[f"cv_x_{name}_dof"] = ("time", np.asarray(dof, dtype=float), {
            "long_name": f"degrees of freedom of cv_x_{name}_sem (replicates - 1, or "
            f"Welch-Satterthwaite over the strata): Student's t intervals", **one})
    verdict_mean = "agrees" if math.isinf(first_mean) else "disagrees"
    verdict_var = "agrees" if math.isinf(first_var) else "disagrees"
    out.attrs.update(
        verdict="agrees" if verdict_mean == verdict_var == "agrees" else "disagrees",
        verdict_mean=verdict_mean, verdict_var=verdict_var,
        first_disagreement_mean=first_mean / T, first_disagreement_var=first_var / T,
        verify_samples=int(drawn), verify_replicates=int(replicates),
        verify_sampling=(f"stratified by element: the true systems at the {len(edges)} "
                         f"edges, then jittered groups of {GROUP} random points, one group "
                         f"per element and the rest half in proportion to P_k times the "
                         f"misfit at the element's ends, half to P_k" if stratify else
                         f"scrambled Sobol' in {replicates} replicates"),
        verify_rounds=int(rounds), verify_seed=int(seed), verify_tolerance=float(tolerance),
        verify_var_tolerance=float(var_tolerance), verify_z=float(z),
        variance_reduction=est["variance_reduction"],
        verify_rhs_evaluations=int(rhs),
    )
    return out


__all__ = ["GROUP", "MEAN_TOLERANCE", "VAR_TOLERANCE", "Z", "check_counts", "edge_indicator",
           "group_allocation", "interval_halfwidth", "neyman_allocation", "paired_estimates",
           "stratified_estimates", "system_of", "verify"]
