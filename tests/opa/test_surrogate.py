"""The OPA surrogate x_hat(t, xi): its moments against quadrature of the law's density
(scipy), and its values against the true systems where OPA is known to be exact."""

import functools

import numpy as np
import pytest
from scipy import integrate, stats

from opa import Oscillator, simulate_opa
from opa._surrogate import surrogate, surrogate_moments
from tests.reference import reference_trajectory

#: densities of the laws on [-1, 1], written out here (scipy)
DENSITY = {"semicircle": stats.beta(1.5, 1.5, loc=-1, scale=2).pdf,
           "uniform": stats.uniform(loc=-1, scale=2).pdf,
           "beta:2,3": stats.beta(2, 3, loc=-1, scale=2).pdf}


@pytest.mark.parametrize("law, elements", [("semicircle", None), ("uniform", None),
                                           ("beta:2,3", 3), ("semicircle", "adaptive")])
def test_moments_of_the_surrogate_are_the_runs_against_quadrature(law, elements):
    budget = {"max_elements": 6} if elements == "adaptive" else {}
    ds = simulate_opa(Oscillator(omega=3.98), sigma=0.05, order=3, periods=2, per_period=2,
                      elements=elements, distribution=None if law == "semicircle" else law,
                      **budget)
    edges = ds.element_edges.values
    pdf = DENSITY[law]

    @functools.lru_cache(maxsize=None)
    def values(t):  # every output at once: quad asks for the same t for each moment
        return surrogate(ds, [t])[0][0]

    for j in (0, 2, 4):  # outputs before, at and after the first impact

        def integrand(t, power, j=j):
            return values(t)[j] ** power * pdf(t)

        first = sum(integrate.quad(integrand, a, b, args=(1,), epsabs=1e-13)[0]
                    for a, b in zip(edges[:-1], edges[1:]))
        second = sum(integrate.quad(integrand, a, b, args=(2,), epsabs=1e-13)[0]
                     for a, b in zip(edges[:-1], edges[1:]))
        moments = surrogate_moments(ds)
        assert first == pytest.approx(float(ds.x_mean[j]), abs=1e-9)
        assert moments["x_mean"][j] == pytest.approx(first, abs=1e-9)
        assert moments["x_second"][j] == pytest.approx(second, abs=1e-9)
        assert float(ds.x_var[j]) == pytest.approx(second - first**2, abs=1e-9)


def test_before_the_first_impact_the_surrogate_is_each_sampled_system():
    """Before any impact x(t, xi) is smooth in xi and OPA of order 8 converges
    spectrally: x_hat at a few xi equals the scipy reference of that system."""
    osc = Oscillator(omega=3.98)
    times = np.linspace(0.0, 1.0, 5)  # the first impact is later (t ~ 1.6)
    ds = simulate_opa(osc, sigma=0.05, order=8, times=times)
    xi = np.array([-0.9, -0.2, 0.5, 1.0])
    x_hat, v_hat = surrogate(ds, xi)
    model = {k: getattr(osc, k) for k in ("a", "c", "f", "omega", "eta", "delta", "F0",
                                          "a1", "omega1", "n", "x0", "v0")}
    for m, point in enumerate(xi):
        ref = reference_trajectory(mu=osc.mu + 0.05 * point, t_out=times, **model)
        assert len(ref["impact_time"]) == 0
        np.testing.assert_allclose(x_hat[m], ref["x"], atol=1e-8)
        np.testing.assert_allclose(v_hat[m], ref["v"], atol=1e-8)


def test_points_outside_the_support_are_refused():
    ds = simulate_opa(Oscillator(), sigma=0.01, order=1, periods=1)
    with pytest.raises(ValueError, match=r"support \[-1, 1\]"):
        surrogate(ds, [1.5])
    with pytest.raises(ValueError, match="must be an OPA run"):
        surrogate(ds.assign_attrs(model="mc"), [0.0])
