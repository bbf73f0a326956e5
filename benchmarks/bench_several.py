"""Several uncertain parameters: OPA against a Monte Carlo reference and against chaospy's
non-intrusive polynomial chaos on the same oscillator, and the d = 1 kernel speed held.

    python -m benchmarks.bench_several [--smoke] [--base TREE [--head TREE]] [--out FILE]
    python -m benchmarks.bench_several --split      # where the first split is (seconds)

Problem: section 3.2 set at omega = 3.98 (``opa.preset("3.2", omega=3.98)``), 10 forcing
periods, 8 outputs per period, rtol = atol = 1e-10 (``SolverOptions()``), semicircle laws.
Cases: d = 2 is (mu, c), d = 3 is (mu, c, a), with scales ``sigma_j = s r_j p_bar_j``, the
relative sizes r = 0.02 (mu), 0.1 (c), 0.02 (a) and a scale factor s.

Where the first split is (:func:`split_scale`): the true systems on a grid over the whole
support [-1, 1]^d of xi (41^2 points for d = 2, 17^3 for d = 3, corners included), the
number of impacts of each over the 10 periods; s* is the smallest s at which they differ
between points, by bisection. Measured: s* = 1.368 (d = 2) and 0.817 (d = 3), both at the
corner xi = (-1, -1, ...) (low mu and c, and for d = 3 high a), where the semicircle's
density vanishes: a 2^10-point Sobol MC sees no split until s = 1.5 in either case. So
``S_BELOW = 0.5`` (below both) and ``S_ABOVE = 2`` (above both; there 1 % (d = 2) and
4 % (d = 3) of a 2^10-point MC have another impact count than the rest).

1. Moments. Reference: ``mc.simulate_mc`` with 2^16 scrambled Sobol points (16
   replicates), whose own RMS standard errors of E[x] and Var[x] are printed as the floor.
   OPA: single element, total-degree basis N = 2..6, with the paper's impact law
   (``mean``) and with ``saltation``; multi-element (``elements=K``) when ``simulate_opa``
   takes it with several parameters (else the refusal is printed). Errors are RMS over
   the 81 outputs.
2. Peers: chaospy (a) pseudo-spectral projection on a Smolyak sparse grid
   (``generate_quadrature(order, joint, sparse=True, rule="gaussian")`` +
   ``fit_quadrature``) and (b) point collocation (``fit_regression`` on 2 x the basis size
   of chaospy's Sobol points), orders 1..6, ``normed`` total-degree expansions of the
   joint ``J(Beta(1.5, 1.5, lower=-1, upper=1), ...)``, which is the semicircle law on
   [-1, 1] (:func:`test_chaospy_beta_is_the_semicircle`); E[x] and Var[x] by
   ``chaospy.E`` / ``chaospy.Var``. The true systems at the nodes run in opa-mc's batch
   runner (``opa.engine.true_runs``: ``run_batch`` on ``System.sampled_inputs``). Each
   peer is checked against the reference below the split (its highest order within
   1e-5 in RMS of E[x]) before it is timed; one that does not agree is not timed.
3. Speed held (with ``--base TREE``): the d = 1 cases of ``bench_peers.py`` run by our
   solver alone (DMR 1000 periods at rtol 1e-10; MC 512 samples x 100 periods [full
   case: 4000 x 200] at rtol 1e-8 on 2 threads; OPA N = 8, 200 periods at rtol 1e-8), in
   a fresh process per tree (``PYTHONPATH=TREE``, numba cache warmed by one run of each
   tree first), trees alternated A/B/A/B for 7 pairs, each case's best of 5 calls per
   process in wall and in process CPU seconds; medians (and minima) over the pairs and
   the ratios HEAD / base. Under load the MC case's wall time is bimodal (its 2 threads
   find 1 or 2 free cores): its CPU seconds are the figure to read.

Costs. *True-system-equivalent RHS evaluations* count right-hand sides of the 2-state true
system: a sampled run or a peer's node contributes its own ``rhs_evaluations``; an OPA
right-hand side evaluates the force at each of its Q quadrature nodes, so an OPA run
counts ``rhs_evaluations * nodes`` (:func:`true_equivalent`; per element, summed, when
there are several). ``cost at 1e-4``: the cost at which a method's RMS error of E[x]
reaches ``TARGET`` = 1e-4, interpolated linearly in log(cost) against log(error) between
the two runs around it (:func:`cost_at`); "not reached" when no run of it gets there.
Wall seconds are printed beside the load average; prefer the RHS counts and ratios.

Results: printed, and appended as one record to ``benchmarks/results/bench_several.json``
(``--out``). ``--smoke`` (d = 2, 2^8 reference, N <= 2, chaospy order <= 2, no speed
part) is what ``pytest benchmarks -m "not slow"`` (CI) runs, writing to a temporary file.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import mc
import opa
from opa.engine import SimulationError, SolverOptions, run_batch, time_grid, true_runs

OMEGA = 3.98
PERIODS, PER_PERIOD = 10, 8
#: d -> (uncertain parameters, relative sizes sigma_j / p_bar_j at s = 1)
CASES = {2: ("mu,c", (0.02, 0.1)), 3: ("mu,c,a", (0.02, 0.1, 0.02))}
#: measured first split s* (see the module docstring; ``split_scale``)
SPLIT_SCALE = {2: 1.368, 3: 0.817}
S_BELOW, S_ABOVE = 0.5, 2.0
TARGET = 1e-4
#: a peer agrees when its highest order's RMS error of E[x] below the split is within
#: ``agree`` (full: 1e-5, ten times the target's tenth; smoke: order 2 reaches only ~1e-4)
SEED = 2026
FULL = dict(dims=(2, 3), log2_reference=16, orders=(2, 3, 4, 5, 6), elements=(2, 4, 8),
            peer_orders=(1, 2, 3, 4, 5, 6), agree=1e-5)
SMOKE = dict(dims=(2,), log2_reference=8, orders=(1, 2), elements=(2,), peer_orders=(1, 2),
             agree=1e-3)
RESULTS_FILE = Path(__file__).resolve().parent / "results" / "bench_several.json"
ROOT = Path(__file__).resolve().parent.parent


# --------------------------------------------------------------------------- bookkeeping


def true_equivalent(attrs) -> int:
    """True-system-equivalent RHS evaluations of a run from its attributes: an OPA run
    (``nodes`` in its attributes) counts ``rhs_evaluations * nodes``, each OPA right-hand
    side evaluating the force at its Q nodes; a run of true systems its own count."""
    rhs = int(np.sum(attrs["rhs_evaluations"]))
    return rhs * int(attrs["nodes"]) if "nodes" in attrs else rhs


def cost_at(errors, costs, target: float = TARGET) -> tuple[float | None, str]:
    """The cost at which the error first reaches ``target``, runs taken in increasing
    cost: log(cost) interpolated linearly in log(error) between the last run above the
    target and the first at or below it.

    Returns
    -------
    (cost, note): ``note`` is ``""`` when interpolated, ``"<="`` when the cheapest run is
    already at or below the target (its cost, an upper bound), ``"not reached"`` (cost
    None) when no run gets there; ``"!"`` is appended when a costlier run is above the
    target again (the error does not fall steadily).
    """
    pairs = sorted((float(c), float(e)) for c, e in zip(costs, errors)
                   if np.isfinite(e) and c > 0)
    for i, (c1, e1) in enumerate(pairs):
        if e1 > target:
            continue
        unsteady = "!" if any(e > target for _, e in pairs[i + 1:]) else ""
        if i == 0:
            return c1, "<=" + unsteady
        c0, e0 = pairs[i - 1]
        slope = (math.log(c1) - math.log(c0)) / (math.log(e1) - math.log(e0))
        return (math.exp(math.log(c0) + slope * (math.log(target) - math.log(e0))),
                unsteady)
    return None, "not reached"


def rms(a, b) -> float:
    """Root mean square of a - b over the outputs."""
    return float(np.sqrt(np.mean((np.asarray(a, float) - np.asarray(b, float)) ** 2)))


def system(d: int, scale: float, order: int = 1, **fields) -> opa.System:
    """The case's :class:`opa.System`: d uncertain parameters at ``sigma = s r p_bar``."""
    osc = opa.preset("3.2", omega=OMEGA)
    names, rel = CASES[d]
    sigma = tuple(scale * r * float(getattr(osc, n)) for n, r in zip(names.split(","), rel))
    return opa.System(osc, uncertain=names, sigma=sigma, distribution="semicircle",
                      order=order, **fields)


