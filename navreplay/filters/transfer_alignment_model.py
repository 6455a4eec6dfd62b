"""The model of the transfer-alignment filter (docs/methods/transfer-alignment.md §4) as numba
kernels: the state and measurement layouts of eqs. (13) and (15), the system matrix, hull
flexure, lever arm, the per-GINS-sample prediction and measurement and the feedback. The
per-sample model is ~40 small matrix operations, which numpy pays for in call overhead. The
quaternion and earth-model helpers are the single-value kernels of navreplay.geo.kernels; the
discretisation, the prediction, the correction and the covariance check are the shared ones of
navreplay.filters.kalman. The filter itself is :mod:`navreplay.filters.transfer_alignment`."""

from __future__ import annotations

import math

import numpy as np

from navreplay.core.jit import kernel
from navreplay.filters import kalman
from navreplay.geo import earth, kernels

# state layout, eq. (13): the dQ_br block holds the matched components s, in order
DV = slice(0, 2)
"""dV_n, dV_e [m/s]."""


DQ_BN = slice(2, 6)
"""dq_bn0..3 [-]."""


N_NAV = 6
"""States before the dQ_br block dq_br[s] [-], which the flexure states (theta_f [rad],
theta_f' [rad/s]) follow when modelled."""


# measurement layout, eq. (15)
ZV = slice(0, 2)
"""Velocity rows."""


ZQ = slice(2, None)
"""Quaternion rows s."""


@kernel
def _mm(A, B):
    """A @ B for small matrices (loops: no BLAS call, quick to compile)."""
    n, k = A.shape
    m = B.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for l in range(k):
            a = A[i, l]
            if a != 0.0:
                for j in range(m):
                    out[i, j] += a * B[l, j]
    return out


@kernel
def _mmt(A, B):
    """A @ B.T for small matrices."""
    n, k = A.shape
    m = B.shape[0]
    out = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            v = 0.0
            for l in range(k):
                v += A[i, l] * B[j, l]
            out[i, j] = v
    return out


@kernel
def _mv(A, x):
    """A @ x."""
    n, k = A.shape
    out = np.zeros(n)
    for i in range(n):
        for l in range(k):
            out[i] += A[i, l] * x[l]
    return out


@kernel
def _put(A, i0, j0, B, scale):
    """A[i0:i0+k, j0:j0+m] = scale B (loops: 2-D slice expressions compile slowly in numba)."""
    for i in range(B.shape[0]):
        for j in range(B.shape[1]):
            A[i0 + i, j0 + j] = scale * B[i, j]


@kernel
def _normalise(q):
    """q / |q| in place."""
    k = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for i in range(4):
        q[i] *= k


@kernel
def rmat(q):
    """The paper's R(q), (4, 3): ``[0, w] (x) q = R(q) w``, columns 1-3 of the right-product
    matrix M(q) (:func:`navreplay.geo.kernels.quat_right_matrix`)."""
    return kernels.quat_right_matrix(q)[:, 1:]


@kernel
def tmat(q):
    """The paper's T(q), (4, 3): ``q (x) [0, w] = T(q) w``, columns 1-3 of the left-product
    matrix L(q) (:func:`navreplay.geo.kernels.quat_left_matrix`)."""
    return kernels.quat_left_matrix(q)[:, 1:]


@kernel
def rate_matrix(w_ib, w_in):
    """The 4x4 ``[w_ib^b - w_in^n]`` of eq. (2): ``M([0, w_ib]) - L([0, w_in])``, (4, 4)."""
    W = kernels.quat_right_matrix(np.array([0.0, w_ib[0], w_ib[1], w_ib[2]]))
    W -= kernels.quat_left_matrix(np.array([0.0, w_in[0], w_in[1], w_in[2]]))
    return W


