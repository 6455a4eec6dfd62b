"""Gyro-free attitude scenarios near runway 32R of Gimpo airport (RKSS).

The scenarios of docs/methods/vector-matching.md §3 (Choe & Park, "Improvement of Attitude
Determination Based on Specific Force Vector Matching", JKSAS 45(2), 2017, section III): an
accelerometer, a magnetometer and a GPS receiver, all at 4 Hz and synchronous.

``gimpo-accel-sweep`` (Figs. 1-3)
    At rest for 0 <= t <= rest, then a constant navigation-frame acceleration ``accel_g`` along
    N, E or D for rest < t <= duration (the sample at t = rest still reads rest). Attitude stays
    level and north-pointing, so body and navigation axes coincide.

``gimpo-accel-yaw`` (Figs. 4-5)
    At rest for 10 s; for 10 < t <= 15 s a body-axis acceleration of +accel_g along x (case
    ``x``) or y (case ``y``) while the yaw turns 0 -> +90 deg at a constant rate; coasting at
    constant velocity for 15 < t <= 20 s; -accel_g along the same body axis while the yaw turns
    back to 0 for 20 < t <= 25 s; at rest to 30 s. The vehicle slides: the body acceleration
    has no centripetal term, so it ends at rest, v(25 s) = 0.

Truth
    Level body, yaw psi(t) piecewise linear; body acceleration a_b piecewise constant
    (:class:`Segment`, each active on ``(start, end]``). Velocity and tangent-plane displacement
    are integrated in closed form (:func:`segment_truth`); the position is the displacement
    mapped exactly through ECEF from the site. The specific force follows the rotating WGS84
    earth::

        f_n = a_n + (2 w_ie_n + w_en_n) x v_n - g_n(lat, h),   f_b = C_bn f_n

    with normal gravity at the current position. The Coriolis and transport terms (below
    1 mg here) and the gravity change with height are ignored by the filter, as in the paper.
    All sensors sample the instantaneous truth at t_k = k / rate (§3.1, "sample meaning"), so
    f_b is evaluated analytically at the sample times rather than as interval means.

Sensors (§3.1, paper Table 1; 1-sigma Gaussian draws per run)
    Accelerometer: :class:`navreplay.sensors.imu.ImuModel` (scale factor and initial bias as
    random constants per axis, Gauss-Markov bias instability, white noise). The model's noise is
    specified as a density N of interval means (per-sample sigma N / sqrt(dt)); the method's
    instantaneous samples with Nyquist bandwidth have sigma ``N_table sqrt(rate / 2)``, so the
    model gets the equivalent density ``N_table / sqrt(2)`` (:meth:`GimpoParams.imu_model`).
    Only the accelerometer is written (the IMU stream has no ``omega_ib_b`` column).
    Magnetometer: :class:`navreplay.sensors.magnetometer.MagnetometerModel` (scale factor, hard
    iron bias, white noise of sigma ``N sqrt(rate / 2)``) on the earth field of the World
    Magnetic Model at the site and date (:func:`navreplay.sensors.magnetometer.earth_field_n`;
    WMM2015 at 2017.0 by default, within 50 nT of the IGRF 2017.0 value of §3.1,
    :data:`IGRF_FIELD_N`).
    The field is a constant vector over the few hundred metres travelled.
    GPS velocity: :class:`navreplay.sensors.gps.GpsModel`, white noise per NED axis, no latency;
    none inside the outages of ``gps_outages`` (recorded in ``extra["gnss_outages"]``).

Metadata
    ``true_errors``: the drawn accelerometer and magnetometer errors; the truth stream carries
    the total accelerometer bias over time. ``extra``: the site, the date, the field model and
    the reference field ``earth_field_n`` [T] (what a filter uses as h_n), the gravity at the
    site. ``initial_nav``: the site position and zero velocity (no attitude: the filter
    initialises itself).

Fast path
    :func:`simulate_runs` produces the sensor arrays of many seeds at once (the truth once, the
    sensor errors per seed with the same calls as :meth:`GimpoScenario.simulate`), for Monte
    Carlo campaigns that skip the stream containers.

Examples
--------
>>> from navreplay.sim.scenario import simulate
>>> rec = simulate("gimpo-accel-sweep", {"axis": "D", "accel_g": "1.0"}, seed=3)
>>> len(rec["imu"]), sorted(rec["imu"].columns)
(41, ['f_b'])
"""

