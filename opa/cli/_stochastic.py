"""``opa-mc stochastic``: the stochastic bifurcation diagram (attractor types and their
probabilities along a control parameter, boundaries in xi, Monte Carlo beside them).

Wired into ``opa.cli._main.build_parser`` by ``register_stochastic(sub)``. User mistakes
raise ``ValueError`` (reported by ``opa.cli._main.main`` as one line, exit 2), and so does
a second run to the same ``--out`` while the first runs (the lock of ``OUT.parts``,
:mod:`opa._lock`). The inputs are checked by ``opa.dynamics._stochastic.check_diagram``
before the lock and any work; its refusals name the keywords, written here as the flags
(``FLAGS``).
"""

from __future__ import annotations

import contextlib
import sys
import time

import numpy as np

from opa.cli._args import parse_sweep, positive_int, whole_number
from opa.cli._flags import _model_flags, _output_flags, _solver_flags, scales, uncertain_names


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
    g.add_argument("--sigma", type=scales, default=0.03, metavar="S[,S...]",
                   help="intensity of the uncertain parameter, or one per --uncertain name "
                        "(default 0.03)")
    g.add_argument("--uncertain", type=uncertain_names, default="mu", metavar="P[,P...]",
                   help="the uncertain parameter among mu, a, c, eta, delta, f, omega, F0 or "
                        "a --model force law's constants (default mu, or the --model file's "
                        "[uncertain.NAME]), or "
                        "several "
                        "such as mu,c: then no boundaries are located (continuation in xi "
                        "is one-dimensional) and the probabilities are sampled, scrambled "
                        "Sobol' points with standard errors from 8 scramblings")
    g.add_argument("--distribution", default=None, metavar="LAW[,LAW...]",
                   help="law of xi: semicircle (default), uniform, beta:A,B, normal-trunc:K; "
                        "one per --uncertain name, or one for all")
    g.add_argument("--samples", type=whole_number, default=1024, metavar="M",
                   help="Monte Carlo samples classified at each value (0: none; default 1024)")
    g.add_argument("--seed", type=whole_number, default=0, metavar="K",
                   help="random seed of the samples (default 0)")
    g.add_argument("--transient", type=positive_int, default=1000, metavar="P",
                   help="the longest transient: a run that has not settled on a period (to "
                        "1e-6) or shown chaos by then is classified from its last --record "
                        "periods (default 1000; most runs settle within 50 to 300)")
    g.add_argument("--record", type=positive_int, default=64, metavar="P",
                   help="the last P forcing periods of a run, after its transient, are "
                        "examined for its period; periods up to P/2 are found (default 64, "
                        "at least 4; it may exceed --transient: the run is transient + P "
                        "long)")
    g.add_argument("--extra-states", type=whole_number, default=2, metavar="K",
                   help="other initial states from which the interval middles and the first "
                        "--coexist samples are classified too, to find coexisting attractors "
                        "(default 2; 0: none)")
    g.add_argument("--coexist", type=whole_number, default=None, metavar="M",
                   help="samples classified from the other initial states too (default 64)")
    g.add_argument("--emr", action="store_true",
                   help="also sweep the EMR (OPA N = --emr-order at the same sigma) and draw "
                        "the paper's diagram beside the stochastic one")
    g.add_argument("--emr-order", type=positive_int, default=None, metavar="N",
                   help="order of the EMR's OPA system (default 4; with --emr)")
    g.add_argument("--workers", type=positive_int, default=2, metavar="W",
                   help="local worker processes, one control value each at a time "
                        "(default 2; 1: in process)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler: the control values run there as tasks instead")
    _solver_flags(p)
    _output_flags(p, parts=True)
    p.set_defaults(func=cmd_stochastic)


#: each keyword of ``stochastic_diagram`` that the CLI sets, named by its flag in refusals
#: (``DiagramInputError.message``, ``WorkBudgetError.message``)
FLAGS = {"sigma": "--sigma", "uncertain": "--uncertain", "distribution": "--distribution",
         "samples": "--samples", "seed": "--seed", "transient": "--transient",
         "record": "--record", "extra_states": "--extra-states", "coexist": "--coexist",
         "emr": "--emr", "emr_order": "--emr-order", "workers": "--workers",
         "scheduler": "--scheduler", "parameter": "--sweep", "values": "--sweep values",
         "transient + record": "--transient + --record", "parts": "--out's parts folder",
         "oscillator": "the model"}


