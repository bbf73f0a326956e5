"""The escape hatch: a force law compiled into a function (``opa._forcefunction``).

Independent references: the built-in paper law and the polynomial path of the same law
(the compiled path must give them to round-off: the issue's "quadrature projection
reproduces the closed-form projections"), scipy's ``solve_ivp`` (a Hertzian contact law
in free flight), Gauss-Legendre quadrature of scipy runs (OPA of its uncertain stiffness)
and the closed-form Floquet multipliers of Shaw & Holmes' period-1 orbits (the Jacobian by
central differences).
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import opa
from opa import _kernel as kernel
from opa._forcefunction import check_addresses, function_parameters, imported_function
from opa._forcelaw import PAPER_EXPRESSION, ForceLaw
from opa._run import sampled
from opa.dynamics import ImpactSystem, periodic_orbit
from tests.impact_truths import SHAW_HOLMES_CASES, shaw_holmes_flight, shaw_holmes_orbits
from tests.opa.test_forcelaw import assert_built_in_runs

HERTZ = "-2*zeta*v - x - k*max(x - g, 0)^1.5"


def hertz(x, v, zeta, k, g):
    """The Hertzian contact law as a Python function (``ForceLaw.from_function``)."""
    return -2.0 * zeta * v - x - k * max(x - g, 0.0) ** 1.5


def hertz_numpy(x, v, zeta, k, g):
    return -2.0 * zeta * v - x - k * np.maximum(x - g, 0.0) ** 1.5


def scipy_flight(k, times, zeta=0.05, g=0.3, f=0.8, omega=1.2):
    def rhs(t, y):
        return [y[1], hertz_numpy(y[0], y[1], zeta, k, g) + f * math.cos(omega * t)]
    return solve_ivp(rhs, (times[0], times[-1]), [0.0, 0.0], t_eval=times, method="DOP853",
                     rtol=1e-12, atol=1e-12).y


def hertz_oscillator(law=None, delta=50.0):
    law = law or ForceLaw(HERTZ, zeta=0.05, k=20.0, g=0.3)
    return opa.Oscillator(force=law, f=0.8, omega=1.2, eta=0.8, delta=delta, F0=0.0,
                          x0=0.0, v0=0.0)


def test_an_expression_that_is_not_a_polynomial_is_compiled_and_evaluates_as_written():
    law = ForceLaw(HERTZ, zeta=0.05, k=20.0, g=0.3)
    assert law.kind == "compiled" and law.names == ("zeta", "k", "g")
    x, v = np.linspace(-1, 1, 21), np.linspace(1, -1, 21)
    np.testing.assert_array_equal(law(x, v), hertz_numpy(x, v, 0.05, 20.0, 0.3))
    C = law.coefficients(dict(zeta=0.05, k=np.array([1.0, 2.0]), g=0.3))
    np.testing.assert_array_equal(C[:, :3], [[0.05, 1.0, 0.3], [0.05, 2.0, 0.3]])
    assert not C[:, 3:].any()
    for text in ("-x - x^5", "-sin(x)", "-x/k", "-x^0.5"):
        assert ForceLaw(text, **({"k": 2.0} if "k" in text else {})).kind == "compiled"
    assert ForceLaw("-x - x^3").kind == "polynomial"
    with pytest.raises(ValueError, match="no expansion"):
        law.terms()


def test_a_function_law_reads_its_constants_from_its_parameters():
    law = ForceLaw.from_function(hertz, zeta=0.05, k=20.0, g=0.3)
    assert law.kind == "function" and law.names == ("zeta", "k", "g")
    assert law.expression == "tests.opa.test_forcefunction:hertz"
    assert imported_function(law.expression) is hertz
    np.testing.assert_array_equal(law(np.array([0.5]), np.array([0.1])),
                                  [hertz(0.5, 0.1, 0.05, 20.0, 0.3)])
    assert pickle.loads(pickle.dumps(law)) == law
    assert law.with_constants(k=10.0).constants == dict(zeta=0.05, k=10.0, g=0.3)
    with pytest.raises(ValueError, match="'k' has no value"):
        ForceLaw.from_function(hertz, zeta=0.05, g=0.3)
    with pytest.raises(ValueError, match="g\\(x, v, constant, ...\\)"):
        function_parameters(lambda y, v: y)
    with pytest.raises(ValueError, match="cannot be imported"):
        imported_function("no_such_module_here:g")


# ------------------------------------------------------------------ through the kernel
def test_the_paper_law_compiled_gives_the_built_in_runs_to_round_off():
    """DMR, OPA with mu, c and (mu, c) uncertain, and Monte Carlo: the projections by
    quadrature of the compiled function equal the built-in law's to round-off."""
    run = assert_built_in_runs(ForceLaw.compiled(PAPER_EXPRESSION))
    assert run.attrs["force_kind"] == "compiled"


