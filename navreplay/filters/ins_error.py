"""Linear INS error model in NED: the 15 navigation error states every INS filter shares.

A filter with more states (sensor scale factors, current, lever arm, ...) places these 15 first
and adds its own columns: the blocks here are the navigation part of its F and G.

States
------
===== =============== ========= ========== ===========================================
index symbol          frame     unit       meaning
===== =============== ========= ========== ===========================================
0     dlat            -         rad        latitude error
1     dlon            -         rad        longitude error
2     dh  (or dd)     -         m          height error (or depth error, ``Vertical.DEPTH``)
3-5   dv_N, dv_E, dv_D n        m/s        velocity error
6-8   phi_N, _E, _D   n         rad        attitude error (phi angle)
9-11  db_a            b (FRD)   m/s^2      accelerometer bias error
12-14 db_g            b (FRD)   rad/s      gyro bias error
===== =============== ========= ========== ===========================================

Error definitions (signs)
-------------------------
Every error is estimate minus truth, ``dx = x_hat - x``, except the attitude, which is the phi
angle of Titterton & Weston::

    C_nb_hat = (I - [phi x]) C_nb                                               (1)

so a positive phi_D means the estimated heading is smaller than the true one (this is
:func:`navreplay.geo.attitude_error`). With depth as the vertical coordinate, ``dd = d_hat - d
= -dh``. Feedback subtracts: ``x_hat <- x_hat - dx`` and, for the attitude,
``q_nb_hat <- normalize([1, phi/2] (x) q_nb_hat)`` (:func:`apply_correction`).

The IMU output is compensated with the bias estimates, ``f_hat = f_meas - b_a_hat`` and
``omega_hat = omega_meas - b_g_hat``. With ``f_meas = f + b_a + n_a`` and
``omega_meas = omega + b_g + n_g`` this gives ``df_b = -db_a + n_a`` and
``domega_ib_b = -db_g + n_g``.

Continuous model
----------------
Mechanization (NED, eqs. 2-4), with R_Mh = R_M + h, R_Nh = R_N + h, s = sin lat, c = cos lat,
t = tan lat, w_in = w_ie + w_en::

    lat' = v_N / R_Mh,  lon' = v_E / (R_Nh c),  h' = -v_D                        (2)
    v_n' = C_nb f_b - (2 w_ie + w_en) x v_n + g_n                                (3)
    C_nb' = C_nb [w_ib_b x] - [w_in x] C_nb                                      (4)

Perturbing (2)-(4) to first order gives ``dx' = F dx + G w`` (eq. 5). With
V = v_n, f_n = C_nb_hat f_hat, R'_M = dR_M/dlat, R'_N = dR_N/dlat, and p = (dlat, dlon, dh)::

    Wp  = d w_ie / dp = [[-W s, 0, 0], [0, 0, 0], [-W c, 0, 0]]                  (6)
    Ep  = d w_en / dp = [[-V_E R'_N/R_Nh^2,                  0, -V_E/R_Nh^2  ],
                         [ V_N R'_M/R_Mh^2,                  0,  V_N/R_Mh^2  ],
                         [-V_E/(R_Nh c^2) + V_E t R'_N/R_Nh^2, 0, V_E t/R_Nh^2]]  (7)
    Ev  = d w_en / dv = [[0, 1/R_Nh, 0], [-1/R_Mh, 0, 0], [0, -t/R_Nh, 0]]       (8)

    F_pp   = [[-V_N R'_M/R_Mh^2,                     0, -V_N/R_Mh^2     ],
              [ V_E (s/(R_Nh c^2) - R'_N/(R_Nh^2 c)), 0, -V_E/(R_Nh^2 c) ],
              [ 0,                                    0,  0              ]]      (9)
    F_pv   = diag(1/R_Mh, 1/(R_Nh c), -1)                                        (10)
    F_vp   = [V x] (2 Wp + Ep) + Gp,  Gp[2, :] = [dg/dlat, 0, dg/dh]              (11)
    F_vv   = -[(2 w_ie + w_en) x] + [V x] Ev                                     (12)
    F_vphi = [f_n x]                                                             (13)
    F_vba  = -C_nb_hat                                                           (14)
    F_phip = Wp + Ep,  F_phiv = Ev,  F_phiphi = -[w_in x]                        (15)
    F_phibg = +C_nb_hat                                                          (16)
    F_bb   = 0 (random constants plus random walk)                               (17)

Noise ``w = [n_a, n_g, n_ba, n_bg]`` (each 3, white, densities q_a, q_g, q_ba, q_bg)::

    G[v, n_a] = C_nb_hat, G[phi, n_g] = -C_nb_hat, G[ba, n_ba] = I, G[bg, n_bg] = I  (18)

For isotropic triad noise ``C q I C^T = q I``, so ``G Qc G^T`` is diagonal and does not depend
on the attitude (:func:`process_noise_diagonal`).

With depth as the vertical coordinate the model is transformed by T = diag(1, 1, -1, 1, ...):
``F_d = T F T`` (row 2 and column 2 change sign, eq. 19). This is the form of the RPM-aided INS,
docs/methods/rpm-aided-ins.md §4.2 (its eqs. 14-19 in NED).

Discrete process noise over a step T (diagonal, attitude independent)::

    Qd = diag(q) T,  q = [0 (3), q_a (3), q_g (3), q_ba (3), q_bg (3)]                (20)
    Qd[v, v] += k_acc |a_n|^2 T,  a_n = C_nb_hat f_hat + g_n;
    Qd[phi, phi] += k_gyro |omega_hat|^2 T                                             (21)

Eq. (21) is optional: it covers unmodelled scale-factor and misalignment errors, which act only
under motion (an error ``(S + M) omega`` of 1-sigma ``sigma |omega|`` per axis). Treating it as
white over a correlation time tau (about the length of a turn) gives ``k = sigma^2 tau``, so
a turn of that length collects the variance ``(sigma |omega| tau)^2`` of the constant error.

Gyro scale-factor and misalignment errors (optional, ``ProcessNoise.gyro_z_states`` and
``gyro_columns``). The gyro measures ``omega_meas = (I + S + M) omega + b + n``
(:mod:`navreplay.sensors.imu`), so each body rate leaks through its column of
``K_g = S + M`` into all three measured rates. The yaw rate of a land vehicle drives the
column z: the misalignments ``m_xz = M[0, 2]``, ``m_yz = M[1, 2]`` leak it into x and y and
the scale factor ``s_z`` mis-scales it, a tilt and heading error of constant sign per turn,
which white noise (21) cannot represent. A banked (coordinated) turn turns the body about its
y axis as well (``omega_y = psi_dot sin(bank)``, of one sign in left and right turns alike)
and rolls it in and out about x: the columns x and y. A filter may estimate the columns
``k_j = K_g[:, j]`` as random constants, three states per column in the order
:data:`GYRO_COLUMNS` (z, then x and y), and compensate
``omega_hat = omega_meas - b_g_hat - sum_j k_j_hat (omega_meas_j - b_g_hat_j)``. With
``dk = k_hat - k`` (estimate minus truth, as the biases) ``domega_ib_b = -db_g - sum_j dk_j
omega_j`` (first order), and since ``phi' = -C_nb_hat domega_ib_b + ...`` (the sign of
eq. 16)::

    F[phi, (k_j)_i] = +C_nb_hat[:, i] omega_j,   i = 0, 1, 2                            (22)

with omega the mean compensated body rate of the step. The column z alone (three states) is
the land-vehicle model; the columns x and y are what roll and pitch rates excite.

Accelerometer scale-factor and misalignment errors (optional, ``ProcessNoise.accel_states``
and ``accel_columns``). The accelerometer measures ``f_meas = (I + S_a + M_a) f + b``. The
columns x and y of ``K_a = S_a + M_a``, ``k_x = (s_x, m_yx, m_zx)`` and ``k_y = (m_xy, s_y,
m_zy)`` (``k_j[i] = K_a[i, j]``), act on the accelerations and turns of the vehicle: an error in
a fixed direction of the body at each speed change and flat turn. The column z meets the 1 g
of gravity, a constant while the vehicle's specific force stays ``(0, 0, -g)``, so it is part
of the effective bias (:func:`navreplay.sensors.imu.effective_biases`); what changes with the
load factor of a banked turn or a pull-up, ``f_z + g0`` (``g0`` standard gravity: the
constant ``k_z (-g0)`` stays in the bias), is the rest. A filter may estimate the columns as
random constants, three states per column in the order :data:`ACCEL_COLUMNS` (x, y, then z),
and compensate ``f_hat = f_meas - b_a_hat - sum_j k_j_hat u_j`` with ``u_x = f_x - b_a_x``,
``u_y = f_y - b_a_y`` and ``u_z = f_z - b_a_z + g0``. With ``dk = k_hat - k``,
``df_b = -db_a - sum_j dk_j u_j`` and so::

    F[v, (k_j)_i] = -C_nb_hat[:, i] u_j,   i = 0, 1, 2                                 (23)

with u from the mean compensated specific force of the step. The z column's states start
correlated with the effective z-column bias they are part of: ``cov(b_a_i, k_z[i]) =
-g0 sigma(k_z[i])^2`` (the bias holds ``k_z (-g0)``).

Every block was checked against central finite differences of (2)-(4) and of
:func:`navreplay.geo.strapdown.propagate` (tests/filters/test_ins_filter.py).

The covariance propagation over this model is :mod:`navreplay.filters.ins_time_update`.
"""

