"""A directory of finished Monte Carlo chunks, so that an interrupted run resumes.

Layout of a checkpoint directory::

    manifest.json                 everything that determines the result (below)
    chunk-000003-192-256.npz      chunk 3 = samples 192..255: its ChunkStats fields,
                                  n_impacts, the paths when kept, the manifest's digest

Every file is written to a temporary beside it and renamed (``opa._dataset.atomic_write``),
so a file under its final name is complete; temporaries of a killed run are removed at
the next start. The manifest records the oscillator, the solver options, sigma, the
uncertain parameter, the sampler, seed, samples and replicates, the order, the output
times, the law of xi, the chunk bounds and keep_paths, plus digests of the sample points
and weights (so a change in the sampler's library is noticed too). A rerun with the same
directory and an identical manifest loads the finished chunks; any difference means the
directory belongs to another run and is refused. The manifest also carries the format
of the chunk files (``FORMAT``): a directory written by a version whose chunks hold other
fields is refused the same way, naming both formats. The chunks are merged in their fixed
order whether loaded or computed, so the resumed result is bit-identical.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import warnings
from collections.abc import Callable

import numpy as np

from opa._dataset import TEMP_PREFIX, atomic_write, clean_stale_temporaries

MANIFEST = "manifest.json"
# Version of the chunk files' contents. 2: ChunkStats gained x_moment_m2 and x_moment_rep
# (the coefficients' standard errors); chunks of format 1 lack them.
FORMAT = "opa-mc monte-carlo checkpoint 2"
_CHUNK = re.compile(r"chunk-(\d+)-(\d+)-(\d+)\.npz")


def digest(array: np.ndarray) -> str:
    """sha256 of an array's dtype, shape and bytes (C order)."""
    array = np.ascontiguousarray(array)
    h = hashlib.sha256(f"{array.dtype.str}{array.shape}".encode())
    h.update(array.tobytes())
    return h.hexdigest()


def _plain(value):
    """``value`` as JSON would give it back (tuples as lists, numpy scalars as Python)."""
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
    return text if len(text) <= 24 else text[:12] + "..."


