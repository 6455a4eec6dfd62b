"""RPM velocity-aided underwater INS with sea-current estimation ("rpm-aided-ins").

An indirect feedback Kalman filter with the 24 error states of Choi (JANT 23(3), 2019) and
three gyro z-rate and six accelerometer scale-factor / misalignment states (method
docs/methods/rpm-aided-ins.md §4). The NED strapdown mechanization of :mod:`navreplay.geo.strapdown`
runs on the compensated IMU at the IMU rate; every ``cov_step`` (0.1 s) the error covariance is
propagated with the 33-state error model; at ``update_rate`` (1 Hz) the propeller-RPM water speed
and the depth sensor correct the errors, and the estimates are fed back. Besides the navigation
errors and the IMU biases the filter estimates the RPM scale factor, the RPM-axis misalignment and
the horizontal sea current, which removes the drift a current causes when water-relative speed is
used as ground speed.

States (eq. 20, NED order)
--------------------------
===== =================== ========= ======== ===============================================
index name (Estimate.x)   frame     unit     error state dx (``Estimate.x`` holds)
===== =================== ========= ======== ===============================================
0     dlat                -         rad      latitude error (0 after feedback)
1     dlon                -         rad      longitude error (0)
2     dd                  -         m        depth error, positive down (0)
3-5   dv_N, dv_E, dv_D    n (NED)   m/s      velocity error (0)
6-8   phi_N, phi_E, phi_D n         rad      attitude error, phi angle (0)
9-11  b_a_x, b_a_y, b_a_z b (FRD)   m/s^2    accelerometer bias error (bias estimate)
12-14 b_g_x, b_g_y, b_g_z b (FRD)   rad/s    gyro bias error (bias estimate)
15    k_rpm               -         -        RPM scale-factor error (k estimate)
16-17 m_y, m_z            b (FRD)   rad      RPM-axis misalignment error (m estimate)
18-19 vc_N, vc_E          n (NED)   m/s      sea-current velocity error (current estimate)
20-22 mu_x, mu_y, mu_z    b         rad      mounting misalignment (transfer alignment; inert)
23    dT                  -         s        master data delay (transfer alignment; inert)
24-25 m_g_xz, m_g_yz      b (FRD)   rad      gyro misalignment of the z rate into x, y (estimate)
26    s_g_z               b (FRD)   -        gyro z scale-factor error (estimate)
27-32 s_a_x, m_a_yx, ...  b (FRD)   -, rad   accelerometer columns x, y of S_a + M_a (estimate)
===== =================== ========= ======== ===============================================

States 24-26 are navreplay's addition (docs/methods/rpm-aided-ins.md §4.1): the gyro z-rate
errors of :mod:`navreplay.filters.ins_error` eq. (22), shared with ``gps-ins``. They act only
in the turns (``F[phi, 24:27] = C_nb_hat omega_z``), where white gyro noise has the wrong
shape; the gyro samples are compensated as ``omega - k_z (omega_z - b_g_z)``. States 27-32
are the accelerometer errors of eq. (23) that the forward and lateral specific force drives
(``F[v, 27 + 3 j + i] = -C_nb_hat[:, i] f_j``, j = x, y), also shared with ``gps-ins``; with
both sets the process noise is the sensors' own ARW and VRW.

In navigation mode the transfer-alignment states 20-23 are inert: zero rows in F, zero Q, zero
columns in H, zero P0; they keep the layout of the paper's unified filter.

Errors (signs)
--------------
Estimate minus truth, ``dx = x_hat - x``, for every state but the attitude, which is the phi
angle of eqs. (14)-(15): ``C_nb_hat = (I - [phi x]) C_nb`` (a positive phi_D is an estimated
heading smaller than the true one). Depth d = -h, so ``dd = d_hat - d = -dh``. The RPM speed
log reads ``V_rpm = (1 + k) u`` for the true water speed u along the RPM axis, which is body x
rotated by ``C_bv = exp([m x])``, ``m = [0, m_y, m_z]``. Feedback subtracts (§4.7)::

    lat, lon, d, v_n, b_a, b_g, k, m, v_c  -=  dx,
    q_nb_hat <- normalize([1, phi/2] (x) q_nb_hat),   then dx = 0.

Models
------
Strapdown and error dynamics (eqs. 1, 8-19, converted from ENU to NED, §4.2)::

    f_hat = f_meas - b_a_hat,  w_hat = w_meas - b_g_hat                                (1)
    nav_k = strapdown(nav_k-1, w_hat, f_hat)                     IMU rate              (2)
    dx' = F dx + G w,  F = [[F_pp  F_pv  0       0      0      | 0 ]
                            [F_vp  F_vv  F_vphi  F_vba  0      | 0 ]
                            [F_phip F_phiv F_phiphi 0   F_phibg | 0 ]
                            [0 (15 rows: biases, k, m, v_c, mu, T random constants)]]  (14)-(19)

with the navigation blocks of :mod:`navreplay.filters.ins_error` in their depth form
(``F_pv = diag(1/(R_M - d), 1/((R_N - d) cos L), 1)``, ``F_vba = -C_nb_hat``,
``F_phibg = +C_nb_hat``, ...). Discretisation and noise (eqs. 21-23)::

    Phi = I + F T + (F T)^2 / 2,  T = cov_step                                        (23)
    G w:  w = [n_a, n_g, n_c],  G[v, n_a] = -C_nb_hat, G[phi, n_g] = C_nb_hat,
          G[v_c, n_c] = I2,  Qc = diag(q_a I3, q_g I3, q_c I2)
    Qd  = G Qc G^T T = diag(0, q_a I3, q_g I3, 0, 0, 0, 0, q_c I2, 0) T               (22)
    P   = Phi P Phi^T + Qd                                                            (21)

F has non-zero rows only for position, velocity and attitude, and non-zero columns only for
those and the biases, so ``Phi = [[M], [0 I]]`` with M the 9 x 15 top block: the product
touches 9 rows of P (:func:`navreplay.filters.ins_time_update.propagate_covariance`, shared with the
other INS filters).

RPM water-velocity measurement (eq. 25, re-derived in §4.4), with the corrected
speed ``u_hat = c_rpm rpm / (1 + k_hat)``, ``w = v_hat - v_c_hat`` (``v_c_hat = [vc_N, vc_E, 0]``;
0 in the ``rpm`` mode)::

    z_rpm = C_nb_hat^T w - C_bv_hat [u_hat, 0, 0]^T                       (3,)  [m/s]   (25)
    H_rpm[:, dv]    = C_nb_hat^T                                                       (27)
    H_rpm[:, phi]   = -C_nb_hat^T [w_0 x]   (w_0: w at the first estimates, below)
    H_rpm[:, k]     = C_bv_hat e_x u_hat / (1 + k_hat)               = [u_hat, 0, 0]^T (*)
    H_rpm[:, m_y,z] = u_hat [(C_bv_hat e_x) x] J(m_hat)[:, 1:3]      = [0, 0, u_hat]^T,
                                                                       [0, -u_hat, 0]^T (*)
    H_rpm[:, v_c]   = -C_nb_hat^T[:, 0:2]
    a     = C_bv_hat e_x  (the estimated RPM axis in the body frame)
    R_rpm = (rpm_sigma / (1 + k_hat))^2 a a^T + constraint_sigma^2 (I - a a^T)

(the speed noise lies along the RPM axis; across it, the vehicle's sideslip and heave
through the water: :func:`rpm_noise_covariance`)

(*) the printed forms of §4.4 are the values at k_hat = m_hat = 0; the ones used here are
the exact first derivatives (J is the left Jacobian of SO(3)), equal to first order.

w_0 is ``v_hat - v_c_hat`` with all velocity and current corrections of the updates undone
(first-estimates Jacobian, :meth:`RpmAidedIns._water_velocity_first_estimate`): a heading
error with its matching current error is unobservable by the RPM update, and a Jacobian at
the corrected estimates would feed the filter heading information the data do not hold.

Depth (§4.5)::

    z_d = d_hat - d_meas,  H_d = e_2^T,  R_d = depth_sigma^2                            (§4.5)

Updates use the shared :func:`navreplay.filters.kalman.correct` (Cholesky, Joseph form) on the
error state 0, sequentially (RPM first, then depth, at the same update time), with the gain rows
of frozen states forced to 0: the inert states always, the current in the ``rpm`` mode.

Variants (§5, parameter ``mode``): ``pure`` (free inertial, no updates, P still
propagated for the sigma plots), ``rpm`` (current frozen at 0: P0 = 0, Q = 0, K rows 0) and
``rpm_current`` (all 33 states). One code path: the mode only sets P0, Q, the frozen mask and
whether updates run.

Initial covariance (§4.6): position, velocity and attitude sigmas from
``metadata.initial_nav["sigma"]`` (or the ``init_*`` parameters), position floored at
``pos_sigma_floor``; the sensor-error sigmas from the parameters.

Examples
--------
>>> from navreplay.sim.scenario import simulate
>>> from navreplay.replay import replay
>>> rec = simulate("underwater-rpm", {"duration": 10.0}, seed=0)
>>> res = replay(rec, RpmAidedIns, {"mode": "rpm_current"})
>>> res.x.shape[1], sorted(res.innovations)
(33, ['depth', 'rpm'])"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from navreplay.core.streams import StreamKind
from navreplay.core.units import (
    ARCSEC,
    DEG,
    DEG_PER_HOUR,
    DEG_PER_SQRT_HOUR,
    MICRO_G,
    MICRO_G_PER_SQRT_HZ,
    PPM,
)
from navreplay.filters import imu_gap, kalman
from navreplay.filters import ins_error as ie
from navreplay.filters import ins_time_update as itu
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
    TrueConstant,
    TruthColumn,
    check_number,
    state_names,
)
from navreplay.filters.ins import (
    ACCEL_MOTION_STATES,
    GYRO_Z_STATES,
    initial_covariance,
    initial_sigma,
    initial_solution,
)
from navreplay.filters.ins_smoothing import InsSmoothing
from navreplay.filters.registry import register_filter
from navreplay.filters.rpm_aided_ins_model import (
    ACCEL,
    ATT,
    BA,
    BG,
    CURRENT,
    GYRO_Z,
    INERT,
    K_RPM,
    M_RPM,
    N_STATES,
    VEL,
    depth_measurement,
    rpm_measurement,
    rpm_second_order,
)
from navreplay.geo import strapdown
from navreplay.sensors.depth import DepthModel
from navreplay.sensors.imu import ImuModel
from navreplay.sensors.specs import SensorSpecs
from navreplay.sensors.speed_log import SpeedLogModel

_CHECK_INTERVAL = 1.0
"""Filter time between full symmetry / PSD checks of the propagated P [s] (every correction
is checked, and every propagation step checks the variances)."""


STATES: tuple[State, ...] = (
    *(dataclasses.replace(s, nees=s.name in ("dlat", "dlon"))
      for s in ie.nav_states(ie.Vertical.DEPTH)),
    State("k_rpm", "-", Quantity.SPEED_SCALE_FACTOR, TrueConstant("rpm_scale_factor")),
    State("m_y", "rad", Quantity.MISALIGNMENT, TrueConstant("rpm_misalignment", (1,))),
    State("m_z", "rad", Quantity.MISALIGNMENT, TrueConstant("rpm_misalignment", (2,))),
    State("vc_N", "m/s", Quantity.CURRENT, TruthColumn("current_n", (0,))),
    State("vc_E", "m/s", Quantity.CURRENT, TruthColumn("current_n", (1,))),
    *(State(f"mu_{a}", "rad", Quantity.MISALIGNMENT) for a in "xyz"),
    State("dT", "s", Quantity.CLOCK),
    *GYRO_Z_STATES,
    *ACCEL_MOTION_STATES,
)
"""Declarations of the entries of ``Estimate.x``. Only the horizontal position errors count
in the NEES: the consistency band of docs/methods/rpm-aided-ins.md §6 is on horizontal
position, 2 dof. Navigation errors are scored by the navigation solution's error, biases
(effective) and current by the truth stream, the RPM parameters by ``Metadata.true_errors``
of the ``underwater-rpm`` scenario."""


STATE_NAMES: tuple[str, ...] = state_names(STATES)


class Mode(enum.StrEnum):
    """Filter variant (docs/methods/rpm-aided-ins.md §5)."""

    PURE = "pure"
    """Free inertial: no updates; P is still propagated (the paper's "Pure navigation")."""
    RPM = "rpm"
    """RPM (and depth) aiding with the current frozen at 0 ("Aided Navi.")."""
    RPM_CURRENT = "rpm_current"
    """RPM aiding with sea-current estimation ("Aided Navi. est Current")."""


TABLE_1 = SensorSpecs(
    {"imu": ImuModel(
        accel_bias=100.0 * MICRO_G, accel_scale_factor=100.0 * PPM,
        accel_vrw=1.0 * MICRO_G_PER_SQRT_HZ, accel_misalignment=5.0 * ARCSEC,
        gyro_bias=0.1 * DEG_PER_HOUR, gyro_scale_factor=100.0 * PPM,
        gyro_arw=0.01 * DEG_PER_SQRT_HOUR, gyro_misalignment=5.0 * ARCSEC),
     "speed_log": SpeedLogModel(scale_factor=0.02, misalignment=0.1 * DEG, noise=5.0,
                                speed_per_rpm=0.01, rate=10.0),
     "depth": DepthModel(noise=0.1, rate=1.0)},
    sources={"imu": "Table 1 of docs/methods/rpm-aided-ins.md",
             "speed_log": "the underwater-rpm speed log",
             "depth": "the underwater-rpm depth sensor"},
)
"""The sensors the defaults of :class:`RpmAidedInsParams` stand for: the paper's IMU (Table 1)
and the speed log and depth sensor of ``underwater-rpm``."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class RpmAidedInsParams(FilterParams):
    """Parameters of ``rpm-aided-ins`` (SI; defaults from docs/methods/rpm-aided-ins.md
    §4.3-4.6)."""

    mode: Mode = Mode.RPM_CURRENT
    """Variant: pure | rpm | rpm_current (docs/methods/rpm-aided-ins.md §5)."""
    accel_noise: float = 1.0 * MICRO_G_PER_SQRT_HZ
    """sqrt(q_a): velocity process noise density [(m/s)/sqrt(s)]: the accelerometer VRW (the
    scale factors and misalignments that the motion drives are states 27-32)."""
    gyro_noise: float = 0.01 * DEG_PER_SQRT_HOUR
    """sqrt(q_g): attitude process noise density [rad/sqrt(s)]: the gyro ARW (the z-rate
    scale factor and misalignments are states 24-26). A larger white noise standing in for
    the scale-factor and misalignment errors overstates the growth of the attitude error
    between updates in straight runs, where those errors do nothing."""
    gyro_z_states: bool = True
    """Estimate the gyro z-rate errors (states 24-26: misalignments m_g_xz, m_g_yz and scale
    factor s_g_z), which act only in the turns; False freezes them at 0."""
    gyro_misalignment_sigma: float = 5.0 * ARCSEC
    """Initial 1-sigma of m_g_xz and m_g_yz [rad] (5 arcsec)."""
    gyro_scale_factor_sigma: float = 100.0 * PPM
    """Initial 1-sigma of s_g_z [-] (100 ppm)."""
    accel_states: bool = True
    """Estimate the accelerometer errors that the x and y specific force drives (states
    27-32: scale factors s_a_x, s_a_y and misalignments of the columns x, y of S_a + M_a);
    False freezes them at 0."""
    accel_misalignment_sigma: float = 5.0 * ARCSEC
    """Initial 1-sigma of the accelerometer misalignments [rad] (5 arcsec)."""
    accel_scale_factor_sigma: float = 100.0 * PPM
    """Initial 1-sigma of the accelerometer scale factors s_a_x, s_a_y [-] (100 ppm)."""
    current_noise: float = 0.0
    """sqrt(q_c): sea-current random-walk density [(m/s)/sqrt(s)] (``rpm_current`` only). 0:
    the current is a random constant, as in ``underwater-rpm``; a current that changes over
    the mission needs a positive value (it widens the position sigma as t^1.5)."""
    accel_bias_sigma: float = 100.0 * MICRO_G
    """Initial 1-sigma of the accelerometer bias per axis [m/s^2] (100 ug)."""
    gyro_bias_sigma: float = 0.1 * DEG_PER_HOUR
    """Initial 1-sigma of the gyro bias per axis [rad/s] (0.1 deg/h)."""
    rpm_scale_factor_sigma: float = 0.02
    """Initial 1-sigma of the RPM scale factor k [-] (2 %)."""
    rpm_misalignment_sigma: float = 0.1 * DEG
    """Initial 1-sigma of the RPM-axis misalignments m_y, m_z [rad] (0.1 deg)."""
    current_sigma: float = 0.25 / math.sqrt(2.0)
    """Initial 1-sigma of the current per horizontal axis [m/s] (``rpm_current`` only): the
    per-axis RMS of a current of known speed (0.25 m/s, ``underwater-rpm``'s default) flowing
    in an unknown direction, ``speed / sqrt(2)``. The position sigma scales with it."""
    init_vel_sigma: float | None = None
    """Initial velocity 1-sigma per axis [m/s]; None: ``initial_nav["sigma"]["v_n"]``."""
    init_level_sigma: float | None = None
    """Initial phi_N, phi_E 1-sigma [rad]; None: ``initial_nav["sigma"]["phi"][:2]``."""
    init_azimuth_sigma: float | None = None
    """Initial phi_D 1-sigma [rad]; None: ``initial_nav["sigma"]["phi"][2]``."""
    init_depth_sigma: float | None = None
    """Initial depth 1-sigma [m]; None: ``initial_nav["sigma"]["pos_ned"][2]``."""
    pos_sigma_floor: float = 0.01
    """Lower bound of the initial position 1-sigma per N, E, D axis [m] (conditioning; a
    known launch point has sigma 0)."""
    rpm_sigma: float = 0.05
    """RPM speed noise along the RPM axis [m/s] (the forward row of the RPM update)."""
    constraint_sigma: float = 0.002
    """Noise of the no-sideslip and no-heave rows of the RPM update [m/s]: the vehicle's sway
    and heave through the water across the RPM axis, 1-sigma (2 mm/s, the ``underwater-rpm``
    default ``sway_heave_sigma``; docs/methods/rpm-aided-ins.md §4.4). A property of the
    vehicle and its autopilot: set it to what the vehicle does."""
    second_order: bool = True
    """Add the covariance of the products of error states in the RPM residual to its R
    (:func:`rpm_second_order`)."""
    first_estimate_jacobian: bool = True
    """Evaluate the attitude columns of the RPM Jacobian at the first-estimate water velocity
    (:meth:`RpmAidedIns._water_velocity_first_estimate`), which keeps the heading / current
    direction the RPM update cannot observe unobservable (docs/methods/rpm-aided-ins.md §4.4);
    False: at the current estimate (heading 3-4 times over-confident in sigma at a tight
    ``constraint_sigma``)."""
    depth_sigma: float = 0.1
    """Depth measurement noise [m]."""
    depth_aiding: bool = True
    """Use the depth sensor (aided modes)."""
    speed_per_rpm: float | None = None
    """Propeller law c_rpm [(m/s)/(rev/min)]; None: ``metadata.params["speed_per_rpm"]``."""
    update_rate: float = 1.0
    """Measurement update rate [Hz]; each update uses the RPM sample nearest its time."""
    cov_step: float = 0.1
    """Covariance propagation step T [s] (cut short at updates and outputs)."""
    curvature_derivatives: bool = True
    """Keep the dR_M/dL, dR_N/dL terms of F (their effect is below 1 %)."""
    gap_accel_sigma: float = 1.0
    """Unknown change of acceleration during an IMU gap, 1-sigma per NED axis [m/s^2]
    (:mod:`navreplay.filters.imu_gap`): the centripetal 0.7 m/s^2 of a 3 deg/s turn at
    13 m/s starting or ending, or a speed change."""
    gap_rate_sigma: float = 0.05
    """Unknown change of body rate during an IMU gap, 1-sigma per axis [rad/s] (a 3 deg/s
    turn starting or ending)."""

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "mode", Mode(self.mode))
        except ValueError:
            raise ValueError(
                f"mode must be one of {', '.join(m.value for m in Mode)}, got {self.mode!r}"
            ) from None
        for name in ("accel_noise", "gyro_noise", "current_noise", "accel_bias_sigma",
                     "gyro_bias_sigma", "rpm_scale_factor_sigma", "rpm_misalignment_sigma",
                     "current_sigma", "gyro_misalignment_sigma", "gyro_scale_factor_sigma",
                     "accel_misalignment_sigma", "accel_scale_factor_sigma",
                     "init_vel_sigma", "init_level_sigma",
                     "init_azimuth_sigma", "init_depth_sigma", "pos_sigma_floor",
                     "gap_accel_sigma", "gap_rate_sigma"):
            check_number(self, name)
        for name in ("rpm_sigma", "constraint_sigma", "depth_sigma", "speed_per_rpm"):
            check_number(self, name, positive=True)
        check_number(self, "update_rate", positive=True, upper=100.0)
        check_number(self, "cov_step", positive=True, upper=10.0)


class _Schedule:
    """Update times k / rate; a sample is used when it is the nearest to the next one."""

    def __init__(self, rate: float) -> None:
        self.rate = rate
        self.k = 0
        self.t_last: float | None = None

    def due(self, t: float) -> bool:
        half = 0.5 * (t - self.t_last) if self.t_last is not None else 0.0
        self.t_last = t
        if t + half < self.k / self.rate - 1e-9:
            return False
        self.k = max(self.k + 1, math.floor((t + half) * self.rate + 1e-9) + 1)
        return True


@register_filter
class RpmAidedIns(Filter, InsSmoothing):
    """33-state RPM velocity-aided INS with sea-current estimation (see the module docstring)."""

    name: ClassVar[str] = "rpm-aided-ins"
    summary: ClassVar[str] = (
        "underwater INS aided by propeller-RPM speed and depth, 33-state feedback KF with RPM"
        " scale factor, misalignment, sea current, gyro z-rate and accelerometer errors"
        " (Choi 2019); mode=pure|rpm|rpm_current"
    )
    requires: ClassVar[tuple[StreamKind, ...]] = (StreamKind.IMU,)
    optional: ClassVar[tuple[StreamKind, ...]] = (StreamKind.SPEED_LOG, StreamKind.DEPTH)
    Params: ClassVar[type[FilterParams]] = RpmAidedInsParams
    states: tuple[State, ...] = STATES
    measurements: tuple[MeasurementKind, ...] | None = (
        MeasurementKind("rpm", ("forward", "lateral", "vertical"), "m/s"),  # body axes, (25)
        MeasurementKind("depth", ("D",), "m"),
    )

    params: RpmAidedInsParams
    smoothing_vertical: ClassVar[ie.Vertical] = ie.Vertical.DEPTH

    @classmethod
    def settings_from_sensors(cls, sensors: SensorSpecs) -> dict[str, Any]:
        """The settings the IMU, speed-log and depth specifications give (SI)::

            accel_noise, gyro_noise        = accel_vrw, gyro_arw
            accel_bias_sigma               = sqrt(accel_bias^2 + accel_bias_instability^2)
            gyro_bias_sigma                = sqrt(gyro_bias^2 + gyro_bias_instability^2)
            gyro_misalignment_sigma, gyro_scale_factor_sigma, accel_misalignment_sigma,
            accel_scale_factor_sigma       = the IMU's misalignments and scale factors
            rpm_scale_factor_sigma, rpm_misalignment_sigma, speed_per_rpm = the speed log's
            rpm_sigma                      = speed log noise [rev/min] x speed_per_rpm
            depth_sigma                    = the depth sensor's noise

        The biases are the turn-on biases of the IMU, as in the paper's model (Table 1; the
        scale factors and misalignments are states of their own)."""
        out: dict[str, Any] = {}
        imu, log = sensors.get("imu"), sensors.get("speed_log")  # read only where stated
        pairs = (("accel_noise", "imu", "accel_vrw"), ("gyro_noise", "imu", "gyro_arw"),
                 ("gyro_misalignment_sigma", "imu", "gyro_misalignment"),
                 ("gyro_scale_factor_sigma", "imu", "gyro_scale_factor"),
                 ("accel_misalignment_sigma", "imu", "accel_misalignment"),
                 ("accel_scale_factor_sigma", "imu", "accel_scale_factor"),
                 ("rpm_scale_factor_sigma", "speed_log", "scale_factor"),
                 ("rpm_misalignment_sigma", "speed_log", "misalignment"),
                 ("speed_per_rpm", "speed_log", "speed_per_rpm"),
                 ("depth_sigma", "depth", "noise"))
        for setting, kind, name in pairs:
            if sensors.has(kind, name):
                out[setting] = getattr(sensors.get(kind), name)
        for triad in ("accel", "gyro"):
            if sensors.has("imu", f"{triad}_bias"):
                instability = (getattr(imu, f"{triad}_bias_instability")
                               if sensors.has("imu", f"{triad}_bias_instability") else 0.0)
                out[f"{triad}_bias_sigma"] = math.hypot(getattr(imu, f"{triad}_bias"),
                                                        instability)
        if sensors.has("speed_log", "noise", "speed_per_rpm"):
            out["rpm_sigma"] = log.noise * log.speed_per_rpm
        return out

    @classmethod
    def default_sensors(cls) -> SensorSpecs:
        return TABLE_1

    def __init__(self, params: RpmAidedInsParams, context: FilterContext) -> None:
        super().__init__(params, context)
        p = params
        self.mode = p.mode
        if self.mode is not Mode.PURE and StreamKind.SPEED_LOG not in context.streams:
            have = ", ".join(sorted(str(k) for k in context.streams)) or "no streams"
            raise ValueError(f"rpm-aided-ins (mode {self.mode}) needs the speed_log stream; "
                             f"the recording has: {have}")
        c_rpm = p.speed_per_rpm
        if c_rpm is None:
            c_rpm = context.metadata.params.get("speed_per_rpm")
            if c_rpm is None and self.mode is not Mode.PURE:
                raise ValueError("rpm-aided-ins: set speed_per_rpm (the recording's metadata "
                                 "has no params.speed_per_rpm)")
        self.speed_per_rpm = float(c_rpm) if c_rpm is not None else 0.0
        self.nav, self.t = initial_solution(context, self.name)
        self.b_a = np.zeros(3)
        self.b_g = np.zeros(3)
        self.k_rpm = 0.0
        self.m_rpm = np.zeros(2)
        self.v_c = np.zeros(2)
        self.gyro_z = np.zeros(3)  # estimates of m_g_xz, m_g_yz, s_g_z
        self.accel_k = np.zeros(6)  # estimates of the columns x, y of S_a + M_a
        self._w_correction = np.zeros(3)  # sum of the velocity minus current feedback

        # P0, §4.6 of the method
        init = context.metadata.initial_nav
        pos_sigma = initial_sigma(init, "pos_ned")
        if p.init_depth_sigma is not None:
            pos_sigma[2] = p.init_depth_sigma
        phi = initial_sigma(init, "phi", p.init_level_sigma, param="init_level_sigma")
        phi[2] = initial_sigma(init, "phi", p.init_azimuth_sigma, param="init_azimuth_sigma")[2]
        estimate_current = self.mode is Mode.RPM_CURRENT
        sig = np.zeros(N_STATES)
        sig[K_RPM] = p.rpm_scale_factor_sigma
        sig[M_RPM] = p.rpm_misalignment_sigma
        sig[CURRENT] = p.current_sigma if estimate_current else 0.0
        if p.gyro_z_states:
            sig[GYRO_Z] = (p.gyro_misalignment_sigma, p.gyro_misalignment_sigma,
                           p.gyro_scale_factor_sigma)
        if p.accel_states:
            s_a, m_a = p.accel_scale_factor_sigma, p.accel_misalignment_sigma
            sig[ACCEL] = (s_a, m_a, m_a, m_a, s_a, m_a)
        self.P = np.diag(sig**2)
        self.P[: ie.N_STATES, : ie.N_STATES] = initial_covariance(
            self.nav[strapdown.POS], np.maximum(pos_sigma, p.pos_sigma_floor),
            initial_sigma(init, "v_n", p.init_vel_sigma, param="init_vel_sigma"), phi,
            p.accel_bias_sigma, p.gyro_bias_sigma,
        )

        # Qd = diag(q) T, eq. (22)
        q = np.zeros(N_STATES)
        q[VEL] = p.accel_noise**2
        q[ATT] = p.gyro_noise**2
        if estimate_current:
            q[CURRENT] = p.current_noise**2
        self._held: tuple[np.ndarray, np.ndarray, float] | None = None
        self._time_update = itu.TimeUpdate(
            itu.ProcessNoise(q, gyro_z_states=GYRO_Z.start, accel_states=ACCEL.start), p.cov_step,
            vertical=ie.Vertical.DEPTH, curvature_derivatives=p.curvature_derivatives,
        )
        self._frozen = np.zeros(N_STATES, dtype=bool)
        self._frozen[INERT] = True
        if not estimate_current:
            self._frozen[CURRENT] = True
        if not p.gyro_z_states:
            self._frozen[GYRO_Z] = True
        if not p.accel_states:
            self._frozen[ACCEL] = True
        self._rpm_schedule = _Schedule(p.update_rate)
        self._depth_schedule = _Schedule(p.update_rate)
        self._next_check = self.t + _CHECK_INTERVAL
        self._x = self._state_vector()
        kalman.check_covariance(self.P, name="P0", t=self.t)

    # -- the Filter interface ----------------------------------------------------------------

    def propagate(self, t: np.ndarray, imu: Mapping[str, np.ndarray]) -> None:
        omega = itu.compensate_gyro_z(imu["omega_ib_b"], self.b_g, self.gyro_z)
        f_b = imu["f_b"]
        if self.accel_k.any():
            f_b = itu.compensate_accel(f_b, self.b_a, self.accel_k)
        step = self._time_update.propagate(self.nav, self.P, self.t, t, omega,
                                           f_b, self.b_a, self.b_g)  # (1), (2), (21)-(23)
        if step is None:
            return
        self._held = (imu["omega_ib_b"][-1], imu["f_b"][-1], step[2] - (
            t[-2] if len(t) > 1 else self.t))  # the last sample and interval, for a gap
        self.nav, self.P, self.t = step
        if self.t >= self._next_check:  # full symmetry / PSD check once per second
            kalman.check_covariance(self.P, t=self.t)
            self._next_check = self.t + _CHECK_INTERVAL

    def update(
        self, kind: StreamKind, t: float, sample: Mapping[str, Any]
    ) -> list[Innovation] | None:
        if self.mode is Mode.PURE:
            return None
        if kind is StreamKind.SPEED_LOG:
            if not self._rpm_schedule.due(t):
                return None
            if not -0.5 < self.k_rpm < 0.5:
                raise kalman.FilterDivergedError(
                    f"RPM scale-factor estimate {self.k_rpm:.3f} is beyond +-0.5", t)
            v_c = self.v_c if self.mode is Mode.RPM_CURRENT else np.zeros(2)
            measurement = rpm_measurement(self.nav, self.speed_per_rpm * float(sample["rpm"]),
                                          self.k_rpm, self.m_rpm, v_c, self.params.rpm_sigma,
                                          self.params.constraint_sigma,
                                          self._water_velocity_first_estimate(v_c)
                                          if self.params.first_estimate_jacobian else None)
            name = "rpm"
        elif kind is StreamKind.DEPTH and self.params.depth_aiding:
            if not self._depth_schedule.due(t):
                return None
            measurement = depth_measurement(self.nav, float(sample["depth"]),
                                            self.params.depth_sigma)
            name = "depth"
        else:
            return None
        z, H, _ = measurement
        if not (np.isfinite(z).all() and np.isfinite(H).all()):
            raise ValueError(f"{name} measurement at t = {t:.6f} s is not finite: z = {z}")
        self._sync_covariance()
        if name == "rpm" and self.params.second_order:
            u_hat = self.speed_per_rpm * float(sample["rpm"]) / (1.0 + self.k_rpm)
            v_c = self.v_c if self.mode is Mode.RPM_CURRENT else np.zeros(2)
            _, cov = rpm_second_order(self.nav, u_hat, self.k_rpm, self.m_rpm, v_c, self.P)
            measurement = kalman.Measurement(z, H, measurement.R + cov)
        # shapes are fixed by construction and R by the parameters; P is checked below
        self._smoothing_prior()
        c = kalman.correct(np.zeros(N_STATES), self.P, *measurement, frozen=self._frozen, t=t,
                           check=False)
        kalman.check_covariance(c.P, name="corrected P", t=t)
        self.P = c.P
        self._feedback(c.x)
        return [c.innovation(name, t)]

    def bridge_imu_gap(self, t: float, since: float) -> None:
        """No IMU samples from ``since`` until after ``t`` [s]. A submarine's motion is smooth:
        the bridge holds the last body rate and specific force (a turn or a speed change goes
        on), integrates them with the filter's own mechanization and error model, and adds the
        covariance of the unknown change of that motion
        (:func:`navreplay.filters.imu_gap.motion_noise`, depth form). The RPM and depth updates
        inside the gap correct it as usual."""
        if t <= self.t or self._held is None:
            return
        p = self.params
        tau = (self.t - since, t - since)
        omega, f_b, step = self._held
        times = imu_gap.held_samples(self.t, t, step)
        k = len(times)
        self.propagate(times, {"omega_ib_b": np.tile(omega, (k, 1)),
                               "f_b": np.tile(f_b, (k, 1))})
        self._sync_covariance()
        self.P = self.P + imu_gap.motion_noise(self.nav, N_STATES, tau, p.gap_accel_sigma,
                                               p.gap_rate_sigma, ie.Vertical.DEPTH)
        self._time_update.prev[:] = 0.0  # no coning/sculling across the gap
        kalman.check_covariance(self.P, t=self.t)

    def estimate(self) -> Estimate:
        self._sync_covariance()
        return Estimate(
            self.t, self._x, self.P,
            NavSolution.from_vector(self.nav),
        )

    # -- internals ---------------------------------------------------------------------------

    def _sync_covariance(self) -> None:
        """Close the open covariance step so that P belongs to the current time."""
        self.P = self._time_update.close(self.P, self.t)

    def _feedback(self, dx: np.ndarray) -> None:
        """Subtract the estimated errors (docs/methods/rpm-aided-ins.md §4.7, step 4); the error
        state is then 0."""
        self._smoothing_feedback(dx)
        self.nav = ie.apply_correction(self.nav, dx, ie.Vertical.DEPTH)
        self.b_a = self.b_a - dx[BA]
        self.b_g = self.b_g - dx[BG]
        self.k_rpm -= float(dx[15])
        self.m_rpm = self.m_rpm - dx[M_RPM]
        self.v_c = self.v_c - dx[CURRENT]
        self._w_correction += dx[VEL]
        self._w_correction[:2] -= dx[CURRENT]
        self.gyro_z = self.gyro_z - dx[GYRO_Z]
        self.accel_k = self.accel_k - dx[ACCEL]
        self._x = self._state_vector()

    def _water_velocity_first_estimate(self, v_c_hat: np.ndarray) -> np.ndarray:
        """Water-relative velocity, NED [m/s], at which the attitude columns of H_rpm are
        evaluated: the estimate ``v_hat - v_c_hat`` with every velocity and current
        correction of the updates undone, i.e. the first estimates of the initial velocity
        and the current plus the INS's own velocity change since.

        A heading error phi_D, with a current error ``phi_D e_z x (v_0 - v_c)``, leaves the
        RPM residual unchanged at every time (the INS turns its velocity change by phi_D as
        it turns the body axes): that direction is unobservable but for the slow
        gyrocompassing through the earth rate. H evaluated at the corrected estimates moves
        that direction from update to update by the corrections (0.1-0.2 m/s of 12-14 m/s),
        and the filter gains heading information the data do not hold; at the first
        estimates the direction stays in H's null space (first-estimates Jacobian, as in
        EKF SLAM's heading consistency)."""
        w = self.nav[3:6] + self._w_correction
        w[:2] -= v_c_hat
        return w

    def _state_vector(self) -> np.ndarray:
        """``Estimate.x``: error states 0 (after feedback), sensor errors as total estimates."""
        x = np.zeros(N_STATES)
        x[BA] = self.b_a
        x[BG] = self.b_g
        x[15] = self.k_rpm
        x[M_RPM] = self.m_rpm
        x[CURRENT] = self.v_c
        x[GYRO_Z] = self.gyro_z
        x[ACCEL] = self.accel_k
        return x
