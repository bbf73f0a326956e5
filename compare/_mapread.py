"""What the report reads off a trust map, and how it says numbers.

The entry checks (:data:`MAP_NEEDS`, :func:`check_map`: a dataset that is not a trust map,
or lacks what an entry point reads, is refused by name), the map's coordinates and names
(the swept values, the horizons, the variants compared across impact laws), the splits
nearest to the nominal value, sigma* as read from its bisection bracket, and the frontier
part of the map. The text (:mod:`compare._findings`), the tables (:mod:`compare._tables`)
and the figures (:mod:`compare._mapfigures`) all read the map through these.
"""

from __future__ import annotations

import numpy as np

from compare._inputs import (
    check_dataset, check_finite, check_standard_error, require_attributes, require_time,
    require_variables,
)

# Variant shown where one must be picked: the paper's OPA (mean impact law) with the
# exact Galerkin truncation.
HEADLINE = 0
# The impact laws drawn and summarised side by side (by name: under a law of xi other than
# the semicircle the paper-truncation variants are left out, and multi-element variants
# named "<law>/ME-<K8|adaptive64>" follow the single-element ones).
DRAWN_VARIANTS = ("mean/galerkin", "ensemble/galerkin", "saltation/galerkin")
# Kinds of the split arrays that do not change the impact sequence.
NOT_SPLITS = ("horizon", "output crossing")


# -- what each entry point reads off the map (issue 45) -------------------------------------
# A map that lacks it (an older or partial validate.nc, or another kind of dataset) is
# refused by name, never with a KeyError. Read only when present, so not listed: the
# variables of newer maps that older ones lack (verdict, variant_ran, opa_status,
# count_unknown, variant_collocated, nominal_slowest_*, crossing_complete_sigma, the
# frontier); `time` may be called `periods` (files written before issue 26).
_MAP = "the trust-map dataset"
#: coordinates and attributes every entry point reads (and the swept parameter's
#: coordinate, named by the attribute `parameter`; the nominal value, by `uncertain`)
_MAP_COORDS = ("sigma", "variant", "N", "horizon", "criterion")
_MAP_ATTRS = ("parameter", "uncertain")
_STARS = ("sigma_star", "sigma_star_upper")
_SPLITS = ("split_value", "split_kind", "split_time", "split_speed", "split_left",
           "split_right", ("split_complete_sigma", "split_truncated"))
_CAUSE = _STARS + _SPLITS + ("agrees", "disagree_time")
_FAILURES = ("err_mean", "opa_x_mean")
#: entry point -> (variables, attributes, reads the time coordinate)
MAP_NEEDS = {
    "run_failures": (_FAILURES, ("per_period",), True),
    "cause": (_CAUSE, ("resolution", "per_period"), False),
    "first_screen": (_CAUSE + _FAILURES, ("tolerance", "var_tolerance", "resolution",
                                          "per_period"), True),
    "boundary_table": (_STARS + _SPLITS, ("resolution",), False),
    "verdict_grid": (("agrees",), (), False),
    "count_table": (("count_prob",) + _SPLITS[-1:], (), False),
    "findings": (_STARS + _SPLITS + ("err_mean", "agrees", "pre_impact_err", "first_impact",
                                     "mc_x_sem", "emr0_dmr_difference",
                                     "emr0_n0_dmr_difference"),
                 ("resolution", "var_tolerance"), True),
    "plot_map": (_STARS + ("agrees", "err_mean_rel", "err_var_rel", "probe_sigma",
                           "split_kind", "split_value"), ("tolerance", "var_tolerance"), False),
    "plot_error_vs_order": (("agrees", "err_mean", "first_impact", "pre_impact_err",
                             "mc_x_sem", "mc_x_var"),
                            ("per_period", "rtol", "atol", "tolerance"), True),
    "plot_mean": (("agrees", "mc_x_mean", "mc_x_sem", "opa_x_mean"), ("per_period",), True),
    "plot_variance": (("agrees", "mc_x_var", "mc_x_var_sem", "opa_x_var"), ("per_period",),
                      True),
    "plot_phase": (("law", "phase_time", "phase_opa_x", "phase_opa_v", "phase_mc_x",
                    "phase_mc_v", "phase_sample_x", "phase_sample_v"),
                   ("delta", "phase_value", "phase_sigma"), False),
}


def _union(*entries: str) -> tuple:
    """The needs of several entry points together."""
    variables, attributes = [], []
    for entry in entries:
        v, a, _ = MAP_NEEDS[entry]
        variables += [x for x in v if x not in variables]
        attributes += [x for x in a if x not in attributes]
    return tuple(variables), tuple(attributes), any(MAP_NEEDS[e][2] for e in entries)


