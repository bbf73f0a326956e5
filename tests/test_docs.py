"""The documentation holds: docs/datasets.md lists what the code returns, and every number of
docs/findings.md (sections 1-6) is one a run of the default job gives."""

from __future__ import annotations

import importlib.util
import os

import pytest

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


def test_datasets_page_examples_run():
    """Every python block of docs/datasets.md runs and its assertions hold."""
    import re

    with open(os.path.join(DOCS, "datasets.md"), encoding="utf-8") as fh:
        blocks = re.findall(r"```python\n(.*?)```", fh.read(), re.S)
    assert blocks
    for block in blocks:
        exec(compile(block, "docs/datasets.md", "exec"), {})


def _fake_run(folder, summary: str, count_prob: list[float]):
    """A results folder with a summary and the dataset variables docs/findings.py reads."""
    import numpy as np
    import xarray as xr

    folder.mkdir()
    (folder / "summary.md").write_text(summary)
    xr.Dataset({"count_prob": ("count", np.array(count_prob))}).to_netcdf(folder / "validate.nc")
    return folder


def test_findings_check_passes_a_doc_whose_numbers_the_run_gives(tmp_path):
    check = _load("findings")
    run = _fake_run(tmp_path / "r", "σ* = 0.0225–0.0231; speed 3.0e-05; slope σ^2.05",
                    [0.9806, 0.0194])
    doc = tmp_path / "doc.md"
    doc.write_text("σ* = 0.0225–0.0231 at ω = 3.98 over 10 periods; grazing at speed\n"
                   "3.0e-5; error like σ^2.05; 98.1% / 1.9% make 4 / 5 impacts.\n")
    assert check.stale(doc, run) == []


def test_findings_check_fails_on_a_number_the_run_does_not_give(tmp_path):
    check = _load("findings")
    run = _fake_run(tmp_path / "r", "σ* = 0.0225–0.0231; speed 3.0e-05", [0.9806, 0.0194])
    doc = tmp_path / "doc.md"
    doc.write_text("σ* = 0.0225–0.0231; grazing at speed 3.9e-5; 98.1% / 1.9%.\n"
                   "## 7. Long runs\nnot checked: 0.123456\n")
    bad = check.stale(doc, run)
    assert len(bad) == 1 and bad[0].startswith("3.9e-5:")


@pytest.mark.slow
def test_the_findings_page_holds_for_a_fresh_run_of_the_default_job(tmp_path):
    """The whole check: run the default job (about 70 s on 2 cores), then every number of
    sections 1-6 of docs/findings.md must be one the run gives."""
    import subprocess
    import sys
    from pathlib import Path

    subprocess.run([sys.executable, "-c", "import sys; from opa.cli._main import main; "
                    "sys.exit(main())", "validate", "--quiet", "--outdir", str(tmp_path)],
                   check=True, timeout=1800)
    assert _load("findings").stale(Path(DOCS) / "findings.md", tmp_path) == []


@pytest.mark.slow
def test_the_elements_page_holds_for_a_fresh_convergence_study(tmp_path):
    """docs/elements.md, section "Convergence against Monte Carlo": every number is one a
    fresh ``opa-mc converge`` gives (about 20 s on 2 cores with a warm numba cache)."""
    import subprocess
    import sys
    from pathlib import Path

    subprocess.run([sys.executable, "-c", "import sys; from opa.cli._main import main; "
                    "sys.exit(main())", "converge", "--quiet", "--outdir", str(tmp_path)],
                   check=True, timeout=1800)
    assert _load("findings").stale(Path(DOCS) / "elements.md", tmp_path,
                                   summary="convergence.md",
                                   start="## Convergence against Monte Carlo",
                                   stop="## σ = 0.03") == []


