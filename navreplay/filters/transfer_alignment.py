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
``V_B_hat = V_R_meas + lever-arm velocity``, the position as in step 6. Because the SDINS starts
from the GINS attitude, ``dQ_bn = L(Q_m) dQ_br`` (eq. 16) and P0 is full (eq. 17, E16), with
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
kernel, correction and covariance check of :mod:`navreplay.filters.kalman`. The tests check the
model functions against finite differences of the nonlinear equations and against
:mod:`navreplay.geo`, and the prediction against :func:`navreplay.filters.kalman.predict`."""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping
from typing import Any

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
from navreplay.filters.transfer_alignment_model import (
    DQ_BN,
    DV,
    N_NAV,
    ZQ,
    ZV,
    attitude_sigma,
    block_intervals,
    earth_terms,
    euler_rate_matrix,
    feedback,
    flexed,
    lever_position,
    lever_velocity,
    predict_and_measure,
    velocity_noise,
)
from navreplay.geo import kernels, strapdown
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


TABLE_2 = SensorSpecs(
    {"imu": ImuModel(accel_bias=250.0 * MICRO_G, accel_misalignment=1.0 * ARCMIN),
     "master_ins": MasterInsModel(tilt=(3.0 * ARCMIN, 3.0 * ARCMIN, 5.0 * ARCMIN),
                                  synchro_bias=3.0 * ARCMIN, synchro_noise=1.0 * ARCMIN,
                                  vel_bias=0.7 * FOOT, vel_noise=0.3 * FOOT)},
    known={"imu": frozenset({"accel_bias", "accel_misalignment"})},
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
    params: TransferAlignmentParams
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
        gins, imu = sensors.get("master_ins"), sensors.get("imu")  # read only where stated

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
        arm: Any
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
            raise ValueError(
                f"transfer-alignment: lever arm needs three finite values, got {arm!r}"
            )
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
        assert self._w_last is not None and self._w_prev is not None  # an IMU block came first
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
