"""The phase clock (compare._phases): every second charged to exactly one phase, on a
clock stepped by hand."""

import compare._phases as phases
from compare._phases import PhaseClock


class _Fake:
    """A clock that moves only when told: wall and CPU seconds."""

    def __init__(self):
        self.wall = 0.0
        self.cpu = 0.0

    def step(self, wall, cpu):
        self.wall += wall
        self.cpu += cpu


def test_nested_phases_pause_their_parent(monkeypatch):
    fake = _Fake()
    monkeypatch.setattr(phases.time, "perf_counter", lambda: fake.wall)
    monkeypatch.setattr(phases.time, "process_time", lambda: fake.cpu)
    clock = PhaseClock()
    with clock("map"):
        fake.step(1.0, 1.0)  # serial work of the map itself
        with clock("runs"):
            fake.step(3.0, 6.0)  # two threads busy
        fake.step(0.5, 0.5)
        with clock("runs"):
            fake.step(1.0, 2.0)
    assert clock.wall == {"map": 1.5, "runs": 4.0}
    assert clock.cpu == {"map": 1.5, "runs": 8.0}
    assert clock.calls == {"map": 1, "runs": 2}
    assert clock.rows()[0] == ("runs", 4.0, 8.0, 2)
    attrs = clock.attrs()
    assert attrs["phase_names"] == "runs,map"
    assert attrs["phase_wall_seconds"] == [4.0, 1.5]
    # the phases add up to the time around them
    assert sum(attrs["phase_wall_seconds"]) == fake.wall


def test_a_phase_that_raises_is_still_charged(monkeypatch):
    fake = _Fake()
    monkeypatch.setattr(phases.time, "perf_counter", lambda: fake.wall)
    monkeypatch.setattr(phases.time, "process_time", lambda: fake.cpu)
    clock = PhaseClock()
    try:
        with clock("fails"):
            fake.step(2.0, 2.0)
            raise RuntimeError
    except RuntimeError:
        pass
    assert clock.wall == {"fails": 2.0} and clock.calls == {"fails": 1}
