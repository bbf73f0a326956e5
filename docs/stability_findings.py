"""Reproduce the measured findings of docs/stability.md.

    python docs/stability_findings.py cascade      # A: period doublings in c, F0 = 0 (DMR)
    python docs/stability_findings.py impulses     # B: the same with the default impulses
    python docs/stability_findings.py sigma        # C: shift of the doublings with sigma (OPA)
    python docs/stability_findings.py lyapunov     # D: section 3.2, diffusion vs exponent
    python docs/stability_findings.py all

Each section prints the numbers quoted in docs/stability.md (times on 1 core of a
shared 2-core machine).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from opa import SolverOptions, preset
from opa.dynamics._continuation import (
    BIFURCATION_KINDS,
    ContinuationOptions,
    continue_orbits,
    locate_period_doubling,
)
from opa.dynamics._orbits import (
    ImpactSystem,
    lyapunov_benettin,
    lyapunov_exponent,
    transverse_lyapunov_exponent,
)

OPTS = SolverOptions(rtol=1e-10, atol=1e-10)


def _bifurcations(ds, name="c"):
    rows = []
    for i in range(ds.sizes["bifurcation"]):
        b = int(ds.bifurcation_branch[i])
        rows.append((BIFURCATION_KINDS[int(ds.bifurcation_kind[i])],
                     float(ds[f"bifurcation_{name}"][i]), int(ds.branch_period[b]),
                     int(ds.bifurcation_located[i])))
    return rows


def _print(ds, name="c"):
    for kind, value, period, located in _bifurcations(ds, name):
        how = "located" if located else "interpolated"
        print(f"    {kind:16s} {name} = {value:.10f}  on a period-{period} branch ({how})")
    print(f"    branch ends: {ds.attrs['branch_end']}")


def _relocate(system, ds, kind="period-doubling"):
    """Locate each period doubling of ``ds`` again with ``system``'s tolerances."""
    out = []
    for i in range(ds.sizes["bifurcation"]):
        if BIFURCATION_KINDS[int(ds.bifurcation_kind[i])] != kind:
            continue
        b = int(ds.bifurcation_branch[i])
        sel = np.flatnonzero(ds.branch.values == b)
        c_pd = float(ds.bifurcation_c[i])
        mu = ds.multiplier_real.values[sel] + 1j * ds.multiplier_imag.values[sel]
        test = np.sign(np.prod(mu + 1.0, axis=1).real)
        pairs = [q for q in range(len(sel) - 1) if test[q] != test[q + 1]]
        q = min(pairs, key=lambda q: abs(ds.c.values[sel[q]] - c_pd))
        j = sel[[q, q + 1]]  # the two branch points around it, re-solved at the new tolerance
        from opa.dynamics._orbits import shoot

        k = int(ds.period.values[j[0]])
        pts = []
        for jj in j:
            c = float(ds.c.values[jj])
            pts.append((c, shoot(system.with_parameter("c", c), ds.state.values[jj], periods=k)))
        out.append(locate_period_doubling(system, "c", pts[0], pts[1]).system.oscillator.c)
    return out


def cascade():
    print("A. section 3.1, F0 = 0, DMR: periodic orbits from c = 0.1 down to 0.01")
    t = time.time()
    system = ImpactSystem(preset("3.1", F0=0.0), options=OPTS)
    ds = continue_orbits(system, "c", 0.1, 0.01, depth=3)
    print(f"  ({time.time() - t:.1f} s, {ds.sizes['point']} orbits, rtol = atol = 1e-10)")
    _print(ds)
    for tol in (1e-9, 1e-11):
        sys_t = ImpactSystem(preset("3.1", F0=0.0), options=SolverOptions(rtol=tol, atol=tol))
        values = _relocate(sys_t, ds)
        print(f"  relocated at rtol = atol = {tol:g}: " + ", ".join(f"{v:.11f}" for v in values))
    emr0 = ImpactSystem(preset("3.1", F0=0.0), model="opa", sigma=0.0, order=4, options=OPTS)
    ds0 = continue_orbits(emr0, "c", 0.1, 0.035, depth=1)
    print("  EMR_0 (OPA N = 4, sigma = 0):")
    _print(ds0)
    return ds


def impulses():
    print("B. section 3.1 with the default impulses (dirac, F0 = 0.1, omega1 = 1, n = 2, "
          "impulse at t = 0): maps over the common period 14 T")
    for tol in (1e-9, 1e-11):
        opts = SolverOptions(rtol=tol, atol=tol)
        system = ImpactSystem(preset("3.1"), options=opts)
        t = time.time()
        down = continue_orbits(system, "c", 0.1, 0.06, depth=0)
        up = continue_orbits(system, "c", 0.1, 0.02, seed=0.05, depth=2 if tol > 1e-10 else 1,
                             continuation=ContinuationOptions(max_multiplier=100))
        print(f"  rtol = atol = {tol:g} ({time.time() - t:.1f} s)")
        print("   from c = 0.1 downwards:")
        _print(down)
        print("   from the orbit at c = 0.05, both ways:")
        _print(up)
    print("  pulse impulses (width 0.1), rtol 1e-10:")
    system = ImpactSystem(preset("3.1"), impulse="pulse",
                          options=SolverOptions(rtol=1e-10, atol=1e-10))
    _print(continue_orbits(system, "c", 0.1, 0.02, seed=0.05, depth=1,
                           continuation=ContinuationOptions(max_multiplier=100)))


