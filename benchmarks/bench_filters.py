"""Filter-only throughput of the INS filters and the cost of the shared Kalman steps.

On one 1-hour 100 Hz ``vehicle-drive`` recording (GPS fix and velocity at 1 Hz), measured in
the same run:

- ``gps-ins`` driven directly (no replay engine, no decoding): per GPS epoch one IMU block,
  the position and velocity updates and an estimate; and the same with an estimate every
  0.1 s (IMU blocks of 10 samples, as the engine's 10 Hz output ticks give);
- ``ins`` (free inertial: strapdown + covariance propagation, estimates at 10 Hz);
- baselines: :func:`navreplay.geo.strapdown.integrate` over the whole record in one call (the
  arithmetic floor) and in 10-sample blocks (the cost of one compiled call per block);
- per-call cost of ``kalman.predict`` and ``kalman.correct`` (15 states, 3 measurements) and
  of the compiled 15-state covariance step.

Throughput is in IMU samples per second, with the ratio to real time and to the baseline.

    python -m benchmarks filters          # or: python -m benchmarks.bench_filters [duration_s]
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks import best


def _driver(recording: Any, filter_cls: type, block_period: float) -> Callable[[], Any]:
    """A minimal replay loop over pre-sliced inputs: blocks of IMU samples ending every
    ``block_period`` seconds, the aiding samples at their times, an estimate after each."""
    from navreplay.core.streams import StreamKind, seconds
    from navreplay.filters.base import FilterContext

    imu = recording[StreamKind.IMU]
    t_imu = seconds(imu.t_ns, recording.t0_ns)
    cols = imu.columns
    aiding = [k for k in (StreamKind.GPS, StreamKind.GPS_VEL)
              if k in recording and (k in filter_cls.requires or k in filter_cls.optional)]
    # block ends on the grid k * block_period, aiding samples at their own times
    ends = np.searchsorted(t_imu, np.arange(block_period, t_imu[-1] + 1e-9, block_period) + 1e-9)
    events: list[tuple[int, list[tuple[StreamKind, float, dict]]]] = []
    samples: dict[int, list] = {}
    for k in aiding:
        s = recording[k]
        ts = seconds(s.t_ns, recording.t0_ns)
        at = np.searchsorted(t_imu, ts + 1e-9)
        for i, j in enumerate(at):
            samples.setdefault(int(j), []).append(
                (k, float(ts[i]), {c: v[i] for c, v in s.columns.items()}))
    cuts = sorted(set(ends.tolist()) | set(samples))
    start = 0
    for end in cuts:
        events.append((end, samples.get(end, [])))
    blocks = []
    for end, upd in events:
        if end > start:
            blocks.append((t_imu[start:end], {c: v[start:end] for c, v in cols.items()}, upd))
            start = end
        elif upd:
            blocks.append((None, None, upd))
    context = FilterContext(recording.metadata, recording.t0_ns, frozenset(recording.kinds()))
    params = filter_cls.Params()

    def run() -> Any:
        f = filter_cls(params, context)
        for t, block, upd in blocks:
            if t is not None:
                f.propagate(t, block)
            for kind, tk, sample in upd:
                f.update(kind, tk, sample)
            f.estimate()
        return f

    return run


def main(duration: float = 3600.0, *, quick: bool = False) -> None:
    from navreplay.core.streams import StreamKind
    from navreplay.filters import ins_error as ie
    from navreplay.filters import ins_time_update as itu
    from navreplay.filters import kalman
    from navreplay.filters.gps_ins import GpsInsFilter
    from navreplay.filters.ins import InsFilter
    from navreplay.geo import strapdown
    from navreplay.sim.scenario import simulate

    if quick:  # the same paths on a short drive, one repeat, few calls
        duration = 20.0
    repeat, number = (1, 20) if quick else (3, 2000)
    rec = simulate("vehicle-drive", {"duration": duration}, seed=0)
    imu = rec[StreamKind.IMU]
    n = len(imu)
    real = duration
    omega, f = imu["omega_ib_b"], imu["f_b"]
    dt = np.full(n, 0.01)
    nav0 = strapdown.nav_vector(rec.metadata.initial_nav["pos"], rec.metadata.initial_nav["v_n"],
                                rec.metadata.initial_nav["q_nb"])
    print(f"vehicle-drive {duration:.0f} s: {n} IMU samples at 100 Hz, "
          f"{len(rec[StreamKind.GPS])} GPS fixes + velocities")

    strapdown.integrate(nav0, omega[:10], f[:10], dt[:10])  # compile
    t_floor = best(lambda: strapdown.integrate(nav0, omega, f, dt), repeat)

    def blocks10() -> None:
        nav = nav0
        for i in range(0, n, 10):
            nav = strapdown.propagate(nav, omega[i:i + 10], f[i:i + 10], dt[i:i + 10])

    t_blocks = best(blocks10, repeat)

    rows: list[tuple[str, float]] = [
        ("strapdown.integrate, one call (baseline)", t_floor),
        ("strapdown.propagate, 10-sample blocks", t_blocks),
    ]
    for label, cls, period in (
        ("ins, estimates at 10 Hz", InsFilter, 0.1),
        ("gps-ins, estimates at 1 Hz (per GPS epoch)", GpsInsFilter, 1.0),
        ("gps-ins, estimates at 10 Hz", GpsInsFilter, 0.1),
    ):
        run = _driver(rec, cls, period)
        _driver(simulate("vehicle-drive", {"duration": 10.0}, seed=0), cls, period)()  # compile
        rows.append((label, best(run, repeat=min(repeat, 2))))

    print(f"{'':46s} {'samples/s':>11s} {'x real time':>12s} {'x baseline':>11s}")
    for label, t in rows:
        print(f"{label:46s} {n / t:11.3g} {real / t:12.0f} {t / t_floor:11.1f}")

    # per-call costs of the shared Kalman math (15 states, 3 measurements)
    rng = np.random.default_rng(0)
    A = rng.normal(size=(15, 15))
    P = A @ A.T + np.eye(15)
    Phi = np.eye(15) + 0.01 * rng.normal(size=(15, 15))
    Qd = np.diag(np.full(15, 1e-6))
    H = rng.normal(size=(3, 15))
    x = np.zeros(15)
    z = rng.normal(size=3)
    R = np.ones(3)
    nav = np.r_[nav0]
    fb = np.array([0.1, 0.2, -9.8])
    noise = GpsInsFilter.Params().process_noise()
    itu.propagate_covariance(P, nav[None], fb[None], np.zeros((1, 3)), np.array([0.1]), noise)
    calls = [
        ("kalman.predict (checked)", lambda: kalman.predict(x, P, Phi, Qd)),
        ("kalman.correct (checked)", lambda: kalman.correct(x, P, z, H, R)),
        ("kalman.correct (check=False)", lambda: kalman.correct(x, P, z, H, R, check=False)),
        ("kalman.check_covariance", lambda: kalman.check_covariance(P)),
        ("ins_error.system_matrix", lambda: ie.system_matrix(nav[:3], nav[3:6], np.eye(3), fb)),
        ("ins_time_update.propagate_covariance, 1 step",
         lambda: itu.propagate_covariance(P, nav[None], fb[None], np.zeros((1, 3)),
                                         np.array([0.1]), noise)),
    ]
    print(f"\n{'per call (15 states, m = 3)':46s} {'us':>11s}")
    for label, fn in calls:
        print(f"{label:46s} {best(fn, repeat, number) * 1e6:11.1f}")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 3600.0)
