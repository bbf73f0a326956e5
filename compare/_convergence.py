"""Convergence of multi-element OPA against Monte Carlo, with its cost beside the peers.

One run (:func:`run_convergence`) computes, on one model and one sigma over a window of
forcing periods:

* a Monte Carlo reference (scrambled Sobol, ``reference`` samples, its own seed);
* multi-element OPA against the number of elements K at fixed N (equal-probability
  elements, and the adaptive edges at the splits with refinement, for a budget of
  elements), and against N at fixed K, for the ``mean`` and ``saltation`` impact laws;
* the non-intrusive twin, multi-element Gauss collocation (Q nodes per element, each a
  true impact system), on the same edges;
* single-element OPA for N = 0..8, single-element collocation, and plain Monte Carlo and
  scrambled Sobol at increasing M (seeds other than the reference's);
* control variates (:func:`compare.verify`): M true systems paired with the adaptive
  ME-OPA of ``order_budget`` elements (saltation law) as the control, at the same M;

each with its RMS error of the mean x_0 (and of the standard deviation) over the window,
its right-hand-side evaluations (for OPA also times the Q nodes each one evaluates) and
its wall time. Slopes are fitted to log error against log K. The errors are meaningful
down to the reference's own standard error, which is stored beside them.
"""

from __future__ import annotations

import math
import os
import re
import time
import warnings
from dataclasses import asdict, dataclass, field

import numpy as np
import xarray as xr

from mc import simulate_mc
from opa.engine import (
    collocation, ElementBudgetWarning, Oscillator, parse, preset, provenance_attrs,
    quadrature_order, simulate_opa, SimulationError, SolverOptions, System, time_grid,
    uniform_edges, write_netcdf,
)
from compare._verify import verify

STUDY_LAWS = ("mean", "saltation")
#: Sobol samples of the reference when a control-variate reference has no control
PLAIN_REFERENCE = 32768


@dataclass(frozen=True)
class ConvergenceConfig:
    """The section 3.2 set at omega = 3.98, sigma = 0.05, 10 periods, 2^16 Sobol samples."""

    oscillator: Oscillator = field(default_factory=lambda: preset("3.2"))
    options: SolverOptions = field(default_factory=lambda: SolverOptions(rtol=1e-9, atol=1e-9))
    sigma: float = 0.05
    uncertain: str = "mu"
    distribution: str = "semicircle"
    periods: float = 10.0
    per_period: int = 8
    order: int = 1
    orders: tuple[int, ...] = (0, 1, 2, 4, 8)
    uniform: tuple[int, ...] = (1, 2, 4, 8, 16, 32, 64, 128)
    budgets: tuple[int, ...] = (4, 8, 16, 24, 32, 48, 64, 96, 128, 192, 256)
    order_budget: int = 64
    nodes: int = 2
    single_nodes: tuple[int, ...] = (1, 2, 4, 8, 16)
    mc_samples: tuple[int, ...] = (256, 512, 1024, 2048, 4096, 8192, 16384, 32768)
    reference: int = 65536
    #: the reference: "sobol" (``reference`` scrambled Sobol samples) or "control" (the
    #: control-variate estimate of ``reference`` true systems paired with the adaptive
    #: ME-OPA of ``order_budget`` elements, saltation law: compare.verify, stratified)
    reference_method: str = "sobol"
    seed: int = 1
    outdir: str = "results-elements"
    allow_negative: bool = False
    impulse: str = "dirac"  # the impulse model: opa.System's fields of the same names
    pulse_width: float = 0.1
    impulse_at_zero: bool = True

    @property
    def system(self) -> System:
        """The :class:`opa.System` of the study (N = ``order``)."""
        return System(self.oscillator, sigma=self.sigma, uncertain=self.uncertain,
                      distribution=self.distribution, allow_negative=self.allow_negative,
                      order=self.order, impulse=self.impulse, pulse_width=self.pulse_width,
                      impulse_at_zero=self.impulse_at_zero)

    def __post_init__(self):
        if not (self.sigma > 0):
            raise ValueError(f"sigma must be > 0, got {self.sigma}")
        self.system  # noqa: B018 -- validates the system's fields
        for name in ("uniform", "budgets", "mc_samples", "orders", "single_nodes"):
            seq = getattr(self, name)
            if any(int(v) != v or v < 0 for v in seq):
                raise ValueError(f"{name} must be non-negative integers, got {seq}")
        if not self.budgets or not self.mc_samples:
            raise ValueError("budgets and mc_samples must not be empty")
        from opa.engine import MAX_ELEMENTS

        # the element rules of simulate_opa: counts 1..MAX_ELEMENTS, budgets 2..MAX_ELEMENTS
        for name, least, what in (("uniform", 1, "element counts of the uniform runs"),
                                  ("budgets", 2, "element budgets of the adaptive runs")):
            bad = [int(v) for v in getattr(self, name) if not least <= v <= MAX_ELEMENTS]
            if bad:
                raise ValueError(f"{name} ({what}) must be integers in {least}.."
                                 f"{MAX_ELEMENTS}, got {bad[0]}")
        if self.reference < 1024:
            raise ValueError(f"reference must be >= 1024 samples, got {self.reference}")
        if self.reference_method not in ("sobol", "control"):
            raise ValueError(f"reference_method must be 'sobol' or 'control', got "
                             f"{self.reference_method!r}")
        if self.reference_method == "control" and self.reference & (self.reference - 1):
            raise ValueError(f"a control-variate reference draws a power of two of true "
                             f"systems, got reference = {self.reference}")


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


