"""``opa-mc bifurcation`` and ``opa-mc reproduce``: sweeps and the paper's figures.

Wired into ``opa.cli._main.build_parser`` by ``register(sub)``.
User mistakes raise ``ValueError`` (reported by ``opa.cli._main.main`` as one line, exit 2).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from opa import DEFAULT_ORDER, SWEEPABLE
from opa.cli._args import positive_int, whole_number
from opa.cli._args import parse_sweep as _parse_sweep
from opa.cli._flags import _common_flags, _impulse_flags, _model_flags
from opa.dynamics import (CONTINUATIONS, DEFAULT_WORKERS, MOTION_GRAZE_GAP,
                          MOTION_GRAZE_VELOCITY, PERIOD_TOL, SWEEP_MODELS, summary_lines)

SECTIONS = ("phase", "constraint", "both")


def parse_sweep(spec: str, oscillator=None) -> tuple[str, np.ndarray]:
    """``--sweep`` of ``bifurcation`` (the grammar of ``opa.cli._args.parse_sweep``):
    the swept parameter and its values; with ``oscillator``, its force law's own
    constants may be swept too (``Oscillator.sweepable_names``).

    >>> name, values = parse_sweep("c=0.01:0.1:10")
    >>> name, len(values), float(values[-1])
    ('c', 10, 0.1)
    """
    names = SWEEPABLE if oscillator is None else oscillator.sweepable_names + ("sigma",)
    name, values, _ = _parse_sweep(spec, names=names)
    return name, values




def _check_sizes(osc, param, values, args) -> None:
    """Refuse sweeps that cannot finish or fit: the span of each run and the sections."""
    from opa.engine import check_memory, check_span

    span = args.transient + args.record
    swept = [float(values.min()), float(values.max())] if param in ("omega", "omega1") else []
    for value in swept:
        varied = osc.replace(**{param: value})
        check_span(varied, span * varied.forcing_period)
    check_span(osc, span * osc.forcing_period)
    check_memory(f"{len(values)} sweep values x {args.record} x {args.per_period} section "
                 f"points", len(values) * (args.record * args.per_period + 1) * 8 * 6)


def cmd_bifurcation(args) -> int:
    from mc import checkpoint_for, sweep_source
    from opa.cli._flags import check_outputs, execution_from, options_from, system_from
    from opa.dynamics import MonteCarlo, MotionTolerances, Window, sweep

    check_outputs(args)
    if args.model != "mc":
        from opa.cli._flags import refuse_given

        refuse_given(args, ["samples", "sampler", "seed"],
                     f"applies to bifurcation mc, not bifurcation {args.model}")
    if args.periods is not None:
        raise ValueError("--periods does not apply to bifurcation sweeps; use --transient P "
                         "and --record P")
    system = system_from(args)
    param, values = parse_sweep(args.sweep, system.oscillator)
    opts = options_from(args)
    _check_sizes(system.oscillator, param, values, args)
    start = time.perf_counter()
    ds = sweep(
        args.model, param, values, system,
        window=Window(args.transient, args.record, args.per_period),
        continuation=args.continuation,
        mc=MonteCarlo(source=sweep_source if args.model == "mc" else None,
                      samples=getattr(args, "samples", 256),
                      sampler=getattr(args, "sampler", "sobol"), seed=getattr(args, "seed", 0)),
        options=opts, out=args.out, locate=args.locate,
        motion=MotionTolerances(period_tol=args.period_tol, graze_velocity=args.graze_velocity,
                                graze_gap=args.graze_gap),
        # --keep-parts: OUT.parts is the run's named checkpoint, kept after the write
        execution=execution_from(args, log=None, checkpoint=(
            checkpoint_for(args.out) if args.keep_parts else None)),
    )
    elapsed = time.perf_counter() - start
    if args.plot:
        from opa.plots import plot_bifurcation

        plot_bifurcation(ds, args.plot, section=args.section)
    if not args.quiet:
        resumed = ds.attrs["points_resumed"]
        print(f"opa-mc bifurcation {args.model}: {len(values)} values of {param} in "
              f"[{values.min():.6g}, {values.max():.6g}], {args.transient} + {args.record} periods"
              f" each, in {elapsed:.2f} s" + (f" ({resumed} resumed from disk)" if resumed
                                                else ""))
        print("\n".join(summary_lines(ds)))
        if args.out:
            print(f"  wrote {args.out}")
        if args.plot:
            print(f"  wrote {args.plot}")
    return 0


def cmd_reproduce(args) -> int:
    from compare import FIGURES, reproduce
    from opa.cli._flags import check_outputs

    check_outputs(args)
    names = list(FIGURES) if args.figure == "all" else [args.figure]
    start = time.perf_counter()
    paths = reproduce(args.figure, args.outdir, full=args.full, impulse=args.impulse,
                      pulse_width=args.pulse_width, impulse_at_zero=args.impulse_at_zero,
                      order=args.order, workers=args.workers,
                      scheduler=args.scheduler, progress=not args.quiet,
                      log=None if args.quiet else print)
    if not args.quiet:
        print(f"opa-mc reproduce {args.figure}: {len(names)} figure(s), {len(paths)} files "
              f"in {time.perf_counter() - start:.1f} s")
    return 0


def _set_help(parser: argparse.ArgumentParser, dest: str, text: str, default) -> None:
    """Change one shared flag's default and help for this subcommand."""
    parser.set_defaults(**{dest: default})
    for action in parser._actions:  # argparse has no public accessor for this
        if action.dest == dest:
            action.help = text


