"""The garbage collector rests while numba compiles a kernel, and only then."""

from __future__ import annotations

import gc

import numba
from numba.core import event

import navreplay.core.jit  # noqa: F401  (registers the listener)


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
