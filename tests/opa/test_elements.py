"""Multi-element OPA: exact assembly, the no-impact limit, elements at a discontinuity
established with scipy, the saltation impact law against finite differences of the scipy
reference, and (slow) convergence against Monte Carlo at sigma = 0.05."""

import math

import numpy as np
import pytest
from scipy import integrate

from mc import simulate_mc
from opa import Oscillator, SolverOptions, preset, simulate_opa
from opa._system import System
from opa._elements import (
    SHARED_SPLITS,
    ElementBudgetWarning,
    SplitCache,
    ElementRun,
    assemble,
    collocate_element,
    global_coefficients,
    run_element,
    run_elements,
    split_edges,
    straddling,
)
from opa._measure import beta, parse, semicircle
from opa._model import time_grid
from opa._splits import event_sequence
from tests.reference import reference_trajectory
from tests.reference_splits import GRAZING_CASE
from tests.truths import semicircle_density

OPTIONS = SolverOptions(rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("law", [semicircle(), beta(2.0, 3.0)])
def test_assembly_is_exact_for_a_polynomial_response(law):
    """x(xi) = 1 + 2 xi - 3 xi^2 + xi^3 projected on each element's basis (degree 3,
    exactly representable): the assembled mean and variance are its exact moments."""
    poly = np.polynomial.Polynomial([1.0, 2.0, -3.0, 1.0])
    edges = [-1.0, -0.3, 0.1, 0.8, 1.0]
    runs = []
    for a, b in zip(edges[:-1], edges[1:]):
        element = law.restrict(a, b)
        x, w = element.gauss(6)
        basis = element.basis(3, x)
        coef = (basis * w) @ poly(x)
        runs.append(ElementRun(a, b, element.probability(), coef[:, None], coef[:, None], 0, 0))
    got = assemble(runs)
    dens = {"semicircle": semicircle_density,
            "beta:2,3": lambda t: 12 * ((1 + t) / 2) * ((1 - t) / 2) ** 2 / 2}[law.name]
    mean = integrate.quad(lambda t: dens(t) * poly(t), -1, 1)[0]
    second = integrate.quad(lambda t: dens(t) * poly(t) ** 2, -1, 1)[0]
    assert got["x_mean"][0] == pytest.approx(mean, abs=1e-13)
    assert got["x_var"][0] == pytest.approx(second - mean**2, abs=1e-12)


def test_without_impacts_one_element_is_the_paper_opa_and_more_converge_spectrally():
    osc = Oscillator(delta=10.0, omega=3.98)  # the wall is never reached
    times = time_grid(3.98, 3, 4)
    kw = dict(sigma=0.2, times=times, options=OPTIONS)
    one = simulate_opa(osc, order=4, **kw)
    same = simulate_opa(osc, order=4, elements=1, **kw)
    np.testing.assert_array_equal(one.x_mean.values, same.x_mean.values)
    np.testing.assert_array_equal(one.x_var.values, same.x_var.values)
    ref = simulate_opa(osc, order=10, elements=4, **kw)
    err = [float(np.abs(simulate_opa(osc, order=n, elements=4, **kw).x_var.values
                        - ref.x_var.values).max()) for n in (1, 2, 3, 4, 5)]
    # geometric decay, about three decades per order, down to round-off by N = 4
    assert all(b < 1e-2 * a for a, b in zip(err[:3], err[1:4])), err
    assert max(err[3:]) < 1e-15, err
    # and K elements of order N agree with one element of high order
    np.testing.assert_allclose(ref.x_mean.values, simulate_opa(osc, order=10, **kw)
                               .x_mean.values, atol=1e-11)


def test_parallel_elements_equal_single_runs():
    osc = Oscillator(omega=3.98)
    times = time_grid(3.98, 4, 4)
    law = semicircle()
    system = System(osc, sigma=0.02, order=2, uncertain="mu", impact_law="saltation")
    parts = [law.restrict(-1.0, 0.0), law.restrict(0.0, 0.5), law.restrict(0.5, 1.0)]
    together = run_elements(system, OPTIONS, parts, times=times)
    for element, run in zip(parts, together):
        alone = run_element(system, OPTIONS, element, times=times)
        np.testing.assert_array_equal(run.x_coef, alone.x_coef)


def test_an_element_edge_sits_on_the_scipy_grazing():
    """GRAZING_CASE (tests/reference_splits.py): for mu < mu_split the sampled system
    makes 3 impacts up to t_end, above it 2. With mu_bar = 0.78 and sigma = 0.01 the
    split is at xi_s = (mu_split - 0.78) / 0.01; an element edge must sit there, and
    every Gauss node of the two elements beside it must make its side's count."""
    mu_bar, sigma = 0.78, 0.01
    osc = Oscillator(mu=mu_bar, **GRAZING_CASE["model"])
    t_end = GRAZING_CASE["t_end"]
    edges, _ = split_edges(System(osc, sigma=sigma, uncertain="mu"), OPTIONS, semicircle(),
                           t_end=t_end)
    xi_s = (GRAZING_CASE["mu_split"] - mu_bar) / sigma
    k = int(np.argmin(np.abs(edges - xi_s)))
    assert abs(edges[k] - xi_s) < 1e-5  # the split in mu to 1e-7 (see test_splits)
    for (a, b), count in (((edges[k - 1], edges[k]), GRAZING_CASE["count_below"]),
                          ((edges[k], edges[k + 1]), GRAZING_CASE["count_above"])):
        nodes, _ = semicircle().restrict(a, b).gauss(4)
        for xi in nodes:
            seq = event_sequence(osc.replace(mu=mu_bar + sigma * xi), OPTIONS, t_end)
            assert seq.count(t_end) == count


def test_split_edges_keep_their_splits_where_the_caller_says(monkeypatch):
    """A caller's own SplitCache: a problem located once while kept, the oldest forgotten
    past its size, the shared one left alone."""
    located = []
    monkeypatch.setattr("opa._splits.find_splits",
                        lambda system, *args, **kw: located.append(system.oscillator.mu)
                        or ([], False))
    own, shared = SplitCache(size=1), len(SHARED_SPLITS)

    def edges(mu):
        system = System(Oscillator(mu=mu), sigma=0.01, uncertain="mu")
        return split_edges(system, OPTIONS, semicircle(), t_end=1.0, splits=own)

    edges(0.8), edges(0.8), edges(0.7), edges(0.8)
    assert located == [0.8, 0.7, 0.8] and len(own) == 1 and len(SHARED_SPLITS) == shared
    with pytest.raises(ValueError, match="size"):
        SplitCache(size=0)


def test_saltation_law_matches_finite_differences_of_the_reference():
    """Small sigma, N = 1: x_1(t) = E[x U_1] ~ (sigma / 2) dx/dmu (U_1 = 2 xi,
    E[xi U_1] = 1/2). Between the first and the second impact, dx/dmu of the scipy
    reference by central differences must match x_1 / (sigma / 2) with the saltation
    law; the ensemble and mean laws leave x_1 unreflected and do not."""
    model = dict(a=0.5, c=0.05, f=1.5, omega=3.98, eta=0.8, delta=0.0, F0=0.1, a1=1.0,
                 omega1=1.0, n=2, x0=-1.0, v0=0.0)
    T = 2 * math.pi / 3.98
    times = np.array([0.0, 1.5 * T, 2.0 * T, 3.0 * T])  # first impact at 1.03 T, next 3.73 T
    h = 1e-6
    plus = reference_trajectory(mu=0.8 + h, t_out=times, **model)
    minus = reference_trajectory(mu=0.8 - h, t_out=times, **model)
    dxdmu = (plus["x"] - minus["x"]) / (2 * h)
    assert len(plus["impact_time"]) == 1 and len(minus["impact_time"]) == 1
    sigma = 1e-5
    osc = Oscillator(mu=0.8, **model)
    got = {law: simulate_opa(osc, sigma=sigma, order=1, impact_law=law, times=times,
                             options=OPTIONS).x_coef.values[1] / (sigma / 2)
           for law in ("saltation", "ensemble", "mean")}
    np.testing.assert_allclose(got["saltation"][1:], dxdmu[1:], rtol=1e-3)
    for law in ("ensemble", "mean"):
        assert np.max(np.abs(got[law][1:] / dxdmu[1:] - 1)) > 0.1


@pytest.mark.parametrize("kw, message", [
    (dict(elements=4, truncation="paper"), "truncation='paper'"),
    (dict(elements=0), "positive integer"),
    (dict(elements="many"), "'adaptive'"),
    (dict(elements=[-1.0, 0.5, 0.2, 1.0]), "edges must increase"),
    (dict(elements=[-0.9, 1.0]), "edges must increase"),
    (dict(elements="adaptive", max_elements=0), "max_elements"),
    (dict(distribution="beta:2"), "distribution must be one of"),
])
def test_bad_element_arguments_are_named(kw, message):
    with pytest.raises(ValueError, match=message):
        simulate_opa(Oscillator(), sigma=0.01, order=1, periods=1, **kw)


def test_monte_carlo_samples_the_same_law():
    xi_mean = 2.0 / 5.0 * 2 - 1  # Beta(2, 3) on [-1, 1]
    ds = simulate_mc(Oscillator(), sigma=0.05, samples=4096, distribution="beta:2,3",
                     periods=1, progress=False, order=2, keep_paths=True)
    assert float(ds.xi.mean()) == pytest.approx(xi_mean, abs=1e-3)
    assert ds.attrs["distribution"] == "beta:2,3"
    # the coefficients are on the law's own orthonormal basis (p_0 = 1)
    np.testing.assert_allclose(ds.x_coef.values[0], ds.x_mean.values, rtol=1e-12)
    p1 = parse("beta:2,3").basis(1, ds.xi.values)[1]
    np.testing.assert_allclose(ds.x_coef.values[1], (p1 * ds.weight.values) @ ds.x.values,
                               rtol=1e-10, atol=1e-14)


@pytest.mark.slow
def test_adaptive_elements_converge_against_monte_carlo_at_sigma_005():
    """Section 3.2, omega = 3.98, sigma = 0.05, 10 periods: the paper's OPA is off by
    7e-2; adaptive multi-element OPA (saltation law) reaches 1e-4 against 2^16 Sobol
    samples and keeps falling with the element budget."""
    osc = Oscillator(omega=3.98)
    opts = SolverOptions(rtol=1e-9, atol=1e-9)
    times = time_grid(3.98, 10, 8)
    ref = simulate_mc(osc, sigma=0.05, samples=2**16, sampler="sobol", seed=1, order=0,
                      times=times, options=opts, progress=False)
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    single = simulate_opa(osc, sigma=0.05, order=4, times=times, options=opts)
    assert rms(single.x_mean.values - ref.x_mean.values) > 5e-2
    with pytest.warns(ElementBudgetWarning):  # tolerance 1e-14: the budget stops each
        errs = [rms(simulate_opa(osc, sigma=0.05, order=1, times=times, options=opts,
                                 impact_law="saltation", elements="adaptive", tolerance=1e-14,
                                 max_elements=b).x_mean.values - ref.x_mean.values)
                for b in (16, 64, 256)]
    assert errs[-1] < 1e-4
    assert errs[0] > errs[1] > errs[2]


def test_global_coefficients_of_a_piecewise_surrogate_against_quadrature():
    """A surrogate that is a different cubic on each element: its coefficients E[x U_i]
    in the semicircle's Chebyshev basis against scipy quad of the piecewise function."""
    from scipy import special

    edges = np.array([-1.0, -0.4, 0.3, 1.0])
    polys = [np.polynomial.Polynomial(c) for c in ([1, 2, 0, 1], [-1, 0.5, 3, 0],
                                                    [0.2, -1, 0, 2])]
    law = semicircle()
    coefs, P = [], []
    for (a, b), poly in zip(zip(edges[:-1], edges[1:]), polys):
        element = law.restrict(a, b)
        x, w = element.gauss(6)
        coefs.append(((element.basis(3, x) * w) @ poly(x))[:, None])
        P.append(element.probability())
    got = global_coefficients(np.array(coefs), edges, P, law, 5)[:, 0]

    def piecewise(t):
        return polys[int(np.searchsorted(edges, t, side="right") - 1)](t)

    want = [sum(integrate.quad(lambda t: piecewise(t) * special.eval_chebyu(i, t)
                               * semicircle_density(t), a, b, epsabs=1e-13)[0]
                for a, b in zip(edges[:-1], edges[1:])) for i in range(6)]
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_collocation_of_an_element_is_the_projection_of_the_scipy_systems():
    """The fallback of a failed element: the true systems at the element's N+1 Gauss
    nodes (scipy reference here), projected on its orthonormal basis."""
    osc = Oscillator(omega=3.98)
    law = beta(2.0, 3.0)
    element = law.restrict(-0.6, 0.2)
    times = time_grid(3.98, 3, 4)
    system = System(osc, sigma=0.05, order=2, distribution="beta:2,3")
    run = collocate_element(system, OPTIONS, element, times=times)
    nodes, weights = element.gauss(3)
    model = {k: getattr(osc, k) for k in ("a", "c", "f", "omega", "eta", "delta", "F0",
                                          "a1", "omega1", "n", "x0", "v0")}
    x = np.array([reference_trajectory(mu=osc.mu + 0.05 * xi, t_out=times, **model)["x"]
                  for xi in nodes])
    want = (element.basis(2, nodes) * weights) @ x
    assert run.method == "collocation"
    np.testing.assert_allclose(run.x_coef, want, atol=1e-8)
    # the discrete rule keeps the basis orthonormal: mean and variance are the rule's
    np.testing.assert_allclose(run.var, weights @ (x - weights @ x) ** 2, atol=1e-8)


def test_elements_default_to_the_saltation_law_and_failed_elements_are_collocated():
    """With elements and keywords the law is saltation (a System keeps its own); beta:2,3
    at sigma = 0.05 over 100 periods: OPA systems of several elements diverge, and each
    is computed by collocation instead of failing the run."""
    osc = Oscillator(omega=3.98)
    ds = simulate_opa(osc, sigma=0.05, order=4, periods=100, elements=16,
                      distribution="beta:2,3")
    assert ds.attrs["impact_law"] == "saltation"
    assert ds.attrs["collocation_elements"] == int(ds.element_method.sum()) > 0
    assert np.isfinite(ds.x_mean).all() and np.isfinite(ds.element_x_coef).all()
    # every element of this long run contains a change of the impact sequence
    assert ds.attrs["straddling_elements"] == 16
    kept = simulate_opa(System(osc, sigma=0.05, order=1), periods=2, elements=2)
    assert kept.attrs["impact_law"] == "mean"


def test_straddling_flags_the_element_with_the_scipy_grazing():
    """GRAZING_CASE: the scipy reference's split at mu_split lies in exactly one element."""
    mu_bar, sigma = 0.78, 0.01
    osc = Oscillator(mu=mu_bar, **GRAZING_CASE["model"])
    xi_s = (GRAZING_CASE["mu_split"] - mu_bar) / sigma
    edges = np.sort(np.r_[-1.0, 1.0, xi_s - 0.05, xi_s + 0.05, xi_s + 0.3])
    edges = edges[(edges >= -1) & (edges <= 1)]
    flags = straddling(System(osc, sigma=sigma), OPTIONS, edges, GRAZING_CASE["t_end"])
    inside = (edges[:-1] < xi_s) & (xi_s < edges[1:])
    np.testing.assert_array_equal(flags, inside.astype(np.int8))
    assert flags.sum() == 1


def test_adaptive_runs_say_whether_the_tolerance_was_met():
    osc = Oscillator(omega=3.98)
    kw = dict(sigma=0.05, order=1, periods=3, per_period=4, elements="adaptive")
    met = simulate_opa(osc, tolerance=1.0, **kw)
    assert met.attrs["tolerance_met"] == 1 and met.attrs["stopped_by"] == "tolerance"
    with pytest.warns(ElementBudgetWarning, match="max_elements"):
        cut = simulate_opa(osc, tolerance=1e-14, max_elements=4, **kw)
    assert cut.attrs["tolerance_met"] == 0 and cut.attrs["stopped_by"] == "element budget"
    assert cut.sizes["element"] == 4
    # the estimate is the RMS change of E[x] in the last step: positive and finite
    assert 0 < cut.attrs["error_estimate"] < 1


def test_adaptive_refinement_does_not_get_worse_with_the_budget():
    """Issue 24: uniform law, sigma = 0.03 (section 3.2, omega = 3.98, 10 periods): four
    elements cut in probability alone were 4x worse than one element (9.2e-2 against
    2.2e-2, an element straddling the grazing under the saltation law). Against a Monte
    Carlo ensemble of the true systems, the adaptive error must not grow with the budget."""
    osc = Oscillator(omega=3.98)
    kw = dict(sigma=0.03, order=1, periods=10, per_period=8, distribution="uniform")
    ref = simulate_mc(osc, samples=2**13, sampler="sobol", seed=1, progress=False, **kw)
    errors = []
    for budget in (1, 2, 4, 8, 16):  # one element (no budget to refine), then adaptive
        if budget == 1:
            ds = simulate_opa(osc, elements=1, **kw)
        else:
            with pytest.warns(ElementBudgetWarning):
                ds = simulate_opa(osc, elements="adaptive", max_elements=budget, **kw)
        errors.append(float(np.sqrt(np.mean((ds.x_mean.values - ref.x_mean.values) ** 2))))
    assert all(b <= a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 0.05 * errors[0]


@pytest.mark.parametrize("budget", [0, 1, 1025, 2.5, True])
def test_the_element_budget_has_one_rule_everywhere(budget, capsys):
    """max_elements is an integer in 2..1024 in simulate_opa as in validate's config (a budget
    of one element cannot refine); the CLI refuses it naming the value, exit status 2."""
    from compare import load_config
    from opa.cli._main import main

    with pytest.raises(ValueError, match=r"max_elements must be an integer in 2\.\.1024"):
        simulate_opa(Oscillator(), sigma=0.01, order=1, periods=1, elements="adaptive",
                     max_elements=budget)
    with pytest.raises(ValueError, match=r"max_elements must be an integer in 2\.\.1024"):
        load_config(None, elements="adaptive", max_elements=budget)
    if isinstance(budget, int) and not isinstance(budget, bool):
        try:
            status = main(["simulate", "opa", "--periods", "1", "--elements", "adaptive",
                           "--max-elements", str(budget)])
        except SystemExit as exit:  # argparse's own refusal of a type
            status = exit.code
        assert status == 2
        err = capsys.readouterr().err
        assert "max" in err and str(budget) in err and err.count("\n") == 1


def test_a_true_system_of_several_parameters_that_stops_is_named_by_its_point():
    """true_runs with rows of xi (several parameters): the message shows the row."""
    from opa._elements import true_runs
    from opa._run import SimulationError

    system = System(preset("3.2"), uncertain="mu,c", sigma=(0.01, 0.001))
    with pytest.raises(SimulationError, match=r"xi = \(0.1, -0.2\) stopped"):
        true_runs(system, SolverOptions(max_steps=10), np.array([[0.1, -0.2]]),
                  np.linspace(0.0, 10.0, 5), what="a sample at")
