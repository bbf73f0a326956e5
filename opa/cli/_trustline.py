"""``opa-mc validate --uncertain mu,c --relative R1,R2``: the trust line of several
uncertain parameters (``compare.trust_line``), its table and files; with ``--values`` or
``--sweep``, several ``--horizons`` or ``--resolution``, the trust map of several
parameters (``compare.trust_map_several``): a trust line per value and horizon, s*
bisected."""

from __future__ import annotations

import os
import shlex
import sys

from opa import SolverOptions, System
from opa.cli._flags import CliError, oscillator_from, scales

#: the grid of scales when --sigmas is not given
DEFAULT_SCALES = (0.25, 0.5, 1.0, 2.0)
#: validate's flags that have no meaning on the trust line, and why
NOT_HERE = {
    "config": ("--config", "the trust line takes its settings from the flags"),
    "long_splits": ("--long-splits", "the split scans are one-dimensional"),
    "elements": ("--elements", "adaptive boxes are always one of its variants"),
    "scheduler": ("--scheduler", "the trust line runs in this process"),
    "workers": ("--workers", "the trust line runs in this process"),
}


def relative_sizes(text: str):
    """``--relative``: the comma-separated sizes r_j."""
    return scales(text)


def cmd_trust_line(args) -> int:
    """The trust line of the parsed ``validate`` flags (several uncertain parameters)."""
    from compare import trust_line
    from opa.engine import OutputLock, write_netcdf

    from opa.cli._paths import check_output_dir

    system, relative, grid = _inputs(args)
    if _is_map(args):
        return _cmd_map(args, system, relative, grid)
    outdir = args.outdir or "results"
    check_output_dir("--outdir", outdir)
    os.makedirs(outdir, exist_ok=True)
    log = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    horizon = max(args.horizons) if args.horizons else 10.0
    with OutputLock(outdir, "output folder", folder=True):
        ds = trust_line(system, relative, grid, periods=horizon,
                        per_period=args.per_period or 8, samples=args.samples or 256,
                        max_samples=args.max_samples or 4096, seed=args.seed or 0,
                        max_elements=args.max_elements or 64, options=_options(args),
                        log=log)
        path = os.path.join(outdir, "validate.nc")
        write_netcdf(ds, path)
        lines = table(ds)
        command = "opa-mc " + shlex.join(getattr(args, "argv", ["validate"]))
        with open(os.path.join(outdir, "summary.md"), "w", encoding="utf-8") as fh:
            fh.write(f"# Trust line\n\n`{command}`\n\n" + "\n".join(lines) + "\n")
    if not args.quiet:
        print("\n".join(lines))
        print(f"wrote {path} and {os.path.join(outdir, 'summary.md')}")
    return 0


def _is_map(args) -> bool:
    """Whether the flags ask for the map (values, horizons, bisection), not one line."""
    return bool(args.sweep or args.values or args.resolution is not None
                or (args.horizons and len(args.horizons) > 1))


def map_parameter(args) -> tuple[str, tuple | None]:
    """The swept parameter and its values: --sweep's, or --values of the preset's
    parameter (3.1: c, else omega); none: the model's own value."""
    from compare import load_config

    if args.sweep:
        return args.sweep
    preset = getattr(args, "preset", None) or "3.2"
    return load_config(None, preset=preset).parameter, args.values


def _cmd_map(args, system, relative, grid) -> int:
    """The trust map of several parameters: its tables, validate.nc and summary.md."""
    from compare import check_map_several, trust_map_several
    from opa.engine import OutputLock, write_netcdf

    from opa.cli._paths import check_output_dir

    parameter, values = map_parameter(args)
    outdir = args.outdir or "results"
    check_output_dir("--outdir", outdir)
    log = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    try:
        kw = dict(parameter=parameter, values=values, horizons=args.horizons or (10.0,),
                  resolution=args.resolution, per_period=args.per_period or 8,
                  samples=args.samples or 256, max_samples=args.max_samples or 4096,
                  seed=args.seed or 0, max_elements=args.max_elements or 64,
                  options=_options(args), log=log)
        check_map_several(system, relative, grid, parameter, values, kw["horizons"],
                          args.resolution)
    except ValueError as err:
        raise CliError(str(err).replace("resolution", "--resolution", 1)) from None
    os.makedirs(outdir, exist_ok=True)
    with OutputLock(outdir, "output folder", folder=True):
        ds = trust_map_several(system, relative, grid, **kw)
        path = os.path.join(outdir, "validate.nc")
        write_netcdf(ds, path)
        lines = map_table(ds)
        command = "opa-mc " + shlex.join(getattr(args, "argv", ["validate"]))
        with open(os.path.join(outdir, "summary.md"), "w", encoding="utf-8") as fh:
            fh.write(f"# Trust map of several parameters\n\n`{command}`\n\n"
                     + "\n".join(lines) + "\n")
    if not args.quiet:
        print("\n".join(lines))
        print(f"wrote {path} and {os.path.join(outdir, 'summary.md')}")
    return 0


