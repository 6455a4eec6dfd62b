"""Loosely coupled GPS/INS ("gps-ins"): error-state EKF with feedback on the NED INS error model.

The strapdown INS of :class:`navreplay.filters.ins.InsFilter` (initial solution from
``metadata.initial_nav``, IMU compensated with the bias estimates) is corrected by GPS position
fixes and, when the recording has them, GPS NED velocities. The filter estimates the errors of
the navigation solution, of the IMU biases, of the gyro scale factors and misalignments (the
column z that the yaw rate drives, ``gyro_misalignment_states``, and the columns x and y that
roll and pitch rates drive, ``gyro_roll_pitch_states``), of the accelerometer's (the columns x
and y that the forward and lateral specific force drive, ``accel_motion_states``, and the
column z that the load factor drives, ``accel_load_states``; all four on by default),
optionally of the GPS antenna lever arm and, when the GNSS error has a time-correlated part
(``gps_pos_gm_sigma``, from the recording's GNSS specification or ``-p``), of that part as
three first-order Gauss-Markov states. It feeds them back into the solution, the IMU
compensation and the Gauss-Markov estimate after every update, and so keeps its error state
at 0.

States
------
===== ==================== ========= ============ =============================================
index name (Estimate.x)    frame     unit         state (error, estimate minus truth)
===== ==================== ========= ============ =============================================
0-2   dlat, dlon, dh       -         rad, rad, m  position error (0 after feedback)
3-5   dv_N, dv_E, dv_D     n (NED)   m/s          velocity error (0)
6-8   phi_N, phi_E, phi_D  n         rad          attitude error, phi angle (0)
9-11  b_a_x, b_a_y, b_a_z  b (FRD)   m/s^2        accelerometer bias error; x holds the estimate
12-14 b_g_x, b_g_y, b_g_z  b (FRD)   rad/s        gyro bias error; x holds the estimate
15-17 l_x, l_y, l_z        b (FRD)   m            lever-arm error (``estimate_lever_arm``);
                                                  x holds the lever-arm estimate
g     m_g_xz, m_g_yz,      b (FRD)   rad, rad, -  column z of S_g + M_g (the z rate into x, y,
      s_g_z                                       z); x holds the estimates
g+3   s_g_x, m_g_yx, m_g_zx b (FRD)  -, rad, rad  column x (``gyro_roll_pitch_states``)
g+6   m_g_xy, s_g_y, m_g_zy b (FRD)  rad, -, rad  column y
a     s_a_x, m_a_yx, m_a_zx b (FRD)  -, rad, rad  column x of S_a + M_a (f_x into x, y, z)
a+3   m_a_xy, s_a_y, m_a_zy b (FRD)  rad, -, rad  column y
a+6   m_a_xz, m_a_yz, s_a_z b (FRD)  rad, rad, -  column z, on f_z + g0 (``accel_load_states``)
p     gm_N, gm_E, gm_D     n (NED)   m            Gauss-Markov GNSS position error
                                                  (``gps_pos_gm_sigma``); x holds its estimate
===== ==================== ========= ============ =============================================

The gyro states follow the lever arm when it is estimated (g = 18 with ``estimate_lever_arm``,
else 15), the accelerometer states follow them (a = g + 9 with all three gyro columns) and the
Gauss-Markov states come last (p = a + 9). Scoring (declared ``states``): the navigation
states and biases as ``ins``; the gyro and accelerometer states against the constants
``metadata.true_errors["imu"]["gyro_misalignment"][i][j]``, ``["gyro_scale_factor"][j]``,
``["accel_misalignment"][i][j]`` and ``["accel_scale_factor"][j]`` (the S and M of
:mod:`navreplay.sensors.imu`, ``omega_meas = (I + S + M) omega + b``); the Gauss-Markov states
against the truth column ``gps_pos_gm``. Why these states and the ensemble consistency:
docs/methods/ins.md.

Errors (signs)
--------------
Position, velocity, biases, scale factors and misalignments, lever arm and the GNSS error:
estimate minus truth, ``dx = x_hat - x``. Attitude: ``C_nb_hat = (I - [phi x]) C_nb`` (a
positive phi_D is an estimated heading smaller than the truth). Feedback subtracts:
``lat, lon, h, v_n, b_a, b_g, k, l, gm -= dx`` and ``q_nb_hat <- normalize([1, phi/2] (x)
q_nb_hat)``, then ``dx = 0``.

Models
------
Process (continuous, :mod:`navreplay.filters.ins_error`)::

    dx' = F dx + G w,   w = [n_a, n_g, n_ba, n_bg]                                      (1)
    F: the 15x15 NED error model, eqs. (6)-(19) there; lever arm: F = 0, Q = 0          (2)
    gyro columns k_j = (S_g + M_g)[:, j], j = z, x, y, random constants:
      omega_hat = omega_meas - b_g_hat - sum_j k_j_hat (omega_meas_j - b_g_hat_j)
      F[phi, (k_j)_i] = +C_nb_hat[:, i] omega_hat_j     (ins_error eq. 22)              (2a)
      P0: gyro_scale_factor_sigma^2 on the diagonal terms, gyro_misalignment_sigma^2 off
    accelerometer columns k_j = (S_a + M_a)[:, j], j = x, y, z, random constants:
      f_hat = f_meas - b_a_hat - sum_j k_j_hat u_j,  u_j = f_j - b_a_j (+ g0 for j = z)
      F[v, (k_j)_i] = -C_nb_hat[:, i] u_j              (ins_error eq. 23)               (2b)
      P0: accel_scale_factor_sigma^2, accel_misalignment_sigma^2; cov(b_a_i, k_z[i]) =
      -g0 sigma(k_z[i])^2 (the effective bias holds k_z (-g0))
    Gauss-Markov GNSS position error gm (N, E, D [m]), tau = gps_pos_gm_tau:
      gm' = -gm / tau + w,  E[w^2] = 2 sigma_gm^2 / tau,  P0 = sigma_gm^2               (13)
      Phi = exp(-T / tau), Qd = sigma_gm^2 (1 - Phi^2) (kalman eq. 5a); the estimate
      decays as exp(-T / tau) between updates
    Phi = I + F T + (F T)^2 / 2,  Qd = G Qc G^T T (the motion terms of ins eq. 5a are
    off with (2a) and (2b)),
    T = cov_step (0.1 s), cut short at updates and outputs                                (3)

GPS position (antenna at ``l_b`` from the IMU, body frame), residual in NED metres::

    D = diag(R_M + h, (R_N + h) cos lat, -1)                   (dlat, dlon, dh) -> N, E, D
    p_ant_hat = p_hat + D^-1 (C_nb_hat l_hat + v_hat tau)       tau = t_fix - t_ins >= 0 (4)
    z = D (p_ant_hat - p_gps)                                   (3,) [m]                  (5)
    H = [ D | 0 | [(C_nb_hat l_hat) x] | 0 | 0 | C_nb_hat ]                               (6)
    R = diag(pos_sigma^2) * gps_pos_sigma_scale^2                                         (7)
        pos_sigma: the fix's (its message covariance), else ``gps_pos_sigma`` (the GNSS
        specification: white and Gauss-Markov parts together)
    with the Gauss-Markov states: z += gm_hat, H[:, p] = I                                (6a)
        R = max(diag(pos_sigma^2) scale^2 - sigma_gm^2, 0.01 diag(pos_sigma^2) scale^2)  (7a)
        (the fix's variance is white and Gauss-Markov together; R is its white part)

GPS velocity, with ``w = omega_ib_b_hat`` (last compensated gyro sample) and
``w_in = w_ie + w_en``::

    v_ant_hat = v_hat + C_nb_hat (w x l_hat) - w_in x (C_nb_hat l_hat)                    (8)
    z = v_ant_hat - v_gps                                       (3,) [m/s]                (9)
    H = [ 0 | I | [(C (w x l)) x] - [w_in x][(C l) x] | 0 | C [l x] | C [w x] - [w_in x] C ] (10)
    H[:, (k_j)_i] = (C [l x])[:, i] w_j                         (gyro columns)          (10a)
    R = diag(vel_sigma^2) * gps_vel_sigma_scale^2                                          (11)
        vel_sigma: the sample's, else ``gps_vel_sigma``; a time-correlated velocity error
        (the specification's ``vel_gm_sigma``) is taken as white, and the run says so once
        (:meth:`GpsInsFilter.modelled_terms`)

Update (the compiled kernel of :func:`navreplay.filters.kalman.correct`, Cholesky + Joseph
form, with its checks) of the error state dx = 0, then feedback (12); the models, update and
feedback are compiled together in :mod:`navreplay.filters.gnss_models`, and the replay engine
hands whole runs of events to :meth:`GpsInsFilter.run_events`. Each update returns its
innovation ``nu = z`` and ``S`` for NIS statistics (``"gps_pos"`` [m], ``"gps_vel"`` [m/s]).

(10) omits the derivatives of w_in with respect to position and velocity in the lever-arm term
(below 1e-8 m/s for metre-level errors); everything else in (6), (6a), (10) and (10a) was
checked against central differences of (4)-(5) and (8)-(9) in tests/filters/test_gps_ins.py.
Samples older than the INS solution (before the initial solution's time) are ignored.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from navreplay.core.streams import StreamKind
from navreplay.filters import gnss_models as gnss
from navreplay.filters import gps_ins_events as ev
from navreplay.filters import ins_time_update as itu
from navreplay.filters import kalman
from navreplay.filters.base import (
    EventRun,
    FilterContext,
    FilterParams,
    Innovation,
    MeasurementKind,
    Quantity,
    State,
    TruthColumn,
    check_number,
    overrides,
)
from navreplay.filters.ins import InsFilter, InsParams
from navreplay.filters.ins_time_update import Imu
from navreplay.filters.registry import register_filter
from navreplay.filters.smoothable import SmoothingSteps
from navreplay.sensors.specs import SensorSpecs

_NO_SUM = np.zeros(0)
"""The corrections of the updates are not summed (no smoother)."""
LEVER = slice(15, 18)
"""Lever-arm error states (present with ``estimate_lever_arm``)."""
LEVER_STATES: tuple[State, ...] = tuple(
    State(f"l_{a}", "m", Quantity.LEVER_ARM) for a in "xyz")
"""Lever-arm estimates (``estimate_lever_arm``), body [m]; the truth is the parameter's."""
GNSS_GM_STATES: tuple[State, ...] = tuple(
    State(f"gm_{a}", "m", Quantity.GNSS_ERROR, TruthColumn("gps_pos_gm", (i,)))
    for i, a in enumerate("NED"))
