"""Hard numerics through the real ``opa-mc`` (issue 45, Hardening 4, "hard numerics").

Each case is one command line, run as its own process (``python -m opa.cli``), with small
sizes but numerics that push the solver: runaways (c < 0, huge f or F0, tiny or huge
omega or omega1), an elastic or almost plastic wall (eta = 1, eta tiny), a wall far away
or a start on the wall, chatter and sticking, tolerances at their allowed limits, the
largest order N with each law of xi, the largest sigma each uncertain parameter allows,
many elements, ``--verify`` on a hard case, the stochastic diagram at a chaotic control
value and a bifurcation sweep across a grazing.

The clean outcomes are:

- exit 0, every number of every netCDF file written finite (apart from the documented
  NaN: :func:`opa._dataset.first_non_finite`'s exceptions, and the padding that
  docs/datasets.md documents for the sweeps' sections and the stochastic diagram's
  boundaries and samples), and no NaN or inf on the summary printed on stdout;
- exit 2: one line on stderr naming the flag (bad input);
- exit 3: one line saying why the run could not be completed, nothing written;

never a traceback, always within :data:`TIME_LIMIT`. What a case that is not clean
shows is one of the categories :data:`CATEGORIES`. Every case is independent of the
others, so the cases of one test session run two at a time (threads, each waiting on its
own process).

Run as a script, the module prints the count per category over all cases:
``python -m tests.opa.cli.test_hard_numerics [NAME ...]``. Of the 68 cases, before the
fixes of issue 45, 61 were clean, 1 hung and 6 were silent NaN: ``simulate mc --sampler
gauss`` printed "± nan (SE)" (fixed: the summary says "Gauss quadrature"); five sweeps
and stability runs wrote a min_gap, impact_rate or min_impact_velocity that
docs/datasets.md did not say may be NaN, stability's min_gap as inf (fixed: "none" is
NaN everywhere and each variable's long_name says when, ``NONE`` below). The hang (one
forcing period at omega = 1e-6: 6.3e6 time units, more steps than the solver's limit,
reached after minutes) is refused up front now (exit 2 naming --omega and --periods: the
work budget counts time under slow forcing and the steps of a trajectory, opa._work).

The last tests check that long work shows progress on stderr within seconds (the
stochastic diagram used to say nothing until its first control value was done).
"""

from __future__ import annotations

import os
import re
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

TIME_LIMIT = 60  # seconds per case on a loaded two-core machine (as in test_bad_inputs.py)
PARALLEL = 2  # cases run at a time
CATEGORIES = ("hang", "silent NaN", "traceback", "wrongly accepted", "unnamed culprit",
              "other")

#: documented NaN beyond first_non_finite's: the padding of the bifurcation sweep's
#: sections (docs/datasets.md, "bifurcation sweep") and of the stochastic diagram's
#: boundaries, intervals and samples ("stochastic bifurcation diagram")
PADDED = {
    "bifurcation": ("section_x", "section_v", "impact_phase", "impact_v"),
    "stochastic": ("mc_lyapunov", "mc_x", "mc_v", "boundary_xi", "located_xi",
                   "interval_lo", "interval_hi"),
}

ENV = {**os.environ, "MPLBACKEND": "Agg", "PYTHONWARNINGS": "ignore::DeprecationWarning"}


@dataclass(frozen=True)
class Case:
    """One command line; ``culprits``: what a refusal (exit 2) may name, one of them at
    least; ``refuse``: the input makes no sense, so exit 0 is "wrongly accepted"."""

    name: str
    argv: tuple[str, ...]
    culprits: tuple[str, ...]
    refuse: bool = False
    xfail: str | None = None


@dataclass
class Outcome:
    status: int | None  # None: still running at TIME_LIMIT (killed)
    seconds: float
    out: str
    err: str
    written: list[str] = field(default_factory=list)
    non_finite: str | None = None


