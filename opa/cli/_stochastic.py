"""``opa-mc stochastic``: the stochastic bifurcation diagram (attractor types and their
probabilities along a control parameter, boundaries in xi, Monte Carlo beside them).

Wired into ``opa.cli._main.build_parser`` by ``register_stochastic(sub)``. User mistakes
raise ``ValueError`` (reported by ``opa.cli._main.main`` as one line, exit 2).
"""

from __future__ import annotations

import sys
import time

from opa.cli._args import parse_sweep, positive_int, whole_number
from opa._model import PARAMETER_NAMES
from opa.cli._flags import _model_flags, _output_flags, _solver_flags


def register_stochastic(sub) -> None:
    p = sub.add_parser(
        "stochastic", help="stochastic bifurcation diagram: which attractors, how likely",
        description="For each value of a control parameter, the attractor types the "
        "sampled systems p = p_bar + sigma xi settle on (period label z = n/p), the "
        "boundaries in xi where the type changes (located bifurcations, by continuation "
        "in the uncertain parameter), their probabilities under the law of xi, and a "
        "Monte Carlo classification with binomial standard errors beside them.")
    _model_flags(p)
    g = p.add_argument_group("diagram")
    g.add_argument("--sweep", required=True, metavar="NAME=START:STOP:COUNT",
                   help="the control parameter and its values (not the uncertain one)")
    g.add_argument("--sigma", type=float, default=0.03, metavar="S",
                   help="intensity of the uncertain parameter (default 0.03)")
    g.add_argument("--uncertain", choices=("mu", "a", "c"), default="mu",
                   help="the uncertain parameter (default mu)")
    g.add_argument("--distribution", default=None, metavar="LAW",
                   help="law of xi: semicircle (default), uniform, beta:A,B, normal-trunc:K")
    g.add_argument("--samples", type=whole_number, default=256, metavar="M",
                   help="Monte Carlo samples classified at each value (0: none; default 256)")
    g.add_argument("--seed", type=whole_number, default=0, metavar="K",
                   help="random seed of the samples (default 0)")
    g.add_argument("--transient", type=positive_int, default=1000, metavar="P",
                   help="forcing periods dropped before a run is classified (default 1000: "
                        "near a period doubling the transient decays slowly)")
    g.add_argument("--record", type=positive_int, default=64, metavar="P",
                   help="forcing periods recorded to find the period (default 64)")
    _solver_flags(p)
    _output_flags(p, parts=True)
    p.set_defaults(func=cmd_stochastic)


def cmd_stochastic(args) -> int:
    from opa.cli._flags import check_outputs, options_from, oscillator_from
    from opa.dynamics._stochastic import stochastic_diagram

    check_outputs(args)  # refuses --keep-parts without --out too
    name, values, _ = parse_sweep(
        args.sweep, names=tuple(n for n in PARAMETER_NAMES
                                if n not in (args.uncertain, "x0", "v0")))
    osc = oscillator_from(args)
    start = time.perf_counter()
    log = None if args.quiet else (lambda line: print(f"opa-mc: {line}", file=sys.stderr))
    ds = stochastic_diagram(osc, name, values, sigma=args.sigma, uncertain=args.uncertain,
                            distribution=args.distribution, samples=args.samples,
                            seed=args.seed, options=options_from(args),
                            transient=args.transient, record=args.record,
                            parts=f"{args.out}.parts" if args.out else None, log=log)
    elapsed = time.perf_counter() - start
    if args.out:
        import shutil

        from opa._dataset import write_netcdf

        write_netcdf(ds, args.out)
        if not args.keep_parts:  # each value was kept as it finished: a killed run resumes
            shutil.rmtree(f"{args.out}.parts", ignore_errors=True)
    if args.plot:
        from opa.plots._stochastic import plot_stochastic

        plot_stochastic(ds, args.plot)
    if not args.quiet:
        print(f"opa-mc stochastic: {len(values)} values of {name}, {args.uncertain} = "
              f"{getattr(osc, args.uncertain):g} + {args.sigma:g} xi, {args.samples} "
              f"samples each, in {elapsed:.1f} s")
        for line in summary(ds):
            print(f"  {line}")
        for path in (args.out, args.plot):
            if path:
                print(f"  wrote {path}")
    return 0


def summary(ds) -> list[str]:
    """One line per control value: the types with their probabilities, how they were
    found, and whether the Monte Carlo classification agrees."""
    param = ds.attrs["sweep_parameter"]
    lines = []
    for i, value in enumerate(ds[param].values):
        shares = [f"{k} {float(p):.3f}" for k, p in zip(ds.type.values, ds.probability[i].values)
                  if p > 0]
        how = "sampled" if int(ds.method[i]) else "continuation"
        agree = {1: "", 0: "; MC DISAGREES", -1: ""}[int(ds.agree[i])]
        lines.append(f"{param} = {value:.6g}: {', '.join(shares)} ({how}{agree})")
    return lines


__all__ = ["cmd_stochastic", "register_stochastic", "summary"]
