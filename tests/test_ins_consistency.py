"""Ensemble consistency of ins and gps-ins on vehicle-drive: the run-averaged NEES of the nine
navigation errors inside its chi-square band, and the tilt RMS error equal to the predicted
sigma, on a small seeded ensemble (about 5 s)."""

import numpy as np
import pytest

from navreplay import metrics
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter
from navreplay.replay.engine import replay
from navreplay.sim.scenario import simulate

RUNS = 40
DURATION = 300.0  # two blocks of the route: eight turns, speed changes and slopes
SEED = 2024  # not used while choosing the models


@pytest.fixture(scope="module")
def drives():
    return [simulate("vehicle-drive", {"duration": DURATION}, seed=s)
            for s in range(SEED, SEED + RUNS)]


def _ensemble(drives, cls, params=None):
    stats = metrics.EnsembleStats()
    for rec in drives:
        stats.add(metrics.run_metrics(replay(rec, cls, params, output_rate=1.0), rec))
    return stats.result()


def _scores(e):
    """Share of epochs (from 10 s) with the NEES inside its 95 % band; tilt RMS / sigma (N and
    E pooled) over those epochs and at the last."""
    later = e.t >= 10.0
    lo, hi = e.nees_bounds
    inside = float(np.mean((e.nees_mean[later] >= lo[later]) & (e.nees_mean[later] <= hi[later])))

    def ratio(rows):
        return float(np.sqrt(np.mean(e.rms["phi"][rows, :2] ** 2))
                     / np.sqrt(np.mean(e.sigma["phi"][rows, :2] ** 2)))

    return inside, ratio(later), ratio(slice(-1, None))


def test_ins_tilt_sigma_is_honest(drives):
    e = _ensemble(drives, InsFilter)
    assert e.nees_dof == 9
    inside, tilt, tilt_end = _scores(e)
    assert inside >= 0.9, inside
    assert 0.8 <= tilt <= 1.2 and 0.8 <= tilt_end <= 1.2, (tilt, tilt_end)
    # the white-noise stand-in for the gyro z-rate errors grows the tilt sigma with every turn
    old = _ensemble(drives, InsFilter, {"gyro_misalignment_states": "false"})
    inside_old, _, tilt_end_old = _scores(old)
    assert inside_old < 0.6 and tilt_end_old < 0.85, (inside_old, tilt_end_old)


def test_gps_ins_nees_and_tilt_sigma_are_honest(drives):
    e = _ensemble(drives, GpsInsFilter)
    assert e.nees_dof == 9
    inside, tilt, tilt_end = _scores(e)
    assert inside >= 0.9, inside
    assert 0.8 <= tilt <= 1.2 and 0.8 <= tilt_end <= 1.2, (tilt, tilt_end)
    # the accelerometer states are scored against metadata.true_errors and consistent
    k = [i for i, s in enumerate(e.states) if s.name.startswith(("s_a_", "m_a_"))]
    assert len(k) == 6
    ratio = e.state_rms[-1, k] / e.state_sigma[-1, k]
    assert np.all((ratio > 0.6) & (ratio < 1.4)), ratio