class _FigureNames:
    """The figures ``reproduce`` draws (:data:`compare.FIGURES`) and "all", read when the
    parser checks or lists them: building the parser imports no matplotlib."""

    def _names(self) -> tuple[str, ...]:
        from compare import FIGURES

        return (*FIGURES, "all")

    def __contains__(self, name) -> bool:
        return name in self._names()

    def __iter__(self):
        return iter(self._names())


def register(subparsers) -> None:
    """Add ``bifurcation`` and ``reproduce`` to the ``opa-mc`` subcommands (flags from
    ``opa.cli._flags``)."""
    b = subparsers.add_parser(
        "bifurcation",
        help="parameter sweep: both Poincaré sections, period labels, grazing",
        description="Sweep one parameter; for each value drop a transient, record the "
        "phase-plane (stroboscopic, t = k 2 pi/omega) and constraint-plane (at impacts: "
        "forcing phase and velocity) sections and identify the motion: period p "
        "(smallest stroboscopic repeat), impacts per period, label z = n/p, grazing. "
        "The bifurcations (period doubling, fold, grazing, impulse-impact) are located "
        "by continuing the observed periodic orbits (--locate, default for dmr); the "
        "observed periods are reported as such. Parallel over values (local processes "
        "or --scheduler); with --out, finished values are kept in OUT.parts/ and a rerun "
        "resumes.",
    )
    b.add_argument("model", choices=SWEEP_MODELS,
                   help="dmr: deterministic system; opa: EMR of the OPA system (--sigma 0: "
                        "EMR_0); mc: Monte Carlo mean")
    _model_flags(b)
    _common_flags(b)
    if "--out" not in b._option_string_actions:  # shared output flags, unless common has them
        o = b.add_argument_group("output")
        o.add_argument("--out", default=None, metavar="FILE.nc",
                       help="write the sweep dataset here; finished values are kept in "
                            "FILE.nc.parts/ meanwhile and a rerun resumes")
        o.add_argument("--plot", default=None, metavar="FILE.png",
                       help="write the bifurcation diagram here")
        o.add_argument("--quiet", action="store_true", help="no progress bars or summaries")
    g = b.add_argument_group("sweep")
    g.add_argument("--sweep", required=True, metavar="NAME=START:STOP:COUNT",
                   help="the swept parameter and its values, e.g. c=0.01:0.1:200 or "
                        "omega=3.98,4.2; NAME is a model parameter or sigma")
    g.add_argument("--section", choices=SECTIONS, default="both",
                   help="Poincaré section(s) in the --plot figure (the dataset holds both; "
                        "default both)")
    g.add_argument("--transient", type=whole_number, default=500, metavar="P",
                   help="forcing periods dropped before recording (default 500)")
    g.add_argument("--record", type=positive_int, default=100, metavar="P",
                   help="forcing periods recorded (default 100)")
    g.add_argument("--continuation", choices=CONTINUATIONS, default="fixed",
                   help="fixed: every value starts from --x0/--v0; forward/backward: each "
                        "value starts from the final state of the previous one, sweeping "
                        "up/down (sequential) (default fixed)")
    g.add_argument("--workers", type=positive_int, default=DEFAULT_WORKERS, metavar="W",
                   help=f"local worker processes (default {DEFAULT_WORKERS}; 1: in process)")
    g.add_argument("--period-tol", type=float, default=PERIOD_TOL, metavar="TOL",
                   help=f"relative tolerance of the stroboscopic repeat (default {PERIOD_TOL:g})")
    g.add_argument("--graze-velocity", type=float, default=MOTION_GRAZE_VELOCITY, metavar="V",
                   help=f"impacts slower than V count as grazing (default "
                        f"{MOTION_GRAZE_VELOCITY:g})")
    g.add_argument("--graze-gap", type=float, default=MOTION_GRAZE_GAP, metavar="D",
                   help="free-flight maxima within D of the wall count as grazing "
                        f"(default {MOTION_GRAZE_GAP:g})")
    g.add_argument("--keep-parts", action="store_true",
                   help="keep OUT.parts/ (one file per finished value) after writing OUT")
    g.add_argument("--locate", action=argparse.BooleanOptionalAction, default=None,
                   help="locate the bifurcations of the observed periodic attractors by "
                        "continuation (Floquet multipliers, to 1e-10 in the parameter); "
                        "the summary lists them and where the observed periods disagree. "
                        "Default: on for dmr (off where the parameter does not allow it: "
                        "x0, v0, or a common period of forcing and impulses that changes), "
                        "off for opa (slower); never for mc. A few seconds to tens of "
                        "seconds")
    _set_help(b, "per_period",
              "outputs per forcing period in the record; >= 8 resolves free-flight maxima "
              "for grazing (default 16)", 16)
    _set_help(b, "periods", "not used by sweeps: see --transient and --record", None)
    b.set_defaults(func=cmd_bifurcation)

    r = subparsers.add_parser(
        "reproduce",
        help="the paper's figures 2-11 (impulse trains, bifurcation diagrams, portraits)",
        description="Regenerate the paper's figures: fig2 impulse trains; fig3, fig9, "
        "fig10 bifurcation diagrams in both sections; fig4-fig8, fig11 phase portraits "
        "with section points and time histories; the Monte Carlo mean and its band beside "
        "every EMR, the DMR beside every EMR_0; bifurcation lines only where located. Each "
        "figure's data is written next to it as netCDF, its caption and measured "
        "differences from the paper as figN.txt. Default sizes took 58.5 s on 2 cores "
        "(docs/figures.md); --full uses the paper's resolution.",
    )
    r.add_argument("figure", choices=_FigureNames(), metavar="FIGURE",
                   help="a figure of the paper, fig2 to fig11, or all")
    r.add_argument("--outdir", default="figures", metavar="DIR",
                   help="where to write the PNG and netCDF files (default ./figures)")
    r.add_argument("--full", action="store_true",
                   help="paper resolution: 200 sweep values, 500 + 100 periods (slow)")
    r.add_argument("--order", type=whole_number, default=DEFAULT_ORDER, metavar="N",
                   help=f"OPA order N of EMR_0 and EMR (default {DEFAULT_ORDER})")
    _impulse_flags(r)
    r.add_argument("--workers", type=positive_int, default=DEFAULT_WORKERS, metavar="W",
                   help=f"local worker processes for sweeps (default {DEFAULT_WORKERS})")
    r.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask distributed scheduler address for the sweeps")
    r.add_argument("--quiet", action="store_true", help="no progress bars or summaries")
    r.set_defaults(func=cmd_reproduce)


__all__ = ["cmd_bifurcation", "cmd_reproduce", "parse_sweep", "register"]
