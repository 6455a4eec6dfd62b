"""The state layout of the RPM-aided INS (eq. 20 of docs/methods/rpm-aided-ins.md) and its
measurement models: the propeller-speed measurement with its axis, noise covariance and
second-order terms, and the depth measurement. The filter is
:mod:`navreplay.filters.rpm_aided_ins`."""

from __future__ import annotations

import math

import numpy as np

from navreplay.filters import ins_error as ie
from navreplay.filters import kalman
from navreplay.geo.rotations import skew

POS = ie.POS
"""dlat [rad], dlon [rad], dd [m]."""


VEL = ie.VEL
"""dv_N, dv_E, dv_D [m/s]."""


ATT = ie.ATT
"""phi_N, phi_E, phi_D [rad]."""


BA = ie.BA
"""Accelerometer bias error, body [m/s^2]."""


BG = ie.BG
"""Gyro bias error, body [rad/s]."""


K_RPM = slice(15, 16)
"""RPM scale-factor error [-]."""


M_RPM = slice(16, 18)
"""RPM-axis misalignment error about body y and z [rad]."""


CURRENT = slice(18, 20)
"""Sea-current velocity error, N and E [m/s]."""


MOUNT = slice(20, 23)
"""Master/slave mounting misalignment [rad] (transfer-alignment mode only; inert)."""


DELAY = slice(23, 24)
"""Master data time delay [s] (transfer-alignment mode only; inert)."""


INERT = slice(20, 24)
"""States without dynamics, noise or measurement in navigation mode."""


GYRO_Z = slice(24, 27)
"""Gyro z-rate errors: misalignments of the z rate into x and y, z scale factor [rad, -]."""


ACCEL = slice(27, 33)
"""Accelerometer errors driven by the x and y specific force: the columns x and y of
S_a + M_a (s_a_x, m_a_yx, m_a_zx, m_a_xy, s_a_y, m_a_zy) [-, rad]."""


N_STATES = 33


def rpm_axis(m_y: float, m_z: float) -> tuple[np.ndarray, np.ndarray]:
    """RPM axis in the body frame and its derivative by (m_y, m_z).

    Parameters
    ----------
    m_y, m_z : float
        Misalignment ``m = [0, m_y, m_z]`` [rad], ``C_bv = exp([m x])``.

    Returns
    -------
    a : ndarray, shape (3,)
        ``C_bv e_x`` (unit vector).
    da : ndarray, shape (3, 2)
        ``d a / d(m_y, m_z) = -[a x] J(m)[:, 1:3]``, J the left Jacobian of SO(3)
        (``exp([(m + dm) x]) = exp([(J dm) x]) exp([m x])`` to first order).
    """
    th2 = m_y * m_y + m_z * m_z
    th = math.sqrt(th2)
    if th < 1e-6:  # series of (1 - cos)/th^2, sin/th, (th - sin)/th^3
        a1, b1, c1 = 0.5 - th2 / 24.0, 1.0 - th2 / 6.0, 1.0 / 6.0 - th2 / 120.0
    else:
        a1, b1, c1 = (1.0 - math.cos(th)) / th2, math.sin(th) / th, (th - math.sin(th)) / th**3
    K = skew((0.0, m_y, m_z))
    KK = K @ K
    a = np.array([1.0 + a1 * KK[0, 0], b1 * m_z + a1 * KK[1, 0], -b1 * m_y + a1 * KK[2, 0]])
    J = np.eye(3) + a1 * K + c1 * KK
    da = -skew(a) @ J[:, 1:3]
    return a, da


def rpm_measurement(
    nav: np.ndarray,
    v_rpm: float,
    k_hat: float,
    m_hat: np.ndarray,
    v_c_hat: np.ndarray,
    speed_sigma: float,
    constraint_sigma: float,
    w_lin: np.ndarray | None = None,
) -> kalman.Measurement:
    """RPM water-velocity residual, its Jacobian and noise, eqs. (25)-(27).

    Parameters
    ----------
    nav : ndarray, shape (10,)
        INS navigation vector at the measurement time.
    v_rpm : float
        RPM speed ``c_rpm rpm`` [m/s], before the scale-factor correction.
    k_hat : float
        Scale-factor estimate [-].
    m_hat : ndarray, shape (2,)
        Misalignment estimates m_y, m_z [rad].
    v_c_hat : ndarray, shape (2,)
        Current estimate N, E [m/s] (zeros when it is not estimated).
    speed_sigma, constraint_sigma : float
        1-sigma of the RPM speed and of the water-relative sideslip and heave [m/s]
        (:func:`rpm_noise_covariance`).
    w_lin : ndarray, shape (3,), optional
        Water-relative velocity NED [m/s] at which the attitude columns of H are evaluated
        (the first-estimates Jacobian); None: ``v_hat - v_c_hat``.

    Returns
    -------
    kalman.Measurement
        z (3,): ``C_nb_hat^T (v_hat - v_c_hat) - C_bv_hat [u_hat, 0, 0]`` [m/s], body axes;
        H (3, 33): ``z ~ H dx`` to first order; R (3, 3) [(m/s)^2].
    """
    C_bn = ie.nav_dcm(nav).T
    a, da = rpm_axis(float(m_hat[0]), float(m_hat[1]))
    u = v_rpm / (1.0 + k_hat)
    w = nav[3:6].copy()
    w[0] -= v_c_hat[0]
    w[1] -= v_c_hat[1]
    z = C_bn @ w - a * u  # (25)
    H = np.zeros((3, N_STATES))  # (27)
    H[:, VEL] = C_bn
    H[:, ATT] = -C_bn @ skew(w if w_lin is None else w_lin)
    H[:, 15] = a * (u / (1.0 + k_hat))
    H[:, M_RPM] = -u * da
    H[:, CURRENT] = -C_bn[:, 0:2]
    return kalman.Measurement(z, H, rpm_noise_covariance(m_hat, k_hat, speed_sigma,
                                                         constraint_sigma))


