"""pytest configuration for the benchmarks: collect ``bench_*.py`` and pick the run size.

``pytest benchmarks`` runs the full benchmarks (1000 forcing periods);
``pytest benchmarks -m "not slow" --benchmark-disable`` (or any run with ``CI=true`` in
the environment) is the smoke mode CI uses: every benchmark body runs once, on 50 periods.
"""

from __future__ import annotations

import os

import pytest

FULL_PERIODS = 1000
SMOKE_PERIODS = 50


def pytest_collect_file(file_path, parent):
    # The project's python_files are the default test_*.py; benchmark modules are named
    # bench_*.py so that the quick suite never picks them up by accident. A file named on
    # the command line is collected by pytest itself whatever its name: not twice.
    if (
        file_path.suffix == ".py"
        and file_path.name.startswith("bench_")
        and not parent.session.isinitpath(file_path)
    ):
        return pytest.Module.from_parent(parent, path=file_path)
    return None


def smoke_mode(config: pytest.Config) -> bool:
    disabled = config.getoption("benchmark_disable") and not config.getoption("benchmark_enable")
    return bool(disabled) or os.environ.get("CI", "").lower() in ("1", "true", "yes")


@pytest.fixture(scope="session")
def periods(request) -> int:
    """Length of the benchmarked trajectory in forcing periods 2 pi / omega."""
    return SMOKE_PERIODS if smoke_mode(request.config) else FULL_PERIODS
