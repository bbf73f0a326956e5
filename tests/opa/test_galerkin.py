"""The OPA system with several uncertain parameters (``opa/_galerkin.py``), against an
independent reference: scipy's ``solve_ivp`` at every node of a tensor Gauss rule of the
product law, integrated here without the package's kernel or bases."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy import special
from scipy.integrate import solve_ivp

import opa

# a case that never reaches the wall: the expansion converges spectrally in N
FREE = dict(mu=0.3, a=1.0, c=0.5, f=0.4, omega=1.3, delta=50.0, F0=0.0, x0=0.5, v0=0.0)
SCALES = (0.06, 0.2)  # mu and c
PERIODS, PER_PERIOD = 3, 8


def gauss_rule(law: str, q: int):
    """The q-point Gauss rule of the semicircle (Chebyshev U) or uniform (Legendre) law
    on [-1, 1], from scipy, weights summing to 1."""
    x, w = special.roots_chebyu(q) if law == "semicircle" else special.roots_legendre(q)
    return x, w / w.sum()


@functools.lru_cache(maxsize=8)  # the test modules of a worker share each case's runs
def reference(laws, q=14, scales=SCALES):
    """E[x], Var[x] and the first-order and total Sobol indices of x over the output
    times, from scipy runs at the q x q tensor rule (mu = 0.3 + 0.06 xi_1,
    c = 0.5 + 0.2 xi_2, or the given ``scales``)."""
    (x1, w1), (x2, w2) = gauss_rule(laws[0], q), gauss_rule(laws[1], q)
    omega = FREE["omega"]
    t_out = np.arange(PERIODS * PER_PERIOD + 1) * (2 * np.pi / omega) / PER_PERIOD
    paths = np.empty((q, q, len(t_out)))
    for i, a in enumerate(x1):
        for j, b in enumerate(x2):
            mu, c = FREE["mu"] + scales[0] * a, FREE["c"] + scales[1] * b

            def rhs(t, y, mu=mu, c=c):
                return [y[1], mu * (1 - y[1] ** 2) * y[1] - FREE["a"] * y[0] - c * y[0] ** 3
                        + FREE["f"] * np.cos(omega * t)]

            sol = solve_ivp(rhs, (0, t_out[-1]), [FREE["x0"], FREE["v0"]], method="DOP853",
                            t_eval=t_out, rtol=1e-12, atol=1e-12)
            paths[i, j] = sol.y[0]
    W = np.outer(w1, w2)[:, :, None]
    mean = (W * paths).sum(axis=(0, 1))
    var = (W * (paths - mean) ** 2).sum(axis=(0, 1))
    given1 = (w2[None, :, None] * paths).sum(axis=1)  # E[x | xi_1]
    given2 = (w1[:, None, None] * paths).sum(axis=0)
    first = np.array([(w1[:, None] * (given1 - mean) ** 2).sum(axis=0),
                      (w2[:, None] * (given2 - mean) ** 2).sum(axis=0)])
    # total: E over the other parameter of Var over this one
    var_over1 = (w1[:, None, None] * (paths - given2[None]) ** 2).sum(axis=0)  # (q2, T)
    var_over2 = (w2[None, :, None] * (paths - given1[:, None]) ** 2).sum(axis=1)
    total = np.array([(w2[:, None] * var_over1).sum(axis=0),
                      (w1[:, None] * var_over2).sum(axis=0)])
    with np.errstate(all="ignore"):
        out = mean, var, first / var, total / var
    for array in out:  # shared by every caller (the cache): read-only
        array.flags.writeable = False
    return out


def run(laws, order, basis="total"):
    system = opa.System(opa.Oscillator(**FREE), uncertain="mu,c", sigma=SCALES,
                        distribution=",".join(laws), order=order)
    return opa.simulate_opa(system, periods=PERIODS, per_period=PER_PERIOD,
                            options=opa.SolverOptions(rtol=1e-12, atol=1e-12), basis=basis)


@pytest.fixture(scope="module", params=[("semicircle", "uniform"), ("uniform", "uniform")])
def case(request):
    return request.param, reference(request.param)


def test_moments_converge_spectrally_to_the_tensor_reference(case):
    """The error of E[x] and Var[x] falls by orders of magnitude from N = 1 to N = 6 and
    ends near the integration tolerance."""
    laws, (mean, var, _, _) = case
    errors = []
    for order in (1, 2, 4, 6):
        ds = run(laws, order)
        errors.append(max(np.abs(ds.x_mean.values - mean).max(),
                          np.abs(ds.x_var.values - var).max()))
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-7 and errors[-1] < errors[0] * 1e-5, errors


def test_sobol_indices_from_the_coefficients_match_the_reference_anova(case):
    laws, (_, var, first, total) = case
    ds = run(laws, 6)
    live = var > 1e-10 * var.max()  # t = 0 has no variance: NaN indices there
    np.testing.assert_allclose(ds.x_sobol_first.values[:, live], first[:, live], atol=1e-6)
    np.testing.assert_allclose(ds.x_sobol_total.values[:, live], total[:, live], atol=1e-6)
    assert np.isnan(ds.x_sobol_first.values[:, 0]).all()  # the deterministic start
    assert ds.x_sobol_first.dims == ("parameter", "time")
    assert list(ds.parameter.values) == ["mu", "c"]


def test_the_multi_index_sets_nest_and_are_carried():
    total, tensor = run(("uniform", "uniform"), 3), run(("uniform", "uniform"), 3, "tensor")
    assert total.sizes["term"] == 10 and tensor.sizes["term"] == 16
    assert total.multi_index.dims == ("term", "parameter")
    assert (total.multi_index.values.sum(axis=1) <= 3).all()
    hyperbolic = run(("uniform", "uniform"), 3, "hyperbolic:0.5")
    assert hyperbolic.sizes["term"] < total.sizes["term"]


def test_a_parameter_of_zero_scale_gives_the_one_dimensional_opa():
    """(mu, c) with sigma_c = 0: the one-parameter OPA's moments, with impacts."""
    osc = opa.preset("3.2", omega=3.98)
    one = opa.simulate_opa(opa.System(osc, uncertain="mu", sigma=0.016, order=3),
                           periods=10, per_period=8)
    two = opa.simulate_opa(opa.System(osc, uncertain="mu,c", sigma=(0.016, 0.0), order=3),
                           periods=10, per_period=8)
    np.testing.assert_allclose(two.x_mean.values, one.x_mean.values, rtol=0, atol=1e-12)
    np.testing.assert_allclose(two.x_var.values, one.x_var.values, rtol=0, atol=1e-12)
    assert one.impact_time.size > 0


