"""``opa-mc sobol`` (``opa/cli/_sobol.py``), run in process: its table and files against an
independent truth (scipy at a tensor Gauss rule), and its refusals: one line naming the
flag, exit 2, no traceback, nothing computed."""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import xarray as xr  # noqa: E402
from scipy import special  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import compare  # noqa: E402
import compare._certify_sobol as certifier  # noqa: E402
from opa.cli._main import main  # noqa: E402

# the no-impact case of tests/compare/test_certify_sobol.py
FREE = dict(mu=0.3, a=1.0, c=0.5, f=0.4, omega=1.3, delta=50.0, F0=0.0, x0=0.5, v0=0.0)
SETTINGS = {"--uncertain": "mu,c", "--sigma": "0.06,0.2", "--distribution": "semicircle,uniform",
            **{f"--{k}": str(value) for k, value in FREE.items()}, "--periods": "2",
            "--per-period": "4", "--order": "4", "--samples": "64", "--rtol": "1e-12",
            "--atol": "1e-12"}


def flags(**changes) -> list[str]:
    """The command line of the no-impact case, each flag once (``samples="0"`` changes
    ``--samples``)."""
    given = {**SETTINGS, **{f"--{k.replace('_', '-')}": v for k, v in changes.items()}}
    return [text for flag, value in given.items() for text in (flag, value)]


def truth_at_the_end(q=10):
    """First-order and total indices of x at t = 2 forcing periods (mu, c), from scipy at
    the q x q Gauss rule of the semicircle and uniform laws."""
    x1, w1 = special.roots_chebyu(q)
    x2, w2 = special.roots_legendre(q)
    w1, w2 = w1 / w1.sum(), w2 / w2.sum()
    omega, end = FREE["omega"], 2 * (2 * np.pi / FREE["omega"])
    x = np.empty((q, q))
    for i, a in enumerate(x1):
        for j, b in enumerate(x2):
            mu, c = FREE["mu"] + 0.06 * a, FREE["c"] + 0.2 * b
            sol = solve_ivp(lambda t, y: [y[1], mu * (1 - y[1] ** 2) * y[1] - y[0]
                                          - c * y[0] ** 3 + FREE["f"] * np.cos(omega * t)],
                            (0, end), [FREE["x0"], 0.0], method="DOP853", rtol=1e-12,
                            atol=1e-12)
            x[i, j] = sol.y[0, -1]
    W = np.outer(w1, w2)
    mean = (W * x).sum()
    var = (W * (x - mean) ** 2).sum()
    given1, given2 = x @ w2, w1 @ x
    first = np.array([w1 @ (given1 - mean) ** 2, w2 @ (given2 - mean) ** 2]) / var
    total = np.array([w2 @ (w1[:, None] * (x - given2[None]) ** 2).sum(axis=0),
                      w1 @ (w2[None] * (x - given1[:, None]) ** 2).sum(axis=1)]) / var
    return first, total


def test_sobol_prints_the_table_and_writes_the_dataset_and_figure(tmp_path, capsys):
    out, png = tmp_path / "sobol.nc", tmp_path / "sobol.png"
    assert main(["sobol", *flags(), "--out", str(out), "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    lines = text.splitlines()
    header = next(i for i, line in enumerate(lines) if "S_i surrogate" in line)
    assert lines[header].split() == ["parameter", "S_i", "surrogate", "S_i", "certified",
                                     "ST_i", "surrogate", "ST_i", "certified"]
    rows = {line.split()[0]: line for line in lines[header + 1:header + 3]}
    assert set(rows) == {"mu", "c"}
    assert "agreement:" in text and "1024" not in rows["mu"]
    with xr.open_dataset(out) as ds:
        ds = ds.load()
    assert ds.attrs["true_system_runs"] == 4 * 64
    first, total = truth_at_the_end()
    for p, parameter in enumerate(("mu", "c")):
        for kind, exact in (("first", first), ("total", total)):
            name = f"x_sobol_{kind}"
            low = float(ds[f"{name}_lower"].sel(parameter=parameter)[-1])
            high = float(ds[f"{name}_upper"].sel(parameter=parameter)[-1])
            assert low <= exact[p] <= high, (parameter, kind, low, exact[p], high)
            # the table shows the file's numbers
            if int(ds[f"{name}_reading"].sel(parameter=parameter)[-1]) == 0:
                value = float(ds[name].sel(parameter=parameter)[-1])
                assert f"{value:.4g} ± " in rows[parameter]
            else:
                assert f"within noise [0, {high:.3g}]" in rows[parameter]
            surrogate = float(ds[f"{name}_surrogate"].sel(parameter=parameter)[-1])
            assert f"{surrogate:.4g}" in rows[parameter]
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize("law, warned", [("mean", True), ("saltation", False)])
def test_an_uncertain_restitution_under_the_mean_law_is_warned(law, warned, capsys):
    """The mean impact law reflects every node with the mean eta: the surrogate has no
    spread from an uncertain eta, and the command says so (as simulate opa does)."""
    impacting = flags(uncertain="eta,c", sigma="0.05,0.005", delta="0.6", periods="1",
                      order="2", impact_law=law, rtol="1e-10", atol="1e-10")
    assert main(["sobol", *impacting, "--quiet"]) == 0
    text = capsys.readouterr().out
    assert ("warning: impact law mean reflects with the mean eta" in text) == warned


@pytest.mark.parametrize("change, flag", [
    (dict(uncertain="mu", sigma="0.06"), "--uncertain mu: Sobol indices need at least two"),
    (dict(samples="0"), "argument --samples"),
    (dict(uncertain="mu,x"), "--uncertain must name parameters among"),
    (dict(samples="100"), "--samples must be a power of two"),
    (dict(sigma="0.06,0.2,0.1"), "--sigma must give one value"),
    (dict(basis="cubic"), "--basis must be one of"),
])
def test_bad_input_exits_2_with_one_line_naming_the_flag(change, flag, capsys, monkeypatch):
    if "basis" not in flag:  # the OPA run refuses a basis itself
        monkeypatch.setattr(certifier, "simulate_opa", _never)
    monkeypatch.setattr(certifier, "run_batch", _never)
    assert exit_code(["sobol", *flags(**change)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and flag in err and "Traceback" not in err, err


def test_an_out_that_cannot_be_written_is_refused_before_computing(tmp_path, capsys,
                                                                      monkeypatch):
    monkeypatch.setattr(compare, "certify_sobol", _never)
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert exit_code(["sobol", *flags(), "--out", str(blocker / "missing" / "s.nc")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("opa-mc: error: --out") and "is not a folder" in err


def _never(*args, **kwargs):
    raise AssertionError("computed before the inputs were checked")


def exit_code(argv) -> int:
    """``main``'s status, or argparse's (which exits)."""
    try:
        return main(argv)
    except SystemExit as done:
        return done.code