# ------------------------------------------------------------------ the documentation site
ROOT = os.path.dirname(DOCS)
GLOSSARY_TERMS = ("OPA", "EMR", "DMR", "ξ", "Law of ξ", "σ\\*", "Split", "Impact law",
                  "`mean`", "`ensemble`", "`saltation`", "Truncation", "`galerkin`", "`paper`",
                  "**N**", "**H**", "Elements", "Certificate", "Control variate", "Frontier")


def _read(*parts):
    with open(os.path.join(ROOT, *parts), encoding="utf-8") as fh:
        return fh.read()


def test_every_tutorial_is_an_executed_notebook_in_the_index():
    """A tutorial is a MyST notebook (myst-nb runs it at build time, so it cannot go stale)
    and the index lists it."""
    index = _read("docs", "index.md")
    tutorials = sorted(f for f in os.listdir(os.path.join(DOCS, "tutorials")) if f.endswith(".md"))
    assert len(tutorials) >= 4
    for name in tutorials:
        text = _read("docs", "tutorials", name)
        assert text.startswith("---\nfile_format: mystnb\n"), name
        assert "```{code-cell} ipython3" in text, name
        assert "placeholder" not in text, name
        assert f"tutorials/{name[:-3]}\n" in index, f"the index does not list {name}"


def test_the_glossary_explains_the_words_and_cites_the_paper():
    import re

    text = _read("docs", "glossary.md")
    missing = [term for term in GLOSSARY_TERMS if term not in text]
    assert missing == []
    text = re.sub(r"\s*\n>?\s*", " ", text)  # the citation is a quote over several lines
    for part in ("Huang", "Rajic", "Computer Modeling in Engineering & Sciences",
                 "10.32604/cmes.2023.029215"):
        assert part in text


def test_the_docs_build_is_one_command_and_ci_runs_it_last():
    """The docs extra holds what the build needs; .ci/run builds with warnings as errors
    after the test steps."""
    import tomllib

    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as fh:
        extras = tomllib.load(fh)["project"]["optional-dependencies"]
    names = " ".join(extras["docs"])
    for package in ("sphinx", "myst-nb", "numpydoc", "ipykernel"):
        assert package in names
    ci = _read(".ci", "run")
    build = ci.index("sphinx-build -W")
    assert ci.index("pip install -e '.[docs]'") < build
    assert ci.index("--doctest-modules tests opa mc compare") < build
    assert ci.index("benchmarks -m \"not slow\"") < build
    command = "sphinx-build -W --keep-going -b html docs build/docs"
    for page in (("README.md",), ("docs", "getting-started.md"), ("docs", "developers.md")):
        assert command in _read(*page), page


@pytest.mark.long  # every block runs as printed: CI runs it, the quick loop does not
def test_the_reference_examples_run(tmp_path, monkeypatch):
    """The Python blocks of docs/reference.md (the README's before) run as printed."""
    import re

    monkeypatch.chdir(tmp_path)
    blocks = re.findall(r"```python\n(.*?)```", _read("docs", "reference.md"), re.S)
    assert blocks
    for block in blocks:
        exec(compile(block, "docs/reference.md", "exec"), {})


@pytest.mark.slow
def test_the_docs_build_without_a_warning(tmp_path):
    """The whole site, tutorials executed, warnings as errors (as .ci/run builds it)."""
    import subprocess
    import sys

    subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                    DOCS, str(tmp_path / "html")], check=True, timeout=1200)


def test_the_own_oscillator_page_is_what_its_commands_print():
    """docs/own-oscillator.md: every ``$ opa-mc`` command of the page, rerun, prints what
    the page shows (wall times aside); ``python docs/own_oscillator.py`` rewrites it."""
    page = _load("own_oscillator")
    with open(page.PAGE, encoding="utf-8") as fh:
        on_disk = fh.read()
    assert on_disk.count(page.PROMPT) >= 10
    assert page.same(on_disk, page.render(on_disk)), \
        "docs/own-oscillator.md is stale: run python docs/own_oscillator.py"
