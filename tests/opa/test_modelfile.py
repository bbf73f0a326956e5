"""The model file reader (opa._modelfile): a round trip to the objects the API builds, and
one ValueError line naming the path and the key or value for every fault of a file."""

from __future__ import annotations

import glob
import os

import numpy as np
import pytest

from opa import ForceLaw, Oscillator, Problem
from opa._modelfile import Model, read_model

DOCS = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "examples")

SHAW = """\
# Shaw & Holmes' linear impact oscillator
force = "-2*zeta*v - x"
[constants]
zeta = 0.05
[oscillator]
f = 1
omega = 2.5
eta = 0.8
F0 = 0.0
x0 = -0.5
[uncertain.zeta]
sigma = 0.01
distribution = "uniform"
"""


def write(tmp_path, text: str | bytes, name: str = "model.toml") -> str:
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return str(path)


def test_round_trip_gives_the_objects_of_the_api(tmp_path):
    model = read_model(write(tmp_path, SHAW))
    law = ForceLaw("-2*zeta*v - x", zeta=0.05)
    assert model.oscillator == Oscillator(force=law, f=1.0, omega=2.5, eta=0.8, F0=0.0,
                                          x0=-0.5)
    names = ("zeta", "eta", "delta", "f", "omega", "F0")  # the law's, the impact's, the drive's
    assert model.problem == Problem("zeta", 0.01, "uniform", coefficients=names)
    assert isinstance(model.oscillator.f, float)  # a TOML integer is a number too


def test_the_paper_law_and_an_empty_file(tmp_path):
    model = read_model(write(tmp_path, "[oscillator]\nomega = 4.0\n[uncertain.c]\n"
                                       "sigma = 0.005\n[uncertain.mu]\nsigma = 0.01\n"))
    assert model.oscillator == Oscillator(omega=4.0) and model.oscillator.force is None
    assert model.problem.names == ("c", "mu") and model.problem.scales == (0.005, 0.01)
    assert read_model(write(tmp_path, "")) == Model(Oscillator(), None,
                                                    str(tmp_path / "model.toml"))


def test_a_law_may_name_the_oscillators_own_coefficients(tmp_path):
    model = read_model(write(tmp_path, 'force = "mu*(1 - x^2)*v - x"\n[oscillator]\n'
                                       'mu = 0.3\n[uncertain.mu]\nsigma = 0.05\n'))
    assert model.oscillator.coefficient_names == ("mu",) and model.oscillator.mu == 0.3
    assert model.problem.names == ("mu",)


@pytest.mark.parametrize("path", sorted(glob.glob(os.path.join(DOCS, "*.toml"))))
def test_the_docs_examples_read_and_the_refused_ones_are_refused(path):
    if os.path.basename(path).startswith("refused-"):
        with pytest.raises(ValueError, match="force law"):
            read_model(path)
    else:
        assert read_model(path).oscillator.force is not None


def test_a_function_beside_the_file_is_the_same_law_as_its_expression():
    """``function = "contact:hertz"`` imports docs/examples/contact.py; the runs equal
    those of the same law written as an expression."""
    import opa

    by_function = read_model(os.path.join(DOCS, "hertz-function.toml")).oscillator
    by_expression = read_model(os.path.join(DOCS, "hertz-contact.toml")).oscillator
    assert by_function.force.kind == "function" and by_expression.force.kind == "compiled"
    assert by_function.force.expression == "contact:hertz"
    a, b = (opa.simulate_dmr(o, periods=5, per_period=8) for o in (by_function, by_expression))
    assert int(a.impact_time.count()) > 2
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-13)