@kernel
def earth_terms(lat, h, v_n):
    """Earth radius of eq. (14) and w_in^n at a position and velocity.

    Returns
    -------
    R : float
        ``sqrt(R_M R_N) + h`` [m], the single radius of eq. (14).
    w_in : ndarray, shape (3,)
        ``w_ie^n + w_en^n`` with the WGS84 radii [rad/s].
    """
    R_M, R_N = kernels.radii(lat)
    ie_n, _, ie_d = kernels.earth_rate(lat)
    en_n, en_e, en_d = kernels.transport_rate(lat, h, v_n[0], v_n[1])
    w_in = np.empty(3)
    w_in[0] = ie_n + en_n
    w_in[1] = en_e
    w_in[2] = ie_d + en_d
    return math.sqrt(R_M * R_N) + h, w_in


@kernel
def system_matrix(q_bn, v_n, lat, R, w_ib_b, w_in_n, f_b, n):
    """A of eq. (14) (errata E1-E5 applied) and G of the process noise, at the estimate.

    Parameters
    ----------
    q_bn : ndarray, shape (4,)
        SDINS attitude Q_bn (q_nb).
    v_n : ndarray, shape (3,)
        SDINS velocity NED [m/s].
    lat : float
        Latitude [rad].
    R : float
        Earth radius of eq. (14) [m].
    w_ib_b : ndarray, shape (3,)
        Body rate, mean over the filter interval [rad/s].
    w_in_n : ndarray, shape (3,)
        Rate of n w.r.t. inertial space [rad/s].
    f_b : ndarray, shape (3,)
        Specific force, mean over the filter interval [m/s^2].
    n : int
        Number of states (6 + len(s)).

    Returns
    -------
    A : ndarray, shape (n, n)
    G : ndarray, shape (n, 6)
        Input of the noise [n_a (3), n_g (3)].
    """
    vn, ve, vd = v_n[0], v_n[1], v_n[2]
    ws = 2.0 * earth.OMEGA_IE * math.sin(lat)
    tl = math.tan(lat)
    C = kernels.quat_to_dcm(q_bn)
    f_n = _mv(C, f_b)
    Rq = rmat(q_bn)
    A = np.zeros((n, n))
    # (1) velocity error, E1/E2: M_vv
    A[0, 0] = vd / R
    A[0, 1] = -(ws + 2.0 * ve * tl / R)
    A[1, 0] = ws + ve * tl / R
    A[1, 1] = (vd + vn * tl) / R
    # (1), E3/E4: A_vq = -2 [f^n x]_(N,E) R(Q_bn)^T
    F2 = np.zeros((2, 3))
    F2[0, 1], F2[0, 2] = -f_n[2], f_n[1]
    F2[1, 0], F2[1, 2] = f_n[2], -f_n[0]
    _put(A, 0, 2, _mmt(F2, Rq), -2.0)
    # (2): A_qv = -1/2 R(Q_bn) Gamma2
    Gamma2 = np.zeros((3, 2))
    Gamma2[0, 1], Gamma2[1, 0], Gamma2[2, 1] = 1.0 / R, -1.0 / R, -tl / R
    _put(A, 2, 0, _mm(Rq, Gamma2), -0.5)
    # (2): A_qq = 1/2 [w_ib^b - w_in^n]
    _put(A, 2, 2, rate_matrix(w_ib_b, w_in_n), 0.5)
    G = np.zeros((n, 6))
    _put(G, 0, 0, C[0:2], 1.0)
    _put(G, 2, 3, tmat(q_bn), 0.5)
    return A, G


_BENT_BY = np.array([2, 3, 0, 1])
"""The component of Q_br that the flexure angle multiplies in each component of
``[0, e_Y] (x) Q_br = [-q2, q3, q0, -q1]``, and its sign (_BENT_SIGN)."""


_BENT_SIGN = np.array([-1.0, 1.0, 1.0, -1.0])


