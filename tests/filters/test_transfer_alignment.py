"""Transfer alignment (docs/methods/transfer-alignment.md): scenario, filter model, reproduction.

Section numbers (§) and errata (E1-E17) are those of docs/methods/transfer-alignment.md.
"""

import dataclasses
import math

import numpy as np
import pytest
from campaign_seeds import SLOW_SEEDS

from navreplay.core.lti import second_order_markov
from navreplay.core.streams import StreamKind
from navreplay.core.units import ARCMIN, DEG, FOOT
from navreplay.filters import kalman
from navreplay.filters import transfer_alignment as ta
from navreplay.filters import transfer_alignment_model as tam
from navreplay.filters.registry import load_filter
from navreplay.geo import earth, kernels, strapdown
from navreplay.geo.rotations import (
    attitude_error,
    euler_to_quat,
    quat_conj,
    quat_left_matrix,
    quat_mult,
    quat_to_dcm,
    quat_to_euler,
)
from navreplay.metrics import consistency, position_error_ned, truth_at
from navreplay.replay import FilterInitError, replay
from navreplay.reproduce import get as get_reproduction
from navreplay.reproduce import transfer_alignment as rep
from navreplay.sim.scenario import simulate
from navreplay.sim.scenarios import ship_transfer_alignment as sc

SCENARIO = "ship-transfer-alignment"
FILTER = load_filter("transfer-alignment")

NO_ERRORS = {
    "lever_arm_sigma": 0.0, "gins_tilt": "0,0,0", "gins_synchro_bias": 0.0,
    "gins_synchro_noise": 0.0, "gins_vel_bias": 0.0, "gins_vel_noise": 0.0,
    "gyro_bias": 0.0, "gyro_scale_factor": 0.0, "gyro_misalignment": 0.0,
    "gyro_g_sensitivity": 0.0, "gyro_arw": 0.0, "accel_bias": 0.0, "accel_scale_factor": 0.0,
    "accel_misalignment": 0.0, "accel_vrw": 0.0,
}  # fmt: skip


def unit(rng, n=4):
    q = rng.standard_normal(n)
    q /= np.linalg.norm(q)
    return q * np.sign(q[0])


def phi_of(result, recording):
    return rep.alignment_errors(result, recording).phi


# --------------------------------------------------------------------------------------------
# the paper's algebra against navreplay.geo


def test_quaternion_matrices_are_the_hamilton_products():
    rng = np.random.default_rng(0)
    for _ in range(5):
        p, q, w = unit(rng), unit(rng), rng.standard_normal(3)
        w0 = np.concatenate([[0.0], w])
        np.testing.assert_allclose(kernels.quat_left_matrix(p), quat_left_matrix(p), atol=0)
        np.testing.assert_allclose(tam.rmat(q) @ w, quat_mult(w0, q), atol=1e-15)  # R(q)
        np.testing.assert_allclose(tam.tmat(q) @ w, quat_mult(q, w0), atol=1e-15)  # T(q)
        np.testing.assert_allclose(kernels.quat_to_dcm(q), quat_to_dcm(q), atol=1e-15)
        e = rng.uniform(-1.0, 1.0, 3)
        qe = kernels.euler_to_quat(e)
        np.testing.assert_allclose(qe * np.sign(qe[0]), euler_to_quat(e), atol=1e-15)
        np.testing.assert_allclose(kernels.quat_to_euler(qe), quat_to_euler(qe), atol=1e-13)


def test_rate_matrix_is_right_w_ib_minus_left_w_in():
    rng = np.random.default_rng(1)
    w_ib, w_in, q = rng.standard_normal(3), rng.standard_normal(3), unit(rng)
    # q' = 1/2 q (x) w_ib - 1/2 w_in (x) q, eq. (2)
    q_dot = 0.5 * quat_mult(q, np.r_[0.0, w_ib]) - 0.5 * quat_mult(np.r_[0.0, w_in], q)
    np.testing.assert_allclose(0.5 * tam.rate_matrix(w_ib, w_in) @ q, q_dot, atol=1e-15)


def test_eq11_recovers_component_2_of_qm_conj_times_qbn():
    rng = np.random.default_rng(2)
    for _ in range(10):
        m, q = unit(rng), unit(rng)
        eq11 = -m[2] * q[0] - m[3] * q[1] + m[0] * q[2] + m[1] * q[3]  # (11), erratum E8
        assert eq11 == pytest.approx(quat_mult(quat_conj(m), q)[2], abs=1e-15)
        assert eq11 == pytest.approx((kernels.quat_left_matrix(quat_conj(m)) @ q)[2], abs=1e-15)


def test_h_rows_are_rows_0_1_3_of_left_qm_conj_and_exact():
    rng = np.random.default_rng(3)
    m = unit(rng)
    m0, m1, m2, m3 = m
    Lc = kernels.quat_left_matrix(quat_conj(m))
    printed = np.array([[m0, m1, m2, m3], [-m1, m0, m3, -m2], [-m3, m2, -m1, m0]])  # (15)
    np.testing.assert_allclose(Lc[[0, 1, 3]], printed, atol=0)
    np.testing.assert_allclose(Lc[2], [-m2, -m3, m0, m1], atol=0)  # the omitted row
    # Z_Q is linear: Z_Q(Q_bn + d, Q_br + e) - Z_Q(Q_bn, Q_br) = L(Q_m*) d - e, eq. (5)
    q_bn, q_br = unit(rng), unit(rng)
    d, e = 1e-3 * rng.standard_normal(4), 1e-3 * rng.standard_normal(4)

    def z(qbn, qbr):
        return quat_mult(quat_conj(m), qbn) - qbr

    np.testing.assert_allclose(z(q_bn + d, q_br + e) - z(q_bn, q_br), Lc @ d - e, atol=1e-15)


