"""The work budget: how long a job would take is estimated before any work starts.

Every command and the API functions behind them count the forcing periods of
deterministic impact systems a job integrates at most (samples x periods x values x
states, split scans and refinements included) and refuse, before starting, a job whose
estimate exceeds the budget. The estimate divides that count by ``PERIODS_PER_SECOND``
per core; it is meant to tell minutes from days, not to time a run.

Slow forcing. The solver's step is bounded by the oscillator's own time scale, not by the
forcing period: at omega = 1e-6 one forcing period is 6.3e6 time units, and the paper's
oscillator (its impulses every 2 pi / omega1 kick the mass off the wall the quasi-static
forcing holds it on) takes about 9 steps and 9 impacts per time unit there, a count of
periods said "1". A job that names its oscillator (``check_work(..., oscillator=)``) is
also counted in time: the time units beyond one oscillator period
(:func:`oscillator_period`, 2 pi / sqrt|a|) per forcing period, at
``TIME_UNITS_PER_SECOND``; the estimate is the larger of the two. One trajectory whose
time under slow forcing would take more steps (``STEPS_PER_TIME_UNIT`` per time unit, the
fewest measured) than the solver's step limit (``SolverOptions.max_steps``) could not be
completed: the kernel would stop it there with a SimulationError, after minutes (one
forcing period at omega = 1e-6: about 3 min for the DMR, 9 for the OPA system of N = 4), so
:func:`check_steps` refuses it up front instead, as a :class:`StepLimitError` naming the
inputs of its length. Runs that stick on the wall most of their time take fewer steps;
the budget ``inf`` lifts this check as it does the others.

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
#: time units of slow forcing one core integrates per second per pair of states (the
#: paper's section 3.2 set at omega = 1e-5 and 1e-6, rtol = atol = 1e-9; the DMR and the
#: OPA system of N = 4 per pair of states); ``NUMBA_NUM_THREADS=1 python -m
#: benchmarks.bench_time_rate`` printed "slowest: 2.95e+04 time units per second; fewest:
#: 9.24 steps per time unit" (DMR 2.95e4 and 3.08e4, OPA 3.25e4 and 3.3e4), rounded down
TIME_UNITS_PER_SECOND = 2.5e4
#: the solver's steps per time unit there (the same run: DMR 9.24, OPA of N = 4 12.7), the
#: fewest, rounded down; at the paper's frequencies a run takes more (13 to 14)
STEPS_PER_TIME_UNIT = 9.0
#: the oscillator's time scale 2 pi / sqrt|a| is taken at |a| >= this (a = 0: 63 time units)
MIN_STIFFNESS = 1e-2
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
    (:meth:`message`). ``time_units``: set where the time under slow forcing, not the
    count of periods, gave the estimate."""

    def __init__(self, what: str, periods: float, drivers: list[tuple[str, object]],
                 seconds: float, limit: float, time_units: float | None = None):
        self.what, self.periods, self.drivers = what, periods, list(drivers)
        self.seconds, self.limit, self.time_units = seconds, limit, time_units
        super().__init__(self.message())

    def message(self, names: dict[str, str] | None = None) -> str:
        """The refusal, each driver named by ``names[keyword]`` where given."""
        amount = (f"{self.periods:.2g} forcing periods" if self.time_units is None else
                  f"{self.time_units:.2g} time units of slow forcing")
        return (f"{self.what} would integrate about {amount} of impact systems "
                f"({_drivers(self.drivers, names)}): about {format_duration(self.seconds)} on "
                f"{_cores()} core{'s' if _cores() > 1 else ''}, more than the work budget of "
                f"{format_duration(self.limit)}; lower one of them, or raise the budget "
                f"with {_flag(names)} (e.g. {_suggest(self.seconds)})")


class StepLimitError(WorkBudgetError):
    """One trajectory that would need more steps than the solver's step limit
    (:func:`check_steps`): refused before any work, as the kernel would stop it there."""

    def __init__(self, what: str, steps: float, max_steps: int,
                 drivers: list[tuple[str, object]], span: float):
        self.steps, self.max_steps, self.span = steps, int(max_steps), span
        super().__init__(what, 0.0, drivers, 0.0, work_budget())

    def message(self, names: dict[str, str] | None = None) -> str:
        more = "" if names else ", or give SolverOptions(max_steps=...) more"
        return (f"{self.what} would take about {self.steps:.2g} solver steps in one "
                f"trajectory ({_drivers(self.drivers, names)}: {self.span:.2g} time units of slow "
                f"forcing "
                f"at about {STEPS_PER_TIME_UNIT:g} steps each), more than the step limit of "
                f"{self.max_steps} where the solver would stop it after minutes of work; "
                f"shorten the run (fewer periods or a larger omega){more}, or lift the check "
                f"with {_flag(names)} inf")


