"""opa.engine: the one door from ``mc`` and ``compare`` into ``opa``'s private modules."""

import ast
from pathlib import Path

import opa.engine
from tests.parsed import tree

ROOT = Path(__file__).resolve().parents[2]


def test_every_exported_name_is_the_object_of_its_private_module():
    for name in opa.engine.__all__:
        obj = getattr(opa.engine, name)
        home = getattr(obj, "__module__", None)
        if home is not None and callable(obj):  # functions and classes keep their module
            assert home.startswith("opa."), (name, home)
    assert len(set(opa.engine.__all__)) == len(opa.engine.__all__)


def test_the_names_mc_and_compare_take_are_exported_and_nothing_more():
    """Every name ``mc``, ``compare`` and ``opa.cli`` import from opa.engine is in its
    ``__all__``, and every name of ``__all__`` is used by one of them (no dead doors)."""
    taken = set()
    for package in ("mc", "compare", "opa/cli"):
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.walk(tree(path)):
                if isinstance(node, ast.ImportFrom) and node.module == "opa.engine":
                    taken |= {a.name for a in node.names}
    assert taken == set(opa.engine.__all__)
