"""Tests for ``opa._model``: parameters, presets and the validation of bad input.

README, 'Errors, limits and resuming': every invalid parameter gets one ``ValueError`` whose
message names the parameter and quotes the value received
(``"eta must be in (0, 1], got 1.3"``). The checks that live at the ``simulate_*`` boundary
(pulse width against the impulse period, the order N, the output grid) are tested here too,
since they are the same contract.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from opa import (
    Oscillator,
    SolverOptions,
    System,
    Uncertainty,
    preset,
    simulate_dmr,
    simulate_opa,
    time_grid,
)
from opa._model import PARAMETER_NAMES, PRESETS


def names_parameter_and_value(name: str, value) -> str:
    """A regex that needs ``name`` and then ``value`` (as str or repr) in the message."""
    shown = "|".join(re.escape(s) for s in {str(value), repr(value)})
    return rf"(?s)\b{re.escape(name)}\b.*({shown})"


# --------------------------------------------------------------------------- defaults


def test_defaults_are_the_section_32_set_with_the_paper_impulse_train():
    osc = Oscillator()
    assert osc.as_dict() == dict(
        mu=0.8, a=0.5, c=0.05, f=1.5, omega=3.98, eta=0.8, delta=0.0,
        F0=0.1, a1=1.0, omega1=1.0, n=2.0, x0=-1.0, v0=0.0,
    )  # fmt: skip
    assert tuple(osc.as_dict()) == PARAMETER_NAMES
    assert osc.forcing_period == pytest.approx(2 * math.pi / 3.98, rel=1e-15)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_hold_the_paper_values_and_accept_changes(name):
    osc = preset(name, x0=-0.5)
    for key, value in PRESETS[name].items():
        assert getattr(osc, key) == value
    assert osc.x0 == -0.5


def test_section_33_leaves_c_open_and_we_document_our_choice():
    assert preset("3.3").c == 0.05
    assert (preset("3.3").a, preset("3.3").f) == (3.5, 3.5)


def test_oscillator_is_frozen_and_replace_validates_again():
    osc = Oscillator()
    with pytest.raises(dataclasses.FrozenInstanceError):
        osc.mu = 1.0  # type: ignore[misc]
    assert osc.replace(mu=0.3).mu == 0.3
    with pytest.raises(ValueError, match=names_parameter_and_value("eta", 2.0)):
        osc.replace(eta=2.0)


def test_numbers_are_stored_as_floats():
    osc = Oscillator(mu=1, n=4, x0=np.float32(-0.5))
    assert all(type(v) is float for v in osc.as_dict().values())


# --------------------------------------------------------------------------- Oscillator


@pytest.mark.parametrize("eta", [0.0, -0.1, 1.0 + 1e-12, 1.3, 7.0])
def test_eta_outside_the_unit_interval_is_refused(eta):
    with pytest.raises(ValueError, match=names_parameter_and_value("eta", float(eta))):
        Oscillator(eta=eta)


@pytest.mark.parametrize("eta", [1e-9, 0.5, 1.0])
def test_eta_inside_the_unit_interval_is_accepted(eta):
    assert Oscillator(eta=eta).eta == eta


@pytest.mark.parametrize("name", PARAMETER_NAMES)
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_values_are_refused_by_name(name, value):
    with pytest.raises(ValueError, match=names_parameter_and_value(name, value)):
        Oscillator(**{name: value})


@pytest.mark.parametrize("value", ["abc", None, [1.0], 1 + 2j])
def test_non_numbers_are_refused_by_name(value):
    with pytest.raises(ValueError, match=names_parameter_and_value("c", value)):
        Oscillator(c=value)


@pytest.mark.parametrize(("x0", "delta"), [(0.5, 0.0), (1e-12, 0.0), (2.0, 1.5)])
def test_initial_state_beyond_the_wall_is_refused(x0, delta):
    with pytest.raises(ValueError, match=names_parameter_and_value("x0", float(x0))):
        Oscillator(x0=x0, delta=delta)


def test_initial_state_on_the_wall_moving_into_it_is_refused():
    with pytest.raises(ValueError, match=names_parameter_and_value("v0", 0.25)):
        Oscillator(x0=0.0, delta=0.0, v0=0.25)
    assert Oscillator(x0=0.0, delta=0.0, v0=-0.25).v0 == -0.25


@pytest.mark.parametrize(("name", "value"), [("omega", 0.0), ("omega", -2.8), ("omega1", 0.0),
                                             ("omega1", -1.0), ("n", 0.0)])
def test_frequencies_must_be_positive_and_n_non_zero(name, value):
    with pytest.raises(ValueError, match=names_parameter_and_value(name, value)):
        Oscillator(**{name: value})


def test_unknown_preset_is_refused():
    with pytest.raises(ValueError, match=names_parameter_and_value("preset", "3.9")):
        preset("3.9")


def test_unknown_parameter_is_refused():
    with pytest.raises(TypeError, match="sigma"):
        Oscillator(sigma=0.1)  # type: ignore[call-arg]


# --------------------------------------------------------------------------- SolverOptions


def test_solver_option_defaults():
    opts = SolverOptions()
    assert (opts.rtol, opts.atol, opts.method) == (1e-10, 1e-10, "dop853")
    assert opts.max_step == math.inf and opts.chatter_velocity == 1e-6
    # numerics only: the impulse model is the System's (tests/opa/test_system.py)
    assert "impulse" not in {f.name for f in dataclasses.fields(SolverOptions)}
    assert opts.impulse is None and opts.legacy_impulse == {}


@pytest.mark.parametrize("name", ["rtol", "atol"])
@pytest.mark.parametrize("value", [0.0, -1e-8, 1e-16, 1.0, 2.0, math.nan, math.inf])
def test_tolerances_out_of_range_are_refused(name, value):
    with pytest.raises(ValueError, match=names_parameter_and_value(name, value)):
        SolverOptions(**{name: value})


@pytest.mark.parametrize(("name", "value"), [
    ("chatter_velocity", -1e-6), ("chatter_velocity", math.nan),
    ("max_step", 0.0), ("max_step", -1.0), ("max_step", math.nan), ("max_steps", 0),
    ("max_steps", -5),
])  # fmt: skip
def test_bad_solver_numbers_are_refused_by_name(name, value):
    with pytest.raises(ValueError, match=names_parameter_and_value(name, value)):
        SolverOptions(**{name: value})


@pytest.mark.parametrize("value", [math.nan, "abc", 1.5])
def test_max_steps_must_be_a_whole_number_named_in_the_message(value):
    with pytest.raises(ValueError, match=names_parameter_and_value("max_steps", value)):
        SolverOptions(max_steps=value)


@pytest.mark.parametrize("name", ["rtol", "atol", "max_step"])
def test_solver_numbers_are_stored_as_floats(name):
    import numpy as np

    opts = SolverOptions(**{name: np.float32(0.25)})
    assert type(getattr(opts, name)) is float and getattr(opts, name) == 0.25


@pytest.mark.parametrize("name", ["rtol", "atol", "max_step"])
@pytest.mark.parametrize("value", ["0.01", True])
def test_solver_numbers_refuse_strings_and_bools(name, value):
    with pytest.raises(ValueError, match=name):
        SolverOptions(**{name: value})


def test_pulse_width_must_be_shorter_than_the_impulse_period():
    T1 = 2 * math.pi  # omega1 = 1
    with pytest.raises(ValueError, match=names_parameter_and_value("pulse_width", T1 + 0.5)):
        simulate_dmr(Oscillator(), periods=1, impulse="pulse", pulse_width=T1 + 0.5)
    # the same width is fine for Dirac impulses, where it plays no role
    simulate_dmr(Oscillator(), periods=1, pulse_width=T1 + 0.5)


# --------------------------------------------------------------------------- Uncertainty


@pytest.mark.parametrize("sigma", [-1e-3, -0.1, -math.inf, math.nan, math.inf])
def test_negative_or_non_finite_sigma_is_refused(sigma):
    with pytest.raises(ValueError, match=names_parameter_and_value("sigma", sigma)):
        Uncertainty(sigma)


@pytest.mark.parametrize("parameter", ["x0", "omega1", "", "x-y"])
def test_unknown_uncertain_parameter_is_refused(parameter):
    with pytest.raises(ValueError, match=names_parameter_and_value("uncertain", parameter)):
        Uncertainty(0.1, parameter)


def test_a_name_that_is_no_coefficient_of_the_law_is_refused_by_the_system():
    """``Uncertainty`` cannot know a user's force law's constants; the System can."""
    assert Uncertainty(0.1, "MU").parameter == "MU"
    with pytest.raises(ValueError, match="among mu, a, c.*got 'MU'"):
        System(sigma=0.1, uncertain="MU")


@pytest.mark.parametrize("parameter", ["mu", "a", "c"])
def test_uncertain_parameter_may_be_mu_a_or_c(parameter):
    assert Uncertainty(0.01, parameter).parameter == parameter


def test_sigma_that_makes_samples_negative_needs_consent():
    """The bound production uses (System.check_samples, called by simulate_opa and
    simulate_mc): p_bar + sigma * (lowest xi of the law) < 0 is refused unless allowed."""
    osc = Oscillator(mu=0.8)
    with pytest.raises(ValueError, match=r"sigma = 0\.9.*mu = 0\.8"):
        simulate_opa(osc, sigma=0.9, order=1, periods=1)
    System(osc, sigma=0.9, allow_negative=True).check_samples()
    System(osc, sigma=0.8).check_samples()  # mu_bar - sigma = 0 is allowed
    with pytest.raises(ValueError, match=r"sigma = 0\.9.*c = 0\.05"):
        simulate_opa(osc, sigma=0.9, uncertain="c", order=1, periods=1)


def test_simulate_opa_refuses_bad_choices_by_name():
    osc = Oscillator()
    for kwargs, name, value in [
        (dict(order=-1), "order", -1), (dict(order=1.5), "order", 1.5),
        (dict(order=True), "order", True), (dict(truncation="exact"), "truncation", "exact"),
        (dict(impact_law="all"), "impact_law", "all"), (dict(sigma=-0.1), "sigma", -0.1),
        (dict(uncertain="omega1"), "uncertain", "omega1"),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match=names_parameter_and_value(name, value)):
            simulate_opa(osc, periods=1, **kwargs)


# --------------------------------------------------------------------------- output grid


def test_time_grid_is_the_stroboscopic_grid():
    t = time_grid(2.0, 3, 4)
    np.testing.assert_allclose(t, np.arange(13) * (math.pi / 4), rtol=0, atol=1e-15)


@pytest.mark.parametrize(("kwargs", "name", "value"), [
    (dict(periods=0), "periods", 0.0), (dict(periods=-3), "periods", -3.0),
    (dict(periods=math.nan), "periods", math.nan), (dict(per_period=0), "per_period", 0),
    (dict(per_period=2.5), "per_period", 2.5),
])  # fmt: skip
def test_bad_output_grid_is_refused_by_name(kwargs, name, value):
    with pytest.raises(ValueError, match=names_parameter_and_value(name, value)):
        simulate_dmr(Oscillator(), **kwargs)


@pytest.mark.parametrize("times", [[0.0, 2.0, 1.0], [0.0, 1.0, 1.0], [0.0, math.nan], [],
                                   [[0.0, 1.0]]])
def test_bad_explicit_times_are_refused(times):
    with pytest.raises(ValueError, match="times"):
        simulate_dmr(Oscillator(), times=times)


@pytest.mark.parametrize("value", [True, np.bool_(True), np.array(True), np.array([0.8]),
                                   "0.8", b"0.8", None, [0.8]])
def test_a_parameter_refuses_bools_of_every_kind_strings_and_arrays(value):
    with pytest.raises(ValueError, match="mu must be a real number"):
        Oscillator(mu=value)


def test_a_parameter_takes_numpy_scalars_and_0d_float_arrays():
    assert Oscillator(mu=np.float64(0.8)).mu == Oscillator(mu=np.array(0.8)).mu == 0.8
