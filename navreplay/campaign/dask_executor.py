"""Campaigns on a Dask cluster: the executor seam of :mod:`navreplay.campaign.executors` over
``dask.distributed``.

``--executor dask`` starts a :class:`distributed.LocalCluster` of ``--workers`` single-threaded
worker processes on this machine; ``--executor dask://HOST:PORT`` (or ``tcp://HOST:PORT``)
connects to a running scheduler, whose workers must have navreplay (and any plug-in filter)
installed. Workers are started once and keep their imports and compiled kernels from one run
to the next; each run is one task (:func:`navreplay.campaign.tasks.run_task`) that returns only
its compact metrics, so the scheduler's memory holds a window of results, not the campaign.

``distributed`` is imported only when a Dask executor is made.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

SCHEMES = ("dask://", "tcp://", "tls://")
"""Prefixes of a scheduler address (``dask://`` stands for ``tcp://``)."""


class DaskExecutorError(RuntimeError):
    """The Dask scheduler cannot be reached or the cluster cannot start."""


class DaskExecutor:
    """``submit`` / ``shutdown`` over a ``distributed.Client``.

    Parameters
    ----------
    address : str, optional
        Scheduler address (``dask://host:port``, ``tcp://host:port``); None: start a local
        cluster.
    workers : int
        Workers of the local cluster (one thread each); ignored with an address.
    processes : bool
        Local cluster of processes (True) or of threads in this process (False: no parallel
        speed-up for Python code, but no start-up cost; for tests).
    timeout : float
        Seconds to wait for the scheduler [s].

    Attributes
    ----------
    parallelism : int
        Worker threads of the cluster (how many runs the campaign keeps in flight, twice over).
    """

    def __init__(self, address: str | None = None, workers: int = 1, *,
                 processes: bool = True, timeout: float = 20.0) -> None:
        import distributed

        self._cluster: Any = None
        try:
            if address is None:
                self._cluster = distributed.LocalCluster(
                    n_workers=workers, threads_per_worker=1, processes=processes,
                    dashboard_address=None, silence_logs=logging.ERROR,
                )
                self._client = distributed.Client(self._cluster, timeout=timeout)
            else:
                url = "tcp://" + address[len("dask://"):] if address.startswith("dask://") \
                    else address
                self._client = distributed.Client(url, timeout=timeout)
        except (OSError, TimeoutError) as e:
            if self._cluster is not None:
                self._cluster.close()
            where = address or "a local cluster"
            raise DaskExecutorError(f"cannot start Dask on {where}: {e}") from None
        self.parallelism = max(1, sum(self._client.nthreads().values()))

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Any:
        # pure=False: every run is its own task even when its arguments repeat
        return self._client.submit(fn, *args, pure=False, **kwargs)

    def shutdown(self, wait: bool = True) -> None:
        if not wait:
            self._client.cancel(list(self._client.futures.values()), force=True)
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()


def is_address(spec: str) -> bool:
    """Whether an ``--executor`` value is a scheduler address."""
    return spec.startswith(SCHEMES)
