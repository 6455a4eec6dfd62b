"""The vector-matching method's declarations and model (docs/methods/vector-matching.md): the
state and measurement layout, the datasheet values of the paper's Table 1, the variants and
parameters, and the model functions (process and measurement noise, the gravity/specific-force
and field measurement, TRIAD, the feedback, the Euler-angle sigmas). The functions are pure and
broadcast over leading axes, so the reference filter and the batched path of
:mod:`navreplay.filters.vector_matching` share them."""

from __future__ import annotations

import dataclasses
import enum
import math
from typing import Any, NamedTuple

import numpy as np

from navreplay.core import chi2
from navreplay.core.units import DEG, GAUSS, MICRO_G_PER_SQRT_HZ, MILLI_G
from navreplay.filters import kalman
from navreplay.filters.base import (
    FilterParams,
    Nav,
    NavError,
    Quantity,
    State,
    check_number,
)
from navreplay.geo.rotations import (
    dcm_to_quat,
    quat_mult,
    quat_normalize,
    skew,
)

QE = slice(0, 3)
"""Error state: vector part of the attitude-error quaternion."""


N_STATES = 3


Z_G = slice(0, 3)
"""Acceleration (gravity / specific-force) residual rows of z and H."""


Z_H = slice(3, 6)
"""Magnetic-field residual rows of z and H."""


N_MEAS = 6


STATES = tuple(State(f"phi_{a}", "rad", Quantity.ATTITUDE, NavError(q), nees=True)
               for a, q in (("N", Nav.PHI_N), ("E", Nav.PHI_E), ("D", Nav.PHI_D)))
"""The outputs' states: the attitude error phi = 2 q_ev [rad] (the filter's own states are q_ev,
the vector part of the attitude-error quaternion), in the sign of the navigation errors."""


SENSOR_RATE = 4.0
"""Accelerometer, magnetometer and GNSS rate of the paper's simulation [Hz]."""


ACCEL_NOISE_DENSITY = 80.0 * MICRO_G_PER_SQRT_HZ
"""Accelerometer white-noise density, 80 ug/sqrt(Hz) [(m/s^2)/sqrt(Hz)]."""


MAG_NOISE_DENSITY = 100e-6 * GAUSS
"""Magnetometer white-noise density, 100 uG/sqrt(Hz) [T/sqrt(Hz)]."""


ACCEL_NOISE_SIGMA = ACCEL_NOISE_DENSITY * math.sqrt(0.5 * SENSOR_RATE)
"""Per-sample accelerometer sigma at 4 Hz, Nyquist bandwidth: 113.1 ug = 1.109e-3 m/s^2."""


MAG_NOISE_SIGMA = MAG_NOISE_DENSITY * math.sqrt(0.5 * SENSOR_RATE)
"""Per-sample magnetometer sigma at 4 Hz, Nyquist bandwidth: 141.4 uG = 14.14 nT."""


ACCEL_BIAS_SIGMA = 2.0 * MILLI_G
"""Accelerometer initial bias of Table 1, 1-sigma per axis: 2 mg [m/s^2]."""


MAG_BIAS_SIGMA = 0.003 * GAUSS
"""Magnetometer initial bias of Table 1, 1-sigma per axis: 0.003 G = 300 nT [T]."""


SCALE_FACTOR_SIGMA = 1e-3
"""Accelerometer and magnetometer scale-factor error of Table 1, 1-sigma per axis: 0.1 %."""


# consider states of the consistent variant (module docstring)
SENSOR = slice(3, 15)
"""The twelve sensor constants: accelerometer bias and scale factor, magnetometer bias and
scale factor (3 each, body frame)."""


W_PREV = slice(15, 18)
"""GNSS velocity error of the previous epoch."""


CLONE = slice(18, 21)
"""Between epochs: the error d of the last measured rotation increment; during an update: the
attitude error of the previous epoch (turn model ``constant-rate``)."""


N_CONSISTENT = 21
"""States of the consistent variant between updates (24 during one: w_v(k) appended)."""