#: what a row that is not computed yet reads as while the study finds its runs
PENDING = {"error": math.nan, "sd_error": math.nan, "rhs": 0, "elements": 0,
            "seconds": 0.0}


def run_convergence(cfg: ConvergenceConfig, *, log=print, write: bool = True,
                    memo=None, workers: int = 1, scheduler=None) -> xr.Dataset:
    """Run the study; returns its dataset (also written to OUTDIR/convergence.nc unless
    ``write`` is false).

    Every run of the study (the reference, each row) is one call
    ``memo(name, spec, compute)``: ``spec`` is a JSON-able dict of everything the run
    depends on, ``compute()`` does the run and returns a dict of arrays, numbers and
    strings, and ``memo`` returns that dict or the one an identical earlier call returned
    (the trust map keeps them in its parts, :class:`opa._dataset.Store`). Without
    ``memo`` every run is done. The dataset's ``wall_seconds`` is the sum of the runs' wall
    times (for reused runs, the time they took when they were done).

    With ``workers`` > 1 or a Dask ``scheduler`` (and no ``memo``), the runs are tasks
    (:func:`compare._scaleout.run_tasks`): after the reference, the study is walked
    without computing to find the runs it needs, those run side by side, and so on until
    every run is known (the adaptive collocation rows need the adaptive runs' edges);
    then the study is assembled from them. The rows are the same as in one process.
    """
    if (workers > 1 or scheduler is not None) and memo is None:
        return _run_parallel(cfg, log=log, write=write, workers=workers,
                             scheduler=scheduler)
    return _study(cfg, log=log, write=write, memo=memo)


def _run_parallel(cfg, *, log, write, workers, scheduler) -> xr.Dataset:
    import cloudpickle

    from compare._scaleout import run_tasks

    known: dict = {}

    def dry(name, spec, compute):
        if name in known:
            return known[name]
        if name == "reference":  # every row's error depends on it: computed here, first
            known[name] = compute()
            return known[name]
        pending.append((name, compute))
        return PENDING

    while True:
        pending: list = []
        _study(cfg, log=lambda *a: None, write=False, memo=dry)
        if not pending:
            break
        log(f"{len(pending)} runs of the study as tasks ...")
        tasks = [(name, _call, (cloudpickle.dumps(compute),)) for name, compute in pending]
        for name, result in run_tasks(tasks, workers=workers, scheduler=scheduler):
            known[name] = result
    return _study(cfg, log=log, write=write, memo=lambda name, spec, compute: known[name])


def _call(blob: bytes):
    """A run of the study sent to a worker (cloudpickle carries its closure)."""
    import cloudpickle

    return cloudpickle.loads(blob)()