MAP_NEEDS["figures"] = _union("plot_map", "plot_error_vs_order", "plot_mean",
                              "plot_variance", "plot_phase")
MAP_NEEDS["write_report"] = _union("first_screen", "boundary_table", "verdict_grid",
                                   "count_table", "findings")
MAP_NEEDS["write_report"] = (MAP_NEEDS["write_report"][0], MAP_NEEDS["write_report"][1] + (
    "wall_seconds", "mc_runs_computed", "opa_runs_computed", "parts_computed", "preset",
    "impulse", "rtol", "atol", "samples", "max_samples", "seed", "criterion_text", "alpha"),
    True)


def check_map(ds, entry: str) -> None:
    """Refuse, with one ValueError naming the culprit, a dataset that is not a trust map
    (``opa-mc validate``'s validate.nc, docs/datasets.md) or lacks what ``entry`` (a key
    of :data:`MAP_NEEDS`) reads, or whose Monte Carlo estimates or standard errors are not
    finite, or whose standard errors are negative, or whose OPA curves are not finite
    where ``opa_status`` says the run finished (after a stop they are NaN, as
    documented)."""
    check_dataset(ds, _MAP, "a trust map (opa-mc validate's validate.nc)")
    model = ds.attrs.get("model", "validate")
    if model != "validate":
        raise ValueError(f"{_MAP} must be a trust map (opa-mc validate's validate.nc, "
                         f"attribute model = 'validate'), got model = {model!r}")
    variables, attributes, time = MAP_NEEDS[entry]
    require_attributes(ds, _MAP, _MAP_ATTRS + attributes)
    if "force_law" not in ds.attrs:  # a user's law holds its constants in force_constants
        require_attributes(ds, _MAP, (str(ds.attrs["uncertain"]),),
                           hint=" (the nominal value of the uncertain parameter)")
    require_variables(ds, _MAP, _MAP_COORDS + (str(ds.attrs["parameter"]),) + variables)
    if time:
        require_time(ds, _MAP, old_name=True)
    if "split_kind" in variables and "flag_meanings" not in ds.split_kind.attrs:
        raise ValueError(f"{_MAP}'s split_kind lacks its attribute flag_meanings")
    for name in ("mc_x_mean", "mc_x_var"):
        if name in variables:
            check_finite(ds, _MAP, name)
    for name in ("mc_x_sem", "mc_x_var_sem"):
        if name in variables:
            check_standard_error(ds, _MAP, name)
    for name in ("opa_x_mean", "opa_x_var"):
        if name in variables and "opa_status" in ds:
            finished = ds.opa_status == 0
            stopped = ~finished.broadcast_like(ds[name]).transpose(*ds[name].dims).values
            check_finite(ds, _MAP, name, allowed=stopped,
                         where=" where opa_status says the run finished")


# -- the map's names, and its numbers in words ----------------------------------------------
def _kinds(ds) -> list[str]:
    return [k.replace("_", " ") for k in ds.split_kind.attrs["flag_meanings"].split()]


def _g(x: float, digits: int = 4) -> str:
    return f"{x:.{digits}g}"


def _e(x: float) -> str:
    if not np.isfinite(x):
        return "∞" if x > 0 else "–"
    return f"{x:.1e}"


def star_text(lo: float, hi: float, smax: float) -> str:
    """sigma* as read from its bisection bracket."""
    if not np.isfinite(hi):
        return f"≥ {_g(smax)}"
    if lo == 0:
        return f"< {_g(hi, 3)}"
    return f"{_g(lo, 3)}–{_g(hi, 3)}"


def star_phrase(lo: float, hi: float, smax: float) -> str:
    """'σ* = a–b', 'σ* < b' or 'σ* ≥ a' from the bisection bracket."""
    text = star_text(lo, hi, smax)
    return f"σ* {text}" if text[0] in "<≥" else f"σ* = {text}"


def _laws(ds) -> list[int]:
    """Indices of the variants compared across impact laws (those in the dataset)."""
    names = [str(v) for v in ds.variant.values]
    return [names.index(n) for n in DRAWN_VARIANTS if n in names]


def _element_variants(ds) -> list[int]:
    """Indices of the multi-element variants (run at N = Nmax only)."""
    return [v for v, name in enumerate(ds.variant.values) if "/ME-" in str(name)]


def _single_of(ds, v: int) -> int | None:
    """The single-element Galerkin variant of the same impact law as variant v."""
    names = [str(n) for n in ds.variant.values]
    name = names[v].split("/")[0] + "/galerkin"
    return names.index(name) if name in names else None


def _time(ds):
    """Output times in forcing periods: the coordinate ``time`` (``periods`` in files
    written before issue 26, still read)."""
    return ds["time"] if "time" in ds.dims else ds["periods"]


