"""Fill numba's cache before the first real run: ``navreplay warm-up``.

The package's kernels are compiled by numba the first time they run and kept in its cache
(``__pycache__`` next to the sources, or numba's user cache directory when that is not
writable, or ``NUMBA_CACHE_DIR``). Without the cache a first ``navreplay run gps-ins`` spends
most of its time compiling. :func:`warm_up` does that work once, ahead of time: it simulates a
short recording for each built-in filter (:data:`PLAN`), writes it to a temporary directory and
replays it with ``navreplay run``'s own code path (decode, filter, summary, no viewer), one
filter per process, as many processes as cores. ``make install`` calls it.

The cache is keyed by the source files and the CPU: after an upgrade of navreplay or numba, or
on another machine kind, a first run compiles again (and warms the cache as it goes).
"""

from __future__ import annotations

import concurrent.futures as cf
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

PLAN: dict[str, tuple[str, float]] = {
    "ins": ("vehicle-drive", 40.0),
    "gps-ins": ("vehicle-drive", 40.0),
    "rpm-aided-ins": ("underwater-rpm", 40.0),
    "transfer-alignment": ("ship-transfer-alignment", 20.0),
    "vector-matching": ("gimpo-accel-yaw", 30.0),
}
"""Built-in filter -> (scenario, duration [s]) of the recording that warms it: the shortest
that takes every kernel of the filter's replay (its measurement updates included)."""
EXPORTS = "gps-ins"
"""The filter whose warm-up run also writes ``--export`` (compiling the exports' number
formatting, :mod:`navreplay.export.numbers`)."""
_ENGINE_ONLY = {"vector-matching"}
"""Filters whose warm-up recording carries no initial attitude for ``navreplay run`` (their
runs take ``--init``): read back and replayed by the engine itself."""


def warm_filter(name: str, directory: str) -> tuple[str, float]:
    """Simulate the filter's warm-up recording into ``directory`` and replay it as
    ``navreplay run NAME REC --no-viz`` does; (name, CPU seconds of this process)."""
    from navreplay.jobs.run import RunJob, run
    from navreplay.jobs.simulate import SimulateJob, simulate
    from navreplay.replay.spec import FilterSpec
    from navreplay.viz.options import VizMode, VizOptions

    start = time.process_time()
    scenario, duration = PLAN[name]
    path = Path(directory) / f"{name}.mcap"
    simulate(SimulateJob(scenario, path, values={"duration": duration}, force=True))
    if name in _ENGINE_ONLY:
        from navreplay.filters.registry import load_filter
        from navreplay.io import read_recording
        from navreplay.replay import replay

        replay(read_recording(path), load_filter(name))
    else:
        run(RunJob(filters=(FilterSpec(name),), recordings=(path,),
                   viz=VizOptions(VizMode.NONE),
                   export_dir=Path(directory) / "export" if name == EXPORTS else None))
    return name, time.process_time() - start


def warm_up(
    filters: Sequence[str] | None = None, workers: int | None = None,
    progress: Callable[[str, float], None] | None = None,
) -> float:
    """Compile the kernels of ``filters`` (default: all of :data:`PLAN`) into numba's cache,
    ``workers`` processes at once (default: one per core); ``progress(name, cpu_s)`` after
    each. Returns the wall time [s]."""
    names = list(PLAN) if filters is None else list(filters)
    unknown = [n for n in names if n not in PLAN]
    if unknown:
        raise ValueError(f"no warm-up for {', '.join(unknown)}; built-in filters: "
                         f"{', '.join(PLAN)}")
    workers = max(1, min(len(names), workers or os.cpu_count() or 1))
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="navreplay-warm-up-") as tmp:
        if workers == 1:
            done = (warm_filter(n, tmp) for n in names)
        else:
            ex = cf.ProcessPoolExecutor(max_workers=workers)
            done = (f.result() for f in cf.as_completed(
                [ex.submit(warm_filter, n, tmp) for n in names]))
        try:
            for name, cpu in done:
                if progress is not None:
                    progress(name, cpu)
        finally:
            if workers > 1:
                ex.shutdown(cancel_futures=True)
    return time.perf_counter() - start
