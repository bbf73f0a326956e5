"""A user's force law (``opa._forcelaw``) and its path through the kernel.

Independent references: Python's own evaluation of the expression (the expansion), the
built-in paper law (the paper's law written as a user's, to round-off), scipy's
``solve_ivp`` (a free flight of a user's law), Gauss quadrature of scipy runs (OPA of an
uncertain constant of a user's law) and the closed-form period-1 orbits of Shaw & Holmes'
linear impact oscillator with their Floquet multipliers (``tests/impact_truths.py``).
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import mc
import opa
from opa._forcelaw import MAX_POWER, N_COEFFICIENTS, PAPER_EXPRESSION, ForceLaw
from opa.dynamics import ImpactSystem, periodic_orbit
from tests.impact_truths import SHAW_HOLMES_CASES, shaw_holmes_flight, shaw_holmes_orbits


def numpy_value(expression, x, v, values):
    """The expression evaluated by Python itself (``^`` read as a power)."""
    return eval(expression.replace("^", "**"), {"__builtins__": {}},  # noqa: S307
                {"x": x, "v": v, **values})


@pytest.mark.parametrize("expression, values", [
    (PAPER_EXPRESSION, dict(mu=0.8, a=0.5, c=0.05)),
    ("-2*zeta*v - x", dict(zeta=0.05)),
    ("mu*(1 - x^2)*v - x", dict(mu=1.3)),
    ("-(k + 0.5*q)^2*x*v^2 + (x - 2*v)^3/4 - 3", dict(k=0.7, q=-1.1)),
    ("-k1*x - k3*x**3 - b*v*abs2", dict(k1=1.0, k3=0.2, b=0.1, abs2=2.0)),
])
def test_the_expansion_is_the_expression(expression, values):
    """C[j, k] x^j v^k summed equals the expression at random points."""
    oscillator = {k: values.pop(k) for k in ("mu", "a", "c") if k in values}
    law = ForceLaw(expression, **values)
    rng = np.random.default_rng(3)
    x, v = rng.uniform(-2, 2, 50), rng.uniform(-2, 2, 50)
    want = numpy_value(expression, x, v, {**values, **oscillator})
    np.testing.assert_allclose(law(x, v, oscillator), want, rtol=1e-13, atol=1e-13)
    assert law.coefficients({**values, **oscillator}).shape == (1, N_COEFFICIENTS)


def test_the_paper_law_expands_to_its_four_terms():
    law = ForceLaw(PAPER_EXPRESSION)
    assert law.terms() == {(0, 1): "mu", (0, 3): "-mu", (1, 0): "-a", (3, 0): "-c"}
    C = law.coefficients(dict(mu=0.8, a=0.5, c=0.05)).reshape(MAX_POWER + 1, -1)
    assert (C[0, 1], C[0, 3], C[1, 0], C[3, 0]) == (0.8, -0.8, -0.5, -0.05)
    assert np.count_nonzero(C) == 4


def test_coefficients_at_many_points_follow_each_constant():
    law = ForceLaw("-k*x - (b + k)*v^2", k=1.0, b=0.5)
    k = np.array([1.0, 2.0, 3.0])
    C = law.coefficients(dict(k=k, b=0.5))
    np.testing.assert_array_equal(C[:, 4], -k)  # C[1, 0]
    np.testing.assert_array_equal(C[:, 2], -(0.5 + k))  # C[0, 2]


@pytest.mark.parametrize("expression, constants, words", [
    ("x/0", {}, "division by zero"),
    ("x*v/(1 - 1)", {}, "division by zero"),
    ("foo(x)", {}, "'foo(x)' calls no allowed function"),
    ("__import__('os')", {}, "calls no allowed function"),
    ("x.real", {}, "'x.real' is not allowed"),
    ("max(x)", {}, "wrong arguments"),
    ("max(x, v, 0)", {}, "wrong arguments"),
    ("sqrt", {}, "call it as sqrt(...)"),
    ("x[0]", {}, "is not allowed"),
    ("v if x else 0", {}, "is not allowed"),
    ("k*x", {}, "'k' has no value"),
    ("-x", {"k": 1.0}, "does not use the constant 'k'"),
    ("omega*x", {}, "'omega'"),
    ("-mu*v", {"mu": 0.3}, "set it on the oscillator"),
    ("x +", {}, "not an expression"),
    ("", {}, "non-empty"),
    ("k*x", {"k": float("nan")}, "must be finite"),
    ("k*x", {"k": "1"}, "must be a real number"),
    ("x == v", {}, "'x == v' is not allowed"),
    ("'x'", {}, "not a finite number"),
    ("1e400*x", {}, "finite"),
    ("-" * 1990 + "x", {}, "nested more than 100 levels"),
    ("x*" * 900 + "x", {}, "nested more than 100 levels"),
])
def test_a_bad_law_gets_one_line_naming_the_piece(expression, constants, words):
    with pytest.raises(ValueError) as err:
        ForceLaw(expression, **constants)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_an_oscillator_takes_a_law_or_its_expression_and_checks_the_uncertain_names():
    law = ForceLaw("-2*zeta*v - x", zeta=0.05)
    osc = opa.Oscillator(force=law)
    assert opa.Oscillator(force="-x").force.terms() == {
        (1, 0): "-1"}
    assert osc.value("zeta") == 0.05 and osc.coefficient_names == ("zeta",)
    assert osc.replace(zeta=0.07).force.constants == {"zeta": 0.07}
    with pytest.raises(ValueError, match="among zeta"):
        opa.System(osc, uncertain="mu", sigma=0.01)
    with pytest.raises(ValueError, match="truncation 'galerkin'"):
        opa.System(osc, uncertain="zeta", sigma=0.01, truncation="paper")
    with pytest.raises(ValueError, match="force must be"):
        opa.Oscillator(force=3)
    system = opa.System(osc, uncertain="zeta", sigma=0.01)
    assert pickle.loads(pickle.dumps(system)) == system


# ------------------------------------------------------------------ through the kernel
PAPER_AS_USER = opa.preset("3.2").replace(force=ForceLaw(PAPER_EXPRESSION))


def assert_built_in_runs(law: ForceLaw):
    """DMR, OPA (mu, c, and (mu, c) together) and Monte Carlo of section 3.2 with ``law``
    (the paper's law written as a user's) equal the built-in law's to 1e-12 over 10
    periods with impacts; returns the Monte Carlo run of ``law``."""
    osc = opa.preset("3.2")
    user = osc.replace(force=law)
    a, b = (opa.simulate_dmr(o, periods=10, per_period=8) for o in (osc, user))
    assert int(a.impact_time.count()) > 3
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-12)
    for uncertain, sigma in (("mu", 0.02), ("c", 0.005), ("mu,c", (0.016, 0.005))):
        runs = [opa.simulate_opa(opa.System(o, uncertain=uncertain, sigma=sigma, order=3),
                                 periods=10, per_period=8) for o in (osc, user)]
        for name in ("x_mean", "x_var"):
            np.testing.assert_allclose(runs[1][name], runs[0][name], rtol=0, atol=1e-12)
    runs = [mc.simulate_mc(opa.System(o, uncertain="c", sigma=0.005), samples=32, periods=10,
                           per_period=8) for o in (osc, user)]
    np.testing.assert_allclose(runs[1].x_mean, runs[0].x_mean, rtol=0, atol=1e-12)
    return runs[1]


def test_the_paper_law_as_a_user_law_gives_the_built_in_runs_to_round_off():
    """The user's polynomial path and the built-in law agree to round-off."""
    assert assert_built_in_runs(PAPER_AS_USER.force).attrs["force_law"] == PAPER_EXPRESSION


