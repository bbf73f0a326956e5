"""The trust map's independent tasks on a local process pool or a Dask cluster.

The map splits into tasks that share nothing but the parts folder: one per swept value
(its split scan, its grid of points, the bisections of its sigma*, its datasets) and the
cost-accuracy frontier. :func:`run_tasks` runs them

* in this process, one after the other (``workers=1``, no scheduler): numba's threads
  share the cores inside each task;
* on ``workers`` local processes (:func:`opa.engine.local_executor`, started by a fork
  server), each with ``cores // workers`` numba threads, so the cores are not
  oversubscribed;
* on a Dask cluster (``scheduler``: an address or a ``distributed.Client``), each task
  with its machine's cores shared out among the tasks that can run there at once (the
  Dask threads of every worker on that host, :func:`dask_threads`).

Every task is a pure function of its arguments: the same inputs give the same arrays to
the bit wherever it runs, and the map assembled from them is the same.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator


#: seconds to wait for a Dask scheduler to answer
CONNECT_TIMEOUT = 5.0


def _threaded(threads: int | None, fn: Callable, args: tuple):
    """``fn(*args)`` with ``threads`` numba threads for the calling thread (None: on a
    Dask worker, :func:`dask_threads`)."""
    import numba

    if threads is None:
        threads = dask_threads()
    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    return fn(*args)


def dask_threads() -> int:
    """numba threads of a task on a Dask worker: the machine's cores shared out among the
    tasks that can run on it at once (the Dask threads of every worker on its host)."""
    try:
        from distributed import get_client, get_worker

        worker = get_worker()
        host = worker.address.rsplit(":", 1)[0]
        workers = get_client().scheduler_info()["workers"]
        slots = sum(int(w["nthreads"]) for address, w in workers.items()
                    if address.rsplit(":", 1)[0] == host) or worker.state.nthreads
    except (ImportError, ValueError, AttributeError, KeyError, OSError):
        return 1
    return max(1, (os.cpu_count() or 1) // max(1, slots))


def threads_per_worker(workers: int) -> int:
    """numba threads of each of ``workers`` local processes: the cores shared out."""
    return max(1, (os.cpu_count() or 1) // max(1, int(workers)))


def auto_workers(tasks: int, cores: int | None = None) -> int:
    """The default ``workers`` (0: auto): one process per core up to the number of
    tasks, where there are at least 3 tasks (a pool's start, 2-3 s, is not worth it for
    fewer); else 1.

    >>> auto_workers(6, cores=2), auto_workers(6, cores=16), auto_workers(2, cores=16)
    (2, 6, 1)
    """
    cores = (os.cpu_count() or 1) if cores is None else cores
    return min(cores, tasks) if tasks >= 3 and cores >= 2 else 1


def run_tasks(tasks: list[tuple[object, Callable, tuple]], *, workers: int = 1,
              scheduler=None) -> Iterator[tuple[object, object]]:
    """Run ``tasks`` = [(key, fn, args), ...]; yield (key, fn(*args)) as each finishes.

    In this process one by one when ``workers`` is 1 and there is no ``scheduler``, in
    the order given; else in the order they finish, never in this process (what a task
    counts in its own thread is its own). A task's exception is raised here.

    >>> list(run_tasks([("a", max, (1, 2)), ("b", min, (1, 2))]))
    [('a', 2), ('b', 1)]
    """
    if not tasks:
        return
    if scheduler is not None:
        yield from _run_dask(tasks, scheduler)
        return
    if workers <= 1:
        for key, fn, args in tasks:
            yield key, fn(*args)
        return
    from concurrent.futures import as_completed

    from opa.engine import local_executor

    threads = threads_per_worker(min(workers, len(tasks)))
    with local_executor(min(workers, len(tasks))) as pool:
        futures = {pool.submit(_threaded, threads, fn, args): key for key, fn, args in tasks}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:
            for future in futures:
                future.cancel()


def _run_dask(tasks, scheduler) -> Iterator[tuple[object, object]]:
    from distributed import as_completed, Client

    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT) if own else scheduler
    except (OSError, TimeoutError) as err:
        raise ValueError(f"scheduler {scheduler!r} did not answer as a Dask scheduler "
                         f"within {CONNECT_TIMEOUT:g} s ({type(err).__name__}); check the "
                         f"address and that the scheduler runs") from None
    try:
        futures = {client.submit(_threaded, None, fn, args, pure=False): key
                   for key, fn, args in tasks}
        for future in as_completed(futures):
            yield futures[future], future.result()
    finally:
        if own:
            client.close()


__all__ = ["CONNECT_TIMEOUT", "auto_workers", "dask_threads", "run_tasks", "threads_per_worker"]
