"""Dataset conventions shared by every model (docs/datasets.md): attributes, safe I/O and
the one resume store of long jobs (:class:`Store`)."""

from __future__ import annotations

import contextvars
import dataclasses
import datetime as _dt
import errno
import functools
import hashlib
import json
import os
import re
import tomllib
import sys
import tempfile
import time
import warnings
import weakref
from collections.abc import Callable
from importlib import metadata

import numpy as np

from opa._lazy import lazy
from opa._lock import LOCK_NAME, OutputLock, forget, holder_elsewhere, pid_alive
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
    attrs.update(system.oscillator.lower_wall_attrs())  # only where a lower wall exists
    attrs.update(system.oscillator.law_attrs())  # a user's force law: expression, constants
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
            {"long_name": "dimensionless time t", "units": "1",
             "forcing_period": 2 * np.pi / omega},
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


#: variables whose NaN or inf is documented (docs/datasets.md), not a failure: the
#: refinement history of adaptive elements
_MAY_BE_NON_FINITE = ("refinement_mean_change", "refinement_share",
                      # NaN where the variance is 0 (a deterministic start)
                      "x_sobol_first", "x_sobol_total", "v_sobol_first", "v_sobol_total")


def first_non_finite(ds) -> tuple[str, int] | None:
    """The first float variable of a run's dataset that holds a NaN or an infinity, with
    how many of its values are not finite; None when the run is finite.

    A run with such a value could not be completed (its result is not to be written).
    The documented non-finite values do not count: the standard errors (``*_sem``) of a
    Gauss quadrature (``attrs["sampler"] == "gauss"``: it has no sampling error), the
    refinement history of adaptive elements (``refinement_share``,
    ``refinement_mean_change``) and the Sobol indices of an output without variance.
    """
    gauss = ds.attrs.get("sampler") == "gauss"
    for name, var in ds.data_vars.items():
        if var.dtype.kind != "f" or name in _MAY_BE_NON_FINITE or (
                gauss and name.endswith("_sem")):
            continue
        bad = int((~np.isfinite(var.values)).sum())
        if bad:
            return name, bad
    return None


# --------------------------------------------------------------------------- TOML files

#: the largest TOML file read (a validate config or a problem table is a few hundred
#: bytes)
MAX_CONFIG_BYTES = 1 << 20
#: the deepest nesting of arrays and tables a TOML file may have ([model] holds numbers)
MAX_CONFIG_DEPTH = 4


