"""Free-inertial navigation ("ins"): the strapdown solution and its predicted error covariance.

The baseline every aided filter is compared to. It integrates the IMU with
:mod:`navreplay.geo.strapdown` from the initial solution in ``metadata.initial_nav`` and
propagates the covariance of the 15 navigation error states of
:mod:`navreplay.filters.ins_error` and of the gyro and accelerometer scale factors and
misalignments (the columns of ``S + M`` that a drive or a banked turn excites) with the IMU
error model, both by
:class:`navreplay.filters.ins_time_update.TimeUpdate`. It makes no measurement update. The class is
the base of :class:`navreplay.filters.gps_ins.GpsInsFilter` (feedback of estimated errors,
extra states); the module's :func:`initial_solution`, :func:`initial_sigma` and
:func:`initial_covariance` also serve ``rpm-aided-ins``.

States (``Estimate.x``)
-----------------------
===== ====================== ========= ========== ==========================================
index name                   frame     unit       value in ``Estimate.x``
===== ====================== ========= ========== ==========================================
0-2   dlat, dlon, dh         -         rad, rad, m position error estimate (0 after feedback)
3-5   dv_N, dv_E, dv_D       n (NED)   m/s        velocity error estimate (0)
6-8   phi_N, phi_E, phi_D    n         rad        attitude error estimate (0)
9-11  b_a_x, b_a_y, b_a_z    b (FRD)   m/s^2      accelerometer bias estimate (total)
12-14 b_g_x, b_g_y, b_g_z    b (FRD)   rad/s      gyro bias estimate (total)
g     m_g_xz                 b (FRD)   rad        gyro misalignment M[0, 2] (z rate into x)
g+1   m_g_yz                 b (FRD)   rad        gyro misalignment M[1, 2] (z rate into y)
g+2   s_g_z                  b (FRD)   -          gyro z scale-factor error
g+3.. s_g_x, m_g_yx, m_g_zx, b (FRD)   -, rad     columns x and y of S_g + M_g
      m_g_xy, s_g_y, m_g_zy                       (``gyro_roll_pitch_states``)
a..   s_a_x, m_a_yx, ...     b (FRD)   -, rad     columns x, y (and z) of S_a + M_a
                                                  (``accel_motion_states``,
                                                  ``accel_load_states``)
===== ====================== ========= ========== ==========================================

The gyro z-rate states (``gyro_misalignment_states``) follow the 15 (g = 15; in ``gps-ins``
after its lever-arm states when it estimates them), the columns x and y of the gyro follow
them, then the accelerometer columns; all are on by default.

``Estimate.P`` is the covariance of the errors of the navigation solution and of the bias,
scale-factor and misalignment estimates in these units. A free INS has nothing to feed back:
its navigation error states stay 0 and its other estimates at their initial value (0).

Errors (signs)
--------------
Estimate minus truth, ``dx = x_hat - x``, for position, velocity and biases; the attitude error
is the phi angle with ``C_nb_hat = (I - [phi x]) C_nb`` (positive phi_D: estimated heading too
small). Feedback subtracts. See :mod:`navreplay.filters.ins_error`.

Models
------
::

    f_hat = f_meas - b_a_hat,   omega_hat = omega_meas - b_g_hat                          (1)
    nav_k = strapdown(nav_k-1, omega_hat, f_hat, dt)            at the IMU rate           (2)
    dx' = F(nav, f_hat) dx + G w                                ins_error eqs. (5)-(18)    (3)
    Phi = I + F T + (F T)^2 / 2,  Qd = diag(q) T + motion terms every T = cov_step        (4)
    q   = [0, 0, 0, VRW^2 I3, ARW^2 I3, q_ba I3, q_bg I3]       per second                 (5)
    motion terms: Qd[v] += s_a^2 tau |a_n|^2 T, Qd[phi] += s_g^2 tau |omega|^2 T          (5a)
    gyro z-rate states k = (m_xz, m_yz, s_z), random constants (F = 0, Q = 0 for them):
      omega_hat = omega_meas - b_g_hat - k_hat (omega_meas_z - b_g_hat_z)
      F[phi, k_j] = +C_nb_hat[:, j] omega_hat_z   (ins_error eq. 22); s_g = 0 in (5a)      (5b)
    accelerometer states (accel_motion_states): the columns x, y of S_a + M_a,
      F[v, k_j[i]] = -C_nb_hat[:, i] f_hat_j (ins_error eq. 23); s_a = 0 in (5a)          (5c)
    roll, pitch and load-factor states (gyro_roll_pitch_states, accel_load_states): the
      gyro columns x, y, F[phi, k_j[i]] = +C_nb_hat[:, i] omega_hat_j,
      and the accelerometer column z on f_z + g0, F[v, k_z[i]] = -C_nb_hat[:, i] (f_hat_z
      + g0), its states correlated with the z-column part of the effective bias:
      cov(b_a_i, k_z[i]) = -g0 sigma(k_z[i])^2 (ins_error eqs. 22, 23)                   (5d)
    P0  = diag(sigma_N^2/(R_M+h)^2, sigma_E^2/((R_N+h) cos lat)^2, sigma_D^2,
               sigma_v^2, sigma_phi^2, sigma_ba^2, sigma_bg^2,
               sigma_m^2, sigma_m^2, sigma_s^2)                                            (6)

The covariance step (4) uses F at the navigation solution at the start of the step and the mean
compensated specific force over the step; a step is cut short at an update or an output so
that ``Estimate.P`` always belongs to ``Estimate.t``. The biases are random constants plus a
random walk whose density covers the bias instability: for a first-order Gauss-Markov
instability of sigma and correlation time tau, ``q_b = 2 sigma^2 / tau`` (the initial slope of
its variance).

At a roughly level attitude the accelerometer scale factor and misalignment times gravity, and
the gyro g-sensitivity times gravity, act as constant biases: the bias states estimate these
*effective* biases, and their initial sigmas are the effective values of the recording's IMU
specification (:func:`imu_settings`; the defaults are those of the ``tactical`` grade of
:func:`navreplay.sensors.imu_grade`): level accelerometer axes the turn-on bias, misalignment x
g and the instability (0.3 mg, 0.5 mrad g, 0.05 mg: 0.585 mg); the z axis sees gravity through
its scale factor instead (300 ppm: 0.427 mg, ``accel_bias_sigma_z``; it drives the
free-inertial vertical channel); gyros the turn-on bias, g-sensitivity x g and the instability
(1 deg/h, 1 deg/h/g, 0.3 deg/h: 1.446 deg/h). Every IMU setting of :class:`InsParams` follows
the specification the same way (docs/methods/ins.md §4). Under motion, the gyro
errors a land vehicle's yaw rate drives, ``(m_xz, m_yz, s_z) omega_z``, are the states (5b):
a constant misalignment turns with the body, so over a turn of angle dpsi it adds the bounded
tilt ``m (sin psi - sin psi_0, cos psi_0 - cos psi)``, and s_z adds ``s_z dpsi`` of heading.
White noise of the same size (5a) would instead add about 1 mrad (in quadrature) to the sigma
of every attitude axis with each 90-deg turn: it made ``ins`` about twice under-confident in
tilt after ten minutes of driving (docs/methods/ins.md). The other scale-factor and
misalignment errors act under roll and pitch rates and a load factor (a banked turn: the body
turns about its y axis at ``psi_dot sin(bank)`` and the specific force grows to ``g /
cos(bank)``), or as ``(S_a + M_a) a`` while the vehicle accelerates or turns, about a tenth of
the effective bias on a drive: both filters carry all of them as states (5c, 5d; without
them a free INS banking at 60 m/s is about 15 % over-confident in NEES, docs/methods/ins.md
§5), and ``accel_sf_mis`` and ``gyro_sf_mis`` enter them as the white motion noise (5a)
(ins_error eq. 21) with a correlation time tau when the states are turned off.

Scoring (:mod:`navreplay.metrics`): the navigation error states are scored by the errors of the
navigation solution (``nav:`` truth keys), the biases by the truth stream's effective biases
``accel_bias_eff`` and ``gyro_bias_eff`` (the total bias plus the scale-factor, misalignment and
g-sensitivity errors at rest, :func:`navreplay.sensors.imu.effective_biases`), the z-rate
states against ``metadata.true_errors["imu"]`` (``gyro_misalignment[0][2]``, ``[1][2]``,
``gyro_scale_factor[2]``); the default NEES block (``nees_states``) is the nine navigation
errors.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from navreplay.core.streams import StreamKind
from navreplay.core.units import G0
from navreplay.filters import imu_gap, kalman
from navreplay.filters import ins_error as ie
from navreplay.filters import ins_time_update as itu
from navreplay.filters.base import (
    TICK,
    Estimate,
    EventRun,
    Filter,
    FilterContext,
    FilterParams,
    Innovation,
    MeasurementKind,
    NavSolution,
    Quantity,
    State,
    TrueConstant,
    check_number,
    overrides,
    state_names,
)
from navreplay.filters.ins_smoothing import InsSmoothing
from navreplay.filters.registry import register_filter
from navreplay.geo import strapdown
from navreplay.geo.earth import OMEGA_IE
from navreplay.sensors.imu import ImuGrade, ImuModel, imu_grade
from navreplay.sensors.specs import SensorSpecs


def imu_settings(sensors: SensorSpecs) -> dict[str, float]:
    """The settings of :class:`InsParams` that follow from the IMU specification (SI), eqs.
    (5)-(6); only those whose fields are stated (a setting needs its first-named field, and
    counts the others where they are stated)::

        accel_vrw, gyro_arw               = the white-noise densities
        accel_bias_sigma   (x, y)         = sqrt(b_a^2 + (m_a g)^2 + s_GM,a^2)   gravity through a
                                            misalignment into a level axis
        accel_bias_sigma_z (z)            = sqrt(b_a^2 + (k_a g)^2 + s_GM,a^2)   ... the z scale
                                            factor
        gyro_bias_sigma                   = sqrt(b_g^2 + (K_g g)^2 + s_GM,g^2
                                                 + (sqrt(k_g^2 + 2 m_g^2) W)^2)
        accel_bias_rw, gyro_bias_rw       = sqrt(q_RW + 2 s_GM^2 / tau)          the random walk and
                                            the initial slope of the Gauss-Markov variance
        gyro_misalignment_sigma, gyro_scale_factor_sigma, accel_scale_factor_sigma,
        accel_misalignment_sigma          = the specification's m and k

    with b the turn-on biases, m the misalignments, k the scale factors, s_GM the bias
    instabilities, K_g the g-sensitivity, g standard gravity and W the earth rate: the bias
    states hold the effective biases of a level IMU at rest (the module docstring).
    """
    imu = sensors.imu
    if imu is None:
        return {}

    def has(*names: str) -> bool:
        return sensors.has("imu", *names)

    def stated(name: str, value: float) -> float:
        return value if has(name) else 0.0

    out: dict[str, float] = {}
    if has("accel_vrw"):
        out["accel_vrw"] = imu.accel_vrw
    if has("gyro_arw"):
        out["gyro_arw"] = imu.gyro_arw
    if has("accel_bias"):
        common = imu.accel_bias**2 + stated("accel_bias_instability",
                                            imu.accel_bias_instability) ** 2
        out["accel_bias_sigma"] = math.sqrt(
            common + (stated("accel_misalignment", imu.accel_misalignment) * G0) ** 2)
        out["accel_bias_sigma_z"] = math.sqrt(
            common + (stated("accel_scale_factor", imu.accel_scale_factor) * G0) ** 2)
    if has("gyro_bias"):
        earth = math.hypot(stated("gyro_scale_factor", imu.gyro_scale_factor),
                           math.sqrt(2.0) * stated("gyro_misalignment", imu.gyro_misalignment))
        out["gyro_bias_sigma"] = math.sqrt(
            imu.gyro_bias**2 + (stated("gyro_g_sensitivity", imu.gyro_g_sensitivity) * G0) ** 2
            + stated("gyro_bias_instability", imu.gyro_bias_instability) ** 2
            + (earth * OMEGA_IE) ** 2)
    for triad, walk in (("accel", "accel_rw"), ("gyro", "gyro_rrw")):
        q, used = 0.0, False
        if has(f"{triad}_bias_instability", f"{triad}_bias_tau"):
            q += 2.0 * getattr(imu, f"{triad}_bias_instability") ** 2 / getattr(
                imu, f"{triad}_bias_tau")
            used = True
        if has(walk):
            q += getattr(imu, walk) ** 2
            used = True
        if used:
            out[f"{triad}_bias_rw"] = math.sqrt(q)
    for setting, name in (("gyro_misalignment_sigma", "gyro_misalignment"),
                          ("gyro_scale_factor_sigma", "gyro_scale_factor"),
                          ("accel_scale_factor_sigma", "accel_scale_factor"),
                          ("accel_misalignment_sigma", "accel_misalignment")):
        if has(name):
            out[setting] = getattr(imu, name)
    return out


TACTICAL = SensorSpecs({"imu": imu_grade(ImuGrade.TACTICAL)},
                       sources={"imu": "grade tactical"})
"""The sensors the defaults of :class:`InsParams` stand for: the ``tactical`` IMU grade."""
_DEFAULT = imu_settings(TACTICAL)


@dataclasses.dataclass(frozen=True, kw_only=True)
class InsParams(FilterParams):
    """IMU error model and covariance schedule of the INS filters (SI). The IMU settings
    follow from the recording's IMU specification (:func:`imu_settings`); their defaults are
    those of the ``tactical`` grade (1 deg/h, 0.3 mg)."""

    accel_vrw: float = _DEFAULT["accel_vrw"]
    """Accelerometer white noise, velocity random walk [(m/s)/sqrt(s)] (tactical: 50
    ug/sqrt(Hz))."""
    gyro_arw: float = _DEFAULT["gyro_arw"]
    """Gyro white noise, angle random walk [rad/sqrt(s)] (tactical: 0.1 deg/sqrt(h))."""
    accel_bias_sigma: float = _DEFAULT["accel_bias_sigma"]
    """Initial 1-sigma of the (effective) accelerometer bias, x and y axes (and z unless
    ``accel_bias_sigma_z`` is set) [m/s^2]: the turn-on bias, the misalignment that couples
    gravity into a level axis and the Gauss-Markov instability, sqrt(0.3 mg^2 +
    (0.5 mrad g)^2 + 0.05 mg^2) = 0.585 mg for the tactical grade."""
    accel_bias_sigma_z: float | None = _DEFAULT["accel_bias_sigma_z"]
    """Initial 1-sigma of the (effective) z (down) accelerometer bias [m/s^2]; None: as
    ``accel_bias_sigma``. Gravity acts on the z axis through its scale factor, not a
    misalignment: sqrt(0.3 mg^2 + (300 ppm g)^2 + 0.05 mg^2) = 0.427 mg for the tactical grade.
    This sigma sets the growth of the free-inertial vertical channel."""
    gyro_bias_sigma: float = _DEFAULT["gyro_bias_sigma"]
    """Initial 1-sigma of the (effective) gyro bias, per axis [rad/s]: turn-on bias,
    g-sensitivity times gravity, instability (and the earth rate through the scale factor and
    misalignments): 1.446 deg/h for the tactical grade."""
    accel_bias_rw: float = _DEFAULT["accel_bias_rw"]
    """Accelerometer bias random walk density [(m/s^2)/sqrt(s)]: the acceleration random walk
    and a Gauss-Markov instability as sigma sqrt(2 / tau) (tactical: 50 ug, 600 s)."""
    gyro_bias_rw: float = _DEFAULT["gyro_bias_rw"]
    """Gyro bias random walk density [(rad/s)/sqrt(s)]: the rate random walk and the
    instability as sigma sqrt(2 / tau) (tactical: 0.3 deg/h, 600 s)."""
    init_pos_sigma: float | None = None
    """Initial position 1-sigma per N, E, D axis [m]; None: ``initial_nav["sigma"]["pos_ned"]``."""
    init_vel_sigma: float | None = None
    """Initial velocity 1-sigma per axis [m/s]; None: ``initial_nav["sigma"]["v_n"]``."""
    init_att_sigma: float | None = None
    """Initial attitude 1-sigma per axis [rad]; None: ``initial_nav["sigma"]["phi"]``."""
    accel_sf_mis: float = 0.0
    """Unmodelled accelerometer scale-factor / misalignment, 1-sigma [-] (eq. 5a; 0: off).
    Off by default: under the accelerations of a land vehicle these errors act mostly as a
    slowly changing bias (their gravity part is in the effective bias)."""
    gyro_misalignment_states: bool = True
    """Carry the gyro errors driven by the z (yaw) rate, misalignments m_xz, m_yz and scale
    factor s_z, as random-constant states (eq. 5b); the motion noise of ``gyro_sf_mis`` is
    then off."""
    gyro_misalignment_sigma: float = _DEFAULT["gyro_misalignment_sigma"]
    """Initial 1-sigma of m_xz and m_yz [rad] (``tactical`` grade: 0.5 mrad)."""
    gyro_scale_factor_sigma: float = _DEFAULT["gyro_scale_factor_sigma"]
    """Initial 1-sigma of s_z [-] (``tactical`` grade: 100 ppm)."""
    gyro_sf_mis: float = 0.5e-3
    """Unmodelled gyro scale-factor / misalignment, 1-sigma [-] (eq. 5a; 0: off); used only
    without ``gyro_misalignment_states``."""
    accel_motion_states: bool = True
    """Carry the accelerometer errors driven by the x and y specific force (the columns x and
    y of S_a + M_a) as six random-constant states (eq. 5c); the motion noise of
    ``accel_sf_mis`` is then off."""
    accel_scale_factor_sigma: float = _DEFAULT["accel_scale_factor_sigma"]
    """Initial 1-sigma of s_a_x, s_a_y (and s_a_z) [-] (``tactical`` grade: 300 ppm)."""
    accel_misalignment_sigma: float = _DEFAULT["accel_misalignment_sigma"]
    """Initial 1-sigma of m_a_yx, m_a_zx, m_a_xy, m_a_zy (and m_a_xz, m_a_yz) [rad]
    (``tactical``: 0.5 mrad)."""
    gyro_roll_pitch_states: bool = True
    """Carry the gyro errors driven by the x and y (roll and pitch) rates, the columns x and
    y of S_g + M_g (s_g_x, m_g_yx, m_g_zx, m_g_xy, s_g_y, m_g_zy), as random-constant states
    (eq. 5d): what a banked turn excites. They extend ``gyro_misalignment_states``: without
    those, there are no gyro states at all."""
    accel_load_states: bool = True
    """Carry the accelerometer errors driven by the load factor, the column z of S_a + M_a
    acting on ``f_z + g0`` (m_a_xz, m_a_yz, s_a_z), as random-constant states (eq. 5d; with
    ``accel_motion_states``, whose states they extend; without those, none): what a banked
    turn or a pull-up excites."""
    sf_mis_time: float = 30.0
    """Correlation time tau of eq. (5a) [s]: a manoeuvre and the time its error persists."""
    cov_step: float = 0.1
    """Covariance propagation step [s] (cut short at updates and outputs)."""
    gap_accel_sigma: float = 2.0
    """Unknown acceleration during an IMU gap, 1-sigma per NED axis, held over the gap
    [m/s^2] (:mod:`navreplay.filters.imu_gap`)."""
    gap_rate_sigma: float = 0.1
    """Unknown body rate during an IMU gap, 1-sigma per axis, held over the gap [rad/s]."""

    def __post_init__(self) -> None:
        for name in ("accel_vrw", "gyro_arw", "accel_bias_sigma", "accel_bias_sigma_z",
                     "gyro_bias_sigma",
                     "accel_bias_rw", "gyro_bias_rw", "init_pos_sigma", "init_vel_sigma",
                     "init_att_sigma", "accel_sf_mis", "gyro_misalignment_sigma",
                     "gyro_scale_factor_sigma", "gyro_sf_mis", "accel_scale_factor_sigma",
                     "accel_misalignment_sigma", "sf_mis_time",
                     "gap_accel_sigma", "gap_rate_sigma"):
            check_number(self, name)
        check_number(self, "cov_step", positive=True, upper=10.0)

    def accel_bias_sigmas(self) -> np.ndarray:
        """Initial 1-sigma of the effective accelerometer bias per axis x, y, z [m/s^2]."""
        z = self.accel_bias_sigma if self.accel_bias_sigma_z is None else self.accel_bias_sigma_z
        return np.array([self.accel_bias_sigma, self.accel_bias_sigma, z])

    def process_noise(self, n_states: int = ie.N_STATES) -> itu.ProcessNoise:
        """The process noise of eqs. (5), (5a) for a filter of ``n_states`` (extra states 0)."""
        q = np.zeros(n_states)
        q[: ie.N_STATES] = ie.process_noise_diagonal(
            ie.noise_densities(self.accel_vrw, self.gyro_arw, self.accel_bias_rw,
                               self.gyro_bias_rw), 1.0)
        k = itu.ProcessNoise.motion_coefficient
        return itu.ProcessNoise(q, k(self.accel_sf_mis, self.sf_mis_time),
                               k(self.gyro_sf_mis, self.sf_mis_time))


def initial_covariance(
    pos: np.ndarray,
    pos_sigma_ned: np.ndarray,
    vel_sigma: np.ndarray,
    att_sigma: np.ndarray,
    accel_bias_sigma: float | np.ndarray,
    gyro_bias_sigma: float | np.ndarray,
) -> np.ndarray:
    """P0 of the 15 states, eq. (6).

    Parameters
    ----------
    pos : ndarray, shape (3,)
        Initial latitude [rad], longitude [rad], height [m].
    pos_sigma_ned : ndarray, shape (3,)
        Position 1-sigma N, E, D [m].
    vel_sigma : ndarray, shape (3,)
        [m/s].
    att_sigma : ndarray, shape (3,)
        phi 1-sigma [rad].
    accel_bias_sigma, gyro_bias_sigma : float or ndarray, shape (3,)
        [m/s^2], [rad/s], the same for each axis or per axis x, y, z.

    Returns
    -------
    P0 : ndarray, shape (15, 15)
    """
    d = np.empty(ie.N_STATES)
    d[ie.POS] = np.asarray(pos_sigma_ned, dtype=float) / np.abs(ie.position_scale(pos))
    d[ie.VEL] = vel_sigma
    d[ie.ATT] = att_sigma
    d[ie.BA] = accel_bias_sigma
    d[ie.BG] = gyro_bias_sigma
    return np.diag(d**2)


class InitialNavError(ValueError):
    """A filter has no initial solution to start from."""


def initial_solution(context: FilterContext, filter_name: str) -> tuple[np.ndarray, float]:
    """The navigation vector (10,) and time [s] of ``metadata.initial_nav``.

    Raises ``ValueError`` naming the filter when a key (t_ns, pos, v_n, q_nb) is missing or a
    value is not finite.
    """
    init = context.metadata.initial_nav
    missing = [k for k in ("t_ns", "pos", "v_n", "q_nb") if k not in init]
    if missing:
        raise InitialNavError(
            f"no initial solution (missing "
            f"{', '.join(missing)}); give one with --init align, --init reference "
            "(with --reference) or an [initial] table"
        )
    nav = strapdown.nav_vector(init["pos"], init["v_n"], init["q_nb"])
    if not np.all(np.isfinite(nav)):
        raise ValueError(f"filter {filter_name!r}: metadata.initial_nav is not finite: {nav}")
    return nav, (int(init["t_ns"]) - int(context.t0_ns)) * 1e-9


def initial_sigma(
    initial_nav: Mapping[str, Any], key: str, value: float | None = None, *,
    param: str | None = None,
) -> np.ndarray:
    """Initial 1-sigma per axis, shape (3,): ``value`` when set (a filter parameter, named
    ``param``), else ``initial_nav["sigma"][key]`` (``pos_ned`` [m], ``v_n`` [m/s], ``phi``
    [rad])."""
    if value is not None:
        return np.full(3, float(value))
    sigma = initial_nav.get("sigma", {})
    if key not in sigma:
        hint = f"; set the filter parameter {param}" if param else ""
        raise ValueError(
            f"metadata.initial_nav has no sigma[{key!r}] (has: {', '.join(sigma) or 'none'})"
            + hint
        )
    out = np.asarray(sigma[key], dtype=float).reshape(-1)
    if out.shape != (3,) or not np.all(np.isfinite(out)) or np.any(out < 0):
        raise ValueError(f"metadata.initial_nav sigma[{key!r}] must be 3 values >= 0, got {out}")
    return out


NAV_STATES: tuple[State, ...] = ie.nav_states(ie.Vertical.HEIGHT)
"""Declarations of the 15 entries of ``Estimate.x`` (biases as total estimates)."""
NAV_STATE_NAMES: tuple[str, ...] = state_names(NAV_STATES)
GYRO_Z_STATES: tuple[State, ...] = (
    State("m_g_xz", "rad", Quantity.GYRO_MISALIGNMENT,
          TrueConstant("imu.gyro_misalignment", (0, 2))),
    State("m_g_yz", "rad", Quantity.GYRO_MISALIGNMENT,
          TrueConstant("imu.gyro_misalignment", (1, 2))),
    State("s_g_z", "-", Quantity.GYRO_SCALE_FACTOR, TrueConstant("imu.gyro_scale_factor", (2,))),
)
"""The gyro z-rate states (``gyro_misalignment_states``): misalignments M[0, 2], M[1, 2] and
scale factor S[2, 2] of :mod:`navreplay.sensors.imu`, scored against the constants in
``metadata.true_errors["imu"]``."""
GYRO_Z_NAMES: tuple[str, ...] = state_names(GYRO_Z_STATES)
GYRO_XY_STATES: tuple[State, ...] = tuple(
    State(f"s_g_{a}", "-", Quantity.GYRO_SCALE_FACTOR,
          TrueConstant("imu.gyro_scale_factor", (i,))) if i == j else
    State(f"m_g_{a}{b}", "rad", Quantity.GYRO_MISALIGNMENT,
          TrueConstant("imu.gyro_misalignment", (i, j)))
    for j, b in enumerate("xy") for i, a in enumerate("xyz"))
"""The gyro roll- and pitch-rate states (``gyro_roll_pitch_states``): the columns x and y of
S + M (s_g_x, m_g_yx, m_g_zx, m_g_xy, s_g_y, m_g_zy)."""
GYRO_STATES: tuple[State, ...] = GYRO_Z_STATES + GYRO_XY_STATES
"""Every gyro scale-factor and misalignment state, in the order of the columns
:data:`~navreplay.filters.ins_error.GYRO_COLUMNS`."""
ACCEL_MOTION_STATES: tuple[State, ...] = tuple(
    State(f"s_a_{a}", "-", Quantity.ACCEL_SCALE_FACTOR,
          TrueConstant("imu.accel_scale_factor", (i,))) if i == j else
    State(f"m_a_{a}{b}", "rad", Quantity.ACCEL_MISALIGNMENT,
          TrueConstant("imu.accel_misalignment", (i, j)))
    for j, b in enumerate("xy") for i, a in enumerate("xyz"))
"""The accelerometer states (``accel_motion_states``): the columns x and y of S_a + M_a of
:mod:`navreplay.sensors.imu` (s_a_x, m_a_yx, m_a_zx, m_a_xy, s_a_y, m_a_zy), scored against the
constants in ``metadata.true_errors["imu"]``."""
ACCEL_LOAD_STATES: tuple[State, ...] = (
    State("m_a_xz", "rad", Quantity.ACCEL_MISALIGNMENT,
          TrueConstant("imu.accel_misalignment", (0, 2))),
    State("m_a_yz", "rad", Quantity.ACCEL_MISALIGNMENT,
          TrueConstant("imu.accel_misalignment", (1, 2))),
    State("s_a_z", "-", Quantity.ACCEL_SCALE_FACTOR, TrueConstant("imu.accel_scale_factor", (2,))),
)
"""The accelerometer load-factor states (``accel_load_states``): the column z of S_a + M_a
acting on ``f_z + g0``."""
ACCEL_STATES: tuple[State, ...] = ACCEL_MOTION_STATES + ACCEL_LOAD_STATES
"""Every accelerometer scale-factor and misalignment state, in the order of the columns
:data:`~navreplay.filters.ins_error.ACCEL_COLUMNS`."""


def column_sigmas(columns: tuple[int, ...], scale_factor: float,
                  misalignment: float) -> np.ndarray:
    """The 1-sigma of the states of the given columns of ``S + M``, three per column (rows x,
    y, z): the scale factor on the diagonal, the misalignment off it, shape (3 columns,).

    >>> column_sigmas((2, 0), 1e-4, 5e-4).tolist()
    [0.0005, 0.0005, 0.0001, 0.0001, 0.0005, 0.0005]
    """
    return np.array([scale_factor if i == j else misalignment
                     for j in columns for i in range(3)])


@register_filter
class InsFilter(Filter, InsSmoothing):
    """Free-inertial navigation with the predicted error covariance (see the module docstring)."""

    name: ClassVar[str] = "ins"
    summary: ClassVar[str] = (
        "free-inertial strapdown INS from metadata.initial_nav, 15-state error covariance"
        " with the gyro and accelerometer scale-factor and misalignment states"
    )
    requires: ClassVar[tuple[StreamKind, ...]] = (StreamKind.IMU,)
    Params: ClassVar[type[FilterParams]] = InsParams
    measurements: tuple[MeasurementKind, ...] | None = ()  # no measurement update

    params: InsParams

    @classmethod
    def settings_from_sensors(cls, sensors: SensorSpecs) -> dict[str, Any]:
        """The IMU settings of :func:`imu_settings`."""
        return imu_settings(sensors)

    @classmethod
    def default_sensors(cls) -> SensorSpecs:
        return TACTICAL

    @classmethod
    def modelled_terms(cls, params: FilterParams) -> dict[str, frozenset[str]]:
        """Every IMU error term: white noise and bias random walks in Q, turn-on bias,
        instability, scale factor, misalignment and g-sensitivity in the initial sigmas of the
        effective biases (:func:`imu_settings`) and in the scale-factor and misalignment
        states."""
        return {"imu": frozenset(ImuModel.error_terms)}

    def __init__(self, params: InsParams, context: FilterContext) -> None:
        super().__init__(params, context)
        self.nav, self.t = initial_solution(context, self.name)
        init = context.metadata.initial_nav
        self.b_a = np.asarray(init.get("accel_bias", np.zeros(3)), dtype=float).reshape(3)
        self.b_g = np.asarray(init.get("gyro_bias", np.zeros(3)), dtype=float).reshape(3)
        p = params
        P0 = initial_covariance(
            self.nav[strapdown.POS],
            initial_sigma(init, "pos_ned", p.init_pos_sigma, param="init_pos_sigma"),
            initial_sigma(init, "v_n", p.init_vel_sigma, param="init_vel_sigma"),
            initial_sigma(init, "phi", p.init_att_sigma, param="init_att_sigma"),
            p.accel_bias_sigmas(),
            p.gyro_bias_sigma,
        )
        extra = self._extra_declarations()
        ng = (3 if p.gyro_roll_pitch_states else 1) if p.gyro_misalignment_states else 0
        na = (3 if p.accel_load_states else 2) if p.accel_motion_states else 0
        gz = ie.N_STATES + len(extra)
        self._gz = slice(gz, gz + 3 * ng) if ng else None
        self.gyro_z = np.zeros(3 * ng)  # estimates of the columns z (x, y) of S_g + M_g
        ga = gz + 3 * ng
        self._ga = slice(ga, ga + 3 * na) if na else None
        self.accel_k = np.zeros(3 * na)  # estimates of the columns x, y (z) of S_a + M_a
        self.states = (NAV_STATES + extra + GYRO_STATES[:3 * ng] + ACCEL_STATES[:3 * na]
                       + self._late_declarations())
        n = len(self.states)
        self.P = np.zeros((n, n))
        self.P[: ie.N_STATES, : ie.N_STATES] = P0
        if self._gz is not None:
            self.P[self._gz, self._gz] = np.diag(column_sigmas(
                ie.GYRO_COLUMNS[:ng], p.gyro_scale_factor_sigma, p.gyro_misalignment_sigma) ** 2)
        if self._ga is not None:
            sigma = column_sigmas(ie.ACCEL_COLUMNS[:na], p.accel_scale_factor_sigma,
                                  p.accel_misalignment_sigma)
            self.P[self._ga, self._ga] = np.diag(sigma**2)
            if na == 3:  # the column z is part of the effective bias: b_a_i holds -g0 k_z[i]
                for i in range(3):
                    b, k = ie.BA.start + i, ga + 6 + i
                    cov = -min(G0 * sigma[6 + i], math.sqrt(self.P[b, b])) * sigma[6 + i]
                    self.P[b, k] = self.P[k, b] = cov
        self._noise = self._process_noise(n)
        self._time_update = itu.TimeUpdate(self._noise, p.cov_step)
        self.omega_ib_b = np.zeros(3)  # compensated body rate of the last IMU sample
        self._init_extra()
        kalman.check_covariance(self.P, name="P0", t=self.t)

    # -- hooks for filters with more states ----------------------------------------------

    def _extra_declarations(self) -> tuple[State, ...]:
        """Declarations of the states after the 15 and before the gyro z-rate states (random
        constants; F = 0, Q = 0 for them)."""
        return ()

    def _late_declarations(self) -> tuple[State, ...]:
        """Declarations of the states after the IMU error states (outside F: random constants,
        random walks or first-order Markov processes of their own)."""
        return ()

    def _init_extra(self) -> None:
        """Set P0 and estimates of the extra states (self.P is allocated)."""

    def _extra_values(self) -> np.ndarray:
        return np.zeros(0)

    def _process_noise(self, n: int) -> itu.ProcessNoise:
        """The process noise (and model options) of the time update for n states: with the
        gyro z-rate states (eq. 5b) the gyro motion noise of eq. (5a) is off, with the
        accelerometer states (eq. 5c) its accelerometer motion noise."""
        noise = self.params.process_noise(n)
        if self._gz is not None:
            noise = dataclasses.replace(noise, k_gyro=0.0, gyro_z_states=self._gz.start,
                                        gyro_columns=len(self.gyro_z) // 3)
        if self._ga is not None:
            noise = dataclasses.replace(noise, k_acc=0.0, accel_states=self._ga.start,
                                        accel_columns=len(self.accel_k) // 3)
        return noise

    def _gyro_z_estimates(self) -> np.ndarray | None:
        """Estimates of the gyro z-rate errors (m_xz, m_yz, s_z) of ins_error eq. (22) that
        the IMU is compensated for, or None without the states."""
        return self.gyro_z if self._gz is not None else None

    def _accel_estimates(self) -> np.ndarray | None:
        """Estimates of the accelerometer errors of ins_error eq. (23), or None."""
        return self.accel_k if self._ga is not None else None

    def _compensate_accel(self, f_b: np.ndarray) -> np.ndarray:
        """Raw accelerometer samples (k, 3) compensated for the errors of eq. (23), if any
        (the time update subtracts the bias estimate)."""
        k_a = self._accel_estimates()
        if k_a is None or not k_a.any():
            return f_b
        return itu.compensate_accel(f_b, self.b_a, k_a)

    def _compensate_gyro(self, omega_ib_b: np.ndarray) -> np.ndarray:
        """Raw gyro samples (k, 3) with the compensations other than the bias applied (the
        time update subtracts the bias estimate): the z-rate errors, if any."""
        k_z = self._gyro_z_estimates()
        if k_z is None or not k_z.any():
            return omega_ib_b
        return itu.compensate_gyro(omega_ib_b, self.b_g, k_z)

    def _state_vector(self) -> np.ndarray:
        """``Estimate.x``: zeros for the error states, the bias and extra estimates."""
        x = np.zeros(self.P.shape[0])
        x[ie.BA] = self.b_a
        x[ie.BG] = self.b_g
        extra = self._extra_values()
        x[ie.N_STATES:ie.N_STATES + extra.shape[0]] = extra
        if self._gz is not None:
            x[self._gz] = self.gyro_z
        if self._ga is not None:
            x[self._ga] = self.accel_k
        return x

    # -- the Filter interface --------------------------------------------------------------

    def propagate(self, t: np.ndarray, imu: Mapping[str, np.ndarray]) -> None:
        omega = self._compensate_gyro(imu["omega_ib_b"])
        step = self._time_update.propagate(self.nav, self.P, self.t, t, omega,
                                           self._compensate_accel(imu["f_b"]), self.b_a,
                                           self.b_g)  # (1)-(5c)
        if step is None:
            return
        self.nav, self.P, self.t = step
        self.omega_ib_b = omega[-1] - self.b_g
        kalman.check_covariance(self.P, t=self.t)

    def update(
        self, kind: StreamKind, t: float, sample: Mapping[str, Any]
    ) -> list[Innovation] | None:
        return None

    def bridge_imu_gap(self, t: float, since: float) -> None:
        """No IMU samples from ``since`` until after ``t`` [s]: dead-reckon to t with the
        covariance of the unknown motion (:func:`navreplay.filters.imu_gap.bridge`)."""
        if t <= self.t:
            return
        self._sync_covariance()
        p = self.params
        phi = np.empty(self.P.shape) if self._smoothing is not None else None
        self.nav, self.P = imu_gap.bridge(self.nav, self.P, (self.t - since, t - since),
                                          p.gap_accel_sigma, p.gap_rate_sigma, self._noise.q,
                                          markov=self._noise.markov, phi_out=phi)
        if phi is not None:
            self._smoothing_transition(phi)
        self.t = t
        self._time_update.prev[:] = 0.0  # no coning/sculling across the gap
        kalman.check_covariance(self.P, t=self.t)

    def estimate(self) -> Estimate:
        self._sync_covariance()
        return Estimate(
            self.t, self._state_vector(), self.P,
            NavSolution.from_vector(self.nav),
        )

    def run_events(self, run: EventRun) -> int:
        """A run of output ticks (all of ``ins``'s events: it consumes no aiding stream) in one
        compiled call of the time update
        (:meth:`~navreplay.filters.ins_time_update.TimeUpdate.propagate_outputs`): for each tick,
        :meth:`propagate` over its IMU segment and :meth:`estimate`, bit for bit. Other runs,
        every run of a subclass that changes :meth:`propagate` or :meth:`estimate`, of a
        smoothed filter, and those of a filter with first-order Markov states (their estimates
        decay from tick to tick, the kernel writes one state vector) go through the default."""
        if (overrides(self, InsFilter, "propagate", "estimate") or self._smoothing is not None
                or (run.codes != TICK).any() or not run.record.all()
                or self._time_update.model.rate.any()):
            return super().run_events(run)
        m = len(run)
        t_out, x_out, P_out, nav_out = run.out()
        state = self._state_vector()
        if x_out.shape[1:] != state.shape:  # the declarations do not fit: named by the default
            return super().run_events(run)
        _, _, _, w_last = self._time_update.propagate_outputs(
            self.nav, self.P, self.t, run.t, run.imu["omega_ib_b"], run.imu["f_b"], self.b_a,
            self.b_g, run.ends, self._gyro_z_estimates(), self._accel_estimates(),
            out=(t_out, nav_out, P_out),
        )
        self.nav = nav_out[m - 1].copy()
        self.P = P_out[m - 1].copy()
        self.t = float(t_out[m - 1])
        if not np.isnan(w_last[0]):
            self.omega_ib_b = w_last
        x_out[:m] = self._state_vector()
        run.add_rows(m)
        run.done = m
        return m

    # -- covariance propagation ------------------------------------------------------------

    def _sync_covariance(self) -> None:
        """Close the open covariance step so that P belongs to the current time."""
        self.P = self._time_update.close(self.P, self.t)

    # -- feedback --------------------------------------------------------------------------

    def _feedback(self, dx: np.ndarray) -> None:
        """Subtract estimated errors (n,) from the navigation solution and the estimates."""
        self._smoothing_feedback(dx)
        self.nav = ie.apply_correction(self.nav, dx)
        self.b_a = self.b_a - dx[ie.BA]
        self.b_g = self.b_g - dx[ie.BG]
        if self._gz is not None:
            self.gyro_z = self.gyro_z - dx[self._gz]
        if self._ga is not None:
            self.accel_k = self.accel_k - dx[self._ga]