def _vals(ds):
    """The swept parameter's coordinate (named after the parameter, docs/datasets.md)."""
    return ds[ds.attrs["parameter"]]


def _par(ds) -> str:
    return {"omega": "ω", "mu": "μ"}.get(ds.attrs["parameter"], ds.attrs["parameter"])


def _unc(ds) -> str:
    return {"mu": "μ"}.get(ds.attrs["uncertain"], ds.attrs["uncertain"])


def nominal(ds) -> float:
    """The uncertain parameter's nominal value: its attribute, or a constant of the run's
    own force law (``force_constants``)."""
    name = str(ds.attrs["uncertain"])
    if name not in ds.attrs and "force_law" in ds.attrs:
        from opa.engine import Oscillator

        return Oscillator.constants_from_attrs(ds.attrs)[name]
    return float(ds.attrs[name])


# -- the boundary and what sits there ------------------------------------------------------
def _nearest(ds, q: int, h: int, wanted):
    kinds = _kinds(ds)
    vals = ds.split_value.values[q, h]
    kind = ds.split_kind.values[q, h]
    ok = np.array([k >= 0 and wanted(kinds[k]) for k in kind], dtype=bool)
    if not ok.any():
        return None
    centre = nominal(ds)
    j = np.flatnonzero(ok)[np.argmin(np.abs(vals[ok] - centre))]
    return dict(value=float(vals[j]), distance=abs(float(vals[j]) - centre),
                kind=kinds[int(kind[j])], time=float(ds.split_time.values[q, h, j]),
                speed=float(ds.split_speed.values[q, h, j]),
                left=int(ds.split_left.values[q, h, j]),
                right=int(ds.split_right.values[q, h, j]))


def nearest_split(ds, q: int, h: int):
    """The split (not a horizon crossing, not an output crossing) nearest to the nominal
    value, as a dict, or None."""
    return _nearest(ds, q, h, lambda kind: kind not in NOT_SPLITS)


def nearest_horizon(ds, q: int, h: int):
    """The 'horizon' split nearest to the nominal value (an impact that crosses the end of
    the horizon: it changes the impact count up to H but no output within H), or None."""
    return _nearest(ds, q, h, lambda kind: kind == "horizon")


def complete_within(ds, q: int, h: int) -> float:
    """The distance from the nominal value within which the split list is complete (inf:
    the whole scan; datasets written before the limit was reported: inf where the list
    was not cut, 0 where it was)."""
    if "split_complete_sigma" in ds:
        return float(ds.split_complete_sigma.values[q, h])
    return 0.0 if int(ds.split_truncated.values[q, h]) else float("inf")


def _star(ds, q, v, h, c) -> str:
    return star_text(float(ds.sigma_star.values[q, v, h, c]),
                     float(ds.sigma_star_upper.values[q, v, h, c]), float(ds.sigma.max()))

# -- the Monte Carlo noise and tolerance over a window of outputs ---------------------------
def _window_sem(ds, q, s, n):
    se = ds.mc_x_sem[q, s, :n].values
    return float(np.sqrt(np.mean(se**2)))


def _window_tolerance(ds, q, s, n):
    """The mean's tolerance over the first n outputs, as the RMS error of the window is
    held against it: tol x RMS spread + the solver floor (the verdict certifies the
    error below it, or above it, at error rate alpha)."""
    spread = np.sqrt(np.maximum(ds.mc_x_var[q, s, :n].values, 0.0))
    floor = 10 * (float(ds.attrs["rtol"]) + float(ds.attrs["atol"]))
    return float(float(ds.attrs["tolerance"]) * np.sqrt(np.mean(spread**2)) + floor)

# -- the frontier ---------------------------------------------------------------------------
def frontier_dataset(ds):
    """The frontier part of a trust-map dataset in the shape of an ``opa-mc converge``
    dataset (None if the map was run without it)."""
    names = [n for n in ds.data_vars if n.startswith("frontier_")]
    if not names:
        return None
    out = ds[names].rename({n: n[len("frontier_"):] for n in names}
                           | {"frontier_run": "run"})
    out.attrs = {k[len("frontier_"):]: v for k, v in ds.attrs.items()
                 if k.startswith("frontier_")}
    if "omega" in ds.attrs:  # files written before frontier_omega
        out.attrs.setdefault("omega", ds.attrs["omega"])
    return out


__all__ = ["DRAWN_VARIANTS", "HEADLINE", "MAP_NEEDS", "NOT_SPLITS", "check_map",
           "complete_within", "frontier_dataset", "nearest_horizon", "nearest_split",
           "nominal", "star_phrase", "star_text"]
