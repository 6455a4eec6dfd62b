"""Smoothed runs for the smoother's tests: vehicle-drive with the GNSS outages of its schedule
(``gps_outages``), replayed forward and smoothed and scored, one by one or as the ensembles
of ``navreplay montecarlo --smooth``."""

import dataclasses

import numpy as np

from navreplay import metrics
from navreplay.campaign import monte_carlo_tasks, run_ensemble
from navreplay.core.streams import Recording
from navreplay.io.source import MemorySource
from navreplay.jobs.run import campaign_extract
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
OUTPUT_RATE = 1.0
"""[Hz]"""
NO_G_SENSITIVITY = {"gyro_g_sensitivity": "0 deg/h/g"}
"""The consumer IMU without the gyro g-sensitivity, the one error term whose change under
the drive's manoeuvres, ``K_g (f - f_0)``, the filters leave out (docs/smoothing.md)."""


def values(duration: float = DURATION, outages=OUTAGES, imu: dict | None = None) -> dict:
    """The scenario's parameters (``imu``: fields of its ``[sensors.imu]`` table)."""
    out = {"duration": duration, "imu_grade": GRADE, "gps_outages": outages, **GNSS}
    if imu:
        out["sensors"] = {"imu": dict(imu)}
    return out


def drive(seed: int, duration: float = DURATION, outages=OUTAGES) -> Recording:
    return simulate("vehicle-drive", values(duration, outages), seed=seed)


@dataclasses.dataclass
class Pair:
    """A forward run and its smoothed run, with their scores."""

    forward: object
    smoothed: object
    m_forward: metrics.RunMetrics
    m_smoothed: metrics.RunMetrics


def smoothed_pair(rec: Recording, filter_name: str = "gps-ins",
                  output_rate: float = OUTPUT_RATE) -> Pair:
    collect = Collect()
    replay_file(MemorySource(rec, "drive"), [FilterSpec(filter_name)], stages=[collect],
                output_rate=output_rate, smooth=True, score=False)
    results = collect.results()
    fwd, rts = results[filter_name], results[filter_name + "/rts"]
    return Pair(fwd, rts, metrics.run_metrics(fwd, rec), metrics.run_metrics(rts, rec))


@dataclasses.dataclass
class Ensembles:
    """The ensemble statistics of a filter and of its smoothed run, and the largest ratio of
    a smoothed sigma to the forward one over every run, scored state and epoch."""

    forward: metrics.EnsembleResult
    smoothed: metrics.EnsembleResult
    sigma_ratio_max: float


def smoothed_ensembles(seed: int, runs: int, workers: int = 1,
                       filter_name: str = "gps-ins", imu: dict | None = None) -> Ensembles:
    """The ensembles of ``navreplay montecarlo vehicle-drive FILTER --smooth`` over seeds
    ``seed`` .. ``seed + runs - 1`` (the campaign's tasks, extractor and statistics;
    ``imu``: fields of the IMU's ``[sensors.imu]`` table)."""
    tasks = [dataclasses.replace(t, smooth=True)
             for t in monte_carlo_tasks("vehicle-drive", runs, values=values(imu=imu),
                                        seed=seed)]
    labels = (filter_name, filter_name + "/rts")
    stats = {label: metrics.EnsembleStats(label) for label in labels}
    ratio = [0.0]

    def add(out) -> None:
        fwd, rts = (out.metrics.metrics[label] for label in labels)
        for label, m in zip(labels, (fwd, rts), strict=True):
            stats[label].add(m)
        ratio[0] = max(ratio[0], float(np.max(np.sqrt(rts.state_var / fwd.state_var))))

    run_ensemble(tasks, [FilterSpec(filter_name)], add, extract=campaign_extract,
                 workers=workers, output_rate=OUTPUT_RATE)
    return Ensembles(*(stats[label].result() for label in labels), ratio[0])
