"""CPU time and peak memory of ``navreplay run gps-ins`` on the real-drive class of log.

The log: a 9-minute car drive (``vehicle-drive``, seed 26) with a consumer MEMS IMU
(``sensors.imu.grade=consumer``: 0.1 deg/s turn-on gyro bias, 20 mg) at 100 Hz and GNSS fixes
at 1 Hz, written as a robot writes it: a rosbag2 folder written by ``rosbags`` (its ``Writer``,
each message serialised by its CDR serialiser), with ``sensor_msgs/Imu`` in ``imu_link`` (FLU,
REP-103) and ``sensor_msgs/NavSatFix`` with its covariance; the start and the IMU's
specifications go in a TOML file (``[initial]``, ``[sensors.imu]``), as KF-GINS takes them from
its configuration. The same drive is written in both rosbag2 storages (MCAP, the default since
ROS 2 Jazzy, and sqlite3, Humble's) and as navreplay's own MCAP recording (``navreplay
simulate``), since each is read by its own path. The files are made once into ``--dir``.

Each figure is a fresh interpreter running the command to its end: its user + system CPU time
(every thread: numba, Rerun's encoder) and its peak resident memory (``VmHWM`` read at exit, so
not the parent's peak carried over by fork), medians of ``--repeat`` runs alternated with the
other commands, after one default run that is not measured (it writes navreplay's byte code
and loads the files into the page cache, as any earlier run has for a user). The runs go
without ``PYTHONDONTWRITEBYTECODE`` even where it is set: with it an editable install compiles
navreplay's modules from source in every run (about 0.2 s of CPU), which an installed package
never does. The commands:

- ``default``: ``navreplay run gps-ins LOG --config drive.toml --init table`` as typed: the run
  is drawn into ``out/LOG.rrd`` (the default without ``--no-viz``, ``--spawn``...);
- ``--no-viz``: the same with ``--no-viz``;
- ``numpy``: a bare ``python -c "import numpy"``, measured in the same command: the memory
  target is its peak plus 150 MB.

Then the memory floor of a run: the resident memory of one fresh interpreter as it imports,
step by step, what ``run gps-ins BAG --no-viz`` loads before it reads any data (numpy, the
command line, llvmlite's LLVM library, numba, the run's navreplay modules, numba's CPU target
with its runtime library, one cached kernel), and then rerun, which the default
run adds to draw; each step split into pages of mapped files (libraries' code and data) and
anonymous memory (heap, Python objects, arrays). Then how much of LLVM's library is resident:
its pages are shared with the page cache, and how many a touch maps depends on the kernel and
on how the file came into the page cache (a kernel that maps a large folio whole maps up to
2 MB per touch of a library just written by ``pip install``, 4 kB after the file was read back
from disk), whether numba's runtime library came from a cache, and whether numba's
registries of implementations or scipy.linalg were imported (they must not be: a cached
kernel needs neither, ``navreplay.core.jit``).

Targets (issue 26): the CPU time within 1.5x that of a C++ filter on such a drive: KF-GINS
took 1.1 s in the issue's own measurement (KF-GINS is not run here), so 1.65 s; the
``--no-viz`` peak RSS at most 150 MB (10^6 bytes) above the bare numpy process.

Usage::

    python -m benchmarks.bench_realdrive [--dir bench-data] [--repeat 3] [--logs bag sqlite mcap]
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DURATION = 540.0
"""Length of the drive [s] (9 minutes)."""
SEED = 26
CPU_TARGET = 1.5 * 1.1
"""CPU seconds: 1.5x KF-GINS's 1.1 s on such a drive (the issue's measurement)."""
RSS_TARGET = 150e6
"""Bytes of peak RSS above a bare ``python -c "import numpy"``."""
LOGS = {"bag": "drive_bag", "sqlite": "drive_db3", "mcap": "drive.mcap"}
"""The drive in each form: a rosbag2 folder with MCAP storage, one with sqlite3 storage,
navreplay's MCAP recording."""

_CHILD = """
import atexit, runpy, sys

def _peak(path=sys.argv[1]):
    with open("/proc/self/status") as f:
        kib = next(int(x.split()[1]) for x in f if x.startswith("VmHWM:"))
    with open(path, "w") as f:
        f.write(str(kib * 1024))

atexit.register(_peak)
if sys.argv[2] == "-c":
    code, sys.argv = sys.argv[3], ["-c", *sys.argv[4:]]
    exec(compile(code, "<string>", "exec"))
else:
    sys.argv = sys.argv[2:]
    runpy.run_module(sys.argv[0], run_name="__main__", alter_sys=True)
"""
"""A fresh interpreter running ``-c CODE ARGS...`` or ``MODULE ARGS...`` (as ``python -m``)
that writes its ``VmHWM`` [bytes] at exit into the file named first."""


