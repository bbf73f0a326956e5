"""A directory of finished Monte Carlo chunks, so that an interrupted run resumes.

The directory is an :class:`opa._dataset.Store` (the one resume store) holding one run::

    store.json                           the store's format and the run's settings (below)
    chunk-000003-192-256_<key>.npz       chunk 3 = samples 192..255: its ChunkStats
                                         fields, n_impacts, the paths when kept

The settings are everything that determines the result: the oscillator, the solver
options, sigma, the uncertain parameter, the sampler, seed, samples and replicates, the
order, the output times, the law of xi, the chunk bounds and keep_paths, digests of the
sample points and weights (so a change in the sampler's library is noticed too), the
version, and the format of the chunk files (``FORMAT``). A rerun with the same directory
and identical settings loads the finished chunks; any difference means the directory
belongs to another run and is refused, naming the first difference; so is a directory of
an older version (without ``store.json``). A chunk file that is damaged or does not fit
is moved aside to ``.bad``, named in the log and computed again; so is a chunk file edited
since it was written (each carries the digest of its content). The chunks are merged in
their fixed order whether loaded or computed, so the resumed result is bit-identical.

The directory is locked while the checkpoint is open (``Store(lock=True)``,
:mod:`opa._lock`): a second run on the same directory is refused at once with one line
naming the process that writes it; the lock of a killed run is taken over (one log line).
It is released by :meth:`Checkpoint.close`, when the checkpoint is collected (at the end
of ``simulate_mc``), by ``remove_checkpoint`` in the same process, or at exit.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections.abc import Callable, Iterator

import numpy as np

from opa.engine import DaskError, SimulationError, remove_store, Store

# Version of the chunk files' contents. 2: ChunkStats gained x_moment_m2 and x_moment_rep
# (the coefficients' standard errors); chunks of format 1 lack them.
FORMAT = "opa-mc monte-carlo checkpoint 2"


class Checkpoint:
    """The finished chunks of one run, in ``directory`` (a :class:`opa._dataset.Store`).

    Parameters
    ----------
    directory : the checkpoint directory (created if missing).
    manifest : JSON-able dict of everything that determines the result.
    log : callable taking one line, for damaged chunk files; default ``warnings.warn``.

    Raises
    ------
    ValueError
        The directory belongs to another run, to an older version, is not a directory,
        or another running process writes it (``OutputInUse``, naming that process).
    """

    def __init__(self, directory: str | os.PathLike, manifest: dict,
                 log: Callable[[str], object] | None = None):
        self.store = Store(directory, "Monte Carlo checkpoint",
                           settings={"format": FORMAT, **manifest}, log=log, lock=True)
        self.directory = self.store.directory

    def close(self) -> None:
        """Release the directory's lock (also done when the checkpoint is collected)."""
        self.store.close()

    @staticmethod
    def _name(index: int) -> str:
        return f"chunk-{index:06d}"

    def path(self, index: int, lo: int, hi: int) -> str:
        return self.store.path(f"{self._name(index)}-{lo}-{hi}", [lo, hi])

    def finished(self, bounds, check) -> set[int]:
        """Indices of the chunks whose files load and pass ``check(arrays, lo, hi)``
        (which returns None, or what is wrong); damaged files are moved aside."""
        return {index for index, (lo, hi) in enumerate(bounds)
                if self.load(index, lo, hi, check) is not None}

    def load(self, index: int, lo: int, hi: int, check) -> dict | None:
        """The arrays of chunk ``index``, or None (logged, file renamed ``.bad``) when its
        file is damaged; None without a message when it is missing."""
        return self.store.load(f"{self._name(index)}-{lo}-{hi}", [lo, hi],
                               check=lambda content: check(_arrays(content), lo, hi))

    def save(self, index: int, lo: int, hi: int, arrays: dict) -> None:
        self.store.save(f"{self._name(index)}-{lo}-{hi}", [lo, hi], arrays)


def _arrays(content: dict) -> dict:
    # the store gives 0-d entries back as Python scalars: the fields' dtypes are checked
    for name, value in content.items():
        content[name] = np.asarray(value)
    return content


def remove_checkpoint(directory: str | os.PathLike) -> None:
    """Delete a checkpoint directory once its run's result is safely written.

    Only the files a checkpoint holds (``store.json``, chunk files, ``.bad`` chunk files,
    stale temporaries) are removed; the directory itself goes when nothing else is left
    in it. A missing directory is fine.
    """
    remove_store(directory)


def checkpoint_for(out: str | os.PathLike | None) -> str | None:
    """The checkpoint folder of a run whose result is written to ``out``: ``OUT.parts``
    beside it (None without ``out``: nothing is kept).

    >>> checkpoint_for("runs/mc.nc"), checkpoint_for(None)
    ('runs/mc.nc.parts', None)
    """
    return None if out is None or os.fspath(out) == "" else f"{os.fspath(out)}.parts"


@contextlib.contextmanager
def checkpoint_lifetime(directory: str | os.PathLike | None, *,
                        keep: bool = False) -> Iterator[None]:
    """Apply the lifetime rules of a run's checkpoint ``directory`` to the block that
    runs the ensemble, checks its result and writes it:

    - the block ends (the result is written): the checkpoint is removed, unless ``keep``;
    - it raises :class:`opa.SimulationError` (a sample that cannot be integrated, a
      result that is not finite): removed, since every rerun of these settings fails
      the same way and would only trip over it;
    - it raises :class:`DaskError` (a lost cluster): kept, so that a rerun resumes from
      the finished chunks; so for anything else (an interruption, a refused or unwritable
      path, a checkpoint of another run, which is never ours to delete).

    ``directory`` None (no checkpoint) makes this a no-op.
    """
    try:
        yield
    except SimulationError as err:
        if directory is not None and not isinstance(err, DaskError):
            remove_checkpoint(directory)
        raise
    if directory is not None and not keep:
        remove_checkpoint(directory)


def stats_arrays(stats) -> dict:
    """The fields of a ChunkStats as arrays (scalars as 0-d arrays), for ``save``."""
    return {f.name: np.asarray(getattr(stats, f.name)) for f in dataclasses.fields(stats)}
