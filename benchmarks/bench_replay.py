"""Replay throughput and peak memory (the Rerun view's cost: :mod:`benchmarks.bench_viz`).

Measured in one run, on one 1-hour 100 Hz ``vehicle-drive`` recording (IMU 100 Hz, GPS fix and
velocity 1 Hz, magnetometer 10 Hz):

- end to end: decode the MCAP file + replay ``gps-ins`` + summary against the truth, in IMU
  samples per second and in multiples of real time (CPU time of the process, best of two);
- decode alone (best of three): every topic; only the topics gps-ins reads (the
  decode + replay figure); and as a streamed ``navreplay run`` reads the file (its aiding
  streams whole, then IMU and truth window by window);
- the filter alone (the replay of the decoded recording) and end to end, again in a fresh
  interpreter that only reads the file and replays it (best of two after a first replay that
  loads the compiled kernels): the in-process figures come after everything above in one
  process; the ratios and targets use the fresh figures where both are printed;
- baselines: the same replay without decoding (filter only), the free inertial ``ins`` filter,
  the engine alone (a filter that does nothing, so every event goes through the one-by-one
  path: merge, slicing and bookkeeping per event; gps-ins takes its events in runs), and
  the strapdown integrator over the whole record in one call (the arithmetic floor);
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
    """Best CPU time of this process (all threads) over ``repeat`` calls [s], and the value.

    CPU time rather than wall time: on a shared machine the wall clock measures the neighbours.
    """
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t)
    return best, out


def _timed_user(fn: Callable[[], Any], repeat: int = 2) -> tuple[float, float]:
    """CPU time (user + system) and user time [s] of the best of ``repeat`` calls."""
    import resource

    best = (np.inf, np.inf)
    for _ in range(repeat):
        t = resource.getrusage(resource.RUSAGE_SELF)
        fn()
        u = resource.getrusage(resource.RUSAGE_SELF)
        user = u.ru_utime - t.ru_utime
        best = min(best, (user + u.ru_stime - t.ru_stime, user))
    return best


def _null_filter() -> type:
    """A filter that does nothing: what remains is the engine's own cost per event."""
    from navreplay.core.streams import StreamKind
    from navreplay.filters.base import Estimate, Filter, NavSolution, Quantity, State

    class Null(Filter):
        name = "null"
        requires = (StreamKind.IMU, StreamKind.GPS)
        optional = (StreamKind.GPS_VEL,)
        states = tuple(State(f"s{i}", "-", Quantity.OTHER) for i in range(15))

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
import sys
if sys.argv[1] != "-":
    from navreplay.filters.registry import load_filter
    from navreplay.io import ReadOptions, read_recording
    from navreplay.replay import replay
    rec = read_recording(sys.argv[1])
    res = replay(rec, load_filter("gps-ins"), validate=False)
    assert res.t.shape[0] > 0
else:
    import navreplay.filters.gps_ins, navreplay.io, navreplay.replay  # noqa: F401
from benchmarks import peak_rss  # VmHWM: ru_maxrss would carry the parent's peak over
print(peak_rss())
"""

_FRESH_CHILD = """
import json, resource, sys
from navreplay.filters.registry import load_filter
from navreplay.io import read_recording
from navreplay.metrics import run_metrics
from navreplay.replay import replay
gps_ins = load_filter("gps-ins")
replay(read_recording(sys.argv[1]), gps_ins)  # loads the compiled kernels
def best(fn):
    out = []
    for _ in range(2):
        t = resource.getrusage(resource.RUSAGE_SELF)
        fn()
        u = resource.getrusage(resource.RUSAGE_SELF)
        user = u.ru_utime - t.ru_utime
        out.append((user + u.ru_stime - t.ru_stime, user))
    return min(out)
rec = read_recording(sys.argv[1])
def end_to_end():
    r = read_recording(sys.argv[1])
    run_metrics(replay(r, gps_ins, validate=False), r).summary()
