"""An uncertain restitution eta or wall delta (the impact law at each node, issue 43) and
an uncertain drive f, omega or F0 (each node's own forcing and kick, issue 42).

Independent reference: scipy's event integrator of ``tests/impact_truths.py`` run at the
20 Gauss-Legendre nodes of the uniform law, on Shaw & Holmes' linear impact oscillator
started on its stable period-1 orbit (one impact per period for every eta and delta of
the support, so E[x] and Var[x] are smooth in xi and the rule is exact to round-off);
for the drive, scipy runs of eq. (1) at 12 Gauss-Legendre nodes, the wall out of reach.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import mc
import opa
from opa import _kernel as kernel
from opa._run import Variational, run
from tests.impact_truths import shaw_holmes_flight, shaw_holmes_orbits, two_wall_impacts

ZETA, OMEGA, DELTA, R = 0.05, 2.5, 0.0, 0.8
T = 2 * math.pi / OMEGA
ENDS = np.arange(1, 13) * T / 4  # three periods, four outputs each
SIGMA = 0.05


def start():
    orbit = shaw_holmes_orbits(ZETA, OMEGA, DELTA, R)[0]
    return shaw_holmes_flight(ZETA, OMEGA, DELTA, R, orbit["phase"], orbit["velocity"],
                              T - orbit["phase"])[:, 0]


def oscillator() -> opa.Oscillator:
    y0 = start()
    return opa.Oscillator(force=opa.ForceLaw("-2*zeta*v - x", zeta=ZETA), a=1.0, f=1.0,
                          omega=OMEGA, eta=R, delta=DELTA, F0=0.0, omega1=OMEGA, x0=y0[0],
                          v0=y0[1])


def scipy_moments(name: str):
    """E[x] and Var[x] at ENDS by a 20-node Gauss-Legendre rule of scipy runs."""
    nodes, weights = np.polynomial.legendre.leggauss(20)
    weights = weights / 2
    y0 = start()
    x = np.empty((len(nodes), len(ENDS)))
    for k, z in enumerate(nodes):
        eta = R + SIGMA * z if name == "eta" else R
        delta = DELTA + SIGMA * z if name == "delta" else DELTA
        for j, t_end in enumerate(ENDS):
            x[k, j] = two_wall_impacts(lambda x, v: -2 * ZETA * v - x, 1.0, OMEGA,
                                       (None, delta), (None, eta), y0, t_end)["state"][0]
    mean = weights @ x
    return mean, weights @ (x - mean) ** 2


@pytest.mark.parametrize("name", ["eta", "delta"])
def test_the_impact_laws_with_an_uncertain_impact_parameter_against_scipy(name):
    """Measured (max over the outputs): E[x] errors 8.4e-4 (eta) and 1.8e-2 (delta) with
    one element under every law, the mean constraint's error, falling 16-fold per
    four-fold more elements; the saltation law's Var[x] error 8e-7 (eta) and 5e-4
    (delta), 340 and 33 times below the mean law's, which misses the variance."""
    mean, var = scipy_moments(name)
    errors = {}
    for law in ("mean", "saltation"):
        for elements in (None, 4, 16):
            system = opa.System(oscillator(), uncertain=name, sigma=SIGMA,
                                distribution="uniform", order=3, impact_law=law)
            ds = opa.simulate_opa(system, times=np.concatenate([[0.0], ENDS]),
                                  elements=elements)
            errors[law, elements] = (float(np.abs(ds.x_mean[1:] - mean).max()),
                                     float(np.abs(ds.x_var[1:] - var).max()))
    assert var.max() > 1e-4  # the impact parameter matters
    for law in ("mean", "saltation"):
        e1, e4, e16 = (errors[law, k][0] for k in (None, 4, 16))
        assert e1 > 10 * e4 > 100 * e16, (law, e1, e4, e16)
        assert e16 < 1e-4, (law, e16)
    assert errors["saltation", None][1] < errors["mean", None][1] / 20, errors
    assert errors["saltation", 16][1] < 1e-5, errors


