"""The README is the contract with a new user: its Python examples run as printed, and
its map of the house names every module of the three packages."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README, flags=re.S)


def test_the_readme_has_python_examples():
    assert len(python_blocks()) >= 2


@pytest.mark.parametrize("index", range(len(python_blocks())))
def test_every_python_example_runs(index, capsys):
    exec(compile(python_blocks()[index], f"README.md python block {index}", "exec"), {})


def test_the_map_names_every_module():
    section = README[README.index("## The map of the house"):]
    section = section[: section.index("\n## ", 1)]
    missing = []
    for package in ("opa", "mc", "compare"):
        for path in (ROOT / package).rglob("*.py"):
            if path.name in ("__init__.py", "__main__.py"):
                continue
            rel = path.relative_to(ROOT)
            stem = path.stem
            if stem not in section and str(rel) not in section:
                missing.append(str(rel))
    assert missing == [], f"the README's map does not name {missing}"
