"""The size of the Rerun view per hour of recording, drawn as min/max envelopes (the default)
and at full rate (``--full-rate``), as a user makes it: ``navreplay run ins,gps-ins REC
--save OUT.rrd`` on a simulated ``vehicle-drive`` (100 Hz IMU and truth, GNSS at 1 Hz,
outputs at ``--output-rate``, default 10 Hz, and at 100 Hz drawn; ``--minutes``, default 60).

Each series is drawn as the smallest and the largest value per second (every peak kept; the
summary and the exports use every row), so the file grows with the hours, not with the output
rate. Target: the default view of two filters at most 30 MB per hour of recording.

    python -m benchmarks.bench_rrd_size [--minutes 60] [--output-rate 10]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_MB_PER_HOUR = 30.0


def _rrd(rec: Path, out: Path, rate: float, *extra: str) -> tuple[float, float]:
    """(size [MB], wall seconds) of the .rrd of one fresh ``navreplay run`` process."""
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "navreplay", "run", "ins,gps-ins", str(rec),
                    "--save", str(out), "--output-rate", f"{rate:g}", *extra],
                   check=True, stdout=subprocess.DEVNULL)
    return out.stat().st_size / 1e6, time.perf_counter() - start


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_rrd_size")
    parser.add_argument("--minutes", type=float, default=1.0 if quick else 60.0,
                        help="recording length [min]")
    parser.add_argument("--output-rate", type=float, default=10.0, help="filter outputs [Hz]")
    args = parser.parse_args([] if argv is None else argv)
    hours = args.minutes / 60.0
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "drive.mcap"
        subprocess.run([sys.executable, "-m", "navreplay", "simulate", "vehicle-drive", "-o",
                        str(rec), "--seed", "1", "--duration", f"{args.minutes * 60:g}"],
                       check=True, stdout=subprocess.DEVNULL)
        full, t_full = _rrd(rec, Path(tmp) / "full.rrd", args.output_rate, "--full-rate")
        drawn, t_drawn = _rrd(rec, Path(tmp) / "drawn.rrd", args.output_rate)
        fast, t_fast = _rrd(rec, Path(tmp) / "fast.rrd", 100.0)
    print(f"run ins,gps-ins over a {args.minutes:g} min vehicle-drive, outputs at "
          f"{args.output_rate:g} Hz")
    print(f"  full rate (--full-rate):   {full:8.1f} MB  {full / hours:8.1f} MB/h  "
          f"({t_full:.1f} s)")
    print(f"  drawn envelopes (default): {drawn:8.1f} MB  {drawn / hours:8.1f} MB/h  "
          f"({t_drawn:.1f} s)")
    print(f"  drawn, outputs at 100 Hz:  {fast:8.1f} MB  {fast / hours:8.1f} MB/h  "
          f"({t_fast:.1f} s)")
    met = "met" if drawn / hours <= TARGET_MB_PER_HOUR else "NOT met"
    print(f"size per hour: {drawn / hours:.1f} MB/h, {full / drawn:.1f}x smaller than full rate "
          f"(target <= {TARGET_MB_PER_HOUR:g} MB/h: {met})")


if __name__ == "__main__":
    main(sys.argv[1:])
