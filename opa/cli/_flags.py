"""Flags declared once for every subcommand, and the objects built from them.

Each group is one function that adds its flags to a subcommand's parser: the model's
parameters, the system (uncertainty, N, closures), the impulse model, the run's output
grid, Monte Carlo, the law of xi and elements, the solver, the output. ``system_from``,
``oscillator_from`` and ``options_from`` turn the parsed flags back into ``opa.System``,
``opa.Oscillator`` and ``opa.SolverOptions``; ``check_outputs`` refuses unwritable paths
before any work starts."""

from __future__ import annotations

import argparse
import math
import os
import sys

from opa import (
    DEFAULT_ORDER,
    DEFAULT_SIGMA,
    IMPACT_LAWS,
    IMPULSE_MODELS,
    METHODS,
    PARAMETER_DOCS,
    PARAMETER_NAMES,
    PRESETS,
    SYSTEM_FIELDS,
    TRUNCATIONS,
    UNCERTAIN_PARAMETERS,
    Execution,
    Oscillator,
    SolverOptions,
    System,
)
from opa.cli._args import positive_int, whole_number

EXIT_SIMULATION = 3
#: a result that failed its own verification under --strict
EXIT_UNVERIFIED = 4
MAX_WORKERS = 4 * (os.cpu_count() or 1)

#: the lower wall's flags (--delta-minus, --eta-minus): Oscillator fields that are not
#: PARAMETER_NAMES (neither swept nor uncertain)
LOWER_WALL = ("delta_minus", "eta_minus")
#: every oscillator flag's name
OSCILLATOR_FLAGS = PARAMETER_NAMES + LOWER_WALL

#: what --uncertain may name with the paper's law: its coefficients, the impact's eta and
#: delta, and the drive's f, omega and F0
UNCERTAIN_NAMES = Oscillator().uncertain_names


class CliError(Exception):
    """A user mistake detected after parsing (reported without traceback)."""


def _model_flags(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("model parameters (paper eq. 1; defaults: section 3.2)")
    group.add_argument("--preset", choices=sorted(PRESETS),
                       help="start from the paper's parameter set of this section; "
                            "explicit flags override it (3.3 uses c = 0.05, our choice)")
    group.add_argument("--model", dest="model_file", default=None, metavar="FILE.toml",
                       help="the oscillator as a TOML model file: its force law g(x, v), "
                            "the law's constants, any of the parameters below and "
                            "optionally [uncertain.NAME] tables (docs/own-oscillator.md); "
                            "explicit flags override the file's values; not with --preset")
    defaults = Oscillator()
    for name in PARAMETER_NAMES:
        group.add_argument(f"--{name}", type=float, default=None, metavar="VALUE",
                           help=f"{PARAMETER_DOCS[name]} (default {getattr(defaults, name):g})")
    group.add_argument("--delta-minus", dest="delta_minus", type=float, default=None,
                       metavar="VALUE",
                       help="position of an optional lower wall, below --delta: the motion "
                            "is then delta_minus < x < delta (default -inf, none; -inf also "
                            "removes a --model file's lower wall)")
    group.add_argument("--eta-minus", dest="eta_minus", type=float, default=None,
                       metavar="VALUE",
                       help="coefficient of restitution of the lower wall, 0 < eta_minus "
                            "<= 1 (default: the value of eta)")


def uncertain_names(text: str):
    """``--uncertain``: one name or a comma-separated list. Which names may be uncertain
    depends on the force law (``--model``): ``opa.System`` checks them against it."""
    names = [part.strip() for part in str(text).split(",")]
    for name in names:
        if not name.isidentifier():
            raise argparse.ArgumentTypeError(
                f"each uncertain parameter must be a name such as "
                f"{', '.join(UNCERTAIN_PARAMETERS)} or a force law's constant, got {name!r:.40}")
    if len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"a parameter is named twice: {text!r:.60}")
    return names[0] if len(names) == 1 else tuple(names)


