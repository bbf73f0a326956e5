"""How batch work runs: one record, :class:`Execution`, for every command that runs batches.

A Monte Carlo ensemble, a sweep, the stochastic diagram, the trust map and the
convergence study all say *what* to compute with their own arguments, and *how* to run it
with this one record:

* where: in this process (``workers=1``, the default), on ``workers`` local processes
  (each with its share of the cores as numba threads), or on a Dask cluster
  (``scheduler``: an address or a ``distributed.Client``), or a GPU (``device``);
* what is kept: ``checkpoint``, a folder where finished pieces are written as they finish
  and read back by a rerun (an interrupted run resumes);
* what is shown: ``progress`` (a bar on stderr; default when stderr is a terminal) and
  ``log`` (a callable taking one line: resume notes, damaged parts, per-piece lines).

The Dask side has one connection rule (:func:`connect_scheduler`: a scheduler must answer
within ``connect_timeout``, refused in one line naming it otherwise) and one policy for
lost workers (:class:`Watchdog`: a cluster with no worker for ``worker_timeout`` seconds,
or a task that killed the workers that ran it, fails the run with :class:`DaskError`).
Results never depend on where the work ran: every batch is a pure function of its inputs.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from opa._model import check_count, check_device, check_scheduler_address
from opa._run import SimulationError

#: seconds a Dask scheduler has to answer
CONNECT_TIMEOUT = 5.0
#: seconds a Dask cluster may have no worker before the run fails
WORKER_TIMEOUT = 60.0
#: a day: longer Dask timeouts are mistakes, not waits
MAX_TIMEOUT = 86400.0
#: seconds between checks that a Dask cluster still has workers
POLL = 0.5


class DaskError(SimulationError):
    """The Dask cluster failed the run: its workers all died, it never had any, or the
    scheduler went away. (A SimulationError, so the CLI reports it as a failed run.)"""


def _timeout(name: str, value, optional: bool) -> float | None:
    if value is None and optional:
        return None
    try:
        good = (not isinstance(value, (bool, str, bytes)) and math.isfinite(float(value))
                and 0 < float(value) <= MAX_TIMEOUT)
    except (TypeError, ValueError, OverflowError):
        good = False
    if not good:
        allowed = f"a number of seconds in (0, {MAX_TIMEOUT:g}]" + (" or None" if optional
                                                                    else "")
        raise ValueError(f"{name} must be {allowed}, got {value!r}")
    return float(value)


def _is_client(value) -> bool:
    """Whether ``value`` is a ``distributed.Client`` (without importing distributed when
    it was never imported: then it cannot be one)."""
    module = sys.modules.get("distributed")
    return module is not None and isinstance(value, module.Client)


@dataclass(frozen=True)
class Execution:
    """How a command's batches run (module docstring); the science is in the command's
    own arguments, so the same inputs give the same result under any Execution.

    Parameters
    ----------
    workers : local processes (1: in this process, numba's threads sharing the cores).
        Ignored with ``scheduler`` or ``device="cuda"``.
    scheduler : a Dask scheduler address (``tcp://host:8786``) or a
        ``distributed.Client``; the batches then run there as tasks.
    device : "cpu" (default) or "cuda" (the Monte Carlo ensembles' trajectories on a
        CUDA GPU, in this process: not with ``scheduler``).
    progress : a progress bar on stderr; None (default): when stderr is a terminal.
    log : a callable taking one line (resume notes, damaged parts set aside, one line a
        finished piece where the command has them), or None: silence.
    checkpoint : a folder where finished pieces are kept as they finish, so that a rerun
        with the same folder and inputs resumes; None: nothing is kept.
    chunk_size : samples per batch of a Monte Carlo ensemble (None: about 32 MiB of paths
        a batch). The result depends on it in the last bits (its sums' order), never on
        the rest of this record.
    connect_timeout : seconds the Dask scheduler has to answer.
    worker_timeout : seconds a Dask cluster may have no worker at all before the run
        fails (:class:`DaskError`); None waits forever.
    executor : a ``concurrent.futures`` executor to reuse instead of starting a pool (a
        warm pool shared by several sweeps).

    >>> Execution(workers=2).workers
    2
    >>> Execution(worker_timeout=-1)
    Traceback (most recent call last):
    ...
    ValueError: worker_timeout must be a number of seconds in (0, 86400] or None, got -1
    """

    workers: int = 1
    scheduler: object = None
    device: str = "cpu"
    progress: bool | None = None
    log: Callable[[str], object] | None = None
    checkpoint: str | os.PathLike | None = None
    chunk_size: int | None = None
    connect_timeout: float = CONNECT_TIMEOUT
    worker_timeout: float | None = WORKER_TIMEOUT
    executor: object = None

    def __post_init__(self):
        object.__setattr__(self, "workers", check_count("workers", self.workers))
        if self.scheduler is not None and not _is_client(self.scheduler):
            if not isinstance(self.scheduler, str):
                raise ValueError(f"scheduler must be an address such as 'tcp://host:8786' "
                                 f"or a distributed.Client, got {self.scheduler!r:.60}")
            check_scheduler_address(self.scheduler)
        check_device(self.device)
        if self.device == "cuda" and self.scheduler is not None:
            raise ValueError('device="cuda" runs in this process: not with scheduler')
        if self.progress not in (True, False, None) or isinstance(self.progress, str):
            raise ValueError(f"progress must be True, False or None, got {self.progress!r}")
        if self.log is not None and not callable(self.log):
            raise ValueError(f"log must be a callable taking one line, or None, got "
                             f"{self.log!r:.60}")
        if self.checkpoint is not None and not isinstance(self.checkpoint,
                                                          (str, os.PathLike)):
            raise ValueError(f"checkpoint must be a directory path, got "
                             f"{self.checkpoint!r:.60}")
        if self.chunk_size is not None:
            try:
                size = check_count("chunk_size", self.chunk_size)
            except ValueError as err:
                raise ValueError(str(err) if "at most" in str(err) else
                                 f"chunk_size must be a positive integer, got "
                                 f"{self.chunk_size!r}") from None
            object.__setattr__(self, "chunk_size", size)
        object.__setattr__(self, "connect_timeout",
                           _timeout("connect_timeout", self.connect_timeout, False))
        object.__setattr__(self, "worker_timeout",
                           _timeout("worker_timeout", self.worker_timeout, True))
        if self.executor is not None and not hasattr(self.executor, "submit"):
            raise ValueError(f"executor must be a concurrent.futures executor, got "
                             f"{self.executor!r:.60}")

    def only(self, where: str, *used: str) -> Execution:
        """This record, refusing a field set away from its default that ``where`` does
        not use (``progress`` and ``log`` are always taken: they only show)."""
        default = Execution()
        for f in dataclasses.fields(self):
            if f.name in (*used, "progress", "log"):
                continue
            value = getattr(self, f.name)
            if value != getattr(default, f.name):
                raise ValueError(f"{where} does not use the execution's {f.name} "
                                 f"({value!r:.40}); it takes {', '.join(used)}")
        return self

    def replace(self, **changes) -> Execution:
        """A copy with ``changes`` (checked like a new one)."""
        return dataclasses.replace(self, **changes)

    @property
    def shows_progress(self) -> bool:
        """Whether a bar is drawn: ``progress``, or when it is None whether stderr is a
        terminal."""
        return sys.stderr.isatty() if self.progress is None else bool(self.progress)

    def say(self, line: str) -> None:
        """One line to ``log`` (nothing without one)."""
        if self.log is not None:
            self.log(line)

    def bar(self, total: int, *, desc: str, unit: str = "it", initial: int = 0):
        """The one progress display: a tqdm bar on stderr, disabled unless
        :attr:`shows_progress`."""
        from tqdm.auto import tqdm

        return tqdm(total=total, initial=initial, unit=unit, desc=desc,
                    disable=not self.shows_progress)

    @contextmanager
    def client(self) -> Iterator[object]:
        """The Dask client of ``scheduler`` for the block (None without one), connected
        by :func:`connect_scheduler` and closed after the block when this record opened
        it; a Client given by the caller stays open."""
        if self.scheduler is None:
            yield None
            return
        client, own = connect_scheduler(self.scheduler, self.connect_timeout)
        try:
            yield client
        finally:
            if own:
                client.close()

    def watchdog(self, client, unfinished: Callable[[], int] = lambda: 0,
                 unit: str = "tasks") -> Watchdog:
        """The lost-worker policy of this record for ``client`` (``unfinished()``: how many
        ``unit`` are left, for its message)."""
        return Watchdog(client, self.worker_timeout, unfinished, unit)


def as_execution(execution: Execution | None) -> Execution:
    """``execution``, or the default record (in this process, no checkpoint) for None."""
    if execution is None:
        return Execution()
    if not isinstance(execution, Execution):
        raise ValueError(f"execution must be an opa.Execution, got {execution!r:.60}")
    return execution


#: the keywords an Execution's fields had before there was one (still taken, for a release)
EXECUTION_KEYWORDS = ("workers", "scheduler", "device", "progress", "log", "checkpoint",
                      "chunk_size", "connect_timeout", "worker_timeout", "executor")


def take_execution(execution: Execution | None, keywords: dict, where: str,
                   defaults: dict | None = None) -> Execution:
    """The Execution of a call: ``execution``, or one made of ``defaults`` (the caller's
    own, e.g. a sweep's two workers) and the execution keywords still found among a
    call's ``keywords`` (removed from them: the keywords of earlier releases, e.g.
    ``simulate_mc(scheduler=...)``); both at once is refused."""
    given = {k: keywords.pop(k) for k in EXECUTION_KEYWORDS if k in keywords}
    if given and execution is not None:
        raise ValueError(f"{where}: give {', '.join(sorted(given))} inside execution="
                         f"Execution(...), not beside it")
    if execution is not None:
        return as_execution(execution)
    return Execution(**{**(defaults or {}), **given})


def connect_scheduler(scheduler, connect_timeout: float = CONNECT_TIMEOUT):
    """(client, whether we own it) for an address or a ``distributed.Client``; a Client
    is returned as it is. An address is checked before anything is contacted (a Client of
    an address that is none would stay distributed's default client), and must answer as a
    Dask scheduler within ``connect_timeout`` seconds: otherwise ValueError naming it."""
    try:
        from distributed import Client
    except ImportError:
        raise ValueError("scheduler needs the 'distributed' package") from None
    if isinstance(scheduler, Client):
        return scheduler, False
    if not isinstance(scheduler, str):
        raise ValueError(f"scheduler must be an address such as 'tcp://host:8786' or a "
                         f"distributed.Client, got {scheduler!r:.60}")
    check_scheduler_address(scheduler)
    silent = f"scheduler {scheduler!r} did not answer within {connect_timeout:g} s " \
             f"(connect_timeout); check the address and that the scheduler is running"
    _probe(scheduler, connect_timeout, silent)
    try:
        return Client(scheduler, timeout=connect_timeout), True
    except (OSError, TimeoutError):
        raise ValueError(silent) from None
    except (ValueError, TypeError) as err:
        raise ValueError(f"scheduler {scheduler!r} is not a Dask scheduler address "
                         f"({err})") from None
    except (Exception, MemoryError) as err:  # noqa: BLE001 -- it answered, but not as Dask
        raise ValueError(f"scheduler {scheduler!r} did not answer as a Dask scheduler "
                         f"({type(err).__name__})") from None


def _probe(address: str, timeout: float, silent: str) -> None:
    """A Dask scheduler speaks first on a new TCP connection: refuse an endpoint that
    accepts the connection and then says nothing within ``timeout`` (distributed's own
    connect would wait for it much longer). Only plain ``tcp://`` addresses are probed."""
    import socket
    from urllib.parse import urlsplit

    if not address.startswith("tcp://"):
        return
    try:
        parts = urlsplit(address)
        host, port = parts.hostname, parts.port
    except ValueError:
        return  # distributed names what is wrong with the address
    if host is None or port is None:
        return
    try:
        with socket.create_connection((host, port), timeout=timeout) as probe:
            probe.settimeout(timeout)
            first = probe.recv(1)
    except OSError:
        raise ValueError(silent) from None
    if not first:
        raise ValueError(silent)


class Watchdog:
    """The one lost-worker policy: fails the run when the cluster has had no worker for
    ``timeout`` seconds (None: never); waits last ``poll`` seconds between checks."""

    def __init__(self, client, timeout: float | None, unfinished: Callable[[], int],
                 unit: str = "tasks"):
        self.client = client
        self.unit = unit
        self.timeout = timeout
        self.unfinished = unfinished
        self.poll = POLL if timeout is None else min(POLL, timeout / 4)
        self.empty_since = None  # when the cluster was first seen without workers

    def check(self) -> None:
        if self.timeout is None:
            return
        try:
            workers = len(self.client.nthreads())
        except (OSError, TimeoutError) as err:
            raise DaskError(f"lost the Dask scheduler ({err})") from None
        now = time.monotonic()
        if workers:
            self.empty_since = None
        elif self.empty_since is None:
            self.empty_since = now
        elif now - self.empty_since > self.timeout:
            raise DaskError(f"the Dask cluster has had no workers for {self.timeout:g} s "
                            f"(all died or none started) with {self.unfinished()} {self.unit} "
                            f"unfinished; start workers or raise worker_timeout")

    def result(self, future, what: str):
        """A task's result, watched (a finished task's result can still be lost with its
        worker, and the scheduler then computes it again); cluster failures become
        :class:`DaskError` naming ``what`` the task was."""
        from concurrent.futures import CancelledError

        from distributed import KilledWorker

        while True:
            try:
                return future.result(timeout=self.poll)
            except TimeoutError:
                self.check()
            except KilledWorker as err:
                first = str(err).splitlines()[0] if str(err) else "KilledWorker"
                raise DaskError(f"Dask workers died running {what}: {first}") from None
            except CancelledError:
                raise DaskError(f"the Dask scheduler dropped the task of {what} (it "
                                f"restarted or went away)") from None

    def finished(self, futures: Iterable) -> Iterator[object]:
        """The futures as they finish, watched: a cluster left without workers stops the
        wait with :class:`DaskError` instead of waiting forever."""
        from distributed import wait

        pending = set(futures)
        while pending:
            try:
                done = wait(pending, timeout=self.poll, return_when="FIRST_COMPLETED").done
            except TimeoutError:
                self.check()
                continue
            for future in done:
                pending.discard(future)
                yield future


__all__ = ["CONNECT_TIMEOUT", "WORKER_TIMEOUT", "DaskError", "Execution", "Watchdog",
           "as_execution", "connect_scheduler",
           "take_execution", "EXECUTION_KEYWORDS"]
