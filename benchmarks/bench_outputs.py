"""What the outputs of ``navreplay run gps-ins REC`` cost against the replay alone, at the
default output rate and at the IMU's, as a user runs them: each figure is a fresh
``navreplay run`` process (its CPU time, user + system, and its peak resident memory).

On a simulated ``vehicle-drive`` recording (100 Hz IMU and truth; ``--minutes``, default 60),
at ``--output-rate`` 10 and 100 Hz:

- ``no-viz``: ``--no-viz`` (the replay, scoring and summary);
- ``export``: ``--no-viz --export DIR`` (CSV, TUM, Odometry MCAP);
- ``rrd``: ``--save OUT.rrd --export DIR`` (the Rerun view as well).

Runs alternate between the commands; each figure is the median of ``--repeat`` runs. Targets:
export at most 1.5x the ``no-viz`` CPU time, with the .rrd at most 2x, and the peak memory at
100 Hz within 1.2x of that at 10 Hz.

    python -m benchmarks.bench_outputs [--minutes 60] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RATES = (10.0, 100.0)
MODES = ("no-viz", "export", "rrd")
TARGET = {"export": 1.5, "rrd": 2.0}
RSS_TARGET = 1.2


def _run(args: list[str], cwd: Path) -> tuple[float, float]:
    """(CPU seconds, peak RSS [MiB]) of one fresh process running ``args`` to its end.

    ``os.wait4`` gives the child's own figures (the parent is small and imports nothing
    of navreplay, so the peak it carries over at fork does not show)."""
    proc = subprocess.Popen([sys.executable, "-m", "navreplay", *args], cwd=cwd,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.returncode:
        raise RuntimeError(f"navreplay {' '.join(args)} failed:\n{err}")
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


def _command(mode: str, rate: float, rec: Path, out: Path) -> list[str]:
    args = ["run", "gps-ins", str(rec), "--output-rate", f"{rate:g}"]
    if mode == "no-viz":
        return [*args, "--no-viz"]
    args += ["--export", str(out / "export"), "--force"]
    return [*args, "--no-viz"] if mode == "export" else [*args, "--save", str(out / "v.rrd")]


def measure(rec: Path, repeat: int, work: Path) -> dict[tuple[str, float], tuple[float, float]]:
    """Median (CPU s, peak MiB) of each mode at each rate, runs alternated."""
    runs: dict[tuple[str, float], list[tuple[float, float]]] = {}
    for _ in range(repeat):
        for rate in RATES:
            for mode in MODES:
                out = work / "out"
                runs.setdefault((mode, rate), []).append(
                    _run(_command(mode, rate, rec, out), work))
                shutil.rmtree(out, ignore_errors=True)
    return {k: (statistics.median(c for c, _ in v), statistics.median(m for _, m in v))
            for k, v in runs.items()}


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_outputs")
    # quick: one run of each on a 20-second drive
    ap.add_argument("--minutes", type=float, default=20.0 / 60.0 if quick else 60.0)
    ap.add_argument("--repeat", type=int, default=1 if quick else 3)
    args = ap.parse_args([] if argv is None else argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        rec = work / "drive.mcap"
        subprocess.run([sys.executable, "-m", "navreplay", "simulate", "vehicle-drive", "-o",
                        str(rec), "--duration", str(args.minutes * 60.0), "--seed", "1"],
                       check=True, cwd=work, capture_output=True)
        if not quick:  # the compiled kernels in the cache first
            subprocess.run([sys.executable, "-m", "navreplay", "run", "gps-ins", str(rec),
                            "--no-viz"], check=True, cwd=work, capture_output=True)
        m = measure(rec, args.repeat, work)
    print(f"navreplay run gps-ins on a {args.minutes:g}-minute vehicle-drive (100 Hz IMU), "
          f"fresh processes, medians of {args.repeat}; load average {os.getloadavg()[0]:.2f}")
    print(f"  {'output rate':>11} {'mode':>7} {'CPU s':>7} {'peak MiB':>9}")
    for rate in RATES:
        for mode in MODES:
            cpu, rss = m[mode, rate]
            print(f"  {rate:>8g} Hz {mode:>7} {cpu:>7.2f} {rss:>9.0f}")
    for rate in RATES:
        base = m["no-viz", rate][0]
        for mode, target in TARGET.items():
            r = m[mode, rate][0] / base
            verdict = "met" if r <= target else "NOT met"
            print(f"{mode} / no-viz CPU at {rate:g} Hz: {r:.2f}x (target <= {target:g}x: "
                  f"{verdict})")
    for mode in MODES:
        r = m[mode, 100.0][1] / m[mode, 10.0][1]
        verdict = "met" if r <= RSS_TARGET else "NOT met"
        print(f"{mode} peak RSS 100 Hz / 10 Hz: {r:.2f}x (target <= {RSS_TARGET:g}x: "
              f"{verdict})")


if __name__ == "__main__":
    main(sys.argv[1:])
