"""Loosely coupled GPS/INS ("gps-ins"): error-state EKF with feedback on the NED INS error model.

The strapdown INS of :class:`navreplay.filters.ins.InsFilter` (initial solution from
``metadata.initial_nav``, IMU compensated with the bias estimates) is corrected by GPS position
fixes and, when the recording has them, GPS NED velocities. The filter estimates the errors of
the navigation solution, of the IMU biases, of the gyro errors driven by the yaw rate (two
misalignments and the z scale factor; ``gyro_misalignment_states``, on by default), of the
accelerometer errors driven by the forward and lateral specific force (``accel_motion_states``,
on by default) and optionally of the GPS antenna lever arm, feeds them back into the solution and the IMU
compensation after every update, and so keeps its error state at 0.

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
g     m_g_xz               b (FRD)   rad          gyro misalignment M[0, 2] error (z rate into
                                                  x); x holds the estimate
g+1   m_g_yz               b (FRD)   rad          gyro misalignment M[1, 2] error (z rate into
                                                  y); x holds the estimate
g+2   s_g_z                b (FRD)   -            gyro z scale-factor error; x holds the estimate
a-a+2 s_a_x, m_a_yx, m_a_zx b (FRD)  -, rad, rad  column x of S_a + M_a (errors of f_x into x, y,
                                                  z); x holds the estimates
a+3-5 m_a_xy, s_a_y, m_a_zy b (FRD)  rad, -, rad  column y of S_a + M_a; x holds the estimates
===== ==================== ========= ============ =============================================

The gyro z-rate states (``gyro_misalignment_states``) follow the lever arm when it is
estimated: g = 18 with ``estimate_lever_arm``, else 15; the accelerometer states follow them
(a = g + 3). Scoring (declared ``states``): the navigation states and biases as ``ins``; m_g_xz,
m_g_yz, s_g_z against the constants ``metadata.true_errors["imu"]["gyro_misalignment"][0][2]``,
``[1][2]`` and ``["gyro_scale_factor"][2]`` (the M and S of :mod:`navreplay.sensors.imu`,
``omega_meas = (I + S + M) omega + b``), the accelerometer states against
``["accel_scale_factor"][j]`` and ``["accel_misalignment"][i][j]``. Why these states and the
ensemble consistency: docs/methods/ins.md.

Errors (signs)
--------------
Position, velocity, biases, gyro z-rate coefficients and lever arm: estimate minus truth,
``dx = x_hat - x``. Attitude: ``C_nb_hat = (I - [phi x]) C_nb`` (a positive phi_D is an
estimated heading smaller than the truth). Feedback subtracts:
``lat, lon, h, v_n, b_a, b_g, k, l -= dx`` and ``q_nb_hat <- normalize([1, phi/2] (x)
q_nb_hat)``, then ``dx = 0``.

Models
------
Process (continuous, :mod:`navreplay.filters.ins_error`)::

    dx' = F dx + G w,   w = [n_a, n_g, n_ba, n_bg]                                      (1)
    F: the 15x15 NED error model, eqs. (6)-(19) there; lever arm: F = 0, Q = 0          (2)
    gyro z-rate states k = (m_xz, m_yz, s_z), random constants (F = 0, Q = 0 for them):
      omega_hat = omega_meas - b_g_hat - k_hat (omega_meas_z - b_g_hat_z)
      F[phi, k_j] = +C_nb_hat[:, j] omega_hat_z     (ins_error eq. 22)                 (2a)
      P0 = diag(gyro_misalignment_sigma^2 (2), gyro_scale_factor_sigma^2)
    accelerometer states k_j = (S_a + M_a)[:, j], j = x, y, random constants:
      f_hat = f_meas - b_a_hat - k_x_hat (f_x - b_a_x) - k_y_hat (f_y - b_a_y)
      F[v, k_j[i]] = -C_nb_hat[:, i] f_hat_j          (ins_error eq. 23)               (2b)
      P0 = diag of accel_scale_factor_sigma^2 (s) and accel_misalignment_sigma^2 (m)
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
        specification: white and Gauss-Markov parts together); the error is taken as white,
        a time-correlated part is not modelled (docs/sensors.md §3)

GPS velocity, with ``w = omega_ib_b_hat`` (last compensated gyro sample) and
``w_in = w_ie + w_en``::

    v_ant_hat = v_hat + C_nb_hat (w x l_hat) - w_in x (C_nb_hat l_hat)                    (8)
    z = v_ant_hat - v_gps                                       (3,) [m/s]                (9)
    H = [ 0 | I | [(C (w x l)) x] - [w_in x][(C l) x] | 0 | C [l x] | C [w x] - [w_in x] C ] (10)
    H[:, k] = C [l x] w_z                                       (gyro z-rate states)
    R = diag(vel_sigma^2) * gps_vel_sigma_scale^2                                          (11)
        vel_sigma: the sample's, else ``gps_vel_sigma``

Update (the compiled kernel of :func:`navreplay.filters.kalman.correct`, Cholesky + Joseph
form, with its checks) of the error state dx = 0, then feedback (12); the models, update and
feedback are compiled together in :mod:`navreplay.filters.gnss_models`, and the replay engine
hands whole runs of events to :meth:`GpsInsFilter.replay_events`. Each update returns its
innovation ``nu = z`` and ``S`` for NIS statistics (``"gps_pos"`` [m], ``"gps_vel"`` [m/s]).

(10) omits the derivatives of w_in with respect to position and velocity in the lever-arm term
(below 1e-8 m/s for metre-level errors); everything else in (6) and (10) was checked against
central differences of (4)-(5) and (8)-(9) in tests/test_gps_ins.py. Samples older than the
INS solution (before the initial solution's time) are ignored.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from navreplay.filters import gnss_models as gnss
from navreplay.filters import gps_ins_events as ev
from navreplay.filters import kalman
from navreplay.filters.base import (
    FilterContext,
    FilterParams,
    Innovation,
    MeasurementKind,
    Quantity,
    State,
    check_number,
)
from navreplay.filters.ins import InsFilter, InsParams
from navreplay.filters.registry import register_filter
from navreplay.sensors.specs import SensorSpecs
from navreplay.streams import StreamKind

LEVER = slice(15, 18)
"""Lever-arm error states (present with ``estimate_lever_arm``)."""
LEVER_STATES: tuple[State, ...] = tuple(
    State(f"l_{a}", "m", Quantity.LEVER_ARM) for a in "xyz")
"""Lever-arm estimates (``estimate_lever_arm``), body [m]; the truth is the parameter's."""
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
    accel_motion_states: bool = True
    """Estimate the accelerometer errors driven by the x and y specific force (the columns x
    and y of S_a + M_a) as six random constants (ins eq. 5c; ``accel_sf_mis`` is then off)."""

    def __post_init__(self) -> None:
        super().__post_init__()
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
) -> kalman.Measurement:
    """GPS position measurement, eqs. (4)-(7).

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

    Returns
    -------
    z : ndarray, shape (3,)
        Residual INS minus GPS, N, E, D [m].
    H : ndarray, shape (3, n_states)
    R : ndarray, shape (3,)
        Diagonal of R [m^2].
    """
    return _measurement(gnss.POSITION, nav, lever_arm_b, pos_gps, pos_sigma, n_states,
                        lag=lag, lever_states=lever_states)


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
        Index of the gyro z-rate states (m_xz, m_yz, s_z), if any.

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
                        gz=-1 if gyro_z_states is None else gyro_z_states)


