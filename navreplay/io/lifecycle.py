"""Stopping cleanly: signals in the command process, and workers that die with their parent.

* :func:`handle_signals` (the command line wraps every command in it) turns SIGTERM and SIGHUP into
  :class:`Terminated` and SIGINT into :class:`Interrupted` (a ``KeyboardInterrupt``), after deleting
  the live temporary files (:func:`navreplay.io.outputs.remove_temporaries`): whatever was being
  written is gone at once, even if unwinding takes a while, and existing targets are untouched.
* :func:`worker_init` is the initializer of the process pools: a worker ignores Ctrl-C (the parent
  cancels the campaign), deletes its temporaries and exits on SIGTERM/SIGHUP, and exits when its
  parent dies — at once on Linux (``prctl(PR_SET_PDEATHSIG)``), within a second elsewhere (a
  thread watching the parent PID).
* :func:`stop_workers` terminates the processes of a pool whose campaign failed or was stopped.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from types import FrameType
from typing import Any

from navreplay.io import outputs

STOP_SIGNALS: tuple[str, ...] = ("SIGTERM", "SIGHUP")
"""Signals that stop a command (SIGINT stops it too, as ``KeyboardInterrupt``)."""


class Terminated(BaseException):  # noqa: N818 - like KeyboardInterrupt
    """The process was told to stop by a signal; ``exit_code`` is ``128 + signum``."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        self.exit_code = 128 + signum
        super().__init__(f"terminated by {signal.Signals(signum).name}")


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) as :func:`handle_signals` raises it: told apart from a
    ``KeyboardInterrupt`` that code (a plug-in filter) raises itself."""


def _on_stop(signum: int, frame: FrameType | None) -> None:
    outputs.remove_temporaries()
    release_children()
    raise Terminated(signum)


def _on_interrupt(signum: int, frame: FrameType | None) -> None:
    outputs.remove_temporaries()
    release_children()
    raise Interrupted


def from_signal(exc: BaseException) -> bool:
    """Whether ``exc`` stops the process because it was signalled (:class:`Terminated`, or
    Ctrl-C), rather than because code raised a ``BaseException`` itself (``SystemExit``,
    ``KeyboardInterrupt``, ``GeneratorExit`` from a plug-in: an error of that code).

    Without the handlers of :func:`handle_signals` (navreplay used as a library), a
    ``KeyboardInterrupt`` is taken as Ctrl-C."""
    if isinstance(exc, Terminated | Interrupted):
        return True
    if isinstance(exc, KeyboardInterrupt):
        try:
            return signal.getsignal(signal.SIGINT) is not _on_interrupt
        except ValueError:  # not the main interpreter
            return True
    return False


@contextlib.contextmanager
def handle_signals() -> Iterator[None]:
    """Install the stop handlers for the block (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    wanted = [(signal.SIGINT, _on_interrupt)] + [
        (getattr(signal, name), _on_stop) for name in STOP_SIGNALS if hasattr(signal, name)
    ]
    old: list[tuple[int, Any]] = []
    try:
        for signum, handler in wanted:
            old.append((signum, signal.signal(signum, handler)))
        yield
    finally:
        for signum, handler in old:
            signal.signal(signum, handler)


def interrupted_by(exc: BaseException) -> BaseException | None:
    """The signal's ``KeyboardInterrupt`` or :class:`Terminated` behind ``exc`` (itself, or the
    context of an error that a compiled function raised while the signal arrived), else None
    (:func:`from_signal`)."""
    seen = 0
    e: BaseException | None = exc
    while e is not None and seen < 16:
        if from_signal(e):
            return e
        e = e.__cause__ or e.__context__
        seen += 1
    return None


# --------------------------------------------------------------------------------------------
# helper processes (a served viewer): they end with this process

_CHILDREN: list[Any] = []


def child_init() -> None:
    """``preexec_fn`` of a helper process: on Linux it gets SIGTERM when this process dies,
    even by ``kill -9``."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


def adopt(proc: Any) -> None:
    """Terminate the ``subprocess.Popen`` ``proc`` when this process stops or exits."""
    if not _CHILDREN:
        atexit.register(release_children)
    _CHILDREN.append(proc)


def release_child(proc: Any) -> None:
    """Terminate an adopted process now and forget it."""
    with contextlib.suppress(ValueError):
        _CHILDREN.remove(proc)
    _end(proc)


def release_children() -> None:
    """Terminate every adopted process (also done at exit and on a stop signal)."""
    while _CHILDREN:
        _end(_CHILDREN.pop())



def _end(proc: Any) -> None:
    with contextlib.suppress(Exception):
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(1.0)
            except Exception:
                proc.kill()


# --------------------------------------------------------------------------------------------
# workers

_PR_SET_PDEATHSIG = 1


def worker_init(parent_pid: int | None = None) -> None:
    """Initializer of a worker process (see the module docstring)."""
    parent = os.getppid() if parent_pid is None else parent_pid
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in STOP_SIGNALS:
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), _worker_stop)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent:  # the parent died before the death signal was armed
        _exit_now(1)
    threading.Thread(target=_watch_parent, args=(parent,), name="navreplay-parent-watch",
                     daemon=True).start()


def _worker_stop(signum: int, frame: FrameType | None) -> None:
    _exit_now(128 + signum)


def _exit_now(code: int) -> None:
    outputs.remove_temporaries()
    os._exit(code)


def _watch_parent(parent: int, interval: float = 1.0) -> None:
    stop = threading.Event()
    while not stop.wait(interval):
        if os.getppid() != parent:
            _exit_now(1)


def stop_workers(executor: Any, grace: float | None = None) -> None:
    """Terminate the worker processes of a ``concurrent.futures.ProcessPoolExecutor`` (call
    it before ``shutdown``, which drops the executor's list of processes); with
    ``grace`` [s], wait that long for them to exit (their handlers delete their temporaries)
    and kill those still running (in a compiled loop that does not look at signals)."""
    processes = list((getattr(executor, "_processes", None) or {}).values())
    for proc in processes:
        with contextlib.suppress(Exception):
            proc.terminate()
    if grace is None:
        return
    end = time.monotonic() + grace
    for proc in processes:
        with contextlib.suppress(Exception):
            proc.join(max(end - time.monotonic(), 0.0))
    for proc in processes:
        with contextlib.suppress(Exception):
            if proc.is_alive():
                proc.kill()
                proc.join(1.0)
