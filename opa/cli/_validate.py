"""``opa-mc validate``: the main job, the trust map (argparse here; the work in _trustmap)."""

from __future__ import annotations

import argparse
import os
import shlex
import sys

import numpy as np

from opa import IMPULSE_FIELDS, MAX_GRID, PARAMETER_NAMES, UNCERTAIN_PARAMETERS
from opa.cli._args import parse_sweep, positive_int, whole_number
from opa.cli._flags import (
    OSCILLATOR_FLAGS, CliError, _elements_arg, _impulse_flags, _model_flags, _solver_flags,
    uncertain_names,
)
from opa.cli._trustline import cmd_trust_line, relative_sizes



def _float_list(text: str) -> tuple[float, ...]:
    """'0.01,0.02' as distinct numbers."""
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") \
            from None
    if not values:
        raise argparse.ArgumentTypeError(f"expected at least one number, got {text!r}")
    if len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(f"values must be distinct, got {text!r}")
    return values


def _order_list(text: str) -> tuple[int, ...]:
    """'0:8' (inclusive range, A <= B) or '0,1,2,4,8' (distinct)."""
    try:
        if ":" in text:
            lo, hi = (int(v) for v in text.split(":"))
            if lo > hi:
                raise argparse.ArgumentTypeError(f"A:B needs A <= B, got {text!r}")
            if hi - lo + 1 > MAX_GRID:  # refused before the range is built
                raise argparse.ArgumentTypeError(f"at most {MAX_GRID} values, got "
                                                 f"{hi - lo + 1} in {text!r}")
            values = tuple(range(lo, hi + 1))
        else:
            values = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A:B or comma-separated integers, got "
                                         f"{text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError(f"expected at least one integer, got {text!r}")
    if len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(f"values must be distinct, got {text!r}")
    if len(values) > MAX_GRID:
        raise argparse.ArgumentTypeError(f"at most {MAX_GRID} values, got {len(values)}")
    return values


def _sweep(text: str) -> tuple[str, tuple[float, ...]]:
    """``--sweep`` of ``validate`` (the grammar of ``opa.cli._args.parse_sweep``)."""
    try:
        name, values, _ = parse_sweep(text, names=PARAMETER_NAMES, max_count=MAX_GRID)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err).removeprefix(f"--sweep {text!r}: ")) \
            from None
    return name, tuple(float(np.round(v, 12)) for v in values)