from __future__ import annotations

import enum
import math

import numpy as np

from navreplay.core.jit import kernel
from navreplay.core.units import G0
from navreplay.filters.base import Nav, NavError, Quantity, State, TruthColumn
from navreplay.geo import earth, kernels, strapdown
from navreplay.geo.rotations import (
    attitude_error,
    quat_to_dcm,
    wrap_angle,
)

# -- state layout ----------------------------------------------------------------------------

POS = slice(0, 3)
"""Position error (dlat [rad], dlon [rad], dh [m] or dd [m])."""
VEL = slice(3, 6)
"""Velocity error, NED [m/s]."""
ATT = slice(6, 9)
"""Attitude error phi, NED [rad]."""
BA = slice(9, 12)
"""Accelerometer bias error, body [m/s^2]."""
BG = slice(12, 15)
"""Gyro bias error, body [rad/s]."""
NAV = slice(0, 9)
"""Position, velocity and attitude errors."""
N_STATES = 15
N_GYRO_Z = 3
"""Gyro z-rate error states of eq. (22): misalignments m_xz, m_yz and scale factor s_z."""
N_ACCEL_HF = 6
"""Accelerometer error states of eq. (23): the columns x and y of S_a + M_a."""
GYRO_COLUMNS = (2, 0, 1)
"""The columns of ``S_g + M_g`` (the body rate each multiplies) in the order of the gyro
states, three states each: z (the yaw rate of a land vehicle), then x and y (roll and pitch
rates)."""
ACCEL_COLUMNS = (0, 1, 2)
"""The columns of ``S_a + M_a`` in the order of the accelerometer states: x and y (forward and
lateral specific force), then z (the load factor, ``f_z + g0``)."""

