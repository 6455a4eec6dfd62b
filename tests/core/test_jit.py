"""The garbage collector rests while numba compiles a kernel, and only then; numba's runtime
library is compiled once and then loaded from the user cache."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
from numba.core import event

import navreplay.core.jit  # noqa: F401  (registers the listener)
from navreplay.core import shipped


class _Seen(event.Listener):
    def __init__(self) -> None:
        self.enabled: list[bool] = []

    def on_start(self, ev: event.Event) -> None:
        self.enabled.append(gc.isenabled())

    def on_end(self, ev: event.Event) -> None:
        pass


def _compile_fresh() -> None:
    numba.njit(lambda x: x * 2.0 + 1.0)(3.0)


def test_collector_is_off_during_a_compilation_and_restored_after():
    seen = _Seen()
    with event.install_listener("numba:compile", seen):
        assert gc.isenabled()
        _compile_fresh()
        assert gc.isenabled()
        gc.disable()  # a caller that disabled it keeps it disabled
        try:
            _compile_fresh()
            assert not gc.isenabled()
        finally:
            gc.enable()
    assert seen.enabled and not any(seen.enabled)


# A child process: a kernel that allocates arrays (numba's runtime at work) compiled for this
# CPU into the cache of NUMBA_CACHE_DIR; then a function numba compiles in the same process.
# Prints the results, where numba's runtime came from, whether the kernel was compiled and the
# registry modules loaded before the second compilation.
_CHILD = """
import json, sys
import numba
import numpy as np
from navreplay.core import jit
from navreplay.core import lti
Phi = lti.discretize(np.array([[0.0, 1.0], [-0.5, -0.1]]), 0.01)
loaded = sorted(m for m in ("numba.np.arraymath", "numba.np.random", "scipy.linalg")
                if m in sys.modules)
later = numba.njit(lambda a: np.cumsum(a) @ a)(np.arange(4.0))
print(json.dumps({"Phi": Phi.tolist(), "runtime": jit.RUNTIME["source"], "later": later,
                  "compiled": sum(lti.discretize._cache_misses.values()), "loaded": loaded}))
"""


def _child(cache: Path) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), shipped.ENV: "0"}
    out = subprocess.run([sys.executable, "-c", _CHILD], env=env, cwd=cache,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_numbas_runtime_is_compiled_once_then_loaded_from_the_user_cache(tmp_path):
    """The first process compiles numba's runtime library and saves its machine code; the next
    loads it (same results); a damaged file is compiled again and replaced."""
    first = _child(tmp_path)
    saved = sorted(tmp_path.rglob("*.nrt"))
    assert first["runtime"] == "compiled" and len(saved) == 1
    assert first["compiled"] == 1 and "numba.np.arraymath" in first["loaded"]
    assert "scipy.linalg" not in first["loaded"]  # numba's BLAS check answered without it
    second = _child(tmp_path)
    assert second["runtime"] == "user cache"
    assert second["Phi"] == first["Phi"]
    saved[0].write_bytes(saved[0].read_bytes()[:100])  # truncated
    third = _child(tmp_path)
    assert third["runtime"] == "compiled" and third["Phi"] == first["Phi"]
    assert _child(tmp_path)["runtime"] == "user cache"


def test_a_cached_kernel_loads_without_numbas_registries_and_numba_still_compiles(tmp_path):
    """A kernel from the cache needs none of the implementations numba compiles with (nor
    scipy); a function compiled after it in the same process has them loaded by numba."""
    first = _child(tmp_path)
    second = _child(tmp_path)
    assert second["compiled"] == 0 and second["loaded"] == []
    assert second["Phi"] == first["Phi"]
    a = np.arange(4.0)
    assert second["later"] == first["later"] == float(np.cumsum(a) @ a)
