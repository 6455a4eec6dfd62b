"""Peak memory of ``navreplay run gps-ins REC --no-viz`` against the length of the log.

Each figure is the ``VmHWM`` of a fresh interpreter (:func:`benchmarks.peak_rss`) that runs
the command on a simulated ``vehicle-drive`` recording of the given length (100 Hz IMU and
truth; simulated once into ``--dir`` and reused). ``streamed`` is the command as shipped (the
file is read in windows); ``rrd`` is the default ``navreplay run gps-ins REC`` that also saves
the .rrd (written block by block); ``outputs`` is ``navreplay run gps-ins REC --no-viz
--export DIR --report r.html`` (CSV, TUM and Odometry MCAP written and the report's series kept
block by block; the files go to a temporary directory, removed afterwards); ``whole`` reads
the recording whole and keeps every estimate, as a replay in memory does, for comparison in
the same run. With ``--gps-pause SECONDS`` the recording has no GPS fix (position and
velocity) for that long from ten minutes in: the streamed replay must not hold the IMU
samples of the pause (the reader knows the stream up to its next fix from the chunk index).

Usage::

    python -m benchmarks.bench_memory [--hours 1 4 24] [--modes streamed rrd outputs whole]
                                      [--dir DIR] [--gps-pause 3600]
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

ROOT = Path(__file__).resolve().parent.parent


def recording(hours: float, directory: Path) -> Path:
    """The simulated recording of ``hours`` (made when missing)."""
    path = directory / f"drive_{hours:g}h.mcap"
    if not path.exists():
        subprocess.run(
            [sys.executable, "-m", "navreplay", "simulate", "vehicle-drive", "-o", str(path),
             "--duration", str(hours * 3600.0), "--seed", "1"],
            check=True, cwd=ROOT, capture_output=True,
        )
    return path


PAUSE_START = 600.0
"""Start of the GPS pause of ``--gps-pause`` [s after the recording's start]."""


def paused_recording(hours: float, pause: float, directory: Path) -> Path:
    """The recording of ``hours`` without GPS fixes for ``pause`` seconds from
    :data:`PAUSE_START` (made when missing)."""
    import dataclasses

    from navreplay.core.streams import Recording, StreamKind
    from navreplay.io import read_recording
    from navreplay.io.writer import write_recording

    path = directory / f"drive_{hours:g}h_gps_pause_{pause:g}s.mcap"
    if not path.exists():
        rec = read_recording(recording(hours, directory))
        streams = dict(rec.streams)
        for kind in (StreamKind.GPS, StreamKind.GPS_VEL):
            s = streams[kind]
            t = (s.t_ns - rec.t0_ns) * 1e-9
            keep = (t < PAUSE_START) | (t > PAUSE_START + pause)
            streams[kind] = dataclasses.replace(
                s, t_ns=s.t_ns[keep], columns={k: v[keep] for k, v in s.columns.items()})
        write_recording(path, Recording(streams, rec.metadata, rec.t0_ns))
    return path


def _child(mode: str, path: str) -> None:
    """Subprocess entry: run the command, print JSON with peak RSS [MiB] and seconds."""
    import importlib
    from pathlib import Path as _Path

    from navreplay.replay.spec import FilterSpec
    from navreplay.viz.options import VizMode, VizOptions

    run = importlib.import_module("navreplay.jobs.run")
    start = time.perf_counter()
    viz = (VizOptions(mode=VizMode.SAVE, path=_Path(path).with_suffix(".rrd")) if mode == "rrd"
           else VizOptions(mode=VizMode.NONE))
    with tempfile.TemporaryDirectory(dir=_Path(path).parent) as out:
        files = ({"export_dir": _Path(out) / "export", "report_path": _Path(out) / "r.html"}
                 if mode == "outputs" else {})
        job = run.RunJob(filters=(FilterSpec("gps-ins", {}),), recordings=(_Path(path),),
                         viz=viz, **files)
        report = run._run_one(job, None) if mode == "whole" else run.run(job)
    seconds = time.perf_counter() - start
    summary = report.summary["filters"]["gps-ins"]
    print(json.dumps({"peak_mib": peak_rss() / 2**20, "seconds": seconds,
                      "pos_rms_h": summary.get("pos_rms_h")}))


def measure(mode: str, path: Path) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_memory", "--child", mode, str(path)],
        check=True, capture_output=True, text=True, cwd=ROOT,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure_all(hours_list: list[float], modes: list[str], directory: Path,
                gps_pause: float) -> None:
    """Print the peak RSS and seconds of each mode on the recording of each length."""
    base: dict[str, float] = {}
    print(f"{'log':>6} {'mode':>9} {'peak RSS':>10} {'vs first':>9} {'seconds':>8}")
    for hours in hours_list:
        path = (paused_recording(hours, gps_pause, directory) if gps_pause
                else recording(hours, directory))
        for mode in modes:
            r = measure(mode, path)
            base.setdefault(mode, r["peak_mib"])
            log = f"{hours:>5g}h" if hours >= 0.01 else f"{hours * 3600:>5g}s"
            print(f"{log} {mode:>9} {r['peak_mib']:>7.0f} MiB {r['peak_mib'] / base[mode]:>8.2f}x"
                  f" {r['seconds']:>8.1f}", flush=True)


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_memory")
    # quick: every mode on a 20-second drive in a temporary directory
    parser.add_argument("--hours", type=float, nargs="+",
                        default=[20.0 / 3600.0] if quick else [1.0, 4.0])
    parser.add_argument("--modes", nargs="+", default=["streamed", "rrd", "outputs", "whole"],
                        choices=["streamed", "rrd", "outputs", "whole"])
    parser.add_argument("--dir", type=Path, default=None,
                        help="where the simulated recordings are kept (default bench-data; "
                        "with quick, a temporary directory)")
    parser.add_argument("--gps-pause", type=float, default=0.0, metavar="SECONDS",
                        help="no GPS fix for this long from ten minutes in")
    parser.add_argument("--child", nargs=2, metavar=("MODE", "PATH"), help=argparse.SUPPRESS)
    args = parser.parse_args([] if argv is None else argv)
    if args.child:
        _child(*args.child)
        return
    if args.dir is None and quick:
        with tempfile.TemporaryDirectory() as tmp:
            measure_all(args.hours, args.modes, Path(tmp), args.gps_pause)
        return
    directory = args.dir or Path("bench-data")
    directory.mkdir(parents=True, exist_ok=True)
    measure_all(args.hours, args.modes, directory.resolve(), args.gps_pause)


if __name__ == "__main__":
    main(sys.argv[1:])