def _measurement(kind: int, nav: np.ndarray, lever_arm_b: np.ndarray, sample: np.ndarray,
                 sigma: np.ndarray, n_states: int, *, lag: float = 0.0,
                 omega_ib_b: np.ndarray | None = None, lever_states: bool = False,
                 gz: int = -1) -> kalman.Measurement:
    """z, H, R of a GPS measurement by the compiled models of
    :mod:`navreplay.filters.gnss_models`."""
    f64 = np.ascontiguousarray
    nav, lever = f64(nav, dtype=float), f64(lever_arm_b, dtype=float)
    sample, sigma = f64(sample, dtype=float), f64(sigma, dtype=float)
    z, H, R = np.empty(3), np.empty((3, n_states)), np.empty((3, 3))
    if kind == gnss.POSITION:
        gnss.position_model(nav, lever, sample, sigma, 1.0, float(lag), lever_states, z, H, R)
    else:
        omega = f64(omega_ib_b, dtype=float)
        gnss.velocity_model(nav, lever, omega, sample, sigma, 1.0, lever_states, gz, z, H, R)
    return kalman.Measurement(z, H, np.diagonal(R).copy())


@register_filter
class GpsInsFilter(InsFilter):
    """Loosely coupled GPS/INS error-state EKF with feedback (see the module docstring)."""

    name: ClassVar[str] = "gps-ins"
    summary: ClassVar[str] = (
        "loosely coupled GPS/INS: 15-state NED error-state EKF with feedback, GPS position"
        " (+ velocity), optional lever arm"
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
        """The IMU settings of ``ins`` and the GNSS noise of fixes without their own sigma."""
        out = super().settings_from_sensors(sensors)
        if sensors.has("gps", "pos_sigma"):
            gm = sensors.gps.pos_gm_sigma if sensors.has("gps", "pos_gm_sigma") else 0.0
            out["gps_pos_sigma"] = tuple(np.hypot(sensors.gps.pos_sigma, gm).tolist())
        if sensors.has("gps", "vel_sigma"):
            gm = sensors.gps.vel_gm_sigma if sensors.has("gps", "vel_gm_sigma") else 0.0
            out["gps_vel_sigma"] = tuple(np.hypot(sensors.gps.vel_sigma, gm).tolist())
        return out

    @classmethod
    def modelled_terms(cls, params: FilterParams) -> dict[str, frozenset[str]]:
        """The IMU terms of ``ins`` and the GNSS white noise (R); the time-correlated errors
        are not modelled: R holds them as white (the velocity's only where it is used)."""
        gps = {"pos_sigma", "vel_sigma"}
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

    def _init_extra(self) -> None:
        if self.params.estimate_lever_arm:
            self.P[LEVER, LEVER] = np.eye(3) * self.params.lever_arm_sigma**2

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
        ok, nav, P, nu, S = gnss.gps_update(
            code, self.nav, self.P, value, sigma, scale, lag, self.omega_ib_b, self.b_a,
            self.b_g, self.lever_arm_b, p.estimate_lever_arm, self.gyro_z,
            -1 if self._gz is None else self._gz.start, self.accel_k,
            -1 if self._ga is None else self._ga.start, kalman.DEFAULT_RTOL)  # (4)-(12)
        if not ok:  # the checked path names what is wrong
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

    def _measurement(self, code: int, value: np.ndarray, sigma: np.ndarray,
                     lag: float) -> kalman.Measurement:
        n = self.P.shape[0]
        lever_states = self.params.estimate_lever_arm
        if code == gnss.POSITION:
            return gps_position_model(self.nav, self.lever_arm_b, value, sigma, n, lag=lag,
                                      lever_states=lever_states)
        return gps_velocity_model(self.nav, self.lever_arm_b, self.omega_ib_b, value, sigma, n,
                                  lever_states=lever_states,
                                  gyro_z_states=None if self._gz is None else self._gz.start)

    def _feedback(self, dx: np.ndarray) -> None:
        super()._feedback(dx)
        if self.params.estimate_lever_arm:
            self.lever_arm_b = self.lever_arm_b - dx[LEVER]


    def replay_events(
        self, t: np.ndarray, imu: Mapping[str, np.ndarray], ends: np.ndarray,
        kinds: tuple[StreamKind, ...], codes: np.ndarray, rows: np.ndarray, t_ev: np.ndarray,
        record: np.ndarray, samples: list[Mapping[str, np.ndarray]],
        out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    ) -> tuple[int, int, dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]]:
        """A run of replay events in one compiled call
        (:func:`navreplay.filters.gps_ins_events.run_events`): for each event e, propagate
        over the IMU segment ``[ends[e-1], ends[e])`` of the block, apply the sample of row
        ``rows[e]`` of stream ``kinds[codes[e]]`` (code -1: none), and when ``record[e]``
        write an estimate into the next row of ``out`` = (t, x, P, nav vectors).

        Returns (events applied, estimates written, innovations by name as (t, nu, S)
        arrays); the events after those applied (the first of them failed a check and was
        undone) are for :meth:`propagate`, :meth:`update` and :meth:`estimate`.
        """
        p = self.params
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
                 "b_a": self.b_a, "b_g": self.b_g, "k_z": self.gyro_z, "k_a": self.accel_k,
                 "lever": self.lever_arm_b, "omega": self.omega_ib_b}
        for key, (a, b) in ev.LAYOUT.items():
            s[a:b] = state[key]
        n_inn = int(np.count_nonzero(local[codes + 1]))
        inn_code = np.zeros(n_inn, np.int64)
        inn_t, inn_nu, inn_S = np.empty(n_inn), np.empty((n_inn, 3)), np.empty((n_inn, 3, 3))
        f64 = np.ascontiguousarray
        done, m, k, self.nav, self.P, self.t = ev.run_events(
            self.nav, self.P, self.t, s, t, f64(imu["omega_ib_b"], dtype=float),
            f64(imu["f_b"], dtype=float), ends, local[codes + 1], rows, t_ev, record,
            *(f64(a, dtype=float) for a in cols[gnss.POSITION]),
            *(f64(a, dtype=float) for a in cols[gnss.VELOCITY]),
            p.gps_pos_sigma_scale, p.gps_vel_sigma_scale, p.estimate_lever_arm,
            self._gz is not None, self._ga is not None, tu.step, *tu._model, *tu._work,
            kalman.DEFAULT_RTOL, *out, inn_code, inn_t, inn_nu, inn_S)
        for key, (a, b) in ev.LAYOUT.items():  # the filter's arrays are updated in place
            state[key][:] = s[a:b]
        innovations = {}
        for code, name in ((gnss.POSITION, "gps_pos"), (gnss.VELOCITY, "gps_vel")):
            sel = inn_code[:k] == code
            if sel.any():
                innovations[name] = (inn_t[:k][sel], inn_nu[:k][sel], inn_S[:k][sel])
        return done, m, innovations