VAN_DER_POL = "mu*(1 - x^2)*v - x + k*x*v^3"


def scipy_flight(law, values, f, omega, y0, times):
    def rhs(t, y):
        return [y[1], law(y[0], y[1], values) + f * math.cos(omega * t)]
    return solve_ivp(rhs, (times[0], times[-1]), y0, t_eval=times, method="DOP853",
                     rtol=1e-12, atol=1e-12).y


def test_a_user_law_flies_as_scipy_integrates_it():
    """A law with x^2 v and x v^3 terms, the wall out of reach: the DMR against scipy."""
    law = ForceLaw(VAN_DER_POL, k=-0.05)
    osc = opa.Oscillator(force=law, mu=0.7, f=0.6, omega=1.1, delta=50.0, F0=0.0, x0=-1.0)
    ds = opa.simulate_dmr(osc, periods=6, per_period=16)
    want = scipy_flight(law, dict(mu=0.7), 0.6, 1.1, [-1.0, 0.0], ds.time.values)
    np.testing.assert_allclose(ds.x, want[0], rtol=0, atol=1e-7)
    np.testing.assert_allclose(ds.v, want[1], rtol=0, atol=1e-7)


def test_opa_of_an_uncertain_constant_of_a_user_law_converges_to_quadrature():
    """Uniform uncertain k, no impacts: E[x] and Var[x] of the OPA system against a
    9-point Gauss-Legendre rule of scipy runs; the error falls geometrically with the
    order."""
    law = ForceLaw(VAN_DER_POL, k=-0.05)
    osc = opa.Oscillator(force=law, mu=0.7, f=0.6, omega=1.1, delta=50.0, F0=0.0, x0=-1.0)
    nodes, weights = np.polynomial.legendre.leggauss(9)
    weights = weights / 2
    times = opa.simulate_dmr(osc, periods=4, per_period=8).time.values
    runs = np.array([scipy_flight(ForceLaw(VAN_DER_POL, k=-0.05 + 0.04 * z), dict(mu=0.7), 0.6,
                                  1.1, [-1.0, 0.0], times)[0] for z in nodes])
    mean = weights @ runs
    var = weights @ (runs - mean) ** 2
    errors = []
    for order in (1, 3, 5, 7):
        system = opa.System(osc, uncertain="k", sigma=0.04, distribution="uniform",
                            order=order)
        ds = opa.simulate_opa(system, periods=4, per_period=8)
        errors.append(max(float(np.abs(ds.x_mean - mean).max()),
                          float(np.abs(ds.x_var - var).max())))
    # measured: 1.3e-2, 8.5e-4, 1.5e-5, 3.1e-7 (a factor 16 to 58 per two orders)
    assert errors[-1] < 1e-6, errors
    assert all(a > 10 * b for a, b in zip(errors, errors[1:])), errors