def make_drive(directory: Path) -> dict[str, Path]:
    """The drive in each form of :data:`LOGS` and its ``drive.toml`` (made when missing)."""
    directory.mkdir(parents=True, exist_ok=True)
    paths = {k: directory / v for k, v in LOGS.items()}
    config = directory / "drive.toml"
    if all(p.exists() for p in paths.values()) and config.exists():
        return {**paths, "config": config}
    from navreplay.io import write_recording
    from navreplay.sim.scenario import simulate

    rec = simulate("vehicle-drive", {"duration": DURATION, "imu_rate": 100.0, "gps_rate": 1.0,
                                     "sensors": {"imu": {"grade": "consumer"}}}, seed=SEED)
    if not paths["mcap"].exists():
        write_recording(paths["mcap"], rec)
    for key, storage in (("bag", "mcap"), ("sqlite", "sqlite3")):
        if not paths[key].exists():
            _write_bag(paths[key], rec, storage)
    config.write_text(_config(rec))
    return {**paths, "config": config}


def _write_bag(path: Path, rec: Any, storage: str) -> None:
    """The IMU (FLU, ``imu_link``) and GNSS fixes of ``rec`` as a rosbag2 folder, every
    message built and serialised by rosbags; written in a temporary folder, then moved."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3

    def header(t_ns: int, frame: str) -> Any:
        stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 1_000_000_000,
                                                 nanosec=t_ns % 1_000_000_000)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def vector(v: np.ndarray) -> Any:
        return T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    flu = np.array([1.0, -1.0, -1.0])  # FRD <-> FLU
    imu, gps = rec["imu"], rec["gps"]
    w, f = imu["omega_ib_b"] * flu, imu["f_b"] * flu
    unknown = np.zeros(9)
    no_orientation = unknown.copy()
    no_orientation[0] = -1.0  # REP-145: orientation not provided
    tmp = path.parent / ".part" / path.name  # the data file is named after the folder
    tmp.parent.mkdir(exist_ok=True)
    with Writer(tmp, version=9, storage_plugin=plugin) as bag:
        c_imu = bag.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=store)
        c_fix = bag.add_connection("/gnss/fix", "sensor_msgs/msg/NavSatFix", typestore=store)
        fixes = iter(range(len(gps)))
        k_fix = next(fixes, None)
        for k, t in enumerate(imu.t_ns.tolist()):
            while k_fix is not None and int(gps.t_ns[k_fix]) <= t:  # in log-time order
                _write_fix(bag, c_fix, store, gps, k_fix, header)
                k_fix = next(fixes, None)
            msg = T["sensor_msgs/msg/Imu"](
                header=header(t, "imu_link"),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=no_orientation, angular_velocity=vector(w[k]),
                angular_velocity_covariance=unknown, linear_acceleration=vector(f[k]),
                linear_acceleration_covariance=unknown)
            bag.write(c_imu, t, store.serialize_cdr(msg, msg.__msgtype__))
        while k_fix is not None:
            _write_fix(bag, c_fix, store, gps, k_fix, header)
            k_fix = next(fixes, None)
    tmp.rename(path)


def _write_fix(bag: Any, conn: Any, store: Any, gps: Any, k: int, header: Any) -> None:
    T = store.types
    lat, lon, h = gps["pos"][k]
    sigma = gps["pos_sigma"][k]
    cov = np.zeros(9)
    cov[[0, 4, 8]] = sigma[[1, 0, 2]] ** 2  # ENU
    t = int(gps.t_ns[k])
    msg = T["sensor_msgs/msg/NavSatFix"](
        header=header(t, "gnss"), status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
        latitude=math.degrees(lat), longitude=math.degrees(lon), altitude=float(h),
        position_covariance=cov, position_covariance_type=2)
    bag.write(conn, t, store.serialize_cdr(msg, msg.__msgtype__))


def _config(rec: Any) -> str:
    """``[initial]`` (the scenario's initial solution, with its errors, and its sigmas) and
    ``[sensors.imu]`` (the grade) of the drive."""
    from navreplay.geo.rotations import quat_to_euler

    init = rec.metadata.initial_nav
    lat, lon, h = init["pos"]
    roll, pitch, yaw = np.degrees(quat_to_euler(np.asarray(init["q_nb"])))
    sigma = init["sigma"]

    def vec(v: Any) -> str:
        return "[" + ", ".join(f"{float(x)!r}" for x in v) + "]"

    return (f"[initial]\nlat_deg = {math.degrees(lat)!r}\nlon_deg = {math.degrees(lon)!r}\n"
            f"h = {float(h)!r}\nv_n = {vec(init['v_n'])}\nroll_deg = {float(roll)!r}\n"
            f"pitch_deg = {float(pitch)!r}\nyaw_deg = {float(yaw)!r}\n"
            f"pos_sigma = {vec(sigma['pos_ned'])}\nvel_sigma = {vec(sigma['v_n'])}\n"
            f"att_sigma_deg = {vec(np.degrees(sigma['phi']))}\n\n"
            "[sensors.imu]\ngrade = \"consumer\"\n")


ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
"""The children's environment: byte code cached, as in a user's shell."""


_FLOOR_CHILD = """
import json
def rss():
    with open("/proc/self/status") as f:
        d = {x.split(":")[0]: int(x.split()[1]) * 1024 for x in f
             if x.startswith(("VmRSS:", "RssAnon:", "RssFile:"))}
    return d["VmRSS"], d["RssFile"], d["RssAnon"]
def llvm():
    rss_kib = size_kib = 0
    with open("/proc/self/smaps") as f:
        inside = False
        for line in f:
            if "-" in line.split()[0] and len(line.split()) >= 5:
                inside = line.rstrip().endswith("libllvmlite.so")
            elif inside and line.startswith(("Rss:", "Size:")):
                kib = int(line.split()[1])
                rss_kib, size_kib = ((rss_kib + kib, size_kib) if line.startswith("Rss:")
                                     else (rss_kib, size_kib + kib))
    return rss_kib * 1024, size_kib * 1024
steps = [("python", *rss())]
import numpy
steps.append(("numpy", *rss()))
import navreplay.cli
steps.append(("the command line (navreplay.cli)", *rss()))
import llvmlite.binding
steps.append(("llvmlite.binding (LLVM)", *rss()))
import numba
steps.append(("numba", *rss()))
import navreplay.filters.gps_ins, navreplay.io.rosbag, navreplay.jobs.run, navreplay.logs.prepare
steps.append(("the run's navreplay modules", *rss()))
from navreplay.core import jit
from numba.core.registry import cpu_target
jit._load_ready(cpu_target.target_context)  # as the first kernel's load does
steps.append(("numba's CPU target and runtime", *rss()))
from navreplay.filters import kalman
kalman.check_covariance(numpy.eye(3))
steps.append(("one cached kernel", *rss()))
library = llvm()
import rerun
steps.append(("rerun (to draw)", *rss()))
import sys
unneeded = [m for m in ("numba.np.arraymath", "scipy.linalg") if m in sys.modules]
print(json.dumps([steps, library, jit.RUNTIME.get("source"), unneeded]))
"""
"""Resident memory [bytes] of a fresh interpreter after each step of a run's imports: (step,
resident, of it mapped files, anonymous); LLVM's library (resident, mapped) before rerun;
where numba's runtime library came from; which of numba's registries (only a compilation
needs them) and scipy.linalg were imported."""


Floor = tuple[list[tuple[str, int, int, int]], tuple[int, int], str, list[str]]


def floor() -> Floor:
    """What :data:`_FLOOR_CHILD` prints."""
    import json

    out = subprocess.run([sys.executable, "-c", _FLOOR_CHILD], env=ENV, check=True,
                         capture_output=True, text=True)
    steps, library, runtime, unneeded = json.loads(out.stdout.strip().splitlines()[-1])
    return [tuple(s) for s in steps], tuple(library), runtime, unneeded


def report_floor(found: Floor) -> None:
    steps, (lib_rss, lib_size), runtime, unneeded = found
    print("memory floor of a run (resident memory of one fresh interpreter after each import; "
          "pages of mapped files and anonymous memory):")
    print(f"  {'':40s} {'files':>6s} {'anon':>5s} {'resident':>9s}")
    last = steps[0][1:]
    for name, rss, files, anon in steps:
        print(f"  + {name:38s} {(files - last[1]) / 1e6:+6.0f} {(anon - last[2]) / 1e6:+5.0f} "
              f"{(rss - last[0]) / 1e6:+5.0f} MB = {rss / 1e6:4.0f} MB")
        last = (rss, files, anon)
    at = [r for _, r, _, _ in steps]
    numba = (at[4] - at[2]) + (at[7] - at[5])
    print(f"before reading any data: {(at[7] - at[1]) / 1e6:+.0f} MB over numpy, of which LLVM "
          f"and numba (their libraries, numba's CPU target and runtime, one cached kernel) "
          f"{numba / 1e6:+.0f} MB")
    print(f"  LLVM's library: {lib_rss / 1e6:.0f} MB of its {lib_size / 1e6:.0f} MB mapped are "
          f"resident (file pages: how many a touch maps depends on the page cache's folio "
          f"size); numba's runtime from: {runtime}; numba's registries or scipy.linalg "
          f"imported: {', '.join(unneeded) or 'none'}")


def measure(argv: list[str], cwd: Path) -> tuple[float, int, float]:
    """(CPU [s], peak RSS [bytes], wall [s]) of a fresh interpreter running ``argv`` (``-c
    CODE`` or a module and its arguments)."""
    with tempfile.NamedTemporaryFile(dir=cwd, delete=False) as f:
        peak_file = Path(f.name)
    try:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", _CHILD, str(peak_file), *argv], cwd=cwd, env=ENV,
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        peak = int(peak_file.read_text())
    finally:
        peak_file.unlink(missing_ok=True)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, peak, wall


def commands(logs: dict[str, Path], config: Path) -> dict[str, list[str]]:
    """The measured commands by label: the default run and ``--no-viz`` per log, and the bare
    numpy interpreter."""
    out = {"numpy": ["-c", "import numpy"]}
    for key, path in logs.items():
        run = ["navreplay", "run", "gps-ins", str(path), "--config", str(config),
               "--init", "table"]
        out[f"{key} default"] = run
        out[f"{key} --no-viz"] = [*run, "--no-viz"]
    return out


def run_all(cmds: dict[str, list[str]], repeat: int) -> dict[str, tuple[float, int, float]]:
    """Medians of (CPU, peak RSS, wall) per command over ``repeat`` rounds, each round every
    command once (alternated, so a change of load touches all alike)."""
    rows: dict[str, list[tuple[float, int, float]]] = {k: [] for k in cmds}
    with tempfile.TemporaryDirectory() as cwd:  # the default run's out/ goes here
        measure(next(v for k, v in cmds.items() if k.endswith(" default")), Path(cwd))
        for _ in range(repeat):
            for label, argv in cmds.items():
                rows[label].append(measure(argv, Path(cwd)))
    return {k: (statistics.median(c for c, _, _ in v), int(statistics.median(p for _, p, _ in v)),
                statistics.median(w for _, _, w in v)) for k, v in rows.items()}


def report(m: dict[str, tuple[float, int, float]], logs: list[str], repeat: int) -> None:
    numpy_peak = m["numpy"][1]
    print(f"gps-ins over a {DURATION / 60:g}-minute drive (100 Hz consumer MEMS IMU, 1 Hz GNSS), "
          f"fresh interpreters, medians of {repeat}; load average {os.getloadavg()[0]:.2f}")
    if "PYTHONDONTWRITEBYTECODE" in os.environ:
        print("  (PYTHONDONTWRITEBYTECODE is set here: the runs go without it, as an installed "
              "package's)")
    print(f"  {'command':18s} {'CPU [s]':>8s} {'wall [s]':>9s} {'peak RSS':>9s} {'- numpy':>9s}")
    for label, (cpu, peak, wall) in m.items():
        print(f"  {label:18s} {cpu:8.2f} {wall:9.2f} {peak / 1e6:6.0f} MB "
              f"{(peak - numpy_peak) / 1e6:+6.0f} MB")
    for key in logs:
        name = f"{key} ({LOGS[key]})"
        for mode in ("default", "--no-viz"):
            cpu = m[f"{key} {mode}"][0]
            verdict = "met" if cpu <= CPU_TARGET else "NOT met"
            print(f"{name} {mode}: {cpu:.2f} s CPU = {cpu / 1.1:.2f}x KF-GINS's 1.1 s "
                  f"(target <= {CPU_TARGET:.2f} s: {verdict})")
        above = m[f"{key} --no-viz"][1] - numpy_peak
        verdict = "met" if above <= RSS_TARGET else "NOT met"
        print(f"{name} --no-viz: peak RSS {above / 1e6:+.0f} MB over bare numpy "
              f"(target <= +{RSS_TARGET / 1e6:.0f} MB: {verdict})")


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_realdrive",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--dir", type=Path, default=None,
                    help="where the drive is kept (default bench-data/realdrive; with quick, a "
                         "temporary directory)")
    ap.add_argument("--repeat", type=int, default=1 if quick else 3)
    ap.add_argument("--logs", nargs="+", default=["bag"] if quick else list(LOGS),
                    choices=list(LOGS))
    args = ap.parse_args([] if argv is None else argv)
    global DURATION
    if quick:  # the same code on a 20-second drive, once
        DURATION = 20.0
    with tempfile.TemporaryDirectory() as tmp:
        directory = (args.dir or (Path(tmp) if quick else Path("bench-data") / "realdrive"))
        made = make_drive(directory.resolve())
        logs = {k: made[k] for k in args.logs}
        report(run_all(commands(logs, made["config"]), args.repeat), args.logs, args.repeat)
        report_floor(floor())


if __name__ == "__main__":
    main(sys.argv[1:])