# --------------------------------------------------------------------------------------------
# A of eq. (14) against finite differences of the nonlinear SDINS equations

LAT, H = 35.0 * DEG, 20.0


def _model_point(seed=4):
    rng = np.random.default_rng(seed)
    q = unit(rng)
    v = np.array([4.4, 2.6, 0.3]) + rng.standard_normal(3)
    w_ib = 0.1 * rng.standard_normal(3)
    f_b = np.array([0.3, -0.2, -9.8]) + 0.5 * rng.standard_normal(3)
    R, w_in = tam.earth_terms(LAT, H, v)
    A, G = tam.system_matrix(q, v, LAT, R, w_ib, w_in, f_b, 9)
    return q, v, w_ib, f_b, R, A, G


def _w_en(v, R):
    """Transport rate with the single radius R of eq. (14)."""
    return np.array([v[1] / R, -v[0] / R, -v[1] * math.tan(LAT) / R])


def _v_dot(q, v, f_b, R):
    """Nonlinear velocity equation v' = C(q) f - (2 w_ie + w_en) x v + g (normalised q)."""
    q = q / np.linalg.norm(q)
    w_ie = earth.omega_ie_n(LAT)
    return quat_to_dcm(q) @ f_b - np.cross(2.0 * w_ie + _w_en(v, R), v) + earth.gravity_n(LAT, H)


def _q_dot(q, w_in, w_ib):
    """Nonlinear quaternion equation q' = 1/2 q (x) w_ib - 1/2 w_in (x) q."""
    return 0.5 * quat_mult(q, np.r_[0.0, w_ib]) - 0.5 * quat_mult(np.r_[0.0, w_in], q)


def _jacobian(fun, x, eps):
    cols = []
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = eps
        cols.append((fun(x + dx) - fun(x - dx)) / (2.0 * eps))
    return np.stack(cols, axis=-1)


def test_m_vv_matches_finite_differences():
    q, v, _, f_b, R, A, _ = _model_point()

    def f(vne):
        return _v_dot(q, np.r_[vne, v[2]], f_b, R)[:2]

    # v' is quadratic in v: central differences are exact up to rounding for any step
    np.testing.assert_allclose(A[0:2, 0:2], _jacobian(f, v[:2], 1.0), rtol=1e-6, atol=1e-15)


def test_a_vq_matches_finite_differences():
    q, v, _, f_b, R, A, _ = _model_point()
    J = _jacobian(lambda qq: _v_dot(qq, v, f_b, R)[:2], q, 1e-6)
    np.testing.assert_allclose(A[0:2, 2:6], J, rtol=1e-6, atol=1e-8)
    # C_nb f^b is rotated: the norm direction of q is not an error direction
    np.testing.assert_allclose(A[0:2, 2:6] @ q, 0.0, atol=1e-12)


def test_a_qv_and_a_qq_match_finite_differences():
    q, v, w_ib, _, R, A, _ = _model_point()

    def f_v(vne):  # the velocity enters through the transport rate (single radius R)
        return _q_dot(q, earth.omega_ie_n(LAT) + _w_en(np.r_[vne, v[2]], R), w_ib)

    np.testing.assert_allclose(A[2:6, 0:2], _jacobian(f_v, v[:2], 1.0), rtol=1e-7,
                               atol=1e-18)
    _, w_in = tam.earth_terms(LAT, H, v)
    J = _jacobian(lambda qq: _q_dot(qq, w_in, w_ib), q, 1.0)  # q' is linear in q
    np.testing.assert_allclose(A[2:6, 2:6], J, rtol=1e-12, atol=1e-16)
    assert not A[:, 6:].any() and not A[6:].any()  # dQ_br: random constant, eq. (9)


def test_noise_input_g():
    q, v, _, f_b, R, A, G = _model_point()
    np.testing.assert_allclose(G[0:2, 0:3], quat_to_dcm(q)[0:2], atol=1e-15)
    np.testing.assert_allclose(G[2:6, 3:6], 0.5 * tam.tmat(q), atol=0)
    assert not G[0:2, 3:].any() and not G[2:6, :3].any() and not G[6:].any()


def test_phi_is_minus_two_r_transpose_dq():
    rng = np.random.default_rng(5)
    q = unit(rng)
    dq = 1e-6 * rng.standard_normal(4)
    q_hat = (q + dq) / np.linalg.norm(q + dq)
    phi = attitude_error(quat_to_dcm(q_hat), quat_to_dcm(q))
    np.testing.assert_allclose(phi, -2.0 * tam.rmat(q).T @ dq, rtol=1e-5, atol=1e-16)