@pytest.mark.parametrize("case", SHAW_HOLMES_CASES)
def test_shaw_holmes_period_one_orbits_and_their_multipliers(case):
    """The linear impact oscillator x'' + 2 zeta x' + x = cos(omega t) as a user's law:
    each closed-form period-1 orbit found by opa's Newton shooting from the closed-form
    state, with its impact phase and velocity to 1e-8 and its Floquet multipliers."""
    zeta, omega, delta, r = case["zeta"], case["omega"], case["delta"], case["r"]
    T = 2 * math.pi / omega
    law = ForceLaw("-2*zeta*v - x", zeta=zeta)
    osc = opa.Oscillator(force=law, a=1.0, f=1.0, omega=omega, eta=r, delta=delta, F0=0.0,
                         omega1=omega, x0=delta - 1.0)
    for orbit in shaw_holmes_orbits(zeta, omega, delta, r):
        start = shaw_holmes_flight(zeta, omega, delta, r, orbit["phase"], orbit["velocity"],
                                   T - orbit["phase"])[:, 0]  # the state at t = T = 0 mod T
        found = periodic_orbit(ImpactSystem(osc), start, periods=1)
        assert len(found.impact_time) == 1
        assert found.impact_time[0] % T == pytest.approx(orbit["phase"], abs=1e-8)
        assert found.impact_velocity[0] == pytest.approx(orbit["velocity"], abs=1e-8)
        got = sorted(found.multipliers, key=lambda z: (-abs(z), z.imag))
        want = sorted(orbit["multipliers"], key=lambda z: (-abs(z), z.imag))
        np.testing.assert_allclose(got, want, atol=1e-6)
        assert found.stable == bool(np.all(np.abs(want) < 1))


def test_a_run_of_a_user_law_is_certified_against_its_own_law():
    """compare.verify rebuilds the true systems from the run's attributes, force law
    included (``Oscillator.from_attrs``): a converged run agrees, and the same run
    claiming another constant, or the paper's law, is found out."""
    import compare

    law = ForceLaw("-2*zeta*v - x - k3*x^3", zeta=0.05, k3=0.1)
    osc = opa.Oscillator(force=law, a=1.0, f=1.0, omega=2.5, eta=0.8, delta=0.3, F0=0.0,
                         omega1=2.5, x0=-0.5)
    system = opa.System(osc, uncertain="k3", sigma=0.05, distribution="uniform", order=3,
                        impact_law="saltation")
    ds = opa.simulate_opa(system, periods=5, per_period=8, elements="adaptive")
    assert opa.Oscillator.from_attrs(ds.attrs) == osc
    assert compare.verify(ds, samples=256, max_samples=1024).attrs["verdict"] == "agrees"
    other = ds.copy()
    other.attrs["force_constants"] = "zeta=0.05,k3=0.5"
    assert compare.verify(other, samples=256, max_samples=1024).attrs["verdict"] == "disagrees"
    paper = ds.copy()
    del paper.attrs["force_law"], paper.attrs["force_constants"]
    paper.attrs["uncertain"] = "c"
    assert compare.verify(paper, samples=256, max_samples=1024).attrs["verdict"] == "disagrees"


