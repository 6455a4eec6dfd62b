"""The RTS smoother of ``navreplay run gps-ins REC --smooth --no-viz --export DIR``: the time of its
backward pass against the forward pass, and the peak memory against the log's length.

Each figure comes from a fresh interpreter running the job on a simulated ``vehicle-drive``
recording (100 Hz IMU and truth, outputs at 10 Hz; the recordings of
:mod:`benchmarks.bench_memory`, simulated once into ``--dir`` and reused): ``forward`` is the
replay up to the last window (with ``--smooth`` the filter's compiled runs of events also
keep each output's transition and covariances, which are stored on disk), ``backward`` the
backward pass over the stored chunks (:func:`navreplay.replay.smoothing.backward`),
``scoring`` the smoothed run through its scorer; ``plain`` is the same job without
``--smooth``, for comparison. The peak is ``VmHWM`` (:func:`benchmarks.peak_rss`) of the process
with and without ``--smooth``. The exports and the chunks go to a temporary directory beside the
recording.

Usage::

    python -m benchmarks.bench_smoothing [--hours 1 4] [--dir DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import peak_rss
from benchmarks.bench_memory import recording

ROOT = Path(__file__).resolve().parent.parent


def _child(smooth: str, path: str) -> None:
    """Subprocess entry: the job, timed by part; JSON on stdout."""
    import importlib

    from navreplay.replay import pipeline, smoothing
    from navreplay.replay.spec import FilterSpec
    from navreplay.viz.options import VizMode, VizOptions

    run_job = importlib.import_module("navreplay.jobs.run")
    parts = {"backward": 0.0, "scoring": 0.0}
    backward, feed = smoothing.backward, pipeline._feed_smoothed

    def timed_backward(*a, **kw):  # type: ignore[no-untyped-def]
        t = time.perf_counter()
        try:
            return backward(*a, **kw)
        finally:
            parts["backward"] += time.perf_counter() - t

    def timed_feed(*a, **kw):  # type: ignore[no-untyped-def]
        t = time.perf_counter()
        try:
            return feed(*a, **kw)
        finally:
            parts["scoring"] += time.perf_counter() - t

    pipeline.backward = timed_backward  # type: ignore[assignment]
    pipeline._feed_smoothed = timed_feed  # type: ignore[assignment]
    with tempfile.TemporaryDirectory(dir=Path(path).parent) as out:
        job = run_job.RunJob(filters=(FilterSpec("gps-ins", {}),), recordings=(Path(path),),
                             viz=VizOptions(mode=VizMode.NONE), smooth=smooth == "smooth",
                             export_dir=Path(out))
        start = time.perf_counter()
        report = run_job.run(job)
        total = time.perf_counter() - start
    filters = report.summary["filters"]
    print(json.dumps({"peak_mib": peak_rss() / 2**20, "total": total, **parts,
                      "pos_rms_h": filters["gps-ins"].get("pos_rms_h"),
                      "pos_rms_h_rts": filters.get("gps-ins/rts", {}).get("pos_rms_h")}))


def measure(smooth: bool, path: Path) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_smoothing", "--child",
         "smooth" if smooth else "plain", str(path)],
        check=True, capture_output=True, text=True, cwd=ROOT,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure_all(hours_list: list[float], directory: Path) -> None:
    print(f"{'log':>6} {'plain s':>8} {'forward s':>9} {'backward s':>10} {'scoring s':>9} "
          f"{'peak plain':>11} {'peak smooth':>12}")
    for hours in hours_list:
        path = recording(hours, directory)
        plain, smooth = measure(False, path), measure(True, path)
        forward = smooth["total"] - smooth["backward"] - smooth["scoring"]
        log = f"{hours:>5g}h" if hours >= 0.01 else f"{hours * 3600:>5g}s"
        print(f"{log} {plain['total']:>8.1f} {forward:>9.1f} {smooth['backward']:>10.1f} "
              f"{smooth['scoring']:>9.1f} {plain['peak_mib']:>7.0f} MiB {smooth['peak_mib']:>8.0f}"
              " MiB", flush=True)
        print(f"{log} ratios: backward / forward = {smooth['backward'] / forward:.2f}, "
              f"forward with --smooth / without = {forward / plain['total']:.2f}, "
              f"peak with / without = {smooth['peak_mib'] / plain['peak_mib']:.2f}; "
              f"pos_rms_h {plain['pos_rms_h']:.3f} m forward, {smooth['pos_rms_h_rts']:.3f} m "
              "smoothed", flush=True)


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_smoothing")
    parser.add_argument("--hours", type=float, nargs="+",
                        default=[20.0 / 3600.0] if quick else [1.0, 4.0])
    parser.add_argument("--dir", type=Path, default=None,
                        help="where the simulated recordings are kept (default bench-data; "
                        "with quick, a temporary directory)")
    parser.add_argument("--child", nargs=2, metavar=("MODE", "PATH"), help=argparse.SUPPRESS)
    args = parser.parse_args([] if argv is None else argv)
    if args.child:
        _child(*args.child)
        return
    if args.dir is None and quick:
        with tempfile.TemporaryDirectory() as tmp:
            measure_all(args.hours, Path(tmp))
        return
    directory = args.dir or Path("bench-data")
    directory.mkdir(parents=True, exist_ok=True)
    measure_all(args.hours, directory.resolve())


if __name__ == "__main__":
    main(sys.argv[1:])
