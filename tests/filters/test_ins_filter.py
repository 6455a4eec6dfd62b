"""The NED INS error model (F, G blocks) and the free-inertial "ins" filter."""

import numpy as np
import pytest
from ins_reference import error_rate, inject_error
from scipy.linalg import expm

from navreplay import metrics
from navreplay.filters import ins_error as ie
from navreplay.filters import ins_time_update as itu
from navreplay.filters import kalman
from navreplay.filters.ins import InsFilter
from navreplay.geo import earth, rotations, strapdown
from navreplay.replay import FilterInitError, replay
from navreplay.sim.scenario import simulate

# --------------------------------------------------------------------------------------------
# F against finite differences of the continuous nonlinear mechanization (tests/ins_reference.py,
# written independently of the code under test)


STEPS = np.array([1e-6, 1e-6, 1.0, 1e-2, 1e-2, 1e-2, 1e-5, 1e-5, 1e-5,
                  1e-4, 1e-4, 1e-4, 1e-6, 1e-6, 1e-6])


def _numeric_F(truth, f_b, w_ib_b):
    F = np.zeros((15, 15))
    for j in range(15):
        e = np.zeros(15)
        e[j] = STEPS[j]
        F[:, j] = (error_rate(truth, e, f_b, w_ib_b) - error_rate(truth, -e, f_b, w_ib_b)) / (
            2 * STEPS[j])
    return F


BLOCKS = [ie.POS, ie.VEL, ie.ATT, ie.BA, ie.BG]


@pytest.mark.parametrize("lat_deg", [47.0, -33.0])
def test_F_matches_finite_differences_of_the_mechanization(lat_deg):
    lat, lon, h = np.deg2rad(lat_deg), 0.3, 350.0
    v = np.array([25.0, -14.0, 0.8])
    C = rotations.euler_to_dcm([0.1, -0.05, 2.0])
    f_b = np.array([0.7, -0.4, -9.7])
    w_ib_b = np.array([0.01, -0.02, 0.05])
    F_num = _numeric_F((lat, lon, h, v, C), f_b, w_ib_b)
    F = ie.system_matrix(np.array([lat, lon, h]), v, C, f_b)
    for rows in BLOCKS:
        for cols in BLOCKS:
            a, b = F[rows, cols], F_num[rows, cols]
            scale = np.abs(b).max()
            np.testing.assert_allclose(
                a, b, rtol=2e-5, atol=1e-6 * scale + 1e-30,
                err_msg=f"block rows {rows} cols {cols}",
            )


def test_depth_form_is_T_F_T():
    pos = np.array([0.6, 2.2, -80.0])
    v = np.array([3.0, 4.0, 0.5])
    C = rotations.euler_to_dcm([0.0, 0.1, 1.0])
    f_b = np.array([0.1, 0.0, -9.8])
    T = np.eye(15)
    T[2, 2] = -1.0
    F_h = ie.system_matrix(pos, v, C, f_b)
    F_d = ie.system_matrix(pos, v, C, f_b, vertical=ie.Vertical.DEPTH)
    np.testing.assert_allclose(F_d, T @ F_h @ T)
    # the gravity entry of docs/methods/rpm-aided-ins.md §4.2 in depth form: +2 g / sqrt(R_M R_N)
    R_M, R_N = earth.radii(pos[0])
    assert F_d[5, 2] == pytest.approx(2 * earth.gravity(pos[0], pos[2]) / np.sqrt(R_M * R_N),
                                      rel=1e-2)


def test_F_written_into_a_larger_matrix():
    big = np.full((18, 18), 7.0)
    pos, v = np.array([0.5, 0.0, 10.0]), np.array([1.0, 2.0, 0.0])
    ie.system_matrix(pos, v, np.eye(3), np.array([0.0, 0.0, -9.8]), out=big)
    np.testing.assert_array_equal(big[:15, :15], ie.system_matrix(pos, v, np.eye(3),
                                                                  np.array([0.0, 0.0, -9.8])))
    assert np.all(big[15:, :] == 7.0) and np.all(big[:, 15:] == 7.0)