@kernel
def flexed(q_rb, theta, recovered):
    """Q_br as the GINS and SDINS attitudes show it when the hull is bent by theta [rad] about
    the ship's Y axis: ``Ry(theta) (x) Q_br``, its matrix in the estimated components and its
    derivative in theta.

    With partial matching (``recovered`` True) q_br2 is recovered from the attitudes after
    every update (eq. 11) and so already holds the flexure, and the normalisation (eq. 10)
    puts the flexure's share in the scalar q_br0: only q_br1 and q_br3 are bent here. With
    full matching every component is a state of the unbent mounting and all four are bent.

    Returns
    -------
    Lf : ndarray, shape (4, 4)
        ``q_pred = Lf q_rb`` (the left product by Ry(theta), rows 0 and 2 the identity's when
        ``recovered``).
    q_pred : ndarray, shape (4,)
    dq_theta : ndarray, shape (4,)
        ``d q_pred / d theta``: ``1/2 [0, e_Y] (x) q_pred`` in the bent components.
    """
    Lf = kernels.quat_left_matrix(np.array([math.cos(0.5 * theta), 0.0,
                                            math.sin(0.5 * theta), 0.0]))
    q_pred = _mv(Lf, q_rb)
    dq_theta = np.array([-0.5 * q_pred[2], 0.5 * q_pred[3], 0.5 * q_pred[0], -0.5 * q_pred[1]])
    if recovered:
        for r in (0, 2):
            for j in range(4):
                Lf[r, j] = 1.0 if r == j else 0.0
            q_pred[r] = q_rb[r]
            dq_theta[r] = 0.0
    return Lf, q_pred, dq_theta


@kernel
def lever_velocity(q_bn, q_m, w_ib_b, w_in_n, lever_arm_r):
    """(6): ``C_nb (w_nb^b x L^b)`` with ``L^b = C_nb^T C(Q_m) L^r``, NED [m/s], (3,).

    Equal to ``(C_nb w_ib^b - w_in^n) x (C(Q_m) L^r)`` (a rotation preserves cross products).
    """
    a = _mv(kernels.quat_to_dcm(q_bn), w_ib_b)
    for i in range(3):
        a[i] -= w_in_n[i]
    b = _mv(kernels.quat_to_dcm(q_m), lever_arm_r)
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


@kernel
def lever_attitude_jacobian(q_bn, q_m, w_ib_b, lever_arm_r):
    """d z_V / d dQ_bn of the lever-arm velocity term, (3, 4).

    The term rotates the body rate into n with the estimated attitude, so an attitude error
    phi (``C_nb_hat = (I - [phi x]) C_nb``, ``phi = -2 R(Q_bn)^T dQ_bn``) moves it by
    ``-(phi x w_nb^n) x L^n``; z_V subtracts it::

        d z_V / d dQ_bn = -2 [L^n x] [w^n x] R(Q_bn)^T,   w^n = C_nb_hat w_ib^b, L^n = C(Q_m) L^r

    (the earth rate w_in^n is not rotated by the SDINS attitude and does not enter).
    """
    wn = _mv(kernels.quat_to_dcm(q_bn), w_ib_b)
    b = _mv(kernels.quat_to_dcm(q_m), lever_arm_r)
    Rq = rmat(q_bn)
    bw = b[0] * wn[0] + b[1] * wn[1] + b[2] * wn[2]
    out = np.empty((3, 4))
    for j in range(4):  # -2 b x (w x r_j), r_j row j of R: b x (w x r) = w (b.r) - r (b.w)
        br = b[0] * Rq[j, 0] + b[1] * Rq[j, 1] + b[2] * Rq[j, 2]
        for i in range(3):
            out[i, j] = -2.0 * (wn[i] * br - Rq[j, i] * bw)
    return out


def flexure_rate_sigma(sigma: float, zeta: float, wn: float, imu_rate: float) -> float:
    """Flexure rate the lever-arm term misses at the GINS time, 1 sigma [rad/s].

    For the second-order Markov flexure of eq. (19) (steady-state sigma, damping zeta, natural
    frequency wn) the rate is driven by white noise of PSD ``q = 4 zeta wn^3 sigma^2``; over
    one IMU interval it wanders like a random walk, so the rate at the GINS time differs from
    the rate the last interval mean (and its extrapolation) gives by ``sqrt(q dt / 3)``,
    dt = 1 / imu_rate.
    """
    return math.sqrt(4.0 * zeta * wn**3 * sigma**2 / (3.0 * imu_rate))