def test_lever_velocity_is_c_nb_omega_nb_cross_lever_b():
    rng = np.random.default_rng(6)
    q_bn, q_m = unit(rng), unit(rng)
    w_ib, w_in, L_r = rng.standard_normal(3), rng.standard_normal(3), 50 * rng.standard_normal(3)
    C_nb = quat_to_dcm(q_bn)
    w_nb_b = w_ib - C_nb.T @ w_in
    L_b = C_nb.T @ quat_to_dcm(q_m) @ L_r
    np.testing.assert_allclose(tam.lever_velocity(q_bn, q_m, w_ib, w_in, L_r),
                               C_nb @ np.cross(w_nb_b, L_b), rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------------------------
# Kalman pieces


def test_prediction_and_measurement_match_the_shared_kalman_math():
    rng = np.random.default_rng(7)
    q_m = unit(rng)
    s, n = np.array([0, 1, 3]), 9
    P0 = ta.initial_covariance(q_m, s, 0.0625, 2.25e-6, 6.9e-4)
    q_bn = quat_mult(q_m, [0.9996, 0.02, 0.01, -0.015])
    nav = np.r_[LAT, 2.2, H, 4.4, 2.6, 0.3, q_bn / np.linalg.norm(q_bn)]
    q_rb = np.array([0.9998, 0.01, 0.012, -0.008])
    sums = np.r_[0.01, -0.02, 0.03, 0.2, -0.1, -9.8] * 10
    w_last, w_prev = np.array([0.01, -0.02, 0.03]), np.array([0.012, -0.021, 0.028])
    lever, dt = np.array([45.7, 15.2, 12.2]), 0.1
    qc = np.r_[[5e-4**2] * 3, [3e-5**2] * 3]
    v_r = np.array([4.3, 2.5, 0.0])
    P, z, H_, R2, q_m2, w_now, w_in = tam.predict_and_measure(
        nav, q_rb, P0, s, -q_m, v_r, sums, 10, w_last, w_prev, lever, dt, qc, 1e-12,
        0, 0.0, np.eye(2), np.zeros((2, 2)), np.zeros(3), 0.0)
    assert not R2.any()  # no flexure states, no Euler noise: the paper's R (the caller's)
    np.testing.assert_allclose(q_m2, q_m, atol=0)  # the sign of §2.2
    R, w_in_ref = tam.earth_terms(LAT, H, nav[3:6])
    A, G = tam.system_matrix(nav[6:], nav[3:6], LAT, R, sums[:3] / 10, w_in_ref, sums[3:] / 10, n)
    Qd = kalman.discrete_noise(G, qc, dt)
    Qd[np.arange(6, n), np.arange(6, n)] += 1e-12 * dt
    _, P_ref = kalman.predict(np.zeros(n), P0, kalman.discretize(A, dt), Qd)
    np.testing.assert_allclose(P, P_ref, rtol=1e-10, atol=1e-22)
    np.testing.assert_allclose(w_now, 1.5 * w_last - 0.5 * w_prev)
    Lc = quat_left_matrix(quat_conj(q_m))
    np.testing.assert_allclose(H_[2:, 2:6], Lc[s], atol=0)
    np.testing.assert_allclose(H_[2:, 6:], -np.eye(3), atol=0)
    np.testing.assert_allclose(z[2:], (Lc @ nav[6:])[s] - q_rb[s], atol=1e-16)
    lever_v = tam.lever_velocity(nav[6:], q_m, w_now, w_in, lever)
    np.testing.assert_allclose(z[:2], (nav[3:6] - v_r - lever_v)[:2], atol=1e-14)
    # the velocity rows' attitude columns: the lever-arm term turns with an attitude error
    # (finite differences of z along rotations of the SDINS attitude, phi = -2 R^T dQ)
    rq = tam.rmat(nav[6:])
    for k in range(3):
        phi = np.zeros(3)
        phi[k] = 1e-6
        dq = -0.5 * rq @ phi  # the dQ_bn of a small phi (R^T R = I)
        up = tam.lever_velocity(nav[6:] + dq, q_m, w_now, w_in, lever)
        down = tam.lever_velocity(nav[6:] - dq, q_m, w_now, w_in, lever)
        np.testing.assert_allclose(H_[:2, 2:6] @ dq, -(up - down)[:2] / 2, rtol=1e-6,
                                   atol=1e-14)


def test_quaternion_noise_is_the_euler_noise_through_the_measurement():
    # cov of z = Q_m(euler + n)* (x) Q_bn against the Jacobian of the exact measurement in the
    # Euler angles (central differences), and a seeded sample of the noise itself
    rng = np.random.default_rng(12)
    euler = np.array([0.09, -0.07, 0.5])
    q_br = euler_to_quat([0.02, -0.03, 0.045])  # a 3 deg class mounting misalignment
    q_bn = quat_mult(euler_to_quat(euler), q_br)
    sigma = ARCMIN

    def z(e):
        return quat_mult(quat_conj(euler_to_quat(e)), q_bn)

    J = np.column_stack([(z(euler + d) - z(euler - d)) / 2e-6 for d in 1e-6 * np.eye(3)])
    R = tam.quaternion_noise(z(euler), euler, sigma)
    np.testing.assert_allclose(R, sigma**2 * J @ J.T, rtol=1e-6, atol=1e-22)
    draws = np.array([z(euler + n) for n in sigma * rng.standard_normal((20000, 3))])
    np.testing.assert_allclose(np.cov(draws.T), R, rtol=0.05, atol=0.03 * R[1, 1])
    # the vector rows move by about half the rotation, the scalar row by the misalignment
    # times it: (0.5 arcmin)^2 against ~40 times less in sigma
    np.testing.assert_allclose(np.diag(R)[1:], (0.5 * sigma) ** 2, rtol=0.02)
    half = np.linalg.norm(q_br[1:])
    assert R[0, 0] == pytest.approx((0.5 * sigma * half) ** 2, rel=0.3)
    assert np.linalg.matrix_rank(R, tol=1e-6 * R[1, 1]) == 3  # z has unit norm


def test_initial_covariance_holds_the_noise_of_the_starting_attitude():
    # the SDINS starts from the measured Q_m: dQ_bn = L(Q_m) dQ_br + T(Q_m) n, where n is the
    # GINS attitude noise per quaternion component (half the rotation), shared with nothing
    rng = np.random.default_rng(5)
    q_m = unit(rng)
    s = np.array([0, 1, 3])
    var = (0.5 * ARCMIN) ** 2
    P0 = ta.initial_covariance(q_m, s, 0.0625, 2.25e-6, 6.9e-4, None, var)
    paper = ta.initial_covariance(q_m, s, 0.0625, 2.25e-6, 6.9e-4)
    A = np.zeros((4, 9))  # dQ_bn - L(Q_m)[:, s] dQ_br[s]: eq. (17) leaves only the unmatched
    A[:, 2:6] = np.eye(4)  # q_br2's share in it, the start adds the noise
    A[:, 6:] = -quat_left_matrix(q_m)[:, s]
    Lu = quat_left_matrix(q_m)[:, 2]
    Tm = tam.tmat(q_m)
    np.testing.assert_allclose(A @ paper @ A.T, 6.9e-4 * np.outer(Lu, Lu), atol=1e-18)
    np.testing.assert_allclose(A @ (P0 - paper) @ A.T, var * Tm @ Tm.T, atol=1e-20)
    assert not (P0 - paper)[6:].any() and not (P0 - paper)[:2].any()
    # the physics: a start from Q_m (x) [1, n] with n ~ N(0, var I3) against the true Q_m
    n = rng.standard_normal((20_000, 3)) * math.sqrt(var)
    q_meas = quat_mult(q_m, np.column_stack([np.sqrt(1.0 - np.sum(n**2, axis=1)), n]))
    cov = np.cov((q_meas - q_m).T)
    np.testing.assert_allclose(cov, var * Tm @ Tm.T, atol=0.05 * var)
    # the attitude sigma at the start: 2 x 0.5 arcmin per axis on top of the paper's
    extra = tam.attitude_sigma(q_m, P0) ** 2 - tam.attitude_sigma(q_m, paper) ** 2
    np.testing.assert_allclose(extra, [ARCMIN**2] * 3, rtol=1e-9)


@pytest.mark.parametrize("s", [[1, 3], [1, 2, 3], [0, 1, 3], [0, 1, 2, 3]])
def test_flexure_states_bend_the_predicted_misalignment(s):
    # the flexure states (theta, theta'): exact second-order Markov block in Phi and Qd, and in
    # the quaternion rows the misalignment bent by theta (partial matching: q_br1 and q_br3
    # only, q_br0 and q_br2 hold it through eqs. 10-11), with its derivative as H
    rng = np.random.default_rng(11)
    q_m = unit(rng)
    s = np.array(s)
    n = 8 + len(s)
    sigma, wn = 0.5 * DEG, 2.0 * math.pi
    P0 = ta.initial_covariance(q_m, s, 0.0625, 2.25e-6, 6.9e-4, (sigma, wn))
    assert P0.shape == (n, n) and P0[-2, -2] == sigma**2 and P0[-1, -1] == (wn * sigma) ** 2
    q_bn = quat_mult(q_m, [0.9996, 0.02, 0.01, -0.015])
    nav = np.r_[LAT, 2.2, H, 4.4, 2.6, 0.3, q_bn / np.linalg.norm(q_bn)]
    q_rb = np.array([0.9995, 0.02, 0.012, -0.018])
    q_rb /= np.linalg.norm(q_rb)
    theta, dt = 0.004, 0.1
    phi_f, qd_f = second_order_markov(sigma, 0.7, wn, dt)
    args = (nav, q_rb, P0, s, q_m, np.array([4.3, 2.5, 0.0]), np.r_[0.1, 0.2, 0.0, 0.0, 0.0, -98.0],
            10, np.zeros(3), np.zeros(3), np.array([45.7, 15.2, 12.2]), dt,
            np.r_[[5e-4**2] * 3, [3e-5**2] * 3], 1e-12, 2)
    P, z, H_, R2, *_ = tam.predict_and_measure(*args, theta, phi_f, qd_f, np.zeros(3), 0.0)
    expected = phi_f @ P0[-2:, -2:] @ phi_f.T + qd_f
    # the off-diagonal of a nearly decoupled block rounds to ~1e-20 (or 0) by CPU kernel: an
    # absolute floor at 1e-12 of the block's scale
    np.testing.assert_allclose(P[-2:, -2:], expected, rtol=1e-12,
                               atol=1e-12 * np.abs(expected).max())
    assert not P[-2:, :-2].any()  # no coupling before the first update
    recovered = 2 not in s
    q_pred = tam.flexed(q_rb, theta, recovered)[1]
    Lc = quat_left_matrix(quat_conj(q_m))
    np.testing.assert_allclose(z[2:], (Lc @ nav[6:])[s] - q_pred[s], atol=1e-15)
    h = 1e-6
    dz = (tam.flexed(q_rb, theta + h, recovered)[1]
          - tam.flexed(q_rb, theta - h, recovered)[1]) / (2 * h)
    np.testing.assert_allclose(H_[2:, -2], -dz[s], atol=1e-9)
    assert not H_[2:, -1].any()
    if recovered:  # q_br0, q_br2 are not bent: rows 0 (and 2) carry no theta
        assert q_pred[0] == q_rb[0] and (0 not in s or H_[2, -2] == 0.0)
    # second-order term: theta times the bent component, both uncertain
    bent = {1: 3, 3: 1} if recovered else {0: 2, 1: 3, 3: 1}  # (row 2 multiplies q_br0 ~ 1)
    i = list(s).index(1)
    j = 6 + list(s).index(bent[1])
    assert R2[i, i] == pytest.approx(0.25 * (P[-2, -2] * P[j, j] + P[-2, j] ** 2), rel=1e-12)


def test_flexure_states_remove_the_flexure_from_full_matching():
    """Error-free sensors, a 3 deg mounting with a large yaw part: the paper's filters under
    flexure. Full matching with the flexure as states aligns as without flexure; the paper's
    partial matching keeps an azimuth error that scales with the flexure variance (a
    second-order effect of the flexure leaking into q_br1, q_br3 through the mounting
    misalignment: docs/methods/transfer-alignment.md §4.9)."""
    clean = {**NO_ERRORS, "duration": 100.0}
    err = {}
    for name, values, params in (
        ("full+flexure", {}, {"match": "vel_quat_full"}),
        ("partial", {}, {"flexure_sigma": 0.0}),
        ("partial, half sigma", {"flexure_sigma": 0.25 * DEG}, {"flexure_sigma": 0.0}),
    ):
        rec = simulate(SCENARIO, {**clean, **values}, seed=503)
        res = replay(rec, FILTER, params)
        err[name] = abs(rep.alignment_errors(res, rec).phi[-1, 2])
    assert err["full+flexure"] < 0.1e-3, err
    assert err["partial"] > 0.5e-3, err
    assert err["partial"] / err["partial, half sigma"] > 3.0, err  # 4 for a variance


@pytest.mark.parametrize(
    "match, s", [("vel_quat_partial", [0, 1, 3]), ("vel_quat_full", [0, 1, 2, 3]),
                 ("vel_only", [])],
)
def test_initial_covariance_is_eq17(match, s):
    rng = np.random.default_rng(8)
    q_m = unit(rng)
    p0, p1 = 1.5e-3**2, math.sin(1.5 * DEG) ** 2
    P = ta.initial_covariance(q_m, np.array(s, dtype=np.int64), 0.0625, p0, p1)
    assert P.shape == (6 + len(s),) * 2
    # (16): [dQ_bn; dQ_br[s]] = J dQ_br with J = [L(Q_m); rows s of I], so P = J P_hat J^T
    J = np.vstack([quat_left_matrix(q_m), np.eye(4)[s]])
    np.testing.assert_allclose(P[2:, 2:], J @ np.diag([p0, p1, p1, p1]) @ J.T, atol=1e-18)
    np.testing.assert_allclose(P[:2, :2], 0.0625 * np.eye(2))
    kalman.check_covariance(P)


# --------------------------------------------------------------------------------------------
# scenario


def test_scenario_streams_truth_and_metadata():
    rec = simulate(SCENARIO, {"duration": 5.0}, seed=3)
    assert len(rec[StreamKind.IMU]) == 500 and len(rec[StreamKind.MASTER_INS]) == 51
    assert not rec[StreamKind.IMU].missing_fields()
    assert not rec[StreamKind.MASTER_INS].missing_fields()
    truth = rec[StreamKind.TRUTH]
    for col in ("q_nb", "q_nr", "q_rb", "theta_f", "misalignment_euler", "v_r_n", "pos_r"):
        assert col in truth.columns
    md = rec.metadata
    te = md.true_errors
    for key in ("lever_arm_error", "q_mis", "C_mis", "gins_tilt", "gins_synchro_bias",
                "gins_vel_bias", "gyro_bias", "accel_bias", "gyro_g_sensitivity"):
        assert key in te
    np.testing.assert_allclose(md.params["lever_arm_r_nom"],
                               np.add(te["lever_arm_r"], te["lever_arm_error"]))
    # C_nb = C_nr Ry(theta_f) C_mis
    q_y = np.stack([np.cos(truth["theta_f"] / 2), 0 * truth["theta_f"],
                    np.sin(truth["theta_f"] / 2), 0 * truth["theta_f"]], axis=1)
    q_nb = quat_mult(truth["q_nr"], quat_mult(q_y, te["q_mis"]))
    np.testing.assert_allclose(attitude_error(quat_to_dcm(q_nb), quat_to_dcm(truth["q_nb"])),
                               0.0, atol=1e-14)
    # same seed, same recording; the paper's units at the boundary
    again = simulate(SCENARIO, {"duration": 5.0}, seed=3)
    np.testing.assert_array_equal(again[StreamKind.IMU]["f_b"], rec[StreamKind.IMU]["f_b"])
    p = sc.ShipTransferAlignmentParams()
    assert p.lever_arm_r == pytest.approx((45.72, 15.24, 12.192))
    assert p.gins_vel_bias == pytest.approx(0.21336) and p.lever_arm_sigma == FOOT
    assert sum(p.roll_amp) / DEG == pytest.approx(6.3) and p.gins_tilt[2] == 5 * ARCMIN


def test_perfect_imu_reproduces_the_truth_and_gins_is_the_ship():
    rec = simulate(SCENARIO, {**NO_ERRORS, "duration": 20.0}, seed=4)
    truth, imu = rec[StreamKind.TRUTH], rec[StreamKind.IMU]
    nav0 = strapdown.nav_vector(truth["pos"][0], truth["v_n"][0], truth["q_nb"][0])
    hist = strapdown.integrate(nav0, imu["omega_ib_b"], imu["f_b"], np.full(len(imu), 0.01))
    np.testing.assert_allclose(hist[:, 3:6], truth["v_n"], atol=1e-9)
    phi = attitude_error(quat_to_dcm(hist[:, 6:]), quat_to_dcm(truth["q_nb"]))
    assert np.abs(phi).max() < 1e-11
    gins = rec[StreamKind.MASTER_INS]
    q_nr = quat_to_dcm(euler_to_quat(gins["euler"]))
    np.testing.assert_allclose(attitude_error(q_nr, quat_to_dcm(truth["q_nr"][::10])), 0.0,
                               atol=1e-14)
    # V_B = V_R + C_nr (w_nr x L^r): the lever arm's velocity is of the paper's size (ft/s)
    lever_v = truth["v_n"] - truth["v_r_n"]
    assert 0.5 < np.sqrt(np.mean(lever_v[:, 2] ** 2)) / FOOT < 15.0


def test_flexure_is_stationary_with_the_requested_sigma():
    n, dt = 400_000, 0.01
    normals = np.random.default_rng(9).standard_normal((n, 2))
    for wn in (2.0 * np.pi, 1.0):
        theta = sc.flexure(n, dt, 0.5 * DEG, 0.7, wn, normals)
        assert np.std(theta) / DEG == pytest.approx(0.5, rel=0.05)
        assert np.std(theta[:1000]) > 0.0
    # a second-order Markov process: its rate is about wn sigma
    theta = sc.flexure(n, dt, 0.5 * DEG, 0.7, 2 * np.pi, normals)
    assert np.std(np.diff(theta) / dt) / (2 * np.pi * 0.5 * DEG) == pytest.approx(1.0, rel=0.1)
    assert not sc.flexure(100, dt, 0.0, 0.7, 1.0, normals[:100]).any()


def test_scenario_rejects_bad_parameters():
    from navreplay.core.params import ParamError

    for bad in ({"duration": -1}, {"flexure_wn": 0}, {"roll_amp": "0.1,0.2"},
                {"lat": 1.6}, {"gyro_bias": -1}):
        with pytest.raises(ParamError):
            simulate(SCENARIO, bad, seed=0)


# --------------------------------------------------------------------------------------------
# filter


def test_variants_share_one_code_path_with_their_dimensions():
    rec = simulate(SCENARIO, {"duration": 3.0}, seed=5)
    # the paper's filters (its rows, no flexure states), then with the two flexure states
    # (none for vel_only, which has no quaternion row they enter); the GINS-noise model (the
    # default) matches the vector components only: one state and one row fewer
    dims = {"vel_quat_partial": (9, 5), "vel_quat_full": (10, 6), "vel_only": (6, 2)}
    for model, flexure, extra in (("paper", 0.0, 0), ("paper", 0.5 * DEG, 2),
                                  ("gins", 0.5 * DEG, 1)):
        for match, (n, m) in dims.items():
            if match != "vel_only":
                n, m = n + extra, m - (model == "gins")
            res = replay(rec, FILTER, {"match": match, "flexure_sigma": flexure,
                                       "quat_model": model})
            assert res.x.shape[1] == n and res.P.shape[1:] == (n, n)
            m_q = sum(s.nu.shape[1] for s in res.innovations.values())
            assert m_q == m
            assert res.t[0] == pytest.approx(0.1)  # the first GINS sample after an IMU sample
            assert res.extras["misalignment_euler"].shape[1] == 3
            if match == "vel_quat_partial" and extra:
                assert res.state_names[-3:] == ("q_rb3", "theta_f", "theta_f_rate")
    assert res.state_names == ("v_N", "v_E", "q_nb0", "q_nb1", "q_nb2", "q_nb3")


def test_error_free_sensors_align_to_the_truth():
    rec = simulate(SCENARIO, {**NO_ERRORS, "flexure_sigma": 0.0}, seed=6)
    truth_q_rb = rec[StreamKind.TRUTH]["q_rb"][-1]
    for match in ("vel_quat_partial", "vel_quat_full"):
        res = replay(rec, FILTER, {"match": match})
        phi = phi_of(res, rec)
        assert np.abs(phi[-1, :2]).max() < 0.05e-3, match
        assert abs(phi[-1, 2]) < 0.3e-3, match
        e = attitude_error(quat_to_dcm(res.extras["q_rb"][-1]), quat_to_dcm(truth_q_rb))
        assert np.abs(e).max() < 0.3e-3
        assert np.all(np.abs(np.linalg.norm(res.extras["q_rb"], axis=1) - 1.0) < 1e-12)
    # the position is the GINS's displaced by the lever arm: the SDINS's own
    pos_err = position_error_ned(res.nav_pos, truth_at(rec, res.t)["pos"])
    assert np.abs(pos_err).max() < 0.01


def test_vel_only_recovers_q_rb_from_the_attitudes():
    rec = simulate(SCENARIO, {"duration": 5.0}, seed=7)
    res = replay(rec, FILTER, {"match": "vel_only"})
    q_m = euler_to_quat(rec[StreamKind.MASTER_INS]["euler"][1:])
    expect = quat_mult(quat_conj(q_m), res.nav_q_nb)  # every component by (11)
    expect *= np.sign(expect[:, :1])
    np.testing.assert_allclose(res.extras["q_rb"], expect / np.linalg.norm(expect, axis=1,
                                                                             keepdims=True),
                               atol=1e-12)


def test_filter_takes_the_lever_arm_from_metadata_or_parameter():
    rec = simulate(SCENARIO, {"duration": 1.0}, seed=8)
    a = replay(rec, FILTER)
    b = replay(rec, FILTER, {"lever_arm_r": ",".join(map(str, rec.metadata.params[
        "lever_arm_r_nom"]))})
    np.testing.assert_array_equal(a.x, b.x)
    c = replay(rec, FILTER, {"lever_arm_r": "0,0,0"})
    assert not np.array_equal(a.x, c.x)
    rec.metadata.params.pop("lever_arm_r_nom")
    with pytest.raises(FilterInitError, match="filter 'transfer-alignment' cannot start on .*"
                       "lever_arm_r"):
        replay(rec, FILTER)


def test_filter_params_are_validated():
    from navreplay.core.params import ParamError, build

    with pytest.raises(ParamError):
        build(ta.TransferAlignmentParams, {"match": "vel_quat_half"})
    with pytest.raises(ParamError):
        build(ta.TransferAlignmentParams, {"quat_sigma": "0"})
    with pytest.raises(ParamError):
        build(ta.TransferAlignmentParams, {"lever_arm_r": "1,2"})
    p = build(ta.TransferAlignmentParams, {"match": "vel_only"})
    assert p.match is ta.Match.VEL_ONLY and p.match.components == ()


def test_replay_is_block_size_independent():
    rec = simulate(SCENARIO, {"duration": 2.0}, seed=9)
    res = replay(rec, FILTER)
    # the same replay with an IMU block per sample (output ticks at 100 Hz)
    fine = replay(rec, FILTER, output_rate=100.0)
    i = np.searchsorted(fine.t, res.t)
    np.testing.assert_allclose(fine.nav_q_nb[i], res.nav_q_nb, atol=1e-15)


# --------------------------------------------------------------------------------------------
# reproduction


def _row_nis(values, params, runs=8):
    """Mean NIS of the velocity (2 dof) and of each quaternion row (1 dof) and their sample
    count: ``runs`` runs of 20 s at seeds never used for tuning, every update from 2 s on (the
    NIS of a consistent filter is white, so each update is a sample)."""
    vel, rows = [], []
    for i in range(runs):
        rec = simulate(SCENARIO, {**values, "duration": 20.0}, seed=9100 + i)
        res = replay(rec, FILTER, params)
        vel.append(res.innovations["velocity"].nis[20:])
        q = res.innovations["quaternion"]
        rows.append(q.nu[20:] ** 2 / np.diagonal(q.S[20:], axis1=1, axis2=2))
    vel, rows = np.concatenate(vel), np.concatenate(rows)
    return float(np.mean(vel)), np.mean(rows, axis=0), len(rows)


@pytest.mark.parametrize("values, params", [
    ({}, {}),  # flexure, partial matching with the flexure states (the default)
    ({}, {"match": "vel_quat_full"}),  # flexure, full matching with the flexure states
    ({"flexure_sigma": 0.0}, {"flexure_sigma": 0.0, "flexure_rate_sigma": 0.0}),  # no flexure
])
def test_innovations_are_consistent_with_their_covariance(values, params):
    """The NIS of the velocity (2 dof) and of every quaternion row (1 dof each) inside the
    chi-square band of docs/methods/consistency.md (false alarm 0.001), 1440 samples each.
    The quaternion rows are the vector components of the match with R the GINS Euler-angle
    noise mapped through the measurement (§4.4). q_br2 of full matching under flexure carries
    the residual of the estimated flexure (1.17 over 108 runs of 100 s) and keeps +20 %."""
    vel, per_row, n = _row_nis(values, params)
    assert consistency.inside(vel, 2, n), vel
    components = [c for c in ta.Match(params.get("match", "vel_quat_partial")).components if c]
    assert len(per_row) == len(components)
    for j, c in enumerate(components):
        if c == 2 and values.get("flexure_sigma", 1.0) > 0.0:
            assert 0.88 < per_row[j] < 1.2, per_row
        else:
            assert consistency.inside(float(per_row[j]), 1, n), per_row


def test_the_papers_quaternion_rows_fail_the_row_check():
    """The check above rejects the paper's measurement model (rows q_br0, q_br1, q_br3, the
    same 0.5 arcmin on each): a rotation moves the scalar part only in proportion to the
    misalignment, so that row's NIS is far below 1 (0.2 under flexure, 0.004 without). The
    vector rows of the same run pass."""
    vel, per_row, n = _row_nis({}, {"quat_model": "paper"}, runs=4)
    assert consistency.inside(vel, 2, n), vel
    assert not consistency.inside(float(per_row[0]), 1, n) and per_row[0] < 0.3, per_row
    assert all(consistency.inside(float(r), 1, n) for r in per_row[1:]), per_row


def test_flexure_rate_sigma_matches_the_simulated_flexure():
    # the rate the lever-arm term misses: the flexure rate at the end of an IMU interval
    # against the interval's mean rate, for the scenario's flexure (eq. 19)
    p = sc.ShipTransferAlignmentParams()
    n, dt = 200_001, 1.0 / p.imu_rate
    normals = np.random.default_rng(3).standard_normal((n, 2))
    theta, rate = sc.flexure_state(n, dt, p.flexure_sigma, p.flexure_zeta, p.flexure_wn, normals)
    missed = rate[1:] - np.diff(theta) / dt
    want = tam.flexure_rate_sigma(p.flexure_sigma, p.flexure_zeta, p.flexure_wn, p.imu_rate)
    assert np.std(missed) == pytest.approx(want, rel=0.03)
    assert want == pytest.approx(ta.TransferAlignmentParams().flexure_rate_sigma, rel=0.01)
    # the rate integrates to the angle (trapezoid, one interval)
    assert np.std(0.5 * (rate[1:] + rate[:-1]) * dt - np.diff(theta)) < 0.2 * np.std(
        np.diff(theta))


def test_short_campaign_partial_beats_full_under_flexure():
    cond = dataclasses.replace(rep.CONDITIONS[0], variants=(rep.PARTIAL, rep.FULL))
    stats, _ = rep.run_campaign(8, seed=100, workers=2, conditions=(cond,))
    part, full = stats[(rep.PARTIAL, "flexure")], stats[(rep.FULL, "flexure")]
    assert part.phi.shape == (8, 1000, 3)
    rp, rf = part.rms_at(100.0), full.rms_at(100.0)
    assert rp[2] < rf[2]  # azimuth: partial matching is not biased by the Y flexure
    assert np.all(rp[:2] < 1e-3)  # level within 1 mrad (Fig. 2)
    # the reported sigma: the consider floors (0.39 mrad level, 1.70 mrad azimuth) over the
    # filter's own sigma, which is of the reference's size (0.08 / 0.11 / 0.47 mrad)
    assert np.all((part.sigma_rms[-1, :2] > 0.39e-3) & (part.sigma_rms[-1, :2] < 0.42e-3))
    assert 1.70e-3 < part.sigma_rms[-1, 2] < 1.80e-3


def test_quick_report_and_rerun_view(tmp_path):
    from rerun.chunk import RrdReader

    repro = get_reproduction("transfer-alignment")
    assert repro is rep.REPRODUCTION
    out = tmp_path / "ta.rrd"
    report = repro.run(runs=2, seed=1, workers=1, rrd=out)
    text = report.format()
    assert "vel_quat_partial" in text and "reference (36 runs, 50 Hz)" in text
    assert "Acceptance bands (docs/methods/transfer-alignment.md §6):" in text
    assert "(Song, Jeon & Lyou): 2 runs per condition, seed 1" in text.splitlines()[0]
    for word in ("spec ", "spec'", "prototype", "(seed 00", "the seed"):  # no outside documents
        assert word not in text
    assert len(report.checks) == 8
    paths = {c.entity_path for c in RrdReader(str(out)).stream().collect().stream().to_chunks()}
    assert any(p.startswith("/ensemble/fig2") and "partial" in p for p in paths)
    assert any(p.startswith("/ensemble/fig3") and "full" in p for p in paths)
    assert set(report.figures["plots"]) >= {"fig2 level error phi_N", "fig3 azimuth error phi_D"}


@pytest.mark.slow
@pytest.mark.parametrize("seed", SLOW_SEEDS)
def test_full_campaign_meets_every_acceptance_band(seed):
    report = rep.REPRODUCTION.run(runs=36, seed=seed, workers=2)
    assert report.figures["timing"]["filter_runs"] == 36 * 9
    names = [c.name for c in report.checks]
    assert len(names) == 8
    failed = [f"{c.name}: {c.value:.4g} (band {c.band})" for c in report.checks if not c.passed]
    assert not failed, "\n".join(failed)


def test_attitude_sigma_with_the_consider_terms_is_honest():
    """The accelerometer bias and misalignment (level) and the GINS heading error (azimuth) are
    not states (as in the paper): once converged the filter's P alone is 2-8 times optimistic.
    With them as consider terms the reported sigma matches the RMS error within the sampling
    spread of 10 runs (each run's constants are one sample). No flexure: under flexure the
    azimuth error of partial matching is larger than any term of the filter
    (docs/reproduction.md)."""
    phi, sigma, sigma_p = [], [], []
    for i in range(10):
        rec = simulate(SCENARIO, {"flexure_sigma": 0.0, "duration": 60.0}, seed=9300 + i)
        res = replay(rec, FILTER, {"flexure_rate_sigma": 0.0})
        e = rep.alignment_errors(res, rec)
        phi.append(e.phi[-1])
        sigma.append(e.sigma[-1])
        sigma_p.append(tam.attitude_sigma(res.nav_q_nb[-1], res.P[-1]))
    rms = np.sqrt(np.mean(np.square(phi), axis=0))
    ratio = rms / np.sqrt(np.mean(np.square(sigma), axis=0))
    assert np.all((ratio > 0.6) & (ratio < 1.3)), ratio
    ratio_p = rms / np.sqrt(np.mean(np.square(sigma_p), axis=0))
    assert np.all(ratio_p > 2.0), ratio_p
    consider = ta.consider_sigma(ta.TransferAlignmentParams(), matched=True)
    np.testing.assert_allclose(consider, [0.39e-3, 0.39e-3, 1.70e-3], rtol=0.02)


@pytest.mark.slow
def test_flexure_states_make_the_azimuth_sigma_honest_over_the_seed_list():
    """36 runs under flexure at every seed of the list, pooled (108 runs, one sample each at
    100 s). The default filter (partial matching with the flexure states) has RMS within 20 %
    of its predicted sigma on every axis (azimuth 1.17: the flexure's second-order bias that
    partial matching keeps, §4.9). Full matching with the flexure states does too, and its
    normalised squared errors pass the chi-square check of docs/methods/consistency.md
    (3 dof, false alarm 0.001). Partial matching with the states keeps less of the flexure
    bias than the paper's filter, whose azimuth the same check rejects."""
    cond = dataclasses.replace(rep.CONDITIONS[0],
                               variants=(rep.PARTIAL, rep.PARTIAL_FLEX, rep.FULL_FLEX))
    phi, sigma = {}, {}
    for seed in SLOW_SEEDS:
        stats, _ = rep.run_campaign(36, seed=seed, workers=2, conditions=(cond,))
        for label in cond.variants:
            st = stats[(label, "flexure")]
            k = st.index(100.0)
            phi.setdefault(label, []).append(st.phi[:, k])
            sigma.setdefault(label, []).append(st.sigma[:, k])
    ratio = {}
    for label in cond.variants:
        e, s = np.concatenate(phi[label]), np.concatenate(sigma[label])
        ratio[label] = np.sqrt(np.mean(e**2, axis=0) / np.mean(s**2, axis=0))
    for label in (rep.PARTIAL_FLEX, rep.FULL_FLEX):
        assert np.all((ratio[label] > 0.8) & (ratio[label] < 1.2)), ratio
    assert ratio[rep.PARTIAL][2] > 1.2, ratio  # the check rejects the paper's filter (1.29)
    nees = np.sum((e / s) ** 2, axis=1)  # full matching
    assert consistency.inside(float(np.mean(nees)), 3, len(nees)), np.mean(nees)
    rms_d = {label: np.sqrt(np.mean(np.concatenate(phi[label])[:, 2] ** 2))
             for label in (rep.PARTIAL, rep.PARTIAL_FLEX)}
    assert rms_d[rep.PARTIAL_FLEX] < rms_d[rep.PARTIAL], rms_d
