"""Check the numbers of docs/findings.md (sections 1-6) against a run of the default job.

    opa-mc validate --outdir results                         # writes results/validate.nc
    python docs/findings.py results                          # the numbers a run gives
    python docs/findings.py results --check docs/findings.md # exit 1 on a stale number
    python docs/findings.py grazing    # x(t, xi) across the omega = 3.98 grazing (section 2)

The same check for the convergence study of docs/elements.md (its section "Convergence
against Monte Carlo", against ``convergence.md`` of ``opa-mc converge``):

    opa-mc converge --outdir results-elements
    python docs/findings.py results-elements --check docs/elements.md \
        --summary convergence.md --from "## Convergence against Monte Carlo" --to "## σ = 0.03"

and for docs/figures.md against the captions of ``opa-mc reproduce all`` (all of it):

    opa-mc reproduce all --outdir figures && cat figures/fig*.txt > figures/captions.md
    python docs/findings.py figures --check docs/figures.md --summary captions.md --to ""

Every number of sections 1-6 of the document must be one the run gives, to the digits the
document prints: the lines of ``results/summary.md`` (written by ``opa-mc validate`` from
the dataset) and a few values the document reads off the dataset directly (the impact-count
shares ``count_prob``, the relative errors ``err_mean_rel`` and ``err_var_rel``, the errors
in standard errors ``err_mean_se``). Numbers
that describe the method rather than the run (the grid, tolerances, the paper's values) are
in ``METHOD_NUMBERS``, and wall times (a number followed by "s") measure the machine, not
the method, so they are not compared; anything else that does not match is printed with
its line and the check fails, so a rerun with another kernel or other defaults cannot
leave a stale number.
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np

# Numbers of the text that are not results of the run: section numbers, the model and the
# grid of the default job, the criterion, the paper's values and plain arithmetic.
METHOD_NUMBERS = {
    1, 2, 3, 4, 5, 6, 7, 8, 10, 25, 50, 100, 1024, 8192, 32768,
    0.1, 0.25, 0.8, 1e-9, 1e-6, 1e-3, 1e-4, 0.005, 0.01, 0.014, 0.02, 0.025, 0.03, 0.04,
    0.05, 3.98, 4.035, 4.09, 4.145, 4.2, 0.000625, 1.25, 1.6, 0.0,
    2.8, 3.9, 5.9, 4.00495, 1000,  # the figures' parameters and impulse_cycle's search
}
# a number not glued to a word or another number ("x43", a count in a run's text, counts)
NUMBER = re.compile(r"(?<![A-Za-wyz_.\d])-?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
SECONDS = re.compile(r"\s?s\b")


def numbers(text: str) -> list[tuple[str, float]]:
    """The numbers of a text as (token, value), wall times ("72 s") left out."""
    text = text.replace("−", "-").replace(",", "")
    out = []
    for match in NUMBER.finditer(text):
        if SECONDS.match(text, match.end()):
            continue
        out.append((match.group(), float(match.group())))
    return out


def digits(token: str) -> int:
    mantissa = token.lstrip("-").split("e")[0].replace(".", "").lstrip("0")
    return max(len(mantissa), 1)


def same(token: str, value: float, candidate: float) -> bool:
    """Does ``candidate`` print as ``token`` (same value to the token's digits)?"""
    if value == candidate:
        return True
    if candidate == 0.0 or value == 0.0 or not math.isfinite(candidate):
        return False
    scale = 10.0 ** (math.floor(math.log10(abs(value))) - digits(token) + 1)
    return abs(candidate - value) <= 0.5 * scale * (1 + 1e-9)


def run_numbers(results: Path, summary: str = "summary.md") -> list[float]:
    """The numbers a run gives: its summary and the dataset values the document quotes."""
    import xarray as xr

    found = [v for _, v in numbers((results / summary).read_text())]
    if not (results / "validate.nc").exists():
        return found
    with xr.open_dataset(results / "validate.nc") as ds:
        for name in ("count_prob", "err_mean_rel", "err_var_rel", "err_mean_se", "split_value",
                     "split_speed", "first_impact"):
            if name in ds:
                values = np.asarray(ds[name].values, dtype=float).ravel()
                values = values[np.isfinite(values)]
                found += values.tolist()
                if name == "count_prob":
                    found += (100 * values).tolist()
                    found += [1.0 - v for v in values]
    return found


def stale(document: Path, results: Path, *, summary: str = "summary.md", start: str = "",
          stop: str = "## 7.") -> list[str]:
    """Lines of ``document`` between ``start`` and ``stop`` (sections 1-6 of findings.md by
    default) with a number the run does not give."""
    text = document.read_text()
    body = text[text.index(start):] if start else text
    body = body.split(stop)[0] if stop else body
    values = run_numbers(results, summary)
    if GRAZING_COMMAND in body:  # the section quotes the grazing measurement: its numbers
        values += [v for line in grazing_lines(results) for _, v in numbers(line)]
    found = np.array(sorted(set(values)))
    bad = []
    for line in body.splitlines():
        if line.startswith("    ") or "`" in line and line.strip().startswith("`"):
            continue  # commands
        for token, value in numbers(line):
            if abs(value) in METHOD_NUMBERS or value in METHOD_NUMBERS:
                continue
            near = found[np.abs(found - value) <= abs(value) * 0.06 + 1e-300]
            if not any(same(token, value, float(c)) for c in near):
                bad.append(f"{token}: {line.strip()}")
    return bad


GRAZING_STEPS = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
GRAZING_COMMAND = "python docs/findings.py grazing"


def grazing_lines(results: Path) -> list[str]:
    """The lines of ``python docs/findings.py grazing``: read from ``results/grazing.txt``
    when a run left it there, else measured now (about 10 s) and written there."""
    path = results / "grazing.txt"
    if path.exists():
        return path.read_text().splitlines()
    lines = grazing()
    if results.is_dir():
        path.write_text("\n".join(lines) + "\n")
    return lines


def grazing(omega: float = 3.98, periods: int = 10, per_period: int = 256) -> list[str]:
    """How x(t, mu) behaves across the grazing split of the default map at ``omega``
    (section 3.2 set): the split located to 1e-13 in mu with rtol = atol = 1e-12, then the
    largest change of x over the window, max_t |x(t, mu_s + d) - x(t, mu_s - d)| on
    ``per_period`` outputs per forcing period, for each d of ``GRAZING_STEPS``, and the
    exponent fitted to it (1/2: continuous with a square-root singularity; 0: a jump)."""
    from opa import SolverOptions, preset, simulate_dmr
    from opa._splits import ScanOptions, scan_splits

    osc = preset("3.2", omega=omega)
    options = SolverOptions(rtol=1e-12, atol=1e-12)
    T = osc.forcing_period
    scan = scan_splits(osc, options, "mu", 0.7775, 0.7776, periods * T,
                       ScanOptions(scan=9, tol=1e-13, center=0.7775630))
    (split,) = [s for s in scan.splits if s.kind == "grazing"]
    lines = [f"omega = {omega:g}, {periods} periods, rtol = atol = {options.rtol:g}: grazing "
             f"split at mu_s = {split.value:.10f} (bracket {split.tol:.1e}), new impact at "
             f"t = {split.time / T:.2f} periods, speed there {abs(split.speed):.1e}"]
    change = []
    for d in GRAZING_STEPS:
        xs = [simulate_dmr(osc.replace(mu=split.value + sign * d), periods=periods,
                           per_period=per_period, options=options).x.values
              for sign in (-1.0, 1.0)]
        change.append(float(np.max(np.abs(xs[1] - xs[0]))))
        lines.append(f"d = {d:.0e}: max_t |x(t, mu_s + d) - x(t, mu_s - d)| = {change[-1]:.2e}")
    slope = np.polyfit(np.log(GRAZING_STEPS), np.log(change), 1)[0]
    lines.append(f"fitted exponent: change ~ d^{slope:.3f}")
    return lines


def main(argv: list[str]) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if argv else 2
    if argv[0] == "grazing":
        print("\n".join(grazing()))
        return 0
    results = Path(argv[0])
    def option(name, default):
        return argv[argv.index(name) + 1] if name in argv else default

    if "--check" in argv:
        document = Path(option("--check", ""))
        bad = stale(document, results, summary=option("--summary", "summary.md"),
                    start=option("--from", ""), stop=option("--to", "## 7."))
        for line in bad:
            print(f"not in the run: {line}")
        print(f"{document}: {'stale numbers' if bad else 'every number matches the run'}"
              f" ({len(bad)} mismatches)")
        return 1 if bad else 0
    print((results / option("--summary", "summary.md")).read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