def test_noise_diagonal_equals_G_Qc_G():
    C = rotations.euler_to_dcm([0.3, -0.2, 1.0])
    Qc = ie.noise_densities(1e-3, 2e-5, 1e-6, 3e-8)
    Qd = kalman.discrete_noise(ie.noise_matrix(C), Qc, 0.1)
    np.testing.assert_allclose(Qd, np.diag(ie.process_noise_diagonal(Qc, 0.1)), atol=1e-22)


def test_propagate_covariance_equals_the_reference_loop():
    rng = np.random.default_rng(0)
    n, k = 18, 7
    A = rng.normal(size=(n, n)) * 1e-3
    P = A @ A.T + np.diag(np.r_[np.full(3, 1e-12), np.full(12, 1e-4), np.full(3, 1e-2)])
    nav = np.zeros((k, 10))
    nav[:, 0] = 0.7 + 1e-6 * np.arange(k)
    nav[:, 2] = 100.0
    nav[:, 3:6] = [10.0, -5.0, 0.2]
    nav[:, 6:10] = rotations.euler_to_quat(np.c_[np.zeros(k), np.zeros(k), 0.1 * np.arange(k)])
    f_b = np.tile([0.2, 0.1, -9.8], (k, 1))
    w_b = np.tile([0.01, -0.02, 0.1], (k, 1))
    dt = np.full(k, 0.1)
    q = np.r_[np.zeros(3), np.full(3, 1e-6), np.full(3, 1e-10), np.full(6, 1e-14), np.zeros(3)]
    noise = itu.ProcessNoise(q, k_acc=3e-6, k_gyro=4e-6)
    P_ref = P.copy()
    for i in range(k):
        F = np.zeros((n, n))
        C = rotations.quat_to_dcm(nav[i, 6:])
        ie.system_matrix(nav[i, :3], nav[i, 3:6], C, f_b[i], out=F)
        a_n = C @ f_b[i] + earth.gravity_n(nav[i, 0], 0.0)  # (21) uses g on the ellipsoid
        Qd = q.copy()
        Qd[3:6] += noise.k_acc * a_n @ a_n
        Qd[6:9] += noise.k_gyro * w_b[i] @ w_b[i]
        _, P_ref = kalman.predict(np.zeros(n), P_ref, kalman.discretize(F, dt[i]),
                                  np.diag(Qd * dt[i]))
    np.testing.assert_allclose(itu.propagate_covariance(P, nav, f_b, w_b, dt, noise), P_ref,
                               rtol=1e-10, atol=1e-24)


@pytest.mark.parametrize(("gz", "vertical"), [(15, ie.Vertical.HEIGHT), (18, ie.Vertical.DEPTH)])
def test_propagate_covariance_with_gyro_z_states_equals_the_dense_prediction(gz, vertical):
    # eq. (22): three more non-zero columns of F in the attitude rows, at gz (after a lever arm
    # at 15-17 for gz = 18)
    rng = np.random.default_rng(3)
    n, k = 21, 5
    A = rng.normal(size=(n, n)) * 1e-3
    P = A @ A.T + np.diag(np.r_[np.full(3, 1e-12), np.full(12, 1e-4), np.full(6, 1e-6)])
    nav = np.zeros((k, 10))
    nav[:, 0] = 0.7
    nav[:, 2] = 100.0
    nav[:, 3:6] = [10.0, -5.0, 0.2]
    nav[:, 6:10] = rotations.euler_to_quat(np.c_[np.full(k, 0.02), np.full(k, -0.01),
                                                 0.3 * np.arange(k)])
    f_b = np.tile([0.2, 1.5, -9.8], (k, 1))
    w_b = np.tile([0.01, -0.02, 0.25], (k, 1))
    dt = np.full(k, 0.1)
    q = np.r_[np.zeros(3), np.full(3, 1e-6), np.full(3, 1e-10), np.full(6, 1e-14), np.zeros(6)]
    noise = itu.ProcessNoise(q, k_acc=3e-6, gyro_z_states=gz)
    P_ref = P.copy()
    for i in range(k):
        F = np.zeros((n, n))
        C = rotations.quat_to_dcm(nav[i, 6:])
        ie.system_matrix(nav[i, :3], nav[i, 3:6], C, f_b[i], vertical=vertical, out=F)
        F[ie.ATT, gz:gz + 3] = ie.gyro_z_rate_matrix(C, w_b[i, 2])
        a_n = C @ f_b[i] + earth.gravity_n(nav[i, 0], 0.0)
        Qd = q.copy()
        Qd[3:6] += noise.k_acc * a_n @ a_n
        _, P_ref = kalman.predict(np.zeros(n), P_ref, kalman.discretize(F, dt[i]),
                                  np.diag(Qd * dt[i]))
    P_new = itu.propagate_covariance(P, nav, f_b, w_b, dt, noise, vertical=vertical)
    np.testing.assert_allclose(P_new, P_ref, rtol=1e-10, atol=1e-24)
    # the accumulating kernel (the time update's) steps the same way
    open_step = itu.OpenStep()
    hist = np.repeat(nav, [10, 10, 10, 10, 11], axis=0)
    P_acc = itu.accumulate_covariance(P, hist, np.repeat(f_b, 10, axis=0),
                                     np.repeat(w_b, 10, axis=0), np.full(50, 0.01), 0.1, noise,
                                     open_step, vertical=vertical)
    np.testing.assert_allclose(P_acc, P_ref, rtol=1e-9, atol=1e-24)
    with pytest.raises(ValueError, match="gyro_z_states"):
        itu.ProcessNoise(q, gyro_z_states=19)


