"""Tests for the Dask backend of mc.simulate_mc: failures of the cluster end the run with
one clear line instead of a traceback or a silent wait, and a Dask run checkpoints and
resumes like a local one, bit for bit (README, 'Errors, limits and resuming')."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

import mc
import opa

distributed = pytest.importorskip("distributed")

OSC = opa.preset("3.2", omega=3.98)
RUN = dict(sigma=0.05, samples=96, sampler="sobol", seed=3, periods=3, per_period=4,
           chunk_size=16, order=3, options=opa.SolverOptions(rtol=1e-8, atol=1e-8),
           progress=False)  # fmt: skip
VARIABLES = ("x_mean", "v_mean", "x_var", "v_var", "x_sem", "v_sem", "x_var_sem", "x_coef",
             "x_coef_sem", "n_impacts", "xi", "weight")  # fmt: skip


def test_a_scheduler_that_does_not_answer_fails_in_connect_timeout_with_one_line(tmp_path):
    """One line after connect_timeout (default 5 s), not a 63-line traceback after 30 s;
    the checkpoint directory is not even created."""
    start = time.monotonic()
    with pytest.raises(ValueError, match=r"^scheduler 'tcp://127.0.0.1:1' did not answer "
                                         r"within 1 s \(connect_timeout\)") as err:  # fmt: skip
        mc.simulate_mc(OSC, scheduler="tcp://127.0.0.1:1", connect_timeout=1,
                       checkpoint=tmp_path / "parts", **RUN)  # fmt: skip
    assert time.monotonic() - start < 8
    assert "\n" not in str(err.value)
    assert not (tmp_path / "parts").exists()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(connect_timeout=0),
         r"connect_timeout must be a number of seconds in \(0, 86400\], got 0"),
        (dict(connect_timeout="5"), r"connect_timeout must be .* got '5'"),
        (dict(worker_timeout=-1), r"worker_timeout must be .* or None, got -1"),
        (dict(scheduler=8786), r"scheduler must be an address such as 'tcp://host:8786' or "
                               r"a distributed.Client, got 8786"),
    ],
)  # fmt: skip
def test_bad_dask_settings_name_the_parameter(kwargs, message):
    with pytest.raises(ValueError, match=message):
        mc.simulate_mc(OSC, **{**RUN, **kwargs})


def test_a_cluster_without_workers_fails_with_dask_error():
    """No worker at all (all died, or none started): DaskError after worker_timeout, not a
    silent wait; DaskError is a SimulationError, which the CLI reports as a failed run."""
    assert issubclass(mc.DaskError, opa.SimulationError)
    with (
        distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=":0")
        as cluster,
        distributed.Client(cluster) as client,
    ):  # fmt: skip
        start = time.monotonic()
        with pytest.raises(mc.DaskError, match=r"^the Dask cluster has had no workers for "
                                               r"0.5 s .* 6 chunks unfinished"):  # fmt: skip
            mc.simulate_mc(OSC, scheduler=client, worker_timeout=0.5, **RUN)
        assert time.monotonic() - start < 5
        assert not client.futures  # our tasks were cancelled


def test_dask_run_checkpoints_and_resumes_bit_identical(tmp_path):
    """Chunks finished on the cluster are saved as they arrive; a rerun after losing two
    of them loads the rest and recomputes only those, and both runs equal the local
    run without a checkpoint on every statistic."""
    local = mc.simulate_mc(OSC, **RUN)
    parts = tmp_path / "parts"
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                 dashboard_address=":0") as cluster,
        distributed.Client(cluster) as client,
    ):  # fmt: skip
        first = mc.simulate_mc(OSC, scheduler=client, checkpoint=parts, **RUN)
        names = sorted(n for n in os.listdir(parts) if n.startswith("chunk-"))
        assert len(names) == 6
        os.remove(parts / names[0])
        (parts / names[5]).write_bytes(b"")
        lines = []
        resumed = mc.simulate_mc(OSC, scheduler=cluster.scheduler_address, checkpoint=parts,
                                 log=lines.append, **RUN)  # fmt: skip
        # several uncertain parameters (their laws pickled to the workers): the same bits
        several = dict(RUN, sigma=(0.05, 0.01), uncertain="mu,c", distribution="beta:2,3,uniform")
        far = mc.simulate_mc(OSC, scheduler=client, **several)
    near = mc.simulate_mc(OSC, **several)
    for name in VARIABLES:
        np.testing.assert_array_equal(far[name].values, near[name].values, err_msg=name)
    assert sum(" is damaged " in line for line in lines) == 1
    for ds in (first, resumed):
        for name in VARIABLES:
            np.testing.assert_array_equal(ds[name].values, local[name].values, err_msg=name)


def test_all_workers_dying_mid_run_fails_with_dask_error():
    """The only worker goes away 0.5 s into a ~10 s run: DaskError about worker_timeout
    later instead of waiting forever for a worker."""
    import threading

    slow = dict(RUN, samples=4096, chunk_size=8, periods=40, per_period=2)
    with (
        distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                 dashboard_address=":0") as cluster,
        distributed.Client(cluster) as client,
    ):  # fmt: skip
        remover = threading.Timer(0.5, cluster.scale, args=(0,))
        remover.start()
        try:
            with pytest.raises(mc.DaskError, match=r"^the Dask cluster has had no workers "
                                                   r"for 1 s \(all died or none started\)"):
                mc.simulate_mc(OSC, scheduler=client, worker_timeout=1, **slow)
        finally:
            remover.cancel()
            remover.join()
