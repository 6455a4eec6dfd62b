"""Writing beside the work: :class:`Background`, one thread that runs the calls handed to it
in order.

An export formats and compresses its rows in compiled kernels and zstd, and writes them, all
without Python's global lock; the replay's filters run theirs the same way. Handed to this
thread, the export's writing overlaps the replay of the next piece instead of following it:
a run waits for the larger of the two, not their sum, on a machine with a second core (the
CPU time is the same).

The calls queue up to ``depth`` at a time (the caller waits beyond that: the rows held stay
bounded). The first exception a call raises stops the thread's work: the calls after it are
dropped, and the exception is raised again in the caller at its next :meth:`Background.submit`
or at :meth:`Background.drain`, so a full disk met in the background surfaces where the
caller handles it (:func:`navreplay.io.outputs.writing`). The caller must not change what it
hands over.

Examples
--------
>>> out = []
>>> with Background("example") as work:
...     for k in range(3):
...         work.submit(out.append, k)
...     work.drain()
>>> out
[0, 1, 2]
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from types import TracebackType
from typing import Any

_STOP = None


class Background:
    """One thread running the calls submitted to it, in order.

    Parameters
    ----------
    name : str
        The thread's name (shown by debuggers and ``faulthandler``).
    depth : int
        Calls queued at most; :meth:`submit` waits for room beyond that.
    """

    def __init__(self, name: str, depth: int = 4) -> None:
        self._jobs: queue.Queue[tuple[Callable[..., Any], tuple[Any, ...]] | None] = \
            queue.Queue(maxsize=depth)
        self._error: BaseException | None = None  # raised in the caller once
        self._failed = False  # a call failed: the later ones are dropped
        self._closed = False
        # a daemon: a process that ends by an error or a signal does not wait for it
        self._thread = threading.Thread(target=self._work, name=name, daemon=True)
        self._thread.start()

    def _work(self) -> None:
        while True:
            job = self._jobs.get()
            try:
                if job is _STOP:
                    return
                if not self._failed:
                    fn, args = job
                    fn(*args)
            except BaseException as exc:  # raised again in the caller
                self._failed = True
                self._error = exc
            finally:
                del job  # what it holds is not kept while the thread waits
                self._jobs.task_done()

    def _raise(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def submit(self, fn: Callable[..., Any], *args: Any) -> None:
        """Queue ``fn(*args)``; raises what a call before it raised (that call and every later
        one dropped)."""
        if self._closed:
            raise ValueError("submit to a closed Background")
        self._raise()
        self._jobs.put((fn, args))

    def drain(self) -> None:
        """Wait until every call submitted has run; raises what one of them raised."""
        self._jobs.join()
        self._raise()

    def close(self) -> None:
        """Stop the thread once the calls queued have run (their errors are not raised:
        :meth:`drain` first for them)."""
        if not self._closed:
            self._closed = True
            self._jobs.put(_STOP)
            self._thread.join()

    def cancel(self) -> None:
        """Drop the calls still queued and stop the thread after the one running."""
        if self._closed:
            return
        self._closed = True
        while True:
            try:
                self._jobs.get_nowait()
            except queue.Empty:
                break
            self._jobs.task_done()
        self._jobs.put(_STOP)
        self._thread.join()
        self._error = None

    def __enter__(self) -> Background:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if kind is None:
            self.close()
        else:
            self.cancel()