def cmd_stochastic(args) -> int:
    from opa.cli._flags import check_outputs, given, options_from, oscillator_from, \
        refuse_given, uncertain_from
    from opa.dynamics import DiagramInputError, check_diagram
    from opa.engine import WorkBudgetError

    check_outputs(args)  # refuses --keep-parts without --out too; --workers bound
    drawn = uncertain_from(args)  # a --model file's [uncertain.NAME], under the flags
    if drawn.pop("allow_negative", False):
        raise ValueError(f"--model {args.model_file}: allow_negative has no effect on "
                         f"stochastic (its sampled systems take any sign); leave it out")
    for key, value in drawn.items():
        setattr(args, key, value)
    swept = args.sweep.partition("=")[0].strip().lstrip("-")
    uncertain = (args.uncertain,) if isinstance(args.uncertain, str) else args.uncertain
    if swept in uncertain:
        which = "the uncertain parameter" if len(uncertain) == 1 else "an uncertain parameter"
        raise ValueError(f"--sweep {args.sweep!r}: {swept} is {which} "
                         f"(--uncertain {','.join(uncertain)}); sweep another parameter, or "
                         f"make another one uncertain")
    names = oscillator_from(args).sweepable_names  # with a --model law's own constants
    name, values, _ = parse_sweep(
        args.sweep, names=tuple(n for n in names if n not in (*uncertain, "x0", "v0")))
    refuse_given(args, [name], f"has no effect: --sweep sets {name}")
    if args.samples == 0:
        refuse_given(args, ["seed"], "has no effect with --samples 0 (no Monte Carlo samples "
                                     "are drawn)")
    if args.scheduler is not None:
        refuse_given(args, ["workers"], "has no effect with --scheduler (the control values "
                                        "run there as tasks)")
    if args.plot and len(values) > 2 and not (np.all(np.diff(values) > 0)
                                              or np.all(np.diff(values) < 0)):
        raise ValueError(f"--sweep {args.sweep!r}: the values are not in order, and --plot "
                         f"joins them in the order given; sort them")
    osc = oscillator_from(args)
    # the default --workers is 2: it shrinks to the values there are, to 1 with --scheduler
    workers = (args.workers if given(args, "workers") else
               1 if args.scheduler else min(args.workers, len(values)))
    keywords = dict(sigma=args.sigma, uncertain=args.uncertain,
                    distribution=args.distribution, samples=args.samples, seed=args.seed,
                    options=options_from(args), transient=args.transient,
                    record=args.record, extra_states=args.extra_states,
                    coexist=args.coexist, emr=args.emr, emr_order=args.emr_order,
                    workers=workers, scheduler=args.scheduler)
    names = {**FLAGS, "values": f"--sweep {args.sweep!r}"}
    try:
        check_diagram(osc, name, values, **keywords)  # before the lock and any work
        return _run(args, osc, name, values, keywords)
    except DiagramInputError as err:
        raise ValueError(err.message(names)) from None
    except WorkBudgetError as err:
        raise ValueError(err.message(FLAGS)) from None


def _run(args, osc, name, values, keywords) -> int:
    """The diagram of the checked inputs, written and summed up."""
    from opa.dynamics import stochastic_diagram
    from opa.engine import OutputLock

    start = time.perf_counter()
    log = None if args.quiet else (lambda line: print(f"opa-mc: {line}", file=sys.stderr))
    parts = f"{args.out}.parts" if args.out else None
    # the lock of OUT.parts, held from before the first value to the final write of OUT
    # and the removal of the parts: a second run to the same --out is refused at once
    with contextlib.ExitStack() as held:
        if parts is not None:
            held.enter_context(OutputLock(parts, "stochastic diagram", folder=True, log=log))
        ds = stochastic_diagram(osc, name, values, **keywords, parts=parts, log=log)
        elapsed = time.perf_counter() - start
        if args.out:
            from opa.engine import remove_store, write_netcdf

            write_netcdf(ds, args.out)
            if not args.keep_parts:  # each value was kept as it finished: a killed run resumes
                remove_store(parts)
    if args.plot:
        from opa.plots import plot_stochastic

        plot_stochastic(ds, args.plot)
    if not args.quiet:
        uncertain = (args.uncertain,) if isinstance(args.uncertain, str) else args.uncertain
        sigma = np.broadcast_to(args.sigma, len(uncertain))
        drawn = ("" if len(uncertain) == 1 else
                 f" (scrambled Sobol', SE from {ds.attrs['scramblings']} scramblings)")
        print(f"opa-mc stochastic: {len(values)} values of {name}, " + ", ".join(
            f"{p} = {osc.value(p):g} + {s:g} xi_{j + 1}" if len(uncertain) > 1 else
            f"{p} = {osc.value(p):g} + {s:g} xi" for j, (p, s) in
            enumerate(zip(uncertain, sigma))) + f", {args.samples} samples each{drawn}, "
            f"in {elapsed:.1f} s")
        if "boundaries" in ds.attrs:
            print(f"  {ds.attrs['boundaries']}")
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
        sampled = "boundaries" in ds.attrs  # several uncertain parameters: with the SE
        shares = [f"{k} {float(p):.3f}" + (f" ± {float(e):.3f}" if sampled else "")
                  for k, p, e in zip(ds.type.values, ds.probability[i].values,
                                     ds.mc_sem[i].values) if p > 0]
        how = ("continuation" if not int(ds.method[i]) else "sampled"
               if ds.attrs["samples"] else "interval middles, no samples")
        agree = {1: "", 0: "; MC DISAGREES", -1: ""}[int(ds.agree[i])]
        both = float(ds.coexist_probability[i]) if "coexist_probability" in ds else 0.0
        shown = float(ds.mc_coexist[i])
        if both > 0 or shown > 0:
            agree += (f"; type depends on the initial state: {both:.3f} of the law, "
                      f"{shown:.3f} of the samples checked")
        lines.append(f"{param} = {value:.6g}: {', '.join(shares)} ({how}{agree})")
    return lines


__all__ = ["cmd_stochastic", "register_stochastic", "summary"]
