"""The Sobol targets of several uncertain parameters on the section 3.2 case (omega 3.98,
10 periods x 8, (mu, c) at sigma (0.016, 0.005), N = 3, saltation law), for the single
element and the adaptive boxes: the share of outputs where the surrogate's indices lie in
plain pick-freeze's 95 % intervals at 2^14 base samples, and how often the certified
(controlled) standard error at 2^9 and 2^10 base samples is at most plain's at 2^14.

    python -m benchmarks.sobol_targets
"""

from __future__ import annotations

import os
import time
import warnings

import numpy as np

import compare
import opa


def main() -> None:
    warnings.simplefilter("ignore")
    print("load", os.getloadavg())
    osc = opa.preset("3.2", omega=3.98)
    s = opa.System(osc, uncertain="mu,c", sigma=(0.016, 0.005), order=3,
                   impact_law="saltation")
    runs = {"single N=3": opa.simulate_opa(s, periods=10, per_period=8),
            "adaptive boxes": opa.simulate_opa(s, periods=10, per_period=8,
                                               elements="adaptive")}
    for name, run in runs.items():
        t = time.time()
        plain = compare.certify_sobol(s, opa=run, samples=2**14, control=False)
        print(f"{name}: plain 2^14 ({plain.attrs['true_system_runs']} runs, "
              f"{time.time() - t:.0f} s): "
              f"surrogate inside the 95 % intervals at {plain.attrs['agreement']:.3f} of outputs "
              f"(x {plain.attrs['agreement_x']:.3f}, v {plain.attrs['agreement_v']:.3f})")
        for m in (2**9, 2**10):
            cv = compare.certify_sobol(s, opa=run, samples=m)
            for kind in ("first", "total"):
                big = plain[f"x_sobol_{kind}_se_plain"].values
                small = cv[f"x_sobol_{kind}_se"].values
                ok = np.isfinite(big) & np.isfinite(small) & (big > 0)
                share = float(np.mean(small[ok] <= big[ok]))
                print(f"  certified M={m} ({cv.attrs['true_system_runs']} runs = 1/"
                      f"{plain.attrs['true_system_runs'] / cv.attrs['true_system_runs']:.0f}): "
                      f"x {kind}: SE <= plain 2^14 SE at {share:.3f} of outputs; median ratio "
                      f"{np.median(small[ok] / big[ok]):.3g}")


if __name__ == "__main__":
    main()