def velocity_noise(q_m: np.ndarray, lever_arm_r: np.ndarray, vel_sigma: float,
                   rate_sigma: float) -> np.ndarray:
    """R of the north and east velocity rows, (2, 2) [m^2/s^2].

    The GINS white velocity noise plus the lever-arm velocity of the flexure rate the filter
    misses: ``dV = C(Q_m) (dw e_Y x L^r)`` with ``dw ~ N(0, rate_sigma^2)``.
    """
    d = kernels.quat_to_dcm(q_m) @ np.cross([0.0, 1.0, 0.0], lever_arm_r)
    return vel_sigma**2 * np.eye(2) + rate_sigma**2 * np.outer(d[:2], d[:2])


@kernel
def euler_rate_matrix(euler):
    """E of ``w = E d(euler)/dt``: the body rate of the ZYX Euler angle rates, (3, 3).

    A small error ``n`` of the Euler angles [roll, pitch, yaw] is the body-frame rotation
    ``E n``: ``C(euler + n) = C(euler) (I + [E n x])``.
    """
    sr, cr = math.sin(euler[0]), math.cos(euler[0])
    sp, cp = math.sin(euler[1]), math.cos(euler[1])
    E = np.zeros((3, 3))
    E[0, 0] = 1.0
    E[0, 2] = -sp
    E[1, 1] = cr
    E[1, 2] = sr * cp
    E[2, 1] = -sr
    E[2, 2] = cr * cp
    return E


@kernel
def quaternion_noise(z, euler, sigma):
    """Covariance of the measured Q_br ``z = Q_m* (x) Q_bn_hat`` under white GINS Euler-angle
    noise of 1 sigma ``sigma`` [rad] per angle, (4, 4).

    An Euler error n turns Q_m by ``a = E n`` in its body frame (:func:`euler_rate_matrix`),
    ``dQ_m = 1/2 Q_m (x) [0, a]``, so ``dz = dQ_m* (x) Q_bn_hat = -1/2 [0, a] (x) z
    = -1/2 R(z) a`` and ``cov(z) = J sigma^2 J^T`` with ``J = -1/2 R(z) E``. The vector rows
    move by about a / 2; the scalar row only by ``-1/2 z_vec . a``, that is, by the
    misalignment (|z_vec| = sin of half its angle) times the noise: a unit quaternion's scalar
    part is second order in a small rotation.
    """
    J = _mm(rmat(z), euler_rate_matrix(euler))
    return _mmt(J, J) * (0.25 * sigma * sigma)


@kernel
def lever_position(pos, q_m, lever_arm_r):
    """The GINS position displaced by the lever arm ``C(Q_m) L^r`` (NED, first order), (3,).

    Parameters
    ----------
    pos : ndarray, shape (3,)
        GINS latitude, longitude [rad] and height [m].
    q_m : ndarray, shape (4,)
        GINS attitude Q_m.
    lever_arm_r : ndarray, shape (3,)
        Lever arm GINS -> SDINS, ship frame [m].
    """
    d = _mv(kernels.quat_to_dcm(q_m), lever_arm_r)
    R_M, R_N = kernels.radii(pos[0])
    out = np.empty(3)
    out[0] = pos[0] + d[0] / (R_M + pos[2])
    out[1] = pos[1] + d[1] / ((R_N + pos[2]) * math.cos(pos[0]))
    out[2] = pos[2] - d[2]
    return out


