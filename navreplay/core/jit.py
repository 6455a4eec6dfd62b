"""Compilation of the package's numba kernels: the cyclic garbage collector rests meanwhile.

numba builds each kernel out of many small, cyclically linked Python objects (its IR, types
and LLVM IR text), so a compilation triggers many passes of Python's cyclic garbage collector,
and the full ones walk every object of the process: numpy, scipy, Rerun and the recording
already loaded. In a first run of ``navreplay run gps-ins`` these passes took about a fifth
of the compile time. Importing this module (the kernel modules do) registers a numba event
listener that disables the collector for each outermost compilation and re-enables it after,
if it was enabled; the garbage of the compilation is then collected as usual.
"""

from __future__ import annotations

import gc

from numba.core import event

__all__: list[str] = []


class _PauseCollector(event.Listener):
    """Collector off from the start of the outermost ``numba:compile`` event to its end
    (numba compiles under one lock, so the events of nested compilations nest)."""

    def __init__(self) -> None:
        self._depth = 0
        self._was_enabled = False

    def on_start(self, ev: event.Event) -> None:
        if self._depth == 0:
            self._was_enabled = gc.isenabled()
            gc.disable()
        self._depth += 1

    def on_end(self, ev: event.Event) -> None:
        self._depth -= 1
        if self._depth == 0 and self._was_enabled:
            gc.enable()


event.register("numba:compile", _PauseCollector())
