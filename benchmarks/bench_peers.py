"""Our solver against the peers a user would pick, in one pytest-benchmark session.

Problem: section 3.2 parameters at omega = 3.98 (``opa.preset("3.2", omega=3.98)``),
Dirac impulses, impact wall at x = delta, stroboscopic output. The peers are in
``benchmarks/peers.py`` (its docstring says how each event loop works).

Cases (full size; ``--benchmark-disable`` or CI=true is the smoke mode, sizes in brackets):

1. ``dmr``: one trajectory, 1000 forcing periods [50], rtol = atol = 1e-10:
   ``opa.simulate_dmr`` against numbalsoda ``dop853`` in a numba event loop (sub-windows
   of 1/4 forcing period, Hermite grazing check, Newton-located impacts), numbalsoda
   ``solve_ivp`` (DOP853 + its Brent events, polished), JAX + diffrax ``Dopri5`` and
   ``Dopri8`` (``Event`` with a root finder, restart in a jitted ``lax.while_loop``) and
   scipy ``solve_ivp`` DOP853 (``bench_dmr.scipy_dmr``). Reported: time per forcing period.
2. ``mc``: 4000 samples x 200 periods [64 x 10], rtol = atol = 1e-8, sigma = 0.01,
   uncertain mu (xi from ``mc.sample_xi("random", M, seed=0)``, the same points as ours),
   2 threads: ``mc.simulate_mc`` (2 numba threads) against both numbalsoda loops under
   ``numba.prange`` (2 threads) and diffrax Dopri5 ``vmap`` (chunks of 500 samples on 2
   host devices). Every peer's time includes forming the mean and variance of x and v
   from its paths (ours streams them). Reported: trajectory-periods per second.
3. ``opa``: the OPA system of order N = 8 (18 states), sigma = 0.01, 200 periods [10],
   rtol = atol = 1e-8: ``opa.simulate_opa`` (galerkin truncation, ``mean`` impact law, its
   defaults) against scipy ``solve_ivp`` DOP853 on the same system written independently
   in numpy (``peers.scipy_opa``: Gauss rule of the semicircle law with Q = 2N + 2 nodes,
   exact for the Galerkin projection of the cubic terms).

Agreement comes before timing: ``test_*_agrees`` runs 20 forcing periods (the ensemble:
32 samples) and requires |x|, |v| differences at the stroboscopic times and impact-time
differences within 1e-7 at rtol 1e-10 (``dmr``) and 1e-5 at rtol 1e-8 (``mc``, ``opa``), and
the same impact counts. A peer that does not agree is not timed (its timing test skips
and says why). Only the first 20 periods are compared: at these tolerances the orbits
separate later (sensitivity; ours alone at rtol 1e-10 and 1e-12 differ by O(1) at period
1000), so the long runs have different impact sequences in every solver.

Compilation is excluded from every timing: numba functions are called once before
(numbalsoda's cfuncs and loops cannot be cached: they embed ctypes addresses), jax
functions are called on the same shapes first (the loops' buffers have fixed capacities,
the ensemble fixed chunks, so one compilation per solver serves every size).

``test_peer_report`` prints the table (time, per-unit figure, RHS evaluations, ratio
peer/ours, agreement, ``os.getloadavg()``) and appends a record to
``benchmarks/results/peers.json``. Nothing is asserted about the ratios.

Installing the peers (``pip install -e '.[bench]'``; measured on Python 3.11, Debian 12):
numbalsoda 0.3.4 has no wheel for this platform and builds from source with CMake and a
Fortran compiler: ``apt-get update && apt-get install -y gfortran`` first (CMake and
ninja come from pip's build isolation). jax 0.10.2 / jaxlib 0.10.2 (CPU wheels),
diffrax 0.7.2 (with equinox 0.13.8, optimistix 0.1.0, lineax 0.1.1) install as wheels.
Without the peers every peer test skips (CI: ``pytest benchmarks -m "not slow"
--benchmark-disable``) and the module still imports.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import json
import os
import time
from pathlib import Path

import numba
import numpy as np
import pytest

import mc
import opa
from benchmarks import peers
from benchmarks.bench_dmr import scipy_dmr
from benchmarks.conftest import smoke_mode

OSC = opa.preset("3.2", omega=3.98)
SIGMA = 0.01
ORDER = 8
THREADS = 2
DMR_TOL, ENS_TOL = 1e-10, 1e-8
AGREE_PERIODS = 20
AGREE_SAMPLES = 32
# agreement required at rtol 1e-10 and at rtol 1e-8
AGREE = {"dmr": 1e-7, "mc": 1e-5, "opa": 1e-5}
RESULTS_FILE = Path(__file__).resolve().parent / "results" / "peers.json"

# --------------------------------------------------------------------------- the peers


def _nbl(method):
    return lambda osc, P, rtol, atol: peers.numbalsoda_dmr(osc, P, rtol, atol, method)


def _drx(solver):
    return lambda osc, P, rtol, atol: peers.diffrax_dmr(osc, P, rtol, atol, solver)


# name -> (module that must import, one trajectory (osc, periods, rtol, atol), rounds)
DMR_PEERS = {
    "numbalsoda dop853 loop": ("numbalsoda", _nbl("dop853"), 5),
    "numbalsoda solve_ivp events": ("numbalsoda", _nbl("ivp"), 5),
    "diffrax Dopri5": ("diffrax", _drx("Dopri5"), 3),
    "diffrax Dopri8": ("diffrax", _drx("Dopri8"), 3),
    "scipy DOP853": ("scipy", lambda osc, P, rtol, atol: scipy_dmr(osc, P, "DOP853", rtol,
                                                                    atol), 1),
}
MC_PEERS = {
    "numbalsoda dop853 loop": (
        "numbalsoda", lambda mus, P: peers.numbalsoda_ensemble(OSC, mus, P, ENS_TOL, ENS_TOL,
                                                               "dop853")),
    "numbalsoda solve_ivp events": (
        "numbalsoda", lambda mus, P: peers.numbalsoda_ensemble(OSC, mus, P, ENS_TOL, ENS_TOL,
                                                               "ivp")),
    "diffrax Dopri5 vmap": (
        "diffrax", lambda mus, P: peers.diffrax_ensemble(OSC, mus, P, ENS_TOL, ENS_TOL,
                                                         "Dopri5")),
}
OPA_PEERS = {
    "scipy DOP853": ("scipy", lambda P: peers.scipy_opa(OSC, SIGMA, ORDER, P, ENS_TOL,
                                                        ENS_TOL, "DOP853")),
}
OURS = "ours (opa)"

# measurements of this session: (case, solver) -> dict
_TIMES: dict[tuple[str, str], dict] = {}
_AGREED: dict[tuple[str, str], dict] = {}


def need(module: str):
    pytest.importorskip(module)
    if module == "diffrax":
        pytest.importorskip("jax")
        peers.import_jax()


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def sizes(request, periods) -> dict:
    smoke = smoke_mode(request.config)
    return dict(smoke=smoke, dmr_periods=periods,
                mc_samples=64 if smoke else 4000, mc_periods=10 if smoke else 200,
                opa_periods=10 if smoke else 200, rounds=1 if smoke else None)


@pytest.fixture()
def two_threads():
    before = numba.get_num_threads()
    numba.set_num_threads(min(THREADS, numba.config.NUMBA_NUM_THREADS))
    yield numba.get_num_threads()
    numba.set_num_threads(before)


def timed(benchmark, fn, rounds: int) -> tuple[float, object]:
    """Best wall time of ``rounds`` calls (one with --benchmark-disable), last result."""
    seconds, out = [], []

    def run():
        start = time.perf_counter()
        out.append(fn())
        seconds.append(time.perf_counter() - start)

    benchmark.pedantic(run, rounds=rounds, iterations=1)
    return min(seconds), out[-1]


def record(case, solver, seconds, work, nfev, benchmark, **extra):
    _TIMES[case, solver] = dict(seconds=seconds, work=work, rhs_evaluations=nfev, **extra)
    benchmark.group = f"peers {case}"
    benchmark.extra_info.update(case=case, solver=solver, work=work, rhs_evaluations=nfev,
                                **extra)


def require_agreement(case, peer):
    if (case, peer) not in _AGREED:
        check = {"dmr": dmr_agreement, "mc": mc_agreement, "opa": opa_agreement}[case]
        _AGREED[case, peer] = check(peer)
    result = _AGREED[case, peer]
    if not result["ok"]:
        pytest.skip(f"{peer} did not agree with ours ({result['why']}): not timed")
    return result


def _compare(why: list, name: str, ours, theirs, tol):
    ours, theirs = np.asarray(ours, float), np.asarray(theirs, float)
    if ours.shape != theirs.shape:
        why.append(f"{name}: {theirs.shape} against ours {ours.shape}")
        return float("inf")
    diff = float(np.abs(ours - theirs).max()) if ours.size else 0.0
    if not diff <= tol:
        why.append(f"{name} differs by {diff:.2g} > {tol:g}")
    return diff


# --------------------------------------------------------------------------- 1. DMR

DMR_OPTIONS = opa.SolverOptions(rtol=DMR_TOL, atol=DMR_TOL)


def dmr_agreement(peer):
    ours = opa.simulate_dmr(OSC, periods=AGREE_PERIODS, options=DMR_OPTIONS)
    t, x, v, impacts, _ = DMR_PEERS[peer][1](OSC, AGREE_PERIODS, DMR_TOL, DMR_TOL)
    why, tol = [], AGREE["dmr"]
    diff = max(_compare(why, "x", ours.x, x, tol), _compare(why, "v", ours.v, v, tol),
               _compare(why, "impact times", ours.impact_time, impacts, tol))
    _compare(why, "output times", ours.time, t, 1e-12)
    return dict(ok=not why, why="; ".join(why), max_difference=diff)


@pytest.mark.parametrize("peer", list(DMR_PEERS))
def test_dmr_agrees(peer):
    need(DMR_PEERS[peer][0])
    result = _AGREED[("dmr", peer)] = dmr_agreement(peer)
    assert result["ok"], result["why"]


def test_dmr_ours(benchmark, sizes):
    P = sizes["dmr_periods"]
    opa.simulate_dmr(OSC, periods=1, options=DMR_OPTIONS)  # load the compiled kernel
    seconds, ds = timed(benchmark, lambda: opa.simulate_dmr(OSC, periods=P,
                                                            options=DMR_OPTIONS),
                        sizes["rounds"] or 5)
    record("dmr", OURS, seconds, P, int(ds.attrs["rhs_evaluations"]), benchmark,
           impacts=int(ds.impact_time.size), method=ds.attrs.get("method", ""))


@pytest.mark.parametrize("peer", list(DMR_PEERS))
def test_dmr_peer(benchmark, sizes, peer):
    module, run, rounds = DMR_PEERS[peer]
    need(module)
    agreed = require_agreement("dmr", peer)
    P = sizes["dmr_periods"]
    run(OSC, 2, DMR_TOL, DMR_TOL)  # compile (numba / jax) before timing
    seconds, (_, x, _, impacts, nfev) = timed(
        benchmark, lambda: run(OSC, P, DMR_TOL, DMR_TOL), sizes["rounds"] or rounds)
    assert np.isfinite(x).all()
    record("dmr", peer, seconds, P, int(nfev), benchmark, impacts=len(impacts),
           agreement=agreed["max_difference"])


# --------------------------------------------------------------------------- 2. MC

ENS_OPTIONS = opa.SolverOptions(rtol=ENS_TOL, atol=ENS_TOL)


def ours_mc(samples, P, **kw):
    return mc.simulate_mc(OSC, sigma=SIGMA, samples=samples, sampler="random", seed=0,
                          periods=P, per_period=1, options=ENS_OPTIONS, progress=False, **kw)


def mc_agreement(peer):
    before = numba.get_num_threads()
    numba.set_num_threads(min(THREADS, numba.config.NUMBA_NUM_THREADS))
    try:
        ours = ours_mc(AGREE_SAMPLES, AGREE_PERIODS, keep_paths=True)
        x, v, n_imp, _ = MC_PEERS[peer][1](OSC.mu + SIGMA * ours.xi.values, AGREE_PERIODS)
    finally:
        numba.set_num_threads(before)
    why, tol = [], AGREE["mc"]
    diff = max(_compare(why, "x", ours.x, x, tol), _compare(why, "v", ours.v, v, tol))
    _compare(why, "impact counts", ours.n_impacts, n_imp, 0)
    return dict(ok=not why, why="; ".join(why), max_difference=diff)


def mc_points(samples):
    xi, _ = mc.sample_xi("random", samples, seed=0)
    return OSC.mu + SIGMA * xi


@pytest.mark.parametrize("peer", list(MC_PEERS))
def test_mc_agrees(peer):
    need(MC_PEERS[peer][0])
    result = _AGREED[("mc", peer)] = mc_agreement(peer)
    assert result["ok"], result["why"]


def test_mc_ours(benchmark, sizes, two_threads):
    M, P = sizes["mc_samples"], sizes["mc_periods"]
    ours_mc(64, 2)  # load the compiled kernel, start the thread pool
    seconds, ds = timed(benchmark, lambda: ours_mc(M, P), sizes["rounds"] or 2)
    assert np.allclose(ds.xi.values, (mc_points(M) - OSC.mu) / SIGMA, rtol=0, atol=1e-14)
    record("mc", OURS, seconds, M * P, int(ds.attrs["rhs_evaluations"]), benchmark,
           threads=two_threads)


@pytest.mark.parametrize("peer", list(MC_PEERS))
def test_mc_peer(benchmark, sizes, two_threads, peer):
    module, run = MC_PEERS[peer]
    need(module)
    agreed = require_agreement("mc", peer)
    M, P = sizes["mc_samples"], sizes["mc_periods"]
    mus = mc_points(M)
    # compile before timing (diffrax: one chunk per host device, the timed shapes)
    run(mc_points(peers.LANES * 2), 1)

    def ensemble():
        x, v, _, nfev = run(mus, P)
        return (x.mean(axis=0), x.var(axis=0), v.mean(axis=0), v.var(axis=0)), nfev

    seconds, (stats, nfev) = timed(benchmark, ensemble, sizes["rounds"] or 2)
    assert np.isfinite(stats[0]).all()
    record("mc", peer, seconds, M * P, int(nfev), benchmark, threads=two_threads,
           agreement=agreed["max_difference"])


# --------------------------------------------------------------------------- 3. OPA


def ours_opa(P):
    return opa.simulate_opa(OSC, sigma=SIGMA, order=ORDER, periods=P, options=ENS_OPTIONS)


def opa_agreement(peer):
    why, tol = [], AGREE["opa"]
    diff = 0.0
    # 5 periods first (before any sensitivity), then the 20 of the other cases
    for P, tol_P in ((5, tol / 10), (AGREE_PERIODS, tol)):
        ours = ours_opa(P)
        _, xc, vc, impacts, _ = OPA_PEERS[peer][1](P)
        diff = max(diff, _compare(why, f"x_coef ({P} periods)", ours.x_coef, xc, tol_P),
                   _compare(why, f"v_coef ({P} periods)", ours.v_coef, vc, tol_P),
                   _compare(why, f"impact times ({P} periods)", ours.impact_time, impacts,
                            tol_P))
    return dict(ok=not why, why="; ".join(why), max_difference=diff)


@pytest.mark.parametrize("peer", list(OPA_PEERS))
def test_opa_agrees(peer):
    need(OPA_PEERS[peer][0])
    result = _AGREED[("opa", peer)] = opa_agreement(peer)
    assert result["ok"], result["why"]


def test_opa_ours(benchmark, sizes):
    P = sizes["opa_periods"]
    ours_opa(1)  # load the compiled kernel
    seconds, ds = timed(benchmark, lambda: ours_opa(P), sizes["rounds"] or 5)
    record("opa", OURS, seconds, P, int(ds.attrs["rhs_evaluations"]), benchmark,
           impacts=int(ds.impact_time.size))


@pytest.mark.parametrize("peer", list(OPA_PEERS))
def test_opa_peer(benchmark, sizes, peer):
    module, run = OPA_PEERS[peer]
    need(module)
    agreed = require_agreement("opa", peer)
    P = sizes["opa_periods"]
    seconds, (_, xc, _, impacts, nfev) = timed(benchmark, lambda: run(P),
                                               sizes["rounds"] or 3)
    assert np.isfinite(xc).all()
    record("opa", peer, seconds, P, int(nfev), benchmark, impacts=len(impacts),
           agreement=agreed["max_difference"])


# --------------------------------------------------------------------------- report

UNITS = {"dmr": ("us/period", 1e6), "mc": ("traj-periods/s", None), "opa": ("us/period", 1e6)}


def _version(name):
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def report_lines(sizes, load) -> list[str]:
    lines = [(f"peers: {'smoke' if sizes['smoke'] else 'full'} mode; load average "
              f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores; ours "
              f"{getattr(opa.SolverOptions(), 'method', '?')}"),
             (f"{'case':<5} {'solver':<30} {'time s':>9} {'per unit':>20} {'RHS evals':>10} "
              f"{'peer/ours':>9}  agreement")]
    for case, title in (("dmr", f"DMR {sizes['dmr_periods']} periods, rtol 1e-10"),
                        ("mc", f"MC {sizes['mc_samples']} x {sizes['mc_periods']}, rtol 1e-8"),
                        ("opa", f"OPA N={ORDER} {sizes['opa_periods']} periods, rtol 1e-8")):
        rows = {s: r for (c, s), r in _TIMES.items() if c == case}
        if not rows:
            continue
        lines.append(f"-- {title}")
        ours = rows.get(OURS)
        unit, scale = UNITS[case]
        for solver in [OURS] + sorted(s for s in rows if s != OURS):
            r = rows[solver]
            per = r["seconds"] / r["work"] * scale if scale else r["work"] / r["seconds"]
            ratio = f"{r['seconds'] / ours['seconds']:9.2f}" if ours else f"{'-':>9}"
            agreed = ("-" if solver == OURS else
                      f"{r['agreement']:.1e}" if "agreement" in r else "?")
            lines.append(f"{case:<5} {solver:<30} {r['seconds']:9.4f} {per:11.4g} "
                         f"{unit:<8} {r['rhs_evaluations']:10d} {ratio}  {agreed}")
        for peer in {"dmr": DMR_PEERS, "mc": MC_PEERS, "opa": OPA_PEERS}[case]:
            a = _AGREED.get((case, peer))
            if a is not None and not a["ok"]:
                lines.append(f"{case:<5} {peer:<30} not timed: {a['why']}")
    return lines


def test_peer_report(sizes, capsys):
    """Prints the table and appends a record to benchmarks/results/peers.json."""
    if not any(solver != OURS for _, solver in _TIMES):
        pytest.skip("no peer was timed in this session (peers not installed?)")
    disagreed = [k for k, a in _AGREED.items() if not a["ok"]]
    load = os.getloadavg()
    lines = report_lines(sizes, load)
    with capsys.disabled():
        print("\n" + "\n".join(lines))
    entry = dict(
        date=datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        mode="smoke" if sizes["smoke"] else "full", loadavg=list(load),
        cpu_count=os.cpu_count(), numba_threads=THREADS,
        versions={n: _version(n) for n in ("opa-mc", "numba", "scipy", "numbalsoda", "jax",
                                           "jaxlib", "diffrax", "optimistix")},
        sizes={k: v for k, v in sizes.items() if k != "rounds"},
        results=[dict(case=c, solver=s, **r) for (c, s), r in _TIMES.items()],
        agreement=[dict(case=c, peer=p, **a) for (c, p), a in _AGREED.items()],
    )
    RESULTS_FILE.parent.mkdir(parents=True, exist_ok=True)
    history = json.loads(RESULTS_FILE.read_text()) if RESULTS_FILE.exists() else []
    history.append(entry)
    RESULTS_FILE.write_text(json.dumps(history, indent=1, default=float) + "\n")
    # every peer that was timed agreed first (a peer that did not is skipped, not timed)
    for (case, solver) in _TIMES:
        if solver != OURS:
            assert _AGREED[case, solver]["ok"]
    assert not [k for k in disagreed if k in _TIMES]
