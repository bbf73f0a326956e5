"""The work budget: how long a job would take is estimated before any work starts.

Every command and the API functions behind them count the forcing periods of
deterministic impact systems a job integrates at most (samples x periods x values x
states, split scans and refinements included) and refuse, before starting, a job whose
estimate exceeds the budget. The estimate divides that count by ``PERIODS_PER_SECOND``
per core; it is meant to tell minutes from days, not to time a run.

The budget is ``DEFAULT_BUDGET_HOURS`` unless ``$OPA_MC_WORK_BUDGET`` (``"30m"``,
``"12h"``, ``"2d"``, or a number of hours) or the CLI's ``--work-budget`` sets another;
``"inf"`` turns the check off.

A job's time as measured starts where its process started (:func:`process_started`), so
that the wall time a command reports includes its imports.
"""

from __future__ import annotations

import math
import os
import re
from contextlib import contextmanager
from contextvars import ContextVar

WORK_BUDGET_ENV = "OPA_MC_WORK_BUDGET"
DEFAULT_BUDGET_HOURS = 4.0
#: forcing periods of one deterministic system (the paper's, rtol = atol = 1e-9) that one
#: core integrates per second; measured with ``python -m benchmarks.bench_work_rate``
PERIODS_PER_SECOND = 1.0e5
_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0, "": 3600.0}
_OVERRIDE: ContextVar[float | None] = ContextVar("work_budget", default=None)


def parse_duration(text) -> float:
    """Seconds from ``"90s"``, ``"30m"``, ``"12h"``, ``"2d"``, ``"inf"`` or a number of hours.

    >>> parse_duration("30m"), parse_duration("1.5"), parse_duration("inf")
    (1800.0, 5400.0, inf)
    """
    match = re.fullmatch(r"\s*(inf|\d+(?:\.\d*)?|\.\d+)\s*([smhd]?)\s*", str(text).lower())
    if match is None or (match[1] != "inf" and float(match[1]) <= 0):
        raise ValueError(f"a work budget is a positive duration such as 30m, 12h, 2d or inf "
                         f"(a bare number is hours), got {text!r}")
    return math.inf if match[1] == "inf" else float(match[1]) * _UNITS[match[2]]


def work_budget() -> float:
    """The budget in seconds: the CLI's ``--work-budget`` (:func:`budget`), else
    ``$OPA_MC_WORK_BUDGET``, else ``DEFAULT_BUDGET_HOURS``."""
    override = _OVERRIDE.get()
    if override is not None:
        return override
    text = os.environ.get(WORK_BUDGET_ENV, "").strip()
    if text:
        try:
            return parse_duration(text)
        except ValueError as err:
            raise ValueError(f"{WORK_BUDGET_ENV}: {err}") from None
    return DEFAULT_BUDGET_HOURS * 3600.0


@contextmanager
def budget(seconds: float | None):
    """The work budget within the block (None: unchanged)."""
    token = _OVERRIDE.set(seconds) if seconds is not None else None
    try:
        yield
    finally:
        if token is not None:
            _OVERRIDE.reset(token)


def format_duration(seconds: float) -> str:
    """``"40 s"``, ``"12 min"``, ``"3.1 h"``, ``"26 days"``.

    >>> format_duration(45), format_duration(720), format_duration(3 * 86400)
    ('45 s', '12 min', '3 days')
    """
    if seconds < 300:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.2g} h"
    return f"{seconds / 86400:.2g} days"


class WorkBudgetError(ValueError):
    """A job whose estimate exceeds the work budget. ``drivers``: (keyword, value) of the
    inputs the cost grows with, as the API names them; the CLI names its flags instead
    (:meth:`message`)."""

    def __init__(self, what: str, periods: float, drivers: list[tuple[str, object]],
                 seconds: float, limit: float):
        self.what, self.periods, self.drivers = what, periods, list(drivers)
        self.seconds, self.limit = seconds, limit
        super().__init__(self.message())

    def message(self, names: dict[str, str] | None = None) -> str:
        """The refusal, each driver named by ``names[keyword]`` where given."""
        names = names or {}
        drivers = " x ".join(f"{names.get(k, k)} {v}" for k, v in self.drivers)
        flag = "--work-budget" if names else f"${WORK_BUDGET_ENV}"
        return (f"{self.what} would integrate about {self.periods:.2g} forcing periods of "
                f"impact systems ({drivers}): about {format_duration(self.seconds)} on "
                f"{_cores()} core{'s' if _cores() > 1 else ''}, more than the work budget of "
                f"{format_duration(self.limit)}; lower one of them, or raise the budget "
                f"with {flag} (e.g. {_suggest(self.seconds)})")


def _cores() -> int:
    return os.cpu_count() or 1


def _suggest(seconds: float) -> str:
    hours = seconds / 3600.0 * 1.5
    return f"{math.ceil(hours)}h" if hours < 48 else f"{math.ceil(hours / 24)}d"


def estimate_seconds(periods: float) -> float:
    """Seconds to integrate ``periods`` forcing periods on every core of this machine."""
    return float(periods) / (PERIODS_PER_SECOND * _cores())


def check_work(what: str, periods: float, drivers: list[tuple[str, object]]) -> float:
    """Refuse (:class:`WorkBudgetError`) a job of ``periods`` forcing periods whose
    estimate exceeds the budget; returns the estimate in seconds.

    >>> check_work("a small job", 1e4, [("samples", 100), ("periods", 100)]) < 1
    True
    """
    if not (isinstance(periods, (int, float)) and periods >= 0):
        raise ValueError(f"work must be a number of periods >= 0, got {periods!r}")
    seconds = estimate_seconds(periods)
    limit = work_budget()
    if seconds > limit:
        raise WorkBudgetError(what, float(periods), drivers, seconds, limit)
    return seconds


def process_started() -> float:
    """The ``time.perf_counter()`` reading at which this process started (Linux: from
    /proc; elsewhere: now), so that a command's wall time includes its imports."""
    import time

    now = time.perf_counter()
    try:
        with open("/proc/self/stat") as fh:
            ticks = int(fh.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as fh:
            uptime = float(fh.read().split()[0])
        age = uptime - ticks / os.sysconf("SC_CLK_TCK")
        return now - age if 0 <= age < 1e6 else now
    except (OSError, ValueError, IndexError):
        return now


__all__ = ["DEFAULT_BUDGET_HOURS", "PERIODS_PER_SECOND", "WORK_BUDGET_ENV", "WorkBudgetError",
           "budget", "check_work", "estimate_seconds", "format_duration", "parse_duration",
           "process_started", "work_budget"]
