"""One mechanism for independent work: a list of picklable tasks in, their results out, in order.

``run_tasks(tasks, scheduler=...)`` runs each task (any picklable callable
taking no argument, e.g. a dataclass with ``__call__`` or a
``functools.partial`` of a module-level function) and returns the results in
the order of ``tasks``.  Where they run:

``"local"`` (default)
    A fresh ``dask.distributed.LocalCluster`` of worker *processes* on
    loopback (one thread each, one worker per core but no more than there are
    tasks), closed when the tasks are done.  A single task runs in-process.
``"tcp://HOST:8786"``
    An existing Dask cluster (``dask scheduler`` + ``dask worker``); the
    workers need this project installed and its caches (mesh, output
    operators) reachable or rebuildable.
``"serial"``
    In this process, one after the other (no Dask): for debugging, and the
    reference a distributed run must match.
a ``distributed.Client``
    Used as is (not closed).

Tasks should carry *names*, not big objects: a worker rebuilds what it needs
from the on-disk caches once per process and keeps it (see :func:`cached`),
e.g. ``build_machine(name, mesh_size)`` for the twin.  A task's exception is
re-raised here with its original type, so user errors keep their message.
BLAS is limited to one thread inside each task, so worker processes do not
oversubscribe the cores.
"""
from __future__ import annotations

import os
import threading
from collections.abc import Callable, Hashable, Iterable
from typing import TypeVar

from ..errors import TwinInputError

SERIAL = "serial"
LOCAL = "local"
_CACHE = {}
_CACHE_LOCK = threading.Lock()
T = TypeVar("T")


def cached(key: Hashable, factory: Callable[[], T]) -> T:
    """Per-process memo: ``factory()`` once per ``key`` in this process (a worker's machine, say).

    Parameters
    ----------
    key : hashable
        What the value is of.
    factory : callable
        Makes the value.

    Returns
    -------
    object
        The value made the first time ``key`` was asked for in this process.
    """
    with _CACHE_LOCK:
        if key in _CACHE:
            return _CACHE[key]
    value = factory()
    with _CACHE_LOCK:
        return _CACHE.setdefault(key, value)


def _call(task):
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl ships with scikit-learn
        return task()
    with threadpool_limits(1):
        return task()


def describe_scheduler(scheduler: str | object | None) -> str:
    """Where :func:`run_tasks` runs for a ``scheduler`` argument, in words (for reports).

    Parameters
    ----------
    scheduler : str or distributed.Client or None
        As :func:`run_tasks` takes it.

    Returns
    -------
    str
        E.g. ``"local Dask cluster"``.
    """
    if scheduler is None or scheduler == LOCAL:
        return "local Dask cluster"
    if scheduler == SERIAL:
        return "serial (this process)"
    return f"Dask cluster at {scheduler}" if isinstance(scheduler, str) else "given Dask client"


def _check_scheduler(scheduler):
    if scheduler is None or scheduler in (LOCAL, SERIAL):
        return
    if isinstance(scheduler, str):
        if not (scheduler.startswith(("tcp://", "tls://", "inproc://", "ucx://")) or ":" in scheduler):
            raise TwinInputError(f"scheduler must be 'local', 'serial' or an address like tcp://HOST:8786, "
                                 f"got {scheduler!r}")
        return
    if not hasattr(scheduler, "submit"):
        raise TwinInputError(f"scheduler must be 'local', 'serial', an address or a distributed.Client, "
                             f"got {type(scheduler).__name__}")


def _run_serial(tasks, progress):
    """The results of ``tasks`` run one after the other in this process."""
    results = []
    for i, task in enumerate(tasks):
        results.append(_call(task))
        if progress is not None:
            progress(i + 1, len(tasks))
    return results


def _connect(scheduler, n_workers, total):
    """(Dask client, local cluster or None) for ``scheduler``; a local cluster gets at most one worker per task."""
    from distributed import Client, LocalCluster

    if scheduler is None or scheduler == LOCAL:
        workers = max(1, min(int(n_workers or os.cpu_count() or 1), total))
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0", silence_logs=40)
        return Client(cluster), cluster
    if isinstance(scheduler, str):
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError) as exc:
            raise TwinInputError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
    return scheduler, None


def run_tasks(tasks: Iterable[Callable[[], T]], scheduler: str | object | None = LOCAL, n_workers: int | None = None,
              progress: Callable[[int, int], None] | None = None) -> list[T]:
    """Run independent tasks, in parallel on Dask or in this process.

    Parameters
    ----------
    tasks : iterable of callable
        Picklable no-argument callables.
    scheduler : str or distributed.Client
        ``"local"`` (default), ``"serial"``, a scheduler address ``tcp://HOST:PORT``,
        or a ``distributed.Client``.
    n_workers : int, optional
        Worker processes of the local cluster (default: cores, at most one per task).
    progress : callable, optional
        ``progress(done, total)``.

    Returns
    -------
    list
        The tasks' results, in the order of ``tasks``; a task's exception is raised here.
    """
    tasks = list(tasks)
    for i, task in enumerate(tasks):
        if not callable(task):
            raise TwinInputError(f"task {i} is not callable: {task!r}")
    _check_scheduler(scheduler)
    total = len(tasks)
    if total == 0:
        return []
    if scheduler == SERIAL or ((scheduler is None or scheduler == LOCAL) and total == 1):
        return _run_serial(tasks, progress)

    from distributed import as_completed

    client, cluster = _connect(scheduler, n_workers, total)
    try:
        futures = [client.submit(_call, task, pure=False) for task in tasks]
        index = {f.key: i for i, f in enumerate(futures)}
        results = [None] * total
        done = 0
        for future in as_completed(futures):
            results[index[future.key]] = future.result()     # re-raises the task's exception
            done += 1
            if progress is not None:
                progress(done, total)
        return results
    finally:
        if client is not scheduler:
            client.close()
        if cluster is not None:
            cluster.close()