def uncertain_name(text: str) -> str:
    """``--uncertain`` where one parameter is uncertain: one name."""
    names = uncertain_names(text)
    if not isinstance(names, str):
        raise argparse.ArgumentTypeError(f"one uncertain parameter here, got {text!r:.60}")
    return names


def scales(text: str):
    """``--sigma``: one number, or a comma-separated list (one per uncertain parameter)."""
    try:
        values = [float(part) for part in str(text).split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number or a comma-separated list of "
                                         f"numbers, got {text!r:.60}") from None
    return values[0] if len(values) == 1 else tuple(values)


def _system_flags(parser: argparse.ArgumentParser, *, laws=IMPACT_LAWS,
                  closures: bool = True, several: bool = False) -> None:
    """The uncertainty, the OPA order and its closures (not with ``closures=False``: a
    Monte Carlo ensemble integrates the true systems), and the impulse model: the fields
    of ``opa.System`` (defaults from there). ``several``: ``--uncertain`` and ``--sigma``
    take comma-separated lists (several uncertain parameters)."""
    g = parser.add_argument_group("system: uncertainty, OPA order and closures" if closures
                                  else "system: uncertainty and Chebyshev coefficients")
    if several:
        g.add_argument("--problem", default=None, metavar="FILE.toml",
                       help="the uncertain parameters as a TOML file: one table [name] each "
                            "with sigma and optionally distribution, in order, and "
                            "optionally allow_negative at the top (instead of --uncertain, "
                            "--sigma, --distribution and --allow-negative)")
        # None when not given: --problem may not be mixed with them
        g.add_argument("--sigma", type=scales, default=None, metavar="S[,S...]",
                       help=f"scale of each uncertain parameter p = p_bar + S xi: one value "
                            f"(applies to all) or one per --uncertain name "
                            f"(default {DEFAULT_SIGMA:g})")
        g.add_argument("--uncertain", type=uncertain_names, default=None,
                       metavar="P[,P...]",
                       help=f"which parameters are uncertain, among "
                            f"{', '.join(UNCERTAIN_NAMES)} (or a --model force law's "
                            f"constants): one, or several such as mu,c (default mu, or the "
                            f"--model file's [uncertain.NAME] tables)")
    else:
        g.add_argument("--sigma", type=float, default=DEFAULT_SIGMA, metavar="S",
                       help=f"intensity of the uncertain parameter p = p_bar + S xi "
                            f"(default {DEFAULT_SIGMA:g})")
        g.add_argument("--uncertain", type=uncertain_name, default="mu", metavar="P",
                       help=f"which parameter is uncertain, among "
                            f"{', '.join(UNCERTAIN_NAMES)} or a --model force law's "
                            f"constants (default mu, or the --model file's [uncertain.NAME])")
    g.add_argument("--allow-negative", action="store_true",
                   help="allow p_bar - sigma < 0 for the uncertain parameter")
    g.add_argument("--order", type=whole_number, default=DEFAULT_ORDER, metavar="N",
                   help=(f"OPA truncation order (default {DEFAULT_ORDER})" if closures else
                         f"highest Chebyshev coefficient E[x U_i(xi)] estimated "
                         f"(default {DEFAULT_ORDER})"))
    if not closures:
        _impulse_flags(parser)
        return
    if several:
        g.add_argument("--basis", default="total", metavar="total|tensor|hyperbolic:Q",
                       help="with several uncertain parameters, the multi-index set of the "
                            "OPA expansion: total degree <= N, tensor (each degree <= N) or "
                            "hyperbolic q-norm <= N (default total)")
    g.add_argument("--truncation", choices=TRUNCATIONS, default="galerkin",
                   help="galerkin: exact projection; paper: eq. (27), drops sigma/2 Y_{N+1} "
                        "(default galerkin)")
    g.add_argument("--impact-law", choices=laws, default=None,
                   help="mean: only x_0' jumps (eq. 28); ensemble: every velocity coefficient "
                        "is multiplied by -eta; saltation: the impact's saltation matrix "
                        "maps the deviation coefficients (default mean; saltation with "
                        "--elements, the law whose elements converge)")
    _impulse_flags(parser)