FIX_ITERATIONS = 2
"""Relinearisations of a fix from a wide prior (consistent variant): a 5 deg prior error leaves
a second-order residual of ~160 nT in z_h, ten times the magnetometer noise."""


class Variant(enum.StrEnum):
    """Noise and process model of the filter (docs/methods/vector-matching.md §4.6)."""

    CONSISTENT = "consistent"
    """Sensor constants and GNSS velocity errors as consider states, attitude held unless the
    innovation shows a rotation: the covariance and innovations are consistent."""
    PAPER = "paper"
    """The paper's model: 3 states, white-noise R, Gauss-Markov process noise at every epoch
    (the reproduction's)."""


VARIANT_DEFAULTS = {
    Variant.CONSISTENT: {"tau": math.inf, "manoeuvre_false_alarm": 1e-6, "p0_sigma": 5.0 * DEG,
                         "accel_bias_sigma": ACCEL_BIAS_SIGMA,
                         "accel_scale_factor_sigma": SCALE_FACTOR_SIGMA,
                         "mag_bias_sigma": MAG_BIAS_SIGMA,
                         "mag_scale_factor_sigma": SCALE_FACTOR_SIGMA},
    Variant.PAPER: {"tau": 10.0, "manoeuvre_false_alarm": 0.0, "p0_sigma": 0.5 * DEG,
                    "accel_bias_sigma": 0.0, "accel_scale_factor_sigma": 0.0,
                    "mag_bias_sigma": 0.0, "mag_scale_factor_sigma": 0.0},
}
"""Values of the parameters left unset (None), per variant."""


SENSOR_PARAMS = ("accel_bias_sigma", "accel_scale_factor_sigma", "mag_bias_sigma",
                 "mag_scale_factor_sigma")
"""The sensor-constant sigmas of the consider states (variant ``consistent`` only)."""


class TurnModel(enum.StrEnum):
    """How the consistent variant predicts the attitude from one epoch to the next."""

    CONSTANT_RATE = "constant-rate"
    """Held, unless the last step measured a rotation: then the same rotation again."""
    HELD = "held"
    """Always held."""


class MatchModel(enum.StrEnum):
    """Measurement model of the acceleration vector (docs/methods/vector-matching.md §5)."""

    GRAVITY = "gravity"
    """Conventional acceleration-compensated gravity matching, H_g = -2[g_n x], eq. (14)."""
    SPECIFIC_FORCE = "specific-force"
    """Proposed specific-force matching, H_g = -2[(g_n - a_hat_n) x], eqs. (28)-(29)."""

    @classmethod
    def _missing_(cls, value: object) -> MatchModel | None:
        # also accept specific_force (underscore)
        if isinstance(value, str):
            key = value.strip().lower().replace("_", "-")
            for member in cls:
                if member.value == key:
                    return member
        return None


