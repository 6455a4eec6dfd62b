"""Chi-square consistency of every built-in navigation filter over small seeded ensembles, and
the statistics of the checks themselves (docs/methods/consistency.md).

NIS: a consistent filter's innovations are white, so every update of every run is a sample.
NEES: a run's errors are correlated in time, so a run's time-averaged NEES is one sample. The
degrees of freedom come from what each filter declares, never from a hard-coded count.
"""

import numpy as np
import pytest

from navreplay import metrics
from navreplay.filters import rpm_aided_ins as rai
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter
from navreplay.metrics import consistency, tables
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


# --------------------------------------------------------------------------------------------
# correlated epochs: effective samples, the per-run NEES test, per-axis RMS/sigma


def _ar1(rng, a, n, k, runs=1):
    """Unit-variance AR(1) series z[t] = a z[t-1] + sqrt(1 - a^2) w[t], shape (runs, n, k)."""
    z = np.empty((runs, n, k))
    z[:, 0] = rng.standard_normal((runs, k))
    w = rng.standard_normal((runs, n, k)) * np.sqrt(1.0 - a * a)
    for t in range(1, n):
        z[:, t] = a * z[:, t - 1] + w[:, t]
    return z


def test_integrated_time_of_squared_ar1():
    """z AR(1) with coefficient a: z^2 has autocorrelation a^(2l), integrated time
    (1 + a^2) / (1 - a^2); pooled over runs from the lag products of z."""
    rng = np.random.default_rng(11)
    for a in (0.5, 0.9, 0.97):
        lags = consistency.LagProducts()
        for z in _ar1(rng, a, 2000, 2, runs=20):
            lags.add(z)
        expected = (1 + a * a) / (1 - a * a)
        assert lags.times() == pytest.approx([expected, expected], rel=0.15)


def test_per_run_nees_test_counts_correlated_epochs_honestly():
    """A consistent filter's NEES (3 dof, errors AR(1) with a = 0.98: 600 epochs worth 11
    samples) fails the per-run time-averaged test at its stated 5 %; counting every epoch as
    a sample fails most runs; a covariance 1.5 times too small in sigma fails it."""
    rng = np.random.default_rng(12)
    z = _ar1(rng, 0.98, 600, 3, runs=400)
    nees = np.sum(z * z, axis=2)
    lags = consistency.LagProducts()  # the integrated time pooled over the runs
    for zr in z:
        lags.add(zr)
    tau = lags.time_of_mean()
    assert tau == pytest.approx((1 + 0.98**2) / (1 - 0.98**2), rel=0.15)
    checks = [consistency.time_average_check(v, tau, 3, 0.05) for v in nees]
    rate = np.mean([not c.passed for c in checks])
    assert 0.025 < rate < 0.08, rate
    naive = np.mean([not consistency.inside(float(v.mean()), 3, 600, 0.05) for v in nees])
    assert naive > 0.5, naive
    power = np.mean([not consistency.time_average_check(2.25 * v, tau, 3, 0.05).passed
                     for v in nees])
    assert power > 0.9, power


def _ensemble(rng, scale_heading, runs=30, n=1200):
    """RunMetrics of ``runs`` runs of nine NEES states whose normalised errors are AR(1)
    (slow heading, a = 0.995), the heading's errors ``scale_heading`` times its sigma."""
    names = ("dlat", "dlon", "dh", "dv_N", "dv_E", "dv_D", "phi_N", "phi_E", "phi_D")
    stats = metrics.EnsembleStats("f")
    per_run = []
    for _ in range(runs):
        z = np.concatenate([_ar1(rng, 0.99, n, 8)[0], _ar1(rng, 0.995, n, 1)[0]], axis=1)
        z[:, 8] *= scale_heading
        var = np.full(z.shape, 4.0)
        m = metrics.RunMetrics(
            label="f", t=np.arange(n) * 0.1, nav=None, nav_sigma={}, state_names=names,
            state_error=2.0 * z, state_var=var, nees=np.sum(z * z, axis=1),
            nees_states=names, nis={}, distance=np.zeros(n))
        stats.add(m)
        per_run.append(m.nees.mean())
    return stats.result(), np.array(per_run)


def test_heading_rms_over_sigma_of_1_6_is_flagged():
    """The issue's case: the heading's errors are 1.6 times its sigma, the other eight states
    are consistent. The NEES check with one sample per run passes (its 9-dof band is wide);
    the per-axis RMS/sigma check flags the heading and only the heading."""
    res, per_run = _ensemble(np.random.default_rng(13), 1.6)
    assert consistency.inside(float(per_run.mean()), 9, len(per_run))  # the old check passes
    c = res.consistency
    heading = c.scale["phi_D"]
    assert not heading.passed and heading.interval[0] > 1.2
    assert heading.ratio == pytest.approx(1.6, rel=0.2)
    assert all(c.scale[n].passed for n in c.names if n != "phi_D")
    summary = res.summary()
    assert summary["rms_over_sigma"]["phi_D"]["passed"] is False
    assert "INCONSISTENT" in tables.format_summaries({"f": summary})
    # a consistent ensemble passes every axis, and its intervals cover 1
    res, _ = _ensemble(np.random.default_rng(14), 1.0)
    assert all(ch.passed for ch in res.consistency.scale.values())
    assert np.mean([ch.interval[0] <= 1.0 <= ch.interval[1]
                    for ch in res.consistency.scale.values()]) >= 7 / 9


def test_scale_interval_covers_the_true_scale():
    """The 95 % interval of RMS/sigma from k independent samples covers the true scale in
    95 % of 4000 draws."""
    rng = np.random.default_rng(15)
    k, s = 40, 1.3
    hits = [(c := consistency.scale_check(s * s * rng.chisquare(k) / k, k)).interval[0]
            <= s <= c.interval[1] for _ in range(4000)]
    assert 0.935 < np.mean(hits) < 0.965


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
