r"""A user's force law: the oscillator's acceleration g(x, v) as a polynomial in x and v.

The paper's equation (1) is x'' = g(x, v) + f cos(omega t) + impulses with
``g = mu (1 - v^2) v - a x - c x^3``. A :class:`ForceLaw` replaces g by any polynomial
written as an expression, with named coefficients:

>>> law = ForceLaw("-2*zeta*v - x", zeta=0.05)          # Shaw & Holmes' linear oscillator
>>> law.names, law.terms()
(('zeta',), {(0, 1): '-2*zeta', (1, 0): '-1'})

The expression takes ``x`` and ``v``, numbers, the law's own named constants (given as
keywords) and the oscillator's ``mu``, ``a`` and ``c`` (their values are the
oscillator's); ``+ - *``, ``/`` by a number and whole powers ``^`` or ``**``. It is
expanded into monomials C[j, k] x^j v^k once; each coefficient C[j, k] is a polynomial in
the named constants, so any of them may be uncertain (:meth:`coefficients` evaluates
them at each quadrature node or sample). The compiled kernel takes the 4 x 4 table
C[j, k] (powers of x and of v up to ``MAX_POWER`` = 3) as numbers, so a new law is not a
new compilation. The paper's law is :data:`PAPER_LAW`.

The escape hatch: an expression that is not such a polynomial (``max``, ``sqrt``,
``tanh``, ..., a power that is not a whole number up to 3, a division by a constant) is
compiled into a function of its own (``opa._forcefunction``: ``kind`` "compiled"), and
:meth:`ForceLaw.from_function` takes a Python function g(x, v, constant, ...) that numba
can compile (``kind`` "function"). Both cost a compile of their own per process, take the
general step rather than the polynomial's unrolled one, and have their Jacobian by
central differences:

>>> hertz = ForceLaw("-2*zeta*v - x - k*max(x - g, 0)^1.5", zeta=0.05, k=50.0, g=0.5)
>>> hertz.kind, hertz.names
('compiled', ('zeta', 'k', 'g'))
"""

from __future__ import annotations

import ast
import math
from collections.abc import Mapping

import numpy as np

from opa._forcefunction import (FUNCTION_NAMES, FUNCTIONS, MAX_CONSTANTS, check_expression,
                                function_address, function_digest, function_parameters,
                                function_reference, expression_address)

#: highest power of x and of v in a term (the kernel's table is C[j, k], j, k <= 3)
MAX_POWER = 3
#: number of coefficients C[j, k] the kernel takes, row-major in j
N_COEFFICIENTS = (MAX_POWER + 1) ** 2
#: the oscillator's coefficients a law may name (their values are the oscillator's)
OSCILLATOR_COEFFICIENTS = ("mu", "a", "c")
#: names a law's own constants may not take: the state, time and the oscillator's others
RESERVED = ("x", "v", "t", "f", "omega", "eta", "delta", "F0", "a1", "omega1", "n", "x0", "v0",
            "sigma", "xi")
#: the paper's law, eq. (1)
PAPER_EXPRESSION = "mu*(1 - v^2)*v - a*x - c*x^3"
#: deepest syntax tree accepted (its readers recurse; a law is a few levels deep)
MAX_DEPTH = 100
#: longest expression accepted (a guard against pathological input, not a modelling limit)
MAX_EXPRESSION = 2000

# A polynomial is {(j, k): coefficient}, a coefficient {monomial: number}, a monomial a
# sorted tuple of (name, power) pairs of the named constants.


# the one check of a real parameter (opa._model takes it from here: this module
# imports only opa._forcefunction, which imports only the kernel)
def _finite(name: str, value) -> float:
    """``value`` as a finite float; bools and strings are refused, not converted."""
    if isinstance(value, (bool, str, bytes)) or (type(value).__module__ == "numpy" and (
            type(value).__name__ in ("bool_", "bool") or getattr(value, "dtype", None) is not None
            and value.dtype.kind == "b")):  # numpy bools, and 0-d boolean arrays
        raise ValueError(f"{name} must be a real number, got {value!r}")
    try:
        value = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    return value


def _constant(value: float) -> dict:
    return {(0, 0): {(): float(value)}} if value != 0.0 else {}


def _add(p: dict, q: dict, sign: float = 1.0) -> dict:
    out = {key: dict(coef) for key, coef in p.items()}
    for key, coef in q.items():
        target = out.setdefault(key, {})
        for mono, value in coef.items():
            target[mono] = target.get(mono, 0.0) + sign * value
    return _clean(out)


def _clean(p: dict) -> dict:
    out = {}
    for key, coef in p.items():
        coef = {mono: value for mono, value in coef.items() if value != 0.0}
        if coef:
            out[key] = coef
    return out


