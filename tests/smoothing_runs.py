"""Smoothed runs for the smoother's tests: vehicle-drive with GNSS outages made by dropping
the GNSS samples of the outage windows, replayed forward and smoothed, scored."""

import dataclasses

import numpy as np

from navreplay import metrics
from navreplay.core.streams import Recording, Stream, StreamKind
from navreplay.io.source import MemorySource
from navreplay.replay.pipeline import Collect, replay_file
from navreplay.replay.spec import FilterSpec
from navreplay.sim.scenario import simulate

DURATION = 300.0
OUTAGES = ((100.0, 30.0), (180.0, 60.0))
"""GNSS outages (start [s], length [s])."""
GRADE = "consumer"
"""An industrial MEMS IMU: metres to tens of metres of drift in a minute without GNSS."""
GNSS = {"gps_pos_sigma_h": 0.5, "gps_pos_sigma_v": 1.0}
"""Differential GNSS, as a survey is post-processed."""
DEV_SEEDS = (100, 101, 102, 103)
"""Seeds the smoother was developed on (and nothing else)."""


def drop_gnss(rec: Recording, outages=OUTAGES) -> Recording:
    """The recording without its GNSS samples in the outage windows."""
    streams = dict(rec.streams)
    for kind in (StreamKind.GPS, StreamKind.GPS_VEL):
        if kind not in rec:
            continue
        s = rec[kind]
        t = (s.t_ns - rec.t0_ns) * 1e-9
        keep = np.ones(len(t), bool)
        for a, length in outages:
            keep &= ~((t >= a) & (t < a + length))
        streams[kind] = Stream(s.kind, s.t_ns[keep], {k: v[keep] for k, v in s.columns.items()},
                               s.frame_id)
    return dataclasses.replace(rec, streams=streams)


def drive(seed: int, duration: float = DURATION) -> Recording:
    return drop_gnss(simulate("vehicle-drive", {"duration": duration, "imu_grade": GRADE,
                                                 **GNSS},
                              seed=seed))


@dataclasses.dataclass
class Pair:
    """A forward run and its smoothed run, with their scores."""

    forward: object
    smoothed: object
    m_forward: metrics.RunMetrics
    m_smoothed: metrics.RunMetrics


def smoothed_pair(rec: Recording, filter_name: str = "gps-ins", output_rate: float = 1.0
                  ) -> Pair:
    collect = Collect()
    replay_file(MemorySource(rec, "drive"), [FilterSpec(filter_name)], stages=[collect],
                output_rate=output_rate, smooth=True, score=False)
    results = collect.results()
    fwd, rts = results[filter_name], results[filter_name + "/rts"]
    return Pair(fwd, rts, metrics.run_metrics(fwd, rec), metrics.run_metrics(rts, rec))


def horizontal(m: metrics.RunMetrics) -> np.ndarray:
    """Horizontal position error [m] of each epoch."""
    return np.hypot(m.nav.pos_ned[:, 0], m.nav.pos_ned[:, 1])


def in_outage(t: np.ndarray, outage) -> np.ndarray:
    a, length = outage
    return (t >= a) & (t < a + length)
