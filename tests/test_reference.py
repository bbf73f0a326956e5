"""Self-checks of the scipy reference (tests/reference.py) against closed-form solutions
(``tests/truths.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.reference import reference_final_state, reference_trajectory
from tests.truths import (
    accumulation_time,
    bouncing_sequence,
    impulse_size,
    kick_at_rest_on_the_wall,
    kicked_linear_oscillator,
    linear_oscillator,
    pulsed_linear_oscillator,
)

NO_WALL = dict(mu=0.0, c=0.0, eta=0.8, delta=1e9)
SLOW_IMPULSES = dict(a1=1.0, omega1=1.0, n=2)


def test_linear_oscillator_without_wall():
    t = np.linspace(0.0, 20.0, 401)
    model = dict(a=1.3, f=2.0, omega=2.8, F0=0.0, x0=-1.0, v0=0.4, **NO_WALL, **SLOW_IMPULSES)
    out = reference_trajectory(t_out=t, **model)
    x, v = linear_oscillator(t, 1.3, 2.0, 2.8, -1.0, 0.4)
    np.testing.assert_allclose(out["x"], x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["v"], v, rtol=0, atol=1e-9)
    assert out["impact_time"].shape == out["impact_velocity"].shape == (0,)


@pytest.mark.parametrize("impulse_at_zero", [True, False])
def test_dirac_impulses_by_superposition(impulse_at_zero):
    a, F0 = 0.7, 0.3
    t = np.linspace(0.0, 4 * 2 * np.pi, 801)  # contains every t_j = 2 pi j exactly
    model = dict(a=a, f=1.5, omega=2.0, F0=F0, x0=-0.5, v0=0.0, **NO_WALL, **SLOW_IMPULSES)
    out = reference_trajectory(t_out=t, impulse_at_zero=impulse_at_zero, **model)
    kicks = [(t_j, impulse_size(t_j, F0, **SLOW_IMPULSES))
             for t_j in 2 * np.pi * np.arange(0 if impulse_at_zero else 1, 5)]
    x, v = kicked_linear_oscillator(t, a, 1.5, 2.0, -0.5, 0.0, kicks)
    np.testing.assert_allclose(out["x"], x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["v"], v, rtol=0, atol=1e-9)
    # Outputs are right-continuous: at t = 0 the first kick is already in.
    first = impulse_size(0.0, F0, **SLOW_IMPULSES)
    assert out["v"][0] == pytest.approx(first if impulse_at_zero else 0.0)


def test_rectangular_pulses_by_superposition():
    a, F0, tau = 0.7, 0.3, 0.25
    t = np.linspace(0.0, 3 * 2 * np.pi, 601)
    model = dict(a=a, f=0.0, omega=2.0, F0=F0, x0=0.0, v0=0.0, **NO_WALL, **SLOW_IMPULSES)
    out = reference_trajectory(t_out=t, impulse="pulse", tau=tau, **model)
    pulses = [(t_j, impulse_size(t_j, F0, **SLOW_IMPULSES)) for t_j in 2 * np.pi * np.arange(0, 4)]
    x, v = pulsed_linear_oscillator(t, a, 0.0, 2.0, 0.0, 0.0, pulses, tau)
    np.testing.assert_allclose(out["x"], x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["v"], v, rtol=0, atol=1e-9)


FREE_MASS = dict(mu=0.0, a=0.0, c=0.0, f=0.0, omega=1.0, F0=0.0, **SLOW_IMPULSES)


def test_free_mass_bounces_once():
    t = np.array([0.0, 0.5, 1.0, 2.0, 3.0, 10.0])
    out = reference_trajectory(eta=0.5, delta=0.0, x0=-1.0, v0=1.0, t_out=t, **FREE_MASS)
    np.testing.assert_allclose(out["impact_time"], [1.0], atol=1e-12)
    np.testing.assert_allclose(out["impact_velocity"], [1.0], atol=1e-12)
    expected_x = np.where(t < 1.0, -1.0 + t, -0.5 * (t - 1.0))
    np.testing.assert_allclose(out["x"], expected_x, atol=1e-12)
    np.testing.assert_allclose(out["v"], np.where(t < 1.0, 1.0, -0.5), atol=1e-12)


def test_kick_at_the_wall_is_an_impact():
    """Resting on the wall, the kick at t = 0 pushes into it and bounces straight back."""
    model = {**FREE_MASS, "F0": 1.0, "a1": 0.0}
    t = np.array([0.0, 2.0, 5.0])
    out = reference_trajectory(eta=0.8, delta=0.0, x0=0.0, v0=0.0, t_out=t, **model)
    np.testing.assert_allclose(out["impact_time"], [0.0])
    np.testing.assert_allclose(out["impact_velocity"], [1.0])
    np.testing.assert_allclose(out["x"], kick_at_rest_on_the_wall(1.0, 0.8) * t, atol=1e-12)


def test_bouncing_under_constant_force():
    g, h, eta = 2.0, 1.0, 0.6  # omega = 0 turns f cos(omega t) into a constant force g
    model = {**FREE_MASS, "f": g, "omega": 0.0}
    times, speeds = bouncing_sequence(g, h, eta, 8)
    t_end = 0.5 * (times[7] + times[6])
    out = reference_trajectory(eta=eta, delta=0.0, x0=-h, v0=0.0, t_out=[0.0, t_end], **model)
    np.testing.assert_allclose(out["impact_time"], times[:7], rtol=0, atol=1e-10)
    np.testing.assert_allclose(out["impact_velocity"], speeds[:7], rtol=1e-9)


def test_chatter_raises_instead_of_hanging():
    g, h, eta = 2.0, 1.0, 0.6
    model = {**FREE_MASS, "f": g, "omega": 0.0}
    accumulation = accumulation_time(g, h, eta)
    with pytest.raises(RuntimeError, match="impacts"):
        reference_trajectory(
            eta=eta, delta=0.0, x0=-h, v0=0.0, t_out=[0.0, accumulation + 1.0],
            max_impacts=200, **model,
        )  # fmt: skip


def test_impacting_van_der_pol_stays_behind_the_wall():
    model = dict(
        mu=0.8, a=0.5, c=0.05, f=1.5, omega=4.0, eta=0.8, delta=0.0, F0=0.1, a1=1.0,
        omega1=1.0, n=2, x0=-1.0, v0=0.0,
    )  # fmt: skip
    t = np.linspace(0.0, 40.0, 4001)
    out = reference_trajectory(t_out=t, **model)
    assert out["impact_time"].size > 5
    assert np.all(out["impact_velocity"] > 0)
    assert np.all(np.diff(out["impact_time"]) > 0)
    assert out["x"].max() <= 1e-10
    x_end, v_end = reference_final_state(40.0, **model)
    assert (x_end, v_end) == (out["x"][-1], out["v"][-1])


def test_rejects_bad_arguments():
    model = dict(mu=0.0, a=1.0, c=0.0, f=0.0, omega=1.0, eta=0.8, delta=0.0, F0=0.0,
                 a1=1.0, omega1=1.0, n=2, v0=0.0)  # fmt: skip
    with pytest.raises(ValueError, match="impulse"):
        reference_trajectory(x0=-1.0, t_out=[0.0, 1.0], impulse="step", **model)
    with pytest.raises(ValueError, match="x0"):
        reference_trajectory(x0=0.5, t_out=[0.0, 1.0], **model)
    with pytest.raises(ValueError, match="t_out"):
        reference_trajectory(x0=-1.0, t_out=[1.0, 2.0], **model)