@dataclasses.dataclass(frozen=True, kw_only=True)
class VectorMatchingParams(FilterParams):
    """Parameters of :class:`VectorMatchingFilter` (SI). Those left None take the value of the
    variant (:data:`VARIANT_DEFAULTS`)."""

    variant: Variant = Variant.CONSISTENT
    """``consistent`` (sensor errors as consider states, attitude held between manoeuvres) or
    ``paper`` (the published model, as reproduced)."""
    model: MatchModel = MatchModel.SPECIFIC_FORCE
    """Acceleration measurement model: ``gravity`` (conventional) or ``specific-force``."""
    tau: float | None = None
    """Correlation time of the attitude-error Gauss-Markov process [s]; inf: a random walk.
    Paper: 10 s (navreplay's choice; the paper gives none); consistent: inf (the nominal
    attitude is held, so nothing pulls its error back)."""
    q_w: float = 0.01
    """Power spectral density of the attitude-error driving noise [1/s]: the unknown rotation
    of the vehicle (navreplay's choice; the paper gives none)."""
    manoeuvre_false_alarm: float | None = None
    """0: add the process noise at every epoch (paper). > 0: add it only where the NIS without
    it rejects "no rotation since the last epoch" at this false-alarm probability (consistent:
    1e-6)."""
    turn_model: TurnModel = TurnModel.CONSTANT_RATE
    """Prediction of the consistent variant: ``constant-rate`` (the last epoch's rotation, when
    significant, predicted to continue) or ``held``."""
    accel_noise_sigma: float = ACCEL_NOISE_SIGMA
    """Accelerometer white noise, 1-sigma per sample and axis [m/s^2] (s_f of eq. 15)."""
    mag_noise_sigma: float = MAG_NOISE_SIGMA
    """Magnetometer white noise, 1-sigma per sample and axis [T] (s_h of eq. 11)."""
    accel_bias_sigma: float | None = None
    """Accelerometer bias, 1-sigma per axis, a consider state [m/s^2] (consistent: the Table 1
    value :data:`ACCEL_BIAS_SIGMA`; paper: 0, not modelled)."""
    accel_scale_factor_sigma: float | None = None
    """Accelerometer scale-factor error, 1-sigma per axis, a consider state [-] (consistent:
    :data:`SCALE_FACTOR_SIGMA`)."""
    mag_bias_sigma: float | None = None
    """Magnetometer (hard-iron) bias, 1-sigma per axis, a consider state [T] (consistent:
    :data:`MAG_BIAS_SIGMA`)."""
    mag_scale_factor_sigma: float | None = None
    """Magnetometer scale-factor error, 1-sigma per axis, a consider state [-] (consistent:
    :data:`SCALE_FACTOR_SIGMA`)."""
    p0_sigma: float | None = None
    """Paper: initial 1-sigma of each q_ev component after TRIAD [-] (0.5 deg in rad: 1 deg of
    angle). Consistent: the prior of the initial fix (5 deg: 10 deg of angle)."""
    earth_field_n: tuple[float, float, float] | None = None
    """Reference geomagnetic field N, E, D [T]; None: the recording's
    ``metadata.extra["earth_field_n"]`` (the field model the recording was made with)."""
    gravity: float | None = None
    """Gravity magnitude [m/s^2]; None: normal gravity at ``metadata.initial_nav["pos"]``."""
    sync_tolerance: float = 1e-6
    """Largest time difference of samples that belong to one epoch [s]."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "model", MatchModel(self.model))
        object.__setattr__(self, "variant", Variant(self.variant))
        object.__setattr__(self, "turn_model", TurnModel(self.turn_model))
        if self.variant is Variant.PAPER:
            for name in SENSOR_PARAMS:
                if getattr(self, name):
                    raise ValueError(f"{name} is a consider state of variant=consistent; "
                                     f"variant=paper has none")
        for name, value in VARIANT_DEFAULTS[self.variant].items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, value)
        if not (isinstance(self.tau, (int, float)) and self.tau > 0.0
                and not math.isnan(self.tau)):
            raise ValueError(f"tau must be > 0 (inf: a random walk), got {self.tau!r}")
        for name in ("accel_noise_sigma", "mag_noise_sigma", "p0_sigma", "sync_tolerance"):
            check_number(self, name, positive=True)
        for name in (*SENSOR_PARAMS, "q_w"):
            check_number(self, name)
        check_number(self, "manoeuvre_false_alarm", upper=1.0)
        if self.earth_field_n is not None:
            h = np.asarray(self.earth_field_n, dtype=float)
            if h.shape != (3,) or not np.all(np.isfinite(h)) or not np.any(h):
                raise ValueError(
                    f"earth_field_n must be three finite values [T], not all zero; got "
                    f"{self.earth_field_n!r}"
                )
            object.__setattr__(self, "earth_field_n", tuple(float(v) for v in h))
        check_number(self, "gravity", positive=True)

    @property
    def turn_threshold(self) -> float:
        """Chi-square(3) value above which the rotation measured over the last step is
        significant (inf: never; turn model ``constant-rate`` with a manoeuvre test only)."""
        a = self.manoeuvre_false_alarm
        assert a is not None  # filled from the variant
        return math.inf if a == 0.0 or a >= 1.0 else chi2.ppf(1.0 - a, 3)

    @property
    def manoeuvre_threshold(self) -> float:
        """NIS above which an epoch gets the process noise (inf: never; 0: always)."""
        a = self.manoeuvre_false_alarm
        assert a is not None  # filled from the variant
        return 0.0 if a == 0.0 else (math.inf if a >= 1.0 else chi2.ppf(1.0 - a, N_MEAS))


class Reference(NamedTuple):
    """Reference vectors in the navigation frame.

    g_n : ndarray, shape (3,)  gravity [m/s^2], ``[0, 0, g]``.
    h_n : ndarray, shape (3,)  geomagnetic field [T].
    """

    g_n: np.ndarray
    h_n: np.ndarray


class EpochSample(NamedTuple):
    """The synchronous samples of one epoch; every array may carry leading run axes.

    t : float or ndarray  [s]
    f_b : ndarray, (..., 3)  measured specific force [m/s^2]
    m_b : ndarray, (..., 3)  measured magnetic field [T]
    v_n : ndarray, (..., 3)  GNSS velocity [m/s]
    vel_sigma : ndarray, (..., 3)  reported GNSS velocity 1-sigma per NED axis [m/s]
    """

    t: float | np.ndarray
    f_b: np.ndarray
    m_b: np.ndarray
    v_n: np.ndarray
    vel_sigma: np.ndarray


def _mv(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Matrix times vector over leading axes: (..., n, m) x (..., m) -> (..., n)."""
    return (M @ v[..., None])[..., 0]


