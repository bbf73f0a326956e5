"""The one kernel (``opa._kernel``): where jitted code may live, the parameter layout,
the two steppers agreeing on one problem, EMR_0 = DMR bit for bit, and trajectories
resumed under an impulse train.

Independent references: the closed-form flight of ``tests/reference.py`` lives in the
solver tests; here the references are the model's own fields (the packer round trip),
a run in one piece (the resumed run) and the other Runge-Kutta pair.
"""

from __future__ import annotations

import ast
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

import opa
from opa import _kernel as kernel
from opa._run import run
from tests.conftest import kernel_inputs, rule
from tests.opa.test_solver import HARMONIC, kernel_step
from tests.parsed import tree

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("opa", "mc", "compare")
NUMBA_DECORATORS = {"njit", "jit", "vectorize", "guvectorize", "cfunc", "stencil",
                    "generated_jit", "jitclass"}


def package_modules():
    for package in PACKAGES:
        yield from sorted((ROOT / package).rglob("*.py"))


def numba_uses(tree: ast.AST) -> list[str]:
    """Names of numba's compiling decorators a module imports or calls."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("numba"):
            found += [a.name for a in node.names if a.name in NUMBA_DECORATORS]
        if isinstance(node, ast.Attribute) and node.attr in NUMBA_DECORATORS:
            if isinstance(node.value, ast.Name) and node.value.id in ("numba", "nb"):
                found.append(node.attr)
    return found


def test_jitted_code_lives_only_in_the_kernel_module():
    offenders = {}
    for path in package_modules():
        uses = numba_uses(tree(path))
        if uses and path != ROOT / "opa" / "_kernel.py":
            offenders[str(path.relative_to(ROOT))] = uses
    assert not offenders, f"jitted code outside opa/_kernel.py: {offenders}"
    assert numba_uses(tree(ROOT / "opa" / "_kernel.py"))


def test_the_kernel_imports_nothing_from_the_package():
    """numba's cache bakes imported globals into compiled code without tracking the
    file they came from: the kernel may import only numpy and numba (and numba's
    llvmlite)."""
    imported = set()
    for node in ast.walk(tree(ROOT / "opa" / "_kernel.py")):
        if isinstance(node, ast.Import):
            imported |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, "relative import in the kernel"
            imported.add(node.module.split(".")[0])
    # llvmlite: numba's own code generator, for the call through a compiled force
    # function's pointer (``_call_function``)
    assert imported <= {"__future__", "math", "numpy", "numba", "llvmlite"}, imported


def test_cuda_kernels_live_only_in_the_gpu_module():
    """``opa/_gpu.py`` holds the only CUDA kernels; every function they run on a GPU thread
    is the kernel module's own (``integrate_with``), compiled again for the device."""
    users = []
    for path in package_modules():
        for node in ast.walk(tree(path)):
            if isinstance(node, ast.Attribute) and node.attr == "jit" and \
                    isinstance(node.value, ast.Name) and node.value.id == "cuda":
                users.append(str(path.relative_to(ROOT)))
    assert sorted(set(users)) == ["opa/_gpu.py"]
    source = (ROOT / "opa" / "_gpu.py").read_text()
    assert "kernel.integrate_with" in source and "def integrate_with" not in source


def test_the_layout_indices_are_a_permutation():
    params = [getattr(kernel, n) for n in dir(kernel) if n.startswith("P_") and n != "P_POLY"]
    params += range(kernel.P_POLY, kernel.P_POLY + kernel.N_POLY)  # C[j, k] of a user's law
    cfg = [getattr(kernel, n) for n in dir(kernel) if n.startswith("C_")]
    stats = [getattr(kernel, n) for n in dir(kernel) if n.startswith("S_")]
    table = [kernel.T_MU, kernel.T_A, kernel.T_C, kernel.T_ETA, kernel.T_DELTA, kernel.T_F,
             kernel.T_OMEGA, kernel.T_F0,
             *range(kernel.T_POLY, kernel.T_POLY + kernel.N_POLY)]
    assert sorted(table) == list(range(kernel.N_TABLE))
    assert sorted(params) == list(range(kernel.N_PARAMS))
    assert sorted(cfg) == list(range(kernel.N_CFG))
    assert sorted(stats) == list(range(kernel.N_STATS))