def times() -> np.ndarray:
    return time_grid(OMEGA, PERIODS, PER_PERIOD)


def split_scale(d: int, points: int | None = None, lo: float = 0.25, hi: float = 2.0,
                steps: int = 8) -> float:
    """The first split's scale s*: the smallest s at which the true systems on a grid of
    ``points`` per axis over [-1, 1]^d (corners included) differ in their number of
    impacts, by bisection between ``lo`` (no split) and ``hi`` (split)."""
    points = points or {2: 41, 3: 17}.get(d, 9)
    axis = np.linspace(-1.0, 1.0, points)
    xi = np.array(list(itertools.product(*[axis] * d)))

    def splits(s):
        _, _, impacts = true_runs(system(d, s), SolverOptions(), xi, times(), what="scan",
                                  impacts=True)
        return len(np.unique(impacts)) > 1

    if splits(lo) or not splits(hi):
        raise ValueError(f"no first split between s = {lo} and {hi} for d = {d}")
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if splits(mid) else (mid, hi)
    return hi


def kinked_outputs(d: int, scale: float, points: int = 9) -> np.ndarray:
    """Indices of the outputs that fall inside the band of an impact's times over the
    support (the true systems on a grid of ``points`` per axis, corners included): there
    x(t, xi) has a kink in xi (x continuous, its velocity reversed at the impact), so no
    global polynomial converges spectrally there even below the split. Without a split
    the j-th impact of every point is the same impact."""
    axis = np.linspace(-1.0, 1.0, points)
    xi = np.array(list(itertools.product(*[axis] * d)))
    sys_, t = system(d, scale), times()
    batch = run_batch(sys_.sampled_inputs(SolverOptions(), xi=xi),
                      sys_.deterministic().initial_state(), t, rtol=SolverOptions().rtol,
                      atol=SolverOptions().atol, capacity=64)
    events = [batch.events(b) for b in range(len(xi))]
    impacts = [e.time[e.kind == e.IMPACT] for e in events]
    count = min(len(i) for i in impacts)
    bands = np.array([i[:count] for i in impacts])
    lo, hi = bands.min(axis=0), bands.max(axis=0)
    return np.flatnonzero(((t[:, None] >= lo) & (t[:, None] <= hi)).any(axis=1))


