"""A hostile-input corpus for the stochastic bifurcation diagram (issue 45, Hardening 4):
``opa-mc stochastic`` (opa/cli/_stochastic.py) and ``stochastic_diagram``
(opa/dynamics/_stochastic.py).

Every flag of ``opa-mc stochastic --help`` gets values that are zero, negative, NaN, inf,
huge, non-numeric, empty or of the wrong kind; flags that make no sense together (a flag
without effect in the combination, ``--coexist`` above ``--samples``, the swept
parameter also given as a model flag, unsorted values under ``--emr`` or ``--plot``, a
sigma that makes the uncertain parameter negative or that double precision cannot
resolve); output paths that cannot be written. A refusal is exit status 2 and one line on
stderr naming the flag (a model or solver parameter handled by the shared ``Oscillator``
and ``SolverOptions`` checks is named as the keyword, ``eta``, ``rtol``), never a
traceback, never a hint at a flag ``opa-mc stochastic`` does not have, and nothing left
on disk. The API's keywords get the wrong types (bools for integers, numpy arrays,
strings, None) and values: one ``ValueError`` naming the keyword. Accepted runs are read
back: probabilities finite and summing to 1 at every control value, and no NaN where
docs/datasets.md does not document one (``mc_lyapunov`` and the padded ``mc_x``,
``mc_v``, ``boundary_*``, ``located_*``, ``interval_*`` may hold NaN; without samples the
Monte Carlo variables are not estimated: ``agree`` is -1).

The work budget (``--work-budget``, opa/_work.py) and the scheduler address check are
not duplicated here; a few cases confirm that they refuse naming the flag.

Each case's first field says what it found before the fixes of issue 45 ("held": it
passed already): ``traceback`` (an internal error or an exception other than
ValueError), ``wrongly accepted``, ``unnamed culprit``, ``silent NaN`` (or a dataset whose
probabilities are not a distribution), ``other`` (a hint at a flag this command does not
have, a refusal only after the work was done, a parts folder left by a refusal). Before
the fixes 115 of the 278 cases were not clean: CLI 58 of 155 (1 traceback, 16 wrongly
accepted, 35 unnamed culprits, 5 silent NaN or empty probabilities, 1 other), API 57 of
123 (20 tracebacks, 19 wrongly accepted, 12 unnamed culprits, 1 silent NaN, 5 other).
"""

from __future__ import annotations

import contextlib
import inspect
import os
import re
import time

import numpy as np
import pytest
import xarray as xr

from opa import SolverOptions, System, preset
from opa.cli._main import build_parser, main
from opa.dynamics._stochastic import stochastic_diagram
from tests.opa.cli.test_bad_inputs import Timeout, time_bound

TIME_LIMIT = 30  # seconds: a refusal comes before any long computing
QUICK = 5  # seconds a refused case may take (numba's first compile aside)

SECTION_31 = preset("3.1", F0=0.0)
#: the smallest diagram that still continues a doubling (c = 0.04: 2/2 and 4/4)
BASE = {"--preset": "3.1", "--F0": "0", "--sweep": "c=0.04", "--samples": "0",
        "--extra-states": "0", "--transient": "200", "--record": "16", "--workers": "1"}
API_BASE = dict(sigma=0.03, samples=0, extra_states=0, transient=200, record=16)




def argv(case: str) -> list[str]:
    """``opa-mc stochastic`` with BASE's flags, those named in ``case`` replaced (a
    ``-FLAG`` token drops one of BASE's flags without replacing it)."""
    tokens = case.split(" ") if case else []
    named = {t.split("=")[0] for t in tokens if t.startswith("--")}
    dropped = {t[1:] for t in tokens if t.startswith("---")}
    tokens = [t for t in tokens if not t.startswith("---")]
    out = ["stochastic"]
    for flag, value in BASE.items():
        if flag not in named and flag not in dropped:
            out += [flag, value]
    return out + ["--quiet"] + tokens


def _flags() -> set[str]:
    sub = next(a for a in build_parser()._actions if a.__class__.__name__ ==
               "_SubParsersAction")
    return {s for a in sub.choices["stochastic"]._actions for s in a.option_strings}


FLAGS = _flags()
KEYWORDS = set(inspect.signature(stochastic_diagram).parameters)


