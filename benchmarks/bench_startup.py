"""CPU time of the first run after ``pip install`` against a warm run, what compiling the
kernels costs without the ones shipped in the wheel, and the fixed cost of starting the command.

Every figure is the user + system CPU time (and the wall time) of a fresh interpreter:

- ``first run``: ``navreplay run FILTER REC --no-viz`` (gps-ins unless ``--filter``) with
  ``NUMBA_CACHE_DIR`` pointing at a new, empty directory and the shipped kernels off (what a
  checkout without them, or an edited kernel, costs): every kernel the run needs is compiled;
- ``warm run``: the same command again, the kernels loaded from that cache;
- ``start-up``: ``navreplay --help`` (imports and the command line, no replay), against a bare
  ``python -c pass`` measured in the same run;
- ``first run after pip install`` (unless ``--no-install``): a new virtual environment,
  ``pip install`` of this source tree (no make: the wheel build compiles the kernels for a
  portable CPU, :mod:`navreplay.core.shipped`), then the same command in it, its numba cache
  empty; with the install's own CPU and wall time (dependencies from pip's cache or the index);
- ``portable / host-tuned kernels``: in that environment, the filter's replay over a simulated
  ``vehicle-drive`` of ``--speed-duration`` seconds (1 h; seed 1) timed in the process (best of
  ``--speed-repeat``; decode not included), with the shipped portable kernels and with kernels
  compiled for this CPU (the shipped ones off).

``compile`` is the first run minus the warm run. Medians over ``--repeat`` runs (each first run
with its own empty cache). Target: the first run after a plain ``pip install`` (no make, no
``navreplay warm-up``) at most 5 s of CPU.

Usage::

    python -m benchmarks.bench_startup [--filter gps-ins] [--recording REC] [--repeat 3]
        [--no-install] [--speed-repeat 5] [--speed-duration 3600]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RECORDING = ROOT / "recordings" / "golden" / "vehicle-drive.mcap"
SHIPPED_OFF = "NAVREPLAY_SHIPPED_KERNELS"
"""Set to 0: the kernels shipped in the wheel are not used (navreplay.core.shipped.ENV)."""
FIRST_RUN_TARGET = 5.0
"""CPU seconds of a first run with an empty cache."""


def _measure(cmd: list[str], env: dict[str, str], cwd: str) -> tuple[float, float]:
    """(CPU [s], wall [s]) of a child process running ``cmd`` to its end."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(cmd, env=env, cwd=cwd, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def measure(recording: Path, repeat: int, filt: str = "gps-ins") -> dict[str, tuple[float, float]]:
    """Medians of (CPU, wall) [s] of the first run, the warm run, start-up and a bare
    interpreter."""
    navreplay = [sys.executable, "-m", "navreplay"]
    run = [*navreplay, "run", filt, str(recording), "--no-viz"]
    rows: dict[str, list[tuple[float, float]]] = {
        "first run": [], "warm run": [], "start-up": [], "python": []}
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as cwd:
            env = {**os.environ, "NUMBA_CACHE_DIR": cache, SHIPPED_OFF: "0"}
            rows["first run"].append(_measure(run, env, cwd))
            rows["warm run"].append(_measure(run, env, cwd))
            rows["start-up"].append(_measure([*navreplay, "--help"], env, cwd))
            rows["python"].append(_measure([sys.executable, "-c", "pass"], env, cwd))
    return {k: (statistics.median(c for c, _ in v), statistics.median(w for _, w in v))
            for k, v in rows.items()}


_SPEED = """
import sys, time
from navreplay.filters.registry import load_filter
from navreplay.io import read_recording
from navreplay.replay import replay
rec, best = read_recording(sys.argv[1]), float("inf")
for _ in range(int(sys.argv[3]) + 1):  # the first loads or compiles the kernels
    t = time.process_time()
    replay(rec, load_filter(sys.argv[2]))
    best = min(best, time.process_time() - t)
print(best)
"""


