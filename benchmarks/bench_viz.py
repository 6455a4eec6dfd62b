"""Scoring and Rerun logging of a 1-hour run against the filter, as ``navreplay run`` does them.

The run: ``navreplay run gps-ins DRIVE.mcap --save OUT.rrd`` over a simulated 1-hour
``vehicle-drive`` (seed 1; IMU and truth at 100 Hz, GNSS at 1 Hz, outputs at 10 Hz), in a fresh
interpreter per measurement: the command itself (window by window, each window's estimates
scored and drawn as they come), after the same command over a 20-second drive in the same
interpreter, with ``--no-viz`` and then with ``--save``: what a process pays once (importing
and loading the compiled kernels, the modules Rerun imports when it first encodes a bar chart)
is neither the filter's time nor the view's; the view's first use, on the 20-second drive, is
printed beside (the imports' cost is :mod:`benchmarks.bench_realdrive`'s whole-run figure).
Timers on the parts of the pipeline take the CPU time of the main thread:

- filter: the replay sessions (``ReplaySession.feed``: the filter over each window);
- scoring: the scorers (``RunScorer.add``, ``add_truth``), less the view's calls made from
  inside them (the scorer hands each block of scored rows to the sink);
- logging: the sink's calls (``Sink.start``, ``truth``, ``rows``, ``innovations``,
  ``summaries``, ``close``) plus the CPU time of the process's other threads from the start of
  the run to its end (Rerun's encoder and file writer; none without a view).

Figures are medians of ``--repeat`` fresh interpreters. The target (issue 26): scoring plus
logging at most the filter's own time. For scale, the same number of rows logged with one
``rr.log`` call each (a few thousand rows timed, extrapolated).

    python -m benchmarks.bench_viz [--minutes 60] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

_CHILD = """
import json, sys, time
t = time.process_time()
import rerun
import navreplay.viz.connect
imported = time.process_time() - t
from navreplay.cli import main
from navreplay.metrics.scoring import RunScorer
from navreplay.replay.session import ReplaySession
from navreplay.viz.sink import Sink

spent = {"filter": 0.0, "scorer": 0.0, "sink": 0.0, "sink_in_scorer": 0.0}
inside = []

def timed(cls, name, part):
    real = getattr(cls, name)
    def call(*args, **kwargs):
        inside.append(part)
        t = time.thread_time()
        try:
            return real(*args, **kwargs)
        finally:
            dt = time.thread_time() - t
            inside.pop()
            if part not in inside:  # not counted twice (a call made from another of the part)
                spent[part] += dt
                if part == "sink" and "scorer" in inside:
                    spent["sink_in_scorer"] += dt
    setattr(cls, name, call)

def run(*args):
    try:
        main(["run", "gps-ins", *args, "--force"])
    except SystemExit as e:
        if e.code:
            raise

def parts(*args):
    # the run's parts [CPU s]: filter, scoring, logging (with Rerun's threads), the whole run
    for k in spent:
        spent[k] = 0.0
    p, m = time.process_time(), time.thread_time()
    run(*args)
    total = time.process_time() - p
    threads = total - (time.thread_time() - m)
    return {"filter": spent["filter"], "scoring": spent["scorer"] - spent["sink_in_scorer"],
            "logging": spent["sink"] + threads, "threads": threads, "total": total}

run(sys.argv[2], "--no-viz")  # kernels and modules loaded
timed(ReplaySession, "feed", "filter")
for name in ("add", "add_truth"):
    timed(RunScorer, name, "scorer")
for name in ("start", "truth", "rows", "innovations", "summaries", "close"):
    timed(Sink, name, "sink")
first = parts(sys.argv[2], "--save", sys.argv[3])  # the view's first use in the process
print(json.dumps({**parts(sys.argv[1], "--save", sys.argv[3]), "import": imported,
                  "first": first["logging"]}))
