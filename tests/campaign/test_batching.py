"""Batching: calls grouped into tasks by their measured cost, results in submission order, a
failing call confined to its own future."""

from __future__ import annotations

import concurrent.futures as cf
import time

import pytest

from navreplay.campaign.batching import Batching, call_batch
from navreplay.campaign.executors import InlineExecutor, make_executor


class _Task:
    """A task run when its result is first asked for; in flight (not done) until then."""

    def __init__(self, fn, args) -> None:
        self._call, self._value = (fn, args), None

    def done(self) -> bool:
        return self._call is None

    def result(self, timeout=None):
        if self._call is not None:
            fn, args = self._call
            self._value, self._call = fn(*args), None
        return self._value


class Counting(InlineExecutor):
    """Runs each task when asked, counting tasks and the calls in each."""

    def __init__(self) -> None:
        self.sizes: list[int] = []

    def submit(self, fn, /, *args, **kwargs):
        assert fn is call_batch and not kwargs
        self.sizes.append(len(args[0]))
        return _Task(fn, args)


def _square(i: int) -> int:
    if i == 13:
        raise ValueError(f"run {i} failed")
    return i * i


def _double(i: int) -> int:
    return 2 * i


def _slow(i: int) -> int:
    time.sleep(0.002)
    return i


def test_cheap_calls_go_in_full_groups_in_order() -> None:
    inner = Counting()
    ex = Batching(inner, workers=2, task_seconds=1.0, max_batch=8)
    futures = [ex.submit(_square, i) for i in range(42)]
    got = []
    for i, f in enumerate(futures):
        if i == 13:
            with pytest.raises(ValueError, match="run 13 failed"):
                f.result()
        else:
            got.append(f.result())
    assert got == [i * i for i in range(42) if i != 13]
    # one probe per worker, then groups of max_batch in the places in flight (two per worker)
    assert inner.sizes == [1, 1, 8, 8, 8, 8, 8]


def test_costly_calls_go_one_per_task() -> None:
    inner = Counting()
    ex = Batching(inner, workers=2, task_seconds=1e-6, max_batch=8)
    futures = [ex.submit(_slow, i) for i in range(10)]
    assert [f.result() for f in futures] == list(range(10))
    assert inner.sizes == [1] * 10


def test_groups_follow_the_submissions_of_a_campaign_window() -> None:
    """Submitting as results are taken (run_ensemble's window) keeps sending full groups."""
    assert Batching(Counting(), workers=3, max_batch=5).parallelism == 15
    inner = Counting()
    ex = Batching(inner, workers=2, task_seconds=1.0, max_batch=4)
    window = 2 * ex.parallelism
    pending = [ex.submit(_double, i) for i in range(window)]
    n, out = window, []
    while pending:
        out.append(pending.pop(0).result())
        if n < 40:
            pending.append(ex.submit(_double, n))
            n += 1
    assert out == [2 * i for i in range(40)]
    assert max(inner.sizes) == 4 and sum(inner.sizes) == 40
    assert len(inner.sizes) <= 2 + 40 // 4 + 2


def test_make_executor_batches_pools_unless_told() -> None:
    """(run_ensemble over a batched pool: tests/campaign/test_ensemble.py, two workers.)"""
    batched, plain = make_executor(2), make_executor(2, batch=False)
    try:
        assert isinstance(batched, Batching) and batched.parallelism == 2 * batched.max_batch
        assert isinstance(plain, cf.ProcessPoolExecutor)
        assert batched.submit(_square, 3).result() == 9
    finally:
        batched.shutdown()
        plain.shutdown()
