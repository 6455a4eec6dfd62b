"""Gyro-free vector matching: Gimpo scenarios, the filter's models, fast path, reproduction.

Section numbers (§) and errata (E1-E11) are those of docs/methods/vector-matching.md.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from campaign_seeds import SLOW_SEEDS

from navreplay.core.params import ParamError
from navreplay.core.streams import StreamKind
from navreplay.core.units import DEG, G0, MICRO_G
from navreplay.filters import kalman
from navreplay.filters.registry import load_filter
from navreplay.filters.vector_matching import (
    ACCEL_NOISE_SIGMA,
    MAG_NOISE_SIGMA,
    MatchModel,
    Reference,
    Variant,
    VectorMatchingFilter,
    VectorMatchingParams,
    euler_sigma,
    feedback,
    measurement,
    measurement_noise,
    model_induced_error,
    process_noise,
    reference,
    run_batch,
    triad,
)
from navreplay.geo.earth import gravity
from navreplay.geo.rotations import (
    dcm_to_euler,
    euler_to_dcm,
    euler_to_quat,
    quat_conj,
    quat_mult,
    quat_to_dcm,
    skew,
)
from navreplay.metrics import consistency
from navreplay.replay import FilterInitError, MissingStreamError, replay
from navreplay.reproduce import get as get_reproduction
from navreplay.reproduce.vector_matching import (
    ACCEL_G,
    REPRODUCTION,
    euler_errors,
    run_sweep_axis,
)
from navreplay.sensors.noise import sample_sigma
from navreplay.sim.scenario import get_scenario, simulate
from navreplay.sim.scenarios.gimpo import (
    IGRF_FIELD_N,
    YAW_RATE,
    GimpoAccelSweepParams,
    GimpoAccelYawParams,
    segment_truth,
    simulate_runs,
    yaw_segments,
)

G_N = np.array([0.0, 0.0, 9.7994])
H_N = np.array([29419e-9, -4307e-9, 41627e-9])


def last_per_epoch(t: np.ndarray) -> np.ndarray:
    """Rows of a RunResult holding the final estimate of each epoch time."""
    return np.r_[np.flatnonzero(np.diff(t)), len(t) - 1]


# --------------------------------------------------------------------------------------------
# scenarios


@pytest.mark.parametrize("case", ["x", "y"])
def test_yaw_truth_matches_the_closed_form_and_ends_at_rest(case):
    p = GimpoAccelYawParams(case=case)
    A = 0.5 * G0
    w = math.pi / 10
    k = A / w
    assert YAW_RATE == pytest.approx(w)
    assert k == pytest.approx(15.608, abs=1e-3)
    t = np.linspace(0.0, 30.0, 601)
    yaw, a_n, v_n, _ = segment_truth(yaw_segments(p), t)
    expect = np.zeros((t.size, 3))
    psi = np.zeros(t.size)
    s1 = t - 10.0
    s3 = t - 20.0
    w1 = (t > 10) & (t <= 15)
    w2 = (t > 15) & (t <= 20)
    w3 = (t > 20) & (t <= 25)
    psi[w1] = w * s1[w1]
    psi[w2] = math.pi / 2
    psi[w3] = math.pi / 2 - w * s3[w3]
    ws1, ws3 = w * s1, w * s3
    if case == "x":
        expect[w1] = k * np.stack([np.sin(ws1), 1 - np.cos(ws1), 0 * t], -1)[w1]
        expect[w2] = k * np.array([1.0, 1.0, 0.0])
        expect[w3] = k * np.stack([np.cos(ws3), 1 - np.sin(ws3), 0 * t], -1)[w3]
    else:
        expect[w1] = k * np.stack([np.cos(ws1) - 1, np.sin(ws1), 0 * t], -1)[w1]
        expect[w2] = k * np.array([-1.0, 1.0, 0.0])
        expect[w3] = k * np.stack([np.sin(ws3) - 1, np.cos(ws3), 0 * t], -1)[w3]
    np.testing.assert_allclose(v_n, expect, atol=1e-12)
    np.testing.assert_allclose(yaw, psi, atol=1e-14)
    # the acceleration is the body-axis acceleration rotated by the yaw (no centripetal term)
    a_b = np.einsum("kji,kj->ki", euler_to_dcm(np.stack([0 * t, 0 * t, yaw], -1)), a_n)
    axis = 0 if case == "x" else 1
    np.testing.assert_allclose(a_b[w1, axis], A, atol=1e-12)
    np.testing.assert_allclose(a_b[w3, axis], -A, atol=1e-12)
    np.testing.assert_allclose(np.delete(a_b[w1 | w3], axis, axis=1), 0.0, atol=1e-12)
    # v(25) = 0 and at rest afterwards
    np.testing.assert_allclose(v_n[t >= 25.0], 0.0, atol=1e-12)
    rec = simulate("gimpo-accel-yaw", {"case": case}, seed=0)
    tr = rec["truth"]
    t_s = (tr.t_ns - rec.t0_ns) * 1e-9
    np.testing.assert_allclose(tr["v_n"][t_s == 25.0], 0.0, atol=1e-12)
    np.testing.assert_allclose(tr["v_n"][-1], 0.0, atol=1e-12)


def test_yaw_truth_velocity_is_the_integral_of_the_acceleration():
    p = GimpoAccelYawParams(case="x")
    t = np.linspace(0.0, 30.0, 30001)
    _, a_n, v_n, d_n = segment_truth(yaw_segments(p), t)
    dt = t[1] - t[0]
    # trapezoid rule, away from the four switching times of the acceleration
    smooth = np.all(np.abs(np.diff(a_n, axis=0)) < 0.1, axis=1)
    assert np.count_nonzero(~smooth) == 4
    dv = v_n[1:] - v_n[:-1]
    np.testing.assert_allclose(dv[smooth], (0.5 * (a_n[1:] + a_n[:-1]) * dt)[smooth], atol=1e-6)
    np.testing.assert_allclose(d_n[1:] - d_n[:-1], 0.5 * (v_n[1:] + v_n[:-1]) * dt, atol=1e-5)


@pytest.mark.parametrize("axis", ["N", "E", "D"])
def test_sweep_truth_and_specific_force(axis):
    a = 1.2
    rec = simulate("gimpo-accel-sweep", {"axis": axis, "accel_g": a}, seed=1)
    tr = rec["truth"]
    t = (tr.t_ns - rec.t0_ns) * 1e-9
    assert len(t) == 41 and t[-1] == 10.0
    i = "NED".index(axis)
    v = np.zeros((41, 3))
    v[:, i] = a * G0 * np.maximum(0.0, t - 5.0)
    np.testing.assert_allclose(tr["v_n"], v, atol=1e-12)
    np.testing.assert_array_equal(tr["q_nb"], np.tile([1.0, 0, 0, 0], (41, 1)))
    g = gravity(37.55 * DEG, 40.0)
    assert g == pytest.approx(9.7994, abs=1e-4)
    # the sample at t = 5 s still reads rest; the next one the acceleration
    k5 = int(np.flatnonzero(t == 5.0)[0])
    np.testing.assert_allclose(tr["f_b"][: k5 + 1], np.tile([0, 0, -g], (k5 + 1, 1)), atol=1e-12)
    f_expect = -np.array([0.0, 0.0, g])
    f_expect[i] += a * G0
    # Coriolis, transport and the gravity change with height stay below 1.2 mg
    np.testing.assert_allclose(tr["f_b"][k5 + 1:], np.tile(f_expect, (41 - k5 - 1, 1)),
                               atol=1.2e-3 * G0)
    # measured streams: 4 Hz, synchronous, accelerometer only
    for kind in (StreamKind.IMU, StreamKind.MAG, StreamKind.GPS_VEL):
        np.testing.assert_array_equal(rec[kind].t_ns, tr.t_ns)
    assert sorted(rec["imu"].columns) == ["f_b"]


def test_free_fall_reads_almost_zero_specific_force():
    rec = simulate("gimpo-accel-sweep", {"axis": "D", "accel_g": 1.0}, seed=1)
    f = rec["truth"]["f_b"][-1]
    assert np.linalg.norm(f) < 1.5e-3 * G0  # gravity here is 9.7994, not 1 g; plus Coriolis


def test_sensor_error_levels_are_the_paper_table():
    p = GimpoAccelSweepParams()
    imu, mag = p.imu_model(), p.mag_model()
    assert sample_sigma(imu.accel_vrw, p.dt) == pytest.approx(113.1 * MICRO_G, rel=1e-3)
    assert sample_sigma(imu.accel_vrw, p.dt) == pytest.approx(1.109e-3, rel=1e-3)
    assert mag.noise == pytest.approx(14.14e-9, rel=1e-3)
    assert ACCEL_NOISE_SIGMA == pytest.approx(1.109e-3, rel=1e-3)
    assert MAG_NOISE_SIGMA == pytest.approx(14.14e-9, rel=1e-3)
    assert imu.accel_bias == pytest.approx(2e-3 * G0)
    assert imu.accel_bias_instability == pytest.approx(0.04e-3 * G0)
    assert imu.accel_bias_tau == 60.0
    assert imu.accel_scale_factor == mag.scale_factor == 1e-3
    assert mag.bias == pytest.approx(300e-9)
    assert p.gps_model().vel_sigma == (0.05, 0.05, 0.05)


def test_noise_statistics_of_a_stationary_recording():
    # rest segment of many runs: f_b, m_b and v_n spread as the table of §3.1 says
    p = GimpoAccelSweepParams(axis="N", accel_g=0.0)
    truth = get_scenario("gimpo-accel-sweep")().truth(p)
    d = simulate_runs(p, truth, range(400))
    dv = d.v_n - truth.v_n
    assert np.std(dv) == pytest.approx(0.05, rel=0.05)
    # white accelerometer noise: sample-to-sample differences remove the constant bias
    df = np.diff(d.f_b, axis=1)
    assert np.std(df) / math.sqrt(2) == pytest.approx(1.109e-3, rel=0.05)
    # constant part: bias (2 mg) and scale factor on g (0.1 % of 9.8 m/s^2 = 1 mg) on z
    mean_f = d.f_b.mean(axis=1) - truth.f_b[0]
    assert np.std(mean_f[:, :2]) == pytest.approx(2e-3 * G0, rel=0.1)
    assert np.std(mean_f[:, 2]) == pytest.approx(math.hypot(2e-3 * G0, 1e-3 * 9.7994), rel=0.1)


def test_earth_field_from_the_wmm_cross_checks_the_igrf_value():
    rec = simulate("gimpo-accel-sweep", {}, seed=0)
    md = rec.metadata
    h = np.asarray(md.extra["earth_field_n"])
    assert md.extra["earth_field_model"] == "WMM2015"
    assert md.extra["decimal_year"] == 2017.0
    np.testing.assert_allclose(h, IGRF_FIELD_N, atol=60e-9)  # WMM2015 vs IGRF, same epoch
    incl = math.degrees(math.atan2(h[2], math.hypot(h[0], h[1])))
    assert incl == pytest.approx(54.39, abs=0.2)
    # the magnetometer at rest reads that field (within bias and scale errors)
    np.testing.assert_allclose(rec["mag"]["m_b"].mean(axis=0), h, atol=2e-6)
    assert md.extra["site"]["lat_deg"] == 37.55
    assert set(md.true_errors) >= {"accel_bias", "accel_scale_factor", "mag_bias",
                                   "mag_scale_factor"}
    assert md.initial_nav["pos"] == [37.55 * DEG, 126.80 * DEG, 40.0]
    assert rec.t0_ns == 1_483_228_800_000_000_000  # 2017-01-01T00:00:00Z


def test_scenarios_are_deterministic_and_validated():
    a = simulate("gimpo-accel-yaw", {"case": "y"}, seed=5)
    b = simulate("gimpo-accel-yaw", {"case": "y"}, seed=5)
    c = simulate("gimpo-accel-yaw", {"case": "y"}, seed=6)
    for kind in a.kinds():
        for name in a[kind].columns:
            np.testing.assert_array_equal(a[kind][name], b[kind][name])
    assert dataclasses.asdict(a.metadata) == dataclasses.asdict(b.metadata)
    assert not np.array_equal(a["imu"]["f_b"], c["imu"]["f_b"])
    with pytest.raises(ParamError, match="axis"):
        simulate("gimpo-accel-sweep", {"axis": "up"})
    with pytest.raises(ParamError, match="accel_g"):
        simulate("gimpo-accel-sweep", {"accel_g": 50})
    with pytest.raises(ParamError, match="decimal year"):
        simulate("gimpo-accel-sweep", {"date": "2012-01-01"})
    assert simulate("gimpo-accel-sweep", {"axis": "e"}, seed=0).metadata.params["axis"] == "E"


def test_fast_simulation_equals_the_scenario_streams():
    p = GimpoAccelYawParams(case="x")
    truth = get_scenario("gimpo-accel-yaw")().truth(p)
    d = simulate_runs(p, truth, [11, 12])
    for i, seed in enumerate((11, 12)):
        rec = simulate("gimpo-accel-yaw", {"case": "x"}, seed=seed)
        np.testing.assert_array_equal(d.f_b[i], rec["imu"]["f_b"])
        np.testing.assert_array_equal(d.m_b[i], rec["mag"]["m_b"])
        np.testing.assert_array_equal(d.v_n[i], rec["gps_vel"]["v_n"])
        np.testing.assert_array_equal(d.vel_sigma[i], rec["gps_vel"]["vel_sigma"])


# --------------------------------------------------------------------------------------------
# filter models


def _nonlinear_residual(model, C_nb, q_ev, a_n, g_n=G_N, h_n=H_N):
    """Noise-free z at an estimate perturbed by q_ev: C_hat = C(q_e)^T C_nb (§2)."""
    q_e = np.r_[math.sqrt(1.0 - q_ev @ q_ev), q_ev]
    C_hat = quat_to_dcm(q_e).T @ C_nb
    f_b = C_nb.T @ (a_n - g_n)
    m_b = C_nb.T @ h_n
    return measurement(model, C_hat, f_b, m_b, a_n, g_n, h_n)


@pytest.mark.parametrize("a_n", [np.zeros(3), np.array([-7.0, 3.0, 1.5]),
                                 np.array([0.0, 0.0, 14.7])])
def test_jacobians_against_finite_differences(a_n):
    C_nb = euler_to_dcm([0.2, -0.3, 2.5])
    eps = 1e-6
    J = np.empty((6, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = eps
        zp, _ = _nonlinear_residual(MatchModel.SPECIFIC_FORCE, C_nb, d, a_n)
        zm, _ = _nonlinear_residual(MatchModel.SPECIFIC_FORCE, C_nb, -d, a_n)
        J[:, j] = (zp - zm) / (2 * eps)
    z0, H_sf = _nonlinear_residual(MatchModel.SPECIFIC_FORCE, C_nb, np.zeros(3), a_n)
    _, H_g = _nonlinear_residual(MatchModel.GRAVITY, C_nb, np.zeros(3), a_n)
    np.testing.assert_allclose(z0, 0.0, atol=1e-12)
    # the proposed model is the true first-order model, eq. (28)
    np.testing.assert_allclose(H_sf[:3], J[:3], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(H_sf[3:], J[3:], rtol=1e-6, atol=1e-14)
    # the conventional one drops +2[a x], eq. (21)
    np.testing.assert_allclose(H_g[:3] - J[:3], -2.0 * skew(a_n), atol=1e-6)
    np.testing.assert_allclose(H_g[3:], H_sf[3:])


def test_models_agree_at_zero_acceleration():
    rng = np.random.default_rng(2)
    C_hat = euler_to_dcm([0.01, -0.02, 0.5])
    f_b, m_b = rng.normal(size=3), rng.normal(size=3) * 1e-5
    zg, Hg = measurement(MatchModel.GRAVITY, C_hat, f_b, m_b, np.zeros(3), G_N, H_N)
    zs, Hs = measurement(MatchModel.SPECIFIC_FORCE, C_hat, f_b, m_b, np.zeros(3), G_N, H_N)
    np.testing.assert_array_equal(zg, zs)
    np.testing.assert_array_equal(Hg, Hs)
    np.testing.assert_array_equal(model_induced_error(zg, np.zeros(3), G_N, H_N), 0.0)


def test_free_fall_residual_vanishes_but_the_gravity_model_predicts_one():
    # D +1 g at the site's gravity: f = a - g = 0
    a_n = G_N.copy()
    q_ev = np.array([0.01, -0.02, 0.015])
    C_nb = np.eye(3)
    z, H_sf = _nonlinear_residual(MatchModel.SPECIFIC_FORCE, C_nb, q_ev, a_n)
    _, H_g = _nonlinear_residual(MatchModel.GRAVITY, C_nb, q_ev, a_n)
    # true model: z_g = -2[(g - a) x] q_ev = 0
    np.testing.assert_allclose(z[:3], 0.0, atol=1e-12)
    np.testing.assert_allclose(H_sf[:3], 0.0, atol=1e-15)
    np.testing.assert_allclose(H_sf[:3] @ q_ev, z[:3], atol=1e-12)
    # the conventional model expects -2[g x] q_ev, about 2 g |q_ev| = 0.4 m/s^2 here
    predicted = H_g[:3] @ q_ev
    np.testing.assert_allclose(predicted, -2.0 * np.cross(G_N, q_ev))
    assert np.linalg.norm(predicted - z[:3]) > 0.3
    # the diagnostic sees the model-induced error of eq. (25)
    assert np.linalg.norm(model_induced_error(z, a_n, G_N, H_N)) > 0.0


def test_least_squares_on_the_model_recovers_the_error_and_feedback_removes_it():
    # signs of z, H and the feedback (errata E3, E6, E9): q_true = [1, q_ev] (x) q_hat
    q_true = euler_to_quat([0.1, 0.2, -1.0])
    q_ev = np.array([0.4, -0.3, 0.6]) * 1e-4
    q_e = np.r_[math.sqrt(1 - q_ev @ q_ev), q_ev]
    q_hat = quat_mult(quat_conj(q_e), q_true)
    a_n = np.array([3.0, -2.0, 1.0])
    C_nb = quat_to_dcm(q_true)
    z, H = measurement(MatchModel.SPECIFIC_FORCE, quat_to_dcm(q_hat), C_nb.T @ (a_n - G_N),
                       C_nb.T @ H_N, a_n, G_N, H_N)
    w = np.r_[np.ones(3), np.full(3, 1e5)]  # balance m/s^2 against tesla
    dq = np.linalg.lstsq(H * w[:, None], z * w, rcond=None)[0]
    np.testing.assert_allclose(dq, q_ev, rtol=1e-3)
    q_fixed = feedback(q_hat, dq)
    assert np.linalg.norm(dcm_to_euler(quat_to_dcm(q_fixed)) - dcm_to_euler(C_nb)) < 1e-6


def test_process_model_is_the_exact_discretisation():
    phi, qd = process_noise(0.25, 10.0, 0.01)
    assert float(qd) == pytest.approx(2.4385e-3, rel=1e-4)
    Phi, Qd = kalman.van_loan(-np.eye(3) / 10.0, np.eye(3), np.full(3, 0.01), 0.25)
    np.testing.assert_allclose(Phi, float(phi) * np.eye(3), rtol=1e-12)
    np.testing.assert_allclose(Qd, float(qd) * np.eye(3), rtol=1e-9)


def test_measurement_noise_is_eqs_11_and_15():
    R = measurement_noise(np.full(3, 0.05), np.full(3, 0.05), 0.25, 1.109e-3, 14.14e-9)
    np.testing.assert_allclose(R[:3], 0.08 + 1.109e-3**2)
    np.testing.assert_allclose(R[3:], 14.14e-9**2)


def test_triad_and_its_failure_on_parallel_vectors():
    C = euler_to_dcm([0.05, -0.1, 2.8])
    q = triad(C.T @ -G_N, C.T @ H_N, G_N, H_N)
    np.testing.assert_allclose(quat_to_dcm(q), C, atol=1e-12)
    with pytest.raises(ValueError, match="parallel"):
        triad(np.array([0, 0, -1.0]), np.array([0, 0, 2e-5]), G_N, H_N)


def test_euler_sigma_maps_the_tilt_covariance():
    euler = np.array([0.3, -0.4, 1.2])
    C = euler_to_dcm(euler)
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3)) * 1e-3
    P = A @ A.T + 1e-8 * np.eye(3)
    # sample q_ev ~ N(0, P), perturb as C_hat = (I - 2[q_ev x]) C, look at the Euler errors
    q = rng.multivariate_normal(np.zeros(3), P, size=20000)
    q_e = np.c_[np.sqrt(1 - np.sum(q**2, axis=1)), q]
    C_hat = np.swapaxes(quat_to_dcm(q_e), -1, -2) @ C
    d = dcm_to_euler(C_hat) - euler
    np.testing.assert_allclose(np.std(d, axis=0), euler_sigma(euler, P), rtol=0.03)


def test_params_validation_and_model_spelling():
    assert VectorMatchingParams(model="specific_force").model is MatchModel.SPECIFIC_FORCE
    assert VectorMatchingParams().model is MatchModel.SPECIFIC_FORCE
    with pytest.raises(ValueError, match="tau"):
        VectorMatchingParams(tau=0.0)
    # the variants' values for what is left unset; explicit values win
    d, paper = VectorMatchingParams(), VectorMatchingParams(variant="paper")
    assert d.variant is Variant.CONSISTENT and math.isinf(d.tau)
    assert d.mag_bias_sigma == pytest.approx(300e-9)
    assert d.manoeuvre_threshold == pytest.approx(38.26, abs=0.01)  # chi-square(6), 1e-6
    assert d.turn_model == "constant-rate" and d.turn_threshold == pytest.approx(30.66, abs=0.01)
    assert math.isinf(VectorMatchingParams(manoeuvre_false_alarm=0.0).turn_threshold)
    with pytest.raises(ValueError):
        VectorMatchingParams(turn_model="spin")
    assert paper.tau == 10.0 and paper.mag_bias_sigma == 0.0 and paper.manoeuvre_threshold == 0
    assert VectorMatchingParams(variant="paper", tau=5.0).tau == 5.0
    with pytest.raises(ValueError, match="mag_bias_sigma is a consider state"):
        VectorMatchingParams(variant="paper", mag_bias_sigma=1e-7)
    with pytest.raises(ValueError, match="manoeuvre_false_alarm"):
        VectorMatchingParams(manoeuvre_false_alarm=2.0)
    phi, qd = process_noise(0.25, math.inf, 0.01)  # the random walk of the held attitude
    assert float(phi) == 1.0 and float(qd) == pytest.approx(0.0025)
    with pytest.raises(ValueError, match="earth_field_n"):
        VectorMatchingParams(earth_field_n=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError):
        VectorMatchingParams(model="magic")


# --------------------------------------------------------------------------------------------
# the filter through the replay engine, and the fast path


def test_registered_and_fails_fast_on_missing_inputs():
    cls = load_filter("vector-matching")
    assert cls is VectorMatchingFilter
    rec = simulate("gimpo-accel-sweep", {}, seed=0)
    no_imu = dataclasses.replace(rec, streams={k: v for k, v in rec.streams.items()
                                               if k is not StreamKind.IMU})
    with pytest.raises(MissingStreamError, match=r"'vector-matching' needs stream\(s\) imu"):
        replay(no_imu, cls)
    no_f = dataclasses.replace(rec, streams=dict(rec.streams))
    no_f.streams[StreamKind.IMU] = rec[StreamKind.IMU].slice(0, len(rec[StreamKind.IMU]))
    del no_f.streams[StreamKind.IMU].columns["f_b"]
    with pytest.raises(MissingStreamError, match="imu lacks column.*f_b"):
        replay(no_f, cls)
    no_mag = dataclasses.replace(rec, streams={k: v for k, v in rec.streams.items()
                                               if k is not StreamKind.MAG})
    with pytest.raises(MissingStreamError, match="mag"):
        replay(no_mag, cls)
    md = dataclasses.replace(rec.metadata, extra={})
    with pytest.raises(FilterInitError, match="earth_field_n"):
        replay(dataclasses.replace(rec, metadata=md), cls)
    # the parameter overrides the metadata
    res = replay(dataclasses.replace(rec, metadata=md), cls,
                 {"earth_field_n": ",".join(str(v) for v in rec.metadata.extra["earth_field_n"])})
    assert res.t[-1] == 10.0


def test_reference_filter_outputs():
    rec = simulate("gimpo-accel-sweep", {"axis": "E", "accel_g": 0.5}, seed=4)
    res = replay(rec, VectorMatchingFilter, {"model": "gravity"}, output_rate=None)
    k = last_per_epoch(res.t)
    np.testing.assert_allclose(res.t[k], np.arange(41) * 0.25)
    assert set(res.extras) == {"q_nb", "euler", "euler_sigma", "model_induced_phi"}
    np.testing.assert_array_equal(res.x, 0.0)  # feedback resets the error state
    assert res.innovations["vector"].nu.shape == (40, 6)
    sig = np.degrees(res.extras["euler_sigma"][k[-1]])
    assert 0.1 < sig[0] < 5.0 and 0.1 < sig[2] < 5.0
    err = np.degrees(euler_errors(res.extras["q_nb"][k[-1]], rec["truth"]["q_nb"][-1]))
    assert np.all(np.abs(err) < 10.0)
    res_sf = replay(rec, VectorMatchingFilter, {"model": "specific-force"}, output_rate=None)
    assert "model_induced_phi" not in res_sf.extras


def test_epoch_completes_in_any_arrival_order():
    from navreplay.filters.base import FilterContext

    rec = simulate("gimpo-accel-sweep", {"axis": "N", "accel_g": 0.7}, seed=2)
    ctx = FilterContext(rec.metadata, rec.t0_ns, frozenset(rec.kinds()))
    t = (rec["imu"].t_ns - rec.t0_ns) * 1e-9
    imu, mag, gps = rec["imu"], rec["mag"], rec["gps_vel"]
    outs = []
    for order in ("imu-gps-mag", "mag-gps-imu", "gps-imu-mag"):
        f = VectorMatchingFilter(VectorMatchingParams(), ctx)
        n_inn = 0
        for k in range(len(t)):
            for step in order.split("-"):
                if step == "imu":
                    f.propagate(t[k:k + 1], {"f_b": imu["f_b"][k:k + 1]})
                    continue
                kind, s_ = (StreamKind.MAG, mag) if step == "mag" else (StreamKind.GPS_VEL, gps)
                inn = f.update(kind, float(t[k]), {c: v[k] for c, v in s_.columns.items()})
                n_inn += len(inn or [])
        est = f.estimate()
        assert est.t == 10.0
        outs.append((est.extras["q_nb"], n_inn))
    for q, n in outs:
        np.testing.assert_array_equal(q, outs[0][0])
        assert n >= 39  # the last epoch's innovation may still be pending


@pytest.mark.parametrize(
    ("scenario", "values", "model"),
    [
        ("gimpo-accel-sweep", {"axis": "D", "accel_g": 1.5}, "gravity"),
        ("gimpo-accel-sweep", {"axis": "N", "accel_g": -0.8}, "specific-force"),
        ("gimpo-accel-yaw", {"case": "y"}, "gravity"),
        ("gimpo-accel-yaw", {"case": "x"}, "specific-force"),
    ],
)
def test_fast_path_reproduces_the_reference_path(scenario, values, model):
    seeds = [3, 4, 5]
    sc = get_scenario(scenario)()
    p = sc.Params(**values)
    truth = sc.truth(p)
    data = simulate_runs(p, truth, seeds)
    fp = VectorMatchingParams(variant="paper", model=model)
    rec0 = simulate(scenario, values, seed=seeds[0])
    ref = reference(fp, rec0.metadata.extra, rec0.metadata.initial_nav)
    fast = run_batch(fp, ref, truth.t, data.f_b, data.m_b, data.v_n, data.vel_sigma,
                     diagnostic=True)
    for i, seed in enumerate(seeds):
        rec = simulate(scenario, values, seed=seed)
        res = replay(rec, VectorMatchingFilter, {"variant": "paper", "model": model})
        k = last_per_epoch(res.t)
        np.testing.assert_allclose(res.t[k], truth.t)
        np.testing.assert_allclose(fast.q_nb[i], res.extras["q_nb"][k], rtol=0, atol=1e-10)
        np.testing.assert_allclose(4.0 * fast.P[i], res.P[k], rtol=1e-8, atol=1e-20)  # phi = 2 q_ev
        np.testing.assert_allclose(fast.euler_sigma()[i], res.extras["euler_sigma"][k],
                                   rtol=1e-8)
        if model == "gravity":
            # a pseudo-inverse mixing m/s^2 and tesla rows: ill-conditioned, looser match
            np.testing.assert_allclose(fast.model_induced_phi[i, 1:],
                                       res.extras["model_induced_phi"][k][1:], rtol=1e-3,
                                       atol=1e-9)


def test_fast_path_accepts_only_consistent_shapes():
    t = np.arange(3) * 0.25
    x = np.zeros((2, 3, 3))
    with pytest.raises(ValueError, match="m_b"):
        run_batch(VectorMatchingParams(variant="paper"), Reference(G_N, H_N), t, x, x[:1], x, x)
    with pytest.raises(ValueError, match="variant=paper"):
        run_batch(VectorMatchingParams(), Reference(G_N, H_N), t, x, x, x, x)


# --------------------------------------------------------------------------------------------
# reproduction


def test_d_axis_breakdown_of_the_gravity_model_only():
    """Fast version of the D-sweep bands: 20 runs per point instead of 100."""
    res = run_sweep_axis("D", runs=20, seed=0)
    rms = res.rms / DEG  # (31, model, angle)
    worst_g = rms[:, 0].max(axis=1)
    i = {a: ACCEL_G.index(a) for a in (0.0, 1.0, 1.2, 1.5)}
    assert worst_g[i[1.2]] >= 10.0
    assert worst_g[i[1.5]] >= 20.0
    assert worst_g[i[1.5]] >= 5.0 * worst_g[i[1.0]]
    # below +1 g the conventional model is fine; the proposed one everywhere
    assert worst_g[: i[1.0]].max() < 15.0
    assert rms[:, 1].max() <= 5.0
    assert rms[i[0.0], 1].max() <= 3.0


def test_quick_reproduction_report_and_rerun_view(tmp_path):
    from rerun.chunk import RrdReader

    rep = get_reproduction("vector-matching")
    assert rep is REPRODUCTION
    out = tmp_path / "vm.rrd"
    report = rep.run(runs=2, seed=1, rrd=out)
    text = report.format()
    assert "N -0.8 g" in text and "yaw" in text and "gravity: reference" in text
    assert "Acceptance bands (docs/methods/vector-matching.md §6):" in text
    assert "Paper claims (checked by the bands below):" in text
    assert "(Choe & Park 2017): 2 runs per sweep point" in text.splitlines()[0]
    for word in ("spec ", "spec'", "prototype", "(seed 00", "the seed"):  # no outside documents
        assert word not in text
    assert len(report.checks) == 25
    fig = report.figures
    assert np.asarray(fig["sweep"]["rms_deg"]["D"]).shape == (31, 2, 3)
    assert np.asarray(fig["yaw"]["rms_deg"]["x"]).shape == (2, 121, 3)
    paths = set()
    for chunk in RrdReader(str(out)).stream().collect().stream().to_chunks():
        paths.add(chunk.entity_path)
    sweep_paths = [p for p in paths if p.startswith("/ensemble/fig3")]
    assert any("gravity" in p for p in sweep_paths)
    assert any("specific-force" in p for p in sweep_paths)
    assert any(p.startswith("/ensemble/fig5") for p in paths)


@pytest.mark.slow
@pytest.mark.parametrize("seed", SLOW_SEEDS)
def test_full_campaign_meets_every_acceptance_band(seed):
    report = REPRODUCTION.run(seed=seed, workers=2)
    assert report.figures["timing"]["filter_runs"] == 22600
    names = [c.name for c in report.checks]
    assert len(names) == 25
    for key in ("a = 0", "D sweep, gravity", "D sweep, specific-force", "N sweep, gravity",
                "N sweep, specific-force", "E sweep", "|a| <= 0.5 g", "yaw case x",
                "yaw case y"):
        assert any(n.startswith(key) for n in names), key
    failed = [f"{c.name}: {c.value:.4g} (band {c.band})" for c in report.checks if not c.passed]
    assert not failed, "\n".join(failed)


# --------------------------------------------------------------------------------------------
# consistency: the default (consistent) variant, and the same checks on the paper's

CONSISTENCY_SEEDS = range(3100, 3124)
CONSISTENCY_CASES = {
    "at rest": ("gimpo-accel-sweep", {"accel_g": 0.0}),
    "N -0.8 g": ("gimpo-accel-sweep", {"axis": "N", "accel_g": -0.8}),
    "D +1.2 g": ("gimpo-accel-sweep", {"axis": "D", "accel_g": 1.2}),
    "yaw x": ("gimpo-accel-yaw", {"case": "x"}),
    "yaw y": ("gimpo-accel-yaw", {"case": "y"}),
}
ROWS = ("g_N", "g_E", "g_D", "h_N", "h_E", "h_D")


def _consistency_ensemble(scenario, values, params, seeds=CONSISTENCY_SEEDS):
    """Per run and epoch: the NIS of each of the six rows (``nu_i^2 / S_ii``), of the two
    attitude-free components of the innovation (along the matched vector u_n of the
    accelerometer block, along h_n of the magnetometer block: H has no attitude column there)
    and of the whole innovation; the Euler errors and their predicted sigma."""
    out = {"rows": [], "acc_u": [], "mag_h": [], "nis": [], "err": [], "sigma": []}
    model = VectorMatchingParams(**params).model
    for seed in seeds:
        rec = simulate(scenario, values, seed=seed)
        res = replay(rec, VectorMatchingFilter, params)
        inn = res.innovations["vector"]
        v_n = rec["gps_vel"].columns["v_n"]
        u = G_N - np.diff(v_n, axis=0) / 0.25  # eq. (13); the H_g direction of either model
        for key, rows, e in (("acc_u", slice(0, 3), u if model == "specific-force" else G_N),
                             ("mag_h", slice(3, 6), H_N)):
            e = np.broadcast_to(e / np.linalg.norm(e, axis=-1, keepdims=True), (len(inn.t), 3))
            nu, S = inn.nu[:, rows], inn.S[:, rows, rows]
            out[key].append(np.einsum("ki,ki->k", nu, e) ** 2
                            / np.einsum("ki,kij,kj->k", e, S, e))
        out["rows"].append(inn.nu**2 / np.diagonal(inn.S, axis1=1, axis2=2))
        out["nis"].append(inn.nis)
        t_truth = (rec["truth"].t_ns - rec.t0_ns) * 1e-9
        q = rec["truth"].columns["q_nb"]
        q_true = np.stack([np.interp(res.t, t_truth, q[:, i]) for i in range(4)], axis=-1)
        q_true /= np.linalg.norm(q_true, axis=-1, keepdims=True)
        out["err"].append(euler_errors(res.extras["q_nb"], q_true))
        out["sigma"].append(res.extras["euler_sigma"])
    out = {k: np.asarray(v) for k, v in out.items()}
    out["t"] = inn.t
    return out


def _turning(t):
    """Epochs of the yaw scenario whose last step turned (10 < t <= 15 s, 20 < t <= 25 s)."""
    t = np.round(t, 6)
    return ((t > 10.0) & (t <= 15.0)) | ((t > 20.0) & (t <= 25.0))


def _failures(m, epochs=slice(None)):
    """The checks: the NIS of every row, of the two attitude-free components and of the whole
    innovation in its chi-square band (run means over ``epochs``, one sample per run: the
    sensor constants are drawn once per run; false alarm 0.001, docs/methods/consistency.md),
    and roll, pitch and yaw RMS within 20 % of the predicted sigma. Returns what fails."""
    runs = len(m["nis"])
    means = {name: m["rows"][:, epochs, i].mean(axis=1) for i, name in enumerate(ROWS)}
    means.update(acc_u=m["acc_u"][:, epochs].mean(axis=1),
                 mag_h=m["mag_h"][:, epochs].mean(axis=1))
    bad = [f"{k} NIS {v.mean():.3g}" for k, v in means.items()
           if not consistency.inside(float(v.mean()), 1, runs)]
    nis = float(m["nis"][:, epochs].mean())
    if not consistency.inside(nis, 6, runs):
        bad.append(f"NIS {nis:.3g}")
    ratio = np.sqrt(np.mean(m["err"] ** 2, axis=(0, 1)) / np.mean(m["sigma"] ** 2, axis=(0, 1)))
    bad += [f"{a} RMS/sigma {r:.2f}" for a, r in zip(("roll", "pitch", "yaw"), ratio, strict=True)
            if not 0.8 < r < 1.2]
    return bad


@pytest.mark.parametrize("case", CONSISTENCY_CASES)
def test_default_filter_is_consistent_and_the_papers_is_not(case):
    """The default variant: every row's NIS, the attitude-free components and the full NIS in
    their bands and the attitude RMS within 20 % of sigma, at rest, under acceleration and in
    the yaw turns. The paper's model fails the same checks: its R ignores the 300 nT
    magnetometer bias (NIS of hundreds) and its process noise at every epoch widens the
    prediction of the rows that depend on the attitude (their NIS near 0)."""
    scenario, values = CONSISTENCY_CASES[case]
    m = _consistency_ensemble(scenario, values, {})
    assert not _failures(m)
    if scenario == "gimpo-accel-yaw":
        assert not _failures(m, _turning(m["t"]))
    paper = _failures(_consistency_ensemble(scenario, values, {"variant": "paper"}))
    assert any(f.startswith("NIS") for f in paper), paper
    assert any(f.startswith(("h_N", "h_E", "h_D")) for f in paper), paper


def test_paper_model_trusts_the_magnetometer_twenty_times_too_much():
    """Known inconsistency of the published model, kept for the reproduction: R_h is the
    14 nT white noise while the magnetometer carries a 300 nT bias. The field component along
    h_n, which no attitude explains, has a NIS of hundreds (1 expected), and the pitch sigma,
    which only the magnetometer sets, is optimistic."""
    m = _consistency_ensemble("gimpo-accel-sweep", {"accel_g": 0.0}, {"variant": "paper"})
    assert np.mean(m["mag_h"]) > 100.0
    pitch = np.sqrt(np.mean(m["err"][..., 1] ** 2) / np.mean(m["sigma"][..., 1] ** 2))
    assert pitch > 1.3, pitch


def test_manoeuvre_test_adds_the_process_noise_only_where_the_rate_changes():
    """At rest the attitude is held (no process noise: the sigma shrinks epoch by epoch). When
    the yaw rate steps (10, 15, 20, 25 s) the epoch's NIS without process noise rejects the
    prediction and the epoch gets the manoeuvre noise: the predicted field residual widens from
    about 300 nT (the bias) to 4000 nT. Inside a turn the last step's rotation predicts the next
    (turn model constant-rate) and no process noise is needed; with the attitude held
    (turn model held) every turn epoch needs it."""
    rec = simulate("gimpo-accel-yaw", {"case": "x"}, seed=5)
    res = replay(rec, VectorMatchingFilter, {})
    k = last_per_epoch(res.t)
    t, yaw_sigma = res.t[k], res.extras["euler_sigma"][k, 2]
    rest = (t > 1.0) & (t <= 10.0)
    assert np.all(np.diff(yaw_sigma[rest]) <= 0.0)
    steps = np.isin(np.round(t, 6), (10.25, 15.25, 20.25, 25.25))
    for params, wide in (({}, steps), ({"turn_model": "held"}, _turning(t))):
        inn = replay(rec, VectorMatchingFilter, params).innovations["vector"]
        assert np.array_equal(np.round(inn.t, 6), np.round(t[1:], 6))
        s_h = np.sqrt(inn.S[:, 3, 3])  # [T]
        assert np.all(s_h[~wide[1:]] < 500e-9), params
        assert np.all(s_h[wide[1:]] > 2000e-9), params


def test_held_attitude_is_pessimistic_in_the_turns():
    """The checks of the default filter on the turn epochs of the yaw cases fail with the
    attitude held between epochs (turn model held): its manoeuvre noise (5.7 deg per axis and
    step for a 4.5 deg yaw step) leaves the rows' NIS far below 1 there."""
    m = _consistency_ensemble("gimpo-accel-yaw", {"case": "x"}, {"turn_model": "held"})
    bad = _failures(m, _turning(m["t"]))
    assert sum(f.startswith(ROWS) for f in bad) >= 4, bad
    assert np.all(m["rows"][:, _turning(m["t"])].mean(axis=(0, 1)) < 0.5)


@pytest.mark.slow
@pytest.mark.parametrize("case", CONSISTENCY_CASES)
def test_default_filter_consistency_over_the_seed_list(case):
    """The default variant, 60 runs from each seed of the list (180 in all, one sample per
    run), on the checks of the default-suite test: over the whole runs and, in the yaw cases,
    over the turn epochs alone (a third of the epochs)."""
    scenario, values = CONSISTENCY_CASES[case]
    m = [_consistency_ensemble(scenario, values, {}, seeds=range(seed, seed + 60))
         for seed in SLOW_SEEDS]
    t = m[0]["t"]
    m = {k: np.concatenate([x[k] for x in m]) for k in m[0] if k != "t"}
    assert not _failures(m)
    if scenario == "gimpo-accel-yaw":
        assert not _failures(m, _turning(t))
