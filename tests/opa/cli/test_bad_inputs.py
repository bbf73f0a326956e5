"""The hostile-user corpus: every bad input gets one line naming the culprit, exit 2.

Each case runs ``opa-mc`` in process (``opa.cli._main.main``) under a time bound and checks
the exit status, that stderr is one line, that it names the parameter, path or value,
and that no traceback was printed. Valid input that argparse used to refuse (negative
numbers in exponent notation) must be accepted. The Python API raises ``ValueError``
naming the argument. Runs that integrate and fail exit 3 with a reason, never NaN with 0.
"""

from __future__ import annotations

import contextlib
import os
import math
import signal
import time

import numpy as np
import pytest

from opa.cli._main import main

TIME_LIMIT = 60  # seconds per case: a bad input is refused before any long computing


class Timeout(BaseException):  # not an Exception: the CLI's catch-all must not take it
    pass


@contextlib.contextmanager
def time_bound(seconds: int):
    """Fail a case that runs past ``seconds`` (raised in Python code between kernels)."""

    def handler(signum, frame):
        raise Timeout(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, handler)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def run_cli(argv, capsys):
    """Run ``opa-mc argv``: (exit status, stdout, stderr, seconds)."""
    start = time.perf_counter()
    with time_bound(TIME_LIMIT):
        try:
            status = main(list(argv))
        except SystemExit as exc:  # argparse
            status = exc.code
    out, err = capsys.readouterr()
    return status, out, err, time.perf_counter() - start


def assert_one_line_error(status, err, names, argv):
    assert status == 2, f"opa-mc {' '.join(argv)}: exit {status}, stderr {err!r}"
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"opa-mc {' '.join(argv)}: expected one line, got {lines}"
    for name in names if isinstance(names, tuple) else (names,):
        assert name in lines[0], f"opa-mc {' '.join(argv)}: {name!r} not named in {lines[0]!r}"


DMR = ["simulate", "dmr", "--periods", "2"]
OPA = ["simulate", "opa", "--periods", "2"]
MC = ["simulate", "mc", "--periods", "2", "--samples", "64", "--quiet"]

