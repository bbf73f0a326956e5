"""How often a trust-map verdict is wrong, on cases it was not tuned to.

The trust map (``opa-mc validate``) decides each grid point with its own ensemble (16
replicates of scrambled Sobol' points, doubled while a verdict at N = Nmax is undecided)
and the three-valued bounds of :mod:`compare._trust`. Here one grid point is evaluated
per seed (``compare._trustmap._Map.evaluate``) at the single-element cases of
``tests/certificate_cases.py``, whose truths come from 2^20 jittered true systems that owe
nothing to ``compare``, and the map's verdict of the case's variant (its impact law,
Galerkin truncation, N = 4, 10 periods) is held against the truth, per quantity (mean,
variance): a *false agree* is "agrees" where the truth exceeds the tolerance, a *false
disagree* the reverse. The stated rate is alpha = 0.01 per verdict.

    python -m benchmarks.bench_map_verdicts --seeds 100

``pytest benchmarks -m "not slow"`` runs one case on 2 seeds with a 2^14-sample truth
(the smoke CI runs); ``pytest benchmarks/bench_map_verdicts.py -m slow`` the full table.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time

import numpy as np
import pytest

from tests.certificate_cases import CASES, run_case, true_ratio, truth

#: the single-element cases a grid point of the map can hold
MAP_CASES = ("rare-2pct", "rare-0.65pct", "rare-0.35pct", "paper-0.023")
NAMES = {1: "agrees", 0: "undecided", -1: "disagrees"}


def _point(name: str, seed: int, folder: str):
    """The map's point at case ``name`` with ``seed``: (verdict per quantity, samples)."""
    from compare import load_config
    from compare._trustmap import _Map

    kw = CASES[name][0]
    omega, sigma = kw["oscillator"]["omega"], kw["sigma"]
    law = kw.get("impact_law", "mean")
    cfg = load_config(None, outdir=folder, values=(omega,), sigmas=(sigma,),
                      orders=(kw["order"],), horizons=(float(kw["periods"]),),
                      per_period=kw["per_period"], seed=seed, frontier=False, plots=False,
                      solver=dict(rtol=1e-10, atol=1e-10))
    v = cfg.variants.index(f"{law}/galerkin")
    point = _Map(cfg, progress=False, log=lambda *a: None).evaluate(omega, sigma)
    return {key: int(point.verdict[v, -1, 0, c]) for c, key in enumerate(("mean", "var"))}, \
        point.samples


def judge(name: str, seeds: int, *, log2_truth: int = 20) -> dict:
    """Verdict counts, false agrees and false disagrees of case ``name`` per quantity."""
    run = run_case(name)
    mean, var, _, _ = truth(name, log2_truth)
    ratio = true_ratio(run, mean, var)
    counts = {key: {1: 0, 0: 0, -1: 0} for key in ratio}
    wrong = {key: 0 for key in ratio}
    samples = []
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        for seed in range(seeds):
            verdicts, m = _point(name, seed, folder)
            samples.append(m)
            for key, said in verdicts.items():
                counts[key][said] += 1
                truly = 1 if ratio[key] <= 1.0 else -1
                wrong[key] += said == -truly
    return {"name": name, "ratio": ratio, "counts": counts, "wrong": wrong,
            "seeds": seeds, "median_samples": float(np.median(samples)),
            "seconds": time.perf_counter() - start}


def table(rows: list[dict]) -> str:
    head = ("case", "true error / tolerance (mean, var)", "mean: agrees / undecided / "
            "disagrees", "variance: agrees / undecided / disagrees", "wrong (mean, var)",
            "median samples")
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        c = r["counts"]
        out.append("| " + " | ".join((
            r["name"], f"{r['ratio']['mean']:.3g}, {r['ratio']['var']:.3g}",
            " / ".join(str(c["mean"][k]) for k in (1, 0, -1)),
            " / ".join(str(c["var"][k]) for k in (1, 0, -1)),
            f"{r['wrong']['mean']}, {r['wrong']['var']} of {r['seeds']}",
            f"{r['median_samples']:g}")) + " |")
    return "\n".join(out)


def test_smoke_one_case_two_seeds():
    """The harness runs (2 seeds, a 2^14-sample truth); no rate is read off it."""
    row = judge("paper-0.023", 2, log2_truth=14)
    assert sum(row["counts"]["mean"].values()) == 2


@pytest.mark.slow
@pytest.mark.parametrize("name", MAP_CASES)
def test_false_verdicts_stay_within_the_stated_rate(name):
    """At most 1 wrong verdict in 40 seeds per quantity (alpha = 0.01: 0.4 expected)."""
    row = judge(name, 40)
    assert max(row["wrong"].values()) <= 1, row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=100)
    parser.add_argument("--cases", default=",".join(MAP_CASES))
    args = parser.parse_args(argv)
    rows = []
    for name in args.cases.split(","):
        rows.append(judge(name, args.seeds))
        print(f"{name}: {rows[-1]['seconds']:.0f} s", file=sys.stderr)
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
