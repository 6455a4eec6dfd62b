"""The nonlinear NED mechanization and the error dynamics it implies, written independently of
the code under test: the reference for the finite-difference checks of the INS error models
(tests/filters/test_ins_filter.py, tests/filters/test_rpm_aided_ins.py)."""

import numpy as np

from navreplay.geo import earth, rotations, strapdown


def rates(lat, lon, h, v, C, f_b, w_ib_b):
    """Time derivatives of (lat, lon, h), v_n and C_nb: NED mechanization."""
    R_M, R_N = earth.radii(lat)
    pos_dot = np.array([v[0] / (R_M + h), v[1] / ((R_N + h) * np.cos(lat)), -v[2]])
    w_ie = earth.omega_ie_n(lat)
    w_en = earth.omega_en_n(lat, h, v)
    g = np.array([0.0, 0.0, float(earth.gravity(lat, h))])
    v_dot = C @ f_b - np.cross(2 * w_ie + w_en, v) + g
    C_dot = C @ rotations.skew(w_ib_b) - rotations.skew(w_ie + w_en) @ C
    return pos_dot, v_dot, C_dot


def error_rate(truth, dx, f_b, w_ib_b, *, depth=False):
    """d(dx)/dt of an estimate carrying the errors dx (15 navigation errors, then constants)
    against the truth ``(lat, lon, h, v_n, C_nb)``; with ``depth`` the third position entry of
    the truth and of dx is the depth d = -h (and dd = -dh)."""
    lat, lon, z, v, C = truth
    sign = -1.0 if depth else 1.0
    dp, dv, phi, dba, dbg = dx[0:3], dx[3:6], dx[6:9], dx[9:12], dx[12:15]
    C_hat = rotations.rotvec_to_dcm(-phi) @ C  # C_hat = (I - [phi x]) C to first order
    p_t, v_t, C_t = rates(lat, lon, sign * z, v, C, f_b, w_ib_b)
    # the estimate runs on the compensated IMU: f_hat = f - db_a, w_hat = w - db_g
    p_e, v_e, C_e = rates(lat + dp[0], lon + dp[1], sign * (z + dp[2]), v + dv, C_hat,
                          f_b - dba, w_ib_b - dbg)
    dp_dot = p_e - p_t
    dp_dot[2] *= sign
    phi_dot = -rotations.vee(C_e @ C.T + C_hat @ C_t.T)
    # biases and any further states are constants: zero rate
    return np.concatenate([dp_dot, v_e - v_t, phi_dot, np.zeros(len(dx) - 9)])


def inject_error(nav_true, dx, depth=False):
    """A navigation vector (10,) carrying the errors dx (9: position [rad, rad, m], velocity,
    phi), the inverse of ``ins_error.nav_error``; the attitude is ``q_hat = q(-phi) (x) q``
    (exact rotation by -phi). With ``depth`` the third position error is dd = -dh."""
    nav = np.array(nav_true, dtype=float)
    dp = np.array(dx[0:3], dtype=float)
    if depth:
        dp[2] = -dp[2]
    nav[strapdown.POS] += dp
    nav[strapdown.VEL] += dx[3:6]
    q = rotations.quat_mult(rotations.rotvec_to_quat(-np.asarray(dx[6:9])), nav[strapdown.QUAT])
    nav[strapdown.QUAT] = rotations.quat_normalize(q)
    return nav
