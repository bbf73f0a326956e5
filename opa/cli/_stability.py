"""``opa-mc stability``: periodic orbits, Floquet multipliers, branches, Lyapunov exponents.

Wired into ``opa.cli._main.build_parser`` by
``register_stability(sub)``. User mistakes raise
``ValueError`` (reported by ``opa.cli._main.main`` as one line, exit 2).
"""

from __future__ import annotations

import time

import numpy as np

from opa.cli._args import parse_sweep, positive_int, whole_number
from opa.cli._flags import _model_flags, _solver_flags, _system_flags, write_and_draw
from opa.dynamics import CONTINUABLE, STABILITY_LAWS


def parse_branch_sweep(spec: str) -> tuple[str, float, float, int]:
    """``--sweep`` of ``stability`` (the grammar of ``opa.cli._args.parse_sweep``):
    follow the branch from START to STOP in at least COUNT steps (default 20).

    >>> parse_branch_sweep("c=0.1:0.02:40")
    ('c', 0.1, 0.02, 40)
    """
    name, _, (start, stop, count) = parse_sweep(spec, names=CONTINUABLE, default_count=20,
                                                ranges_only=True)
    if count < 2:
        raise ValueError(f"--sweep {spec!r}: START and STOP must differ")
    return name, start, stop, count


def _system(args):
    from opa.cli._flags import options_from, system_from
    from opa.dynamics import ImpactSystem

    return ImpactSystem.of(system_from(args), model=args.model, options=options_from(args))


def _format_multipliers(mu: np.ndarray, count: int = 4) -> str:
    parts = []
    for m in mu[:count]:
        if abs(m.imag) > 1e-12:
            parts.append(f"{m.real:+.6f}{m.imag:+.6f}i (|mu| = {abs(m):.6f})")
        else:
            parts.append(f"{m.real:+.6f}")
    more = f" ... ({len(mu)} in all)" if len(mu) > count else ""
    return ", ".join(parts) + more


def cmd_stability(args) -> int:
    from opa.cli._flags import check_outputs, refuse_given

    check_outputs(args)
    if args.model == "dmr":
        refuse_given(args, ["sigma", "uncertain", "allow_negative", "order", "truncation",
                            "impact_law"], "applies to stability opa, not stability dmr (the "
                                           "deterministic system has no uncertain parameter)")
    if not args.lyapunov:
        refuse_given(args, ["benettin", "lyapunov_periods"], "applies with --lyapunov only")
    if not args.sweep:
        refuse_given(args, ["seed_value", "depth", "max_points"],
                     "applies with --sweep only (the continuation of a branch)")
    from opa.dynamics import (BIFURCATION_KINDS, ContinuationOptions, benettin_engine,
                              continue_orbits, impulse_cycle, lyapunov_benettin,
                              lyapunov_exponent, orbit_dataset, periodic_orbit)

    system = _system(args)
    start = time.perf_counter()
    periods = args.orbit_periods
    if system.oscillator.F0 != 0.0 and not args.quiet:
        k0 = impulse_cycle(system.oscillator)
        cycle = (f"the forcing repeats every {k0} forcing periods: orbits are fixed points "
                 f"of P^{k0} (or its multiples)" if k0 else
                 "the forcing has no common period: only --lyapunov is meaningful")
        print(f"opa-mc stability: impulses on (F0 = {system.oscillator.F0:g}); {cycle}")
    if args.sweep:
        name, lo, hi, count = parse_branch_sweep(args.sweep)
        ds = continue_orbits(system, name, lo, hi, seed=args.seed_value, periods=periods,
                             t0=args.t0, depth=args.depth, continuation=ContinuationOptions(
                                 step=1.0 / count, max_step=1.0 / count,
                                 max_points=args.max_points, transient=args.transient),
                             progress=not args.quiet)
        if not args.quiet:
            print(f"opa-mc stability: {ds.sizes['branch_id']} branch(es), {ds.sizes['point']} "
                  f"orbits in {time.perf_counter() - start:.1f} s")
            for i in range(ds.sizes["bifurcation"]):
                kind = BIFURCATION_KINDS[int(ds.bifurcation_kind[i])]
                how = "located" if int(ds.bifurcation_located[i]) else "interpolated"
                print(f"  {kind:16s} {name} = {float(ds[f'bifurcation_{name}'][i]):.10g} "
                      f"({how}; branch {int(ds.bifurcation_branch[i])}, period "
                      f"{int(ds.branch_period[int(ds.bifurcation_branch[i])])})")
    else:
        orbit = periodic_orbit(system, periods=periods, t0=args.t0, transient=args.transient)
        ds = orbit_dataset(system, orbit, t0=args.t0)
        if not args.quiet:
            print(f"opa-mc stability {args.model}: period-{orbit.periods} orbit (label "
                  f"{orbit.label}) in {time.perf_counter() - start:.2f} s; "
                  f"{', '.join(orbit.classify())}")
            print(f"  state at t0 = {args.t0:g}: {np.array2string(orbit.state, precision=8)}")
            print(f"  Floquet multipliers: {_format_multipliers(orbit.multipliers)}")
            print(f"  Newton residual {orbit.residual:.2g} after {orbit.iterations} iterations; "
                  f"smallest impact velocity {orbit.min_impact_velocity:.4g}")
    if args.lyapunov:
        est = lyapunov_exponent(system, periods=args.lyapunov_periods, transient=args.transient,
                                t0=args.t0)
        ds.attrs["lyapunov_exponent"] = est.exponent
        ds.attrs["lyapunov_standard_error"] = est.standard_error
        if not args.quiet:
            print(f"  largest Lyapunov exponent {est.exponent:+.5f} ± {est.standard_error:.5f} "
                  f"per unit time ({est.periods} periods, {est.method})")
        if args.benettin:
            check = lyapunov_benettin(system, periods=args.lyapunov_periods,
                                      transient=args.transient, engine=benettin_engine(system))
            ds.attrs["lyapunov_benettin"] = check.exponent
            if not args.quiet:
                print(f"  Benettin check            {check.exponent:+.5f} ± "
                      f"{check.standard_error:.5f} ({check.method})")
    from opa.plots import plot_branches

    write_and_draw(ds, args, plot_branches)
    return 0