#: the commands with their small sizes (--periods, when a case does not give its own)
DMR = ("simulate", "dmr", "--per-period", "4", "--out", "run.nc")
OPA = ("simulate", "opa", "--per-period", "2", "--out", "run.nc")
MC = ("simulate", "mc", "--per-period", "2", "--samples", "64", "--out", "run.nc")
PERIODS = {"dmr": "20", "opa": "10", "mc": "10"}
LAWS = ("semicircle", "uniform", "beta:0.5,0.5", "beta:2,3")


def case(name, base, flags, culprits, **kw) -> Case:
    """A case of ``base`` with ``flags`` (and the base's --periods unless given)."""
    flags = tuple(flags.split())
    if base[0] == "simulate" and "--periods" not in flags:
        flags += ("--periods", PERIODS[base[1]])
    return Case(name, tuple(base) + flags, tuple(culprits.split()), **kw)


#: the quick part (the rest is marked long): about 30 s on two cores, two at a time
QUICK = {"dmr c<0", "mc F0 huge", "opa F0 huge", "dmr eta 1", "opa eta 1 saltation",
         "mc eta 1e-300", "opa start on the wall", "dmr start far", "dmr chatter",
         "opa saltation grazing start", "dmr max-step 1e-300", "opa tightest tolerances",
         "opa omega tiny",
         "mc loosest tolerances", "opa N 500 semicircle", "mc gauss N 500",
         "opa sigma max mu", "opa 256 elements", "stochastic chaotic", "bifurcation grazing"}

