"""Metrics: errors and signs, CEP50 and %DT, NEES/NIS bounds, the ensemble accumulator."""

import numpy as np
import pytest

from navreplay import metrics
from navreplay.core.streams import Metadata, Recording, Stream, StreamKind
from navreplay.filters.base import Nav, NavError, Quantity, State, TrueConstant, TruthColumn
from navreplay.filters.result import InnovationSeries, RunResult
from navreplay.geo import earth, rotations
from navreplay.metrics import tables

LAT0, LON0, H0 = np.deg2rad(36.0), np.deg2rad(130.0), 10.0
T0_NS = 1_500_000_000_000_000_000


def _recording(n=101, dt=1.0, speed=10.0, true_errors=None, extra_columns=None):
    """Truth: due north at constant speed, level, heading 0; one sample per dt."""
    t = np.arange(n) * dt
    R_M, _ = earth.radii(LAT0)
    pos = np.c_[LAT0 + speed * t / (R_M + H0), np.full(n, LON0), np.full(n, H0)]
    v = np.tile([speed, 0.0, 0.0], (n, 1))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    cols = {"pos": pos, "v_n": v, "q_nb": q, **(extra_columns or {})}
    truth = Stream(StreamKind.TRUTH, T0_NS + np.rint(t * 1e9).astype(np.int64), cols)
    return Recording({StreamKind.TRUTH: truth}, Metadata(true_errors=true_errors or {}),
                     t0_ns=T0_NS)


def _result(rec, t, pos_ned_err=None, x=None, P=None, states=(), innovations=None,
            euler_err=None):
    truth = metrics.truth_at(rec, t)
    M = t.shape[0]
    pos = truth["pos"].copy()
    if pos_ned_err is not None:
        R_M, R_N = earth.radii(pos[:, 0])
        pos[:, 0] += pos_ned_err[:, 0] / (R_M + pos[:, 2])
        pos[:, 1] += pos_ned_err[:, 1] / ((R_N + pos[:, 2]) * np.cos(pos[:, 0]))
        pos[:, 2] -= pos_ned_err[:, 2]
    q = truth["q_nb"]
    if euler_err is not None:
        q = rotations.euler_to_quat(rotations.quat_to_euler(q) + euler_err)
    k = len(states)
    return RunResult(
        filter_name="synthetic", label="syn", recording="rec", t0_ns=T0_NS, t=t,
        states=tuple(states),
        x=np.zeros((M, k)) if x is None else x,
        P=np.zeros((M, k, k)) if P is None else P,
        nav_pos=pos, nav_v_n=truth["v_n"], nav_q_nb=q,
        innovations=innovations or {},
    )


def test_position_and_attitude_error_signs():
    rec = _recording()
    t = np.array([10.0, 20.5])
    err = np.array([[3.0, -4.0, 1.5], [-2.0, 1.0, -0.5]])
    res = _result(rec, t, pos_ned_err=err, euler_err=np.array([[0.0, 0.0, 0.01]] * 2))
    m = metrics.run_metrics(res, rec)
    np.testing.assert_allclose(m.nav.pos_ned, err, atol=1e-6)
    # a heading too large by 0.01 rad: phi_D = -0.01 (C_hat = (I - [phi x]) C)
    np.testing.assert_allclose(m.nav.phi, [[0, 0, -0.01]] * 2, atol=1e-6)
    np.testing.assert_allclose(m.nav.euler, [[0, 0, 0.01]] * 2, atol=1e-9)


def test_yaw_difference_wrapped():
    n = 3
    q_true = rotations.euler_to_quat(np.tile([0.0, 0.0, np.deg2rad(179.0)], (n, 1)))
    q_hat = rotations.euler_to_quat(np.tile([0.0, 0.0, np.deg2rad(-179.0)], (n, 1)))
    truth = {"pos": np.tile([LAT0, LON0, 0.0], (n, 1)), "v_n": np.zeros((n, 3)), "q_nb": q_true}
    e = metrics.nav_errors(truth["pos"], truth["v_n"], q_hat, truth)
    np.testing.assert_allclose(e.euler[:, 2], np.deg2rad(2.0), atol=1e-9)
    np.testing.assert_allclose(e.phi[:, 2], -np.deg2rad(2.0), rtol=1e-3)  # small angle