def test_gyro_z_rate_block_matches_the_strapdown():
    # eq. (22): compensating omega with k_hat = k + dk leaves domega = -dk omega_z; the phi
    # error it causes over a short interval, against F[phi, gz:] T
    nav0 = strapdown.nav_vector([np.deg2rad(40.0), 0.5, 120.0], [18.0, -9.0, 0.4],
                                rotations.euler_to_quat([0.05, -0.03, 2.4]))
    k, dt = 10, 0.01
    f_b = np.tile([0.9, -0.6, -9.7], (k, 1))
    w_b = np.tile([0.004, -0.003, 0.3], (k, 1))
    nav_T = strapdown.propagate(nav0, w_b, f_b, dt)

    def phi_after(dk):
        est_T = strapdown.propagate(nav0, w_b - np.outer(w_b[:, 2], dk), f_b, dt)
        return ie.nav_error(est_T, nav_T)[6:9]

    num = np.array([(phi_after(e) - phi_after(-e)) / 2e-4 for e in np.eye(3) * 1e-4]).T
    F = ie.gyro_z_rate_matrix(ie.nav_dcm(nav0), 0.3)
    # F at the start of the step; the body turns by 0.03 rad over it
    np.testing.assert_allclose(num / (k * dt), F, atol=0.03 * 0.3)
    assert np.all(np.sign(np.diag(num)) == np.sign(np.diag(F)))


@pytest.mark.parametrize("gz", [15, -1])
def test_propagate_covariance_with_accel_states_equals_the_dense_prediction(gz):
    # eq. (23): six more non-zero columns of F in the velocity rows, after the gyro z-rate
    # states (or right after the 15)
    rng = np.random.default_rng(5)
    ga = 18 if gz >= 0 else 15
    n, k = ga + 6, 4
    A = rng.normal(size=(n, n)) * 1e-3
    P = A @ A.T + np.diag(np.r_[np.full(3, 1e-12), np.full(12, 1e-4), np.full(n - 15, 1e-6)])
    nav = np.zeros((k, 10))
    nav[:, 0] = 0.6
    nav[:, 3:6] = [12.0, 4.0, -0.1]
    nav[:, 6:10] = rotations.euler_to_quat(np.c_[np.full(k, 0.01), np.full(k, 0.03),
                                                 -0.4 * np.arange(k)])
    f_b = np.c_[np.linspace(-1.0, 1.2, k), np.linspace(2.0, -0.5, k), np.full(k, -9.8)]
    w_b = np.tile([0.003, 0.01, -0.2], (k, 1))
    dt = np.full(k, 0.1)
    q = np.r_[np.zeros(3), np.full(3, 1e-6), np.full(3, 1e-10), np.full(6, 1e-14),
              np.zeros(n - 15)]
    noise = itu.ProcessNoise(q, gyro_z_states=gz, accel_states=ga)
    P_ref = P.copy()
    for i in range(k):
        F = np.zeros((n, n))
        C = rotations.quat_to_dcm(nav[i, 6:])
        ie.system_matrix(nav[i, :3], nav[i, 3:6], C, f_b[i], out=F)
        if gz >= 0:
            F[ie.ATT, gz:gz + 3] = ie.gyro_z_rate_matrix(C, w_b[i, 2])
        F[ie.VEL, ga:ga + 6] = ie.accel_motion_matrix(C, f_b[i])
        _, P_ref = kalman.predict(np.zeros(n), P_ref, kalman.discretize(F, dt[i]),
                                  np.diag(q * dt[i]))
    np.testing.assert_allclose(itu.propagate_covariance(P, nav, f_b, w_b, dt, noise), P_ref,
                               rtol=1e-10, atol=1e-24)
    with pytest.raises(ValueError, match="accel_states"):
        itu.ProcessNoise(q, accel_states=n - 5)


