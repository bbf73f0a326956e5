"""Issue 43's target for an uncertain impact: eta = 0.8 + 0.05 xi and delta = 0 + 0.05 xi
(and, with ``--drive``, issue 42's f = 1.5 + 0.05 xi, omega = 3.98 + 0.01 xi and
F0 = 0.1 + 0.02 xi).

Case: the section 3.2 set at omega = 3.98, 10 forcing periods, 8 outputs per period, xi
of the paper's semicircle law (``--distribution`` to change it). For each uncertain
impact parameter:

- the reference: E[x] and Var[x] of 2^16 scrambled Sobol samples of the true systems, in
  16 independent scramblings whose spread gives the reference's own standard error;
- the paper's OPA: one element, the mean impact law (eq. (28)), N = 4;
- one element with the saltation law, N = 4;
- adaptive ME-OPA (saltation law, N = 2) with element budgets 64, 256 and 1024 (the
  adaptive refinement stops earlier where its tolerance, 1e-6, is met);
- the certificate: ``compare.verify`` of the largest budget's run (its verdict).

Prints the RMS over the 81 outputs of the error of E[x] and Var[x] against the reference,
the elements used and the seconds, then the verdict. The target is RMS(E[x]) <= 1e-4 and
the verdict "agrees".

    python -m benchmarks.impact_uncertain [--smoke] [--distribution uniform]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

import compare
import mc
import opa

PARAMETERS = {"eta": 0.05, "delta": 0.05}
DRIVE = {"f": 0.05, "omega": 0.01, "F0": 0.02}
TARGET = 1e-4


def rms(a, b) -> float:
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def rows(name: str, distribution: str | None, log2_samples: int, budgets) -> list[str]:
    osc = opa.preset("3.2", omega=3.98)
    base = opa.System(osc, uncertain=name, sigma={**PARAMETERS, **DRIVE}[name],
                      distribution=distribution, order=4)
    grid = dict(periods=10, per_period=8)
    start = time.perf_counter()
    ref = mc.simulate_mc(base, samples=2**log2_samples, replicates=16, progress=False, **grid)
    own = float(np.sqrt(np.mean(ref.x_sem.values ** 2)))
    lines = [f"{name}: reference 2^{log2_samples} Sobol samples, "
             f"{time.perf_counter() - start:.1f} s; max Var[x] {float(ref.x_var.max()):.3g}; "
             f"its own standard error of E[x], RMS {own:.2e}"]
    runs = [("paper: 1 element, mean law, N = 4", base, None, None),
            ("1 element, saltation law, N = 4", base.replace(impact_law="saltation"), None,
             None)]
    runs += [(f"adaptive ME-OPA, saltation, N = 2, budget {k}",
              base.replace(impact_law="saltation", order=2), "adaptive", k) for k in budgets]
    last = None
    for label, system, elements, budget in runs:
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the budget warning: the row says the count
            ds = opa.simulate_opa(system, elements=elements, max_elements=budget, **grid)
        seconds = time.perf_counter() - start
        count = ds.sizes.get("element", 1)
        err_mean, err_var = rms(ds.x_mean, ref.x_mean), rms(ds.x_var, ref.x_var)
        flag = "meets" if err_mean <= TARGET else "misses"
        lines.append(f"  {label:44s} elements {count:4d}  RMS E[x] {err_mean:.2e} ({flag} "
                     f"1e-4)  RMS Var[x] {err_var:.2e}  {seconds:6.1f} s")
        last = ds
    start = time.perf_counter()
    checked = compare.verify(last, samples=256, max_samples=4096)
    lines.append(f"  verify (256..4096 true systems) of the last run: "
                 f"{checked.attrs['verdict']} (mean {checked.attrs['verdict_mean']}, var "
                 f"{checked.attrs['verdict_var']}), {checked.attrs['verify_samples']} true "
                 f"systems, {time.perf_counter() - start:.1f} s")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="tiny sizes")
    parser.add_argument("--distribution", default=None, help="law of xi (default semicircle)")
    parser.add_argument("--drive", action="store_true",
                        help="f, omega and F0 uncertain instead of eta and delta")
    args = parser.parse_args(argv)
    load = os.getloadavg()
    print(f"impact_uncertain: load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; "
          f"distribution {args.distribution or 'semicircle'}", flush=True)
    for name in DRIVE if args.drive else PARAMETERS:
        sizes = (10, (8,)) if args.smoke else (16, (64, 256, 1024))
        print("\n".join(rows(name, args.distribution, *sizes)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
