"""Tests for ``opa.cli._stability``: ``opa-mc stability`` finds the period-2 orbit of
section 3.1 without impulses at c = 0.05 (section x = -0.3996) and, over a sweep of c,
locates the period doubling at c = 0.0891 (docs/stability.md, finding A)."""

from __future__ import annotations

import argparse

import pytest

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


#: the linear impact oscillator whose period-1 orbit is known in closed form
LINEAR = dict(a=1.0, f=1.0, omega=1.6, eta=0.8, delta=0.1)
LINEAR_FLAGS = ["--mu", "0", "--c", "0", "--a", "1", "--f", "1", "--omega", "1.6", "--eta",
                "0.8", "--delta", "0.1", "--F0", "0", "--x0", "-0.5"]


def test_one_orbit_is_the_dataset_the_api_and_the_cli_write_alike(tmp_path):
    """``opa.dynamics.orbit_dataset`` (what ``stability`` writes without --sweep) holds the
    closed-form linear impact orbit, and the CLI's file is that dataset."""
    import numpy as np
    import xarray as xr

    import opa
    from opa.cli._main import main
    from opa.dynamics import ImpactSystem, orbit_dataset, periodic_orbit
    from tests.truths import linear_impact_orbit

    system = ImpactSystem.of(opa.System(opa.Oscillator(mu=0.0, c=0.0, F0=0.0, x0=-0.5,
                                                       **LINEAR)),
                             options=opa.SolverOptions(rtol=1e-10, atol=1e-10))
    ds = orbit_dataset(system, periodic_orbit(system, transient=300))
    state, _, _, speed = linear_impact_orbit(**LINEAR)
    np.testing.assert_allclose(ds.state.values[0], state, rtol=0, atol=1e-9)
    assert ds.sizes["branch_id"] == ds.sizes["point"] == 1 and ds.period.item() == 1
    assert ds.min_impact_velocity.item() == pytest.approx(speed, rel=1e-9)
    out = tmp_path / "s.nc"
    assert main(["stability", "dmr", *LINEAR_FLAGS, "--out", str(out), "--quiet"]) == 0
    written = xr.load_dataset(out)
    xr.testing.assert_equal(written.drop_attrs(), ds.drop_attrs())


def test_the_benettin_check_runs_the_kernel_without_impulses_and_the_plain_flow_with_them():
    """docs/stability.md: the kernel's own runs ("solver") resumed every period, and with
    impulses (F0 != 0) the plain flow."""
    import opa
    from opa.dynamics import ImpactSystem, benettin_engine

    for F0, engine in ((0.0, "solver"), (0.1, "plain"), (-0.2, "plain")):
        system = ImpactSystem.of(opa.System(opa.preset("3.1", F0=F0)))
        assert benettin_engine(system) == engine
