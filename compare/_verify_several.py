r"""Paired Monte Carlo certificates of OPA runs with several uncertain parameters.

The run defines the surrogate :math:`\hat x(t, \xi) = \sum_\alpha x_\alpha(t)
\Psi_\alpha(\xi)` (on each box its own conditional basis), whose moments
:math:`E[\hat x]` (``x_mean``) and :math:`E[\hat x^2]` (``x_var + x_mean^2``) are exact. At
points :math:`\xi_m` of the run's own law the true sampled systems give
:math:`x(t, \xi_m)`, and as in one dimension (:mod:`compare._verify`) the paired
differences estimate the run's errors without bias, the surrogate being a control
variate:

.. math::

    E_{cv}[x] = E[\hat x] + \overline{x - \hat x}, \qquad
    Var_{cv}[x] = E[\hat x^2] + \overline{x^2 - \hat x^2} - E_{cv}[x]^2 .

**The points** are ``REPLICATES`` = 16 (:mod:`compare._pairs`'s) independent scramblings
of a Sobol' sequence in d dimensions (:meth:`opa.Problem.sample`), M/16 points each.
Each replicate gives its own estimates; their spread over the 16 is the standard error,
with 15 degrees of freedom for Student's t intervals (randomised QMC: the replicates are
independent and identically distributed whatever the integrand).

**The verdict** is the one-dimensional certificate's (:func:`compare._trust.
bounded_verdict`): round r spends ``alpha / 2^r`` of the error rate on a Bonferroni band
over the outputs and the two quantities, each round draws fresh independent points, and
the sample size doubles until the verdict is decided or ``max_samples`` is reached.

**What it cannot see.** In one dimension the changes of the impact sequence are located
and made strata of their own, so that a rare region with another impact sequence cannot
hide between the points. In d dimensions they are curves or surfaces that are not
located. Two rules keep the certificate honest about it:

* when the sampled true systems do not all make the same number of impacts and the
  rarer counts were seen at fewer than ``MIN_RARE`` points, the spread of 16 replicate
  means does not bound that region's error: the verdicts are ``undecided`` (and the
  procedure doubles while it may);
* a region of probability p is missed by all M points with probability
  :math:`(1-p)^M`; the certificate says so (``verify_unseen_probability`` = 3/M: below
  it a region is missed with probability above 5 %).
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from compare._inputs import check_dataset, lower_wall, require_time, run_fields, run_options
from compare._pairs import REPLICATES
from compare._trust import band_multiplier, bounded_verdict
from opa.engine import (
    PARAMETER_NAMES, Oscillator, SolverOptions, System, check_work, run_batch, split_list,
    surrogate_several,
)

#: fewest points a rarer number of impacts must be seen at before a verdict is given
MIN_RARE = 64


def several_system_of(run: xr.Dataset, options: SolverOptions | None = None):
    """The System (several uncertain parameters) and the solver options of a run, from
    its attributes."""
    attrs = run.attrs
    needed = PARAMETER_NAMES + ("sigma", "uncertain", "distribution", "impulse",
                                "pulse_width", "impulse_at_zero") + (
        () if options else ("rtol", "atol"))
    missing = [name for name in needed if name not in attrs]
    if missing:
        raise ValueError(f"the run lacks the attribute{'s' if len(missing) > 1 else ''} "
                         f"{', '.join(missing)}: the true systems it describes are not "
                         f"known, so it cannot be verified")
    laws = tuple(None if law == "semicircle" else law for law in
                 split_list(str(attrs["distribution"])))
    system = System(Oscillator(**{name: float(attrs[name]) for name in PARAMETER_NAMES},
                               **lower_wall(attrs)),
                    uncertain=str(attrs["uncertain"]),
                    sigma=tuple(float(s) for s in np.atleast_1d(attrs["sigma"])),
                    distribution=laws, **run_fields(attrs))
    return system, run_options(attrs, options)


def replicate_estimates(x: np.ndarray, g: np.ndarray, exact_mean: np.ndarray,
                        exact_second: np.ndarray, replicates: int = REPLICATES) -> dict:
    """The control-variate estimates and their standard errors from true values ``x``
    and surrogate values ``g`` (M, T), the points in ``replicates`` equal consecutive
    groups; ``exact_mean``, ``exact_second``: E[x_hat] and E[x_hat^2] (T,).

    >>> rng = np.random.default_rng(0)
    >>> g = rng.normal(size=(64, 3)); x = g + 0.01
    >>> est = replicate_estimates(x, g, np.zeros(3), np.ones(3), replicates=4)
    >>> bool(np.allclose(est["mean"], 0.01)), bool(np.allclose(est["d_se"], 0.0))
    (True, True)
    """
    R = replicates
    d = (x - g).reshape(R, -1, x.shape[1]).mean(axis=1)
    s = (x ** 2 - g ** 2).reshape(R, -1, x.shape[1]).mean(axis=1)
    mean_r = exact_mean + d
    var_r = exact_second + s - mean_r ** 2
    root = math.sqrt(R)
    var_d = float(np.var(x - g, axis=0).sum())
    reduction = float(np.var(x, axis=0).sum()) / var_d if var_d > 0 else math.inf
    return dict(mean=mean_r.mean(axis=0), mean_se=mean_r.std(axis=0, ddof=1) / root,
                variance_reduction=reduction,
                d=d.mean(axis=0), d_se=d.std(axis=0, ddof=1) / root,
                var=var_r.mean(axis=0), var_se=var_r.std(axis=0, ddof=1) / root,
                dof=np.full(x.shape[1], R - 1.0))


def _judge(est, err_mean, err_var, spent, tolerance, var_tolerance, floor):
    """The verdicts on the mean and the variance in a band of rate ``spent``."""
    T = len(err_mean)
    width_mean = band_multiplier(spent, T, est["dof"]) * est["d_se"]
    width_var = band_multiplier(spent, T, est["dof"]) * est["var_se"]
    var_low = np.maximum(est["var"] - width_var, 0.0)
    var_high = np.maximum(est["var"] + width_var, 0.0)
    mean = bounded_verdict(err_mean, width_mean, np.sqrt(var_low), np.sqrt(var_high),
                           tol=tolerance, floor=floor)
    var = bounded_verdict(err_var, width_var, var_low, var_high, tol=var_tolerance,
                          floor=floor)
    return [mean[0], var[0]], [mean[1], var[1]]


def _rare(impacts: np.ndarray) -> int:
    """How many points made a number of impacts other than the commonest (0: all the
    same)."""
    _, counts = np.unique(impacts, return_counts=True)
    return int(len(impacts) - counts.max())


def verify_several(run: xr.Dataset, *, samples: int, max_samples: int, seed: int,
                   tolerance: float, var_tolerance: float, alpha: float, sequential: bool,
                   options: SolverOptions | None = None, log=None) -> xr.Dataset:
    """:func:`compare.verify` for a run of several uncertain parameters (its keywords
    checked by the caller: ``samples`` a power of two >= 64, so a multiple of the
    replicates): the run with its certificate's variables and attributes."""
    check_dataset(run, "the run", "an OPA run")
    require_time(run, "the run")
    for name in ("multi_index", "x_coef" if "element_lower" not in run else "element_x_coef"):
        if name not in run:
            raise ValueError(f"the run lacks {name}: it is not an OPA run of several "
                             f"uncertain parameters")
    system, options = several_system_of(run, options)
    times = run.time.values
    periods = float(times[-1] - times[0]) / system.oscillator.forcing_period
    check_work("this certificate", max_samples * periods,
               [("max_samples", max_samples), ("periods", f"{periods:g}")])
    exact_mean = run.x_mean.values
    exact_second = run.x_var.values + exact_mean ** 2
    floor = 10 * (options.rtol + options.atol)
    streams = np.random.SeedSequence(seed).spawn(64)
    M, rounds, drawn, rhs = int(samples), 0, 0, 0
    while True:
        rounds += 1
        spent = alpha / 2 ** rounds if sequential else alpha
        round_seed = int(streams[rounds - 1].generate_state(1, dtype=np.uint32)[0])
        xi = system.problem.sample(M, "sobol", round_seed, replicates=REPLICATES)
        batch = run_batch(system.sampled_inputs(options, xi=xi),
                          system.deterministic().initial_state(), times, rtol=options.rtol,
                          atol=options.atol, stop_on_failure=True)
        if batch.failed.any():
            m = int(np.flatnonzero(batch.failed)[0])
            raise ValueError(f"the true system at xi = {np.round(xi[m], 6).tolist()} could "
                             f"not be completed: {batch.message(m)}")
        drawn, rhs = drawn + M, rhs + int(batch.rhs_evaluations.sum())
        x_hat = surrogate_several(run, system.problem.measures, xi)
        est = replicate_estimates(batch.states[:, :, 0], x_hat,
                                  exact_mean, exact_second)
        err_mean, err_var = -est["d"], run.x_var.values - est["var"]
        verdicts, firsts = _judge(est, err_mean, err_var, spent, tolerance, var_tolerance,
                                  floor)
        rare, because = _rare(batch.impacts), ""
        if 0 < rare < MIN_RARE:
            because = (f"a change of the impact sequence was seen at only {rare} of {M} "
                       f"points (fewer than {MIN_RARE}): the spread of the replicates does "
                       f"not bound the error of its region")
            verdicts = ["undecided", "undecided"]
        if not all(np.isfinite(est[k]).all() for k in ("d", "var", "d_se", "var_se")):
            because, verdicts = "an estimate is not finite", ["undecided", "undecided"]
        decided = "disagrees" in verdicts or verdicts == ["agrees", "agrees"]
        if log is not None:
            log(f"verify: {M} true systems, error of E[x] RMS "
                f"{float(np.sqrt(np.mean(err_mean ** 2))):.3g}: mean {verdicts[0]}, "
                f"variance {verdicts[1]}" + (f" ({because})" if because else ""))
        if decided or not sequential or 2 * M > max_samples or rounds >= len(streams):
            break
        M *= 2
    return _certificate(run, est, err_mean, err_var, verdicts, firsts, because,
                        dict(samples=drawn, rounds=rounds, rhs=rhs, seed=seed, last=M,
                             tolerance=tolerance, var_tolerance=var_tolerance, alpha=alpha,
                             period=system.oscillator.forcing_period))


