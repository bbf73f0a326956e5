"""Every source file of opa, mc and compare, parsed once when this module is first
imported (at collection, before any test runs): CPython 3.11's ``ast.parse`` can fail
with "AST constructor recursion depth mismatch" while another thread compiles code (a
Dask cluster shutting down, a worker pool's helper thread), so the tests that read the
code's structure take their trees from here instead of parsing while tests run."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("opa", "mc", "compare")

#: path -> its parsed module, for every .py file of the packages
TREES = {path: ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
         for package in PACKAGES for path in sorted((ROOT / package).rglob("*.py"))}


def tree(path: Path) -> ast.Module:
    """The parsed module of a source file of the packages."""
    return TREES[Path(path).resolve()]
