"""End to end: a tiny validation, its netCDF round trip, report and figures, and the CLI."""

import os
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from compare import load_config, run_validation, write_report
from opa import write_netcdf

TINY = dict(sigmas=(0.01, 0.02), orders=(0, 1, 2), samples=64, periods=4, per_period=4,
            window=2, study_samples=(16, 32), study_nodes=(2, 4))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("validate")
    cfg = load_config(None, outdir=str(out), **TINY)
    ds = run_validation(cfg, progress=False, log=lambda *a: None)
    return cfg, ds, out


def test_validation_dataset_contract(tiny):
    cfg, ds, out = tiny
    assert set(ds.sigma.values) == {0.01, 0.02}
    assert list(ds.N.values) == [0, 1, 2]
    assert ds.rms_error_window.dims == ("sigma", "variant", "N")
    assert np.all(np.isfinite(ds.rms_error_window.values))
    # x_mean of OPA at N = 0 is the DMR for every sigma; MC differs by O(sigma^2)
    assert ds.attrs["N"] == 2 and ds.attrs["samples"] == 64
    for name in ("mu", "a", "c", "f", "omega", "eta", "delta", "F0", "rtol", "atol", "seed",
                 "sampler", "impulse", "truncation", "impact_law", "Conventions", "history"):
        assert name in ds.attrs, name
    assert os.path.exists(out / "validate.nc")
    # the MC part was written as it finished and is reused on a rerun
    parts = os.listdir(out / "parts")
    assert len(parts) == 2


def test_netcdf_round_trip_is_identical(tiny, tmp_path):
    _, ds, _ = tiny
    path = tmp_path / "v.nc"
    write_netcdf(ds, path)
    with xr.open_dataset(path) as back:
        back = back.load()
    xr.testing.assert_identical(ds, back)


def test_resume_reuses_finished_parts(tiny):
    cfg, ds, out = tiny
    stamp = {p: os.path.getmtime(out / "parts" / p) for p in os.listdir(out / "parts")}
    again = run_validation(cfg, progress=False, log=lambda *a: None)
    assert {p: os.path.getmtime(out / "parts" / p) for p in os.listdir(out / "parts")} == stamp
    np.testing.assert_array_equal(again.mc_x_mean.values, ds.mc_x_mean.values)


def test_report_and_figures(tiny):
    cfg, ds, out = tiny
    written = write_report(ds, str(out))
    names = {os.path.basename(p) for p in written}
    assert {"summary.md", "error_vs_N.png", "mean_vs_mc.png", "variance.png", "phase.png",
            "cost.png"} <= names
    for p in written:
        assert os.path.getsize(p) > 2000, p
    text = (out / "summary.md").read_text()
    assert "| σ | N |" in text and "## Findings" in text


def test_cli_bad_input_gets_one_clear_line(tmp_path):
    for args, needle in ((["--eta", "1.5"], "eta must be in (0, 1], got 1.5"),
                         (["--sigmas", "-0.1"], "sigmas must be non-negative"),
                         (["--config", str(tmp_path / "missing.toml")], "config file not found")):
        proc = subprocess.run([sys.executable, "-m", "opa._cli", "validate", *args,
                               "--outdir", str(tmp_path)], capture_output=True, text=True)
        assert proc.returncode == 2, proc.stderr
        assert needle in proc.stderr
        assert "Traceback" not in proc.stderr


def test_toml_config(tmp_path):
    cfg_file = tmp_path / "v.toml"
    cfg_file.write_text('sigmas = [0.03]\norders = [0, 4]\n[model]\nomega = 4.2\n'
                        '[solver]\nrtol = 1e-8\n')
    cfg = load_config(str(cfg_file), samples=128)
    assert cfg.sigmas == (0.03,) and cfg.orders == (0, 4) and cfg.samples == 128
    assert cfg.oscillator.omega == 4.2 and cfg.oscillator.a == 0.5
    assert cfg.options.rtol == 1e-8
    cfg_file.write_text("bogus = 1\n")
    with pytest.raises(ValueError, match="unknown config key"):
        load_config(str(cfg_file))