def _impulse_flags(parser: argparse.ArgumentParser, *, defaults: bool = True) -> None:
    """The impulse model (``opa.System``); with ``defaults=False`` unset flags stay None
    (a config file decides)."""
    s = parser.add_argument_group("impulse model")
    s.add_argument("--impulse", choices=IMPULSE_MODELS, default="dirac" if defaults else None,
                   help="dirac: velocity jumps at t_j = j 2 pi/omega1; pulse: rectangular "
                        "force of width --pulse-width (default dirac)")
    s.add_argument("--pulse-width", type=float, default=0.1 if defaults else None,
                   metavar="TAU", help="width of the rectangular pulses (default 0.1)")
    s.add_argument("--impulse-at-zero", action=argparse.BooleanOptionalAction,
                   default=True if defaults else None,
                   help="include the impulse at t = 0 (j = 0) (default yes)")


def _run_flags(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("run")
    g.add_argument("--periods", type=float, default=100.0, metavar="P",
                   help="length in forcing periods 2 pi/omega (default 100)")
    g.add_argument("--per-period", type=positive_int, default=1, metavar="K",
                   help="outputs per forcing period: t_j = j (2 pi/omega)/K, j = 0..P K; "
                        "K = 1 gives the stroboscopic samples (default 1)")


def _mc_flags(parser: argparse.ArgumentParser, *, connect_timeout: bool = False,
              device: bool = False) -> None:
    g = parser.add_argument_group("Monte Carlo")
    g.add_argument("--samples", type=positive_int, default=1024, metavar="M",
                   help="Monte Carlo samples (default 1024)")
    g.add_argument("--sampler", choices=("random", "sobol", "gauss"), default="sobol",
                   help="random, scrambled sobol, or gauss collocation (default sobol)")
    g.add_argument("--seed", type=whole_number, default=0, metavar="K",
                   help="random seed (default 0)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask distributed scheduler address (default: local threads)")
    if device:
        g.add_argument("--device", choices=("cpu", "cuda"), default="cpu",
                       help="where the samples' trajectories run: cpu (default, numba "
                            "threads) or cuda (one GPU thread per sample; needs an NVIDIA "
                            "GPU and the 'gpu' extra, numba-cuda)")
    if connect_timeout:
        g.add_argument("--connect-timeout", type=float, default=5.0, metavar="S",
                       help="with --scheduler: seconds to wait for the Dask scheduler to "
                            "answer (default 5)")


def _common_flags(parser: argparse.ArgumentParser, *, mc: bool = True) -> None:
    """Run, system, Monte Carlo (with ``mc``) and solver flags."""
    _run_flags(parser)
    _system_flags(parser)
    if mc:
        _mc_flags(parser)
    _solver_flags(parser)


def _elements_arg(text: str):
    if text == "adaptive":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer or 'adaptive', got "
                                         f"{text!r}") from None


def _law_flag(parser: argparse.ArgumentParser, *, elements: bool = True) -> None:
    """The law of xi (simulate opa and mc) and, with ``elements``, multi-element OPA
    (simulate opa)."""
    g = parser.add_argument_group("law of xi and multi-element OPA" if elements
                                  else "law of xi")
    g.add_argument("--distribution", default=None, metavar="LAW[,LAW...]",
                   help="law of xi: semicircle (the paper's), uniform, beta:A,B or "
                        "normal-trunc:K, all on [-1, 1] (default semicircle); with several "
                        "uncertain parameters one law for all or one per parameter, "
                        "comma-separated (semicircle,beta:2,3)")
    if not elements:
        return
    g.add_argument("--elements", type=_elements_arg, default=None, metavar="K|adaptive",
                   help="multi-element OPA: K equal-probability elements, or 'adaptive' "
                        "(edges at the impact-sequence splits, then refinement) "
                        "(default: one element, the paper's OPA)")
    g.add_argument("--element-tolerance", type=float, default=1e-6, metavar="TOL",
                   help="with --elements adaptive: refine while an element's variance share "
                        "P_k max_t Var_k exceeds TOL (default 1e-6; API: tolerance=)")
    g.add_argument("--max-elements", type=positive_int, default=64, metavar="K",
                   help="with --elements adaptive: the element budget (default 64)")