def _study(cfg: ConvergenceConfig, *, log, write: bool, memo) -> xr.Dataset:
    """The study itself (:func:`run_convergence`)."""
    osc, opts = cfg.oscillator, cfg.options
    measure = parse(cfg.distribution)
    base = cfg.system.replace(distribution=measure)
    times = time_grid(osc.omega, cfg.periods, cfg.per_period)
    common = dict(times=times, options=opts)
    # what every run depends on; the errors also depend on the reference (samples, seed)
    settings = {"oscillator": osc.as_dict(), "options": asdict(opts), "sigma": cfg.sigma,
                "uncertain": cfg.uncertain, "distribution": cfg.distribution,
                "periods": cfg.periods, "per_period": cfg.per_period,
                "allow_negative": cfg.allow_negative, "reference": cfg.reference,
                "seed": cfg.seed}
    if cfg.reference_method == "control":
        # "certificate": the version of compare.verify's design (2: stratified at the
        # splits), so that parts kept from the earlier design are not read back
        settings["reference_control"] = {"budget": int(cfg.order_budget),
                                         "order": int(cfg.order), "certificate": 2}
    if (cfg.impulse, cfg.pulse_width, cfg.impulse_at_zero) != ("dirac", 0.1, True):
        settings["impulse"] = [cfg.impulse, cfg.pulse_width, cfg.impulse_at_zero]

    def run(name, spec, compute):
        spec = {**settings, "run": name, **spec}
        return compute() if memo is None else memo(name, spec, compute)

    controls = []  # the control run, computed once when a row needs it

    def control_run():
        if not controls:
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ElementBudgetWarning)
                controls.append(simulate_opa(
                    base.replace(order=cfg.order, impact_law="saltation"),
                    elements="adaptive", tolerance=1e-14, max_elements=cfg.order_budget,
                    **common))
            controls.append(time.perf_counter() - t)
        return controls

    def reference():
        t0 = time.perf_counter()
        if cfg.reference_method == "control":
            try:
                control, control_seconds = control_run()
                t0 -= control_seconds
                cv = verify(control, samples=cfg.reference, max_samples=cfg.reference,
                            sequential=False, seed=cfg.seed)
            except (SimulationError, ValueError) as err:  # no control: plain Sobol
                log(f"  the control run cannot serve ({err}): the reference is "
                    f"{PLAIN_REFERENCE} Sobol samples")
                return plain(PLAIN_REFERENCE, t0)
            return {"x_mean": cv.cv_x_mean.values, "x_var": cv.cv_x_var.values,
                    "x_sem": cv.cv_x_mean_sem.values,
                    "rhs": int(control.attrs["rhs_evaluations"])
                    + int(cv.attrs["verify_rhs_evaluations"]),
                    "seconds": time.perf_counter() - t0,
                    "text": reference_text(cfg.reference, "control", cfg.order_budget)}
        return plain(cfg.reference, t0)

    def plain(samples, t0):
        ref = simulate_mc(base.replace(order=0), samples=samples, sampler="sobol",
                          seed=cfg.seed, progress=False, **common)
        return {"x_mean": ref.x_mean.values, "x_var": ref.x_var.values,
                "x_sem": ref.x_sem.values, "rhs": int(ref.attrs["rhs_evaluations"]),
                "seconds": time.perf_counter() - t0,
                "text": reference_text(samples, "sobol", cfg.order_budget),
                "samples": int(samples)}

    log(f"reference: {reference_text(cfg.reference, cfg.reference_method, cfg.order_budget)}"
        f" ...")
    ref = run("reference", {}, reference)
    m_ref, sd_ref = ref["x_mean"], np.sqrt(ref["x_var"])
    floor = _rms(ref["x_sem"])
    seconds = [ref["seconds"]]

    def errors(mean, var):
        return _rms(mean - m_ref), _rms(np.sqrt(np.maximum(var, 0.0)) - sd_ref)

    rows = []  # (method, law, size_name, size, N, err, sd_err, rhs, node_rhs, seconds)

    def opa_row(method, law, size, order, **kw):
        def compute():
            t = time.perf_counter()
            try:
                with warnings.catch_warnings():  # the budget is the study's variable
                    warnings.simplefilter("ignore", ElementBudgetWarning)
                    ds = simulate_opa(base.replace(order=order, impact_law=law), **common,
                                      **kw)
            except SimulationError as err:  # a diverged OPA system: no error to report
                return {"failure": str(err), "seconds": time.perf_counter() - t}
            sec = time.perf_counter() - t
            e, s = errors(ds.x_mean.values, ds.x_var.values)
            out = {"error": e, "sd_error": s, "rhs": int(ds.attrs["rhs_evaluations"]),
                   "elements": int(ds.attrs["elements"]), "seconds": sec}
            if "element_edges" in ds:
                out["edges"] = ds.element_edges.values
            return out

        name = f"{method}-{law}-N{order}-K{kw.get('max_elements', kw.get('elements'))}"
        result = run(_slug(name), {"method": method, "law": law, "order": order, **kw},
                     compute)
        seconds.append(result["seconds"])
        if "failure" in result:
            log(f"  {method} ({law}), N = {order}, {kw}: {result['failure']}")
            failures.append(f"{method} ({law} law), N = {order}, "
                            f"{kw.get('max_elements', kw.get('elements'))}: "
                            f"{result['failure']}")
            return None
        rhs = result["rhs"]
        q = 1 if order == 0 else quadrature_order(order)
        rows.append((method, law, size if size is not None else result["elements"],
                     order, result["error"], result["sd_error"], rhs, rhs * q,
                     result["seconds"]))
        return result

    adaptive = {}  # budget -> the saltation law's adaptive edges
    failures: list[str] = []
    for law in STUDY_LAWS:
        log(f"multi-element OPA ({law} law) ...")
        for k in cfg.uniform:
            opa_row("ME-OPA uniform", law, k, cfg.order, elements=int(k))
        for b in cfg.budgets:
            result = opa_row("ME-OPA adaptive", law, None, cfg.order, elements="adaptive",
                             tolerance=1e-14, max_elements=int(b))
            if law == "saltation" and result is not None and "edges" in result:
                adaptive[int(b)] = result["edges"]
        for n in cfg.orders:
            opa_row("ME-OPA adaptive, N", law, None, n, elements="adaptive", tolerance=1e-14,
                    max_elements=cfg.order_budget)
            opa_row("OPA (one element), N", law, 1, n, elements=1)

    def collocation_row(method, edges, nodes):
        def compute():
            t = time.perf_counter()
            mean, var, rhs = collocation(base, opts, measure, edges, nodes, times=times)
            sec = time.perf_counter() - t
            e, s = errors(mean, var)
            return {"error": e, "sd_error": s, "rhs": int(rhs), "seconds": sec}

        result = run(_slug(f"{method}-K{len(edges) - 1}-Q{nodes}"),
                     {"method": method, "edges": np.asarray(edges, float).tolist(),
                      "nodes": int(nodes)}, compute)
        seconds.append(result["seconds"])
        rows.append((method, "true system", len(edges) - 1, int(nodes), result["error"],
                     result["sd_error"], result["rhs"], result["rhs"], result["seconds"]))

    log("collocation ...")
    for method, sizes in (("ME-collocation uniform", cfg.uniform),
                          ("ME-collocation adaptive", cfg.budgets)):
        for k in sizes:
            if method.endswith("uniform"):
                edges = uniform_edges(measure, int(k))
            elif int(k) in adaptive:  # the edges adaptive ME-OPA (saltation) chose
                edges = adaptive[int(k)]
            else:
                continue
            collocation_row(method, edges, cfg.nodes)
    for q in cfg.single_nodes:
        collocation_row("collocation (one element), Q", np.array([measure.lo, measure.hi]),
                        int(q))
    log("Monte Carlo and Sobol ladders ...")
    for sampler, name in (("random", "MC"), ("sobol", "QMC (Sobol)")):
        for m in cfg.mc_samples:
            def compute(sampler=sampler, m=m):
                t = time.perf_counter()
                ds = simulate_mc(base.replace(order=0), samples=int(m), sampler=sampler,
                                 seed=cfg.seed + 1, progress=False, **common)
                e, s = errors(ds.x_mean.values, ds.x_var.values)
                return {"error": e, "sd_error": s, "rhs": int(ds.attrs["rhs_evaluations"]),
                        "seconds": time.perf_counter() - t}

            result = run(_slug(f"{name}-M{int(m)}"),
                         {"sampler": sampler, "samples": int(m), "ladder_seed": cfg.seed + 1},
                         compute)
            seconds.append(result["seconds"])
            rows.append((name, "true system", int(m), 0, result["error"], result["sd_error"],
                         result["rhs"], result["rhs"], result["seconds"]))
    log("control variates on the adaptive ME-OPA (saltation law) ...")
    for m in cfg.mc_samples:
        if m < 8 or m & (m - 1):  # the certificate draws powers of two
            continue

        def compute(m=m):
            control, control_seconds = control_run()
            t = time.perf_counter() - control_seconds  # each row pays for its control
            cv = verify(control, samples=int(m), max_samples=int(m), sequential=False,
                        seed=cfg.seed + 1)
            e, s = errors(cv.cv_x_mean.values, cv.cv_x_var.values)
            # the true systems run: more than m where the certificate's first round grew
            # to give each of its strata a group (compare.verify)
            return {"error": e, "sd_error": s, "seconds": time.perf_counter() - t,
                    "rhs": int(control.attrs["rhs_evaluations"])
                    + int(cv.attrs["verify_rhs_evaluations"]),
                    "samples": int(cv.attrs["verify_samples"])}

        result = run(_slug(f"CV-K{cfg.order_budget}-M{int(m)}"),
                     {"method": "control variate", "samples": int(m),
                      "budget": int(cfg.order_budget), "order": int(cfg.order),
                      "ladder_seed": cfg.seed + 1, "certificate": 2}, compute)
        seconds.append(result["seconds"])
        rows.append((f"control variate (ME-OPA K={cfg.order_budget})", "true system",
                     int(result.get("samples", m)), 0, result["error"], result["sd_error"],
                     result["rhs"], result["rhs"], result["seconds"]))
    cols = list(zip(*rows))
    one = {"units": "1"}
    ds = xr.Dataset(
        {
            "method": ("run", np.array(cols[0], dtype=object),
                       {"long_name": "method of the run (ME-OPA uniform or adaptive, "
                        "collocation, MC, QMC (Sobol), control variate, ...)"}),
            "law": ("run", np.array(cols[1], dtype=object),
                    {"long_name": "impact law of the OPA system, or 'true system'"}),
            "size": ("run", np.array(cols[2], dtype=np.int64),
                     {"long_name": "elements (OPA, collocation) or samples (MC)", **one}),
            "order": ("run", np.array(cols[3], dtype=np.int64),
                      {"long_name": "N (OPA) or nodes per element (collocation)", **one}),
            "error": ("run", np.array(cols[4]), {"long_name": "RMS error of E[x] over the "
                                                 "window against the reference", **one}),
            "sd_error": ("run", np.array(cols[5]), {"long_name": "RMS error of the standard "
                                                    "deviation of x", **one}),
            "rhs_evaluations": ("run", np.array(cols[6], dtype=np.int64),
                                {"long_name": "right-hand-side evaluations", **one}),
            "node_rhs_evaluations": ("run", np.array(cols[7], dtype=np.int64),
                                     {"long_name": "right-hand sides times the nodes each "
                                      "evaluates (OPA: Q = 2N + 1)", **one}),
            "seconds": ("run", np.array(cols[8]), {"long_name": "wall time", "units": "s"}),
        },
        coords={"run": ("run", np.arange(len(rows)), {"long_name": "run index", **one})},
        attrs=provenance_attrs("convergence", base, opts, seed=cfg.seed, sampler="sobol"),
    )
    ds.attrs.update(
        periods=float(cfg.periods), per_period=int(cfg.per_period),
        distribution=measure.name,
        reference_samples=int(ref.get("samples", cfg.reference)),
        reference_method="sobol" if "samples" in ref else cfg.reference_method,
        reference_text=str(ref.get("text", reference_text(cfg.reference, cfg.reference_method,
                                                          cfg.order_budget))),
        reference_sem=floor, reference_seconds=ref["seconds"],
        reference_rhs_evaluations=int(ref["rhs"]),
        wall_seconds=float(sum(seconds)), failures=len(failures),
        failure_text=" | ".join(failures) if failures else "none",
    )
    if write:
        write_netcdf(ds, os.path.join(cfg.outdir, "convergence.nc"))
    return ds