# --------------------------------------------------------------------------- 1. moments


def reference(d: int, scale: float, log2_samples: int) -> dict:
    """The scrambled-Sobol MC reference: E[x], Var[x], their RMS standard errors, the
    share of samples whose impact count is not the most common one."""
    start = time.perf_counter()
    ds = mc.simulate_mc(system(d, scale), samples=2 ** log2_samples, sampler="sobol",
                        seed=SEED, periods=PERIODS, per_period=PER_PERIOD, progress=False)
    seconds = time.perf_counter() - start
    counts = np.bincount(ds.n_impacts.values)
    kinked = kinked_outputs(d, scale).tolist() if scale < SPLIT_SCALE[d] else None
    return dict(kinked=kinked, x_mean=ds.x_mean.values, x_var=ds.x_var.values,
                se_mean=float(np.sqrt(np.mean(ds.x_sem.values ** 2))),
                se_var=float(np.sqrt(np.mean(ds.x_var_sem.values ** 2))),
                split_share=1.0 - counts.max() / counts.sum(), samples=2 ** log2_samples,
                rhs=true_equivalent(ds.attrs), seconds=seconds)


def _row(d, scale, method, setting, ref, x_mean, x_var, rhs, seconds, **extra) -> dict:
    return dict(d=d, scale=scale, method=method, setting=str(setting),
                err_mean=rms(x_mean, ref["x_mean"]), err_var=rms(x_var, ref["x_var"]),
                rhs=int(rhs), seconds=seconds, load=os.getloadavg()[0], **extra)