def test_truth_interpolation():
    rec = _recording(n=11, dt=1.0)
    tr = metrics.truth_at(rec, np.array([2.0, 2.25, 10.0, 10.4, 12.0]))
    R_M, _ = earth.radii(LAT0)
    north = (tr["pos"][:, 0] - LAT0) * (R_M + H0)
    # within half a sample past the end: the end sample; further: not scored
    np.testing.assert_allclose(north, [20.0, 22.5, 100.0, 100.0, np.nan], atol=1e-6)


def test_cep50_and_distance_travelled_on_constructed_data():
    # 5 runs with known final north/east errors over a 1000 m drive
    rec = _recording(n=101, dt=1.0, speed=10.0)
    assert metrics.Reference.of(rec).distance() == pytest.approx(1000.0)
    t = np.arange(0.0, 101.0, 10.0)
    north = np.array([3.0, -1.0, 2.0, 0.0, -4.0])
    east = np.array([1.0, 1.0, -2.0, 5.0, 0.0])
    stats = metrics.EnsembleStats()
    for i in range(5):
        err = np.zeros((t.size, 3))
        err[-1, :2] = north[i], east[i]
        stats.add(metrics.run_metrics(_result(rec, t, pos_ned_err=err), rec))
    res = stats.result()
    lat_rms, long_rms = np.sqrt(np.mean(north**2)), np.sqrt(np.mean(east**2))
    assert res.cep50[-1] == pytest.approx(0.5887 * (lat_rms + long_rms), rel=1e-6)
    assert res.distance[-1] == pytest.approx(1000.0)
    assert res.dt_cep50[-1] == pytest.approx(0.5887 * (lat_rms + long_rms) / 1000.0 * 100.0,
                                             rel=1e-6)
    s = res.summary()
    assert s["lat_rms_final"] == pytest.approx(lat_rms, rel=1e-6)
    assert s["dt_cep50_final"] == pytest.approx(res.dt_cep50[-1])
    assert metrics.cep50(north, east) == pytest.approx(res.cep50[-1], rel=1e-6)


def _zero_states(k):
    return tuple(State(f"s{i}", "-", Quantity.OTHER, TruthColumn("zero", (i,)), nees=True)
                 for i in range(k))


def _consistent_runs(rng, runs, M, k=4):
    """Runs whose state errors are N(0, P) with a random, time-varying P."""
    rec = _recording(n=M, dt=1.0, extra_columns={"zero": np.zeros((M, k))})
    t = np.arange(M, dtype=float)
    states = _zero_states(k)
    A = rng.normal(size=(M, k, k)) * np.array([1.0, 1e-3, 1e2, 1e-6])  # mixed units
    P = A @ A.transpose(0, 2, 1) + np.diag([1.0, 1e-6, 1e4, 1e-12])
    out = []
    for _ in range(runs):
        x = np.einsum("kij,kj->ki", np.linalg.cholesky(P), rng.normal(size=(M, k)))
        S = np.tile(np.diag([4.0, 9.0]), (M, 1, 1))
        nu = rng.normal(size=(M, 2)) * [2.0, 3.0]
        nis = np.einsum("ki,ki->k", nu, np.linalg.solve(S, nu[..., None])[..., 0])
        inn = {"meas": InnovationSeries(t=t, nu=nu, S=S, nis=nis)}
        out.append(metrics.run_metrics(_result(rec, t, x=x, P=P, states=states, innovations=inn),
                                       rec))
    return out


def test_nees_and_nis_of_consistent_gaussian_errors_inside_bounds():
    rng = np.random.default_rng(11)
    runs, M = 30, 200
    ms = _consistent_runs(rng, runs, M)
    stats = metrics.EnsembleStats()
    for m in ms:
        stats.add(m)
    res = stats.result()
    lo, hi = metrics.chi2_bounds(4, runs)
    np.testing.assert_allclose(res.nees_bounds[0], lo)
    inside = (res.nees_mean >= lo) & (res.nees_mean <= hi)
    assert 0.9 <= inside.mean()  # 95 % expected
    # the mean over all runs and epochs (independent samples here) is tight around the dof
    lo_all, hi_all = metrics.chi2_bounds(4, runs * M)
    assert lo_all < res.nees_mean.mean() < hi_all
    _, nis_mean, count, dof = res.nis_mean["meas"]
    assert dof == 2 and np.all(count == runs)
    lo_all, hi_all = metrics.chi2_bounds(2, runs * M)
    assert lo_all < nis_mean.mean() < hi_all
    s = res.summary()
    assert s["nees_dof"] == 4 and 0.9 <= s["nees_in_bounds"] <= 1.0
    # a single run: the time average of a white sequence
    one = ms[0].summary()
    assert 0.85 < one["nees_in_bounds"] and 0.85 < one["nis_in_bounds_meas"]
    # an over-confident filter (P / 4) is caught
    e = np.stack([m.state_error for m in ms])
    P = np.stack([np.apply_along_axis(np.diag, 1, m.state_var) for m in ms])
    assert metrics.nees(e[0], P[0] / 4).mean() > hi