def process_noise(dt: float | np.ndarray, tau: float, q_w: float) -> tuple[Any, Any]:
    """Scalar factors of ``Phi = phi I3`` and ``Q_d = qd I3``, exact discretisation, (16)-(18).

    Parameters
    ----------
    dt : float or ndarray
        Step [s].
    tau : float
        Correlation time [s]; inf: a random walk (``phi = 1``, ``qd = q_w dt``).
    q_w : float
        Driving-noise power spectral density [1/s].

    Returns
    -------
    phi, qd : float or ndarray
        ``exp(-dt/tau)`` and ``(q_w tau / 2)(1 - exp(-2 dt/tau))``.

    Examples
    --------
    >>> phi, qd = process_noise(0.25, 10.0, 0.01)
    >>> round(float(qd), 7)
    0.0024385
    """
    dt = np.asarray(dt, dtype=float)
    if math.isinf(tau):  # random walk
        return np.ones_like(dt), q_w * dt
    phi = np.exp(-dt / tau)
    qd = 0.5 * q_w * tau * -np.expm1(-2.0 * dt / tau)
    return phi, qd


def gps_acceleration(v_n: np.ndarray, v_n_prev: np.ndarray, dt: Any) -> np.ndarray:
    """Backward difference of GNSS velocities, eq. (13) (its half-step lag is ignored, E11).

    Parameters
    ----------
    v_n, v_n_prev : ndarray, shape (..., 3)
        Velocities at t_k and t_k-1 [m/s].
    dt : float or ndarray
        t_k - t_k-1 [s], broadcastable against ``v_n[..., 0]``.

    Returns
    -------
    ndarray, shape (..., 3)
        [m/s^2].
    """
    return (v_n - v_n_prev) / np.asarray(dt, dtype=float)[..., None]


