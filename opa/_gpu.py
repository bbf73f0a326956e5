"""Ensembles of true impact systems on a CUDA GPU: one thread per sampled system.

Each thread runs the CPU kernel's own driver, :func:`opa._kernel.integrate_with`, compiled
for the device by numba-cuda: a CUDA kernel that calls a numba ``njit`` function compiles
that function again for the GPU. So the DOP853 step, its dense output, the wall scan and
the re-step to the wall, the impact law, chatter -> sticking -> release, the impulse kicks
and the status checks are the CPU's code, not a copy of it. What is here is only what the
GPU needs of its own:

- the work arrays of ``integrate_with`` as each thread's local memory (sized for the 2-D
  true system: N = 0, one node, no tangent columns, which is all an ensemble runs);
- the launch: inputs copied to the device once, one thread per sample, the states, event
  logs and counters copied back (:func:`run_batch`);
- a reduction on the device for the moments of a large ensemble, so that only the
  moments cross back (:func:`moments`).

Nothing here is imported unless a caller asks for ``device="cuda"``; ``numba.cuda`` is
imported then. ``NUMBA_ENABLE_CUDASIM=1`` runs the same kernels in numba's CUDA simulator
(slow: tests at tiny sizes), which is how CI checks this module without a GPU.
"""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np

from . import _kernel as kernel

THREADS = 128  # threads per block of the ensemble kernel
REDUCE_ROWS = 8  # sample rows per block of the reduction (x 32 output columns)
# the shapes of each thread's work arrays, as module constants (a CUDA local array's
# shape must be a compile-time constant)
_ROWS, _STATS, _NODES = kernel.K_ROWS, kernel.N_STATS, 1


class DeviceError(ValueError):
    """``device="cuda"`` was asked for on a machine that cannot run it (a ValueError:
    the command line answers it as bad input, exit status 2)."""


def unavailable() -> str | None:
    """Why ``device="cuda"`` cannot run here, or None when it can (a GPU that numba
    sees, or numba's CUDA simulator)."""
    try:
        from numba import cuda
    except Exception as e:  # noqa: BLE001 - any import failure means no CUDA here
        return f"numba's CUDA target does not import ({type(e).__name__}: {e})"
    try:
        if cuda.is_available():
            return None
    except Exception as e:  # noqa: BLE001
        return f"numba found no usable CUDA driver ({type(e).__name__}: {e})"
    return ("numba found no CUDA GPU (install the 'gpu' extra, numba-cuda, on a machine "
            "with an NVIDIA GPU and driver; NUMBA_ENABLE_CUDASIM=1 runs the simulator)")


def require() -> None:
    """Raise :class:`DeviceError` with the reason when ``device="cuda"`` cannot run."""
    why = unavailable()
    if why is not None:
        raise DeviceError(f'device="cuda" cannot run here: {why}')


def _unwrapped(fn):
    """``fn`` called with the CUDA simulator's array wrappers replaced by the numpy arrays
    they wrap (the simulator runs a kernel as Python; the CPU-compiled driver then takes
    numpy arrays)."""
    def call(*args):
        return fn(*(_numpy(a) for a in args))
    return call


def _numpy(a):
    item = vars(a).get("_item") if hasattr(a, "__dict__") else None
    return a if item is None else item._ary


_integrate = None  # the driver a kernel calls: kernel.integrate_with (unwrapped when simulated)
cuda = None  # numba.cuda, imported by the first _kernels() (a module global, so that the
# CUDA simulator can swap it for its own while a kernel runs)


@functools.cache
def _kernels():
    """The CUDA kernels, compiled at their first launch (the first launch took 46 s on the
    H100 machine, compilation included; ``benchmarks/bench_gpu.py``)."""
    global cuda, _integrate
    if not hasattr(np, "row_stack"):
        # numba-cuda (0.30 and before) registers an overload of np.row_stack at its first
        # compilation, which fails under NumPy 2.5, where row_stack (an alias of vstack)
        # was removed: give it back the alias it names
        np.row_stack = np.vstack
    from numba import config, cuda

    float64 = np.float64
    _integrate = (_unwrapped(kernel.integrate_with) if config.ENABLE_CUDASIM
                  else kernel.integrate_with)

    @cuda.jit
    def ensemble(Y0, include_start, t_out, P, cfgs, table, weights, U, rtol, atol, out, logs,
                 counters):
        b = cuda.grid(1)
        if b >= P.shape[0]:
            return
        z = cuda.local.array(2, float64)
        z[0] = Y0[b, 0]
        z[1] = Y0[b, 1]
        k1 = cuda.local.array((_ROWS, 2), float64)
        k2 = cuda.local.array((_ROWS, 2), float64)
        f = cuda.local.array((7, 2), float64)
        z_new = cuda.local.array(2, float64)
        ztmp = cuda.local.array(2, float64)
        z_top = cuda.local.array(2, float64)
        f_minus = cuda.local.array(2, float64)
        f_plus = cuda.local.array(2, float64)
        work = cuda.local.array((6, _NODES), float64)
        none2 = cuda.local.array((1, _STATS), float64)
        none1 = cuda.local.array(1, float64)
        res = _integrate(z, np.int64(0), t_out, include_start, np.bool_(False), P[b],
                         cfgs[b], table[b], weights[b], U[b], rtol, atol, out[b], none2[:0],
                         none1[:0], logs[b], k1, k2, f, z_new, ztmp, z_top, f_minus, f_plus,
                         work)
        for j in range(5):
            counters[b, j] = res[j]

    @cuda.jit
    def shifted_sums(out, ref, sums):
        """sums[k, i, j] += sum over this block's samples of (out[b, i, j] - ref[i, j])^k
        for k = 1, 2 (k = 0: the count of finite values), one column (i, j) per thread."""
        col = cuda.blockIdx.x * cuda.blockDim.x + cuda.threadIdx.x
        n_cols = out.shape[1] * out.shape[2]
        if col >= n_cols:
            return
        i = col // out.shape[2]
        j = col - i * out.shape[2]
        B = out.shape[0]
        per = (B + cuda.gridDim.y - 1) // cuda.gridDim.y
        lo = cuda.blockIdx.y * per
        hi = min(lo + per, B)
        s0 = s1 = s2 = 0.0
        for b in range(lo + cuda.threadIdx.y, hi, cuda.blockDim.y):
            d = out[b, i, j] - ref[i, j]
            if math.isfinite(d):
                s0 += 1.0
                s1 += d
                s2 += d * d
        cuda.atomic.add(sums, (0, i, j), s0)
        cuda.atomic.add(sums, (1, i, j), s1)
        cuda.atomic.add(sums, (2, i, j), s2)

    return cuda, ensemble, shifted_sums


