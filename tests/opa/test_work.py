"""The work budget (opa._work): durations, the budget's sources, and refusals before any
work starts, named by keyword in the API and by flag on the CLI."""

import math
import time

import pytest

from mc import simulate_mc
from opa import Oscillator, preset, simulate_dmr, simulate_opa
from opa._run import DEFAULT_MAX_STEPS
from opa._work import (PERIODS_PER_SECOND, WORK_BUDGET_ENV, StepLimitError, WorkBudgetError,
                       _cores, budget, check_steps, check_work, estimate_seconds,
                       oscillator_period, parse_duration, work_budget)
from opa.cli._main import main


@pytest.mark.parametrize("text, seconds", [("90s", 90.0), ("30m", 1800.0), ("12h", 43200.0),
                                           ("2d", 172800.0), ("1.5", 5400.0),
                                           (" 2H ", 7200.0), ("inf", math.inf)])
def test_durations(text, seconds):
    assert parse_duration(text) == seconds


@pytest.mark.parametrize("text", ["0", "-1h", "1y", "", "nan", "h", "1e3h"])
def test_bad_durations_are_refused(text):
    with pytest.raises(ValueError, match="positive duration"):
        parse_duration(text)


def test_the_budget_comes_from_the_flag_then_the_environment_then_the_default(monkeypatch):
    monkeypatch.delenv(WORK_BUDGET_ENV, raising=False)
    assert work_budget() == 4 * 3600.0
    monkeypatch.setenv(WORK_BUDGET_ENV, "30m")
    assert work_budget() == 1800.0
    with budget(60.0):
        assert work_budget() == 60.0
    assert work_budget() == 1800.0
    monkeypatch.setenv(WORK_BUDGET_ENV, "soon")
    with pytest.raises(ValueError, match=WORK_BUDGET_ENV):
        work_budget()


def test_a_job_past_the_budget_is_refused_naming_what_drives_it(monkeypatch):
    monkeypatch.setattr("opa._work.PERIODS_PER_SECOND", 1.0)
    monkeypatch.setattr("opa._work.os.cpu_count", lambda: 1)
    with budget(100.0):
        assert check_work("a job", 99.0, [("samples", 9)]) == 99.0
        with pytest.raises(WorkBudgetError, match=r"a job would integrate about 1e\+02 "
                           r"forcing periods of impact systems \(samples 101\).*about 1[0-9]"
                           r"{2} s on 1 core, more than the work budget of 100 s"):
            check_work("a job", 101.0, [("samples", 101)])


def test_an_adaptive_opa_run_of_100000_periods_is_refused_at_once():
    start = time.perf_counter()
    with pytest.raises(WorkBudgetError, match="periods 100000 x order 4 x elements adaptive"):
        simulate_opa(Oscillator(), sigma=0.01, order=4, periods=100000, elements="adaptive")
    assert time.perf_counter() - start < 5


@pytest.mark.parametrize("argv, flags", [
    (["simulate", "opa", "--periods", "100000", "--elements", "adaptive"],
     ("--periods 100000", "--elements adaptive")),
    (["simulate", "opa", "--omega", "1e-6", "--periods", "1", "--out", "OUT.nc"],
     ("--omega 1e-06", "--periods 1", "step limit of 50000000")),
    (["simulate", "mc", "--periods", "100000", "--samples", "100000"],
     ("--samples 100000", "--periods 100000")),
    (["validate", "--sweep", "omega=3.9:4.3:1000", "--outdir", "OUT"],
     ("--sweep values 1000", "--sigmas 8", "--max-samples 8192", "--horizons 50")),
    (["stochastic", "--sweep", "c=0.0:1.0:100000", "--samples", "1024", "--transient",
      "1000", "--out", "OUT.nc"],
     ("--sweep values 100000", "--samples 1024", "--transient + --record (1000 + 64)")),
    (["bifurcation", "mc", "--sweep", "c=0.0:1.0:100000", "--transient", "10000",
      "--samples", "256", "--out", "OUT.nc"],
     ("--sweep values 100000", "--transient + --record (10000 + 100)", "--samples 256")),
])
def test_the_cli_refuses_at_once_naming_its_flags(argv, flags, tmp_path, capsys):
    argv = [str(tmp_path / a.replace("OUT", "v")) if a.startswith("OUT") else a for a in argv]
    start = time.perf_counter()
    assert main(argv) == 2
    assert not any(tmp_path.iterdir())  # refused before anything is written
    assert time.perf_counter() - start < 20
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    assert all(flag in err for flag in flags), err
    assert "--work-budget" in err