CASES = [    # runaways
    case("dmr c<0", DMR, "--c -1 --periods 50", "c"),
    case("opa c<0", OPA, "--c -0.5 --periods 50", "c"),
    case("mc c<0 in part of the ensemble", MC,
         "--c 0.01 --uncertain c --sigma 0.03 --allow-negative --periods 50", "c sigma"),
    case("opa f huge", OPA, "--f 1e6", "f"),
    case("mc F0 huge", MC, "--F0 1e6", "F0"),
    case("dmr omega tiny", DMR, "--omega 1e-5 --periods 1", "omega periods"),
    case("opa omega tiny", OPA, "--omega 1e-6 --periods 1", "omega periods"),
    case("dmr omega huge", DMR, "--omega 6e6 --periods 4", "omega"),
    case("opa omega1 huge", OPA, "--omega1 6e6 --periods 1", "omega1"),
    case("opa F0 huge", OPA, "--F0 1e6", "F0"),
    case("dmr f 1e12", DMR, "--f 1e12", "f"),
    case("opa c<0 in part of the law", OPA,
         "--uncertain c --sigma 0.5 --allow-negative --periods 50", "c sigma"),
    # the wall
    case("dmr eta 1", DMR, "--eta 1 --periods 50", "eta"),
    case("opa eta 1 saltation", OPA, "--eta 1 --impact-law saltation --sigma 0.05", "eta"),
    case("dmr eta tiny", DMR, "--eta 1e-12", "eta"),
    case("mc eta 1e-300", MC, "--eta 1e-300", "eta"),
    case("dmr wall far", DMR, "--delta 1e6", "delta"),
    case("opa wall at 1e300", OPA, "--delta 1e300", "delta"),
    case("opa start on the wall", OPA, "--x0 0 --v0 0", "x0 v0"),
    case("opa start on the wall leaving", OPA, "--x0 0 --v0 -1e-300", "x0 v0"),
    case("dmr start far", DMR, "--x0 -1e150", "x0"),
    case("mc start on the wall, wide sigma", MC, "--x0 0 --v0 0 --sigma 0.5", "x0 sigma"),
    # chatter and sticking
    case("dmr chatter", DMR, "--eta 0.01 --f 50", "eta f"),
    case("opa chatter impulses", OPA, "--eta 0.05 --F0 20 --order 6", "eta F0"),
    case("opa chatter ensemble law", OPA, "--eta 0.01 --f 20 --impact-law ensemble",
         "eta f"),
    case("mc chatter", MC, "--eta 0.01 --f 20", "eta f"),
    case("dmr no chatter limit", DMR, "--chatter-velocity 1e-300 --eta 0.5 --f 20",
         "chatter-velocity chatter_velocity"),
    case("opa everything sticks", OPA, "--chatter-velocity 1e300",
         "chatter-velocity chatter_velocity"),
    case("opa saltation grazing start", OPA, "--x0 0 --v0 -1e-300 --impact-law saltation",
         "x0 v0"),
    case("opa eta tiny saltation", OPA, "--eta 1e-300 --impact-law saltation", "eta"),
    case("opa narrow strong pulses", OPA, "--impulse pulse --pulse-width 1e-9 --F0 1e4",
         "pulse-width pulse_width F0"),
    # step sizes and tolerances at their limits
    case("dmr max-step 1e-300", DMR, "--max-step 1e-300 --periods 1", "max-step max_step"),
    case("opa max-step 1e-7", OPA, "--max-step 1e-7", "max-step max_step"),
    case("dmr tightest tolerances", DMR, "--rtol 1e-15 --atol 1e-15 --periods 10",
         "rtol atol"),
    case("opa tightest tolerances", OPA, "--rtol 1e-15 --atol 1e-15 --order 8", "rtol atol"),
    case("mc loosest tolerances", MC, "--rtol 0.99 --atol 0.99", "rtol atol"),
    case("opa loosest tolerances dp5", OPA, "--rtol 0.99 --atol 0.99 --method dp5",
         "rtol atol"),
    # the largest order with each law of xi
    *[case(f"opa N 500 {law}", OPA, f"--order 500 --distribution {law} --periods 1",
           "order N distribution") for law in LAWS],
    *[case(f"mc N 500 {law}", MC, f"--order 500 --distribution {law}", "order N distribution")
      for law in LAWS],
    case("mc gauss N 500", MC, "--order 500 --sampler gauss", "order N sampler"),
    # the largest sigma of each uncertain parameter
    case("opa sigma max mu", OPA, "--uncertain mu --sigma 0.8", "sigma"),
    case("opa sigma max a", OPA, "--uncertain a --sigma 0.5", "sigma"),
    case("opa sigma max c", OPA, "--uncertain c --sigma 0.05", "sigma"),
    case("mc sigma max a uniform", MC, "--uncertain a --sigma 0.5 --distribution uniform",
         "sigma"),
    # many elements
    case("opa 256 elements", OPA, "--elements 256 --order 2 --sigma 0.3", "elements"),
    case("opa adaptive 256", OPA, "--elements adaptive --max-elements 256 "
         "--element-tolerance 1e-12 --sigma 0.3", "elements max-elements"),
    case("opa 64 elements beta", OPA, "--elements 64 --sigma 0.8 "
         "--distribution beta:0.5,0.5", "elements"),
    # a certificate on a hard case
    case("opa verify chatter", OPA, "--verify 64 --verify-max 64 --eta 0.05 --f 20 "
         "--sigma 0.3", "verify eta"),
    case("opa verify chatter, doubling", OPA, "--verify 64 --eta 0.05 --f 20 --sigma 0.3",
         "verify verify-max eta"),
    case("opa adaptive chatter", OPA, "--elements adaptive --eta 0.01 --f 20 --sigma 0.3",
         "elements eta"),
    case("mc gauss chatter", MC, "--sampler gauss --eta 0.01 --f 20 --sigma 0.3",
         "sampler eta"),
    case("opa N 500 sigma max", OPA, "--order 500 --sigma 0.8 --periods 1", "order sigma"),
    case("mc sigma max mu beta", MC, "--sigma 0.8 --distribution beta:0.5,0.5",
         "sigma distribution"),
    # the stochastic diagram where the motion is chaotic, a sweep across a grazing
    case("stochastic chaotic", ("stochastic", "--out", "run.nc"),
         "--preset 3.1 --F0 0 --sweep c=0.02 --samples 32 --transient 200 --record 32 "
         "--extra-states 0 --workers 1", "c"),
    case("stochastic chaotic with the EMR", ("stochastic", "--out", "run.nc"),
         "--preset 3.1 --F0 0 --sweep c=0.02,0.025 --samples 16 --transient 100 --record 16 "
         "--extra-states 1 --coexist 4 --emr --emr-order 8 --workers 2", "c"),
    case("stochastic at a grazing, sigma max a", ("stochastic", "--out", "run.nc"),
         "--preset 3.3 --F0 0 --sweep omega=5.7052 --uncertain a --sigma 3.5 "
         "--samples 16 --transient 100 --record 16 --extra-states 0 --workers 1", "sigma a"),
    case("stability chaotic", ("stability", "dmr", "--out", "run.nc"),
         "--preset 3.1 --F0 0 --c 0.02 --lyapunov", "c"),
    case("stability opa grazing", ("stability", "opa", "--out", "run.nc"),
         "--preset 3.3 --F0 0 --omega 5.7052 --sigma 0.1 --orbit-periods 2", "omega"),
    case("bifurcation opa grazing", ("bifurcation", "opa", "--out", "run.nc"),
         "--preset 3.3 --F0 0 --sigma 0.1 --sweep omega=5.69:5.72:3 --transient 100 "
         "--record 20 --workers 2", "omega sigma"),
    case("stability opa chaotic", ("stability", "opa", "--out", "run.nc"),
         "--preset 3.1 --F0 0 --c 0.02 --sigma 0.03 --lyapunov", "c sigma"),
    case("bifurcation mc grazing", ("bifurcation", "mc", "--out", "run.nc"),
         "--preset 3.3 --F0 0 --sigma 0.1 --samples 16 --sweep omega=5.69:5.72:3 "
         "--transient 100 --record 20 --workers 2", "omega sigma"),
    case("bifurcation grazing", ("bifurcation", "dmr", "--out", "run.nc"),
         "--preset 3.3 --F0 0 --sweep omega=5.69:5.72:4 --transient 100 --record 20 "
         "--workers 2", "omega"),
]