def test_monte_carlo_samples_the_impact_parameters():
    """Each Monte Carlo sample is the true system at its own eta and delta (the scipy
    run at the sample's xi)."""
    for name in ("eta", "delta"):
        system = opa.System(oscillator(), uncertain=name, sigma=SIGMA, distribution="uniform")
        ds = mc.simulate_mc(system, samples=4, times=np.array([0.0, 2 * T]), keep_paths=True,
                            progress=False)
        for xi, x in zip(ds.xi.values.ravel(), ds.x.values[:, -1]):
            eta = R + SIGMA * xi if name == "eta" else R
            delta = DELTA + SIGMA * xi if name == "delta" else DELTA
            want = two_wall_impacts(lambda x, v: -2 * ZETA * v - x, 1.0, OMEGA, (None, delta),
                                    (None, eta), start(), 2 * T)["state"][0]
            assert x == pytest.approx(want, abs=1e-8), (name, xi)


@pytest.mark.parametrize("fields, words", [
    (dict(uncertain="eta", sigma=0.3), "every restitution must be in (0, 1]"),
    (dict(uncertain="delta", sigma=2.0), "below the start x0"),
    (dict(uncertain="eta", sigma=0.05, truncation="paper"), "truncation 'galerkin'"),
])
def test_impossible_impact_parameters_are_refused_in_one_line(fields, words):
    with pytest.raises(ValueError) as err:
        opa.simulate_opa(opa.System(opa.preset("3.2"), **fields), periods=1)
    assert words in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("uncertain", ["eta", "delta"])
@pytest.mark.parametrize("law", ["mean", "ensemble"])
def test_tangents_through_impacts_at_nodes_are_the_flow_maps_derivative(law, uncertain):
    """With an uncertain eta or delta the impact reads each node (the ensemble law
    reflects each node with its own eta): W after three periods with impacts is the
    derivative of the OPA flow map, checked against central differences of plain runs
    in every direction of the state (three periods, one impact)."""
    sigma = 0.05 if uncertain == "eta" else 0.02
    system = opa.System(opa.preset("3.2", omega=3.98), uncertain=uncertain, sigma=sigma,
                        order=2, impact_law=law)
    inputs = system.kernel_inputs(opa.SolverOptions(rtol=1e-12, atol=1e-12))
    assert inputs.cfg[kernel.C_WALL_NODES] == 1
    y0 = system.initial_state() + 0.01 * np.arange(len(system.initial_state()))
    times = np.linspace(0.0, 3 * system.oscillator.forcing_period, 4)
    kw = dict(rtol=1e-12, atol=1e-12)
    plain = run(inputs, y0, times, events=True, **kw)
    assert plain.impacts >= 1  # the window holds an impact, not grazing
    W = run(inputs, y0, times, variational=Variational(np.eye(len(y0))), **kw).tangent
    eps = 1e-6
    for j in range(len(y0)):
        step = eps * np.eye(len(y0))[j]
        ahead = run(inputs, y0 + step, times, **kw).states[-1]
        behind = run(inputs, y0 - step, times, **kw).states[-1]
        np.testing.assert_allclose(W[:, j], (ahead - behind) / (2 * eps), rtol=1e-5,
                                   atol=1e-6, err_msg=f"column {j}")


def test_tangents_are_refused_under_the_saltation_law_at_nodes():
    system = opa.System(opa.preset("3.2"), uncertain="eta", sigma=0.05, order=2,
                        impact_law="saltation")
    inputs = system.kernel_inputs(opa.SolverOptions())
    assert inputs.p[kernel.P_ETA] == pytest.approx(0.8, abs=1e-15)  # the rule's mean
    y0 = system.initial_state()
    with pytest.raises(ValueError, match="take the impact law mean or ensemble"):
        run(inputs, y0, np.array([0.0, 1.0]), rtol=1e-8, atol=1e-8,
            variational=Variational(np.eye(len(y0))))