def register_validate(sub) -> None:
    p = sub.add_parser(
        "validate",
        help="the main job: the trust map of OPA against Monte Carlo, its boundary and why",
        description="Run OPA (N = 0..8, the mean, ensemble and saltation impact laws, both "
        "truncations; with --elements also multi-element OPA) beside Monte Carlo ensembles of "
        "the true sampled impact systems over a grid of sigma and one model parameter; "
        "locate the trust boundary sigma* by bisection and the splits of "
        "the sampled systems' impact sequences. With no arguments: the embedded default "
        "(section 3.2 set, omega in {3.98, 4.035, 4.09, 4.145, 4.2}, sigma from 0.005 to "
        "0.05, horizons of 10 and 50 forcing periods). Writes OUTDIR/validate.nc, "
        "summary.md and figures; finished Monte Carlo runs are kept in OUTDIR/parts and "
        "reused, so an interrupted run resumes.",
    )
    _model_flags(p)
    g = p.add_argument_group("trust map")
    g.add_argument("--config", default=None, metavar="FILE.toml",
                   help="TOML file with any of the settings below and [model]/[solver] tables")
    g.add_argument("--sweep", type=_sweep, default=None, metavar="NAME=START:STOP:COUNT",
                   help="the swept model parameter and its values (default: the preset's "
                        "range; 3.1: c, 3.2 and 3.3: omega)")
    g.add_argument("--values", type=_float_list, default=None, metavar="V1,V2,...",
                   help="values of the swept parameter (instead of --sweep's range)")
    g.add_argument("--sigmas", type=_float_list, default=None, metavar="S1,S2,...",
                   help="grid of intensities (default 0.005,0.01,0.014,0.02,0.025,0.03,0.04,"
                        "0.05; preset 3.3: up to 0.2)")
    g.add_argument("--orders", type=_order_list, default=None, metavar="A:B",
                   help="OPA orders, 'A:B' inclusive or a comma list (default 0:8)")
    g.add_argument("--uncertain", type=uncertain_names, default=None, metavar="P[,P...]",
                   help="the uncertain parameter (default mu); several (mu,c) run the trust "
                        "line instead: the verdicts along one scale s of --relative, "
                        "--sigmas being the grid of s (docs/several.md)")
    g.add_argument("--relative", type=relative_sizes, default=None, metavar="R1,R2,...",
                   help="several uncertain parameters: each one's spread relative to its "
                        "nominal value at scale 1 (sigma_j = s x R_j x |p_bar_j|)")
    g.add_argument("--distribution", default=None, metavar="LAW",
                   help="law of xi: semicircle (the paper's), uniform, beta:A,B or "
                        "normal-trunc:K, all on [-1, 1]; the Monte Carlo ensembles sample it "
                        "and single-element OPA runs in its orthonormal basis (the paper "
                        "truncation exists for the semicircle only) (default semicircle)")
    g.add_argument("--elements", type=_elements_arg, default=None, metavar="K|adaptive",
                   help="add multi-element variants (mean, ensemble and saltation laws, "
                        "at N = Nmax, with their own verdicts and sigma*): K >= 2 "
                        "equal-probability elements, or 'adaptive' (edges at the "
                        "impact-sequence splits, then refinement) (default: single element "
                        "only)")
    g.add_argument("--max-elements", type=positive_int, default=None, metavar="K",
                   help="adaptive elements: the element budget (default 64)")
    g.add_argument("--horizons", type=_float_list, default=None, metavar="H1,H2",
                   help="horizons in forcing periods (default 10,50)")
    g.add_argument("--tolerance", type=float, default=None, metavar="TOL",
                   help="the mean agrees while its running RMS error <= TOL x the running RMS "
                        "MC spread, certified at error rate ALPHA (default 0.1)")
    g.add_argument("--var-tolerance", type=float, default=None, metavar="TOL",
                   help="the same for the variance, relative to the MC variance (default 0.25)")
    g.add_argument("--alpha", type=float, default=None, metavar="ALPHA",
                   help="the error rate of each verdict: agrees / disagrees hold with "
                        "probability >= 1 - ALPHA over the doublings and the outputs "
                        "(default 0.01)")
    g.add_argument("--resolution", type=float, default=None, metavar="DS",
                   help="bisection resolution of sigma* (default 1e-3)")
    g.add_argument("--samples", type=positive_int, default=None, metavar="M",
                   help="Sobol samples of a point's first round, paired with every OPA "
                   "run (default 128; 16 replicates)")
    g.add_argument("--max-samples", type=positive_int, default=None, metavar="M",
                   help="samples are doubled up to M while a verdict is undecided "
                        "(default 8192)")
    g.add_argument("--long-splits", type=positive_int, default=None, metavar="K",
                   help="the most splits located per value over each horizon but the "
                        "shortest (default 128; the shortest: 1024); past it the impact "
                        "counts are marked incomplete")
    g.add_argument("--seed", type=whole_number, default=None, metavar="K",
                   help="random seed (default 0)")
    g.add_argument("--per-period", type=positive_int, default=None, metavar="K",
                   help="outputs per forcing period (default 8)")
    g.add_argument("--outdir", default=None, metavar="DIR", help="output folder (default results)")
    g.add_argument("--no-plots", action="store_true", help="skip the figures")
    g.add_argument("--no-frontier", action="store_true",
                   help="skip the cost-accuracy frontier (multi-element OPA, collocation, "
                        "MC and Sobol at the first value and the largest sigma)")
    g.add_argument("--workers", type=positive_int, default=None, metavar="W",
                   help="local processes for the map's tasks (split scans, grid points, "
                        "bisections, the frontier's runs), each task with its share of the "
                        "free cores as numba threads (default: one per core up to the "
                        "number of first tasks when the values and the frontier are at "
                        "least 3, else 1)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler that runs the map's tasks (each with its "
                        "machine's cores shared out among the Dask threads there)")
    g.add_argument("--quiet", action="store_true", help="no progress bars or log lines")
    _solver_flags(p, tolerance=1e-9, defaults=False)
    _impulse_flags(p, defaults=False)
    p.set_defaults(func=cmd_validate)


