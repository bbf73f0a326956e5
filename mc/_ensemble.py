"""Monte Carlo ensembles of the true sampled impact system, with streamed statistics.

Each sample is the deterministic impact oscillator (eq. (1)) with its own value of the
uncertain parameter ``p = p_bar + sigma xi``: its own impacts, chatter and sticking,
integrated by the same compiled kernel as the DMR (``opa._kernel.run_batch``).

Samples are processed in fixed chunks. A chunk's paths live only while its statistics
are formed; chunk statistics (weight, mean, centred sum of squares, Chebyshev moments
with their centred sums of squares, and the sums over each randomised-QMC replicate)
are merged in chunk order with Chan's pairwise update. Memory is therefore
O(chunk * T + R * N * T), independent of the number of samples, and the result depends
only on the seed and the chunk size, never on the thread count or on where a chunk ran,
which is what makes the Dask backend return exactly the local result. To keep it so, no
statistic goes through BLAS: a BLAS product's summation order depends on its thread
count, while numpy's reduction of a fresh C-ordered array along axis 0 adds the rows one
after the other.

With ``checkpoint``, each finished chunk is written to a directory as it finishes
(``mc._checkpoint``); a rerun with the same inputs loads those chunks instead of
computing them again and returns the bit-identical result.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import xarray as xr

from mc._checkpoint import Checkpoint, stats_arrays
from mc._control import check_control, controlled
from mc._sampling import check_sampler, sample_xi
from opa.engine import (
    Execution, IMPULSE_FIELDS, as_system, chebyshev_u, check_instance, set_threads,
    take_execution, thread_count,
    check_memory, digest,
    orthonormal, require_gpu, add_true_system_work, true_system_work,
    Oscillator, output_times, package_version, provenance_attrs, run_batch, SimulationError,
    SolverOptions, System, time_coord,
)

#: the System fields a Monte Carlo ensemble takes (it has no closures: each sample is the
#: true impact system)
MC_FIELDS = ("sigma", "uncertain", "distribution", "allow_negative", "order",
             *IMPULSE_FIELDS)

#: how simulate_mc takes its System (as_system's keywords)
_MC_ENTRY = dict(allowed=MC_FIELDS, where="simulate_mc")

CHUNK_BYTES = 32 * 2**20
GPU_CHUNK, GPU_CHUNK_BYTES = 2**18, 2**30  # device="cuda": samples a launch, paths' bytes
# Memory a sample takes outside the paths: xi, its weight, replicate index and impact
# count and the sample coordinate (8 bytes each), the sampler's uniforms (up to 16 for a
# Sobol' set rounded up to a power of two) and the quantile function's temporaries.
SAMPLE_BYTES = 96

def _weighted_sum(w: np.ndarray, x: np.ndarray) -> np.ndarray:
    """sum_m w[m] x[m, :] for x of shape (M, T), in a fixed order of summation.

    ``w @ x`` would go through BLAS, whose result depends on its thread count in the last
    bits; numpy adds the rows of the fresh C-ordered product one after the other.
    """
    return (w[:, None] * x).sum(axis=0)


@dataclass
class ChunkStats:
    """Sufficient statistics of a set of samples at every output time (weights w_m)."""

    weight: float  # sum of weights
    count: int
    x_mean: np.ndarray  # (T,)
    x_m2: np.ndarray  # (T,) sum w (x - mean)^2
    v_mean: np.ndarray
    v_m2: np.ndarray
    x_moment: np.ndarray  # (N+1, T) sum w x U_i(xi)
    x_moment_m2: np.ndarray  # (N+1, T) sum w (x U_i - mean of x U_i)^2 (coefficients' SE)
    x_moment_rep: np.ndarray  # (R, N+1, T) sum w x U_i(xi) over each replicate
    x_rep: np.ndarray  # (R, T) sum w x over each randomised-QMC replicate
    v_rep: np.ndarray
    x2_rep: np.ndarray  # (R, T) sum w x^2 over each replicate (for the variance's SE)
    rep_weight: np.ndarray  # (R,) sum w over each replicate
    rhs_evaluations: int = 0

    @classmethod
    def of(cls, x: np.ndarray, v: np.ndarray, xi: np.ndarray, w: np.ndarray, order: int,
           rep: np.ndarray, replicates: int, recurrence=None):
        """Statistics of paths x, v of shape (M, T) for sample values xi, weights w and
        replicate indices ``rep`` (all 0 without replicates)."""
        W = float(w.sum())
        x_rep = np.zeros((replicates, x.shape[1]))
        v_rep = np.zeros((replicates, x.shape[1]))
        x2_rep = np.zeros((replicates, x.shape[1]))
        rep_weight = np.zeros(replicates)
        for r in np.unique(rep):
            sel = rep == r
            x_rep[r] = _weighted_sum(w[sel], x[sel])
            v_rep[r] = _weighted_sum(w[sel], v[sel])
            x2_rep[r] = _weighted_sum(w[sel], x[sel] ** 2)
            rep_weight[r] = w[sel].sum()
        xm = _weighted_sum(w, x) / W
        vm = _weighted_sum(w, v) / W
        # (N+1, M): Chebyshev U for the semicircle, else the law's orthonormal polynomials;
        # with several parameters (P, M), the product basis over the multi-index set
        if hasattr(recurrence, "evaluate"):
            basis = recurrence.evaluate(xi).T
        else:
            basis = chebyshev_u(order, xi) if recurrence is None else orthonormal(
                order, xi, *recurrence)
        moments = np.empty((len(basis), x.shape[1]))
        moments_m2 = np.empty_like(moments)
        for i, u in enumerate(basis):
            moments[i] = _weighted_sum(u * w, x)
            moments_m2[i] = _weighted_sum(w, (u[:, None] * x - moments[i] / W) ** 2)
        if replicates == 1:
            moments_rep = moments[None].copy()  # what the loop below would sum, bit for bit
        else:
            moments_rep = np.zeros((replicates, *moments.shape))
            for r in np.unique(rep):
                sel = rep == r
                x_r = x[sel]
                for i, u in enumerate(basis):
                    moments_rep[r, i] = _weighted_sum((u * w)[sel], x_r)
        return cls(
            weight=W,
            count=len(w),
            x_mean=xm,
            x_m2=_weighted_sum(w, (x - xm) ** 2),
            v_mean=vm,
            v_m2=_weighted_sum(w, (v - vm) ** 2),
            x_moment=moments,
            x_moment_m2=moments_m2,
            x_moment_rep=moments_rep,
            x_rep=x_rep,
            v_rep=v_rep,
            x2_rep=x2_rep,
            rep_weight=rep_weight,
        )

    def merge(self, other: ChunkStats) -> ChunkStats:
        """Chan et al.'s pairwise combination (exact, order-dependent only by round-off)."""
        W = self.weight + other.weight
        f = other.weight / W
        g = self.weight * other.weight / W
        dx = other.x_mean - self.x_mean
        dv = other.v_mean - self.v_mean
        dc = other.x_moment / other.weight - self.x_moment / self.weight
        return ChunkStats(
            weight=W,
            count=self.count + other.count,
            x_mean=self.x_mean + dx * f,
            x_m2=self.x_m2 + other.x_m2 + dx**2 * g,
            v_mean=self.v_mean + dv * f,
            v_m2=self.v_m2 + other.v_m2 + dv**2 * g,
            x_moment=self.x_moment + other.x_moment,
            x_moment_m2=self.x_moment_m2 + other.x_moment_m2 + dc**2 * g,
            x_moment_rep=self.x_moment_rep + other.x_moment_rep,
            x_rep=self.x_rep + other.x_rep,
            v_rep=self.v_rep + other.v_rep,
            x2_rep=self.x2_rep + other.x2_rep,
            rep_weight=self.rep_weight + other.rep_weight,
            rhs_evaluations=self.rhs_evaluations + other.rhs_evaluations,
        )


