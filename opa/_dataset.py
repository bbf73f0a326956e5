"""Dataset conventions shared by every model (SPEC section 5): attributes and safe I/O."""

from __future__ import annotations

import datetime as _dt
import os
import sys
import tempfile
from importlib import metadata

import numpy as np
import xarray as xr

from opa._model import PARAMETER_NAMES, Oscillator, SolverOptions


def package_version() -> str:
    try:
        return metadata.version("opa-mc")
    except metadata.PackageNotFoundError:  # running from a source tree
        return "0+unknown"


def provenance_attrs(
    model: str,
    oscillator: Oscillator,
    options: SolverOptions,
    *,
    sigma: float = 0.0,
    order: int = 0,
    uncertain: str = "mu",
    truncation: str = "galerkin",
    impact_law: str = "mean",
    seed: int = -1,
    sampler: str = "none",
) -> dict:
    """Attributes every dataset carries: each parameter by its name and the choices made.

    netCDF attributes cannot be bools, dicts or None, so flags are stored as 0/1 ints,
    a missing seed as -1 and a missing sampler as "none".
    """
    attrs = {name: float(getattr(oscillator, name)) for name in PARAMETER_NAMES}
    attrs.update(
        model=model,
        sigma=float(sigma),
        N=int(order),
        uncertain=uncertain,
        impulse=options.impulse,
        pulse_width=float(options.pulse_width),
        impulse_at_zero=int(bool(options.impulse_at_zero)),
        truncation=truncation,
        impact_law=impact_law,
        rtol=float(options.rtol),
        atol=float(options.atol),
        chatter_velocity=float(options.chatter_velocity),
        seed=int(seed),
        sampler=sampler,
        Conventions="CF-1.8",
        history=f"{_dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')} "
        f"{' '.join(os.path.basename(a) if i == 0 else a for i, a in enumerate(sys.argv))}",
        source="opa-mc",
        opa_mc_version=package_version(),
    )
    return attrs


def time_coord(times: np.ndarray, omega: float) -> dict:
    return {
        "time": (
            "time",
            np.asarray(times, dtype=float),
            {"long_name": "dimensionless time t", "units": "1", "forcing_period": 2 * np.pi / omega},
        )
    }


def write_netcdf(ds: xr.Dataset, path: str | os.PathLike) -> None:
    """Write ``ds`` atomically: to a temporary file beside ``path``, then rename.

    A crash or interruption never leaves a truncated netCDF file under ``path``.
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".nc", dir=directory)
    os.close(fd)
    try:
        ds.to_netcdf(tmp, engine="netcdf4")
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