# ------------------------------------------------------------------ an uncertain drive
def scipy_paper_flight(osc: opa.Oscillator, times) -> np.ndarray:
    """x(t) of eq. (1) with the wall out of reach, the one impulse in [0, 3 T] at t = 0
    (a kick of F0 (1 + a1 sin 0) = F0), by scipy."""
    def rhs(t, y):
        x, v = y
        return [v, osc.mu * (1 - v * v) * v - osc.a * x - osc.c * x**3
                + osc.f * math.cos(osc.omega * t)]
    return solve_ivp(rhs, (0.0, times[-1]), [osc.x0, osc.v0 + osc.F0], t_eval=times,
                     method="DOP853", rtol=1e-12, atol=1e-12).y[0]


@pytest.mark.parametrize("name, sigma", [("f", 0.1), ("omega", 0.02), ("F0", 0.05)])
def test_an_uncertain_drive_converges_to_quadrature_of_scipy_runs(name, sigma):
    """f, omega or F0 uniform, no impacts over three periods: the OPA system's E[x] and
    Var[x] against a 12-node Gauss-Legendre rule of scipy runs; the error falls
    geometrically with the order (each node's own drive and kick)."""
    osc = opa.preset("3.2", delta=50.0)
    T3 = 3 * 2 * math.pi / osc.omega
    times = np.linspace(0.0, T3, 13)
    nodes, weights = np.polynomial.legendre.leggauss(12)
    weights = weights / 2
    runs = np.array([scipy_paper_flight(osc.replace(**{name: getattr(osc, name) + sigma * z}),
                                        times) for z in nodes])
    mean = weights @ runs
    var = weights @ (runs - mean) ** 2
    errors = []
    for order in (1, 3, 6):
        system = opa.System(osc, uncertain=name, sigma=sigma, distribution="uniform",
                            order=order)
        ds = opa.simulate_opa(system, times=times)
        errors.append(max(float(np.abs(ds.x_mean - mean).max()),
                          float(np.abs(ds.x_var - var).max())))
    assert var.max() > 1e-5, name  # the drive's uncertainty matters
    assert errors[-1] < 1e-8 and errors[0] > 100 * errors[-1], (name, errors)
    assert opa.System(osc, uncertain=name, sigma=sigma, order=2).kernel_inputs(
        opa.SolverOptions()).cfg[kernel.C_DRIVE_NODES] == 1


@pytest.mark.parametrize("fields, words", [
    (dict(uncertain="omega", sigma=5.0), "every frequency must be > 0"),
    (dict(uncertain="F0", sigma=0.05, impulse="pulse"), "impulse 'dirac'"),
    (dict(uncertain="f", sigma=0.05, truncation="paper"), "truncation 'galerkin'"),
])
def test_an_impossible_drive_is_refused_in_one_line(fields, words):
    with pytest.raises(ValueError) as err:
        opa.simulate_opa(opa.System(opa.preset("3.2"), **fields), periods=1)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_the_trust_map_of_an_uncertain_restitution(tmp_path):
    """validate with eta uncertain: the paper's truncation (a force-law closure) is left
    out, the map is computed and says why."""
    import xarray as xr

    from opa.cli._main import main

    status = main(["validate", "--uncertain", "eta", "--values", "3.99", "--sigmas",
                   "0.01,0.03", "--orders", "0:1", "--horizons", "2", "--samples", "128",
                   "--max-samples", "256", "--no-frontier", "--no-plots", "--quiet",
                   "--outdir", str(tmp_path / "map")])
    assert status == 0
    ds = xr.open_dataset(tmp_path / "map" / "validate.nc")
    variants = [str(v) for v in ds.variant.values]
    assert not any("paper" in v for v in variants) and "saltation/galerkin" in variants
    assert "uncertain eta" in ds.attrs["variants_dropped"]
    ds.close()


def test_simulate_says_the_mean_law_misses_an_uncertain_wall(capsys):
    """simulate opa with eta uncertain under the mean law warns that Var[x] misses it."""
    from opa.cli._main import main

    assert main(["simulate", "opa", "--uncertain", "eta", "--sigma", "0.03",
                 "--periods", "1"]) == 0
    assert "impact law mean reflects with the mean eta" in capsys.readouterr().out
    assert main(["simulate", "opa", "--uncertain", "eta", "--sigma", "0.03", "--periods",
                 "1", "--impact-law", "saltation"]) == 0
    assert "impact law mean reflects" not in capsys.readouterr().out
