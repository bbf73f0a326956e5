"""Where a map's time goes: exclusive wall and CPU seconds per named phase.

A phase entered inside another pauses it, so every second is charged to exactly one
phase and the phases add up to the time measured around them. CPU seconds are the whole
process's (``time.process_time``: every thread), so CPU / wall of a phase is the number
of cores it kept busy: 1 for a serial phase, up to the thread count for a parallel one.
"""

from __future__ import annotations

import time
from contextlib import contextmanager


class PhaseClock:
    """Exclusive wall and CPU time per phase.

    >>> clock = PhaseClock()
    >>> with clock("outer"):
    ...     with clock("inner"):
    ...         pass
    >>> sorted(clock.calls.items())
    [('inner', 1), ('outer', 1)]
    >>> clock.wall["outer"] >= 0.0 and clock.cpu["inner"] >= 0.0
    True
    """

    def __init__(self):
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self._stack: list[list] = []  # [name, wall at (re)start, cpu at (re)start]

    def _charge(self, entry, wall: float, cpu: float) -> None:
        name = entry[0]
        self.wall[name] = self.wall.get(name, 0.0) + wall - entry[1]
        self.cpu[name] = self.cpu.get(name, 0.0) + cpu - entry[2]

    @contextmanager
    def __call__(self, name: str):
        wall, cpu = time.perf_counter(), time.process_time()
        if self._stack:
            self._charge(self._stack[-1], wall, cpu)
        self._stack.append([name, wall, cpu])
        try:
            yield
        finally:
            wall, cpu = time.perf_counter(), time.process_time()
            self._charge(self._stack.pop(), wall, cpu)
            self.calls[name] = self.calls.get(name, 0) + 1
            if self._stack:
                self._stack[-1][1:] = [wall, cpu]

    def rows(self) -> list[tuple[str, float, float, int]]:
        """(phase, wall, cpu, calls), the longest first."""
        return sorted(((name, self.wall[name], self.cpu[name], self.calls[name])
                       for name in self.wall), key=lambda row: -row[1])

    def attrs(self) -> dict:
        """The table as netCDF attributes: ``phase_names`` (comma-separated),
        ``phase_wall_seconds``, ``phase_cpu_seconds`` and ``phase_calls`` in that order."""
        rows = self.rows()
        return {"phase_names": ",".join(r[0] for r in rows),
                "phase_wall_seconds": [float(r[1]) for r in rows],
                "phase_cpu_seconds": [float(r[2]) for r in rows],
                "phase_calls": [int(r[3]) for r in rows]}


__all__ = ["PhaseClock"]