def _mono_times(m1: tuple, m2: tuple) -> tuple:
    powers = dict(m1)
    for name, power in m2:
        powers[name] = powers.get(name, 0) + power
    return tuple(sorted(powers.items()))


def _mul(p: dict, q: dict) -> dict:
    out: dict = {}
    for (j1, k1), c1 in p.items():
        for (j2, k2), c2 in q.items():
            target = out.setdefault((j1 + j2, k1 + k2), {})
            for m1, v1 in c1.items():
                for m2, v2 in c2.items():
                    mono = _mono_times(m1, m2)
                    target[mono] = target.get(mono, 0.0) + v1 * v2
    return _clean(out)


def _number(node, expression: str) -> float | None:
    """The value of a numeric literal (or a signed one), else None."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = _number(node.operand, expression)
        return None if inner is None else (-inner if isinstance(node.op, ast.USub) else inner)
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
            and not isinstance(node.value, bool):
        return float(node.value)
    return None


class _Expander:
    """Expands the expression's syntax tree into a polynomial, refusing anything else."""

    def __init__(self, expression: str):
        self.expression = expression
        self.names: list[str] = []

    def fail(self, node, why: str):
        piece = ast.get_source_segment(self.expression, node) or "?"
        raise ValueError(f"force law {self.expression!r:.80}: {why} at {piece!r:.40}")

    def expand(self, node) -> dict:
        number = _number(node, self.expression)
        if number is not None:
            if not math.isfinite(number):
                self.fail(node, "a number must be finite")
            return _constant(number)
        if isinstance(node, ast.Name):
            if node.id == "x":
                return {(1, 0): {(): 1.0}}
            if node.id == "v":
                return {(0, 1): {(): 1.0}}
            if node.id not in self.names:
                self.names.append(node.id)
            return {(0, 0): {((node.id, 1),): 1.0}}
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            inner = self.expand(node.operand)
            return _add({}, inner, -1.0) if isinstance(node.op, ast.USub) else inner
        if isinstance(node, ast.BinOp):
            return self.binary(node)
        self.fail(node, "only numbers, x, v, named constants, + - *, / by a number and whole "
                        "powers are allowed")

    def binary(self, node) -> dict:
        if isinstance(node.op, ast.Pow):
            power = _number(node.right, self.expression)
            if power is None or power != int(power) or power < 0 or power > 16:
                self.fail(node, "a power must be a whole number from 0 to 16")
            base = self.expand(node.left)
            out = _constant(1.0)
            for _ in range(int(power)):
                out = _mul(out, base)
            return out
        if isinstance(node.op, ast.Div):
            divisor = _number(node.right, self.expression)
            if divisor is None or divisor == 0.0:
                self.fail(node, "division only by a non-zero number")
            return _mul(self.expand(node.left), _constant(1.0 / divisor))
        left, right = self.expand(node.left), self.expand(node.right)
        if isinstance(node.op, ast.Add):
            return _add(left, right)
        if isinstance(node.op, ast.Sub):
            return _add(left, right, -1.0)
        if isinstance(node.op, ast.Mult):
            return _mul(left, right)
        self.fail(node, "only + - * / and powers are allowed")


def _coefficient_text(coef: dict) -> str:
    parts = []
    for mono, value in sorted(coef.items()):
        names = "*".join(name if power == 1 else f"{name}^{power}" for name, power in mono)
        if not names:
            parts.append(f"{value:g}")
        elif value == 1.0:
            parts.append(names)
        elif value == -1.0:
            parts.append("-" + names)
        else:
            parts.append(f"{value:g}*{names}")
    return " + ".join(parts).replace("+ -", "- ")


#: the kinds of law: a polynomial (the kernel's table), a compiled expression, a function
KINDS = ("polynomial", "compiled", "function")


