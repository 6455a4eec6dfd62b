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
from navreplay.replay import replay
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
    """Depth (1 dof) and each row of the RPM update (forward, no-sideslip, no-heave; 1 dof
    each) inside its chi-square band: the across-axis rows' noise is the vehicle's sway and
    heave through the water, which the scenario simulates and the filter's constraint_sigma
    states (docs/methods/rpm-aided-ins.md §4.4). A constraint noise below the real sway and
    heave makes them optimistic, one above it (or a residual the model does not explain)
    pessimistic."""
    nis, dof = _nis_samples(rpm_runs, "depth")
    assert dof == 1
    lo, hi = consistency.mean_band(1, nis.size)
    assert lo <= nis.mean() <= hi, ("depth", nis.mean(), lo, hi)
    nu = np.concatenate([r.innovations["rpm"].nu[10:] for r in rpm_runs])
    S = np.concatenate([r.innovations["rpm"].S[10:] for r in rpm_runs])
    assert nu.shape[1] == 3
    row = (nu**2 / np.diagonal(S, 0, 1, 2)).mean(axis=0)
    lo, hi = consistency.mean_band(1, len(nu))
    for name, value in zip(("forward", "no-sideslip", "no-heave"), row, strict=True):
        assert lo <= value <= hi, (name, value, lo, hi)


def test_rpm_aided_ins_across_axis_nis_rejects_a_mis_stated_sway_and_heave():
    """The same check has power: with the filter's constraint noise at half or twice the
    simulated sway and heave the across-axis rows leave their band (NIS 3.5-3.8 and 0.25-0.29)."""
    rec = simulate("underwater-rpm", {"duration": 200.0}, seed=900)
    for scale in (0.5, 2.0):
        res = replay(rec, rai.RpmAidedIns, {"mode": "rpm_current",
                                            "constraint_sigma": scale * 0.002}, output_rate=None)
        inn = res.innovations["rpm"]
        row = (inn.nu[10:] ** 2 / np.diagonal(inn.S[10:], 0, 1, 2)).mean(axis=0)
        lo, hi = consistency.mean_band(1, len(inn.nu) - 10)
        assert np.all((row[1:] < lo) | (row[1:] > hi)), (scale, row)