def reference_text(samples: int, method: str, budget: int) -> str:
    """The reference in words."""
    if method == "control":
        return (f"the control-variate estimate from {samples} true systems on the adaptive "
                f"ME-OPA (K = {budget}, saltation law)")
    return f"{samples} Sobol samples"


def _slug(text: str) -> str:
    """A file-name-safe form of a run's name."""
    return re.sub(r"[^A-Za-z0-9.]+", "-", text).strip("-")


def _select(ds, method, law=None):
    sel = ds.method.values == method
    if law is not None:
        sel &= ds.law.values == law
    return np.flatnonzero(sel)


def slope(ds, method, law, lo=None) -> float:
    """Fitted slope of log error against log K (elements), over K >= lo."""
    idx = _select(ds, method, law)
    k = ds["size"].values[idx].astype(float)
    e = ds.error.values[idx]
    ok = (k >= (lo or 1)) & (e > 0)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(k[ok]), np.log(e[ok]), 1)[0])


def cheapest_reaching(ds, method, target, law=None):
    """The run of ``method`` with the fewest right-hand sides reaching ``target``."""
    idx = [i for i in _select(ds, method, law) if ds.error.values[i] <= target]
    return min(idx, key=lambda i: ds.rhs_evaluations.values[i]) if idx else None