def _check_outdir(path: str) -> None:
    """Fail before computing when the output folder cannot be written."""
    from opa.cli._paths import check_output_dir

    check_output_dir("--outdir", path)  # probes a write in the folder or its nearest parent
    try:
        os.makedirs(os.path.join(path, "parts"), exist_ok=True)
    except OSError as err:
        raise ValueError(f"--outdir {path} cannot be created: {err.strerror}") from None


def _validate_model(args) -> None:
    """``validate --model FILE``: the file's oscillator and force law under the
    parameter flags. The file's [uncertain.NAME] tables name the uncertain parameters
    and their laws unless ``--uncertain`` is given; validate sweeps its own grid of
    sigma, so with several parameters the file's sigma_j / |p_bar_j| are the relative
    sizes (``--relative``, sigma_j at scale 1) unless given, and with one the file's
    sigma is not used (said on stderr)."""
    from opa.cli._flags import model_from, oscillator_from, say

    model = model_from(args)
    if model is None:
        oscillator_from(args)  # a refused flag's value named as its flag
        return
    osc = oscillator_from(args)
    if model.problem is not None and args.uncertain is None:
        _uncertain_of_file(args, model.problem, osc)
    elif model.problem is not None:
        given = args.uncertain if isinstance(args.uncertain, str) else ",".join(args.uncertain)
        say(f"--model {args.model_file}: its [uncertain.NAME] tables are set aside for "
            f"--uncertain {given}")
    unused = () if osc.force is None else tuple(  # mu, a, c a user's law does not name
        name for name in ("mu", "a", "c") if name not in osc.force.names)
    for name in OSCILLATOR_FLAGS:  # every value of the file, the flags' included
        if name not in unused:  # (as flags they would be refused as having no effect)
            setattr(args, name, getattr(osc, name))
    args.force_law = osc.force  # and its force law (None: the paper's)


def _uncertain_of_file(args, problem, osc) -> None:
    """``--uncertain``, ``--distribution`` and (several parameters) ``--relative`` from a
    model file's [uncertain.NAME] tables, each unless its flag was given."""
    from opa.cli._flags import say

    names, laws = problem.names, ["semicircle" if law is None else str(law)
                                  for law in problem.laws]
    several = problem.dimension > 1
    args.uncertain = names if several else names[0]
    if args.distribution is None:
        args.distribution = ",".join(laws)
    if not several:
        say(f"--model {args.model_file}: uncertain {names[0]} ({laws[0]}) from its "
            f"[uncertain.{names[0]}] table; validate sweeps its own grid of sigma "
            f"(--sigmas), so the file's sigma = {problem.scales[0]:g} is not used")
        return
    if args.relative is None:
        means = [abs(osc.value(name)) for name in names]
        if not all(means):
            zero = ",".join(n for n, m in zip(names, means) if not m)
            raise CliError(f"--model {args.model_file}: {zero} = 0 has no size relative to "
                           f"its nominal value: give --relative R1,R2,... (sigma_j = scale x "
                           f"R_j x |p_bar_j|) or --uncertain")
        args.relative = tuple(s / m for s, m in zip(problem.scales, means))
    sizes = ("" if args.relative is None else
             f"; relative sizes {', '.join(f'{r:.4g}' for r in args.relative)} (the file's "
             f"sigma at scale 1)")
    say(f"--model {args.model_file}: uncertain {','.join(names)} ({','.join(laws)}) from "
        f"its [uncertain.NAME] tables{sizes}")