def test_a_law_other_than_the_papers_compiled_gives_its_polynomial_runs():
    """A Duffing law with impacts (not the paper's: the 2-D register path of the built-in
    law must not be taken) on the DOP853 and DP5 steps."""
    text = "-2*zeta*v - x - k*x^3"
    for method in ("dop853", "dp5"):
        options = opa.SolverOptions(method=method)
        runs = [opa.simulate_dmr(hertz_oscillator(make(text, zeta=0.05, k=2.0), delta=0.6),
                                 periods=8, per_period=8, options=options)
                for make in (ForceLaw, ForceLaw.compiled)]
        assert int(runs[0].impact_time.count()) > 3
        np.testing.assert_allclose(runs[1].x, runs[0].x, rtol=0, atol=1e-11)


def test_a_hertzian_contact_flies_as_scipy_integrates_it():
    """The expression and the Python function both, the wall out of reach. The contact's
    second derivative jumps at x = g, which costs the step control accuracy: at the
    default tolerance 1e-10 the distance to scipy is 3.7e-7 in x, at 1e-12 3.4e-9 in x and
    1.0e-8 in v (measured)."""
    options = opa.SolverOptions(rtol=1e-12, atol=1e-12)
    for law in (ForceLaw(HERTZ, zeta=0.05, k=20.0, g=0.3),
                ForceLaw.from_function(hertz, zeta=0.05, k=20.0, g=0.3)):
        ds = opa.simulate_dmr(hertz_oscillator(law), periods=6, per_period=16, options=options)
        assert float(ds.x.max()) > 0.35  # the contact is reached
        want = scipy_flight(20.0, ds.time.values)
        np.testing.assert_allclose(ds.x, want[0], rtol=0, atol=3e-8)
        np.testing.assert_allclose(ds.v, want[1], rtol=0, atol=3e-8)


def test_opa_of_an_uncertain_contact_stiffness_converges_to_quadrature():
    """Uniform k in [12, 28], no impacts: OPA's E[x] and Var[x] against a 12-point
    Gauss-Legendre rule of scipy runs. The contact term is C^1 only, so the error falls
    algebraically; it must fall with the order and reach 1e-4."""
    nodes, weights = np.polynomial.legendre.leggauss(12)
    weights = weights / 2
    times = opa.simulate_dmr(hertz_oscillator(), periods=3, per_period=8).time.values
    runs = np.array([scipy_flight(20.0 + 8.0 * z, times)[0] for z in nodes])
    mean = weights @ runs
    var = weights @ (runs - mean) ** 2
    errors = []
    for order in (1, 3, 6):
        system = opa.System(hertz_oscillator(), uncertain="k", sigma=8.0,
                            distribution="uniform", order=order)
        ds = opa.simulate_opa(system, periods=3, per_period=8)
        errors.append(max(float(np.abs(ds.x_mean - mean).max()),
                          float(np.abs(ds.x_var - var).max())))
    assert errors[-1] < 1e-4, errors
    assert errors[0] > errors[1] > errors[2], errors


