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