def cmd_validate(args) -> int:
    _validate_model(args)
    if isinstance(args.uncertain, tuple):  # several uncertain parameters: the trust line
        return cmd_trust_line(args)
    if args.relative is not None:
        raise CliError("--relative applies with several uncertain parameters (--uncertain "
                       "mu,c); with one, --sigmas are the intensities themselves")
    from compare import load_config

    model = {name: getattr(args, name) for name in OSCILLATOR_FLAGS
             if getattr(args, name, None) is not None}
    if args.preset:
        model["preset"] = args.preset
    if getattr(args, "force_law", None) is not None:
        model["force"] = args.force_law
    solver = {k: getattr(args, k) for k in ("rtol", "atol", "max_step", "chatter_velocity",
                                            "method")
              if getattr(args, k, None) is not None}
    impulse = {k: getattr(args, k) for k in IMPULSE_FIELDS if getattr(args, k, None) is not None}
    parameter, values = (args.sweep if args.sweep else (None, None))
    if args.values is not None:
        values = args.values
    cfg = load_config(
        args.config, model=model, solver=solver, parameter=parameter, values=values,
        sigmas=args.sigmas, orders=args.orders, uncertain=args.uncertain,
        distribution=args.distribution, elements=args.elements,
        max_elements=args.max_elements, horizons=args.horizons, tolerance=args.tolerance,
        var_tolerance=args.var_tolerance,
        alpha=args.alpha, resolution=args.resolution, samples=args.samples,
        max_samples=args.max_samples, seed=args.seed, per_period=args.per_period,
        long_splits=args.long_splits,
        outdir=args.outdir, plots=False if args.no_plots else None, scheduler=args.scheduler,
        workers=args.workers, frontier=False if args.no_frontier else None, **impulse,
    )
    _check_outdir(cfg.outdir)
    from opa.engine import announce_compilation

    announce_compilation()  # here, once: the workers started below then compile in silence
    if cfg.processes > 1 and cfg.scheduler is None:
        # the workers' fork server imports the map's modules while this process does
        from compare import map_preload
        from opa.engine import start_fork_server

        start_fork_server(map_preload(cfg.plots))
    from compare import (bullet, cause, findings, first_screen, frontier_lines,
                         run_validation, verdict_grid, wall_text, write_report)
    from opa.engine import OutputLock, process_started

    start = process_started()  # the one clock of the run: every wall time below reads it
    log = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    command = "opa-mc " + shlex.join(getattr(args, "argv", ["validate"]))
    timing: dict = {}
    # the figures side by side on the map's processes (its fork server is started then)
    figures = cfg.processes if cfg.scheduler is None and cfg.processes > 1 else 1
    # OUTDIR stays locked until the last figure is written (run_validation takes it again)
    with OutputLock(cfg.outdir, "output folder", folder=True,
                    log=lambda line: print(line, file=sys.stderr)):
        ds = run_validation(cfg, progress=not args.quiet, log=log, started=start)
        written = write_report(ds, cfg.outdir, plots=cfg.plots, command=command,
                               started=start, timing=timing, workers=figures,
                               source=os.path.join(cfg.outdir, "validate.nc"))
    print("\n".join(first_screen(ds)))
    print()
    for h in range(ds.sizes["horizon"]):
        print(verdict_grid(ds, h, compact=True))
        print()
    elements = [v for v, name in enumerate(ds.variant.values) if "/ME-" in str(name)]
    for q in range(ds.sizes[ds.attrs["parameter"]]):
        for h in range(ds.sizes["horizon"]):
            print(bullet(cause(ds, q, h)))
            for v in elements:  # the multi-element variants' own boundaries
                print(bullet(f"[{ds.variant.values[v]}] {cause(ds, q, h, v)}"))
    if ds.attrs.get("variants_dropped", "none") != "none":
        print(bullet(f"variants left out: {ds.attrs['variants_dropped']}"))
    print()
    for line in findings(ds):
        print(bullet(line))
    front = frontier_lines(ds)
    if front:
        print("\n" + bullet(front[0], mark=""))
        for line in front[1:]:
            print(bullet(line))
    print("\n" + bullet(f"wrote {os.path.join(cfg.outdir, 'validate.nc')}, "
                        + ", ".join(written) + " (tables in summary.md)", mark=""))
    print(f"wall time {wall_text(timing)}, from the command's start")
    return 0