def _run_chunk(y0, xi, w, rep, replicates, times, system, options, order, keep_paths,
              recurrence=None, single_thread=False, device="cpu"):
    """Integrate one chunk of samples of ``system``'s law (on ``device``) and reduce it:
    (ChunkStats, n_impacts, finished (a mask), paths), or (None, n_impacts, finished, (m,
    xi_m, why)) for the first sample m that failed."""
    if single_thread:
        set_threads(1)
    batch = integrate_chunk(y0, xi, times, system, options, device)
    return reduce_chunk(batch, xi, w, rep, replicates, order, keep_paths, recurrence)


def integrate_chunk(y0, xi, times, system, options, device="cpu"):
    """The runs of one chunk's samples (a ``Batch``), the first half of :func:`_run_chunk`."""
    return run_batch(system.sampled_inputs(options, xi=xi), y0, times, rtol=options.rtol,
                     atol=options.atol, stop_on_failure=device == "cpu", device=device)


def reduce_chunk(batch, xi, w, rep, replicates, order, keep_paths, recurrence=None):
    """The chunk's statistics from its runs, the second half of :func:`_run_chunk`."""
    # the first sample that failed (the others may have been skipped after it)
    bad = np.flatnonzero(batch.failed)
    if len(bad):
        m = bad[0]
        return None, batch.impacts, batch.ok, (m, xi[m], batch.message(m))
    # C-ordered copies: the reductions' order then depends on nothing but the shape
    x = np.ascontiguousarray(batch.states[:, :, 0])
    v = np.ascontiguousarray(batch.states[:, :, 1])
    stats = ChunkStats.of(x, v, xi, w, order, rep, replicates, recurrence)
    stats.rhs_evaluations = int(batch.rhs_evaluations.sum())
    return stats, batch.impacts, batch.ok, (batch.states if keep_paths else None)