def test_the_packer_puts_every_model_field_in_its_slot():
    """Distinct values for every field of the model and the options: each lands in its
    own slot of ``p`` or ``cfg`` (a swap of two slots would show)."""
    osc = opa.Oscillator(mu=0.11, a=1.13, c=0.17, f=0.19, omega=2.3, eta=0.29, delta=0.31,
                         F0=0.37, a1=0.41, omega1=4.3, n=3, x0=-0.5, v0=0.25,
                         delta_minus=-0.67, eta_minus=0.71)
    opts = opa.SolverOptions(impulse="pulse", pulse_width=0.53, impulse_at_zero=False,
                             rtol=1e-9, atol=1e-11, max_steps=12345, chatter_velocity=3e-6,
                             max_step=0.59, method="dp5")
    inputs = kernel_inputs(osc, opts, sigma=0.061, order=7, uncertain="c",
                           truncation="paper", impact_law="saltation")
    p, cfg = inputs.p, inputs.cfg
    want = {kernel.P_MU: 0.11, kernel.P_A: 1.13, kernel.P_C: 0.17, kernel.P_F: 0.19,
            kernel.P_OMEGA: 2.3, kernel.P_ETA: 0.29, kernel.P_DELTA: 0.31, kernel.P_F0: 0.37,
            kernel.P_A1: 0.41, kernel.P_OMEGA1: 4.3, kernel.P_N: 3.0, kernel.P_TAU: 0.53,
            kernel.P_SIGMA: 0.061, kernel.P_CHATTER_V: 3e-6,
            kernel.P_HMAX: 0.59, kernel.P_DELTA_MINUS: -0.67, kernel.P_ETA_MINUS: 0.71}
    want.update({kernel.P_POLY + i: 0.0 for i in range(kernel.N_POLY)})  # the paper's law
    assert len(want) == kernel.N_PARAMS
    for slot, value in want.items():
        assert p[slot] == value, slot
    want_cfg = {kernel.C_NCOEF: 8,
                kernel.C_IMPULSE: kernel.IMPULSE_PULSE, kernel.C_AT_ZERO: 0,
                kernel.C_TRUNC: kernel.TRUNC_PAPER_X, kernel.C_LAW: kernel.LAW_SALTATION,
                kernel.C_MAXSTEPS: 12345, kernel.C_METHOD: kernel.METHOD_DP5,
                kernel.C_FORCE: kernel.FORCE_PAPER, kernel.C_WALL_NODES: 0,
                kernel.C_DRIVE_NODES: 0, kernel.C_FUNCTION: 0}
    assert len(want_cfg) == kernel.N_CFG
    for slot, value in want_cfg.items():
        assert cfg[slot] == value, slot
    # the other choices of each switch
    cfg = kernel_inputs(osc, dataclasses.replace(opts, impulse="dirac", method="dop853",
                                                 impulse_at_zero=True),
                        uncertain="a", truncation="galerkin", impact_law="ensemble").cfg
    assert (cfg[kernel.C_IMPULSE], cfg[kernel.C_METHOD], cfg[kernel.C_AT_ZERO]) == (
        kernel.IMPULSE_DIRAC, kernel.METHOD_DOP853, 1)
    assert (cfg[kernel.C_TRUNC], cfg[kernel.C_LAW]) == (kernel.TRUNC_GALERKIN,
                                                        kernel.LAW_ENSEMBLE)
    # the paper's closure: on the velocities for an uncertain mu, none for an uncertain a
    for uncertain, closure in (("mu", kernel.TRUNC_PAPER_V), ("a", kernel.TRUNC_GALERKIN)):
        cfg = kernel_inputs(osc, opts, sigma=0.061, order=7, uncertain=uncertain,
                            truncation="paper").cfg
        assert cfg[kernel.C_TRUNC] == closure, uncertain
    # the table: the force law's coefficients at each node, the uncertain one c + sigma xi
    nodes = opa.gauss_nodes(15)[0]
    assert np.array_equal(inputs.table[:, kernel.T_C], 0.17 + 0.061 * nodes)
    assert np.all(inputs.table[:, kernel.T_MU] == 0.11)
    assert np.all(inputs.table[:, kernel.T_A] == 1.13)
    # the x0, v0 fields are the initial state, not parameters
    assert osc.x0 not in p and osc.v0 not in p


@pytest.mark.parametrize("method", ["dop853", "dp5"])
@pytest.mark.parametrize("section", ["3.1", "3.2"])
def test_emr0_with_n_zero_is_the_dmr_bit_for_bit(section, method):
    """With N = 0 the OPA system has the one-node rule at xi = 0: whatever sigma, it is the
    DMR, and the kernel computes it with the same arithmetic (every array equal)."""
    osc = opa.preset(section)
    options = opa.SolverOptions(method=method)
    dmr = opa.simulate_dmr(osc, periods=30, per_period=4, options=options)
    emr = opa.simulate_opa(osc, sigma=0.02, order=0, periods=30, per_period=4,
                           options=options)
    assert dmr.sizes["impact"] >= 3
    np.testing.assert_array_equal(emr.x_mean.values, dmr.x.values)
    np.testing.assert_array_equal(emr.v_mean.values, dmr.v.values)
    np.testing.assert_array_equal(emr.impact_time.values, dmr.impact_time.values)
    np.testing.assert_array_equal(emr.impact_velocity.values, dmr.impact_velocity.values)
    assert emr.attrs["steps"] == dmr.attrs["steps"]


