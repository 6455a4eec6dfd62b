"""navreplay.sim.kinematics: ideal IMU from truth and truth position from velocity.

The generator is compared with closed-form mean rates and specific forces (earth rate,
transport rate, Coriolis and centripetal terms included), with the first-order formula of
docs/methods/transfer-alignment.md §3.2, step 3, and its position integration with
meridian-arc and parallel-circle geometry.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from navreplay.geo import earth
from navreplay.geo import rotations as rot
from navreplay.sim import kinematics as km

DEG = np.pi / 180.0
W = earth.OMEGA_IE


def _static(n, lat, h):
    pos = np.tile([lat, 0.4, h], (n, 1))
    return pos, np.zeros((n, 3))


def test_constant_yaw_rate_gives_rate_plus_earth_rate():
    # level body at rest, turning about its z axis at w: the gyro reads [0, 0, w] plus the
    # earth rate resolved in the turning body, averaged over each interval
    lat, h, w, dt = 37 * DEG, 50.0, 0.2, 0.01
    t = np.arange(0.0, 20.0 + dt / 2, dt)
    yaw = 0.3 + w * t
    q = rot.euler_to_quat(np.stack([0 * t, 0 * t, yaw], axis=-1))
    pos, v = _static(t.size, lat, h)
    omega, f = km.imu_from_truth(t, pos, v, q)
    # (1/dt) int Rz(yaw)^T w_ie^n dt, closed form
    w_n, w_d = W * np.cos(lat), -W * np.sin(lat)
    y0, y1 = yaw[:-1], yaw[1:]
    expected = np.stack(
        [
            w_n * (np.sin(y1) - np.sin(y0)) / (w * dt),
            w_n * (np.cos(y1) - np.cos(y0)) / (w * dt),
            w + w_d + 0 * y0,
        ],
        axis=-1,
    )
    # from the second sample on, the two-sample coning inversion recovers the mean rate; the
    # first sample has no predecessor and holds the rotation vector, which differs from the
    # mean rate by the coning integral 1/2 int(theta x omega) (~ w W dt / 12 here)
    np.testing.assert_allclose(omega[1:], expected[1:], rtol=0, atol=1e-13)
    np.testing.assert_allclose(omega[0], expected[0], rtol=0, atol=w * W * dt)
    # the earth-rate part is really there (7.3e-5 rad/s scale), not hidden by the tolerance
    assert np.abs(omega[:, :2]).max() > 0.99 * W * np.cos(lat)
    # the second-order velocity scheme leaves a residual ~ g |W dt| |w dt| / 4 (4e-9 m/s^2)
    g = earth.gravity(lat, h)
    np.testing.assert_allclose(f, np.tile([0.0, 0.0, -g], (t.size - 1, 1)), rtol=0, atol=5e-9)


def test_stationary_level_reads_earth_rate_and_minus_g():
    lat, h = 37 * DEG, 0.0
    t = np.arange(0.0, 5.0, 0.1)
    euler = np.array([0.0, 0.0, 1.0])  # heading 57 deg
    q = np.tile(rot.euler_to_quat(euler), (t.size, 1))
    omega, f = km.imu_from_truth(t, *_static(t.size, lat, h), q)
    C_bn = rot.euler_to_dcm(euler).T
    np.testing.assert_allclose(
        omega, np.tile(C_bn @ earth.omega_ie_n(lat), (t.size - 1, 1)), rtol=1e-15, atol=1e-20
    )
    # the second-order velocity scheme leaves a relative residual ~ |W dt|^2 / 4 (1e-11 here)
    np.testing.assert_allclose(
        f, np.tile([0, 0, -earth.gravity(lat, h)], (t.size - 1, 1)), rtol=0, atol=1e-9
    )


def test_constant_acceleration_north_gives_expected_specific_force():
    # level, heading north, v_N = v0 + a t: f_b = v' - g_n + (2 w_ie + w_en) x v, i.e.
    #   f_N = a,  f_E = -2 W sin(lat) v_N (Coriolis),  f_D = -g + v_N^2 / (R_M + h) (centripetal)
    lat0, h, a, v0, dt = 37 * DEG, 200.0, 0.5, 5.0, 0.01
    t = np.arange(0.0, 100.0 + dt / 2, dt)
    v = np.zeros((t.size, 3))
    v[:, 0] = v0 + a * t
    pos = km.integrate_position(t, v, [lat0, 1.0, h])
    q = np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1))
    omega, f = km.imu_from_truth(t, pos, v, q)

    lat_m = 0.5 * (pos[1:, 0] + pos[:-1, 0])
    v_m = v0 + a * 0.5 * (t[1:] + t[:-1])
    R_M, _ = earth.radii(lat_m)
    f_expected = np.stack(
        [a + 0 * v_m, -2 * W * np.sin(lat_m) * v_m, -earth.gravity(lat_m, h) + v_m**2 / (R_M + h)],
        axis=-1,
    )
    np.testing.assert_allclose(f, f_expected, rtol=0, atol=1e-10)
    assert np.abs(f[:, 1]).max() > 4e-3  # Coriolis at 55 m/s is resolved
    # the gyro reads the rate of the level frame: earth rate + transport rate -v_N/(R_M+h) on E
    w_expected = np.stack([W * np.cos(lat_m), -v_m / (R_M + h), -W * np.sin(lat_m)], axis=-1)
    np.testing.assert_allclose(omega, w_expected, rtol=0, atol=1e-13)


def test_agrees_with_the_first_order_formula_of_transfer_alignment():
    # docs/methods/transfer-alignment.md §3.2, step 3:
    #   dtheta = log(C_nb(k-1)^T C_nb(k)) + C_bn(mid) w_in^n dt,
    #   dv = C_bn(mid) [v(k) - v(k-1) - (g^n - (2 w_ie^n + w_en^n) x v) dt]
    dt = 0.01
    t = np.arange(0.0, 30.0 + dt / 2, dt)
    euler = np.stack([0.2 * np.sin(1.3 * t), 0.1 * np.sin(0.7 * t + 1), 0.5 + 0.1 * t], axis=-1)
    v = np.stack([15 * np.cos(0.5 + 0.1 * t), 15 * np.sin(0.5 + 0.1 * t), 0.3 * np.sin(t)], -1)
    pos = km.integrate_position(t, v, [0.6, 2.0, 30.0])
    q = rot.euler_to_quat(euler)
    omega, f = km.imu_from_truth(t, pos, v, q)

    C = rot.quat_to_dcm(q)
    lat_m, h_m = 0.5 * (pos[1:, 0] + pos[:-1, 0]), 0.5 * (pos[1:, 2] + pos[:-1, 2])
    v_m = 0.5 * (v[1:] + v[:-1])
    w_ie = earth.omega_ie_n(lat_m)
    w_en = earth.omega_en_n(lat_m, h_m, v_m)
    q_mid = rot.quat_mult(
        q[:-1],
        rot.rotvec_to_quat(0.5 * rot.quat_to_rotvec(rot.quat_mult(rot.quat_conj(q[:-1]), q[1:]))),
    )
    C_bn_mid = np.swapaxes(rot.quat_to_dcm(q_mid), -1, -2)
    dtheta = (
        rot.dcm_to_rotvec(np.swapaxes(C[:-1], -1, -2) @ C[1:])
        + np.einsum("kij,kj->ki", C_bn_mid, w_ie + w_en) * dt
    )
    acc = earth.gravity_n(lat_m, h_m) - np.cross(2 * w_ie + w_en, v_m)
    dv = np.einsum("kij,kj->ki", C_bn_mid, v[1:] - v[:-1] - acc * dt)
    # they differ by second-order terms only: coning ~ |w x w'| dt^2 / 12 (w ~ 0.26 rad/s,
    # w' ~ 0.35 rad/s^2 here: 8e-7 rad/s), sculling and rotation ~ |w| |f| dt^2 (3e-4 m/s^2)
    np.testing.assert_allclose(omega, dtheta / dt, rtol=0, atol=8e-7)
    np.testing.assert_allclose(f, dv / dt, rtol=0, atol=3e-4)


def test_integrate_position_north_follows_meridian_arc():
    lat0, h, vn, T = -20 * DEG, 1000.0, 250.0, 3600.0
    t = np.linspace(0.0, T, 3601)
    v = np.tile([vn, 0.0, 0.0], (t.size, 1))
    pos = km.integrate_position(t, v, [lat0, 0.5, h])
    arc, _ = quad(lambda p: earth.radii(p)[0] + h, lat0, pos[-1, 0], epsabs=1e-9)
    assert arc == pytest.approx(vn * T, abs=1e-6)  # 900 km along the meridian to a micrometre
    np.testing.assert_array_equal(pos[:, 1], 0.5)
    np.testing.assert_array_equal(pos[:, 2], h)


def test_integrate_position_east_and_down():
    lat0, h0 = 60 * DEG, 0.0
    t = np.linspace(0.0, 100.0, 101)
    v = np.tile([0.0, 20.0, -2.0], (t.size, 1))
    pos = km.integrate_position(t, v, [lat0, 0.0, h0])
    np.testing.assert_array_equal(pos[:, 0], lat0)
    np.testing.assert_allclose(pos[:, 2], h0 + 2.0 * t, atol=1e-12)
    # parallel circle radius (R_N + h) cos(lat), with h at the interval mid-point
    _, R_N = earth.radii(lat0)
    dlon = 20.0 * 1.0 / ((R_N + 0.5 * (pos[1:, 2] + pos[:-1, 2])) * np.cos(lat0))
    np.testing.assert_allclose(np.diff(pos[:, 1]), dlon, rtol=1e-12)


def test_integrate_position_wraps_at_the_antimeridian():
    lat0 = 10 * DEG
    t = np.linspace(0.0, 10.0, 11)
    v = np.tile([0.0, 1000.0, 0.0], (t.size, 1))
    pos = km.integrate_position(t, v, [lat0, np.pi - 1e-4, 0.0])
    assert np.all(np.abs(pos[:, 1]) <= np.pi)
    assert pos[0, 1] > 3.14 and pos[-1, 1] < -3.14
    # the geodesic step is unaffected: compare the unwrapped longitude with a straight run
    pos0 = km.integrate_position(t, v, [lat0, 0.0, 0.0])
    np.testing.assert_allclose(np.unwrap(pos[:, 1]) - pos[0, 1], pos0[:, 1], atol=1e-12)


def test_euler_rates_to_body_rates_match_dcm_derivative():
    rng = np.random.default_rng(4)
    for _ in range(20):
        e = rng.uniform([-np.pi, -1.4, -np.pi], [np.pi, 1.4, np.pi])
        ed = rng.normal(size=3)
        d = 1e-6
        C0, C1 = rot.euler_to_dcm(e - d * ed), rot.euler_to_dcm(e + d * ed)
        # C_nb' = C_nb [w_nb^b x]
        w_fd = rot.vee(rot.euler_to_dcm(e).T @ (C1 - C0) / (2 * d))
        w = km.euler_rates_to_body_rates(e, ed)
        np.testing.assert_allclose(w, w_fd, atol=1e-8)
        np.testing.assert_allclose(km.body_rates_to_euler_rates(e, w), ed, atol=1e-12)


def test_euler_rates_vectorised():
    e = np.zeros((4, 3))
    ed = np.tile([0.1, 0.2, 0.3], (4, 1))
    np.testing.assert_allclose(km.euler_rates_to_body_rates(e, ed), ed)


def test_imu_from_truth_accepts_quaternion_sign_flips_and_scale():
    t = np.arange(0.0, 2.0, 0.01)
    q = rot.euler_to_quat(np.stack([0 * t, 0.3 * np.sin(t), 0.2 * t], -1))
    pos, v = _static(t.size, 0.5, 0.0)
    omega, f = km.imu_from_truth(t, pos, v, q)
    q2 = q * np.where(np.arange(t.size) % 3 == 0, -2.0, 1.0)[:, None]
    omega2, f2 = km.imu_from_truth(t, pos, v, q2)
    np.testing.assert_allclose(omega2, omega, atol=1e-15)
    np.testing.assert_allclose(f2, f, atol=1e-12)


def test_bad_input_is_named():
    t = np.array([0.0, 0.1, 0.1, 0.3])
    pos, v = _static(4, 0.5, 0.0)
    q = np.tile([1.0, 0, 0, 0], (4, 1))
    with pytest.raises(ValueError, match=r"strictly increasing: t\[2\]"):
        km.imu_from_truth(t, pos, v, q)
    t = np.array([0.0, 0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match=r"q_nb must have shape \(4, 4\)"):
        km.imu_from_truth(t, pos, v, q[:, :3])
    v[2, 1] = np.nan
    with pytest.raises(ValueError, match="v_n has non-finite values"):
        km.imu_from_truth(t, pos, v, q)
    with pytest.raises(ValueError, match="N >= 2"):
        km.integrate_position(t[:1], v[:1], [0, 0, 0])
    with pytest.raises(ValueError, match="pos0"):
        km.integrate_position(t, np.zeros((4, 3)), [0, 0])
