"""The trust map of several parameters on a case it was not tuned to: are the ends of its
bisected intervals of s* right?

Case: section 3.2 at omega = 4.09 and 4.145, (mu, c) uncertain (semicircle), relative
sizes (0.02, 0.1), scales 0.5, 1, 2, horizon 5 periods, N = 2, s* bisected to 0.2. At
each end of each bisected interval the variant's run is read against the truth, 2^14
scrambled Sobol samples of the true systems, with the certificate's own rule
(``benchmarks.verify_several_untuned.ratios``). The lower end says "certified to agree":
it is wrong if the truth's ratio there is above 1.1 (mean or variance). The upper end
says "not certified": it is wrong only if the certificate said disagrees where the
truth's ratios are both below 0.9.

    python -m benchmarks.trustmap_several_untuned
"""

import os
import warnings

import mc
import opa
from benchmarks.verify_several_untuned import ratios
from compare import trust_map_several, trust_scaled, verify
from compare._trustline import LINE_VARIANTS

if __name__ == "__main__":
    print(f"load average {os.getloadavg()[0]:.2f}")
    wrong = checked = 0
    for omega in (4.09, 4.145):
        system = opa.System(opa.preset("3.2", omega=omega), uncertain="mu,c", order=2,
                            sigma=(0.0, 0.0))
        ds = trust_map_several(system, (0.02, 0.1), (0.5, 1.0, 2.0), horizons=(5,),
                               resolution=0.2)
        for i, (name, law, elements) in enumerate(LINE_VARIANTS):
            lower = float(ds.scale_star_lower.values[0, i])
            upper = float(ds.scale_star_upper.values[0, i])
            for end, scale in (("lower", lower), ("upper", upper)):
                if not 0 < scale < float("inf"):
                    continue
                at = trust_scaled(system, (0.02, 0.1), scale).replace(impact_law=law)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    try:
                        run = opa.simulate_opa(at, periods=5, per_period=8,
                                               elements=elements)
                    except opa.SimulationError:
                        continue
                truth = mc.simulate_mc(at, samples=2**14, periods=5, per_period=8,
                                       progress=False)
                rm, rv = ratios(run, truth)
                verdict = verify(run, samples=256, max_samples=4096).attrs["verdict"]
                bad = (end == "lower" and max(rm, rv) > 1.1) or (
                    end == "upper" and verdict == "disagrees" and max(rm, rv) < 0.9)
                checked += 1
                wrong += bad
                print(f"omega {omega}: {name:15s} {end} end s = {scale:.4g}: truth ratios "
                      f"{rm:.3g} (mean), {rv:.3g} (var); certificate {verdict}"
                      f"{'  WRONG' if bad else ''}", flush=True)
    print(f"{checked} ends checked, {wrong} wrong")
