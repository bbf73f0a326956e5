"""The trust map's records and datasets: one grid point's results (:class:`Point`), the
split scan of one swept value (:class:`HorizonSplits`, stored as arrays in the map's
parts), the distribution of impact counts, and the datasets of the map, built per point
(:func:`point_dataset`) and per swept value (:func:`value_dataset`) and joined by
:func:`combine` into ``validate.nc`` (docs/datasets.md). No computation: the map
(:mod:`compare._trustmap`) fills these."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import xarray as xr

from compare._config import CRITERIA, ValidateConfig
from mc import semicircle_cdf
from opa.engine import SPLIT_KINDS, STATUS_NAMES, Split, atomic_write, count_probabilities


@dataclass
class Point:
    """One (q, sigma) of the map: the MC reference, the OPA curves and their verdicts."""

    sigma: float
    samples: int
    mc: dict  # x_mean, x_var, x_sem, x_var_sem (over outputs), impacts (min, max), seconds
    opa_mean: np.ndarray  # (variant, N, output)
    opa_var: np.ndarray
    first_impact: np.ndarray  # (variant, N) in forcing periods
    errors: np.ndarray  # (variant, N, horizon, criterion, 3): abs, in SE, relative
    pre_impact: np.ndarray  # (variant, N) RMS error of the mean before OPA's first impact
    disagree: np.ndarray  # (variant, N, criterion) first time of disagreement [periods]
    agrees: np.ndarray  # (variant, N, horizon, criterion) bool
    seconds: float = 0.0
    elements: np.ndarray | None = None  # (variant,) elements at N = Nmax (0: failed)
    collocated: np.ndarray | None = None  # (variant,) of them computed by collocation
    failure: str = ""  # why a multi-element variant could not be run
    status: np.ndarray | None = None  # (variant, N) kernel status of the OPA run (-1: not run)
    reduction: np.ndarray | None = None  # (variant, N) Var(x) / Var(x - x_hat): pairing's gain
    # (variant, N, horizon, criterion): 1 agrees, 0 undecided, -1 disagrees
    verdict: np.ndarray | None = None
    evaluated: np.ndarray | None = None  # (horizon,) the horizons the point's runs reach


@dataclass
class HorizonSplits:
    """What the split scan at one swept value found up to one horizon."""

    horizon: float  # forcing periods
    splits: list[Split]  # sorted by value
    truncated: bool  # the split limit left changes unlocated
    slowest_speed: float  # the nominal system's slowest impact within the horizon (NaN: none)
    slowest_time: float  # its time, forcing periods
    count: int  # the nominal system's impacts up to the horizon
    complete_within: float = math.inf  # every split with |value - centre| below it is listed
    crossings_within: float = math.inf  # the same for the output crossings


_SPLIT_FIELDS = ("value", "tol", "kind", "time", "speed", "left", "right")


def splits_to_arrays(scans: list[HorizonSplits]) -> dict:
    every = [(h, sp) for h, scan in enumerate(scans) for sp in scan.splits]
    out = {"horizon": np.array([s.horizon for s in scans], float),
           "truncated": np.array([s.truncated for s in scans], np.int8),
           "slowest_speed": np.array([s.slowest_speed for s in scans], float),
           "slowest_time": np.array([s.slowest_time for s in scans], float),
           "count": np.array([s.count for s in scans], np.int64),
           "complete_within": np.array([s.complete_within for s in scans], float),
           "crossings_within": np.array([s.crossings_within for s in scans], float),
           "split_horizon": np.array([h for h, _ in every], np.int64)}
    for name in _SPLIT_FIELDS:
        dtype = str if name == "kind" else (np.int64 if name in ("left", "right") else float)
        out[f"split_{name}"] = np.array([getattr(sp, name) for _, sp in every], dtype=dtype)
    return out


def splits_from_arrays(stored: dict) -> list[HorizonSplits]:
    scans = []
    for h in range(len(stored["horizon"])):
        idx = np.flatnonzero(stored["split_horizon"] == h)
        splits = [Split(**{name: stored[f"split_{name}"][i].item() for name in _SPLIT_FIELDS})
                  for i in idx]
        scans.append(HorizonSplits(float(stored["horizon"][h]), splits,
                                   bool(stored["truncated"][h]),
                                   float(stored["slowest_speed"][h]),
                                   float(stored["slowest_time"][h]), int(stored["count"][h]),
                                   float(stored["complete_within"][h]),
                                   float(stored["crossings_within"][h])))
    return scans


def count_distribution(centre, sigma, splits, count_at_centre, cdf=None,
                       complete_within=math.inf) -> dict[int, float]:
    """P(impacts up to the horizon = k) for the ensemble ``centre + sigma xi``, exact
    between the located changes of the count (``splits`` sorted by value, each with the
    counts on its two sides); ``cdf`` is that of the law of xi on [-1, 1] (default the
    semicircle). Only the samples with ``|value - centre| < complete_within`` (where the
    split list is complete) are counted: the probabilities then sum to less than 1
    (:func:`opa._splits.count_probabilities`)."""
    cdf = semicircle_cdf if cdf is None else cdf
    return count_probabilities(splits, centre, sigma, count_at_centre, cdf, complete_within)[0]


# --------------------------------------------------------------------------- the dataset

ONE = {"units": "1"}
#: the verdict of a horizon a point's runs do not reach
NOT_FORMED = -2
VERDICT_FLAGS = {"flag_values": np.array([NOT_FORMED, -1, 0, 1], np.int8),
                 "flag_meanings": "not_formed disagrees undecided agrees"}
#: the flag attributes of opa_status: the kernel's status codes and names, and -1 for a
#: variant not run at that N
STATUS_FLAGS = {"flag_values": np.arange(-1, len(STATUS_NAMES), dtype=np.int8),
                "flag_meanings": " ".join(("not_run",) + STATUS_NAMES)}
#: padding of the dimensions whose length differs between swept values or points
PADDING = {"probe_sigma": np.nan, "probe_agrees": -1, "probe_verdict": NOT_FORMED,
           "split_value": np.nan, "split_kind": -1, "split_time": np.nan,
           "split_speed": np.nan, "split_left": -1, "split_right": -1, "count_prob": 0.0}
# concatenation and merging spelled out: xarray's defaults are changing
_JOIN = dict(data_vars="all", coords="minimal", compat="override", join="outer",
             combine_attrs="override")


def _coords(cfg: ValidateConfig, *names: str, **sizes: int) -> dict:
    """The coordinates ``names`` of the map (docs/datasets.md), and index coordinates of
    the given ``sizes``."""
    n_out = int(round(max(cfg.horizons) * cfg.per_period)) + 1
    known = {
        "variant": (np.array(cfg.variants, dtype=object),
                    {"long_name": "OPA variant: impact law/truncation, or impact "
                     "law/ME-<elements> for multi-element OPA"}),
        "N": (np.array(cfg.orders), {"long_name": "order of the OPA expansion", **ONE}),
        "horizon": (np.array(cfg.horizons, float), {"long_name": "length of the comparison "
                                                    "window", "units": "forcing periods"}),
        "criterion": (np.array(CRITERIA, dtype=object),
                      {"long_name": "quantity compared with Monte Carlo"}),
        "time": (np.arange(n_out) / cfg.per_period,
                 {"long_name": "time in forcing periods t omega / (2 pi) (the forcing "
                  "period differs along the sweep)", "units": "forcing periods"}),
    }
    index = {"count": "number of impacts up to the horizon",
             "probe": "index of an evaluated sigma (ascending; NaN-padded)",
             "split": "index of a located split (kind -1: padding)"}
    out = {name: (name, *known[name]) for name in names}
    out.update({name: (name, np.arange(size), {"long_name": index[name], **ONE})
                for name, size in sizes.items()})
    return out


def _dims(dims) -> tuple[str, ...]:
    return (dims,) if isinstance(dims, str) else tuple(dims)


def _grid_coords(cfg: ValidateConfig, value: float, sigma: float | None = None) -> dict:
    """The grid coordinates of one swept value (and one sigma), each of length 1."""
    unc = cfg.uncertain
    out = {"value": ("value", [float(value)], {"long_name": f"swept parameter "
                                                f"{cfg.parameter}", **ONE})}
    if sigma is not None:
        out["sigma"] = ("sigma", [float(sigma)],
                        {"long_name": f"intensity of the uncertainty: {unc} = nominal {unc} + "
                         "sigma xi", **ONE})
    return out


def point_dataset(cfg: ValidateConfig, value: float, point: Point, centre: float,
                  scans: list[HorizonSplits], cdf=None) -> xr.Dataset:
    """One grid point (value, sigma) of the map, over ``value`` and ``sigma`` of length 1:
    OPA's errors against Monte Carlo and its verdicts per variant, N, horizon and
    criterion, the OPA and Monte Carlo curves, the costs, the elements of the
    multi-element variants, and the distribution of impact counts over the point's
    ensemble (from the splits ``scans`` of its swept value about ``centre``; ``cdf``: the
    law of xi's, None for the semicircle). Attribute ``element_failure``: why a
    multi-element variant was not run ("" when all were)."""
    H = len(cfg.horizons)
    counts = [count_distribution(centre, point.sigma, scan.splits, scan.count, cdf,
                                 scan.complete_within) for scan in scans]
    count_prob = np.zeros((H, max(max(d, default=0) for d in counts) + 1))
    unknown = np.zeros(H)
    for h, (scan, dist) in enumerate(zip(scans, counts)):
        for n, prob in dist.items():
            count_prob[h, n] = prob
        if scan.complete_within < point.sigma:
            unknown[h] = 1.0 - sum(dist.values())
    e = point.errors
    vn = ("variant", "N")
    vnh = vn + ("horizon",)
    data = {
        "err_mean": (vnh, e[..., 0, 0], {"long_name": "RMS error of x_0 against E[x] (paired "
                                         "estimate)", **ONE}),
        "err_mean_se": (vnh, e[..., 0, 1], {"long_name": "RMS error of x_0 in RMS standard "
                                            "errors of its paired estimate", **ONE}),
        "err_mean_rel": (vnh, e[..., 0, 2], {"long_name": "RMS error of x_0 relative to the "
                                             "RMS MC spread", **ONE}),
        "err_var": (vnh, e[..., 1, 0], {"long_name": "RMS error of the OPA variance against "
                                        "the MC variance", **ONE}),
        "err_var_se": (vnh, e[..., 1, 1], {"long_name": "RMS variance error in RMS standard "
                                           "errors of its paired estimate", **ONE}),
        "err_var_rel": (vnh, e[..., 1, 2], {"long_name": "RMS variance error relative to the "
                                            "RMS MC variance", **ONE}),
        "agrees": (vnh + ("criterion",), point.agrees.astype(np.int8),
                   {"long_name": "1 where OPA is certified to agree with MC over the horizon",
                    **ONE}),
        "verdict": (vnh + ("criterion",), point.verdict.astype(np.int8),
                    {"long_name": "three-valued verdict over the horizon, wrong with "
                     "probability <= alpha", **VERDICT_FLAGS, **ONE}),
        "disagree_time": (vn + ("criterion",), point.disagree,
                          {"long_name": "first time the estimated running RMS error exceeds "
                           "the tolerance (inf: never within the longest horizon)",
                           "units": "forcing periods"}),
        "pre_impact_err": (vn, point.pre_impact, {"long_name": "RMS error of x_0 before OPA's "
                                                  "first impact", **ONE}),
        "first_impact": (vn, point.first_impact, {"long_name": "time of OPA's first impact",
                                                  "units": "forcing periods"}),
        "opa_x_mean": (vn + ("time",), point.opa_mean, {"long_name": "OPA mean x_0", **ONE}),
        "opa_status": (vn, point.status.astype(np.int8),
                       {"long_name": "how the OPA run ended: -1 not run, 0 finished, > 0 "
                        "the kernel's reason to stop, named by flag_meanings (the curves are "
                        "NaN after it)", **STATUS_FLAGS}),
        "opa_x_var": (vn + ("time",), point.opa_var, {"long_name": "OPA variance", **ONE}),
        "mc_x_mean": ("time", point.mc["x_mean"], {"long_name": "MC mean E[x] (control "
                                                   "variate: mc_control)", **ONE}),
        "mc_x_var": ("time", point.mc["x_var"], {"long_name": "MC variance Var[x] (control "
                                                 "variate: mc_control)", **ONE}),
        "mc_x_sem": ("time", point.mc["x_sem"], {"long_name": "MC standard error of E[x]",
                                                 **ONE}),
        "mc_x_var_sem": ("time", point.mc["x_var_sem"],
                         {"long_name": "MC standard error of Var[x]", **ONE}),
        "mc_control": ((), np.int64(-1 if point.mc.get("control") is None
                                    else point.mc["control"][0]),
                       {"long_name": "variant (at N = Nmax) whose control-variate estimate "
                        "is mc_x_mean and mc_x_var; -1: the plain ensemble", **ONE}),
        "pair_reduction": (vn, np.full(point.opa_mean.shape[:2], np.nan)
                           if point.reduction is None else point.reduction,
                           {"long_name": "Var(x) / Var(x - x_hat) over the point's ensemble: "
                            "how much pairing with the run narrows its error bar", **ONE}),
        "mc_samples": ((), np.int64(point.samples), {"long_name": "MC samples of the last "
                                                     "round (true systems paired with "
                                                     "every OPA run)", **ONE}),
        "mc_impacts_min": ((), np.int64(point.mc["impacts"][0]),
                           {"long_name": "fewest impacts of an MC sample (longest horizon)",
                            **ONE}),
        "mc_impacts_max": ((), np.int64(point.mc["impacts"][1]),
                           {"long_name": "most impacts of an MC sample (longest horizon)",
                            **ONE}),
        "mc_seconds": ((), float(point.mc["seconds"]), {"long_name": "MC wall time",
                                                        "units": "s"}),
        "mc_rhs_evaluations": ((), np.int64(point.mc["rhs"]),
                               {"long_name": "MC right-hand sides", **ONE}),
        "point_seconds": ((), float(point.seconds),
                          {"long_name": "wall time of the point (OPA + MC)", "units": "s"}),
        "count_prob": (("horizon", "count"), count_prob,
                       {"long_name": "probability of k impacts up to the horizon (exact "
                        "where the split list is complete)", **ONE}),
        "count_unknown": ("horizon", unknown,
                          {"long_name": "probability of the samples beyond "
                           "split_complete_sigma, whose count is not known (0: complete)",
                           **ONE}),
        "variant_elements": ("variant", np.asarray(point.elements, np.int64),
                             {"long_name": "elements of the variant at N = Nmax (0: not "
                              "computed, see the attribute element_failures)", **ONE}),
        "variant_collocated": ("variant", np.asarray(point.collocated, np.int64),
                               {"long_name": "elements whose OPA system could not be "
                                "completed, computed by collocation of the true systems "
                                "(as simulate_opa does)", **ONE}),
    }
    coords = {**_grid_coords(cfg, value, point.sigma),
              **_coords(cfg, "variant", "N", "horizon", "criterion", "time",
                        count=count_prob.shape[1])}
    ds = xr.Dataset({name: (("value", "sigma", *_dims(dims)), np.asarray(array)[None, None],
                            attrs) for name, (dims, array, attrs) in data.items()},
                    coords=coords)
    return ds.assign_attrs(element_failure=point.failure)


def value_dataset(cfg: ValidateConfig, value: float, centre: float,
                  scans: list[HorizonSplits], star: np.ndarray, steps: np.ndarray,
                  probes: dict[float, np.ndarray]) -> xr.Dataset:
    """One swept value of the map, over ``value`` of length 1: sigma* by bisection
    (``star``: (variant, horizon, criterion, 2) bracket, ``steps``), every sigma evaluated
    (``probes``: sigma -> its verdicts (variant, horizon, criterion) at N = Nmax, -1 where
    not formed), and the splits of the sampled systems' event sequences per horizon
    (``scans``, about ``centre``)."""
    T = cfg.oscillator_at(value).forcing_period
    H = len(cfg.horizons)
    nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
    width = max(1, max(len(scan.splits) for scan in scans))
    sv, stime, sspeed = nan(H, width), nan(H, width), nan(H, width)
    skind = np.full((H, width), -1, np.int8)
    sleft, sright = (np.full((H, width), -1, np.int64) for _ in range(2))
    truncated = np.array([scan.truncated for scan in scans], np.int8)
    complete = np.array([scan.complete_within for scan in scans], float)
    crossing_complete = np.array([scan.crossings_within for scan in scans], float)
    slow_speed = np.array([scan.slowest_speed for scan in scans], float)
    slow_time = np.array([scan.slowest_time for scan in scans], float)
    sigma_split, nearest = nan(H), np.full(H, -1, np.int8)
    for h, scan in enumerate(scans):
        real = [sp for sp in scan.splits if sp.kind not in ("horizon", "output crossing")]
        if real:
            near = min(real, key=lambda sp: abs(sp.value - centre))
            sigma_split[h] = abs(near.value - centre)
            nearest[h] = SPLIT_KINDS.index(near.kind)
        for j, sp in enumerate(scan.splits):
            sv[h, j], stime[h, j], sspeed[h, j] = sp.value, sp.time / T, sp.speed
            skind[h, j] = SPLIT_KINDS.index(sp.kind)
            sleft[h, j], sright[h, j] = sp.left, sp.right
    ordered = sorted(probes.items())
    probe_sigma = np.array([sig for sig, _ in ordered], float)
    probe_verdict = np.array([verdicts for _, verdicts in ordered], np.int8)
    probe_agrees = np.where(probe_verdict == NOT_FORMED, -1, probe_verdict == 1).astype(np.int8)
    kinds = {"flag_values": np.arange(len(SPLIT_KINDS), dtype=np.int8),
             "flag_meanings": " ".join(k.replace(" ", "_") for k in SPLIT_KINDS),
             "units": "1"}
    vhc = ("variant", "horizon", "criterion")
    hs = ("horizon", "split")
    data = {
        "sigma_star": (vhc, star[..., 0],
                       {"long_name": "largest sigma at which OPA (N = Nmax) agrees: lower end "
                        "of the bisection bracket", **ONE}),
        "sigma_star_upper": (vhc, star[..., 1],
                             {"long_name": "upper end of the bisection bracket (NaN: agrees at "
                              "every sigma tried)", **ONE}),
        "bisection_steps": (vhc, steps, {"long_name": "bisection evaluations", **ONE}),
        "probe_sigma": ("probe", probe_sigma,
                        {"long_name": "every sigma evaluated (grid and bisection)", **ONE}),
        "probe_agrees": (("probe", *vhc), probe_agrees,
                         {"long_name": "1 where OPA (N = Nmax) is certified to agree at each "
                          "evaluated sigma (-1: not formed)", **ONE}),
        "probe_verdict": (("probe", *vhc), probe_verdict,
                          {"long_name": "three-valued verdict at N = Nmax at each evaluated "
                           "sigma", **VERDICT_FLAGS, **ONE}),
        "split_value": (hs, sv, {"long_name": f"value of {cfg.uncertain} where the sampled "
                                 "systems' event sequence changes", **ONE}),
        "split_kind": (hs, skind, {"long_name": "what happens at the split (-1: none)",
                                   **kinds}),
        "split_time": (hs, stime, {"long_name": "time of the first differing event (output "
                                   "crossing: the output time)", "units": "forcing periods"}),
        "split_speed": (hs, sspeed, {"long_name": "speed of the first differing event "
                                     "(output crossing: of the impact)", **ONE}),
        "split_left": (hs, sleft, {"long_name": "impacts up to the horizon just below the "
                                   "split", **ONE}),
        "split_right": (hs, sright, {"long_name": "impacts up to the horizon just above the "
                                     "split", **ONE}),
        "split_truncated": ("horizon", truncated,
                            {"long_name": "1 where the split limit left changes unlocated "
                             "(the list is complete within split_complete_sigma)", **ONE}),
        "split_complete_sigma": ("horizon", complete,
                                 {"long_name": "every split with |value - nominal| below "
                                  "this is listed (inf: the whole scan)", **ONE}),
        "crossing_complete_sigma": ("horizon", crossing_complete,
                                    {"long_name": "every output crossing with |value - "
                                     "nominal| below this is listed (inf: the whole scan)",
                                     **ONE}),
        "nominal_slowest_speed": ("horizon", slow_speed,
                                  {"long_name": "slowest impact of the nominal system within "
                                   "the horizon: its speed (NaN: no impact)", **ONE}),
        "nominal_slowest_time": ("horizon", slow_time,
                                 {"long_name": "time of that impact",
                                  "units": "forcing periods"}),
        "sigma_split": ("horizon", sigma_split,
                        {"long_name": "smallest sigma whose ensemble contains a split "
                         "(NaN: none within the largest sigma)", **ONE}),
        "sigma_split_kind": ("horizon", nearest, {"long_name": "kind of that nearest split",
                                                  **kinds}),
    }
    coords = {**_grid_coords(cfg, value),
              **_coords(cfg, "variant", "horizon", "criterion", probe=len(ordered),
                        split=width)}
    return xr.Dataset({name: (("value", *_dims(dims)), np.asarray(array)[None], attrs)
                       for name, (dims, array, attrs) in data.items()}, coords=coords)


def combine(cfg: ValidateConfig, points: list[list[xr.Dataset]],
            values: list[xr.Dataset]) -> xr.Dataset:
    """The map: the grid points (``points[q][s]``, :func:`point_dataset`) and the swept
    values (:func:`value_dataset`) joined over ``value`` and ``sigma``, the dimensions
    whose length differs padded (``PADDING``), with the map-wide ``variant_ran`` and the
    attribute ``element_failures`` (the grid points' failures; bisection probes say so in
    the log): :func:`combine_slices` of each value's :func:`value_slice`."""
    slices = [value_slice(cfg, v, row, by_value)
              for v, row, by_value in zip(cfg.values, points, values)]
    return combine_slices(cfg, slices)


def value_slice(cfg: ValidateConfig, value: float, points: list[xr.Dataset],
                by_value: xr.Dataset) -> xr.Dataset:
    """One swept value's part of the map (``value`` of length 1): its grid points
    (``points[s]``) joined over ``sigma`` and merged with its :func:`value_dataset`; its
    points' failures in the attribute ``slice_failures`` (:func:`combine_slices` joins
    the slices, which a map may keep on disk until then)."""
    grid = xr.combine_nested([points], concat_dim=["value", "sigma"], fill_value=PADDING,
                             **_JOIN)
    one = xr.concat([by_value], "value", fill_value=PADDING, **_JOIN)
    merged = xr.merge([grid, one], compat="no_conflicts", join="outer",
                      combine_attrs="override")
    failures = [f"{cfg.parameter} = {value:g}, sigma = {sigma:g}: "
                f"{point.attrs['element_failure']}"
                for sigma, point in zip(cfg.sigmas, points) if point.attrs["element_failure"]]
    return merged.assign_attrs(slice_failures=" | ".join(failures))


#: the dimension of the map's bulk: the variables along the output times (the OPA and
#: Monte Carlo moments, 0.29 of the 0.30 MB per grid point of the default map) wait on
#: disk from their value's end to validate.nc (:func:`spill`), never whole in memory
STREAMED_DIM = "time"


class SpilledArray:
    """An array kept in a ``.npy`` file, read whole when indexed (dask's chunk of it)."""

    def __init__(self, path: str, shape: tuple, dtype):
        self.path, self.shape, self.dtype = path, tuple(shape), np.dtype(dtype)
        self.ndim = len(self.shape)

    def __getitem__(self, key):
        return np.load(self.path)[key]


def spill(ds: xr.Dataset, folder: str, name: str) -> xr.Dataset:
    """``ds`` with its variables along ``STREAMED_DIM`` written to ``folder`` (one
    ``.npy`` file each, ``<name>_<variable>.npy``, for the caller to remove once the
    dataset is written) and read back lazily from there (dask, one chunk each): the same
    values, dtypes and attributes, without their bytes."""
    import dask.array

    os.makedirs(folder, exist_ok=True)
    lazy = {}
    for var, v in ds.data_vars.items():
        if STREAMED_DIM not in v.dims:
            continue
        path = os.path.join(folder, f"{name}_{var}.npy")
        data = np.asarray(v.values)
        atomic_write(path, lambda tmp, data=data: np.save(tmp, data), suffix=".npy",
                     clean=False)
        lazy[var] = v.copy(data=dask.array.from_array(
            SpilledArray(path, data.shape, data.dtype), chunks=data.shape,
            name=f"spilled-{path}", meta=np.empty((0,) * data.ndim, data.dtype)))
    return ds.assign(lazy)


def combine_slices(cfg: ValidateConfig, slices: list[xr.Dataset]) -> xr.Dataset:
    """The map from its values' :func:`value_slice` (in ``cfg.values`` order): joined over
    ``value``, the dimensions whose length differs padded (``PADDING``), with the
    map-wide ``variant_ran`` and the attribute ``element_failures``. Slices whose bulk is
    on disk (:func:`spill`) give a map whose bulk is read as it is written."""
    failures = [one.attrs["slice_failures"] for one in slices
                if one.attrs.get("slice_failures")]
    grid = xr.concat(slices, "value", fill_value=PADDING, **_JOIN)
    V, N, S = len(cfg.variants), len(cfg.orders), len(cfg.single_variants)
    ran = np.zeros((V, N), np.int8)
    ran[:S] = 1
    ran[S:, -1] = 1
    wide = xr.Dataset({"variant_ran": (("variant", "N"), ran,
                                       {"long_name": "1 where the variant is run at this N "
                                        "(multi-element variants: N = Nmax only)", **ONE})},
                      coords=_coords(cfg, "variant", "N"))
    merged = xr.merge([grid, wide], compat="no_conflicts", join="outer",
                      combine_attrs="override")
    # the grid's coordinates first, then the rest in the order they come (docs/datasets.md)
    first = ["value", "sigma"]
    ds = xr.Dataset({name: merged[name].variable for name in merged.data_vars},
                    coords={name: merged[name].variable
                            for name in first + [c for c in merged.coords if c not in first]})
    return ds.assign_attrs(element_failures=" | ".join(failures)) if failures else ds