def opa_rows(d: int, scale: float, ref: dict, orders, elements) -> list[dict]:
    """Single-element OPA at each order with the ``mean`` and ``saltation`` impact laws,
    and multi-element OPA (saltation, order 2) at each K where simulate_opa takes it."""
    rows = []
    for law, order in itertools.product(("mean", "saltation"), orders):
        sys_ = system(d, scale, order, impact_law=law)
        opa.simulate_opa(sys_, periods=0.5, per_period=PER_PERIOD)  # compile, warm caches
        start = time.perf_counter()
        ds = opa.simulate_opa(sys_, periods=PERIODS, per_period=PER_PERIOD)
        seconds = time.perf_counter() - start
        rows.append(_row(d, scale, f"opa {law}", f"N={order}", ref, ds.x_mean, ds.x_var,
                         true_equivalent(ds.attrs), seconds, nodes=int(ds.attrs["nodes"])))
    for k in elements:
        sys_ = system(d, scale, 2, impact_law="saltation")
        start = time.perf_counter()
        try:
            ds = opa.simulate_opa(sys_, periods=PERIODS, per_period=PER_PERIOD, elements=k)
        except (ValueError, NotImplementedError, TypeError, SimulationError) as err:
            # refused (not taken with several parameters) or failed (a box's system)
            rows.append(dict(d=d, scale=scale, method="opa elements", setting=f"K={k}/axis",
                             refused=f"{type(err).__name__}: {str(err).splitlines()[0]}"))
            if not isinstance(err, SimulationError):
                break
            continue
        seconds = time.perf_counter() - start
        rhs = sum(int(r) for r in np.atleast_1d(ds.attrs["rhs_evaluations"]))
        nodes = int(ds.attrs.get("nodes", 1))
        rows.append(_row(d, scale, "opa elements", f"K={ds.attrs['elements']},N=2", ref,
                         ds.x_mean, ds.x_var, rhs * nodes, seconds, nodes=nodes))
    return rows


# --------------------------------------------------------------------------- 2. peers


def semicircle_joint(d: int):
    """chaospy's joint law of xi: independent semicircles on [-1, 1] as Beta(1.5, 1.5)."""
    import chaospy

    return chaospy.J(*[chaospy.Beta(1.5, 1.5, lower=-1.0, upper=1.0) for _ in range(d)])


def chaospy_fit(d: int, scale: float, order: int, kind: str) -> dict:
    """One chaospy PCE of x(t, xi): nodes, true runs at them, fit, E[x] and Var[x].
    ``kind``: ``spectral`` (Smolyak sparse Gauss grid + fit_quadrature) or
    ``regression`` (fit_regression on 2 x the basis size of chaospy's Sobol points)."""
    import chaospy

    start = time.perf_counter()
    joint = semicircle_joint(d)
    expansion = chaospy.generate_expansion(order, joint, normed=True)
    if kind == "spectral":
        nodes, weights = chaospy.generate_quadrature(order, joint, sparse=True,
                                                     rule="gaussian")
    else:
        nodes = joint.sample(2 * len(expansion), rule="sobol")
    nodes = np.atleast_2d(nodes)
    paths, rhs = true_runs(system(d, scale), SolverOptions(), nodes.T, times(),
                           what=f"chaospy {kind} node")
    x = paths[:, :, 0]
    if kind == "spectral":
        fit = chaospy.fit_quadrature(expansion, nodes, weights, x)
    else:
        fit = chaospy.fit_regression(expansion, nodes, x)
    x_mean, x_var = chaospy.E(fit, joint), chaospy.Var(fit, joint)
    return dict(x_mean=x_mean, x_var=x_var, rhs=rhs, points=nodes.shape[1],
                seconds=time.perf_counter() - start)