BAD = [
    ("colour = 1\n", "'colour'"),
    ("force = 3\n", "force"),
    ('force = "foo(x)"\n', "foo(x)"),
    ('force = "x.real"\n', "x.real"),
    ('function = "contact"\n', "module:name"),
    ('function = 3\n', "module:name"),
    ('function = "no_such_module_xyz:g"\n', "cannot be imported"),
    ('function = "math:pi"\n', "not a function"),
    ('function = "math:hypot"\n', "no signature"),
    ('function = "os.path:join"\n', "g(x, v, constant, ...)"),
    ('force = "-x"\nfunction = "math:hypot"\n', "not both"),
    ('force = "-k*x"\n', "'k'"),  # a constant with no value
    ('force = "-x"\n[constants]\nk = 1.0\n', "'k'"),  # a constant the law does not use
    ('force = "-k*x"\n[constants]\nk = "1"\n', "[constants] k"),
    ('force = "-k*x"\n[constants]\nk = true\n', "[constants] k"),
    ("[constants]\nk = 1.0\n", "[constants]"),
    ('constants = 3\nforce = "-x"\n', "[constants]"),
    ("oscillator = 3\n", "[oscillator]"),
    ("[oscillator]\nzeta = 0.1\n", "'zeta'"),
    ("[oscillator]\nforce = '-x'\n", "'force'"),
    ("[oscillator]\nomega = '2'\n", "[oscillator] omega"),
    ("[oscillator]\neta = 1.5\n", "eta"),
    ("[oscillator]\nx0 = 1.0\n", "x0"),
    ("[oscillator]\nomega = nan\n", "omega"),
    ('force = "-x"\n[oscillator]\nmu = 0.3\n', "[oscillator] mu"),  # no effect
    ('force = "-k*x"\n[constants]\nk = 1.0\n[uncertain.mu]\nsigma = 0.1\n', "'mu'"),
    ("[uncertain.zeta]\nsigma = 0.1\n", "'zeta'"),
    ("[uncertain.mu]\ndistribution = 'uniform'\n", "sigma"),
    ("[uncertain.mu]\nsigma = -0.1\n", "sigma"),
    ("[uncertain.mu]\nsigma = 0.1\ncolour = 1\n", "'colour'"),
    ("[uncertain.mu]\nsigma = 0.1\ndistribution = 'cauchy'\n", "cauchy"),
    ("uncertain = 3\n", "[uncertain]"),
    ("[uncertain]\n", "no uncertain parameter"),
    ("[oscillator]\nmu = 0.005\n[uncertain.mu]\nsigma = 0.01\n", "allow_negative"),
    ("force = \n", "TOML"),
]


@pytest.mark.parametrize("text,named", BAD, ids=[t for t, _ in BAD])
def test_every_fault_is_one_line_naming_the_path_and_the_key(tmp_path, text, named):
    path = write(tmp_path, text)
    with pytest.raises(ValueError) as info:
        read_model(path)
    message = str(info.value)
    assert "\n" not in message and path in message and named in message, message


def test_unreadable_and_binary_files_are_named(tmp_path):
    for path in (str(tmp_path / "missing.toml"), str(tmp_path),
                 write(tmp_path, bytes(range(256)), "binary.toml")):
        with pytest.raises(ValueError, match="model file") as info:
            read_model(path)
        assert path in str(info.value) and "\n" not in str(info.value)


def test_a_lower_wall_in_the_file(tmp_path):
    """delta_minus and eta_minus in [oscillator] give the oscillator its lower wall; a
    lower wall above the upper one is refused in one line naming it."""
    here = os.path.dirname(os.path.abspath(__file__))
    model = read_model(os.path.join(here, "..", "..", "docs", "examples", "gear-pair.toml"))
    assert (model.oscillator.delta_minus, model.oscillator.eta_minus) == (-0.8, 0.7)
    assert model.oscillator.two_walls and model.oscillator.delta == 0.5
    path = tmp_path / "bad.toml"
    path.write_text("[oscillator]\ndelta = 0.5\ndelta_minus = 0.6\nx0 = 0.0\n")
    with pytest.raises(ValueError) as err:
        read_model(path)
    assert "delta_minus" in str(err.value) and "\n" not in str(err.value)
