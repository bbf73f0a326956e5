"""The oscillator's flags of every subcommand (opa.cli._flags): the lower wall's
``--delta-minus`` and ``--eta-minus`` beside the parameters' own flags.

Their bad values are in the hostile-user corpus (test_bad_inputs.py). Independent
reference for a run with them: the scipy event integrator of ``tests/impact_truths.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr

from opa.cli._flags import oscillator_from
from opa.cli._main import _leaves, build_parser, main
from tests.impact_truths import two_wall_impacts


def leaves():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return list(_leaves(sub))


def options(parser) -> set[str]:
    return {flag for action in parser._actions for flag in action.option_strings}


def test_every_command_with_the_oscillators_flags_has_the_lower_walls():
    with_delta = [p for p in leaves() if "--delta" in options(p)]
    assert len(with_delta) >= 8  # simulate x3, bifurcation x3, validate, converge, ...
    for parser in with_delta:
        assert {"--delta-minus", "--eta-minus"} <= options(parser), parser.prog


def parse(argv):
    return build_parser().parse_args(argv)


def test_the_flags_override_a_model_files_lower_wall(tmp_path):
    path = tmp_path / "gear.toml"
    path.write_text("[oscillator]\nx0 = -0.5\ndelta_minus = -0.8\neta_minus = 0.7\n")
    base = ["simulate", "dmr", "--model", str(path)]
    osc = oscillator_from(parse(base))
    assert (osc.delta_minus, osc.eta_minus) == (-0.8, 0.7)
    osc = oscillator_from(parse(base + ["--delta-minus", "-1.5", "--eta-minus", "0.4"]))
    assert (osc.delta_minus, osc.eta_minus, osc.lower_restitution) == (-1.5, 0.4, 0.4)
    osc = oscillator_from(parse(base + ["--delta-minus", "-inf"]))
    assert not osc.two_walls  # -inf removes the file's wall
    osc = oscillator_from(parse(["simulate", "dmr", "--delta-minus", "-2e0"]))
    assert (osc.delta_minus, osc.lower_restitution) == (-2.0, osc.eta)
    assert not oscillator_from(parse(["simulate", "dmr"])).two_walls


def test_a_preset_takes_the_lower_wall_too():
    osc = oscillator_from(parse(["simulate", "dmr", "--preset", "3.1", "--delta-minus",
                                 "-1.5", "--eta-minus", "1"]))
    assert (osc.delta_minus, osc.eta_minus) == (-1.5, 1.0)


@pytest.mark.parametrize("extra", [[], ["--model", "{model}"]])
def test_simulate_dmr_with_a_lower_wall_impacts_it_as_scipy_says(extra, tmp_path, capsys):
    """The paper's law (section 3.2, no impulses, f = 4) between -1.2 and 0: impacts on
    both walls over five periods, the same walls and times within 1e-8 of scipy's, given
    as flags or as flags over a model file's other wall."""
    model = tmp_path / "walls.toml"
    model.write_text("[oscillator]\ndelta_minus = -1.1\neta_minus = 0.9\n")
    out = tmp_path / "run.nc"
    argv = ["simulate", "dmr", "--preset", "3.2", "--F0", "0", "--f", "4", "--periods", "5",
            "--delta-minus", "-1.2", "--eta-minus", "0.6", "--rtol", "1e-11", "--atol",
            "1e-11", "--out", str(out), "--quiet"]
    if extra:
        argv = [a for a in argv if a not in ("--preset", "3.2")] + [
            str(model) if a == "{model}" else a for a in extra]
    assert main(argv) == 0, capsys.readouterr().err
    with xr.open_dataset(out) as ds:
        ds.load()
    mu, a, c, f, omega = (ds.attrs[k] for k in ("mu", "a", "c", "f", "omega"))
    want = two_wall_impacts(lambda x, v: mu * (1 - v * v) * v - a * x - c * x ** 3, f, omega,
                            (-1.2, 0.0), (0.6, ds.attrs["eta"]), (-1.0, 0.0),
                            5 * 2 * math.pi / omega, rtol=1e-12, atol=1e-13)
    assert (ds.attrs["delta_minus"], ds.attrs["eta_minus"]) == (-1.2, 0.6)
    assert set(want["wall"]) == {-1, 1}
    np.testing.assert_array_equal(ds.impact_wall.values, want["wall"])
    np.testing.assert_allclose(ds.impact_time.values, want["times"], rtol=0, atol=1e-8)
