"""Ensemble consistency of ins and gps-ins on vehicle-drive (docs/methods/consistency.md): each
run's NEES of the nine navigation errors averaged from 10 s is one chi-square(9) sample, and
the mean over the runs must lie in its band at the false alarm consistency.CHECK_FALSE_ALARM;
the tilt RMS error must equal the predicted sigma. A small seeded ensemble (about 10 s)."""

import dataclasses

import numpy as np
import pytest

from navreplay import metrics
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter
from navreplay.metrics import consistency
from navreplay.replay import replay
from navreplay.sim.scenario import simulate

RUNS = 40
DURATION = 300.0  # two blocks of the route: eight turns, speed changes and slopes
SEED = 2024  # not used while choosing the models
DOF = 9
POWER_SIGMA_ERROR = 0.2
"""With 40 runs the check rejects a covariance 20 % off in sigma, either way, with a
probability above 0.9 (a 9 % error needs 161 runs: consistency.samples_needed)."""


@pytest.fixture(scope="module")
def drives():
    return [simulate("vehicle-drive", {"duration": DURATION}, seed=s)
            for s in range(SEED, SEED + RUNS)]


def _ensemble(drives, cls, params=None):
    """Per-run NEES samples (each run's mean from 10 s) and the ensemble statistics."""
    stats = metrics.EnsembleStats()
    samples = []
    for rec in drives:
        m = metrics.run_metrics(replay(rec, cls, params, output_rate=1.0), rec)
        assert m.nees_states == ("dlat", "dlon", "dh", "dv_N", "dv_E", "dv_D",
                                 "phi_N", "phi_E", "phi_D")
        samples.append(float(np.mean(m.nees[m.t >= 10.0])))
        stats.add(m)
    return np.array(samples), stats.result()


def _nees_check(samples):
    """The chi-square check: (accepted, mean NEES, band)."""
    mean = float(samples.mean())
    return (consistency.inside(mean, DOF, samples.size), mean,
            consistency.mean_band(DOF, samples.size))


def _tilt_ratios(e):
    """Tilt RMS / sigma (N and E pooled) over the epochs from 10 s and at the last."""
    def ratio(rows):
        return float(np.sqrt(np.mean(e.rms["phi"][rows, :2] ** 2))
                     / np.sqrt(np.mean(e.sigma["phi"][rows, :2] ** 2)))

    return ratio(e.t >= 10.0), ratio(slice(-1, None))


def _scaled_ins(factor):
    """ins with its initial covariance and process noise both times ``factor``: without
    updates its covariance is then ``factor`` times the model's at every epoch, the estimate
    unchanged (``factor`` > 1 under-confident, < 1 over-confident)."""
    class ScaledIns(InsFilter):
        def _process_noise(self, n):
            noise = super()._process_noise(n)
            return dataclasses.replace(noise, q=noise.q * factor, k_acc=noise.k_acc * factor,
                                       k_gyro=noise.k_gyro * factor)

        def _init_extra(self):
            super()._init_extra()
            self.P *= factor

    return ScaledIns


def test_the_check_has_its_stated_power():
    for s in (1.0 + POWER_SIGMA_ERROR, 1.0 / (1.0 + POWER_SIGMA_ERROR)):
        assert consistency.rejection_probability(DOF, RUNS, s) > 0.9, s
    assert consistency.rejection_probability(DOF, RUNS, 1.0) == pytest.approx(
        consistency.CHECK_FALSE_ALARM, rel=1e-6)


def test_ins_nees_and_tilt_sigma_are_honest(drives):
    samples, e = _ensemble(drives, InsFilter)
    ok, mean, band = _nees_check(samples)
    assert ok, (mean, band)
    tilt, tilt_end = _tilt_ratios(e)
    assert 0.8 <= tilt <= 1.2 and 0.8 <= tilt_end <= 1.2, (tilt, tilt_end)
    # the white-noise stand-in for the gyro z-rate errors grows the tilt sigma with every turn:
    # the nine-error NEES drops (7.59, still in the band of 40 runs: about 11 % in sigma, below
    # the power of the check) and the tilt sigma at 300 s is about 40 % too large (RMS / sigma 0.72)
    old, e_old = _ensemble(drives, InsFilter, {"gyro_misalignment_states": "false"})
    _, tilt_end_old = _tilt_ratios(e_old)
    assert old.mean() < 0.9 * mean and tilt_end_old < 0.85, (old.mean(), tilt_end_old)


@pytest.mark.parametrize("sigma_scale", [1.0 + POWER_SIGMA_ERROR, 1.0 / (1.0 + POWER_SIGMA_ERROR)],
                         ids=["under-confident", "over-confident"])
def test_ins_nees_check_rejects_a_mis_scaled_covariance(drives, sigma_scale):
    """The same runs with P0 and Q scaled by sigma_scale^2: the predicted sigma 20 % too large
    or too small is rejected."""
    samples, _ = _ensemble(drives, _scaled_ins(sigma_scale ** 2))
    reference, _ = _ensemble(drives[:2], InsFilter)
    assert np.allclose(samples[:2] * sigma_scale ** 2, reference, rtol=1e-9)
    ok, mean, band = _nees_check(samples)
    assert not ok, (sigma_scale, mean, band)
    assert (mean < band[0]) if sigma_scale > 1.0 else (mean > band[1]), (mean, band)


def test_gps_ins_nees_and_tilt_sigma_are_honest(drives):
    samples, e = _ensemble(drives, GpsInsFilter)
    ok, mean, band = _nees_check(samples)
    assert ok, (mean, band)
    tilt, tilt_end = _tilt_ratios(e)
    assert 0.8 <= tilt <= 1.2 and 0.8 <= tilt_end <= 1.2, (tilt, tilt_end)
    # the scale-factor and misalignment states are scored against metadata.true_errors and
    # consistent
    k = [i for i, s in enumerate(e.states) if s.name.startswith(("s_a_", "m_a_", "s_g_", "m_g_"))]
    assert len(k) == 18
    ratio = e.state_rms[-1, k] / e.state_sigma[-1, k]
    assert np.all((ratio > 0.6) & (ratio < 1.4)), ratio