def peer_rows(d: int, scale: float, ref: dict, sizes: dict, agreed: dict) -> list[dict]:
    """chaospy's two PCEs at each order. Below the split (``scale`` < s*) each peer is
    first checked at its highest order against the reference on the outputs where x is
    smooth in xi (:func:`kinked_outputs` left out; ``agreed[kind]`` records the RMS
    error); a peer that has not agreed within ``sizes["agree"]`` at this d is
    not timed."""
    rows, orders = [], sizes["peer_orders"]
    for kind in ("spectral", "regression"):
        method = f"chaospy {kind}"
        if scale < SPLIT_SCALE[d]:
            check = chaospy_fit(d, scale, max(orders), kind)
            smooth = np.setdiff1d(np.arange(len(ref["x_mean"])), kinked_outputs(d, scale))
            agreed[d, kind] = rms(check["x_mean"][smooth], ref["x_mean"][smooth])
        if not agreed.get((d, kind), np.inf) <= sizes["agree"]:
            rows.append(dict(d=d, scale=scale, method=method, setting="-",
                             refused=f"not timed: did not agree below the split "
                                     f"(RMS err E[x] {agreed.get((d, kind), np.nan):.2g})"))
            continue
        for order in orders:
            fit = chaospy_fit(d, scale, order, kind)
            rows.append(_row(d, scale, method, f"order={order}", ref, fit["x_mean"],
                             fit["x_var"], fit["rhs"], fit["seconds"], nodes=fit["points"]))
    return rows


def equal_error_lines(rows) -> tuple[list[str], list[dict]]:
    """Each method's cost at RMS error of E[x] = TARGET, and the ratios OPA / chaospy."""
    lines, out = [], []
    groups = {}
    for r in rows:
        if "err_mean" in r:
            groups.setdefault((r["d"], r["scale"], r["method"]), []).append(r)
    for (d, scale, method), rs in groups.items():
        rhs, rhs_note = cost_at([r["err_mean"] for r in rs], [r["rhs"] for r in rs])
        sec, _ = cost_at([r["err_mean"] for r in rs], [r["seconds"] for r in rs])
        out.append(dict(d=d, scale=scale, method=method, rhs=rhs, seconds=sec, note=rhs_note))
    lines.append(f"{'d':>2} {'scale':>5} {'method':<18} {'RHS at 1e-4':>14} {'s at 1e-4':>10}"
                 f"   ratio opa/chaospy (RHS; s)")
    for c in out:
        cost = (f"{c['note']:>3}{c['rhs']:11.3g}" if c["rhs"] is not None
                else f"{'not reached':>14}")
        secs = f"{c['seconds']:10.3g}" if c["seconds"] is not None else f"{'-':>10}"
        ratios = []
        if c["method"].startswith("opa"):
            for p in out:
                if (p["d"], p["scale"]) == (c["d"], c["scale"]) and \
                        p["method"].startswith("chaospy"):
                    ratios.append(f"/{p['method'][8:]}: " + _ratio(c, p))
        lines.append(f"{c['d']:>2} {c['scale']:>5} {c['method']:<18} {cost} {secs}   "
                     + "; ".join(ratios))
    return lines, out


def _ratio(a: dict, b: dict) -> str:
    if a["rhs"] is None or b["rhs"] is None:
        return "not reached by " + ("both" if a["rhs"] is None and b["rhs"] is None
                                    else "opa" if a["rhs"] is None else "chaospy")
    return f"{a['rhs'] / b['rhs']:.3g}; {a['seconds'] / b['seconds']:.3g}"


# --------------------------------------------------------------------------- 3. speed held

#: one process of the speed check: ours alone on the bench_peers d = 1 cases, each case's
#: best of 5 calls after a warm-up call, wall and process CPU seconds (all threads), printed
#: as JSON (argv: MC samples, MC periods)
SPEED_SCRIPT = r"""
import json, sys, time
import numba
import mc, opa
osc = opa.preset("3.2", omega=3.98)
tight, loose = opa.SolverOptions(rtol=1e-10, atol=1e-10), opa.SolverOptions(rtol=1e-8,
                                                                             atol=1e-8)
M, P = int(sys.argv[1]), int(sys.argv[2])
numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
cases = {
    "dmr": (1000, lambda p: opa.simulate_dmr(osc, periods=p, options=tight)),
    "mc": (P, lambda p: mc.simulate_mc(osc, sigma=0.01, samples=M, sampler="random", seed=0,
                                       periods=p, per_period=1, options=loose,
                                       progress=False)),
    "opa": (200, lambda p: opa.simulate_opa(osc, sigma=0.01, order=8, periods=p,
                                            options=loose)),
}
out = {"module": opa.__file__}
for name, (periods, fn) in cases.items():
    fn(2)
    wall = cpu = float("inf")
    for _ in range(5):
        start, start_cpu = time.perf_counter(), time.process_time()
        fn(periods)
        wall = min(wall, time.perf_counter() - start)
        cpu = min(cpu, time.process_time() - start_cpu)
    out[name], out[name + " cpu"] = wall, cpu
print(json.dumps(out))
"""


