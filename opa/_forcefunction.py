r"""The escape hatch of a force law that is not a polynomial: a compiled function.

A :class:`opa.ForceLaw` whose expression is not a polynomial in x and v of powers up to
3 (a Hertz contact ``k*max(x - g, 0)^1.5``, a ``tanh`` friction, ``x^5``), or one built
from a Python function (:meth:`opa.ForceLaw.from_function`), is compiled here into a C
function ``g(x, v, theta)`` with ``theta`` its constants. The kernel calls it through its
address (``cfg[C_FUNCTION]``), so the kernel is not compiled again and its on-disk cache
stays valid: a model costs one compile of its own small function per process (about
0.1 s for an expression; a Python function also compiles its own body). Its Jacobian is
taken by central differences (``opa._kernel._function_law``), and OPA projects it on the
quadrature nodes as it does every law.

An expression may use x, v, numbers, its named constants, the oscillator's ``mu``,
``a``, ``c``, the operators ``+ - * / **`` (or ``^``) and the functions of
:data:`FUNCTIONS`; nothing else is compiled (no attribute, subscript, comparison or other
name), so a model file cannot run arbitrary code.

>>> address = expression_address("-k*max(x - g, 0.0)**1.5", ("k", "g"))
>>> address > 0
True
"""

from __future__ import annotations

import ast
import hashlib
import importlib
import inspect
import math

import numpy as np

from opa import _kernel as kernel

#: the functions an expression may call, with their numpy forms (for ``ForceLaw.__call__``)
FUNCTIONS = {
    "abs": np.abs, "sqrt": np.sqrt, "exp": np.exp, "log": np.log, "sin": np.sin,
    "cos": np.cos, "tan": np.tan, "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh,
    "atan": np.arctan, "max": np.maximum, "min": np.minimum, "sign": np.sign,
}
#: their compiled forms (math's, and numba's builtins abs, max, min)
_COMPILED = {"abs": abs, "sqrt": math.sqrt, "exp": math.exp, "log": math.log,
             "sin": math.sin, "cos": math.cos, "tan": math.tan, "sinh": math.sinh,
             "cosh": math.cosh, "tanh": math.tanh, "atan": math.atan, "max": max, "min": min}
#: their names
FUNCTION_NAMES = tuple(FUNCTIONS)
#: the most constants a compiled law may have (the kernel's slots of a law)
MAX_CONSTANTS = kernel.N_POLY
_ALLOWED_NODES = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Call, ast.Name, ast.Constant,
                  ast.Load, ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow, ast.USub, ast.UAdd)

# process-local: compiled functions by key, kept alive while their addresses are in use
_COMPILED_LAWS: dict = {}
_ADDRESSES: set[int] = set()


def check_expression(expression: str, tree: ast.Expression) -> list[str]:
    """The names an expression uses besides x, v and its functions (in order of first
    use), after refusing anything but the allowed syntax in one line naming the piece."""
    names: list[str] = []
    for node in _in_order(tree):
        piece = ast.get_source_segment(expression, node) if hasattr(node, "lineno") else ""
        if not isinstance(node, _ALLOWED_NODES):
            raise ValueError(f"force law {expression!r:.80}: {piece or type(node).__name__!r:.40} "
                             f"is not allowed (numbers, x, v, named constants, + - * / ** and "
                             f"the functions {', '.join(FUNCTIONS)})")
        if isinstance(node, ast.Constant) and (
                isinstance(node.value, bool) or not isinstance(node.value, (int, float))
                or not math.isfinite(node.value)):
            raise ValueError(f"force law {expression!r:.80}: {piece!r:.40} is not a finite number")
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div) and _is_zero(node.right):
            raise ValueError(f"force law {expression!r:.80}: {piece!r:.40} is a division by zero")
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
                raise ValueError(f"force law {expression!r:.80}: {piece!r:.40} calls no allowed "
                                 f"function ({', '.join(FUNCTIONS)})")
            if node.keywords or len(node.args) != (2 if node.func.id in ("max", "min") else 1):
                raise ValueError(f"force law {expression!r:.80}: {piece!r:.40} has the wrong "
                                 f"arguments")
    called = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    for node in _in_order(tree):
        if isinstance(node, ast.Name) and id(node) not in called \
                and node.id not in ("x", "v") and node.id not in names:
            if node.id in FUNCTIONS:
                raise ValueError(f"force law {expression!r:.80}: {node.id!r} is a function, "
                                 f"call it as {node.id}(...)")
            names.append(node.id)
    return names


def _is_zero(node) -> bool:
    """Whether a node is a number that is 0 (a literal, or arithmetic of literals)."""
    if not all(isinstance(n, (ast.Constant, ast.UnaryOp, ast.BinOp, ast.operator, ast.unaryop))
               and not isinstance(n, ast.Pow) for n in ast.walk(node)):
        return False  # names, calls and powers: not evaluated here
    try:
        return float(eval(compile(ast.Expression(node), "<force law>", "eval"),  # noqa: S307
                          {"__builtins__": {}})) == 0.0
    except (ArithmeticError, TypeError, ValueError):
        return False


