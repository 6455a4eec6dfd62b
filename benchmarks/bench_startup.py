"""CPU time of a first run after install (numba compiles its kernels) against a warm run, and
the fixed cost of starting the command.

Every figure is the user + system CPU time (and the wall time) of a fresh interpreter:

- ``first run``: ``navreplay run FILTER REC --no-viz`` (gps-ins unless ``--filter``) with
  ``NUMBA_CACHE_DIR`` pointing at a new, empty directory, as after ``pip install``: every
  kernel the run needs is compiled;
- ``warm run``: the same command again, the kernels loaded from that cache;
- ``start-up``: ``navreplay --help`` (imports and the command line, no replay), against a bare
  ``python -c pass`` measured in the same run.

``compile`` is the first run minus the warm run. Medians over ``--repeat`` runs (each first run
with its own empty cache). Target: the first run at most 5 s of CPU (what a user waits for after a
plain ``pip install``, without ``navreplay warm-up``).

Usage::

    python -m benchmarks.bench_startup [--filter gps-ins] [--recording REC] [--repeat 3]
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
            env = {**os.environ, "NUMBA_CACHE_DIR": cache}
            rows["first run"].append(_measure(run, env, cwd))
            rows["warm run"].append(_measure(run, env, cwd))
            rows["start-up"].append(_measure([*navreplay, "--help"], env, cwd))
            rows["python"].append(_measure([sys.executable, "-c", "pass"], env, cwd))
    return {k: (statistics.median(c for c, _ in v), statistics.median(w for _, w in v))
            for k, v in rows.items()}


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # quick: once, with ins (the fewest kernels to compile of the INS filters)
    ap.add_argument("--filter", default="ins" if quick else "gps-ins",
                    help="filter to run (default gps-ins)")
    ap.add_argument("--recording", type=Path, default=RECORDING)
    ap.add_argument("--repeat", type=int, default=1 if quick else 3)
    args = ap.parse_args([] if argv is None else argv)
    m = measure(args.recording, args.repeat, args.filter)
    print(f"navreplay run {args.filter} {args.recording.name} --no-viz, fresh interpreters, medians "
          f"of {args.repeat}; load average {os.getloadavg()[0]:.2f}")
    for name, (cpu, wall) in m.items():
        print(f"  {name:10s} {cpu:6.2f} s CPU  {wall:6.2f} s wall")
    first, warm = m["first run"][0], m["warm run"][0]
    print(f"  compile (first - warm)  {first - warm:6.2f} s CPU")
    print(f"  first run / warm run    {first / warm:6.2f}x CPU")
    print(f"  start-up - python       {m['start-up'][0] - m['python'][0]:6.2f} s CPU")
    verdict = "met" if first <= FIRST_RUN_TARGET else "NOT met"
    print(f"first run with an empty cache: {first:.2f} s CPU (target <= {FIRST_RUN_TARGET:g} s: "
          f"{verdict})")


if __name__ == "__main__":
    main(sys.argv[1:])