def _speed_once(tree: Path, samples: int, periods: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree), MPLBACKEND="Agg")
    done = subprocess.run([sys.executable, "-c", SPEED_SCRIPT, str(samples), str(periods)],
                          cwd=tree, env=env, capture_output=True, text=True, check=True)
    out = json.loads(done.stdout.strip().splitlines()[-1])
    if not Path(out.pop("module")).resolve().is_relative_to(tree.resolve()):
        raise RuntimeError(f"the speed check of {tree} imported opa from elsewhere")
    return out


def speed_held(base: Path, head: Path = ROOT, pairs: int = 7, samples: int = 512,
               periods: int = 100) -> dict:
    """Median best-of-5 seconds (wall and process CPU) of the bench_peers d = 1 cases in
    ``head`` and in ``base``, alternated base/head for ``pairs`` pairs after one run of
    each (numba's cache), with the load average before each run; ratio head / base per
    case. Under load the CPU seconds of the single-threaded cases (dmr, opa) wait for no
    one and are the steadier figure."""
    trees = {"base": Path(base), "head": Path(head)}
    for tree in trees.values():
        _speed_once(tree, 64, 2)  # each tree's numba cache
    runs = {name: [] for name in trees}
    for _ in range(pairs):
        for name, tree in trees.items():
            load = os.getloadavg()[0]
            runs[name].append(dict(_speed_once(tree, samples, periods), load=load))
    keys = [f"{case}{kind}" for case in ("dmr", "mc", "opa") for kind in ("", " cpu")]
    medians = {name: {key: float(np.median([r[key] for r in rs])) for key in keys}
               for name, rs in runs.items()}
    minima = {name: {key: min(r[key] for r in rs) for key in keys} for name, rs in runs.items()}
    return dict(runs=runs, medians=medians, minima=minima,
                ratio_of_minima={key: minima["head"][key] / minima["base"][key]
                                 for key in keys},
                trees={k: str(v) for k, v in trees.items()},
                sizes=dict(mc_samples=samples, mc_periods=periods),
                ratio={key: medians["head"][key] / medians["base"][key] for key in keys})


# --------------------------------------------------------------------------- report


def row_lines(rows) -> list[str]:
    lines = [f"{'d':>2} {'scale':>5} {'method':<18} {'setting':<10} {'err E[x]':>9} "
             f"{'err Var':>9} {'true RHS':>11} {'pts':>5} {'wall s':>8} {'load':>5}"]
    for r in rows:
        if "refused" in r:
            lines.append(f"{r['d']:>2} {r['scale']:>5} {r['method']:<18} {r['setting']:<10} "
                         f"{r['refused'][:140]}")
            continue
        lines.append(f"{r['d']:>2} {r['scale']:>5} {r['method']:<18} {r['setting']:<10} "
                     f"{r['err_mean']:9.2e} {r['err_var']:9.2e} {r['rhs']:11d} "
                     f"{r.get('nodes', 0):5d} {r['seconds']:8.3f} {r['load']:5.2f}")
    return lines


def reference_lines(refs) -> list[str]:
    lines = [f"{'d':>2} {'scale':>5} {'s*':>6} {'samples':>8} {'SE E[x]':>9} {'SE Var':>9} "
             f"{'split share':>11} {'true RHS':>11} {'wall s':>7}  outputs in an impact band"]
    for (d, scale), r in refs.items():
        lines.append(f"{d:>2} {scale:>5} {SPLIT_SCALE[d]:6.3f} {r['samples']:8d} "
                     f"{r['se_mean']:9.2e} {r['se_var']:9.2e} {r['split_share']:11.4f} "
                     f"{r['rhs']:11d} {r['seconds']:7.2f}  "
                     + (str(r["kinked"]) if r["kinked"] is not None else "(split)"))
    return lines