def _in_order(node):
    """The nodes of a syntax tree depth first, left to right (the order of reading)."""
    yield node
    for child in ast.iter_child_nodes(node):
        yield from _in_order(child)


def _sign(value):
    return math.copysign(1.0, value) if value != 0.0 else 0.0


def _register(key, make) -> int:
    """The address of the compiled function of ``key``, compiled by ``make`` once per
    process."""
    compiled = _COMPILED_LAWS.get(key)
    if compiled is None:
        try:
            compiled = kernel.compile_force_function(make())
        except ValueError:
            raise
        except Exception as error:  # noqa: BLE001 - numba's typing and lowering errors
            first = next((line.strip() for line in str(error).splitlines() if line.strip()),
                         type(error).__name__)
            raise ValueError(f"force law {key[1]!r:.80} does not compile with numba "
                             f"({type(error).__name__}: {first:.200})") from None
        _COMPILED_LAWS[key] = compiled
        _ADDRESSES.add(int(compiled.address))
    return int(compiled.address)


def _unpack(names) -> str:
    return "".join(f"    {name} = theta[{i}]\n" for i, name in enumerate(names))


def expression_address(expression: str, names) -> int:
    """The address of ``expression`` (``^`` already ``**``) compiled with its constants
    ``names`` read from theta in that order."""
    def make():
        tree = ast.parse(expression, mode="eval")
        check_expression(expression, tree)  # nothing else reaches exec
        source = f"def g(x, v, theta):\n{_unpack(names)}    return {expression}\n"
        namespace = dict(_COMPILED, sign=kernel.jit_user_function(_sign))
        exec(compile(source, "<force law>", "exec"), namespace)  # noqa: S102 (checked above)
        return namespace["g"]
    return _register(("expression", expression, tuple(names)), make)


def function_parameters(function) -> tuple[str, ...]:
    """The names of a force function's constants: its parameters after x and v."""
    target = getattr(function, "py_func", function)
    if not callable(target):
        raise ValueError(f"a force function must be callable, got {function!r:.60}")
    try:
        parameters = list(inspect.signature(target).parameters.values())
    except (TypeError, ValueError):
        raise ValueError(f"the force function {function!r:.60} has no signature to read") from None
    if len(parameters) < 2 or [p.name for p in parameters[:2]] != ["x", "v"] or any(
            p.kind not in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) for p in parameters):
        raise ValueError(f"a force function is g(x, v, constant, ...), with plain positional "
                         f"parameters; {getattr(target, '__name__', target)!r:.40} has "
                         f"({', '.join(p.name for p in parameters)})")
    return tuple(p.name for p in parameters[2:])


def function_reference(function) -> str:
    """``module:qualified name`` of a function, by which another process imports it."""
    target = getattr(function, "py_func", function)
    return f"{getattr(target, '__module__', '?')}:{getattr(target, '__qualname__', '?')}"


def function_digest(function) -> str:
    """A hash of a force function's source (its code object where the source is gone):
    stored parts of an edited function do not resume."""
    target = getattr(function, "py_func", function)
    try:
        text = inspect.getsource(target)
    except (OSError, TypeError):
        code = target.__code__
        text = repr((code.co_code, code.co_consts, code.co_names))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def imported_function(reference: str):
    """The function of a ``module:qualified name`` reference (a dataset's or a model
    file's), in one line when it cannot be imported."""
    module_name, _, qualname = str(reference).partition(":")
    try:
        target = importlib.import_module(module_name)
        for part in qualname.split("."):
            target = getattr(target, part)
    except Exception as error:  # noqa: BLE001 - a user's module may raise anything
        text = " ".join(str(error).split())
        raise ValueError(f"force function {reference!r:.80} cannot be imported "
                         f"({type(error).__name__}: {text:.200}); a force function must live "
                         f"in an importable module") from None
    if not callable(target):
        raise ValueError(f"force function {reference!r:.80} is not a function")
    return target


def function_address(function, n_constants: int) -> int:
    """The address of a user's Python ``function(x, v, c_0, ..., c_{n-1})``, jitted, and
    called with its constants read from theta."""
    def make():
        args = "".join(f", theta[{i}]" for i in range(n_constants))
        namespace = {"user": kernel.jit_user_function(function)}
        exec(compile(f"def g(x, v, theta):\n    return user(x, v{args})\n",  # noqa: S102
                     "<force function>", "exec"), namespace)
        return namespace["g"]
    return _register(("function", function_reference(function), function_digest(function),
                      id(function)), make)


def check_addresses(cfg) -> None:
    """Refuse kernel inputs whose compiled force function was not made in this process
    (inputs built in another process carry an address that is meaningless here)."""
    cfg = np.asarray(cfg)
    forces = cfg[..., kernel.C_FORCE] == kernel.FORCE_FUNCTION
    if forces.any():
        for address in np.unique(cfg[..., kernel.C_FUNCTION][forces]):
            if int(address) not in _ADDRESSES:
                raise ValueError("these kernel inputs hold a compiled force function made in "
                                 "another process: build them in the process that runs them "
                                 "(opa.System.kernel_inputs)")