def test_accel_motion_block_matches_the_strapdown():
    # eq. (23): compensating f with k_hat = k + dk leaves df = -dk_x f_x - dk_y f_y; the
    # velocity error it causes over a short interval, against F[v, ga:] T
    nav0 = strapdown.nav_vector([np.deg2rad(40.0), 0.5, 120.0], [18.0, -9.0, 0.4],
                                rotations.euler_to_quat([0.05, -0.03, 2.4]))
    k, dt = 10, 0.01
    f_b = np.tile([1.4, -2.1, -9.7], (k, 1))
    w_b = np.tile([0.004, -0.003, 0.05], (k, 1))
    nav_T = strapdown.propagate(nav0, w_b, f_b, dt)
    b_a = np.zeros(3)

    def dv_after(dk):
        est_T = strapdown.propagate(nav0, w_b, itu.compensate_accel(f_b, b_a, dk), dt)
        return ie.nav_error(est_T, nav_T)[3:6]

    num = np.array([(dv_after(e) - dv_after(-e)) / 2e-4 for e in np.eye(6) * 1e-4]).T
    F = ie.accel_motion_matrix(ie.nav_dcm(nav0), f_b[0])
    np.testing.assert_allclose(num / (k * dt), F, rtol=0.01, atol=0.01)


def test_accumulate_covariance_steps_and_carries_the_open_step():
    k = 25
    hist = np.zeros((k + 1, 10))
    hist[:, 0] = 0.6
    hist[:, 6] = 1.0
    f_b = np.tile([0.0, 0.0, -9.8], (k, 1))
    w_b = np.zeros((k, 3))
    dt = np.full(k, 0.01)
    noise = itu.ProcessNoise(np.r_[np.zeros(3), np.full(3, 1e-4), np.zeros(9)])
    P0 = np.eye(15) * 1e-6
    open_step = itu.OpenStep()
    P = itu.accumulate_covariance(P0, hist, f_b, w_b, dt, 0.1, noise, open_step)
    assert open_step.dt == pytest.approx(0.05)
    P = itu.close_step(P, noise, open_step)
    assert open_step.dt == 0.0
    ref = itu.propagate_covariance(P0, hist[[0, 10, 20]], f_b[:3], w_b[:3],
                                  np.array([0.1, 0.1, 0.05]), noise)
    np.testing.assert_allclose(P, ref, rtol=1e-12, atol=1e-18)


def test_error_definitions_round_trip():
    nav = np.r_[0.7, 0.2, 50.0, 3.0, -2.0, 0.1, rotations.euler_to_quat([0.1, 0.2, -2.5])]
    dx = np.array([1e-6, -2e-6, 3.0, 0.1, -0.2, 0.05, 1e-3, -2e-3, 3e-3])
    for vertical in ie.Vertical:
        est = inject_error(nav, dx, vertical is ie.Vertical.DEPTH)
        np.testing.assert_allclose(ie.nav_error(est, nav, vertical), dx, rtol=1e-5, atol=1e-12)
        back = ie.apply_correction(est, dx, vertical)
        np.testing.assert_allclose(back[:6], nav[:6], atol=1e-12)
        assert np.linalg.norm(rotations.attitude_error(rotations.quat_to_dcm(back[6:]),
                                                       rotations.quat_to_dcm(nav[6:]))) < 1e-8
    # the sign: a positive phi_D is a smaller estimated heading
    est = inject_error(nav, np.r_[np.zeros(8), 0.01])
    yaw = rotations.quat_to_euler(np.array([est[6:], nav[6:]]))[:, 2]
    assert rotations.wrap_angle(yaw[0] - yaw[1]) == pytest.approx(-0.01, rel=1e-3)


