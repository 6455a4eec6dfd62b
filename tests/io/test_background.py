"""The writing thread (:class:`navreplay.io.background.Background`): calls run in order, the
queue is bounded, a failure is raised in the caller and drops the calls after it, cancel drops
what is queued."""

from __future__ import annotations

import threading

import pytest

from navreplay.io.background import Background


def test_calls_run_in_order_in_another_thread() -> None:
    seen: list[tuple[int, str]] = []
    with Background("test") as work:
        for k in range(200):
            work.submit(lambda k: seen.append((k, threading.current_thread().name)), k)
        work.drain()
    assert [k for k, _ in seen] == list(range(200))
    assert {name for _, name in seen} == {"test"}


def test_the_queue_is_bounded() -> None:
    """With the thread held, submit returns for ``depth`` calls and waits at the next."""
    gate = threading.Event()
    work = Background("test", depth=2)
    work.submit(gate.wait)  # taken by the thread, which then waits
    work.submit(lambda: None)
    work.submit(lambda: None)  # the queue is full now
    blocked = threading.Thread(target=work.submit, args=(lambda: None,))
    blocked.start()
    blocked.join(0.2)
    assert blocked.is_alive()  # waiting for room
    gate.set()
    blocked.join(5.0)
    assert not blocked.is_alive()
    work.drain()
    work.close()


def test_a_failure_is_raised_in_the_caller_and_drops_the_calls_after_it() -> None:
    done: list[int] = []

    def fail() -> None:
        raise OSError(28, "No space left on device")

    work = Background("test")
    work.submit(done.append, 1)
    work.submit(fail)
    work.submit(done.append, 2)
    with pytest.raises(OSError, match="No space left"):
        work.drain()
    work.submit(done.append, 3)  # still dropped: the export behind it is broken
    work.drain()
    work.close()
    assert done == [1]


def test_a_failure_is_raised_at_the_next_submit() -> None:
    work = Background("test")
    work.submit(lambda: 1 / 0)
    work._jobs.join()  # the failure has happened
    with pytest.raises(ZeroDivisionError):
        work.submit(lambda: None)
    work.cancel()


def test_cancel_drops_what_is_queued() -> None:
    gate = threading.Event()
    done: list[int] = []
    work = Background("test", depth=8)
    work.submit(gate.wait)
    for k in range(5):
        work.submit(done.append, k)
    threading.Timer(0.1, gate.set).start()
    work.cancel()  # waits for the call in hand (released by the timer), drops the rest
    assert done == []
    assert not work._thread.is_alive()
    with pytest.raises(ValueError, match="closed"):
        work.submit(done.append, 9)