@kernel
def predict_and_measure(nav, q_rb, P, s, q_m, v_r, sums, count, w_last, w_prev, lever_arm_r,
                        dt, qc, q_br, nf, theta, phi_f, qd_f, euler, euler_sigma):
    """Steps 2-3 of a cycle up to the correction: the predicted P, z and H.

    Parameters
    ----------
    nav : ndarray, shape (10,)
        SDINS state [lat, lon, h, v_n, q_nb] at the GINS time.
    q_rb : ndarray, shape (4,)
        Q_br estimate.
    P : ndarray, shape (n, n)
        Covariance after the previous cycle.
    s : ndarray of int
        Matched components of Q_br.
    q_m : ndarray, shape (4,)
        GINS attitude Q_m from its Euler angles (either sign).
    v_r : ndarray, shape (3,)
        GINS velocity NED [m/s].
    sums : ndarray, shape (6,)
        Sums of the raw IMU samples [omega_ib_b, f_b] over the filter interval.
    count : int
        Number of samples summed (0: hold the last rate, no specific-force term).
    w_last, w_prev : ndarray, shape (3,)
        The last two raw body rates [rad/s]; the lever-arm term extrapolates them to the GINS
        time (each is a mean over its interval, half a sample old): 1.5 w_last - 0.5 w_prev.
    lever_arm_r : ndarray, shape (3,)
        Lever arm GINS -> SDINS, ship frame [m].
    dt : float
        Filter interval [s].
    qc : ndarray, shape (6,)
        Noise densities squared [q_a x3, q_g x3].
    q_br : float
        Density squared of the dQ_br states [1/s].
    nf : int
        Number of flexure states (0, or 2: theta_f, theta_f' last in the state).
    theta : float
        Flexure angle estimate at the GINS time [rad] (0 without flexure states).
    phi_f, qd_f : ndarray, shape (2, 2)
        Exact transition and process noise of the flexure states over dt
        (:func:`navreplay.core.lti.second_order_markov`; unused without flexure states).
    euler : ndarray, shape (3,)
        GINS Euler angles of the sample [rad].
    euler_sigma : float
        GINS white noise per Euler angle [rad]; 0: none in R2 (the caller adds the paper's
        uniform R).

    Returns
    -------
    P : ndarray, shape (n, n)
        Predicted covariance.
    z : ndarray, shape (2 + len(s),)
        Measurement (3), (5).
    H : ndarray, shape (2 + len(s), n)
        Measurement matrix (15), with the flexure column.
    R2 : ndarray, shape (len(s), len(s))
        R of the quaternion rows: the GINS Euler-angle noise mapped through the measurement
        (:func:`quaternion_noise`) plus the second-order term of the flexure (zero without
        flexure states).
    q_m : ndarray, shape (4,)
        Q_m with the sign of docs/methods/transfer-alignment.md §2.2.
    w_now : ndarray, shape (3,)
        Body rate at the GINS time [rad/s].
    w_in : ndarray, shape (3,)
        w_in^n [rad/s].
    """
    n = P.shape[0]
    ns = s.shape[0]
    q_bn = nav[6:10].copy()
    w_now = np.empty(3)
    w_ib = np.empty(3)
    f_b = np.zeros(3)
    for i in range(3):
        w_now[i] = 1.5 * w_last[i] - 0.5 * w_prev[i]
        if count > 0:  # interval means of the raw IMU for (14)
            w_ib[i] = sums[i] / count
            f_b[i] = sums[3 + i] / count
        else:  # no sample in the interval: hold the last rate, no specific-force term
            w_ib[i] = w_last[i]
    # (4): Q_m* (x) Q_bn_hat; the sign of Q_m puts Q_br in the hemisphere of [1, 0, 0, 0]
    sign = 1.0
    if q_m[0] * q_bn[0] + q_m[1] * q_bn[1] + q_m[2] * q_bn[2] + q_m[3] * q_bn[3] < 0.0:
        sign = -1.0  # (Q_m* (x) Q_bn)_0 is the dot product of Q_m and Q_bn
    q_m = np.array([sign * q_m[0], sign * q_m[1], sign * q_m[2], sign * q_m[3]])
    Lc = kernels.quat_left_matrix(np.array([q_m[0], -q_m[1], -q_m[2], -q_m[3]]))  # L(Q_m*)
    q_br_meas = _mv(Lc, q_bn)

    # prediction: (14), then Phi = I + A dt + (A dt)^2/2 and Qd = G Qc G^T dt (kalman (3), (4))
    R, w_in = earth_terms(nav[0], nav[2], nav[3:6])
    A, G = system_matrix(q_bn, nav[3:6], nav[0], R, w_ib, w_in, f_b, n)
    Gq = np.empty((n, 6))
    for i in range(n):
        for j in range(6):
            Gq[i, j] = G[i, j] * qc[j] * dt
    Qd = _mmt(Gq, G)
    for i in range(6, 6 + ns):
        Qd[i, i] += q_br * dt
    Phi = kalman.discretize(A, dt)
    k = n - nf  # the flexure block, exact (wn dt is not small)
    for i in range(nf):
        for j in range(nf):
            Phi[k + i, k + j] = phi_f[i, j]
            Qd[k + i, k + j] += qd_f[i, j]
    P = kalman.predict_kernel(P, Phi, Qd)  # kalman (3), (6)

    # measurement: (3), (6) velocity; (5) quaternion rows s; H of (15)
    H = np.zeros((2 + ns, n))
    arm = lever_arm_r.copy()
    if nf > 0:  # the lever arm bent with the SDINS: L + theta (e_Y x L)
        arm[0] += theta * lever_arm_r[2]
        arm[2] -= theta * lever_arm_r[0]
    lever_v = lever_velocity(q_bn, q_m, w_now, w_in, arm)
    if nf > 0:
        d_arm = np.array([lever_arm_r[2], 0.0, -lever_arm_r[0]])
        dv = lever_velocity(q_bn, q_m, w_now, w_in, d_arm)
        H[0, k] = -dv[0]
        H[1, k] = -dv[1]
    z = np.empty(2 + ns)
    z[0] = nav[3] - v_r[0] - lever_v[0]
    z[1] = nav[4] - v_r[1] - lever_v[1]
    H[0, 0] = 1.0
    H[1, 1] = 1.0
    # the lever-arm velocity turns with the SDINS attitude error: its dQ_bn columns
    _put(H, 0, 2, lever_attitude_jacobian(q_bn, q_m, w_now, arm)[0:2], 1.0)
    # predicted Q_br: the mounting misalignment bent by the flexure (flexed())
    recovered = True  # q_br2 comes from the attitudes (eq. 11) unless it is matched
    for i in range(ns):
        if s[i] == 2:
            recovered = False
    Lf, q_pred, dq_theta = flexed(q_rb, theta, recovered)
    for i in range(ns):
        z[2 + i] = q_br_meas[s[i]] - q_pred[s[i]]
        for j in range(4):
            H[2 + i, 2 + j] = Lc[s[i], j]
        for j in range(ns):
            H[2 + i, 6 + j] = -Lf[s[i], s[j]]
        if nf > 0:
            H[2 + i, k] = -dq_theta[s[i]]
    # second-order term of the bent components: dq_theta is bilinear in theta and Q_br, so
    # the product of their errors adds 1/4 (P_tt P_ab + P_ta P_tb) (signed) to R; it matters
    # while the 3 deg mounting misalignment is being removed and then vanishes
    R2 = np.zeros((ns, ns))
    if euler_sigma > 0.0:
        Rz = quaternion_noise(q_br_meas, euler, euler_sigma)
        for i in range(ns):
            for j in range(ns):
                R2[i, j] = Rz[s[i], s[j]]
    if nf > 0:
        col = np.full(ns, -1)  # state index of the component each bent row multiplies
        sgn = np.zeros(ns)
        for i in range(ns):
            c, g = _BENT_BY[s[i]], _BENT_SIGN[s[i]]
            bent = not recovered or s[i] == 1 or s[i] == 3  # as in flexed()
            if bent and c != 0:  # row 2 of full matching multiplies q_br0 ~ 1: no product
                for j in range(ns):
                    if s[j] == c:
                        col[i], sgn[i] = 6 + j, g
        for i in range(ns):
            for j in range(ns):
                if col[i] >= 0 and col[j] >= 0:
                    R2[i, j] += 0.25 * sgn[i] * sgn[j] * (P[k, k] * P[col[i], col[j]]
                                                         + P[k, col[i]] * P[k, col[j]])
    return P, z, H, R2, q_m, w_now, w_in


