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

Before it loads a cached kernel, numba's cache has its CPU target load every registry of
implementations (about 60 modules of numba's: 8 MB of resident memory and 0.1 s of CPU), which
only a compilation uses, and among them ``numba.np.arraymath``, which decides whether ``np.dot``
may call BLAS by importing ``scipy.linalg.cython_blas`` (scipy's linear algebra: 20 MB and
0.1 s more), although no kernel of the package calls BLAS. :class:`KernelCache` loads a kernel
with what its machine code needs only: numba's runtime and the symbols of Python's hash
secret (the C helpers' symbols numba registers as it creates the target). When numba must
compile, its compiler loads the registries as usual, ``numba.np.arraymath`` imported first
with the BLAS question answered by finding scipy's module file
(:func:`_arraymath_without_scipy`); a kernel that does call BLAS still has numba import scipy
when it is compiled, and numba's helper library imports it at the kernel's first BLAS call.

numba's runtime (NRT: reference counting, the arrays' memory) is a small LLVM module that
numba compiles in every process, before its first kernel: that compilation runs LLVM's
optimiser and code generator, whose code (about 27 MB of the LLVM library's pages) would
otherwise stay untouched in a run whose kernels all come from a cache. Importing this module
has numba take the runtime's machine code from the same places as a kernel's
(:func:`runtime_library`): the user cache, the shipped kernels, else compiled and saved to the
user cache.
"""

from __future__ import annotations

import gc
import hashlib
import importlib.util
import os
import pickle
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba
from numba.core import event
from numba.core.caching import CompileResultCacheImpl, FunctionCache
from numba.core.runtime import nrtdynmod, rtsys

from navreplay.core import shipped

__all__ = ["KERNELS", "RUNTIME", "KernelCache", "kernel", "runtime_library"]

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
        """numba's ``load_overload`` without its refresh of the target context's registries
        (the machine code needs none of them), then the shipped kernels; before a compilation
        (nothing found), ``numba.np.arraymath`` is imported without scipy."""
        _load_ready(target_context)
        with self._guard_against_spurious_io_errors():
            cres = self._load_overload(sig, target_context)
        if cres is None:
            cres = shipped.load(self._py_func, self._impl, sig, target_context, self._index_key)
        if cres is None:
            _arraymath_without_scipy()  # numba compiles next, and loads its registries
        return cres


def _load_ready(target_context: Any) -> None:
    """What a kernel's machine code needs of numba beyond its target: its runtime (which
    numba's refresh of the registries would initialise) and the symbols of Python's hash
    secret (registered as ``numba.cpython.hashing`` is imported)."""
    rtsys.initialize(target_context)
    import numba.cpython.hashing  # noqa: F401


def _blas_findable() -> None:
    """numba's ``ensure_blas`` for ``numba.np.arraymath``'s import-time check, answered by
    finding ``scipy.linalg.cython_blas``'s file without importing scipy (ImportError if none)."""
    spec = importlib.util.find_spec("scipy")  # a top-level find imports nothing
    folders = spec.submodule_search_locations if spec is not None else None
    if not folders or not any(any((Path(f) / "linalg").glob("cython_blas.*")) for f in folders):
        raise ImportError("scipy 0.16+ is required for linear algebra")


def _arraymath_without_scipy() -> None:
    """Import ``numba.np.arraymath`` (once) with its BLAS check done by
    :func:`_blas_findable`; numba's own ``ensure_blas`` is left in place for everything else."""
    if "numba.np.arraymath" in sys.modules:
        return
    from numba.np import linalg

    ensure_blas = linalg.ensure_blas
    linalg.ensure_blas = _blas_findable  # what arraymath binds and calls as it is imported
    try:
        import numba.np.arraymath  # noqa: F401
    finally:
        linalg.ensure_blas = ensure_blas
    from numba.np import arraymath

    arraymath.ensure_blas = ensure_blas  # its later uses (none in numba 0.68) get numba's


def kernel(func: Callable[..., Any] | None = None, /, **options: Any) -> Any:
    """``numba.njit(**options)`` cached on disk through :class:`KernelCache`: ``@kernel`` or
    ``@kernel(inline="always", error_model="numpy")``."""

    def wrap(f: Callable[..., Any]) -> Any:
        dispatcher = numba.njit(**options)(f)
        dispatcher._cache = KernelCache(f)  # what numba's cache=True sets: its FunctionCache
        KERNELS.append(dispatcher)
        return dispatcher

    return wrap if func is None else wrap(func)


RUNTIME: dict[str, str] = {}
"""Where this process's numba runtime came from: ``source`` is ``user cache``, ``shipped`` or
``compiled``."""


def runtime_file(magic: tuple[Any, ...]) -> str:
    """The file name of the runtime's machine code for numba's code-generation key ``magic``
    (this numba, llvmlite and Python)."""
    import llvmlite

    key = repr((numba.__version__, llvmlite.__version__, sys.version_info[:2], tuple(magic)))
    return f"numba-runtime-{hashlib.sha256(key.encode()).hexdigest()[:16]}.nrt"


def _user_cache() -> Path | None:
    """numba's user cache directory for this module, chosen as numba chooses it for a kernel
    declared here, or None where there is none to write."""
    try:
        locator = CompileResultCacheImpl(runtime_library)._locator
        locator.ensure_cache_path()
    except (OSError, RuntimeError):  # no locator, or none writable
        return None
    return Path(locator.get_cache_path())


def _rebuild(ctx: Any, data: Any) -> Any:
    """The runtime library from its pickled object code and bitcode, or None if unusable."""
    try:
        name, kind, payload = pickle.loads(data)
        if name != "nrt" or kind != "object":
            return None
        return ctx.codegen().unserialize_library((name, kind, payload))
    except Exception:  # a truncated or foreign file: compile instead
        return None


def runtime_library(ctx: Any) -> Any:
    """numba's runtime library (its ``compile_nrt_functions``) for the target context ``ctx``:
    its machine code from the user cache, else from the shipped kernels, else compiled (with
    its object code kept) and saved to the user cache."""
    magic = ctx.codegen().magic_tuple()
    name = runtime_file(magic)
    cache = _user_cache()
    if cache is not None and (cache / name).is_file():
        library = _rebuild(ctx, (cache / name).read_bytes())
        if library is not None:
            RUNTIME["source"] = "user cache"
            return library
    data = shipped.load_runtime(ctx, runtime_file)
    if data is not None and (library := _rebuild(ctx, data)) is not None:
        RUNTIME["source"] = "shipped"
        return library
    ir_module, library = nrtdynmod.create_nrt_module(ctx)
    library.enable_object_caching()  # what the cache saves: the machine code
    library.add_ir_module(ir_module)
    library.finalize()
    RUNTIME["source"] = "compiled"
    if cache is not None:
        _save(cache / name, pickle.dumps(library.serialize_using_object_code(), protocol=4))
    return library


def _save(path: Path, data: bytes) -> None:
    """``data`` written to a temporary file beside ``path``, then renamed to it (processes
    that save the same file at once leave one whole copy); nothing if the folder refuses."""
    tmp: Path | None = None
    try:
        with tempfile.NamedTemporaryFile(dir=path.parent, delete=False, suffix=".tmp") as f:
            tmp = Path(f.name)
            f.write(data)
        os.replace(tmp, path)
    except OSError:  # read-only, full: compiled again next time
        if tmp is not None:
            tmp.unlink(missing_ok=True)


nrtdynmod.compile_nrt_functions = runtime_library
"""numba's runtime initialisation (``rtsys.initialize``) calls this module attribute."""


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
