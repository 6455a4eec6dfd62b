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

    R_g = diag(s_v(k)^2 + s_v(k-1)^2) / dt^2 + s_f^2 I3     (= (2/dt^2) s_v^2 + s_f^2 for
                                                             constant s_v)
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
``manoeuvre_false_alarm``; the epoch is then updated again with it. The initial fix is the TRIAD
attitude corrected by the first epoch's measurement (at rest: a_n = 0) from a prior of p0_sigma,
which gives P its correlation with the sensor constants.

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
True"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay.core.streams import StreamKind
from navreplay.filters import kalman
from navreplay.filters.base import (
    Estimate,
    Filter,
    FilterContext,
    Innovation,
    MeasurementKind,
    NavSolution,
)
from navreplay.filters.registry import register_filter
from navreplay.filters.vector_matching_model import (
    ACCEL_BIAS_SIGMA,
    ACCEL_NOISE_DENSITY,
    ACCEL_NOISE_SIGMA,
    CLONE,
    FIX_ITERATIONS,
    MAG_BIAS_SIGMA,
    MAG_NOISE_DENSITY,
    MAG_NOISE_SIGMA,
    N_CONSISTENT,
    N_MEAS,
    N_STATES,
    QE,
    SCALE_FACTOR_SIGMA,
    SENSOR,
    SENSOR_PARAMS,
    SENSOR_RATE,
    STATES,
    VARIANT_DEFAULTS,
    W_PREV,
    Z_G,
    Z_H,
    EpochSample,
    MatchModel,
    Reference,
    TurnModel,
    Variant,
    VectorMatchingParams,
    consider_columns,
    consider_covariance,
    epoch_measurement,
    euler_sigma,
    feedback,
    gps_acceleration,
    held_prediction,
    measurement,
    measurement_noise,
    model_induced_error,
    process_noise,
    triad,
)
from navreplay.geo.earth import gravity as normal_gravity
from navreplay.geo.rotations import (
    quat_conj,
    quat_mult,
    quat_normalize,
    quat_to_dcm,
    quat_to_euler,
)
from navreplay.sensors.imu import ImuModel
from navreplay.sensors.magnetometer import MagnetometerModel
from navreplay.sensors.specs import SensorSpecs

# the method's declarations and model are importable from here, beside the filter
__all__ = [
    "ACCEL_BIAS_SIGMA",
    "ACCEL_NOISE_DENSITY",
    "ACCEL_NOISE_SIGMA",
    "BatchEstimates",
    "CLONE",
    "EpochSample",
    "FIX_ITERATIONS",
    "MAG_BIAS_SIGMA",
    "MAG_NOISE_DENSITY",
    "MAG_NOISE_SIGMA",
    "MatchModel",
    "N_CONSISTENT",
    "N_MEAS",
    "N_STATES",
    "QE",
    "Reference",
    "SCALE_FACTOR_SIGMA",
    "SENSOR",
    "SENSOR_PARAMS",
    "SENSOR_RATE",
    "STATES",
    "TurnModel",
    "VARIANT_DEFAULTS",
    "Variant",
    "VectorMatchingFilter",
    "VectorMatchingParams",
    "W_PREV",
    "Z_G",
    "Z_H",
    "consider_columns",
    "consider_covariance",
    "epoch_measurement",
    "euler_sigma",
    "feedback",
    "gps_acceleration",
    "held_prediction",
    "measurement",
    "measurement_noise",
    "model_induced_error",
    "process_noise",
    "reference",
    "run_batch",
    "triad",
]


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
        imu, mag = sensors.get("imu"), sensors.get("mag")  # read only where stated
        if sensors.has("imu", "accel_vrw") and sensors.has("mag", "rate"):
            out["accel_noise_sigma"] = imu.accel_vrw * math.sqrt(mag.rate)
        if sensors.has("mag", "noise"):
            out["mag_noise_sigma"] = mag.noise
        return out

    @classmethod
    def default_sensors(cls) -> SensorSpecs:
        rate = SENSOR_RATE
        return SensorSpecs(
            {"imu": ImuModel(accel_vrw=ACCEL_NOISE_SIGMA / math.sqrt(rate)),
             "mag": MagnetometerModel(noise=MAG_NOISE_SIGMA, rate=rate)},
            known={"imu": frozenset({"accel_vrw"}), "mag": frozenset({"noise", "rate"})},
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
        assert p.p0_sigma is not None  # filled from the variant
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
        assert self._prev is not None and p.tau is not None  # an epoch before; from the variant
        phi, qd = process_noise(float(cur.t) - float(self._prev.t), p.tau, p.q_w)  # (16)-(18)
        if p.variant is Variant.PAPER:
            _, self.P = kalman.predict(np.zeros(N_STATES), self.P, float(phi) * np.eye(N_STATES),
                                       float(qd) * np.eye(N_STATES), t=float(cur.t))
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
        assert prev is not None and self.q_nb is not None and p.tau is not None
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
                float(qd) * np.eye(N_STATES), t=float(cur.t),
            )
            m, a_n = epoch_measurement(p, self.ref, quat_to_dcm(self.q_nb), cur.f_b, cur.m_b,
                                       cur.v_n, prev.v_n, cur.vel_sigma, prev.vel_sigma, dt)
            c = kalman.correct(np.zeros(N_STATES), P, *m, t=float(cur.t))
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
            return kalman.correct(x, Pa, z, H, R, frozen=frozen, t=float(cur.t))

        q_prev = self._q_fix  # the fix of the last epoch
        c = correct(self.q_nb) if qd is None or p.manoeuvre_threshold > 0.0 else None
        wide = qd is None
        if qd is not None and (c is None or c.nis > p.manoeuvre_threshold):
            Pa[QE, QE] += qd * np.eye(3)  # the vehicle turned: unknown rotation since k-1
            c = correct(self.q_nb)
            wide = p.manoeuvre_threshold > 0.0
        assert c is not None  # corrected in one of the branches above
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
    assert params.p0_sigma is not None and params.tau is not None  # filled from the variant
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
