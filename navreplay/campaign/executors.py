"""Where the runs of a campaign go: the executor seam.

A campaign needs of its executor only ``submit(fn, *args)`` and ``shutdown()``, and of a future
only ``result()`` (a subset of :class:`concurrent.futures.Executor`). :func:`make_executor`
makes the one ``--executor`` names: a :class:`concurrent.futures.ProcessPoolExecutor` of
``--workers`` (or :class:`InlineExecutor` for one), or a Dask cluster, local or remote
(:class:`navreplay.campaign.dask_executor.DaskExecutor`), the pool and the cluster wrapped in
:class:`navreplay.campaign.batching.Batching` (several runs per task); other engines plug in
through a thin adapter of the same two methods.
"""

from __future__ import annotations

import concurrent.futures as cf
import os
from collections.abc import Callable
from typing import Any, Protocol

from navreplay.io import lifecycle


class Future(Protocol):
    """What the campaign needs of a future."""

    def result(self, timeout: float | None = None) -> Any: ...


class Executor(Protocol):
    """What the campaign needs of an executor (a subset of ``concurrent.futures.Executor``)."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future: ...

    def shutdown(self, wait: bool = True) -> None: ...


class InlineExecutor:
    """Runs each task in the calling process when its result is asked for (one worker).

    Exceptions surface from ``result()`` as they would from a process pool.
    """

    class _Lazy:
        def __init__(self, fn: Callable[..., Any], args: tuple, kwargs: dict) -> None:
            self._call = (fn, args, kwargs)

        def result(self, timeout: float | None = None) -> Any:
            fn, args, kwargs = self._call
            return fn(*args, **kwargs)

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        return self._Lazy(fn, args, kwargs)

    def shutdown(self, wait: bool = True) -> None:
        return None


EXECUTORS = ("process", "dask", "dask://HOST:PORT")
"""What ``--executor`` takes: a process pool on this machine (the default), a Dask
LocalCluster of ``--workers`` processes, or a running Dask scheduler."""


POOL_TASK_SECONDS = 0.1
"""Work per task of a process pool [s] (a task costs it about a millisecond)."""
DASK_TASK_SECONDS = 0.5
"""Work per task of a Dask cluster [s] (a task costs it about 10-20 ms)."""
MAX_BATCH = 32
"""Most runs per task."""


def make_executor(workers: int, spec: str = "process", *, batch: bool = True) -> Executor:
    """The executor of a campaign: for ``spec == "process"`` an :class:`InlineExecutor` for one
    worker, else a process pool of ``workers``; for ``"dask"`` a Dask LocalCluster of
    ``workers`` processes; for a scheduler address (``dask://host:port``, ``tcp://...``) a
    client of that cluster (:mod:`navreplay.campaign.dask_executor`).

    With ``batch`` (for many calls of similar cost, a campaign's runs) the pool and the cluster
    run consecutive calls together, as many per task as carry about
    :data:`POOL_TASK_SECONDS` or :data:`DASK_TASK_SECONDS` of work
    (:class:`navreplay.campaign.batching.Batching`)."""
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    from navreplay.campaign import dask_executor
    from navreplay.campaign.batching import Batching

    if spec == "dask" or dask_executor.is_address(spec):
        dask = dask_executor.DaskExecutor(None if spec == "dask" else spec, workers)
        return Batching(dask, dask.parallelism, task_seconds=DASK_TASK_SECONDS,
                        max_batch=MAX_BATCH) if batch else dask
    if spec != "process":
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}; got {spec!r}")
    if workers == 1:
        return InlineExecutor()
    pool = cf.ProcessPoolExecutor(max_workers=workers, initializer=lifecycle.worker_init,
                                  initargs=(os.getpid(),))
    return Batching(pool, workers, task_seconds=POOL_TASK_SECONDS,
                    max_batch=MAX_BATCH) if batch else pool
