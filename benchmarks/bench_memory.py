"""The map's memory as its grid grows (issue 29, item 4): bytes per grid point.

``opa-mc validate`` runs in a fresh process twice, on a grid of K and 2K swept values,
and the peak resident memory of that main process (``ru_maxrss``, after the report) is
read for each; the difference over the extra grid points is the memory each point costs
there. The workers hold one task's data each and are not counted. The dataset's own
size per point (``nbytes`` of validate.nc) is printed beside it::

    python -m pytest -q -s benchmarks/bench_memory.py -m slow   # 5 and 10 values x 8 sigmas

The smoke run (CI) takes tiny maps through the same path.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

# the main process of one `opa-mc validate` run, its peak memory printed after the report
_RUN = ("import json, resource, sys\n"
        "from opa.cli._main import main\n"
        "code = main(sys.argv[1:])\n"
        "print(json.dumps({'code': code, 'maxrss_kB': "
        "resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}))\n")


def _peak(outdir, values, extra) -> dict:
    env = dict(os.environ, MPLBACKEND="Agg")
    args = ["validate", "--quiet", "--no-frontier", "--outdir", str(outdir), "--values",
            ",".join(f"{v:g}" for v in values), *extra]
    proc = subprocess.run([sys.executable, "-c", _RUN, *args], env=env, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["code"] == 0
    with xr.open_dataset(os.path.join(outdir, "validate.nc")) as ds:
        out["nbytes"] = int(ds.nbytes)
        out["points"] = int(ds.sizes[ds.attrs["parameter"]] * ds.sizes["sigma"])
    return out


def _per_point(tmp_path, count: int, extra) -> tuple[dict, dict, float]:
    values = np.round(np.linspace(3.98, 4.2, 2 * count), 4)
    small = _peak(tmp_path / "small", values[::2], extra)
    large = _peak(tmp_path / "large", values, extra)
    per = (large["maxrss_kB"] - small["maxrss_kB"]) * 1024 / (large["points"]
                                                              - small["points"])
    print(f"\n{small['points']} points: peak {small['maxrss_kB'] / 1024:.1f} MB, "
          f"{large['points']} points: {large['maxrss_kB'] / 1024:.1f} MB; "
          f"{per / 2**20:.2f} MB per grid point (the map itself "
          f"{large['nbytes'] / large['points'] / 2**20:.2f} MB per point); load average "
          f"{os.getloadavg()[0]:.2f}")
    return small, large, per


def test_memory_tiny(tmp_path):
    """The smoke run: two tiny maps; every number read is there and positive."""
    small, large, _ = _per_point(tmp_path, 1, ["--sigmas", "0.01,0.03", "--orders", "0:2",
                                               "--horizons", "2,4", "--samples", "64",
                                               "--max-samples", "128", "--no-plots"])
    assert large["points"] == 2 * small["points"] == 4
    assert small["maxrss_kB"] > 0 and large["nbytes"] > small["nbytes"] > 0


@pytest.mark.slow
def test_memory_default_grid(tmp_path):
    """5 and 10 swept values of the default map (8 sigmas each, no frontier)."""
    _per_point(tmp_path, 5, [])
