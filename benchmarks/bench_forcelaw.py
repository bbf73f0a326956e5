"""Speed of a user's force law (``opa.ForceLaw``) against the built-in paper law.

Issue 43's target: a user's polynomial law runs within 10 % of the built-in law on the
bench_peers DMR and Monte Carlo cases. Cases (section 3.2 at omega = 3.98, Dirac impulse
train), all in one pytest-benchmark session:

- ``dmr``: one DMR trajectory, 1000 forcing periods (50 in smoke mode), rtol = atol =
  1e-10, stroboscopic output;
- ``mc``: 512 random samples of sigma = 0.01 on mu, 100 periods (8 samples x 5 periods
  in smoke mode), rtol = atol = 1e-8, two threads;

each with seven laws: ``builtin`` (the paper's law, eq. (1)), ``paper-as-user`` (the same
law written as ``opa.ForceLaw("mu*(1 - v^2)*v - a*x - c*x^3")``, the kernel's polynomial
path), ``duffing-user`` (``-2*zeta*v - a*x - c*x^3 + mu*(1 - v^2)*v`` with zeta = 0:
five terms, the same motion to round-off), ``cross-user`` and ``cross-v3-user`` (the
paper's law plus k x^2 v, or k x v^3, with k = 1e-300: a cross term, which takes the
register path's longer evaluation (``opa._kernel._poly_value``: one row of cross terms,
or three), on the same motion), and the escape hatch's two ways: ``paper-compiled``
(the expression compiled, ``opa.ForceLaw.compiled``) and
``paper-function`` (the Python function :func:`paper_law`, ``ForceLaw.from_function``),
both called through a pointer, with their compile excluded by the warm-up round. Each
oscillator is built once, outside the timed runs, as a user builds it once. Before
timing, each user law is checked to agree with the built-in run over 20 periods (states
to 1e-9; longer, round-off grows).

Run ``python -m pytest benchmarks/bench_forcelaw.py -p no:xdist -s`` for the numbers:
``test_force_law_ratios`` prints the ratios of the medians to the built-in law.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

import mc
import opa

OSCILLATOR = opa.preset("3.2", omega=3.98)


def paper_law(x, v, mu, a, c):
    """The paper's law as a Python function (the escape hatch's second way)."""
    return mu * (1.0 - v * v) * v - a * x - c * x * x * x


LAWS = {
    "builtin": None,
    "paper-as-user": opa.ForceLaw("mu*(1 - v^2)*v - a*x - c*x^3"),
    "duffing-user": opa.ForceLaw("-2*zeta*v - a*x - c*x^3 + mu*(1 - v^2)*v", zeta=0.0),
    "cross-user": opa.ForceLaw("mu*(1 - v^2)*v - a*x - c*x^3 + k*x^2*v", k=1e-300),
    "cross-v3-user": opa.ForceLaw("mu*(1 - v^2)*v - a*x - c*x^3 + k*x*v^3", k=1e-300),
    "paper-compiled": opa.ForceLaw.compiled("mu*(1 - v^2)*v - a*x - c*x^3"),
    "paper-function": opa.ForceLaw.from_function(paper_law),
}
TIGHT = opa.SolverOptions(rtol=1e-10, atol=1e-10)
LOOSE = opa.SolverOptions(rtol=1e-8, atol=1e-8)
_MEDIANS: dict[tuple[str, str], float] = {}
#: the horizon of the agreement check: round-off differences grow along these motions
#: (after 1000 periods the built-in and user runs differ by O(1), like two runs of the
#: built-in law started 1e-15 apart), so the runs are compared over the first 20 periods
AGREE_PERIODS = 20


OSCILLATORS = {law: OSCILLATOR if force is None else OSCILLATOR.replace(force=force)
               for law, force in LAWS.items()}


def oscillator(law: str) -> opa.Oscillator:
    return OSCILLATORS[law]


def run_dmr(law: str, periods: int):
    return opa.simulate_dmr(oscillator(law), periods=periods, options=TIGHT)


def run_mc(law: str, samples: int, periods: int):
    return mc.simulate_mc(oscillator(law), uncertain="mu", sigma=0.01, samples=samples,
                          sampler="random",
                          seed=0, periods=periods, per_period=1, options=LOOSE, progress=False)


@pytest.fixture(scope="module")
def mc_size(periods) -> tuple[int, int]:
    return (8, 5) if periods < 1000 else (512, 100)


@pytest.mark.parametrize("law", list(LAWS))
def test_force_law_dmr(benchmark, law, periods):
    reference = run_dmr("builtin", AGREE_PERIODS)
    got = run_dmr(law, AGREE_PERIODS)
    np.testing.assert_allclose(got.x, reference.x, rtol=0, atol=1e-9)  # agrees first
    benchmark.pedantic(run_dmr, args=(law, periods), rounds=31, warmup_rounds=1)
    if benchmark.stats is not None:
        _MEDIANS["dmr", law] = benchmark.stats.stats.median


@pytest.mark.parametrize("law", list(LAWS))
def test_force_law_mc(benchmark, law, mc_size):
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    reference = run_mc("builtin", mc_size[0], AGREE_PERIODS)
    got = run_mc(law, mc_size[0], AGREE_PERIODS)
    np.testing.assert_allclose(got.x_mean, reference.x_mean, rtol=0, atol=1e-9)
    benchmark.pedantic(run_mc, args=(law, *mc_size), rounds=11, warmup_rounds=1)
    if benchmark.stats is not None:
        _MEDIANS["mc", law] = benchmark.stats.stats.median


def test_force_law_ratios():
    """Median seconds of each user law over the built-in law's, per case (printed with
    ``-s``); nothing to print in smoke mode."""
    for case in ("dmr", "mc"):
        base = _MEDIANS.get((case, "builtin"))
        for law in LAWS:
            if base and (case, law) in _MEDIANS:
                print(f"{case:4s} {law:14s} {_MEDIANS[case, law]:.4f} s  "
                      f"ratio {_MEDIANS[case, law] / base:.3f}")