def map_table(ds) -> list[str]:
    """The map as markdown: per horizon a row per (value, variant), a column per scale
    and s*; then the bisected intervals of s* at the longest horizon."""
    parameter = ds.attrs["parameter"]
    names = {0: "agrees", 1: "disagrees", 2: "undecided", 3: "failed"}
    sizes = ", ".join(f"{r:g}" for r in ds.attrs["relative"])
    out = [f"Uncertain {ds.attrs['uncertain']} with sigma_j = s x ({sizes})_j x |p_bar_j|; "
           f"each cell: the certificate's verdict (the RMS error of E[x] it estimates)"]
    head = [parameter, "variant", *(f"s = {s:g}" for s in ds.scale.values), "s*"]
    for h, horizon in enumerate(ds.horizon.values):
        out += ["", f"Over {horizon:g} periods:", "",
                "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for q, value in enumerate(ds[parameter].values):
            for i, variant in enumerate(ds.variant.values):
                cells = [f"{names[int(v)]} ({e:.2g})" if e == e else names[int(v)]
                         for v, e in zip(ds.verdict.values[q, h, i],
                                         ds.err_mean_rms.values[q, h, i])]
                out.append("| " + " | ".join([f"{value:g}", str(variant), *cells,
                                              f"{float(ds.scale_star.values[q, h, i]):g}"])
                           + " |")
    if ds.attrs["resolution"] > 0:
        out += ["", f"s* bisected to {ds.attrs['resolution']:g} over "
                    f"{ds.horizon.values[-1]:g} periods (certified to agree at the lower end, "
                    f"not at the upper; inf: every scale of the grid agrees):", ""]
        for q, value in enumerate(ds[parameter].values):
            for i, variant in enumerate(ds.variant.values):
                lo, hi = ds.scale_star_lower.values[q, i], ds.scale_star_upper.values[q, i]
                out.append(f"* {parameter} = {value:g}, {variant}: s* in [{lo:.4g}, {hi:.4g}) "
                           f"({int(ds.bisection_steps.values[q, i])} midpoints)")
    return out


def _inputs(args):
    """(system at scale 1's law, relative sizes, scales), every flag checked first."""
    for name, (flag, why) in NOT_HERE.items():
        if getattr(args, name, None) not in (None, False):
            raise CliError(f"{flag} does not apply with several uncertain parameters: {why}")
    if args.relative is None:
        raise CliError("--relative R1,R2,... is needed with several uncertain parameters: "
                       "each one's spread relative to its nominal value at scale 1 "
                       "(sigma_j = scale x R_j x |p_bar_j|)")
    relative = args.relative if isinstance(args.relative, tuple) else (args.relative,)
    grid = tuple(args.sigmas) if args.sigmas else DEFAULT_SCALES
    order = max(args.orders) if args.orders else 3
    try:
        system = System(oscillator_from(args), uncertain=args.uncertain,
                        distribution=args.distribution, order=order,
                        sigma=tuple(0.0 for _ in args.uncertain))
        from compare import trust_scaled

        for scale in grid:
            trust_scaled(system, relative, scale).check_samples()
    except ValueError as err:
        text = str(err)
        for name, flag in (("relative", "--relative"), ("each scale", "--sigmas")):
            text = text.replace(name, flag, 1) if text.startswith(name) else text
        raise CliError(text) from None
    return system, relative, grid


def _options(args) -> SolverOptions:
    solver = {k: getattr(args, k) for k in ("rtol", "atol", "max_step", "chatter_velocity",
                                            "method") if getattr(args, k, None) is not None}
    return SolverOptions(**solver)


def table(ds) -> list[str]:
    """The trust line as a markdown table: a row per variant, a column per scale, and
    s*."""
    names = {0: "agrees", 1: "disagrees", 2: "undecided", 3: "failed"}
    scales_ = [f"{s:g}" for s in ds.scale.values]
    head = ["variant", *(f"s = {s}" for s in scales_), "s*"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i, variant in enumerate(ds.variant.values):
        cells = [f"{names[int(v)]} ({e:.2g})" if e == e else names[int(v)]
                 for v, e in zip(ds.verdict.values[i], ds.err_mean_rms.values[i])]
        rows.append("| " + " | ".join([str(variant), *cells,
                                       f"{float(ds.scale_star.values[i]):g}"]) + " |")
    sizes = ", ".join(f"{r:g}" for r in ds.attrs["relative"])
    return [f"Uncertain {ds.attrs['uncertain']} with sigma_j = s x ({sizes})_j x |p_bar_j|; "
            f"each cell: the certificate's verdict (the RMS error of E[x] it estimates)", "",
            *rows]


__all__ = ["DEFAULT_SCALES", "NOT_HERE", "cmd_trust_line", "map_parameter", "map_table",
           "relative_sizes", "table"]