def _launch(Y0, include_start, times, P, cfgs, table, weights, U, rtol, atol, capacity):
    """The ensemble on the device: (device states (B, n_out, 2), logs, counters)."""
    cuda, ensemble, _ = _kernels()
    B = P.shape[0]
    with warnings.catch_warnings():  # a small ensemble is a small grid, and that is fine
        warnings.filterwarnings("ignore", message=".*under-utilization")
        return _launch_ensemble(cuda, ensemble, B, Y0, include_start, times, P, cfgs, table,
                                weights, U, rtol, atol, capacity)


def _launch_ensemble(cuda, ensemble, B, Y0, include_start, times, P, cfgs, table, weights, U,
                     rtol, atol, capacity):
    d_out = cuda.device_array((B, len(times), 2))
    d_logs = cuda.device_array((B, max(capacity, 1), 3))
    d_counters = cuda.device_array((B, 5), dtype=np.int64)
    ensemble[(B + THREADS - 1) // THREADS, THREADS](
        cuda.to_device(np.ascontiguousarray(Y0, dtype=float)), np.bool_(include_start),
        cuda.to_device(times), cuda.to_device(np.ascontiguousarray(P, dtype=float)),
        cuda.to_device(np.ascontiguousarray(cfgs, dtype=np.int64)),
        *(cuda.to_device(np.ascontiguousarray(a, dtype=float)) for a in (table, weights, U)),
        float(rtol), float(atol), d_out, d_logs, d_counters)
    return d_out, d_logs, d_counters


def _check_inputs(P, cfgs, table, U):
    """Only the 2-D true systems: N = 0 and one node (``opa._run.sampled``)."""
    if table.shape[1] != 1 or U.shape[1:] != (1, 2) or np.any(cfgs[:, kernel.C_NCOEF] != 1):
        raise ValueError('device="cuda" runs ensembles of the true (sampled) systems only: '
                         "state dimension 2, one node")


def run_batch(Y0, include_start, times, P, cfgs, table, weights, U, rtol, atol, capacity):
    """B plain runs of the 2-D true systems on the GPU, as ``opa._kernel.run_batch_from``
    on the CPU: run b from ``Y0[b]`` with ``P[b], cfgs[b]``. Returns (states (B, n_out,
    2), logs (B, capacity, 3), counters (B, 5)) on the host. Every run is made (no run is
    skipped after a failure)."""
    require()
    _check_inputs(P, cfgs, table, U)
    d_out, d_logs, d_counters = _launch(Y0, include_start, times, P, cfgs, table, weights, U,
                                        rtol, atol, capacity)
    logs = d_logs.copy_to_host()[:, :capacity]
    return d_out.copy_to_host(), np.ascontiguousarray(logs), d_counters.copy_to_host()


def moments(Y0, include_start, times, P, cfgs, table, weights, U, rtol, atol):
    """The ensemble's mean and variance (ddof 1) of x and v at each output time, reduced
    on the device: only the moments and the counters cross back. Returns (mean (n_out,
    2), var (n_out, 2), finite counts (n_out, 2), counters (B, 5)).

    The sums are shifted by the first sample's state at each time (so the variance does
    not cancel), accumulated per block in float64 and added across blocks atomically, so
    the last digits may differ between launches; the states themselves do not."""
    require()
    _check_inputs(P, cfgs, table, U)
    cuda, _, shifted_sums = _kernels()
    d_out, _, d_counters = _launch(Y0, include_start, times, P, cfgs, table, weights, U, rtol,
                                   atol, 0)
    B, n_out = P.shape[0], len(times)
    ref = d_out[0].copy_to_host()
    ref[~np.isfinite(ref)] = 0.0
    d_sums = cuda.to_device(np.zeros((3, n_out, 2)))
    n_cols = 2 * n_out
    groups = max(1, min(1024, B // (4 * REDUCE_ROWS)))
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*under-utilization")
        shifted_sums[((n_cols + 31) // 32, groups), (32, REDUCE_ROWS)](
            d_out, cuda.to_device(ref), d_sums)
    sums = d_sums.copy_to_host()
    count = sums[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        shift = sums[1] / count
        mean = ref + shift
        var = (sums[2] - count * shift * shift) / (count - 1.0)
    return mean, np.maximum(var, 0.0), count.astype(np.int64), d_counters.copy_to_host()
