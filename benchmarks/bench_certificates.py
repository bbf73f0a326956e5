"""How often a certificate is wrong, and how well its intervals cover, on cases it was
not tuned to (tests/certificate_cases.py: truths from 2^20 jittered true systems that
owe nothing to ``compare``).

For each case and seed:

* the sequential certificate (``compare.verify``, 256 true systems doubling to 4096):
  its verdict against the case's true verdict (the criterion evaluated with the truth);
  a *false agree* is "agrees" where the truth disagrees, a *false disagree* the reverse;
* one round at M = 256 and at M = 1024: whether the 95 % Student's t intervals of
  ``cv_x_mean`` and ``cv_x_var`` hold the truth, over the seeds and the outputs (t = 0,
  where every sample sits at x0, is left out; the truth's own standard error is added
  in quadrature).

The full table (100 seeds per case, about 20 minutes on 2 cores)::

    python -m benchmarks.bench_certificates --seeds 100 --out certificates.md

``pytest benchmarks -m "not slow"`` runs one case on 2 seeds with a 2^14-sample truth
(the smoke CI runs); ``pytest benchmarks/bench_certificates.py -m slow`` the full table.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np
import pytest

from tests.certificate_cases import CASES, run_case, true_ratio, truth


def _t_half(se, dof):
    from scipy import stats

    return stats.t.ppf(0.975, np.asarray(dof, dtype=float)) * se


def judge(name: str, seeds: int, *, log2_truth: int = 20, sizes=(256, 1024),
          sequential_from: int = 256, sequential_to: int = 4096) -> dict:
    """The false-agree and false-disagree counts and the coverage of case ``name``."""
    from compare import verify

    run = run_case(name)
    mean, var, mean_se, var_se = truth(name, log2_truth)
    ratio = true_ratio(run, mean, var)
    truly = "agrees" if max(ratio.values()) <= 1.0 else "disagrees"
    verdicts = {"agrees": 0, "disagrees": 0, "undecided": 0}
    # per quantity: how often its own verdict contradicts its own truth
    truly_each = {key: "agrees" if r <= 1.0 else "disagrees" for key, r in ratio.items()}
    wrong_each = {"mean": 0, "var": 0}
    samples = []
    for seed in range(seeds):
        v = verify(run, samples=sequential_from, max_samples=sequential_to, seed=seed)
        verdicts[v.attrs["verdict"]] += 1
        for key in wrong_each:
            said = v.attrs[f"verdict_{key}"]
            wrong_each[key] += said != "undecided" and said != truly_each[key]
        samples.append(int(v.attrs["verify_samples"]))
    coverage = {}
    for M in sizes:
        hits = {"mean": [], "var": []}
        for seed in range(seeds):
            v = verify(run, samples=M, max_samples=M, sequential=False, seed=1000 + seed)
            for key, want, want_se in (("mean", mean, mean_se), ("var", var, var_se)):
                se = np.hypot(v[f"cv_x_{key}_sem"].values, want_se)
                half = _t_half(se, v[f"cv_x_{key}_dof"].values)
                hits[key].append((np.abs(v[f"cv_x_{key}"].values - want) <= half)[1:])
        coverage[M] = {key: float(np.mean(h)) for key, h in hits.items()}
    wrong = verdicts["agrees"] if truly == "disagrees" else verdicts["disagrees"]
    return {"case": name, "ratio": ratio, "truly": truly, "verdicts": verdicts,
            "wrong": wrong, "wrong_each": wrong_each, "seeds": seeds,
            "median_samples": float(np.median(samples)),
            "coverage": coverage}


def cost(name: str, seeds: int, *, log2_truth: int = 20, rms_at: int = 512) -> dict:
    """What a default certificate (``verify(run)``: 256 doubling to 4096) costs on case
    ``name``: the median true runs and seconds over ``seeds`` seeds, and the RMS error
    of the control-variate E[x] over seeds and outputs from one round of ``rms_at``."""
    from compare import verify

    run = run_case(name)
    mean = truth(name, log2_truth)[0]
    verify(run, seed=0)  # compiled and warm
    runs, seconds, errors = [], [], []
    for seed in range(seeds):
        start = time.perf_counter()
        v = verify(run, seed=seed)
        seconds.append(time.perf_counter() - start)
        runs.append(int(v.attrs["verify_samples"]))
        one = verify(run, samples=rms_at, max_samples=rms_at, sequential=False,
                     seed=500 + seed)
        errors.append(one.cv_x_mean.values - mean)
    return {"case": name, "median_runs": float(np.median(runs)),
            "median_seconds": float(np.median(seconds)),
            "rms_error": float(np.sqrt(np.mean(np.square(errors)))), "rms_at": rms_at}


def coverage_by_dof(name: str, seeds: int, M: int = 256, *, log2_truth: int = 20,
                    bands=((0, 10), (10, 30), (30, math.inf))) -> dict:
    """Coverage of the 95 % intervals of case ``name`` at one round of ``M``, over seeds,
    outputs and both estimates, split by the interval's Welch-Satterthwaite degrees of
    freedom: a standard error that holds on average may still fail where its degrees of
    freedom are few. Returns {(lo, hi): (cells, coverage)}."""
    from compare import verify

    run = run_case(name)
    mean, var, mean_se, var_se = truth(name, log2_truth)
    hits, dofs = [], []
    for seed in range(seeds):
        v = verify(run, samples=M, max_samples=M, sequential=False, seed=2000 + seed)
        for key, want, want_se in (("mean", mean, mean_se), ("var", var, var_se)):
            dof = v[f"cv_x_{key}_dof"].values
            half = _t_half(np.hypot(v[f"cv_x_{key}_sem"].values, want_se), dof)
            hits.append((np.abs(v[f"cv_x_{key}"].values - want) <= half)[1:])
            dofs.append(dof[1:])
    hits, dofs = np.concatenate(hits), np.concatenate(dofs)
    out = {}
    for lo, hi in bands:
        inside = (dofs >= lo) & (dofs < hi)
        out[(lo, hi)] = (int(inside.sum()),
                         float(hits[inside].mean()) if inside.any() else math.nan)
    return out


def table(rows: list[dict]) -> str:
    sizes = sorted(rows[0]["coverage"])
    head = ("| case | true error / tolerance (mean, var) | truly | agrees | disagrees | "
            "undecided | wrong verdicts | wrong (mean, var) | median true runs | "
            + " | ".join(f"coverage M={M} (mean, var)" for M in sizes) + " |")
    lines = [head, "|" + "---|" * (9 + len(sizes))]
    for r in rows:
        v = r["verdicts"]
        lines.append(
            f"| {r['case']} | {r['ratio']['mean']:.3g}, {r['ratio']['var']:.3g} | "
            f"{r['truly']} | {v['agrees']} | {v['disagrees']} | {v['undecided']} | "
            f"{r['wrong']} of {r['seeds']} | {r['wrong_each']['mean']}, "
            f"{r['wrong_each']['var']} | {r['median_samples']:.0f} | "
            + " | ".join(f"{r['coverage'][M]['mean']:.3f}, {r['coverage'][M]['var']:.3f}"
                         for M in sizes) + " |")
    return "\n".join(lines)


def test_certificates_smoke():
    """One case, two seeds, a small truth: the harness runs and its numbers are sane."""
    row = judge("rare-2pct", 2, log2_truth=14, sizes=(256,), sequential_to=512)
    assert row["truly"] == "disagrees" and sum(row["verdicts"].values()) == 2
    assert 0.0 <= row["coverage"][256]["mean"] <= 1.0


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_certificate_error_rates(name):
    """The targets: no more than 1 wrong verdict in 100 seeds; coverage of the 95 %
    intervals 93-97 %. 100 seeds measure a coverage to about +-2 % (the outputs of one
    seed move together), so the test holds it to at least 0.93, the side that matters
    for honesty, and at most 0.98 (not grossly conservative)."""
    row = judge(name, 100)
    print("\n" + table([row]))
    assert row["wrong"] <= 1 and max(row["wrong_each"].values()) <= 1
    for M, cover in row["coverage"].items():
        assert 0.93 <= cover["mean"] <= 0.98 and 0.93 <= cover["var"] <= 0.98, (M, cover)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=100)
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--out", default=None)
    parser.add_argument("--cost", action="store_true",
                        help="the cost of a default certificate instead (median true runs "
                             "and seconds, RMS error of the control-variate E[x])")
    parser.add_argument("--by-dof", action="store_true",
                        help="the coverage at M = 256 split by the intervals' degrees of "
                             "freedom instead")
    args = parser.parse_args(argv)
    if args.by_dof:
        for name in args.cases.split(","):
            for (lo, hi), (cells, cover) in coverage_by_dof(name, args.seeds).items():
                print(f"{name}: dof in [{lo:g}, {hi:g}): {cells} cells, coverage {cover:.3f}")
        return 0
    if args.cost:
        for name in args.cases.split(","):
            print(cost(name, args.seeds))
        return 0
    rows = []
    start = time.perf_counter()
    for name in args.cases.split(","):
        rows.append(judge(name, args.seeds))
        print(f"{name}: {rows[-1]['verdicts']}, coverage {rows[-1]['coverage']} "
              f"({time.perf_counter() - start:.0f} s)", file=sys.stderr, flush=True)
    text = table(rows)
    print(text)
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
