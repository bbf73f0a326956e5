"""``opa-mc sobol``: the Sobol indices of the true impact systems, certified, beside the
OPA surrogate's (``compare.certify_sobol``).

Wired into ``opa.cli._main.build_parser`` by ``register_sobol(sub)``. User mistakes raise
``ValueError`` or ``CliError`` (reported by ``opa.cli._main.main`` as one line naming the
flag, exit 2).
"""

from __future__ import annotations

import math

from opa.cli._args import positive_int, whole_number
from opa.cli._flags import (
    mean_law_blind,
    CliError,
    _law_flag,
    _model_flags,
    _run_flags,
    _solver_flags,
    _system_flags,
    check_outputs,
    flagged,
    write_and_draw,
    options_from,
    system_from,
)

#: the reading codes of the dataset (``compare._sobol.READINGS``)
_RESOLVED, _NOISE = 0, 1


def cell(ds, name: str, parameter: str, t: int = -1) -> str:
    """One certified index as the table shows it: ``value ± SE`` where resolved,
    ``within noise [0, u]``, or ``undefined``."""
    pick = dict(parameter=parameter, time=ds.time.values[t])
    code = int(ds[f"{name}_reading"].sel(pick))
    if code == _RESOLVED:
        return f"{float(ds[name].sel(pick)):.4g} ± {float(ds[f'{name}_se'].sel(pick)):.2g}"
    if code == _NOISE:
        return f"within noise [0, {float(ds[f'{name}_upper'].sel(pick)):.3g}]"
    return "undefined"


def table_lines(ds, state: str = "x") -> list[str]:
    """The table of ``state``'s indices at the last output: per parameter the surrogate's
    S_i and ST_i and the certified ones."""
    header = ("parameter", "S_i surrogate", "S_i certified", "ST_i surrogate",
              "ST_i certified")
    rows = [header]
    for parameter in (str(p) for p in ds.parameter.values):
        row = [parameter]
        for kind in ("first", "total"):
            name = f"{state}_sobol_{kind}"
            value = float(ds[f"{name}_surrogate"].sel(parameter=parameter)[-1])
            row += ["undefined" if math.isnan(value) else f"{value:.4g}",
                    cell(ds, name, parameter)]
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    return ["  ".join(text.ljust(w) for text, w in zip(r, widths)).rstrip() for r in rows]


def cmd_sobol(args) -> int:
    check_outputs(args)
    if isinstance(args.uncertain, str):
        raise CliError(f"--uncertain {args.uncertain}: Sobol indices need at least two "
                       f"uncertain parameters (e.g. --uncertain mu,c)")
    system = system_from(args)
    if system.dimension < 2:  # the default, or the uncertain parameters of a --model file
        where = (f"--model {args.model_file}: its [uncertain.NAME] tables name one "
                 f"({system.uncertain}); " if getattr(args, "model_file", None) else
                 "")
        raise CliError(f"{where}Sobol indices need at least two uncertain parameters "
                       f"(e.g. --uncertain mu,c)")
    options = options_from(args)
    import compare

    try:
        ds = compare.certify_sobol(system, samples=args.samples, seed=args.seed,
                                   periods=args.periods, per_period=args.per_period,
                                   basis=args.basis, options=options,
                                   control=not args.no_control, sampler=args.sampler)
    except ValueError as err:
        raise CliError(flagged(err, ("samples", "seed", "basis", "sampler", "periods",
                                     "order", "truncation"))) from None
    t_end = float(ds.time[-1])
    periods = t_end / float(ds.time.attrs["forcing_period"])
    print(f"opa-mc sobol: Sobol indices of x at t = {t_end:.6g} ({periods:.4g} forcing "
          f"periods): the OPA surrogate (N = {ds.attrs['N']}, {ds.attrs['terms']} "
          f"terms) and {ds.attrs['true_system_runs']} true systems ({ds.attrs['samples']} "
          f"pick-freeze samples, {args.sampler}"
          f"{'' if args.no_control else ', the surrogate as control variate'})")
    for line in table_lines(ds):
        print(f"  {line}")
    for line in mean_law_blind(system.impact_law, ",".join(system.problem.names)):
        print(f"  {line.replace(' with --elements adaptive', '')}")
    print(f"agreement: the surrogate's indices lie in the certified intervals at "
          f"{100 * ds.attrs['agreement']:.0f} % of the outputs of x and v")
    if not args.quiet:
        print(ds.attrs["verdict"])
    from opa.plots import plot_sensitivity

    write_and_draw(ds, args, plot_sensitivity)
    return 0


def register_sobol(subparsers) -> None:
    """Add ``sobol`` to the ``opa-mc`` subcommands (flags from ``opa.cli._flags``)."""
    p = subparsers.add_parser(
        "sobol",
        help="Sobol indices of the true impact systems, certified, beside the OPA "
             "surrogate's",
        description="The first-order and total Sobol indices of x(t) and v(t) for each "
        "uncertain parameter (two or more: --uncertain mu,c): exactly those of the OPA "
        "surrogate (from its coefficients), and those of the true sampled impact systems "
        "by pick-freeze Monte Carlo ((d + 2) M true systems) with standard errors, the "
        "surrogate as control variate. An index within the noise is reported as its "
        "interval [0, u], never as a negative number.",
    )
    _model_flags(p)
    _run_flags(p)
    _system_flags(p, several=True)
    _law_flag(p, elements=False)
    g = p.add_argument_group("pick-freeze Monte Carlo")
    g.add_argument("--samples", type=positive_int, default=1024, metavar="M",
                   help="rows of each of the two samples A and B (a power of two >= 8 with "
                        "--sampler sobol); the true systems run (d + 2) M times "
                        "(default 1024)")
    g.add_argument("--sampler", choices=("sobol", "random"), default="sobol",
                   help="A and B: the two halves of scrambled Sobol' points in 2d "
                        "dimensions, or independent random points (default sobol)")
    g.add_argument("--seed", type=whole_number, default=0, metavar="K",
                   help="random seed (default 0)")
    g.add_argument("--no-control", action="store_true",
                   help="certify by plain pick-freeze Monte Carlo, without the surrogate "
                        "as control variate (both standard errors are written either way)")
    _solver_flags(p)
    o = p.add_argument_group("output")
    o.add_argument("--out", default=None, metavar="FILE.nc", help="write the dataset here")
    o.add_argument("--plot", default=None, metavar="FILE.png",
                   help="write the figure of the indices of x over time here")
    o.add_argument("--quiet", action="store_true", help="only the table and the agreement")
    p.set_defaults(func=cmd_sobol)


__all__ = ["register_sobol", "cmd_sobol", "table_lines"]
