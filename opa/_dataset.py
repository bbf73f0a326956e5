"""Dataset conventions shared by every model (docs/datasets.md): attributes and safe I/O."""

from __future__ import annotations

import contextvars
import datetime as _dt
import functools
import os
import re
import sys
import tempfile
import time
from collections.abc import Callable
from importlib import metadata

import numpy as np

from opa._lazy import lazy
from opa._model import PARAMETER_NAMES, SolverOptions

xr = lazy("xarray")

#: the command a dataset's ``history`` records: set by ``opa.cli.main`` for the command it
#: runs (so that an in-process ``main([...])`` records its own arguments); None: sys.argv
COMMAND: contextvars.ContextVar[tuple[str, ...] | None] = contextvars.ContextVar(
    "opa_mc_command", default=None)


@functools.cache
def package_version() -> str:
    """The installed opa-mc version (read once: the metadata lookup scans sys.path)."""
    try:
        return metadata.version("opa-mc")
    except metadata.PackageNotFoundError:  # running from a source tree
        return "0+unknown"


def provenance_attrs(model: str, system, options: SolverOptions, *, seed: int = -1,
                     sampler: str = "none") -> dict:
    """Attributes every dataset carries: each parameter by its name and the choices made
    (the :class:`opa.System`'s and the solver's).

    netCDF attributes cannot be bools, dicts or None, so flags are stored as 0/1 ints,
    a missing seed as -1 and a missing sampler as "none".
    """
    attrs = {name: float(getattr(system.oscillator, name)) for name in PARAMETER_NAMES}
    attrs.update(model=model, **system.dataset_attrs())
    attrs.update(
        rtol=float(options.rtol),
        atol=float(options.atol),
        method=options.method,
        chatter_velocity=float(options.chatter_velocity),
        seed=int(seed),
        sampler=sampler,
        Conventions="CF-1.8",
        history=f"{_dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')} "
        f"{_command_line()}",
        source="opa-mc",
        opa_mc_version=package_version(),
    )
    return attrs


def _command_line() -> str:
    argv = COMMAND.get() or sys.argv
    return " ".join(os.path.basename(a) if i == 0 else a for i, a in enumerate(argv))


def time_coord(times: np.ndarray, omega: float) -> dict:
    return {
        "time": (
            "time",
            np.asarray(times, dtype=float),
            {"long_name": "dimensionless time t", "units": "1", "forcing_period": 2 * np.pi / omega},
        )
    }


OPA_LAYOUT = ("x_mean", "x_var", "v_mean", "v_var", "element_x_coef", "element_v_coef",
              "element_edges", "element_probability")


def element_layout(x_coefs, v_coefs, edges, probability, impacts, rhs_evaluations) -> tuple:
    """The element variables and coordinates every OPA dataset carries (docs/datasets.md).

    One schema for every OPA run: the single-element OPA of the paper is the case K = 1
    (one element over the whole support, probability 1); multi-element runs have K > 1.
    ``x_coefs``, ``v_coefs``: (K, N+1, T) coefficients in each element's orthonormal
    basis; ``edges`` (K+1,) in xi; ``probability``, ``impacts``, ``rhs_evaluations`` (K,).

    Returns (data_vars, coords) for :class:`xarray.Dataset`.
    """
    one = {"units": "1"}
    K = len(probability)
    data = {
        "element_x_coef": (("element", "order", "time"), np.asarray(x_coefs),
                           {"long_name": "coefficients of x in each element's orthonormal "
                            "basis", **one}),
        "element_v_coef": (("element", "order", "time"), np.asarray(v_coefs),
                           {"long_name": "coefficients of x' per element", **one}),
        "element_edges": ("edge", np.asarray(edges, dtype=float),
                          {"long_name": "element edges in xi", **one}),
        "element_probability": ("element", np.asarray(probability, dtype=float),
                                {"long_name": "probability of each element", **one}),
        "element_impacts": ("element", np.asarray(impacts, dtype=np.int64),
                            {"long_name": "impacts of each element's mean", **one}),
        "element_rhs_evaluations": ("element", np.asarray(rhs_evaluations, dtype=np.int64),
                                    {"long_name": "right-hand sides per element", **one}),
    }
    coords = {"element": ("element", np.arange(K), {"long_name": "element index", **one}),
              "edge": ("edge", np.arange(K + 1), {"long_name": "edge index", **one})}
    return data, coords


