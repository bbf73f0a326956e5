"""The register step alone: the seconds of one 2-D DOP853 step of a polynomial force law
against the built-in law's, in a compiled loop of steps (no driver, no events).

It separates the cost of the step from the rest of a DMR run (``bench_forcelaw``'s DMR
case times both). The law is the paper's written as a user's polynomial, so the two loops
compute the same numbers to round-off; the script checks that they do (1e-9 relative).

    python -m benchmarks.register_step_speed [--steps N] [--repeats R]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from numba import njit

import opa
from opa import _kernel as kernel
from opa._forcelaw import PAPER_EXPRESSION


@njit
def _loop_builtin(n, mu, a, c):
    x, v, total = 0.1, 0.2, 0.0
    for i in range(n):
        err, _, xn, _, kx, _ = kernel.register_step(0.001 * i, x, v, 0.01, v, -x, mu, a, c,
                                                    1.5, 3.98, 0.0, False, 1e-10, 1e-10)
        total += xn + kx[11] + err
    return total


@njit
def _loop_polynomial(n, law):
    x, v, total = 0.1, 0.2, 0.0
    for i in range(n):
        err, _, xn, _, kx, _ = kernel.register_step_poly(0.001 * i, x, v, 0.01, v, -x, law,
                                                         1.5, 3.98, 0.0, False, 1e-10, 1e-10)
        total += xn + kx[11] + err
    return total


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2_000_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    mu, a, c = 0.8, 0.5, 0.05
    p = np.zeros(kernel.P_POLY + kernel.N_POLY)
    p[kernel.P_POLY:] = opa.ForceLaw(PAPER_EXPRESSION).coefficients(dict(mu=mu, a=a, c=c))[0]
    law = kernel.force_law(p)  # the coefficients and the cross-term flag, as the driver's
    _loop_builtin(10, mu, a, c)
    _loop_polynomial(10, law)
    print(f"register_step_speed: load average {os.getloadavg()[0]:.2f}, {args.steps} steps")
    for _ in range(args.repeats):
        start = time.perf_counter()
        built_in = _loop_builtin(args.steps, mu, a, c)
        middle = time.perf_counter()
        polynomial = _loop_polynomial(args.steps, law)
        end = time.perf_counter()
        if abs(built_in - polynomial) > 1e-9 * abs(built_in):
            raise SystemExit(f"the two loops disagree: {built_in!r} != {polynomial!r}")
        ns = 1e9 / args.steps
        print(f"built-in {(middle - start) * ns:.1f} ns/step, polynomial "
              f"{(end - middle) * ns:.1f} ns/step, ratio {(end - middle) / (middle - start):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