class ForceLaw:
    """g(x, v) of x'' = g(x, v) + f cos(omega t) + impulses: a polynomial in x and v, or
    (the escape hatch) a compiled expression or function.

    Parameters
    ----------
    expression : the law, e.g. ``"-2*zeta*v - x"`` or ``"mu*(1 - x^2)*v - x"``.
    **constants : the values of the law's own named constants (any name in the
        expression other than x, v and the oscillator's mu, a, c).

    Refused, in one line naming the piece: anything but numbers, x, v, named constants,
    ``+ - * / **`` and the functions of ``opa._forcefunction.FUNCTIONS``; a named constant
    without a value or with a value not used; a constant named like the state, time or
    one of the oscillator's other parameters. A polynomial with powers of x and v up to
    ``MAX_POWER`` is expanded (``kind`` "polynomial"); any other allowed expression is
    compiled (``kind`` "compiled"); :meth:`compiled` compiles a polynomial too.
    """

    kind = "polynomial"
    function = None
    _forced = False  # compiled by ForceLaw.compiled, though a polynomial

    def __init__(self, expression: str, **constants):
        self._setup(expression, constants, compile_it=False)

    @classmethod
    def compiled(cls, expression: str, **constants) -> ForceLaw:
        """The law compiled as a function even where it is a polynomial (the escape
        hatch's path, e.g. to compare it with the polynomial one)."""
        law = cls.__new__(cls)
        law._setup(expression, constants, compile_it=True)
        return law

    @classmethod
    def from_function(cls, function, **constants) -> ForceLaw:
        """A law g(x, v, c_0, ...) given as a Python function that numba can compile
        (or a numba ``njit`` function), its constants named by its parameters after x and
        v and valued by ``constants``. Processes that run it (``--workers``, Dask) import
        it by its module and name, so it must live in an importable module there."""
        law = cls.__new__(cls)
        names = function_parameters(function)
        law._check_names(f"force function {function_reference(function)}", names, constants)
        law.kind = "function"
        law.function = function
        law.expression = function_reference(function)
        law.constants = {name: _finite(f"force law constant {name}", value)
                         for name, value in constants.items()}
        law.names = names
        law._terms = None
        return law

    def _setup(self, expression, constants: dict, compile_it: bool) -> None:
        if not isinstance(expression, str) or not expression.strip():
            raise ValueError(f"force law must be a non-empty expression in x and v, got "
                             f"{expression!r:.60}")
        if len(expression) > MAX_EXPRESSION:
            raise ValueError(f"force law is longer than {MAX_EXPRESSION} characters")
        text = expression.strip().replace("^", "**")
        try:
            tree = ast.parse(text, mode="eval")
        except (SyntaxError, RecursionError, MemoryError):
            raise ValueError(f"force law {expression!r:.80} is not an expression in x and v "
                             f"(write e.g. \"-2*zeta*v - x - c*x^3\")") from None
        if _depth(tree) > MAX_DEPTH:
            raise ValueError(f"force law {expression!r:.80} is nested more than {MAX_DEPTH} "
                             f"levels deep")
        terms, names = (None, None) if compile_it else _polynomial(text, tree)
        if terms is None:  # not a polynomial the kernel's table holds: compiled
            names = tuple(check_expression(text, tree))
            if len(names) > MAX_CONSTANTS:
                raise ValueError(f"force law {expression!r:.80} has {len(names)} constants; a "
                                 f"compiled law takes at most {MAX_CONSTANTS}")
            self.kind = "compiled"
        self._forced = compile_it
        self._check_names(f"force law {expression!r:.80}", names, constants)
        self.expression = expression.strip()
        self._text = text
        self.constants = {name: _finite(f"force law constant {name}", value)
                          for name, value in constants.items()}
        self.names = names
        self._terms = terms

    @staticmethod
    def _check_names(what: str, names, constants: dict) -> None:
        for name in names:
            if name in RESERVED:
                raise ValueError(f"{what} names {name!r}, which is the oscillator's own "
                                 f"parameter or the state; a law may use x, v, mu, a, c and "
                                 f"constants of its own")
            if name not in OSCILLATOR_COEFFICIENTS and name not in constants:
                raise ValueError(f"{what}: the constant {name!r} has no value (give it as "
                                 f"{name}=...)")
        for name in constants:
            if name not in names:
                raise ValueError(f"{what} does not use the constant {name!r} given a value")
            if name in OSCILLATOR_COEFFICIENTS:
                raise ValueError(f"force law constant {name!r} is the oscillator's own: set it "
                                 f"on the oscillator (opa.Oscillator({name}=...))")

    def __repr__(self) -> str:
        extra = "".join(f", {k}={v!r}" for k, v in self.constants.items())
        if self.kind == "function":
            return f"ForceLaw.from_function({self.expression}{extra})"
        if self.kind == "compiled" and self._forced:
            return f"ForceLaw.compiled({self.expression!r}{extra})"
        return f"ForceLaw({self.expression!r}{extra})"

    def _identity(self) -> tuple:
        return (self.kind, self.expression, self.function,
                tuple(sorted(self.constants.items())))

    def __eq__(self, other) -> bool:
        return isinstance(other, ForceLaw) and self._identity() == other._identity()

    def __hash__(self) -> int:
        return hash(self._identity())

    def digest_payload(self) -> dict:
        """What defines the law, for the keys of stored parts (``opa._dataset.digest``);
        a polynomial's is what it always was."""
        payload = dict(expression=self.expression, constants=dict(self.constants))
        if self.kind == "function":
            payload.update(kind=self.kind, source=function_digest(self.function))
        elif self.kind == "compiled":
            payload.update(kind=self.kind)
        return payload

    def __reduce__(self):
        if self.kind == "function":
            return (_rebuild_function, (self.function, dict(self.constants)))
        if self.kind == "compiled":
            return (_rebuild_compiled, (self.expression, dict(self.constants)))
        return (_rebuild, (self.expression, dict(self.constants)))

    def with_constants(self, **changes) -> ForceLaw:
        """The same law with some constants' values changed."""
        constants = {**self.constants, **changes}
        if self.kind == "function":
            return ForceLaw.from_function(self.function, **constants)
        if self.kind == "compiled":
            return ForceLaw.compiled(self.expression, **constants)
        return ForceLaw(self.expression, **constants)

    def address(self) -> int:
        """The address of a compiled law's C function in this process (compiled on first
        use); 0 for a polynomial."""
        if self.kind == "compiled":
            return expression_address(self._text, self.names)
        if self.kind == "function":
            return function_address(self.function, len(self.names))
        return 0

    @property
    def is_paper(self) -> bool:
        """Whether this is the paper's law as written in :data:`PAPER_EXPRESSION`."""
        return (self.kind == "polynomial" and self.expression == PAPER_EXPRESSION
                and not self.constants)

    def terms(self) -> dict:
        """{(j, k): coefficient of x^j v^k as text}, the expanded law (a polynomial's)."""
        if self._terms is None:
            raise ValueError(f"the {self.kind} force law {self.expression!r:.60} has no "
                             f"expansion in powers of x and v")
        return {key: _coefficient_text(coef) for key, coef in sorted(self._terms.items())}

    def coefficients(self, values: Mapping) -> np.ndarray:
        """C[j, k] at each of M points, shape (M, N_COEFFICIENTS) row-major in j, with
        ``values`` the named constants' values: arrays (M,) or numbers, one per name of
        :attr:`names` (the oscillator's mu, a, c included where the law names them). A
        compiled law's are its constants themselves, in the order of :attr:`names`."""
        arrays = {name: np.atleast_1d(np.asarray(values[name], dtype=float))
                  for name in self.names}
        size = max((len(a) for a in arrays.values()), default=1)
        out = np.zeros((size, N_COEFFICIENTS))
        if self._terms is None:  # a compiled law reads its constants in these slots
            for i, name in enumerate(self.names):
                out[:, i] = arrays[name]
            return out
        for (j, k), coef in self._terms.items():
            column = np.zeros(size)
            for mono, number in coef.items():
                term = np.full(size, number)
                for name, power in mono:
                    term = term * arrays[name] ** power
                column = column + term
            out[:, (MAX_POWER + 1) * j + k] = column
        return out

    def __call__(self, x, v, values: Mapping | None = None):
        """g(x, v) in numpy at the law's constants (or ``values``), for checks and plots."""
        merged = {**self.constants, **(values or {})}
        x, v = np.asarray(x, dtype=float), np.asarray(v, dtype=float)
        if self.kind == "function":
            return np.vectorize(self.function, otypes=[float])(
                x, v, *(merged[name] for name in self.names))
        if self.kind == "compiled":
            scope = {"__builtins__": {}, **FUNCTIONS, "x": x, "v": v,
                     **{name: merged[name] for name in self.names}}
            return eval(compile(self._text, "<force law>", "eval"), scope)  # noqa: S307 (checked)
        coef = self.coefficients(merged)[0].reshape(MAX_POWER + 1, MAX_POWER + 1)
        return sum(coef[j, k] * x**j * v**k for j in range(MAX_POWER + 1)
                   for k in range(MAX_POWER + 1) if coef[j, k] != 0.0)


