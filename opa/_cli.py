"""The ``opa-mc`` command line (``opa-mc COMMAND --help`` explains every flag).

Every model parameter is a flag of its own name (``--omega 3.98 --F0 0``); the common
flags are shared by every subcommand. User mistakes get one line on stderr naming the
parameter and the value, and exit status 2; a trajectory that cannot be completed exits
with status 3. No tracebacks for either.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

from opa._model import (
    IMPACT_LAWS,
    IMPULSE_MODELS,
    METHODS,
    PARAMETER_DOCS,
    PARAMETER_NAMES,
    PRESETS,
    TRUNCATIONS,
    UNCERTAIN_PARAMETERS,
    Oscillator,
    SolverOptions,
)

from opa._argtypes import EXIT_USAGE, Parser, positive_int, whole_number

EXIT_SIMULATION = 3
MAX_WORKERS = 4 * (os.cpu_count() or 1)


class CliError(Exception):
    """A user mistake detected after parsing (reported without traceback)."""


def _model_flags(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("model parameters (paper eq. 1; defaults: section 3.2)")
    group.add_argument("--preset", choices=sorted(PRESETS),
                       help="start from the paper's parameter set of this section; "
                            "explicit flags override it (3.3 uses c = 0.05, our choice)")
    defaults = Oscillator()
    for name in PARAMETER_NAMES:
        group.add_argument(f"--{name}", type=float, default=None, metavar="VALUE",
                           help=f"{PARAMETER_DOCS[name]} (default {getattr(defaults, name):g})")


def _common_flags(parser: argparse.ArgumentParser, *, mc: bool = True) -> None:
    g = parser.add_argument_group("run")
    g.add_argument("--periods", type=float, default=100.0, metavar="P",
                   help="length in forcing periods 2 pi/omega (default 100)")
    g.add_argument("--per-period", type=positive_int, default=1, metavar="K",
                   help="outputs per forcing period: t_j = j (2 pi/omega)/K, j = 0..P K; "
                        "K = 1 gives the stroboscopic samples (default 1)")
    g.add_argument("--sigma", type=float, default=0.01, metavar="S",
                   help="intensity of the uncertain parameter p = p_bar + S xi (default 0.01)")
    g.add_argument("--uncertain", choices=UNCERTAIN_PARAMETERS, default="mu",
                   help="which parameter is uncertain (default mu)")
    g.add_argument("--allow-negative", action="store_true",
                   help="allow p_bar - sigma < 0 for the uncertain parameter")
    g.add_argument("--order", type=whole_number, default=4, metavar="N",
                   help="OPA truncation order / highest MC Chebyshev coefficient (default 4)")
    g.add_argument("--truncation", choices=TRUNCATIONS, default="galerkin",
                   help="galerkin: exact projection; paper: eq. (27), drops sigma/2 Y_{N+1} "
                        "(default galerkin)")
    g.add_argument("--impact-law", choices=IMPACT_LAWS, default="mean",
                   help="mean: only x_0' jumps (eq. 28); ensemble: every velocity coefficient "
                        "is multiplied by -eta; saltation: the impact's saltation matrix "
                        "maps the deviation coefficients (default mean)")
    if mc:
        g.add_argument("--samples", type=positive_int, default=1024, metavar="M",
                       help="Monte Carlo samples (default 1024)")
        g.add_argument("--sampler", choices=("random", "sobol", "gauss"), default="sobol",
                       help="random, scrambled sobol, or gauss collocation (default sobol)")
        g.add_argument("--seed", type=whole_number, default=0, metavar="K",
                       help="random seed (default 0)")
        g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="Dask distributed scheduler address (default: local threads)")
    _solver_flags(parser)


def _elements_arg(text: str):
    if text == "adaptive":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer or 'adaptive', got "
                                         f"{text!r}") from None


def _element_flags(parser: argparse.ArgumentParser) -> None:
    """The law of xi and multi-element OPA (simulate only)."""
    g = parser.add_argument_group("law of xi and multi-element OPA")
    g.add_argument("--distribution", default=None, metavar="LAW",
                   help="law of xi: semicircle (the paper's), uniform, beta:A,B or "
                        "normal-trunc:K, all on [-1, 1] (default semicircle)")
    g.add_argument("--elements", type=_elements_arg, default=None, metavar="K|adaptive",
                   help="multi-element OPA: K equal-probability elements, or 'adaptive' "
                        "(edges at the impact-sequence splits, then refinement) "
                        "(default: one element, the paper's OPA)")
    g.add_argument("--tolerance", type=float, default=1e-6, metavar="TOL",
                   help="adaptive elements: refine while an element's variance share "
                        "P_k max_t Var_k exceeds TOL (default 1e-6)")
    g.add_argument("--max-elements", type=positive_int, default=64, metavar="K",
                   help="adaptive elements: the element budget (default 64)")


def _solver_flags(parser: argparse.ArgumentParser, *, tolerance: float = 1e-10,
                  defaults: bool = True) -> None:
    """Solver flags; with ``defaults=False`` unset flags stay None (a config file decides)."""

    def d(value):
        return value if defaults else None

    s = parser.add_argument_group("solver")
    s.add_argument("--impulse", choices=IMPULSE_MODELS, default=d("dirac"),
                   help="dirac: velocity jumps at t_j = j 2 pi/omega1; pulse: rectangular "
                        "force of width --pulse-width (default dirac)")
    s.add_argument("--pulse-width", type=float, default=d(0.1), metavar="TAU",
                   help="width of the rectangular pulses (default 0.1)")
    s.add_argument("--impulse-at-zero", action=argparse.BooleanOptionalAction, default=d(True),
                   help="include the impulse at t = 0 (j = 0) (default yes)")
    s.add_argument("--rtol", type=float, default=d(tolerance),
                   help=f"relative tolerance (default {tolerance:g})")
    s.add_argument("--atol", type=float, default=d(tolerance),
                   help=f"absolute tolerance (default {tolerance:g})")
    s.add_argument("--method", choices=METHODS, default=d("dop853"),
                   help="Runge-Kutta pair: dop853 (Dormand-Prince 8(5,3), 7th-order dense "
                        "output) or dp5 (Dormand-Prince 5(4)) (default dop853)")
    s.add_argument("--max-step", type=float, default=d(math.inf), metavar="H",
                   help="largest step size (default unlimited)")
    s.add_argument("--chatter-velocity", type=float, default=d(1e-6), metavar="V",
                   help="impacts slower than V with the force into the wall end a chatter "
                        "sequence: rest on the wall at the accumulation point (default 1e-6)")


def _output_flags(parser: argparse.ArgumentParser) -> None:
    o = parser.add_argument_group("output")
    o.add_argument("--out", default=None, metavar="FILE.nc", help="write the dataset here")
    o.add_argument("--plot", default=None, metavar="FILE.png", help="write a figure here")
    o.add_argument("--quiet", action="store_true", help="no progress bars or summaries")
    o.add_argument("--keep-parts", action="store_true",
                   help="simulate mc: keep OUT.parts/ (the finished chunks, from which a "
                        "killed run resumes) after writing OUT")


def oscillator_from(args) -> Oscillator:
    base = dict(PRESETS[args.preset]) if getattr(args, "preset", None) else {}
    for name in PARAMETER_NAMES:
        value = getattr(args, name, None)
        if value is not None:
            base[name] = value
    return Oscillator(**base)


def options_from(args) -> SolverOptions:
    return SolverOptions(
        impulse=args.impulse,
        pulse_width=args.pulse_width,
        impulse_at_zero=args.impulse_at_zero,
        rtol=args.rtol,
        atol=args.atol,
        max_step=args.max_step,
        chatter_velocity=args.chatter_velocity,
        method=args.method,
    )


def _summary_events(ds) -> str:
    n = ds.sizes.get("impact", 0)
    parts = [f"{n} impacts"]
    if n:
        parts.append(f"last at t = {float(ds.impact_time[-1]):.6g} with velocity "
                     f"{float(ds.impact_velocity[-1]):.6g}")
        grazes = int(ds.impact_graze.sum())
        if grazes:
            parts.append(f"{grazes} grazing")
    if ds.sizes.get("stick", 0):
        parts.append(f"{ds.sizes['stick']} chatter sequences ended in sticking")
    return ", ".join(parts)


def check_outputs(args) -> None:
    """Refuse --out, --plot and --outdir that could not be written, before computing."""
    from opa._paths import FIGURE_SUFFIXES, check_output_dir, check_output_file

    check_output_file("--out", getattr(args, "out", None))
    check_output_file("--plot", getattr(args, "plot", None), suffixes=FIGURE_SUFFIXES)
    if getattr(args, "outdir", None) is not None:
        check_output_dir("--outdir", args.outdir)
    if getattr(args, "plot", None):  # the figure writers do not create folders
        os.makedirs(os.path.dirname(os.path.abspath(args.plot)), exist_ok=True)
    workers = getattr(args, "workers", None)
    if workers is not None and workers > MAX_WORKERS:
        raise CliError(f"--workers must be at most {MAX_WORKERS} (4 per CPU), got {workers}")


def cmd_simulate(args) -> int:
    from opa._dataset import write_netcdf
    from opa._plot import plot_run

    check_outputs(args)
    osc = oscillator_from(args)
    opts = options_from(args)
    if args.model != "opa" and args.elements is not None:
        raise CliError(f"--elements applies to simulate opa, not simulate {args.model}")
    if args.model == "dmr" and args.distribution is not None:
        raise CliError("--distribution applies to simulate opa and mc, not simulate dmr")
    start = time.perf_counter()
    if args.model == "dmr":
        from opa._simulate import simulate_dmr

        ds = simulate_dmr(osc, periods=args.periods, per_period=args.per_period, options=opts)
        final = f"x = {float(ds.x[-1]):.10g}, v = {float(ds.v[-1]):.10g}"
    elif args.model == "opa":
        from opa._simulate import simulate_opa

        ds = simulate_opa(osc, sigma=args.sigma, order=args.order, uncertain=args.uncertain,
                          truncation=args.truncation, impact_law=args.impact_law,
                          allow_negative=args.allow_negative, periods=args.periods,
                          per_period=args.per_period, options=opts,
                          distribution=args.distribution, elements=args.elements,
                          tolerance=args.tolerance, max_elements=args.max_elements)
        final = (f"E[x] = {float(ds.x_mean[-1]):.10g}, Var[x] = "
                 f"{float(ds.x_var[-1]):.4g}")
        if "element" in ds.dims:
            final += f" ({ds.sizes['element']} elements)"
    else:
        from mc import simulate_mc

        from opa._simulate import SimulationError

        # with --out, finished chunks are kept in OUT.parts/ so a killed run resumes
        parts = f"{args.out}.parts" if args.out else None

        try:
            ds = simulate_mc(osc, sigma=args.sigma, samples=args.samples,
                             sampler=args.sampler, seed=args.seed, order=args.order,
                             uncertain=args.uncertain, allow_negative=args.allow_negative,
                             periods=args.periods, per_period=args.per_period, options=opts,
                             scheduler=args.scheduler, progress=not args.quiet,
                             distribution=args.distribution, checkpoint=parts,
                             connect_timeout=args.connect_timeout,
                             log=None if args.quiet else
                             (lambda message: print(f"opa-mc: {message}", file=sys.stderr)))
        except SimulationError as err:
            from mc import DaskError, remove_checkpoint

            # a sample that cannot be integrated fails every rerun of these settings: keep
            # no checkpoint to trip over; a lost cluster keeps its finished chunks
            if parts and not isinstance(err, DaskError):
                remove_checkpoint(parts)
            raise
        sem = float(ds.x_sem[-1])
        final = (f"E[x] = {float(ds.x_mean[-1]):.8g} ± {sem:.2g} (SE), Var[x] = "
                 f"{float(ds.x_var[-1]):.4g}; impacts per sample "
                 f"{int(ds.n_impacts.min())}..{int(ds.n_impacts.max())}")
    elapsed = time.perf_counter() - start
    if args.out:
        write_netcdf(ds, args.out)
        if args.model == "mc" and not args.keep_parts:
            from mc import remove_checkpoint

            remove_checkpoint(f"{args.out}.parts")
    if args.plot:
        plot_run(ds, args.plot, per_period=args.per_period)
    if not args.quiet:
        print(f"opa-mc simulate {args.model}: t in [0, {float(ds.time[-1]):.6g}] "
              f"({args.periods:g} forcing periods, {ds.sizes['time']} outputs) in {elapsed:.2f} s")
        if "impact" in ds.dims:
            print(f"  {_summary_events(ds)}")
        print(f"  final state: {final}")
        if args.out:
            print(f"  wrote {args.out}")
        if args.plot:
            print(f"  wrote {args.plot}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="opa-mc",
        description="Orthogonal polynomial approximation (OPA) of a vibro-impact oscillator "
        "with an uncertain parameter, checked against Monte Carlo ensembles of the true "
        "sampled impact systems.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    sim = sub.add_parser("simulate", help="one run: dmr (deterministic), opa (EMR), mc (ensemble)",
                         description="One run of the deterministic system (dmr), the OPA "
                         "equivalent system (opa) or a Monte Carlo ensemble (mc).")
    sim.add_argument("model", choices=("dmr", "opa", "mc"))
    _model_flags(sim)
    _common_flags(sim)
    sim.add_argument("--connect-timeout", type=float, default=5.0, metavar="S",
                     help="simulate mc: seconds to wait for the Dask scheduler to answer "
                          "(default 5)")
    _element_flags(sim)
    _output_flags(sim)
    sim.set_defaults(func=cmd_simulate)

    from compare._cli import register_converge, register_validate
    from opa._bifurcation_cli import register as register_bifurcation

    from opa._stability_cli import register_stability

    register_validate(sub, _model_flags, _solver_flags)
    register_converge(sub, _model_flags, _solver_flags)
    register_bifurcation(sub, _model_flags, _common_flags)
    register_stability(sub, _model_flags, _solver_flags)

    return parser


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


def main(argv: list[str] | None = None) -> int:
    """Run one command. Mistakes print one line and return 2; a run that cannot be
    completed returns 3; anything unforeseen prints one line naming the error (set
    OPA_MC_TRACEBACK=1 for the traceback) and returns 1."""
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    from opa._simulate import SimulationError

    try:
        return args.func(args)
    except (ValueError, CliError) as err:
        print(f"opa-mc: error: {_one_line(err)}", file=sys.stderr)
        return EXIT_USAGE
    except SimulationError as err:
        print(f"opa-mc: simulation failed: {_one_line(err)}", file=sys.stderr)
        return EXIT_SIMULATION
    except MemoryError:
        print("opa-mc: error: out of memory; ask for fewer outputs, samples or sweep values",
              file=sys.stderr)
        return EXIT_USAGE
    except OSError as err:
        where = f"{err.filename}: " if err.filename else ""
        print(f"opa-mc: error: {where}{err.strerror or _one_line(err)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("opa-mc: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # noqa: BLE001 -- one line, never a traceback, unless asked
        if os.environ.get("OPA_MC_TRACEBACK"):
            raise
        print(f"opa-mc: internal error: {type(err).__name__}: {_one_line(err)} (please "
              f"report it; OPA_MC_TRACEBACK=1 shows the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
