"""Monte Carlo ensembles of the true sampled impact system, with streamed statistics.

Each sample is the deterministic impact oscillator (eq. (1)) with its own value of the
uncertain parameter ``p = p_bar + sigma xi``: its own impacts, chatter and sticking,
integrated by the same compiled kernel as the DMR (``opa._solver.run_samples``).

Samples are processed in fixed chunks. A chunk's paths live only while its statistics
are formed; chunk statistics (weight, mean, centred sum of squares, Chebyshev moments)
are merged in chunk order with Chan's pairwise update. Memory is therefore
O(chunk * T + N * T), independent of the number of samples, and the result depends
only on the seed and the chunk size, never on the thread count or on where a chunk ran,
which is what makes the Dask backend return exactly the local result.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np
import xarray as xr

from mc._sampling import SAMPLERS, sample_xi
from opa import _solver as K
from opa._basis import chebyshev_u, orthonormal
from opa._dataset import provenance_attrs, time_coord
from opa._model import Oscillator, SolverOptions, Uncertainty, _choice, check_order
from opa._simulate import SimulationError, _times, pack_parameters

CHUNK_BYTES = 32 * 2**20


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
            x_rep[r] = w[sel] @ x[sel]
            v_rep[r] = w[sel] @ v[sel]
            x2_rep[r] = w[sel] @ x[sel] ** 2
            rep_weight[r] = w[sel].sum()
        xm = w @ x / W
        vm = w @ v / W
        # (N+1, M): Chebyshev U for the semicircle, else the law's orthonormal polynomials
        basis = chebyshev_u(order, xi) if recurrence is None else orthonormal(order, xi,
                                                                               *recurrence)
        return cls(
            weight=W,
            count=len(w),
            x_mean=xm,
            x_m2=w @ (x - xm) ** 2,
            v_mean=vm,
            v_m2=w @ (v - vm) ** 2,
            x_moment=(basis * w) @ x,
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
        return ChunkStats(
            weight=W,
            count=self.count + other.count,
            x_mean=self.x_mean + dx * f,
            x_m2=self.x_m2 + other.x_m2 + dx**2 * g,
            v_mean=self.v_mean + dv * f,
            v_m2=self.v_m2 + other.v_m2 + dv**2 * g,
            x_moment=self.x_moment + other.x_moment,
            x_rep=self.x_rep + other.x_rep,
            v_rep=self.v_rep + other.v_rep,
            x2_rep=self.x2_rep + other.x2_rep,
            rep_weight=self.rep_weight + other.rep_weight,
            rhs_evaluations=self.rhs_evaluations + other.rhs_evaluations,
        )


def run_chunk(y0, xi, w, rep, replicates, times, p, cfg, rtol, atol, order, keep_paths,
              recurrence=None, single_thread=False):
    """Integrate one chunk of samples and reduce it: (ChunkStats, n_impacts, status, paths)."""
    if single_thread:
        import numba

        numba.set_num_threads(1)
    paths = np.empty((len(xi), len(times), 2))
    n_impacts = np.zeros(len(xi), dtype=np.int64)
    n_rhs = np.zeros(len(xi), dtype=np.int64)
    status = np.zeros(len(xi), dtype=np.int64)
    K.run_samples(y0, xi, times, p, cfg, rtol, atol, paths, n_impacts, n_rhs, status)
    bad = np.flatnonzero(status != K.OK)
    if len(bad):
        m = bad[0]
        return None, n_impacts, status, (m, xi[m], int(status[m]))
    stats = ChunkStats.of(paths[:, :, 0], paths[:, :, 1], xi, w, order, rep, replicates,
                          recurrence)
    stats.rhs_evaluations = int(n_rhs.sum())
    return stats, n_impacts, status, (paths if keep_paths else None)


def _chunk_size(n_times: int, requested: int | None) -> int:
    if requested is not None:
        if int(requested) != requested or requested < 1:
            raise ValueError(f"chunk_size must be a positive integer, got {requested}")
        return int(requested)
    return int(min(4096, max(64, CHUNK_BYTES // (16 * n_times))))


def simulate_mc(
    oscillator: Oscillator | None = None,
    *,
    sigma: float = 0.01,
    samples: int = 1024,
    sampler: str = "sobol",
    seed: int | None = 0,
    replicates: int | None = None,
    order: int = 4,
    uncertain: str = "mu",
    allow_negative: bool = False,
    periods: float = 100,
    per_period: int = 1,
    options: SolverOptions | None = None,
    times: np.ndarray | None = None,
    keep_paths: bool = False,
    chunk_size: int | None = None,
    scheduler: str | None = None,
    progress: bool | None = None,
    distribution=None,
) -> xr.Dataset:
    """Monte Carlo ensemble of the sampled impact system, eq. (1), p = p_bar + sigma xi.

    Parameters
    ----------
    sigma, uncertain : intensity and name of the uncertain parameter (mu, a or c).
    samples, sampler, seed : M samples of xi from ``random``, ``sobol`` (scrambled) or
        ``gauss`` (M collocation nodes with their weights); the same seed gives the same
        result whatever the thread count or scheduler.
    replicates : for ``sobol``, the number R of independent scramblings whose spread gives
        the standard error (randomised QMC); default 16 when M is a multiple of 16 and
        M >= 64, else 1 (then the standard error is the naive sqrt(Var/M), which
        overstates a QMC error). Ignored by the other samplers.
    order : N, the highest Chebyshev coefficient estimated, E[x U_i(xi)] for i <= N.
    keep_paths : also return every sample path (memory O(M T)); otherwise only the
        streamed statistics are kept (memory O(N T)).
    chunk_size : samples per task (default: about 32 MiB of paths per chunk).
    scheduler : address of a Dask distributed scheduler (``tcp://host:port``) or a
        ``distributed.Client``; chunks then run as tasks there. Default: local threads.
    progress : show a progress bar (default: when stderr is a terminal).

    Returns
    -------
    xarray.Dataset ``mc`` of SPEC section 5: ``x_mean, v_mean, x_var, v_var, x_sem,
    v_sem (time)``, ``x_coef (order, time)``, ``n_impacts, xi, weight (sample)``.
    For ``gauss`` the weights are the quadrature weights, variances are weighted and
    the standard errors are NaN (a quadrature has no sampling error).
    """
    oscillator = oscillator or Oscillator()
    options = options or SolverOptions()
    _choice("sampler", sampler, SAMPLERS)
    order = check_order(order)
    unc = Uncertainty(sigma, uncertain, allow_negative)
    unc.check(oscillator)
    times = _times(oscillator, periods, per_period, times)
    if sampler != "sobol":
        replicates = 1
    elif replicates is None:
        replicates = 16 if samples % 16 == 0 and samples >= 64 else 1
    measure = None
    if distribution is not None:
        from opa._measure import parse
        from opa._simulate import check_support

        measure = parse(distribution)
        check_support(oscillator, unc, measure)
        if measure.name == "semicircle" and measure.is_whole:
            measure = None
    xi, w = sample_xi(sampler, samples, seed, replicates, distribution=measure)
    recurrence = None if measure is None else measure.recurrence(order + 1)
    rep = np.arange(len(xi)) // (len(xi) // replicates)
    p, cfg = pack_parameters(oscillator, options, sigma=unc.sigma, uncertain=uncertain)
    y0 = np.array([oscillator.x0, oscillator.v0])
    size = _chunk_size(len(times), chunk_size)
    bounds = [(s, min(s + size, len(xi))) for s in range(0, len(xi), size)]
    args = (times, p, cfg, options.rtol, options.atol, int(order), keep_paths, recurrence)

    total = None
    n_impacts = np.empty(len(xi), dtype=np.int64)
    paths = np.empty((len(xi), len(times), 2)) if keep_paths else None
    # chunks arrive in order and are merged at once: memory does not grow with M
    for (lo, hi), (stats, imp, status, extra) in _run_chunks(
        y0, xi, w, rep, replicates, bounds, args, scheduler, progress
    ):
        if stats is None:
            m, xi_m, code = extra
            raise SimulationError(
                f"Monte Carlo sample {lo + m} (xi = {xi_m:.6g}, {uncertain} = "
                f"{getattr(oscillator, uncertain) + unc.sigma * xi_m:.6g}) stopped: "
                f"{K.STATUS_MESSAGES[code]}"
            )
        n_impacts[lo:hi] = imp
        if keep_paths:
            paths[lo:hi] = extra
        total = stats if total is None else total.merge(stats)
    return _dataset(total, xi, w, n_impacts, paths, times, oscillator, options, unc, sampler,
                    seed, order, replicates, "semicircle" if measure is None else measure.name)


def _run_chunks(y0, xi, w, rep, replicates, bounds, args, scheduler, progress):
    """Yield ``((lo, hi), chunk result)`` in chunk order."""
    if progress is None:
        progress = sys.stderr.isatty()
    if scheduler is not None:
        yield from _run_chunks_dask(y0, xi, w, rep, replicates, bounds, args, scheduler,
                                    progress)
        return
    from tqdm.auto import tqdm

    with tqdm(total=len(xi), unit="sample", disable=not progress, desc="Monte Carlo") as bar:
        for lo, hi in bounds:
            yield (lo, hi), run_chunk(y0, xi[lo:hi], w[lo:hi], rep[lo:hi], replicates, *args)
            bar.update(hi - lo)


def _run_chunks_dask(y0, xi, w, rep, replicates, bounds, args, scheduler, progress):
    """Chunks as Dask tasks; results are yielded (and released) in submission order, so
    the merge order, hence the result, is the local one."""
    from distributed import Client
    from tqdm.auto import tqdm

    own = not isinstance(scheduler, Client)
    client = Client(scheduler) if own else scheduler
    try:
        futures = [
            client.submit(run_chunk, y0, xi[lo:hi], w[lo:hi], rep[lo:hi], replicates, *args,
                          True, pure=False)
            for lo, hi in bounds
        ]
        with tqdm(total=len(futures), unit="chunk", disable=not progress,
                  desc="Monte Carlo (dask)") as bar:
            for i, bound in enumerate(bounds):
                result = futures[i].result()
                futures[i] = None  # let the cluster forget it
                bar.update(1)
                yield bound, result
    finally:
        if own:
            client.close()


def _dataset(total, xi, w, n_impacts, paths, times, oscillator, options, unc, sampler, seed,
             order, replicates, distribution="semicircle"):
    M = total.count
    if sampler == "gauss":
        x_var = total.x_m2 / total.weight
        v_var = total.v_m2 / total.weight
        x_sem = np.full_like(x_var, np.nan)
        v_sem = np.full_like(v_var, np.nan)
        x_var_sem = np.full_like(x_var, np.nan)
    else:
        corr = M / (M - 1) if M > 1 else math.nan
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
        else:
            x_sem = np.sqrt(x_var / M)
            v_sem = np.sqrt(v_var / M)
            # normal-theory standard error of a sample variance
            x_var_sem = x_var * math.sqrt(2.0 / (M - 1)) if M > 1 else np.full_like(x_var, math.nan)
    data = {
        "x_mean": ("time", total.x_mean, {"long_name": "Monte Carlo mean E[x]", "units": "1"}),
        "v_mean": ("time", total.v_mean, {"long_name": "Monte Carlo mean E[x']", "units": "1"}),
        "x_var": ("time", x_var, {"long_name": "Monte Carlo variance Var[x]", "units": "1"}),
        "v_var": ("time", v_var, {"long_name": "Monte Carlo variance Var[x']", "units": "1"}),
        "x_sem": ("time", x_sem, {"long_name": "standard error of the mean of x", "units": "1"}),
        "v_sem": ("time", v_sem, {"long_name": "standard error of the mean of x'", "units": "1"}),
        "x_var_sem": ("time", x_var_sem, {"long_name": "standard error of the variance of x",
                                          "units": "1"}),
        "x_coef": (("order", "time"), total.x_moment / total.weight,
                   {"long_name": "Monte Carlo estimate of E[x U_i(xi)]", "units": "1"}),
        "n_impacts": ("sample", n_impacts, {"long_name": "impacts of each sample", "units": "1"}),
        "xi": ("sample", xi, {"long_name": "uncertain variable xi (semicircle on [-1, 1])",
                              "units": "1"}),
        "weight": ("sample", w, {"long_name": "sample weight", "units": "1"}),
    }
    if paths is not None:
        data["x"] = (("sample", "time"), paths[:, :, 0], {"long_name": "sample path x",
                                                          "units": "1"})
        data["v"] = (("sample", "time"), paths[:, :, 1], {"long_name": "sample path x'",
                                                          "units": "1"})
    ds = xr.Dataset(
        data,
        coords={**time_coord(times, oscillator.omega), "order": ("order", np.arange(order + 1)),
                "sample": ("sample", np.arange(M))},
        attrs=provenance_attrs(
            "mc", oscillator, options, sigma=unc.sigma, order=order, uncertain=unc.parameter,
            seed=-1 if seed is None else int(seed), sampler=sampler,
        ),
    )
    ds.attrs["samples"] = int(M)
    ds.attrs["replicates"] = int(replicates)
    ds.attrs["sem_method"] = (
        "none (quadrature)" if sampler == "gauss"
        else "spread of randomised-QMC replicates" if replicates > 1
        else "sqrt(Var/M)"
    )
    ds.attrs["rhs_evaluations"] = int(total.rhs_evaluations)
    ds.attrs["allow_negative"] = int(unc.allow_negative)
    ds.attrs["distribution"] = distribution
    return ds