@kernel
def feedback(nav, q_rb, dx, P, s, u, q_m, v_r, pos, w_now, w_in, lever_arm_r):
    """Steps 4-6 of a cycle, in place on nav and q_rb; returns the predicted sigma of phi.

    Parameters
    ----------
    nav : ndarray, shape (10,)
        SDINS state; corrected in place.
    q_rb : ndarray, shape (4,)
        Q_br estimate; corrected in place.
    dx : ndarray, shape (n,)
        Estimated errors of the correction.
    P : ndarray, shape (n, n)
        Corrected covariance.
    s, u : ndarray of int
        Matched and unmatched components of Q_br.
    q_m, v_r, pos, w_now, w_in, lever_arm_r
        As returned by / passed to :func:`predict_and_measure`; ``pos`` is the GINS position.

    Returns
    -------
    sigma_phi : ndarray, shape (3,)
        Predicted 1 sigma of phi N, E, D [rad]: ``Sigma_phi = 4 R^T P_qq R``.
    """
    ns = s.shape[0]
    # x_hat <- x_hat - dx
    nav[3] -= dx[0]
    nav[4] -= dx[1]
    q = np.empty(4)
    for i in range(4):
        q[i] = nav[6 + i] - dx[2 + i]
    _normalise(q)
    for i in range(4):
        nav[6 + i] = q[i]
    for i in range(ns):
        q_rb[s[i]] -= dx[6 + i]
    # (11), E8: unmatched components (q_br2 for partial matching) of Q_m* (x) Q_bn_hat
    q_br_new = _mv(kernels.quat_left_matrix(np.array([q_m[0], -q_m[1], -q_m[2], -q_m[3]])), q)
    scalar = False
    for i in u:
        if i == 0:  # the scalar part is not matched: it follows from the vector part
            scalar = True
        else:
            q_rb[i] = q_br_new[i]
    if scalar:
        q_rb[0] = math.sqrt(max(1.0 - q_rb[1] ** 2 - q_rb[2] ** 2 - q_rb[3] ** 2, 0.0))
    _normalise(q_rb)  # (10), E10
    # the vertical channel and the position are slaved to the GINS (method §4.1)
    nav[5] = v_r[2] + lever_velocity(q, q_m, w_now, w_in, lever_arm_r)[2]
    nav[0:3] = lever_position(pos, q_m, lever_arm_r)
    return attitude_sigma(q, P)