#: --verify-max when not given (or --verify, when larger)
DEFAULT_VERIFY_MAX = 4096


def _verify_flags(parser: argparse.ArgumentParser) -> None:
    """The paired Monte Carlo certificate of an OPA run (simulate opa only)."""
    g = parser.add_argument_group("certificate (simulate opa)")
    g.add_argument("--verify", type=positive_int, default=None, metavar="M",
                   help="run M true sampled systems at random points of the run's law of "
                        "xi, stratified at its elements and at the changes of the impact "
                        "sequence, paired with the OPA surrogate: the errors of the mean "
                        "and the variance with standard errors, a verdict (agrees, "
                        "disagrees or undecided, wrong with probability at most 0.01), and "
                        "control-variate estimates of E[x] and Var[x]; doubled while the "
                        "verdict is undecided (M a power of two >= 64)")
    g.add_argument("--verify-max", type=positive_int, default=None, metavar="M",
                   help=f"the most --verify doubles to (a power of two >= --verify; "
                        f"default {DEFAULT_VERIFY_MAX}, or --verify when larger)")
    g.add_argument("--strict", action="store_true",
                   help="with --verify: exit with status 4 unless the run agrees")
    g.add_argument("--seed", type=whole_number, default=0, metavar="K",
                   help="with --verify: seed of the random points (default 0)")


def _solver_flags(parser: argparse.ArgumentParser, *, tolerance: float = 1e-10,
                  defaults: bool = True) -> None:
    """Solver flags (``opa.SolverOptions``: numerics only); with ``defaults=False`` unset
    flags stay None (a config file decides)."""

    def d(value):
        return value if defaults else None

    s = parser.add_argument_group("solver")
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


def _output_flags(parser: argparse.ArgumentParser, *, parts: bool = False) -> None:
    o = parser.add_argument_group("output")
    o.add_argument("--out", default=None, metavar="FILE.nc", help="write the dataset here")
    o.add_argument("--plot", default=None, metavar="FILE.png", help="write a figure here")
    o.add_argument("--quiet", action="store_true", help="no progress bars or summaries")
    if parts:
        o.add_argument("--keep-parts", action="store_true",
                       help="with --out: keep OUT.parts/ (the finished chunks, from which a "
                            "killed run resumes) after writing OUT")


def given(args, dest: str) -> str | None:
    """The flag of ``dest`` as typed on the command line, or None where it was not given
    (its default then stands)."""
    return getattr(args, "given_flags", {}).get(dest)


def refuse_given(args, dests, why: str) -> None:
    """Refuse the first of ``dests`` given on the command line: "FLAG VALUE why"."""
    for dest in dests:
        flag = given(args, dest)
        if flag:
            value = getattr(args, dest, None)
            shown = "" if isinstance(value, bool) or value is None else f" {value}"
            raise CliError(f"{flag}{shown} {why}")


def check_combinations(args) -> None:
    """Refuse flags that have no effect in the given combination (shared rules)."""
    if getattr(args, "impulse", "pulse") != "pulse":
        refuse_given(args, ["pulse_width"], "has no effect without --impulse pulse")
    if getattr(args, "out", None) is None:
        refuse_given(args, ["keep_parts"], "has no effect without --out (only a run that "
                                           "writes OUT keeps OUT.parts/)")
    if getattr(args, "scheduler", None) is None:
        refuse_given(args, ["connect_timeout"], "has no effect without --scheduler")
    out, plot = getattr(args, "out", None), getattr(args, "plot", None)
    if out and plot and os.path.realpath(out) == os.path.realpath(plot):
        raise CliError(f"--out {out} and --plot {plot} name the same file: the figure would "
                       f"overwrite the dataset")


