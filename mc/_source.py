"""The Monte Carlo mean as a trajectory source of ``opa.dynamics``' sweeps.

The dynamics layer integrates the DMR and the OPA system itself and takes every other
model as a *source*, ``source(task, times) -> arrays``; this is the one for ``"mc"``.
"""

from __future__ import annotations

import numpy as np

from mc._ensemble import simulate_mc


def sweep_source(task, times: np.ndarray) -> dict:
    """One sweep point of the Monte Carlo mean: ``task.samples`` sampled systems, their
    mean state at ``times`` (no impact log: the mean has none)."""
    ds = simulate_mc(task.system.replace(order=0, truncation="galerkin", impact_law="mean"),
                     samples=task.samples, sampler=task.sampler, seed=task.seed, times=times,
                     options=task.options, progress=False)
    x, v = ds.x_mean.values, ds.v_mean.values
    return {"x": x, "v": v, "impact_time": None, "impact_velocity": None,
            "stick_time": np.zeros(0), "release_time": np.zeros(0),
            "final": np.array([[x[-1]], [v[-1]]])}
