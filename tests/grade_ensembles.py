"""Ensembles of ``ins`` and ``gps-ins`` on ``vehicle-drive`` recordings of each IMU grade with
the settings the filters derive from the recordings (docs/methods/ins.md §4, docs/sensors.md).

The checks of an ensemble, the NEES at the false alarm ``consistency.CHECK_FALSE_ALARM`` and
the nine RMS / sigma together at the same (:data:`RATIO_FALSE_ALARM` each):

- NEES of the nine navigation errors: each run's NEES averaged from 10 s is one chi-square(9)
  sample, the mean over the runs must lie in the band of that many samples
  (docs/methods/consistency.md);
- RMS / sigma per axis (position, velocity, attitude, each N E D): at each epoch the RMS error
  over the runs divided by the RMS predicted sigma, averaged over the epochs from 10 s (each
  epoch weighs the same, so the large errors of the first minute do not hide a later
  mismatch). Counted as one sample per run (a run's error is mostly one draw held in time),
  the squared ratio of a consistent filter at an epoch is a mean of ``runs`` chi-square(1)
  samples: the band is the square root of that mean's band (conservative where the errors
  decorrelate in time).

Run as a script to print the table of docs/methods/ins.md §4::

    python tests/grade_ensembles.py [RUNS] [SEED ...]
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay import metrics
from navreplay.filters.registry import load_filter
from navreplay.metrics import consistency
from navreplay.replay import replay
from navreplay.sim.scenario import simulate

GRADES = ("consumer", "mems", "tactical", "navigation")
FILTERS = ("ins", "gps-ins")
DURATION = {("consumer", "ins"): 30.0}
"""Drive length [s] where not 300 s: the free INS of a consumer IMU leaves the linear regime of
its error model after about half a minute (its attitude error passes 3 deg; docs/methods/ins.md
§4), so it is checked where the model holds."""
DEFAULT_DURATION = 300.0
START = 10.0
"""The statistics start here [s] (after the initial transient)."""
AXES = {"pos_ned": "pos", "v_n": "vel", "phi": "att"}
DOF = 9


@dataclasses.dataclass
class Ensemble:
    """One grade x filter ensemble: NEES / dof with its band, RMS / sigma per axis with its
    band, and the ensemble statistics (for figures)."""

    grade: str
    filter: str
    seed: int
    runs: int
    duration: float
    nees_dof: float
    nees_band: tuple[float, float]
    ratios: dict[str, np.ndarray]
    ratio_band: tuple[float, float]
    stats: Any
    state_ratios: dict[str, float] = dataclasses.field(default_factory=dict)
    """RMS / sigma of every other scored state (biases, scale factors, GNSS errors), as the
    navigation axes: averaged over the epochs from :data:`START`."""
    nis: dict[str, float] = dataclasses.field(default_factory=dict)
    """NIS / dof of each measurement over every update of the runs from :data:`START`."""

    @property
    def nees_inside(self) -> bool:
        return self.nees_band[0] <= self.nees_dof <= self.nees_band[1]

    def ratios_outside(self) -> dict[str, list[float]]:
        """The axes whose RMS / sigma leaves its band."""
        lo, hi = self.ratio_band
        return {k: v.round(3).tolist() for k, v in self.ratios.items()
                if np.any((v < lo) | (v > hi))}

    def row(self) -> str:
        """A row of the table in docs/methods/ins.md."""
        r = " | ".join(" ".join(f"{x:.2f}" for x in self.ratios[k]) for k in AXES)
        return (f"| {self.grade} | {self.filter} | {self.seed} | {self.runs} x "
                f"{self.duration:.0f} s | {self.nees_dof:.3f} | "
                f"{self.nees_band[0]:.3f}-{self.nees_band[1]:.3f} | {r} |")


def duration(grade: str, name: str, length: float = DEFAULT_DURATION,
             lengths: Mapping[tuple[str, str], float] = DURATION) -> float:
    """Drive length of ``name`` on ``grade`` [s]: ``lengths`` (:data:`DURATION`), else
    ``length``."""
    return lengths.get((grade, name), length)


RATIO_FALSE_ALARM = consistency.CHECK_FALSE_ALARM / DOF
"""False alarm of each axis's RMS / sigma check: the nine of an ensemble together have at most
``CHECK_FALSE_ALARM`` (Bonferroni), as its NEES check."""


def ratio_band(runs: int) -> tuple[float, float]:
    """Band of an RMS / sigma counted as one chi-square(1) sample per run."""
    lo, hi = consistency.mean_band(1, runs, RATIO_FALSE_ALARM)
    return math.sqrt(lo), math.sqrt(hi)


Variant = tuple[str, str, Any]
"""(label, filter name, parameters) of an ensemble: one filter run with given settings."""


def ensembles(grade: str, seed: int, runs: int, filters: tuple[str | Variant, ...] = FILTERS,
              params: dict[str, Any] | None = None, length: float = DEFAULT_DURATION,
              lengths: Mapping[tuple[str, str], float] = DURATION,
              scenario: Mapping[str, Any] | None = None) -> dict[str, Ensemble]:
    """Run ``filters`` with their derived settings (or ``params`` by filter name; a
    :data:`Variant` names its own label and parameters) over ``runs`` drives of ``grade``
    (``length`` s, or as ``lengths`` says; the other ``vehicle-drive`` parameters as
    ``scenario`` says) simulated with seeds ``seed``, ``seed + 1``, ...; the filters of one
    drive length share the recordings. The ensembles by label (a filter's name)."""
    params = params or {}
    out: dict[str, Ensemble] = {}
    groups: dict[float, list[Variant]] = {}
    for f in filters:
        label, name, p = (f, f, params.get(f)) if isinstance(f, str) else f
        groups.setdefault(duration(grade, name, length, lengths), []).append((label, name, p))
    for length, variants in groups.items():
        stats = {label: metrics.EnsembleStats(label) for label, _, _ in variants}
        nees: dict[str, list[float]] = {label: [] for label, _, _ in variants}
        for s in range(seed, seed + runs):
            rec = simulate("vehicle-drive", {**(scenario or {}), "duration": length,
                                             "imu_grade": grade}, seed=s)
            for label, name, p in variants:
                m = metrics.run_metrics(replay(rec, load_filter(name), p, output_rate=1.0), rec)
                nees[label].append(float(np.mean(m.nees[m.t >= START])))
                stats[label].add(m)
        for label, _, _ in variants:
            e = stats[label].result()
            sel = e.t >= START
            ratios = {key: np.mean(e.rms[key][sel] / e.sigma[key][sel], axis=0)
                      for key in AXES}
            band = consistency.mean_band(DOF, runs)
            nav = {s.name for s in e.states if s.nees}
            with np.errstate(invalid="ignore", divide="ignore"):
                z = e.state_rms[sel] / e.state_sigma[sel]
            others = {name: float(np.mean(z[:, i])) for i, name in enumerate(e.state_names)
                      if name not in nav and np.all(np.isfinite(z[:, i]))}
            nis = {}
            for name, (t, mean, count, dof) in e.nis_mean.items():
                u = t >= START
                nis[name] = float(np.sum(mean[u] * count[u]) / np.sum(count[u]) / dof)
            out[label] = Ensemble(grade, label, seed, runs, length,
                                  float(np.mean(nees[label])) / DOF,
                                  (band[0] / DOF, band[1] / DOF), ratios, ratio_band(runs), e,
                                  others, nis)
    return out


def main(argv: list[str]) -> int:
    runs = int(argv[0]) if argv else 100
    seeds = [int(s) for s in argv[1:]] or [0, 777, 4242]
    print("| grade | filter | seed | runs | NEES / dof | band | RMS / sigma pos N E D | "
          "vel N E D | att N E D |")
    print("|---|---|---|---|---|---|---|---|---|")
    for grade in GRADES:
        for seed in seeds:
            for e in ensembles(grade, seed, runs).values():
                print(e.row(), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