def _drivers(drivers, names) -> str:
    names = names or {}
    return " x ".join(f"{names.get(k, k)} {v}" for k, v in drivers)


def _flag(names) -> str:
    return "--work-budget" if names else f"${WORK_BUDGET_ENV}"


def _cores() -> int:
    return os.cpu_count() or 1


def _suggest(seconds: float) -> str:
    hours = seconds / 3600.0 * 1.5
    return f"{math.ceil(hours)}h" if hours < 48 else f"{math.ceil(hours / 24)}d"


def oscillator_period(oscillator) -> float:
    """The oscillator's own time scale 2 pi / sqrt|a| (|a| at least ``MIN_STIFFNESS``)."""
    return 2.0 * math.pi / math.sqrt(max(abs(float(oscillator.a)), MIN_STIFFNESS))


def slow_time(periods: float, oscillator) -> float:
    """Time units of ``periods`` forcing periods of ``oscillator`` beyond one oscillator
    period each: the time whose steps the forcing does not bound (0 where the forcing is
    faster than the oscillator)."""
    forcing = 2.0 * math.pi / float(oscillator.omega)
    return float(periods) * max(forcing - oscillator_period(oscillator), 0.0)


def estimate_seconds(periods: float, oscillator=None) -> float:
    """Seconds to integrate ``periods`` forcing periods on every core of this machine; of
    ``oscillator``, the larger of that and the time under slow forcing (:func:`slow_time`)
    at ``TIME_UNITS_PER_SECOND``.

    >>> from opa import preset
    >>> round(estimate_seconds(1.0, preset("3.2", omega=1e-5)) * _cores())
    25
    """
    seconds = float(periods) / PERIODS_PER_SECOND
    if oscillator is not None:
        seconds = max(seconds, slow_time(periods, oscillator) / TIME_UNITS_PER_SECOND)
    return seconds / _cores()


def check_work(what: str, periods: float, drivers: list[tuple[str, object]], *,
               oscillator=None) -> float:
    """Refuse (:class:`WorkBudgetError`) a job of ``periods`` forcing periods (of
    ``oscillator``, where given: :func:`estimate_seconds`) whose estimate exceeds the
    budget; returns the estimate in seconds.

    >>> check_work("a small job", 1e4, [("samples", 100), ("periods", 100)]) < 1
    True
    """
    if not (isinstance(periods, (int, float)) and periods >= 0):
        raise ValueError(f"work must be a number of periods >= 0, got {periods!r}")
    seconds = estimate_seconds(periods, oscillator)
    limit = work_budget()
    if seconds > limit:
        slow = None if oscillator is None else slow_time(periods, oscillator)
        timed = slow is not None and slow / TIME_UNITS_PER_SECOND > periods / PERIODS_PER_SECOND
        raise WorkBudgetError(what, float(periods), drivers, seconds, limit,
                              slow if timed else None)
    return seconds


def check_steps(what: str, periods: float, oscillator, max_steps: int,
                drivers: list[tuple[str, object]]) -> float:
    """Refuse (:class:`StepLimitError`) one trajectory of ``periods`` forcing periods of
    ``oscillator`` whose time under slow forcing (:func:`slow_time`, where the steps were
    measured) would take more than ``max_steps`` steps at ``STEPS_PER_TIME_UNIT`` (not
    with the budget ``inf``); returns the estimated steps. At the paper's frequencies the
    forcing bounds the steps and the kernel's own limit is left to stop a run.

    >>> from opa import preset
    >>> check_steps("a run", 1e6, preset("3.2"), 100, [("periods", 10)])
    0.0
    """
    span = slow_time(periods, oscillator)
    steps = span * STEPS_PER_TIME_UNIT
    if steps > max_steps and work_budget() < math.inf:
        raise StepLimitError(what, steps, max_steps, drivers, span)
    return steps


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


__all__ = ["DEFAULT_BUDGET_HOURS", "MIN_STIFFNESS", "PERIODS_PER_SECOND", "STEPS_PER_TIME_UNIT",
           "StepLimitError", "TIME_UNITS_PER_SECOND", "WORK_BUDGET_ENV", "WorkBudgetError",
           "budget", "check_steps", "check_work", "estimate_seconds", "format_duration",
           "oscillator_period", "parse_duration", "process_started", "slow_time",
           "work_budget"]