@pytest.mark.parametrize("case", SHAW_HOLMES_CASES[:1])
def test_a_compiled_law_has_shaw_holmes_multipliers_by_differences(case):
    """The Jacobian by central differences: Floquet multipliers of the closed-form orbit
    to 1e-6, as the polynomial law gives them."""
    zeta, omega, delta, r = case["zeta"], case["omega"], case["delta"], case["r"]
    T = 2 * math.pi / omega
    law = ForceLaw.compiled("-2*zeta*v - x", zeta=zeta)
    osc = opa.Oscillator(force=law, f=1.0, omega=omega, eta=r, delta=delta, F0=0.0,
                         omega1=omega, x0=delta - 1.0)
    for orbit in shaw_holmes_orbits(zeta, omega, delta, r):
        start = shaw_holmes_flight(zeta, omega, delta, r, orbit["phase"], orbit["velocity"],
                                   T - orbit["phase"])[:, 0]
        found = periodic_orbit(ImpactSystem(osc), start, periods=1)
        assert found.impact_velocity[0] == pytest.approx(orbit["velocity"], abs=1e-8)
        got = sorted(found.multipliers, key=lambda z: (-abs(z), z.imag))
        want = sorted(orbit["multipliers"], key=lambda z: (-abs(z), z.imag))
        np.testing.assert_allclose(got, want, atol=1e-6)


def test_a_compiled_run_is_certified_against_its_own_law():
    """The dataset names the law's kind; compare.verify rebuilds it (``from_attrs``): a
    converged run agrees, and the same run claiming a stiffer contact is found out."""
    import compare

    osc = hertz_oscillator(ForceLaw.from_function(hertz, zeta=0.05, k=20.0, g=0.3), delta=0.6)
    system = opa.System(osc, uncertain="k", sigma=4.0, distribution="uniform", order=3,
                        impact_law="saltation")
    ds = opa.simulate_opa(system, periods=5, per_period=8, elements="adaptive")
    assert ds.attrs["force_kind"] == "function"
    assert opa.Oscillator.from_attrs(ds.attrs) == osc
    assert compare.verify(ds, samples=256, max_samples=1024).attrs["verdict"] == "agrees"
    other = ds.copy()
    other.attrs["force_constants"] = "zeta=0.05,k=30.0,g=0.3"
    assert compare.verify(other, samples=256, max_samples=1024).attrs["verdict"] == "disagrees"


def test_inputs_from_another_process_and_the_gpu_are_refused():
    """An address compiled elsewhere is meaningless here: refused before the kernel runs
    (it would otherwise call into arbitrary memory); a GPU has no such function."""
    system = opa.System(hertz_oscillator(), uncertain="k", sigma=1.0, order=0)
    inputs = system.kernel_inputs(opa.SolverOptions())
    check_addresses(inputs.cfg)  # made here: accepted
    foreign = inputs.cfg.copy()
    foreign[kernel.C_FUNCTION] += 8
    with pytest.raises(ValueError, match="another process"):
        check_addresses(foreign)
    batch = sampled(inputs, {"k": [20.0]}, inputs.p[None, kernel.P_POLY:kernel.P_POLY + 16])
    with pytest.raises(ValueError, match="CPU only"):
        opa._run.run_batch(batch, [0.0, 0.0], [0.0, 1.0], rtol=1e-8, atol=1e-8,
                           device="cuda")


@pytest.mark.parametrize("source, words", [
    ("def g(x, v, k):\n    return -k * x +\n", "cannot be imported (SyntaxError"),
    ("raise RuntimeError('no')\ndef g(x, v, k):\n    return -k * x\n",
     "cannot be imported (RuntimeError: no)"),
    ("def g(x, v, k):\n    return -k * x + len('abc' + x)\n", "does not compile with numba"),
])
def test_a_broken_function_beside_a_model_file_is_one_line_and_exit_2(tmp_path, capsys, source,
                                                                       words):
    """The user's module may not import, or its function may not compile: one line
    naming it, exit status 2, never a traceback."""
    from opa.cli._main import main

    name = f"user_law_{abs(hash(source)) % 10**8}"
    (tmp_path / f"{name}.py").write_text(source)
    model = tmp_path / "model.toml"
    model.write_text(f'function = "{name}:g"\n[constants]\nk = 1.0\n[oscillator]\nF0 = 0.0\n')
    assert main(["simulate", "dmr", "--model", str(model), "--periods", "1"]) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1, err