from __future__ import annotations

import dataclasses
import datetime
import enum
import math
from collections.abc import Sequence
from typing import NamedTuple, cast

import numpy as np

from navreplay.core.outages import OUTAGES_KEY
from navreplay.core.params import check_nonnegative, check_positive
from navreplay.core.streams import Recording, Stream, StreamKind, nanoseconds
from navreplay.core.units import DEG, G0, GAUSS, MICRO_G_PER_SQRT_HZ, MILLI_G
from navreplay.geo.earth import gravity, gravity_n, ned_offset_to_lla, omega_en_n, omega_ie_n
from navreplay.geo.rotations import euler_to_quat
from navreplay.sensors.gps import (
    GpsModel,
    check_outages,
    outage_mask,
    outages_extra,
)
from navreplay.sensors.imu import ImuErrors, ImuModel
from navreplay.sensors.magnetometer import (
    MagnetometerErrors,
    MagnetometerModel,
    WmmEpoch,
    decimal_year,
    earth_field_n,
)
from navreplay.sensors.noise import nyquist_sample_sigma
from navreplay.sensors.specs import SensorSpecs
from navreplay.sim.scenario import Scenario, register_scenario
from navreplay.sim.trajectory import parse_utc, utc_ns

SITE_NAME = "Gimpo airport (RKSS), near runway 32R"
IGRF_FIELD_N = (29467e-9, -4330e-9, 41593e-9)
"""The field at the site from IGRF 2017.0 (docs/methods/vector-matching.md §3.1) [T]: a
cross-check only."""
YAW_WINDOW = 5.0
"""Length of each yaw window of the yaw scenario [s]."""
YAW_RATE = (math.pi / 2) / YAW_WINDOW
"""Yaw rate during the turns: 90 deg in 5 s = pi/10 rad/s."""


class Axis(enum.StrEnum):
    """Navigation axis of the sweep acceleration."""

    N = "N"
    E = "E"
    D = "D"

    @classmethod
    def _missing_(cls, value: object) -> Axis | None:
        return cls.__members__.get(value.upper()) if isinstance(value, str) else None

    @property
    def column(self) -> int:
        """The column of the axis in a NED vector."""
        return "NED".index(self.value)


class BodyAxis(enum.StrEnum):
    """Body axis of the yaw-scenario acceleration (the case)."""

    X = "x"
    Y = "y"

    @classmethod
    def _missing_(cls, value: object) -> BodyAxis | None:
        return cls.__members__.get(value.upper()) if isinstance(value, str) else None

    @property
    def column(self) -> int:
        """The column of the body axis in a vector."""
        return "xy".index(self.value)


# --------------------------------------------------------------------------------------------
# parameters


