"""compare_runs / error_metrics on synthetic datasets whose answers are known."""

import numpy as np
import pytest
import xarray as xr

from compare import compare_runs, error_metrics

OMEGA = 2.0
T = 2 * np.pi / OMEGA


def _pair(err, sem, *, n=3, per_period=4, periods=5):
    t = np.arange(periods * per_period + 1) * T / per_period
    base = np.sin(t)
    coef = np.vstack([base] + [np.full_like(t, 0.1 * i) for i in range(1, n)])
    opa = xr.Dataset(
        {"x_mean": ("time", base + err(t)), "x_var": ("time", np.full_like(t, 2.0)),
         "x_coef": (("order", "time"), coef + 0.5)},
        coords={"time": t}, attrs={"omega": OMEGA},
    )
    mc = xr.Dataset(
        {"x_mean": ("time", base), "x_sem": ("time", sem(t)), "x_var": ("time", np.ones_like(t)),
         "x_coef": (("order", "time"), coef[:2])},
        coords={"time": t}, attrs={"omega": OMEGA},
    )
    return opa, mc, t


def test_constant_error_gives_known_metrics():
    opa, mc, t = _pair(lambda t: np.full_like(t, 1e-3), lambda t: np.full_like(t, 1e-4))
    cmp = compare_runs(opa, mc, z=3.0, floor=0.0)
    m = error_metrics(cmp)
    assert m["rms_error"] == pytest.approx(1e-3)
    assert m["max_error"] == pytest.approx(1e-3)
    assert m["strobe_rms_error"] == pytest.approx(1e-3)
    assert m["sem_rms"] == pytest.approx(1e-4)
    assert m["var_rms_error"] == pytest.approx(1.0)
    # 1e-3 > 3 * 1e-4 from the first output on
    assert m["agree_periods"] == 0.0
    # coefficients: only the orders both datasets carry, each off by 0.5
    assert cmp.sizes["order"] == 2
    np.testing.assert_allclose(cmp.err_coef.values, 0.5)


def test_agreement_time_is_the_first_output_outside_the_band():
    # error grows linearly in time; band 3 * 1e-3: leaves it when t/T > 3 (first output after)
    opa, mc, t = _pair(lambda t: 1e-3 * t / T, lambda t: np.full_like(t, 1e-3))
    m = error_metrics(compare_runs(opa, mc, z=3.0, floor=0.0))
    first_out = t[np.flatnonzero(1e-3 * t / T > 3e-3)[0]] / T
    assert m["agree_periods"] == pytest.approx(first_out)
    assert m["agree_periods"] == pytest.approx(3.25)


def test_window_and_strobe_points():
    # error only at non-stroboscopic outputs after period 2
    def err(t):
        phase = t / T
        on_strobe = np.abs(phase - np.round(phase)) < 1e-9
        return np.where((phase > 2) & ~on_strobe, 1.0, 0.0)

    opa, mc, t = _pair(err, lambda t: np.full_like(t, 1.0))
    cmp = compare_runs(opa, mc)
    early = error_metrics(cmp, window_periods=2)
    assert early["rms_error"] == 0.0 and early["max_error"] == 0.0
    full = error_metrics(cmp)
    assert full["strobe_rms_error"] == 0.0
    assert full["max_error"] == 1.0
    n_bad = np.count_nonzero(err(t))
    assert full["rms_error"] == pytest.approx(np.sqrt(n_bad / t.size))
    assert full["agree_periods"] == np.inf  # 1.0 <= 3 * 1.0 everywhere


def test_grids_must_match():
    opa, mc, _ = _pair(lambda t: 0 * t, lambda t: 0 * t + 1)
    with pytest.raises(ValueError, match="time grid"):
        compare_runs(opa.isel(time=slice(0, -1)), mc)