def check_opa_layout(ds, name: str = "the opa dataset") -> None:
    """Refuse, naming the variable, a dataset that lacks the OPA layout (written by an
    older version, or not an OPA run)."""
    if ds.attrs.get("model") != "opa":
        raise ValueError(f"{name} must be an OPA run (attribute model = 'opa'), got "
                         f"model = {ds.attrs.get('model')!r}")
    missing = [v for v in OPA_LAYOUT if v not in ds.variables]
    if missing:
        raise ValueError(f"{name} lacks {', '.join(missing)} (written by an older "
                         f"opa-mc?); run it again")


# --------------------------------------------------------------------------- atomic files

# Temporaries are named .tmp-opa-mc-<pid>-<random><suffix> so that a later run can tell
# whether their writer is still alive and remove those a crash left behind.
TEMP_PREFIX = ".tmp-opa-mc-"
_TEMPORARY = re.compile(re.escape(TEMP_PREFIX) + r"(\d+)-")
_LEGACY = re.compile(r"\.tmp-.*\.nc")  # tempfile.mkstemp(prefix=".tmp-") of older versions
_LEGACY_AGE = 60.0  # seconds


def current_umask() -> int:
    """The process's umask, read without changing it where Linux allows."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    old = os.umask(0o077)  # not thread-safe, hence only the fallback
    os.umask(old)
    return old


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True  # another user's process, or not ours to judge
    return True


def clean_stale_temporaries(directory: str | os.PathLike) -> list[str]:
    """Remove the temporaries that interrupted writes left in ``directory``.

    Removed: ``.tmp-opa-mc-<pid>-*`` files whose process ``pid`` is no longer running
    (on this machine: a writer on another host sharing the directory is not seen), and
    empty ``.tmp-*.nc`` files of older versions untouched for a minute. The
    temporaries of running writers are left alone.

    Returns
    -------
    list of str : the paths removed.
    """
    directory = os.fspath(directory)
    removed = []
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return removed
    now = time.time()
    for entry in entries:
        match = _TEMPORARY.match(entry.name)
        try:
            if match:
                stale = not _pid_alive(int(match[1]))
            elif _LEGACY.fullmatch(entry.name):
                info = entry.stat(follow_symlinks=False)
                stale = info.st_size == 0 and now - info.st_mtime > _LEGACY_AGE
            else:
                continue
            if stale and entry.is_file(follow_symlinks=False):
                os.remove(entry.path)
                removed.append(entry.path)
        except OSError:  # gone already, or not ours to remove
            continue
    return removed


def atomic_write(path: str | os.PathLike, write: Callable[[str], object], *,
                 suffix: str = "", clean: bool = True) -> None:
    """Create ``path`` by ``write(temporary)`` on a temporary beside it, then a rename.

    The file is complete or absent under ``path``, never truncated: the temporary is
    flushed to disk before it replaces ``path``, and removed if ``write`` fails. The
    file gets the mode a plain ``open`` would give it (``0o666`` less the umask), not
    the ``0o600`` of ``tempfile.mkstemp``. With ``clean``, stale temporaries in the
    directory are removed first (:func:`clean_stale_temporaries`).
    """
    path = os.path.realpath(os.fspath(path))  # through a symlink to its target
    directory = os.path.dirname(path)
    os.makedirs(directory, exist_ok=True)
    if clean:
        clean_stale_temporaries(directory)
    fd, tmp = tempfile.mkstemp(prefix=f"{TEMP_PREFIX}{os.getpid()}-", suffix=suffix,
                               dir=directory)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~current_umask())
        _fsync(tmp, os.O_RDONLY)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.remove(tmp)
        except OSError:
            pass
        raise
    try:  # make the rename itself durable
        _fsync(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        pass


def _fsync(path: str, flags: int) -> None:
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_netcdf(ds: xr.Dataset, path: str | os.PathLike) -> None:
    """Write ``ds`` atomically (:func:`atomic_write`): to a temporary file beside
    ``path``, then rename.

    A crash or interruption never leaves a truncated netCDF file under ``path``, and the
    temporaries of earlier crashed writes in that directory are removed.
    """
    atomic_write(path, lambda tmp: ds.to_netcdf(tmp, engine="netcdf4"), suffix=".nc")