@dataclasses.dataclass(frozen=True, kw_only=True)
class GimpoParams:
    """Site, timing and sensor errors shared by the Gimpo scenarios (SI; defaults of
    docs/methods/vector-matching.md §3.1)."""

    rate: float = 4.0
    """Rate of the accelerometer, magnetometer and GPS [Hz] (synchronous)."""
    lat: float = 37.55 * DEG
    """Site latitude [rad]."""
    lon: float = 126.80 * DEG
    """Site longitude [rad]."""
    height: float = 40.0
    """Site ellipsoidal height [m] (about 18 m above mean sea level plus the geoid)."""
    date: str = "2017-01-01"
    """UTC date (ISO 8601) of the recording start: the field-model epoch (2017.0: WMM2015)."""
    accel_scale_factor: float = 1e-3
    """Accelerometer scale-factor error, random constant per axis [-] (0.1 %)."""
    accel_bias: float = 2.0 * MILLI_G
    """Accelerometer initial bias, random constant per axis [m/s^2] (2 mg)."""
    accel_bias_instability: float = 0.04 * MILLI_G
    """Accelerometer bias instability, Gauss-Markov steady-state sigma [m/s^2] (0.04 mg)."""
    accel_bias_tau: float = 60.0
    """Correlation time of the Gauss-Markov bias [s]."""
    accel_noise_density: float = 80.0 * MICRO_G_PER_SQRT_HZ
    """Accelerometer white-noise density [(m/s^2)/sqrt(Hz)] (80 ug/sqrt(Hz))."""
    mag_scale_factor: float = 1e-3
    """Magnetometer scale-factor error, random constant per axis [-] (0.1 %)."""
    mag_bias: float = 0.003 * GAUSS
    """Magnetometer initial (hard-iron) bias, random constant per axis [T] (0.003 G)."""
    mag_noise_density: float = 100e-6 * GAUSS
    """Magnetometer white-noise density [T/sqrt(Hz)] (100 uG/sqrt(Hz))."""
    gps_vel_sigma: float = 0.05
    """GPS velocity white noise, 1-sigma per NED axis [m/s]."""
    gps_outages: tuple[tuple[float, float], ...] = ()
    """GNSS outages, (start, length) pairs [s]: no GPS velocity inside each (``-p
    gps_outages=6:2``; :func:`navreplay.sensors.gps.check_outages`)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "gps_outages", check_outages(
            self.gps_outages, getattr(self, "duration", math.inf)))
        check_positive(self, "rate", "accel_bias_tau")
        check_nonnegative(self, "accel_scale_factor", "accel_bias", "accel_bias_instability",
                          "accel_noise_density", "mag_scale_factor", "mag_bias",
                          "mag_noise_density", "gps_vel_sigma")
        if not abs(self.lat) < 89.0 * DEG:
            raise ValueError(f"lat must be within +-89 deg, got {self.lat!r} rad")
        WmmEpoch.for_year(self.decimal_year)  # raises outside the field models' years

    @property
    def start(self) -> datetime.datetime:
        """Recording start as a naive UTC date-time."""
        return parse_utc(self.date)

    @property
    def decimal_year(self) -> float:
        """Date of the recording start as a decimal year."""
        return decimal_year(self.start)

    @property
    def dt(self) -> float:
        """Sample interval [s]."""
        return 1.0 / self.rate

    def imu_model(self) -> ImuModel:
        """Accelerometer errors; the white noise as the equivalent interval-mean density."""
        return ImuModel(
            accel_bias=self.accel_bias,
            accel_bias_instability=self.accel_bias_instability,
            accel_bias_tau=self.accel_bias_tau,
            accel_scale_factor=self.accel_scale_factor,
            # sample_sigma(vrw, dt) = vrw / sqrt(dt) must equal N sqrt(rate / 2)
            accel_vrw=self.accel_noise_density / math.sqrt(2.0),
        )

    def mag_model(self) -> MagnetometerModel:
        """Magnetometer errors; white noise over the Nyquist band."""
        return MagnetometerModel(
            scale_factor=self.mag_scale_factor,
            bias=self.mag_bias,
            noise=nyquist_sample_sigma(self.mag_noise_density, self.dt),
            rate=self.rate,
        )

    def sensor_models(self) -> SensorModels:
        """The three error models."""
        return SensorModels(self.imu_model(), self.mag_model(), self.gps_model())

    def gps_model(self) -> GpsModel:
        """GPS velocity errors (the position fix is not recorded)."""
        return GpsModel(pos_sigma=0.0, vel_sigma=self.gps_vel_sigma, rate=self.rate)


def _check_window(p: GimpoParams, name: str, value: float) -> None:
    k = value * p.rate
    if not (math.isfinite(value) and value > 0 and abs(k - round(k)) < 1e-9):
        raise ValueError(f"{name} = {value!r} s must be a positive whole number of samples")


def _check_accel_g(p: GimpoAccelSweepParams | GimpoAccelYawParams) -> None:
    if not (math.isfinite(p.accel_g) and abs(p.accel_g) <= 10.0):
        raise ValueError(f"accel_g must be within +-10 g, got {p.accel_g!r}")


@dataclasses.dataclass(frozen=True, kw_only=True)
class GimpoAccelSweepParams(GimpoParams):
    """Parameters of ``gimpo-accel-sweep`` (SI; docs/methods/vector-matching.md §3.2)."""

    axis: Axis = Axis.N
    """Navigation axis of the acceleration: N, E or D."""
    accel_g: float = 0.5
    """Acceleration along the axis, in units of 1 g = 9.80665 m/s^2 (the paper's sweep:
    -1.5 .. +1.5)."""
    rest: float = 5.0
    """Time at rest before the acceleration starts [s]."""
    duration: float = 10.0
    """Length of the recording [s]; the acceleration lasts from ``rest`` to here."""

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "axis", Axis(self.axis))
        _check_accel_g(self)
        _check_window(self, "rest", self.rest)
        _check_window(self, "duration", self.duration)
        if not self.duration > self.rest:
            raise ValueError(f"duration ({self.duration} s) must exceed rest ({self.rest} s)")


@dataclasses.dataclass(frozen=True, kw_only=True)
class GimpoAccelYawParams(GimpoParams):
    """Parameters of ``gimpo-accel-yaw`` (SI; docs/methods/vector-matching.md §3.3)."""

    case: BodyAxis = BodyAxis.X
    """Body axis of the acceleration: x or y."""
    accel_g: float = 0.5
    """Magnitude A of the body acceleration, in units of 1 g = 9.80665 m/s^2."""
    duration: float = 30.0
    """Length of the recording [s], at least 25 s (the manoeuvre ends at 25 s)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "case", BodyAxis(self.case))
        _check_accel_g(self)
        _check_window(self, "duration", self.duration)
        if self.duration < 25.0:
            raise ValueError(f"duration must be at least 25 s, got {self.duration!r}")


