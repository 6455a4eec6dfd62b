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
# CPU into the cache of NUMBA_CACHE_DIR; prints its result and where numba's runtime came from.
_CHILD = """
import json
import numpy as np
from navreplay.core import jit
from navreplay.core import lti
Phi = lti.discretize(np.array([[0.0, 1.0], [-0.5, -0.1]]), 0.01)
print(json.dumps({"Phi": Phi.tolist(), "runtime": jit.RUNTIME["source"]}))
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
    second = _child(tmp_path)
    assert second["runtime"] == "user cache"
    assert second["Phi"] == first["Phi"]
    saved[0].write_bytes(saved[0].read_bytes()[:100])  # truncated
    third = _child(tmp_path)
    assert third["runtime"] == "compiled" and third["Phi"] == first["Phi"]
    assert _child(tmp_path)["runtime"] == "user cache"
