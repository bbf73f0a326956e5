"""Boxes above the first split with three uncertain parameters: how the RMS error of E[x]
of multi-element OPA falls with the number of boxes, against scrambled Sobol Monte Carlo
of the true systems.

Case (issue 42's d = 3 case above the split): section 3.2 at omega = 3.98, 10 periods, 8
outputs per period, (mu, c, a) uncertain, semicircle laws, relative sizes (0.02, 0.1,
0.02) at scale s = 2 (above the first split at s = 0.817, ``benchmarks.bench_several``),
impact law ``saltation``. Runs: adaptive boxes with budgets 64, 256 and 1024 and uniform
boxes K = 4, 8 per parameter, at N = 1 and 2. Each row says how many boxes were computed
by collocation of the true systems (their OPA system escaped near grazing) and the
right-hand sides: the OPA systems' times the rule's nodes, plus the collocated boxes'
true systems. The reference's own RMS standard error is printed with it.

With ``--verify`` each run is also certified (``compare.verify``) and its verdicts on
the mean and the variance are read against the reference with the certificate's own rule
(``benchmarks.verify_several_untuned.ratios`` and ``reading``): the count of wrong
verdicts is printed (a case the certificate was not tuned to).

With ``--oracle`` the first adaptive run's boxes flagged ``element_split_inside`` get
their mean from 400 true systems each (uniform points in the box weighted by the
semicircle density) in place of OPA's: the error left is that of the boxes with no
detected split.

    python -m benchmarks.boxes_above_split [--log2-samples 20] [--budgets 64,256,1024]
        [--verify] [--oracle]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

import mc
import opa
from benchmarks.bench_several import PER_PERIOD, PERIODS, rms, system
from opa._elements import ElementBudgetWarning


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log2-samples", type=int, default=20)
    parser.add_argument("--budgets", default="64,256,1024")
    parser.add_argument("--uniform", default="4,8")
    parser.add_argument("--orders", default="1,2")
    parser.add_argument("--verify", action="store_true")
    parser.add_argument("--oracle", action="store_true")
    args = parser.parse_args(argv)
    print(f"load average before: {os.getloadavg()[0]:.2f}", flush=True)
    start = time.perf_counter()
    ref = mc.simulate_mc(system(3, 2.0), samples=2 ** args.log2_samples, sampler="sobol",
                         periods=PERIODS, per_period=PER_PERIOD, progress=False)
    print(f"reference: 2^{args.log2_samples} Sobol samples, "
          f"{time.perf_counter() - start:.1f} s, RMS standard error of E[x] "
          f"{float(np.sqrt((ref.x_sem ** 2).mean())):.2e}", flush=True)
    print("| N | boxes | computed | collocated | RMS error E[x] | RMS error Var[x] | "
          "OPA RHS x nodes + true RHS | wall s |")
    print("|---|---|---|---|---|---|---|---|")
    runs = []
    settings = ([("adaptive", int(b)) for b in args.budgets.split(",")]
                + [(int(k), None) for k in args.uniform.split(",")])
    for order in (int(n) for n in args.orders.split(",")):
        for elements, budget in settings:
            run = system(3, 2.0, order, impact_law="saltation")
            extra = {} if budget is None else {"max_elements": budget}
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ElementBudgetWarning)
                ds = opa.simulate_opa(run, periods=PERIODS, per_period=PER_PERIOD,
                                      elements=elements, **extra)
            seconds = time.perf_counter() - start
            label = f"adaptive, budget {budget}" if budget else f"uniform, K = {elements}"
            cost = (int(ds.attrs["rhs_evaluations"]) * int(ds.attrs["nodes"])
                    + int(ds.attrs["collocation_rhs_evaluations"]))
            print(f"| {order} | {label} | {ds.attrs['elements']} | "
                  f"{ds.attrs['collocation_elements']} | {rms(ds.x_mean, ref.x_mean):.2e} | "
                  f"{rms(ds.x_var, ref.x_var):.2e} | {cost:,} | {seconds:.1f} |", flush=True)
            runs.append((f"N = {order}, {label}", ds))
    if args.verify:
        _verify(runs, ref)
    if args.oracle:
        _oracle(next(ds for label, ds in runs if "adaptive" in label), ref)
    print(f"load average after: {os.getloadavg()[0]:.2f}")


def _oracle(ds, ref, points: int = 400, seed: int = 3) -> None:
    """The run's E[x] with each flagged box's mean from sampled true systems."""
    from opa._run import run_batch

    run = system(3, 2.0, int(ds.attrs["N"]), impact_law="saltation")
    options = opa.SolverOptions()
    rng = np.random.default_rng(seed)
    flags = ds.element_split_inside.values.astype(bool)
    means = ds.element_x_coef.values[:, 0, :].copy()
    for e in np.flatnonzero(flags):
        lower, upper = ds.element_lower.values[e], ds.element_upper.values[e]
        xi = lower + (upper - lower) * rng.random((points, 3))
        weight = np.prod(np.sqrt(1.0 - xi ** 2), axis=1)
        batch = run_batch(run.sampled_inputs(options, xi=xi), run.deterministic()
                          .initial_state(), ds.time.values, rtol=options.rtol,
                          atol=options.atol)
        means[e] = weight / weight.sum() @ batch.states[:, :, 0]
    probability = ds.element_probability.values
    mean = (probability[:, None] * means).sum(axis=0)
    print(f"oracle ({ds.attrs['elements']} boxes, N = {ds.attrs['N']}): {int(flags.sum())} "
          f"flagged boxes of probability {probability[flags].sum():.3f}; RMS error of E[x] "
          f"{rms(ds.x_mean, ref.x_mean):.2e} with OPA's means, {rms(mean, ref.x_mean):.2e} "
          f"with the flagged boxes' from {points} true systems each")


def _verify(runs, ref) -> None:
    """Each run's certificate, read against the reference (``reading``'s words)."""
    import compare
    from benchmarks.verify_several_untuned import ratios, reading

    tally: dict[str, int] = {}
    for label, ds in runs:
        verdicts = compare.verify(ds).attrs
        truth = ratios(ds, ref)
        words = [reading(verdicts[f"verdict_{q}"], r) for q, r in zip(("mean", "var"), truth)]
        for word in words:
            tally[word] = tally.get(word, 0) + 1
        print(f"{label}: mean {verdicts['verdict_mean']} (truth's ratio {truth[0]:.2f}: "
              f"{words[0]}), variance {verdicts['verdict_var']} ({truth[1]:.2f}: {words[1]})",
              flush=True)
    print("verdicts:", ", ".join(f"{k} {v}" for k, v in sorted(tally.items())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