@pytest.mark.parametrize("section", ["3.1", "3.2"])
def test_both_pairs_agree_on_the_paper_presets(section):
    """DOP853 and DP5 at rtol = atol = 1e-12 agree over 20 forcing periods with impacts
    and impulses to the 1e-9 level (the motion amplifies differences ~10-fold there)."""
    osc = opa.preset(section)
    runs = [opa.simulate_dmr(osc, periods=20, per_period=4,
                             options=opa.SolverOptions(rtol=1e-12, atol=1e-12, method=m))
            for m in ("dop853", "dp5")]
    assert runs[0].sizes["impact"] == runs[1].sizes["impact"] >= 3
    np.testing.assert_allclose(runs[0].x, runs[1].x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(runs[0].v, runs[1].v, rtol=0, atol=1e-9)
    np.testing.assert_allclose(runs[0].impact_time, runs[1].impact_time, rtol=0, atol=1e-9)
    # the higher-order pair takes fewer steps at this tolerance
    assert runs[0].attrs["steps"] < 0.5 * runs[1].attrs["steps"]


@pytest.mark.parametrize("impulse", ["dirac", "pulse"])
@pytest.mark.parametrize("split", [10, 14])
def test_a_trajectory_resumes_under_the_impulse_train(split, impulse):
    """Section 3.1 (impulses every 2.8 forcing periods; 14 periods is one impulse time):
    a run in two pieces, the second resumed without re-applying the impulse at its start,
    equals the run in one piece to the tolerance level."""
    osc = opa.preset("3.1")
    opts = opa.SolverOptions(impulse=impulse, pulse_width=0.3, rtol=1e-12, atol=1e-12)
    T = osc.forcing_period
    inputs = kernel_inputs(osc, opts)
    y0 = np.array([osc.x0, osc.v0])
    whole = run(inputs, y0, np.array([0.0, split * T, 28 * T]), rtol=opts.rtol,
                atol=opts.atol)
    first = run(inputs, y0, np.array([0.0, split * T]), rtol=opts.rtol, atol=opts.atol).states
    second = run(inputs, first[-1], np.array([split * T, 28 * T]), rtol=opts.rtol,
                 atol=opts.atol, include_start=False).states
    log, whole = whole.events, whole.states
    assert len(log) >= 3
    np.testing.assert_allclose(first[-1], whole[1], rtol=0, atol=0)
    np.testing.assert_allclose(second[-1], whole[-1], rtol=0, atol=1e-8)
    # re-applying the start impulse (include_start) is a different trajectory when an
    # impulse falls on the split
    if split == 14 and impulse == "dirac":
        again = run(inputs, first[-1], np.array([split * T, 28 * T]), rtol=opts.rtol,
                    atol=opts.atol, include_start=True).states
        assert np.abs(again[-1] - whole[-1]).max() > 1e-3


def test_benettin_by_plain_kernel_runs_works_under_impulses():
    """The plain-run Benettin engine resumes every forcing period under the impulse
    train (it used to need F0 = 0) and agrees with the flow engine."""
    system = opa.ImpactSystem(opa.preset("3.1", c=0.05))
    a = opa.lyapunov_benettin(system, periods=60, transient=20, engine="solver")
    b = opa.lyapunov_benettin(system, periods=60, transient=20, engine="plain")
    assert a.impacts == b.impacts > 0
    assert a.exponent == pytest.approx(b.exponent, abs=1e-6)
    assert math.isfinite(a.exponent)


# --------------------------------------------------------------------------- the 2-D step


def _wrapped_sum(terms, indent):
    """' + '.join(terms) broken into lines of at most 100 characters, the first line
    starting at column ``indent`` and the others aligned under it."""
    lines, line = [], ""
    for term in terms:
        piece = term if not line else " + " + term
        if indent + len(line + piece) > 97 and line:
            lines.append(line + " +")
            line = term
        else:
            line += piece
    lines.append(line)
    return ("\n" + " " * indent).join(lines)


#: the force law's arguments and right-hand side of each 2-D register path: the paper's
#: law (mu, a, c), a user's polynomial law (``force_law``'s tuple of C[j, k]) and a
#: compiled force function (its address and its constants' address)
LAWS = {"paper": ("mu, a, c", "_f2"), "polynomial": ("law", "_f2_poly"),
        "function": ("address, theta", "_f2_fn")}
SUFFIX = {"paper": "", "polynomial": "_poly", "function": "_fn"}


def unrolled_step(name, A, C, B, last, law="paper"):
    """Source of the kernel's unrolled step of the two-dimensional system for a tableau:
    every stage a scalar, the sums in the order of the general loops (zero coefficients,
    which add exact zeros there, skipped)."""
    args, f2 = LAWS[law]
    lines = ["@njit(cache=True)",
             f"def {name}(t, x, v, h, k0x, k0v, {args}, f, w, cw, sw, force, sticking):",
             '    """One step of the 2-D system, generated from the tableau (see ``step2``)."""']
    for s in range(1, last):
        for comp, state in (("x", "x"), ("v", "v")):
            terms = [f"{float(A[s, r])!r} * k{r}{comp}" for r in range(s) if A[s, r] != 0.0]
            head = f"    {state}{s} = {state} + h * ("
            lines.append(head + _wrapped_sum(terms, len(head)) + ")")
        lines.append(f"    drive = stage_forcing(t, {float(C[s])!r}, h, f, w, cw, sw, force)")
        lines.append(f"    k{s}x, k{s}v = {f2}(x{s}, v{s}, {args}, drive, sticking)")
    for comp in ("x", "v"):
        terms = [f"{float(B[r])!r} * k{r}{comp}" for r in range(last) if B[r] != 0.0]
        head = f"    {comp}n = {comp} + h * ("
        lines.append(head + _wrapped_sum(terms, len(head)) + ")")
    if float(C[last - 1]) != 1.0:  # else stage last - 1 is at t + h too: its force is reused
        lines.append("    drive = stage_forcing(t, 1.0, h, f, w, cw, sw, force)")
    lines.append(f"    k{last}x, k{last}v = {f2}(xn, vn, {args}, drive, sticking)")
    for comp in ("x", "v"):
        names = [f"k{s}{comp}" for s in range(1, last + 1)]
        lines.append(f"    k{comp} = ({_wrapped_sum(names, 10).replace(' +', ',')})")
    lines.append("    return xn, vn, kx, kv")
    return "\n".join(lines) + "\n"


def unrolled_dense_stages(name, A, C, first, stop, law="paper"):
    """Source of the kernel's dense-output stages first..stop-1 of the two-dimensional
    system: the earlier stages read from K, the new ones kept in scalars and stored."""
    args, f2 = LAWS[law]
    lines = ["@njit(cache=True)",
             f"def {name}(t, h, K, x, v, {args}, f, w, cw, sw, force, sticking):",
             f'    """Rows {first}-{stop - 1} of K (the dense-output stages) of the 2-D system, '
             'generated from',
             '    the tableau (see ``step2``)."""']
    for s in range(first, stop):
        for comp, j in (("x", 0), ("v", 1)):
            terms = [f"{float(A[s, r])!r} * " + (f"K[{r}, {j}]" if r < first else f"k{r}{comp}")
                     for r in range(s) if A[s, r] != 0.0]
            head = f"    {comp}{s} = {comp} + h * ("
            lines.append(head + _wrapped_sum(terms, len(head)) + ")")
        lines.append(f"    drive = stage_drive(t, {float(C[s])!r}, h, f, w, cw, sw, force)")
        lines.append(f"    k{s}x, k{s}v = {f2}(x{s}, v{s}, {args}, drive, sticking)")
        lines.append(f"    K[{s}, 0] = k{s}x")
        lines.append(f"    K[{s}, 1] = k{s}v")
    return "\n".join(lines) + "\n"


def kernel_steps_source(law: str = "paper") -> str:
    suffix = SUFFIX[law]
    return (unrolled_step(f"_stages2_dop853{suffix}", kernel.D8_A, kernel.D8_C, kernel.D8_B,
                          12, law) + "\n\n"
            + unrolled_dense_stages(f"_dense_stages2_dop853{suffix}", kernel.D8_A, kernel.D8_C,
                                    13, 16, law))


def test_the_unrolled_steps_are_generated_from_the_tableaux():
    """The kernel's unrolled 2-D step is exactly what the tableau generates (print
    ``kernel_steps_source()`` to regenerate them after a tableau change)."""
    source = (ROOT / "opa" / "_kernel.py").read_text()
    assert kernel_steps_source("paper") in source
    assert kernel_steps_source("polynomial") in source
    assert kernel_steps_source("function") in source


@pytest.mark.parametrize("expression, top", [
    ("mu*(1 - v^2)*v - a*x - c*x^3", 0), ("x^3 + v^3 + x^2 + v^2 + 1", 0),
    ("x*v", 1), ("x^3*v^3", 3), ("-x + 0.1*x^2*v^2", 2), ("-x + 0*x*v", 0),
    ("(1 - x^2)*v - x", 1), ("x*v + x*v^3", 3)])
def test_force_law_flags_the_highest_power_of_v_in_its_cross_terms(expression, top):
    """The register path sums the cross terms C[j, k] x^j v^k (j, k >= 1) only up to the
    highest k with a non-zero C[j, k] (none when all are zero), and gives the same g as
    the full sum."""
    coefficients = opa.ForceLaw(expression).coefficients(dict(mu=0.8, a=0.5, c=0.05))[0]
    p = np.zeros(kernel.P_POLY + kernel.N_POLY)
    p[kernel.P_POLY:] = coefficients
    law = kernel.force_law(p)
    assert law[:kernel.N_POLY] == tuple(coefficients)
    assert law[kernel.N_POLY] == float(top)
    C = np.asarray(coefficients).reshape(4, 4)  # C[j, k] of x^j v^k
    for x, v in [(0.3, -0.7), (-1.2, 0.4), (2.0, 1.5)]:
        g = sum(C[j, k] * x ** j * v ** k for j in range(4) for k in range(4))
        assert kernel._f2_poly(x, v, law, 0.25, False) == pytest.approx((v, g + 0.25),
                                                                         rel=1e-14, abs=1e-14)


def two_node_rule(inputs):
    """The DMR's rule written with two nodes, the second of weight 0: the same system,
    but not the kernel's one-node deterministic case, so its general loop runs (each
    node's deviation from the force at the mean state is exactly 0)."""
    table, weights, U = rule(inputs)
    return (np.ascontiguousarray(np.repeat(table, 2, axis=0)), np.array([1.0, 0.0]),
            np.ascontiguousarray(np.repeat(U, 2, axis=0)))


@pytest.mark.parametrize("law", [None, "mu*(1 - v^2)*v - a*x - c*x^3 + 0.1*x^2*v",
                                 "-0.1*v^3 + 0.2*v^2 - 0.3*v - a*x + 0.4*x^2 - c*x^3 + 0.05",
                                 "-x - c*x^3 + 0.2*x*v^2 - 0.1*x^2*v",
                                 "-x - 0.3*v + 0.1*x^3*v^3 + 0.2*x*v^2 + 0.05*x^2*v"])
@pytest.mark.parametrize("method", [kernel.METHOD_DOP853, kernel.METHOD_DP5])
@pytest.mark.parametrize("h, force, sticking", [(0.07, 0.0, False), (0.3, 0.8, False),
                                                (1.0, 0.0, False), (0.07, 0.5, True)])
def test_the_two_dimensional_step_equals_the_general_loop_bit_for_bit(method, h, force,
                                                                       sticking, law):
    """The same step and dense output by the unrolled 2-D path and by the general loop
    (forced by :func:`two_node_rule`): every stage, the new state and every dense-output
    coefficient equal, for the paper's law and a user's polynomial law."""
    osc = opa.preset("3.2", force=law)
    inputs = kernel_inputs(osc, opa.SolverOptions())
    p, cfg = inputs.p, inputs.cfg
    nodes, weights, U = rule(inputs)
    general_nodes, general_weights, general_U = two_node_rule(inputs)
    z = np.array([-0.37, 0.81])
    stages, results = [], []
    for rule_nodes, weights, U in ((nodes, weights, U),
                                   (general_nodes, general_weights, general_U)):
        Ks = np.zeros((kernel.K_ROWS, 2))
        work = np.empty((6, 2))
        drive = kernel.forcing(2.3, p, force)
        kernel.vector_field(z, 0, p, cfg, rule_nodes, weights, U, 2.3, drive, sticking, Ks[0],
                            work)
        z_new = np.empty(2)
        kernel.rk_step(method, 2.3, z, h, Ks, z_new, np.empty(2), 0, p, cfg, rule_nodes, weights,
                       U, force, sticking, work)
        F = np.zeros((7, 2))  # and the dense output: DOP853's three more stages, then F
        kernel.dense_prepare(method, 2.3, z, z_new, h, Ks, F, np.empty(2), 0, p, cfg, rule_nodes,
                             weights, U, force, sticking, work)
        stages.append(Ks)
        results.append(np.concatenate([z_new, F.ravel()]))
    assert kernel.is_deterministic(0, cfg, nodes, p)
    assert not kernel.is_deterministic(0, cfg, general_nodes, p)
    shifted = nodes.copy()
    column = kernel.T_MU if law is None else kernel.T_POLY + 1  # mu, or C[0, 1]
    shifted[0, column] += 1e-12  # a sample's own table is not the parameter vector's
    assert not kernel.is_deterministic(0, cfg, shifted, p)
    np.testing.assert_array_equal(stages[0], stages[1])
    np.testing.assert_array_equal(results[0], results[1])


# Cases for the driver's 2-D register path against its general loop: impacts with Dirac
# kicks and with pulses, and chattering into sticking with releases (Dirac and pulsed).
REGISTER_CASES = {
    "impacts, Dirac": (opa.preset("3.2"), {}, 1e-8),
    "impacts, pulses": (opa.preset("3.2"), {"impulse": "pulse", "pulse_width": 0.3}, 1e-8),
    "sticking": (opa.preset("3.2", mu=0.1, a=1.0, c=0.0, f=1.0, omega=1.3, eta=0.5, delta=-0.5,
                            x0=-1.0, F0=0.4), {}, 1e-9),
    "sticking, pulses": (opa.preset("3.2", mu=0.1, a=1.0, c=0.0, f=1.0, omega=1.3, eta=0.5,
                                    delta=-0.5, x0=-1.0, F0=0.4),
                         {"impulse": "pulse", "pulse_width": 0.7}, 1e-9),
}


@pytest.mark.parametrize("case", list(REGISTER_CASES))
@pytest.mark.parametrize("with_stats", [False, True])
def test_the_register_path_of_the_driver_is_the_general_loop_bit_for_bit(case, with_stats):
    """A whole DOP853 trajectory by the driver's 2-D register path (stages in scalars,
    stored for the dense output only when needed) and by its general loop (forced by
    :func:`two_node_rule`): every output, event, statistic and counter equal."""
    osc, fields, tol = REGISTER_CASES[case]
    options = opa.SolverOptions(rtol=tol, atol=tol, chatter_velocity=0.05)
    inputs = kernel_inputs(osc, options, **fields)
    p, cfg = inputs.p, inputs.cfg
    nodes, weights, U = rule(inputs)
    times = np.linspace(0.0, 80.0, 161)
    runs = []
    for rule_nodes, weights, U in ((nodes, weights, U), two_node_rule(inputs)):
        out, log = np.empty((len(times), 2)), np.empty((4000, 3))
        stats = np.empty((len(times) - 1 if with_stats else 0, kernel.N_STATS))
        counters = kernel.integrate(np.array([osc.x0, osc.v0]), 0, times, True, False, p, cfg,
                                    rule_nodes, weights, U, options.rtol, options.atol, out, stats,
                                    np.empty(0), log)
        runs.append((counters, out, stats, log[:counters[1]]))
    (counters, out, stats, log), general = runs
    assert counters[0] == kernel.OK and counters[2] >= 5  # impacts
    kinds = set(log[:, 2].astype(int))
    if case.startswith("sticking"):
        assert {kernel.EV_STICK, kernel.EV_RELEASE} <= kinds
    assert counters == general[0]
    for mine, theirs in zip((out, stats, log), general[1:]):
        np.testing.assert_array_equal(mine, theirs)


@pytest.mark.parametrize("method", ["dop853", "dp5"])
@pytest.mark.parametrize("depth, tol", [(1e-6, 1e-8), (1e-6, 1e-10), (1e-6, 1e-12),
                                        (1e-9, 1e-10), (1e-9, 1e-12)])
def test_a_shallow_impact_is_found_whatever_the_step_length(depth, tol, method):
    """x'' = -x, x = -cos t peaks at 1 at t = pi; the wall at 1 - depth is reached at
    t = pi - arccos(1 - depth) with speed sqrt(1 - (1 - depth)^2) (4.5e-5 for depth 1e-9).
    Steps are long at loose tolerances (about a radian at 1e-8): the cheap exclusion
    (``wall_margin``) must let the step through to the dense-output scan. The tolerance
    must be below the depth (a global error of the size of the depth can lower the
    computed apex below the wall); the impact time is then sensitive as 1/speed
    (measured errors 2e-11 to 7e-6)."""
    delta = 1.0 - depth
    osc = opa.Oscillator(mu=0.0, a=1.0, c=0.0, f=0.0, omega=1.0, F0=0.0, delta=delta,
                         eta=1.0, x0=-1.0, v0=0.0)
    ds = opa.simulate_dmr(osc, times=np.array([0.0, 4.0]),
                          options=opa.SolverOptions(rtol=tol, atol=tol, method=method))
    assert ds.impact_time.size == 1
    assert ds.impact_time.item() == pytest.approx(math.pi - math.acos(delta), abs=1e-5)
    # the speed near the apex is pi - t: a time error of 2e-6 is 5% of 4.5e-5
    assert ds.impact_velocity.item() == pytest.approx(math.sqrt(1 - delta**2), rel=0.1)


@pytest.mark.parametrize("method", [kernel.METHOD_DOP853, kernel.METHOD_DP5])
@pytest.mark.parametrize("h", [0.05, 0.3, 1.0, 1.5])
def test_the_wall_margin_bounds_the_rise_inside_a_step(h, method):
    """On x = -cos t the true excess of x over the higher end value inside a step (the
    apex 1 at t = pi where the step contains it) and the dense output's excess stay below
    ``wall_margin``, for steps placed anywhere around the apex."""
    last = kernel.last_stage(method)
    for start in np.linspace(math.pi - 1.2 * h, math.pi + 0.2 * h, 15):
        y0 = np.array([-math.cos(start), math.sin(start)])
        stages, y_new, F = kernel_step(HARMONIC, start, y0, h, method)
        margin = kernel.wall_margin(stages, last, 1, h)
        theta = np.linspace(0.0, 1.0, 401)
        true_top = np.max(-np.cos(start + theta * h))
        dense_top = max(kernel.dense_value(method, th, y0, F, 0) for th in theta)
        ends = max(y0[0], y_new[0])
        assert true_top - ends <= margin
        assert dense_top - ends <= margin


# --------------------------------------------------------------------------- the phases
# The driver's phases one at a time, on cases with closed forms: a mass in free flight
# (x'' = 0) or pushed by a constant force g (mu = a = c = 0, f = g, omega tiny), and
# x'' = cos t at rest on the wall.
ETA, G = 0.5, 1.0


def phase_system(osc):
    """(p, cfg, nodes, weights, U, work) of the DMR of ``osc`` (the one-node rule)."""
    inputs = kernel_inputs(osc, opa.SolverOptions())
    return (inputs.p, inputs.cfg, *rule(inputs), np.empty((6, 1)))


def free_mass(f=0.0, omega=1e-6):
    return opa.Oscillator(mu=0.0, a=0.0, c=0.0, f=f, omega=omega, eta=ETA, delta=0.0, F0=0.0,
                          x0=-0.5, v0=0.0)


@pytest.mark.parametrize("method", [kernel.METHOD_DOP853, kernel.METHOD_DP5])
def test_the_impact_phase_restepping_to_the_wall_reflects_the_velocity(method):
    """Free flight x = -0.5 + 2 t reaches the wall at t = 0.25, halfway through a step
    of 0.5: the impact phase re-steps there (exact for a straight line), applies
    v+ = -eta v-, logs the impact with v- and sets K[0] = f(t, y+)."""
    p, cfg, nodes, weights, U, work = phase_system(free_mass())
    cfg[kernel.C_METHOD] = method
    z, z_new, ztmp = np.array([-0.5, 2.0]), np.empty(2), np.empty(2)
    stages, stages2 = np.zeros((kernel.K_ROWS, 2)), np.zeros((kernel.K_ROWS, 2))
    stages[0] = [2.0, 0.0]  # f(0, z)
    f_minus, f_plus = np.empty(2), np.empty(2)
    stats = np.zeros((1, kernel.N_STATS))
    stats[0, kernel.S_MIN_VELOCITY] = np.inf
    log = np.zeros((4, 3))
    t, status, sticking, n_events, n_impacts, evals = kernel.impact_event(
        method, 0.0, 0.5, 0.5, z, z_new, 0, 0.0, 0, 0, 0, p, cfg, nodes, weights, U, stages,
        stages2, ztmp, f_minus, f_plus, work, stats, log, np.inf)
    assert status == kernel.OK and not sticking and (n_events, n_impacts) == (1, 1)
    assert t == pytest.approx(0.25, abs=1e-14)
    np.testing.assert_allclose(z, [0.0, -ETA * 2.0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(log[0], [t, 2.0, kernel.EV_IMPACT], rtol=1e-14)
    assert stats[0, kernel.S_IMPACTS] == 1.0
    assert stats[0, kernel.S_MIN_VELOCITY] == pytest.approx(2.0)
    np.testing.assert_allclose(stages[0], [-ETA * 2.0, 0.0], rtol=0, atol=1e-14)
    assert evals >= kernel.last_stage(method) + 1


@pytest.mark.parametrize("g", [G, -G])
def test_the_chatter_phase_sticks_at_the_accumulation_time(g):
    """After an impact at v- (below the chatter velocity) with a constant force g into
    the wall, the bounces of speeds eta^k v- last 2 eta^k v- / g each, together
    2 eta v- / (g (1 - eta)): the mean sticks then. Pulled away (g < 0), the rebound
    v+ = -eta v- stands."""
    p, cfg, nodes, weights, U, work = phase_system(free_mass(f=g))
    v_minus = 1e-7
    z = np.array([0.0, -ETA * v_minus])  # after the impact law
    sticking, t_stick = kernel.chatter(1.0, z, 0, v_minus, 0.0, p, cfg, nodes, weights, U,
                                       np.empty(2), work)
    if g > 0:
        assert sticking
        assert t_stick == pytest.approx(1.0 + 2 * ETA * v_minus / (g * (1 - ETA)), rel=1e-12)
        np.testing.assert_array_equal(z, [0.0, 0.0])
    else:
        assert not sticking
        np.testing.assert_array_equal(z, [0.0, -ETA * v_minus])


@pytest.mark.parametrize("strength", [0.4, -0.5])
def test_the_kick_phase_at_rest_on_the_wall(strength):
    """A kick into the wall while the mean rests on it is an impact at once (v = -eta
    kick, logged EV_KICK with the kick); either kick ends the sticking (EV_RELEASE)."""
    p, cfg, table, weights, U, _ = phase_system(free_mass())
    z = np.array([0.0, 0.0])
    stats, log = np.zeros((1, kernel.N_STATS)), np.zeros((4, 3))
    sticking, n_events, n_impacts = kernel.kick(2.0, z, 0, strength, True, 0, 0, 0, p, cfg,
                                                table, weights, U, stats, log)
    into = strength > 0
    assert not sticking and n_impacts == int(into) and stats[0, kernel.S_IMPACTS] == int(into)
    assert z[1] == (-ETA * strength if into else strength)
    kinds = [kernel.EV_KICK, kernel.EV_RELEASE] if into else [kernel.EV_RELEASE]
    np.testing.assert_array_equal(log[:n_events, 2], kinds)
    if into:
        np.testing.assert_array_equal(log[0, :2], [2.0, strength])


def test_the_release_phase_finds_where_the_force_turns():
    """x'' = cos t held on the wall over a step from 1 to 2.5: released at t = pi/2,
    where the force turns away from the wall, at rest there, with K[0] = f(t, y)."""
    p, cfg, nodes, weights, U, work = phase_system(free_mass(f=1.0, omega=1.0))
    method, t0, h = kernel.METHOD_DOP853, 1.0, 1.5
    z, z_new, ztmp = np.zeros(2), np.empty(2), np.empty(2)
    stages, F = np.zeros((kernel.K_ROWS, 2)), np.empty((7, 2))
    kernel.rk_step(method, t0, z, h, stages, z_new, ztmp, 0, p, cfg, nodes, weights, U, 0.0, True,
                   work)
    kernel.dense_prepare(method, t0, z, z_new, h, stages, F, ztmp, 0, p, cfg, nodes, weights, U,
                         0.0, True, work)
    assert kernel.pulls_off(t0 + h, z_new, 0.0, p, cfg, nodes, weights, U, np.empty(2), work)
    assert not kernel.pulls_off(t0, z, 0.0, p, cfg, nodes, weights, U, np.empty(2), work)
    log = np.zeros((2, 3))
    t, status, n_events, evals = kernel.release_event(method, t0, h, z, 0, 0.0, 0, p, cfg, nodes,
                                                      weights, U, stages, F, ztmp, np.empty(2),
                                                      work, log, np.inf)
    assert status == kernel.OK and n_events == 1 and evals > 30
    assert t == pytest.approx(math.pi / 2, abs=1e-12)
    np.testing.assert_array_equal(z, [0.0, 0.0])
    np.testing.assert_array_equal(log[0], [t, 0.0, kernel.EV_RELEASE])
    np.testing.assert_allclose(stages[0], [0.0, math.cos(t)], rtol=0, atol=1e-15)


def test_the_outputs_phase_stores_and_renormalises():
    """Every output time reached is stored with the interval's sticking flag; Benettin's
    step scales W to unit norm and logs the growth, or -inf (W restarted from equal
    entries) when sticking collapsed it."""
    z = np.array([1.0, 2.0, 3.0, 4.0, 0.0, 0.0])  # y (2) and W (2 x 2)
    t_out = np.array([0.0, 1.0, 1.0 + 1e-9, 2.0])
    out, stats = np.full((4, 2), np.nan), np.zeros((3, kernel.N_STATS))
    k = kernel.store_outputs(1.0, z, 2, 1, True, t_out, out, stats)
    assert k == 2 and np.isnan(out[0]).all() and np.isnan(out[2:]).all()
    np.testing.assert_array_equal(out[1], [1.0, 2.0])
    assert stats[0, kernel.S_STICKING] == 1.0 and stats[1, kernel.S_STICKING] == 0.0
    growth = np.zeros(3)
    kernel.renormalise_tangent(z, 2, 1, 3, growth)
    assert growth[0] == pytest.approx(math.log(5.0)) and growth[1] == pytest.approx(0.0)
    np.testing.assert_allclose(z[2:], [0.6, 0.8, 0.0, 0.0])
    z[2:] = 0.0
    kernel.renormalise_tangent(z, 2, 3, 4, growth)
    assert growth[2] == -np.inf
    np.testing.assert_array_equal(z[2:], np.full(4, 0.5))


@pytest.mark.parametrize("sticking, acc, x0, v0, changes", [
    (True, -1.0, 0.0, 0.0, True), (True, 1.0, 0.0, 0.0, False),
    (False, 1.0, 0.0, 0.0, True), (False, 1.0, 0.0, 1e-9, False),
    (False, 1.0, -1e-9, 0.0, False), (False, -1.0, 0.0, 0.0, False)])
def test_the_contact_at_a_breakpoint(sticking, acc, x0, v0, changes):
    """Sticking ends at a breakpoint when the force turns away from the wall, and begins
    there only at rest on the wall with the force into it."""
    assert kernel.contact_changes(sticking, acc, x0, v0, 0.0) == changes
