#!/usr/bin/env bash
# The checks that need the lent GPU machine (16 cores, one H100/H200), one part per call:
#   bash benchmarks/device.sh gpu   # bench_gpu.py: agreement, ours vs diffrax vs 16 cores
#   bash benchmarks/device.sh threads  # bench_threads.py: the MC kernel at 1..16 cores
#   bash benchmarks/device.sh phases   # bench_phases.py: the default map at 1 and 16
#   bash benchmarks/device.sh profile  # Nsight Compute on one launch of the GPU kernel
# (an optional second argument is the part's time limit in seconds)
# The machine has no registry: the wheels that its image lacks (chaospy, numpoly,
# netCDF4, cftime, dask, distributed and theirs) travel in .whl/ (Python 3.12 builds;
# name .whl in the call's carry). Made here, with /.whl/ in .git/info/exclude:
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp #     --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 #     --platform manylinux2014_x86_64 --platform manylinux1_x86_64 -d .whl #     chaospy==4.3.21 netCDF4==1.7.5.1.post1 cftime==1.6.6.1 dask==2026.8.0 #     distributed==2026.8.0 locket==1.0.0 tblib==3.2.2 tornado==6.6.1 zict==3.0.0 #     partd==1.4.2
#   PYENV_VERSION=3.12.1 python3.12 -m pip wheel --no-deps -w .whl numpoly==1.3.9
# (numpoly 1.3.9 has no Python 3.12 wheel on the index: it is built here.)
set -u
export NUMBA_CUDA_LOW_OCCUPANCY_WARNINGS=0
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 MPLBACKEND=Agg XLA_PYTHON_CLIENT_PREALLOCATE=false
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm --format=csv,noheader
nproc; uptime
python3 -c "import numba, numpy, jax, diffrax; print('numba', numba.__version__, 'numpy', \
numpy.__version__, 'jax', jax.__version__, 'diffrax', diffrax.__version__)"
case "${1:-gpu}" in
gpu)
    timeout "${2:-420}" python3 -m pytest -q -s -p no:cacheprovider benchmarks/bench_gpu.py \
        2>&1 | tee "$OUT/gpu.log" ;;
threads)
    timeout "${2:-150}" python3 -m pytest -q -s -p no:cacheprovider benchmarks/bench_threads.py \
        -m slow 2>&1 | tee "$OUT/threads.log" ;;
profile)
    # Nsight Compute on one launch (it reads counters on Firecracker machines; clocks left
    # as they are); -c 2: the warm-up launch and the measured one, both reported
    timeout "${2:-240}" ncu --clock-control none -k regex:ensemble -c 2 \
        --section SpeedOfLight --section Occupancy --section LaunchStats \
        --section MemoryWorkloadAnalysis python3 benchmarks/gpu_profile.py \
        2>&1 | tee "$OUT/profile.log" ;;
phases)
    PHASE_COUNTS=${PHASE_COUNTS:-1,16} timeout "${2:-330}" python3 -m pytest -q -s \
        -p no:cacheprovider benchmarks/bench_phases.py -m slow 2>&1 | tee "$OUT/phases.log" ;;
esac
cp benchmarks/results/gpu.json "$OUT/" 2>/dev/null
uptime