def _certificate(run, est, err_mean, err_var, verdicts, firsts, because, info) -> xr.Dataset:
    """The run with the certificate's variables and attributes (the names of the
    one-dimensional certificate's, :mod:`compare._verify`)."""
    one = {"units": "1"}
    out = run.copy()
    out["verify_err_mean"] = ("time", err_mean, {
        "long_name": "paired estimate of the error of E[x]: E[x_hat] - E[x]", **one})
    out["verify_err_mean_sem"] = ("time", est["d_se"], {
        "long_name": "standard error of verify_err_mean", **one})
    out["verify_err_var"] = ("time", err_var, {
        "long_name": "paired estimate of the error of Var[x]: Var[x_hat] - Var[x]", **one})
    out["verify_err_var_sem"] = ("time", est["var_se"], {
        "long_name": "standard error of verify_err_var", **one})
    for name, text in (("mean", "E[x]"), ("var", "Var[x]")):
        out[f"cv_x_{name}"] = ("time", est[name], {
            "long_name": f"control-variate estimate of {text}", **one})
        out[f"cv_x_{name}_sem"] = ("time", est[f"{name}_se"], {
            "long_name": f"standard error of cv_x_{name}", **one})
        out[f"cv_x_{name}_dof"] = ("time", est["dof"], {
            "long_name": f"degrees of freedom of cv_x_{name}_sem (replicates - 1): "
                         f"Student's t intervals", **one})
    times = run.time.values
    first = [float(times[i] / info["period"]) if v == "disagrees" and i >= 0 else math.inf
             for v, i in zip(verdicts, firsts)]
    verdict = ("disagrees" if "disagrees" in verdicts else
               "agrees" if verdicts == ["agrees", "agrees"] else "undecided")
    out.attrs.update(
        verdict=verdict, verdict_mean=verdicts[0], verdict_var=verdicts[1],
        first_disagreement_mean=first[0], first_disagreement_var=first[1],
        verify_samples=int(info["samples"]), verify_replicates=REPLICATES,
        verify_strata=1, verify_splits=0, verify_splits_complete=0,
        verify_sampling=(f"{REPLICATES} independent scramblings of a Sobol' sequence in "
                         f"{run.sizes['parameter']} dimensions, fresh points each round; "
                         f"the changes of the impact sequence are not located"),
        verify_rounds=int(info["rounds"]), verify_seed=int(info["seed"]),
        verify_tolerance=float(info["tolerance"]),
        verify_var_tolerance=float(info["var_tolerance"]),
        verify_alpha=float(info["alpha"]), verify_min_dof=REPLICATES - 1,
        verify_undecided_because=because or "none",
        verify_unseen_probability=3.0 / info["last"],
        verify_rhs_evaluations=int(info["rhs"]),
        variance_reduction=est["variance_reduction"],
    )
    return out
