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

The simulator holds a whole drive in memory (about 190 MB per hour), so a day-long drive does
not fit a small machine. ``--parked`` measures any length instead: a vehicle parked at the
drive's start for the whole log, with the drive's sensors (100 Hz IMU sensing gravity and the
earth's rate with a constant bias and white noise at the grade's ARW and VRW; 1 Hz GNSS fixes
and velocity; a 10 Hz magnetometer; 100 Hz truth), written an hour at a time into one file
(``write_recording(..., more=...)``). The filter does the same work per sample parked as
driving.

Usage::

    python -m benchmarks.bench_memory [--hours 1 4 24] [--modes streamed rrd outputs whole]
                                      [--dir DIR] [--gps-pause 3600] [--parked]
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


PIECE_S = 3600.0
"""Length of each piece of a parked recording [s]."""
PARKED_WHOLE_HOURS = 4.0
"""Longest parked log the ``whole`` mode (every sample and estimate held) is run on [h]."""


def parked_recording(hours: float, directory: Path) -> Path:
    """A vehicle parked for ``hours`` at the start of the simulated drive (seed 1), with its
    site, metadata and sensors, written an hour at a time (made when missing)."""
    path = directory / f"parked_{hours:g}h.mcap"
    if path.exists():
        return path
    import dataclasses

    import numpy as np

    from navreplay.core.streams import Recording, Stream, StreamKind
    from navreplay.geo.earth import gravity_n, ned_offset_to_lla, omega_ie_n
    from navreplay.geo.rotations import quat_to_dcm
    from navreplay.io.writer import write_recording
    from navreplay.sim.scenario import simulate

    drive = simulate("vehicle-drive", {"duration": 10.0}, seed=1)
    truth, spec = drive[StreamKind.TRUTH], drive.metadata.sensors
    pose = {name: col[0] for name, col in truth.columns.items()}
    lat, lon, h = pose["pos"]
    C_bn = quat_to_dcm(pose["q_nb"]).T
    f_b = C_bn @ -gravity_n(lat, h) + pose["accel_bias_eff"]
    w_b = C_bn @ omega_ie_n(lat) + pose["gyro_bias_eff"]
    m_b = C_bn @ np.asarray(drive.metadata.extra["mag_field_n"])
    rate = float(drive.metadata.params["imu_rate"])
    gps = spec["gps"]
    rng = np.random.default_rng(1)
    frames = {kind: s.frame_id for kind, s in drive.streams.items()}

    def stream(kind: StreamKind, t_s: np.ndarray, **columns: np.ndarray) -> Stream:
        t_ns = drive.t0_ns + np.round(t_s * 1e9).astype(np.int64)
        return Stream(kind, t_ns, columns, frames[kind])

    def piece(k: int) -> Recording:
        lo, hi = k * PIECE_S, min((k + 1) * PIECE_S, hours * 3600.0)
        n_imu = round((hi - lo) * rate)
        t_imu = lo + np.arange(1, n_imu + 1) / rate  # the mean over the preceding interval
        t_truth = lo + np.arange(0 if k == 0 else 1, n_imu + 1) / rate
        t_gps = lo + np.arange(0 if k == 0 else 1, round(hi - lo) + 1, dtype=float)
        t_mag = lo + np.arange(0 if k == 0 else 1, round((hi - lo) * 10) + 1) / 10.0
        white = np.sqrt(rate)
        imu = stream(StreamKind.IMU, t_imu,
                     omega_ib_b=w_b + spec["imu"]["gyro_arw"] * white * rng.standard_normal(
                         (n_imu, 3)),
                     f_b=f_b + spec["imu"]["accel_vrw"] * white * rng.standard_normal((n_imu, 3)))
        sigma = np.asarray(gps["pos_sigma"], dtype=float)
        fixes = ned_offset_to_lla(lat, lon, h, sigma * rng.standard_normal((len(t_gps), 3)))
        n = len(t_truth)
        still = {name: np.broadcast_to(value, (n, *np.shape(value))).copy()
                 for name, value in pose.items()}
        still["v_n"][:] = 0.0
        still["gps_pos_gm"][:] = 0.0
        still["gyro_bias"], still["accel_bias"] = still["gyro_bias_eff"], still["accel_bias_eff"]
        vel_sigma = np.asarray(gps["vel_sigma"], dtype=float)
        return Recording({
            StreamKind.IMU: imu,
            StreamKind.GPS: stream(StreamKind.GPS, t_gps, pos=np.column_stack(fixes),
                                   pos_sigma=np.tile(sigma, (len(t_gps), 1))),
            StreamKind.GPS_VEL: stream(
                StreamKind.GPS_VEL, t_gps,
                v_n=vel_sigma * rng.standard_normal((len(t_gps), 3)),
                vel_sigma=np.tile(vel_sigma, (len(t_gps), 1))),
            StreamKind.MAG: stream(StreamKind.MAG, t_mag, m_b=m_b + spec["mag"]["noise"]
                                   * rng.standard_normal((len(t_mag), 3))),
            StreamKind.TRUTH: stream(StreamKind.TRUTH, t_truth, **still),
        }, metadata, drive.t0_ns)

    metadata = dataclasses.replace(
        drive.metadata, params={**drive.metadata.params, "duration": hours * 3600.0})
    count = int(np.ceil(hours * 3600.0 / PIECE_S))
    write_recording(path, piece(0), more=(piece(k) for k in range(1, count)))
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
                gps_pause: float, parked: bool = False) -> None:
    """Print the peak RSS and seconds of each mode on the recording of each length."""
    base: dict[str, float] = {}
    if parked:
        print("a vehicle parked for the whole log, with the simulated drive's sensors")
    print(f"{'log':>6} {'mode':>9} {'peak RSS':>10} {'vs first':>9} {'seconds':>8}")
    warm: set[str] = set()  # a first run of each mode fills numba's cache (a compile raises a peak)
    for hours in hours_list:
        path = (parked_recording(hours, directory) if parked
                else paused_recording(hours, gps_pause, directory) if gps_pause
                else recording(hours, directory))
        for mode in modes:
            if parked and mode == "whole" and hours > PARKED_WHOLE_HOURS:
                continue  # holds the whole log: its memory grows with the length by design
            if mode not in warm:
                measure(mode, path)
                warm.add(mode)
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
    parser.add_argument("--parked", action="store_true",
                        help="a vehicle parked for the whole log (any length; see above)")
    parser.add_argument("--child", nargs=2, metavar=("MODE", "PATH"), help=argparse.SUPPRESS)
    args = parser.parse_args([] if argv is None else argv)
    if args.child:
        _child(*args.child)
        return
    if args.dir is None and quick:
        with tempfile.TemporaryDirectory() as tmp:
            measure_all(args.hours, args.modes, Path(tmp), args.gps_pause, args.parked)
        return
    directory = args.dir or Path("bench-data")
    directory.mkdir(parents=True, exist_ok=True)
    measure_all(args.hours, args.modes, directory.resolve(), args.gps_pause, args.parked)


if __name__ == "__main__":
    main(sys.argv[1:])
