"""One uncertain parameter gives the same bits as another tree: the check behind "d = 1
unchanged bit for bit" when the kernel or the system's packing changes.

    git worktree add /tmp/w974 974e3a3
    python -m benchmarks.one_dimension_unchanged --base /tmp/w974

runs the same set of one-parameter runs in this tree and in ``--base`` (each in its own
process, with that tree first on the path) and compares every float array of their
datasets with ``np.array_equal``: ``simulate_opa`` for mu, a and c uncertain, both
truncations, the three impact laws, a Beta law (N = 3 and N = 0, sigma 0 too), pulses
and adaptive elements; the DMR; ``simulate_mc`` for mu and c. It prints the number of
arrays and lists any that differ (exit status 1 then).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

CASES = {
    "mu_gal": dict(uncertain="mu", sigma=0.02, order=4),
    "c_gal": dict(uncertain="c", sigma=0.01, order=3),
    "a_gal": dict(uncertain="a", sigma=0.02, order=3),
    "mu_paper": dict(uncertain="mu", sigma=0.02, order=4, truncation="paper"),
    "c_paper": dict(uncertain="c", sigma=0.02, order=4, truncation="paper"),
    "mu_ens": dict(uncertain="mu", sigma=0.02, order=4, impact_law="ensemble"),
    "mu_salt": dict(uncertain="mu", sigma=0.02, order=4, impact_law="saltation"),
    "beta_mu": dict(uncertain="mu", sigma=0.02, order=3, distribution="beta:2,3"),
    "beta_N0": dict(uncertain="mu", sigma=0.02, order=0, distribution="beta:2,3"),
    "sig0_beta": dict(uncertain="mu", sigma=0.0, order=0, distribution="beta:2,3"),
    "pulse": dict(uncertain="c", sigma=0.01, order=3, impulse="pulse"),
}


def snapshot(path: str) -> None:
    """Every float array of the runs, written to ``path`` (.npz)."""
    import mc
    import opa

    osc = opa.preset("3.2")
    arrays = {}

    def keep(prefix, ds):
        for name in ds.data_vars:
            if ds[name].dtype.kind == "f":
                arrays[f"{prefix}/{name}"] = ds[name].values

    for key, fields in CASES.items():
        keep(key, opa.simulate_opa(opa.System(osc, **fields), periods=10, per_period=8))
    keep("adaptive", opa.simulate_opa(opa.System(osc, uncertain="mu", sigma=0.05, order=3),
                                      periods=10, per_period=8, elements="adaptive"))
    keep("dmr", opa.simulate_dmr(opa.System(osc), periods=10, per_period=8))
    for name in ("mu", "c"):
        keep(f"mc_{name}", mc.simulate_mc(opa.System(osc, uncertain=name, sigma=0.02),
                                          samples=64, periods=10, per_period=8))
    np.savez(path, **arrays)


def compare(a_path: str, b_path: str) -> list[str]:
    """The arrays that differ (or are missing) between two snapshots."""
    a, b = np.load(a_path), np.load(b_path)
    return [k for k in a.files if k not in b.files
            or not np.array_equal(a[k], b[k], equal_nan=True)] + \
        [k for k in b.files if k not in a.files]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", help="the other tree (a git worktree)")
    parser.add_argument("--snapshot", help=argparse.SUPPRESS)  # one tree's runs, to a file
    args = parser.parse_args()
    if args.snapshot:
        snapshot(args.snapshot)
        return 0
    if not args.base:
        parser.error("--base is needed")
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for name, root in (("here", here), ("base", os.path.abspath(args.base))):
            out = os.path.join(tmp, f"{name}.npz")
            # this file, run with the tree's packages first on the path
            env = dict(os.environ, PYTHONPATH=root, MPLBACKEND="Agg")
            subprocess.run([sys.executable, os.path.abspath(__file__), "--snapshot", out],
                           check=True, env=env, cwd=tmp)
            paths.append(out)
        differ = compare(*paths)
        count = len(np.load(paths[0]).files)
    print(f"{count} arrays compared: {len(differ)} differ" + (f": {differ}" if differ else ""))
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