def run_cli(args: list[str]):
    """(exit status or 'traceback: ...', stderr, seconds) of ``opa-mc args``."""
    start = time.perf_counter()
    err = ""
    with contextlib.redirect_stderr(_Capture()) as captured, \
            contextlib.redirect_stdout(_Capture()):
        try:
            with time_bound(TIME_LIMIT):
                status = main(args)
        except SystemExit as exc:  # argparse
            status = exc.code
        except Timeout:
            status = "timeout"
        except Exception as exc:  # noqa: BLE001 -- the corpus records it
            status = f"traceback: {type(exc).__name__}: {exc}"
        err = captured.getvalue()
    return status, err, time.perf_counter() - start


class _Capture(list):
    def write(self, text):
        self.append(text)

    def flush(self):
        pass

    def getvalue(self):
        return "".join(self)


def cli_flaw(status, err: str, names, seconds: float, left: list[str]) -> str | None:
    """What is wrong with a refusal, tagged with its kind; None when it is clean."""
    lines = [line for line in err.splitlines() if line.strip()]
    if status == "timeout" or status == 0:
        return f"[wrongly accepted] exit {status}, stderr {err!r}"
    if isinstance(status, str) or status == 1 or "Traceback" in err:
        return f"[traceback] {status}: {err!r}"
    if status != 2:
        return f"[other] exit {status}: {err!r}"
    if len(lines) != 1:
        return f"[other] expected one line, got {lines}"
    for name in (names if isinstance(names, tuple) else (names,)):
        if name not in lines[0]:
            return f"[unnamed culprit] {name!r} not named in {lines[0]!r}"
    foreign = sorted(set(re.findall(r"--[A-Za-z][\w-]*", lines[0])) - FLAGS)
    if foreign:
        return f"[other] hints at {foreign}, not flags of opa-mc stochastic: {lines[0]!r}"
    if left:
        return f"[other] a refused run left {left}"
    if seconds > QUICK:
        return f"[other] refused only after {seconds:.1f} s: {lines[0]!r}"
    return None


