"""The README is the contract with a new user: short, its Python example runs as printed,
its commands are the ones CI runs, every link resolves, and it carries no lab notebook
(commit hashes, machine loads, issue numbers). The developers' map of the house
(docs/developers.md) names every module of the three packages."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")
DEVELOPERS = (ROOT / "docs" / "developers.md").read_text(encoding="utf-8")
TEST_COMMAND = ('python -m pytest -q -n 2 -m "not slow and not long" --doctest-modules '
                'tests opa mc compare')


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README, flags=re.S)


def test_the_readme_has_a_python_example():
    assert len(python_blocks()) >= 1


@pytest.mark.parametrize("index", range(len(python_blocks())))
def test_every_python_example_runs(index, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # the example writes its figure to the working directory
    exec(compile(python_blocks()[index], f"README.md python block {index}", "exec"), {})
    assert "certificate:" in capsys.readouterr().out


def test_the_readme_is_short():
    assert len(README.splitlines()) <= 150


def test_the_readme_keeps_no_lab_notebook():
    """No commit hashes, machine loads or issue numbers: those live in docs/performance.md
    and the CHANGELOG."""
    assert not re.search(r"\bissue \d+", README, flags=re.I)
    assert not re.search(r"\bload(?: average)? \d", README)
    assert not re.search(r"\bcommit [0-9a-f]{7}", README)
    hashes = [w for w in re.findall(r"\b[0-9a-f]{7,40}\b", README) if re.search(r"[a-f]", w)
              and re.search(r"\d", w)]
    assert hashes == [], f"commit hashes in the README: {hashes}"


def test_the_two_commands_are_there():
    """One command installs and runs the main job; the other installs the test extra and
    runs exactly the test command of .ci/run."""
    assert "pip install -e . && opa-mc validate\n" in README
    assert f"pip install -e '.[test]' && {TEST_COMMAND}\n" in README
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert f"\n{TEST_COMMAND}\n" in ci
    assert shlex.split(TEST_COMMAND)  # a command a shell can read


def test_every_link_of_the_readme_resolves():
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README)
    local = [link for link in links if "://" not in link]
    assert local
    missing = [link for link in local if not (ROOT / link).exists()]
    assert missing == [], f"the README links to missing files {missing}"


def test_the_readme_picture_is_there():
    pictures = re.findall(r"!\[[^\]]+\]\(([^)]+\.png)\)", README)
    assert pictures and all((ROOT / p).is_file() for p in pictures)


def test_the_map_names_every_module():
    section = DEVELOPERS[DEVELOPERS.index("## The map of the house"):]
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
    assert missing == [], f"the map of the house (docs/developers.md) does not name {missing}"