def test_F_matches_finite_differences_of_the_strapdown_integration():
    # the error after T seconds of navreplay.geo.strapdown with an erroneous start and IMU,
    # against Phi = expm(F T) of the linear model
    nav0 = strapdown.nav_vector([np.deg2rad(40.0), 0.5, 120.0], [18.0, -9.0, 0.4],
                                rotations.euler_to_quat([0.05, -0.03, 2.4]))
    k, dt = 20, 0.01
    f_b = np.tile([0.9, -0.6, -9.7], (k, 1))
    w_b = np.tile([0.004, -0.003, 0.03], (k, 1))
    T = k * dt
    nav_T = strapdown.propagate(nav0, w_b, f_b, dt)

    def error_after(dx):
        est = inject_error(nav0, dx[:9])
        est_T = strapdown.propagate(est, w_b - dx[12:15], f_b - dx[9:12], dt)
        return np.r_[ie.nav_error(est_T, nav_T), dx[9:]]

    Phi_num = np.zeros((15, 15))
    for j in range(15):
        e = np.zeros(15)
        e[j] = STEPS[j]
        Phi_num[:, j] = (error_after(e) - error_after(-e)) / (2 * STEPS[j])
    # F at the middle of the interval, as the strapdown integrates mid-point quantities
    nav_m = strapdown.propagate(nav0, w_b[: k // 2], f_b[: k // 2], dt)
    F = ie.system_matrix(nav_m[:3], nav_m[3:6], rotations.quat_to_dcm(nav_m[6:]), f_b[0])
    D_num = Phi_num - np.eye(15)
    D = expm(F * T) - np.eye(15)
    for rows in BLOCKS[:3]:
        for cols in BLOCKS:
            a, b = D[rows, cols], D_num[rows, cols]
            np.testing.assert_allclose(a, b, rtol=2e-3, atol=2e-3 * np.abs(b).max() + 1e-30,
                                       err_msg=f"block rows {rows} cols {cols}")


# --------------------------------------------------------------------------------------------
# the "ins" filter

STATIONARY = {"duration": 120, "init_tilt_sigma": 1e-3, "init_heading_sigma": 3e-3,
              "init_vel_sigma": 0.01, "init_pos_sigma": 0.5}
RUNS = 40


@pytest.fixture(scope="module")
def stationary_ensemble():
    stats = metrics.EnsembleStats()
    for seed in range(RUNS):
        rec = simulate("stationary", STATIONARY, seed=seed)
        stats.add(metrics.run_metrics(replay(rec, InsFilter, output_rate=1.0), rec))
    return stats.result()


def _pooled_ratio(res, group, axes):
    """Ensemble RMS error over predicted sigma, pooled over the given axes, per epoch."""
    return np.sqrt(np.mean(res.rms[group][:, axes] ** 2, axis=1)
                   / np.mean(res.sigma[group][:, axes] ** 2, axis=1))


def test_ins_sigma_matches_the_ensemble_rms_error(stationary_ensemble):
    # 40 seeded stationary runs (tactical IMU, random initial errors): the filter's predicted
    # sigma and the RMS error over the runs agree within 20 % at every output after 5 s
    res = stationary_ensemble
    later = res.t >= 5.0
    horizontal = _pooled_ratio(res, "pos_ned", [0, 1])[later]
    attitude = _pooled_ratio(res, "phi", [0, 1, 2])[later]
    velocity = _pooled_ratio(res, "v_n", [0, 1])[later]
    # the vertical channel, driven by the effective z accelerometer bias (scale factor x g,
    # not misalignment x g: smaller than the level axes' one); one axis, so one draw per run
    # of a random constant: the ratio's sampling spread over 40 runs is about 0.11 (it was
    # 0.6 when P0 used the level axes' bias sigma for z)
    vertical = np.r_[_pooled_ratio(res, "pos_ned", [2])[res.t >= 30.0],
                     _pooled_ratio(res, "v_n", [2])[later]]
    assert np.all(np.abs(vertical - 1.0) < 0.25), vertical
    assert np.all(np.abs(horizontal - 1.0) < 0.2), horizontal
    assert np.all(np.abs(attitude - 1.0) < 0.2), attitude
    assert np.all(np.abs(velocity - 1.0) < 0.2), velocity
    # the errors grow (free inertial): tens of metres after two minutes
    assert 10.0 < np.hypot(*res.rms["pos_ned"][-1, :2]) < 1000.0


def test_ins_runs_from_the_initial_solution_without_updates():
    rec = simulate("stationary", {"duration": 2, "imu_grade": "ideal"}, seed=0)
    res = replay(rec, InsFilter, output_rate=10.0)
    assert res.state_names[:3] == ("dlat", "dlon", "dh") and not res.innovations
    # a perfect IMU at rest: the free INS stays put (strapdown round trip)
    m = metrics.run_metrics(res, rec)
    assert np.abs(m.nav.pos_ned).max() < 1e-6 and np.abs(m.nav.phi).max() < 1e-9
    np.testing.assert_array_equal(res.x, 0.0)
    # P0 from initial_nav: zero nav sigmas; bias sigmas from the recording's IMU
    # specification, which states an ideal IMU (no bias), or without it the defaults
    np.testing.assert_array_equal(res.P[0].diagonal()[9:15], 0.0)
    assert res.settings.sources["accel_bias_sigma"] == "spec"
    rec.metadata.sensors = {}
    res = replay(rec, InsFilter, output_rate=10.0)
    p = InsFilter.Params()
    np.testing.assert_allclose(np.sqrt(res.P[0].diagonal()[9:12]),
                               [p.accel_bias_sigma, p.accel_bias_sigma, p.accel_bias_sigma_z],
                               rtol=1e-3)
    assert res.settings.sources["accel_bias_sigma"] == "default"
    assert "keep the defaults, which are for imu: grade tactical" in res.settings.note


def test_ins_needs_an_initial_solution():
    rec = simulate("stationary", {"duration": 1}, seed=0)
    rec.metadata.initial_nav = {}
    with pytest.raises(FilterInitError, match="filter 'ins' cannot start on .*no initial solution"):
        replay(rec, InsFilter)
    rec = simulate("stationary", {"duration": 1}, seed=0)
    del rec.metadata.initial_nav["sigma"]["phi"]
    with pytest.raises(FilterInitError, match="init_att_sigma"):
        replay(rec, InsFilter)
    replay(rec, InsFilter, {"init_att_sigma": "0.001"})


def test_ins_params_validated():
    with pytest.raises(ValueError, match="cov_step"):
        InsFilter.Params(cov_step=0.0)
    with pytest.raises(ValueError, match="gyro_arw"):
        InsFilter.Params(gyro_arw=-1.0)


def test_propagate_covariance_with_every_column_and_markov_states_equals_the_dense_prediction():
    """Eqs. (22), (23) for all three columns of the gyro and accelerometer S + M (the column z
    of the accelerometer on f_z + g0), then three first-order Markov states outside F (kalman
    eq. 5a): the compiled step equals the dense prediction with Phi = discretize(F) but the
    Markov diagonal exp(-dt / tau) and their noise sigma^2 (1 - a^2)."""
    rng = np.random.default_rng(8)
    gz, ga, gp = 15, 24, 33
    n, k = 36, 4
    A = rng.normal(size=(n, n)) * 1e-3
    P = A @ A.T + np.diag(np.r_[np.full(3, 1e-12), np.full(12, 1e-4), np.full(n - 15, 1e-6)])
    nav = np.zeros((k, 10))
    nav[:, 0] = 0.6
    nav[:, 3:6] = [40.0, 4.0, -0.3]
    nav[:, 6:10] = rotations.euler_to_quat(np.c_[np.linspace(0.2, 0.7, k),
                                                 np.full(k, 0.03), -0.4 * np.arange(k)])
    f_b = np.c_[np.linspace(-1.0, 1.2, k), np.linspace(0.3, -0.2, k), np.linspace(-9.8, -13.5, k)]
    w_b = np.c_[np.linspace(0.1, -0.05, k), np.full(k, 0.12), np.full(k, 0.15)]
    dt = np.full(k, 0.1)
    tau = np.array([60.0, 60.0, 300.0])
    q = np.r_[np.zeros(3), np.full(3, 1e-6), np.full(3, 1e-10), np.full(6, 1e-14),
              np.zeros(18), 2.0 * np.array([1.0, 1.0, 4.0]) / tau]
    rate = np.r_[np.zeros(gp), 1.0 / tau]
    noise = itu.ProcessNoise(q, gyro_z_states=gz, gyro_columns=3, accel_states=ga,
                             accel_columns=3, markov=rate)
    P_ref = P.copy()
    for i in range(k):
        F = np.zeros((n, n))
        C = rotations.quat_to_dcm(nav[i, 6:])
        ie.system_matrix(nav[i, :3], nav[i, 3:6], C, f_b[i], out=F)
        F[ie.ATT, gz:gz + 9] = ie.gyro_error_matrix(C, w_b[i])
        F[ie.VEL, ga:ga + 9] = ie.accel_error_matrix(C, f_b[i])
        Phi = kalman.discretize(F, dt[i])
        a, qd = kalman.markov_transition(rate, q, dt[i])
        Phi[gp:, gp:] = np.diag(a[gp:])
        _, P_ref = kalman.predict(np.zeros(n), P_ref, Phi, np.diag(qd))
    np.testing.assert_allclose(itu.propagate_covariance(P, nav, f_b, w_b, dt, noise), P_ref,
                               rtol=1e-10, atol=1e-24)
    with pytest.raises(ValueError, match="markov"):
        itu.ProcessNoise(q, gyro_z_states=gz, gyro_columns=3, markov=np.r_[np.ones(1),
                                                                           np.zeros(n - 1)])
    with pytest.raises(ValueError, match="gyro_columns"):
        itu.ProcessNoise(q, gyro_z_states=gz, gyro_columns=2)


@pytest.mark.parametrize("triad", ["gyro", "accel"])
def test_every_column_block_matches_the_strapdown(triad):
    """Eqs. (22), (23): compensating with K_hat = K + dK leaves ``-dK omega`` in the rate and
    ``-dK u`` in the specific force (u_z = f_z + g0 for the accelerometer's column z); the
    attitude or velocity error they cause over a short interval, against F T."""
    nav0 = strapdown.nav_vector([np.deg2rad(40.0), 0.5, 120.0], [45.0, -9.0, 0.4],
                                rotations.euler_to_quat([0.6, -0.03, 2.4]))
    k, dt = 10, 0.01
    f_b = np.tile([1.4, -0.3, -13.2], (k, 1))  # a banked turn's load factor
    w_b = np.tile([0.05, 0.12, 0.15], (k, 1))
    nav_T = strapdown.propagate(nav0, w_b, f_b, dt)
    zero = np.zeros(3)

    def err_after(dk):
        if triad == "gyro":
            est = strapdown.propagate(nav0, itu.compensate_gyro(w_b, zero, dk), f_b, dt)
            return ie.nav_error(est, nav_T)[6:9]
        est = strapdown.propagate(nav0, w_b, itu.compensate_accel(f_b, zero, dk), dt)
        return ie.nav_error(est, nav_T)[3:6]

    num = np.array([(err_after(e) - err_after(-e)) / 2e-5 for e in np.eye(9) * 1e-5]).T
    C = ie.nav_dcm(nav0)
    F = ie.gyro_error_matrix(C, w_b[0]) if triad == "gyro" else ie.accel_error_matrix(C, f_b[0])
    # F at the start of the step; the body turns by about 2 mrad over it
    scale = np.abs(F).max()
    np.testing.assert_allclose(num / (k * dt), F, rtol=0.02, atol=0.02 * scale)
