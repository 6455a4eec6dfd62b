"""Chi-square consistency of every built-in navigation filter over small seeded ensembles, and
the statistics of the checks themselves (docs/methods/consistency.md).

NIS: a consistent filter's innovations are white, so every update of every run is a sample.
NEES: a run's errors are correlated in time, so a run's time-averaged NEES is one sample. The
degrees of freedom come from what each filter declares, never from a hard-coded count.
"""

import numpy as np
import pytest

from navreplay import consistency, metrics
from navreplay.filters import rpm_aided_ins as rai
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter
from navreplay.replay.engine import replay
from navreplay.sim.scenario import simulate

# --------------------------------------------------------------------------------------------
# the checks themselves


@pytest.mark.parametrize(("dof", "samples"), [(1, 400), (2, 100), (3, 30), (15, 8)])
def test_false_alarm_of_the_check_on_consistent_draws(dof, samples):
    """Means of chi-square draws (what a consistent filter produces) leave the band at the
    stated rate: 200 000 simulated checks at a false alarm of 1 %."""
    rng = np.random.default_rng(dof * 1000 + samples)
    means = rng.chisquare(dof * samples, size=200_000) / samples
    lo, hi = consistency.mean_band(dof, samples, 0.01)
    rate = np.mean((means < lo) | (means > hi))
    assert 0.0085 < rate < 0.0115, rate
    assert consistency.rejection_probability(dof, samples, 1.0, 0.01) == pytest.approx(0.01)


def test_power_against_a_nine_percent_mis_scaled_sigma():
    """The pooled position check (900 runs of 2 dof) rejects a covariance 9 % off in sigma,
    either way, in more than 95 % of campaigns, and keeps its false alarm at 0.1 %; 100 runs
    (one seed's campaign) cannot tell 9 % from chance."""
    k = consistency.SIGMA_ERROR
    rng = np.random.default_rng(9)
    for scale in (1.0 + k, 1.0 / (1.0 + k)):
        p = consistency.rejection_probability(2, 900, scale)
        means = scale**2 * rng.chisquare(2 * 900, size=100_000) / 900
        lo, hi = consistency.mean_band(2, 900)
        assert np.mean((means < lo) | (means > hi)) == pytest.approx(p, abs=0.005)
        assert p > 0.95
        assert consistency.rejection_probability(2, 100, scale) < 0.1
    assert 600 < consistency.samples_needed(2) <= 900


def test_checks_reject_a_deliberately_mis_scaled_covariance():
    """The NEES of a covariance scaled by s^2 is the NEES divided by s^2: consistent draws pass
    the 900-sample check, the same draws with P scaled 9 % in sigma either way fail it."""
    rng = np.random.default_rng(2024)
    e = rng.standard_normal((900, 2))  # errors of a filter with P = I
    for s, passes in ((1.0, True), (1.09, False), (1.0 / 1.09, False)):
        P = np.broadcast_to(np.eye(2) * s * s, (900, 2, 2))
        mean = float(np.mean(metrics.nees(e, P)))
        assert consistency.inside(mean, 2, 900) is passes, (s, mean)


# --------------------------------------------------------------------------------------------
# NIS of every measurement, NEES over the declared states


def _nis_samples(results, name):
    """All NIS values of measurement ``name`` over the runs (first 10 updates left out: the
    initial transient), and the measurement's dof."""
    inn = [r.innovations[name] for r in results]
    return np.concatenate([i.nis[10:] for i in inn]), inn[0].nu.shape[1]


def test_ins_has_no_measurements():
    rec = simulate("vehicle-drive", {"duration": 20.0}, seed=0)
    assert replay(rec, InsFilter, output_rate=1.0).innovations == {}


@pytest.fixture(scope="module")
def gps_ins_runs():
    recs = [simulate("vehicle-drive", {"duration": 300.0}, seed=8100 + s) for s in range(6)]
    return recs, [replay(r, GpsInsFilter, output_rate=1.0) for r in recs]


@pytest.mark.parametrize("name", ["gps_pos", "gps_vel"])
def test_gps_ins_nis_of_every_measurement(gps_ins_runs, name):
    _, results = gps_ins_runs
    nis, dof = _nis_samples(results, name)
    assert dof == 3
    lo, hi = consistency.mean_band(dof, nis.size)
    assert lo <= nis.mean() <= hi, (name, nis.mean(), lo, hi)


def test_gps_ins_nees_over_its_declared_states(gps_ins_runs):
    """Each run's time-averaged NEES (from 10 s) over the states gps-ins declares for the NEES
    is one chi-square sample of that many dof (conservative: the curve decorrelates)."""
    recs, results = gps_ins_runs
    per_run = []
    for rec, res in zip(recs, results, strict=True):
        m = metrics.run_metrics(res, rec)
        dof = len(m.nees_states)
        assert dof == sum(s.nees for s in res.states) >= 9
        per_run.append(np.nanmean(m.nees[m.t >= 10.0]))
    lo, hi = consistency.mean_band(dof, len(per_run))
    assert lo <= np.mean(per_run) <= hi, (np.mean(per_run), lo, hi)


@pytest.fixture(scope="module")
def rpm_runs():
    return [replay(simulate("underwater-rpm", {"duration": 200.0}, seed=900 + s),
                   rai.RpmAidedIns, {"mode": "rpm_current"}, output_rate=None)
            for s in range(8)]


def test_rpm_aided_ins_nis_of_depth_and_of_each_rpm_row(rpm_runs):
    """Depth (1 dof) and the RPM forward row (1 dof) inside their bands. The no-sideslip and
    no-heave rows are not yet: their NIS is 0.1-0.2 (0.02-0.03 with the former 2 mm/s
    constraint noise, gyro noise 1.7 x ARW and no accelerometer states), still pessimistic
    (docs/methods/rpm-aided-ins.md §6). The check fails if they fall back below 0.1 or reach
    their band without this docstring being revised."""
    nis, dof = _nis_samples(rpm_runs, "depth")
    assert dof == 1
    lo, hi = consistency.mean_band(1, nis.size)
    assert lo <= nis.mean() <= hi, ("depth", nis.mean(), lo, hi)
    nu = np.concatenate([r.innovations["rpm"].nu[10:] for r in rpm_runs])
    S = np.concatenate([r.innovations["rpm"].S[10:] for r in rpm_runs])
    row = nu**2 / np.diagonal(S, 0, 1, 2)
    lo, hi = consistency.mean_band(1, len(nu))
    assert lo <= row[:, 0].mean() <= hi, ("forward", row[:, 0].mean(), lo, hi)
    across = row[:, 1:].mean(axis=0)
    assert np.all((across > 0.1) & (across < lo)), across