def test_the_cli_budget_flag_lets_the_work_run(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("opa._work.PERIODS_PER_SECOND", 1.0)
    argv = ["simulate", "mc", "--periods", "2", "--samples", "64", "--quiet"]
    assert main(argv + ["--work-budget", "10s"]) == 2  # 128 periods at 1 per second
    assert "more than the work budget of 10 s" in capsys.readouterr().err
    assert main(argv + ["--work-budget", "inf"]) == 0


def test_process_started_reads_the_start_of_the_process_not_now():
    """A process that waits 0.5 s before asking finds its start at least 0.5 s back on the
    perf_counter clock (the /proc clock ticks are 10 ms), and not minutes back."""
    import subprocess
    import sys

    code = ("import time; time.sleep(0.5); from opa._work import process_started; "
            "print(time.perf_counter() - process_started())")
    age = float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                               check=True).stdout)
    assert 0.5 - 0.02 <= age < 60


# ------------------------------------------------------------ slow forcing: time, not periods
def test_below_the_oscillators_frequency_the_estimate_grows_like_one_over_omega():
    """One forcing period at omega = 1e-6 is 6.3e6 time units, each with steps of the
    oscillator's own scale: the estimate of a fixed number of periods grows like 1/omega
    below the oscillator's frequency (sqrt(a) = 0.71 in section 3.2), and is the count of
    periods at the paper's frequencies, as before."""
    seconds = {w: estimate_seconds(1.0, preset("3.2", omega=w)) for w in (1e-4, 1e-5, 1e-6)}
    assert seconds[1e-5] / seconds[1e-4] == pytest.approx(10, rel=1e-3)
    assert seconds[1e-6] / seconds[1e-5] == pytest.approx(10, rel=1e-4)
    assert seconds[1e-6] > 100 * estimate_seconds(1.0)  # the count of periods said 1
    paper = preset("3.2")
    assert 2 * math.pi / paper.omega < oscillator_period(paper)
    assert estimate_seconds(1000.0, paper) == estimate_seconds(1000.0) == pytest.approx(
        1000.0 / PERIODS_PER_SECOND / _cores())


def test_one_slow_dmr_period_at_omega_1e_5_stays_within_the_defaults(monkeypatch):
    """``opa-mc simulate dmr --omega 1e-5 --periods 1`` (about 11 s) is not refused."""
    monkeypatch.delenv(WORK_BUDGET_ENV, raising=False)
    dmr = preset("3.2", omega=1e-5)
    assert check_work("one DMR period", 1.0, [("periods", 1)], oscillator=dmr) < 60
    assert check_steps("one DMR period", 1.0, dmr, DEFAULT_MAX_STEPS,
                       [("periods", 1)]) < DEFAULT_MAX_STEPS / 5


def test_a_budget_past_its_hours_under_slow_forcing_names_the_time(monkeypatch):
    monkeypatch.setattr("opa._work.os.cpu_count", lambda: 1)
    with budget(60.0), pytest.raises(WorkBudgetError, match=r"about 6.3e\+06 time units "
                                     r"of slow forcing .*\(omega 1e-06 x periods 1\)"):
        check_work("a job", 1.0, [("omega", "1e-06"), ("periods", 1)],
                   oscillator=preset("3.2", omega=1e-6))


def test_a_trajectory_past_the_step_limit_is_refused_at_once_by_the_api(monkeypatch):
    """At omega = 1e-6 one forcing period takes more steps than the default step limit:
    the kernel would stop there after minutes (OPA of N = 4: about 9), so both models
    refuse it before any work; more steps, or the budget inf, let it through."""
    monkeypatch.delenv(WORK_BUDGET_ENV, raising=False)
    slow = preset("3.2", omega=1e-6)
    start = time.perf_counter()
    for simulate in (simulate_opa, simulate_dmr, simulate_mc):  # each sample: a trajectory
        with pytest.raises(StepLimitError, match=r"omega 1e-06 x periods 1: 6.3e\+06 time "
                           r"units.*more than the step limit of 50000000.*max_steps"
                           rf".*\${WORK_BUDGET_ENV} inf"):
            simulate(slow, periods=1)
    assert time.perf_counter() - start < 5
    assert check_steps("a run", 1.0, slow, 10 * DEFAULT_MAX_STEPS, []) > DEFAULT_MAX_STEPS
    with budget(math.inf):
        assert check_steps("a run", 1.0, slow, DEFAULT_MAX_STEPS, []) > DEFAULT_MAX_STEPS
    # at the paper's frequencies the forcing bounds the steps: the kernel's limit stops a run
    assert check_steps("a run", 1e6, preset("3.2"), 100, []) == 0.0
