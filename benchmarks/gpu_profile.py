"""One launch of the GPU ensemble kernel, for a profiler (``benchmarks/device.sh profile``
runs it under Nsight Compute): 65,536 samples of ``bench_gpu.py``'s case over 20 periods,
after a warm-up launch that compiles the kernels.

    ncu --clock-control none -k regex:ensemble -c 1 --section SpeedOfLight \\
        --section Occupancy --section LaunchStats python3 benchmarks/gpu_profile.py
"""

from __future__ import annotations

import time

from benchmarks.bench_gpu import ours_moments

if __name__ == "__main__":
    ours_moments(1024, 2)  # compile (its launch is the profiler's first, skipped by -k/-c)
    start = time.perf_counter()
    ours_moments(65_536, 20)
    print(f"65,536 samples x 20 periods: {time.perf_counter() - start:.3f} s")
