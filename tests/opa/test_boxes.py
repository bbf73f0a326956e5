"""Multi-element OPA with several uncertain parameters (``opa/_boxes.py``): against the
scipy tensor reference of tests/opa/test_galerkin.py, the one-parameter elements, and
Monte Carlo of the true impact systems."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import mc
import opa
from opa._elements import ElementBudgetWarning
from tests.opa.test_galerkin import FREE, PER_PERIOD, PERIODS, SCALES, reference

IMPACTING = opa.preset("3.2", omega=3.98)


def free_run(elements, order=4, **kwargs):
    system = opa.System(opa.Oscillator(**FREE), uncertain="mu,c", sigma=SCALES,
                        distribution="semicircle,uniform", order=order)
    return opa.simulate_opa(system, periods=PERIODS, per_period=PER_PERIOD,
                            options=opa.SolverOptions(rtol=1e-12, atol=1e-12),
                            elements=elements, **kwargs)


@pytest.fixture(scope="module")
def truth():
    return reference(("semicircle", "uniform"))


def test_boxes_give_the_moments_and_sobol_indices_of_the_reference(truth):
    """K = 2 boxes per parameter (4 boxes): moments and the Sobol indices of the piecewise
    expansion (by quadrature on its cells) against scipy at a 14 x 14 tensor rule."""
    mean, var, first, total = truth
    ds = free_run(2)
    assert ds.sizes["element"] == 4
    assert np.isnan(ds.x_sobol_first.values[:, 0]).all()  # the deterministic start
    np.testing.assert_allclose(ds.element_probability.sum(), 1.0, rtol=1e-12)
    np.testing.assert_allclose(ds.x_mean, mean, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ds.x_var, var, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ds.x_sobol_first[:, 1:], first[:, 1:], rtol=0, atol=1e-5)
    np.testing.assert_allclose(ds.x_sobol_total[:, 1:], total[:, 1:], rtol=0, atol=1e-5)
    # more boxes at a low order: the error falls (h-convergence)
    errors = [np.abs(free_run(k, order=1).x_var.values - var).max() for k in (1, 2, 4)]
    assert errors[2] < errors[1] < errors[0], errors


def test_a_parameter_of_zero_scale_gives_the_one_parameter_elements():
    """(mu, c) with sigma_mu = 0 and 4 boxes per parameter: the moments of the
    one-parameter OPA of c on 4 equal-probability elements, impacts included."""
    kw = dict(periods=10, per_period=8)
    one = opa.simulate_opa(opa.System(IMPACTING, uncertain="c", sigma=0.005, order=3,
                                      impact_law="saltation"), elements=4, **kw)
    two = opa.simulate_opa(opa.System(IMPACTING, uncertain="mu,c", sigma=(0.0, 0.005),
                                      order=3, impact_law="saltation"), elements=4, **kw)
    assert two.sizes["element"] == 16
    np.testing.assert_allclose(two.x_mean, one.x_mean, rtol=0, atol=1e-10)
    np.testing.assert_allclose(two.x_var, one.x_var, rtol=0, atol=1e-10)


def test_adaptive_boxes_converge_to_monte_carlo_of_the_impact_systems():
    """The paper's section 3.2 set at omega = 3.98 (four impacts in ten periods), mu and
    c uncertain: the RMS error of E[x] against 2^14 scrambled Sobol samples of the true
    systems falls as the element budget grows, and ends below 1e-4."""
    system = opa.System(IMPACTING, uncertain="mu,c", sigma=(0.016, 0.005), order=3,
                        impact_law="saltation")
    ref = mc.simulate_mc(system, samples=2**14, periods=10, per_period=8)
    errors = []
    for budget in (4, 16, 64):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ElementBudgetWarning)
            ds = opa.simulate_opa(system, periods=10, per_period=8, elements="adaptive",
                                  max_elements=budget)
        assert ds.sizes["element"] <= budget
        errors.append(float(np.sqrt(np.mean((ds.x_mean.values - ref.x_mean.values) ** 2))))
    assert errors[2] < errors[1] < errors[0] and errors[2] < 1e-4, errors
    assert float(ref.x_sem.max()) < 0.1 * errors[2]  # the reference is far better


def test_a_box_whose_corners_differ_in_their_impacts_is_flagged():
    """Above the first split: each flag says whether the DMRs at the box's four corners
    (run here one by one) differ in their number of impacts."""
    system = opa.System(IMPACTING, uncertain="mu,c", sigma=(0.128, 0.04), order=1,
                        impact_law="saltation")
    ds = opa.simulate_opa(system, periods=10, per_period=8, elements=6)
    flags = []
    for lower, upper in zip(ds.element_lower.values, ds.element_upper.values):
        counts = set()
        for xi_mu in (lower[0], upper[0]):
            for xi_c in (lower[1], upper[1]):
                osc = IMPACTING.replace(mu=IMPACTING.mu + 0.128 * xi_mu,
                                        c=IMPACTING.c + 0.04 * xi_c)
                counts.add(opa.simulate_dmr(osc, periods=10, per_period=8).sizes.get("impact", 0))
        flags.append(len(counts) > 1)
    assert ds.element_split_inside.values.astype(bool).tolist() == flags
    assert any(flags)


def test_the_budget_and_the_box_count_are_bounded():
    with pytest.raises(ValueError, match="more than 4096"):
        free_run(65, order=1)
    with pytest.warns(ElementBudgetWarning, match="adaptive boxes stopped at"):
        free_run("adaptive", order=1, max_elements=3, tolerance=1e-12)


def test_a_box_whose_system_diverges_is_halved_first_and_named_if_it_stays():
    """(mu, c, a) at twice the issue's scales: near grazing a box's OPA system escapes.
    Uniform boxes stop there naming the box; the adaptive refinement halves such boxes
    first, and when its budget runs out with one still failing it names that box."""
    from opa import SimulationError

    osc = IMPACTING
    system = opa.System(osc, uncertain="mu,c,a", order=2, impact_law="saltation",
                        sigma=(2 * 0.02 * osc.mu, 2 * 0.1 * osc.c, 2 * 0.02 * osc.a))
    with pytest.raises(SimulationError, match=r"box \[.*\] x \[.*\] x \[.*\] of the OPA "
                                              r"\(N=2\) system stopped: the trajectory"):
        opa.simulate_opa(system, periods=10, per_period=8, elements=4)
    with pytest.raises(SimulationError, match=r"the element budget \(max_elements 128\) "
                                              r"ran out before halving it mended it"):
        opa.simulate_opa(system, periods=10, per_period=8, elements="adaptive",
                         max_elements=128)
