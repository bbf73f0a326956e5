"""How often the certificate is wrong on compiled force laws it was not tuned to.

Cases (docs/examples): a pendulum against a wall with its damping b uncertain, a quintic
spring with the restitution eta uncertain, the Hertzian contact with its gap g uncertain,
and the same contact as a Python function with its damping zeta uncertain; each uniform,
5 periods, N = 3. Each is run as one element with the mean impact law and as adaptive
elements with the saltation law, and certified with two seeds (256 to 4096 true systems).
The truth is 2^14 scrambled Sobol samples of the true systems, read with the
certificate's own rule (``benchmarks.verify_several_untuned.ratios``): a verdict is wrong
when it says agrees where the truth's ratio to the tolerance is above 1.1, or disagrees
where it is below 0.9.

    python -m benchmarks.verify_compiled_untuned
"""

import os
import warnings

import compare
import mc
import opa
from benchmarks.verify_several_untuned import ratios, reading
from opa._modelfile import read_model

CASES = [
    ("pendulum b", "docs/examples/pendulum-wall.toml", "b", 0.02),
    ("quintic eta", "docs/examples/quintic.toml", "eta", 0.05),
    ("hertz g", "docs/examples/hertz-contact.toml", "g", 0.03),
    ("hertz-function zeta", "docs/examples/hertz-function.toml", "zeta", 0.01),
]
if __name__ == "__main__":
    print(f"load average {os.getloadavg()[0]:.2f}")
    counts: dict = {}
    for label, path, name, sigma in CASES:
        osc = read_model(path).oscillator
        base = opa.System(osc, uncertain=name, sigma=sigma, distribution="uniform", order=3)
        grid = dict(periods=5, per_period=8)
        truth = mc.simulate_mc(base, samples=2**14, progress=False, **grid)
        for law, elements in (("mean", None), ("saltation", "adaptive")):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                run = opa.simulate_opa(base.replace(impact_law=law), elements=elements, **grid)
            rm, rv = ratios(run, truth)
            for seed in (1, 2):
                v = compare.verify(run, samples=256, max_samples=4096, seed=seed)
                got = (reading(v.attrs["verdict_mean"], rm), reading(v.attrs["verdict_var"], rv))
                for g in got:
                    counts[g] = counts.get(g, 0) + 1
                print(f"{label:20s} {law:9s} seed {seed}: mean {v.attrs['verdict_mean']} "
                      f"(truth ratio {rm:.3g}) -> {got[0]}; var {v.attrs['verdict_var']} "
                      f"({rv:.3g}) -> {got[1]}", flush=True)
    print(counts)