def rpm_noise_covariance(m_hat: np.ndarray, k_hat: float, speed_sigma: float,
                         constraint_sigma: float) -> np.ndarray:
    """R of the RPM residual (25), shape (3, 3) [(m/s)^2].

    The speed noise n (``speed_sigma`` [m/s] on ``c_rpm rpm``) enters z as
    ``-C_bv_hat e_x n / (1 + k_hat)``: along the estimated RPM axis a, which the misalignment
    tilts out of body x, so it also reaches the no-sideslip and no-heave rows (about
    ``m speed_sigma``). Across a, the water-relative sideslip and heave of the vehicle
    (``constraint_sigma``)::

        R = (speed_sigma / (1 + k_hat))^2 a a^T + constraint_sigma^2 (I - a a^T)
    """
    a, _ = rpm_axis(float(m_hat[0]), float(m_hat[1]))
    aa = np.outer(a, a)
    return (speed_sigma / (1.0 + k_hat)) ** 2 * aa + constraint_sigma**2 * (np.eye(3) - aa)


_SECOND_ORDER = np.r_[3:9, 15:20]
"""The states of the bilinear terms of the RPM residual: dv, phi, k, m, v_c."""


def rpm_second_order(nav: np.ndarray, u_hat: float, k_hat: float, m_hat: np.ndarray,
                     v_c_hat: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the second-order terms of the RPM residual (25) (Gaussian
    second-order filter, docs/methods/rpm-aided-ins.md §4.4).

    Beyond ``H dx`` the residual holds products of error states as large as its across-axis
    part: the attitude error turning the velocity and current errors, ``C_bn [phi x] (dv -
    dv_c)`` (a 3 mil heading error times a 0.2 m/s velocity error is 0.6 mm/s), and the
    scale-factor error scaling the misalignment, ``u_hat dk / (1 + k_hat) (da/dm) dm`` (2 % of
    0.1 deg at 14 m/s is 0.5 mm/s); the squares ``C_bn [phi x]^2 w / 2``, ``-a u_hat dk^2 /
    (1 + k_hat)^2`` and ``-u_hat (d^2 a / dm^2) dm dm / 2`` complete the second order. Each row
    is a quadratic form ``z2_i = dx^T S_i dx`` (S_i symmetric, half the Hessian); for
    dx ~ N(0, P)::

        E[z2_i] = tr(S_i P),   Cov(z2_i, z2_j) = 2 tr(S_i P S_j P)

    Parameters
    ----------
    nav : ndarray, shape (10,)
    u_hat : float
        Corrected RPM speed [m/s].
    k_hat : float
    m_hat, v_c_hat : ndarray, shape (2,)
    P : ndarray, shape (33, 33)

    Returns
    -------
    mean : ndarray, shape (3,) [m/s]
    cov : ndarray, shape (3, 3) [(m/s)^2]
    """
    C_bn = ie.nav_dcm(nav).T
    a, da = rpm_axis(float(m_hat[0]), float(m_hat[1]))
    w = nav[3:6].copy()
    w[:2] -= v_c_hat
    s = u_hat / (1.0 + k_hat)
    S = np.zeros((3, 11, 11))  # local order: dv 0-2, phi 3-5, k 6, m 7-8, v_c 9-10
    for i in range(3):
        c = C_bn[i]
        L = -0.5 * skew(c)  # c . (phi x dw) = -phi^T [c x] dw, half in each triangle
        S[i, 3:6, 0:3] = L
        S[i, 3:6, 9:11] = -L[:, 0:2]
        S[i, 6, 7:9] = 0.5 * s * da[i]
        S[i] += S[i].T
        S[i, 3:6, 3:6] = 0.25 * (np.outer(c, w) + np.outer(w, c)) - 0.5 * (c @ w) * np.eye(3)
        S[i, 6, 6] = -a[i] * s / (1.0 + k_hat)
        S[i, 7:9, 7:9] = 0.5 * u_hat * a[0] * (i == 0) * np.eye(2)  # exp([m x]) e_x at m_x = 0
    Ps = P[np.ix_(_SECOND_ORDER, _SECOND_ORDER)]
    SP = S @ Ps
    mean = np.trace(SP, axis1=1, axis2=2)
    cov = 2.0 * np.einsum("iab,jba->ij", SP, SP)
    return mean, cov


def depth_measurement(nav: np.ndarray, depth: float, sigma: float) -> kalman.Measurement:
    """Depth residual ``d_hat - d_meas`` [m], shape (1,), H (1, 27) and R (1,) of the 1-sigma
    ``sigma`` [m] (docs/methods/rpm-aided-ins.md §4.5)."""
    H = np.zeros((1, N_STATES))
    H[0, 2] = 1.0
    return kalman.Measurement(np.array([-nav[2] - depth]), H, np.array([sigma * sigma]))
