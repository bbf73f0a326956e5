"""The size rules of the house (issue 41): outside ``opa/_kernel.py`` (where numba asks for
scalars), no function of ``opa``, ``mc`` and ``compare`` is over 120 lines, and no public
function or method takes more than 12 named parameters. A ``**`` bag (the fields of a
record given inline, e.g. a System's to ``simulate_mc``, or the keywords of an earlier
release) is not a named parameter; ``self`` and ``cls`` are not counted. Group the rest
into records."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 120
MAX_PARAMETERS = 12


# parsed once, at collection (as tests/test_architecture.py does): CPython 3.11.7's
# ast.parse can fail with "AST constructor recursion depth mismatch" while threads of an
# earlier test (a Dask cluster shutting down) still compile code
SOURCES = [(path, ast.parse(path.read_text(encoding="utf-8"), filename=str(path)))
           for package in ("opa", "mc", "compare")
           for path in sorted((ROOT / package).rglob("*.py")) if path.name != "_kernel.py"]


def _sources():
    return SOURCES


def _named(args: ast.arguments) -> int:
    names = [a.arg for a in (*args.posonlyargs, *args.args, *args.kwonlyargs)]
    return sum(name not in ("self", "cls") for name in names)


def _public_functions(tree: ast.Module):
    """Module-level functions and the methods of module-level classes whose names and
    whose class's names do not start with an underscore."""
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if not node.name.startswith("_"):
                yield node.name, node
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) \
                        and not item.name.startswith("_"):
                    yield f"{node.name}.{item.name}", item


def test_no_function_is_over_120_lines():
    long = [f"{path.relative_to(ROOT)}:{node.name} ({node.end_lineno - node.lineno + 1})"
            for path, tree in _sources() for node in ast.walk(tree)
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > MAX_LINES]
    assert long == []


def test_no_public_function_takes_more_than_12_named_parameters():
    wide = [f"{path.relative_to(ROOT)}:{name} ({_named(node.args)})"
            for path, tree in _sources() for name, node in _public_functions(tree)
            if _named(node.args) > MAX_PARAMETERS]
    assert wide == []


_BODY = "\n".join(["    x = 1"] * 120)
#: a written example (parsed at collection too)
EXAMPLE = ast.parse(f"def long():\n{_BODY}\n"
                    "def wide(a, b, c, d, e, f, g, h, i, j, k, l, m): pass\n"
                    "def bag(a, b, c, d, e, f, g, h, i, j, k, l, **more): pass\n"
                    "def _private(a, b, c, d, e, f, g, h, i, j, k, l, m): pass\n"
                    "class C:\n    def method(self, a, b, c, d, e, f, g, h, i, j, k, l): pass\n")


def test_the_rules_see_what_they_are_meant_to():
    """The counts on a written example: a 121-line function and a 13-parameter public
    one are caught, ``self`` and a ``**`` bag are not counted, private names pass."""
    lengths = {n.name: n.end_lineno - n.lineno + 1 for n in ast.walk(EXAMPLE)
               if isinstance(n, ast.FunctionDef)}
    assert lengths["long"] == 121 > MAX_LINES
    counts = {name: _named(node.args) for name, node in _public_functions(EXAMPLE)}
    assert counts == {"long": 0, "wide": 13, "bag": 12, "C.method": 12}
