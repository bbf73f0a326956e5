"""Paired Monte Carlo certificates of OPA runs, and control-variate estimates.

An OPA run of any K and any law of xi defines the surrogate x_hat(t, xi)
(:mod:`opa._surrogate`) whose moments E[x_hat], E[x_hat^2] are exact. At M points xi_m
drawn from the run's own law the true sampled systems give x(t, xi_m), and the paired
differences ``d_m = x(t, xi_m) - x_hat(t, xi_m)`` estimate, without bias,

    E[x] - E[x_hat] = E[d],      E[x^2] - E[x_hat^2] = E[x^2 - x_hat^2],

with a variance Var(d) that shrinks as OPA gets better: the surrogate is a control
variate (Glasserman 2004, ch. 4; multi-fidelity Monte Carlo: Peherstorfer, Willcox &
Gunzburger 2016). So the same runs give the **error of the run** (``err_mean = -mean d``,
``err_var = Var[x_hat] - Var_cv[x]``) with standard errors, a verdict, and
**control-variate estimates** ``E_cv[x] = E[x_hat] + mean d``, ``Var_cv[x] = E[x_hat^2] +
mean(x^2 - x_hat^2) - E_cv[x]^2`` with standard errors and degrees of freedom.

**Where are the points?** Stratified, always (:mod:`compare._strata`). The strata are the
run's elements cut at the changes of the impact sequence located in the support (a rare
region of the law that makes an extra impact becomes a stratum of its own, so it cannot
hide between the points). First the true systems at the S + 1 cuts: a stratum's
indicator is the misfit of its element's polynomial at its two ends; where the first round
has room, a pilot group per stratum adds what it sees inside (it only allocates, and is
left out of the estimate). Then jittered groups of ``GROUP`` = 4 points: stratum j gets
n_j >= 1 groups (the rest half in proportion to P_j times its indicator, half to P_j),
cuts itself into n_j slices (:func:`compare._strata.slices`: equal under half the law and
half the uniform law) and draws 4 independent points of the law in each, weighted by the
slice's probability. The estimate sums the slices; its standard error comes from the
within-slice variances, with Welch-Satterthwaite degrees of freedom for Student's t
intervals (``cv_x_mean_dof``). A later round adds an independent batch allocated by each
stratum's spread seen so far too; the batches are summed with fixed weights (their
groups), so the sum stays unbiased.

**The verdict** (:func:`compare._trust.bounded_verdict`) has three outcomes. Round r of
the sequential procedure spends ``alpha / 2^r`` of the error rate ``alpha``
(``ALPHA`` = 0.01): a Bonferroni band of Student's t intervals holds for the mean's and
the variance's estimates at every output at once with probability 1 - alpha / 2^r, so
the bands of all rounds hold together with probability >= 1 - alpha, whatever round the
procedure stops at. Inside the band the running RMS error (the trust map's criterion:
``R_e(t) <= tol R_scale(t) + floor`` at every output) is bounded above and below:

* **agrees**: the upper bound is within the tolerance at every output;
* **disagrees**: the lower bound exceeds it at some output;
* **undecided**: neither, after ``max_samples`` true systems; or whatever the bounds say
  when the split scan hit its limit (``verify_splits_complete`` 0): a change of the
  impact sequence it did not reach may hide inside a stratum, where no standard error
  sees it, so nothing is certified (``verify_undecided_because``).

A round whose degrees of freedom fall below ``MIN_DOF`` at some output decides nothing (a
variance estimated from too few points cannot bound anything): the procedure doubles. So
the stated rate ``alpha`` bounds the chance that the verdict is wrong, over the doublings
and the outputs; the tolerance is the map's, and the noise is no longer added to it.

**What is certified** is what the run reports: before any true system runs, the run's
``x_mean``, ``x_var`` and ``element_probability`` must follow from its coefficients and
its law (:func:`check_reported`), or the run is refused.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np
import xarray as xr

from compare._inputs import (
    check_attribute_number, check_dataset, require_time, run_fields, run_options,
    several,
)
from compare._strata import (
    build_strata, group_allocation, least_samples, neyman_allocation, slices, split_values,
)
from compare._trust import band_multiplier, bounded_verdict
from mc import cv_estimates
from opa.engine import (
    PARAMETER_NAMES, check_memory, check_opa_layout, Oscillator, run_measure, SolverOptions,
    surrogate, surrogate_moments, surrogate_values, System, true_runs,
)

#: points in each jittered group of a stratum: 4 give each slice 3 degrees of freedom
GROUP = 4

#: the trust map's tolerances (README, "The main job")
MEAN_TOLERANCE = 0.1
VAR_TOLERANCE = 0.25
#: the verdict's error rate over the whole sequential procedure and every output
ALPHA = 0.01
#: the fewest Welch-Satterthwaite degrees of freedom at any output before a round decides
MIN_DOF = 10
#: the fewest true systems of a first round (16 groups of 4: MIN_DOF with room to spare)
MIN_SAMPLES = 64
#: how far the reported moments may stand from those of the coefficients, relative to
#: the response's scale (1 + |E[x]|, or the variance plus its scale squared)
REPORTED_TOLERANCE = 1e-9


def system_of(run: xr.Dataset, options: SolverOptions | None = None
              ) -> tuple[System, SolverOptions]:
    """The System and solver options an OPA run was computed with, from its attributes
    (``options``: the solver options to use instead, e.g. with a ``max_step``)."""
    attrs = run.attrs
    one_parameter(run)
    needed = PARAMETER_NAMES + ("sigma", "uncertain", "impulse", "pulse_width",
                                "impulse_at_zero") + (() if options else ("rtol", "atol"))
    missing = [name for name in needed if name not in attrs]
    if missing:
        raise ValueError(f"the run lacks the attribute{'s' if len(missing) > 1 else ''} "
                         f"{', '.join(missing)}: the true systems it describes are not "
                         f"known, so it cannot be verified")
    words = ("uncertain", "impulse", "distribution", "method")
    for name in needed:
        if name not in words:
            check_attribute_number(run, "the run", name)
    oscillator = Oscillator.from_attrs(attrs)
    distribution = attrs.get("distribution", "semicircle")
    system = System(oscillator, sigma=float(attrs["sigma"]), order=0,
                    uncertain=str(attrs["uncertain"]),
                    distribution=None if distribution == "semicircle" else distribution,
                    **run_fields(attrs))
    return system, run_options(attrs, options)


def _check_count(name: str, value, least: int) -> int:
    if not (isinstance(value, numbers.Integral) and not isinstance(value, bool)
            and value >= least and value & (value - 1) == 0):
        raise ValueError(f"{name} must be a power of two >= {least}, got {value!r}"
                         + (f": a verdict needs {MIN_DOF} degrees of freedom, so the "
                            f"smallest that works is {name} {least}" if least == MIN_SAMPLES
                            else ""))
    return int(value)


def check_counts(samples, max_samples, *, flags: bool = False) -> tuple[int, int]:
    """``samples`` and ``max_samples`` checked (``flags``: named as the CLI's flags):
    powers of two, ``samples >= MIN_SAMPLES`` and ``max_samples >= samples``."""
    first, most = ("--verify", "--verify-max") if flags else ("samples", "max_samples")
    samples = _check_count(first, samples, MIN_SAMPLES)
    return samples, _check_count(most, max_samples, samples)


def one_parameter(run: xr.Dataset) -> None:
    """Refuse in one line a run of several uncertain parameters where one is needed."""
    if several(run):
        raise ValueError(f"the run has several uncertain parameters "
                         f"({run.attrs['uncertain']}); this takes one")


def check_reported(run: xr.Dataset, measure) -> None:
    """Refuse a run whose reported moments or element probabilities do not follow from
    its coefficients and its law (a dataset edited after the run, or another run's
    numbers): the certificate vouches for what the dataset says."""
    check_dataset(run, "the run", "an OPA run")
    check_opa_layout(run, "the run")
    require_time(run, "the run")
    edges = run.element_edges.values
    law = np.diff(np.asarray(measure.cdf(edges), dtype=float))
    reported = run.element_probability.values
    if not np.allclose(reported, law, rtol=1e-9, atol=1e-12):
        k = int(np.argmax(np.abs(reported - law)))
        raise ValueError(f"the run's element_probability[{k}] = {reported[k]:.6g} is not "
                         f"the law's probability {law[k]:.6g} of the element "
                         f"[{edges[k]:.6g}, {edges[k + 1]:.6g}]: the dataset was changed "
                         f"after the run, so it cannot be certified")
    moments = surrogate_moments(run)
    mean, second = moments["x_mean"], moments["x_second"]
    reported_mean, reported_var = run.x_mean.values, run.x_var.values
    scale = 1.0 + np.abs(mean)
    bad_mean = ~(np.abs(reported_mean - mean) <= REPORTED_TOLERANCE * scale)
    bad_var = ~(np.abs(reported_var - (second - mean**2))
                <= REPORTED_TOLERANCE * scale**2)
    for name, bad in (("x_mean", bad_mean), ("x_var", bad_var)):
        if bad.any():
            t = int(np.flatnonzero(bad)[0])
            raise ValueError(f"the run's {name} does not follow from its coefficients at "
                             f"t = {float(run.time[t]):.6g} (and {int(bad.sum()) - 1} "
                             f"other outputs): the dataset was changed after the run, so "
                             f"it cannot be certified")


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
    return _misfit_at_ends(x_coef, edges, measure, edges, np.arange(len(edges) - 1),
                           np.asarray(x_edges, dtype=float))


def _misfit_at_ends(x_coef, edges, measure, cuts, element, x_cuts) -> np.ndarray:
    """Piece j = [cuts[j], cuts[j + 1]] of element ``element[j]``: the larger over its two
    ends of the RMS over time of the truth ``x_cuts`` minus that element's polynomial."""
    out = np.empty(len(element))
    for j, k in enumerate(element):
        ends = surrogate_values(x_coef[k:k + 1], edges[k:k + 2], measure, cuts[j:j + 2])
        out[j] = np.sqrt(np.mean((x_cuts[j:j + 2] - ends) ** 2, axis=1)).max()
    return out


def interval_halfwidth(se, dof, level: float = 0.95):
    """Half-width of a two-sided ``level`` confidence interval: Student's t with ``dof``
    degrees of freedom (scalar or per time) times the standard error; R replicates give
    R - 1 (16: 2.13 SE), strata their ``*_dof`` (the dataset's ``cv_x_mean_dof``)."""
    from scipy import stats

    return stats.t.ppf(0.5 + level / 2, np.asarray(dof, dtype=float)) * np.asarray(se)




def stratum_indicator(x_coef: np.ndarray, edges, measure, strata, x_cuts: np.ndarray
                      ) -> np.ndarray:
    """:func:`edge_indicator` for strata inside elements: stratum j's indicator is the
    larger over its two ends of the RMS over time of ``x(t, e) - x_hat_k(t, e)``, with
    x_hat_k the polynomial of its element k; ``x_cuts`` (S + 1, T): the true systems at
    the strata's cuts."""
    out = _misfit_at_ends(x_coef, np.asarray(edges, dtype=float), measure, strata.cuts,
                          strata.element, x_cuts)
    # a non-finite misfit (a true run at a cut that went far) counts as the largest
    return np.where(np.isfinite(out), out, np.nanmax(out, initial=0.0) + 1.0)


def _check_rate(name: str, value, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not (math.isfinite(value) and lo <= value <= hi):
        raise ValueError(f"{name} must be a finite number in [{lo:g}, {hi:g}], got "
                         f"{value!r}")
    return float(value)


def _non_finite_estimate(est: dict, err_mean: np.ndarray, err_var: np.ndarray) -> str:
    """Why no verdict can be read off the round's estimates: the first of them (by the
    name it gets in the dataset) that holds a non-finite value, or "" if none does."""
    for name, values in (("verify_err_mean", err_mean), ("verify_err_mean_sem", est["d_se"]),
                         ("verify_err_var", err_var), ("verify_err_var_sem", est["var_se"]),
                         ("cv_x_mean", est["mean"]), ("cv_x_var", est["var"]),
                         ("cv_x_mean_dof", est["mean_dof"]),
                         ("cv_x_var_dof", est["var_dof"])):
        bad = ~np.isfinite(np.asarray(values, dtype=float))
        if bad.any():
            return (f"{name} has {int(bad.sum())} non-finite value"
                    f"{'' if bad.sum() == 1 else 's'} of {bad.size} (a true system or the "
                    f"surrogate went far?): no verdict is read off it")
    return ""


def verify(run: xr.Dataset, *, samples: int = 256, max_samples: int = 4096, seed: int = 0,
           tolerance: float = MEAN_TOLERANCE, var_tolerance: float = VAR_TOLERANCE,
           alpha: float = ALPHA, sequential: bool = True,
           options: SolverOptions | None = None, log=None) -> xr.Dataset:
    """The run with its paired Monte Carlo certificate and control-variate estimates.

    Parameters
    ----------
    run : an OPA dataset (any number of elements, any law of xi, any uncertain parameter).
    samples : true systems of the first round (a power of two >= ``MIN_SAMPLES`` = 64);
        a first round grows to the least power of two that gives every stratum a group.
    max_samples : the most a sequential certificate doubles to (a power of two >=
        ``samples``).
    seed : seed of the random points.
    tolerance, var_tolerance : the verdict's tolerances for the mean and the variance
        (the trust map's 0.1 and 0.25).
    alpha : the verdict's error rate over the whole procedure (default 0.01).
    sequential : double the samples while the verdict is undecided; False: one round.
    options : solver options of the true systems (default: the run's own attributes;
        give them to pass a ``max_step``).
    log : callable taking a line of progress, or None.

    Returns
    -------
    A copy of ``run`` with ``verify_err_mean``, ``verify_err_var`` (OPA minus truth) and
    their standard errors, the control-variate estimates ``cv_x_mean``, ``cv_x_var`` with
    their standard errors and degrees of freedom (``cv_x_mean_dof``, ``cv_x_var_dof``),
    and the attributes ``verdict`` (``agrees`` | ``disagrees`` | ``undecided``),
    ``verdict_mean``, ``verdict_var``, ``first_disagreement_mean`` and ``_var`` (forcing
    periods at which the error is certified above the tolerance; inf: nowhere),
    ``verify_samples`` (true runs: the cuts and every round's batch), ``verify_strata``,
    ``verify_splits``, ``verify_sampling`` (in words), ``verify_rounds``,
    ``verify_alpha``, ``variance_reduction`` and ``verify_rhs_evaluations``.

    A run of several uncertain parameters is certified by :mod:`compare._verify_several`
    (the same variables and verdicts; replicated Sobol' points instead of strata, and its
    own rules for the changes of the impact sequence it cannot locate).

    A verdict is never read off a non-finite estimate: if any estimate a round forms (the
    errors, the control-variate estimates, their standard errors or degrees of freedom)
    holds NaN or inf, the verdict is ``undecided`` and ``verify_undecided_because`` names
    the estimate and how many of its values are not finite; no further round is drawn.

    Raises
    ------
    ValueError
        Naming the culprit: ``run`` not an OPA dataset, lacking a variable of the OPA
        layout, the coordinate ``time`` (``periods`` in older files) or an attribute of
        the system (:func:`system_of`), holding a non-finite value in its coefficients,
        moments or system attributes, or moments that do not follow from its coefficients
        (:func:`check_reported`); a keyword out of its range (NaN included).
    """
    samples, max_samples, tolerance, var_tolerance, alpha = _check_arguments(
        run, samples, max_samples, tolerance, var_tolerance, alpha, seed, sequential, options)
    if several(run):
        from compare._verify_several import verify_several

        return verify_several(run, samples=samples, max_samples=max_samples, seed=seed,
                              tolerance=tolerance, var_tolerance=var_tolerance, alpha=alpha,
                              sequential=sequential, options=options, log=log)
    system, options = system_of(run, options)
    measure = run_measure(run)
    _check_certifiable(run, system, measure)
    times = run.time.values
    rule = _Rule(tolerance, var_tolerance, alpha, sequential,
                 floor=10 * (options.rtol + options.atol),
                 period=2 * math.pi / system.oscillator.omega)

    # the strata: the elements cut at the changes of the impact sequence
    split_xi, complete = split_values(system, options, measure, float(times[-1]))
    edges = run.element_edges.values
    strata = build_strata(measure, edges, split_xi, complete=complete,
                          max_strata=max(len(edges) - 1, (samples - 1) // (1 + GROUP)))
    least = least_samples(len(strata), GROUP)
    if least > samples and log is not None:
        log(f"verify: {strata.describe()}: the first round grows to {least} true systems "
            f"(the cuts and a group of {GROUP} in every stratum)")
    M = max(samples, least)
    max_samples = max(max_samples, M)
    check_memory("verification paths", max_samples * len(times) * 8 * 5,
                 f"max_samples {max_samples} x {len(times)} outputs x 5 arrays")
    draws = _Draws(run, system, options, measure, strata, np.random.default_rng(seed))
    outcome = _rounds(draws, rule, M, max_samples, log)
    return _certificate(run, outcome, strata, rule, seed, log)


def _check_arguments(run, samples, max_samples, tolerance, var_tolerance, alpha, seed,
                     sequential, options) -> tuple:
    """``verify``'s keywords checked, and the run checked to be an OPA dataset that ran to
    its end: (samples, max_samples, tolerance, var_tolerance, alpha)."""
    check_dataset(run, "the run", "an OPA run")
    if not several(run):  # several parameters: the layout of opa._galerkin / opa._boxes
        check_opa_layout(run, "the run")
    require_time(run, "the run")
    samples, max_samples = check_counts(samples, max_samples)
    tolerance = _check_rate("tolerance", tolerance, 0.0, math.inf)
    var_tolerance = _check_rate("var_tolerance", var_tolerance, 0.0, math.inf)
    alpha = _check_rate("alpha", alpha, 1e-12, 0.5)
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) \
            or seed < 0:
        raise ValueError(f"seed must be a whole number >= 0, got {seed!r}")
    if not isinstance(sequential, (bool, np.bool_)):
        raise ValueError(f"sequential must be True or False, got {sequential!r}")
    if options is not None and not isinstance(options, SolverOptions):
        raise ValueError(f"options must be SolverOptions or None, got {options!r}")
    if "failure" in run.attrs:
        raise ValueError(f"the run did not complete ({run.attrs['failure']}): nothing to "
                         f"verify")
    return samples, max_samples, tolerance, var_tolerance, alpha


def _check_certifiable(run: xr.Dataset, system: System, measure) -> None:
    """Refuse a run whose true systems are not those of its attributes (it was continued
    from another state), whose numbers are not finite, or whose reported moments do not
    follow from its coefficients (:func:`check_reported`)."""
    # at t = 0 every sample is at x0 (x' may have jumped by an impulse at t = 0, by the
    # same amount for every sample unless F0 is uncertain): x_0 = x0 and no higher
    # coefficient
    start = np.zeros(run.sizes["order"])
    start[0] = system.oscillator.x0
    first_x = run.element_x_coef.values[:, :, 0]
    first_v = run.element_v_coef.values[:, 1:, 0]
    own_kicks = "F0" in system.problem.names
    if run.time.values[0] == 0.0 and not (
            np.allclose(first_x, start, rtol=0.0, atol=1e-12)
            and (own_kicks or np.allclose(first_v, 0.0, rtol=0.0, atol=1e-12))):
        raise ValueError("the run does not start from the x0, v0 of its attributes (an "
                         "OPA run continued with initial=...): the true systems it "
                         "describes are not known, so it cannot be verified")
    for name in ("element_x_coef", "element_v_coef", "element_edges",
                 "element_probability", "x_mean", "x_var"):
        bad = ~np.isfinite(run[name].values)
        if bad.any():
            raise ValueError(f"the run's {name} holds {int(bad.sum())} non-finite values "
                             f"of {bad.size} (a run that stopped, or an edited file): "
                             f"nothing to certify")
    check_reported(run, measure)


@dataclass(frozen=True)
class _Rule:
    """How a round's estimates become verdicts: the tolerances of the mean and of the
    variance, the error rate ``alpha`` (spent ``alpha / 2^r`` in round r when
    ``sequential``), the absolute ``floor`` of the tolerance (from the solver's) and the
    forcing ``period`` that first disagreements are counted in."""

    tolerance: float
    var_tolerance: float
    alpha: float
    sequential: bool
    floor: float
    period: float


@dataclass
class _Draws:
    """The true systems of a certificate: those at the strata's cuts, and batches of
    jittered groups inside the strata (:meth:`batch`), with the surrogate at the same
    points; ``rhs`` counts their right-hand-side evaluations."""

    run: xr.Dataset
    system: System
    options: SolverOptions
    measure: object
    strata: object
    rng: np.random.Generator
    rhs: int = 0

    def at_cuts(self) -> np.ndarray:
        """The true systems at the strata's cuts, (S + 1, T)."""
        paths, rhs = true_runs(self.system, self.options, self.strata.cuts,
                               self.run.time.values, what="stratum cut")
        self.rhs += rhs
        return paths[:, :, 0]

    def batch(self, total: int, indicator: np.ndarray) -> tuple:
        """A batch of ``total`` true runs in jittered groups, allocated by the indicator:
        stratum j's n_j groups cut it into n_j slices (:func:`compare._strata.slices`),
        with GROUP independent points of the law in each (the last total % GROUP points
        join the first group of the stratum with the most groups).

        Returns (true values per group, surrogate values per group, each slice's
        probability, each group's stratum)."""
        measure, strata = self.measure, self.strata
        P = strata.probability
        groups = group_allocation(total // GROUP, P, indicator)
        size = [np.full(n, GROUP) for n in groups]
        size[int(np.argmax(groups))][0] += total % GROUP
        xi, weight = [], []
        for j, (n, m) in enumerate(zip(groups, size)):
            bounds, p = slices(measure, strata.cuts[j], strata.cuts[j + 1], int(n))
            lo = np.asarray(measure.cdf(bounds[:-1]), dtype=float)
            u = np.repeat(lo, m) + self.rng.random(m.sum()) * np.repeat(p, m)
            xi.append(np.clip(measure.ppf_full(u), np.repeat(bounds[:-1], m),
                              np.repeat(bounds[1:], m)))
            weight.append(p)
        xi = np.concatenate(xi)
        # each slice's probability under the law, the strata's summing to theirs
        ends = np.asarray(measure.cdf(strata.cuts[[0, -1]]), dtype=float).ravel()
        weight = np.concatenate(weight) / (ends[1] - ends[0])
        paths, rhs = true_runs(self.system, self.options, xi, self.run.time.values,
                               what="verification sample")
        self.rhs += rhs
        x_hat = surrogate(self.run, xi, measure=measure)[0]
        cut = np.cumsum(np.concatenate(size))[:-1]
        return (np.split(paths[:, :, 0], cut), np.split(x_hat, cut), weight,
                np.repeat(np.arange(len(P)), groups))


def _observed(batches: list, strata: int) -> np.ndarray:
    """Each stratum's spread of x - x_hat seen so far (RMS over time of the standard
    deviation over its points): a later round allocates by it too, so a stratum whose
    inside is rougher than its ends gets its share (the allocation is fixed before the
    batch is drawn, so every batch stays a stratified sample)."""
    out = np.zeros(strata)
    for j in range(strata):
        d = [x - h for b in batches for x, h, k in zip(b[0], b[1], b[3]) if k == j]
        d = np.concatenate(d)
        out[j] = np.sqrt(np.mean(np.var(d, axis=0, ddof=1))) if len(d) > 1 else 0.0
    return np.where(np.isfinite(out), out, 0.0)


@dataclass
class _Outcome:
    """The last round of a certificate: its estimates (:func:`stratified_estimates`), the
    errors of the run's mean and variance, the verdicts of the mean and the variance and
    where each first disagrees (forcing periods), why no verdict could be read
    (``broken``), the true systems drawn, the rounds, and the right-hand-side
    evaluations of every true system drawn."""

    est: dict
    err_mean: np.ndarray
    err_var: np.ndarray
    verdicts: list
    firsts: list
    broken: str
    drawn: int
    rounds: int
    rhs: int


def _rounds(draws: _Draws, rule: _Rule, M: int, max_samples: int, log) -> _Outcome:
    """The sequential procedure: the cuts, a pilot where the first round has room for
    one, then rounds of M true systems in all, M doubling while undecided (up to
    ``max_samples``, one round unless ``rule.sequential``)."""
    strata, run = draws.strata, draws.run
    P = strata.probability
    indicator = stratum_indicator(run.element_x_coef.values, run.element_edges.values,
                                  draws.measure, strata, draws.at_cuts())
    drawn, rounds, batches = len(strata.cuts), 0, []
    pilot = GROUP * len(P)
    if M - drawn >= 4 * pilot:
        # a pilot of one group per stratum, where the first round has room for it: it
        # only allocates the rest of the round, by what it saw inside each stratum (the
        # misfit at a stratum's ends cannot see a rough inside, such as a chatter zone),
        # and is left out of the estimate (a batch of one slice per stratum would bring
        # its few degrees of freedom to every standard error)
        seen = draws.batch(pilot, indicator)
        drawn += pilot
        indicator = np.maximum(indicator, _observed([seen], len(P)))
    moments = surrogate_moments(run)
    while True:
        rounds += 1
        batches.append(draws.batch(M - drawn, indicator if not batches else
                                   np.maximum(indicator, _observed(batches, len(P)))))
        drawn = M
        # the rounds' batches are independent stratified estimates, weighted by their
        # groups (fixed weights: the sum stays unbiased, its variance the weighted sum)
        weight = np.concatenate([np.full(len(b[2]), len(b[2])) for b in batches])
        est = stratified_estimates(
            [s for b in batches for s in b[0]], [s for b in batches for s in b[1]],
            np.concatenate([b[2] for b in batches]) * weight / len(weight),
            moments["x_mean"], moments["x_second"])
        err_mean, err_var = -est["d"], run.x_var.values - est["var"]
        # the band of this round: alpha / 2^r of the rate (one round: all of it)
        spent = rule.alpha / 2**rounds if rule.sequential else rule.alpha
        verdicts, firsts, short = _judge(est, err_mean, err_var, spent, rule,
                                         run.time.values)
        broken = _non_finite_estimate(est, err_mean, err_var)
        if broken:  # no verdict is read off NaN; more points cannot mend those drawn
            verdicts, firsts = ["undecided", "undecided"], [math.inf, math.inf]
        decided = "disagrees" in verdicts or verdicts == ["agrees", "agrees"]
        if log is not None:
            log(f"verify: {M} true systems in {len(strata)} strata, error of E[x] RMS "
                f"{float(np.sqrt(np.mean(err_mean**2))):.3g} ± "
                f"{float(np.sqrt(np.mean(est['d_se']**2))):.2g}: mean {verdicts[0]}, "
                f"variance {verdicts[1]}"
                + (f" (fewer than {MIN_DOF} degrees of freedom)" if short else "")
                + (" (doubling)" if not decided and rule.sequential and M < max_samples
                   else ""))
        # an incomplete split scan certifies nothing: more points cannot change that
        if decided or not rule.sequential or M >= max_samples or not strata.complete \
                or broken:
            return _Outcome(est, err_mean, err_var, verdicts, firsts, broken, drawn, rounds,
                            draws.rhs)
        M *= 2


def _judge(est: dict, err_mean: np.ndarray, err_var: np.ndarray, spent: float, rule: _Rule,
           times: np.ndarray) -> tuple[list, list, bool]:
    """A round's verdicts on the mean and the variance (:func:`bounded_verdict` in a band
    of rate ``spent``), where each first disagrees (forcing periods; inf: nowhere), and
    whether a verdict was withheld for too few degrees of freedom."""
    width_mean = band_multiplier(spent, len(times), est["mean_dof"]) * est["d_se"]
    width_var = band_multiplier(spent, len(times), est["var_dof"]) * est["var_se"]
    var_low = np.maximum(est["var"] - width_var, 0.0)
    var_high = np.maximum(est["var"] + width_var, 0.0)  # a CV estimate may be < 0
    # the degrees of freedom must be enough wherever the band matters: where it is
    # wider than a tenth of what the tolerance allows (elsewhere the band, already
    # widened by the t quantile of its few degrees of freedom, is a small part of
    # the allowance), over the outputs the verdict reads: all of them for "agrees",
    # those up to the first certain excess for "disagrees"
    mean = bounded_verdict(err_mean, width_mean, np.sqrt(var_low), np.sqrt(var_high),
                           tol=rule.tolerance, floor=rule.floor)
    var = bounded_verdict(err_var, width_var, var_low, var_high, tol=rule.var_tolerance,
                          floor=rule.floor)
    verdicts, firsts, short = [], [], False
    for (verdict, above, _), width, dof, allowance in (
            (mean, width_mean, est["mean_dof"], rule.tolerance * np.sqrt(var_low)),
            (var, width_var, est["var_dof"], rule.var_tolerance * var_low)):
        reads = slice(None) if verdict == "agrees" else slice(0, above + 1)
        weak = (width > 0.1 * (allowance + rule.floor)) & (dof < MIN_DOF)
        if verdict != "undecided" and weak[reads].any():
            verdict, short = "undecided", True
        verdicts.append(verdict)
        firsts.append(times[above] / rule.period if verdict == "disagrees" else math.inf)
    return verdicts, firsts, short


def _certificate(run: xr.Dataset, outcome: _Outcome, strata, rule: _Rule, seed: int,
                 log) -> xr.Dataset:
    """The run with the certificate's variables and attributes (:func:`verify`)."""
    est = outcome.est
    one = {"units": "1"}
    out = run.copy()
    out["verify_err_mean"] = ("time", outcome.err_mean, {
        "long_name": "paired estimate of the error of E[x]: E[x_hat] - E[x]", **one})
    out["verify_err_mean_sem"] = ("time", est["d_se"], {
        "long_name": "standard error of verify_err_mean", **one})
    out["verify_err_var"] = ("time", outcome.err_var, {
        "long_name": "paired estimate of the error of Var[x]: Var[x_hat] - Var[x]", **one})
    out["verify_err_var_sem"] = ("time", est["var_se"], {
        "long_name": "standard error of verify_err_var", **one})
    out["cv_x_mean"] = ("time", est["mean"], {
        "long_name": "control-variate estimate of E[x] (surrogate + paired differences)",
        **one})
    out["cv_x_mean_sem"] = ("time", est["mean_se"], {
        "long_name": "standard error of cv_x_mean", **one})
    out["cv_x_var"] = ("time", est["var"], {"long_name": "control-variate estimate of Var[x]",
                                            **one})
    out["cv_x_var_sem"] = ("time", est["var_se"], {
        "long_name": "standard error of cv_x_var", **one})
    for name in ("mean", "var"):
        out[f"cv_x_{name}_dof"] = ("time", np.asarray(est[f"{name}_dof"], dtype=float), {
            "long_name": f"Welch-Satterthwaite degrees of freedom of cv_x_{name}_sem over "
            f"the strata: Student's t intervals", **one})
    verdicts, firsts, broken = outcome.verdicts, outcome.firsts, outcome.broken
    because = ""
    if not strata.complete:
        # a change of the impact sequence the scan did not reach may sit inside a stratum,
        # where no standard error sees it: nothing is certified
        because = ("the split scan hit its limit, so a change of the impact sequence may "
                   "hide inside a stratum: the bounds do not hold")
        if log is not None and verdicts != ["undecided", "undecided"]:
            log(f"verify: {because}; the verdicts ({verdicts[0]}, {verdicts[1]}) are "
                f"reported as undecided")
        verdicts = ["undecided", "undecided"]
        firsts = [math.inf, math.inf]
    if broken:
        because = (because + "; " if because else "") + broken
        if log is not None:
            log(f"verify: {broken}")
    verdict_mean, verdict_var = verdicts
    verdict = ("disagrees" if "disagrees" in verdicts else
               "agrees" if verdicts == ["agrees", "agrees"] else "undecided")
    out.attrs.update(
        verdict=verdict, verdict_mean=verdict_mean, verdict_var=verdict_var,
        first_disagreement_mean=float(firsts[0]),
        first_disagreement_var=float(firsts[1]),
        verify_samples=int(outcome.drawn), verify_replicates=0,
        verify_strata=int(len(strata)),
        verify_splits=int(strata.splits), verify_splits_complete=int(strata.complete),
        verify_sampling=(f"stratified: {strata.describe()}; the true systems at the "
                         f"{len(strata.cuts)} cuts, then jittered groups of {GROUP} random "
                         f"points, one group per stratum and the rest half in proportion "
                         f"to P_j times the misfit at the stratum's ends, half to P_j"),
        verify_rounds=int(outcome.rounds), verify_seed=int(seed),
        verify_tolerance=float(rule.tolerance),
        verify_var_tolerance=float(rule.var_tolerance), verify_alpha=float(rule.alpha),
        verify_min_dof=int(MIN_DOF), verify_undecided_because=because or "none",
        variance_reduction=est["variance_reduction"],
        verify_rhs_evaluations=int(outcome.rhs),
    )
    return out


__all__ = ["ALPHA", "GROUP", "MEAN_TOLERANCE", "MIN_DOF", "MIN_SAMPLES", "VAR_TOLERANCE",
           "check_counts", "check_reported", "edge_indicator", "group_allocation",
           "interval_halfwidth", "neyman_allocation", "paired_estimates",
           "stratified_estimates", "stratum_indicator", "system_of", "verify"]
