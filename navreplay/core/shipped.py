"""The compiled kernels that ship with the package: machine code for a portable CPU, built with
the wheel, so that the first run after ``pip install`` loads its kernels instead of compiling
them (:class:`navreplay.core.jit.KernelCache` looks here after the user cache).

The store is the directory :data:`STORE` inside the installed package: numba's cache files
(``<module>.<function>-<line>.py311.nbi`` index and ``.nbc`` data) under the path of their
source directory in the package (``filters/``, ``geo/``, ...), and ``manifest.json``: the
numba, llvmlite and Python it was built with, numba's code-generation key (target triple, CPU
``generic``: the architecture's baseline, so any CPU of that architecture runs it; no
instruction set extension is assumed) and the SHA-256 of every file.
``navreplay.jobs.warmup.ship`` builds it; the wheel build runs that (``setup.py``). Beside the
kernels, ``core/`` holds numba's runtime library built with them (``numba-runtime-*.nrt``,
:func:`load_runtime`; :func:`navreplay.core.jit.runtime_library` uses it).

A shipped kernel is used only when all of these hold, else numba compiles it as it would
without a store (nothing is ever half-used):

- the manifest names this numba, llvmlite, Python and target triple;
- every module of the package that declares kernels hashes as it did at the build (a kernel's
  code holds the kernels it calls, from other modules: an edited callee makes the whole store
  stale);
- the index and data files of the function hash as the manifest says (a changed or truncated
  file is never unpickled);
- numba's own index checks pass: its version, the source file's stamp (numba stamps it by its
  contents, so an installed copy of the same source matches and an edited one does not) and
  the function's bytecode.

``NAVREPLAY_SHIPPED_KERNELS=0`` turns the store off (``navreplay warm-up`` does, to compile for
this CPU). :data:`STATS` counts what was loaded and what was refused.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import shutil
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import llvmlite
import numba
from numba.core.caching import (
    IndexDataCacheFile,
    UserProvidedCacheLocator,
    _CacheLocator,
    _SourceFileBackedLocatorMixin,
)

__all__ = ["ENV", "STATS", "STORE", "load", "load_runtime", "write"]

PACKAGE = Path(__file__).resolve().parents[1]
"""The installed ``navreplay`` package directory."""
STORE = PACKAGE / "core" / "compiled"
"""Where the shipped kernels are: absent when the package was installed without them."""
MANIFEST = "manifest.json"
FORMAT = 1
"""Version of the store's layout (the manifest's ``format``)."""
PORTABLE_CPU = "generic"
"""The CPU the shipped kernels are built for (numba's ``NUMBA_CPU_NAME``, no extra features)."""
ENV = "NAVREPLAY_SHIPPED_KERNELS"
"""Environment variable: ``0`` turns the store off."""

STATS: Counter[str] = Counter()
"""``loaded``: signatures served by the store; ``refused``: a store entry that failed a check
(its function is then compiled)."""


def enabled() -> bool:
    """Whether the store may serve kernels (:data:`ENV` is not ``0``)."""
    return os.environ.get(ENV, "1") != "0"


def _environment() -> dict[str, Any]:
    """What a store must have been built with to serve this process."""
    return {"format": FORMAT, "numba": numba.__version__, "llvmlite": llvmlite.__version__,
            "python": f"{sys.version_info[0]}.{sys.version_info[1]}{sys.abiflags}"}


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _kernel_sources() -> dict[str, str]:
    """SHA-256 of each module of the package that declares kernels, by path in the package."""
    return {p.relative_to(PACKAGE).as_posix(): hashlib.sha256(text).hexdigest()
            for p in sorted(PACKAGE.rglob("*.py"))
            if _DECLARES in (text := p.read_bytes())}


_DECLARES = b"from navreplay.core.jit import kernel"
"""How a module that declares kernels imports the decorator."""


class _Codegen:
    """Stands for numba's code generator where its cache only asks for the key of the code
    (the shipped code's, not this process's)."""

    def __init__(self, magic: tuple[Any, ...]) -> None:
        self._magic = magic

    def magic_tuple(self) -> tuple[Any, ...]:
        return self._magic


class _Locator(_SourceFileBackedLocatorMixin, _CacheLocator):
    """The store's directory of one source file, read only; the source stamped as numba stamps
    its own cache (its contents)."""

    def __init__(self, py_func: Any, py_file: str, path: Path) -> None:
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._path = path

    def get_cache_path(self) -> str:
        return str(self._path)


class Store:
    """A store whose manifest matches this process (:func:`_open`)."""

    def __init__(self, root: Path, manifest: dict[str, Any]) -> None:
        self.root = root
        self.magic = tuple(manifest["magic"])
        self.files: dict[str, str] = manifest["files"]
        self._host_ok: bool | None = None

    def runs_here(self, target_context: Any) -> bool:
        """The code runs on this CPU: same target triple, and the portable CPU or this one."""
        if self._host_ok is None:
            host = target_context.codegen().magic_tuple()
            self._host_ok = self.magic[0] == host[0] and (
                (self.magic[1], self.magic[2]) == (PORTABLE_CPU, "") or self.magic == host)
        return self._host_ok

    def load(self, py_func: Any, impl: Any, sig: Any, target_context: Any,
             index_key: Any) -> Any:
        """numba's compile result of ``py_func`` for ``sig`` from the store, or None."""
        source = Path(py_func.__code__.co_filename).resolve()
        try:
            rel = source.parent.relative_to(PACKAGE).as_posix()
        except ValueError:  # not a module of this package
            return None
        base = impl.filename_base
        prefix = f"{rel}/{base}." if rel != "." else f"{base}."
        if f"{prefix}nbi" not in self.files or not self.runs_here(target_context):
            return None
        for name, digest in self.files.items():
            if name.startswith(prefix) and _sha256(self.root / name) != digest:
                STATS["refused"] += 1
                return None
        locator = _Locator(py_func, str(source), self.root / rel)
        cache_file = IndexDataCacheFile(locator.get_cache_path(), base,
                                        locator.get_source_stamp())
        data = cache_file.load(index_key(sig, _Codegen(self.magic)))
        if data is None:
            return None
        cres = impl.rebuild(target_context, data)
        STATS["loaded"] += 1
        return cres


@functools.cache
def _open(root: Path) -> Store | None:
    """The store at ``root`` if its manifest matches this process, else None."""
    try:
        manifest = json.loads((root / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(manifest, dict) or any(
            manifest.get(k) != v for k, v in _environment().items()):
        return None
    if manifest.get("sources") != _kernel_sources():
        STATS["refused"] += 1  # built from other sources
        return None
    try:
        return Store(root, manifest)
    except (KeyError, TypeError):
        return None


def load(py_func: Any, impl: Any, sig: Any, target_context: Any, index_key: Any) -> Any:
    """The compile result of a kernel for ``sig`` from the shipped kernels, or None (no store,
    turned off, built elsewhere, a file changed, or the signature was not built); never
    raises: numba then compiles."""
    if not enabled():
        return None
    store = _open(STORE)
    if store is None:
        return None
    try:
        return store.load(py_func, impl, sig, target_context, index_key)
    except Exception:  # a store file numba cannot read: compile instead
        STATS["refused"] += 1
        return None


def load_runtime(target_context: Any, file_name: Callable[[tuple[Any, ...]], str]
                 ) -> bytes | None:
    """The saved machine code of numba's runtime library in the store
    (:func:`navreplay.core.jit.runtime_library`; ``file_name(magic)`` names it for the store's
    code-generation key), or None: no store, turned off, built elsewhere or changed."""
    if not enabled():
        return None
    store = _open(STORE)
    if store is None or not store.runs_here(target_context):
        return None
    name = f"core/{file_name(store.magic)}"
    digest = store.files.get(name)
    if digest is None:
        return None
    try:
        data = (store.root / name).read_bytes()
    except OSError:
        STATS["refused"] += 1
        return None
    if hashlib.sha256(data).hexdigest() != digest:
        STATS["refused"] += 1
        return None
    return data


def write(cache_dir: Path, out: Path, magic: tuple[Any, ...]) -> int:
    """Make the store ``out`` from a numba cache directory (``NUMBA_CACHE_DIR`` of a process
    that compiled the package's kernels with the code-generation key ``magic``): each source
    directory's cache files (and numba's runtime library, saved beside ``core``'s) under the
    directory's path in the package, and the manifest.
    Returns the number of kernels (index files)."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    files: dict[str, str] = {}
    for directory in sorted({p.parent for p in PACKAGE.rglob("*.py")}):
        rel = directory.relative_to(PACKAGE)
        src = cache_dir / UserProvidedCacheLocator.get_suitable_cache_subpath(
            str(directory / "__init__.py"))
        if not src.is_dir():
            continue
        for path in sorted(src.iterdir()):
            if path.suffix in (".nbi", ".nbc", ".nrt"):
                dest = out / rel / path.name
                dest.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(path, dest)
                files[dest.relative_to(out).as_posix()] = _sha256(dest)
    manifest = {**_environment(), "magic": list(magic), "files": files,
                "sources": _kernel_sources()}
    (out / MANIFEST).write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    _open.cache_clear()
    return sum(name.endswith(".nbi") for name in files)
