"""``opa-mc validate --uncertain mu,c --relative R1,R2`` (``opa/cli/_trustline.py``)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from opa.cli._main import main

FREE = ["--mu", "0.3", "--a", "1.0", "--c", "0.5", "--f", "0.4", "--omega", "1.3",
        "--delta", "50.0", "--F0", "0.0", "--x0", "0.5", "--v0", "0.0"]


def test_the_trust_line_writes_its_dataset_and_table(tmp_path, capsys):
    out = tmp_path / "line"
    assert main(["validate", "--uncertain", "mu,c", "--relative", "0.2,0.4", "--sigmas",
                 "0.25,1", "--orders", "1", "--horizons", "3", "--samples", "64",
                 "--max-samples", "128", *FREE, "--outdir", str(out)]) == 0
    with xr.open_dataset(out / "validate.nc") as ds:
        assert ds.verdict.dims == ("variant", "scale")
        np.testing.assert_array_equal(ds.scale.values, [0.25, 1.0])
        np.testing.assert_allclose(ds.attrs["sigma"], [0.2 * 0.3, 0.4 * 0.5])
        stars = ds.scale_star.values
    printed = capsys.readouterr().out
    summary = (out / "summary.md").read_text()
    assert "| adaptive boxes |" in printed and "| adaptive boxes |" in summary
    assert f"| {stars[2]:g} |" in summary.splitlines()[-1]


@pytest.mark.parametrize("argv, words", [
    (["--uncertain", "mu,c"], "--relative R1,R2,... is needed"),
    (["--uncertain", "mu,c", "--relative", "0.02"], "--relative must give one positive size"),
    (["--uncertain", "mu,c", "--relative", "0.02,0.1", "--values", "3.9,-4"],
     "omega = -4: omega must be > 0"),
    (["--uncertain", "mu,c", "--relative", "0.02,0.1", "--sweep", "mu=0.7:0.9:2"],
     "the swept parameter 'mu' is one of the uncertain ones"),
    (["--uncertain", "mu,c", "--relative", "0.02,0.1", "--values", "3.9", "--resolution",
      "-1"], "--resolution must be a positive number"),
    (["--uncertain", "mu,c", "--relative", "0.02,0.1", "--config", "x.toml"],
     "--config does not apply"),
    (["--uncertain", "mu,c", "--relative", "0.02,0.1", "--elements", "4"],
     "--elements does not apply"),
    (["--uncertain", "mu,c", "--relative", "0.02,0.1", "--sigmas", "-1"],
     "--sigmas must be a positive number"),
    (["--relative", "0.02"], "--relative applies with several uncertain parameters"),
    (["--uncertain", "mu,c", "--relative", "0.02,20"], "negative for some samples"),
])
def test_refusals_name_the_flag_before_any_work(argv, words, capsys, tmp_path):
    assert main(["validate", *argv, "--outdir", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_the_trust_map_of_several_parameters_writes_its_dataset_and_tables(tmp_path, capsys):
    """--values and two horizons with --resolution: the map's dims, one table per horizon
    and the bisected intervals, whose ends bracket the grid's s*."""
    out = tmp_path / "map"
    assert main(["validate", "--uncertain", "mu,c", "--relative", "0.2,0.4", "--sigmas",
                 "0.25,1", "--orders", "1", "--horizons", "2,3", "--samples", "64",
                 "--max-samples", "128", "--values", "1.3,1.4", "--resolution", "0.5", *FREE,
                 "--outdir", str(out)]) == 0
    with xr.open_dataset(out / "validate.nc") as ds:
        assert ds.verdict.dims == ("omega", "horizon", "variant", "scale")
        np.testing.assert_array_equal(ds.omega.values, [1.3, 1.4])
        np.testing.assert_array_equal(ds.horizon.values, [2.0, 3.0])
        star = ds.scale_star.isel(horizon=-1).values
        lower, upper = ds.scale_star_lower.values, ds.scale_star_upper.values
    assert (lower >= star).all() and (lower < upper).all()
    summary = (out / "summary.md").read_text()
    assert "Over 2 periods:" in summary and "Over 3 periods:" in summary
    assert summary.count("| 1.4 | adaptive boxes |") == 2
    assert "s* bisected to 0.5" in capsys.readouterr().out


def test_several_parameters_of_a_model_files_own_law(tmp_path, capsys):
    """A model file whose law names none of mu, a, c (a Python function beside it):
    validate's own copy of the file's values must not turn the unnamed mu into a flag
    that "has no effect" (it did: the trust line was refused)."""
    import shutil
    from pathlib import Path

    examples = Path(__file__).resolve().parents[3] / "docs" / "examples"
    shutil.copy(examples / "contact.py", tmp_path / "contact.py")
    text = (examples / "hertz-function.toml").read_text()
    model = tmp_path / "hertz.toml"
    model.write_text(text[:text.index("[uncertain.k]")])
    out = tmp_path / "line"
    assert main(["validate", "--model", str(model), "--uncertain", "k,zeta", "--relative",
                 "0.2,0.2", "--sigmas", "0.5", "--orders", "1", "--horizons", "2",
                 "--samples", "64", "--max-samples", "128", "--quiet", "--outdir",
                 str(out)]) == 0, capsys.readouterr().err
    with xr.open_dataset(out / "validate.nc") as ds:
        assert ds.attrs["force_kind"] == "function" and ds.verdict.dims == ("variant", "scale")


def test_a_model_files_uncertain_tables_name_validates_parameters(tmp_path, capsys):
    """validate --model FILE with [uncertain.NAME] tables and no --uncertain: the file
    names the parameters and their laws; with several, the file's sigma_j / |p_bar_j| are
    the relative sizes, so scale 1 is the file's sigma (read back from the dataset)."""
    from pathlib import Path

    examples = Path(__file__).resolve().parents[3] / "docs" / "examples"
    out = tmp_path / "line"
    assert main(["validate", "--model", str(examples / "duffing-impact.toml"), "--sigmas",
                 "1", "--orders", "1", "--horizons", "2", "--samples", "64",
                 "--max-samples", "128", "--quiet", "--outdir", str(out)]) == 0
    err = capsys.readouterr().err
    assert "uncertain k,b (semicircle,uniform) from its [uncertain.NAME] tables" in err
    with xr.open_dataset(out / "validate.nc") as ds:
        assert ds.attrs["uncertain"] == "k,b"
        # the file: k = 1.0 with sigma 0.05, b = 0.2 with sigma 0.04 (uniform)
        np.testing.assert_allclose(ds.attrs["relative"], [0.05 / 1.0, 0.04 / 0.2])
    one = tmp_path / "one"
    assert main(["validate", "--model", str(examples / "shaw-holmes.toml"), "--values",
                 "2.5", "--sigmas", "0.01", "--orders", "0:1", "--horizons", "1",
                 "--samples", "64", "--max-samples", "128", "--no-frontier", "--no-plots",
                 "--quiet", "--outdir", str(one)]) == 0
    err = capsys.readouterr().err
    assert "uncertain zeta (uniform) from its [uncertain.zeta] table" in err
    with xr.open_dataset(one / "validate.nc") as ds:
        assert ds.attrs["uncertain"] == "zeta" and ds.attrs["distribution"] == "uniform"
