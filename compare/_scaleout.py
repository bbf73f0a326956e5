"""The trust map's tasks on a local process pool or a Dask cluster.

The map's tasks share nothing but the parts folder: split scans, grid points,
bisections, value assemblies and the frontier's runs (:mod:`compare._mapflow`), some
ready only once others have finished. :func:`run_flow` runs them

* in this process, one after the other (``workers=1``, no scheduler): numba's threads
  share the cores inside each task;
* on ``workers`` local processes (:func:`opa.engine.local_executor`, started by a fork
  server), the running tasks sharing the cores (:func:`share_cores`; the cores of this
  process's CPU affinity, :func:`opa.engine.usable_cores`) as numba threads: one each
  while as many tasks run as there are cores, more as fewer run. The shares are
  recomputed whenever a task starts or ends, and a running task reads its own before
  each parallel batch (:func:`opa.engine.follow_thread_grant`), so the last tasks of a
  flow take the cores the finished ones left while they run;
* on a Dask cluster (``scheduler``: an address or a ``distributed.Client``), each task
  with its machine's cores shared out among the tasks that can run there at once (the
  Dask threads of every worker on that host, :func:`dask_threads`).

Every task is a pure function of its arguments: the same inputs give the same arrays to
the bit wherever it runs, and the map assembled from them is the same.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator

from opa.engine import Execution, set_threads, take_execution, usable_cores


#: what the map's worker processes import once, in the fork server they come from: its
#: tasks, and the report's figures, drawn on processes of the same server
#: (:func:`compare._report.draw_figures`)
MAP_PRELOAD = ("compare._mapflow", "compare._report", "compare._mapfigures")
#: what the figures' processes import besides (0.6 s each on the 2-core machine, paid once
#: in the server instead)
FIGURE_PRELOAD = ("matplotlib.pyplot",)


def map_preload(plots: bool) -> tuple[str, ...]:
    """The fork server's imports for a map (:data:`MAP_PRELOAD`) and, where it draws
    figures, matplotlib's (:data:`FIGURE_PRELOAD`)."""
    return MAP_PRELOAD + (FIGURE_PRELOAD if plots else ())


def _threaded(threads: int | None, fn: Callable, args: tuple):
    """``fn(*args)`` with ``threads`` numba threads for the calling thread (None: on a
    Dask worker, :func:`dask_threads`)."""
    import numba

    if threads is None:
        threads = dask_threads()
    set_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    return fn(*args)


