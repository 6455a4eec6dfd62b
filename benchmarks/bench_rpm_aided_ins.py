"""RPM-aided underwater INS: replay throughput and the 300-run campaign, ratios in one run.

* replay: one 480-s ``underwater-rpm`` recording (48,000 IMU samples) written to MCAP, then
  decoded (``read_recording``) and replayed with ``rpm-aided-ins`` in each mode; reported in
  IMU samples/s end to end (decode + filter), as a multiple of real time, and as a ratio to
  the free-inertial replay (the ``ins`` filter) of the same recording, decoded the same way;
* campaign: ``navreplay reproduce rpm-aided-ins`` with 100 runs (100 simulations, 300 filter
  runs), wall time against the 2-minute target.

Wall times on a shared machine vary; each timing is the best of ``--repeat`` and the CPU time
of this process is shown beside it.

    python -m benchmarks.bench_rpm_aided_ins [--repeat 5] [--runs 100] [--workers 2]
                                             [--skip-campaign]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from navreplay.filters.registry import load_filter
from navreplay.io import read_recording, write_recording
from navreplay.replay import replay
from navreplay.sim.scenario import simulate

TARGET_SAMPLES_PER_S = 100_000
TARGET_CAMPAIGN_S = 120.0


def _best(repeat: int, fn: Callable[[], Any]) -> tuple[float, float]:
    """Best wall time and the CPU time of that call [s]."""
    best = (float("inf"), float("inf"))
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        w, c = time.perf_counter() - w0, time.process_time() - c0
        if w < best[0]:
            best = (w, c)
    return best


def bench_replay(repeat: int, values: dict[str, Any] | None = None) -> dict[str, float]:
    """Decode + replay of one recording per mode (scenario ``values``: its defaults), and the
    free-inertial baseline."""
    values = values or {}
    rec = simulate("underwater-rpm", values, seed=0)
    n_imu = len(rec["imu"])
    duration = n_imu / rec.metadata.params["imu_rate"]
    sim_w, sim_c = _best(repeat, lambda: simulate("underwater-rpm", values, seed=0))
    rpm_ins = load_filter("rpm-aided-ins")
    ins = load_filter("ins")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "underwater-rpm.mcap"
        write_recording(path, rec)
        dec_w, dec_c = _best(repeat, lambda: read_recording(path))
        decoded = read_recording(path)
        runs: dict[str, tuple[type, dict[str, str] | None]] = {
            "ins (free inertial)": (ins, None),
            "rpm-aided-ins mode=pure": (rpm_ins, {"mode": "pure"}),
            "rpm-aided-ins mode=rpm": (rpm_ins, {"mode": "rpm"}),
            "rpm-aided-ins mode=rpm_current": (rpm_ins, {"mode": "rpm_current"}),
        }
        out = {}
        for label, (cls, params) in runs.items():
            replay(decoded, cls, params)  # compile / warm up
            out[label] = _best(repeat, lambda c=cls, p=params: replay(decoded, c, p,
                                                                      validate=False))
    print(f"recording: {n_imu} IMU samples, {duration:.0f} s; simulate {sim_w * 1e3:.0f} ms "
          f"(cpu {sim_c * 1e3:.0f} ms); decode {dec_w * 1e3:.0f} ms (cpu {dec_c * 1e3:.0f} ms)")
    base = dec_w + out["ins (free inertial)"][0]
    print(f"{'replay':<32}{'filter [ms]':>12}{'cpu [ms]':>10}{'end to end [ms]':>17}"
          f"{'IMU samples/s':>15}{'x real time':>13}{'/ ins':>8}")
    result = {"decode_s": dec_w, "simulate_s": sim_w}
    for label, (w, c) in out.items():
        e2e = dec_w + w
        rate = n_imu / e2e
        print(f"{label:<32}{w * 1e3:>12.0f}{c * 1e3:>10.0f}{e2e * 1e3:>17.0f}{rate:>15,.0f}"
              f"{duration / e2e:>13.0f}{e2e / base:>8.2f}")
        result[label] = e2e
    rate = n_imu / result["rpm-aided-ins mode=rpm_current"]
    verdict = "meets" if rate >= TARGET_SAMPLES_PER_S else "MISSES"
    print(f"rpm_current end to end: {rate:,.0f} IMU samples/s, {verdict} the target of "
          f"{TARGET_SAMPLES_PER_S:,}/s")
    return result


def bench_campaign(runs: int, workers: int, values: dict[str, Any] | None = None) -> float:
    """Wall time of the reproduction campaign, simulation included [s]."""
    from navreplay.reproduce import get

    w0 = time.perf_counter()
    report = get("rpm-aided-ins").run(runs=runs, workers=workers, values=values)
    wall = time.perf_counter() - w0
    timing = report.figures["timing"]
    passed = sum(c.passed for c in report.checks)
    per_run = timing["worker_s"] / timing["filter_runs"]
    print(f"campaign: {runs} simulations + {3 * runs} filter runs in {wall:.1f} s wall "
          f"(incl. warm-up; {timing['wall_s']:.1f} s in the pool), {workers} worker(s), "
          f"{per_run * 1e3:.0f} ms of worker time per filter run incl. its share of the "
          f"simulation; checks {passed}/{len(report.checks)} passed")
    if runs == 100:
        verdict = "meets" if wall < TARGET_CAMPAIGN_S else "MISSES"
        print(f"300-run campaign: {verdict} the target of {TARGET_CAMPAIGN_S:.0f} s "
              f"({wall / TARGET_CAMPAIGN_S:.2f} of it)")
    return wall


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_rpm_aided_ins")
    # quick: the same replays and campaign on 30-second recordings, two runs in this process
    parser.add_argument("--repeat", type=int, default=1 if quick else 5,
                        help="runs per timing, best kept")
    parser.add_argument("--runs", type=int, default=2 if quick else 100,
                        help="campaign runs (default 100)")
    parser.add_argument("--workers", type=int, default=1 if quick else 2,
                        help="campaign processes (default 2)")
    parser.add_argument("--skip-campaign", action="store_true", help="replay timings only")
    args = parser.parse_args([] if argv is None else argv)
    values = {"duration": 30.0} if quick else None
    bench_replay(args.repeat, values)
    if not args.skip_campaign:
        bench_campaign(args.runs, args.workers, values)


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