# --------------------------------------------------------------------- CLI: refusals
# (kind before the fixes, the flags after BASE, what the one line must name)
BAD_CLI = [
    # --sigma
    ("unnamed culprit", "--sigma 0", "--sigma"),
    ("unnamed culprit", "--sigma -0.1", "--sigma"),
    ("unnamed culprit", "--sigma nan", "--sigma"),
    ("unnamed culprit", "--sigma inf", "--sigma"),
    ("unnamed culprit", "--sigma -inf", "--sigma"),
    ("held", "--sigma abc", "--sigma"),
    ("held", "--sigma=", "--sigma"),
    ("unnamed culprit", "--sigma 1e300", "--sigma"),
    ("unnamed culprit", "--sigma 5", ("--sigma", "mu")),
    ("wrongly accepted", "--sigma 1e-320", "--sigma"),
    ("wrongly accepted", "--sigma 1e-300", "--sigma"),
    ("wrongly accepted", "--sigma 1e-17", "--sigma"),
    # --uncertain, and sigma beyond the uncertain parameter's range
    ("held", "--uncertain a1", "--uncertain"),
    ("held", "--uncertain=", "--uncertain"),
    ("held", "--uncertain MU", "--uncertain"),
    ("held", "--uncertain x0", "--uncertain"),
    ("unnamed culprit", "--uncertain a --sigma 2", ("--sigma", "a")),
    ("unnamed culprit", "--uncertain c --sigma 1 --sweep mu=0.8", ("--sigma", "c")),
    ("unnamed culprit", "--uncertain c --c 0 --sweep mu=0.8", ("--sigma", "c = 0")),
    ("held", "--preset 9.9", "--preset"),
    # --distribution
    ("unnamed culprit", "--distribution foo", ("--distribution", "foo")),
    ("unnamed culprit", "--distribution=", "--distribution"),
    ("unnamed culprit", "--distribution beta:0,1", "--distribution"),
    ("unnamed culprit", "--distribution beta:nan,2", "--distribution"),
    ("unnamed culprit", "--distribution beta:2", "--distribution"),
    ("unnamed culprit", "--distribution beta:2,3,4", "--distribution"),
    ("unnamed culprit", "--distribution beta:1e6,1e6", "--distribution"),
    ("unnamed culprit", "--distribution normal-trunc:0", "--distribution"),
    ("unnamed culprit", "--distribution normal-trunc:-1", "--distribution"),
    ("unnamed culprit", "--distribution normal-trunc:inf", "--distribution"),
    ("unnamed culprit", "--distribution normal-trunc:1e6", "--distribution"),
    ("unnamed culprit", "--distribution uniform:3", "--distribution"),
    ("unnamed culprit", "--distribution semicircle:x", "--distribution"),
    # --samples
    ("held", "--samples -1", "--samples"),
    ("held", "--samples 1", "--samples"),
    ("held", "--samples 2.5", "--samples"),
    ("held", "--samples nan", "--samples"),
    ("held", "--samples inf", "--samples"),
    ("held", "--samples abc", "--samples"),
    ("held", "--samples=", "--samples"),
    ("held", "--samples 1e20", "--samples"),
    ("held", "--samples 1e9", "--samples"),  # the work budget
    ("wrongly accepted", "--samples 10000000 --transient 4 --record 4", "--samples"),
    # --seed
    ("held", "--seed -1", "--seed"),
    ("held", "--seed 1.5", "--seed"),
    ("held", "--seed 1e20", "--seed"),
    ("held", "--seed abc", "--seed"),
    ("wrongly accepted", "--seed 3", ("--seed", "--samples 0")),
    # --transient and --record
    ("held", "--transient 0", "--transient"),
    ("held", "--transient -5", "--transient"),
    ("held", "--transient 1.5", "--transient"),
    ("held", "--transient nan", "--transient"),
    ("held", "--transient=", "--transient"),
    ("unnamed culprit", "--transient 1e9", "--transient"),
    ("held", "--record 0", "--record"),
    ("held", "--record 3", "--record"),
    ("held", "--record 4.5", "--record"),
    ("unnamed culprit", "--record 1e9", "--record"),
    ("wrongly accepted", "--record 10000000 --work-budget 1m", ("--record",
                                                                    "--work-budget")),
    # --extra-states and --coexist
    ("held", "--extra-states -1", "--extra-states"),
    ("held", "--extra-states 1.5", "--extra-states"),
    ("held", "--extra-states=", "--extra-states"),
    ("unnamed culprit", "--extra-states 1e9", "--extra-states"),
    ("wrongly accepted", "--extra-states 100000", "--extra-states"),
    ("held", "--coexist -1", "--coexist"),
    ("held", "--coexist 5", ("--coexist", "--extra-states")),
    ("wrongly accepted", "--samples 4 --extra-states 1 --coexist 8", ("--coexist", "--samples")),
    ("wrongly accepted", "--extra-states 1 --coexist 3", ("--coexist", "--samples 0")),
    ("wrongly accepted", "--extra-states 1 --coexist 0", ("--coexist", "--samples 0")),
    # --emr and --emr-order
    ("unnamed culprit", "--emr --distribution uniform", ("--emr", "uniform")),
    ("unnamed culprit", "--emr --sweep c=0.05,0.04", ("--sweep", "--emr")),
    ("held", "--emr-order 2", ("--emr-order", "--emr")),
    ("held", "--emr --emr-order 0", "--emr-order"),
    ("held", "--emr --emr-order -3", "--emr-order"),
    ("unnamed culprit", "--emr --emr-order 100000", "--emr-order"),
    ("unnamed culprit", "--emr --emr-order 501", "--emr-order"),
    # --workers and --scheduler
    ("held", "--workers 0", "--workers"),
    ("held", "--workers -1", "--workers"),
    ("held", "--workers 1000000", "--workers"),
    ("held", "--workers nan", "--workers"),
    ("unnamed culprit", "--workers 2 --scheduler tcp://127.0.0.1:1", ("--workers",
                                                                      "--scheduler")),
    ("wrongly accepted", "--workers 2", ("--workers", "one")),
    ("held", "--scheduler=", "--scheduler"),
    ("held", "--scheduler nonsense", "--scheduler"),
    ("held", "--scheduler tcp://host", "--scheduler"),
    # --sweep
    ("held", "--sweep c", "--sweep"),
    ("held", "--sweep c=", "--sweep"),
    ("held", "--sweep =0.04", "--sweep"),
    ("held", "--sweep q=0.04", ("--sweep", "q")),
    ("held", "--sweep mu=0.8", ("--sweep", "--uncertain mu")),
    ("held", "--sweep x0=-1", ("--sweep", "x0")),
    ("held", "--sweep v0=0", ("--sweep", "v0")),
    ("held", "--sweep c=nan", "--sweep"),
    ("held", "--sweep c=inf", "--sweep"),
    ("held", "--sweep c=0.04,0.04", "--sweep"),
    ("held", "--sweep c=0.04,", "--sweep"),
    ("wrongly accepted", "--sweep c=1:1.0000000000000002:5", ("--sweep", "distinct")),
    ("held", "--sweep c=0.01:0.1:0", "--sweep"),
    ("held", "--sweep c=0.01:0.1:1000000", "--sweep"),
    ("held", "--sweep c=0.0:1.0:100000 --samples 1024", "--sweep values"),  # the budget
    ("unnamed culprit", "--sweep eta=0.5,1.5", ("--sweep", "eta")),
    ("unnamed culprit", "--sweep omega=0", ("--sweep", "omega")),
    ("unnamed culprit", "--sweep n=0", ("--sweep", "n")),
    ("unnamed culprit", "--sweep delta=-2", ("--sweep", "delta")),
    ("wrongly accepted", "--sweep omega=1e300", ("--sweep", "omega")),
    ("traceback", "--sweep omega=1e-300", ("--sweep", "omega")),
    ("wrongly accepted", "--F0 0.1 --sweep omega1=1e300", ("--sweep", "omega1")),
    ("wrongly accepted", "--sweep c=0.04 --c 0.05", ("--c", "--sweep")),
    ("wrongly accepted", "--sweep c=0.05,0.04,0.06 --plot s.png", ("--sweep", "--plot")),
    # model parameters (the shared Oscillator checks name the keyword)
    ("held", "--eta 0", "eta"),
    ("held", "--eta 1.5", "eta"),
    ("held", "--omega nan", "omega"),
    ("held", "--mu inf", "mu"),
    ("held", "--a nan", "a"),
    ("held", "--x0 1", "x0"),
    ("held", "--c abc", "--c"),
    # solver flags (the shared SolverOptions checks name the keyword)
    ("held", "--rtol 0", "rtol"),
    ("held", "--rtol nan", "rtol"),
    ("held", "--atol -1", "atol"),
    ("held", "--max-step 0", "max_step"),
    ("held", "--max-step nan", "max_step"),
    ("held", "--chatter-velocity nan", "chatter_velocity"),
    ("held", "--method rk4", "--method"),
    # output paths
    ("held", "--out .", "--out"),
    ("held", "--out=", "--out"),
    ("held", "--out /proc/x.nc", "--out"),
    ("held", "--out /proc/missing/x.nc", "--out"),
    ("held", "--plot s.txt", "--plot"),
    ("held", "--plot .", "--plot"),
    ("held", "--plot /proc/s.png", "--plot"),
    ("held", "--out s.nc --plot s.nc", ("--out", "--plot")),
    ("held", "--keep-parts", ("--keep-parts", "--out")),
    # the work budget itself
    ("held", "--work-budget 0", "--work-budget"),
    ("held", "--work-budget -1", "--work-budget"),
    ("held", "--work-budget abc", "--work-budget"),
    ("held", "--samples 100000 --work-budget 1s", ("--samples", "--work-budget")),
]