def _granted(slot: int, fn: Callable, args: tuple):
    """``fn(*args)`` on a local pool's worker, with the numba threads of its slot in the
    pool's grants (:func:`opa.engine.pool_shared`), read again before each parallel
    batch: the cores other tasks free while it runs are its to take."""
    from opa.engine import follow_thread_grant, pool_shared

    grants = pool_shared()
    follow_thread_grant(lambda: grants[slot])
    try:
        return fn(*args)
    finally:
        follow_thread_grant(None)


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
    return max(1, usable_cores() // max(1, slots))


def share_cores(cores: int, running: int) -> list[int]:
    """The numba threads of each of the ``running`` tasks of a local pool, oldest first:
    the cores shared out equally, the cores left over to the oldest tasks (the longest
    chains of a flow start first), at least one each. Recomputed whenever a task starts
    or ends, so the last tasks of a flow take the cores the finished ones left.

    >>> share_cores(16, 16), share_cores(16, 3), share_cores(2, 1), share_cores(2, 3)
    ([1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1], [6, 5, 5], [2], [1, 1, 1])
    """
    cores, running = max(1, int(cores)), int(running)
    return [max(1, cores // running + (k < cores % running)) for k in range(running)]


def auto_workers(tasks: int, cores: int | None = None) -> int:
    """The default ``workers`` (0: auto): one process per core up to the number of
    tasks, where there are at least 3 tasks (a pool's start, 2-3 s, is not worth it for
    fewer); else 1.

    >>> auto_workers(6, cores=2), auto_workers(6, cores=16), auto_workers(2, cores=16)
    (2, 6, 1)
    """
    cores = usable_cores() if cores is None else cores
    return min(cores, tasks) if tasks >= 3 and cores >= 2 else 1


def run_tasks(tasks: list[tuple[object, Callable, tuple]], *,
              execution: Execution | None = None, **legacy) -> Iterator[tuple[object, object]]:
    """Run ``tasks`` = [(key, fn, args), ...]; yield (key, fn(*args)) as each finishes
    (:func:`run_flow` with no followers; at most one process per task).

    >>> list(run_tasks([("a", max, (1, 2)), ("b", min, (1, 2))]))
    [('a', 2), ('b', 1)]
    """
    run = _execution(execution, legacy, "run_tasks")
    yield from run_flow(tasks, execution=run.replace(
        workers=min(run.workers, max(1, len(tasks)))))


def _execution(execution, legacy: dict, where: str) -> Execution:
    """The Execution of a flow: ``execution``, or the keywords ``workers`` and
    ``scheduler`` of earlier releases."""
    unknown = sorted(set(legacy) - {"workers", "scheduler"})
    if unknown:
        raise TypeError(f"{where}() got an unexpected keyword argument {unknown[0]!r}")
    return take_execution(execution, legacy, where).only(
        where, "workers", "scheduler", "connect_timeout", "worker_timeout")


def run_flow(tasks: list[tuple[object, Callable, tuple]],
             follow: Callable[[object, object], list] | None = None, *,
             preload: tuple[str, ...] = (), execution: Execution | None = None,
             **legacy) -> Iterator[tuple[object, object]]:
    """Run ``tasks`` = [(key, fn, args), ...] and the tasks that become ready as they
    finish: ``follow(key, result)``, called (here) as each finishes, returns the tasks it
    made ready (those that needed it). Yields (key, fn(*args)) as each finishes.

    Tasks start in the order given, the ones ``follow`` returned ahead of those not yet
    started (the work the rest waits on); at most ``workers`` run at once on a local
    pool, sharing the cores as numba threads (:func:`share_cores`, read by each task
    before each of its parallel batches). Where they run is ``execution``'s
    (:class:`opa.Execution`: ``workers``, ``scheduler``, its Dask connection timeout and
    lost-worker policy; the keywords ``workers`` and ``scheduler`` are still taken).
    With ``workers`` 1 and no ``scheduler`` they run in this process, one after the
    other; else never in this process (what a task counts in its own thread is its
    own). On a Dask cluster every ready task is submitted at once, the followers with a
    higher priority. A task's exception is raised here, and the tasks not yet finished
    are cancelled. ``preload``: modules the local pool's processes get imported
    (:func:`opa.engine.local_executor`).

    >>> follow = lambda key, result: [("b", abs, (-result,))] if key == "a" else []
    >>> list(run_flow([("a", max, (1, 2))], follow))
    [('a', 2), ('b', 2)]
    """
    follow = follow or (lambda key, result: [])
    run = _execution(execution, legacy, "run_flow")
    if run.scheduler is not None:
        yield from _flow_dask(tasks, follow, run)
        return
    workers = run.workers
    ready = deque(tasks)
    if workers <= 1:
        while ready:
            key, fn, args = ready.popleft()
            result = fn(*args)
            ready.extendleft(reversed(list(follow(key, result))))
            yield key, result
        return
    from concurrent.futures import FIRST_COMPLETED, wait

    from opa.engine import local_executor

    from multiprocessing.sharedctypes import RawArray

    workers, cores = int(workers), usable_cores()
    # each running task's numba threads, by its slot: written here whenever a task
    # starts or ends, read by the task before each of its parallel batches
    grants = RawArray("q", workers)
    free = list(range(workers - 1, -1, -1))
    running: dict = {}  # future: (key, slot), oldest first
    with local_executor(workers, preload, shared=grants) as pool:
        try:
            while ready or running:
                starting = [(ready.popleft(), free.pop())
                            for _ in range(min(len(ready), workers - len(running)))]
                slots = [slot for _, slot in running.values()] + [s for _, s in starting]
                for slot, threads in zip(slots, share_cores(cores, len(slots))):
                    grants[slot] = threads  # before the new tasks start
                for (key, fn, args), slot in starting:
                    running[pool.submit(_granted, slot, fn, args)] = key, slot
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for future in sorted(done, key=lambda f: _order(running[f][0])):
                    key, slot = running.pop(future)
                    free.append(slot)
                    result = future.result()
                    ready.extendleft(reversed(list(follow(key, result))))
                    yield key, result
        finally:
            for future in running:
                future.cancel()


def _order(key) -> str:
    """A fixed order among tasks that finish together (their keys as text)."""
    return repr(key)


def _flow_dask(tasks, follow, run: Execution) -> Iterator[tuple[object, object]]:
    """The flow on ``run``'s Dask cluster: connected, and its waits watched for lost
    workers, by the one rule of :class:`opa.Execution`."""
    from distributed import wait

    with run.client() as client:
        keys: dict = {}

        def submit(batch, priority):
            for i, (key, fn, args) in enumerate(batch):
                future = client.submit(_threaded, None, fn, args, pure=False,
                                       priority=priority - i)
                keys[future] = key

        watchdog = run.watchdog(client, lambda: len(keys), "tasks")
        try:
            submit(tasks, 0)
            followers = 0
            while keys:
                try:
                    done = wait(list(keys), timeout=watchdog.poll,
                                return_when="FIRST_COMPLETED").done
                except TimeoutError:
                    watchdog.check()
                    continue
                for future in sorted(done, key=lambda f: _order(keys[f])):
                    key = keys.pop(future)
                    result = watchdog.result(future, f"the task {key!r}")
                    more = list(follow(key, result))
                    if more:
                        followers += 1
                        submit(more, 1_000_000 * followers)
                    yield key, result
        finally:
            for future in keys:
                future.cancel()


__all__ = ["FIGURE_PRELOAD", "MAP_PRELOAD", "auto_workers", "dask_threads",
           "map_preload", "run_flow", "run_tasks", "share_cores"]