def model_from(args):
    """The ``opa._modelfile.Model`` of ``--model FILE.toml`` (read once), or None."""
    path = getattr(args, "model_file", None)
    if path is None:
        return None
    cached = getattr(args, "_model_read", None)
    if cached is None:
        from opa.engine import read_model

        if getattr(args, "preset", None):
            raise CliError(f"--preset {args.preset} and --model {path} both give the "
                           f"oscillator: give one (the model file's values may be "
                           f"overridden by the parameter flags)")
        try:
            cached = read_model(path)
        except ValueError as err:
            raise CliError(f"--model: {err}") from None
        args._model_read = cached
    return cached


def oscillator_from(args) -> Oscillator:
    """The oscillator of ``--preset`` or ``--model`` (or the defaults), each parameter
    flag given overriding it."""
    flags = {name: getattr(args, name) for name in OSCILLATOR_FLAGS
             if getattr(args, name, None) is not None}
    model = model_from(args)
    if model is None:
        base = dict(PRESETS[args.preset]) if getattr(args, "preset", None) else {}
        return _lower_wall_flagged(lambda: Oscillator(**{**base, **flags}), flags)
    law = model.oscillator.force
    if law is not None:
        from opa.engine import OSCILLATOR_COEFFICIENTS

        unused = [name for name in OSCILLATOR_COEFFICIENTS
                  if name in flags and name not in law.names]
        if unused:
            raise CliError(f"--{unused[0]} {flags[unused[0]]:g} has no effect: the force law "
                           f"{law.expression!r:.60} of --model {args.model_file} does not "
                           f"name {unused[0]}")
    return _lower_wall_flagged(lambda: model.oscillator.replace(**flags), flags)


def _lower_wall_flagged(build, flags: dict) -> Oscillator:
    """``build()``, its refusal of a lower wall's value given as a flag (``--delta-minus``,
    ``--eta-minus``) named as that flag; other refusals as they are (exit 2 either way)."""
    try:
        return build()
    except ValueError as err:
        raise CliError(flagged(err, [name for name in LOWER_WALL if name in flags])) from None


def uncertain_from(args) -> dict:
    """The ``--model`` file's [uncertain.NAME] tables as the keywords ``uncertain``,
    ``sigma``, ``distribution`` and ``allow_negative``, each unless its flag was given
    (the flag wins); none when the file has no such tables, with ``--problem``, or when
    ``--uncertain`` names other parameters."""
    model = model_from(args)
    if model is None or model.problem is None or getattr(args, "problem", None):
        return {}
    problem = model.problem
    if given(args, "uncertain"):
        names = (args.uncertain,) if isinstance(args.uncertain, str) else args.uncertain
        if tuple(names) != problem.names:
            return {}

    def one(values: tuple):
        return values[0] if problem.dimension == 1 else values

    out = {"uncertain": one(problem.names)}
    if not given(args, "sigma"):
        out["sigma"] = one(problem.scales)
    if not given(args, "distribution"):
        out["distribution"] = one(problem.laws)
    if not getattr(args, "allow_negative", False):
        out["allow_negative"] = problem.allow_negative
    return out


def options_from(args) -> SolverOptions:
    return SolverOptions(rtol=args.rtol, atol=args.atol, max_step=args.max_step,
                         chatter_velocity=args.chatter_velocity, method=args.method)


def say(message: str) -> None:
    """One line on stderr, ``opa-mc: message`` (a command's log)."""
    print(f"opa-mc: {message}", file=sys.stderr)


def execution_from(args, **changes) -> Execution:
    """The ``opa.Execution`` of the parsed flags: ``--workers``, ``--scheduler``,
    ``--connect-timeout`` and ``--device`` where the subcommand has them, a progress bar
    and log lines on stderr unless ``--quiet``; ``changes`` (e.g. ``checkpoint=``) win."""
    fields = {name: getattr(args, name) for name in ("workers", "scheduler", "device",
                                                     "connect_timeout")
              if getattr(args, name, None) is not None}
    quiet = getattr(args, "quiet", False)
    return Execution(**{**fields, "progress": not quiet, "log": None if quiet else say,
                        **changes})


