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


def test_a_box_computed_by_collocation_gives_the_moments_of_the_reference(truth,
                                                                           monkeypatch):
    """The fallback's projection on a smooth case: K = 2 boxes with the first box's OPA
    system made to fail, so that box comes from the true systems at its tensor Gauss
    nodes. The moments and Sobol indices still match scipy's 14 x 14 tensor reference."""
    import opa._boxes as boxes

    real = boxes.run_boxes

    def first_fails(*args, **kwargs):
        runs, chaos, nodes = real(*args, **kwargs)
        runs[0].failure = "made to fail by the test"
        return runs, chaos, nodes

    monkeypatch.setattr(boxes, "run_boxes", first_fails)
    mean, var, first, total = truth
    ds = free_run(2)
    assert ds.element_method.values.tolist() == [1, 0, 0, 0]
    assert ds.attrs["collocation_elements"] == 1
    assert ds.attrs["collocation_rhs_evaluations"] > 0
    np.testing.assert_allclose(ds.x_mean, mean, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ds.x_var, var, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ds.x_sobol_first[:, 1:], first[:, 1:], rtol=0, atol=1e-5)
    np.testing.assert_allclose(ds.x_sobol_total[:, 1:], total[:, 1:], rtol=0, atol=1e-5)


def test_a_box_whose_system_diverges_is_collocated():
    """(mu, c, a) at twice the issue's scales: near grazing a box's OPA system escapes.
    Uniform boxes compute such a box by collocation of the true systems; the adaptive
    refinement halves it first and collocates what halving did not mend. The collocated
    boxes' mean against the true systems in the box by importance sampling (uniform
    points weighted by the semicircle density), independent of the box's rule."""
    from opa._run import run_batch

    osc = IMPACTING
    system = opa.System(osc, uncertain="mu,c,a", order=2, impact_law="saltation",
                        sigma=(2 * 0.02 * osc.mu, 2 * 0.1 * osc.c, 2 * 0.02 * osc.a))
    ds = opa.simulate_opa(system, periods=10, per_period=8, elements=4)
    collocated = np.flatnonzero(ds.element_method.values)
    assert len(collocated) == ds.attrs["collocation_elements"] >= 1
    assert np.isfinite(ds.x_mean).all() and np.isfinite(ds.x_var).all()
    rng = np.random.default_rng(7)
    e = collocated[0]
    lower, upper = ds.element_lower.values[e], ds.element_upper.values[e]
    xi = lower + (upper - lower) * rng.random((2000, 3))
    weight = np.prod(np.sqrt(1.0 - xi ** 2), axis=1)
    weight /= weight.sum()
    options = opa.SolverOptions()
    batch = run_batch(system.sampled_inputs(options, xi=xi),
                      system.deterministic().initial_state(), ds.time.values,
                      rtol=options.rtol, atol=options.atol)
    x = batch.states[:, :, 0]
    mean = weight @ x
    se = np.sqrt(weight ** 2 @ (x - mean) ** 2)
    # the box holds a change of the impact sequence (its N = 2 projection is rough
    # there: about 0.1 at worst of a standard deviation of 0.65), yet it is that box's
    # motion, not a diverged one
    assert batch.impacts.min() != batch.impacts.max()
    error = np.abs(ds.element_x_coef.values[e, 0] - mean)
    assert np.sqrt(np.mean(error ** 2)) < 0.05 and error.max() < 0.15, (error.max(), se.max())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ElementBudgetWarning)
        adaptive = opa.simulate_opa(system, periods=10, per_period=8, elements="adaptive",
                                    max_elements=128)
    assert np.isfinite(adaptive.x_mean).all()
    assert adaptive.attrs["collocation_elements"] == int(adaptive.element_method.sum())