def register_stability(subparsers) -> None:
    """Add ``stability`` to the ``opa-mc`` subcommands (flags from ``opa.cli._flags``)."""
    p = subparsers.add_parser(
        "stability",
        help="periodic orbits, Floquet multipliers, branches through period doubling, "
             "Lyapunov exponents",
        description="Find a periodic orbit of the stroboscopic map by Newton shooting with "
        "the exact Jacobian (variational equation with saltation matrices at impacts) and "
        "print its Floquet multipliers and classification; with --sweep, follow its branch "
        "by pseudo-arclength continuation, locate period doublings to 1e-10 in the "
        "parameter and switch onto the doubled branches; with --lyapunov, the largest "
        "Lyapunov exponent. With impulses (F0 != 0) the map is taken over the common "
        "period of the harmonic forcing and the impulse train.",
    )
    p.add_argument("model", choices=("dmr", "opa"),
                   help="dmr: deterministic system (eq. 29); opa: OPA equivalent system")
    _model_flags(p)
    _system_flags(p, laws=STABILITY_LAWS)
    s = p.add_argument_group("orbit and branch")
    s.add_argument("--orbit-periods", type=positive_int, default=None, metavar="K",
                   help="period of the orbit in forcing periods (default: detected after "
                        "the transient)")
    s.add_argument("--t0", type=float, default=0.0,
                   help="section time: the orbit is sampled at t0 + j 2 pi/omega (default 0)")
    s.add_argument("--transient", type=whole_number, default=300, metavar="P",
                   help="forcing periods run from x0, v0 before shooting (default 300)")
    s.add_argument("--sweep", default=None, metavar="NAME=START:STOP[:COUNT]",
                   help="follow the branch in NAME from START to STOP with at least COUNT "
                        "steps (default 20)")
    s.add_argument("--seed-value", type=float, default=None, metavar="VALUE",
                   help="find the first orbit at this parameter value (default START) and "
                        "follow it both ways")
    s.add_argument("--depth", type=whole_number, default=1,
                   help="levels of period-doubled branches to switch onto (default 1)")
    s.add_argument("--max-points", type=positive_int, default=500,
                   help="largest number of orbits on one branch (default 500)")
    s.add_argument("--lyapunov", action="store_true",
                   help="also compute the largest Lyapunov exponent (variational, saltation)")
    s.add_argument("--lyapunov-periods", type=positive_int, default=2000, metavar="P",
                   help="forcing periods averaged for the Lyapunov exponent (default 2000)")
    s.add_argument("--benettin", action="store_true",
                   help="with --lyapunov: the two-trajectory check as well")
    _solver_flags(p)
    o = p.add_argument_group("output")
    o.add_argument("--out", default=None, metavar="FILE.nc", help="write the dataset here")
    o.add_argument("--plot", default=None, metavar="FILE.png",
                   help="write the branch diagram here (stable solid, unstable dashed)")
    o.add_argument("--quiet", action="store_true", help="no summaries")
    p.set_defaults(func=cmd_stability)


__all__ = ["register_stability", "parse_branch_sweep", "cmd_stability"]
