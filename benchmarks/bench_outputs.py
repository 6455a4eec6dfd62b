"""What the outputs of ``navreplay run gps-ins REC`` cost against the replay alone, at the
default output rate and at the IMU's, as a user runs them: each figure is a fresh
``navreplay run`` process (the time from its start to its end, its CPU time, user + system,
and its peak resident memory), with its bytecode cached as an installed package's is
(``PYTHONDONTWRITEBYTECODE`` is dropped for the runs: compiling the sources on every start is
not what a user pays).

On simulated ``vehicle-drive`` recordings (100 Hz IMU and truth; ``--minutes``, default 10 and
60), at ``--output-rate`` 10 and 100 Hz:

- ``no-viz``: ``--no-viz`` (the replay, scoring and summary);
- ``export``: ``--no-viz --export DIR`` (CSV, TUM, the estimates MCAP);
- ``rrd``: ``--save OUT.rrd --export DIR`` (the Rerun view as well).

Runs alternate between the commands; each figure is the median of ``--repeat`` runs. Targets:
export at most 1.5x the ``no-viz`` time a user waits (wall), with the .rrd at most 2x, and the
peak memory at 100 Hz within 1.2x of that at 10 Hz. The export is written by a thread of its
own beside the replay (:mod:`navreplay.io.background`): the wall ratio is what a second core
saves; the CPU ratio, printed beside it, is the work, whatever the cores. Wall times need an
idle machine (the load average is printed).

    python -m benchmarks.bench_outputs [--minutes 10,60] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RATES = (10.0, 100.0)
MODES = ("no-viz", "export", "rrd")
TARGET = {"export": 1.5, "rrd": 2.0}
RSS_TARGET = 1.2


def _environment() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def _run(args: list[str], cwd: Path) -> tuple[float, float, float]:
    """(wall seconds, CPU seconds, peak RSS [MiB]) of one fresh process running ``args`` to
    its end.

    ``os.wait4`` gives the child's own figures (the parent is small and imports nothing
    of navreplay, so the peak it carries over at fork does not show)."""
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "navreplay", *args], cwd=cwd,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env=_environment())
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.returncode:
        raise RuntimeError(f"navreplay {' '.join(args)} failed:\n{err}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


def _command(mode: str, rate: float, rec: Path, out: Path) -> list[str]:
    args = ["run", "gps-ins", str(rec), "--output-rate", f"{rate:g}"]
    if mode == "no-viz":
        return [*args, "--no-viz"]
    args += ["--export", str(out / "export"), "--force"]
    return [*args, "--no-viz"] if mode == "export" else [*args, "--save", str(out / "v.rrd")]


def measure(rec: Path, repeat: int,
            work: Path) -> dict[tuple[str, float], tuple[float, float, float]]:
    """Median (wall s, CPU s, peak MiB) of each mode at each rate, runs alternated."""
    runs: dict[tuple[str, float], list[tuple[float, float, float]]] = {}
    for _ in range(repeat):
        for rate in RATES:
            for mode in MODES:
                out = work / "out"
                runs.setdefault((mode, rate), []).append(
                    _run(_command(mode, rate, rec, out), work))
                shutil.rmtree(out, ignore_errors=True)
    return {k: tuple(statistics.median(r[i] for r in v) for i in range(3))  # type: ignore[misc]
            for k, v in runs.items()}


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_outputs")
    # quick: one run of each on a 20-second drive
    ap.add_argument("--minutes", default="0.333" if quick else "10,60",
                    help="drive lengths [min], comma-separated")
    ap.add_argument("--repeat", type=int, default=1 if quick else 3)
    args = ap.parse_args([] if argv is None else argv)
    for minutes in (float(m) for m in args.minutes.split(",")):
        _one(minutes, args.repeat, warm=not quick)


def _one(minutes: float, repeat: int, *, warm: bool) -> None:
    """The table and the ratios of one drive length."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        rec = work / "drive.mcap"
        subprocess.run([sys.executable, "-m", "navreplay", "simulate", "vehicle-drive", "-o",
                        str(rec), "--duration", str(minutes * 60.0), "--seed", "1"],
                       check=True, cwd=work, capture_output=True, env=_environment())
        if warm:  # the compiled kernels and the bytecode in their caches first
            for mode in MODES:
                _run(_command(mode, 100.0, rec, work / "out"), work)
            shutil.rmtree(work / "out", ignore_errors=True)
        m = measure(rec, repeat, work)
    length = f"{minutes:g} min"
    print(f"navreplay run gps-ins on a {minutes:g}-minute vehicle-drive (100 Hz IMU), "
          f"fresh processes, medians of {repeat}; load average {os.getloadavg()[0]:.2f}")
    print(f"  {'output rate':>11} {'mode':>7} {'wall s':>7} {'CPU s':>7} {'peak MiB':>9}")
    for rate in RATES:
        for mode in MODES:
            wall, cpu, rss = m[mode, rate]
            print(f"  {rate:>8g} Hz {mode:>7} {wall:>7.2f} {cpu:>7.2f} {rss:>9.0f}")
    for rate in RATES:
        base_wall, base_cpu, _ = m["no-viz", rate]
        for mode, target in TARGET.items():
            r = m[mode, rate][0] / base_wall
            verdict = "met" if r <= target else "NOT met"
            print(f"{mode} / no-viz wall at {rate:g} Hz, {length}: {r:.2f}x (target <= "
                  f"{target:g}x: {verdict}); CPU {m[mode, rate][1] / base_cpu:.2f}x")
    for mode in MODES:
        r = m[mode, 100.0][2] / m[mode, 10.0][2]
        verdict = "met" if r <= RSS_TARGET else "NOT met"
        print(f"{mode} peak RSS 100 Hz / 10 Hz, {length}: {r:.2f}x (target <= {RSS_TARGET:g}x: "
              f"{verdict})")


if __name__ == "__main__":
    main(sys.argv[1:])
