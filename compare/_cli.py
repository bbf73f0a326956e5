"""``opa-mc validate``: the main job (the argparse part; the work is in _validate)."""

from __future__ import annotations

import argparse
import os
import sys
import time

from opa._model import PARAMETER_NAMES


def _float_list(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}")


def _order_list(text: str) -> tuple[int, ...]:
    """'0:8' (inclusive range) or '0,1,2,4,8'."""
    try:
        if ":" in text:
            lo, hi = (int(v) for v in text.split(":"))
            return tuple(range(lo, hi + 1))
        return tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A:B or comma-separated integers, got {text!r}")


def register_validate(sub, model_flags, solver_flags) -> None:
    p = sub.add_parser(
        "validate",
        help="the main job: OPA against Monte Carlo, error tables, figures, netCDF",
        description="Run OPA for N = 0..Nmax beside a Monte Carlo ensemble of the true "
        "sampled impact system and report where they agree. With no arguments: the "
        "embedded default (section 3.2 parameters, omega = 3.98, sigma in {0.005, 0.01, "
        "0.02}, N = 0..8, 2^14 Sobol samples, 100 forcing periods).",
    )
    model_flags(p)
    g = p.add_argument_group("validation")
    g.add_argument("--config", default=None, metavar="FILE.toml",
                   help="TOML file with any of the settings below and [model]/[solver] tables")
    g.add_argument("--sigmas", type=_float_list, default=None, metavar="S1,S2,...",
                   help="intensities of the uncertain parameter (default 0.005,0.01,0.02)")
    g.add_argument("--orders", type=_order_list, default=None, metavar="A:B",
                   help="OPA orders, 'A:B' inclusive or a comma list (default 0:8)")
    g.add_argument("--uncertain", choices=("mu", "a", "c"), default=None,
                   help="the uncertain parameter (default mu)")
    g.add_argument("--samples", type=int, default=None, metavar="M",
                   help="Monte Carlo samples of the reference (default 16384)")
    g.add_argument("--sampler", choices=("random", "sobol", "gauss"), default=None,
                   help="sampler of the reference (default sobol)")
    g.add_argument("--seed", type=int, default=None, metavar="K", help="random seed (default 0)")
    g.add_argument("--periods", type=float, default=None, metavar="P",
                   help="length in forcing periods (default 100)")
    g.add_argument("--per-period", type=int, default=None, metavar="K",
                   help="outputs per forcing period (default 4)")
    g.add_argument("--window", type=float, default=None, metavar="W",
                   help="error tables summarise the first W periods (default 10)")
    g.add_argument("--outdir", default=None, metavar="DIR", help="output folder (default results)")
    g.add_argument("--no-plots", action="store_true", help="skip the figures")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask distributed scheduler for the Monte Carlo chunks")
    g.add_argument("--quiet", action="store_true", help="no progress bars")
    solver_flags(p, tolerance=1e-9, defaults=False)
    p.set_defaults(func=cmd_validate)


def cmd_validate(args) -> int:
    from compare._report import error_table, findings, write_report
    from compare._validate import load_config, run_validation

    model = {name: getattr(args, name) for name in PARAMETER_NAMES
             if getattr(args, name, None) is not None}
    if args.preset:
        model["preset"] = args.preset
    solver = {k: getattr(args, k) for k in ("rtol", "atol", "impulse", "pulse_width",
                                            "impulse_at_zero", "max_step", "chatter_velocity")
              if getattr(args, k, None) is not None}
    cfg = load_config(
        args.config, model=model, solver=solver, sigmas=args.sigmas, orders=args.orders,
        uncertain=args.uncertain, samples=args.samples, sampler=args.sampler, seed=args.seed,
        periods=args.periods, per_period=args.per_period, window=args.window,
        outdir=args.outdir, plots=False if args.no_plots else None, scheduler=args.scheduler,
    )
    start = time.perf_counter()
    log = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    ds = run_validation(cfg, progress=not args.quiet, log=log)
    written = write_report(ds, cfg.outdir, plots=cfg.plots)
    print(error_table(ds))
    print()
    for line in findings(ds):
        print(f"* {line}")
    print(f"\nwrote {os.path.join(cfg.outdir, 'validate.nc')}, "
          + ", ".join(written) + f" in {time.perf_counter() - start:.1f} s")
    return 0
