"""What a piece of the trust map's work did: the ledger each task returns.

Every task of the map (a split scan, a grid point, a horizon's bisections, a value, a run
of the frontier) works in a :class:`Work` of its own: the parts folder, the phase clock,
its counts and its caches, none shared with another task. At its end it returns
``work.ledger()``, a frozen :class:`Ledger`; the main process adds the ledgers up
(``sum(ledgers, Ledger())``) and writes the total to the map's attributes. No task
changes another's counts, and nothing outside a task changes its own.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from compare._phases import PhaseClock
from opa.engine import Store

#: the counts a ledger keeps, and the map attribute each is written to
COUNTS = {
    "mc_runs": "mc_runs_computed",  # Monte Carlo ensembles run (one per round computed)
    "true_runs": "true_runs_computed",  # their true sampled systems
    "true_periods": "true_periods_computed",  # forcing periods those integrated
    "opa_runs": "opa_runs_computed",  # OPA parts computed (single- and multi-element)
    "parts_computed": "parts_computed",  # parts written to the store
    "parts_set_aside": "parts_set_aside",  # damaged parts moved aside
    "system_runs": "true_system_runs",  # every true impact system, the kernel's count
    "system_time": "true_system_time",  # the time units they integrated
}


@dataclass(frozen=True)
class Ledger:
    """Counts of work and the phase table (phase -> (wall s, CPU s, calls)); ledgers add.

    >>> a = Ledger(mc_runs=1, phases={"split scans": (1.0, 2.0, 1)})
    >>> b = Ledger(mc_runs=2, true_runs=64, phases={"split scans": (0.5, 0.5, 1)})
    >>> total = a + b
    >>> total.mc_runs, total.true_runs, total.phases["split scans"]
    (3, 64, (1.5, 2.5, 2))
    """

    mc_runs: int = 0
    true_runs: int = 0
    true_periods: float = 0.0
    opa_runs: int = 0
    parts_computed: int = 0
    parts_set_aside: int = 0
    system_runs: int = 0
    system_time: float = 0.0
    phases: dict = field(default_factory=dict)

    def __add__(self, other: Ledger) -> Ledger:
        if not isinstance(other, Ledger):
            return NotImplemented
        counts = {name: getattr(self, name) + getattr(other, name) for name in COUNTS}
        phases = dict(self.phases)
        for name, row in other.phases.items():
            mine = phases.get(name, (0.0, 0.0, 0))
            phases[name] = (mine[0] + row[0], mine[1] + row[1], mine[2] + row[2])
        return Ledger(**counts, phases=phases)

    def attrs(self) -> dict:
        """The map's attributes of this work: the counts (``COUNTS``) and the phase table
        (as :meth:`compare._phases.PhaseClock.attrs`, the longest first)."""
        rows = sorted(self.phases.items(), key=lambda item: -item[1][0])
        out = {attr: getattr(self, name) for name, attr in COUNTS.items()}
        out.update({"phase_names": ",".join(name for name, _ in rows),
                    "phase_wall_seconds": [float(row[0]) for _, row in rows],
                    "phase_cpu_seconds": [float(row[1]) for _, row in rows],
                    "phase_calls": [int(row[2]) for _, row in rows]})
        return out


class Work:
    """One task's context: the map's parts folder (:class:`opa.engine.Store`), its phase
    clock, its counts, its log, and its caches (a value's split scan, read back once;
    the last ensemble run at a point, which the next round extends). Made fresh for each
    task and never shared; :meth:`ledger` is what the task returns."""

    def __init__(self, outdir: str, *, log=None, bar=None):
        self.log = log if log is not None else (lambda line: None)
        # what a point says of its runs (a point computed ahead of its value's task says
        # nothing: the value's task reads it back and says it, as in one process)
        self.point_log = self.log
        self.parts = Store(os.path.join(outdir, "parts"), "trust map", log=self.log)
        self.clock = PhaseClock()
        self.counts = dict.fromkeys(COUNTS, 0)
        self.scans: dict = {}  # value -> (centre, its split scan)
        self.ensembles: dict = {}  # (value, sigma, outputs) -> the last ensemble there
        self.bar = bar  # a progress bar whose postfix counts the bisection probes
        self.probes = 0

    def count(self, **counts) -> None:
        """Add to this task's counts (names of ``COUNTS``)."""
        for name, value in counts.items():
            self.counts[name] += value

    def timed(self, phase: str, compute):
        """``compute`` with its time charged to ``phase``."""
        def timed():
            with self.clock(phase):
                return compute()
        return timed

    def tick(self) -> None:
        """One more bisection probe: counted beside the bar (its total stays the grid's
        points, which are known up front; the probes are found as the bisection goes)."""
        self.probes += 1
        if self.bar is not None:
            self.bar.set_postfix(probes=self.probes)

    def ledger(self, system: tuple[int, float] = (0, 0.0)) -> Ledger:
        """What this task did: its counts, its store's parts, its phase table, and
        ``system``: the true impact systems it integrated (runs, time;
        :func:`opa.engine.true_system_work`, read by the caller around the task)."""
        counts = {**self.counts, "parts_computed": self.parts.computed,
                  "parts_set_aside": self.parts.set_aside,
                  "system_runs": int(system[0]), "system_time": float(system[1])}
        phases = {name: (wall, cpu, calls) for name, wall, cpu, calls in self.clock.rows()}
        return Ledger(**counts, phases=phases)


__all__ = ["COUNTS", "Ledger", "Work"]
