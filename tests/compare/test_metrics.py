"""compare_runs / error_metrics on synthetic datasets whose answers are known, and the
coefficients at t = 0 of real runs, where the truth is known exactly."""

import numpy as np
import pytest
import xarray as xr

import mc as mc_package
import opa as opa_package
from compare import compare_runs, error_metrics

OMEGA = 2.0
T = 2 * np.pi / OMEGA


def _pair(err, sem, *, n=3, per_period=4, periods=5, var_sem=0.1, coef_sem=0.1):
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
         "x_var_sem": ("time", np.full_like(t, var_sem)),
         "x_coef": (("order", "time"), coef[:2]),
         "x_coef_sem": (("order", "time"), np.full((2, t.size), coef_sem))},
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


def test_variance_and_coefficients_are_read_against_their_own_standard_errors():
    """err_var = 1 and err_coef = 0.5 everywhere: within the band z SE + floor exactly when
    the SE makes it wide enough; a NaN SE (Gauss quadrature) leaves the floor alone."""
    opa, mc, _ = _pair(lambda t: 0 * t, lambda t: 0 * t + 1, var_sem=0.4, coef_sem=0.1)
    cmp = compare_runs(opa, mc, z=3.0, floor=0.0)
    np.testing.assert_allclose(cmp.var_sem.values, 0.4)
    np.testing.assert_allclose(cmp.coef_sem.values, 0.1)
    assert cmp.coef_sem.dims == cmp.coef_within_noise.dims == ("order", "time")
    assert np.all(cmp.var_within_noise.values == 1)  # 1 <= 1.2
    assert np.all(cmp.coef_within_noise.values == 0)  # 0.5 > 0.3
    cmp = compare_runs(*_pair(lambda t: 0 * t, lambda t: 0 * t + 1, var_sem=0.3,
                              coef_sem=0.2)[:2], z=3.0, floor=0.0)  # fmt: skip
    assert np.all(cmp.var_within_noise.values == 0)  # 1 > 0.9
    assert np.all(cmp.coef_within_noise.values == 1)  # 0.5 <= 0.6
    # NaN standard errors are a quadrature's (docs/datasets.md), and said so by its sampler
    opa, mc, _ = _pair(lambda t: 0 * t, lambda t: 0 * t + 1, var_sem=np.nan, coef_sem=np.nan)
    cmp = compare_runs(opa, mc.assign_attrs(sampler="gauss"), z=3.0, floor=0.6)
    assert np.all(cmp.coef_within_noise.values == 1)  # 0.5 <= floor = 0.6
    assert np.all(cmp.var_within_noise.values == 0)  # 1 > floor


def test_an_mc_dataset_without_standard_errors_is_refused():
    opa, mc, _ = _pair(lambda t: 0 * t, lambda t: 0 * t + 1)
    with pytest.raises(ValueError, match=r"lacks the standard errors \['x_coef_sem'\]"):
        compare_runs(opa, mc.drop_vars("x_coef_sem"))


def test_coefficient_errors_at_t0_are_mc_noise():
    """Issue 15: at t = 0 every sample sits at x0 = -1, so E[x U_i] = 0 for i >= 1 and the
    OPA coefficients are exactly that; 256 random samples estimate x0 mean(U_i(xi)), off
    by up to 0.16. Read against x_coef_sem (~0.057 = |x0| sqrt(Var U_i / M) = 1/16) those
    errors are noise; against the floor alone they were flagged."""
    osc = opa_package.preset("3.2", omega=3.98)
    kwargs = dict(sigma=0.05, order=4, periods=2, per_period=4)
    ens = mc_package.simulate_mc(osc, samples=256, sampler="random", seed=0, progress=False,
                                 **kwargs)  # fmt: skip
    cmp = compare_runs(opa_package.simulate_opa(osc, **kwargs), ens)
    start = cmp.isel(time=0)
    np.testing.assert_array_equal(start.err_coef.values[1:], -ens.x_coef.values[1:, 0])
    assert np.abs(start.err_coef.values[1:]).max() > 0.1
    np.testing.assert_allclose(start.coef_sem.values[1:], 1 / 16, rtol=0.15)
    assert np.all(start.coef_within_noise.values[1:] == 1)
    assert np.all(np.abs(start.err_coef.values[1:]) > cmp.attrs["floor"])  # floor alone: out
    assert start.coef_within_noise.values[0] == 1 and start.within_noise.values == 1


def test_runs_of_several_parameters_are_compared_on_moments_and_shared_terms():
    """A single-element run of (mu, c) against its ensemble: err_mean is x_mean minus the
    ensemble's, and the coefficients are compared over the terms both carry (the run's
    order-2 set is the first 6 rows of the ensemble's order-4 set); a run on boxes is
    compared on its moments only."""
    system = opa_package.System(opa_package.preset("3.2"), uncertain="mu,c",
                                sigma=(0.016, 0.005), order=2)
    run = opa_package.simulate_opa(system, periods=4, per_period=4)
    ens = mc_package.simulate_mc(system.replace(order=4), samples=256, periods=4, per_period=4)
    cmp = compare_runs(run, ens)
    np.testing.assert_array_equal(cmp.err_mean.values, run.x_mean.values - ens.x_mean.values)
    assert cmp.err_coef.dims == ("term", "time") and cmp.sizes["term"] == 6
    np.testing.assert_array_equal(cmp.err_coef.values,
                                  run.x_coef.values - ens.x_coef.values[:6])
    boxes = opa_package.simulate_opa(system, periods=4, per_period=4, elements=2)
    assert compare_runs(boxes, ens).sizes["term"] == 0
    with pytest.raises(ValueError, match="sigma = 0.016,0.005 in the opa dataset"):
        compare_runs(run, mc_package.simulate_mc(system.replace(sigma=(0.016, 0.004)), samples=64,
                                         periods=4, per_period=4))
