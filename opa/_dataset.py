"""Dataset conventions shared by every model (docs/datasets.md): attributes, safe I/O and
the memory budget that sizes are checked against before any work starts."""

from __future__ import annotations

import datetime as _dt
import os
import re
import sys
import tempfile
import time
from collections.abc import Callable
from importlib import metadata

import numpy as np

from opa._lazy import lazy
from opa._model import PARAMETER_NAMES, Oscillator, SolverOptions

xr = lazy("xarray")


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
        method=options.method,
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


# --------------------------------------------------------------------------- memory budget

MEMORY_BUDGET_ENV = "OPA_MC_MEMORY_BUDGET"
_UNITS = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40, "P": 2**50}


def parse_bytes(text: str) -> int:
    """A size in bytes from ``"1073741824"``, ``"512M"``, ``"8G"``, ``"1.5GiB"`` or ``"8GB"``.

    Suffixes are binary (K = 1024, M = 1024^2, ...), with or without a trailing ``B`` or
    ``iB``.

    >>> parse_bytes("8G") == 8 * 2**30
    True
    """
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([kKmMgGtTpP]?)(?:i?[bB])?\s*", str(text))
    if match is None:
        raise ValueError(f"a size must be a number of bytes with an optional suffix K, M, G, "
                         f"T or P, got {text!r}")
    return int(float(match[1]) * _UNITS[match[2].upper()])


def _half_physical_memory() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (ValueError, OSError, AttributeError):  # no sysconf (Windows) or no such name
        return 8 * 2**30


def _budget_from_environment() -> int | None:
    text = os.environ.get(MEMORY_BUDGET_ENV)
    if text is None or not text.strip():
        return None
    try:
        return parse_bytes(text)
    except ValueError as err:
        raise ValueError(f"{MEMORY_BUDGET_ENV}: {err}") from None


def _initial_budget() -> int:
    try:
        budget = _budget_from_environment()
    except ValueError:  # reported by memory_budget() when a size is checked
        budget = None
    return _half_physical_memory() if budget is None else budget


# The largest allocation a run may plan, in bytes: $OPA_MC_MEMORY_BUDGET at import if set,
# else half the physical memory. memory_budget() reads the variable again at each check.
MEMORY_BUDGET_BYTES = _initial_budget()


def memory_budget() -> int:
    """The budget in bytes: ``$OPA_MC_MEMORY_BUDGET`` if set now, else MEMORY_BUDGET_BYTES."""
    budget = _budget_from_environment()
    return MEMORY_BUDGET_BYTES if budget is None else budget


def format_bytes(nbytes: float) -> str:
    """``"17.9 GiB"``, ``"12 GiB"``, ``"512 B"``: binary units, one decimal at most."""
    value, unit = float(nbytes), "B"
    for name in ("KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if value < 1023.95:  # would not round to 1024.0
            break
        value, unit = value / 1024, name
    return f"{value:.1f}".removesuffix(".0") + f" {unit}"


def check_memory(what: str, nbytes: int, detail: str | None = None) -> None:
    """Refuse, before any work starts, an allocation larger than the memory budget.

    Parameters
    ----------
    what : what would be allocated, as the message's subject (``"keep_paths"``,
        ``"1001 output times (periods 1000 x per_period 1)"``).
    nbytes : its size in bytes (a Python int: it may be far beyond 2^63).
    detail : how ``nbytes`` was counted, put in brackets after the size
        (``"samples 100000 x 12001 outputs x 2 states"``).

    Raises
    ------
    ValueError
        One line such as ``keep_paths needs 17.9 GiB (samples 100000 x 12001 outputs x 2
        states), more than the memory budget of 12 GiB (set OPA_MC_MEMORY_BUDGET to change
        it)``. The budget is :func:`memory_budget`: ``$OPA_MC_MEMORY_BUDGET`` (bytes, or
        with a suffix such as ``8G``) if set, else half the physical memory.

    Examples
    --------
    >>> check_memory("a small array", 800)
    """
    budget = memory_budget()
    if nbytes > budget:
        counted = f" ({detail})" if detail else ""
        raise ValueError(f"{what} needs {format_bytes(nbytes)}{counted}, more than the memory "
                         f"budget of {format_bytes(budget)} (set {MEMORY_BUDGET_ENV} to "
                         f"change it)")


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