# -- noise layout (columns of G) --------------------------------------------------------------

W_ACC = slice(0, 3)
"""Accelerometer white noise [(m/s^2) sqrt(s)] -> velocity."""
W_GYRO = slice(3, 6)
"""Gyro white noise [(rad/s) sqrt(s)] -> attitude."""
W_BA = slice(6, 9)
"""Accelerometer bias random walk [(m/s^2)/sqrt(s)]."""
W_BG = slice(9, 12)
"""Gyro bias random walk [(rad/s)/sqrt(s)]."""
N_NOISE = 12

# -- blocks of the navigation vector of navreplay.geo.strapdown -----------------------------------

NAV_POS = strapdown.POS
NAV_VEL = strapdown.VEL
NAV_Q = strapdown.QUAT

class Vertical(enum.StrEnum):
    """Vertical coordinate of the position error state."""

    HEIGHT = "height"
    """dh, ellipsoidal height error [m], positive up."""
    DEPTH = "depth"
    """dd = -dh, depth error [m], positive down."""


def nav_states(vertical: Vertical = Vertical.HEIGHT) -> tuple[State, ...]:
    """Declarations of the 15 states of a filter's ``Estimate.x`` that uses this model: the
    9 navigation errors (scored against the navigation solution's error, in the NEES) and the
    accelerometer and gyro biases as total estimates ``b_a_*``, ``b_g_*``: effective biases
    that also hold the scale-factor, misalignment and g-sensitivity errors at rest, scored
    against the truth stream's ``accel_bias_eff`` and ``gyro_bias_eff`` columns; not in the
    NEES."""
    depth = vertical is Vertical.DEPTH
    return (
        State("dlat", "rad", Quantity.POSITION, NavError(Nav.LAT), nees=True),
        State("dlon", "rad", Quantity.POSITION, NavError(Nav.LON), nees=True),
        State("dd" if depth else "dh", "m", Quantity.POSITION,
              NavError(Nav.DEPTH if depth else Nav.H), nees=True),
        *(State(f"dv_{a}", "m/s", Quantity.VELOCITY, NavError(Nav(f"v_{a}")), nees=True)
          for a in "NED"),
        *(State(f"phi_{a}", "rad", Quantity.ATTITUDE, NavError(Nav(f"phi_{a}")), nees=True)
          for a in "NED"),
        *(State(f"b_a_{a}", "m/s^2", Quantity.ACCEL_BIAS, TruthColumn("accel_bias_eff", (i,)))
          for i, a in enumerate("xyz")),
        *(State(f"b_g_{a}", "rad/s", Quantity.GYRO_BIAS, TruthColumn("gyro_bias_eff", (i,)))
          for i, a in enumerate("xyz")),
    )