@pytest.mark.parametrize("kwargs, words", [
    (dict(initial=[[0.0] * 6, [0.0] * 6]), "initial is not available with several"),
    (dict(basis="sparse"), "basis must be one of total, tensor, hyperbolic:Q"),
    (dict(basis="hyperbolic:x"), "basis hyperbolic:Q takes a number"),
])
def test_what_several_parameters_do_not_take_yet_is_refused_by_name(kwargs, words):
    system = opa.System(uncertain="mu,c", sigma=0.01, order=2)
    with pytest.raises(ValueError, match=words):
        opa.simulate_opa(system, periods=1, **kwargs)


def test_a_basis_with_one_parameter_is_refused():
    with pytest.raises(ValueError, match="applies with several uncertain parameters"):
        opa.simulate_opa(opa.System(order=2), periods=1, basis="tensor")


def test_sizes_past_the_bounds_are_refused_before_any_work():
    """P = C(N + d, d) terms on up to (2N + 1)^d nodes, counted before anything is built;
    Q x P past MAX_NODE_TERMS refused naming the order, the basis and the parameters."""
    from opa._galerkin import MAX_NODE_TERMS, check_chaos_size

    system = opa.System(uncertain="mu,a,c", sigma=0.01, order=6)
    assert check_chaos_size(system) == (84, 13**3)
    assert check_chaos_size(system, "tensor") == (7**3, 13**3)
    big = system.replace(order=40)
    assert 12341 * 81**3 > MAX_NODE_TERMS
    with pytest.raises(ValueError, match=r"order 40 with 3 uncertain parameters \(mu,a,c\) "
                                         r"and the total basis makes 12341 terms"):
        opa.simulate_opa(big, periods=1)