def run_case(c: Case, folder: Path, limit: float = TIME_LIMIT) -> Outcome:
    """Run ``opa-mc`` with the case's flags in ``folder``; kill its process group at
    ``limit`` seconds."""
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "opa.cli", *c.argv], cwd=folder, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=limit)
        status = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        status = None
    outcome = Outcome(status, time.perf_counter() - start, out, err)
    outcome.written = sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))
    if status == 0:
        outcome.non_finite = _non_finite(folder, c.argv[0])
    return outcome


#: documented "none" (docs/datasets.md, the variables' long_name): a motion's minimum over
#: no event is NaN; the Monte Carlo mean has no impact record, so its impact rate is NaN
NONE = {"bifurcation": ("min_gap", "min_impact_velocity"),
        "stability": ("min_gap", "min_impact_velocity")}


#: the cases run two at a time in threads, and the netCDF/HDF5 libraries are not
#: thread-safe (two reads at once crashed the process): one read at a time
_READ = threading.Lock()


def _non_finite(folder: Path, command: str) -> str | None:
    with _READ:
        return _non_finite_locked(folder, command)


def _non_finite_locked(folder: Path, command: str) -> str | None:
    import xarray as xr

    from opa._dataset import first_non_finite

    for path in sorted(folder.rglob("*.nc")):
        with xr.open_dataset(path) as ds:
            documented = PADDED.get(command, ()) + NONE.get(command, ()) + (
                ("impact_rate",) if command == "bifurcation" and ds.attrs.get("model") == "mc"
                else ())
            for name in NONE.get(command, ()):
                if name in ds and np.isinf(ds[name].values).any():
                    return f"{path.name}: {name} holds inf, not the documented NaN"
            ds = ds.drop_vars([v for v in documented if v in ds])
            found = first_non_finite(ds)
            if found:
                return f"{path.name}: {found[1]} values of {found[0]} not finite"
    return None