@kernel(inline="always")
def _set_skew(M: np.ndarray, r: int, c: int, x: float, y: float, z: float, k: float) -> None:
    """M[r:r+3, c:c+3] += k [v x] with v = (x, y, z)."""
    M[r, c + 1] -= k * z
    M[r, c + 2] += k * y
    M[r + 1, c] += k * z
    M[r + 1, c + 2] -= k * x
    M[r + 2, c] -= k * y
    M[r + 2, c + 1] += k * x


@kernel(inline="always")
def fill_system_matrix(
    lat: float, h: float, vN: float, vE: float, vD: float,
    C: np.ndarray, f_b: np.ndarray, depth: bool, curvature: bool, F: np.ndarray,
) -> None:
    """Write eqs. (6)-(19) into ``F[:15, :15]`` (zeroed by the caller); callable from compiled
    code. Without ``curvature`` the dR_M/dlat, dR_N/dlat terms (column 0 only) are left out.
    Arguments as :func:`system_matrix` (C is C_nb, depth selects eq. 19)."""
    s, c = math.sin(lat), math.cos(lat)
    t = s / c
    R_M, R_N = kernels.radii(lat)
    dR_M, dR_N = kernels.radii_derivatives(lat) if curvature else (0.0, 0.0)
    R_Mh = R_M + h
    R_Nh = R_N + h
    W = earth.OMEGA_IE
    w_ie = kernels.earth_rate(lat)
    w_en = kernels.transport_rate(lat, h, vN, vE)
    Wp = np.zeros((3, 3))  # (6)
    Wp[0, 0] = -W * s
    Wp[2, 0] = -W * c
    Ep = np.zeros((3, 3))  # (7)
    Ep[0, 0] = -vE * dR_N / R_Nh**2
    Ep[0, 2] = -vE / R_Nh**2
    Ep[1, 0] = vN * dR_M / R_Mh**2
    Ep[1, 2] = vN / R_Mh**2
    Ep[2, 0] = -vE / (R_Nh * c * c) + vE * t * dR_N / R_Nh**2
    Ep[2, 2] = vE * t / R_Nh**2
    Ev = np.zeros((3, 3))  # (8)
    Ev[0, 1] = 1.0 / R_Nh
    Ev[1, 0] = -1.0 / R_Mh
    Ev[2, 1] = -t / R_Nh
    Vx = np.zeros((3, 3))
    _set_skew(Vx, 0, 0, vN, vE, vD, 1.0)
    f_n = np.zeros(3)
    for i in range(3):
        for j in range(3):
            f_n[i] += C[i, j] * f_b[j]

    F[0, 0] = -vN * dR_M / R_Mh**2  # (9)
    F[0, 2] = -vN / R_Mh**2
    F[1, 0] = vE * (s / (R_Nh * c * c) - dR_N / (R_Nh**2 * c))
    F[1, 2] = -vE / (R_Nh**2 * c)
    F[0, 3] = 1.0 / R_Mh  # (10)
    F[1, 4] = 1.0 / (R_Nh * c)
    F[2, 5] = -1.0
    for i in range(3):
        for j in range(3):
            vp = 0.0  # (11) [V x] (2 Wp + Ep)
            vv = 0.0  # (12) [V x] Ev
            for k in range(3):
                vp += Vx[i, k] * (2.0 * Wp[k, j] + Ep[k, j])
                vv += Vx[i, k] * Ev[k, j]
            F[3 + i, j] = vp
            F[3 + i, 3 + j] = vv
            F[3 + i, 9 + j] = -C[i, j]  # (14)
            F[6 + i, j] = Wp[i, j] + Ep[i, j]  # (15)
            F[6 + i, 3 + j] = Ev[i, j]
            F[6 + i, 12 + j] = C[i, j]  # (16)
    dg_dlat, dg_dh = kernels.gravity_derivatives(lat, h)  # (11) Gp
    F[5, 0] += dg_dlat
    F[5, 2] += dg_dh
    _set_skew(F, 3, 3, 2.0 * w_ie[0] + w_en[0], 2.0 * w_ie[1] + w_en[1],
              2.0 * w_ie[2] + w_en[2], -1.0)  # (12)
    _set_skew(F, 3, 6, f_n[0], f_n[1], f_n[2], 1.0)  # (13)
    _set_skew(F, 6, 6, w_ie[0] + w_en[0], w_ie[1] + w_en[1], w_ie[2] + w_en[2], -1.0)  # (15)
    if depth:  # (19)
        for j in range(F.shape[1]):
            F[2, j] = -F[2, j]
        for i in range(F.shape[0]):
            F[i, 2] = -F[i, 2]


