"""Transfer alignment: replay throughput, the per-GINS-sample Kalman step, the campaign.

Measured in one run on the ``ship-transfer-alignment`` scenario (100 s, 100 Hz IMU, 10 Hz GINS):

* simulate: one recording;
* replay: each variant of the ``transfer-alignment`` filter through the replay engine, in IMU
  samples per second and as a multiple of real time, against two baselines replayed over the
  same recording: the engine alone (a filter that does nothing) and a free strapdown INS
  (:func:`navreplay.geo.strapdown.propagate` only);
* step at a GINS sample: each part (numba model and prediction, the shared correction with its
  checks, numba feedback), and the numpy discretisation and prediction of
  :mod:`navreplay.filters.kalman` as a baseline for the first;
* campaign: ``REPRODUCTION.run`` wall time (36 runs x 3 conditions, 252 filter runs).

Times are the minimum over repeats (the machine is shared).

    python -m benchmarks.bench_transfer_alignment [--repeat 7] [--campaign-runs 36] [--workers 2]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from benchmarks import best
from navreplay.core.streams import StreamKind
from navreplay.filters import kalman
from navreplay.filters import transfer_alignment as ta
from navreplay.filters import transfer_alignment_model as tam
from navreplay.filters.base import Estimate, Filter, Quantity, State
from navreplay.geo import kernels, strapdown
from navreplay.replay import replay
from navreplay.reproduce.transfer_alignment import REPRODUCTION
from navreplay.sim.scenario import simulate

SCENARIO = "ship-transfer-alignment"


class _Engine(Filter):
    """Baseline: the engine's own cost (merge, dispatch, columns)."""

    name = "bench-engine"
    requires = (StreamKind.IMU,)
    states = tuple(State(f"x{i}", "-", Quantity.OTHER) for i in range(9))

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


def kf_step(repeat: int, number: int = 2000) -> dict[str, float]:
    """Seconds per call of each part of the filter's step at a GINS sample (9 states, 5
    measurements), and of the numpy model + prediction that the first part replaces."""
    q_m = kernels.euler_to_quat(np.array([0.05, -0.03, 0.52]))
    s, u = np.array([0, 1, 3]), np.array([2])
    P0 = ta.initial_covariance(q_m, s, 0.0625, 2.25e-6, np.sin(np.radians(1.5)) ** 2)
    nav = np.concatenate(([0.61, 2.25, 0.0], [4.46, 2.57, 0.1], q_m))
    w, f = np.array([0.01, 0.02, 0.0]), np.array([0.1, 0.2, -9.8])
    v_r, lever = np.array([4.46, 2.57, 0.0]), np.array([45.7, 15.2, 12.2])
    qc = np.r_[[5e-4**2] * 3, [3e-5**2] * 3]
    r = np.r_[[0.09144**2] * 2, [2.06e-4**2] * 3]
    q_rb = np.array([1.0, 0.0, 0.0, 0.0])
    sums = np.r_[w, f] * 10

    def model():
        return tam.predict_and_measure(nav, q_rb, P0, s, q_m, v_r, sums, 10, w, w, lever, 0.1,
                                      qc, 1e-12, 0, 0.0, np.eye(2), np.zeros((2, 2)),
                                      np.zeros(3), 0.0)

    P, z, H, _, qm, w_now, w_in = model()
    c = kalman.correct(np.zeros(9), P, z, H, r, check=False)

    def feedback():
        tam.feedback(nav.copy(), q_rb.copy(), c.x, c.P, s, u, qm, v_r, nav[0:3], w_now, w_in,
                    lever)

    def numpy_model():
        R, w_in = tam.earth_terms(nav[0], nav[2], nav[3:6])
        A, G = tam.system_matrix(q_m, nav[3:6], nav[0], R, w, w_in, f, 9)
        kalman.predict(np.zeros(9), P0, kalman.discretize(A, 0.1),
                       kalman.discrete_noise(G, qc, 0.1), check=False)

    feedback()
    return {
        "model + prediction + z, H (numba)": best(model, repeat, number),
        "correction + checks (kalman.correct)": best(
            lambda: kalman.correct(np.zeros(9), P, z, H, r), repeat, number),
        "feedback + recovery (numba)": best(feedback, repeat, number),
        "baseline: numpy discretize + predict": best(numpy_model, repeat, number // 2),
    }


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # quick: the same replays and step on a 10-second recording, one campaign run per condition
    ap.add_argument("--repeat", type=int, default=1 if quick else 7,
                    help="repeats (the minimum is reported)")
    ap.add_argument("--campaign-runs", type=int, default=1 if quick else 36,
                    help="runs per condition of the campaign (0: skip it)")
    ap.add_argument("--workers", type=int, default=1 if quick else 2,
                    help="processes of the campaign")
    args = ap.parse_args([] if argv is None else argv)

    values = {"duration": 10.0} if quick else {}
    rec = simulate(SCENARIO, values, seed=0)
    n_imu = len(rec[StreamKind.IMU])
    n_gins = len(rec[StreamKind.MASTER_INS])
    duration = n_imu / 100.0
    t_sim = best(lambda: simulate(SCENARIO, values, seed=1), args.repeat)
    print(f"recording: {n_imu} IMU samples, {n_gins} GINS samples, {duration:.0f} s; "
          f"simulate {t_sim * 1e3:.1f} ms")

    rows = [("engine only (baseline)", _Engine, {}), ("free INS (baseline)", _FreeIns, {})]
    rows += [(f"transfer-alignment {m}", ta.TransferAlignment, {"match": m})
             for m in ("vel_quat_partial", "vel_quat_full", "vel_only")]
    print(f"  {'replay':<38}{'ms/run':>9}{'IMU samples/s':>15}{'x real time':>13}"
          f"{'us/GINS':>10}")
    for label, cls, params in rows:
        replay(rec, cls, params)  # compile / warm up
        t = best(lambda cls=cls, params=params: replay(rec, cls, params), args.repeat)
        print(f"  {label:<38}{t * 1e3:>9.1f}{n_imu / t:>15,.0f}{duration / t:>13,.0f}"
              f"{t / n_gins * 1e6:>10.1f}")

    print("step at a GINS sample (9 states, 5 measurements):")
    for label, t in kf_step(args.repeat, 20 if quick else 2000).items():
        print(f"  {label:<40}{t * 1e6:>8.1f} us")

    if args.campaign_runs > 0:
        t0 = time.perf_counter()
        report = REPRODUCTION.run(runs=args.campaign_runs, workers=args.workers)
        wall = time.perf_counter() - t0
        timing = report.figures["timing"]
        print(f"campaign: {timing['recordings']} recordings, {timing['filter_runs']} filter runs"
              f" in {wall:.1f} s wall ({args.workers} workers, incl. warm-up); "
              f"checks {'all pass' if report.passed else 'FAIL'}")


if __name__ == "__main__":
    main(sys.argv[1:])