def _depth(tree) -> int:
    """The depth of a syntax tree, counted without recursion."""
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, level = stack.pop()
        deepest = max(deepest, level)
        stack.extend((child, level + 1) for child in ast.iter_child_nodes(node))
    return deepest


def _polynomial(text: str, tree) -> tuple[dict | None, tuple | None]:
    """(the expansion, the names it uses besides x and v in order of first use) of a
    polynomial of powers up to MAX_POWER; (None, None) for any other expression (which
    the compiled path checks and refuses in its own words)."""
    if any(isinstance(n, ast.Name) and n.id in FUNCTION_NAMES for n in ast.walk(tree)):
        return None, None
    expander = _Expander(text)
    try:
        terms = expander.expand(tree.body)
    except ValueError:
        return None, None
    if any(j > MAX_POWER or k > MAX_POWER for (j, k) in terms):
        return None, None
    return terms, tuple(expander.names)


def _rebuild(expression: str, constants: dict) -> ForceLaw:
    return ForceLaw(expression, **constants)


def _rebuild_compiled(expression: str, constants: dict) -> ForceLaw:
    return ForceLaw.compiled(expression, **constants)


def _rebuild_function(function, constants: dict) -> ForceLaw:
    return ForceLaw.from_function(function, **constants)


#: the paper's force law, eq. (1), as a user's law (the built-in one is faster to the bit)
PAPER_LAW = ForceLaw(PAPER_EXPRESSION)