def installed(recording: Path, filt: str, speed_repeat: int,
              speed_duration: float) -> dict[str, float]:
    """A new virtual environment with this source tree ``pip install``-ed into it: the
    install's CPU and wall time [s], the first and the second ``navreplay run`` in it (CPU,
    wall [s]), and the best replay CPU time [s] of a simulated drive of ``speed_duration``
    seconds with the shipped and with host-compiled kernels."""
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="navreplay-install-") as tmp:
        venv = Path(tmp) / "venv"
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        py = str(venv / "bin" / "python")
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", SHIPPED_OFF)}
        out["install"], out["install wall"] = _measure(
            [py, "-m", "pip", "install", "-q", str(ROOT)], env, tmp)
        run = [str(venv / "bin" / "navreplay"), "run", filt, str(recording), "--no-viz"]
        for name in ("first", "second"):  # its own cache (site-packages) empty at first
            out[name], out[f"{name} wall"] = _measure(run, env, tmp)
        drive = Path(tmp) / "speed.mcap"
        subprocess.run([str(venv / "bin" / "navreplay"), "simulate", "vehicle-drive", "-o",
                        str(drive), "--duration", str(speed_duration), "--seed", "1"],
                       env=env, cwd=tmp, check=True, stdout=subprocess.DEVNULL)
        for name, extra in (("portable", {}), ("host", {SHIPPED_OFF: "0"})):
            with tempfile.TemporaryDirectory() as cache:
                done = subprocess.run(
                    [py, "-c", _SPEED, str(drive), filt, str(speed_repeat)],
                    env={**env, **extra, "NUMBA_CACHE_DIR": cache}, cwd=tmp, check=True,
                    capture_output=True, text=True)
                out[name] = float(done.stdout.split()[-1])
    return out


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # quick: once, with ins (the fewest kernels to compile of the INS filters)
    ap.add_argument("--filter", default="ins" if quick else "gps-ins",
                    help="filter to run (default gps-ins)")
    ap.add_argument("--recording", type=Path, default=RECORDING)
    ap.add_argument("--repeat", type=int, default=1 if quick else 3)
    ap.add_argument("--no-install", action="store_true",
                    help="skip the fresh virtual environment (pip install, about 2 min)")
    ap.add_argument("--speed-repeat", type=int, default=5)
    ap.add_argument("--speed-duration", type=float, default=3600.0)
    args = ap.parse_args([] if argv is None else argv)
    m = measure(args.recording, args.repeat, args.filter)
    print(f"navreplay run {args.filter} {args.recording.name} --no-viz, fresh interpreters, "
          f"medians of {args.repeat}; load average {os.getloadavg()[0]:.2f}")
    for name, (cpu, wall) in m.items():
        print(f"  {name:10s} {cpu:6.2f} s CPU  {wall:6.2f} s wall")
    first, warm = m["first run"][0], m["warm run"][0]
    print(f"  compile (first - warm)  {first - warm:6.2f} s CPU")
    print(f"  first run / warm run    {first / warm:6.2f}x CPU")
    print(f"  start-up - python       {m['start-up'][0] - m['python'][0]:6.2f} s CPU")
    print(f"first run with an empty cache, no shipped kernels: {first:.2f} s CPU")
    if args.no_install or quick:
        return
    i = installed(args.recording, args.filter, args.speed_repeat, args.speed_duration)
    print(f"fresh virtual environment, pip install of the source tree: {i['install']:.1f} s CPU, "
          f"{i['install wall']:.1f} s wall")
    print(f"  first run  {i['first']:6.2f} s CPU  {i['first wall']:6.2f} s wall")
    print(f"  second run {i['second']:6.2f} s CPU  {i['second wall']:6.2f} s wall")
    print(f"  {args.filter} replay of a {args.speed_duration:g}-s drive, best of "
          f"{args.speed_repeat}: shipped portable kernels "
          f"{i['portable']:.3f} s, host-tuned {i['host']:.3f} s, portable / host = "
          f"{i['portable'] / i['host']:.2f}x")
    verdict = "met" if i["first"] <= FIRST_RUN_TARGET else "NOT met"
    print(f"first run after pip install: {i['first']:.2f} s CPU, {first / i['first']:.1f}x less "
          f"than compiling (target <= {FIRST_RUN_TARGET:g} s: {verdict})")


if __name__ == "__main__":
    main(sys.argv[1:])
