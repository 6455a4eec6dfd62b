"""Replay throughput, Rerun logging cost and peak memory.

Measured in one run, on one 1-hour 100 Hz ``vehicle-drive`` recording (IMU 100 Hz, GPS fix and
velocity 1 Hz, magnetometer 10 Hz):

- end to end: decode the MCAP file + replay ``gps-ins`` + summary against the truth, in IMU
  samples per second and in multiples of real time;
- baselines: the same replay without decoding (filter only), the free inertial ``ins`` filter,
  the engine alone (a filter that does nothing: merge, slicing and bookkeeping per event), and
  the strapdown integrator over the whole record in one call (the arithmetic floor);
- Rerun logging of the gps-ins result (+ truth) into an .rrd, relative to the filter time (must
  not exceed it);
- peak resident memory of a fresh process that reads a 1-hour 200 Hz recording and replays
  gps-ins over it (must stay below 1 GiB), next to that of a process that only imports.

    python -m benchmarks replay          # or: python -m benchmarks.bench_replay [duration_s]
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

SCENARIO = "vehicle-drive"
GIB = 1024**3


def _timed(fn: Callable[[], Any], repeat: int = 1) -> tuple[float, Any]:
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def _null_filter() -> type:
    """A filter that does nothing: what remains is the engine's own cost per event."""
    from navreplay.filters.base import Estimate, Filter, NavSolution
    from navreplay.streams import StreamKind

    class Null(Filter):
        name = "null"
        requires = (StreamKind.IMU, StreamKind.GPS)
        optional = (StreamKind.GPS_VEL,)
        state_names = tuple(f"s{i}" for i in range(15))

        def __init__(self, params: Any, context: Any) -> None:
            super().__init__(params, context)
            self.t = 0.0
            self.x = np.zeros(15)
            self.P = np.eye(15)
            self.nav = NavSolution(np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))

        def propagate(self, t: np.ndarray, imu: Any) -> None:
            self.t = t[-1]

        def update(self, kind: Any, t: float, sample: Any) -> None:
            self.t = t

        def estimate(self) -> Estimate:
            return Estimate(self.t, self.x, self.P, self.nav)

    return Null


_RSS_CHILD = """
import resource, sys, time
from navreplay.filters.registry import load_filter
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
if sys.argv[1] != "-":
    from navreplay.io import read_recording
    from navreplay.replay import replay
    rec = read_recording(sys.argv[1])
    res = replay(rec, load_filter("gps-ins"), validate=False)
    assert res.t.shape[0] > 0
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
"""


def _peak_rss(path: str) -> int:
    out = subprocess.run([sys.executable, "-c", _RSS_CHILD, path], check=True,
                         capture_output=True, text=True)
    return int(out.stdout.strip().splitlines()[-1])


def _summary(result: Any, recording: Any) -> Any:
    from navreplay import jobs

    return jobs.run_summary(result, recording)


def main(duration: float = 3600.0) -> None:
    from navreplay import strapdown
    from navreplay.filters.registry import load_filter
    from navreplay.io import read_recording, write_recording
    from navreplay.replay import replay
    from navreplay.sim.scenario import simulate
    from navreplay.viz import Save, open_sink

    gps_ins = load_filter("gps-ins")
    ins = load_filter("ins")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "drive.mcap"
        t_sim, rec = _timed(lambda: simulate(SCENARIO, {"duration": duration}, seed=1))
        t_write, _ = _timed(lambda: write_recording(path, rec))
        n_imu = len(rec["imu"])
        span = (rec["imu"].t_ns[-1] - rec["imu"].t_ns[0]) * 1e-9
        print(f"recording: {SCENARIO}, {span / 3600:.2f} h, {n_imu} IMU samples, "
              f"{path.stat().st_size / 1e6:.1f} MB (simulated in {t_sim:.1f} s, "
              f"written in {t_write:.1f} s)")
        del rec

        replay(read_recording(path), gps_ins)  # warm up (numba compilation, caches)

        def end_to_end() -> tuple[Any, Any]:
            r = read_recording(path)
            res = replay(r, gps_ins, validate=False)
            _summary(res, r)
            return res, r

        t_e2e, (result, recording) = _timed(end_to_end, repeat=2)
        t_dec, _ = _timed(lambda: read_recording(path), repeat=2)
        t_filt, _ = _timed(lambda: replay(recording, gps_ins, validate=False), repeat=2)
        t_sum, _ = _timed(lambda: _summary(result, recording), repeat=2)
        t_ins, _ = _timed(lambda: replay(recording, ins, validate=False), repeat=2)
        t_null, _ = _timed(lambda: replay(recording, _null_filter(), validate=False), repeat=2)
        imu = recording["imu"]
        dt = np.diff(imu.t_ns, prepend=imu.t_ns[0] - (imu.t_ns[1] - imu.t_ns[0])) * 1e-9
        nav0 = strapdown.nav_vector(recording.metadata.initial_nav["pos"],
                                    recording.metadata.initial_nav["v_n"],
                                    recording.metadata.initial_nav["q_nb"])
        t_sd, _ = _timed(
            lambda: strapdown.propagate(nav0, imu["omega_ib_b"], imu["f_b"], dt), repeat=3
        )
        events = len(result.t)

        def rate(t: float) -> str:
            return f"{n_imu / t / 1e3:8.0f}k IMU/s {span / t:8.0f}x real time"

        print(f"outputs: {events} estimates, "
              f"{sum(len(s.t) for s in result.innovations.values())} updates")
        print(f"end to end (decode + gps-ins + summary) {t_e2e:7.2f} s  {rate(t_e2e)}")
        print(f"  decode                                {t_dec:7.2f} s  {rate(t_dec)}")
        print(f"  gps-ins replay (filter only)          {t_filt:7.2f} s  {rate(t_filt)}")
        print(f"  summary vs truth                      {t_sum:7.2f} s")
        print("baselines")
        print(f"  ins replay (free inertial)            {t_ins:7.2f} s  {rate(t_ins)}")
        print(f"  engine alone (null filter)            {t_null:7.2f} s  {rate(t_null)}"
              f"  ({t_null / events * 1e6:.1f} us per output event)")
        print(f"  strapdown, one call over the record   {t_sd:7.2f} s  {rate(t_sd)}")
        print(f"ratios: end to end / strapdown floor = {t_e2e / t_sd:.1f}, "
              f"engine share of the gps-ins replay = {t_null / t_filt:.0%}")

        rrd = Path(tmp) / "drive.rrd"

        def log() -> None:
            with open_sink(Save(rrd), recording_name=path.name) as sink:
                sink.log_run(result, truth=recording)

        t_viz, _ = _timed(log)
        verdict = "ok" if t_viz <= t_filt else "EXCEEDS the filter time"
        print(f"Rerun logging of the gps-ins run + truth {t_viz:7.2f} s = {t_viz / t_filt:.2f} x "
              f"the filter time ({verdict}); .rrd {rrd.stat().st_size / 1e6:.1f} MB")
        del result, recording

        path200 = Path(tmp) / "drive200.mcap"
        write_recording(path200, simulate(SCENARIO, {"duration": duration, "imu_rate": 200.0},
                                          seed=2))
        base = _peak_rss("-")
        peak = _peak_rss(str(path200))
        verdict = "ok" if peak < GIB else "EXCEEDS 1 GiB"
        print(f"peak RSS, read + replay gps-ins of {duration / 3600:.2f} h at 200 Hz: "
              f"{peak / 2**20:.0f} MiB ({verdict}); a process that only imports: "
              f"{base / 2**20:.0f} MiB")


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:2]))
