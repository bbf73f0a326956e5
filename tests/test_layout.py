"""The tests mirror the source tree (issue 13, item 4; see ``tests/__init__.py``).

The test module of ``PKG/.../_NAME.py`` is ``tests/PKG/.../test_NAME.py``. A test module
with no source module of that name tests a theme and is listed in ``THEMES``; a source
module with no test module of its own is listed in ``TESTED_IN`` with the test modules
that cover it, each of which must name it.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TESTS = ROOT / "tests"
PACKAGES = ("opa", "mc", "compare")

#: test modules that test a theme across source modules rather than one module
THEMES = {
    "tests/test_architecture.py": "the import layers of every package",
    "tests/test_docs.py": "docs/ against fresh runs",
    "tests/test_readme.py": "the README's examples run and its map names every module",
    "tests/test_layout.py": "this rule",
    "tests/test_reference.py": "tests/reference.py against closed forms",
    "tests/test_truths.py": "tests/truths.py against scipy",
    "tests/test_impact_truths.py": "tests/impact_truths.py against scipy and closed forms",
    "tests/test_sizes.py": "no function over 120 lines, no public one over 12 named "
                           "parameters",
    "tests/test_matrix.py": "every law, uncertain parameter and element setting through "
                            "simulate, --plot and compare_runs",
    "tests/opa/test_solver.py": "the event-driven integrator (opa._kernel) and simulate_dmr",
    "tests/opa/test_impact_uncertain.py":
        "an uncertain eta, delta, f, omega or F0 (opa._kernel, _problem, _run, _system)",
    "tests/opa/test_opa_system.py": "the OPA equivalent system against the paper's equations",
    "tests/opa/test_two_walls.py": "a lower wall (opa._kernel, _model, _run, _system) vs scipy",
    "tests/opa/test_hard_dynamics.py": "failures and time bounds across kernel, runs, orbits",
    "tests/opa/dynamics/test_pool.py": "the sweep's worker processes die with their owner",
    "tests/opa/dynamics/test_nordmark.py":
        "Nordmark's square-root law near grazing, on a user's force law",
    "tests/opa/cli/test_bad_inputs.py": "the hostile-user corpus of every subcommand",
    "tests/compare/test_report_sentences.py": "the validate report's sentences (compare._findings)",
    "tests/opa/cli/test_commands.py": "the happy path of every subcommand",
    "tests/mc/test_coef_sem.py": "standard errors of the Monte Carlo coefficients",
    "tests/mc/test_dask.py": "the Dask backend of simulate_mc",
    "tests/compare/test_parts.py":
        "the trust map's parts on disk (compare._trustmap, opa._dataset.Store)",
    "tests/compare/test_hostile_inputs.py":
        "the hostile-input corpus of compare's entry points (compare._inputs)",
    "tests/opa/dynamics/test_stochastic_hostile.py":
        "the hostile-input corpus of opa-mc stochastic and stochastic_diagram",
    "tests/opa/cli/test_hard_numerics.py": "the hard-numerics corpus of opa-mc (real processes)",
}

#: source modules without a test module of their own -> the test modules that cover them
TESTED_IN = {
    "opa/_simulate.py": ("tests/opa/test_solver.py",),
    "opa/dynamics/_warm_worker.py": ("tests/opa/dynamics/test_pool.py",),
    "opa/cli/_main.py": ("tests/opa/cli/test_bad_inputs.py", "tests/opa/cli/test_commands.py"),
    "opa/cli/_args.py": ("tests/opa/cli/test_bad_inputs.py",),
    "opa/cli/_paths.py": ("tests/opa/cli/test_bad_inputs.py",),
    "opa/cli/_validate.py": ("tests/opa/cli/test_bad_inputs.py",),
    "opa/cli/_stochastic.py": ("tests/opa/cli/test_commands.py",),
    "mc/_source.py": ("tests/opa/cli/test_commands.py",),
    "compare/_report.py": ("tests/compare/test_trustmap.py",),
    "compare/_findings.py": ("tests/compare/test_report_sentences.py",
                             "tests/compare/test_trust.py"),
    "compare/_tables.py": ("tests/compare/test_trust.py",),
    "compare/_mapfigures.py": ("tests/compare/test_figures.py", "tests/compare/test_trustmap.py"),
    "compare/_config.py": ("tests/compare/test_trustmap.py",),
    "compare/_mapdata.py": ("tests/compare/test_trustmap.py", "tests/compare/test_trust.py"),
    "compare/_inputs.py": ("tests/compare/test_hostile_inputs.py",),
}

#: what a covering test module must contain to name the source module
NAMED_AS = {
    "opa/_simulate.py": "simulate_dmr",
    "opa/dynamics/_warm_worker.py": "_warm_worker",
    "opa/cli/_main.py": "opa.cli._main",
    "opa/cli/_flags.py": "opa.cli._flags",
    "opa/cli/_args.py": "opa-mc",
    "opa/cli/_paths.py": "--out",
    "opa/cli/_validate.py": "opa.cli._validate",
    "opa/cli/_stochastic.py": "opa-mc stochastic",
    "mc/_source.py": "sweep_source",
    "compare/_report.py": "write_report",
    "compare/_findings.py": "compare._findings",
    "compare/_tables.py": "compare._tables",
    "compare/_mapfigures.py": "compare._mapfigures",
    "compare/_config.py": "load_config",
    "compare/_mapdata.py": "compare._mapdata",
    "compare/_inputs.py": "compare._inputs",
}


def source_modules() -> list[str]:
    return sorted(str(p.relative_to(ROOT)) for package in PACKAGES
                  for p in (ROOT / package).rglob("*.py")
                  if p.name not in ("__init__.py", "__main__.py"))


def mirror(source: str) -> str:
    path = Path(source)
    return str(Path("tests") / path.parent / f"test_{path.stem.removeprefix('_')}.py")


def modules_of_tests() -> list[str]:
    return sorted(str(p.relative_to(ROOT)) for p in TESTS.rglob("test_*.py"))


def test_every_test_folder_is_a_package():
    folders = {p.parent for p in TESTS.rglob("*.py")}
    assert sorted(str(f) for f in folders if not (f / "__init__.py").exists()) == []


def test_every_source_module_has_its_test_module_or_says_where_it_is_tested():
    untested = [s for s in source_modules()
                if not (ROOT / mirror(s)).exists() and s not in TESTED_IN]
    assert untested == [], "add tests/PKG/.../test_NAME.py, or list the module in TESTED_IN"
    for source, tests in TESTED_IN.items():
        assert (ROOT / source).exists(), f"{source} is gone: drop it from TESTED_IN"
        assert not (ROOT / mirror(source)).exists(), f"{source} has {mirror(source)} now"
        for test in tests:
            assert NAMED_AS[source] in (ROOT / test).read_text(), (source, test)


def test_every_test_module_mirrors_a_source_module_or_is_a_theme():
    mirrors = {mirror(s) for s in source_modules()}
    strays = [t for t in modules_of_tests() if t not in mirrors and t not in THEMES]
    assert strays == [], "a test module named after no source module: rename it or list it"
    assert sorted(t for t in THEMES if not (ROOT / t).exists()) == []