"""
"""A fresh interpreter's parts of ``run gps-ins DRIVE --save OUT`` [CPU s] (argv: the drive,
the short drive to warm up on, the .rrd)."""


def _environment() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    return env


def _simulate(path: Path, seconds: float) -> None:
    from navreplay.io import write_recording
    from navreplay.sim.scenario import simulate

    write_recording(path, simulate("vehicle-drive", {"duration": seconds, "imu_rate": 100.0},
                                   seed=1))


def measure(drive: Path, warm: Path, rrd: Path, work: Path) -> dict[str, float]:
    """The parts of one run in a fresh interpreter [CPU s]."""
    out = subprocess.run([sys.executable, "-c", _CHILD, str(drive), str(warm), str(rrd)],
                         cwd=work, env=_environment(), check=True, capture_output=True,
                         text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def per_sample_seconds(rows: int, directory: Path) -> float:
    """Seconds per row of logging one scalar per ``rr.log`` call (with its time set)."""
    import numpy as np
    import rerun as rr

    rec = rr.RecordingStream("navreplay-bench", recording_id="per-sample")
    rec.save(directory / "per_sample.rrd")
    values = np.random.default_rng(0).normal(size=rows)
    start = time.perf_counter()
    for i in range(rows):
        rec.set_time("time", duration=i * 0.1)
        rec.log("/f/state/x", rr.Scalars(values[i]))
    rec.flush()
    elapsed = time.perf_counter() - start
    rec.disconnect()
    return elapsed / rows


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_viz")
    # quick: the same run on a half-minute drive, once
    parser.add_argument("--minutes", type=float, default=0.5 if quick else 60.0,
                        help="length of the drive [min]")
    parser.add_argument("--repeat", type=int, default=1 if quick else 3)
    parser.add_argument("--per-sample-rows", type=int, default=200 if quick else 3000)
    args = parser.parse_args([] if argv is None else argv)

    import rerun as rr

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        drive, warm, rrd = work / "drive.mcap", work / "warm.mcap", work / "drive.rrd"
        _simulate(drive, args.minutes * 60.0)
        _simulate(warm, 20.0)
        runs = [measure(drive, warm, rrd, work) for _ in range(args.repeat)]
        chunks = rr.chunk.RrdReader(rrd).stream().to_chunks()
        rows = sum(c.num_rows for c in chunks if not c.is_static)
        entities = len({c.entity_path for c in chunks})
        size_mb = rrd.stat().st_size / 1e6
        per_row = per_sample_seconds(args.per_sample_rows, work)
    m = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    load = os.getloadavg()[0]
    print(f"navreplay run gps-ins over a {args.minutes:g}-minute vehicle-drive (100 Hz IMU, "
          f"10 Hz outputs) --save: CPU seconds, medians of {args.repeat} fresh interpreters; "
          f"load average {load:.2f}")
    print(f"filter (the replay sessions):      {m['filter']:8.2f} s")
    print(f"scoring (the scorers):             {m['scoring']:8.2f} s")
    print(f"Rerun logging (the sink):          {m['logging']:8.2f} s   (of which Rerun's threads "
          f"{m['threads']:.2f} s; {rows} rows in {entities} entities, {size_mb:.1f} MB .rrd)")
    print(f"the whole run:                     {m['total']:8.2f} s   (importing rerun and the "
          f"view before it: {m['import']:.2f} s; the view's first use in the process, on a "
          f"20 s drive: {m['first']:.2f} s)")
    ratio = (m["scoring"] + m["logging"]) / m["filter"]
    met = "met" if ratio <= 1.0 else "NOT met"
    print(f"ratio (scoring + logging) / filter: {ratio:7.2f}   (target <= 1: {met}); "
          f"logging / filter {m['logging'] / m['filter']:.2f}")
    t_per_sample = per_row * rows
    print(
        f"per-sample rr.log, extrapolated:   {t_per_sample:8.2f} s   "
        f"({per_row * 1e6:.1f} us/row from {args.per_sample_rows} rows; "
        f"{t_per_sample / m['logging']:.0f}x the columnar sink)"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
