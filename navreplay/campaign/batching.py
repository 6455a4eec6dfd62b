"""Several runs per task: :class:`Batching`, an executor over another that groups the calls
submitted to it.

Each task an executor runs has a fixed cost beside the run itself (pickling the call and its
result, the trip to the worker and back; for Dask the scheduler as well: about 10-20 ms), so
runs of a few milliseconds are slower on two workers than in one process. :class:`Batching`
sends consecutive calls as one task of its executor (:func:`call_batch`), as many as carry
about :attr:`Batching.task_seconds` of work, and hands back one future per call, so the
campaign above it is unchanged.

How many: the first call of each worker goes alone, to time a run; the calls submitted
meanwhile wait. Once a run's time is known (the first result asked for; then the mean of the
latest group's), the waiting calls go in groups of ``task_seconds / (time of a run)`` (at least
1, at most ``max_batch``); later calls are sent as soon as a group is full, while fewer than
two groups per worker are in flight. When a result is asked for (the caller will wait), the
waiting calls are spread in even groups over the free places in flight, so no worker idles
while calls wait. Results come back in submission order; a call that raises does so from its
own future's ``result()``, the others of its group unaffected.
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import threading
import time
from collections.abc import Callable
from typing import Any

from navreplay.campaign.executors import Executor, Future
from navreplay.io import lifecycle


def _true() -> bool:
    return True


def call_batch(
        calls: list[tuple[Callable[..., Any], tuple, dict]]) -> list[tuple[bool, Any, float]]:
    """Run the calls one after the other: per call (returned, its value or the exception it
    raised, seconds). Runs in the worker."""
    out = []
    for fn, args, kwargs in calls:
        start = time.perf_counter()
        try:
            value = fn(*args, **kwargs)
        except Exception as e:  # handed to that call's future
            out.append((False, e, time.perf_counter() - start))
        else:
            out.append((True, value, time.perf_counter() - start))
    return out


class _Group:
    """A group sent: its executor's future, whose result is fetched once (a Dask future
    fetches it from the worker at each ``result()``)."""

    def __init__(self, future: Future) -> None:
        self.future: Future | None = future
        self.outcomes: list[tuple[bool, Any, float]] | None = None

    def done(self) -> bool:
        return self.future is None or getattr(self.future, "done", _true)()

    def result(self, timeout: float | None = None) -> list[tuple[bool, Any, float]]:
        if self.outcomes is None:
            assert self.future is not None
            self.outcomes, self.future = self.future.result(timeout), None
        return self.outcomes


class _Call:
    """The future of one call in a group."""

    def __init__(self, owner: Batching, call: tuple[Callable[..., Any], tuple, dict]) -> None:
        self._owner = owner
        self.call: tuple[Callable[..., Any], tuple, dict] | None = call
        self.group: _Group | None = None  # set when sent
        self.index = 0

    def result(self, timeout: float | None = None) -> Any:
        self._owner._before_wait(self)
        assert self.group is not None
        outcomes = self.group.result(timeout)
        if self.index == 0:  # each group's times counted once
            self._owner._timed(outcomes)
        ok, value, _ = outcomes[self.index]
        if not ok:
            raise value
        return value


class Batching:
    """An executor whose tasks are groups of the calls submitted to it (see the module
    docstring).

    Parameters
    ----------
    executor : Executor
        Runs the groups (a process pool, a Dask client); shut down with this one.
    workers : int
        How many groups ``executor`` runs at once.
    task_seconds : float
        Work per task [s] the groups are sized to.
    max_batch : int
        Most calls per task.

    Attributes
    ----------
    parallelism : int
        ``workers * max_batch``: a campaign keeps twice as many calls in flight, so that every
        worker has full groups queued.
    """

    def __init__(self, executor: Executor, workers: int, *, task_seconds: float = 0.25,
                 max_batch: int = 8) -> None:
        self.executor = executor
        self.workers = max(1, workers)
        self.task_seconds = task_seconds
        self.max_batch = max(1, max_batch)
        self.parallelism = self.workers * self.max_batch
        self._lock = threading.Lock()
        self._waiting: list[_Call] = []
        self._probes: list[_Call] = []
        self._in_flight: list[_Group] = []  # groups sent and maybe not done
        self._run_seconds: float | None = None  # time of a run, once one is known

    @property
    def batch(self) -> int:
        """Calls per task (1 until a run has been timed)."""
        if not self._run_seconds:
            return 1 if self._run_seconds is None else self.max_batch
        return max(1, min(self.max_batch, math.floor(self.task_seconds / self._run_seconds)))

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        call = _Call(self, (fn, args, kwargs))
        with self._lock:
            if self._run_seconds is None and len(self._probes) < self.workers:
                self._probes.append(call)
                self._send([call])
            else:
                self._waiting.append(call)
                if self._run_seconds is not None:
                    self._flush(whole=True)
        return call

    def _before_wait(self, call: _Call) -> None:
        """A result is wanted (the caller is about to wait): learn a run's time if need be,
        then spread the waiting calls over the free places in flight in even groups (at most
        :attr:`batch` each), so that no worker idles while calls wait; the call itself is
        sent in any case."""
        if self._run_seconds is None:
            probe = self._probes[0]
            assert probe.group is not None
            self._timed(probe.group.result())
        with self._lock:
            self._in_flight = [g for g in self._in_flight if not g.done()]
            free = 2 * self.workers - len(self._in_flight)
            if not self._waiting or (free <= 0 and call.group is not None):
                return
            size = max(1, min(self.batch, math.ceil(len(self._waiting) / max(free, 1))))
            while self._waiting and (free > 0 or call.group is None):
                group, self._waiting = self._waiting[:size], self._waiting[size:]
                self._send(group)
                free -= 1

    def _timed(self, outcomes: list[tuple[bool, Any, float]]) -> None:
        """A group's mean run time, the latest estimate (when its first result is asked
        for): the sizes follow the runs of the campaign at hand, not a worker's first run with
        its imports."""
        with self._lock:
            self._run_seconds = sum(s for _, _, s in outcomes) / len(outcomes)

    def _flush(self, whole: bool) -> None:
        """Send the waiting calls in groups of :attr:`batch`; ``whole``: only full groups, and
        only while fewer than two groups per worker are in flight (the executor's queue stays
        short whatever the campaign's window); else all of them (the last group as it is)."""
        size = self.batch
        self._in_flight = [g for g in self._in_flight if not g.done()]
        while self._waiting and (not whole or (
                len(self._waiting) >= size and len(self._in_flight) < 2 * self.workers)):
            group, self._waiting = self._waiting[:size], self._waiting[size:]
            self._send(group)

    def _send(self, group: list[_Call]) -> None:
        calls = []
        for i, c in enumerate(group):
            assert c.call is not None
            calls.append(c.call)
            c.index, c.call = i, None
        sent = _Group(self.executor.submit(call_batch, calls))
        self._in_flight.append(sent)
        for c in group:
            c.group = sent

    def shutdown(self, wait: bool = True) -> None:
        """With ``wait``, finish every call; without, drop the waiting ones, stop the running
        ones (a process pool's workers are terminated) and return."""
        if wait:
            with self._lock:
                self._flush(whole=False)
            self.executor.shutdown(wait=True)
            return
        self._waiting.clear()
        if isinstance(self.executor, cf.Executor):
            lifecycle.stop_workers(self.executor)  # before shutdown forgets the processes
            self.executor.shutdown(wait=False, cancel_futures=True)
        else:
            self.executor.shutdown(wait=False)