"""The Gauss-Markov part of the GNSS position error N, E, D [m] (``gps_pos_gm_sigma``),
scored against the truth column ``gps_pos_gm`` of the simulated drives."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class GpsInsParams(InsParams):
    """Parameters of ``gps-ins``: the INS error model of ``ins`` plus the GPS measurements."""

    lever_arm_b: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """GPS antenna position relative to the IMU, body FRD [m] (initial estimate)."""
    estimate_lever_arm: bool = False
    """Add the three lever-arm error states (random constants)."""
    lever_arm_sigma: float = 0.1
    """Initial 1-sigma of the lever arm per axis [m] (with ``estimate_lever_arm``)."""
    gps_pos_sigma: tuple[float, float, float] | None = None
    """1-sigma position noise N, E, D of a fix whose message gives none (no ``pos_sigma``
    column) [m]; None: such fixes are refused. Derived from the GNSS specification
    (``sqrt(pos_sigma^2 + pos_gm_sigma^2)``)."""
    gps_vel_sigma: tuple[float, float, float] | None = None
    """1-sigma velocity noise N, E, D of a velocity sample without its own [m/s]; None:
    refused. Derived from the GNSS specification."""
    gps_pos_sigma_scale: float = 1.0
    """Factor on the fix's ``pos_sigma`` in R [-]."""
    gps_vel_sigma_scale: float = 1.0
    """Factor on the velocity's ``vel_sigma`` in R [-]."""
    use_gps_vel: bool = True
    """Use the ``gps_vel`` stream when the recording has it."""
    accel_sf_mis: float = 0.4e-3
    """Accelerometer scale-factor / misalignment under motion, 1-sigma [-] (ins eq. 5a), used
    only without ``accel_motion_states``: for the ``tactical`` grade (300 ppm, 0.5 mrad) the
    per-axis RMS of ``(S_a + M_a) a`` is sqrt((300 ppm)^2 + 2 (0.5 mrad)^2) / sqrt(3) =
    0.46e-3 |a|; the white-noise form with tau = ``sf_mis_time`` slightly overstates a
    constant error."""
    gps_pos_gm_sigma: tuple[float, ...] = (0.0,)
    """Stationary 1-sigma of the time-correlated (first-order Gauss-Markov) GNSS position
    error, N, E, D (or one value for all) [m]; above 0: three Gauss-Markov states (eqs. 6a,
    7a, 13) and R holds the rest of the fix's variance. Derived from the GNSS specification
    (``pos_gm_sigma``)."""
    gps_pos_gm_tau: float = 300.0
    """Correlation time of the Gauss-Markov GNSS position error [s] (``pos_gm_tau``)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        gm = tuple(float(v) for v in self.gps_pos_gm_sigma)
        if len(gm) == 1:
            gm *= 3
        if len(gm) != 3 or not all(math.isfinite(v) and v >= 0.0 for v in gm):
            raise ValueError(f"gps_pos_gm_sigma must be one or three finite values >= 0 [m], "
                             f"got {self.gps_pos_gm_sigma!r}")
        object.__setattr__(self, "gps_pos_gm_sigma", gm)
        check_number(self, "gps_pos_gm_tau", positive=True)
        lever = tuple(float(v) for v in self.lever_arm_b)
        if len(lever) != 3 or not all(math.isfinite(v) for v in lever):
            raise ValueError(f"lever_arm_b must be three finite values [m], got {lever!r}")
        if max(abs(v) for v in lever) > 100.0:
            raise ValueError(f"lever_arm_b must be within 100 m per axis, got {lever!r}")
        object.__setattr__(self, "lever_arm_b", lever)
        for name in ("gps_pos_sigma", "gps_vel_sigma"):
            value = getattr(self, name)
            if value is None:
                continue
            sigma = tuple(float(v) for v in value)
            if len(sigma) != 3 or not all(math.isfinite(v) and v > 0.0 for v in sigma):
                raise ValueError(f"{name} must be three finite values > 0, got {value!r}")
            object.__setattr__(self, name, sigma)
        check_number(self, "lever_arm_sigma")
        for name in ("gps_pos_sigma_scale", "gps_vel_sigma_scale"):
            check_number(self, name, positive=True)


def gps_position_model(
    nav: np.ndarray,
    lever_arm_b: np.ndarray,
    pos_gps: np.ndarray,
    pos_sigma: np.ndarray,
    n_states: int,
    *,
    lag: float = 0.0,
    lever_states: bool = False,
    gm_states: int | None = None,
    gm: np.ndarray | None = None,
    gm_var: np.ndarray | None = None,
) -> kalman.Measurement:
    """GPS position measurement, eqs. (4)-(7a).

    Parameters
    ----------
    nav : ndarray, shape (10,)
        INS navigation vector at ``t_fix - lag``.
    lever_arm_b : ndarray, shape (3,)
        Antenna lever arm estimate, body [m].
    pos_gps : ndarray, shape (3,)
        GPS latitude [rad], longitude [rad], height [m].
    pos_sigma : ndarray, shape (3,)
        GPS 1-sigma N, E, D [m].
    n_states : int
        Length of the error state.
    lag : float
        Time of the fix after the INS solution [s] (the position is extrapolated over it).
    lever_states : bool
        Whether states 15-17 are the lever-arm errors.
    gm_states : int, optional
        Index of the GNSS Gauss-Markov states (N, E, D), if any.
    gm, gm_var : ndarray, shape (3,), optional
        Their estimate [m] and stationary variance [m^2] (with ``gm_states``).

    Returns
    -------
    z : ndarray, shape (3,)
        Residual INS minus GPS, N, E, D [m].
    H : ndarray, shape (3, n_states)
    R : ndarray, shape (3,)
        Diagonal of R [m^2].
    """
    return _measurement(gnss.POSITION, nav, lever_arm_b, pos_gps, pos_sigma, n_states,
                        lag=lag, lever_states=lever_states,
                        gp=-1 if gm_states is None else gm_states, gm=gm, gm_var=gm_var)


def gps_velocity_model(
    nav: np.ndarray,
    lever_arm_b: np.ndarray,
    omega_ib_b: np.ndarray,
    v_gps: np.ndarray,
    vel_sigma: np.ndarray,
    n_states: int,
    *,
    lever_states: bool = False,
    gyro_z_states: int | None = None,
    gyro_columns: int = 1,
) -> kalman.Measurement:
    """GPS velocity measurement, eqs. (8)-(11).

    Parameters
    ----------
    nav : ndarray, shape (10,)
    lever_arm_b : ndarray, shape (3,)
        [m].
    omega_ib_b : ndarray, shape (3,)
        Bias-compensated body rate [rad/s].
    v_gps : ndarray, shape (3,)
        GPS velocity NED [m/s].
    vel_sigma : ndarray, shape (3,)
        [m/s].
    n_states : int
    lever_states : bool
    gyro_z_states : int, optional
        Index of the gyro scale-factor and misalignment states, if any: the columns z (m_xz,
        m_yz, s_z) and, with ``gyro_columns`` 3, x and y.
    gyro_columns : int

    Returns
    -------
    z : ndarray, shape (3,)
        Residual INS minus GPS [m/s].
    H : ndarray, shape (3, n_states)
    R : ndarray, shape (3,)
        Diagonal of R [(m/s)^2].
    """
    return _measurement(gnss.VELOCITY, nav, lever_arm_b, v_gps, vel_sigma, n_states,
                        omega_ib_b=omega_ib_b, lever_states=lever_states,
                        gz=-1 if gyro_z_states is None else gyro_z_states,
                        ng=0 if gyro_z_states is None else gyro_columns)


def _measurement(kind: int, nav: np.ndarray, lever_arm_b: np.ndarray, sample: np.ndarray,
                 sigma: np.ndarray, n_states: int, *, lag: float = 0.0,
                 omega_ib_b: np.ndarray | None = None, lever_states: bool = False,
                 gz: int = -1, ng: int = 0, gp: int = -1, gm: np.ndarray | None = None,
                 gm_var: np.ndarray | None = None) -> kalman.Measurement:
    """z, H, R of a GPS measurement by the compiled models of
    :mod:`navreplay.filters.gnss_models`."""
    f64 = np.ascontiguousarray
    nav, lever = f64(nav, dtype=float), f64(lever_arm_b, dtype=float)
    sample, sigma = f64(sample, dtype=float), f64(sigma, dtype=float)
    z, H, R = np.empty(3), np.empty((3, n_states)), np.empty((3, 3))
    if kind == gnss.POSITION:
        zero = np.zeros(3)
        gnss.position_model(nav, lever, sample, sigma, 1.0, float(lag), lever_states, gp,
                            zero if gm is None else f64(gm, dtype=float),
                            zero if gm_var is None else f64(gm_var, dtype=float), z, H, R)
    else:
        omega = f64(omega_ib_b, dtype=float)
        gnss.velocity_model(nav, lever, omega, sample, sigma, 1.0, lever_states, gz, ng, z, H,
                            R)
    return kalman.Measurement(z, H, np.diagonal(R).copy())


@register_filter
class GpsInsFilter(InsFilter):
    """Loosely coupled GPS/INS error-state EKF with feedback (see the module docstring)."""

    name: ClassVar[str] = "gps-ins"
    summary: ClassVar[str] = (
        "loosely coupled GPS/INS: NED error-state EKF with feedback (navigation, biases, IMU"
        " scale factors and misalignments), GPS position (+ velocity), optional lever arm and"
        " Gauss-Markov GNSS error"
    )
    requires: ClassVar[tuple[StreamKind, ...]] = (StreamKind.IMU, StreamKind.GPS)
    optional: ClassVar[tuple[StreamKind, ...]] = (StreamKind.GPS_VEL,)
    required_columns: ClassVar[Mapping[StreamKind, tuple[str, ...]]] = {
        StreamKind.GPS: ("pos",)}  # pos_sigma: the fix's, else gps_pos_sigma
    Params: ClassVar[type[FilterParams]] = GpsInsParams
    measurements: tuple[MeasurementKind, ...] | None = (
        MeasurementKind("gps_pos", ("N", "E", "D"), "m"),
        MeasurementKind("gps_vel", ("N", "E", "D"), "m/s"),
    )

    params: GpsInsParams

    @classmethod
    def settings_from_sensors(cls, sensors: SensorSpecs) -> dict[str, Any]:
        """The IMU settings of ``ins``, the GNSS noise of fixes without their own sigma and the
        GNSS Gauss-Markov position error."""
        out = super().settings_from_sensors(sensors)
        gps = sensors.get("gps")  # read only where stated
        if sensors.has("gps", "pos_gm_sigma"):
            out["gps_pos_gm_sigma"] = tuple(float(v) for v in gps.pos_gm_sigma)
            if sensors.has("gps", "pos_gm_tau"):
                out["gps_pos_gm_tau"] = float(gps.pos_gm_tau)
        if sensors.has("gps", "pos_sigma"):
            gm = gps.pos_gm_sigma if sensors.has("gps", "pos_gm_sigma") else 0.0
            out["gps_pos_sigma"] = tuple(np.hypot(gps.pos_sigma, gm).tolist())
        if sensors.has("gps", "vel_sigma"):
            gm = gps.vel_gm_sigma if sensors.has("gps", "vel_gm_sigma") else 0.0
            out["gps_vel_sigma"] = tuple(np.hypot(gps.vel_sigma, gm).tolist())
        return out

    @classmethod
    def modelled_terms(cls, params: FilterParams) -> dict[str, frozenset[str]]:
        """The IMU terms of ``ins``, the GNSS white noise (R) and, with the Gauss-Markov
        states, the time-correlated position error; R holds the velocity's time-correlated
        error as white (where the velocities are used)."""
        assert isinstance(params, GpsInsParams)  # the class's own Params
        gps = {"pos_sigma", "vel_sigma"}
        if any(params.gps_pos_gm_sigma):
            gps |= {"pos_gm_sigma"}
        if not params.use_gps_vel:  # the velocities are not used
            gps |= {"vel_gm_sigma"}
        return {**super().modelled_terms(params), "gps": frozenset(gps)}

    def __init__(self, params: GpsInsParams, context: FilterContext) -> None:
        self.lever_arm_b = np.array(params.lever_arm_b, dtype=float)
        super().__init__(params, context)
        # updated in place by the compiled feedback: arrays of their own
        self.b_a, self.b_g = self.b_a.copy(), self.b_g.copy()

    # -- extra states ----------------------------------------------------------------------

    def _extra_declarations(self) -> tuple[State, ...]:
        return LEVER_STATES if self.params.estimate_lever_arm else ()

    def _late_declarations(self) -> tuple[State, ...]:
        return GNSS_GM_STATES if any(self.params.gps_pos_gm_sigma) else ()

    def _init_extra(self) -> None:
        p = self.params
        if p.estimate_lever_arm:
            self.P[LEVER, LEVER] = np.eye(3) * p.lever_arm_sigma**2
        n = self.P.shape[0]
        self._gp = slice(n - 3, n) if any(p.gps_pos_gm_sigma) else None
        self.gnss_gm = np.zeros(3)  # the Gauss-Markov estimate [m] at the time gm_t
        self.gm_t = np.array([self.t])
        self._gm_var = np.asarray(p.gps_pos_gm_sigma, dtype=float) ** 2
        if self._gp is not None:
            self.P[self._gp, self._gp] = np.diag(self._gm_var)  # (13)

    def _process_noise(self, n: int) -> itu.ProcessNoise:
        noise = super()._process_noise(n)
        if not any(self.params.gps_pos_gm_sigma):
            return noise
        tau = self.params.gps_pos_gm_tau  # (13): gm' = -gm / tau + w, E[w^2] = 2 sigma^2 / tau
        q, rate = noise.q.copy(), np.zeros(n)
        rate[n - 3:] = 1.0 / tau
        q[n - 3:] = 2.0 * np.asarray(self.params.gps_pos_gm_sigma) ** 2 / tau
        return dataclasses.replace(noise, q=q, markov=rate)

    def _state_vector(self) -> np.ndarray:
        x = super()._state_vector()
        if self._gp is not None:
            gnss.gm_at(self.gnss_gm, float(self.gm_t[0]), self.t, self.params.gps_pos_gm_tau,
                       x[self._gp])
        return x

    def _layout(self) -> gnss.Layout:
        return gnss.Layout(self.params.estimate_lever_arm,
                           -1 if self._gz is None else self._gz.start, len(self.gyro_z) // 3,
                           -1 if self._ga is None else self._ga.start, len(self.accel_k) // 3,
                           -1 if self._gp is None else self._gp.start)

    def _extra_values(self) -> np.ndarray:
        return self.lever_arm_b if self.params.estimate_lever_arm else np.zeros(0)

    # -- updates ---------------------------------------------------------------------------

    def update(
        self, kind: StreamKind, t: float, sample: Mapping[str, Any]
    ) -> list[Innovation] | None:
        if t < self.t - 1e-6:
            return None  # before the initial solution
        p = self.params
        if kind is StreamKind.GPS:
            code, name, lag = gnss.POSITION, "gps_pos", max(t - self.t, 0.0)
            value, scale = sample["pos"], p.gps_pos_sigma_scale
        elif kind is StreamKind.GPS_VEL and p.use_gps_vel:
            code, name, lag = gnss.VELOCITY, "gps_vel", 0.0
            value, scale = sample["v_n"], p.gps_vel_sigma_scale
        else:
            return None
        sigma = self._sigma(kind, sample)
        self._sync_covariance()
        f64 = np.ascontiguousarray
        value, sigma = f64(value, dtype=float), f64(sigma, dtype=float)
        self._smoothing_prior()
        log = self._smoothing
        ok, nav, P, nu, S = gnss.gps_update(
            code, self.nav, self.P, self.t, value, sigma, scale, lag, self.omega_ib_b,
            self._estimates(), self._layout(), self._gauss_markov(), kalman.DEFAULT_RTOL,
            _NO_SUM if log is None else log.dx)  # (4)-(12), the correction kept for a smoother
        if not ok:  # the checked path names what is wrong (and keeps the correction)
            c = kalman.correct(np.zeros(self.P.shape[0]), self.P, *self._measurement(
                code, value, sigma * scale, lag), t=t)
            self.P = c.P
            self._feedback(c.x)
            return [c.innovation(name, t)]
        self.nav, self.P = nav, P
        return [Innovation(name, t, nu, S)]

    def _sigma(self, kind: StreamKind, sample: Mapping[str, Any]) -> np.ndarray:
        """The 1-sigma of a GPS sample (3,) or of a block of them (k, 3): the sample's own,
        else the ``gps_pos_sigma`` / ``gps_vel_sigma`` parameter."""
        column, param = (("pos_sigma", "gps_pos_sigma") if kind is StreamKind.GPS
                         else ("vel_sigma", "gps_vel_sigma"))
        if column in sample:
            return sample[column]
        fallback = getattr(self.params, param)
        if fallback is None:
            raise ValueError(f"the {kind} samples carry no {column} (no covariance in the "
                             f"messages): set {param}, or give [sensors.gps] in --config")
        shape = np.shape(sample["pos" if kind is StreamKind.GPS else "v_n"])
        return np.broadcast_to(np.asarray(fallback, dtype=float), shape)

    def _estimates(self) -> gnss.Estimates:
        """The estimates the compiled update corrects in place."""
        return gnss.Estimates(self.b_a, self.b_g, self.lever_arm_b, self.gyro_z, self.accel_k,
                              self.gnss_gm, self.gm_t)

    def _gauss_markov(self) -> gnss.GaussMarkov:
        return gnss.GaussMarkov(float(self.params.gps_pos_gm_tau), self._gm_var)

    def _measurement(self, code: int, value: np.ndarray, sigma: np.ndarray,
                     lag: float) -> kalman.Measurement:
        """z, H, R of the update at the filter's time, by the compiled models (the checked
        path of a failing update)."""
        layout = self._layout()
        gm = np.zeros(3)
        if self._gp is not None:
            gnss.gm_at(self.gnss_gm, float(self.gm_t[0]), self.t, self.params.gps_pos_gm_tau,
                       gm)
        return _measurement(code, self.nav, self.lever_arm_b, value, sigma, self.P.shape[0],
                            lag=lag, omega_ib_b=self.omega_ib_b, lever_states=layout.lever,
                            gz=layout.gz, ng=layout.ng, gp=layout.gp, gm=gm,
                            gm_var=self._gm_var)

    def _feedback(self, dx: np.ndarray) -> None:
        super()._feedback(dx)
        if self.params.estimate_lever_arm:
            self.lever_arm_b = self.lever_arm_b - dx[LEVER]
        if self._gp is not None:
            gnss.gm_at(self.gnss_gm, float(self.gm_t[0]), self.t, self.params.gps_pos_gm_tau,
                       self.gnss_gm)
            self.gnss_gm = self.gnss_gm - dx[self._gp]
            self.gm_t = np.array([self.t])


    def run_events(self, run: EventRun) -> int:
        """A run of replay events in one compiled call
        (:func:`navreplay.filters.gps_ins_events.run_events`): for each event, propagate over
        its IMU segment, apply its GPS sample (if any) and write the estimate after it into
        the run's rows, bit for bit as :meth:`propagate`, :meth:`update` and :meth:`estimate`
        one by one, every estimate checked as :func:`navreplay.filters.kalman.check_covariance`
        checks it; with a smoother, each estimate's smoothing step too (handed over with the
        rows, :class:`~navreplay.filters.smoothable.SmoothingSteps`). The kernel stops before an
        event that fails a check (undone): the default then applies it, which names the problem. A
        subclass that changes ``propagate``, ``update`` or ``estimate`` gets the default (its runs
        of ticks still compiled when :class:`~navreplay.filters.ins.InsFilter`'s kernel applies).
        """
        if overrides(self, GpsInsFilter, "propagate", "update", "estimate"):
            return super().run_events(run)
        p = self.params
        kinds, samples = run.kinds, run.samples
        local = np.zeros(len(kinds) + 1, np.int64)  # code + 1 -> event code of the kernel
        empty = np.zeros((0, 3))
        cols = {gnss.POSITION: (empty, empty), gnss.VELOCITY: (empty, empty)}
        for c, kind in enumerate(kinds):
            if kind is StreamKind.GPS:
                local[c + 1] = gnss.POSITION
                cols[gnss.POSITION] = (samples[c]["pos"], self._sigma(kind, samples[c]))
            elif kind is StreamKind.GPS_VEL and p.use_gps_vel:
                local[c + 1] = gnss.VELOCITY
                cols[gnss.VELOCITY] = (samples[c]["v_n"], self._sigma(kind, samples[c]))
        s = np.zeros(ev.PACKED)
        tu = self._time_update
        state = {"prev": tu.prev, "open_nav": tu.open_step.nav, "open_sums": tu.open_step.sums,
                 "b_a": self.b_a, "b_g": self.b_g, "k_g": self.gyro_z, "k_a": self.accel_k,
                 "lever": self.lever_arm_b, "omega": self.omega_ib_b, "gm": self.gnss_gm,
                 "gm_t": self.gm_t}
        for key, (a, _) in ev.LAYOUT.items():
            s[a:a + len(state[key])] = state[key]
        codes = local[run.codes + 1]
        n_inn = int(np.count_nonzero(codes))
        inn_code = np.zeros(n_inn, np.int64)
        inn_t, inn_nu, inn_S = np.empty(n_inn), np.empty((n_inn, 3)), np.empty((n_inn, 3, 3))
        f64 = np.ascontiguousarray
        smoothing, log = ev.NO_SMOOTHING, self._smoothing
        if log is not None:  # the smoother's rows, one per estimate
            r, n = int(np.count_nonzero(run.record)), self.P.shape[0]
            smoothing = ev.Smoothing(log.dx, log.P_prior, log.has_prior, np.empty((r, n, n)),
                                     np.empty((r, n, n)), np.empty((r, n)))
        pos, pos_sigma = (f64(a, dtype=float) for a in cols[gnss.POSITION])
        vel, vel_sigma = (f64(a, dtype=float) for a in cols[gnss.VELOCITY])
        done, m, k, self.nav, self.P, self.t = ev.run_events(
            self.nav, self.P, self.t, s,
            Imu(run.t, f64(run.imu["omega_ib_b"], dtype=float), f64(run.imu["f_b"], dtype=float)),
            ev.Events(run.ends, codes, run.rows, run.t_ev, run.record),
            ev.Gnss(pos, pos_sigma, vel, vel_sigma, p.gps_pos_sigma_scale, p.gps_vel_sigma_scale),
            ev.Options(p.estimate_lever_arm, -1 if self._gp is None else self._gp.start,
                       gnss.GaussMarkov(float(p.gps_pos_gm_tau), self._gm_var),
                       kalman.DEFAULT_RTOL),
            tu.step, tu.model, tu.work, ev.Rows(*run.out()),
            ev.Updates(inn_code, inn_t, inn_nu, inn_S), smoothing)
        for key, (a, _) in ev.LAYOUT.items():  # the filter's arrays are updated in place
            state[key][:] = s[a:a + len(state[key])]
        run.add_rows(m, checked=True, steps=None if log is None else SmoothingSteps(
            smoothing.phi_out[:m], smoothing.P_prior_out[:m], smoothing.dx_out[:m]))
        for code, name in ((gnss.POSITION, "gps_pos"), (gnss.VELOCITY, "gps_vel")):
            sel = inn_code[:k] == code
            if sel.any():
                run.add_innovation_rows(name, inn_t[:k][sel], inn_nu[:k][sel], inn_S[:k][sel])
        run.done = done
        return done
