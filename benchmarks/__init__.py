"""Benchmarks: each ``bench_*.py`` module has a ``main()`` that prints ratios against a baseline
measured in the same run. Run them all with ``python -m benchmarks`` (or one with
``python -m benchmarks.bench_io``); ``main(quick=True)`` (``python -m benchmarks --quick``)
runs the same code at tiny sizes in seconds, to check that they still run."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any


def best(fn: Callable[[], Any], repeat: int = 3, number: int = 1) -> float:
    """Shortest mean time of one call of ``fn`` [s] over ``repeat`` batches of ``number``
    calls."""
    shortest = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        shortest = min(shortest, time.perf_counter() - start)
    return shortest / number


def peak_rss() -> int:
    """Peak resident memory of this process [bytes] (``VmHWM``; Linux).

    Not ``resource.getrusage(...).ru_maxrss``: Linux carries that over from the parent at fork
    and keeps it across exec, so a fresh interpreter started by a large parent reports the
    parent's peak. Measure each figure in a fresh interpreter and read this there."""
    with open("/proc/self/status") as f:
        line = next(x for x in f if x.startswith("VmHWM:"))
    return int(line.split()[1]) * 1024
