"""The generated documentation pages hold: docs/datasets.md lists what the code returns."""

from __future__ import annotations

import importlib.util
import os

DOCS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "docs")


def _load(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(DOCS, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_datasets_page_is_what_the_code_returns():
    """Regenerate docs/datasets.md from fresh runs: it must equal the page on disk."""
    page = _load("datasets")
    with open(page.PAGE, encoding="utf-8") as fh:
        on_disk = fh.read()
    assert page.render() == on_disk, "docs/datasets.md is stale: run python docs/datasets.py"
