"""Benchmarks: each ``bench_*.py`` module has a ``main()`` that prints ratios against a baseline
measured in the same run. Run them all with ``python -m benchmarks`` (or one with
``python -m benchmarks.bench_io``)."""

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