def speed_lines(speed) -> list[str]:
    lines = [f"{'case':<8} {'base s':>9} {'HEAD s':>9} {'HEAD/base':>9} {'of minima':>9}   "
             f"(medians over {len(speed['runs']['head'])} alternated pairs of each "
             f"process's best of 5; wall and CPU seconds; MC {speed['sizes']}; the MC's "
             f"wall time is bimodal under load, 1 or 2 cores free: read its CPU line)"]
    for key, ratio in speed["ratio"].items():
        lines.append(f"{key:<8} {speed['medians']['base'][key]:9.4f} "
                     f"{speed['medians']['head'][key]:9.4f} {ratio:9.3f} "
                     f"{speed['ratio_of_minima'][key]:9.3f}")
    loads = [r["load"] for rs in speed["runs"].values() for r in rs]
    lines.append(f"load average before the runs: {min(loads):.2f} to {max(loads):.2f}")
    return lines


def run(sizes: dict, base: Path | None = None, head: Path = ROOT) -> dict:
    """Every part of the benchmark at ``sizes`` (``FULL`` or ``SMOKE``): the rows, the
    references, the costs at equal error and (with ``base``) the speed check."""
    refs, rows, agreed = {}, [], {}
    for d in sizes["dims"]:
        for scale in (S_BELOW, S_ABOVE):
            ref = refs[d, scale] = reference(d, scale, sizes["log2_reference"])
            rows += opa_rows(d, scale, ref, sizes["orders"], sizes["elements"])
            rows += peer_rows(d, scale, ref, sizes, agreed)
    lines, costs = equal_error_lines(rows)
    speed = speed_held(base, head) if base is not None else None
    return dict(refs=refs, rows=rows, costs=costs, cost_lines=lines, speed=speed,
                agree=sizes["agree"], agreed={f"d={d} {k}": v for (d, k), v in agreed.items()})


def record(result: dict, smoke: bool, load_before) -> dict:
    """The JSON record of one run."""
    import chaospy

    refs = [dict(d=d, scale=s, split_scale=SPLIT_SCALE[d],
                 **{k: v for k, v in r.items() if k not in ("x_mean", "x_var")})
            for (d, s), r in result["refs"].items()]
    return dict(date=datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
                mode="smoke" if smoke else "full", loadavg_before=list(load_before),
                loadavg_after=list(os.getloadavg()), cpu_count=os.cpu_count(),
                commit=_commit(), versions=dict(chaospy=chaospy.__version__),
                scales=dict(below=S_BELOW, above=S_ABOVE), target=TARGET,
                references=refs, rows=result["rows"], costs_at_target=result["costs"],
                peer_agreement=result["agreed"], speed_held=result["speed"])


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True,
                              capture_output=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="tiny sizes (CI)")
    parser.add_argument("--base", type=Path, default=None,
                        help="a worktree of the commit to hold the d = 1 speed against")
    parser.add_argument("--head", type=Path, default=ROOT,
                        help="the tree held against --base (default: this one; a clean "
                             "worktree of HEAD leaves uncommitted edits out)")
    parser.add_argument("--out", type=Path, default=RESULTS_FILE)
    parser.add_argument("--split", action="store_true",
                        help="only locate the first split's scale s* of each d, and print it")
    args = parser.parse_args(argv)
    if args.split:
        for d in CASES:
            s_star = split_scale(d)  # bisection of [0.25, 2] in 8 steps
            print(f"d = {d}: first split at s* in ({s_star - 1.75 / 2 ** 8:.4f}, "
                  f"{s_star:.4f}]; SPLIT_SCALE says {SPLIT_SCALE[d]}", flush=True)
        return 0
    load = os.getloadavg()
    print(f"bench_several: {'smoke' if args.smoke else 'full'} mode; load average "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores; "
          f"commit {_commit()}; s_below {S_BELOW}, s_above {S_ABOVE}", flush=True)
    result = run(SMOKE if args.smoke else FULL, args.base, args.head)
    print("\n-- reference (scrambled Sobol MC)\n" + "\n".join(reference_lines(result["refs"])))
    print("\n-- moments: RMS errors against the reference\n"
          + "\n".join(row_lines(result["rows"])))
    print("\n-- cost at RMS error of E[x] = 1e-4 (true-system-equivalent RHS evaluations; "
          "<=: the cheapest run is already below, its cost; !: a costlier run is above "
          "1e-4 again)\n" + "\n".join(result["cost_lines"]))
    print(f"\npeer agreement below the split (RMS err E[x], needs <= {result['agree']:g}): "
          + ", ".join(f"{k} {v:.2g}" for k, v in result["agreed"].items()))
    if result["speed"]:
        print("\n-- speed held (d = 1, bench_peers cases, ours)\n"
              + "\n".join(speed_lines(result["speed"])))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    history = json.loads(args.out.read_text()) if args.out.exists() else []
    history.append(record(result, args.smoke, load))
    args.out.write_text(json.dumps(history, indent=1, default=float) + "\n")
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}; appended to {args.out}")
    return 0