def _chunk_size(n_times: int, requested: int | None, device: str = "cpu") -> int:
    if requested is not None:  # checked by the Execution
        return int(requested)
    if device == "cuda":  # a GPU wants many threads: up to GPU_CHUNK samples a launch
        return int(min(GPU_CHUNK, max(1024, GPU_CHUNK_BYTES // (16 * n_times))))
    return int(min(4096, max(64, CHUNK_BYTES // (16 * n_times))))


def simulate_mc(
    system: System | Oscillator | None = None,
    *,
    samples: int = 1024,
    sampler: str = "sobol",
    seed: int | None = 0,
    replicates: int | None = None,
    periods: float = 100,
    per_period: int = 1,
    options: SolverOptions | None = None,
    times: np.ndarray | None = None,
    keep_paths: bool = False,
    control: xr.Dataset | None = None,
    execution: Execution | None = None,
    **fields,
) -> xr.Dataset:
    """Monte Carlo ensemble of the sampled impact system, eq. (1), p = p_bar + sigma xi.

    Parameters
    ----------
    system : an :class:`opa.System`, or an :class:`opa.Oscillator` (paper defaults when
        omitted) with these System fields as keywords: ``sigma`` (default 0.01) and
        ``uncertain`` (mu, a or c), the intensity and name of the uncertain parameter;
        ``distribution`` (the law of xi, default the semicircle); ``allow_negative``;
        ``order`` (below); ``impulse``, ``pulse_width``, ``impulse_at_zero``.
    samples, sampler, seed : M samples of xi from ``random``, ``sobol`` (scrambled) or
        ``gauss`` (M collocation nodes with their weights); the same seed gives the same
        result whatever the thread count or scheduler.
    replicates : for ``sobol``, the number R of independent scramblings whose spread gives
        the standard error (randomised QMC); default 16 when M is a multiple of 16 and
        M >= 64, else 1 (then the standard error is the naive sqrt(Var/M), which
        overstates a QMC error). Ignored by the other samplers.
    order : N, the highest Chebyshev coefficient estimated, E[x U_i(xi)] for i <= N,
        each with its standard error (``x_coef_sem``, formed like ``x_sem``).
    keep_paths : also return every sample path (memory O(M T)); otherwise only the
        streamed statistics are kept (memory O(R N T)).
    control : an OPA run of the same system (:func:`opa.simulate_opa`, any K, any law) as
        a control variate (:mod:`mc._control`): adds ``cv_x_mean``, ``cv_x_var`` with
        their standard errors and the attribute ``variance_reduction``. Needs ``sobol``
        with R >= 2 replicates; the output times default to the run's.
    execution : how the chunks run (:class:`opa.Execution`; default: in this process):
        ``chunk_size`` samples per chunk (default about 32 MiB of paths); ``scheduler``,
        a Dask cluster where the chunks run as tasks (the result is bit-identical to the
        local one); ``device="cuda"``, the samples' trajectories on a CUDA GPU, one
        thread per sample, each running the CPU kernel's own driver compiled for the GPU
        (:mod:`opa._gpu`, the ``gpu`` extra numba-cuda), chunks of up to 2^18 samples
        (about 1 GiB of paths) whose paths are reduced here as on the CPU (its results
        are not the CPU's to the bit: states within 9.3e-9 of them at rtol 1e-10 over 20
        periods in ``benchmarks/bench_gpu.py``'s run on an H100, with the same impact
        counts); ``checkpoint``, a directory where each finished chunk is written as it
        finishes, with a manifest of everything that determines the result: a rerun with
        the same directory and inputs loads the finished chunks (the progress bar counts
        them as done) and returns the bit-identical result, a directory of another run is
        refused, damaged chunk files are reported through ``log``, renamed ``*.bad`` and
        computed again (remove the directory with ``mc.remove_checkpoint`` once the
        result is saved); ``progress``; ``log`` (damaged checkpoint files and resume
        notes; default: ``warnings.warn`` for damage and silence otherwise);
        ``connect_timeout`` and ``worker_timeout`` (:class:`opa.Execution`). ``workers``
        is not used: one ensemble runs in this process, numba's threads sharing the
        cores. The keywords of these fields are still taken on their own, as before.

    Returns
    -------
    xarray.Dataset ``mc`` of docs/datasets.md: ``x_mean, v_mean, x_var, v_var, x_sem,
    v_sem, x_var_sem (time)``, ``x_coef, x_coef_sem (order, time)``, ``n_impacts, xi,
    weight (sample)``. For ``gauss`` the weights are the quadrature weights, variances
    are weighted and the standard errors are NaN (a quadrature has no sampling error).

    Every standard error is formed the same way, for the estimate
    ``c_hat = sum_m w_m y_m / W`` of ``E[y]`` with ``y = x`` (``x_sem``), ``y = x'``
    (``v_sem``) or ``y = x U_i(xi)`` (``x_coef_sem``):

    * R > 1 randomised-QMC replicates (``sobol``): ``SE = std_r(c_hat_r) / sqrt(R)``
      (ddof 1), ``c_hat_r`` the estimate from replicate r alone;
    * otherwise (``random``, or R = 1): ``SE = sqrt(s^2 / M)`` with the weighted sample
      variance ``s^2 = M / (M - 1) sum_m w_m (y_m - c_hat)^2 / W``.

    ``x_var_sem`` is the spread of the replicates' variances / sqrt(R), or without
    replicates the normal-theory ``Var sqrt(2 / (M - 1))``. ``x_var`` (and ``v_var``) is
    the weighted sample variance about the estimated mean, which misses that mean's own
    variance: Bessel's ``M / (M - 1)`` restores it for ``random`` points; for scrambled
    Sobol' points, whose mean varies far less, ``x_sem^2`` is added instead (with R > 1;
    with R = 1 nothing).

    Raises
    ------
    ValueError
        Bad input, named with its value; sizes beyond the memory budget
        (``opa._dataset.check_memory``, ``$OPA_MC_MEMORY_BUDGET``); a checkpoint of
        another run; a scheduler that does not answer within ``connect_timeout``.
    SimulationError
        A sample's trajectory could not be completed.
    DaskError
        The Dask cluster lost all its workers (or never had any) for ``worker_timeout``
        seconds, a chunk killed the workers that ran it, or the scheduler went away.
    """
    run = take_execution(execution, fields, "simulate_mc").only(
        "simulate_mc", "scheduler", "device", "checkpoint", "chunk_size", "connect_timeout",
        "worker_timeout")
    options = check_instance("options", options, SolverOptions, SolverOptions())
    system = as_system(system, options, several=True, **_MC_ENTRY, **fields)
    if keep_paths not in (True, False) or isinstance(keep_paths, str):
        raise ValueError(f"keep_paths must be True or False, got {keep_paths!r}")
    plan = _plan(system, options, samples, sampler, seed, replicates, control,
                 output_times(system.oscillator, periods, per_period, _control_times(
                     control, system, times, samples, sampler, seed)), keep_paths, run)
    # connect before the checkpoint is made: a wrong address leaves nothing behind
    with run.client() as client:
        runner = _Chunks.of(plan, run)
        results = runner.local(run) if client is None else runner.dask(client, run)
        try:
            total, n_impacts, paths = _merged(results, plan)
        finally:
            results.close()  # a Dask run cancels the tasks left now, not at collection
    ds = _dataset(total, plan.xi, plan.w, n_impacts, paths, plan.times, system, options,
                  sampler, seed, plan.replicates, plan.law, plan.chaos)
    if control is not None:
        ds = controlled(ds, total.x_rep, total.x2_rep, total.rep_weight, plan.xi,
                        plan.replicates, control, system.problem)
    return ds


def _control_times(control, system, times, samples, sampler, seed):
    """The output times asked for, or a control run's (checked against the system) once
    the sampler's settings are known to be good."""
    check_sampler(sampler, samples, seed)
    if samples < 2 and sampler != "gauss":
        raise ValueError(f"samples must be >= 2 for a variance and a standard error, got "
                         f"{samples}")
    check_memory("sampling", samples * SAMPLE_BYTES,
                 f"samples {samples} x {SAMPLE_BYTES} bytes")
    return times if control is None else check_control(control, system, times)


@dataclass(frozen=True)
class _Plan:
    """One ensemble, checked and sampled: everything its chunks need."""

    system: System
    options: SolverOptions
    sampler: str
    samples: int
    seed: int | None
    replicates: int
    times: np.ndarray
    keep_paths: bool
    size: int
    measure: object
    xi: np.ndarray
    w: np.ndarray
    recurrence: object

    @property
    def chaos(self):
        """The product basis of several uncertain parameters' coefficients, else None."""
        return self.recurrence if self.system.dimension > 1 else None

    @property
    def law(self) -> str:
        if self.system.dimension > 1:
            return "product of " + ", ".join(m.name for m in self.system.problem.measures)
        return "semicircle" if self.measure is None else self.measure.name

    @property
    def bounds(self) -> list[tuple[int, int]]:
        n = len(self.xi)
        return [(s, min(s + self.size, n)) for s in range(0, n, self.size)]


def _plan(system, options, samples, sampler, seed, replicates, control, times, keep_paths,
          run) -> _Plan:
    """The ensemble's replicates, chunks and samples, after every budget check."""
    samples, order, T = int(samples), system.order, len(times)
    if run.device == "cuda":
        require_gpu()
    system.check_samples()
    if sampler != "sobol":
        replicates = 1
    elif replicates is None:
        replicates = 16 if samples % 16 == 0 and samples >= 64 else 1
    if control is not None and replicates < 2:
        raise ValueError(f"control needs sampler='sobol' with replicates >= 2 (its "
                         f"standard errors are the replicates' spread), got sampler="
                         f"{sampler!r}, replicates={replicates}")
    from opa.engine import check_steps, check_work

    periods = float(times[-1] - times[0]) / system.oscillator.forcing_period
    drivers = [("samples", samples), ("periods", f"{periods:g}")]
    # each sample is one trajectory: the step limit of slow forcing, as for the DMR
    check_steps("this Monte Carlo ensemble", periods, system.oscillator, options.max_steps,
                [("omega", f"{system.oscillator.omega:g}"), ("periods", f"{periods:g}")])
    check_work("this Monte Carlo ensemble", samples * periods, drivers,
               oscillator=system.oscillator)
    size = min(_chunk_size(T, run.chunk_size, run.device), samples)
    if keep_paths:
        check_memory("keep_paths", samples * T * 2 * 8,
                     f"samples {samples} x {T} outputs x 2 states")
    check_memory("a chunk of paths", size * T * 2 * 8 * 3,
                 f"chunk_size {size} x {T} outputs x 2 states, with the statistics' "
                 f"temporaries and the next chunk's paths")
    if system.dimension > 1:
        xi, w, basis = _sample_problem(system, sampler, samples, seed, replicates)
        terms, measure = basis.size, None
    else:
        measure = None if system.semicircle else system.measure
        xi, w = sample_xi(sampler, samples, seed, replicates, distribution=measure)
        terms = order + 1
    check_memory("the replicate sums", 3 * replicates * T * 8 * 2,
                 f"3 x replicates {replicates} x {T} outputs, running sums and a chunk's")
    count = (f"order + 1 = {terms}" if system.dimension == 1
             else f"the multi-index set's {terms}")
    check_memory("x_coef", terms * T * 8 * 2,
                 f"{count} coefficients x {T} outputs, running sum and a chunk's")
    check_memory("x_coef_sem", (replicates + 1) * terms * T * 8 * 2,
                 f"(replicates {replicates} + 1) x {count} coefficients x {T} outputs, "
                 f"running sums and a chunk's")
    if system.dimension > 1:
        recurrence = basis
    else:
        recurrence = None if measure is None else measure.recurrence(order + 1)
    return _Plan(system, options, sampler, samples, seed, replicates, times, keep_paths,
                 size, measure, xi, w, recurrence)


def _sample_problem(system, sampler, samples, seed, replicates):
    """Points (M, d) and weights of several uncertain parameters' law, and the product
    basis of order N their coefficients E[x Psi_alpha] are estimated in."""
    from opa.engine import ChaosBasis

    if sampler == "gauss":
        raise ValueError("sampler 'gauss' (collocation nodes) takes one uncertain parameter; "
                         "with several use 'sobol' or 'random'")
    from math import comb

    from opa.engine import MAX_CHAOS_TERMS

    problem = system.problem
    terms = comb(system.order + problem.dimension, problem.dimension)
    if terms > MAX_CHAOS_TERMS:
        raise ValueError(f"order {system.order} with {problem.dimension} uncertain parameters "
                         f"makes {terms} coefficients E[x Psi_alpha] to estimate, more than "
                         f"{MAX_CHAOS_TERMS}; lower the order")
    xi = problem.sample(samples, sampler, seed, replicates)
    basis = ChaosBasis.from_order(problem.measures, system.order)
    return xi, np.full(samples, 1.0 / samples), basis


def _merged(results, plan: _Plan):
    """The chunks' statistics merged in chunk order (memory does not grow with M), the
    impact counts and, with keep_paths, the paths; a sample that stopped is raised."""
    system = plan.system
    total = None
    n_impacts = np.empty(len(plan.xi), dtype=np.int64)
    paths = np.empty((len(plan.xi), len(plan.times), 2)) if plan.keep_paths else None
    for (lo, hi), (stats, imp, status, extra) in results:
        if stats is None:
            m, xi_m, why = extra
            values = system.problem.values(np.reshape(xi_m, (1, -1)), system.oscillator)
            where = ", ".join(f"{name} = {v[0]:.6g}" for name, v in values.items())
            point = (f"{xi_m:.6g}" if np.ndim(xi_m) == 0
                     else "(" + ", ".join(f"{x:.6g}" for x in xi_m) + ")")
            raise SimulationError(f"Monte Carlo sample {lo + m} (xi = {point}, {where}) "
                                  f"stopped: {why}")
        n_impacts[lo:hi] = imp
        if plan.keep_paths:
            paths[lo:hi] = extra
        total = stats if total is None else total.merge(stats)
    return total, n_impacts, paths


def _manifest(system, options, sampler, samples, seed, replicates, times, measure,
              recurrence, xi, w, bounds, keep_paths, device="cpu") -> dict:
    """Everything that determines the result of a run, for its checkpoint (the device
    only when it is a GPU, so that CPU checkpoints of earlier versions still resume)."""
    if system.dimension > 1:  # recurrence: the product basis
        law = {"laws": [str(law) for law in system.problem.laws],
               "indices": digest(np.ascontiguousarray(recurrence.indices))}
    elif measure is None:
        law = "semicircle"
    else:
        law = {key: getattr(measure, key) for key in ("name", "lo", "hi", "alpha", "beta",
                                                      "a", "b")}
        law["recurrence"] = [digest(np.asarray(c)) for c in recurrence]
    return {
        "opa_mc_version": package_version(),
        "oscillator": system.oscillator.as_dict(),
        "options": dataclasses.asdict(options),
        "impulse": {k: getattr(system, k) for k in IMPULSE_FIELDS},
        "sigma": system.sigma if system.dimension == 1 else list(system.sigma),
        "uncertain": system.uncertain if system.dimension == 1 else list(system.uncertain),
        "distribution": law,
        "sampler": sampler,
        "samples": samples,
        "seed": None if seed is None else int(seed),
        "replicates": int(replicates),
        "order": int(system.order),
        "times": {"count": len(times), "first": float(times[0]), "last": float(times[-1]),
                  "sha256": digest(times)},
        "xi": digest(xi),
        "weight": digest(w),
        "chunks": [list(b) for b in bounds],
        "keep_paths": bool(keep_paths),
        **({"device": device} if device != "cpu" else {}),
    }


def _chunk_check(T: int, terms: int, replicates: int, keep_paths: bool):
    """check(arrays, lo, hi): None when a loaded chunk has every field with its shape and
    kind (``terms`` coefficients: N + 1, or the multi-index set's), else what is wrong."""
    R = replicates
    fields = {"weight": ((), "f"), "count": ((), "i"), "x_mean": ((T,), "f"),
              "x_m2": ((T,), "f"), "v_mean": ((T,), "f"), "v_m2": ((T,), "f"),
              "x_moment": ((terms, T), "f"), "x_moment_m2": ((terms, T), "f"),
              "x_moment_rep": ((R, terms, T), "f"), "x_rep": ((R, T), "f"),
              "v_rep": ((R, T), "f"), "x2_rep": ((R, T), "f"), "rep_weight": ((R,), "f"),
              "rhs_evaluations": ((), "i")}

    def check(arrays, lo, hi):
        expected = {**fields, "n_impacts": ((hi - lo,), "i")}
        if keep_paths:
            expected["paths"] = ((hi - lo, T, 2), "f")
        if set(arrays) != set(expected):
            return f"fields {sorted(set(arrays) ^ set(expected))} missing or unexpected"
        for name, (shape, kind) in expected.items():
            if arrays[name].shape != shape or arrays[name].dtype.kind != kind:
                return f"{name} has shape {arrays[name].shape} and dtype {arrays[name].dtype}"
        if int(arrays["count"]) != hi - lo:
            return f"count {int(arrays['count'])} for {hi - lo} samples"
        return None

    return check


def _from_arrays(a: dict, keep_paths: bool):
    """A chunk result (stats, n_impacts, status, paths) from its checkpoint arrays."""
    stats = ChunkStats(
        weight=float(a["weight"]), count=int(a["count"]), x_mean=a["x_mean"],
        x_m2=a["x_m2"], v_mean=a["v_mean"], v_m2=a["v_m2"], x_moment=a["x_moment"],
        x_moment_m2=a["x_moment_m2"], x_moment_rep=a["x_moment_rep"], x_rep=a["x_rep"],
        v_rep=a["v_rep"], x2_rep=a["x2_rep"], rep_weight=a["rep_weight"],
        rhs_evaluations=int(a["rhs_evaluations"]),
    )
    n_impacts = a["n_impacts"].astype(np.int64)
    return stats, n_impacts, np.ones(len(n_impacts), bool), (a["paths"] if keep_paths
                                                               else None)


@dataclass
class _Chunks:
    """The chunks of one run; ``local`` and ``dask`` yield ``((lo, hi), result)`` in
    chunk order, loading finished chunks from the checkpoint and saving new ones."""

    y0: np.ndarray
    xi: np.ndarray
    w: np.ndarray
    rep: np.ndarray
    replicates: int
    bounds: list
    args: tuple
    store: Checkpoint | None
    finished: set
    check: Callable
    device: str = "cpu"

    @classmethod
    def of(cls, plan: _Plan, run: Execution) -> _Chunks:
        """The chunks of ``plan``, with the finished ones of ``run``'s checkpoint."""
        order, T, replicates = int(plan.system.order), len(plan.times), plan.replicates
        bounds = plan.bounds
        terms = order + 1 if plan.chaos is None else plan.chaos.size
        check = _chunk_check(T, terms, replicates, plan.keep_paths)
        store, finished = None, set()
        if run.checkpoint is not None:
            store = Checkpoint(run.checkpoint, _manifest(
                plan.system, plan.options, plan.sampler, plan.samples, plan.seed,
                replicates, plan.times, plan.measure, plan.recurrence, plan.xi, plan.w,
                bounds, plan.keep_paths, run.device), run.log)
            finished = store.finished(bounds, check)
            if finished:
                run.say(f"resuming from checkpoint {store.directory}: {len(finished)} of "
                        f"{len(bounds)} chunks already finished")
        rep = np.arange(len(plan.xi)) // (len(plan.xi) // replicates)
        args = (plan.times, plan.system, plan.options, order, plan.keep_paths,
                plan.recurrence)
        return cls(plan.system.deterministic().initial_state(), plan.xi, plan.w, rep,
                   replicates, bounds, args, store, finished, check, run.device)

    @property
    def keep_paths(self) -> bool:
        return bool(self.args[4])  # (times, system, options, order, keep_paths, recurrence)

    def task(self, i: int) -> tuple:
        lo, hi = self.bounds[i]
        return (self.y0, self.xi[lo:hi], self.w[lo:hi], self.rep[lo:hi], self.replicates,
                *self.args)

    def compute(self, i: int):
        return self.reduce(i, self.integrate(i))

    def integrate(self, i: int):
        """Chunk i's runs, and the true-system work they were (counted in the thread
        that ran them: ``reduce`` adds it to the thread that asked)."""
        lo, hi = self.bounds[i]
        times, system, options = self.args[:3]
        runs, time_units = true_system_work()
        batch = integrate_chunk(self.y0, self.xi[lo:hi], times, system, options, self.device)
        after = true_system_work()
        return batch, (after[0] - runs, after[1] - time_units), threading.get_ident()

    def reduce(self, i: int, integrated):
        batch, work, thread = integrated
        if thread != threading.get_ident():
            add_true_system_work(*work)
        lo, hi = self.bounds[i]
        times, system, options, order, keep_paths, recurrence = self.args
        return reduce_chunk(batch, self.xi[lo:hi], self.w[lo:hi], self.rep[lo:hi],
                            self.replicates, order, keep_paths, recurrence)

    def loaded(self, i: int, ahead=None):
        """Chunk i from the checkpoint; computed (and saved) again if its file went bad
        since it was first read (its runs on ``ahead``, the one thread that integrates,
        when there is one)."""
        lo, hi = self.bounds[i]
        arrays = self.store.load(i, lo, hi, self.check)
        if arrays is None:
            batch = self.integrate(i) if ahead is None else \
                ahead.submit(self.integrate, i).result()
            result = self.reduce(i, batch)
            self.save(i, result)
            return result
        return _from_arrays(arrays, self.keep_paths)

    def save(self, i: int, result) -> None:
        stats, n_impacts, _, extra = result
        if self.store is None or stats is None:
            return
        arrays = {**stats_arrays(stats), "n_impacts": np.asarray(n_impacts)}
        if self.keep_paths:
            arrays["paths"] = extra
        self.store.save(i, *self.bounds[i], arrays)

    def done_samples(self) -> int:
        return sum(hi - lo for i, (lo, hi) in enumerate(self.bounds) if i in self.finished)

    def local(self, run: Execution):
        """The chunks in order, pipelined: one thread integrates the next chunk (the
        kernel's parallel batch, or the GPU's launch) while this one reduces the last, so
        the serial reduction no longer idles the kernel's threads. Every integration runs
        on that one thread (never two parallel batches at once); chunks are reduced and
        merged in order, so the result is the sequential one to the bit. numba's thread
        count is per thread: the helper takes this thread's (a map's worker process sets
        its share of the cores)."""
        from concurrent.futures import ThreadPoolExecutor

        todo = [i for i in range(len(self.bounds)) if i not in self.finished]
        with run.bar(len(self.xi), initial=self.done_samples(), unit="sample",
                     desc="Monte Carlo") as bar, \
                ThreadPoolExecutor(1, thread_name_prefix="opa-mc-chunks",
                                   initializer=set_threads,
                                   initargs=(thread_count(),)) as ahead:
            pending = {}
            try:
                for i, (lo, hi) in enumerate(self.bounds):
                    if i in self.finished:
                        yield (lo, hi), self.loaded(i, ahead)
                        continue
                    for j in todo[:2]:  # this chunk and the next
                        if j not in pending:
                            pending[j] = ahead.submit(self.integrate, j)
                    todo.remove(i)
                    result = self.reduce(i, pending.pop(i).result())
                    self.save(i, result)
                    bar.update(hi - lo)
                    yield (lo, hi), result
            finally:
                for future in pending.values():
                    future.cancel()

    def dask(self, client, run: Execution):
        """Chunks as Dask tasks on ``client``. Results are merged (and released) in
        submission order, so the result is the local one; with a checkpoint each result
        is saved as soon as it arrives, whatever its order."""
        from distributed import wait

        futures = {}
        watchdog = run.watchdog(client, lambda: sum(f is not None for f in futures.values()),
                                 "chunks")
        try:
            for i in range(len(self.bounds)):
                if i not in self.finished:
                    futures[i] = client.submit(_run_chunk, *self.task(i), True, pure=False)
            unsaved = set(futures) if self.store is not None else set()
            with run.bar(len(self.bounds), initial=len(self.finished), unit="chunk",
                         desc="Monte Carlo (dask)") as bar:
                for i, bound in enumerate(self.bounds):
                    if i in self.finished:
                        yield bound, self.loaded(i)
                        continue
                    current = futures[i]
                    while not current.done():
                        self._save_arrived(futures, unsaved, i, watchdog)
                        watched = [futures[j] for j in unsaved] or [current]
                        try:
                            wait(watched, timeout=watchdog.poll, return_when="FIRST_COMPLETED")
                        except TimeoutError:
                            watchdog.check()
                    result = watchdog.result(current, _samples(bound))
                    if i in unsaved:
                        unsaved.discard(i)
                        self.save(i, result)
                    futures[i] = None  # let the cluster forget it
                    bar.update(1)
                    yield bound, result
        finally:
            left = [f for f in futures.values() if f is not None]
            if left:
                client.cancel(left)

    def _save_arrived(self, futures, unsaved, current: int, watchdog) -> None:
        """Save every result that has arrived, but chunk ``current``'s (its caller's)."""
        for j in sorted(unsaved):
            if j != current and futures[j].done():
                self.save(j, watchdog.result(futures[j], _samples(self.bounds[j])))
                unsaved.discard(j)


def _samples(bound) -> str:
    """What a chunk's task is, for a failure's message."""
    return f"samples {bound[0]}..{bound[1] - 1}"


def _dataset(total, xi, w, n_impacts, paths, times, system, options, sampler, seed,
             replicates, distribution="semicircle", chaos=None):
    M = total.count
    # several parameters: the coefficients run over the multi-index set's terms
    term, basis = ("order", "U_i") if chaos is None else ("term", "Psi_alpha")
    if sampler == "gauss":
        x_var = total.x_m2 / total.weight
        v_var = total.v_m2 / total.weight
        x_sem = np.full_like(x_var, np.nan)
        v_sem = np.full_like(v_var, np.nan)
        x_var_sem = np.full_like(x_var, np.nan)
        x_coef_sem = np.full_like(total.x_moment, np.nan)
    else:
        # the sample variance about the sample mean misses the variance of that mean:
        # Var(mean) = Var / M for independent points (Bessel's M / (M - 1)); far less
        # for scrambled Sobol' points, whose mean's variance is estimated from the
        # replicates and added below (M / (M - 1) there was a bias of 1/M)
        corr = (M / (M - 1) if M > 1 else math.nan) if sampler == "random" else 1.0
        x_var = total.x_m2 / total.weight * corr
        v_var = total.v_m2 / total.weight * corr
        if replicates > 1:
            # randomised QMC: the spread of the replicate means (each of weight W/R)
            share = total.weight / replicates
            x_sem = np.std(total.x_rep / share, axis=0, ddof=1) / np.sqrt(replicates)
            v_sem = np.std(total.v_rep / share, axis=0, ddof=1) / np.sqrt(replicates)
            # each replicate's own variance estimate; their spread is the variance's SE
            wr = total.rep_weight[:, None]
            m_r = total.x_rep / wr
            var_r = np.maximum(total.x2_rep / wr - m_r**2, 0.0)
            x_var_sem = np.std(var_r, axis=0, ddof=1) / np.sqrt(replicates)
            x_coef_sem = (np.std(total.x_moment_rep / share, axis=0, ddof=1)
                          / np.sqrt(replicates))
            if sampler != "random":
                x_var = x_var + x_sem**2
                v_var = v_var + v_sem**2
        else:
            x_sem = np.sqrt(x_var / M)
            v_sem = np.sqrt(v_var / M)
            # normal-theory standard error of a sample variance
            x_var_sem = x_var * math.sqrt(2.0 / (M - 1)) if M > 1 else np.full_like(x_var, math.nan)
            x_coef_sem = np.sqrt(total.x_moment_m2 / total.weight * corr / M)
    data = {
        "x_mean": ("time", total.x_mean, {"long_name": "Monte Carlo mean E[x]", "units": "1"}),
        "v_mean": ("time", total.v_mean, {"long_name": "Monte Carlo mean E[x']", "units": "1"}),
        "x_var": ("time", x_var, {"long_name": "Monte Carlo variance Var[x]", "units": "1"}),
        "v_var": ("time", v_var, {"long_name": "Monte Carlo variance Var[x']", "units": "1"}),
        "x_sem": ("time", x_sem, {"long_name": "standard error of the mean of x", "units": "1"}),
        "v_sem": ("time", v_sem, {"long_name": "standard error of the mean of x'", "units": "1"}),
        "x_var_sem": ("time", x_var_sem, {"long_name": "standard error of the variance of x",
                                          "units": "1"}),
        "x_coef": ((term, "time"), total.x_moment / total.weight,
                   {"long_name": f"Monte Carlo estimate of E[x {basis}(xi)]", "units": "1"}),
        "x_coef_sem": ((term, "time"), x_coef_sem,
                       {"long_name": f"standard error of the estimate of E[x {basis}(xi)]",
                        "units": "1"}),
        "n_impacts": ("sample", n_impacts, {"long_name": "impacts of each sample", "units": "1"}),
        "xi": (("sample",) + (() if xi.ndim == 1 else ("parameter",)), xi,
               {"long_name": f"uncertain variable xi ({distribution} law)", "units": "1"}),
        "weight": ("sample", w, {"long_name": "sample weight", "units": "1"}),
    }
    if paths is not None:
        data["x"] = (("sample", "time"), paths[:, :, 0], {"long_name": "sample path x",
                                                          "units": "1"})
        data["v"] = (("sample", "time"), paths[:, :, 1], {"long_name": "sample path x'",
                                                          "units": "1"})
    coords = {**time_coord(times, system.oscillator.omega), "sample": ("sample", np.arange(M))}
    if chaos is None:
        coords["order"] = ("order", np.arange(system.order + 1))
    else:
        coords.update(term=("term", np.arange(chaos.size)),
                      parameter=("parameter", list(system.problem.names)))
        data["multi_index"] = (("term", "parameter"), chaos.indices.astype(np.int64), {
            "long_name": "degree of each parameter's polynomial in Psi_alpha", "units": "1"})
    ds = xr.Dataset(
        data,
        coords=coords,
        attrs=provenance_attrs("mc", system, options, sampler=sampler,
                               seed=-1 if seed is None else int(seed)),
    )
    ds.attrs["samples"] = int(M)
    ds.attrs["replicates"] = int(replicates)
    ds.attrs["sem_method"] = (
        "none (quadrature)" if sampler == "gauss"
        else "spread of randomised-QMC replicates" if replicates > 1
        else "sqrt(Var/M)"
    )
    ds.attrs["rhs_evaluations"] = int(total.rhs_evaluations)
    if chaos is None:  # several parameters keep the problem's own attribute
        ds.attrs["distribution"] = distribution
    return ds
