"""The ``opa-mc`` command line (``opa-mc COMMAND --help`` explains every flag).

Every model parameter is a flag of its own name (``--omega 3.98 --F0 0``); the common
flags are shared by every subcommand. User mistakes get one line on stderr naming the
parameter and the value, and exit status 2; a trajectory that cannot be completed exits
with status 3. No tracebacks for either.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
import warnings

import numpy as np

from opa.cli._args import EXIT_USAGE, Parser
from opa.cli._flags import (
    mean_law_blind,
    DEFAULT_VERIFY_MAX,
    EXIT_SIMULATION,
    EXIT_UNVERIFIED,
    CliError,
    _impulse_flags,
    _law_flag,
    _mc_flags,
    _model_flags,
    _output_flags,
    _run_flags,
    _solver_flags,
    _system_flags,
    _verify_flags,
    _summary_events,
    check_outputs,
    execution_from,
    flagged,
    refuse_given,
    options_from,
    say,
    system_from,
)


def cmd_simulate(args) -> int:
    from opa.engine import OutputLock

    check_outputs(args)
    if not args.out:
        return _simulate(args)
    # OUT stays locked from before the run until it is written (its checkpoint has its own)
    with OutputLock(args.out, "output file", folder=False, log=say):
        return _simulate(args)


def _simulate(args) -> int:
    from opa import write_netcdf
    from opa.engine import default_impact_law

    if args.model == "opa":
        if args.elements != "adaptive":
            refuse_given(args, ["element_tolerance", "max_elements"],
                         "applies with --elements adaptive only (the refinement of "
                         "adaptive elements)")
        if args.verify is None:
            refuse_given(args, ["strict", "verify_max", "seed"],
                         "applies with --verify M only")

    if args.model == "mc" and args.sampler == "gauss":
        refuse_given(args, ["seed"], "has no effect with --sampler gauss (a quadrature "
                                     "draws nothing)")
    system = (system_from(args, impact_law=args.impact_law or
                          default_impact_law(args.elements)) if args.model == "opa" else
              system_from(args, **({"sigma": 0.0} if args.model == "dmr" else {})))
    opts = options_from(args)
    if args.model == "opa" and args.verify is not None:
        from compare import check_counts

        check_counts(args.verify, _verify_max(args), flags=True)
    lifetime = contextlib.nullcontext()
    if args.model == "mc":
        from mc import checkpoint_for, checkpoint_lifetime

        # with --out, finished chunks are kept in OUT.parts/ so a killed run resumes; the
        # folder's lifetime (removed after a failed sample, kept after a lost cluster) is mc's
        lifetime = checkpoint_lifetime(checkpoint_for(args.out), keep=args.keep_parts)
    start = time.perf_counter()
    with lifetime:
        ds, final = _run(args, system, opts)
        elapsed = time.perf_counter() - start
        _refuse_non_finite(ds, args)
        if args.out:
            write_netcdf(ds, args.out)
    if args.plot:
        from opa.plots import plot_run

        plot_run(ds, args.plot, per_period=args.per_period)
    if not args.quiet:
        print(f"opa-mc simulate {args.model}: t in [0, {float(ds.time[-1]):.6g}] "
              f"({args.periods:g} forcing periods, {ds.sizes['time']} outputs) in {elapsed:.2f} s")
        if "impact" in ds.dims:
            print(f"  {_summary_events(ds)}")
        print(f"  final state: {final}")
        for line in _element_lines(ds) + _verify_lines(ds):
            print(f"  {line}")
        if args.out:
            print(f"  wrote {args.out}")
        if args.plot:
            print(f"  wrote {args.plot}")
    if getattr(args, "strict", False) and ds.attrs["verdict"] != "agrees":
        said = ("disagrees with" if ds.attrs["verdict"] == "disagrees" else
                "is not certified by")
        print(f"opa-mc: the OPA run {said} its Monte Carlo certificate (mean: "
              f"{ds.attrs['verdict_mean']}, variance: {ds.attrs['verdict_var']}, after "
              f"{ds.attrs['verify_samples']} true systems); --strict", file=sys.stderr)
        return EXIT_UNVERIFIED
    return 0


def _several(args, system, opts):
    """``simulate opa`` with several uncertain parameters: the Galerkin system on the
    multi-index basis, its moments and the Sobol indices of x at the last output."""
    from opa import simulate_opa

    from opa.engine import ElementBudgetWarning

    adaptive = args.elements == "adaptive"
    try:
        with warnings.catch_warnings():  # the budget warning is said in the summary
            warnings.simplefilter("ignore", ElementBudgetWarning)
            ds = simulate_opa(system, periods=args.periods, per_period=args.per_period,
                              options=opts, basis=args.basis, elements=args.elements,
                              **({"tolerance": args.element_tolerance,
                                  "max_elements": args.max_elements} if adaptive else {}))
    except ValueError as err:
        raise CliError(flagged(err, ("basis", "order", "max_elements"))) from None
    indices = ", ".join(
        f"{name} {float(ds.x_sobol_first.sel(parameter=name)[-1]):.3g}/"
        f"{float(ds.x_sobol_total.sel(parameter=name)[-1]):.3g}"
        for name in ds.parameter.values)
    boxes = (f", {ds.sizes['element']} boxes ({ds.attrs['element_mode']}"
             + (f", stopped by {ds.attrs['stopped_by']}" if adaptive else "") + ")"
             if "element" in ds.dims else "")
    final = (f"E[x] = {float(ds.x_mean[-1]):.10g}, Var[x] = {float(ds.x_var[-1]):.4g} "
             f"({ds.sizes['term']} terms, {ds.attrs['nodes']} nodes{boxes}); Sobol indices "
             f"of x (first/total): {indices}")
    if args.verify is not None:
        from compare import verify

        ds = verify(ds, samples=args.verify, max_samples=_verify_max(args), seed=args.seed,
                    options=opts, log=None if args.quiet else say)
    return ds, final


def _verify_max(args) -> int:
    return args.verify_max if args.verify_max is not None else max(args.verify,
                                                                   DEFAULT_VERIFY_MAX)


def _run(args, system, opts):
    """The dataset of ``simulate MODEL`` and its final state in words."""
    if args.model == "dmr":
        from opa import simulate_dmr

        ds = simulate_dmr(system, periods=args.periods, per_period=args.per_period,
                          options=opts)
        return ds, f"x = {float(ds.x[-1]):.10g}, v = {float(ds.v[-1]):.10g}"
    if args.model == "opa":
        from opa import simulate_opa
        from opa.engine import ElementBudgetWarning

        if system.dimension > 1:
            return _several(args, system, opts)
        with warnings.catch_warnings():  # the budget warning is said in the summary
            warnings.simplefilter("ignore", ElementBudgetWarning)
            ds = simulate_opa(system, periods=args.periods, per_period=args.per_period,
                              options=opts, elements=args.elements, basis=args.basis,
                              **({"tolerance": args.element_tolerance,
                                  "max_elements": args.max_elements}
                                 if args.elements == "adaptive" else {}))
        final = (f"E[x] = {float(ds.x_mean[-1]):.10g}, Var[x] = "
                 f"{float(ds.x_var[-1]):.4g}")
        if ds.sizes["element"] > 1:
            final += f" ({ds.sizes['element']} elements)"
        if args.verify is not None:
            from compare import verify

            ds = verify(ds, samples=args.verify, max_samples=_verify_max(args),
                        seed=args.seed, options=opts, log=None if args.quiet else say)
        return ds, final
    from mc import checkpoint_for, simulate_mc

    ds = simulate_mc(system, samples=args.samples, sampler=args.sampler, seed=args.seed,
                     periods=args.periods, per_period=args.per_period, options=opts,
                     execution=execution_from(args, checkpoint=checkpoint_for(args.out)))
    # a Gauss quadrature has no sampling error: its standard errors are NaN by design
    error = ("(Gauss quadrature)" if ds.attrs.get("sampler") == "gauss" else
             f"± {float(ds.x_sem[-1]):.2g} (SE)")
    return ds, (f"E[x] = {float(ds.x_mean[-1]):.8g} {error}, "
                f"Var[x] = {float(ds.x_var[-1]):.4g}; impacts per sample "
                f"{int(ds.n_impacts.min())}..{int(ds.n_impacts.max())}")


def _refuse_non_finite(ds, args) -> None:
    """A result with a non-finite number (:func:`opa.engine.first_non_finite` says which
    are documented) is a run that could not be completed: nothing is written, exit
    status 3."""
    from opa import SimulationError
    from opa.engine import first_non_finite

    found = first_non_finite(ds)
    if found is not None:
        name, bad = found
        law = ds.attrs.get("distribution", "")
        raise SimulationError(
            f"simulate {args.model}: {bad} of {ds[name].size} values of {name} are not "
            f"finite" + (f" (law of xi {law}, N = {ds.attrs.get('N', '?')})" if law else "")
            + "; nothing written: try a lower --order, a milder --distribution or "
              "smaller --sigma")


def _verify_lines(ds) -> list[str]:
    """The certificate in three lines: verdict, errors with standard errors, estimates."""
    if "verdict" not in ds.attrs:
        return []
    a = ds.attrs

    def rms(name):
        return float(np.sqrt(np.mean(ds[name].values ** 2)))

    def when(periods):
        return "" if periods == float("inf") else f", first disagreement at {periods:.4g} periods"

    return [
        f"certificate ({a['verify_samples']} true systems in {a['verify_strata']} strata, "
        f"error rate {a['verify_alpha']:g}): {a['verdict'].upper()} (mean {a['verdict_mean']}"
        f"{when(a['first_disagreement_mean'])}; variance {a['verdict_var']}"
        f"{when(a['first_disagreement_var'])})"
        + (f": {a['verify_undecided_because']}"
           if a.get("verify_undecided_because", "none") != "none" else ""),
        f"error of E[x]: RMS {rms('verify_err_mean'):.3g} ± {rms('verify_err_mean_sem'):.2g}; "
        f"of Var[x]: RMS {rms('verify_err_var'):.3g} ± {rms('verify_err_var_sem'):.2g} "
        f"(paired estimates ± standard errors)",
        f"control variate: E[x] = {float(ds.cv_x_mean[-1]):.8g} ± "
        f"{float(ds.cv_x_mean_sem[-1]):.2g}, Var[x] = {float(ds.cv_x_var[-1]):.4g} ± "
        f"{float(ds.cv_x_var_sem[-1]):.2g} at the end; variance reduction "
        f"{a['variance_reduction']:.3g}x"
        + (" (below 1: x - x_hat varies more than x itself, so the paired estimate is "
           "noisier than plain Monte Carlo of as many runs; the surrogate is far off)"
           if a["variance_reduction"] < 1 else ""),
    ]


def _share(share: float) -> str:
    return ("an element's OPA system failed" if share == float("inf")
            else f"largest variance share {share:.3g}")


def _element_lines(ds) -> list[str]:
    """What a user must know of an element run: the law, the adaptive tolerance, the
    elements computed by collocation and those that contain a split; and that the mean
    impact law misses an uncertain eta's or delta's spread."""
    if ds.attrs.get("model") != "opa":
        return []
    notes = mean_law_blind(ds.attrs.get("impact_law"), ds.attrs.get("uncertain", ""))
    if ds.attrs.get("element_mode", "single") == "single":
        return notes
    K = ds.sizes["element"]
    lines = notes + [f"{K} elements ({ds.attrs['element_mode']}), {ds.attrs['distribution']} law, "
             f"impact law {ds.attrs['impact_law']}"]
    if ds.attrs["element_mode"] == "adaptive":
        if ds.attrs["tolerance_met"]:
            lines.append(f"adaptive: tolerance {ds.attrs['tolerance']:g} met")
        else:
            lines.append(f"warning: adaptive tolerance {ds.attrs['tolerance']:g} NOT met: "
                         f"stopped by the {ds.attrs['stopped_by']} "
                         f"({_share(float(ds.refinement_share[-1]))}); "
                         f"raise --max-elements (now {ds.attrs['max_elements']})")
        estimate = ds.attrs["error_estimate"]
        if estimate == estimate:  # not NaN
            lines.append(f"error estimate: E[x] changed by {estimate:.2g} (RMS over time) in "
                         f"the last refinement step")
    if ds.attrs.get("collocation_elements"):
        lines.append(f"{ds.attrs['collocation_elements']} elements computed by collocation "
                     f"of the true systems: their OPA systems could not be completed")
    if ds.attrs.get("straddling_elements"):
        lines.append(f"warning: {ds.attrs['straddling_elements']} of {K} elements "
                     f"(probability {ds.attrs['straddling_probability']:.3g}) contain a change "
                     f"of the impact sequence over the run, which their polynomials cannot "
                     f"follow: check against `opa-mc simulate mc`, or "
                     + ("raise --max-elements" if ds.attrs["element_mode"] == "adaptive"
                        else "use --elements adaptive") + " or fewer --periods")
    return lines


SIMULATE_MODELS = {
    "dmr": ("the deterministic system (eq. 29): the mean parameters",
            "One run of the deterministic impact system (eq. 29) at the given parameters: "
            "the states at the output times and every impact."),
    "opa": ("the OPA equivalent system (EMR): E[x], Var[x] from N + 1 coefficients",
            "One run of the OPA equivalent system of order N (the paper's EMR), on one "
            "element or several (--elements), optionally certified against true sampled "
            "systems (--verify)."),
    "mc": ("a Monte Carlo ensemble of the true sampled systems",
           "One Monte Carlo ensemble of the sampled impact systems p = p_bar + sigma xi: "
           "mean, variance and Chebyshev coefficients with standard errors; with --out, "
           "finished chunks are kept in OUT.parts/ and a rerun resumes."),
}

# which simulate models take a flag the others do not (the reason given when refused)
_ONLY = {
    "--sigma": ("opa", "mc"), "--uncertain": ("opa", "mc"), "--allow-negative": ("opa", "mc"),
    "--order": ("opa", "mc"), "--distribution": ("opa", "mc"),
    "--truncation": ("opa",), "--impact-law": ("opa",), "--elements": ("opa",),
    "--element-tolerance": ("opa",), "--max-elements": ("opa",), "--verify": ("opa",),
    "--verify-max": ("opa",), "--strict": ("opa",), "--basis": ("opa",),
    "--samples": ("mc",), "--sampler": ("mc",), "--scheduler": ("mc",),
    "--connect-timeout": ("mc",), "--keep-parts": ("mc",), "--device": ("mc",),
    "--seed": ("opa", "mc"),
}
_WHY = {
    "--truncation": "closures of the OPA system: simulate mc integrates the true sampled "
                    "systems",
    "--impact-law": "closures of the OPA system: simulate mc integrates the true sampled "
                    "systems",
    "--sigma": "the deterministic system has no uncertain parameter",
    "--uncertain": "the deterministic system has no uncertain parameter",
    "--allow-negative": "the deterministic system has no uncertain parameter",
    "--seed": "the deterministic system draws nothing",
}


def _foreign(model: str) -> dict[str, str]:
    """The flags of the other simulate models, each with why it does not apply to
    ``model``."""
    out = {}
    for flag, models in _ONLY.items():
        if model not in models:
            where = " and ".join(f"simulate {m}" for m in models)
            why = _WHY.get(flag) if flag not in ("--truncation", "--impact-law") or \
                model == "mc" else None
            out[flag] = f"applies to {where}, not simulate {model}" + (f" ({why})" if why
                                                                       else "")
    if model == "opa":
        out["--tolerance"] = ("is not a flag of simulate opa: the refinement tolerance of "
                              "adaptive elements is --element-tolerance (--tolerance is "
                              "validate's verdict tolerance)")
    return out


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
                         "equivalent system (opa) or a Monte Carlo ensemble (mc); "
                         "`opa-mc simulate MODEL --help` lists the flags of each.")
    models = sim.add_subparsers(dest="model", required=True, metavar="MODEL")
    for name, (helptext, description) in SIMULATE_MODELS.items():
        p = models.add_parser(name, help=helptext, description=description,
                              foreign=_foreign(name))
        _model_flags(p)
        _run_flags(p)
        if name == "dmr":
            _impulse_flags(p)
        else:
            _system_flags(p, closures=name == "opa", several=True)
            if name == "mc":
                _mc_flags(p, connect_timeout=True, device=True)
        _solver_flags(p)
        if name != "dmr":
            _law_flag(p, elements=name == "opa")
        if name == "opa":
            _verify_flags(p)
        _output_flags(p, parts=name == "mc")
        p.set_defaults(func=cmd_simulate)

    from opa.cli._validate import register_converge, register_validate
    from opa.cli._bifurcation import register as register_bifurcation

    from opa.cli._sobol import register_sobol
    from opa.cli._stability import register_stability
    from opa.cli._stochastic import register_stochastic

    register_validate(sub)
    register_converge(sub)
    register_bifurcation(sub)
    register_stability(sub)
    register_stochastic(sub)
    register_sobol(sub)
    for leaf in _leaves(sub):
        for action in leaf._actions:  # one rule for every command's --scheduler
            if "--scheduler" in action.option_strings:
                action.type = _scheduler
        leaf.add_argument("--work-budget", type=_duration, default=None, metavar="T",
                          help="refuse work estimated to take longer than T (30m, 12h, 2d, "
                               "inf; a bare number is hours); default $OPA_MC_WORK_BUDGET, "
                               "else 4h")
    return parser


def _leaves(subparsers):
    """The parsers that run a command (simulate's models, not simulate itself)."""
    for parser in subparsers.choices.values():
        nested = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if nested:
            yield from _leaves(nested[0])
        else:
            yield parser


def _scheduler(text: str) -> str:
    from mc import check_scheduler_address

    try:
        return check_scheduler_address(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _duration(text: str) -> float:
    from opa.engine import parse_duration

    try:
        return parse_duration(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


#: the flag of each keyword a work estimate names (opa._work.WorkBudgetError.drivers)
WORK_FLAGS = {"samples": "--samples", "periods": "--periods", "order": "--order",
              "elements": "--elements", "values": "--sweep values", "transient": "--transient",
              "record": "--record", "sigmas": "--sigmas", "max_samples": "--max-samples",
              "horizons": "--horizons", "states": "--extra-states",
              "transient + record": "--transient + --record", "omega": "--omega"}


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


def main(argv: list[str] | None = None) -> int:
    """Run one command. Mistakes print one line and return 2; a run that cannot be
    completed returns 3; anything unforeseen prints one line naming the error (set
    OPA_MC_TRACEBACK=1 for the traceback) and returns 1."""
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    from opa import SimulationError
    from opa.engine import COMMAND, WorkBudgetError, budget

    token = COMMAND.set(("opa-mc", *args.argv))

    try:
        with budget(getattr(args, "work_budget", None)):
            return args.func(args)
    except WorkBudgetError as err:
        print(f"opa-mc: error: {_one_line(err.message(WORK_FLAGS))}", file=sys.stderr)
        return EXIT_USAGE
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
    finally:
        COMMAND.reset(token)


if __name__ == "__main__":
    sys.exit(main())
