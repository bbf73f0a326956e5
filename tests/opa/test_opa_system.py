"""Tests of the OPA equivalent system (``opa._kernel.vector_field``, ``opa.simulate_opa``).

Each check is pinned against a reference that shares no code with the library:

* the right-hand side against the paper's Galerkin equations (10)-(13), written out here
  term by term, with ``X_i = E[x^3 U_i]`` and ``Y_i = E[(x')^3 U_i]`` from a 200-point
  Gauss-Jacobi rule (``scipy.special.roots_jacobi``) and ``scipy.special.eval_chebyu``
  (``tests.truths.semicircle_cubic_projection``);
* ``sigma = 0`` against the deterministic model (EMR_0 == DMR, paper section 3.1);
* means and variances against ensembles of the sampled systems ``p = p_bar + sigma xi_k``
  integrated one by one with ``tests/reference.py`` (scipy DOP853, rtol = atol = 1e-12)
  at Gauss nodes of the semicircle from the closed form (``tests.truths``).

Measured values (quoted in the test docstrings) are printed; run with ``-s`` to see them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import opa
from opa import _kernel
from tests.conftest import kernel_inputs, rule
from tests.reference import reference_trajectory
from tests.truths import semicircle_cubic_projection, semicircle_gauss_rule

RNG_SEED = 20240612
PRESET = "3.2"  # section 3.2 of the paper: omega = 3.98, impacts on delta = 0
ACCURATE = opa.SolverOptions(rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------- references


def paper_rhs(t, y, model, sigma, uncertain, truncation, pulse=0.0):
    """Right-hand side of the order-N system written from the paper's eqs. (10)-(13).

    With ``v_i = x_i'`` the i-th Galerkin equation of eq. (6) (uncertain mu) reads

        v_i' = mu v_i + sigma/2 (v_{i-1} + v_{i+1}) - a x_i
               - mu Y_i - sigma/2 (Y_{i-1} + Y_{i+1}) - c X_i + [i = 0] (f cos(omega t) + F)

    with ``v_{-1} = Y_{-1} = 0`` and ``v_{N+1} = 0`` (x is truncated at N). ``Y_{N+1}``
    is kept by the exact projection (``galerkin``) and dropped by eq. (27) (``paper``).
    The same steps for ``a + sigma xi`` give ``- sigma/2 (x_{i-1} + x_{i+1})`` (no
    truncated term: ``x_{N+1} = 0``), and for ``c + sigma xi``
    ``- sigma/2 (X_{i-1} + X_{i+1})`` with ``X_{N+1}`` kept or dropped like ``Y_{N+1}``.
    """
    n1 = len(y) // 2
    x, v = y[:n1], y[n1:]
    X = semicircle_cubic_projection(x, n1)  # X_0 .. X_{N+1}
    Y = semicircle_cubic_projection(v, n1)
    if truncation == "paper":
        X[n1] = Y[n1] = 0.0

    def neighbours(z, i):  # z_{i-1} + z_{i+1}, zero outside the stored range
        return (z[i - 1] if i >= 1 else 0.0) + (z[i + 1] if i + 1 < len(z) else 0.0)

    mu, a, c = model["mu"], model["a"], model["c"]
    out = np.empty_like(y)
    out[:n1] = v
    for i in range(n1):
        acc = mu * v[i] - a * x[i] - mu * Y[i] - c * X[i]
        if uncertain == "mu":
            acc += 0.5 * sigma * (neighbours(v, i) - neighbours(Y, i))
        elif uncertain == "a":
            acc -= 0.5 * sigma * neighbours(x, i)
        else:
            acc -= 0.5 * sigma * neighbours(X, i)
        if i == 0:
            acc += model["f"] * math.cos(model["omega"] * t) + pulse
        out[n1 + i] = acc
    return out


def kernel_rhs(t, y, oscillator, sigma, order, uncertain, truncation, pulse=0.0):
    """``opa._kernel.vector_field`` at (t, y); returns (derivative, release value)."""
    inputs = kernel_inputs(
        oscillator, opa.SolverOptions(), sigma=sigma, order=order, uncertain=uncertain,
        truncation=truncation,
    )  # fmt: skip
    p, cfg = inputs.p, inputs.cfg
    nodes, weights, basis = rule(inputs)
    out = np.empty_like(y)
    work = np.empty((6, len(nodes)))
    release = _kernel.vector_field(y, 0, p, cfg, nodes, weights, basis, t,
                                   _kernel.forcing(t, p, pulse), False, out, work)
    return out, release


def sampled_moments(oscillator, sigma, uncertain, t_out, q):
    """E[x], Var[x] at t_out and per-sample impact times, from q sampled systems.

    Each sample ``p_bar + sigma xi_k`` is integrated by the scipy reference
    (DOP853, rtol = atol = 1e-12); the q-point semicircle Gauss rule averages them.
    """
    nodes, weights = semicircle_gauss_rule(q)
    paths, impacts = [], []
    for xi in nodes:
        model = oscillator.as_dict()
        model[uncertain] += sigma * xi
        ref = reference_trajectory(**model, t_out=t_out, rtol=1e-12, atol=1e-12)
        paths.append(ref["x"])
        impacts.append(ref["impact_time"])
    paths = np.array(paths)
    mean = weights @ paths
    return mean, weights @ paths**2 - mean**2, impacts


def forcing_times(oscillator, periods, per_period):
    """t_j = j (2 pi / omega) / K, j = 0 .. P K, built here (not opa.time_grid)."""
    return np.arange(periods * per_period + 1) * (2.0 * np.pi / oscillator.omega / per_period)


def decades_per_order(orders, errors, floor):
    """Least-squares slope of log10(error) vs N over the errors above ``floor``."""
    orders, errors = np.asarray(orders), np.asarray(errors)
    keep = errors > floor
    return np.polyfit(orders[keep], np.log10(errors[keep]), 1)[0], int(keep.sum())


# --------------------------------------------------------------------------- right-hand side


RHS_CASES = [
    (unc, trunc, order)
    for unc in ("mu", "a", "c")
    for trunc in ("galerkin", "paper")
    for order in (1, 4)
]


@pytest.mark.parametrize(("uncertain", "truncation", "order"), RHS_CASES)
def test_rhs_matches_paper_equations(uncertain, truncation, order):
    """The compiled pseudo-spectral RHS equals eqs. (10)-(13) built by brute force."""
    rng = np.random.default_rng(RNG_SEED)
    oscillator = opa.preset(PRESET)
    sigma = {"mu": 0.3, "a": 0.2, "c": 0.04}[uncertain]
    for _ in range(5):
        y = rng.normal(scale=0.7, size=2 * (order + 1))
        t, pulse = rng.uniform(0.0, 20.0), rng.uniform(0.0, 0.2)
        got, release = kernel_rhs(t, y, oscillator, sigma, order, uncertain, truncation, pulse)
        want = paper_rhs(t, y, oscillator.as_dict(), sigma, uncertain, truncation, pulse)
        scale = max(1.0, np.abs(want).max())
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * scale)
        # the release function is the unconstrained mean acceleration v_0'
        assert release == pytest.approx(want[order + 1], abs=1e-12 * scale)


@pytest.mark.parametrize("order", [1, 4, 8])
@pytest.mark.parametrize("uncertain", ["mu", "a", "c"])
def test_paper_truncation_differs_by_the_dropped_term(uncertain, order):
    """paper - galerkin = sigma/2 Y_{N+1} (X_{N+1} for c) in the last equation only."""
    rng = np.random.default_rng(RNG_SEED + order)
    oscillator = opa.preset(PRESET)
    sigma = 0.04
    y = rng.normal(scale=0.7, size=2 * (order + 1))
    galerkin, _ = kernel_rhs(1.3, y, oscillator, sigma, order, uncertain, "galerkin")
    paper, _ = kernel_rhs(1.3, y, oscillator, sigma, order, uncertain, "paper")
    diff = paper - galerkin
    # everything but the last velocity equation is computed identically
    np.testing.assert_array_equal(diff[:-1], 0.0)
    if uncertain == "a":
        # (a + sigma xi) x projects onto x_{N+1} = 0: nothing is dropped
        assert diff[-1] == 0.0
        return
    coef = y[order + 1 :] if uncertain == "mu" else y[: order + 1]
    dropped = 0.5 * sigma * semicircle_cubic_projection(coef, order + 1)[order + 1]
    assert abs(dropped) > 1e-4  # the check is not vacuous
    assert diff[-1] == pytest.approx(dropped, rel=1e-12, abs=1e-14)


# --------------------------------------------------------------------------- EMR_0 == DMR


@pytest.mark.parametrize("order", [1, 4, 8])
def test_sigma_zero_reproduces_dmr(order):
    """EMR_0 == DMR (paper section 3.1) to round-off over 10 forcing periods.

    With sigma = 0 the mean equation is the DMR's up to the rounding of
    ``sum_k w_k U_0 U_0 = 1``, and the higher coefficients are driven only by the rounding
    of ``E[U_i] = 0`` (~1e-17). Both perturbations are amplified by the dynamics
    (destabilising van der Pol damping, 4 impacts in 10 periods); measured with the
    default tolerances, max |x_0 - x_DMR| over 10/20/50/100 periods is about
    2e-14 / 3e-13 / 2e-10 / 4e-8, hence the 10-period horizon for a 1e-12 bound.
    The max-norm step control makes the step sequences identical.
    """
    oscillator = opa.preset(PRESET)
    dmr = opa.simulate_dmr(oscillator, periods=10, per_period=20)
    emr0 = opa.simulate_opa(oscillator, sigma=0.0, order=order, periods=10, per_period=20)
    assert dmr.sizes["impact"] >= 3  # the horizon includes impacts
    np.testing.assert_allclose(emr0.x_mean, dmr.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(emr0.v_mean, dmr.v, rtol=0, atol=1e-12)
    assert np.abs(emr0.x_coef.values[1:]).max() < 1e-12
    assert np.abs(emr0.v_coef.values[1:]).max() < 1e-12
    assert emr0.attrs["steps"] == dmr.attrs["steps"]
    np.testing.assert_allclose(emr0.impact_time, dmr.impact_time, rtol=0, atol=1e-12)
    np.testing.assert_allclose(emr0.impact_velocity, dmr.impact_velocity, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- convergence in N


SPECTRAL_CASES = {
    # uncertain: (sigma, least decay in decades per order asserted)
    "mu": (0.2, -1.0),
    "a": (0.2, -0.5),
    "c": (0.04, -1.0),
}


@pytest.mark.parametrize("uncertain", list(SPECTRAL_CASES))
def test_spectral_convergence_without_impacts(uncertain):
    """Mean and variance converge geometrically in N to a 40-node sampled ensemble.

    Wall moved away (delta = 10, no impact in any sample or in the OPA run), section 3.2
    parameters, 5 forcing periods, outputs every half period, both sides at
    rtol = atol = 1e-12 (error floor ~5e-13, so only errors above 1e-10 enter the fit).
    Measured max errors over the outputs (mean / variance):

        N   mu, sigma = 0.2        a, sigma = 0.2        c, sigma = 0.04
        0   4.2e-03 / 1.4e-03     1.7e-01 / 1.8e-01     9.8e-03 / 1.1e-02
        1   7.7e-05 / 2.5e-05     9.9e-03 / 3.1e-02     9.2e-05 / 2.4e-04
        2   9.9e-07 / 5.0e-07     7.4e-05 / 1.5e-03     1.4e-06 / 4.2e-06
        3   5.1e-09 / 8.3e-09     3.6e-04 / 2.8e-04     1.4e-08 / 6.2e-08
        4   4.6e-11 / 2.8e-11     3.7e-05 / 1.9e-04     2.0e-10 / 9.0e-10
        5   6.8e-13 / 1.6e-12     4.5e-06 / 1.7e-05     4.1e-12 / 1.3e-11
        6   5.6e-13 / 2.6e-14     1.9e-06 / 1.7e-06     5.5e-13 / 1.6e-13
        7   5.6e-13 / 1.3e-14     5.2e-07 / 1.8e-06     5.4e-13 / 6.5e-14
        8   5.6e-13 / 1.3e-14     5.4e-08 / 3.0e-07     5.3e-13 / 6.5e-14

    Fitted rates (decades per order): mu -2.0 / -1.7, a -0.73 / -0.72, c -1.9 / -1.8.
    Uncertain stiffness decays slowest: a spread of natural frequencies makes x
    oscillate in xi as phases drift apart. Asserted: about half the measured rates.
    """
    sigma, bound = SPECTRAL_CASES[uncertain]
    oscillator = opa.preset(PRESET, delta=10.0)
    times = forcing_times(oscillator, 5, 2)
    mean, var, impacts = sampled_moments(oscillator, sigma, uncertain, times, q=40)
    assert all(len(t) == 0 for t in impacts)
    orders = list(range(9))
    errors = []
    for order in orders:
        ds = opa.simulate_opa(
            oscillator, sigma=sigma, order=order, uncertain=uncertain, options=ACCURATE,
            times=times,
        )  # fmt: skip
        assert ds.sizes["impact"] == 0
        errors.append((np.abs(ds.x_mean - mean).max(), np.abs(ds.x_var - var).max()))
    errors = np.array(errors, dtype=float)
    print(f"\nOPA vs 40-node ensemble, uncertain {uncertain}, sigma = {sigma}, no impacts")
    print(" N   |E[x] error|   |Var[x] error|")
    for order, (e_mean, e_var) in zip(orders, errors):
        print(f"{order:2d}   {e_mean:11.3e}   {e_var:11.3e}")
    for name, column in (("mean", errors[:, 0]), ("variance", errors[:, 1])):
        slope, used = decades_per_order(orders, column, floor=1e-10)
        print(f"{name}: {slope:.2f} decades per order (fit over {used} orders)")
        assert used >= 3
        assert slope < bound, (name, slope)
        assert column.min() < 1e-3 * column[0]  # a real decay, not a tilted plateau


# --------------------------------------------------------------------------- with impacts


def test_mean_error_with_impacts_is_second_order_in_sigma():
    """OPA (N = 4, mean law) vs a 20-node sampled ensemble over 5 periods with impacts.

    Before the first impact the OPA mean is exact to the tolerance (~3e-13). After it,
    the mean constraint x_0 = delta and the mean jump (eqs. (21)-(23)) replace the
    per-sample impacts and the error grows. Measured over 5 periods (2 impacts), max
    |E[x] error| / |Var[x] error| / true max Var[x]:

        sigma = 0.005: 8.6e-06 / 2.7e-06 / 7.2e-07
        sigma = 0.01:  3.4e-05 / 1.1e-05 / 2.9e-06   (N = 1: same to 3 digits)

    i.e. the error scales as sigma^2 and the OPA variance is off by several times its
    size. For comparison, ignoring the uncertainty (DMR) gives a mean error of 1.1e-05
    at sigma = 0.01: smaller than the OPA's. The ``ensemble`` law gives 1.4e-05 / 3.0e-06.
    Over 20 periods (8 impacts) the OPA mean error at sigma = 0.01 reaches 9e-03.
    A 40-node ensemble changes E[x] by < 1e-14, so the reference is converged.
    Asserted: exactness before impacts, a loose 1e-3 bound, and the sigma^2 scaling.
    """
    oscillator = opa.preset(PRESET)
    times = forcing_times(oscillator, 5, 4)
    dmr = opa.simulate_dmr(oscillator, options=ACCURATE, times=times)
    mean_errors = {}
    for sigma in (0.005, 0.01):
        mean, var, impacts = sampled_moments(oscillator, sigma, "mu", times, q=20)
        ds = opa.simulate_opa(oscillator, sigma=sigma, order=4, options=ACCURATE, times=times)
        assert ds.sizes["impact"] >= 2
        assert all(len(t) == ds.sizes["impact"] for t in impacts)
        first_impact = min(t[0] for t in impacts)
        before = times < min(first_impact, float(ds.impact_time[0]))
        err_mean = np.abs(ds.x_mean.values - mean)
        err_var = np.abs(ds.x_var.values - var)
        err_dmr = np.abs(dmr.x.values - mean).max()
        print(
            f"\nsigma = {sigma}: OPA N=4 |E[x] err| before impacts {err_mean[before].max():.2e}, "
            f"over 5 periods {err_mean.max():.2e}; |Var err| {err_var.max():.2e} "
            f"(max Var {var.max():.2e}); DMR |E[x] err| {err_dmr:.2e}"
        )
        assert before.sum() >= 3
        assert err_mean[before].max() < 1e-10
        assert err_var[before].max() < 1e-10
        assert err_mean.max() < 1e-3
        mean_errors[sigma] = err_mean.max()
    ratio = mean_errors[0.01] / mean_errors[0.005]
    print(f"error ratio for doubled sigma: {ratio:.3f} (4 for second order)")
    assert 3.0 < ratio < 5.0


# --------------------------------------------------------------------------- impact laws


@pytest.mark.parametrize("impact_law", ["mean", "ensemble"])
def test_impact_law_at_the_first_impact(impact_law):
    """``mean`` (eq. (28)) flips only v_0; ``ensemble`` multiplies every v_i by -eta.

    The first impact time comes from one run; a second run puts output times at
    t* -/+ eps and t* -/+ 2 eps (outputs are breakpoints, the impact time is the same to
    ~1e-14) and extrapolates linearly to t*-, t*+ (error O(eps^2)).
    """
    oscillator = opa.preset(PRESET)
    eta = oscillator.eta
    kwargs = dict(sigma=0.1, order=4, impact_law=impact_law, options=ACCURATE)
    first = opa.simulate_opa(oscillator, periods=2, per_period=4, **kwargs)
    t_star = float(first.impact_time[0])
    eps = 1e-6
    times = [0.0, t_star - 2 * eps, t_star - eps, t_star + eps, t_star + 2 * eps]
    ds = opa.simulate_opa(oscillator, times=times, **kwargs)
    assert float(ds.impact_time[0]) == pytest.approx(t_star, abs=1e-12)
    x, v = ds.x_coef.values, ds.v_coef.values
    x_minus, x_plus = 2 * x[:, 2] - x[:, 1], 2 * x[:, 3] - x[:, 4]
    v_minus, v_plus = 2 * v[:, 2] - v[:, 1], 2 * v[:, 3] - v[:, 4]
    tol = 1e-10  # measured residuals ~5e-12 at eps = 1e-6 (5e-10 at 1e-5: O(eps^2))
    assert x_minus[0] == pytest.approx(oscillator.delta, abs=tol)
    assert v_minus[0] == pytest.approx(float(ds.impact_velocity[0]), abs=tol)
    np.testing.assert_allclose(x_plus, x_minus, rtol=0, atol=tol)  # positions do not jump
    mean_law = v_minus * np.r_[-eta, np.ones(len(v_minus) - 1)]
    ensemble_law = -eta * v_minus
    expected, other = (mean_law, ensemble_law) if impact_law == "mean" else (ensemble_law, mean_law)
    np.testing.assert_allclose(v_plus, expected, rtol=0, atol=tol)
    # every higher coefficient takes part: the other law would miss by (1 + eta) |v_i|
    assert np.abs(v_plus - other)[1:].min() > 1e3 * tol


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        (dict(order=-1), ["order", "-1"]),
        (dict(order=2.5), ["order", "2.5"]),
        (dict(order=True), ["order", "True"]),
        (dict(sigma=-0.1), ["sigma", "-0.1"]),
        (dict(sigma=float("nan")), ["sigma", "nan"]),
        (dict(sigma=float("inf")), ["sigma", "inf"]),
        (dict(uncertain="b"), ["uncertain", "'b'"]),
        (dict(truncation="exact"), ["truncation", "'exact'"]),
        (dict(impact_law="average"), ["impact_law", "'average'"]),
        (dict(sigma=0.9), ["sigma", "0.9", "mu", "0.8"]),
        (dict(sigma=0.06, uncertain="c"), ["sigma", "0.06", "c", "0.05"]),
        (dict(sigma=0.6, uncertain="a"), ["sigma", "0.6", "a", "0.5"]),
    ],
)
def test_bad_input_names_parameter_and_value(kwargs, words):
    with pytest.raises(ValueError) as info:
        opa.simulate_opa(opa.preset(PRESET), periods=1, **kwargs)
    message = str(info.value)
    for word in words:
        assert word in message, (word, message)


@pytest.mark.parametrize("uncertain", ["mu", "a", "c"])
def test_allow_negative_runs(uncertain):
    oscillator = opa.preset(PRESET)
    sigma = 1.2 * getattr(oscillator, uncertain)
    ds = opa.simulate_opa(
        oscillator, sigma=sigma, order=4, uncertain=uncertain, allow_negative=True, periods=2
    )
    assert np.all(np.isfinite(ds.x_coef))
    assert ds.attrs["sigma"] == sigma
    assert ds.attrs["allow_negative"] == 1
