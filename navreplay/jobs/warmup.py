"""Fill numba's cache before the first real run: ``navreplay warm-up``.

The package's kernels are compiled by numba the first time they run and kept in its cache
(``__pycache__`` next to the sources, or numba's user cache directory when that is not
writable, or ``NUMBA_CACHE_DIR``). Without the cache a first ``navreplay run gps-ins`` spends
most of its time compiling. :func:`warm_up` does that work once, ahead of time: it simulates a
short recording for each built-in filter (:data:`PLAN`), writes it to a temporary directory and
replays it with ``navreplay run``'s own code path (decode, filter, summary, no viewer), one
filter per process, as many processes as cores. ``make install`` calls it.

The cache is keyed by the source files and the CPU: after an upgrade of navreplay or numba, or
on another machine kind, a first run compiles again (and warms the cache as it goes). Warm-up
compiles for this CPU, so it turns the shipped kernels off (:mod:`navreplay.core.shipped`).

:func:`ship` builds those shipped kernels: the same plan, in one process whose numba compiles
for a portable CPU into an empty cache, then stored as the package's store. The wheel build
runs it (``python -m navreplay.jobs.warmup --ship DIR``, from ``setup.py``).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import os
import platform
import shutil
import subprocess
import sys
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
    from navreplay.core import shipped

    before = os.environ.get(shipped.ENV)
    os.environ[shipped.ENV] = "0"  # compile for this CPU (the worker processes inherit it)
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
            if before is None:
                del os.environ[shipped.ENV]
            else:
                os.environ[shipped.ENV] = before
    return time.perf_counter() - start


PORTABLE = {"NUMBA_CPU_NAME": "generic", "NUMBA_CPU_FEATURES": ""}
"""numba's settings for code that runs on any CPU of the architecture (its baseline)."""


def ship(out: Path) -> int:
    """Build the shipped kernels into ``out``: every filter of :data:`PLAN` replayed in one
    child process whose numba compiles for :data:`PORTABLE` into an empty cache (in
    :data:`PLAN`'s order, with a fixed hash seed, without address randomisation where
    ``setarch -R`` is at hand and without numba's type annotations, so that the same sources
    and tools give the same files), then stored with its manifest
    (:func:`navreplay.core.shipped.write`). Returns the number of kernels stored; raises
    ``subprocess.CalledProcessError`` when the child fails."""
    from navreplay.core import shipped

    with tempfile.TemporaryDirectory(prefix="navreplay-kernels-") as tmp:
        cache = Path(tmp) / "cache"
        env = {**os.environ, **PORTABLE, "NUMBA_CACHE_DIR": str(cache), shipped.ENV: "0",
               "PYTHONHASHSEED": "0"}  # numba names some constants by their hash
        # no address randomisation: numba names array expressions by an object's address
        cmd = [*_no_aslr(), sys.executable, "-m", "navreplay.jobs.warmup", "--compile"]
        subprocess.run(cmd, env=env, cwd=tmp, check=True)
        magic = json.loads((cache / "magic.json").read_text())
        return shipped.write(cache, out, tuple(magic))


def _no_aslr() -> list[str]:
    """``setarch ARCH -R`` (run a command without address randomisation) where it works."""
    setarch = shutil.which("setarch")
    if sys.platform != "linux" or setarch is None:
        return []
    cmd = [setarch, platform.machine(), "-R"]
    return cmd if subprocess.run([*cmd, "true"], capture_output=True).returncode == 0 else []


def _compile_plan() -> None:
    """The child of :func:`ship`: warm every filter in this process, then write numba's
    code-generation key next to the cache."""
    from numba.core.registry import cpu_target

    from navreplay.core.jit import KernelCache

    KernelCache.annotations = False  # the same files from the same sources
    with tempfile.TemporaryDirectory() as tmp:
        for name in PLAN:
            warm_filter(name, tmp)
    magic = cpu_target.target_context.codegen().magic_tuple()
    (Path(os.environ["NUMBA_CACHE_DIR"]) / "magic.json").write_text(json.dumps(list(magic)))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="Build the shipped kernels (navreplay.core.shipped).")
    ap.add_argument("--ship", type=Path, help="store to write")
    ap.add_argument("--compile", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.compile:
        _compile_plan()
    elif args.ship:
        n = ship(args.ship)
        print(f"navreplay: {n} kernels compiled for a portable CPU into {args.ship}")
        if n == 0:
            sys.exit("navreplay: no kernel was compiled")
    else:
        ap.error("--ship DIR is required")
