"""Transfer alignment: replay throughput, the per-GINS-sample Kalman step, the campaign.

Measured in one run on the ``ship-transfer-alignment`` scenario (100 s, 100 Hz IMU, 10 Hz GINS):

* simulate: one recording;
* replay: each variant of the ``transfer-alignment`` filter through the replay engine, in IMU
  samples per second and as a multiple of real time, against two baselines replayed over the
  same recording: the engine alone (a filter that does nothing) and a free strapdown INS
  (:func:`navreplay.strapdown.propagate` only);
* Kalman step: the filter's numba cycle (model, prediction, Joseph correction, feedback, PSD
  check) against the shared numpy kernels :func:`navreplay.filters.kalman.predict` and
  :func:`~navreplay.filters.kalman.correct` for the same 9-state, 5-measurement problem (the
  numpy side does only the prediction and the correction);
* campaign: ``REPRODUCTION.run`` wall time (36 runs x 3 conditions, 252 filter runs).

Times are the minimum over repeats (the machine is shared).

    python -m benchmarks.bench_transfer_alignment [--repeat 7] [--campaign-runs 36] [--workers 2]
"""

from __future__ import annotations

import argparse
import time
import timeit

import numpy as np

from navreplay import strapdown
from navreplay.filters import kalman
from navreplay.filters import transfer_alignment as ta
from navreplay.filters.base import Estimate, Filter
from navreplay.replay.engine import replay
from navreplay.reproduce.transfer_alignment import REPRODUCTION
from navreplay.sim.scenario import simulate
from navreplay.streams import StreamKind

SCENARIO = "ship-transfer-alignment"


class _Engine(Filter):
    """Baseline: the engine's own cost (merge, dispatch, columns)."""

    name = "bench-engine"
    requires = (StreamKind.IMU,)
    state_names = ("x",) * 9

    def propagate(self, t, imu):
        self.t = float(t[-1])

    def update(self, kind, t, sample):
        return None

    def estimate(self):
        return Estimate(0.0, np.zeros(9), np.zeros((9, 9)))


class _FreeIns(_Engine):
    """Baseline: a free strapdown INS over the same IMU blocks."""

    name = "bench-free-ins"

    def __init__(self, params, context):
        super().__init__(params, context)
        self.nav = strapdown.nav_vector([0.61, 2.25, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])
        self.t_prev = 0.0

    def propagate(self, t, imu):
        dt = np.diff(t, prepend=self.t_prev)
        self.nav = strapdown.propagate(self.nav, imu["omega_ib_b"], imu["f_b"], dt)
        self.t_prev = float(t[-1])


def _best(fn, repeat: int, number: int = 1) -> float:
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def kf_step(repeat: int) -> tuple[float, float]:
    """Seconds per step: the filter's numba cycle and the shared numpy predict + correct."""
    q_m = ta.euler_quat(np.array([0.05, -0.03, 0.52]))
    s, u = np.array([0, 1, 3]), np.array([2])
    P0 = ta.initial_covariance(q_m, s, 0.0625, 2.25e-6, np.sin(np.radians(1.5)) ** 2)
    nav = np.concatenate(([0.61, 2.25, 0.0], [4.46, 2.57, 0.1], q_m))
    w, f = np.array([0.01, 0.02, 0.0]), np.array([0.1, 0.2, -9.8])
    args = (nav, np.array([1.0, 0, 0, 0]), P0, s, u, q_m, np.array([4.46, 2.57, 0.0]),
            nav[0:3].copy(), np.r_[w, f] * 10, 10, w, w, np.array([45.7, 15.2, 12.2]), 0.1,
            np.r_[[5e-4**2] * 3, [3e-5**2] * 3], 1e-12, np.r_[[0.09144**2] * 2, [2.06e-4**2] * 3],
            ta.RTOL)
    ta.cycle(*args)
    t_numba = _best(lambda: ta.cycle(*args), repeat, 2000)
    R, w_in = ta.earth_terms(nav[0], nav[2], nav[3:6])
    A, G = ta.system_matrix(q_m, nav[3:6], nav[0], R, w, w_in, f, 9)
    Phi = kalman.discretize(A, 0.1)
    Qd = kalman.discrete_noise(G, args[14], 0.1)
    H = np.zeros((5, 9))
    H[0, 0] = H[1, 1] = 1.0
    H[2:, 2:6] = ta.left(q_m * [1, -1, -1, -1])[s]
    H[2:, 6:] = -np.eye(3)
    z, r, x0 = np.full(5, 1e-4), args[16], np.zeros(9)

    def numpy_step():
        x, P = kalman.predict(x0, P0, Phi, Qd, check=False)
        kalman.correct(x, P, z, H, r)

    t_numpy = _best(numpy_step, repeat, 500)
    return t_numba, t_numpy


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="repeats (the minimum is reported)")
    ap.add_argument("--campaign-runs", type=int, default=36,
                    help="runs per condition of the campaign (0: skip it)")
    ap.add_argument("--workers", type=int, default=2, help="processes of the campaign")
    args = ap.parse_args(argv)

    rec = simulate(SCENARIO, {}, seed=0)
    n_imu = len(rec[StreamKind.IMU])
    n_gins = len(rec[StreamKind.MASTER_INS])
    duration = n_imu / 100.0
    t_sim = _best(lambda: simulate(SCENARIO, {}, seed=1), args.repeat)
    print(f"recording: {n_imu} IMU samples, {n_gins} GINS samples, {duration:.0f} s; "
          f"simulate {t_sim * 1e3:.1f} ms")

    rows = [("engine only (baseline)", _Engine, {}), ("free INS (baseline)", _FreeIns, {})]
    rows += [(f"transfer-alignment {m}", ta.TransferAlignment, {"match": m})
             for m in ("vel_quat_partial", "vel_quat_full", "vel_only")]
    print(f"  {'replay':<38}{'ms/run':>9}{'IMU samples/s':>15}{'x real time':>13}"
          f"{'us/GINS':>10}")
    for label, cls, params in rows:
        replay(rec, cls, params)  # compile / warm up
        t = _best(lambda cls=cls, params=params: replay(rec, cls, params), args.repeat)
        print(f"  {label:<38}{t * 1e3:>9.1f}{n_imu / t:>15,.0f}{duration / t:>13,.0f}"
              f"{t / n_gins * 1e6:>10.1f}")

    t_numba, t_numpy = kf_step(args.repeat)
    print(f"Kalman step (9 states, 5 measurements): numba cycle {t_numba * 1e6:.1f} us "
          f"(model + predict + correct + feedback + PSD check); shared numpy predict + correct "
          f"{t_numpy * 1e6:.1f} us; ratio {t_numpy / t_numba:.1f}x")

    if args.campaign_runs > 0:
        t0 = time.perf_counter()
        report = REPRODUCTION.run(runs=args.campaign_runs, workers=args.workers)
        wall = time.perf_counter() - t0
        timing = report.figures["timing"]
        print(f"campaign: {timing['recordings']} recordings, {timing['filter_runs']} filter runs"
              f" in {wall:.1f} s wall ({args.workers} workers, incl. warm-up); "
              f"checks {'all pass' if report.passed else 'FAIL'}")


if __name__ == "__main__":
    main()