def read_toml(path, what: str = "config file") -> dict:
    """A TOML file (``what``: how messages name it): a regular file (not a FIFO, device
    or folder) of at most MAX_CONFIG_BYTES, nested at most MAX_CONFIG_DEPTH deep; one
    line naming the path and the fault otherwise."""
    import stat

    try:
        info = os.stat(path)
    except OSError as err:
        raise ValueError(f"{what} {path}: {err.strerror}") from None
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"{what} {path}: not a regular file")
    if info.st_size > MAX_CONFIG_BYTES:
        raise ValueError(f"{what} {path}: {info.st_size} bytes, more than the "
                         f"{MAX_CONFIG_BYTES} a {what} may have")
    try:
        with open(path, "rb") as fh:
            blob = fh.read(MAX_CONFIG_BYTES + 1)
    except OSError as err:
        raise ValueError(f"{what} {path}: {err.strerror}") from None
    if len(blob) > MAX_CONFIG_BYTES:
        raise ValueError(f"{what} {path}: more than the {MAX_CONFIG_BYTES} bytes a "
                         f"{what} may have")
    try:
        data = tomllib.loads(blob.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{what} {path} is not valid TOML: {err}") from None
    except RecursionError:
        raise ValueError(f"{what} {path}: arrays or tables nested too deeply (at most "
                         f"{MAX_CONFIG_DEPTH} levels)") from None

    def depth(value) -> int:
        if isinstance(value, dict):
            return 1 + max(map(depth, value.values()), default=0)
        if isinstance(value, list):
            return 1 + max(map(depth, value), default=0)
        return 0

    for key, value in data.items():
        if depth(value) > MAX_CONFIG_DEPTH - 1:
            raise ValueError(f"{what} {path}: key {key!r} is nested too deeply (at most "
                             f"{MAX_CONFIG_DEPTH} levels)")
    return data


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
                stale = not pid_alive(int(match[1]))
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
    except BaseException as err:
        try:
            os.remove(tmp)
        except OSError:
            pass
        if isinstance(err, (OSError, RuntimeError)):  # a full disk, netCDF's own errors:
            # name the file asked for, not the temporary
            code = getattr(err, "errno", None) or errno.EIO
            why = getattr(err, "strerror", None) or str(err) or type(err).__name__
            raise OSError(code, f"could not be written ({why})", path) from err
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


# --------------------------------------------------------------------------- the store

#: the format of a store folder, written to its marker file: a folder without the marker
#: (the parts of a version before the one store) or with another format is refused.
#: 2: every part carries the digest of its content (``DIGEST_ENTRY``); the parts of
#: format 1 do not, and cannot be trusted
STORE_FORMAT = "opa-mc store 2"
STORE_MARKER = "store.json"
#: where a part keeps its key: an ``.npz`` entry, a netCDF attribute, a JSON member
KEY_ENTRY = "store_key"
#: where a part keeps the digest of its content (:func:`content_digest`), likewise
DIGEST_ENTRY = "store_digest"
_SUFFIXES = (".npz", ".nc", ".json")
_PART = re.compile(r".+_[0-9a-f]{12}\.(npz|nc|json)(\.bad)?")


def digest(payload) -> str:
    """sha256 (64 hex digits) of ``payload``, the key of a part of a :class:`Store`.

    ``payload`` is made of JSON values (dict keys sorted, tuples as lists, floats
    exactly), numpy scalars (as their values), numpy arrays (by dtype, shape and bytes;
    object arrays by their elements), dataclass instances (by type name and their
    compared fields: an :class:`opa.System` or a law of xi by what defines it; a field in
    the class's ``_digest_optional`` only when it is not at its default) and objects with
    a ``digest_payload()`` (an :class:`opa.ForceLaw`: its expression and constants). Anything
    else is a TypeError: a key never rests on an object's ``repr``.

    >>> digest({"b": (1, 2.5), "a": np.arange(3)}) == digest({"a": np.arange(3),
    ...                                                        "b": [1, 2.5]})
    True
    >>> digest(np.arange(3)) == digest(np.arange(3.0))   # the dtype counts
    False
    """
    text = json.dumps(_canonical(payload), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _canonical(value):
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.ndarray):
        if value.dtype.hasobject:
            return {"__ndarray__": list(value.shape), "items": _canonical(value.ravel().tolist())}
        array = np.ascontiguousarray(value)
        return {"__ndarray__": list(array.shape), "dtype": array.dtype.str,
                "sha256": hashlib.sha256(array.tobytes()).hexdigest()}
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            raise TypeError(f"digest: dict keys must be strings, got {list(value)!r:.80}")
        return {k: _canonical(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        # fields added later with a default (``_digest_optional``) count only when set, so
        # that the keys of every part written before them still match
        optional = getattr(type(value), "_digest_optional", ())
        return {"__dataclass__": type(value).__qualname__,
                **{f.name: _canonical(getattr(value, f.name))
                   for f in dataclasses.fields(value) if f.compare and not (
                       f.name in optional and getattr(value, f.name) == f.default)}}
    if hasattr(value, "digest_payload"):  # an object that says what defines it
        return {"__object__": type(value).__qualname__,
                "payload": _canonical(value.digest_payload())}
    raise TypeError(f"digest: cannot hash a {type(value).__name__} ({value!r:.60})")


def content_digest(key: str, content) -> str:
    """The digest a part is written with and checked against on every read: sha256 of
    its key and its content as it reads back (:func:`digest`; a part's arrays by dtype,
    shape and bytes, a Dataset by :func:`_dataset_form`)."""
    return digest({"key": key, "content": content})


def _dataset_form(ds) -> dict:
    """What a netCDF part holds, for :func:`content_digest`: every variable's dims,
    values and attributes, and the global attributes but the store's own."""
    return {"attrs": _attrs_form(ds.attrs),
            "variables": {str(name): {"dims": list(v.dims), "values": _values_form(v.values),
                                      "attrs": _attrs_form(v.attrs)}
                          for name, v in ds.variables.items()}}


def _attrs_form(attrs) -> dict:
    return {str(k): _values_form(v) for k, v in attrs.items()
            if k not in (KEY_ENTRY, DIGEST_ENTRY)}


def _values_form(value):
    if isinstance(value, bytes):
        return {"__bytes__": value.hex()}
    if isinstance(value, np.ndarray) and value.dtype.hasobject:
        return {"__objects__": list(value.shape),
                "items": [_values_form(v) for v in value.ravel().tolist()]}
    if isinstance(value, (list, tuple)):
        return [_values_form(v) for v in value]
    return value


def _plain(value):
    """``value`` as JSON gives it back (tuples as lists, numpy scalars as Python)."""
    return json.loads(json.dumps(value, default=lambda v: v.item()))


def _first_difference(old, new, path=""):
    """(dotted key, old value, new value) of the first difference, or None."""
    if isinstance(old, dict) and isinstance(new, dict):
        for key in list(new) + [k for k in old if k not in new]:
            if key not in old or key not in new:
                return f"{path}{key}", old.get(key, "absent"), new.get(key, "absent")
            found = _first_difference(old[key], new[key], f"{path}{key}.")
            if found:
                return found
        return None
    if old != new:
        return path.rstrip("."), old, new
    return None


def _short(value) -> str:
    if isinstance(value, list):
        return f"{len(value)} entries"
    text = json.dumps(value) if not isinstance(value, str) else value
    return text if len(text) <= 48 else text[:36] + "..."


class Store:
    """The one resume store: a folder of the finished parts of long jobs, each found again
    by a hash of its inputs (:func:`digest`), each trusted only with the content it was
    written with (:func:`content_digest`).

    Layout::

        store.json                    the format (STORE_FORMAT), the job, its settings
        <name>_<key[:12]>.npz         a part: arrays, numbers, strings (+ key, digest)
        <name>_<key[:12]>.nc          a part: an xarray Dataset (key, digest: attributes)
        <name>_<key[:12]>.json        a part: JSON values (key, digest: members)
        .opa-mc.lock                  with ``lock``: the process writing the folder

    The key of a part is the digest of the store's settings and the part's ``inputs``
    (everything the part depends on), and the file stores it: a part copied or left from
    other inputs is found out. The file also stores the digest of its key and content as
    they read back, checked on every read: a part edited after it was written (a value
    changed on disk, a NaN set) is found out too. Every file is written to a temporary
    beside it, flushed and renamed (:func:`atomic_write`), so a file under its final name
    is complete; temporaries of a killed writer are removed when a store opens the folder
    (``removed``). A part that cannot be read, stores another key or another content
    than its digest, or fails the caller's ``check`` is damaged: moved aside to
    ``<file>.bad`` (replacing an older one), named in one ``log`` line, and computed
    again.

    A folder without ``store.json`` that holds anything (the parts of an opa-mc version
    before this store, or files that are not a store's) is refused with one message
    naming it: remove it to start over. So is a folder of another format (format 1: its
    parts carry no content digest) or another job.

    With ``lock``, the store takes the folder's lock (:class:`opa._lock.OutputLock`)
    before it looks at anything: a folder another running process writes is refused
    (``OutputInUse``, a ValueError naming that process), a lock left by a dead process is
    taken over (one ``log`` line). The lock is held until :meth:`close` (or the end of a
    ``with`` block, or the store's collection, or :func:`remove_store` of the folder in
    this process). Stores written by several processes at once (the trust map's tasks,
    each with its own ``Store`` of OUTDIR/parts) take none: their run locks OUTDIR.

    Parameters
    ----------
    directory : the folder (created if missing).
    job : what the folder holds, for messages ("Monte Carlo checkpoint", "sweep", ...).
    settings : JSON-able dict of everything one run depends on, for a folder that holds
        one run (a checkpoint, a sweep's points): a folder written with other settings is
        refused naming the first difference. None: the folder is shared by runs (the
        trust map's parts), each part found by its own inputs alone.
    log : callable taking one line (damaged parts, a stale lock taken over); default
        ``warnings.warn`` (RuntimeWarning) for parts, the ``opa_mc`` logger for a lock.
    lock : take the folder's lock (above); default False.

    Examples
    --------
    >>> import tempfile
    >>> store = Store(tempfile.mkdtemp(), "example")
    >>> store.get("square", {"x": 3}, lambda: {"y": 9})["y"]
    9
    >>> store.get("square", {"x": 3}, lambda: {"y": -1})["y"], store.computed  # read back
    (9, 1)
    """

    def __init__(self, directory: str | os.PathLike, job: str, settings: dict | None = None,
                 log: Callable[[str], object] | None = None, *, lock: bool = False):
        self.directory = os.fspath(directory)
        self.job = job
        self.log = log if log is not None else _warn
        self.computed = 0  # parts written by this object
        self.set_aside = 0  # damaged parts it moved aside
        if os.path.exists(self.directory) and not os.path.isdir(self.directory):
            raise ValueError(f"{job} {self.directory!r} is not a directory")
        self.lock = None
        self._release = None
        if lock:
            self.lock = OutputLock(self.directory, job, folder=True, log=log).acquire()
            self._release = weakref.finalize(self, self.lock.release)
        try:
            self._open(settings)
        except BaseException:
            self.close()
            raise

    def _open(self, settings: dict | None) -> None:
        job = self.job
        os.makedirs(self.directory, exist_ok=True)
        self.removed = sorted(clean_stale_temporaries(self.directory))
        header = {"format": STORE_FORMAT, "job": job,
                  "settings": None if settings is None else _plain(settings)}
        marker = os.path.join(self.directory, STORE_MARKER)
        if os.path.exists(marker):
            self._check(marker, header)
        else:
            found = sorted(n for n in os.listdir(self.directory)
                           if not n.startswith((TEMP_PREFIX, LOCK_NAME)))
            if found:
                raise ValueError(
                    f"{job} {self.directory!r} holds files but no {STORE_MARKER} ({found[0]}"
                    f"{', ...' if len(found) > 1 else ''}): the parts of an opa-mc version "
                    f"before the one store, or not a {job}'s; remove it (or name another "
                    f"folder) to start over")
            text = json.dumps(header, indent=1, sort_keys=True)
            atomic_write(marker, lambda tmp: _write_text(tmp, text), suffix=".json",
                         clean=False)
        self.header = header

    def close(self) -> None:
        """Release the folder's lock, if the store took it (again: nothing)."""
        if self._release is not None:
            self._release()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _check(self, marker: str, header: dict) -> None:
        where = f"{self.job} {self.directory!r}"
        try:
            with open(marker, encoding="utf-8") as file:
                old = json.load(file)
            if not isinstance(old, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as err:
            raise ValueError(f"{where} has an unreadable {STORE_MARKER} ({err}); remove it "
                             f"to start over") from None
        if old.get("format") == "opa-mc store 1":
            raise ValueError(f"{where} holds parts of format 'opa-mc store 1', written "
                             f"without the digests of their contents that this version "
                             f"({STORE_FORMAT!r}) checks on resume: remove it to start "
                             f"over")
        if old.get("format") != STORE_FORMAT:
            raise ValueError(f"{where} holds parts of another format ({old.get('format')!r}; "
                             f"this version reads {STORE_FORMAT!r}): remove it to start over")
        if old.get("job") != header["job"]:
            raise ValueError(f"{where} holds the parts of a {old.get('job')}, not of a "
                             f"{header['job']}: name another folder")
        found = _first_difference(old.get("settings"), header["settings"])
        if found:
            key, before, now = found
            raise ValueError(f"{where} belongs to another run: {key} is {_short(before)} "
                             f"there, {_short(now)} here; rerun it with its own settings to "
                             f"finish it, or remove it to start over")

    # -- parts -------------------------------------------------------------------------
    def key(self, inputs) -> str:
        """The key of a part: the digest of the store's settings and the part's inputs."""
        return digest({"settings": self.header["settings"], "inputs": inputs})

    def path(self, name: str, inputs, suffix: str = ".npz") -> str:
        """The file of part ``name`` with ``inputs``."""
        return self._where(name, self.key(inputs), suffix)

    def _where(self, name: str, key: str, suffix: str) -> str:
        if suffix not in _SUFFIXES:
            raise ValueError(f"a part's suffix must be one of {_SUFFIXES}, got {suffix!r}")
        return os.path.join(self.directory, f"{name}_{key[:12]}{suffix}")

    def load(self, name: str, inputs, suffix: str = ".npz", check=None):
        """The part, or None: absent, or damaged (then moved aside and logged).

        ``.npz``: a dict (0-d entries as Python scalars); ``.nc``: an xarray Dataset;
        ``.json``: the JSON value saved. ``check(content)`` returns what is wrong with a
        part that reads, stores its key and matches its digest, or None."""
        key = self.key(inputs)
        return self._load(self._where(name, key, suffix), key, suffix, check)

    def _load(self, path: str, key: str, suffix: str, check):
        if not os.path.lexists(path):
            return None
        try:
            stored, sealed, content, form = _READ[suffix](path)
            if stored is None:
                reason = "stores no key"
            elif stored != key:
                reason = f"stores the key {stored[:12]}, not {key[:12]}: other inputs"
            elif sealed is None:
                reason = "stores no digest of its content (written by another version?)"
            elif sealed != content_digest(key, form):
                reason = ("its content differs from the digest it was written with: "
                          "edited or corrupted since")
            else:
                reason = None
        except Exception as err:  # noqa: BLE001 -- whatever makes it unreadable: recompute
            reason = f"cannot be read ({type(err).__name__}: {err})".replace("\n", " ")
        else:
            if reason is None:
                reason = None if check is None else check(content)
                if reason is None:
                    return content
        file = os.path.basename(path)
        try:
            os.replace(path, path + ".bad")
            where = f"moved aside to {file}.bad"
        except OSError as err:
            where = f"could not be moved aside ({err})"
        self.set_aside += 1
        self.log(f"{self.job} part {path} is damaged ({reason}); {where}, computing it again")
        return None

    def save(self, name: str, inputs, content, suffix: str = ".npz") -> None:
        """Write part ``name`` atomically, with its key and the digest of its content."""
        key = self.key(inputs)
        self._save(self._where(name, key, suffix), key, content, suffix)

    def _save(self, path: str, key: str, content, suffix: str) -> None:
        if suffix == ".npz" and (KEY_ENTRY in content or DIGEST_ENTRY in content):
            raise ValueError(f"{KEY_ENTRY} and {DIGEST_ENTRY} are reserved names in a part")
        atomic_write(path, lambda tmp: _WRITE[suffix](tmp, content, key), suffix=suffix,
                     clean=False)

    def get(self, name: str, inputs, compute: Callable[[], object], suffix: str = ".npz",
            check=None):
        """The part ``name`` with ``inputs``: loaded, or ``compute()``-d, saved and read
        back (so that a fresh result and a reused one are the same to the bit)."""
        key = self.key(inputs)  # once: the digest of large inputs is not free
        path = self._where(name, key, suffix)
        found = self._load(path, key, suffix, check)
        if found is not None:
            return found
        content = compute()  # before the temporary exists: a kill here leaves nothing
        self._save(path, key, content, suffix)
        self.computed += 1
        return _READ[suffix](path)[2]


def remove_store(directory: str | os.PathLike) -> None:
    """Delete a store folder's files once its job's result is safely written.

    Only what a store holds (its marker, part files, ``.bad`` parts, stale temporaries,
    this process's lock or a stale one) is removed; the folder itself goes when nothing
    else is left in it. A missing folder is fine; a folder whose lock another running
    process holds is left alone.
    """
    directory = os.fspath(directory)
    if not os.path.isdir(directory) or holder_elsewhere(directory, folder=True) is not None:
        return
    clean_stale_temporaries(directory)
    for name in os.listdir(directory):
        if name == STORE_MARKER or _PART.fullmatch(name) or name.startswith(
                f"{TEMP_PREFIX}{os.getpid()}-"):
            try:
                os.remove(os.path.join(directory, name))
            except OSError:
                pass
    forget(directory, folder=True)  # this process's lock
    if holder_elsewhere(directory, folder=True) is None:
        try:
            os.remove(os.path.join(directory, LOCK_NAME))  # a stale one
        except OSError:
            pass
    try:
        os.rmdir(directory)
    except OSError:  # something else lives there
        pass


def _write_text(path: str, text: str) -> None:
    with open(path, "w", encoding="utf-8") as file:
        file.write(text)


# Each reader returns (key, digest stored, content, what the digest covers); each writer
# stores the digest of the content as its reader gives it back.

def _write_npz(path: str, content: dict, key: str) -> None:
    arrays = {name: np.asanyarray(value) for name, value in content.items()}
    with open(path, "wb") as file:
        np.savez(file, **arrays, **{KEY_ENTRY: np.str_(key),
                                    DIGEST_ENTRY: np.str_(content_digest(key, arrays))})


def _read_npz(path: str):
    # our own handle: np.load leaks its file when the archive is damaged
    with open(path, "rb") as file, np.load(file, allow_pickle=False) as npz:
        arrays = {name: npz[name] for name in npz.files}  # reads, CRCs all
    stored, sealed = arrays.pop(KEY_ENTRY, None), arrays.pop(DIGEST_ENTRY, None)
    content = {name: (a.item() if a.ndim == 0 else a) for name, a in arrays.items()}
    return (None if stored is None else str(stored)), \
        (None if sealed is None else str(sealed)), content, arrays


def _write_nc(path: str, ds, key: str) -> None:
    ds = ds.copy(deep=False)
    ds.attrs = {k: v for k, v in ds.attrs.items() if k != DIGEST_ENTRY}
    ds.attrs[KEY_ENTRY] = key
    ds.to_netcdf(path, engine="netcdf4")
    # the digest of the dataset as it reads back (netCDF turns attributes into numpy
    # values, masks fill values, ...), added beside the key
    form = _read_nc(path)[3]
    import netCDF4

    with netCDF4.Dataset(path, "a") as nc:
        nc.setncattr(DIGEST_ENTRY, content_digest(key, form))


def _read_nc(path: str):
    with xr.open_dataset(path, engine="netcdf4") as ds:
        ds = ds.load()
    stored = ds.attrs.pop(KEY_ENTRY, None)
    sealed = ds.attrs.pop(DIGEST_ENTRY, None)
    return (None if stored is None else str(stored)), \
        (None if sealed is None else str(sealed)), ds, _dataset_form(ds)


def _write_json(path: str, content, key: str) -> None:
    content = json.loads(json.dumps(content))  # as it reads back
    _write_text(path, json.dumps({KEY_ENTRY: key, DIGEST_ENTRY: content_digest(key, content),
                                  "content": content}))


def _read_json(path: str):
    with open(path, encoding="utf-8") as file:
        data = json.load(file)
    if not isinstance(data, dict) or "content" not in data:
        raise ValueError("not a part")
    stored, sealed = data.get(KEY_ENTRY), data.get(DIGEST_ENTRY)
    return (None if stored is None else str(stored)), \
        (None if sealed is None else str(sealed)), data["content"], data["content"]


_WRITE = {".npz": _write_npz, ".nc": _write_nc, ".json": _write_json}
_READ = {".npz": _read_npz, ".nc": _read_nc, ".json": _read_json}


def _warn(message: str) -> None:
    warnings.warn(message, RuntimeWarning, stacklevel=4)