def test_nees_block_and_singular_epochs():
    rng = np.random.default_rng(3)
    e = rng.normal(size=(5, 3))
    P = np.tile(np.eye(3), (5, 1, 1))
    P[2, 1, 1] = 0.0  # a zero variance at epoch 2
    v = metrics.nees(e, P)
    np.testing.assert_allclose(v[[0, 1, 3, 4]], np.sum(e[[0, 1, 3, 4]] ** 2, axis=1))
    assert np.isnan(v[2])


def test_nees_is_the_quadratic_form_of_correlated_covariances():
    """e^T P^-1 e of full covariances whose states differ in scale by ten orders (metres and
    radians, a rad/s bias), against an explicit inverse of each."""
    rng = np.random.default_rng(8)
    M, k = 300, 9
    scale = 10.0 ** rng.uniform(-6.0, 3.0, k)
    A = rng.normal(size=(M, k, k))
    P = (A @ A.transpose(0, 2, 1) + 0.1 * np.eye(k)) * scale[:, None] * scale[None, :]
    e = rng.normal(size=(M, k)) * scale
    want = np.einsum("ki,kij,kj->k", e, np.linalg.inv(P), e)
    np.testing.assert_allclose(metrics.nees(e, P), want, rtol=1e-8)


def test_ensemble_stats_equals_batch_computation():
    rng = np.random.default_rng(5)
    runs, M = 7, 40
    ms = _consistent_runs(rng, runs, M)
    # give the navigation solutions errors too
    rec = _recording(n=M, dt=1.0, extra_columns={"zero": np.zeros((M, 4))})
    t = np.arange(M, dtype=float)
    ms = []
    pos_err = rng.normal(size=(runs, M, 3)) * [2.0, 3.0, 5.0]
    for i in range(runs):
        x = rng.normal(size=(M, 4))
        P = np.tile(np.eye(4), (M, 1, 1)) * (1 + i)
        ms.append(metrics.run_metrics(
            _result(rec, t, pos_ned_err=pos_err[i], x=x, P=P, states=_zero_states(4)), rec))
    stats = metrics.EnsembleStats()
    for m in ms:
        stats.add(m)
    res = stats.result()
    pos = np.stack([m.nav.pos_ned for m in ms])
    np.testing.assert_allclose(res.rms["pos_ned"], np.sqrt(np.mean(pos**2, axis=0)), rtol=1e-10)
    np.testing.assert_allclose(res.mean["pos_ned"], np.mean(pos, axis=0), atol=1e-9)
    np.testing.assert_allclose(pos, pos_err, atol=1e-5)
    se = np.stack([m.state_error for m in ms])
    np.testing.assert_allclose(res.state_rms, np.sqrt(np.mean(se**2, axis=0)), rtol=1e-12)
    np.testing.assert_allclose(res.state_sigma, np.sqrt(np.mean(np.arange(1, runs + 1))),
                               rtol=1e-12)
    nees = np.stack([m.nees for m in ms])
    np.testing.assert_allclose(res.nees_mean, nees.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(
        res.cep50, 0.5887 * np.sqrt(np.mean(pos[..., :2] ** 2, axis=0)).sum(axis=1), rtol=1e-10)


def test_ensemble_rejects_other_time_grids():
    rng = np.random.default_rng(0)
    a = _consistent_runs(rng, 1, 20)[0]
    b = _consistent_runs(rng, 1, 20)[0]
    b.t = b.t + 0.5
    stats = metrics.EnsembleStats()
    stats.add(a)
    with pytest.raises(ValueError, match="other output times"):
        stats.add(b)


def test_declared_truths_from_metadata_and_nav():
    rec = _recording(n=11, true_errors={"imu": {"gyro_bias": [1e-5, 2e-5, 3e-5]}})
    t = np.array([5.0])
    x = np.array([[2.5e-5, 0.0]])
    res = _result(rec, t, pos_ned_err=np.array([[0.0, 0.0, 2.0]]), x=x,
                  P=np.diag([1e-10, 4.0])[None],
                  states=[State("b_g_y", "rad/s", Quantity.GYRO_BIAS,
                                TrueConstant("imu.gyro_bias", (1,)), nees=True),
                          State("dh", "m", Quantity.POSITION, NavError(Nav.H), nees=True)])
    m = metrics.run_metrics(res, rec)
    # down error 2 m is height error -2 m; the state estimate 0 leaves e = -2 m
    np.testing.assert_allclose(m.state_error, [[0.5e-5, -2.0]], atol=1e-9)
    assert m.nees[0] == pytest.approx(0.25 + 1.0)
    # a constant the reference does not hold leaves that state unscored (and out of the NEES)
    other = (State("b_g_y", "rad/s", Quantity.GYRO_BIAS, TrueConstant("imu.accel_bias", (1,)),
                   nees=True), res.states[1])
    m = metrics.run_metrics(res, rec, states=other)
    assert m.state_names == ("dh",) and m.nees_states == ("dh",)
    assert m.nees[0] == pytest.approx(1.0)


def test_a_reference_with_positions_only_scores_positions():
    rec = _recording(n=21)
    t = np.array([5.0, 10.0])
    err = np.array([[3.0, -4.0, 1.0], [1.0, 2.0, -1.0]])
    states = (State("dh", "m", Quantity.POSITION, NavError(Nav.H), nees=True),
              State("dv_N", "m/s", Quantity.VELOCITY, NavError(Nav.V_N), nees=True),
              State("b", "-", Quantity.OTHER, TruthColumn("accel_bias", (0,)), nees=True))
    res = _result(rec, t, pos_ned_err=err, states=states, P=np.tile(np.eye(3), (2, 1, 1)))
    truth = rec[StreamKind.TRUTH]
    ref = metrics.Reference(Stream(StreamKind.TRUTH, truth.t_ns, {"pos": truth["pos"]}), T0_NS)
    m = metrics.run_metrics(res, ref)
    np.testing.assert_allclose(m.nav.pos_ned, err, atol=1e-6)
    assert np.isnan(m.nav.v_n).all() and np.isnan(m.nav.phi).all()
    assert m.state_names == ("dh",) and m.nees_states == ("dh",)
    s = m.summary()
    assert "pos_rms_h" in s and "vel_rms" not in s and "att_rms_heading" not in s
    assert s["distance"] == pytest.approx(100.0, rel=1e-6)  # 10 m/s for 10 s, from positions
    assert s["nees_dof"] == 1


def test_a_reference_that_ends_early_leaves_later_outputs_unscored():
    """Outputs past the reference's end (beyond half a sample) are not scored against its last
    sample: the final error is the last one inside the reference."""
    rec = _recording(n=21)
    t = np.array([5.0, 10.0, 15.0])
    err = np.array([[3.0, -4.0, 1.0], [1.0, 2.0, -1.0], [100.0, 0.0, 0.0]])
    states = (State("dh", "m", Quantity.POSITION, NavError(Nav.H), nees=True),)
    res = _result(rec, t, pos_ned_err=err, states=states, P=np.tile(np.eye(1), (3, 1, 1)))
    truth = rec[StreamKind.TRUTH]
    keep = slice(0, 11)  # 0..10 s
    short = Stream(StreamKind.TRUTH, truth.t_ns[keep],
                   {k: v[keep] for k, v in truth.columns.items()})
    m = metrics.run_metrics(res, metrics.Reference(short, T0_NS))
    assert np.isfinite(m.nav.pos_ned[:2]).all() and np.isnan(m.nav.pos_ned[2]).all()
    assert np.isnan(m.nees[2])
    s = m.summary()
    assert s["pos_err_final_h"] == pytest.approx(np.hypot(1.0, 2.0), rel=1e-6)
    assert s["pos_rms_h"] == pytest.approx(np.sqrt((25.0 + 5.0) / 2), rel=1e-6)


def test_format_table():
    table = tables.format_table({
        "ins": {"pos_rms_h": 812.0, "att_rms_level": 1.23e-3, "nees_in_bounds": 0.5},
        "gps-ins": {"pos_rms_h": 0.91, "nis_mean_gps_pos": 3.02},
    })
    lines = table.splitlines()
    assert lines[0].split() == ["label", "pos_rms_h", "att_rms_level", "nees_in_bounds",
                                "nis_mean_gps_pos"]
    assert lines[1].split() == ["[m]", "[mrad]", "[%]"]
    assert lines[2].split() == ["ins", "812", "1.23", "50", "-"]
    assert lines[3].split() == ["gps-ins", "0.91", "-", "-", "3.02"]