def sigma():
    print("C. section 3.1, F0 = 0, OPA (mean impact law, galerkin): period doublings vs sigma")
    base = {}
    for order, law, trunc in ((4, "mean", "galerkin"), (2, "mean", "galerkin"),
                              (6, "mean", "galerkin"), (4, "ensemble", "galerkin"),
                              (4, "mean", "paper")):
        for s in (0.0, 0.01, 0.02, 0.05):
            if order != 4 or law != "mean" or trunc != "galerkin":
                if s not in (0.0, 0.05):
                    continue
            t = time.time()
            system = ImpactSystem(preset("3.1", F0=0.0), model="opa", order=order, sigma=s,
                                  impact_law=law, truncation=trunc, options=OPTS)
            ds = continue_orbits(system, "c", 0.1, 0.035, depth=1)
            pds = [v for k, v, _, loc in _bifurcations(ds) if k == "period-doubling" and loc]
            key = (order, law, trunc)
            base.setdefault(key, pds)
            shift = ", ".join(f"{v:.9f} ({v - b:+.3e})" for v, b in zip(pds, base[key]))
            print(f"  N = {order}, {law}, {trunc}, sigma = {s:<5g}: {shift}   "
                  f"({time.time() - t:.1f} s)")
    print("  with the default impulses (P^14), N = 4: the 14T -> 28T doubling")
    for s in (0.0, 0.01, 0.02, 0.05):
        system = ImpactSystem(preset("3.1"), model="opa", order=4, sigma=s, options=OPTS)
        ds = continue_orbits(system, "c", 0.05, 0.03, depth=0)
        pds = [v for k, v, _, loc in _bifurcations(ds) if k == "period-doubling" and loc]
        print(f"    sigma = {s:<5g}: " + ", ".join(f"{v:.9f}" for v in pds))


def lyapunov(periods=10000):
    print(f"D. section 3.2: largest Lyapunov exponent (per unit time, {periods} forcing periods "
          "after 500, batch-means standard error)")
    for F0 in (0.1, 0.0):
        for omega in (3.98, 4.2):
            osc = preset("3.2", omega=omega, F0=F0)
            dmr = lyapunov_exponent(ImpactSystem(osc, options=OPTS), periods=periods)
            engine = "solver" if F0 == 0.0 else "plain"
            ben = lyapunov_benettin(ImpactSystem(osc, options=OPTS), periods=periods,
                                    engine=engine)
            print(f"  F0 = {F0}, omega = {omega}: DMR {dmr.exponent:+.4f} ± "
                  f"{dmr.standard_error:.4f} (Benettin, {engine}: {ben.exponent:+.4f}); "
                  f"impacts/period {dmr.impacts / dmr.periods:.3f}, slowest impact "
                  f"{dmr.min_impact_velocity:.3g}, closest free-flight approach "
                  f"{dmr.min_gap:.3g}")
            samples = []
            for mu in (0.77, 0.79, 0.81, 0.83):
                est = lyapunov_exponent(ImpactSystem(osc.replace(mu=mu), options=OPTS),
                                        periods=periods // 5)
                samples.append(f"{mu:g}: {est.exponent:+.4f}")
            print("    DMR samples mu = " + "; ".join(samples))
            for law in ("mean", "ensemble"):
                cells = []
                for s in (0.0, 0.01, 0.014, 0.02, 0.03):
                    system = ImpactSystem(osc, model="opa", order=4, sigma=s, impact_law=law,
                                          options=OPTS)
                    est = lyapunov_exponent(system, periods=periods)
                    cells.append(f"{s:g}: {est.exponent:+.4f} ± {est.standard_error:.4f}")
                print(f"    OPA N = 4 ({law} law), sigma " + "; ".join(cells))
            for law in ("mean", "ensemble"):
                system = ImpactSystem(osc, model="opa", sigma=0.0, order=1, impact_law=law,
                                      options=OPTS)
                tr = transverse_lyapunov_exponent(system, periods=periods)
                print(f"    transverse exponent of EMR_0 = DMR ({law} law): "
                      f"{tr.exponent:+.4f} ± {tr.standard_error:.4f}")


if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "all"
    jobs = {"cascade": cascade, "impulses": impulses, "sigma": sigma, "lyapunov": lyapunov}
    for name, job in jobs.items():
        if which in (name, "all"):
            job()
            print()