def measurement(
    model: MatchModel,
    C_nb_hat: np.ndarray,
    f_b: np.ndarray,
    m_b: np.ndarray,
    a_n: np.ndarray,
    g_n: np.ndarray,
    h_n: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Stacked residual z and its matrix H for either model, eqs. (10), (14), (28).

    Parameters
    ----------
    model : MatchModel
    C_nb_hat : ndarray, shape (..., 3, 3)
        Attitude estimate before the correction.
    f_b : ndarray, shape (..., 3)
        Measured specific force [m/s^2].
    m_b : ndarray, shape (..., 3)
        Measured magnetic field [T].
    a_n : ndarray, shape (..., 3)
        Motion acceleration from GNSS, eq. (13) [m/s^2].
    g_n, h_n : ndarray, shape (3,) or (..., 3)
        Reference gravity [m/s^2] and geomagnetic field [T].

    Returns
    -------
    z : ndarray, shape (..., 6)
        ``[z_g; z_h]``, [m/s^2] and [T].
    H : ndarray, shape (..., 6, 3)
        ``dz / dq_ev``.
    """
    z_g = g_n - (a_n - _mv(C_nb_hat, f_b))  # (14)
    z_h = h_n - _mv(C_nb_hat, m_b)  # (10) with E4: the magnetometer reading
    u_n = g_n if model is MatchModel.GRAVITY else g_n - a_n  # (14) vs (28)
    shape = np.broadcast_shapes(z_g.shape, z_h.shape)
    z = np.empty(shape[:-1] + (N_MEAS,))
    z[..., Z_G] = z_g
    z[..., Z_H] = z_h
    H = np.empty(shape[:-1] + (N_MEAS, N_STATES))
    H[..., Z_G, QE] = -2.0 * skew(u_n)  # (14) / (28)
    H[..., Z_H, QE] = -2.0 * skew(h_n)  # (10)
    return z, H


def measurement_noise(
    vel_sigma: np.ndarray,
    vel_sigma_prev: np.ndarray,
    dt: Any,
    accel_noise_sigma: float,
    mag_noise_sigma: float,
) -> np.ndarray:
    """Diagonal of R = blkdiag(R_g, R_h), eqs. (11) and (15) (both blocks are diagonal).

    Parameters
    ----------
    vel_sigma, vel_sigma_prev : ndarray, shape (..., 3)
        GNSS velocity 1-sigma per NED axis at t_k and t_k-1 [m/s].
    dt : float or ndarray
        t_k - t_k-1 [s].
    accel_noise_sigma : float
        s_f [m/s^2].
    mag_noise_sigma : float
        s_h [T].

    Returns
    -------
    ndarray, shape (..., 6)
        [(m/s^2)^2] for the first three, [T^2] for the last three.
    """
    var_a = (vel_sigma**2 + vel_sigma_prev**2) / (np.asarray(dt, dtype=float)[..., None] ** 2)
    R = np.empty(var_a.shape[:-1] + (N_MEAS,))
    R[..., Z_G] = var_a + accel_noise_sigma**2  # (15)
    R[..., Z_H] = mag_noise_sigma**2  # (11), E5: C (s_h^2 I) C^T = s_h^2 I
    return R


def consider_columns(
    C_nb_hat: np.ndarray, f_b: np.ndarray, m_b: np.ndarray, dt: Any
) -> np.ndarray:
    """Columns of H for the sensor constants and GNSS velocity errors of the consistent variant
    (states 3-17 and, during an update, 21-23; the rotation states 18-20 do not enter z).

    A bias b and a scale-factor error s of a reading u_b enter the residuals (14) and (10) as
    ``+C_nb_hat (b + diag(s) u_b)`` (accelerometer) and ``-C_nb_hat (b + diag(s) u_b)``
    (magnetometer); the GNSS velocity errors w_v enter a_hat_n of eq. (13), so z_g, as
    ``(w_v(k-1) - w_v(k)) / dt``.

    Parameters
    ----------
    C_nb_hat : ndarray, shape (3, 3)
    f_b, m_b : ndarray, shape (3,)
        Accelerometer [m/s^2] and magnetometer [T] readings.
    dt : float
        t_k - t_k-1 [s]; 0: the first epoch, with no GNSS difference.

    Returns
    -------
    ndarray, shape (6, 18)
        d z / d [b_a, s_a, b_m, s_m, w_v(k-1), w_v(k)].
    """
    H = np.zeros((N_MEAS, 18))  # 12 sensor constants, w_v(k-1), w_v(k)
    H[Z_G, 0:3] = C_nb_hat
    H[Z_G, 3:6] = C_nb_hat * f_b
    H[Z_H, 6:9] = -C_nb_hat
    H[Z_H, 9:12] = -C_nb_hat * m_b
    if dt:
        H[Z_G, 12:15] = np.eye(3) / dt
        H[Z_G, 15:18] = -np.eye(3) / dt
    return H


def held_prediction(P: np.ndarray, phi: float, qd: float) -> np.ndarray:
    """Prediction of the consistent variant's covariance: the attitude rows and columns scaled
    by ``phi`` (1 for the random walk), ``qd I3`` added to the attitude block; the consider
    states are constant."""
    P = P.copy()
    P[QE, :] *= phi
    P[:, QE] *= phi
    P[QE, QE] += qd * np.eye(3)
    return P


def consider_covariance(params: VectorMatchingParams) -> np.ndarray:
    """Covariance of the twelve sensor constants (diagonal), shape (12, 12)."""
    sig = np.repeat([params.accel_bias_sigma, params.accel_scale_factor_sigma,
                     params.mag_bias_sigma, params.mag_scale_factor_sigma], 3)
    return np.diag(sig**2)


def epoch_measurement(
    params: VectorMatchingParams,
    ref: Reference,
    C_nb_hat: np.ndarray,
    f_b: np.ndarray,
    m_b: np.ndarray,
    v_n: np.ndarray,
    v_n_prev: np.ndarray,
    vel_sigma: np.ndarray,
    vel_sigma_prev: np.ndarray,
    dt: float,
) -> tuple[kalman.Measurement, np.ndarray]:
    """The measurement of an epoch of the paper variant, eqs. (10)-(15), (28): ``(z, H, R)``
    and the GNSS acceleration a_n of eq. (13) it used; leading axes (...) for a stack of runs.

    Parameters
    ----------
    params : VectorMatchingParams
    ref : Reference
    C_nb_hat : ndarray, shape (..., 3, 3)
        Attitude estimate before the correction.
    f_b, m_b : ndarray, shape (..., 3)
        Accelerometer [m/s^2] and magnetometer [T] at t_k.
    v_n, v_n_prev : ndarray, shape (..., 3)
        GNSS velocity at t_k and t_k-1 [m/s].
    vel_sigma, vel_sigma_prev : ndarray, shape (..., 3)
        Their reported 1-sigma [m/s].
    dt : float
        t_k - t_k-1 [s].
    """
    a_n = gps_acceleration(v_n, v_n_prev, dt)  # (13)
    z, H = measurement(params.model, C_nb_hat, f_b, m_b, a_n, ref.g_n, ref.h_n)
    R = measurement_noise(vel_sigma, vel_sigma_prev, dt, params.accel_noise_sigma,
                          params.mag_noise_sigma)
    return kalman.Measurement(z, H, R), a_n


def triad(f_b: np.ndarray, m_b: np.ndarray, g_n: np.ndarray, h_n: np.ndarray) -> np.ndarray:
    """Attitude from two vector pairs by TRIAD, for a vehicle at rest.

    The primary pair (exactly matched) is the up direction ``-g_n/|g_n|`` and ``f_b/|f_b|``;
    the secondary pair is (h_n, m_b).

    Parameters
    ----------
    f_b, m_b : ndarray, shape (..., 3)
        Measured specific force [m/s^2] and magnetic field [T].
    g_n, h_n : ndarray, shape (3,)
        Reference gravity and field.

    Returns
    -------
    q_nb : ndarray, shape (..., 4)

    Raises
    ------
    ValueError
        A zero vector, or the two vectors of a pair parallel.

    Examples
    --------
    >>> import numpy as np
    >>> from navreplay.geo import euler_to_dcm, quat_to_euler
    >>> g_n, h_n = np.array([0.0, 0.0, 9.8]), np.array([3e-5, -4e-6, 4e-5])
    >>> C = euler_to_dcm([0.1, -0.2, 2.0])
    >>> q = triad(C.T @ -g_n, C.T @ h_n, g_n, h_n)
    >>> np.round(quat_to_euler(q), 12).tolist()
    [0.1, -0.2, 2.0]
    """

    def frame(v1: np.ndarray, v2: np.ndarray, what: str) -> np.ndarray:
        n1 = np.linalg.norm(v1, axis=-1, keepdims=True)
        c = np.cross(v1, v2)
        nc = np.linalg.norm(c, axis=-1, keepdims=True)
        scale = n1 * np.linalg.norm(v2, axis=-1, keepdims=True)
        if np.any(n1 == 0.0) or np.any(nc <= 1e-6 * scale):
            raise ValueError(f"TRIAD: the {what} vectors are zero or parallel")
        t1 = v1 / n1
        t2 = c / nc
        return np.stack([t1, t2, np.cross(t1, t2)], axis=-1)

    T_n = frame(-np.asarray(g_n, dtype=float), np.asarray(h_n, dtype=float), "reference")
    T_b = frame(np.asarray(f_b, dtype=float), np.asarray(m_b, dtype=float), "measured")
    return dcm_to_quat(T_n @ np.swapaxes(T_b, -1, -2))


def feedback(q_nb_hat: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """Apply the estimated q_ev: ``normalize([1, dq] (x) q_nb_hat)``.

    Parameters
    ----------
    q_nb_hat : ndarray, shape (..., 4)
    dq : ndarray, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 4)
    """
    q_e = np.concatenate([np.ones(dq.shape[:-1] + (1,)), dq], axis=-1)
    return quat_normalize(quat_mult(q_e, q_nb_hat))


def euler_sigma(euler: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Predicted 1-sigma of the roll, pitch, yaw errors from the covariance of q_ev.

    A small rotation phi = 2 q_ev of the navigation frame changes the ZYX angles by
    ``d_euler = -M^-1 phi`` with ``M = [Rz Ry e1, Rz e2, e3]`` (the frame rate of each angle),
    so ``cov(d_euler) = 4 M^-1 P M^-T``. Infinite at pitch = +-90 deg.

    Parameters
    ----------
    euler : ndarray, shape (..., 3)
        Roll, pitch, yaw [rad].
    P : ndarray, shape (..., 3, 3)
        Covariance of q_ev.

    Returns
    -------
    ndarray, shape (..., 3)
        [rad].
    """
    sp, cp = np.sin(euler[..., 1]), np.cos(euler[..., 1])
    sy, cy = np.sin(euler[..., 2]), np.cos(euler[..., 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        sec = 1.0 / cp
        Minv = np.zeros(euler.shape[:-1] + (3, 3))
        Minv[..., 0, 0] = cy * sec
        Minv[..., 0, 1] = sy * sec
        Minv[..., 1, 0] = -sy
        Minv[..., 1, 1] = cy
        Minv[..., 2, 0] = sp * cy * sec
        Minv[..., 2, 1] = sp * sy * sec
        Minv[..., 2, 2] = 1.0
        cov = 4.0 * Minv @ P @ np.swapaxes(Minv, -1, -2)
    return np.sqrt(np.clip(np.diagonal(cov, axis1=-2, axis2=-1), 0.0, None))


def model_induced_error(
    z: np.ndarray, a_n: np.ndarray, g_n: np.ndarray, h_n: np.ndarray
) -> np.ndarray:
    """Attitude error caused by the conventional model's dropped term, eqs. (23)-(25), E7.

    Parameters
    ----------
    z : ndarray, shape (..., 6)
        Stacked residual.
    a_n : ndarray, shape (..., 3)
        GNSS acceleration [m/s^2].
    g_n, h_n : ndarray, shape (3,)

    Returns
    -------
    ndarray, shape (..., 3)
        ``2 (pinv(H_conv) z - pinv(H_true) z)`` [rad].
    """
    z_dummy = np.zeros(3)
    _, H_conv = measurement(MatchModel.GRAVITY, np.eye(3), z_dummy, z_dummy, a_n, g_n, h_n)
    _, H_true = measurement(
        MatchModel.SPECIFIC_FORCE, np.eye(3), z_dummy, z_dummy, a_n, g_n, h_n
    )
    dq_conv = _mv(np.linalg.pinv(H_conv), z)  # (24)
    dq_true = _mv(np.linalg.pinv(H_true), z)  # (23)
    return 2.0 * (dq_conv - dq_true)  # (25)