class Checkpoint:
    """The finished chunks of one run, in ``directory``.

    Parameters
    ----------
    directory : the checkpoint directory (created if missing).
    manifest : JSON-able dict of everything that determines the result.
    log : callable taking one line, for damaged chunk files; default ``warnings.warn``.

    Raises
    ------
    ValueError
        The directory holds the manifest of another run, chunk files without a manifest,
        or is not a directory.
    """

    def __init__(self, directory: str | os.PathLike, manifest: dict,
                 log: Callable[[str], object] | None = None):
        self.directory = os.fspath(directory)
        self.manifest = _plain({"format": FORMAT, **manifest})
        text = json.dumps(self.manifest, sort_keys=True)
        self.run = hashlib.sha256(text.encode()).hexdigest()
        self.log = log if log is not None else _warn
        if os.path.exists(self.directory) and not os.path.isdir(self.directory):
            raise ValueError(f"checkpoint {self.directory!r} is not a directory")
        os.makedirs(self.directory, exist_ok=True)
        clean_stale_temporaries(self.directory)
        path = os.path.join(self.directory, MANIFEST)
        if os.path.exists(path):
            self._check_manifest(path)
        else:
            if any(_CHUNK.fullmatch(name) for name in os.listdir(self.directory)):
                raise ValueError(f"checkpoint {self.directory!r} holds chunk files but no "
                                 f"{MANIFEST}: it belongs to another run or is damaged; "
                                 f"use a new directory or delete it")
            atomic_write(path, lambda tmp: _write_text(tmp, text), suffix=".json",
                         clean=False)

    def _check_manifest(self, path: str) -> None:
        try:
            with open(path, encoding="utf-8") as file:
                old = json.load(file)
        except (OSError, ValueError) as err:
            raise ValueError(f"checkpoint {self.directory!r} has an unreadable {MANIFEST} "
                             f"({err}); use a new directory or delete it") from None
        if isinstance(old, dict) and old.get("format") != FORMAT:
            raise ValueError(f"checkpoint {self.directory!r} holds chunks of another format "
                             f"({old.get('format', 'none')!r}; this version reads "
                             f"{FORMAT!r}): it cannot be resumed; use a new directory or "
                             f"delete it (mc.remove_checkpoint) to start over")
        found = _first_difference(old, self.manifest)
        if found:
            key, before, now = found
            raise ValueError(f"checkpoint {self.directory!r} belongs to another run: "
                             f"{key} is {_short(before)} there, {_short(now)} here; use a "
                             f"new directory or delete it to start over")

    # -- chunks ------------------------------------------------------------------------
    def path(self, index: int, lo: int, hi: int) -> str:
        return os.path.join(self.directory, f"chunk-{index:06d}-{lo}-{hi}.npz")

    def finished(self, bounds, check) -> set[int]:
        """Indices of the chunks whose files load and pass ``check(arrays, lo, hi)``
        (which returns None, or what is wrong); damaged files are moved aside."""
        names = set(os.listdir(self.directory))
        done = set()
        for index, (lo, hi) in enumerate(bounds):
            if os.path.basename(self.path(index, lo, hi)) in names:
                if self.load(index, lo, hi, check) is not None:
                    done.add(index)
        return done

    def load(self, index: int, lo: int, hi: int, check) -> dict | None:
        """The arrays of chunk ``index``, or None (logged, file renamed ``.bad``) when its
        file is damaged; None without a message when it is missing."""
        path = self.path(index, lo, hi)
        try:
            # our own handle: np.load leaks its file when the zip is unreadable
            with open(path, "rb") as file:
                data = np.load(file, allow_pickle=False)
                if not isinstance(data, np.lib.npyio.NpzFile):
                    raise ValueError("not an .npz archive")
                with data:
                    arrays = {name: data[name] for name in data.files}  # reads, CRCs all
            reason = None
            if str(arrays.get("run", "")) != self.run:
                reason = "written by another run"
            else:
                reason = check(arrays, lo, hi)
        except FileNotFoundError:
            return None
        except Exception as err:  # noqa: BLE001 - zip, zlib, format and OS errors alike
            reason = f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
        if reason is None:
            return arrays
        try:
            os.replace(path, path + ".bad")
            where = f"moved it to {path}.bad"
        except OSError as err:
            where = f"could not move it aside ({err})"
        self.log(f"checkpoint chunk {path} is damaged ({reason}); {where} and computing "
                 f"samples {lo}..{hi - 1} again")
        return None

    def save(self, index: int, lo: int, hi: int, arrays: dict) -> None:
        arrays = {**arrays, "run": np.array(self.run)}
        atomic_write(self.path(index, lo, hi), lambda tmp: np.savez(tmp, **arrays),
                     suffix=".npz", clean=False)


def remove_checkpoint(directory: str | os.PathLike) -> None:
    """Delete a checkpoint directory once its run's result is safely written.

    Only the files a checkpoint holds (the manifest, chunk files, ``.bad`` chunk files,
    stale temporaries) are removed; the directory itself goes when nothing else is left
    in it. A missing directory is fine.
    """
    directory = os.fspath(directory)
    if not os.path.isdir(directory):
        return
    clean_stale_temporaries(directory)
    for name in os.listdir(directory):
        chunk = _CHUNK.fullmatch(name.removesuffix(".bad"))
        ours = name == MANIFEST or chunk or name.startswith(f"{TEMP_PREFIX}{os.getpid()}-")
        if ours:
            try:
                os.remove(os.path.join(directory, name))
            except OSError:
                pass
    try:
        os.rmdir(directory)
    except OSError:  # something else lives there
        pass


def stats_arrays(stats) -> dict:
    """The fields of a ChunkStats as arrays (scalars as 0-d arrays), for ``save``."""
    return {f.name: np.asarray(getattr(stats, f.name)) for f in dataclasses.fields(stats)}


def _write_text(path: str, text: str) -> None:
    with open(path, "w", encoding="utf-8") as file:
        file.write(text)


def _warn(message: str) -> None:
    warnings.warn(message, RuntimeWarning, stacklevel=4)