print(json.dumps({"filter": best(lambda: replay(rec, gps_ins, validate=False)),
                  "end_to_end": best(end_to_end)}))
"""
"""A fresh interpreter's CPU times [s] (user + system, and user) of the gps-ins replay of a
decoded recording and of decode + replay + summary (best of two, after a first replay)."""


def _peak_rss(path: str) -> int:
    out = subprocess.run([sys.executable, "-c", _RSS_CHILD, path], check=True,
                         cwd=Path(__file__).resolve().parent.parent,
                         capture_output=True, text=True)
    return int(out.stdout.strip().splitlines()[-1])


def _fresh(path: Path) -> dict[str, tuple[float, float]]:
    import json

    out = subprocess.run([sys.executable, "-c", _FRESH_CHILD, str(path)], check=True,
                         cwd=Path(__file__).resolve().parent.parent, capture_output=True,
                         text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _met(ok: bool) -> str:
    return "met" if ok else "NOT met"


def _summary(result: Any, recording: Any) -> Any:
    from navreplay import metrics

    return metrics.run_metrics(result, recording).summary()


def _make_recording(path: Path, duration: float, imu_rate: float = 100.0, seed: int = 1) -> str:
    from navreplay.io import write_recording
    from navreplay.sim.scenario import simulate

    t_sim, rec = _timed(lambda: simulate(SCENARIO, {"duration": duration, "imu_rate": imu_rate},
                                         seed=seed))
    t_write, _ = _timed(lambda: write_recording(path, rec))
    span = (rec["imu"].t_ns[-1] - rec["imu"].t_ns[0]) * 1e-9
    return (f"{SCENARIO}, {span / 3600:.2f} h, {len(rec['imu'])} IMU samples at {imu_rate:g} Hz, "
            f"{path.stat().st_size / 1e6:.1f} MB (simulated in {t_sim:.1f} s, written in "
            f"{t_write:.1f} s)")


def _read_streamed(path: Path) -> int:
    """Decode a file the way a streamed run of gps-ins does (one pass, every stream the run
    needs in windows); the number of IMU rows."""
    from navreplay.filters.registry import load_filter
    from navreplay.io import ReadOptions, open_recording
    from navreplay.logs.prepare import streams_needed

    kinds = streams_needed([load_filter("gps-ins")])
    with open_recording(path, ReadOptions(kinds=kinds)) as source:
        return sum(len(w["imu"]) for w in source if "imu" in w)


def _throughput(path: Path) -> None:
    """Print the replay timings."""
    from navreplay.filters.registry import load_filter
    from navreplay.geo import strapdown
    from navreplay.io import ReadOptions, read_recording
    from navreplay.replay import replay

    gps_ins = load_filter("gps-ins")
    ins = load_filter("ins")
    replay(read_recording(path), gps_ins)  # warm up (numba compilation, caches)

    def end_to_end() -> tuple[Any, Any]:
        r = read_recording(path)
        res = replay(r, gps_ins, validate=False)
        _summary(res, r)
        return res, r

    t_e2e, (result, recording) = _timed(end_to_end, repeat=2)
    t_all, _ = _timed(lambda: read_recording(path), repeat=3)
    needed = [k.value for k in (*gps_ins.requires, *gps_ins.optional)]
    t_dec, _ = _timed(lambda: read_recording(path, ReadOptions(kinds=needed)), repeat=3)
    t_win, _ = _timed(lambda: _read_streamed(path), repeat=3)
    t_filt, user_filt = _timed_user(lambda: replay(recording, gps_ins, validate=False))
    t_sum, _ = _timed(lambda: _summary(result, recording), repeat=2)
    t_ins, _ = _timed(lambda: replay(recording, ins, validate=False), repeat=2)
    null = _null_filter()
    t_null, _ = _timed(lambda: replay(recording, null, validate=False), repeat=2)
    imu = recording["imu"]
    n_imu = len(imu)
    span = (imu.t_ns[-1] - imu.t_ns[0]) * 1e-9
    dt = np.diff(imu.t_ns, prepend=imu.t_ns[0] - (imu.t_ns[1] - imu.t_ns[0])) * 1e-9
    init = recording.metadata.initial_nav
    nav0 = strapdown.nav_vector(init["pos"], init["v_n"], init["q_nb"])
    t_sd, _ = _timed(lambda: strapdown.propagate(nav0, imu["omega_ib_b"], imu["f_b"], dt),
                     repeat=3)
    events = len(result.t)

    def rate(t: float) -> str:
        return f"{n_imu / t / 1e3:7.0f}k IMU samples/s {span / t:7.0f}x real time"

    fresh = _fresh(path)
    (f_filt, f_user), (f_e2e, _) = fresh["filter"], fresh["end_to_end"]

    print("CPU seconds (best of 2)")

    updates = sum(len(s.t) for s in result.innovations.values())
    print(f"gps-ins: {events} estimates (10 Hz outputs), {updates} measurement updates")
    print(f"end to end (decode + gps-ins + summary)  {t_e2e:6.2f} s {rate(t_e2e)}")
    print(f"  in a fresh interpreter                 {f_e2e:6.2f} s {rate(f_e2e)}")
    print(f"  decode, every topic                    {t_all:6.2f} s {rate(t_all)}")
    print(f"  decode, the replay's topics ({', '.join(needed)})"
          f"\n                                         {t_dec:6.2f} s {rate(t_dec)}")
    print(f"  decode as `navreplay run` streams it   {t_win:6.2f} s {rate(t_win)}"
          " (one pass, the run's streams in windows)")
    print(f"  gps-ins replay (filter only)           {t_filt:6.2f} s {rate(t_filt)}"
          f" (user {user_filt:.2f} s)")
    print(f"    in a fresh interpreter               {f_filt:6.2f} s {rate(f_filt)}"
          f" (user {f_user:.2f} s; in this process / fresh = {t_filt / f_filt:.2f})")
    print("    (the rest is system time: the page faults of the arrays the replay allocates, "
          "a covariance per output row, which vary with the allocator's state)")
    print(f"  summary vs truth                       {t_sum:6.2f} s")
    print("baselines (same run)")
    print(f"  ins replay (free inertial)             {t_ins:6.2f} s {rate(t_ins)}")
    print(f"  engine alone, events one by one        {t_null:6.2f} s {rate(t_null)}"
          f" ({t_null / events * 1e6:.1f} us per output event; gps-ins takes them in runs)")
    print(f"  strapdown, one call over the record    {t_sd:6.2f} s {rate(t_sd)}")
    print(f"ratios: end to end / strapdown = {f_e2e / t_sd:.1f}")
    print(f"gps-ins replay / strapdown on the same samples = {f_filt / t_sd:.1f} (fresh "
          f"interpreter; target <= 4: {_met(f_filt <= 4.0 * t_sd)})")
    throughput = n_imu / (t_dec + f_filt)
    print(f"decode (the replay's topics) + replay {throughput / 1e3:.0f}k IMU samples/s "
          f"(target >= 500k: {_met(throughput >= 500e3)}); streamed decode + replay "
          f"{n_imu / (t_win + f_filt) / 1e3:.0f}k")


def main(duration: float = 3600.0, *, quick: bool = False) -> None:
    if quick:  # the same measurements on a 20-second drive
        duration = 20.0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "drive.mcap"
        print("recording:", _make_recording(path, duration))
        _throughput(path)  # its result and recording are freed before the memory figure
        path.unlink()
        path200 = Path(tmp) / "drive200.mcap"
        print("recording:", _make_recording(path200, duration, imu_rate=200.0, seed=2))
        base = _peak_rss("-")
        peak = _peak_rss(str(path200))
        print(f"peak RSS of a process reading + replaying gps-ins over it: {peak / 2**20:.0f} MiB "
              f"(target < 1 GiB: {_met(peak < GIB)}); a process that only imports navreplay: "
              f"{base / 2**20:.0f} MiB")


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:2]))
