"""``device="cuda"`` (``opa/_gpu.py``): the choice and its refusals here, and the kernels'
glue in numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, in a subprocess: the
simulator must be chosen before numba.cuda is imported). The simulator runs each GPU
thread as Python calling the CPU-compiled driver, so it checks the launch, the layout of
the inputs and outputs, the local work arrays, the event logs, the counters and the
reduction, not the device's arithmetic: that is ``benchmarks/bench_gpu.py``'s agreement
test on a GPU (against the CPU kernel within 1e-9 at rtol 1e-10)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import mc
import opa
from opa import _gpu
from opa.cli import main

REPO = Path(__file__).resolve().parents[2]
NO_GPU = _gpu.unavailable() is not None


def _simulated(script: str) -> dict:
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(script)], env=env, cwd=REPO,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_device_other_than_cpu_or_cuda_is_named():
    with pytest.raises(ValueError, match="device must be one of 'cpu', 'cuda', got 'gpu'"):
        mc.simulate_mc(samples=4, periods=1, device="gpu")


@pytest.mark.skipif(not NO_GPU, reason="this machine can run device='cuda'")
def test_no_gpu_is_one_clear_error_and_exit_status_2(capsys):
    with pytest.raises(_gpu.DeviceError, match='device="cuda" cannot run here: '):
        mc.simulate_mc(samples=4, periods=1, device="cuda")
    status = main(["simulate", "mc", "--samples", "8", "--periods", "1", "--device", "cuda",
                   "--quiet"])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and err.startswith('opa-mc: error: device="cuda" cannot run')


def test_cuda_with_a_scheduler_is_refused_before_connecting():
    with pytest.raises(ValueError, match='device="cuda" runs in this process: not with '
                                         "scheduler"):
        mc.simulate_mc(samples=4, periods=1, device="cuda", scheduler="tcp://127.0.0.1:1")


def test_device_is_a_flag_of_simulate_mc_only(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "opa", "--periods", "1", "--device", "cuda"])
    assert exc.value.code == 2
    assert "--device applies to simulate mc, not simulate opa" in capsys.readouterr().err


def test_the_gpu_runs_only_true_systems():
    system = opa.System(opa.Oscillator(), sigma=0.01, order=2)
    inputs = system.kernel_inputs(opa.SolverOptions())
    P, cfg = inputs.p[None, :], inputs.cfg[None, :]
    with pytest.raises(ValueError, match="true \\(sampled\\) systems only"):
        _gpu._check_inputs(P, cfg, inputs.table[None, :], inputs.basis[None, :])


def test_the_simulated_gpu_gives_the_cpu_kernel_result():
    """States, counters and event logs of a chattering section 3.2 ensemble equal the
    CPU kernel's (the simulator runs the CPU-compiled driver on each thread), including
    the sample that chatters and sticks; the moments reduced 'on the device' equal numpy's
    mean and variance (ddof 1) of the CPU states; ``simulate_mc(device="cuda")`` equals
    the CPU ensemble."""
    got = _simulated("""
        import json
        import numpy as np
        import mc, opa
        from opa import _run
        from opa._kernel import EV_STICK
        osc = opa.preset("3.2", omega=3.98)
        system = opa.System(osc, sigma=0.05)
        options = opa.SolverOptions(rtol=1e-8, atol=1e-8)
        xi = np.append(np.linspace(-1.0, 1.0, 23), -0.5767)  # the last one sticks
        inputs = system.sampled_inputs(options, xi=xi)
        times = _run.output_times(osc, 17, 2, None)  # it sticks at t = 25.65
        y0 = system.deterministic().initial_state()
        kw = dict(rtol=1e-8, atol=1e-8, capacity=64)
        cpu = _run.run_batch(inputs, y0, times, **kw)
        gpu = _run.run_batch(inputs, y0, times, **kw, device="cuda")
        logs = all(np.array_equal(cpu.events(b).time, gpu.events(b).time)
                   and np.array_equal(cpu.events(b).kind, gpu.events(b).kind)
                   for b in range(len(xi)))
        mean, var, count, counters = _run.gpu_moments(inputs, y0, times, rtol=1e-8,
                                                      atol=1e-8)
        kw = dict(sigma=0.05, samples=32, sampler="random", seed=3, periods=3,
                  per_period=2, options=options, progress=False)
        a, b = mc.simulate_mc(osc, **kw), mc.simulate_mc(osc, **kw, device="cuda")
        print(json.dumps(dict(
            states=bool(np.array_equal(cpu.states, gpu.states)),
            counters=bool(np.array_equal(cpu._counters, gpu._counters)),
            moment_counters=bool(np.array_equal(cpu._counters, counters)),
            logs=bool(logs), sticks=bool(np.any(cpu.events(len(xi) - 1).kind == EV_STICK)),
            mean=float(np.max(np.abs(mean - cpu.states.mean(axis=0)))),
            var=float(np.max(np.abs(var - cpu.states.var(axis=0, ddof=1))
                             / cpu.states.var(axis=0, ddof=1).max())),
            count=int(count.min()),
            mc=[bool(np.array_equal(a[k].values, b[k].values))
                for k in ("x_mean", "x_var", "v_mean", "x_coef", "n_impacts")])))
        """)
    assert got["states"] and got["counters"] and got["logs"] and got["moment_counters"]
    assert got["sticks"]
    assert got["mean"] < 1e-14 and got["var"] < 1e-12 and got["count"] == 24
    assert all(got["mc"])


def test_step_guards_are_the_guard_of_each_row():
    from opa import _run

    osc = opa.Oscillator()
    inputs = opa.System(osc, sigma=0.05).sampled_inputs(opa.SolverOptions(),
                                                        xi=np.linspace(-1, 1, 5))
    inputs.p[:, _run.kernel.P_OMEGA] = [0.5, 1.0, 3.98, 40.0, 400.0]
    for times in (np.linspace(0.0, 30.0, 7), np.linspace(0.0, 3000.0, 3), np.zeros(0)):
        expected = [_run.step_guard(times, p) for p in inputs.p]
        assert list(_run.step_guards(times, inputs.p)) == expected
