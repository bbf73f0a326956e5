"""Fixtures shared by the tests of compare."""

import pytest
import xarray as xr


@pytest.fixture(scope="session")
def smallest_trust_map(tmp_path_factory) -> xr.Dataset:
    """The smallest trust map (docs/datasets.md's example): one omega, sigma 0.01 and
    0.03, N = 0 and 1, 2 periods at 4 outputs per period, read back into memory. Computed
    once per session; take a copy before changing it."""
    from compare import load_config, run_validation

    out = tmp_path_factory.mktemp("map")
    cfg = load_config(None, values=(3.98,), sigmas=(0.01, 0.03), orders=(0, 1),
                      horizons=(2,), samples=64, max_samples=64, per_period=4,
                      frontier=False, plots=False, outdir=str(out))
    run_validation(cfg, progress=False, log=lambda *a: None)
    with xr.open_dataset(out / "validate.nc") as ds:
        return ds.load()