# (argv, what the message must name)
BAD_CLI = [
    # model parameters
    (DMR + ["--eta", "0"], "eta"),
    (DMR + ["--eta", "1.5"], "eta"),
    (DMR + ["--omega", "0"], "omega"),
    (DMR + ["--omega", "nan"], "omega"),
    (DMR + ["--omega", "-inf"], "omega"),
    (DMR + ["--mu", "inf"], "mu"),
    (DMR + ["--n", "0"], "n"),
    (DMR + ["--omega1", "-1"], "omega1"),
    (DMR + ["--x0", "1"], "x0"),
    (DMR + ["--x0", "0", "--v0", "1"], "v0"),
    (DMR + ["--omega", "x"], "--omega"),
    (DMR + ["--omega", "1e-300"], "periods"),
    (DMR + ["--omega1", "1e300"], "omega1"),
    (DMR + ["--f", "1", "--omega", "1e300"], "omega"),
    (DMR + ["--preset", "9.9"], "--preset"),
    (DMR + ["--delta-minus", "0.5"], ("--delta-minus", "0.5")),
    (DMR + ["--delta-minus", "0"], ("--delta-minus", "0")),
    (DMR + ["--delta", "-2", "--x0", "-3", "--delta-minus", "-1.5"], ("--delta-minus", "-1.5")),
    (DMR + ["--delta-minus", "inf"], ("--delta-minus", "inf")),
    (DMR + ["--delta-minus", "nan"], ("--delta-minus", "nan")),
    (DMR + ["--delta-minus", "low"], ("--delta-minus", "low")),
    (DMR + ["--delta-minus", "-2", "--eta-minus", "0"], ("--eta-minus", "0")),
    (DMR + ["--delta-minus", "-2", "--eta-minus", "1.5"], ("--eta-minus", "1.5")),
    (DMR + ["--delta-minus", "-2", "--eta-minus", "-inf"], ("--eta-minus", "inf")),
    (DMR + ["--eta-minus", "x"], ("--eta-minus", "'x'")),
    (DMR + ["--delta-minus", "-0.5"], ("x0", "-0.5")),
    (OPA + ["--delta-minus", "-2", "--eta-minus", "2"], "--eta-minus"),
    (MC + ["--delta-minus", "1"], "--delta-minus"),
    (["bifurcation", "dmr", "--sweep", "omega=3.9:4:2", "--delta-minus", "0.1"],
     "--delta-minus"),
    (["stability", "dmr", "--delta-minus", "0.1"], "--delta-minus"),
    (["stochastic", "--sweep", "omega=3.9", "--eta-minus", "3"], "--eta-minus"),
    (["validate", "--delta-minus", "0.1"], "--delta-minus"),
    # run length and sizes
    (["simulate", "dmr", "--periods", "1e9"], "periods"),
    (["simulate", "dmr", "--periods", "0"], "periods"),
    (["simulate", "dmr", "--periods", "-3"], "periods"),
    (["simulate", "dmr", "--periods", "nan"], "periods"),
    (["simulate", "dmr", "--periods", "inf"], "periods"),
    (DMR + ["--per-period", "0"], "--per-period"),
    (DMR + ["--per-period", "1.5"], "--per-period"),
    (["simulate", "dmr", "--periods", "1000", "--per-period", "1000000000"], "output"),
    (OPA + ["--order", "-1"], "--order"),
    (OPA + ["--order", "2.5"], "--order"),
    (OPA + ["--order", "100000"], "order"),
    (MC + ["--samples", "0"], "--samples"),
    (MC + ["--samples", "x"], "--samples"),
    (MC + ["--samples", "1e12"], "samples"),
    (MC + ["--order", "100000"], "order"),
    # uncertainty
    (OPA + ["--sigma", "-0.1"], "sigma"),
    (OPA + ["--sigma", "nan"], "sigma"),
    (OPA + ["--mu", "0.005", "--sigma", "0.01"], "allow_negative"),
    (OPA + ["--uncertain", "x"], "--uncertain"),
    (OPA + ["--impact-law", "magic"], "--impact-law"),
    (OPA + ["--truncation", "x"], "--truncation"),
    (OPA + ["--distribution", "cauchy"], "cauchy"),
    (OPA + ["--elements", "0"], "element"),
    (OPA + ["--elements", "many"], "--elements"),
    (DMR + ["--elements", "4"], "--elements"),
    (DMR + ["--distribution", "uniform"], "--distribution"),
    (MC + ["--sampler", "lhs"], "--sampler"),
    (MC + ["--seed", "-1"], "--seed"),
    # solver
    (DMR + ["--rtol", "0"], "rtol"),
    (DMR + ["--rtol", "2"], "rtol"),
    (DMR + ["--atol", "nan"], "atol"),
    (DMR + ["--pulse-width", "0", "--impulse", "pulse"], "pulse_width"),
    (DMR + ["--pulse-width", "100", "--impulse", "pulse"], "pulse_width"),
    (DMR + ["--chatter-velocity", "-1"], "chatter_velocity"),
    (DMR + ["--max-step", "0"], "max_step"),
    (DMR + ["--impulse", "gauss"], "--impulse"),
    # output paths, checked before computing
    (DMR + ["--out", ""], "--out"),
    (DMR + ["--out", "/proc/opa-mc-test.nc"], "/proc"),
    (DMR + ["--out", "/"], "--out"),
    (DMR + ["--out", "/etc/hostname/x.nc"], "/etc/hostname"),
    (DMR + ["--plot", "/tmp"], "--plot"),
    (DMR + ["--plot", "run.xyz"], ".xyz"),
    (DMR + ["--out", "x" * 230 + ".nc"], "longer than 200"),
    (DMR + ["--plot", "/proc/opa-mc-test.png"], "/proc"),
    (["validate", "--outdir", "/proc/opa-mc-test"], "/proc"),
    (["validate", "--outdir", "/etc/hostname"], "/etc/hostname"),
    (["validate", "--outdir", ""], "outdir"),
    (["converge", "--outdir", "/proc/opa-mc-test"], "/proc"),
    (["reproduce", "fig3", "--outdir", "/etc/hostname"], "/etc/hostname"),
    (["bifurcation", "dmr", "--sweep", "c=0.01:0.1:3", "--out", "/proc/x.nc"], "/proc"),
    (["stability", "dmr", "--out", "/proc/x.nc"], "/proc"),
    # sweeps and grids
    (["bifurcation", "dmr", "--sweep", "c=0.01:0.1:1000000000"], "COUNT"),
    (["bifurcation", "dmr", "--sweep", "q=0.01:0.1:3"], "'q'"),
    (["bifurcation", "dmr", "--sweep", "c=0.1:0.1:3"], "START"),
    (["bifurcation", "dmr", "--sweep", "c"], "--sweep"),
    (["bifurcation", "dmr", "--sweep", "c=0.01:0.1:3", "--periods", "10"], "--periods"),
    (["bifurcation", "dmr", "--sweep", "c=0.01:0.1:3", "--workers", "0"], "--workers"),
    (["bifurcation", "dmr", "--sweep", "c=0.01:0.1:3", "--record", "0"], "--record"),
    (["bifurcation", "dmr", "--sweep", "c=0.01:0.1:3", "--transient", "1e9"], "span"),
    (["stability", "dmr", "--sweep", "c=0.1:0.02:0"], "COUNT"),
    (["stochastic", "--sweep", "c=0.04", "--record", "2"], "--record"),
    (["stochastic", "--sweep", "c=0.04", "--samples", "1"], "--samples"),
    (["stochastic", "--sweep", "c=0.04", "--extra-states", "0", "--coexist", "8"],
     ("--coexist", "--extra-states")),
    (["stochastic", "--sweep", "c=0.04", "--emr-order", "2"], ("--emr-order", "--emr")),
    (["stochastic", "--sweep", "c=0.04", "--emr", "--distribution", "uniform"], "emr"),
    (["stochastic", "--sweep", "c=0.04", "--workers", "0"], "--workers"),
    (["stochastic", "--sweep", "c=0.04", "--sigma", "-0.1"], "sigma"),
    (["stochastic", "--sweep", "mu=0.7:0.9:3"], "mu"),
    (["stochastic", "--sweep", "c=0.04", "--uncertain", "x"], "--uncertain"),
    (["stability", "dmr", "--t0", "nan"], "t0"),
    (["stability", "dmr", "--t0", "inf"], "t0"),
    (["stability", "dmr", "--t0", "1e300"], "t0"),
    (["validate", "--sigmas", "0.01,0.01"], "--sigmas"),
    (["validate", "--sigmas", "x"], "--sigmas"),
    (["validate", "--sigmas", "-0.01"], "sigmas"),
    (["validate", "--orders", "8:0"], "--orders"),
    (["validate", "--orders", "0:100000"], "--orders"),
    (["validate", "--horizons", "1e9"], "horizon"),
    (["validate", "--samples", "10"], "samples"),
    (["validate", "--sweep", "omega=3:4:100000000"], "--sweep"),
    (["validate", "--config", "/nonexistent/opa-mc.toml"], "/nonexistent/opa-mc.toml"),
    (["converge", "--budgets", "8:0"], "--budgets"),
    (["converge", "--sigma", "-1"], "sigma"),
    (DMR + ["--per-period", "1e308"], "--per-period"),
    (MC + ["--seed", "1e30"], "--seed"),
    (MC + ["--samples", "1"], "samples"),
    (MC + ["--connect-timeout", "1e308", "--scheduler", "tcp://127.0.0.1:1"], "connect_timeout"),
    (["bifurcation", "dmr", "--sweep", "c=0.01:0.1:3", "--workers", "1000000000"], "--workers"),
    (["reproduce", "fig3", "--workers", "1e9"], "--workers"),
    (["converge", "--reference", "1e308"], "--reference"),
    (["converge", "--workers", "1000"], "--workers"),
    (["validate", "--workers", "1000"], "workers"),
    (["validate", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "workers"),
    (["converge", "--workers", "0"], "--workers"),
    # flags
    (["simulate", "dmr", "--no-such-flag"], "--no-such-flag"),
    (["simulate", "fem"], "fem"),
    (["reproduce", "fig99"], "fig99"),
]


@pytest.mark.parametrize("argv,names", BAD_CLI, ids=[" ".join(a) for a, _ in BAD_CLI])
def test_bad_input_gets_one_line_and_exit_2(argv, names, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, out, err, seconds = run_cli(argv, capsys)
    assert_one_line_error(status, err, names, argv)
    assert seconds < TIME_LIMIT


def write(tmp_path, name, content: bytes | str):
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return str(path)


BAD_TOML = [
    ('sigmas = "0.01"\n', "sigmas"),
    ("model = 3\n", "model"),
    ('plots = "no"\n', "plots"),
    ("samples = 1e3\n", "samples"),
    ("sigmas = [0.01, 0.01]\n", "sigmas"),
    ("[model]\neta = 2\n", "eta"),
    ("[solver]\nrtol = true\n", "rtol"),
    ("[model]\nomega = true\n", "omega"),
    ("colour = 1\n", "colour"),
    ("sigmas = [0.01,\n", "TOML"),
]


@pytest.mark.parametrize("content,name", BAD_TOML, ids=[c for c, _ in BAD_TOML])
def test_bad_config_file(content, name, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = write(tmp_path, "bad.toml", content)
    status, out, err, _ = run_cli(["validate", "--config", path], capsys)
    assert_one_line_error(status, err, name, ["validate", "--config", path])


def test_binary_config_file_is_named(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = write(tmp_path, "binary.toml", bytes(range(256)))
    status, out, err, _ = run_cli(["validate", "--config", path], capsys)
    assert_one_line_error(status, err, path, ["validate", "--config", path])


@pytest.mark.parametrize("argv", [
    DMR + ["--a", "-1e-3"],
    DMR + ["--x0", "-1e-9"],
    DMR + ["--v0", "-2.5E+0"],
])
def test_negative_numbers_in_exponent_notation_are_values(argv, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, out, err, _ = run_cli(argv + ["--out", "run.nc"], capsys)
    assert status == 0, err
    import xarray as xr

    with xr.open_dataset(tmp_path / "run.nc") as ds:
        flag, value = argv[-2].lstrip("-"), float(argv[-1])
        assert ds.attrs[flag] == value
        assert np.isfinite(ds.x.values).all()


def test_a_silent_scheduler_fails_within_the_connect_timeout(capsys, tmp_path, monkeypatch):
    """An endpoint that accepts the connection and never speaks Dask: one line, exit 2,
    within the timeout (distributed alone waits far longer)."""
    import socket

    monkeypatch.chdir(tmp_path)
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
        argv = MC + ["--scheduler", address, "--connect-timeout", "2"]
        status, out, err, seconds = run_cli(argv, capsys)
    assert_one_line_error(status, err, address, argv)
    assert seconds < 15


@pytest.mark.parametrize("command", [["validate", "--outdir", "OUT"], ["simulate", "mc"],
                                     ["stochastic", "--sweep", "c=0.01:0.02:2"],
                                     ["bifurcation", "--sweep", "c=0.01:0.02:2"]])
def test_a_scheduler_that_is_not_an_address_names_the_flag(command, capsys, tmp_path,
                                                         monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = [str(tmp_path / "v") if a == "OUT" else a for a in command]
    status, out, err, seconds = run_cli(argv + ["--scheduler", "garbage"], capsys)
    assert status == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert "--scheduler" in err and "'garbage'" in err and seconds < 10
    assert not (tmp_path / "v").exists()


def test_negative_lists_plot_folders_and_symlinks(capsys, tmp_path, monkeypatch):
    """Negative comma lists are values; --plot may name a new folder; --out through a
    symlink writes the link's target and keeps the link."""
    monkeypatch.chdir(tmp_path)
    from opa.cli._validate import _float_list
    from opa.cli._main import build_parser

    args = build_parser().parse_args(["validate", "--values", "-0.2,-0.1"])
    assert args.values == _float_list("-0.2,-0.1") == (-0.2, -0.1)
    target = tmp_path / "target.nc"
    target.write_bytes(b"")
    (tmp_path / "link.nc").symlink_to(target)
    status, out, err, _ = run_cli(DMR + ["--out", "link.nc", "--plot", "new/sub/p.png"], capsys)
    assert status == 0, err
    assert (tmp_path / "link.nc").is_symlink() and target.stat().st_size > 0
    assert (tmp_path / "new" / "sub" / "p.png").exists()


@pytest.mark.parametrize("argv", [
    DMR + ["--mu", "1e300"],
    DMR + ["--v0", "1e200"],
    DMR + ["--f", "1e300"],
    DMR + ["--c", "1e300"],
    OPA + ["--mu", "1e300"],
    MC + ["--mu", "1e300"],
    ["simulate", "dmr", "--preset", "3.1", "--F0", "1e12", "--periods", "5"],
    ["simulate", "dmr", "--c", "-1", "--periods", "50"],
])
def test_divergence_exits_3_and_writes_nothing(argv, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, out, err, seconds = run_cli(argv + ["--out", "run.nc"], capsys)
    assert status == 3, f"exit {status}: {out} {err}"
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "run.nc").exists()
    assert seconds < 30


def test_failed_output_path_costs_no_computing(capsys, tmp_path, monkeypatch):
    """The path is checked first: a run that would take minutes is refused at once."""
    monkeypatch.chdir(tmp_path)
    status, out, err, seconds = run_cli(
        ["simulate", "mc", "--samples", "100000", "--periods", "1000", "--out",
         "/proc/none.nc"], capsys)
    assert status == 2 and seconds < 10


# --- the Python API: ValueError naming the argument -------------------------------------

def _api_cases():
    from compare import ValidateConfig
    from mc import simulate_mc
    from opa import Oscillator, SolverOptions, System, simulate_dmr, simulate_opa
    from opa._model import Uncertainty

    return [
        (lambda: simulate_dmr("x"), "oscillator"),
        (lambda: simulate_dmr(options="fast"), "options"),
        (lambda: simulate_opa(Oscillator(), order="4"), "order"),
        (lambda: simulate_opa(Oscillator(), order=True), "order"),
        (lambda: simulate_dmr(Oscillator(), periods=math.nan), "periods"),
        (lambda: simulate_dmr(Oscillator(), periods="10"), "periods"),
        (lambda: simulate_dmr(Oscillator(), per_period=0), "per_period"),
        (lambda: simulate_dmr(Oscillator(), times=[0.0, math.inf]), "times"),
        (lambda: simulate_dmr(Oscillator(), times=["a"]), "times"),
        (lambda: simulate_dmr(Oscillator(omega=1e-300)), "periods"),
        (lambda: simulate_mc(Oscillator(), samples=10**12), "samples"),
        (lambda: simulate_mc(Oscillator(), samples=2.5), "samples"),
        (lambda: simulate_mc(Oscillator(), samples=200_000, periods=1000, per_period=100,
                             keep_paths=True), "keep_paths"),
        (lambda: Oscillator(omega=True), "omega"),
        (lambda: Oscillator(mu="0.8"), "mu"),
        (lambda: Oscillator(eta=np.nan), "eta"),
        (lambda: SolverOptions(rtol=True), "rtol"),
        (lambda: SolverOptions(impulse_at_zero="no"), "impulse_at_zero"),
        (lambda: SolverOptions(max_step=math.nan), "max_step"),
        (lambda: Uncertainty(0.01, "mu", allow_negative="yes"), "allow_negative"),
        (lambda: ValidateConfig(sigmas=0.01), "sigmas"),
        (lambda: ValidateConfig(sigmas=(0.01, 0.01)), "sigmas"),
        (lambda: ValidateConfig(plots="no"), "plots"),
        (lambda: ValidateConfig(samples=True), "samples"),
        (lambda: simulate_mc("x"), "oscillator"),
        (lambda: simulate_mc(Oscillator(), keep_paths="no"), "keep_paths"),
        (lambda: simulate_dmr(Oscillator(), times=[-1e9, 0.0]), "start"),
        (lambda: Oscillator(n=np.True_), "n"),
        # issue 31: wrongly accepted, overflow, silently rounded, unnamed culprits
        (lambda: System(Oscillator(), allow_negative=1), "allow_negative"),
        (lambda: System(Oscillator(), impulse_at_zero=0.0), "impulse_at_zero"),
        (lambda: simulate_opa(Oscillator(), order=np.bool_(True), periods=2), "order"),
        (lambda: ValidateConfig(scheduler=5), "scheduler"),
        (lambda: simulate_opa(Oscillator(), periods=2, tolerance=1e-3), "tolerance"),
        (lambda: simulate_opa(Oscillator(), periods=2, max_elements=8), "max_elements"),
        (lambda: simulate_opa(Oscillator(), periods=2, elements=4, max_elements=8),
         "max_elements"),
        (lambda: simulate_mc(Oscillator(), periods=2, samples=64, seed=2**53 + 1), "seed"),
        (lambda: SolverOptions(max_steps=math.inf), "max_steps"),
        (lambda: SolverOptions(max_steps=10**400), "max_steps"),
        (lambda: simulate_mc(Oscillator(), periods=2, samples=64, chunk_size=math.inf),
         "chunk_size"),
        (lambda: ValidateConfig(orders=(0, math.inf)), "orders"),
        (lambda: simulate_opa(Oscillator(), periods=2, elements=math.inf), "elements"),
        (lambda: simulate_dmr(Oscillator(), periods=2.5), "periods"),
        (lambda: simulate_mc(Oscillator(), periods=2.5, samples=64), "periods"),
        (lambda: simulate_opa(Oscillator(), periods=2, sigma=0.01,
                              distribution="beta:1000,1000"), "beta:1000,1000"),
        (lambda: simulate_opa(Oscillator(), periods=2, order=500, elements=2), "order"),
        (lambda: _find_splits_to(1e-300), "tol"),
    ]


def _find_splits_to(tol):
    from opa import Oscillator, SolverOptions
    from opa._splits import find_splits

    return find_splits(Oscillator(), SolverOptions(), "mu", 0.7, 0.9, 8.0, tol=tol)


def test_api_bad_arguments_raise_value_error_naming_them():
    failures = []
    for i, (call, name) in enumerate(_api_cases()):
        with time_bound(TIME_LIMIT):
            try:
                call()
            except ValueError as err:
                if name not in str(err):
                    failures.append(f"case {i}: {name!r} not in {err}")
            except (Exception, Timeout) as err:  # noqa: BLE001 -- report every wrong kind
                failures.append(f"case {i}: {type(err).__name__}: {err}")
            else:
                failures.append(f"case {i}: accepted, expected a ValueError naming {name!r}")
    assert not failures, "\n".join(failures)


def test_api_divergence_raises_and_returns_no_nan():
    from opa import Oscillator, simulate_dmr, simulate_opa
    from opa._run import SimulationError

    for call in (lambda: simulate_dmr(Oscillator(mu=1e300), periods=2),
                 lambda: simulate_opa(Oscillator(mu=1e300), sigma=0.01, periods=2)):
        with time_bound(TIME_LIMIT), pytest.raises(SimulationError):
            call()


def test_unknown_errors_are_one_line_too(capsys, monkeypatch):
    """A bug is reported in one line with exit 1 (the traceback on request)."""
    import opa.cli._main as cli

    def boom(args):
        raise RuntimeError("an unforeseen failure\nwith two lines")

    monkeypatch.setattr(cli, "cmd_simulate", boom)
    parser_main = cli.main
    monkeypatch.delenv("OPA_MC_TRACEBACK", raising=False)
    status, out, err, _ = run_cli(["simulate", "dmr"], capsys)
    assert status == 1
    assert err.count("\n") == 1 and "RuntimeError: an unforeseen failure with two lines" in err
    monkeypatch.setenv("OPA_MC_TRACEBACK", "1")
    with pytest.raises(RuntimeError):
        parser_main(["simulate", "dmr"])


# --- the real entry point, as a user's shell runs it ---------------------------------------

def _run_process(argv, cwd, timeout=TIME_LIMIT):
    import subprocess
    import sys

    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", "import sys; from opa.cli._main import main; "
                           "sys.exit(main())", *argv], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr, time.perf_counter() - start


QUICK_PROCESS = [
    (DMR + ["--eta", "0"], "eta"),
    (DMR + ["--out", "/proc/opa-mc-test.nc"], "/proc"),
    (["stability", "dmr", "--t0", "nan"], "t0"),
    (MC + ["--scheduler", "tcp://127.0.0.1:1"], "tcp://127.0.0.1:1"),
]


@pytest.mark.parametrize("argv,names", QUICK_PROCESS, ids=[" ".join(a) for a, _ in QUICK_PROCESS])
def test_real_process_prints_one_line(argv, names, tmp_path):
    status, out, err, seconds = _run_process(argv, tmp_path)
    assert_one_line_error(status, err, names, argv)


@pytest.mark.slow
def test_whole_corpus_in_real_processes(tmp_path):
    """Every bad input of the corpus, each in its own process: exit 2, one line, in time."""
    failures = []
    for argv, names in BAD_CLI:
        status, out, err, seconds = _run_process(argv, tmp_path)
        try:
            assert_one_line_error(status, err, names, argv)
        except AssertionError as exc:
            failures.append(str(exc).splitlines()[0])
    assert not failures, "\n".join(failures)


# the law of xi and multi-element variants of validate, the uncertain parameter of converge
BAD_LAW_CLI = [
    (["validate", "--distribution", "triangle"], ("distribution", "triangle")),
    (["validate", "--distribution", "beta:0,1"], ("distribution", "beta:0,1")),
    (["validate", "--distribution", "normal-trunc:x"], ("distribution", "normal-trunc:x")),
    (["validate", "--elements", "1"], ("elements", "1")),
    (["validate", "--elements", "0"], ("elements", "0")),
    (["validate", "--elements", "100000"], ("elements", "100000")),
    (["validate", "--elements", "many"], ("--elements", "many")),
    (["validate", "--max-elements", "8"], ("max_elements", "8")),
    (["validate", "--elements", "4", "--max-elements", "8"], ("max_elements", "8")),
    (["validate", "--elements", "adaptive", "--max-elements", "1025"],
     ("max_elements", "1025")),
    (["validate", "--elements", "adaptive", "--max-elements", "0"], ("--max-elements", "0")),
    (["converge", "--uncertain", "x"], ("--uncertain", "'x'")),
    (["converge", "--uncertain", "m-u"], ("--uncertain", "m-u")),
    (["converge", "--distribution", "triangle"], ("distribution", "triangle")),
]


@pytest.mark.parametrize("argv,names", BAD_LAW_CLI, ids=[" ".join(a) for a, _ in BAD_LAW_CLI])
def test_bad_law_or_elements_get_one_line_and_exit_2(argv, names, capsys, tmp_path,
                                                      monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, out, err, seconds = run_cli(argv, capsys)
    assert_one_line_error(status, err, names, argv)
    assert seconds < TIME_LIMIT


@pytest.mark.parametrize("content, name", [
    ('distribution = "triangle"\n', "distribution"),
    ('distribution = 3\n', "distribution"),
    ('elements = "many"\n', "elements"),
    ('max_elements = 16\n', "max_elements"),
    ('elements = "adaptive"\nmax_elements = 1.5\n', "max_elements"),
])
def test_bad_law_toml_gets_one_line_and_exit_2(content, name, capsys, tmp_path):
    path = write(tmp_path, "law.toml", content)
    status, out, err, _ = run_cli(["validate", "--config", path, "--outdir",
                                   str(tmp_path / "r")], capsys)
    assert_one_line_error(status, err, name, ["validate", "--config", path])


# --- issue 31: every flag means something where it is accepted -------------------------

RUNAWAY = ["simulate", "opa", "--a", "-0.005", "--c", "-0.01", "--mu", "0.001", "--omega", "0.1",
           "--F0", "2", "--a1", "-3", "--omega1", "0.1", "--n", "0.5", "--periods", "1",
           "--order", "8", "--sigma", "0.0005"]

# (category, argv, what the one line must name)
BAD_CLI_31 = [
    # silently wrong: a fraction of an output interval, a figure over the dataset
    ("silently wrong", ["simulate", "dmr", "--periods", "2.5", "--out", "p.nc"],
     ("periods", "2.5")),
    ("silently wrong", ["simulate", "opa", "--periods", "2.5", "--out", "p.nc"],
     ("periods", "2.5")),
    ("silently wrong", ["simulate", "mc", "--periods", "2.5", "--samples", "64", "--out", "p.nc"],
     ("periods", "2.5")),
    ("silently wrong", DMR + ["--out", "same.png", "--plot", "same.png"], ("--out", "--plot")),
    ("silently wrong", DMR + ["--out", "same.nc", "--plot", "./same.nc"], ("--out", "--plot")),
    # wrongly accepted: a flag with no effect in the given combination
    ("wrongly accepted", DMR + ["--samples", "3"], ("--samples", "simulate mc")),
    ("wrongly accepted", DMR + ["--scheduler", "tcp://127.0.0.1:1"], "--scheduler"),
    ("wrongly accepted", DMR + ["--keep-parts"], "--keep-parts"),
    ("wrongly accepted", DMR + ["--connect-timeout", "3"], "--connect-timeout"),
    ("wrongly accepted", DMR + ["--sigma", "0.02"], ("--sigma", "deterministic")),
    ("wrongly accepted", DMR + ["--order", "3"], "--order"),
    ("wrongly accepted", DMR + ["--seed", "3"], "--seed"),
    ("wrongly accepted", DMR + ["--verify", "8"], "--verify"),
    ("wrongly accepted", DMR + ["--pulse-width", "0.2"], ("--pulse-width", "--impulse pulse")),
    ("wrongly accepted", OPA + ["--tolerance", "1e-3"], ("--tolerance", "--element-tolerance")),
    ("wrongly accepted", OPA + ["--element-tolerance", "1e-3"],
     ("--element-tolerance", "adaptive")),
    ("wrongly accepted", OPA + ["--max-elements", "8"], ("--max-elements", "adaptive")),
    ("wrongly accepted", OPA + ["--elements", "4", "--max-elements", "8"], "--max-elements"),
    ("wrongly accepted", OPA + ["--samples", "64"], ("--samples", "simulate mc")),
    ("wrongly accepted", OPA + ["--seed", "3"], ("--seed", "--verify")),
    ("wrongly accepted", OPA + ["--verify", "256", "--verify-max", "128"],
     ("--verify-max", ">= 256", "128")),
    ("wrongly accepted", OPA + ["--verify", "8"], ("--verify", "smallest that works is "
                                                   "--verify 64")),
    ("wrongly accepted", OPA + ["--keep-parts"], "--keep-parts"),
    ("wrongly accepted", MC + ["--keep-parts"], ("--keep-parts", "--out")),
    ("wrongly accepted", MC + ["--connect-timeout", "3"], ("--connect-timeout", "--scheduler")),
    ("wrongly accepted", MC + ["--sampler", "gauss", "--seed", "3"], ("--seed", "gauss")),
    ("wrongly accepted", MC + ["--seed", "9007199254740993"], ("--seed", "9007199254740993")),
    ("wrongly accepted", MC + ["--seed", "9007199254740993.0"], "--seed"),
    ("wrongly accepted", MC + ["--truncation", "paper"], ("--truncation", "simulate opa")),
    ("wrongly accepted", MC + ["--elements", "2"], "--elements"),
    ("wrongly accepted", MC + ["--verify", "8"], "--verify"),
    ("wrongly accepted", ["stability", "dmr", "--benettin"], ("--benettin", "--lyapunov")),
    ("wrongly accepted", ["stability", "dmr", "--lyapunov-periods", "20"], "--lyapunov-periods"),
    ("wrongly accepted", ["stability", "dmr", "--sigma", "0.1"], ("--sigma", "stability opa")),
    ("wrongly accepted", ["stability", "dmr", "--depth", "2"], ("--depth", "--sweep")),
    ("wrongly accepted", ["stability", "opa", "--max-points", "9"], ("--max-points", "--sweep")),
    ("wrongly accepted", ["bifurcation", "dmr", "--sweep", "c=0.01:0.1:3", "--samples", "8"],
     ("--samples", "bifurcation mc")),
    ("wrongly accepted", ["bifurcation", "dmr", "--sweep", "c=0.01:0.1:3", "--keep-parts"],
     ("--keep-parts", "--out")),
    # the uncertain parameter swept: it was "unknown parameter"
    ("unnamed culprit", ["stochastic", "--sweep", "mu=0.5:0.9:3"],
     ("--sweep", "mu is the uncertain parameter", "--uncertain mu")),
    # a one-value flag given twice: argparse kept the last without a word
    ("silently wrong", OPA + ["--uncertain", "c", "--uncertain", "mu"],
     ("--uncertain given twice", "c", "mu")),
    ("silently wrong", MC + ["--seed", "3", "--seed=4"], ("--seed given twice", "3", "4")),
    # tracebacks and internal errors: ranges refused before they are built
    ("traceback", ["validate", "--orders", "0:1000000000"], ("--orders", "1000000001")),
    ("traceback", ["converge", "--budgets", "1:1000000000"], "--budgets"),
    ("traceback", ["converge", "--uniform", "1:1000000000"], "--uniform"),
    ("traceback", MC + ["--seed", "1" * 5000], "--seed"),
    # refused without naming the culprit
    ("unnamed culprit", OPA + ["--distribution", "beta:1000,1000", "--order", "20"],
     ("beta:1000,1000", "works up to")),
    ("unnamed culprit", MC + ["--distribution", "normal-trunc:1e6"], ("normal-trunc:1e6",
                                                                     "works up to")),
    ("unnamed culprit", OPA + ["--order", "500", "--elements", "2"], ("order", "500")),
    # silent NaN: a law the Chebyshev coefficients cannot be formed for is refused up front
    ("silent NaN", MC + ["--distribution", "beta:1000,1000", "--order", "20", "--out", "r.nc"],
     "beta:1000,1000"),
]


@pytest.mark.parametrize("category,argv,names", BAD_CLI_31,
                         ids=[f"{c}: {' '.join(a)}"[:120] for c, a, _ in BAD_CLI_31])
def test_issue31_bad_input_gets_one_line_and_exit_2(category, argv, names, capsys, tmp_path,
                                                     monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, out, err, seconds = run_cli(argv, capsys)
    assert_one_line_error(status, err, names, argv)
    assert seconds < TIME_LIMIT
    assert not any(tmp_path.iterdir()), "a refused run wrote something"


BAD_TOML_31 = [
    ("impulse_at_zero = 1\n", "impulse_at_zero"),
    ("plots = 1\n", "plots"),
    ("scheduler = 5\n", "scheduler"),
    ("seed = 9223372036854775807\n", "seed"),
    ("orders = [0, 1.5]\n", "orders"),
    ("split_resolution = 1e-300\n", "split_resolution"),
    ("resolution = 1e-300\n", "resolution"),
    ("a = " + "[" * 1000 + "]" * 1000 + "\n", "nested"),
    ("values = [[[[[1.0]]]]]\n", "nested"),
    ("#" + "x" * (1 << 20) + "\n", "bytes"),
]


@pytest.mark.parametrize("content,name", BAD_TOML_31, ids=[c[:40] for c, _ in BAD_TOML_31])
def test_issue31_bad_config_file(content, name, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = write(tmp_path, "bad.toml", content)
    status, out, err, seconds = run_cli(["validate", "--config", path], capsys)
    assert_one_line_error(status, err, name, ["validate", "--config", path])
    assert seconds < TIME_LIMIT


# --- issue 43: --model FILE.toml, the oscillator as a model file -------------------------

SHAW = os.path.join(os.path.dirname(__file__), "..", "..", "..", "docs", "examples",
                    "shaw-holmes.toml")

# (argv with {model} for a file of the given content, or the Shaw & Holmes example; what
# the message must name)
BAD_MODEL = [
    (DMR + ["--model", "/nonexistent/model.toml"], ("--model", "/nonexistent/model.toml")),
    (DMR + ["--model"], "--model"),
    (DMR + ["--model", "{model}"], ("--model", "TOML"), "force = \n"),
    (DMR + ["--model", "{model}"], ("--model", "'colour'"), "colour = 1\n"),
    (DMR + ["--model", "{model}"], ("--model", "eta"), "[oscillator]\neta = 2.0\n"),
    (DMR + ["--model", "{model}"], ("--model", "j0(x)"), 'force = "j0(x)"\n'),
    (DMR + ["--model", "{model}"], ("--model", "no_such_module"),
     'function = "no_such_module:g"\n'),
    (DMR + ["--model", "{model}"], ("--model", "[constants] k"),
     'force = "-k*x"\n[constants]\nk = "one"\n'),
    (DMR + ["--model", SHAW, "--preset", "3.1"], ("--preset", "--model")),
    (DMR + ["--model", SHAW, "--mu", "0.3"], ("--mu", "no effect")),
    (DMR + ["--model", SHAW, "--eta", "1.5"], "eta"),
    (DMR + ["--model", SHAW, "--delta-minus", "0.2"], ("--delta-minus", "0.2")),
    (DMR + ["--model", "{model}"], ("--model", "delta_minus"),
     "[oscillator]\ndelta_minus = 0.5\n"),
    (DMR + ["--model", "{model}", "--eta-minus", "1.01"], ("--eta-minus", "1.01"),
     "[oscillator]\ndelta_minus = -2.0\n"),
    (OPA + ["--model", SHAW, "--uncertain", "mu"], ("--uncertain", "zeta")),
    (OPA + ["--model", SHAW, "--uncertain", "zeta", "--sigma", "-0.01"], "sigma"),
    (OPA + ["--model", SHAW, "--truncation", "paper"], "paper"),
    (OPA + ["--model", SHAW, "--problem", "{model}"], ("--problem", "'mu'"),
     "[mu]\nsigma = 0.01\n"),
    (MC + ["--model", SHAW, "--distribution", "cauchy"], "cauchy"),
    (["validate", "--model", "{model}"], ("delta = 0", "--relative"),
     "[oscillator]\nomega = 4.0\ndelta = 0.0\n[uncertain.c]\nsigma = 0.005\n"
     "[uncertain.delta]\nsigma = 0.01\n"),
    (["sobol", "--model", SHAW, "--periods", "1"], ("--model", "two")),
    (["bifurcation", "dmr", "--model", SHAW, "--sweep", "kappa=0.04:0.06:3"], "kappa"),
    (["stochastic", "--model", SHAW, "--sweep", "zeta=0.1"], ("--sweep", "zeta")),
    (["stability", "dmr", "--model", SHAW, "--preset", "3.2"], "--preset"),
]


@pytest.mark.parametrize("case", BAD_MODEL, ids=[" ".join(c[0]).replace(SHAW, "SHAW")
                                                 for c in BAD_MODEL])
def test_bad_model_file_or_flags_get_one_line_and_exit_2(case, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv, names = case[:2]
    if len(case) > 2:
        path = write(tmp_path, "model.toml", case[2])
        argv = [path if arg == "{model}" else arg for arg in argv]
    status, out, err, seconds = run_cli(argv, capsys)
    assert_one_line_error(status, err, names, argv)
    assert seconds < 20  # refused before any integration


def test_a_fifo_as_config_is_refused_at_once(capsys, tmp_path, monkeypatch):
    """Reading a FIFO would wait for a writer for ever."""
    monkeypatch.chdir(tmp_path)
    path = str(tmp_path / "fifo.toml")
    os.mkfifo(path)
    status, out, err, seconds = run_cli(["validate", "--config", path], capsys)
    assert_one_line_error(status, err, (path, "regular file"), ["validate", "--config", path])
    assert seconds < 10


def test_a_runaway_opa_system_stops_within_seconds(capsys, tmp_path, monkeypatch):
    """c < 0 blows up in finite time: the steps collapse; the runaway guard ends it (it
    used to run ~200 s in silence before the 50-million-step limit)."""
    monkeypatch.chdir(tmp_path)
    status, out, err, seconds = run_cli(RUNAWAY + ["--out", "run.nc"], capsys)
    assert status == 3, err
    assert "runaway guard" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "run.nc").exists()
    assert seconds < 30


def test_the_runaway_guard_is_lifted_by_an_explicit_max_steps():
    """The guard applies under the default max_steps only: given explicitly, the limit is
    the user's (here smaller than the guard: the plain step-limit message)."""
    from opa import Oscillator, SolverOptions, simulate_dmr
    from opa._run import SimulationError

    osc = Oscillator(c=-1.0)
    with pytest.raises(SimulationError, match="runaway guard"):
        simulate_dmr(osc, periods=50)
    with pytest.raises(SimulationError, match="maximum number of steps") as raised:
        simulate_dmr(osc, periods=50, options=SolverOptions(max_steps=100_000))
    assert "runaway guard" not in str(raised.value)


def test_whole_periods_and_fractions_that_land_on_outputs_are_accepted(capsys, tmp_path,
                                                                        monkeypatch):
    """--periods 2.5 with --per-period 2 is 5 whole output intervals: it runs to exactly
    2.5 forcing periods."""
    monkeypatch.chdir(tmp_path)
    status, out, err, _ = run_cli(["simulate", "dmr", "--periods", "2.5", "--per-period", "2",
                                   "--out", "p.nc", "--quiet"], capsys)
    assert status == 0, err
    import xarray as xr

    with xr.open_dataset(tmp_path / "p.nc") as ds:
        assert ds.sizes["time"] == 6
        assert float(ds.time[-1]) == pytest.approx(2.5 * 2 * math.pi / 3.98, rel=1e-14)


@pytest.mark.parametrize("model,own,others", [
    ("dmr", ["--omega", "--periods", "--impulse", "--rtol", "--out"],
     ["--sigma", "--order", "--samples", "--elements", "--verify", "--keep-parts", "--seed"]),
    ("opa", ["--sigma", "--order", "--elements", "--element-tolerance", "--verify", "--seed"],
     ["--samples", "--sampler", "--scheduler", "--keep-parts", "--connect-timeout",
      "--tolerance "]),
    ("mc", ["--samples", "--sampler", "--seed", "--scheduler", "--connect-timeout",
            "--keep-parts", "--order", "--distribution"],
     ["--elements", "--verify", "--truncation", "--impact-law", "--strict"]),
])
def test_simulate_help_lists_only_the_models_flags(model, own, others, capsys):
    """Issue 26, item 5: `opa-mc simulate MODEL --help` lists the flags of MODEL only."""
    with pytest.raises(SystemExit) as done:
        main(["simulate", model, "--help"])
    assert done.value.code == 0
    text = capsys.readouterr().out
    for flag in own:
        assert flag in text, f"{flag} missing from simulate {model} --help"
    for flag in others:
        assert flag not in text, f"{flag} in simulate {model} --help"


def test_adaptive_element_flags_act_under_their_new_name(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, out, err, _ = run_cli(OPA + ["--sigma", "0.05", "--order", "1", "--elements",
                                         "adaptive", "--element-tolerance", "0.5",
                                         "--max-elements", "4", "--out", "me.nc",
                                         "--quiet"], capsys)
    assert status == 0, err
    import xarray as xr

    with xr.open_dataset(tmp_path / "me.nc") as ds:
        assert ds.attrs["tolerance"] == 0.5 and ds.attrs["max_elements"] == 4


# --- property: random flag combinations -------------------------------------------------

_VALUES = ["0", "1", "2", "2.5", "-1", "1e-300", "1e300", "nan", "inf", "-inf", "x", "",
           "9007199254740993", "0.5", "8", "3.98", "adaptive", "beta:2,3", "gauss",
           "tcp://127.0.0.1:1", "cuda"]
_FLAGS = {
    "simulate dmr": ["--periods", "--per-period", "--omega", "--c", "--eta", "--x0", "--F0",
                     "--impulse", "--pulse-width", "--rtol", "--max-step", "--sigma",
                     "--samples", "--seed", "--keep-parts", "--quiet"],
    "simulate opa": ["--periods", "--per-period", "--sigma", "--order", "--mu", "--elements",
                     "--element-tolerance", "--max-elements", "--distribution", "--verify",
                     "--seed", "--strict", "--truncation", "--impact-law", "--samples",
                     "--quiet"],
    "simulate mc": ["--periods", "--samples", "--sampler", "--seed", "--sigma", "--order",
                    "--distribution", "--scheduler", "--connect-timeout", "--keep-parts",
                    "--elements", "--device", "--quiet"],
    "stability dmr": ["--benettin", "--lyapunov", "--depth", "--sigma", "--t0", "--transient",
                      "--orbit-periods", "--quiet"],
    "bifurcation dmr": ["--sweep", "--samples", "--record", "--transient", "--workers",
                        "--keep-parts", "--periods", "--quiet"],
    "validate": ["--orders", "--sigmas", "--horizons", "--samples", "--resolution",
                 "--max-elements", "--elements", "--seed", "--quiet"],
    "converge": ["--budgets", "--uniform", "--sigma", "--order", "--reference", "--quiet"],
}
_SWITCHES = {"--keep-parts", "--quiet", "--strict", "--benettin", "--lyapunov"}


def _cheap(argv) -> list[str]:
    """Keep a generated run small: short runs, few samples, no long validate or converge
    jobs (a refusal is what the property is after; work that is accepted must be quick)."""
    head = argv[:2] if argv[0] in ("simulate", "stability", "bifurcation") else argv[:1]
    if head[0] == "simulate":
        return argv + ["--periods", "1", "--per-period", "1"] + (
            ["--samples", "16"] if head[1] == "mc" else [])
    if head[0] == "stability":
        return argv + ["--transient", "5", "--orbit-periods", "1"]
    if head[0] == "bifurcation":
        return argv + ["--sweep", "c=0.05:0.06:2", "--transient", "2", "--record", "2",
                       "--workers", "1", "--no-locate"]
    return argv + ["--sigma", "-1"] if head[0] == "converge" else argv + ["--sigmas", "-1"]


def _property(data, budget):
    from hypothesis import strategies as st

    command = data.draw(st.sampled_from(sorted(_FLAGS)))
    argv = command.split()
    for flag in data.draw(st.lists(st.sampled_from(_FLAGS[command]), max_size=4, unique=True)):
        argv += [flag] if flag in _SWITCHES else [flag, data.draw(st.sampled_from(_VALUES))]
    return _cheap(argv)


def _check_property(argv, tmp_path, capsys):
    import glob
    import shutil

    import xarray as xr

    work = tmp_path / "prop"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    os.chdir(work)
    argv = argv + ["--out", "r.nc"] if argv[0] in ("simulate", "stability") and \
        "--out" not in argv else argv
    status, out, err, seconds = run_cli(argv, capsys)
    assert status in (0, 2, 3), f"opa-mc {' '.join(argv)}: exit {status}: {err}"
    assert "Traceback" not in err and "internal error" not in err, err
    if status in (2, 3):
        assert len([line for line in err.splitlines() if line.strip()]) == 1, err
    if status == 0:
        for path in glob.glob(str(work / "**" / "*.nc"), recursive=True):
            with xr.open_dataset(path) as ds:
                gauss = ds.attrs.get("sampler") == "gauss"
                for name, var in ds.data_vars.items():
                    if var.dtype.kind == "f" and not (gauss and name.endswith("_sem")) and \
                            not name.startswith("refinement_"):
                        assert np.isfinite(var.values).all(), f"{name} non-finite: {argv}"
    assert seconds < TIME_LIMIT


def _property_test(examples):
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    @settings(max_examples=examples, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(st.data())
    def prop(tmp_path, capsys, data):
        _check_property(_property(data, examples), tmp_path, capsys)

    return prop


def test_random_flag_combinations_exit_0_2_or_3_without_tracebacks(tmp_path, capsys,
                                                                    monkeypatch):
    """Random flags and values thrown at every subcommand: exit 0, 2 or 3, one line on a
    refusal, no traceback, nothing non-finite written with exit 0, in bounded time."""
    monkeypatch.chdir(tmp_path)
    _property_test(25)(tmp_path, capsys)


@pytest.mark.slow
def test_random_flag_combinations_many(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _property_test(400)(tmp_path, capsys)


@pytest.mark.parametrize("command", [["simulate", "mc", "--samples", "64", "--periods", "1"],
                                     ["stochastic", "--sweep", "c=0.01:0.02:2", "--samples",
                                      "8", "--transient", "10"],
                                     ["bifurcation", "dmr", "--sweep", "c=0.01:0.02:2"]])
def test_a_parts_path_that_is_a_file_names_out(command, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "r.nc.parts").write_text("not a folder")
    status, out, err, seconds = run_cli(command + ["--out", "r.nc"], capsys)
    assert status == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert "--out r.nc: its parts folder r.nc.parts" in err and "is a file" in err
    assert not (tmp_path / "r.nc").exists()


def test_a_non_finite_result_exits_3_writes_nothing_and_keeps_no_checkpoint(
        tmp_path, capsys, monkeypatch):
    """The run's numbers are judged by opa.engine.first_non_finite; the CLI words it with
    its flags (the line as before the rule moved) and mc.checkpoint_lifetime removes the
    run's OUT.parts."""
    import mc

    real = mc.simulate_mc

    def with_nan(*args, **kwargs):
        ds = real(*args, **kwargs)
        ds["x_var"][-1] = np.nan
        return ds

    monkeypatch.setattr(mc, "simulate_mc", with_nan)
    monkeypatch.chdir(tmp_path)
    status, out, err, _ = run_cli(MC + ["--distribution", "uniform", "--out", "r.nc"], capsys)
    assert status == 3
    assert err == ("opa-mc: simulation failed: simulate mc: 1 of 3 values of x_var are not "
                   "finite (law of xi uniform, N = 4); nothing written: try a lower --order, "
                   "a milder --distribution or smaller --sigma\n")
    assert sorted(os.listdir(tmp_path)) == []  # neither r.nc nor r.nc.parts
