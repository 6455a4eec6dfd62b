"""Compilation of the package's numba kernels: where their machine code comes from, and the
cyclic garbage collector resting while numba compiles.

Every kernel of the package is declared with :func:`kernel` (``numba.njit`` with its options,
cached on disk). A kernel's code for a signature comes from, in this order
(:class:`KernelCache`):

1. the user cache: numba's own on-disk cache (``NUMBA_CACHE_DIR``, else ``__pycache__`` next to
   the sources, else numba's user-wide cache directory), code tuned for this CPU that an earlier
   compilation or ``navreplay warm-up`` wrote;
2. the shipped kernels (:mod:`navreplay.core.shipped`): code for a portable CPU built with the
   wheel, used only where it matches this interpreter, numba, platform and source file;
3. numba compiles it, and saves it to the user cache.

numba builds each kernel out of many small, cyclically linked Python objects (its IR, types
and LLVM IR text), so a compilation triggers many passes of Python's cyclic garbage collector,
and the full ones walk every object of the process: numpy, scipy, Rerun and the recording
already loaded. In a first run of ``navreplay run gps-ins`` these passes took about a fifth
of the compile time. Importing this module registers a numba event listener that disables
the collector for each outermost compilation and re-enables it after, if it was enabled; the
garbage of the compilation is then collected as usual.
"""

from __future__ import annotations

import gc
from collections.abc import Callable
from typing import Any

import numba
from numba.core import event
from numba.core.caching import CompileResultCacheImpl, FunctionCache

from navreplay.core import shipped

__all__ = ["KERNELS", "KernelCache", "kernel"]

KERNELS: list[Any] = []
"""Every kernel declared with :func:`kernel` so far (numba dispatchers), in declaration order."""


class _Impl(CompileResultCacheImpl):
    """numba's serialisation of a compile result, without its type annotation when
    :attr:`KernelCache.annotations` is off."""

    def reduce(self, cres: Any) -> Any:
        data = super().reduce(cres)
        if not KernelCache.annotations and len(data) == 9 and isinstance(data[6], str):
            data = (*data[:6], "", *data[7:])  # the typed IR as text, with object addresses
        return data


class KernelCache(FunctionCache):
    """numba's cache of one kernel (the user cache) with the shipped kernels behind it: a
    signature the user cache does not hold is looked up among the shipped kernels before
    numba compiles it. What numba compiles goes to the user cache only."""

    _impl_class = _Impl
    annotations = True
    """Whether a saved kernel keeps numba's type annotation (``inspect_types`` of a loaded
    kernel): the shipped kernels' build turns it off, as the text holds the addresses of
    Python objects and would differ from one build to the next."""

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        cres = super().load_overload(sig, target_context)
        if cres is None:
            cres = shipped.load(self._py_func, self._impl, sig, target_context, self._index_key)
        return cres


def kernel(func: Callable[..., Any] | None = None, /, **options: Any) -> Any:
    """``numba.njit(**options)`` cached on disk through :class:`KernelCache`: ``@kernel`` or
    ``@kernel(inline="always", error_model="numpy")``."""

    def wrap(f: Callable[..., Any]) -> Any:
        dispatcher = numba.njit(**options)(f)
        dispatcher._cache = KernelCache(f)  # what numba's cache=True sets: its FunctionCache
        KERNELS.append(dispatcher)
        return dispatcher

    return wrap if func is None else wrap(func)


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