@pytest.mark.parametrize("kind, case, names", BAD_CLI,
                         ids=[f"{k}: {c}"[:100] for k, c, _ in BAD_CLI])
def test_the_cli_refuses_in_one_line_naming_the_flag(kind, case, names, tmp_path,
                                                     monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, err, seconds = run_cli(argv(case))
    left = sorted(os.listdir(tmp_path))
    flaw = cli_flaw(status, err, names, seconds, left)
    assert flaw is None, f"opa-mc {' '.join(argv(case))}: {flaw}"


def test_a_parts_path_that_is_a_file_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.nc.parts").write_text("not a folder")
    status, err, seconds = run_cli(argv("--out s.nc"))
    flaw = cli_flaw(status, err, "--out", seconds, [])
    assert flaw is None, flaw
    assert sorted(os.listdir(tmp_path)) == ["s.nc.parts"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes in read-only folders")
def test_a_read_only_folder_is_refused(tmp_path, monkeypatch):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        status, err, seconds = run_cli(argv(f"--out {folder}/s.nc"))
        assert cli_flaw(status, err, "--out", seconds, os.listdir(folder)) is None
    finally:
        folder.chmod(0o755)


@pytest.mark.slow
def test_a_scheduler_that_does_not_answer_is_refused_naming_it(tmp_path, monkeypatch):
    """The existing check (5 s): refused, named, nothing written."""
    monkeypatch.chdir(tmp_path)
    status, err, seconds = run_cli(argv("---workers --scheduler tcp://127.0.0.1:1 --out s.nc"))
    assert cli_flaw(status, err, "tcp://127.0.0.1:1", min(seconds, 1), []) is None
    assert not os.listdir(tmp_path)


# ------------------------------------------------------------ datasets read back
def dataset_flaws(ds: xr.Dataset) -> list[str]:
    """What is wrong in a diagram read back, each tagged with its kind."""
    flaws = []
    samples = int(ds.attrs["samples"])
    P = ds.probability.values
    if not np.isfinite(P).all():
        flaws.append("[silent NaN] probability")
    elif P.shape[1] == 0 or not np.allclose(P.sum(axis=1), 1.0, atol=1e-9) \
            or (P < 0).any():
        flaws.append(f"[silent NaN] probability is not a distribution at every value: "
                     f"row sums {P.sum(axis=1)}")
    if not np.isfinite(ds.coexist_probability.values).all():
        flaws.append("[silent NaN] coexist_probability")
    for name in ("agree", "method", "mc_mismatch"):
        if not np.isfinite(ds[name].values.astype(float)).all():
            flaws.append(f"[silent NaN] {name}")
    if samples:
        for name in ("mc_probability", "mc_sem", "mc_xi"):
            if not np.isfinite(ds[name].values).all():
                flaws.append(f"[silent NaN] {name} with {samples} samples")
        if not np.allclose(ds.mc_probability.values.sum(axis=1), 1.0):
            flaws.append("[other] mc_probability does not sum to 1")
        if int(ds.attrs["coexist_samples"]) and not np.isfinite(ds.mc_coexist.values).all():
            flaws.append("[silent NaN] mc_coexist")
        if (ds.mc_type.values == "").any() or (ds.mc_periods.values < 0).any():
            flaws.append("[other] a sample without a type or a run")
    elif (ds.agree.values != -1).any():
        flaws.append("[other] agree is not -1 without samples")
    for value, kind in (("boundary_xi", "boundary_kind"), ("located_xi", "located_kind"),
                        ("interval_lo", "interval_type"), ("interval_hi", "interval_type")):
        named = ds[kind].values != ""
        if not np.isfinite(ds[value].values[named]).all():
            flaws.append(f"[silent NaN] {value} where {kind} is given")
    return flaws


# (kind before the fixes, the flags after BASE)
GOOD_CLI = [
    ("held", ""),
    ("silent NaN", "--sweep f=0,1"),  # no harmonic forcing at f = 0
    ("silent NaN", "--mu -0.2 --sigma 0.1"),  # a negative mean may spread
    ("silent NaN", "--sweep c=0.01"),  # chaotic: no periodic attractor, no samples
    ("silent NaN", "--extra-states 1000 --transient 4 --record 4"),  # none settles
    ("held", "--sweep c=0.01,0.04 --samples 4 --extra-states 1 --coexist 2"),
    ("held", "--sweep c=0.05,0.04"),  # unsorted without --emr and --plot: each on its own
    ("held", "--sweep c=0.04 --samples 6 --seed 9007199254740992"),
    ("silent NaN", "--uncertain c --sigma 0.05 --sweep mu=0.8"),  # c reaches 0, not below
    ("held", "--distribution uniform"),
    ("held", "--distribution beta:2,3"),
    ("held", "--distribution normal-trunc:3 --sigma 0.01"),
    ("held", "--distribution normal-trunc:9000"),  # the law is scaled to [-1, 1]
    ("held", "--sigma 1e-6"),
    ("held", "--sweep c=1e300 --samples 2"),  # every run escapes
    ("held", "--out sub/folder/d.nc"),  # missing folders are created
]


@pytest.mark.parametrize("kind, case", GOOD_CLI, ids=[f"{k}: {c}"[:100] for k, c in GOOD_CLI])
def test_accepted_runs_write_finite_results(kind, case, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = argv(case) + ([] if "--out" in case else ["--out", "d.nc"])
    status, err, _ = run_cli(args)
    assert status == 0, f"opa-mc {' '.join(args)}: exit {status}: {err!r}"
    out = args[args.index("--out") + 1]
    with xr.open_dataset(out) as ds:
        flaws = dataset_flaws(ds.load())
    assert not flaws, f"opa-mc {' '.join(args)}: {flaws}"
    assert sorted(os.listdir(tmp_path)) == [out.split("/")[0]]  # no parts left behind


# --------------------------------------------------------------------- API: refusals
def api_flaw(call, names) -> str | None:
    try:
        with time_bound(TIME_LIMIT):
            call()
    except Timeout:
        return "[wrongly accepted] still running"
    except ValueError as err:
        for name in (names if isinstance(names, tuple) else (names,)):
            if name not in str(err):
                return f"[unnamed culprit] {name!r} not named in {str(err)!r}"
        if "\n" in str(err):
            return f"[other] more than one line: {str(err)!r}"
        foreign = sorted(set(re.findall(r"\b([a-z_]+)=", str(err))) - KEYWORDS)
        if foreign:
            return f"[other] hints at {foreign}, not keywords of stochastic_diagram: {err}"
        return None
    except Exception as err:  # noqa: BLE001 -- the corpus records it
        return f"[traceback] {type(err).__name__}: {err}"
    return "[wrongly accepted] no error"


# (kind before the fixes, keywords over API_BASE (the positional arguments under "args"),
#  what the ValueError must name)
BAD_API = [
    ("held", dict(args=("osc", "c", [0.04])), "oscillator"),
    ("held", dict(args=(None, "c", [0.04])), "oscillator"),
    ("traceback", dict(args=(SECTION_31, 3, [0.04])), "parameter"),
    ("traceback", dict(args=(SECTION_31, None, [0.04])), "parameter"),
    ("traceback", dict(args=(SECTION_31, "replace", [0.04])), "parameter"),
    ("traceback", dict(args=(SECTION_31, "forcing_period", [0.04])), "parameter"),
    ("held", dict(args=(SECTION_31, "x0", [0.04])), "parameter"),
    ("wrongly accepted", dict(args=(System(SECTION_31, sigma=0.05), "c", [0.04])),
     ("oscillator", "sigma")),
    ("held", dict(args=(SECTION_31, "mu", [0.8])), "parameter"),
    ("held", dict(args=(SECTION_31, "", [0.8])), "parameter"),
    ("held", dict(args=(SECTION_31, "c", [])), "values"),
    ("held", dict(args=(SECTION_31, "c", [[0.04]])), "values"),
    ("unnamed culprit", dict(args=(SECTION_31, "c", ["a"])), "values"),
    ("held", dict(args=(SECTION_31, "c", "0.04")), "values"),
    ("held", dict(args=(SECTION_31, "c", None)), "values"),
    ("held", dict(args=(SECTION_31, "c", 0.04)), "values"),
    ("held", dict(args=(SECTION_31, "c", [np.nan])), "values"),
    ("held", dict(args=(SECTION_31, "c", [np.inf])), "values"),
    ("traceback", dict(args=(SECTION_31, "c", [1 + 2j])), "values"),
    ("wrongly accepted", dict(args=(SECTION_31, "c", [True])), "values"),
    ("wrongly accepted", dict(args=(SECTION_31, "c", [0.04, 0.04])), "values"),
    ("unnamed culprit", dict(args=(SECTION_31, "eta", [0.5, 1.5])), ("values", "eta")),
    ("unnamed culprit", dict(args=(SECTION_31, "omega", [0.0])), ("values", "omega")),
    ("wrongly accepted", dict(args=(SECTION_31, "omega", [1e300])), ("values", "omega")),
    ("traceback", dict(args=(SECTION_31, "omega", [1e-300])), ("values", "omega")),
    ("held", dict(sigma=True), "sigma"),
    ("held", dict(sigma="0.03"), "sigma"),
    ("held", dict(sigma=None), "sigma"),
    ("held", dict(sigma=np.array([0.03])), "sigma"),
    ("held", dict(sigma=0), "sigma"),
    ("held", dict(sigma=-1.0), "sigma"),
    ("held", dict(sigma=np.nan), "sigma"),
    ("held", dict(sigma=np.inf), "sigma"),
    ("wrongly accepted", dict(sigma=1e-320), "sigma"),
    ("wrongly accepted", dict(sigma=1e-17), "sigma"),
    ("other", dict(sigma=5.0), ("sigma", "mu")),
    ("other", dict(sigma=1e305, distribution="normal-trunc:9000"), "sigma"),
    ("traceback", dict(args=(SECTION_31.replace(c=-1e308), "mu", [0.8]), uncertain="c",
                              sigma=1.7e308), "sigma"),  # c_bar + sigma xi overflows
    ("held", dict(uncertain=None), "uncertain"),
    ("held", dict(uncertain="MU"), "uncertain"),
    ("held", dict(uncertain="omega1"), "uncertain"),
    ("held", dict(uncertain=1), "uncertain"),
    ("held", dict(distribution=3), "distribution"),
    ("held", dict(distribution=""), "distribution"),
    ("held", dict(distribution="foo"), "distribution"),
    ("unnamed culprit", dict(distribution="beta:0,1"), "distribution"),
    ("unnamed culprit", dict(distribution="normal-trunc:-1"), "distribution"),
    ("held", dict(samples=True), "samples"),
    ("held", dict(samples=2.0), "samples"),
    ("held", dict(samples="8"), "samples"),
    ("held", dict(samples=None), "samples"),
    ("held", dict(samples=-1), "samples"),
    ("held", dict(samples=1), "samples"),
    ("held", dict(samples=10**20), "samples"),  # the work budget
    ("unnamed culprit", dict(seed=-1, samples=4), "seed"),
    ("traceback", dict(seed="a", samples=4), "seed"),
    ("traceback", dict(seed=1.5, samples=4), "seed"),
    ("traceback", dict(seed=None, samples=4), "seed"),
    ("wrongly accepted", dict(seed=True, samples=4), "seed"),
    ("wrongly accepted", dict(seed=5), ("seed", "samples")),
    ("held", dict(transient=True), "transient"),
    ("traceback", dict(transient=50.0), "transient"),
    ("held", dict(transient="50"), "transient"),
    ("traceback", dict(transient=None), "transient"),
    ("unnamed culprit", dict(transient=np.nan), "transient"),
    ("traceback", dict(transient=np.inf), "transient"),
    ("held", dict(transient=0), "transient"),
    ("held", dict(record=4.5), "record"),
    ("traceback", dict(record=None), "record"),
    ("held", dict(record=3), "record"),
    ("held", dict(record=True), "record"),
    ("held", dict(record=10**12), "record"),  # the work budget
    ("wrongly accepted", dict(xtol=True), "xtol"),
    ("wrongly accepted", dict(xtol=1e300), "xtol"),
    ("wrongly accepted", dict(xtol=1e-320), "xtol"),
    ("held", dict(xtol="1e-10"), "xtol"),
    ("held", dict(xtol=np.nan), "xtol"),
    ("held", dict(xtol=0.0), "xtol"),
    ("held", dict(extra_states=True), "extra_states"),
    ("held", dict(extra_states=1.0), "extra_states"),
    ("held", dict(extra_states=-1), "extra_states"),
    ("wrongly accepted", dict(extra_states=10**6), "extra_states"),
    ("held", dict(coexist=True, extra_states=1, samples=4), "coexist"),
    ("held", dict(coexist=-1, extra_states=1, samples=4), "coexist"),
    ("wrongly accepted", dict(coexist=5, samples=2, extra_states=1), ("coexist", "samples")),
    ("wrongly accepted", dict(coexist=4, samples=0, extra_states=1), ("coexist", "samples")),
    ("wrongly accepted", dict(coexist=4, samples=4, extra_states=0), ("coexist",
                                                                      "extra_states")),
    ("held", dict(emr="yes"), "emr"),
    ("held", dict(emr=1), "emr"),
    ("held", dict(emr=None), "emr"),
    ("held", dict(emr=True, emr_order=True), "emr_order"),
    ("held", dict(emr=True, emr_order=0), "emr_order"),
    ("held", dict(emr=True, emr_order=4.0), "emr_order"),
    ("unnamed culprit", dict(emr=True, emr_order=10**6), "emr_order"),
    ("wrongly accepted", dict(emr=False, emr_order=6), ("emr_order", "emr")),
    ("held", dict(emr=True, distribution="uniform"), "emr"),
    ("held", dict(args=(SECTION_31, "c", [0.05, 0.04]), emr=True), ("values", "emr")),
    ("held", dict(workers=True), "workers"),
    ("held", dict(workers=2.0), "workers"),
    ("held", dict(workers=0), "workers"),
    ("held", dict(workers="2"), "workers"),
    ("unnamed culprit", dict(workers=2, scheduler="tcp://127.0.0.1:1"), ("workers",
                                                                        "scheduler")),
    ("wrongly accepted", dict(workers=2), ("workers", "one")),
    ("traceback", dict(scheduler=3), "scheduler"),
    ("traceback", dict(scheduler=[]), "scheduler"),
    ("unnamed culprit", dict(scheduler=""), "scheduler"),
    ("unnamed culprit", dict(scheduler="nonsense"), "scheduler"),
    ("traceback", dict(parts=3), "parts"),
    ("unnamed culprit", dict(parts=""), "parts"),
    ("held", dict(parts="/proc/x.parts"), "parts"),
    ("traceback", dict(log="x"), "log"),
    ("traceback", dict(log=3), "log"),
    ("wrongly accepted", dict(options={}), "options"),
    ("traceback", dict(options="fast"), "options"),
    ("wrongly accepted", dict(options=SolverOptions), "options"),
]


def _call(case):
    kw = dict(case)
    args = kw.pop("args", (SECTION_31, "c", [0.04]))
    return lambda: stochastic_diagram(*args, **{**API_BASE, **kw})


@pytest.mark.parametrize("kind, case, names", BAD_API,
                         ids=[f"{k}: {c!r}"[:100] for k, c, _ in BAD_API])
def test_the_api_refuses_naming_the_keyword(kind, case, names):
    flaw = api_flaw(_call(case), names)
    assert flaw is None, f"stochastic_diagram({case!r}): {flaw}"


def test_a_parts_path_that_is_a_file_is_refused_by_the_api(tmp_path):
    path = tmp_path / "parts"
    path.write_text("a file")
    flaw = api_flaw(_call(dict(parts=str(path))), ("parts", str(path)))
    assert flaw is None, flaw
    assert path.read_text() == "a file"


# (kind before the fixes, keywords over API_BASE)
GOOD_API = [
    ("other", dict(samples=np.int64(4), transient=np.int64(200))),
    ("other", dict(sigma=np.float32(0.03))),
    ("held", dict(sigma=np.float64(0.03), extra_states=np.int64(1))),
    ("other", dict(xtol=np.float32(1e-6))),
    ("silent NaN", dict(args=(SECTION_31, "c", [0.01]))),
    ("held", dict(args=(SECTION_31, "c", np.array([0.04, 0.07])), samples=4,
                  extra_states=1, coexist=2)),
    ("held", dict(args=(SECTION_31.replace(c=0.04), "f", (1.9, 2.0)))),
]


@pytest.mark.parametrize("kind, case", GOOD_API, ids=[f"{k}: {c!r}"[:100] for k, c in GOOD_API])
def test_accepted_api_calls_give_finite_results(kind, case):
    try:
        ds = _call(case)()
    except ValueError as err:
        pytest.fail(f"[other] stochastic_diagram({case!r}) refused: {err}")
    except Exception as err:  # noqa: BLE001
        pytest.fail(f"[traceback] stochastic_diagram({case!r}): {type(err).__name__}: {err}")
    flaws = dataset_flaws(ds)
    assert not flaws, f"stochastic_diagram({case!r}): {flaws}"