def system_from(args, **changes) -> System:
    """The ``opa.System`` of the parsed flags: the oscillator (``--preset`` and the
    parameter flags) and every System field the subcommand has a flag for."""
    fields = {name: getattr(args, name) for name in SYSTEM_FIELDS
              if name != "oscillator" and getattr(args, name, None) is not None}
    oscillator = oscillator_from(args)
    if "sigma" not in changes:  # not the deterministic system of simulate dmr
        fields.update(uncertain_from(args))
    if getattr(args, "problem", None) is not None:
        mixed = [flag for flag, name in (("--uncertain", "uncertain"), ("--sigma", "sigma"),
                                         ("--distribution", "distribution"))
                 if name in fields] + (["--allow-negative"] if args.allow_negative else [])
        if mixed:
            raise CliError(f"--problem {args.problem} names the uncertain parameters; "
                           f"{', '.join(mixed)} may not be given with it")
        fields.pop("allow_negative", None)
        from opa.engine import read_toml, uncertain_problem

        try:  # the names are checked against the oscillator's force law (--model)
            fields["uncertain"] = uncertain_problem(
                read_toml(args.problem, "problem file"), f"problem file {args.problem}",
                oscillator)
        except ValueError as err:
            raise CliError(f"--problem: {err}") from None
    try:
        return System(oscillator, **{**fields, **changes})
    except ValueError as err:
        raise CliError(flagged(err, ("sigma", "distribution", "uncertain"))) from None


def flagged(err: Exception, names) -> str:
    """The library's message ``"name ..."`` as the flag the user typed (``"--name ..."``)
    when it starts with one of ``names``."""
    text = str(err)
    for name in names:
        if text.startswith((f"{name} ", f"{name}:")):
            return "--" + name.replace("_", "-") + text[len(name):]
    return text


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
    from opa.cli._paths import FIGURE_SUFFIXES, check_output_dir, check_output_file

    check_combinations(args)
    check_output_file("--out", getattr(args, "out", None))
    out = getattr(args, "out", None)
    command = getattr(args, "command", "")
    parts = command in ("stochastic", "bifurcation") or (
        command == "simulate" and getattr(args, "model", None) == "mc")
    if parts and out and os.path.lexists(f"{out}.parts") \
            and not os.path.isdir(f"{out}.parts"):
        raise CliError(f"--out {out}: its parts folder {out}.parts (where a long run keeps "
                       f"what it finished, to resume) is a file; remove it or name another "
                       f"--out")
    check_output_file("--plot", getattr(args, "plot", None), suffixes=FIGURE_SUFFIXES)
    if getattr(args, "outdir", None) is not None:
        check_output_dir("--outdir", args.outdir)
    if getattr(args, "plot", None):  # the figure writers do not create folders
        os.makedirs(os.path.dirname(os.path.abspath(args.plot)), exist_ok=True)
    workers = getattr(args, "workers", None)
    if workers is not None and workers > MAX_WORKERS:
        raise CliError(f"--workers must be at most {MAX_WORKERS} (4 per CPU), got {workers}")


def write_and_draw(ds, args, draw) -> None:
    """A command's ``--out`` (the dataset written) and ``--plot`` (``draw(ds, path)``),
    each said unless ``--quiet``."""
    from opa import write_netcdf

    for path, write in ((getattr(args, "out", None), write_netcdf),
                        (getattr(args, "plot", None), draw)):
        if path:
            write(ds, path)
            if not args.quiet:
                print(f"  wrote {path}")


def mean_law_blind(impact_law: str, uncertain: str) -> list[str]:
    """The warning a run with the mean impact law and an uncertain eta or delta needs (the
    law reflects every node with the mean eta at the mean wall: it adds no spread from
    them), or nothing."""
    if impact_law != "mean" or not {"eta", "delta"} & set(str(uncertain).split(",")):
        return []
    return ["warning: impact law mean reflects with the mean eta at the mean wall: it adds "
            "no spread from an uncertain eta or delta, so Var[x] misses it; use "
            "--impact-law saltation with --elements adaptive"]