def register_converge(sub) -> None:
    from opa.cli._flags import scales, uncertain_names

    p = sub.add_parser(
        "converge",
        help="multi-element OPA against Monte Carlo: error against elements, N and cost",
        description="Convergence of multi-element OPA (uniform and adaptive elements, mean "
        "and saltation impact laws) and multi-element collocation against a Sobol "
        "reference, beside single-element OPA, collocation, MC and QMC, with right-hand "
        "sides and wall times. Default: section 3.2 set, omega = 3.98, sigma = 0.05, 10 "
        "forcing periods, 2^16 reference samples. With several uncertain parameters "
        "(--uncertain mu,c) the elements are boxes, and collocation and the control-variate "
        "ladder (one parameter only) are left out.",
    )
    _model_flags(p)
    g = p.add_argument_group("study")
    g.add_argument("--sigma", type=scales, default=0.05, metavar="S[,S...]",
                   help="scale of each uncertain parameter: one value, or one per --uncertain "
                        "name (default 0.05)")
    g.add_argument("--uncertain", type=uncertain_names, default="mu", metavar="P[,P...]",
                   help=f"the uncertain parameters p = p_bar + sigma xi, among "
                        f"{', '.join(UNCERTAIN_PARAMETERS)}: one, or several such as mu,c "
                        f"(default mu, or the --model file's [uncertain.NAME] tables)")
    g.add_argument("--distribution", default="semicircle", metavar="LAW[,LAW...]",
                   help="law of xi: semicircle, uniform, beta:A,B, normal-trunc:K; one, or "
                        "one per --uncertain name")
    g.add_argument("--periods", type=float, default=10.0, metavar="P",
                   help="window in forcing periods (default 10)")
    g.add_argument("--order", type=whole_number, default=1, metavar="N",
                   help="OPA order of every element for the sweeps in K (default 1)")
    g.add_argument("--budgets", type=_order_list, default=None, metavar="B1,B2,...",
                   help="element budgets of the adaptive runs "
                        "(default 4,8,16,24,32,48,64,96,128,192,256)")
    g.add_argument("--uniform", type=_order_list, default=None, metavar="K1,K2,...",
                   help="element counts of the uniform runs (default 1,2,...,128)")
    g.add_argument("--reference", type=positive_int, default=65536, metavar="M",
                   help="Sobol samples of the reference (default 65536)")
    g.add_argument("--outdir", default="results-elements", metavar="DIR",
                   help="output folder (default results-elements)")
    g.add_argument("--workers", type=positive_int, default=1, metavar="W",
                   help="local processes for the study's runs, each with cores/W numba "
                        "threads (default 1: one process)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler: the study's runs as tasks there")
    g.add_argument("--quiet", action="store_true", help="no log lines")
    _solver_flags(p, tolerance=1e-9)
    _impulse_flags(p)
    p.set_defaults(func=cmd_converge)


def cmd_converge(args) -> int:
    from compare import (ConvergenceConfig, convergence_lines, run_convergence,
                         write_convergence_report)
    from opa.cli._flags import (MAX_WORKERS, CliError, flagged, oscillator_from,
                                options_from, uncertain_from)

    if args.workers > MAX_WORKERS:
        raise ValueError(f"--workers must be at most {MAX_WORKERS} (4 per CPU), got "
                         f"{args.workers}")
    oscillator = oscillator_from(args)
    _check_outdir(args.outdir)
    kw = {k: v for k, v in (("budgets", args.budgets), ("uniform", args.uniform))
          if v is not None}
    drawn = uncertain_from(args)  # a --model file's [uncertain.NAME], under the flags
    for key, value in drawn.items():
        setattr(args, key, value)
    if drawn.get("allow_negative"):
        kw["allow_negative"] = True
    if args.distribution is None or isinstance(args.distribution, tuple):
        args.distribution = ",".join("semicircle" if law is None else str(law)
                                     for law in np.atleast_1d(args.distribution))
    uncertain = (",".join(args.uncertain) if isinstance(args.uncertain, tuple)
                 else args.uncertain)
    try:
        cfg = ConvergenceConfig(oscillator=oscillator, options=options_from(args),
                                sigma=args.sigma, uncertain=uncertain,
                                distribution=args.distribution, periods=args.periods,
                                order=args.order, reference=args.reference,
                                outdir=args.outdir, impulse=args.impulse,
                                pulse_width=args.pulse_width,
                                impulse_at_zero=args.impulse_at_zero, **kw)
    except ValueError as err:  # the library's "sigma ..." as the flag typed, "--sigma ..."
        raise CliError(flagged(err, ("sigma", "distribution", "uncertain", "budgets",
                                     "uniform", "reference"))) from None
    log = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    ds = run_convergence(cfg, log=log, workers=args.workers, scheduler=args.scheduler)
    from compare import plot_frontier  # matplotlib, once the study's workers are done

    command = "opa-mc " + shlex.join(getattr(args, "argv", ["converge"]))
    written = write_convergence_report(ds, args.outdir, draw=plot_frontier, command=command)
    for line in convergence_lines(ds):
        print(f"* {line}")
    print(f"\nwrote {os.path.join(args.outdir, 'convergence.nc')}, " + ", ".join(written))
    return 0