def system_matrix(
    pos: np.ndarray,
    v_n: np.ndarray,
    C_nb: np.ndarray,
    f_b: np.ndarray,
    *,
    vertical: Vertical = Vertical.HEIGHT,
    curvature_derivatives: bool = True,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """The system matrix F of the 15 navigation error states, eqs. (6)-(19).

    Parameters
    ----------
    pos : ndarray, shape (3,)
        Estimated latitude [rad], longitude [rad], height [m] (height also in the depth form).
    v_n : ndarray, shape (3,)
        Estimated velocity NED [m/s].
    C_nb : ndarray, shape (3, 3)
        Estimated attitude DCM, b to n.
    f_b : ndarray, shape (3,)
        Bias-compensated specific force, body [m/s^2] (mean over the step).
    vertical : Vertical
        Height or depth as the third position error state.
    curvature_derivatives : bool
        Keep the dR_M/dlat, dR_N/dlat terms of (7) and (9) (column 0; their effect is small).
    out : ndarray, shape (n, n) with n >= 15, optional
        A larger filter's F: its top-left 15x15 block is overwritten, the rest left as it is.

    Returns
    -------
    F : ndarray, shape (15, 15), or ``out``
    """
    if out is None:
        F = np.zeros((N_STATES, N_STATES))
    else:
        F = out
        F[:N_STATES, :N_STATES] = 0.0
    fill_system_matrix(
        float(pos[0]), float(pos[2]), float(v_n[0]), float(v_n[1]), float(v_n[2]),
        np.ascontiguousarray(C_nb, dtype=np.float64), np.ascontiguousarray(f_b, dtype=np.float64),
        vertical is Vertical.DEPTH, bool(curvature_derivatives), F,
    )
    return F


def gyro_z_rate_matrix(C_nb: np.ndarray, omega_z: float) -> np.ndarray:
    """``F[phi, (dm_xz, dm_yz, ds_z)] = C_nb_hat omega_z``, eq. (22) of the column z, shape
    (3, 3).

    Column j is the attitude-error rate per unit error of the gyro z-rate coefficient of body
    axis j (m_xz, m_yz, s_z) at the body rate ``omega_z`` [rad/s].
    """
    return np.asarray(C_nb, dtype=float) * float(omega_z)


def gyro_error_matrix(C_nb: np.ndarray, omega_b: np.ndarray, columns: int = 3) -> np.ndarray:
    """``F[phi, (k_j)_i] = C_nb_hat[:, i] omega_j``, eq. (22), for the first ``columns`` gyro
    columns of :data:`GYRO_COLUMNS`, shape (3, 3 columns).

    Column ``3 c + i`` is the attitude-error rate per unit error of ``(S_g + M_g)[i, j]``,
    ``j = GYRO_COLUMNS[c]``, at the body rate ``omega_b`` [rad/s].
    """
    C = np.asarray(C_nb, dtype=float)
    w = np.asarray(omega_b, dtype=float)
    return np.hstack([C * w[j] for j in GYRO_COLUMNS[:columns]])


def accel_motion_matrix(C_nb: np.ndarray, f_b: np.ndarray) -> np.ndarray:
    """``F[v, dk] = -C_nb_hat[:, i] f_j`` for the six states ``dk_j[i]`` (j = x, y), eq. (23),
    shape (3, 6).

    Column ``3 j + i`` is the velocity-error rate per unit error of the coefficient
    ``(S_a + M_a)[i, j]`` at the specific force ``f_b`` [m/s^2].
    """
    return accel_error_matrix(C_nb, f_b, 2)


def accel_error_matrix(C_nb: np.ndarray, f_b: np.ndarray, columns: int = 3) -> np.ndarray:
    """``F[v, (k_j)_i] = -C_nb_hat[:, i] u_j``, eq. (23), for the first ``columns``
    accelerometer columns of :data:`ACCEL_COLUMNS` (``u = f_b`` but ``u_z = f_z + g0``),
    shape (3, 3 columns)."""
    C = np.asarray(C_nb, dtype=float)
    u = np.array(f_b, dtype=float)
    u[2] += G0
    return np.hstack([-C * u[j] for j in ACCEL_COLUMNS[:columns]])


def noise_matrix(C_nb: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Noise input matrix G, eq. (18), columns ``[n_a, n_g, n_ba, n_bg]``.

    Parameters
    ----------
    C_nb : ndarray, shape (3, 3)
    out : ndarray, shape (n, p), optional
        Write into the top-left 15x12 block of this (zeroed) array and return it.

    Returns
    -------
    G : ndarray, shape (15, 12) or the shape of ``out``
    """
    G = np.zeros((N_STATES, N_NOISE)) if out is None else out
    G[VEL, W_ACC] = C_nb
    G[ATT, W_GYRO] = -C_nb
    G[BA, W_BA] = np.eye(3)
    G[BG, W_BG] = np.eye(3)
    return G


def noise_densities(
    accel_vrw: float, gyro_arw: float, accel_bias_rw: float, gyro_bias_rw: float
) -> np.ndarray:
    """Diagonal Qc of ``[n_a, n_g, n_ba, n_bg]`` from the four densities, shape (12,).

    Parameters
    ----------
    accel_vrw : float
        Velocity random walk [(m/s)/sqrt(s)].
    gyro_arw : float
        Angle random walk [rad/sqrt(s)].
    accel_bias_rw : float
        Accelerometer bias random walk [(m/s^2)/sqrt(s)].
    gyro_bias_rw : float
        Gyro bias random walk [(rad/s)/sqrt(s)].
    """
    return np.repeat(np.array([accel_vrw, gyro_arw, accel_bias_rw, gyro_bias_rw]) ** 2, 3)


def process_noise_diagonal(Qc: np.ndarray, dt: float) -> np.ndarray:
    """Diagonal of ``G Qc G^T dt`` for isotropic triad noise, shape (15,).

    Equal to ``kalman.discrete_noise(noise_matrix(C_nb), Qc, dt)`` for any C_nb when each triad
    of Qc has equal entries (``C q I C^T = q I``).
    """
    d = np.zeros(N_STATES)
    d[VEL] = Qc[W_ACC]
    d[ATT] = Qc[W_GYRO]
    d[BA] = Qc[W_BA]
    d[BG] = Qc[W_BG]
    return d * dt


# -- error definitions on the navigation vector ----------------------------------------------


def position_scale(pos: np.ndarray, vertical: Vertical = Vertical.HEIGHT) -> np.ndarray:
    """Metres per unit of (dlat, dlon, dh or dd) along N, E, D: ``dr_ned = D dp``, shape (3,).

    ``D = diag(R_M + h, (R_N + h) cos lat, -1)`` for height (``+1`` for depth).
    """
    lat, _, h = pos
    R_M, R_N = earth.radii(lat)
    return np.array(
        [float(R_M) + h, (float(R_N) + h) * math.cos(lat),
         -1.0 if vertical is Vertical.HEIGHT else 1.0]
    )


def nav_error(
    nav_hat: np.ndarray, nav_true: np.ndarray, vertical: Vertical = Vertical.HEIGHT
) -> np.ndarray:
    """The 9 navigation error states of an estimate against the truth, eq. (1).

    Parameters
    ----------
    nav_hat, nav_true : ndarray, shape (..., 10)
        Navigation vectors ``[lat, lon, h, v_N, v_E, v_D, q0, q1, q2, q3]``.
    vertical : Vertical

    Returns
    -------
    dx : ndarray, shape (..., 9)
        (dlat, dlon, dh or dd, dv_n, phi).
    """
    nav_hat = np.asarray(nav_hat, dtype=float)
    nav_true = np.asarray(nav_true, dtype=float)
    dx = np.empty(nav_hat.shape[:-1] + (9,))
    dx[..., 0:3] = nav_hat[..., NAV_POS] - nav_true[..., NAV_POS]
    dx[..., 1] = wrap_angle(dx[..., 1])
    if vertical is Vertical.DEPTH:
        dx[..., 2] *= -1.0
    dx[..., 3:6] = nav_hat[..., NAV_VEL] - nav_true[..., NAV_VEL]
    dx[..., 6:9] = attitude_error(
        quat_to_dcm(nav_hat[..., NAV_Q]), quat_to_dcm(nav_true[..., NAV_Q])
    )
    return dx


def apply_correction(
    nav: np.ndarray, dx: np.ndarray, vertical: Vertical = Vertical.HEIGHT
) -> np.ndarray:
    """Feedback of the estimated navigation errors ``dx`` (9,): subtract, eq. (1).

    Position and velocity: ``x_hat - dx``; attitude: ``q_hat <- normalize([1, phi/2] (x) q_hat)``.

    Parameters
    ----------
    nav : ndarray, shape (10,)
        Navigation vector to correct (not modified).
    dx : ndarray, shape (>= 9,)
        Estimated errors; only the first 9 entries are used.
    vertical : Vertical

    Returns
    -------
    ndarray, shape (10,)
    """
    out = np.array(nav, dtype=float)
    out[0] -= dx[0]
    out[1] -= dx[1]
    out[2] -= dx[2] if vertical is Vertical.HEIGHT else -dx[2]
    out[NAV_VEL] -= dx[VEL]
    a, b, c = (0.5 * dx[ATT]).tolist()
    out[NAV_Q] = kernels.correct_quat(a, b, c, *out[NAV_Q].tolist())  # [1, phi/2] (x) q
    return out


def nav_dcm(nav: np.ndarray) -> np.ndarray:
    """Attitude DCM C_nb of a navigation vector (10,), shape (3, 3)."""
    return kernels.quat_to_dcm(nav[NAV_Q])
