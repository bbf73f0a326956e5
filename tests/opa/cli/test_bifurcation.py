"""Tests for ``opa.cli._bifurcation``: ``opa-mc bifurcation`` and ``opa-mc reproduce``.

The sweep specification parser (``NAME=START:STOP:COUNT`` or a list) and its refusals,
a sweep of section 3.1 without impulses whose labels are known (4/4 at c = 0.035, 2/2 at
c = 0.05), the located period doubling at c = 0.0891223 (docs/stability.md, finding A)
and ``--no-locate``, and the paper's Fig. 2 written by ``reproduce``.
"""

from __future__ import annotations

import argparse

import pytest
import xarray as xr

from opa.cli._bifurcation import parse_sweep, register


def cli(argv):
    from opa.cli._flags import CliError

    parser = argparse.ArgumentParser(prog="opa-mc")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, CliError) as err:
        return str(err)


@pytest.mark.parametrize(
    "spec, match",
    [
        ("c=0.01:0.1", "expected NAME=START:STOP:COUNT"),
        ("c0.01:0.1:3", "expected NAME=START:STOP:COUNT"),
        ("cc=0.01:0.1:3", "unknown parameter 'cc'"),
        ("c=x:0.1:3", "START 'x' is not a number"),
        ("c=0.01:0.1:2.5", "COUNT must be an integer >= 1, got '2.5'"),
        ("c=0.01:0.1:0", "COUNT must be an integer in 1..100000, got 0"),
        ("c=0.1:0.1:5", "START and STOP are equal"),
        ("c=0.1,0.1", "distinct"),
        ("c=0.01:inf:3", "STOP must be finite"),
    ],
)
def test_bad_sweep_spec_names_the_value(spec, match):
    with pytest.raises(ValueError, match=match) as err:
        parse_sweep(spec)
    assert repr(spec) in str(err.value)


def test_parse_sweep():
    name, values = parse_sweep("omega=3.98:4.2:12")
    assert name == "omega" and len(values) == 12 and values[0] == 3.98 and values[-1] == 4.2
    assert parse_sweep("F0=0,0.1")[1].tolist() == [0.0, 0.1]
    assert parse_sweep("c=0.05:0.05:1")[1].tolist() == [0.05]


def test_cli_bifurcation_writes_dataset_and_plot(tmp_path, capsys):
    out, png = tmp_path / "b.nc", tmp_path / "b.png"
    code = cli(["bifurcation", "dmr", "--preset", "3.1", "--F0", "0", "--sweep",
                "c=0.035,0.05", "--transient", "200", "--record", "40", "--workers", "1",
                "--out", str(out), "--plot", str(png)])
    assert code == 0
    text = capsys.readouterr().out
    assert "c = 0.035: 4/4" in text and "c = 0.05: 2/2" in text
    with xr.open_dataset(out) as ds:
        assert ds.label.values.tolist() == ["4/4", "2/2"]
    assert png.stat().st_size > 10_000
    assert "use --transient" in cli(["bifurcation", "dmr", "--sweep", "c=0.1:0.2:2",
                                     "--periods", "5"])
    assert "unknown parameter" in cli(["bifurcation", "dmr", "--sweep", "q=1:2:2"])


def test_cli_reproduce_fig2(tmp_path):
    assert cli(["reproduce", "fig2", "--outdir", str(tmp_path), "--quiet"]) == 0
    assert (tmp_path / "fig2.png").stat().st_size > 10_000


def test_cli_locates_by_default_and_no_locate_skips(capsys):
    base = ["bifurcation", "dmr", "--preset", "3.1", "--F0", "0", "--sweep", "c=0.08:0.1:5",
            "--transient", "200", "--record", "40", "--workers", "1"]
    assert cli(base) == 0
    text = capsys.readouterr().out
    assert "observed periods" in text
    assert "period-doubling  c = 0.08912234" in text
    assert cli(base + ["--no-locate"]) == 0
    assert "bifurcations not located: locate=False" in capsys.readouterr().out
    assert "locate=True: the Monte Carlo mean" in cli(
        ["bifurcation", "mc", "--sweep", "c=0.05,0.06", "--locate", "--samples", "4"])