def table(ds, *, markdown=True) -> str:
    head = ["method", "law", "K / M", "N / Q", "RMS error E[x]", "RMS error sd", "RHS",
            "node RHS", "wall [s]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i in range(ds.sizes["run"]):
        lines.append("| " + " | ".join([
            str(ds.method.values[i]), str(ds.law.values[i]), str(int(ds["size"].values[i])),
            str(int(ds.order.values[i])), f"{ds.error.values[i]:.2e}",
            f"{ds.sd_error.values[i]:.2e}", f"{int(ds.rhs_evaluations.values[i]):,}",
            f"{int(ds.node_rhs_evaluations.values[i]):,}", f"{ds.seconds.values[i]:.2f}",
        ]) + " |")
    return "\n".join(lines)


def summary_lines(ds) -> list[str]:
    out = []
    a = ds.attrs
    reference = a.get("reference_text", f"{a['reference_samples']} Sobol samples")
    out.append(f"Reference: {reference}, RMS standard error "
               f"{a['reference_sem']:.1e} (errors near it are not resolved). An adaptive "
               f"run's wall time includes its split search unless one of the last 8 "
               f"searches was of the same problem with the same split budget.")
    if a.get("failures", 0):
        out.append(f"{a['failures']} OPA runs diverged and are left out: {a['failure_text']}")
    for law in STUDY_LAWS:
        for method in ("ME-OPA uniform", "ME-OPA adaptive"):
            idx = _select(ds, method, law)
            if len(idx) >= 2:
                e = ds.error.values[idx]
                k = ds["size"].values[idx]
                out.append(f"{method}, {law} law, N = {int(ds.order.values[idx[0]])}: error "
                           f"{e[0]:.1e} (K = {k[0]}) → {e[-1]:.1e} (K = {k[-1]}); fitted slope "
                           f"{slope(ds, method, law, lo=2):.2f} in K for K ≥ 2.")
    for target in (1e-3, 1e-4):
        me = cheapest_reaching(ds, "ME-OPA adaptive", target, "saltation")
        qmc = cheapest_reaching(ds, "QMC (Sobol)", target)
        if me is None:
            out.append(f"Adaptive ME-OPA (saltation) does not reach {target:g} within the "
                       f"budgets tried.")
            continue
        text = (f"To reach {target:g}: adaptive ME-OPA (saltation law) with K = "
                f"{int(ds['size'].values[me])} elements, {int(ds.rhs_evaluations.values[me]):,}"
                f" right-hand sides ({int(ds.node_rhs_evaluations.values[me]):,} node "
                f"evaluations), {ds.seconds.values[me]:.2f} s")
        if qmc is not None:
            r = ds.rhs_evaluations.values[qmc] / ds.rhs_evaluations.values[me]
            rn = ds.rhs_evaluations.values[qmc] / ds.node_rhs_evaluations.values[me]
            text += (f"; Sobol with M = {int(ds['size'].values[qmc])}: "
                     f"{int(ds.rhs_evaluations.values[qmc]):,} right-hand sides, "
                     f"{ds.seconds.values[qmc]:.2f} s — {r:.0f}× more right-hand sides "
                     f"({rn:.0f}× more node evaluations).")
        else:
            text += "; no Sobol run of the ladder reaches it."
        out.append(text)
    return out


def write_report(ds, outdir, *, draw, command="opa-mc converge") -> list[str]:
    """convergence.md and convergence.png in ``outdir``; ``draw(ds, path)`` draws the
    figure (``compare._report.plot_frontier``, the trust map's frontier figure: the study
    is the same)."""
    os.makedirs(outdir, exist_ok=True)
    png = draw(ds, os.path.join(outdir, "convergence.png"))
    md = os.path.join(outdir, "convergence.md")
    with open(md, "w") as fh:
        fh.write(f"# Multi-element OPA against Monte Carlo\n\nCommand: `{command}` "
                 f"({ds.attrs['wall_seconds']:.0f} s)\n\n")
        fh.write("\n".join(f"- {line}" for line in summary_lines(ds)) + "\n\n")
        fh.write(table(ds) + "\n\n![convergence](convergence.png)\n")
    return [md, png]


__all__ = ["PENDING", "ConvergenceConfig", "cheapest_reaching", "run_convergence", "slope",
           "summary_lines", "table", "write_report"]
