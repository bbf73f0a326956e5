r"""A model file: the oscillator (force law, constants, parameters) and its uncertain
parameters as one TOML file (``opa-mc COMMAND --model FILE.toml``).

The format, every part optional::

    # Shaw & Holmes' linear impact oscillator
    force = "-2*zeta*v - x"     # g(x, v) in x'' = g + f cos(omega t) + impulses
                                # (opa.ForceLaw; left out: the paper's law, eq. (1));
                                # or function = "module:name", a Python function
                                # g(x, v, zeta) in module.py beside the file
    [constants]                 # the law's named constants (only with force)
    zeta = 0.05

    [oscillator]                # any of opa.Oscillator's fields: mu a c f omega eta
    f = 1.0                     #   delta F0 a1 omega1 n x0 v0, and delta_minus eta_minus
    omega = 2.5                 # the others keep Oscillator's defaults (the paper's
    eta = 0.8                   # section 3.2 set: F0 = 0.1 gives an impulse train,
    F0 = 0.0                    # F0 = 0 none)
    x0 = -0.5

    [uncertain.zeta]            # the uncertain parameters, one table each, in order:
    sigma = 0.01                # the tables of --problem FILE.toml (opa.Problem);
    distribution = "uniform"    # allow_negative = true under [uncertain]

``delta_minus`` (< delta) adds a lower wall, with the restitution ``eta_minus`` (eta when
left out): the motion is then delta_minus < x < delta (a gear pair's backlash). With a
user's force law, ``mu``, ``a`` and ``c`` are fields of [oscillator] only where the
law names them (elsewhere they would have no effect, and are refused). Numbers are TOML
numbers (``1`` or ``1.0``), never strings or booleans. Every fault of a file is one
``ValueError`` line naming the path and the key or value: an unreadable file, one that is
not TOML, an unknown key, a wrong type, a bad expression (``opa.ForceLaw``'s message), a
constant with no value, a value the oscillator refuses.

>>> import tempfile, pathlib
>>> text = 'force = "-2*zeta*v - x"\n[constants]\nzeta = 0.05\n[oscillator]\nF0 = 0.0\n'
>>> with tempfile.TemporaryDirectory() as folder:
...     path = pathlib.Path(folder) / "shaw.toml"
...     _ = path.write_text(text)
...     model = read_model(path)
>>> model.oscillator.force.expression, model.oscillator.value("zeta"), model.problem
('-2*zeta*v - x', 0.05, None)
"""

from __future__ import annotations

from dataclasses import dataclass

from opa._forcelaw import OSCILLATOR_COEFFICIENTS, ForceLaw
from opa._model import PARAMETER_NAMES, Oscillator, _finite
from opa._problem import Problem

#: the top-level keys and tables of a model file
KEYS = ("force", "function", "constants", "oscillator", "uncertain")
#: the keys of [oscillator]: every parameter, and a lower wall's delta_minus, eta_minus
OSCILLATOR_KEYS = PARAMETER_NAMES + ("delta_minus", "eta_minus")


@dataclass(frozen=True)
class Model:
    """What a model file gives: the oscillator and, where the file has [uncertain.*]
    tables, the :class:`opa.Problem` of its uncertain parameters (else None)."""

    oscillator: Oscillator
    problem: Problem | None = None
    path: str = ""


def _number(where: str, value) -> float:
    """A TOML number (int or float, not a bool or a string) as a finite float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where} must be a number, got {value!r:.40}")
    return _finite(where, value)


def _table(where: str, value) -> dict:
    if not isinstance(value, dict):
        raise ValueError(f"{where} must be a table, got {value!r:.40}")
    return value


def _function_law(where: str, reference, values: dict, folder: str) -> ForceLaw:
    """The law of ``function = "module:name"``: a Python function g(x, v, constant, ...)
    imported from ``module``, looked for first in the model file's own folder."""
    import sys

    from opa._forcefunction import imported_function

    if not isinstance(reference, str) or ":" not in reference:
        raise ValueError(f"{where}: function must be a string \"module:name\" (a Python "
                         f"function g(x, v, constant, ...) in module.py), got {reference!r:.40}")
    if folder not in sys.path:
        sys.path.insert(0, folder)  # a module beside the file (workers inherit the path)
    try:
        return ForceLaw.from_function(imported_function(reference), **values)
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None