_NAN = re.compile(r"(?<![\w-])[-+]?(nan|inf)\b", re.IGNORECASE)


def flaw(c: Case, o: Outcome) -> tuple[str, str] | None:
    """(category, what happened) of an outcome that is not clean; None when clean."""
    lines = [line for line in o.err.splitlines() if line.strip() and "%|" not in line]
    said = f"exit {o.status} after {o.seconds:.1f} s: {' | '.join(lines)[-300:]!r}"
    if o.status is None or o.seconds > TIME_LIMIT:
        return "hang", f"still running after {o.seconds:.0f} s"
    if "Traceback" in o.err or o.status not in (0, 2, 3):
        return "traceback", said
    if o.status == 0:
        if c.refuse:
            return "wrongly accepted", said
        if o.non_finite:
            return "silent NaN", o.non_finite
        if _NAN.search(o.out):
            return "silent NaN", f"printed: {o.out!r}"
        return None
    errors = [line for line in lines if line.startswith("opa-mc")]
    if len(errors) != 1:
        return "other", f"expected one line, got {said}"
    if o.status == 2 and not any(re.search(rf"(?<![\w-])(--)?{re.escape(n)}(?![\w-])",
                                           errors[0]) for n in c.culprits):
        return "unnamed culprit", f"none of {c.culprits} in {errors[0]!r}"
    if o.status == 3 and any(w.endswith(".nc") or w.endswith(".parts") for w in o.written):
        return "other", f"exit 3 but left {o.written}"
    return None


def _params():
    out = []
    for c in CASES:
        marks = []
        if c.name not in QUICK:
            marks.append(pytest.mark.long)
        if c.xfail:
            marks.append(pytest.mark.xfail(strict=True, reason=c.xfail))
        out.append(pytest.param(c, id=c.name, marks=marks))
    return out


def run_all(cases, parallel: int = PARALLEL) -> dict[str, Outcome]:
    """Outcomes of ``cases`` by name, ``parallel`` at a time, each in a fresh folder."""

    def one(c):
        with tempfile.TemporaryDirectory(prefix="opa-mc-hard-") as folder:
            return c.name, run_case(c, Path(folder))

    with ThreadPoolExecutor(parallel) as pool:
        return dict(pool.map(one, cases))


@pytest.fixture(scope="module")
def outcomes(request):
    """The outcomes of the cases this session selected, run together (two at a time)."""
    names = {item.callspec.params["c"].name for item in request.session.items
             if getattr(getattr(item, "module", None), "__name__", None) == __name__
             and hasattr(item, "callspec")
             and "c" in item.callspec.params}
    return run_all([c for c in CASES if c.name in names])


@pytest.mark.parametrize("c", _params())
def test_hard_numerics_end_cleanly(c, outcomes):
    found = flaw(c, outcomes[c.name])
    assert found is None, f"opa-mc {' '.join(c.argv)}: [{found[0]}] {found[1]}"


def report(results: dict[str, Outcome]) -> str:
    counts = dict.fromkeys(CATEGORIES, 0)
    lines = []
    for c in CASES:
        if c.name not in results:
            continue
        o = results[c.name]
        found = flaw(c, o)
        if found:
            counts[found[0]] += 1
        lines.append(f"{o.seconds:5.1f} s  exit {o.status}  {c.name}: "
                     + (f"[{found[0]}] {found[1]}" if found else "clean"))
    clean = len(results) - sum(counts.values())
    lines.append(f"{len(results)} cases: {clean} clean, " + ", ".join(
        f"{k} {v}" for k, v in counts.items()))
    return "\n".join(lines)


