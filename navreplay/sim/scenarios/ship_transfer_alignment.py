"""Shipboard transfer alignment: a slave SDINS on a rolling, pitching, flexing ship and its GINS.

The scenario of docs/methods/transfer-alignment.md §3 (Song, Jeon and Lyou, "A Transfer
Alignment Algorithm Using Velocity and Quaternion Partial Matching Methods", section IV).
Errata E11 and E17 are those of docs/methods/transfer-alignment.md §7.

Motion
    The ship (frame r: X bow, Y starboard, Z down) cruises at constant ground velocity along a
    constant heading psi0 and rolls and pitches as the sums of seven harmonics of Table 1,
    eq. (18), with phases drawn uniformly on [0, 2 pi) for every run (erratum E11)::

        roll(t)  = sum_i A_i sin(2 pi f_i t + p_i)          (same for pitch)
        omega_nr_r = [roll', pitch' cos(roll), -pitch' sin(roll)]    (constant yaw)

    The rotation centre is the GINS, so the GINS (master) velocity is the constant cruise
    velocity V_R. The SDINS sits at the lever arm L^r from the GINS::

        V_B = V_R + C_nr (omega_nr_r x L_f^r + dL_f^r/dt)    (w_en ignored)

    where L_f^r is the lever arm as the flexure bends it (:func:`flexed_lever_arm`).

Flexure and mounting
    The SDINS frame b is mounted with a fixed misalignment C_mis (three ZYX Euler angles, each
    N(0, mounting_sigma^2)) and bent about the ship's Y axis by theta_f, the second-order Markov
    process of eq. (19)::

        theta'' + 2 zeta wn theta' + wn^2 theta = w,   E[w w] = 4 zeta wn^3 sigma^2 delta(t)
        C_rb = Ry(theta_f) C_mis,   C_nb = C_nr C_rb

    discretised exactly (Van Loan) at the IMU rate and started from its stationary
    distribution. ``flexure_wn`` selects the reading of the paper's "1.0 Hz": 2 pi rad/s (the
    default, the literal value) or 1.0 rad/s (erratum E17).

Sensors
    SDINS IMU, 100 Hz (:class:`navreplay.sensors.imu.ImuModel`, Table 2): bias, scale factor,
    six off-diagonal misalignments, gyro mass unbalance K_g f_b and white noise, whose 1-s average
    has the table's 1 sigma. The ideal samples are the mean rate and specific force over each
    interval (:func:`navreplay.sim.kinematics.imu_from_truth`).
    GINS, 10 Hz (:class:`navreplay.sensors.master_ins.MasterInsModel`, eqs. (20)-(22) with exact
    rotations): platform tilt, synchro bias and noise on the Euler angles, velocity bias and
    noise; position is the truth.

Every paper number is a field of :class:`ShipTransferAlignmentParams` with the paper's value as
default. The truth at the IMU grid and every drawn error are written to the recording (truth
stream columns and ``Metadata.true_errors``). The surveyed lever arm, with its knowledge error,
is ``Metadata.params["lever_arm_r_nom"]``: the transfer-alignment filter uses it by default.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.signal import lfilter, lfiltic

from navreplay.core.lti import second_order_markov
from navreplay.core.params import check_nonnegative, check_positive
from navreplay.core.streams import Recording, Stream, StreamKind, nanoseconds
from navreplay.core.units import (
    ARCMIN,
    DEG,
    DEG_PER_HOUR,
    DEG_PER_HOUR_PER_G,
    FOOT,
    KNOT,
    MICRO_G,
    PPM,
)
from navreplay.geo.earth import ned_offset_to_lla
from navreplay.geo.rotations import euler_to_quat, quat_mult, quat_to_dcm, quat_to_euler
from navreplay.sensors.imu import ImuModel
from navreplay.sensors.master_ins import MasterInsModel
from navreplay.sensors.noise import density_from_average_sigma
from navreplay.sensors.specs import SensorSpecs
from navreplay.sim.kinematics import imu_from_truth, integrate_position
from navreplay.sim.scenario import Scenario, imu_stream, register_scenario

T0_NS = 1_704_067_200_000_000_000
"""Recording start, 2024-01-01T00:00:00Z [ns since the UNIX epoch]."""

ROLL_FREQ = (0.071, 0.090, 0.097, 0.115, 0.139, 0.167, 0.182)
"""Table 1, roll harmonic frequencies [Hz]."""
ROLL_AMP_DEG = (0.3, 0.75, 1.2, 1.5, 1.35, 0.9, 0.3)
"""Table 1, roll harmonic amplitudes [deg]."""
PITCH_FREQ = (0.107, 0.136, 0.161, 0.170, 0.179, 0.205, 0.224)
"""Table 1, pitch harmonic frequencies [Hz]."""
PITCH_AMP_DEG = (0.6, 0.95, 1.2, 1.1, 0.85, 0.5, 0.25)
"""Table 1, pitch harmonic amplitudes [deg]."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class ShipTransferAlignmentParams:
    """Parameters of the ship transfer-alignment scenario (SI; paper values as defaults).

    All 1-sigma values are per axis (per Euler angle, per matrix entry) and drawn once per run
    unless called noise.
    """

    duration: float = 100.0
    """Length of the recording [s] (the paper's alignment time)."""
    imu_rate: float = 100.0
    """SDINS IMU rate [Hz]; each sample is the mean over the preceding interval."""
    gins_rate: float = 10.0
    """GINS output rate [Hz] (Euler angles, NED velocity, position)."""
    lat: float = 35.0 * DEG
    """Latitude of the start point [rad]."""
    lon: float = 129.0 * DEG
    """Longitude of the start point [rad]."""
    height: float = 0.0
    """Ellipsoidal height [m]."""
    yaw: float = 30.0 * DEG
    """Constant heading psi0 of the ship [rad]."""
    speed: float = 10.0 * KNOT
    """Constant ground speed along the heading [m/s] (10 kn)."""
    roll_freq: tuple[float, ...] = ROLL_FREQ
    """Roll harmonic frequencies f_i [Hz], Table 1."""
    roll_amp: tuple[float, ...] = tuple(a * DEG for a in ROLL_AMP_DEG)
    """Roll harmonic amplitudes A_i [rad], Table 1."""
    pitch_freq: tuple[float, ...] = PITCH_FREQ
    """Pitch harmonic frequencies f_i [Hz], Table 1."""
    pitch_amp: tuple[float, ...] = tuple(a * DEG for a in PITCH_AMP_DEG)
    """Pitch harmonic amplitudes A_i [rad], Table 1."""
    lever_arm_r: tuple[float, float, float] = (150.0 * FOOT, 50.0 * FOOT, 40.0 * FOOT)
    """True lever arm from the GINS to the SDINS in the ship frame (X, Y, Z) [m]."""
    lever_arm_sigma: float = 1.0 * FOOT
    """Lever-arm knowledge (survey) error, random constant per axis [m]."""
    flexure_sigma: float = 0.5 * DEG
    """Steady-state 1 sigma of the Y-axis flexure angle theta_f [rad] (0 switches it off)."""
    flexure_zeta: float = 0.7
    """Damping ratio of the flexure model, eq. (19) [-]."""
    flexure_wn: float = 2.0 * math.pi
    """Natural frequency of the flexure model [rad/s]: 2 pi (the paper's "1.0 Hz") or 1.0."""
    mounting_sigma: float = 3.0 * DEG
    """Fixed mounting misalignment, each ZYX Euler angle of C_mis [rad]."""
    gins_tilt: tuple[float, float, float] = (3.0 * ARCMIN, 3.0 * ARCMIN, 5.0 * ARCMIN)
    """GINS platform tilt eps_N, eps_E, eps_D, random constants [rad]."""
    gins_synchro_bias: float = 3.0 * ARCMIN
    """GINS synchro error per Euler angle, random constant [rad]."""
    gins_synchro_noise: float = 1.0 * ARCMIN
    """GINS synchro white noise per Euler angle, per sample [rad]."""
    gins_vel_bias: float = 0.7 * FOOT
    """GINS velocity error per NED axis, random constant [m/s]."""
    gins_vel_noise: float = 0.3 * FOOT
    """GINS velocity white noise per NED axis, per sample [m/s]."""
    gyro_bias: float = 0.6 * DEG_PER_HOUR
    """SDINS gyro bias, random constant [rad/s], Table 2."""
    gyro_scale_factor: float = 300.0 * PPM
    """SDINS gyro scale-factor error [-], Table 2."""
    gyro_misalignment: float = 1.0 * ARCMIN
    """SDINS gyro misalignment, each off-diagonal term [rad], Table 2."""
    gyro_g_sensitivity: float = 0.3 * DEG_PER_HOUR_PER_G
    """SDINS gyro mass unbalance, each entry of K_g [(rad/s)/(m/s^2)], Table 2."""
    gyro_arw: float = density_from_average_sigma(0.1 * DEG_PER_HOUR)
    """SDINS gyro white noise density [rad/sqrt(s)]: Table 2's 0.1 deg/h as a 1-s average."""
    accel_bias: float = 250.0 * MICRO_G
    """SDINS accelerometer bias, random constant [m/s^2], Table 2."""
    accel_scale_factor: float = 300.0 * PPM
    """SDINS accelerometer scale-factor error [-], Table 2."""
    accel_misalignment: float = 1.0 * ARCMIN
    """SDINS accelerometer misalignment, each off-diagonal term [rad], Table 2."""
    accel_vrw: float = density_from_average_sigma(20.0 * MICRO_G)
    """SDINS accelerometer white noise density [(m/s)/sqrt(s)]: Table 2's 20 ug, 1-s average."""

    def __post_init__(self) -> None:
        check_positive(self, "duration", "imu_rate", "gins_rate", "flexure_zeta", "flexure_wn")
        if not abs(self.lat) < 89.0 * DEG:
            raise ValueError(f"lat must be within +-89 deg, got {self.lat!r} rad")
        check_nonnegative(self, "speed")
        for axis in ("roll", "pitch"):
            f, a = getattr(self, f"{axis}_freq"), getattr(self, f"{axis}_amp")
            if len(f) != len(a):
                raise ValueError(
                    f"{axis}_freq and {axis}_amp must have equal lengths, got {len(f)} and"
                    f" {len(a)}"
                )
            check_nonnegative(self, f"{axis}_freq", f"{axis}_amp")
            if sum(a) >= 80.0 * DEG:
                raise ValueError(f"{axis}_amp sums to {sum(a) / DEG:.1f} deg; must be < 80 deg")
        if len(self.lever_arm_r) != 3 or len(self.gins_tilt) != 3:
            raise ValueError("lever_arm_r and gins_tilt need three values each")
        check_nonnegative(
            self, "lever_arm_sigma", "flexure_sigma", "mounting_sigma", "gins_tilt",
            "gins_synchro_bias", "gins_synchro_noise", "gins_vel_bias", "gins_vel_noise",
            "gyro_bias", "gyro_scale_factor", "gyro_misalignment", "gyro_g_sensitivity",
            "gyro_arw", "accel_bias", "accel_scale_factor", "accel_misalignment", "accel_vrw",
        )
        if self.duration * self.imu_rate < 2.0 or self.duration * self.gins_rate < 1.0:
            raise ValueError("duration must hold at least two IMU and two GINS samples")

    def imu_model(self) -> ImuModel:
        """The SDINS error model of Table 2."""
        return ImuModel(
            gyro_bias=self.gyro_bias,
            gyro_scale_factor=self.gyro_scale_factor,
            gyro_misalignment=self.gyro_misalignment,
            gyro_g_sensitivity=self.gyro_g_sensitivity,
            gyro_arw=self.gyro_arw,
            accel_bias=self.accel_bias,
            accel_scale_factor=self.accel_scale_factor,
            accel_misalignment=self.accel_misalignment,
            accel_vrw=self.accel_vrw,
        )

    def gins_model(self) -> MasterInsModel:
        """The GINS error model of eqs. (20)-(22) and section IV.3."""
        return MasterInsModel(
            tilt=self.gins_tilt,
            synchro_bias=self.gins_synchro_bias,
            synchro_noise=self.gins_synchro_noise,
            vel_bias=self.gins_vel_bias,
            vel_noise=self.gins_vel_noise,
            rate=self.gins_rate,
        )


