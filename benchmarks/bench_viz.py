"""Rerun logging cost of a 1-hour run against the filter that produced it, measured in one run.

* filter: :func:`navreplay.replay.replay` of the free-inertial ``ins`` filter (strapdown at
  100 Hz, 15-state covariance, outputs at 10 Hz) over a synthetic stationary hour;
* log: ``open_sink(Save(...))``, the run as one block of the replay pipeline (truth, rows
  with their scores: an error series and +-3 sigma for each scored state, the navigation
  errors, the NEES), then ``close()`` (blueprint, flush, atomic rename);
* per-sample: ``rr.log`` of one scalar per call for a few thousand rows, extrapolated to the
  number of rows the sink sent (what logging sample by sample would have cost).

The design asks that logging cost no more than the filter: ratio log / filter <= 1.

    python -m benchmarks.bench_viz [--minutes 60]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import rerun as rr

from benchmarks.bench_replay import log_one_block
from navreplay.core.streams import Metadata, Recording, Stream, StreamKind
from navreplay.filters.ins import InsFilter
from navreplay.geo import gravity, omega_ie_n
from navreplay.metrics import run_metrics
from navreplay.replay import replay
from navreplay.viz import Save, open_sink

T0_NS = 1_700_000_000_000_000_000
IMU_RATE_HZ = 100
POS0 = np.array([np.deg2rad(37.55), np.deg2rad(126.8), 20.0])


def stationary_recording(minutes: float, seed: int = 0) -> Recording:
    """A level, north-facing, stationary IMU at ``IMU_RATE_HZ`` with a truth stream."""
    n = int(round(minutes * 60 * IMU_RATE_HZ))
    rng = np.random.default_rng(seed)
    t_ns = T0_NS + np.arange(1, n + 1, dtype=np.int64) * (1_000_000_000 // IMU_RATE_HZ)
    w = omega_ie_n(POS0[0])  # body = NED for a level, north-facing vehicle
    g = float(gravity(POS0[0], POS0[2]))
    imu = Stream(
        StreamKind.IMU,
        t_ns,
        {
            "omega_ib_b": w + rng.normal(0.0, 1e-6, (n, 3)),
            "f_b": np.array([0.0, 0.0, -g]) + rng.normal(0.0, 1e-3, (n, 3)),
        },
        "imu_frd",
    )
    truth = Stream(
        StreamKind.TRUTH,
        t_ns,
        {
            "pos": np.tile(POS0, (n, 1)),
            "v_n": np.zeros((n, 3)),
            "q_nb": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        },
        "ned",
    )
    meta = Metadata(
        scenario="bench-stationary",
        seed=seed,
        initial_nav={
            "t_ns": T0_NS,
            "pos": POS0.tolist(),
            "v_n": [0.0, 0.0, 0.0],
            "q_nb": [1.0, 0.0, 0.0, 0.0],
            "sigma": {"pos_ned": [1.0] * 3, "v_n": [0.05] * 3, "phi": [1e-3] * 3},
        },
    )
    return Recording({StreamKind.IMU: imu, StreamKind.TRUTH: truth}, meta, T0_NS)


def per_sample_seconds(rows: int, directory: Path) -> float:
    """Seconds per row of logging one scalar per ``rr.log`` call (with its time set)."""
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
    # quick: the same filter, sink and per-sample logging on a half-minute run
    parser.add_argument("--minutes", type=float, default=0.5 if quick else 60.0,
                        help="recording length [min]")
    parser.add_argument("--per-sample-rows", type=int, default=200 if quick else 3000)
    args = parser.parse_args([] if argv is None else argv)

    recording = stationary_recording(args.minutes)
    n_imu = len(recording[StreamKind.IMU])

    # warm-up: JIT compilation and first-use costs stay out of both timings
    warm = stationary_recording(0.2)
    warm_result = replay(warm, InsFilter, output_rate=10.0, label="ins")
    with tempfile.TemporaryDirectory() as tmp:
        with open_sink(Save(Path(tmp) / "warm.rrd")) as sink:
            log_one_block(sink, warm_result, warm, run_metrics(warm_result, warm))

    start = time.perf_counter()
    result = replay(recording, InsFilter, output_rate=10.0, label="ins")
    t_filter = time.perf_counter() - start

    metrics = run_metrics(result, recording)

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench.rrd"
        start = time.perf_counter()
        with open_sink(Save(out), recording_name="bench") as sink:
            log_one_block(sink, result, recording, metrics)
        t_log = time.perf_counter() - start
        size_mb = os.path.getsize(out) / 1e6
        chunks = rr.chunk.RrdReader(out).stream().to_chunks()
        rows = sum(c.num_rows for c in chunks if not c.is_static)
        n_entities = len({c.entity_path for c in chunks})
        per_row = per_sample_seconds(args.per_sample_rows, Path(tmp))

    m = result.t.shape[0]
    t_per_sample = per_row * rows
    print(
        f"run: {args.minutes:g} min, {n_imu} IMU samples at {IMU_RATE_HZ} Hz, {m} outputs, "
        f"{len(result.state_names)} states"
    )
    print(f"filter (replay of 'ins'):          {t_filter:8.2f} s")
    print(
        f"Rerun logging (open..close):       {t_log:8.2f} s   "
        f"{rows} rows in {n_entities} entities, {size_mb:.1f} MB .rrd"
    )
    met = "met" if t_log <= t_filter else "NOT met"
    print(f"ratio logging / filter:            {t_log / t_filter:8.3f}   (target <= 1: {met})")
    print(
        f"per-sample rr.log, extrapolated:   {t_per_sample:8.2f} s   "
        f"({per_row * 1e6:.1f} us/row from {args.per_sample_rows} rows; "
        f"{t_per_sample / t_log:.0f}x the columnar sink)"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