if __name__ == "__main__":
    chosen = [c for c in CASES if not sys.argv[1:] or any(a in c.name for a in sys.argv[1:])]
    print(report(run_all(chosen)))


# --------------------------------------------------- long work shows progress within seconds
PROGRESS_LIMIT = 5.0  # seconds from the process start to the first output on stderr

#: commands that run a minute or more on two cores (issue 45, item 5)
LONG_WORK = {
    "simulate mc": ["simulate", "mc", "--samples", "20000", "--periods", "300"],
    "bifurcation": ["bifurcation", "dmr", "--sweep", "c=0.01:0.1:200", "--transient", "500",
                    "--record", "100", "--workers", "2"],
    "stochastic": ["stochastic", "--preset", "3.1", "--F0", "0", "--sweep", "c=0.02:0.03:4",
                   "--samples", "4096", "--workers", "2"],
    "validate": ["validate", "--outdir", "map"],
}


def first_output(argv, folder, wait: float = 30.0) -> tuple[float | None, str]:
    """Seconds from the start of ``opa-mc argv`` to its first bytes on stderr (None: none
    within ``wait``), and those bytes; the process group is killed then."""
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "opa.cli", *argv], cwd=folder, env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        ready, _, _ = select.select([proc.stderr], [], [], wait)
        seconds = time.perf_counter() - start if ready else None
        text = os.read(proc.stderr.fileno(), 4096).decode(errors="replace") if ready else ""
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stderr.close()
    return seconds, text


@pytest.mark.long
@pytest.mark.parametrize("command", sorted(LONG_WORK))
def test_long_work_shows_progress_within_seconds(command, tmp_path):
    seconds, text = first_output(LONG_WORK[command], tmp_path)
    assert seconds is not None, f"opa-mc {command}: nothing on stderr within 30 s"
    assert "Traceback" not in text and "error" not in text, text
    assert seconds < PROGRESS_LIMIT, f"opa-mc {command}: first output after {seconds:.1f} s"


def test_the_stochastic_diagram_says_what_it_computes_before_the_first_value():
    """The quick check of the fix above: the first log line comes before any value is
    done (it used to be the first value's line, after its whole computation)."""
    from opa import Execution, preset
    from opa.dynamics._stochastic import stochastic_diagram

    lines = []
    stochastic_diagram(preset("3.1", F0=0.0), "c", [0.04, 0.05], sigma=0.03, samples=8,
                       extra_states=0, transient=100, record=16,
                       execution=Execution(log=lines.append))
    assert lines[0] == ("computing 2 of 2 values of c (8 samples each) on 1 worker "
                        "process; a line as each is done"), lines
    assert [line[:4] for line in lines[1:]] == ["1/2 ", "2/2 "], lines


def test_a_run_stopped_at_the_default_step_cap_is_not_called_a_runaway():
    """One forcing period at omega = 1e-6 (6.3e6 time units) needs more than the 50
    million default steps: the runaway guard's allowance is the cap itself there, so the
    run did not stop early and its state did not run away. It used to be told so ("the
    step size collapsed ... check the signs of a and c"); a guard below the cap still
    is."""
    from opa import _kernel as kernel
    from opa._run import DEFAULT_MAX_STEPS, _failure

    times = np.array([0.0, 6.3e6])
    out = np.array([[-1.0, 0.0], [np.nan, np.nan]])
    z = np.array([0.5, 0.1])
    at_cap = _failure("DMR trajectory", kernel.MAX_STEPS, out, times, z, DEFAULT_MAX_STEPS,
                      12_878_382, DEFAULT_MAX_STEPS)
    assert "runaway" not in at_cap and "maximum number of steps" in at_cap, at_cap
    guarded = _failure("DMR trajectory", kernel.MAX_STEPS, out, times, z, 200_000, 3,
                       200_000)
    assert "runaway guard" in guarded, guarded