# --------------------------------------- the paper's law as a user's: the map, the diagram
PAPER_FILE = """force = "{expression}"
[oscillator]
mu = 0.8
a = 0.5
c = 0.05
f = 1.5
eta = 0.8
delta = 0.0
F0 = 0.1
x0 = -1.0
"""
#: statistics of paired differences that are round-off themselves (an error SE, or a
#: variance reduction Var[x] / Var[x - x_hat] with x - x_hat ~ 1e-12): compared relatively;
#: the times of a run are not compared
ILL_CONDITIONED = ("err_mean_se", "err_var_se", "pair_reduction")
TIMES = ("mc_seconds", "point_seconds")


def _validate(tmp_path, name, *source):
    from opa.cli._main import main

    out = tmp_path / name
    assert main(["validate", *source, "--values", "3.98", "--sigmas", "0.01,0.02",
                 "--orders", "0:2", "--horizons", "2,4", "--samples", "256",
                 "--max-samples", "1024", "--seed", "7", "--no-frontier", "--no-plots",
                 "--quiet", "--outdir", str(out)]) == 0
    import xarray as xr

    return xr.load_dataset(out / "validate.nc")


@pytest.mark.long
@pytest.mark.parametrize("compiled", [False, True])
def test_the_paper_law_as_a_user_law_gives_the_validate_map_to_round_off(tmp_path, compiled):
    """``opa-mc validate`` of section 3.2 at omega = 3.98 (2 sigmas, N = 0..2, 2 horizons):
    the built-in law and the same law in a model file (polynomial, or compiled with
    ``max(v, v)`` = v) give every verdict, sigma* and variable of the variants they share
    to 1e-10 or 1e-9 relative (the user's map leaves out the paper's truncation, which
    closes the built-in law only)."""
    expression = PAPER_EXPRESSION + ("" if not compiled else " + 0*max(v, v)")
    model = tmp_path / "paper.toml"
    model.write_text(PAPER_FILE.format(expression=expression))
    built_in = _validate(tmp_path, "built-in", "--preset", "3.2")
    user = _validate(tmp_path, "user", "--model", str(model))
    assert list(user.variant.values) == [v for v in built_in.variant.values
                                         if not v.endswith("/paper")]
    built_in["mc_control"] = xr_variant_name(built_in, "mc_control")
    user["mc_control"] = xr_variant_name(user, "mc_control")
    built_in = built_in.sel(variant=user.variant.values)
    for name in built_in.data_vars:
        if name in TIMES:
            continue
        a, b = built_in[name].values, user[name].values
        if a.dtype.kind not in "fc":
            np.testing.assert_array_equal(a, b, err_msg=name)
        elif name in ILL_CONDITIONED:
            np.testing.assert_allclose(b, a, rtol=1e-3, err_msg=name)
        else:
            np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-10, err_msg=name)
    assert (built_in.verdict.values != 0).any()  # verdicts were made


def xr_variant_name(ds, name):
    """The variant named by an index variable (its position differs between the maps)."""
    return ds[name].copy(data=np.vectorize(lambda i: "-" if i < 0 else
                                           str(ds.variant.values[i]))(ds[name].values))


@pytest.mark.parametrize("law", [ForceLaw(PAPER_EXPRESSION),
                                 ForceLaw.compiled(PAPER_EXPRESSION)], ids=["poly", "compiled"])
def test_the_paper_law_as_a_user_law_gives_the_stochastic_diagram_at_c_004(law):
    """The stochastic diagram's slice of section 3.1 at c = 0.04 (mu uncertain, sigma =
    0.05, 64 Monte Carlo samples with two other initial states): the types, boundaries,
    probabilities and the samples' types and Lyapunov exponents of the built-in law."""
    from opa.dynamics._stochastic import stochastic_slice

    osc = opa.preset("3.1", c=0.04)
    slices = [stochastic_slice(o, "mu", 0.05, "semicircle", samples=64, seed=3,
                               options=opa.SolverOptions(), extra_states=2)
              for o in (osc, osc.replace(force=law))]
    assert len(slices[0]["mc_type"]) == 64
    for key, a in slices[0].items():
        if key == "cpu_seconds":
            continue
        b = slices[1][key]
        if isinstance(a, np.ndarray) and a.dtype.kind in "fc":
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-9, err_msg=key)
        elif isinstance(a, np.ndarray):
            np.testing.assert_array_equal(b, a, err_msg=key)
        else:
            assert b == a or (a != a and b != b), key  # NaN: the same "none"