# --------------------------------------------------------------------------- tests


def test_cost_at_interpolates_on_log_log():
    """Between two runs log(cost) is linear in log(error); at or below the target first:
    that run's cost as a bound; never below it: not reached."""
    cost, note = cost_at([1e-2, 1e-3, 1e-5], [10.0, 100.0, 1e4])
    assert note == "" and math.isclose(cost, 1e3, rel_tol=1e-12)
    assert cost_at([1e-5, 1e-6], [7.0, 70.0]) == (7.0, "<=")
    assert cost_at([1e-2, 2e-3], [1.0, 2.0]) == (None, "not reached")
    cost, note = cost_at([1e-3, 1e-5, 2e-4], [1.0, 100.0, 1e3])
    assert note == "!" and math.isclose(cost, 10.0, rel_tol=1e-12)
    # runs given out of order are taken by cost; NaN errors are left out
    cost, _ = cost_at([1e-5, float("nan"), 1e-3], [1e4, 50.0, 100.0])
    assert math.isclose(cost, 1e3, rel_tol=1e-12)


def test_true_equivalent_counts_nodes_of_an_opa_run():
    """An OPA run's right-hand side is Q true ones; a true run counts its own."""
    assert true_equivalent({"rhs_evaluations": 3134, "nodes": 49}) == 3134 * 49
    assert true_equivalent({"rhs_evaluations": np.array([10, 20])}) == 30
    ds = opa.simulate_opa(system(2, S_BELOW, 1), periods=1, per_period=2)
    assert true_equivalent(ds.attrs) == ds.attrs["rhs_evaluations"] * ds.attrs["nodes"]


def test_chaospy_beta_is_the_semicircle():
    """chaospy's Beta(1.5, 1.5) on [-1, 1] is the semicircle law 2/pi sqrt(1 - x^2): its
    density, and its moments up to 12 (Catalan numbers / 4^k)."""
    import chaospy

    law = semicircle_joint(1)
    x = np.linspace(-0.99, 0.99, 11)
    assert np.allclose(law.pdf(x), 2.0 / np.pi * np.sqrt(1.0 - x ** 2), rtol=1e-10)
    for k in range(1, 7):
        catalan = math.comb(2 * k, k) / (k + 1)
        moment = float(chaospy.E(chaospy.variable(1) ** (2 * k), law))
        assert math.isclose(moment, catalan / 4 ** k, rel_tol=1e-8), k
    assert abs(float(chaospy.E(chaospy.variable(1) ** 3, law))) < 1e-12


def test_smoke(tmp_path, capsys):
    """The smoke run: every part but the speed check, at tiny sizes, on a temporary file."""
    out = tmp_path / "several.json"
    assert main(["--smoke", "--out", str(out)]) == 0
    rec = json.loads(out.read_text())[-1]
    assert rec["mode"] == "smoke" and rec["rows"]
    assert all(r["err_mean"] < 0.1 for r in rec["rows"] if "err_mean" in r)


if __name__ == "__main__":
    raise SystemExit(main())