# --------------------------------------------------------------------------------------------
# pure pieces (each a function of its arguments)


def harmonics(
    t: np.ndarray, freq: tuple[float, ...], amp: tuple[float, ...], phase: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sum of harmonics, eq. (18), and its time derivative.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Times [s].
    freq, amp : tuple of float, length K
        Frequencies [Hz] and amplitudes [rad].
    phase : ndarray, shape (K,)
        Phases [rad].

    Returns
    -------
    angle, rate : ndarray, shape (N,)
        [rad] and [rad/s].
    """
    w = 2.0 * np.pi * np.asarray(freq, dtype=float)
    arg = np.outer(t, w) + phase
    a = np.asarray(amp, dtype=float)
    return np.sin(arg) @ a, np.cos(arg) @ (a * w)


def flexure(
    n: int, dt: float, sigma: float, zeta: float, wn: float, normals: np.ndarray
) -> np.ndarray:
    """The flexure angle theta_f of :func:`flexure_state` [rad], (n,)."""
    return flexure_state(n, dt, sigma, zeta, wn, normals)[0]


def flexure_state(
    n: int, dt: float, sigma: float, zeta: float, wn: float, normals: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Stationary second-order Markov flexure angle and rate, eq. (19), exactly discretised.

    State s = [theta, theta'], ``s' = F s + [0, 1]^T w`` with ``F = [[0, 1], [-wn^2,
    -2 zeta wn]]`` and PSD ``4 zeta wn^3 sigma^2``. ``s_0 ~ N(0, diag(sigma^2, (wn sigma)^2))``
    (the stationary distribution) and ``s_k+1 = Phi s_k + w_k`` with (Phi, Qd) by Van Loan.
    The recursion for theta alone (Cayley-Hamilton) runs as one IIR filter, and the rate's row
    ``theta'_k+1 = Phi10 theta_k + Phi11 theta'_k + w1_k`` as a second one.

    Parameters
    ----------
    n : int
        Number of samples (at t = k dt, k = 0..n-1).
    dt : float
        Sample interval [s].
    sigma, zeta, wn : float
        Steady-state 1 sigma [rad], damping ratio [-], natural frequency [rad/s].
    normals : ndarray, shape (n, 2)
        Standard normal draws: row 0 for s_0, rows 1..n-1 for w_0..w_n-2.

    Returns
    -------
    theta : ndarray, shape (n,)
        [rad].
    theta_rate : ndarray, shape (n,)
        [rad/s].
    """
    Phi, Qd = second_order_markov(1.0, zeta, wn, dt)  # unit sigma, scaled below
    Lq = np.linalg.cholesky(Qd)
    s0 = normals[0] * np.array([1.0, wn])
    w = normals[1:n] @ Lq.T  # w_0 .. w_n-2
    theta = np.empty(n)
    rate = np.empty(n)
    theta[0], rate[0] = s0
    if n > 1:
        theta[1] = Phi[0] @ s0 + w[0, 0]
    if n > 2:
        # theta_k = tr theta_k-1 - det theta_k-2 + w0_k-1 - Phi11 w0_k-2 + Phi01 w1_k-2
        u = w[1:, 0] - Phi[1, 1] * w[:-1, 0] + Phi[0, 1] * w[:-1, 1]
        a = [1.0, -np.trace(Phi), np.linalg.det(Phi)]
        zi = lfiltic([1.0], a, y=[theta[1], theta[0]])
        theta[2:], _ = lfilter([1.0], a, u, zi=zi)
    if n > 1:
        a1 = [1.0, -Phi[1, 1]]
        rate[1:], _ = lfilter([1.0], a1, Phi[1, 0] * theta[:-1] + w[:, 1],
                              zi=lfiltic([1.0], a1, y=[rate[0]]))
    return sigma * theta, sigma * rate


def flexed_lever_arm(
    lever_arm_r: np.ndarray, theta: np.ndarray, theta_rate: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Lever arm GINS -> SDINS in the ship frame as the flexure bends it, and its rate.

    The bending that turns the SDINS by theta_f about the ship's Y axis turns the lever arm
    with it (to first order in theta_f)::

        L_f^r = L^r + theta_f (e_Y x L^r),    dL_f^r/dt = theta_f' (e_Y x L^r)

    so that the SDINS velocity ``V_R + C_nr (w_nr^r x L_f^r + dL_f^r/dt)`` is the rigid-body
    lever-arm velocity with the SDINS's own rate ``w_nb = w_nr + theta_f' e_Y``, the rate the
    SDINS gyro senses (docs/methods/transfer-alignment.md §3.2).

    Parameters
    ----------
    lever_arm_r : ndarray, shape (3,)
        Unbent lever arm [m].
    theta, theta_rate : ndarray, shape (N,)
        Flexure angle [rad] and rate [rad/s].

    Returns
    -------
    arm, arm_rate : ndarray, shape (N, 3)
        [m] and [m/s].
    """
    ey_x_arm = np.cross([0.0, 1.0, 0.0], lever_arm_r)
    return lever_arm_r + np.outer(theta, ey_x_arm), np.outer(theta_rate, ey_x_arm)


@register_scenario
class ShipTransferAlignment(Scenario):
    """Ship rolling and pitching at sea; SDINS transfer-aligned to the ship's GINS."""

    name = "ship-transfer-alignment"
    summary = (
        "Ship roll/pitch (Table 1), lever arm, Y flexure; SDINS 100 Hz + GINS 10 Hz "
        "(transfer alignment, Song et al.)"
    )
    streams = (StreamKind.IMU, StreamKind.MASTER_INS, StreamKind.TRUTH)
    Params = ShipTransferAlignmentParams

    def sensor_specs(self, params: ShipTransferAlignmentParams) -> SensorSpecs:
        return SensorSpecs({"imu": params.imu_model(), "master_ins": params.gins_model()},
                           sources={"imu": f"scenario {self.name} (Table 2)",
                                    "master_ins": f"scenario {self.name} (eqs. 20-22)"})

    def simulate(
        self, params: ShipTransferAlignmentParams, rng: np.random.Generator, seed: int,
        sensors: SensorSpecs,
    ) -> Recording:
        p = params
        gins, imu = sensors.require(MasterInsModel), sensors.require(ImuModel)
        n = int(round(p.duration * p.imu_rate))
        dt = 1.0 / p.imu_rate
        t = np.arange(n + 1) * dt  # truth grid; IMU sample k covers (t[k-1], t[k]]
        m = int(math.floor(p.duration * gins.rate + 1e-9))
        if m < 1:
            raise ValueError(f"duration must hold at least two GINS samples at {gins.rate:g} Hz")
        t_gins = np.arange(m + 1) / gins.rate

        # random constants, always drawn in this order and number (paired runs across
        # parameter changes such as flexure on/off)
        roll_phase = rng.uniform(0.0, 2.0 * np.pi, len(p.roll_freq))
        pitch_phase = rng.uniform(0.0, 2.0 * np.pi, len(p.pitch_freq))
        lever_arm_error = rng.standard_normal(3) * p.lever_arm_sigma
        mounting_euler = rng.standard_normal(3) * p.mounting_sigma
        flexure_normals = rng.standard_normal((n + 1, 2))
        gins_errors = gins.draw(rng)
        imu_errors = imu.draw(rng)

        lever_arm_r = np.asarray(p.lever_arm_r, dtype=float)
        v_r_n = p.speed * np.array([math.cos(p.yaw), math.sin(p.yaw), 0.0])

        def ship(tt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            roll, roll_rate = harmonics(tt, p.roll_freq, p.roll_amp, roll_phase)
            pitch, pitch_rate = harmonics(tt, p.pitch_freq, p.pitch_amp, pitch_phase)
            euler = np.column_stack([roll, pitch, np.full_like(tt, p.yaw)])
            omega_nr_r = np.column_stack(
                [roll_rate, pitch_rate * np.cos(roll), -pitch_rate * np.sin(roll)]
            )
            return euler, omega_nr_r

        # truth on the IMU grid
        euler_r, omega_nr_r = ship(t)
        q_nr = euler_to_quat(euler_r)
        C_nr = quat_to_dcm(q_nr)
        theta_f, theta_rate = flexure_state(n + 1, dt, p.flexure_sigma, p.flexure_zeta,
                                            p.flexure_wn, flexure_normals)
        q_mis = euler_to_quat(mounting_euler)
        q_flex = np.zeros((n + 1, 4))  # Ry(theta_f)
        q_flex[:, 0] = np.cos(0.5 * theta_f)
        q_flex[:, 2] = np.sin(0.5 * theta_f)
        q_rb = quat_mult(q_flex, q_mis)  # C_rb = Ry(theta_f) C_mis
        q_nb = quat_mult(q_nr, q_rb)  # C_nb = C_nr C_rb
        arm_r, arm_rate_r = flexed_lever_arm(lever_arm_r, theta_f, theta_rate)
        v_b_n = v_r_n + np.einsum(
            "kij,kj->ki", C_nr, np.cross(omega_nr_r, arm_r) + arm_rate_r
        )
        pos_r0 = np.array([p.lat, p.lon, p.height])
        pos_r = integrate_position(t, np.tile(v_r_n, (n + 1, 1)), pos_r0)
        pos_b = integrate_position(
            t, v_b_n, np.array(ned_offset_to_lla(p.lat, p.lon, p.height, C_nr[0] @ arm_r[0]))
        )

        # SDINS IMU (Table 2 errors on the ideal interval means)
        omega_ideal, f_ideal = imu_from_truth(t, pos_b, v_b_n, q_nb)
        meas = imu.measure(imu_errors, omega_ideal, f_ideal, dt, rng)

        # GINS at its own rate (its truth is analytic: no flexure, constant velocity)
        euler_g, _ = ship(t_gins)
        q_nr_g = euler_to_quat(euler_g)
        v_r_g = np.tile(v_r_n, (m + 1, 1))
        gins_cols = gins.measure(
            gins_errors, q_nr_g, v_r_g, integrate_position(t_gins, v_r_g, pos_r0), rng
        )

        lever_arm_nom = lever_arm_r + lever_arm_error
        truth = Stream(
            StreamKind.TRUTH,
            nanoseconds(t, T0_NS),
            {
                "pos": pos_b,
                "v_n": v_b_n,
                "q_nb": q_nb,
                "q_nr": q_nr,
                "pos_r": pos_r,
                "v_r_n": np.tile(v_r_n, (n + 1, 1)),
                "theta_f": theta_f,
                "theta_f_rate": theta_rate,
                "q_rb": q_rb,
                "misalignment_euler": quat_to_euler(q_rb),
            },
            frame_id="ned",
        )
        streams = {
            StreamKind.IMU: imu_stream(t, meas, T0_NS, "sdins_frd"),
            StreamKind.MASTER_INS: Stream(StreamKind.MASTER_INS, nanoseconds(t_gins, T0_NS),
                                          gins_cols, frame_id="ned"),
            StreamKind.TRUTH: truth,
        }
        true_errors = {
            "lever_arm_r": lever_arm_r,
            "lever_arm_error": lever_arm_error,
            "mounting_euler": mounting_euler,
            "q_mis": q_mis,
            "C_mis": quat_to_dcm(q_mis),
            "roll_phase": roll_phase,
            "pitch_phase": pitch_phase,
            "gins_tilt": gins_errors.tilt,
            "gins_synchro_bias": gins_errors.synchro_bias,
            "gins_vel_bias": gins_errors.vel_bias,
            **imu_errors.as_dict(),
        }
        metadata = self.metadata(
            p, seed,
            derived={"lever_arm_r_nom": lever_arm_nom},
            true_errors=true_errors,
            sensors=sensors,
            extra={
                "params_derived": {
                    "lever_arm_r_nom": "surveyed lever arm GINS -> SDINS in the ship frame [m]"
                                       " = lever_arm_r + the knowledge error; what the filter"
                                       " uses"
                },
                "truth_columns": {
                    "pos": "SDINS position [rad, rad, m]",
                    "v_n": "SDINS velocity V_B NED [m/s]",
                    "q_nb": "SDINS attitude b -> n",
                    "q_nr": "ship (GINS body) attitude r -> n",
                    "pos_r": "GINS position [rad, rad, m]",
                    "v_r_n": "GINS velocity V_R NED [m/s]",
                    "theta_f": "Y-axis flexure angle [rad]",
                    "theta_f_rate": "Y-axis flexure rate [rad/s]",
                    "q_rb": "true misalignment b -> r, Ry(theta_f) C_mis",
                    "misalignment_euler": "ZYX Euler angles of C_rb [rad]",
                },
            },
        )
        return Recording(streams, metadata, t0_ns=T0_NS)

