"""``opa-mc validate``: does OPA agree with Monte Carlo here, and to what N?

For each sigma: one Monte Carlo ensemble of the true sampled impact system (the
reference), then the OPA equivalent system for N = 0..Nmax with both impact laws
(``mean``, eq. (28); ``ensemble``) and, for the mean law, both truncations (``galerkin``,
``paper``). Errors are measured against the MC mean with its standard error. Two
side studies put cost beside accuracy: MC/QMC error against the number of samples M,
and Gauss collocation against its number of nodes Q.

Long parts (one MC ensemble per sigma) are written to ``OUTDIR/parts/`` as they finish
and reused by a rerun with the same configuration, so an interrupted validation resumes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
import tomllib
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from compare._metrics import compare_runs, error_metrics
from mc._ensemble import simulate_mc
from opa._dataset import provenance_attrs, time_coord, write_netcdf
from opa._model import IMPACT_LAWS, Oscillator, SolverOptions, preset
from opa._simulate import simulate_opa


@dataclass(frozen=True)
class ValidateConfig:
    """What ``opa-mc validate`` runs; the defaults are the embedded default job.

    Section 3.2 parameters at omega = 3.98, sigma in {0.005, 0.01, 0.02}, N = 0..8,
    2^14 scrambled Sobol samples, 100 forcing periods with 4 outputs per period, errors
    summarised over the first ``window`` periods and over the whole run.
    """

    oscillator: Oscillator = field(default_factory=lambda: preset("3.2", omega=3.98))
    options: SolverOptions = field(default_factory=lambda: SolverOptions(rtol=1e-9, atol=1e-9))
    sigmas: tuple[float, ...] = (0.005, 0.01, 0.02)
    orders: tuple[int, ...] = tuple(range(9))
    uncertain: str = "mu"
    samples: int = 2**14
    sampler: str = "sobol"
    seed: int = 0
    periods: float = 100.0
    per_period: int = 4
    window: float = 10.0
    study_samples: tuple[int, ...] = (2**6, 2**8, 2**10, 2**12)
    study_nodes: tuple[int, ...] = (2, 4, 8, 16, 32, 64)
    outdir: str = "results"
    plots: bool = True
    scheduler: str | None = None

    def __post_init__(self):
        if not self.sigmas or any(not np.isfinite(s) or s < 0 for s in self.sigmas):
            raise ValueError(f"sigmas must be non-negative finite values, got {self.sigmas}")
        if not self.orders or any(int(n) != n or n < 0 for n in self.orders):
            raise ValueError(f"orders must be non-negative integers, got {self.orders}")
        if int(self.samples) != self.samples or self.samples < 2:
            raise ValueError(f"samples must be an integer >= 2, got {self.samples}")
        if not 0 < self.window:
            raise ValueError(f"window must be > 0 periods, got {self.window}")
        if self.per_period < 1:
            raise ValueError(f"per_period must be >= 1, got {self.per_period}")

    def key(self, sigma: float) -> str:
        """A hash of everything the MC ensemble at ``sigma`` depends on."""
        blob = json.dumps(
            [self.oscillator.as_dict(), dataclasses.asdict(self.options), sigma, self.uncertain,
             self.samples, self.sampler, self.seed, self.periods, self.per_period,
             max(self.orders)],
            sort_keys=True, default=str,
        )
        return hashlib.sha256(blob.encode()).hexdigest()[:12]


def load_config(path: str | None, **overrides) -> ValidateConfig:
    """A configuration from a TOML file (all keys optional) and keyword overrides.

    TOML layout::

        sigmas = [0.005, 0.01]
        orders = [0, 1, 2, 4, 8]
        samples = 4096
        [model]            # any Oscillator parameter, or preset = "3.2"
        omega = 4.2
        [solver]           # any SolverOptions field
        rtol = 1e-9
    """
    data: dict = {}
    if path is not None:
        try:
            with open(path, "rb") as fh:
                data = tomllib.load(fh)
        except FileNotFoundError:
            raise ValueError(f"config file not found: {path}") from None
        except tomllib.TOMLDecodeError as err:
            raise ValueError(f"config file {path} is not valid TOML: {err}") from None
    model = dict(data.pop("model", {}))
    solver = dict(data.pop("solver", {}))
    model.update(overrides.pop("model", {}) or {})
    solver.update(overrides.pop("solver", {}) or {})
    name = model.pop("preset", "3.2")
    if "omega" not in model and name == "3.2":
        model["omega"] = 3.98
    known = {f.name for f in dataclasses.fields(ValidateConfig)} - {"oscillator", "options"}
    unknown = set(data) - known
    if unknown:
        raise ValueError(f"unknown config key(s) {sorted(unknown)}; known: {sorted(known)}")
    data.update({k: v for k, v in overrides.items() if v is not None})
    for key in ("sigmas", "orders", "study_samples", "study_nodes"):
        if key in data:
            data[key] = tuple(data[key])
    base = SolverOptions(rtol=1e-9, atol=1e-9)
    try:
        options = dataclasses.replace(base, **solver)
        osc = preset(name, **model)
    except TypeError as err:
        raise ValueError(f"unknown model or solver key: {err}") from None
    return ValidateConfig(oscillator=osc, options=options, **data)


def _mc_part(cfg: ValidateConfig, sigma: float, progress: bool) -> tuple[xr.Dataset, float]:
    parts = os.path.join(cfg.outdir, "parts")
    path = os.path.join(parts, f"mc_sigma{sigma:g}_{cfg.key(sigma)}.nc")
    if os.path.exists(path):
        with xr.open_dataset(path) as ds:
            ds = ds.load()
        return ds, float(ds.attrs["wall_seconds"])
    start = time.perf_counter()
    ds = simulate_mc(
        cfg.oscillator, sigma=sigma, samples=cfg.samples, sampler=cfg.sampler, seed=cfg.seed,
        order=max(cfg.orders), uncertain=cfg.uncertain, periods=cfg.periods,
        per_period=cfg.per_period, options=cfg.options, scheduler=cfg.scheduler,
        progress=progress,
    )
    ds.attrs["wall_seconds"] = time.perf_counter() - start
    write_netcdf(ds, path)
    return ds, float(ds.attrs["wall_seconds"])


STUDY_REPEATS = 4  # independent draws averaged at each M of the MC/QMC cost study
VARIANTS = (("mean", "galerkin"), ("ensemble", "galerkin"), ("mean", "paper"))
METRICS = ("rms_error", "max_error", "strobe_rms_error", "var_rms_error", "agree_periods")


def run_validation(cfg: ValidateConfig, *, progress: bool = True, log=print) -> xr.Dataset:
    """Run the whole validation and return its dataset (also written to OUTDIR)."""
    os.makedirs(cfg.outdir, exist_ok=True)
    osc, opts = cfg.oscillator, cfg.options
    orders = list(cfg.orders)
    variants = [f"{law}/{trunc}" for law, trunc in VARIANTS]
    S, V, N = len(cfg.sigmas), len(variants), len(orders)
    shape = (S, V, N)
    metric = {f"{m}_{w}": np.full(shape, np.nan) for m in METRICS
              for w in ("window", "full", "pre")}
    first_impact = np.full(shape, np.nan)
    opa_seconds = np.full(shape, np.nan)
    opa_rhs = np.zeros(shape, dtype=np.int64)
    mc_seconds = np.zeros(S)
    mc_rhs = np.zeros(S, dtype=np.int64)
    curves = {}
    for s, sigma in enumerate(cfg.sigmas):
        log(f"sigma = {sigma:g}: Monte Carlo reference, {cfg.samples} {cfg.sampler} samples, "
            f"{cfg.periods:g} periods ...")
        mc_ds, mc_seconds[s] = _mc_part(cfg, sigma, progress)
        mc_rhs[s] = int(mc_ds.attrs.get("rhs_evaluations", 0))
        curves[("mc", s)] = mc_ds
        for v, (law, trunc) in enumerate(VARIANTS):
            for k, order in enumerate(orders):
                start = time.perf_counter()
                opa_ds = simulate_opa(
                    osc, sigma=sigma, order=order, uncertain=cfg.uncertain, truncation=trunc,
                    impact_law=law, periods=cfg.periods, per_period=cfg.per_period, options=opts,
                    allow_negative=True,
                )
                opa_seconds[s, v, k] = time.perf_counter() - start
                opa_rhs[s, v, k] = opa_ds.attrs["rhs_evaluations"]
                cmp = compare_runs(opa_ds, mc_ds, floor=10 * opts.atol + 10 * opts.rtol)
                first = (float(opa_ds.impact_time[0]) if opa_ds.sizes["impact"]
                         else float(opa_ds.time[-1]) + 1.0)
                for w, window, until in (("window", cfg.window, None), ("full", None, None),
                                         ("pre", None, first)):
                    for m, value in error_metrics(cmp, window_periods=window,
                                                  until=until).items():
                        if m in METRICS:
                            metric[f"{m}_{w}"][s, v, k] = value
                first_impact[s, v, k] = first
                curves[(variants[v], s, order)] = opa_ds
    ds = _assemble(cfg, curves, metric, opa_seconds, opa_rhs, mc_seconds, mc_rhs, variants)
    ds["first_impact_time"] = (("sigma", "variant", "N"), first_impact,
                               {"long_name": "time of the OPA system's first impact",
                                "units": "1"})
    ds = xr.merge([ds, cost_studies(cfg, curves, progress=progress, log=log)],
                  combine_attrs="drop_conflicts")
    ds.attrs.update(_attrs(cfg))
    write_netcdf(ds, os.path.join(cfg.outdir, "validate.nc"))
    return ds


def _attrs(cfg: ValidateConfig) -> dict:
    attrs = provenance_attrs(
        "validate", cfg.oscillator, cfg.options, sigma=max(cfg.sigmas), order=max(cfg.orders),
        uncertain=cfg.uncertain, truncation="galerkin,paper", impact_law=",".join(IMPACT_LAWS),
        seed=cfg.seed, sampler=cfg.sampler,
    )
    attrs.update(samples=int(cfg.samples), periods=float(cfg.periods),
                 per_period=int(cfg.per_period), window_periods=float(cfg.window))
    return attrs


def _assemble(cfg, curves, metric, opa_seconds, opa_rhs, mc_seconds, mc_rhs, variants):
    mcs = [curves[("mc", s)] for s in range(len(cfg.sigmas))]
    times = mcs[0].time.values
    nmax = max(cfg.orders)
    opa_mean = np.stack([[[curves[(v, s, n)].x_mean.values for n in cfg.orders]
                          for v in variants] for s in range(len(cfg.sigmas))])
    opa_var = np.stack([[[curves[(v, s, n)].x_var.values for n in cfg.orders]
                         for v in variants] for s in range(len(cfg.sigmas))])
    opa_v = np.stack([[curves[(v, s, nmax)].v_mean.values for v in variants]
                      for s in range(len(cfg.sigmas))])
    dims3 = ("sigma", "variant", "N")
    data = {
        "opa_x_mean": (dims3 + ("time",), opa_mean, {"long_name": "OPA mean x_0", "units": "1"}),
        "opa_x_var": (dims3 + ("time",), opa_var, {"long_name": "OPA variance", "units": "1"}),
        "opa_v_mean": (("sigma", "variant", "time"), opa_v,
                       {"long_name": "OPA mean velocity at N = Nmax", "units": "1"}),
        "mc_x_mean": (("sigma", "time"), np.stack([m.x_mean.values for m in mcs]),
                      {"long_name": "MC mean E[x]", "units": "1"}),
        "mc_v_mean": (("sigma", "time"), np.stack([m.v_mean.values for m in mcs]),
                      {"long_name": "MC mean E[x']", "units": "1"}),
        "mc_x_sem": (("sigma", "time"), np.stack([m.x_sem.values for m in mcs]),
                     {"long_name": "MC standard error of E[x]", "units": "1"}),
        "mc_x_var": (("sigma", "time"), np.stack([m.x_var.values for m in mcs]),
                     {"long_name": "MC variance", "units": "1"}),
        "mc_seconds": ("sigma", mc_seconds, {"long_name": "MC wall time", "units": "s"}),
        "mc_rhs_evaluations": ("sigma", mc_rhs, {"long_name": "MC right-hand sides",
                                                 "units": "1"}),
        "opa_seconds": (dims3, opa_seconds, {"long_name": "OPA wall time", "units": "s"}),
        "opa_rhs_evaluations": (dims3, opa_rhs, {"long_name": "OPA right-hand sides",
                                                 "units": "1"}),
    }
    for name, values in metric.items():
        unit = "forcing periods" if name.startswith("agree") else "1"
        data[name] = (dims3, values, {"long_name": name.replace("_", " "), "units": unit})
    return xr.Dataset(
        data,
        coords={"sigma": ("sigma", np.array(cfg.sigmas, float)),
                "variant": ("variant", np.array(variants, dtype=object)),
                "N": ("N", np.array(cfg.orders)),
                **time_coord(times, cfg.oscillator.omega)},
    )


def cost_studies(cfg: ValidateConfig, curves, *, progress: bool, log=print) -> xr.Dataset:
    """Error against cost, over the first ``window`` periods at the middle sigma.

    The reference is the main MC run's mean (2^14 Sobol samples by default). Each study
    point reports the RMS error of its mean over the window (root mean square over
    ``STUDY_REPEATS`` independent draws for MC and QMC), its wall time and its
    right-hand-side evaluations: MC (random) and QMC (Sobol) against M, Gauss
    collocation against Q, and OPA (both laws) against N (from the main study).
    """
    s = len(cfg.sigmas) // 2
    sigma = cfg.sigmas[s]
    ref = curves[("mc", s)]
    T = 2 * np.pi / cfg.oscillator.omega
    t = ref.time.values
    n_win = int(np.searchsorted(t, cfg.window * T + 1e-9))
    ref_mean = ref.x_mean.values[:n_win]
    times = t[:n_win]
    log(f"cost studies at sigma = {sigma:g} over the first {cfg.window:g} periods ...")

    def run(sampler, m, seed):
        start = time.perf_counter()
        ds = simulate_mc(cfg.oscillator, sigma=sigma, samples=m, sampler=sampler, seed=seed,
                         order=0, uncertain=cfg.uncertain, times=times, options=cfg.options,
                         progress=False, allow_negative=True)
        seconds = time.perf_counter() - start
        err = float(np.sqrt(np.mean((ds.x_mean.values - ref_mean) ** 2)))
        return err, seconds, int(ds.attrs["rhs_evaluations"])

    samplers = ("random", "sobol")
    Ms = list(cfg.study_samples)
    mc_err = np.zeros((2, len(Ms)))
    mc_sec = np.zeros((2, len(Ms)))
    mc_rhs = np.zeros((2, len(Ms)), dtype=np.int64)
    for i, sampler in enumerate(samplers):
        for j, m in enumerate(Ms):
            # one draw's error is strongly correlated over time, so average over draws;
            # seeds unrelated to the reference's, so the reference is an independent draw
            draws = [run(sampler, m, cfg.seed + 1000 + 10 * j + r)
                     for r in range(STUDY_REPEATS)]
            mc_err[i, j] = np.sqrt(np.mean([d[0] ** 2 for d in draws]))
            mc_sec[i, j] = np.mean([d[1] for d in draws])
            mc_rhs[i, j] = int(np.mean([d[2] for d in draws]))
    Qs = list(cfg.study_nodes)
    col = np.array([run("gauss", q, None) for q in Qs])
    return xr.Dataset(
        {
            "study_mc_error": (("sampler", "M"), mc_err,
                               {"long_name": "RMS error of the mean over the window vs "
                                "the reference", "units": "1"}),
            "study_mc_seconds": (("sampler", "M"), mc_sec, {"long_name": "wall time",
                                                            "units": "s"}),
            "study_mc_rhs": (("sampler", "M"), mc_rhs, {"long_name": "right-hand sides",
                                                        "units": "1"}),
            "study_gauss_error": ("Q", col[:, 0], {"long_name": "collocation RMS error of "
                                  "the mean over the window", "units": "1"}),
            "study_gauss_seconds": ("Q", col[:, 1], {"long_name": "wall time", "units": "s"}),
            "study_gauss_rhs": ("Q", col[:, 2].astype(np.int64),
                                {"long_name": "right-hand sides", "units": "1"}),
            "study_reference_sem": ((), float(np.sqrt(np.mean(ref.x_sem.values[:n_win] ** 2))),
                                    {"long_name": "RMS standard error of the reference",
                                     "units": "1"}),
        },
        coords={"sampler": ("sampler", np.array(samplers, dtype=object)),
                "M": ("M", np.array(Ms)), "Q": ("Q", np.array(Qs))},
        attrs={"study_sigma": float(sigma)},
    )