# --------------------------------------------------------------------------------------------
# truth (pure functions)


@dataclasses.dataclass(frozen=True)
class Segment:
    """A time window ``(start, end]`` of constant yaw rate and constant body acceleration.

    The body stays level; ``a_b`` is the motion acceleration ``dv/dt`` resolved in the body
    frame [m/s^2]; ``yaw_rate`` [rad/s].
    """

    start: float
    end: float
    yaw_rate: float = 0.0
    a_b: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclasses.dataclass(frozen=True)
class Truth:
    """Truth at the sample times.

    t (N,) [s]; yaw (N,) [rad]; q_nb (N, 4); a_n, v_n (N, 3) [m/s^2, m/s]; d_n (N, 3)
    tangent-plane displacement from the site [m]; pos (N, 3) [rad, rad, m]; f_b (N, 3) specific
    force [m/s^2]; h_n (3,) earth field NED at the site [T].
    """

    t: np.ndarray
    yaw: np.ndarray
    q_nb: np.ndarray
    a_n: np.ndarray
    v_n: np.ndarray
    d_n: np.ndarray
    pos: np.ndarray
    f_b: np.ndarray
    h_n: np.ndarray


def _segment_state(
    psi0: float, v0: np.ndarray, d0: np.ndarray, seg: Segment, s: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Yaw, a_n, v_n, d_n at times s (..., since the segment start) from the start state."""
    w = float(seg.yaw_rate)
    ax, ay, az = (float(a) for a in seg.a_b)
    c0, s0 = math.cos(psi0), math.sin(psi0)
    psi = psi0 + w * s
    if w == 0.0:
        S1, C1, S2, C2 = s * c0, s * s0, 0.5 * s * s * c0, 0.5 * s * s * s0
    else:
        S1 = (np.sin(psi) - s0) / w  # int_0^s cos(psi)
        C1 = (c0 - np.cos(psi)) / w  # int_0^s sin(psi)
        S2 = (C1 - s * s0) / w  # int_0^s S1
        C2 = (s * c0 - S1) / w  # int_0^s C1
    a = np.stack([np.cos(psi) * ax - np.sin(psi) * ay, np.sin(psi) * ax + np.cos(psi) * ay,
                  np.full_like(s, az)], axis=-1)
    v = v0 + np.stack([S1 * ax - C1 * ay, C1 * ax + S1 * ay, s * az], axis=-1)
    d = d0 + v0 * s[..., None] + np.stack(
        [S2 * ax - C2 * ay, C2 * ax + S2 * ay, 0.5 * s * s * az], axis=-1)
    return psi, a, v, d


def segment_truth(
    segments: Sequence[Segment], t: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Yaw, acceleration, velocity and displacement of a level body, in closed form.

    Starts at rest at yaw 0 before the first segment; between and after segments the body keeps
    its yaw and velocity. With ``psi = psi0 + w s`` over a segment (s = time since its start)
    and ``a_n = Rz(psi) a_b``::

        v_n(s) = v0 + [[S1, -C1], [C1, S1]] a_b_h,     S1 = int cos psi, C1 = int sin psi
        d_n(s) = d0 + v0 s + [[S2, -C2], [C2, S2]] a_b_h    (S2, C2 the second integrals)

    and the vertical channel integrates a_b_z directly.

    Parameters
    ----------
    segments : sequence of Segment
        Non-overlapping, in time order.
    t : ndarray, shape (N,)
        Sample times [s].

    Returns
    -------
    yaw : ndarray, shape (N,)
        [rad].
    a_n, v_n, d_n : ndarray, shape (N, 3)
        [m/s^2], [m/s], [m] (NED).

    Examples
    --------
    Case x of the yaw scenario ends at rest:

    >>> import numpy as np
    >>> A, w = 0.5 * 9.80665, np.pi / 10
    >>> segs = [Segment(10, 15, w, (A, 0, 0)), Segment(20, 25, -w, (-A, 0, 0))]
    >>> _, _, v, _ = segment_truth(segs, np.array([17.0, 25.0]))
    >>> np.round(v / (A / w), 12).tolist()
    [[1.0, 1.0, 0.0], [0.0, 0.0, 0.0]]
    """
    t = np.asarray(t, dtype=float)
    n = t.shape[0]
    yaw = np.zeros(n)
    a_n = np.zeros((n, 3))
    v_n = np.zeros((n, 3))
    d_n = np.zeros((n, 3))
    psi0, v0, d0 = 0.0, np.zeros(3), np.zeros(3)
    t_last = 0.0  # before the first segment v0 = 0: the coast start does not matter

    def coast(mask: np.ndarray, since: float, psi: float, v: np.ndarray, d: np.ndarray) -> None:
        yaw[mask] = psi
        v_n[mask] = v
        d_n[mask] = d + v * (t[mask] - since)[:, None]

    first = True
    for seg in segments:
        if not seg.end > seg.start or (not first and seg.start < t_last):
            raise ValueError(f"segments must be ordered and non-empty, got {seg}")
        coast((t <= seg.start) if first else (t > t_last) & (t <= seg.start),
              t_last, psi0, v0, d0)
        if not first:
            d0 = d0 + v0 * (seg.start - t_last)  # coasted since the previous segment
        inside = (t > seg.start) & (t <= seg.end)
        yaw[inside], a_n[inside], v_n[inside], d_n[inside] = _segment_state(
            psi0, v0, d0, seg, t[inside] - seg.start)
        psi_e, _, v_e, d_e = _segment_state(psi0, v0, d0, seg, np.array([seg.end - seg.start]))
        psi0, v0, d0, t_last = float(psi_e[0]), v_e[0], d_e[0], seg.end
        first = False
    coast((t > t_last) if not first else np.ones(n, bool), t_last, psi0, v0, d0)
    return yaw, a_n, v_n, d_n


def truth_from_segments(
    p: GimpoParams, segments: Sequence[Segment], duration: float
) -> Truth:
    """Truth at the sensor times ``k / rate``, k = 0..duration*rate, with the specific force.

    Parameters
    ----------
    p : GimpoParams
    segments : sequence of Segment
    duration : float
        [s].

    Returns
    -------
    Truth
    """
    n = round(duration * p.rate) + 1
    t = np.arange(n) / p.rate
    yaw, a_n, v_n, d_n = segment_truth(segments, t)
    lat, lon, h = ned_offset_to_lla(p.lat, p.lon, p.height, d_n)
    pos = np.stack([lat, lon, h], axis=-1)
    w_in = 2.0 * omega_ie_n(lat) + omega_en_n(lat, h, v_n)
    f_n = a_n + np.cross(w_in, v_n) - gravity_n(lat, h)
    # level body: C_bn = Rz(yaw)^T
    c, s = np.cos(yaw), np.sin(yaw)
    f_b = np.stack([c * f_n[:, 0] + s * f_n[:, 1], -s * f_n[:, 0] + c * f_n[:, 1], f_n[:, 2]],
                   axis=-1)
    q_nb = euler_to_quat(np.stack([np.zeros(n), np.zeros(n), yaw], axis=-1))
    h_n = earth_field_n(p.lat, p.lon, p.height, p.decimal_year)
    return Truth(t=t, yaw=yaw, q_nb=q_nb, a_n=a_n, v_n=v_n, d_n=d_n, pos=pos, f_b=f_b, h_n=h_n)


def sweep_segments(p: GimpoAccelSweepParams) -> list[Segment]:
    """Rest, then ``accel_g`` along the navigation axis (= body axis: yaw stays 0)."""
    a_b = [0.0, 0.0, 0.0]
    a_b[p.axis.column] = p.accel_g * G0
    return [Segment(p.rest, p.duration, 0.0, (a_b[0], a_b[1], a_b[2]))]


def yaw_segments(p: GimpoAccelYawParams) -> list[Segment]:
    """+A along the body axis while turning +90 deg; coast; -A while turning back."""
    a_b = [0.0, 0.0, 0.0]
    a_b[p.case.column] = p.accel_g * G0
    minus = (-a_b[0], -a_b[1], -a_b[2])
    return [
        Segment(10.0, 10.0 + YAW_WINDOW, YAW_RATE, (a_b[0], a_b[1], a_b[2])),
        Segment(20.0, 20.0 + YAW_WINDOW, -YAW_RATE, minus),
    ]


# --------------------------------------------------------------------------------------------
# sensors


class SensorModels(NamedTuple):
    """The error models of one parameter set (built once, used for every run)."""

    imu: ImuModel
    mag: MagnetometerModel
    gps: GpsModel


@dataclasses.dataclass
class SensorData:
    """Measured samples of one or many runs at the truth times; leading run axis optional.

    f_b (..., N, 3) [m/s^2]; m_b (..., N, 3) [T]; v_n, vel_sigma (..., N, 3) [m/s];
    accel_bias (..., N, 3) true total accelerometer bias [m/s^2]; errors: the drawn random
    constants (one run) or a list of them.
    """

    f_b: np.ndarray
    m_b: np.ndarray
    v_n: np.ndarray
    vel_sigma: np.ndarray
    accel_bias: np.ndarray
    errors: tuple[ImuErrors, MagnetometerErrors] | list[tuple[ImuErrors, MagnetometerErrors]]


def true_errors(imu_errors: ImuErrors, mag_errors: MagnetometerErrors) -> dict:
    """``Metadata.true_errors`` of one run: accelerometer and magnetometer random constants."""
    out = {
        "accel_bias": imu_errors.accel_bias,
        "accel_scale_factor": imu_errors.accel_scale_factor,
        "accel_misalignment": imu_errors.accel_misalignment,
    }
    out.update({f"mag_{k}": v for k, v in mag_errors.as_dict().items()})
    return out


def measure(
    models: SensorModels, dt: float, truth: Truth, rng: np.random.Generator
) -> SensorData:
    """Draw one run's sensor errors and apply them to the truth (the order of draws is fixed).

    Parameters
    ----------
    models : SensorModels
        From :meth:`GimpoParams.sensor_models`.
    dt : float
        Sample interval [s].
    truth : Truth
    rng : numpy.random.Generator

    Returns
    -------
    SensorData
        Without a run axis.
    """
    imu_errors = models.imu.draw(rng)
    mag_errors = models.mag.draw(rng)
    gps_errors = models.gps.draw(rng)
    n = truth.t.shape[0]
    imu_meas = models.imu.measure(imu_errors, np.zeros((n, 3)), truth.f_b, dt, rng)
    m_b = models.mag.measure(mag_errors, truth.q_nb, truth.h_n, rng)["m_b"]
    gps_meas = models.gps.measure(gps_errors, truth.pos, truth.v_n, rng)
    return SensorData(
        f_b=imu_meas.f_b,
        m_b=m_b,
        v_n=gps_meas.v_n,
        vel_sigma=gps_meas.vel_sigma,
        accel_bias=imu_meas.accel_bias[1:],
        errors=(imu_errors, mag_errors),
    )


def simulate_runs(p: GimpoParams, truth: Truth, seeds: Sequence[int],
                  models: SensorModels | None = None) -> SensorData:
    """Sensor data of many runs, stacked on a leading run axis.

    Run i is identical to the streams of ``simulate(scenario, values, seeds[i])``: the same
    generator seeding and the same calls as :meth:`GimpoScenario.simulate` (without GNSS
    outages: the stacked runs keep every epoch, so ``p.gps_outages`` must be empty).

    Parameters
    ----------
    p : GimpoParams
    truth : Truth
        From the scenario's :meth:`GimpoScenario.truth` (computed once for all runs).
    seeds : sequence of int
    models : SensorModels, optional
        The sensors (default: ``p.sensor_models()``).

    Returns
    -------
    SensorData
        Arrays (B, N, 3); ``errors`` a list of B pairs.
    """
    if p.gps_outages:
        raise ValueError("simulate_runs stacks runs of every epoch: GNSS outages "
                         f"({p.gps_outages}) need the scenario's own simulate")
    models = models or p.sensor_models()
    runs = [measure(models, p.dt, truth, np.random.default_rng(s)) for s in seeds]
    return SensorData(
        f_b=np.stack([r.f_b for r in runs]),
        m_b=np.stack([r.m_b for r in runs]),
        v_n=np.stack([r.v_n for r in runs]),
        vel_sigma=np.stack([r.vel_sigma for r in runs]),
        accel_bias=np.stack([r.accel_bias for r in runs]),
        errors=[cast(tuple[ImuErrors, MagnetometerErrors], r.errors) for r in runs],
    )


# --------------------------------------------------------------------------------------------
# scenarios


class GimpoScenario(Scenario):
    """Common recording builder of the Gimpo scenarios; subclasses give the segments."""

    streams = (StreamKind.IMU, StreamKind.MAG, StreamKind.GPS_VEL, StreamKind.TRUTH)

    def segments(self, p) -> list[Segment]:  # pragma: no cover - abstract
        raise NotImplementedError

    def truth(self, p) -> Truth:
        """The truth of parameters ``p`` at the sensor times."""
        return truth_from_segments(p, self.segments(p), p.duration)

    def sensor_specs(self, params: GimpoParams) -> SensorSpecs:
        models = params.sensor_models()
        source = f"scenario {self.name}"
        return SensorSpecs(models._asdict(), sources=dict.fromkeys(models._fields, source))

    def simulate(self, params, rng: np.random.Generator, seed: int,
                 sensors: SensorSpecs) -> Recording:
        p = params
        for kind in ("mag", "gps"):
            if sensors.get(kind).rate != p.rate:
                raise ValueError(f"the {kind} rate of gimpo recordings is the scenario's rate "
                                 f"({p.rate:g} Hz), got {sensors.get(kind).rate:g} Hz")
        truth = self.truth(p)
        data = measure(SensorModels(sensors.require(ImuModel), sensors.require(MagnetometerModel),
                                    sensors.require(GpsModel)), p.dt, truth, rng)
        t0_ns = utc_ns(p.start)
        t_ns = nanoseconds(truth.t, t0_ns)
        up = ~outage_mask(truth.t, p.gps_outages)  # epochs with a GNSS solution
        streams = {
            StreamKind.IMU: Stream(StreamKind.IMU, t_ns, {"f_b": data.f_b}, frame_id="body_frd"),
            StreamKind.MAG: Stream(StreamKind.MAG, t_ns, {"m_b": data.m_b}, frame_id="body_frd"),
            StreamKind.GPS_VEL: Stream(
                StreamKind.GPS_VEL, t_ns[up], {"v_n": data.v_n[up],
                                               "vel_sigma": data.vel_sigma[up]},
                frame_id="ned",
            ),
            StreamKind.TRUTH: Stream(
                StreamKind.TRUTH,
                t_ns,
                {
                    "pos": truth.pos,
                    "v_n": truth.v_n,
                    "q_nb": truth.q_nb,
                    "a_n": truth.a_n,
                    "f_b": truth.f_b,
                    "accel_bias": data.accel_bias,
                },
                frame_id="ned",
            ),
        }
        g_site = float(gravity(p.lat, p.height))
        metadata = self.metadata(
            p, seed,
            true_errors=true_errors(*data.errors),
            sensors=sensors,
            initial_nav={
                "t_ns": int(t0_ns),
                "pos": [p.lat, p.lon, p.height],
                "v_n": [0.0, 0.0, 0.0],
            },
            extra={
                "site": {"name": SITE_NAME, "lat_deg": p.lat / DEG, "lon_deg": p.lon / DEG,
                         "height": p.height},
                "date": p.date,
                "decimal_year": p.decimal_year,
                "earth_field_model": str(WmmEpoch.for_year(p.decimal_year)),
                "earth_field_n": truth.h_n,
                "gravity": g_site,
                OUTAGES_KEY: outages_extra(p.gps_outages),
                "truth_columns": {
                    "pos": "position [rad, rad, m]",
                    "v_n": "velocity NED [m/s]",
                    "q_nb": "attitude b -> n",
                    "a_n": "motion acceleration dv_n/dt NED [m/s^2]",
                    "f_b": "true specific force, FRD [m/s^2]",
                    "accel_bias": "total accelerometer bias applied to the sample [m/s^2]",
                },
            },
        )
        return Recording(streams, metadata, t0_ns=int(t0_ns))


@register_scenario
class GimpoAccelSweep(GimpoScenario):
    """Constant acceleration along N, E or D after 5 s at rest (vector-matching Figs. 1-3)."""

    name = "gimpo-accel-sweep"
    summary = (
        "Gyro-free attitude: 5 s at rest, then 5 s of constant N/E/D acceleration near Gimpo "
        "(accelerometer, magnetometer, GPS velocity at 4 Hz)"
    )
    Params = GimpoAccelSweepParams

    def segments(self, p: GimpoAccelSweepParams) -> list[Segment]:
        return sweep_segments(p)


@register_scenario
class GimpoAccelYaw(GimpoScenario):
    """Body-axis acceleration with a 90 deg yaw turn and back (vector-matching Figs. 4-5)."""

    name = "gimpo-accel-yaw"
    summary = (
        "Gyro-free attitude: +-0.5 g along body x or y while yawing 90 deg and back, "
        "30 s near Gimpo (accelerometer, magnetometer, GPS velocity at 4 Hz)"
    )
    Params = GimpoAccelYawParams

    def segments(self, p: GimpoAccelYawParams) -> list[Segment]:
        return yaw_segments(p)
