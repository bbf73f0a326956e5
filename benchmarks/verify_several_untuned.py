"""How often the certificate of several parameters is wrong, on a case it was not tuned
to: omega = 4.1, (a, c) uncertain with the laws beta:2,3 and uniform, relative sizes
(0.02, 0.1) at scales 0.5, 1, 2; the single element (mean and saltation laws) and the
adaptive boxes, each certified with four seeds; the truth is 2^15 scrambled Sobol samples
of the true systems, read with the certificate's own rule (running RMS error against 0.1
of the running RMS spread for the mean, 0.25 of the running RMS variance for the
variance). A verdict counts as wrong when it says agrees where the truth's ratio is above
1.1, or disagrees where it is below 0.9.

    python -m benchmarks.verify_several_untuned
"""

import os
import warnings

import numpy as np

import compare
import mc
import opa

def ratios(run, truth):
    """The truth's reading of the certificate's rule for the run: (mean, variance)."""
    T = np.arange(1, truth.sizes["time"] + 1)
    spread = np.sqrt(np.cumsum(truth.x_var.values) / T)
    scale = np.sqrt(np.cumsum(truth.x_var.values ** 2) / T)
    em = np.sqrt(np.cumsum((run.x_mean.values - truth.x_mean.values) ** 2) / T)
    ev = np.sqrt(np.cumsum((run.x_var.values - truth.x_var.values) ** 2) / T)
    return (float(np.max(em / (0.1 * spread + 2e-8))),
            float(np.max(ev / (0.25 * scale + 2e-8))))


def reading(verdict: str, ratio: float) -> str:
    if verdict == "agrees" and ratio > 1.1:
        return "agree_on_broken"
    if verdict == "disagrees" and ratio < 0.9:
        return "disagree_on_fine"
    if (verdict == "agrees" and ratio < 0.9) or (verdict == "disagrees" and ratio > 1.1):
        return "right"
    return "borderline/undecided"


def main() -> None:
    warnings.simplefilter("ignore")
    print("load", os.getloadavg())
    base = opa.System(opa.preset("3.2", omega=4.1), uncertain="a,c",
                      distribution="beta:2,3,uniform", order=3)
    tally = dict.fromkeys(("agree_on_broken", "disagree_on_fine", "right",
                           "borderline/undecided"), 0)
    for scale in (0.5, 1.0, 2.0):
        system = compare.trust_scaled(base, (0.02, 0.1), scale)
        truth = mc.simulate_mc(system, samples=2**15, periods=10, per_period=8, seed=11)
        for law, elements in (("mean", None), ("saltation", None), ("saltation", "adaptive")):
            run = opa.simulate_opa(system.replace(impact_law=law), periods=10, per_period=8,
                                   elements=elements)
            truth_ratios = ratios(run, truth)
            for seed in range(4):
                v = compare.verify(run, samples=256, max_samples=4096, seed=seed)
                for which, ratio in zip(("mean", "var"), truth_ratios):
                    verdict = v.attrs[f"verdict_{which}"]
                    kind = reading(verdict, ratio)
                    tally[kind] += 1
                    if seed == 0 or kind in ("agree_on_broken", "disagree_on_fine"):
                        print(f"s={scale} {law:9s} {str(elements):8s} {which}: truth ratio "
                              f"{ratio:.3g} verdict {verdict} ({kind})")
    print(tally)
    print("load", os.getloadavg())


if __name__ == "__main__":
    main()
