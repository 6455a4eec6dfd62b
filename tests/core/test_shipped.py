"""The compiled kernels shipped with the package: a store built for the portable CPU serves a
process whose own cache is empty (nothing compiled), with the host-compiled results; a changed
file or a store built elsewhere is never loaded (numba compiles, same results); every kernel of
the package goes through the store."""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from navreplay.core import jit, shipped

ROOT = Path(__file__).resolve().parents[2]

# A child process: lti.discretize (a small kernel of the package) on a fixed system, with the
# store at argv[1] (or none); prints the result, the compiles, what the store did and where
# numba's runtime came from. With
# argv[2] == "write", writes the store from its own cache (NUMBA_CACHE_DIR) after the call.
_CHILD = """
import json, os, sys
from pathlib import Path
import numpy as np
from navreplay.core import jit, shipped
shipped.STORE = Path(sys.argv[1])
from navreplay.core import lti
F = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-0.3, -0.2, -0.1]])
Phi = lti.discretize(F, 0.01)
if sys.argv[2] == "write":
    from numba.core.registry import cpu_target
    magic = cpu_target.target_context.codegen().magic_tuple()
    shipped.write(Path(os.environ["NUMBA_CACHE_DIR"]), Path(sys.argv[1]), magic)
k = lti.discretize
print(json.dumps({"Phi": Phi.tolist(), "misses": sum(k._cache_misses.values()),
                  "stats": dict(shipped.STATS), "runtime": jit.RUNTIME["source"]}))
"""


def _child(store: Path, cache: Path, mode: str = "run", **env: str) -> dict:
    cache.mkdir(parents=True, exist_ok=True)
    full = {**os.environ, "NUMBA_CACHE_DIR": str(cache), **env}
    full.pop(shipped.ENV, None)
    out = subprocess.run([sys.executable, "-c", _CHILD, str(store), mode], env=full,
                         capture_output=True, text=True, check=True, cwd=cache)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    """A store built for the portable CPU, and the host-compiled result (store off)."""
    tmp = tmp_path_factory.mktemp("shipped")
    store = tmp / "store"
    _child(store, tmp / "build", "write", NUMBA_CPU_NAME="generic", NUMBA_CPU_FEATURES="")
    host = _child(tmp / "none", tmp / "host")
    assert host["misses"] == 1 and not host["stats"] and host["runtime"] == "compiled"
    return store, np.array(host["Phi"])


def test_the_store_serves_a_process_with_an_empty_cache(store, tmp_path):
    path, host = store
    manifest = json.loads((path / shipped.MANIFEST).read_text())
    assert manifest["magic"][1:] == [shipped.PORTABLE_CPU, ""]
    assert any(name.startswith("core/lti.discretize-") for name in manifest["files"])
    assert [name for name in manifest["files"] if name.endswith(".nrt")] == [
        f"core/{jit.runtime_file(tuple(manifest['magic']))}"]
    got = _child(path, tmp_path / "user")
    assert got["misses"] == 0 and got["stats"] == {"loaded": 1}
    assert got["runtime"] == "shipped"
    np.testing.assert_allclose(got["Phi"], host, rtol=1e-14, atol=1e-15)
    for pattern in ("*.nbi", "*.nrt"):  # nothing compiled, nothing saved
        assert not list((tmp_path / "user").rglob(pattern))


@pytest.mark.parametrize("pattern", ["lti.discretize-*.nbc", "numba-runtime-*.nrt"])
def test_a_changed_file_is_refused_and_numba_compiles(store, tmp_path, pattern):
    """A kernel's data file, or numba's runtime library."""
    path, host = store
    copy = tmp_path / "store"
    subprocess.run(["cp", "-r", str(path), str(copy)], check=True)
    data = sorted(copy.rglob(pattern))[0]
    raw = bytearray(data.read_bytes())
    raw[len(raw) // 2] ^= 0xFF  # same size, one byte changed
    data.write_bytes(bytes(raw))
    got = _child(copy, tmp_path / "user")
    if pattern.endswith(".nbc"):
        assert got["misses"] == 1 and got["stats"] == {"refused": 1}
        assert got["runtime"] == "shipped"
        np.testing.assert_array_equal(got["Phi"], host)  # host-compiled, as without a store
    else:  # the kernel from the store, numba's runtime compiled
        assert got["misses"] == 0 and got["stats"] == {"loaded": 1, "refused": 1}
        assert got["runtime"] == "compiled"
        np.testing.assert_allclose(got["Phi"], host, rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("change", ["numba", "sources"])
def test_a_store_built_elsewhere_or_from_other_sources_is_not_opened(store, tmp_path, change):
    """Another numba version; a module that declares kernels edited since the build (a
    kernel's code holds its callees from other modules)."""
    path, host = store
    copy = tmp_path / "store"
    subprocess.run(["cp", "-r", str(path), str(copy)], check=True)
    manifest = json.loads((copy / shipped.MANIFEST).read_text())
    if change == "numba":
        manifest["numba"] = "0.0.0"
    else:
        assert "geo/kernels.py" in manifest["sources"]
        manifest["sources"]["geo/kernels.py"] = "0" * 64
    (copy / shipped.MANIFEST).write_text(json.dumps(manifest))
    got = _child(copy, tmp_path / "user")
    assert got["misses"] == 1
    assert got["stats"] == ({} if change == "numba" else {"refused": 1})
    np.testing.assert_array_equal(got["Phi"], host)


def test_only_the_portable_cpu_or_this_one_runs_here():
    from numba.core.registry import cpu_target

    ctx = cpu_target.target_context
    host = ctx.codegen().magic_tuple()
    manifest = {"magic": [host[0], shipped.PORTABLE_CPU, ""], "files": {}}
    assert shipped.Store(Path("."), manifest).runs_here(ctx)
    for magic in ([host[0], "some-other-cpu", "+avx512f"], ["aarch64-unknown-linux-gnu",
                                                            shipped.PORTABLE_CPU, ""]):
        assert not shipped.Store(Path("."), {"magic": magic, "files": {}}).runs_here(ctx)
    assert shipped.Store(Path("."), {"magic": list(host), "files": {}}).runs_here(ctx)


def test_every_kernel_of_the_package_goes_through_the_store():
    """No kernel is declared with numba.njit directly (it would never be shipped), and every
    declared kernel has the two-tier cache."""
    for path in (ROOT / "navreplay").rglob("*.py"):
        if path.name == "jit.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and node.attr in ("njit", "jit", "generated_jit"):
                assert not (isinstance(node.value, ast.Name) and node.value.id == "numba"), (
                    f"{path.relative_to(ROOT)}:{node.lineno}: declare kernels with "
                    "navreplay.core.jit.kernel")
    import navreplay.filters.gps_ins_events  # noqa: F401  (a module of kernels)

    assert len(jit.KERNELS) > 10
    assert all(isinstance(k._cache, jit.KernelCache) for k in jit.KERNELS)
    declaring = set(shipped._kernel_sources())  # the modules whose edits make a store stale
    for k in jit.KERNELS:
        assert Path(k.py_func.__code__.co_filename).relative_to(shipped.PACKAGE).as_posix() \
            in declaring, k
