"""Gyro-free attitude by vector matching: specific force (proposed) or gravity (conventional).

Estimates the attitude of a vehicle without gyros from an accelerometer, a magnetometer and GNSS
velocity sampled together at a few hertz, with a 3-state error-quaternion EKF that matches two
vectors per epoch: the acceleration-compensated specific force and the geomagnetic field
(Choe & Park, "Improvement of Attitude Determination Based on Specific Force Vector Matching",
JKSAS 45(2), 2017; the method as navreplay implements it: docs/methods/vector-matching.md).
Equation numbers are the paper's; E1-E11 are the errata in docs/methods/vector-matching.md §7.

State
-----
===== ========================= ===== ==== ===============================================
index symbol                    frame unit meaning
===== ========================= ===== ==== ===============================================
0-2   q_ev = [q_e1, q_e2, q_e3] n     -    vector part of the attitude-error quaternion q_e
===== ========================= ===== ==== ===============================================

The nominal attitude ``q_nb_hat`` is the only navigation output. It is held constant between
updates (no gyros, no time propagation); after every update the error estimate is fed back and
reset to zero, so only P is propagated.

Error definition and sign (E9)
------------------------------
::

    q_nb_true = q_e (x) q_nb_hat          (Hamilton product; q_e = [q_e0, q_ev], q_e0 ~ 1)
    C_nb_hat  = (I - 2[q_ev x]) C_nb_true = (I - [phi x]) C_nb_true,   phi = 2 q_ev    (3)-(5)

phi [rad] has the sign of :func:`navreplay.geo.attitude_error` (a positive phi_D means the
estimated heading is smaller than the true one).

Process model, first-order Gauss-Markov (16)-(18), exactly discretised
----------------------------------------------------------------------
::

    d/dt q_ev = F q_ev + G w,   F = -(1/tau) I3,   G = -tau F = I3,   E[w w^T] = q_w delta(t) I3
    Phi = exp(-dt/tau) I3,   Q_d = (q_w tau / 2) (1 - exp(-2 dt/tau)) I3
    P <- Phi P Phi^T + Q_d

The process noise stands in for the missing gyros.

Measurement model, at each epoch k >= 1 (accelerometer, magnetometer, GNSS velocity at t_k)
-------------------------------------------------------------------------------------------
::

    a_hat_n = (v_gps_n(k) - v_gps_n(k-1)) / dt                                        (13)
    z_g = g_n - (a_hat_n - C_nb_hat f_b)       = -2[u_n x] q_ev + v_g                 (14), (28)
    z_h = h_n - C_nb_hat m_b                   = -2[h_n x] q_ev + v_h                 (10), E4
    z = [z_g; z_h] (6),   H = [-2[u_n x]; -2[h_n x]] (6x3)

    model "gravity"        (conventional, (14)):  u_n = g_n
    model "specific-force" (proposed, (28)):      u_n = g_n - a_hat_n = -f_ref_n

The true first-order model of z_g is ``-2[(g_n - a_n) x] q_ev`` (derivation (19)-(21), E7,
E8): the conventional model drops ``+2[a_n x] q_ev``. Eq. (29) is the same update written with
``z_f = -z_g`` and ``H_f = -2[f_ref_n x]``; this module uses the (14) residual with the (28)
matrix throughout (never z_g with H_f: E6). The residual, the noise, the process model and the
initialisation are the same for both models: the model only chooses u_n.

Noise (11), (15), E3, E5, E10, variant ``paper``::

    R_g = diag(s_v(k)^2 + s_v(k-1)^2) / dt^2 + s_f^2 I3     (= (2/dt^2) s_v^2 + s_f^2 for constant s_v)
    R_h = C_nb_hat (s_h^2 I3) C_nb_hat^T = s_h^2 I3
    R   = blkdiag(R_g, R_h)

s_v is the GNSS velocity 1-sigma per NED axis as reported in the stream (``vel_sigma``), s_f and
s_h the per-sample white noise of the accelerometer and magnetometer (parameters). Sensor biases
are not modelled, so R_h is optimistic by design (the paper's).

Update and feedback (docs/methods/vector-matching.md §4.4)
----------------------------------------------------------
::

    S = H P H^T + R;  K = P H^T S^-1 (Cholesky);  dq = K z;  P = (I-KH) P (I-KH)^T + K R K^T
    q_nb_hat <- normalize([1, dq] (x) q_nb_hat);  x_hat <- 0

C_nb_hat is the one from before the correction; no iterations (plain EKF).

Variant ``consistent`` (the default; docs/methods/vector-matching.md §4.6)
-------------------------------------------------------------------------
The same attitude states, residual and feedback, with each sensor error modelled as what it is.
The covariance carries 18 more states that the update never corrects (Schmidt consider states:
their rows of K are 0)::

    index  symbol     unit    meaning (body frame; constant over a run)
    3-5    b_a        m/s^2   accelerometer bias
    6-8    s_a        -       accelerometer scale-factor error
    9-11   b_m        T       magnetometer (hard-iron) bias
    12-14  s_m        -       magnetometer scale-factor error
    15-17  w_v(k-1)   m/s     GNSS velocity error of the previous epoch (white from epoch to epoch)
    18-20  d / e(k-1) -       error of the last step's measured rotation / previous attitude error

    z_g = -2[u_n x] q_ev + C_nb_hat (b_a + diag(f_b) s_a) + (w_v(k-1) - w_v(k)) / dt + n_f
    z_h = -2[h_n x] q_ev - C_nb_hat (b_m + diag(m_b) s_m) + n_h
    R   = blkdiag(s_f^2 I3, s_h^2 I3)

w_v(k) joins the state for the update (variance vel_sigma(k)^2) and replaces w_v(k-1) after it:
the backward difference (13) shares each GNSS error between two epochs. The nominal attitude is
held, so its error does not decay: tau = inf, Phi = I, Q_d = q_w dt I3 (a random walk), unless
the last step measured a rotation (turn model ``constant-rate``): the rotation of the last step
``T = q_fix(k-1) (x) q_fix(k-2)^-1`` (significant when ``d^T P_d^-1 d`` of its vector part d
exceeds the chi-square(3) value of ``manoeuvre_false_alarm``) is predicted to repeat::

    q_nb_hat(k) = T (x) q_fix(k-1),   e(k) = C(T) e(k-1) + d,   d = e(k-1) - C(T) e(k-2)
    a_n <- a_n + T_v x a_n            (13) turned through half the step: its half-step lag (E11)

with e the attitude error (q_ev) and d the error of the measured rotation, whose covariance
with e and the consider states P carries (states 18-20: d between epochs, e(k-1) during the
update). Q_d is added only at an epoch whose NIS without it rejects the prediction ("no rotation
since the last epoch", or "the same rotation again") at the false-alarm probability
``manoeuvre_false_alarm``; the epoch is then updated again with it. The initial fix is the TRIAD attitude corrected by the first epoch's measurement (at rest: a_n = 0)
from a prior of p0_sigma, which gives P its correlation with the sensor constants.

Initialisation (navreplay's choice): TRIAD at the first complete epoch, which must be at rest:
primary pair (-g_n/|g_n|, f_b/|f_b|), secondary pair (h_n, m_b); variant ``paper``:
P0 = p0_sigma^2 I3.

Model-induced error diagnostic, eqs. (23)-(25) with E7 (gravity model only)::

    dq_conv - dq_true = pinv([-2[g_n x]; -2[h_n x]]) z - pinv([-2[(g_n - a_hat_n) x]; -2[h_n x]]) z

reported as the angle ``2 (dq_conv - dq_true)`` [rad].

Dimensions (paper): x 3, Phi and Q_d 3x3, z 6, H 6x3, R 6x6, K 3x6, P 3x3. Consistent: P 21x21
(24x24 during the update, with H 6x24); the attitude block of P is the output.

Two code paths, one model
-------------------------
:class:`VectorMatchingFilter` is the reference: it runs through the replay engine, one epoch at
a time, with the shared :func:`navreplay.filters.kalman.correct`. :func:`run_batch` runs the
same epochs of the ``paper`` variant (the reproduction's) for many synchronous runs at once
(arrays with a leading run axis) for Monte Carlo campaigns; it calls the same model functions
(:func:`process_noise`, :func:`gps_acceleration`, :func:`measurement`, :func:`triad`,
:func:`feedback`) and differs only in doing the Kalman
prediction and correction for a stack of runs (:func:`navreplay.filters.kalman.predict_batch`
and :func:`navreplay.filters.kalman.correct_batch`, the same equations as
:func:`navreplay.filters.kalman.predict` and :func:`navreplay.filters.kalman.correct`).

Outputs (:meth:`VectorMatchingFilter.estimate`)
-----------------------------------------------
``x`` is the attitude error state after feedback (zero), ``P`` its covariance (3x3; the consider
states stay inside the filter), both in phi = 2 q_ev [rad], declared as the navigation errors
phi_N, phi_E, phi_D; ``nav`` holds the attitude ``q_nb`` only (``navigation = ("q_nb",)``:
position and velocity NaN, the filter estimates attitude only); extras:

- ``q_nb`` (4,): attitude estimate, Hamilton scalar first;
- ``euler`` (3,) [rad]: roll, pitch, yaw of ``q_nb``;
- ``euler_sigma`` (3,) [rad]: predicted 1-sigma of the Euler angle errors, from P;
- ``model_induced_phi`` (3,) [rad]: the diagnostic above (model "gravity" only).

Errors against the truth are computed outside the filter.

Examples
--------
At rest and level, both models see the same residual and matrices:

>>> import numpy as np
>>> g_n, h_n = np.array([0.0, 0.0, 9.8]), np.array([3e-5, -4e-6, 4e-5])
>>> f_b, m_b, a_n = -g_n, h_n, np.zeros(3)
>>> zg, Hg = measurement(MatchModel.GRAVITY, np.eye(3), f_b, m_b, a_n, g_n, h_n)
>>> zs, Hs = measurement(MatchModel.SPECIFIC_FORCE, np.eye(3), f_b, m_b, a_n, g_n, h_n)
>>> bool(np.allclose(zg, 0.0) and np.array_equal(Hg, Hs))
True
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from navreplay.core import chi2
from navreplay.core.streams import StreamKind
from navreplay.core.units import DEG, GAUSS, MICRO_G_PER_SQRT_HZ, MILLI_G
from navreplay.filters import kalman
from navreplay.filters.base import (
    Estimate,
    Filter,
    FilterContext,
    FilterParams,
    Innovation,
    MeasurementKind,
    Nav,
    NavError,
    NavSolution,
    Quantity,
    State,
    check_number,
)
from navreplay.filters.registry import register_filter
from navreplay.geo.earth import gravity as normal_gravity
from navreplay.geo.rotations import (
    dcm_to_quat,
    quat_conj,
    quat_mult,
    quat_normalize,
    quat_to_dcm,
    quat_to_euler,
    skew,
)
from navreplay.sensors.imu import ImuModel
from navreplay.sensors.magnetometer import MagnetometerModel
from navreplay.sensors.specs import SensorSpecs

# --------------------------------------------------------------------------------------------
# indices

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

# --------------------------------------------------------------------------------------------
# datasheet values of the paper's Table 1 (docs/methods/vector-matching.md §3.1), converted once

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
        return math.inf if a == 0.0 or a >= 1.0 else chi2.ppf(1.0 - a, 3)

    @property
    def manoeuvre_threshold(self) -> float:
        """NIS above which an epoch gets the process noise (inf: never; 0: always)."""
        a = self.manoeuvre_false_alarm
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


# --------------------------------------------------------------------------------------------
# model functions (pure; they broadcast over leading axes)


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


# --------------------------------------------------------------------------------------------
# the reference filter


@register_filter
class VectorMatchingFilter(Filter):
    """Gyro-free attitude EKF; see the module docstring.

    Streams: ``imu`` (accelerometer only: the ``f_b`` column; a gyro column is ignored),
    ``mag`` and ``gps_vel`` sampled at the same times. An epoch is processed once all three
    samples of one time (within ``sync_tolerance``) have arrived, in whatever order the
    engine hands them over.
    """

    name = "vector-matching"
    summary = (
        "Gyro-free attitude from accelerometer, magnetometer and GPS velocity "
        "(specific-force or gravity vector matching, Choe & Park 2017)"
    )
    requires = (StreamKind.IMU, StreamKind.MAG, StreamKind.GPS_VEL)
    required_columns = {StreamKind.IMU: ("f_b",)}  # an accelerometer: no gyro column needed
    initial = ("pos",)  # the site (gravity, earth field); the attitude comes from TRIAD
    navigation = ("q_nb",)  # attitude only: position and velocity of the solution are NaN
    Params = VectorMatchingParams
    states = STATES
    measurements = (MeasurementKind("vector", ("g_N", "g_E", "g_D", "h_N", "h_E", "h_D"),
                                    ("m/s^2",) * 3 + ("T",) * 3),)  # [z_g; z_h], (10), (14)

    @classmethod
    def settings_from_sensors(cls, sensors: SensorSpecs) -> dict[str, Any]:
        """The per-sample noise of the accelerometer and magnetometer (SI)::

            accel_noise_sigma = accel_vrw sqrt(rate)    an interval-mean sample at the epoch
                                                        rate (the magnetometer's)
            mag_noise_sigma   = the magnetometer's per-sample noise

        The sigmas of the consider states follow the variant (``paper`` has none)."""
        out: dict[str, Any] = {}
        if sensors.has("imu", "accel_vrw") and sensors.has("mag", "rate"):
            out["accel_noise_sigma"] = sensors.imu.accel_vrw * math.sqrt(sensors.mag.rate)
        if sensors.has("mag", "noise"):
            out["mag_noise_sigma"] = sensors.mag.noise
        return out

    @classmethod
    def default_sensors(cls) -> SensorSpecs:
        rate = SENSOR_RATE
        return SensorSpecs(
            {"imu": ImuModel(accel_vrw=ACCEL_NOISE_SIGMA / math.sqrt(rate)),
             "mag": MagnetometerModel(noise=MAG_NOISE_SIGMA, rate=rate)},
            known={"imu": ("accel_vrw",), "mag": ("noise", "rate")},
            sources={"imu": "Table 1 of docs/methods/vector-matching.md",
                     "mag": "Table 1 of docs/methods/vector-matching.md"})

    def __init__(self, params: VectorMatchingParams, context: FilterContext) -> None:
        super().__init__(params, context)
        self.params: VectorMatchingParams = params
        self.ref = reference(params, context.metadata.extra, context.metadata.initial_nav)
        self._f: tuple[np.ndarray, np.ndarray] | None = None  # accelerometer block (t, f_b)
        self._m: tuple[float, np.ndarray] | None = None
        self._v: tuple[float, np.ndarray, np.ndarray] | None = None
        self._prev: EpochSample | None = None
        self.t = 0.0
        self.q_nb: np.ndarray | None = None
        self.P = np.zeros((N_STATES, N_STATES))
        self._diag = np.zeros(3)
        self._estimate: Estimate | None = None
        self._pending: list[Innovation] = []  # of an epoch completed by propagate()
        self._in_gap = False  # an IMU gap is being bridged
        self._turn: np.ndarray | None = None  # the last step's rotation, when significant
        self._q_fix: np.ndarray | None = None  # attitude after the last update

    # -- engine callbacks

    def propagate(self, t: np.ndarray, imu: Mapping[str, np.ndarray]) -> None:
        # Gyro-free: the attitude is not propagated; keep the accelerometer samples for the
        # epoch they belong to.
        self._f = (np.asarray(t, dtype=float), np.asarray(imu["f_b"], dtype=float))
        self._in_gap = False
        self._pending += self._try_epoch()

    def bridge_imu_gap(self, t: float, since: float) -> None:
        """No accelerometer samples from ``since`` until after ``t`` [s]. The attitude is held
        between epochs anyway, its covariance grown by the process model that stands in for
        the gyros; the epochs inside the gap (magnetometer and GNSS without an accelerometer)
        only carry the covariance and the GNSS velocity forward, so that the first epoch after
        the gap differences the GNSS velocity over one epoch (eq. 13), not over the gap."""
        self._in_gap = True

    def update(
        self, kind: StreamKind, t: float, sample: Mapping[str, Any]
    ) -> list[Innovation] | None:
        if kind is StreamKind.MAG:
            self._m = (t, np.asarray(sample["m_b"], dtype=float))
        elif kind is StreamKind.GPS_VEL:
            self._v = (
                t,
                np.asarray(sample["v_n"], dtype=float),
                np.asarray(sample["vel_sigma"], dtype=float),
            )
        else:
            return None
        done = self._pending + self._try_epoch()
        self._pending = []
        return done or None

    def estimate(self) -> Estimate | None:
        # the estimate changes only at epochs: build it once per epoch
        if self._estimate is None and self.q_nb is not None:
            self._estimate = self._build_estimate()
        return self._estimate

    def _build_estimate(self) -> Estimate:
        assert self.q_nb is not None
        euler = quat_to_euler(self.q_nb)
        extras = {
            "q_nb": self.q_nb.copy(),
            "euler": euler,
            "euler_sigma": euler_sigma(euler, self.P[QE, QE]),
        }
        if self.params.model is MatchModel.GRAVITY:
            extras["model_induced_phi"] = self._diag.copy()
        # declared as phi = 2 q_ev (STATES): x = 0 after feedback, P_phi = 4 P_qe
        nav = NavSolution(np.full(3, np.nan), np.full(3, np.nan), self.q_nb.copy())
        return Estimate(self.t, np.zeros(N_STATES), 4.0 * self.P[QE, QE], nav, extras)

    # -- epochs

    def _try_epoch(self) -> list[Innovation]:
        """Run the epoch whose accelerometer, magnetometer and GNSS samples are all in."""
        if self._m is None or self._v is None or self._f is None:
            return []
        t = self._v[0]
        tol = self.params.sync_tolerance
        if abs(self._m[0] - t) > tol or (self._prev is not None and t <= self._prev.t + tol):
            return []
        t_f, f_b = self._f
        j = np.flatnonzero(np.abs(t_f - t) <= tol)
        if j.size == 0:
            if self._in_gap and self._prev is not None:
                self._coast(EpochSample(t, self._prev.f_b, self._m[1], self._v[1], self._v[2]))
            return []
        cur = EpochSample(t, f_b[j[-1]], self._m[1], self._v[1], self._v[2])
        if self._prev is None:
            self._initialise(cur)
            return []
        return [self._epoch(cur)]

    def _initialise(self, cur: EpochSample) -> None:
        p = self.params
        self.q_nb = triad(cur.f_b, cur.m_b, self.ref.g_n, self.ref.h_n)
        if p.variant is Variant.PAPER:
            self.P = p.p0_sigma**2 * np.eye(N_STATES)
        else:
            # the first fix: TRIAD corrected by this epoch's measurement from a wide prior, at
            # rest (a_n = 0, no GNSS difference): P learns its correlation with the constants
            P = np.zeros((N_CONSISTENT, N_CONSISTENT))
            P[QE, QE] = p.p0_sigma**2 * np.eye(3)
            P[SENSOR, SENSOR] = consider_covariance(p)
            P[W_PREV, W_PREV] = np.diag(cur.vel_sigma**2)
            self._consider_update(P, cur, np.zeros(3), 0.0, None)
        self.t = float(cur.t)
        self._prev = cur
        self._estimate = None

    def _coast(self, cur: EpochSample) -> None:
        """An epoch without an accelerometer sample (IMU gap): predict only."""
        p = self.params
        phi, qd = process_noise(float(cur.t) - float(self._prev.t), p.tau, p.q_w)  # (16)-(18)
        if p.variant is Variant.PAPER:
            _, self.P = kalman.predict(np.zeros(N_STATES), self.P, float(phi) * np.eye(N_STATES),
                                       float(qd) * np.eye(N_STATES), t=cur.t)
        else:
            # no measurement tests the rotation over a gap: the process noise applies; this
            # epoch's GNSS velocity becomes the previous one, with a fresh error
            self.P = held_prediction(self.P, float(phi), float(qd))
            self.P[W_PREV, :] = 0.0
            self.P[:, W_PREV] = 0.0
            self.P[W_PREV, W_PREV] = np.diag(cur.vel_sigma**2)
            self._turn = None
        self.t = float(cur.t)
        self._prev = cur
        self._estimate = None

    def _epoch(self, cur: EpochSample) -> Innovation:
        p = self.params
        prev = self._prev
        assert prev is not None and self.q_nb is not None
        dt = float(cur.t) - float(prev.t)
        phi, qd = process_noise(dt, p.tau, p.q_w)  # (16)-(18)
        if p.variant is Variant.CONSISTENT:
            a_n = gps_acceleration(cur.v_n, prev.v_n, dt)  # (13)
            P = held_prediction(self.P, float(phi), 0.0)
            A = np.eye(N_CONSISTENT)
            A[CLONE, :] = 0.0
            A[CLONE, QE] = np.eye(3)  # the clone becomes e(k-1)
            if self._turn is not None:  # e(k) = R e(k-1) + d(k-1): the same rotation again
                A[QE, QE] = quat_to_dcm(self._turn)
                A[QE, CLONE] = np.eye(3)
                self.q_nb = quat_normalize(quat_mult(self._turn, self.q_nb))
                # (13) is the step's mean acceleration, half a step old (E11): turned with
                # the vehicle through half the step's rotation to t_k
                a_n = a_n + np.cross(self._turn[1:], a_n)
            c = self._consider_update(A @ P @ A.T, cur, a_n, dt, float(qd))
        else:
            _, P = kalman.predict(
                np.zeros(N_STATES), self.P, float(phi) * np.eye(N_STATES),
                float(qd) * np.eye(N_STATES), t=cur.t,
            )
            m, a_n = epoch_measurement(p, self.ref, quat_to_dcm(self.q_nb), cur.f_b, cur.m_b,
                                       cur.v_n, prev.v_n, cur.vel_sigma, prev.vel_sigma, dt)
            c = kalman.correct(np.zeros(N_STATES), P, *m, t=cur.t)
            self.q_nb = feedback(self.q_nb, c.x[QE])  # x_hat <- 0
            self.P = c.P
            if p.model is MatchModel.GRAVITY:
                self._diag = model_induced_error(m.z, a_n, self.ref.g_n, self.ref.h_n)
        self.t = float(cur.t)
        self._prev = cur
        self._estimate = None
        return c.innovation("vector", self.t)

    def _consider_update(self, P: np.ndarray, cur: EpochSample, a_n: np.ndarray, dt: float,
                         qd: float | None) -> kalman.Correction:
        """Update of the consistent variant (module docstring): P (21x21, states 18-20 the
        previous attitude error) predicted without process noise; ``qd`` is added (and the
        update redone) when the NIS rejects the prediction (None: never, the initial fix). A
        fix from a wide prior (a manoeuvre, the initial fix) is iterated: the residual is
        relinearised at the corrected attitude (:data:`FIX_ITERATIONS` times). Then the
        rotation of the step is measured and kept when significant (turn model
        ``constant-rate``). Sets q_nb, P and the diagnostic; returns the correction whose
        innovation is that of the prior."""
        p = self.params
        assert self.q_nb is not None
        R = np.r_[np.full(3, p.accel_noise_sigma**2), np.full(3, p.mag_noise_sigma**2)]
        Pa = np.zeros((N_CONSISTENT + 3, N_CONSISTENT + 3))
        Pa[:N_CONSISTENT, :N_CONSISTENT] = P
        Pa[N_CONSISTENT:, N_CONSISTENT:] = np.diag(cur.vel_sigma**2)  # w_v(k)
        frozen = np.arange(N_CONSISTENT + 3) >= 3
        x = np.zeros(N_CONSISTENT + 3)

        def correct(q_nb: np.ndarray) -> kalman.Correction:
            C = quat_to_dcm(q_nb)
            z, H_q = measurement(p.model, C, cur.f_b, cur.m_b, a_n, self.ref.g_n, self.ref.h_n)
            cc = consider_columns(C, cur.f_b, cur.m_b, dt)
            H = np.concatenate([H_q, cc[:, :15], np.zeros((N_MEAS, 3)), cc[:, 15:]], axis=1)
            return kalman.correct(x, Pa, z, H, R, frozen=frozen, t=cur.t)

        q_prev = self._q_fix  # the fix of the last epoch
        c = correct(self.q_nb) if qd is None or p.manoeuvre_threshold > 0.0 else None
        wide = qd is None
        if qd is not None and (c is None or c.nis > p.manoeuvre_threshold):
            Pa[QE, QE] += qd * np.eye(3)  # the vehicle turned: unknown rotation since k-1
            c = correct(self.q_nb)
            wide = p.manoeuvre_threshold > 0.0
        first = c
        self.q_nb = feedback(self.q_nb, c.x[QE])  # x_hat <- 0
        if wide:
            x[QE] = -c.x[QE]  # the prior attitude, seen from the corrected one
            for _ in range(FIX_ITERATIONS):
                c = correct(self.q_nb)
                self.q_nb = feedback(self.q_nb, c.x[QE])
                x[QE] -= c.x[QE]
        keep = np.r_[0:W_PREV.start, N_CONSISTENT:N_CONSISTENT + 3, CLONE]  # w_v(k) -> w_v(k-1)
        P = c.P[np.ix_(keep, keep)]
        self._turn = None
        if qd is not None and p.turn_model is TurnModel.CONSTANT_RATE:
            # the rotation of this step and its error d = e(k) - R e(k-1); kept for the next
            # step when significant at the manoeuvre test's false alarm
            turn = quat_mult(self.q_nb, quat_conj(q_prev))
            turn *= np.sign(turn[0])
            A = np.eye(N_CONSISTENT)
            A[CLONE, QE] = np.eye(3)
            A[CLONE, CLONE] = -quat_to_dcm(turn)
            P = A @ P @ A.T
            d = turn[1:]
            if d @ np.linalg.solve(P[CLONE, CLONE], d) > p.turn_threshold:
                self._turn = turn
        self.P = P
        self._q_fix = self.q_nb
        if p.model is MatchModel.GRAVITY:
            self._diag = model_induced_error(first.nu, a_n, self.ref.g_n, self.ref.h_n)
        return first


def reference(
    params: VectorMatchingParams, extra: Mapping[str, Any], initial_nav: Mapping[str, Any]
) -> Reference:
    """Reference gravity and field from the parameters, else from the recording's metadata.

    Raises
    ------
    ValueError
        Neither the parameters nor the metadata give the value.
    """
    if params.earth_field_n is not None:
        h_n = np.array(params.earth_field_n)
    elif "earth_field_n" in extra:
        h_n = np.asarray(extra["earth_field_n"], dtype=float)
        if h_n.shape != (3,) or not np.all(np.isfinite(h_n)):
            raise ValueError(f"metadata earth_field_n must be three finite values, got {h_n}")
    else:
        raise ValueError(
            "filter 'vector-matching' needs the reference geomagnetic field: set the parameter "
            "earth_field_n (N, E, D in tesla) or record metadata extra['earth_field_n']"
        )
    if params.gravity is not None:
        g = params.gravity
    elif "pos" in initial_nav:
        lat, _, h = np.asarray(initial_nav["pos"], dtype=float)
        g = float(normal_gravity(lat, h))
    else:
        raise ValueError(
            "filter 'vector-matching' needs gravity: set the parameter gravity [m/s^2] or "
            "record the site in metadata initial_nav['pos']"
        )
    return Reference(np.array([0.0, 0.0, g]), h_n)


# --------------------------------------------------------------------------------------------
# the batched path


@dataclasses.dataclass
class BatchEstimates:
    """Estimates of :func:`run_batch` at every epoch; leading axes (B, K) = (runs, epochs).

    Attributes
    ----------
    t : ndarray, shape (K,)
        Epoch times [s].
    q_nb : ndarray, shape (B, K, 4)
    P : ndarray, shape (B, K, 3, 3)
        Covariance of q_ev after the epoch's update.
    model_induced_phi : ndarray, shape (B, K, 3) or None
        The gravity-model diagnostic [rad] (zero at the first epoch); None for the
        specific-force model or when not asked for.
    """

    t: np.ndarray
    q_nb: np.ndarray
    P: np.ndarray
    model_induced_phi: np.ndarray | None

    def euler(self) -> np.ndarray:
        """Roll, pitch, yaw [rad], shape (B, K, 3)."""
        return quat_to_euler(self.q_nb)

    def euler_sigma(self) -> np.ndarray:
        """Predicted 1-sigma of the Euler angle errors [rad], shape (B, K, 3)."""
        return euler_sigma(self.euler(), self.P)


def run_batch(
    params: VectorMatchingParams,
    ref: Reference,
    t: np.ndarray,
    f_b: np.ndarray,
    m_b: np.ndarray,
    v_n: np.ndarray,
    vel_sigma: np.ndarray,
    *,
    diagnostic: bool = False,
) -> BatchEstimates:
    """Run the filter over B synchronous recordings at once (the Monte Carlo fast path).

    Epoch 0 initialises by TRIAD; epochs 1..K-1 propagate and update exactly as
    :class:`VectorMatchingFilter` does with ``variant=paper``.

    Parameters
    ----------
    params : VectorMatchingParams
    ref : Reference
    t : ndarray, shape (K,)
        Epoch times [s], common to all runs, increasing.
    f_b, m_b, v_n, vel_sigma : ndarray, shape (B, K, 3)
        Accelerometer [m/s^2], magnetometer [T], GNSS velocity and its reported 1-sigma [m/s].
    diagnostic : bool
        Also compute the model-induced error of the gravity model (a pseudo-inverse per run
        and epoch: it triples the cost).

    Returns
    -------
    BatchEstimates

    Raises
    ------
    ValueError
        Inconsistent shapes, or ``params.variant`` is not ``paper``.
    """
    if params.variant is not Variant.PAPER:
        raise ValueError("run_batch runs variant=paper (the reproduction's model); the "
                         "consistent variant runs in VectorMatchingFilter")
    t = np.asarray(t, dtype=float)
    B, K = f_b.shape[:2]
    for name, a in (("f_b", f_b), ("m_b", m_b), ("v_n", v_n), ("vel_sigma", vel_sigma)):
        if a.shape != (B, K, 3):
            raise ValueError(f"{name} must have shape ({B}, {K}, 3), got {a.shape}")
    if t.shape != (K,) or K < 1 or np.any(np.diff(t) <= 0.0):
        raise ValueError(f"t must be {K} increasing epoch times, got shape {t.shape}")
    gravity_model = params.model is MatchModel.GRAVITY
    q_out = np.empty((B, K, 4))
    P_out = np.empty((B, K, N_STATES, N_STATES))
    diag = np.zeros((B, K, 3)) if gravity_model and diagnostic else None

    q = triad(f_b[:, 0], m_b[:, 0], ref.g_n, ref.h_n)
    P = np.broadcast_to(params.p0_sigma**2 * np.eye(N_STATES), (B, N_STATES, N_STATES)).copy()
    q_out[:, 0], P_out[:, 0] = q, P
    eye = np.eye(N_STATES)
    x0 = np.zeros((B, N_STATES))  # the error state after feedback
    for k in range(1, K):
        dt = t[k] - t[k - 1]
        phi, qd = process_noise(dt, params.tau, params.q_w)  # (16)-(18)
        _, P = kalman.predict_batch(x0, P, float(phi) * eye, float(qd) * eye, t=float(t[k]))
        m, a_n = epoch_measurement(params, ref, quat_to_dcm(q), f_b[:, k], m_b[:, k],
                                   v_n[:, k], v_n[:, k - 1], vel_sigma[:, k],
                                   vel_sigma[:, k - 1], dt)
        c = kalman.correct_batch(x0, P, *m, t=float(t[k]))
        q = feedback(q, c.x[..., QE])  # x_hat <- 0
        P = c.P
        q_out[:, k], P_out[:, k] = q, P
        if diag is not None:
            diag[:, k] = model_induced_error(m.z, a_n, ref.g_n, ref.h_n)
    return BatchEstimates(t, q_out, P_out, diag)
