"""Tests for ``opa.cli._stability``: ``opa-mc stability`` finds the period-2 orbit of
section 3.1 without impulses at c = 0.05 (section x = -0.3996) and, over a sweep of c,
locates the period doubling at c = 0.0891 (docs/stability.md, finding A)."""

from __future__ import annotations

import argparse

from opa.cli._stability import register_stability


def test_cli_orbit_and_sweep(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    register_stability(parser.add_subparsers())
    args = parser.parse_args(["stability", "dmr", "--preset", "3.1", "--F0", "0", "--c", "0.05"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "period-2 orbit" in out and "-0.3996" in out
    nc = tmp_path / "b.nc"
    args = parser.parse_args(["stability", "dmr", "--preset", "3.1", "--F0", "0", "--sweep",
                              "c=0.095:0.085:10", "--depth", "0", "--out", str(nc)])
    assert args.func(args) == 0
    assert "period-doubling  c = 0.0891" in capsys.readouterr().out and nc.exists()