@kernel
def attitude_sigma(q_bn, P):
    """Predicted 1 sigma of phi N, E, D [rad], (3,): phi = -2 R(Q_bn)^T dQ_bn, so
    ``Sigma_phi = 4 R^T P_qq R`` with P_qq the dQ_bn block of P (n, n)."""
    Rq = rmat(q_bn)
    sigma_phi = np.empty(3)
    for i in range(3):
        v = 0.0
        for k in range(4):
            for j in range(4):
                v += Rq[k, i] * P[2 + k, 2 + j] * Rq[j, i]
        sigma_phi[i] = math.sqrt(max(4.0 * v, 0.0))
    return sigma_phi


@kernel
def block_intervals(t, t_prev, omega_ib_b, f_b, sums, last):
    """Sample intervals of an IMU block, the running sums for the means of eq. (14) and the
    increments of the block's last sample.

    (The mechanization itself, :func:`navreplay.geo.strapdown.propagate_kernel`, is called from
    Python, which reports an invalid sample through the checked
    :func:`navreplay.geo.strapdown.propagate`.)

    Parameters
    ----------
    t : ndarray, shape (k,)
        Sample times [s].
    t_prev : float
        Time of the sample before the block [s].
    omega_ib_b, f_b : ndarray, shape (k, 3)
        Raw IMU samples [rad/s], [m/s^2].
    sums : ndarray, shape (6,)
        Running sums [omega, f]; the block is added.
    last : ndarray, shape (6,)
        Receives the increments [dtheta, dv] of the last sample (the coning and sculling terms
        of the next block).

    Returns
    -------
    dt : ndarray, shape (k,)
        [s]
    """
    k = t.shape[0]
    dt = np.empty(k)
    dt[0] = t[0] - t_prev
    for i in range(1, k):
        dt[i] = t[i] - t[i - 1]
    for i in range(k):
        for j in range(3):
            sums[j] += omega_ib_b[i, j]
            sums[3 + j] += f_b[i, j]
    for j in range(3):
        last[j] = omega_ib_b[k - 1, j] * dt[k - 1]
        last[3 + j] = f_b[k - 1, j] * dt[k - 1]
    return dt
