"""Transfer alignment by velocity and quaternion (partial) matching: a 9-state Kalman filter.

Aligns a strapdown slave INS (SDINS, frame b) to a ship's master gimballed INS (GINS, frame r)
while the ship rolls, pitches and bends, after Song, Jeon and Lyou, "A Transfer Alignment
Algorithm Using Velocity and Quaternion Partial Matching Methods" (equation numbers below are
the paper's, with the errata E1-E17 of docs/methods/transfer-alignment.md §7 applied; that
document is the method as navreplay implements it).

The filter matches the lever-arm compensated north and east velocity and three of the four
components of the misalignment quaternion Q_br. The component q_br2, which the ship's Y-axis
(hull bending) flexure corrupts, is left out of the filter and recovered from the SDINS and
GINS attitudes after every update (eq. 11), so that flexure does not bias the azimuth estimate.

Names: the paper's Q_bn is ``q_nb`` (SDINS attitude, rotates b to n), Q_m = Q_rn is ``q_nr``
(GINS attitude from its Euler angles), Q_br is ``q_rb`` (misalignment, rotates b to r); all are
Hamilton, scalar first, and ``q_nb = q_nr (x) q_rb``, hence eq. (4): ``Q_br = Q_m* (x) Q_bn``.

States, eq. (13)
----------------
===== ===================== ====== ===== ================================================
index symbol                frame  unit  meaning
===== ===================== ====== ===== ================================================
0-1   dV_n, dV_e            n      m/s   SDINS north and east velocity error
2-5   dq_bn0 .. dq_bn3      b -> n -     additive error of the SDINS quaternion Q_bn
6-8   dq_br0, dq_br1, dq_br3 b -> r -    additive error of the matched components of Q_br
9-10  theta_f, theta_f'     r      rad   flexure about the ship's Y axis, its rate (rad/s)
===== ===================== ====== ===== ================================================

That is the paper's layout (``quat_model=paper``). navreplay's quaternion measurement model
(``quat_model=gins``, the default, :class:`QuatModel`) matches only the vector components of
the index set (partial {1, 3}, full {1, 2, 3}), so dq_br0 is not a state and the blocks after
it move up by one.

States 9-10 (not in the paper; ``flexure_sigma > 0``, the default;
docs/methods/transfer-alignment.md §4.9) follow the second-order Markov model of eq. (19),
discretised exactly;
they enter the quaternion rows through the misalignment bent by the estimate,
``Ry(theta_f) (x) Q_br`` (:func:`flexed`), and the velocity rows through the lever arm bent
with the SDINS. ``vel_only`` has no row they enter and carries none; ``flexure_sigma = 0``
gives the paper's filters.

Variants (parameter ``match``, :class:`Match`) differ only in the index set s of matched
quaternion components; one code path serves all three:

- ``vel_quat_partial`` (default): s = {0, 1, 3}, 9 states, 2 + 3 measurements;
- ``vel_quat_full``: s = {0, 1, 2, 3}, 10 states, 2 + 4 measurements (flexure unmodelled);
- ``vel_only``: s = {}, 6 states, 2 measurements (azimuth unobservable without manoeuvres).

(The paper's counts, without the flexure states; ``quat_model=gins`` has one state and one
measurement fewer in the first two.)

``Estimate.x`` holds the *total* quantities whose errors are the states:
``[v_N, v_E, q_nb0..3, q_rb[s], theta_f, theta_f']``, and ``Estimate.P`` the covariance of those
errors. The extras ``q_rb`` and ``misalignment_euler`` are Q_br as the attitudes show it now
(bent by the flexure estimate).

Error definitions (signs)
-------------------------
Additive, estimate minus truth::

    dV = V_hat - V,   dQ_bn = Q_bn_hat - Q_bn,   dQ_br = Q_br_hat - Q_br

The correction after an update subtracts: ``x_hat <- x_hat - dx_hat``. For reporting, the
alignment error is the small-angle vector phi [rad] in n with

    C_nb_hat C_nb^T = I - [phi x],   phi = -2 R(Q_bn)^T dQ_bn

(:func:`navreplay.geo.attitude_error`): phi_N, phi_E are the level errors, phi_D the azimuth
error, and a positive phi_D means the estimated heading is smaller than the true one. The
filter's predicted covariance of phi is ``Sigma_phi = 4 R^T P_qq R`` (extras
``attitude_sigma_n``, with the consider terms of :func:`consider_sigma` added in quadrature).
The filter never sees the truth; metrics compute phi against it.

Process model, eqs. (1), (2), (9), (14)
---------------------------------------
Continuous, evaluated at the current estimate (V = [V_n, V_e, V_d], latitude L, earth rate W,
R = sqrt(R_M R_N) + h, f^n = C_nb_hat f^b, f^b and w_ib^b the mean raw IMU samples of the
last filter interval)::

    d/dt [dV; dQ_bn; dQ_br] = A [dV; dQ_bn; dQ_br] + G [n_a; n_g]

    A = [[ M_vv  A_vq  0 ],
         [ A_qv  A_qq  0 ],
         [ 0     0     0 ]]                               dQ_br: random constant (eq. 9, w_rb = 0)
    M_vv = [[ V_d/R,                  -(2 W sinL + 2 V_e tanL/R) ],
            [ 2 W sinL + V_e tanL/R,   (V_d + V_n tanL)/R        ]]           (1), E1, E2
    A_vq = -2 [f^n x]_(N,E) R(Q_bn)^T                                        (1), E3, E4
    A_qv = -1/2 R(Q_bn) Gamma2,  Gamma2 = [[0, 1/R], [-1/R, 0], [0, -tanL/R]]        (2)
    A_qq = 1/2 (right(w_ib^b) - left(w_in^n))            the 4x4 [w_ib - w_in] of (2)
    G    = [[ C_nb(rows N,E)  0          ],
            [ 0               1/2 T(Q_bn) ],
            [ 0               0          ]]
    Phi  = I + A dt + (A dt)^2 / 2,   Q_d = G diag(q_a I3, q_g I3) G^T dt + diag(0, q_br dt I)

Measurement model, eqs. (3), (5), (6), (15)
-------------------------------------------
::

    Z_V = [ V_B_hat - V_R_meas - C_nb_hat (w_nb_hat^b x L^b) ]_(N,E)      (3), (6)
          with w_nb_hat^b = w_ib^b - C_nb_hat^T w_in^n and L^b = C_nb_hat^T C(Q_m) L^r_nom,
          i.e. the lever-arm velocity (C_nb_hat w_ib^b - w_in^n) x (C(Q_m) L^r_nom)
    Z_Q = [ Q_m* (x) Q_bn_hat - Q_br_hat ]_s                                 (5)
          (the paper's s; quat_model=gins drops the scalar component 0)
    H   = [[ I2  H_vq          0      ],
           [ 0   L(Q_m*)[s,:]  -I_s   ]]                                     (15)
    H_vq = -2 [L^n x] [w^n x] R(Q_bn)^T, w^n = C_nb_hat w_ib^b, L^n = C(Q_m) L^r_nom
          (the lever-arm term turns with the attitude error; not in the paper's eq. 15)

The rate w_ib^b of the lever-arm term is extrapolated to the GINS time from the last two IMU
samples (each a mean over its interval, half a sample old). R of the velocity rows: r_v I2 plus
the flexure rate the lever-arm term misses (:func:`velocity_noise`). R of the quaternion rows:
``quat_model=gins``, the GINS Euler-angle noise mapped through the measurement,
``J Sigma J^T`` with ``J = -1/2 R(Z) E`` (:func:`quaternion_noise`), correlated; the scalar
part moves only by the misalignment times the noise, and that row, with its true R, would
over-constrain the additive quaternion error (its norm direction, which the normalisations
correct without P), so it is not matched: it follows from the vector part. ``quat_model=paper``:
``quat_sigma^2`` on every row of the paper's s, the scalar row included.

Cycle (at every GINS sample)
----------------------------
1. SDINS mechanization (:func:`navreplay.geo.strapdown.propagate_kernel`) at the IMU rate, raw
   IMU, with the coning and sculling terms carried across blocks.
2. Q_m from the GINS Euler angles, its sign such that ``(Q_m* (x) Q_bn_hat)_0 >= 0``.
3. Predict P with (Phi, Q_d) (:func:`predict_and_measure`); update with the shared Cholesky /
   Joseph-form correction, :func:`navreplay.filters.kalman.correct`.
4. Feedback: V_ne -= dV; Q_bn -= dQ_bn, normalised; Q_br[s] -= dQ_br.
5. Recover the unmatched vector components u of Q_br (q_br2 for partial matching, eq. 11, E8)
   as component u of ``Q_m* (x) Q_bn_hat``; an unmatched scalar part follows from the vector
   part, ``sqrt(1 - |q_vec|^2)``; then normalise Q_br (eq. 10, E10).
6. Slave the SDINS vertical velocity and the position to the GINS (the vertical channel is not
   a state): ``V_d = V_R,d + [lever-arm velocity]_d``, position = the GINS position displaced
   by ``C(Q_m) L^r`` (:func:`lever_position`).
7. x = 0; P keeps its value through the normalisations (as in the paper) and is checked to be
   symmetric and PSD.

Initialisation, eqs. (16), (17)
-------------------------------
At the first GINS sample after an IMU sample: ``Q_bn_hat = Q_m``, ``Q_br_hat = [1, 0, 0, 0]``,
``V_B_hat = V_R_meas + lever-arm velocity``, the position as in step 6. Because the SDINS starts from the GINS attitude,
``dQ_bn = L(Q_m) dQ_br`` (eq. 16) and P0 is full (eq. 17, E16), with
``P_hat = diag(p0, p1, p1, p1)``, ``p0 = init_q0_sigma^2``,
``p1 = sin(init_misalignment / 2)^2``, ``r_V = init_vel_sigma^2``::

    P0 = [[ r_V I2   0                   0               ],
          [ 0        L P_hat L^T         L P_hat[:, s]   ],
          [ 0        P_hat[s, :] L^T     P_hat[s, s]     ]],   L = L(Q_m(0))

plus ``quat_sigma^2 T(Q_m) T(Q_m)^T`` on the dQ_bn block: the start holds the GINS noise of
that one sample, which Q_br does not share (:func:`initial_covariance`).

Lever arm
---------
``lever_arm_r`` is the surveyed GINS-to-SDINS lever arm in the ship frame. When it is not set,
the filter reads ``Metadata.params["lever_arm_r_nom"]`` (the ship-transfer-alignment scenario
writes the nominal lever arm there, with its knowledge error) and fails if that is missing.

Implementation
--------------
The model, the prediction and the feedback (steps 2, 3 and 4-6) are numba kernels,
:func:`predict_and_measure` and :func:`feedback`, around the shared discretisation, prediction
kernel, correction and covariance check of :mod:`navreplay.filters.kalman`. The tests check the model functions against finite
differences of the nonlinear equations and against :mod:`navreplay.geo`, and the prediction
against :func:`navreplay.filters.kalman.predict`.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping
from typing import Any

import numba
import numpy as np

from navreplay.core.lti import second_order_markov
from navreplay.core.streams import StreamKind
from navreplay.core.units import ARCMIN, DEG, FOOT, G0, MICRO_G
from navreplay.filters import kalman
from navreplay.filters.base import (
    Estimate,
    Filter,
    FilterContext,
    FilterParams,
    Innovation,
    MeasurementKind,
    NavSolution,
    Quantity,
    State,
    TruthColumn,
    check_number,
)
from navreplay.filters.registry import register_filter
from navreplay.geo import earth, kernels, strapdown
from navreplay.sensors.imu import ImuModel
from navreplay.sensors.master_ins import MasterInsModel
from navreplay.sensors.specs import SensorSpecs


class Match(enum.StrEnum):
    """What the filter matches (docs/methods/transfer-alignment.md §5)."""

    VEL_QUAT_PARTIAL = "vel_quat_partial"
    """Velocity + quaternion components {0, 1, 3} (the paper's proposal)."""
    VEL_QUAT_FULL = "vel_quat_full"
    """Velocity + all four quaternion components."""
    VEL_ONLY = "vel_only"
    """Velocity only (azimuth unobservable without manoeuvres)."""

    @property
    def components(self) -> tuple[int, ...]:
        """Index set s of the matched components of Q_br."""
        return _COMPONENTS[self]


class QuatModel(enum.StrEnum):
    """Model of the quaternion measurement (docs/methods/transfer-alignment.md §4.4)."""

    GINS = "gins"
    """The vector components of the match, with R the GINS Euler-angle noise mapped through
    the measurement (:func:`quaternion_noise`); the scalar part is not matched: it is a
    function of the vector part (unit norm), and its row with its true, tiny R over-constrains
    the additive error model."""
    PAPER = "paper"
    """The paper's rows (the scalar q_br0 included) with the same R, ``quat_sigma``, on each."""


_COMPONENTS = {
    Match.VEL_QUAT_PARTIAL: (0, 1, 3),
    Match.VEL_QUAT_FULL: (0, 1, 2, 3),
    Match.VEL_ONLY: (),
}

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


TABLE_2 = SensorSpecs(
    {"imu": ImuModel(accel_bias=250.0 * MICRO_G, accel_misalignment=1.0 * ARCMIN),
     "master_ins": MasterInsModel(tilt=(3.0 * ARCMIN, 3.0 * ARCMIN, 5.0 * ARCMIN),
                                  synchro_bias=3.0 * ARCMIN, synchro_noise=1.0 * ARCMIN,
                                  vel_bias=0.7 * FOOT, vel_noise=0.3 * FOOT)},
    known={"imu": ("accel_bias", "accel_misalignment")},
    sources={"imu": "Table 2 of docs/methods/transfer-alignment.md (the SDINS)",
             "master_ins": "the GINS of docs/methods/transfer-alignment.md §3.2"},
)
"""The sensors the defaults of :class:`TransferAlignmentParams` stand for (those of its
settings that follow from sensors): the SDINS accelerometer of Table 2 and the ship's GINS."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class TransferAlignmentParams(FilterParams):
    """Parameters of the transfer-alignment filter (SI). Tuning defaults:
    docs/methods/transfer-alignment.md §4.3-4.5."""

    match: Match = Match.VEL_QUAT_PARTIAL
    """Matched quantities: vel_quat_partial, vel_quat_full or vel_only."""
    quat_model: QuatModel = QuatModel.GINS
    """Quaternion measurement model: gins (vector rows, R from ``gins_euler_noise``) or paper
    (the paper's rows and R, ``quat_sigma``)."""
    lever_arm_r: tuple[float, float, float] | None = None
    """Surveyed lever arm GINS -> SDINS in the ship frame (X, Y, Z) [m]; None: the recording's
    ``Metadata.params["lever_arm_r_nom"]``."""
    accel_noise: float = 5e-4
    """Velocity process noise density sqrt(q_a) [(m/s)/sqrt(s)]."""
    gyro_noise: float = 3e-5
    """Attitude process noise density sqrt(q_g) [rad/sqrt(s)]."""
    misalignment_noise: float = 1e-6
    """Process noise density of the dQ_br states sqrt(q_br) [1/sqrt(s)]."""
    vel_sigma: float = 0.3 * FOOT
    """Velocity measurement noise, 1 sigma per axis [m/s] (the GINS white velocity noise)."""
    gins_euler_noise: float = 1.0 * ARCMIN
    """GINS white noise per Euler angle, 1 sigma [rad] (the synchro noise): the R of the
    quaternion rows of ``quat_model=gins`` is this noise mapped through the measurement,
    ``J sigma^2 J^T`` (:func:`quaternion_noise`), correlated across the rows."""
    quat_sigma: float = 0.5 * ARCMIN
    """The paper's quaternion measurement noise (``quat_model=paper``), 1 sigma per component
    [-]: half the GINS synchro white noise of 1 arcmin per Euler angle (a small rotation phi
    moves a vector component by phi / 2), the scalar row included. It also sets the GINS noise
    of the starting attitude of that model."""
    init_vel_sigma: float = 0.25
    """Initial velocity error, 1 sigma per axis [m/s]."""
    init_misalignment: float = 3.0 * DEG
    """Initial mounting misalignment per axis [rad]; p1 = sin(init_misalignment / 2)^2."""
    init_q0_sigma: float = 1.5e-3
    """Initial 1 sigma of the scalar part of dQ_br, sqrt(p0) [-]."""
    flexure_sigma: float = 0.5 * DEG
    """Steady-state 1 sigma of the ship's Y-axis flexure angle theta_f [rad], modelled as two
    states (theta_f, theta_f'), the second-order Markov process of eq. (19); they bend the
    misalignment in the quaternion rows and the lever arm in the velocity rows
    (:func:`predict_and_measure`). 0: no flexure states (the paper's filters). Only with
    quaternion matching (``vel_only`` carries none)."""
    flexure_zeta: float = 0.7
    """Damping ratio of the flexure model [-]."""
    flexure_wn: float = 2.0 * math.pi
    """Natural frequency of the flexure model [rad/s]."""
    flexure_rate_sigma: float = 0.0133
    """1 sigma of the flexure rate about the ship's Y axis that the lever-arm term misses at
    the GINS time [rad/s]: the body rate is extrapolated from the last IMU samples, and the
    flexure rate wanders in the meantime (:func:`flexure_rate_sigma`; 0.0133 for the
    scenario's default flexure at 100 Hz, 0 without flexure)."""

    accel_bias_sigma: float = 250.0 * MICRO_G
    """SDINS accelerometer bias, 1 sigma per axis [m/s^2] (Table 2): not a state; a consider
    term of the reported attitude sigma (0: the paper's sigma, from P alone)."""
    accel_misalignment_sigma: float = 1.0 * ARCMIN
    """SDINS accelerometer misalignment, 1 sigma per off-diagonal term [rad] (Table 2):
    consider term of the level sigma."""
    gins_heading_sigma: float = math.hypot(5.0 * ARCMIN, 3.0 * ARCMIN)
    """Constant error of the GINS heading, 1 sigma [rad]: platform tilt eps_D (5 arcmin) and
    synchro yaw bias (3 arcmin). Consider term of the azimuth sigma of quaternion matching."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "match", Match(self.match))
        object.__setattr__(self, "quat_model", QuatModel(self.quat_model))
        for name in ("accel_bias_sigma", "accel_misalignment_sigma", "gins_heading_sigma"):
            check_number(self, name, positive=False)
        for name in ("accel_noise", "gyro_noise", "misalignment_noise", "vel_sigma",
                     "quat_sigma", "init_vel_sigma", "init_misalignment", "init_q0_sigma",
                     "gins_euler_noise"):
            check_number(self, name, positive=True)
        for name in ("flexure_rate_sigma", "flexure_sigma"):
            check_number(self, name, positive=False)
        for name in ("flexure_zeta", "flexure_wn"):
            check_number(self, name, positive=True)
        if self.init_misalignment >= math.pi:
            raise ValueError(f"init_misalignment must be < pi rad, got {self.init_misalignment}")
        if self.lever_arm_r is not None:
            arm = tuple(float(v) for v in self.lever_arm_r)
            if len(arm) != 3 or not all(math.isfinite(v) for v in arm):
                raise ValueError(f"lever_arm_r needs three finite values, got {self.lever_arm_r}")
            object.__setattr__(self, "lever_arm_r", arm)


# --------------------------------------------------------------------------------------------
# The model as numba kernels: the per-GINS-sample model and feedback are ~40 small matrix
# operations, which numpy pays for in call overhead. The quaternion and earth-model helpers are
# the single-value kernels of navreplay.geo.kernels; the discretisation, the prediction, the
# correction and the covariance check are the shared ones of navreplay.filters.kalman.


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
def _mv(A, x):
    """A @ x."""
    n, k = A.shape
    out = np.zeros(n)
    for i in range(n):
        for l in range(k):
            out[i] += A[i, l] * x[l]
    return out


@numba.njit(cache=True)
def _put(A, i0, j0, B, scale):
    """A[i0:i0+k, j0:j0+m] = scale B (loops: 2-D slice expressions compile slowly in numba)."""
    for i in range(B.shape[0]):
        for j in range(B.shape[1]):
            A[i0 + i, j0 + j] = scale * B[i, j]


@numba.njit(cache=True)
def _normalise(q):
    """q / |q| in place."""
    k = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for i in range(4):
        q[i] *= k


@numba.njit(cache=True)
def rmat(q):
    """The paper's R(q), (4, 3): ``[0, w] (x) q = R(q) w``, columns 1-3 of the right-product
    matrix M(q) (:func:`navreplay.geo.kernels.quat_right_matrix`)."""
    return kernels.quat_right_matrix(q)[:, 1:]


@numba.njit(cache=True)
def tmat(q):
    """The paper's T(q), (4, 3): ``q (x) [0, w] = T(q) w``, columns 1-3 of the left-product
    matrix L(q) (:func:`navreplay.geo.kernels.quat_left_matrix`)."""
    return kernels.quat_left_matrix(q)[:, 1:]


@numba.njit(cache=True)
def rate_matrix(w_ib, w_in):
    """The 4x4 ``[w_ib^b - w_in^n]`` of eq. (2): ``M([0, w_ib]) - L([0, w_in])``, (4, 4)."""
    W = kernels.quat_right_matrix(np.array([0.0, w_ib[0], w_ib[1], w_ib[2]]))
    W -= kernels.quat_left_matrix(np.array([0.0, w_in[0], w_in[1], w_in[2]]))
    return W


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


FLEXURE_STATES = (
    State("theta_f", "rad", Quantity.MISALIGNMENT, TruthColumn("theta_f")),
    State("theta_f_rate", "rad/s", Quantity.MISALIGNMENT, TruthColumn("theta_f_rate")),
)
"""The flexure states: angle and rate of the hull bending about the ship's Y axis."""
_NO_FLEXURE = (np.eye(2), np.zeros((2, 2)))


def consider_sigma(params: TransferAlignmentParams, matched: bool) -> np.ndarray:
    """1 sigma of the attitude errors that constant errors outside the state leave [rad], (3,).

    The filter cannot tell a horizontal accelerometer error from a level error (velocity
    matching aligns the level axes to the accelerometers), nor, with quaternion matching, the
    GINS heading error from an azimuth error: once converged, phi_N, phi_E carry
    ``sqrt(b_a^2 + (g m_a)^2) / g`` (bias and the misalignment that tilts the vertical specific
    force into the horizontal) and phi_D the GINS heading error. These are the consider
    (Schmidt) terms of the unobservable constants; the reported sigma adds them to
    ``4 R^T P_qq R`` in quadrature. Without quaternion matching (``matched`` False) the azimuth
    does not come from the GINS heading, and its term is 0.
    """
    level = math.hypot(params.accel_bias_sigma, G0 * params.accel_misalignment_sigma) / G0
    return np.array([level, level, params.gins_heading_sigma if matched else 0.0])


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


def initial_covariance(
    q_m: np.ndarray, s: np.ndarray, vel_var: float, p0: float, p1: float,
    flexure: tuple[float, float] | None = None, quat_var: float | np.ndarray = 0.0,
) -> np.ndarray:
    """P0 of eq. (17) for the matched index set s, of the flexure states, and the GINS
    attitude noise the SDINS starts with.

    Parameters
    ----------
    q_m : ndarray, shape (4,)
        GINS attitude Q_m at the initialisation.
    s : ndarray of int
        Matched components of Q_br.
    vel_var : float
        Initial velocity error variance per axis [(m/s)^2].
    p0, p1 : float
        Variances of the scalar and of each vector component of dQ_br [-].
    flexure : (sigma, wn) or None
        Flexure states last, at their stationary covariance ``diag(sigma^2, (wn sigma)^2)``
        [rad], [rad/s]; None: no flexure states.
    quat_var : float or ndarray, shape (3, 3)
        Covariance of n, the GINS white attitude noise as ``dQ_m = T(Q_m) n`` [-]: a variance
        per component (``quat_sigma`` squared, the paper's R), or ``1/4 E Sigma E^T`` of the
        Euler-angle noise (:func:`euler_rate_matrix`). The SDINS starts from the *measured*
        Q_m, so its attitude error holds that sample's noise, which Q_br does not share:
        ``dQ_bn = L(Q_m) dQ_br + T(Q_m) n``,
        ``n ~ N(0, quat_var)``. Without it eq. (17) declares ``dQ_bn - L(Q_m) dQ_br``
        exactly zero, a constraint that only the ship's rolling and pitching can relax: the
        filter stays optimistic in attitude, and so in velocity, for the first 10-20 s.

    Returns
    -------
    ndarray, shape (n, n), n = 6 + len(s) (+ 2 with the flexure states)
    """
    ns = len(s)
    n = N_NAV + ns + (2 if flexure is not None else 0)
    br = slice(N_NAV, N_NAV + ns)
    P_hat = np.diag([p0, p1, p1, p1])
    Lm = kernels.quat_left_matrix(q_m)
    P = np.zeros((n, n))
    P[DV, DV] = vel_var * np.eye(2)
    Tm = Lm[:, 1:]  # T(Q_m): the start's own noise, a rotation of Q_m
    Qn = quat_var * np.eye(3) if np.ndim(quat_var) == 0 else np.asarray(quat_var)
    P[DQ_BN, DQ_BN] = Lm @ P_hat @ Lm.T + Tm @ Qn @ Tm.T  # (16): dQ_bn = L(Q_m) dQ_br
    P[DQ_BN, br] = Lm @ P_hat[:, s]
    P[br, DQ_BN] = P[DQ_BN, br].T
    P[br, br] = P_hat[np.ix_(s, s)]
    if flexure is not None:
        sigma, wn = flexure
        P[n - 2, n - 2] = sigma**2
        P[n - 1, n - 1] = (wn * sigma) ** 2
    return P


@register_filter
class TransferAlignment(Filter):
    """SDINS transfer alignment to a ship's GINS: velocity + quaternion (partial) matching."""

    name = "transfer-alignment"
    summary = (
        "Shipboard transfer alignment, velocity + quaternion partial matching (Song et al.);"
        " match=vel_quat_partial|vel_quat_full|vel_only"
    )
    requires = (StreamKind.IMU, StreamKind.MASTER_INS)
    initial = ()  # starts from the first master INS sample
    Params = TransferAlignmentParams
    scored_extras = (
        State("misalignment_euler", "rad", Quantity.MISALIGNMENT,
              TruthColumn("misalignment_euler")),
        State("q_rb", "-", Quantity.MISALIGNMENT, TruthColumn("q_rb")),
    )

    @classmethod
    def settings_from_sensors(cls, sensors: SensorSpecs) -> dict[str, Any]:
        """The settings the SDINS IMU and GINS specifications give (SI)::

            vel_sigma              = GINS velocity white noise (RMS over the axes)
            gins_euler_noise       = GINS synchro white noise (RMS over the angles)
            quat_sigma             = gins_euler_noise / 2
            gins_heading_sigma     = sqrt(tilt_D^2 + synchro_bias_yaw^2)
            accel_bias_sigma, accel_misalignment_sigma = the IMU's

        The process noise (``accel_noise``, ``gyro_noise``) stays a tuning value: it covers the
        ship's flexure and lever-arm motion besides the IMU noise
        (docs/methods/transfer-alignment.md §4.3)."""
        out: dict[str, Any] = {}
        gins, imu = sensors.master_ins, sensors.imu

        def rms(v: Any) -> float:
            return float(np.sqrt(np.mean(np.square(v))))

        if sensors.has("master_ins", "vel_noise"):
            out["vel_sigma"] = rms(gins.vel_noise)
        if sensors.has("master_ins", "synchro_noise"):
            out["gins_euler_noise"] = rms(gins.synchro_noise)
            out["quat_sigma"] = 0.5 * rms(gins.synchro_noise)
        if sensors.has("master_ins", "tilt", "synchro_bias"):
            out["gins_heading_sigma"] = math.hypot(gins.tilt[2], gins.synchro_bias[2])
        for name in ("accel_bias", "accel_misalignment"):
            if sensors.has("imu", name):
                out[f"{name}_sigma"] = getattr(imu, name)
        return out

    @classmethod
    def default_sensors(cls) -> SensorSpecs:
        return TABLE_2

    def __init__(self, params: TransferAlignmentParams, context: FilterContext) -> None:
        super().__init__(params, context)
        p = params
        if p.lever_arm_r is not None:
            arm = p.lever_arm_r
        else:
            arm = context.metadata.params.get("lever_arm_r_nom")
            if arm is None:
                raise ValueError(
                    "transfer-alignment: set the filter parameter lever_arm_r (the recording's"
                    " metadata has no params.lever_arm_r_nom)"
                )
        self.lever_arm_r = np.asarray(arm, dtype=float)
        if self.lever_arm_r.shape != (3,) or not np.all(np.isfinite(self.lever_arm_r)):
            raise ValueError(f"transfer-alignment: lever arm needs three finite values, got {arm!r}")
        paper = p.quat_model == QuatModel.PAPER
        self.s = np.array([c for c in p.match.components if c or paper], dtype=np.int64)
        self.u = np.array([i for i in range(4) if i not in p.match.components], dtype=np.int64)
        # the flexure states enter only the quaternion rows
        self.nf = 2 if p.flexure_sigma > 0.0 and len(self.s) else 0
        self.n = N_NAV + len(self.s) + self.nf
        self.states = (
            State("v_N", "m/s", Quantity.VELOCITY),
            State("v_E", "m/s", Quantity.VELOCITY),
            *(State(f"q_nb{i}", "-", Quantity.ATTITUDE) for i in range(4)),
            *(State(f"q_rb{i}", "-", Quantity.MISALIGNMENT) for i in self.s),
            *FLEXURE_STATES[: self.nf],
        )
        self.measurements = (MeasurementKind("velocity", ("N", "E"), "m/s"),) + (
            (MeasurementKind("quaternion", tuple(f"q{i}" for i in self.s), "-"),)
            if len(self.s) else ())  # eq. (15): rows ZV, ZQ
        self.flex = np.zeros(2)  # theta_f, theta_f' estimates [rad, rad/s]
        self._flex_model: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._qc = np.array([p.accel_noise**2] * 3 + [p.gyro_noise**2] * 3)
        self._q_br = p.misalignment_noise**2
        # R of the quaternion rows: the paper's, uniform, or the GINS noise mapped
        self._r_q = p.quat_sigma**2 if paper else 0.0
        self._euler_noise = 0.0 if paper else p.gins_euler_noise
        self._x0 = np.zeros(self.n)

        self.t = 0.0
        self.nav: np.ndarray | None = None  # [lat, lon, h, v_n, q_nb], strapdown layout
        self.q_rb = np.array([1.0, 0.0, 0.0, 0.0])  # Q_br, the matched part unbent (flexed())
        self.P = np.zeros((self.n, self.n))
        self.sigma_phi = np.zeros(3)
        self._consider = consider_sigma(params, len(self.s) > 0)
        # IMU bookkeeping: last sample time, last two rates, the increments of the last sample
        # (coning and sculling of the next) and the sums [omega, f] for the means of eq. (14)
        self._t_imu: float | None = None
        self._w_last: np.ndarray | None = None
        self._w_prev: np.ndarray | None = None
        self._prev = np.zeros(6)
        self._last = np.zeros(6)
        self._sums = np.zeros(6)
        self._count = 0

    # ---------------------------------------------------------------------------------------
    # engine callbacks

    def propagate(self, t: np.ndarray, imu: Mapping[str, np.ndarray]) -> None:
        w = imu["omega_ib_b"]
        f = imu["f_b"]
        k = t.shape[0]
        if w.shape != (k, 3) or f.shape != (k, 3):
            raise ValueError(
                f"IMU block: expected omega_ib_b and f_b of shape ({k}, 3), got {w.shape}, "
                f"{f.shape}"
            )
        if self.nav is not None:
            # step 1: SDINS mechanization with the raw IMU
            dt = block_intervals(t, self._t_imu, w, f, self._sums, self._last)
            nav = np.empty(strapdown.NAV_SIZE)
            bad = strapdown.propagate_kernel(self.nav, w, f, dt, self._prev, nav)
            if bad != -1:  # let the checked wrapper name the bad sample
                strapdown.propagate(self.nav, w, f, dt)
                raise ValueError(f"IMU block at t = {t[0]:.6f} s: invalid sample {bad}")
            self.nav = nav
            self._prev, self._last = self._last, self._prev
            self._count += k
        elif k > 1 or self._t_imu is not None:
            dt_last = t[-1] - (t[-2] if k > 1 else self._t_imu)
            self._prev[0:3] = w[-1] * dt_last
            self._prev[3:6] = f[-1] * dt_last
        self._w_prev = w[-2] if k > 1 else self._w_last if self._w_last is not None else w[0]
        self._w_last = w[-1]
        self._t_imu = float(t[-1])

    def update(
        self, kind: StreamKind, t: float, sample: Mapping[str, Any]
    ) -> list[Innovation] | None:
        if kind != StreamKind.MASTER_INS:
            return None
        euler = sample["euler"]
        v_r = sample["v_n"]
        pos = sample["pos"]
        if euler.shape != (3,) or v_r.shape != (3,) or pos.shape != (3,):
            raise ValueError("master_ins sample: euler, v_n and pos must have shape (3,)")
        q_m = kernels.euler_to_quat(euler)
        if self.nav is None:
            if self._w_last is not None:  # the lever-arm velocity needs a body rate
                self._initialise(t, q_m, euler, v_r, pos)
            return None
        return self._step(t, q_m, euler, v_r, pos)

    def estimate(self) -> Estimate | None:
        if self.nav is None:
            return None
        nav = self.nav
        q_rb = flexed(self.q_rb, self.flex[0], 2 not in self.s)[1]  # bent by the flexure
        return Estimate(
            t=self.t,
            x=np.concatenate((nav[3:5], nav[6:10], self.q_rb[self.s], self.flex[: self.nf])),
            P=self.P.copy(),
            nav=NavSolution.from_vector(nav.copy()),  # nav is corrected in place
            extras={
                "q_rb": q_rb,
                "misalignment_euler": kernels.quat_to_euler(q_rb),
                "attitude_sigma_n": self.sigma_phi.copy(),
            },
        )

    # ---------------------------------------------------------------------------------------
    # steps

    def _start_noise(self, euler: np.ndarray) -> float | np.ndarray:
        """Covariance of the GINS white attitude noise in the starting attitude, as the
        ``quat_var`` of :func:`initial_covariance`."""
        sigma = self._euler_noise
        if sigma == 0.0:
            return self.params.quat_sigma**2
        E = euler_rate_matrix(euler)
        return 0.25 * sigma**2 * E @ E.T

    def _initialise(
        self, t: float, q_m: np.ndarray, euler: np.ndarray, v_r: np.ndarray, pos: np.ndarray
    ) -> None:
        """(16), (17): start from the GINS attitude, lever-arm compensated GINS velocity."""
        p = self.params
        _, w_in = earth_terms(pos[0], pos[2], v_r)
        w_now = 1.5 * self._w_last - 0.5 * self._w_prev  # as in predict_and_measure()
        v_b = v_r + lever_velocity(q_m, q_m, w_now, w_in, self.lever_arm_r)
        self.nav = np.concatenate((lever_position(pos, q_m, self.lever_arm_r), v_b, q_m))
        self.q_rb = np.array([1.0, 0.0, 0.0, 0.0])
        self.flex = np.zeros(2)  # the mean of the stationary flexure
        self.P = initial_covariance(
            q_m, self.s, p.init_vel_sigma**2, p.init_q0_sigma**2,
            math.sin(0.5 * p.init_misalignment) ** 2,
            (p.flexure_sigma, p.flexure_wn) if self.nf else None,
            self._start_noise(euler),
        )
        kalman.check_covariance(self.P, name="P0", t=t)
        self.sigma_phi = np.hypot(attitude_sigma(q_m, self.P), self._consider)
        self.t = t
        self._reset_sums()

    def _flexure_model(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact transition and process noise of the flexure states over dt (the identity and
        zero without them); cached per interval in nanoseconds."""
        if not self.nf:
            return _NO_FLEXURE
        key = round(dt * 1e9)
        if key not in self._flex_model:
            p = self.params
            self._flex_model[key] = second_order_markov(p.flexure_sigma, p.flexure_zeta,
                                                        p.flexure_wn, dt)
        return self._flex_model[key]

    def _reset_sums(self) -> None:
        self._sums[:] = 0.0
        self._count = 0

    def _step(
        self, t: float, q_m: np.ndarray, euler: np.ndarray, v_r: np.ndarray, pos: np.ndarray
    ) -> list[Innovation]:
        dt = t - self.t
        if not dt > 0.0:
            raise ValueError(f"master_ins time does not increase: {t} s after {self.t} s")
        phi_f, qd_f = self._flexure_model(dt)
        self.flex = phi_f @ self.flex
        P, z, H, R2, q_m, w_now, w_in = predict_and_measure(
            self.nav, self.q_rb, self.P, self.s, q_m, v_r, self._sums, self._count,
            self._w_last, self._w_prev, self.lever_arm_r, dt, self._qc, self._q_br,
            self.nf, self.flex[0], phi_f, qd_f, euler, self._euler_noise,
        )
        R = np.zeros((len(z), len(z)))
        R[ZQ, ZQ] = R2 + self._r_q * np.eye(len(self.s))
        R[ZV, ZV] = velocity_noise(q_m, self.lever_arm_r, self.params.vel_sigma,
                                   self.params.flexure_rate_sigma)
        c = kalman.correct(self._x0, P, z, H, R, t=t)  # also step 7's check of P
        if self.nf:
            self.flex -= c.x[self.n - 2:]
        sigma_phi = feedback(self.nav, self.q_rb, c.x, c.P, self.s, self.u, q_m, v_r, pos,
                             w_now, w_in, self.lever_arm_r)
        self.P = c.P
        self.sigma_phi = np.hypot(sigma_phi, self._consider)
        self.t = t
        self._reset_sums()
        out = [c.innovation("velocity", t, ZV)]
        if len(self.s):
            out.append(c.innovation("quaternion", t, ZQ))
        return out
