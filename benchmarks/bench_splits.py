"""The trust map's split phase alone: ``_Map.splits`` (one split scan per horizon) at each
swept value, timed (wall and CPU seconds), and its lists compared between two checkouts.

``pytest benchmarks/bench_splits.py`` times a one-value map over short horizons (the smoke
run) and, outside smoke mode, the default map's five values of omega (``slow``). As a
script it times the checkout of the current directory and saves its lists, or compares
two saved runs (e.g. before and after a change of the scan)::

    cd OLD && python NEW/benchmarks/bench_splits.py --save before.json
    cd NEW && python benchmarks/bench_splits.py --save after.json
    python benchmarks/bench_splits.py --compare before.json after.json

The comparison says, per value and horizon, whether the lists are the same (every split's
value, bracket, kind and the impacts on its two sides; time and speed to 1e-9 relative),
whether within the radius where the new list is complete it is the old one, how that
radius moved, and whether the impact-count tables at the grid sigmas are the same (and at
how many of them they are exact: the list complete within sigma).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import tempfile
import time

import pytest

SMOKE = dict(values=(3.98,), sigmas=(0.01, 0.03), horizons=(4.0, 8.0))


def _cpu() -> float:
    use = resource.getrusage(resource.RUSAGE_SELF)
    return use.ru_utime + use.ru_stime


def split_phase(**fields) -> dict:
    """Time ``_Map.splits`` at every value of ``ValidateConfig(**fields)`` (a fresh parts
    folder: every scan computed), after one short scan that loads the kernels."""
    from compare._config import ValidateConfig
    from compare._trustmap import _Map
    from opa._splits import ScanOptions, scan_splits

    out = {"values": []}
    with tempfile.TemporaryDirectory() as tmp:
        cfg = ValidateConfig(**fields, outdir=tmp)
        value = cfg.values[0]
        osc = cfg.oscillator_at(value)
        scan_splits(cfg.system_at(value), cfg.options, cfg.uncertain, osc.mu - 0.01,
                    osc.mu + 0.01, osc.forcing_period, ScanOptions(tol=1e-4))
        out.update(horizons=list(cfg.horizons), sigmas=list(cfg.sigmas))
        maps = _Map(cfg, progress=False, log=lambda *a: None)
        start, cpu = time.perf_counter(), _cpu()
        for value in cfg.values:
            w, c = time.perf_counter(), _cpu()
            centre, scans = maps.splits(value)
            out["values"].append({
                "value": value, "centre": centre, "wall": time.perf_counter() - w,
                "cpu": _cpu() - c,
                "scans": [{"horizon": s.horizon, "truncated": bool(s.truncated),
                           "count": s.count, "complete_within": s.complete_within,
                           "crossings_within": s.crossings_within,
                           "splits": [[sp.value, sp.tol, sp.kind, sp.time, sp.speed, sp.left,
                                       sp.right] for sp in s.splits]} for s in scans]})
        out["wall"], out["cpu"] = time.perf_counter() - start, _cpu() - cpu
    out["load"] = os.getloadavg()
    return out


def _table(run: dict) -> str:
    lines = [f"{'value':>8} {'wall s':>8} {'CPU s':>8}"]
    lines += [f"{v['value']:>8g} {v['wall']:>8.2f} {v['cpu']:>8.2f}" for v in run["values"]]
    lines.append(f"{'all':>8} {run['wall']:>8.2f} {run['cpu']:>8.2f}   load average "
                 + " ".join(f"{x:.2f}" for x in run["load"]))
    return "\n".join(lines)


def _same_split(a, b) -> bool:
    return a[:3] + a[5:] == b[:3] + b[5:] and all(
        math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-12) for x, y in zip(a[3:5], b[3:5]))


def _table_of(scan, centre, sigma):
    from compare._mapdata import count_distribution
    from opa._splits import Split

    splits = [Split(*sp) for sp in scan["splits"] if sp[2] != "output crossing"]
    return count_distribution(centre, sigma, splits, scan["count"], None,
                              scan["complete_within"])


def compare(old: dict, new: dict) -> str:
    """One line per value and horizon: how the new lists relate to the old ones."""
    lines = []
    for vo, vn in zip(old["values"], new["values"]):
        for so, sn in zip(vo["scans"], vn["scans"]):
            kinds = {}
            for name, pick in (("splits", lambda k: k != "output crossing"),
                               ("crossings", lambda k: k == "output crossing")):
                a = [sp for sp in so["splits"] if pick(sp[2])]
                b = [sp for sp in sn["splits"] if pick(sp[2])]
                r = sn["complete_within" if name == "splits" else "crossings_within"]
                near = [[sp for sp in x if abs(sp[0] - vo["centre"]) < r] for x in (a, b)]
                kinds[name] = (len(a), len(b), len(a) == len(b) and all(map(_same_split, a, b)),
                               len(near[0]) == len(near[1])
                               and all(map(_same_split, *near)))
            tables = all(_table_of(so, vo["centre"], s) == _table_of(sn, vn["centre"], s)
                         for s in old["sigmas"])
            exact = [sum(scan["complete_within"] >= s for s in old["sigmas"])
                     for scan in (so, sn)]
            (n0, n1, same, prefix), (c0, c1, csame, cprefix) = kinds["splits"], \
                kinds["crossings"]
            lines.append(
                f"{vo['value']:g} / {so['horizon']:g} periods: splits {n0} -> {n1} "
                f"{'same' if same else 'prefix' if prefix else 'DIFFER'}, complete within "
                f"{so['complete_within']:.4g} -> {sn['complete_within']:.4g}; crossings "
                f"{c0} -> {c1} {'same' if csame else 'prefix' if cprefix else 'DIFFER'}; "
                f"count tables {'same' if tables else 'differ'} (exact at {exact[0]} -> "
                f"{exact[1]} of {len(old['sigmas'])} sigmas)")
    return "\n".join(lines)


def test_split_phase_smoke(benchmark):
    benchmark.group = "split phase"
    run = benchmark.pedantic(split_phase, kwargs=SMOKE, rounds=1, iterations=1)
    assert all(scan["complete_within"] > 0 for v in run["values"] for scan in v["scans"])


@pytest.mark.slow
def test_split_phase_default(benchmark, request):
    """The default map's five values of omega, horizons 10 and 50."""
    from benchmarks.conftest import smoke_mode

    if smoke_mode(request.config):
        pytest.skip("the default map's scans only outside smoke mode")
    benchmark.group = "split phase"
    run = benchmark.pedantic(split_phase, rounds=1, iterations=1)
    print("\n" + _table(run))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--save", help="time the current directory's checkout, save here")
    parser.add_argument("--compare", nargs=2, metavar=("OLD", "NEW"),
                        help="compare two saved runs")
    args = parser.parse_args(argv)
    sys.path.insert(0, os.getcwd())  # the checkout timed (or read) is the current directory's
    if args.compare:
        runs = []
        for path in args.compare:
            with open(path) as f:
                runs.append(json.load(f))
        for run in runs:
            print(_table(run))
        print(compare(*runs))
        return
    run = split_phase()
    print(_table(run))
    if args.save:
        with open(args.save, "w") as f:
            json.dump(run, f)


if __name__ == "__main__":
    main()