def _law(where: str, data: dict, folder: str = ".") -> ForceLaw | None:
    """The force law of the file's ``force`` or ``function`` and ``[constants]`` (None:
    the paper's)."""
    constants = _table(f"{where}: [constants]", data.get("constants", {}))
    if "function" in data:
        if "force" in data:
            raise ValueError(f"{where}: give force or function, not both")
        values = {name: _number(f"{where}: [constants] {name}", value)
                  for name, value in constants.items()}
        return _function_law(where, data["function"], values, folder)
    if "force" not in data:
        if constants:
            raise ValueError(f"{where}: [constants] needs force = \"...\" (the paper's law "
                             f"has no constants of its own: set mu, a, c in [oscillator])")
        return None
    expression = data["force"]
    if not isinstance(expression, str):
        raise ValueError(f"{where}: force must be a string, an expression in x and v, got "
                         f"{expression!r:.40}")
    values = {name: _number(f"{where}: [constants] {name}", value)
              for name, value in constants.items()}
    try:
        return ForceLaw(expression, **values)
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None


def _oscillator(where: str, data: dict, law: ForceLaw | None) -> Oscillator:
    fields = _table(f"{where}: [oscillator]", data.get("oscillator", {}))
    values = {}
    for name, value in fields.items():
        if name not in OSCILLATOR_KEYS:
            raise ValueError(f"{where}: [oscillator] has unknown key {name!r:.40} (it takes "
                             f"{' '.join(OSCILLATOR_KEYS)}; a force law's constants go in "
                             f"[constants])")
        if law is not None and name in OSCILLATOR_COEFFICIENTS and name not in law.names:
            raise ValueError(f"{where}: [oscillator] {name} has no effect: the force law "
                             f"{law.expression!r:.60} does not name {name}")
        values[name] = _number(f"{where}: [oscillator] {name}", value)
    try:
        return Oscillator(**values, force=law)
    except ValueError as err:
        raise ValueError(f"{where}: [oscillator] {err}") from None


def uncertain_problem(table: dict, where: str, oscillator: Oscillator) -> Problem:
    """The :class:`opa.Problem` of [uncertain.*] tables (``opa.Problem.from_table``'s
    format), its names checked against ``oscillator``'s force law: the paper's mu, a, c
    or a user's law's constants, and the impact's and the drive's parameters
    (``Oscillator.uncertain_names``)."""
    coefficients = None if oscillator.force is None else oscillator.uncertain_names
    try:
        problem = Problem.from_table(table, where, coefficients)
        problem.check(oscillator)
    except ValueError as err:  # the Problem's own refusals name no file: say which
        text = str(err)
        raise ValueError(text if text.startswith(where) else f"{where}: {text}") from None
    return problem


def read_model(path) -> Model:
    """The :class:`Model` of the TOML model file at ``path`` (the format in this module's
    docstring); a fault of the file raises one ``ValueError`` line naming the path and
    the key or value."""
    from opa._dataset import read_toml

    data = read_toml(path, "model file")
    where = f"model file {path}"
    unknown = [key for key in data if key not in KEYS]
    if unknown:
        raise ValueError(f"{where}: unknown key {unknown[0]!r:.40} (a model file takes force "
                         f"or function, [constants], [oscillator] and [uncertain.NAME] "
                         f"tables)")
    import os

    folder = os.path.dirname(os.path.abspath(str(path)))
    oscillator = _oscillator(where, data, _law(where, data, folder))
    problem = None
    if "uncertain" in data:
        table = _table(f"{where}: [uncertain]", data["uncertain"])
        problem = uncertain_problem(table, f"{where}: [uncertain]", oscillator)
    return Model(oscillator, problem, str(path))


__all__ = ["KEYS", "Model", "read_model", "uncertain_problem"]
