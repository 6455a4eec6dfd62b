"""Underwater vehicle with a propeller-RPM speed log in a sea current.

The scenario of the RPM-aided INS, docs/methods/rpm-aided-ins.md §3 (section numbers below are
that document's; erratum E11 is in its §7).

``underwater-rpm``
    A deep-running vehicle (start 36.0 N, 130.0 E, 50 m deep, heading 000) runs the 480-s course
    of §3.2 (:data:`ROUTE`, linear ramps): a speed-up 12 -> 14 m/s, a 5 deg dive
    (depth 50 -> about 105 m), four 90 deg turns at 3 deg/s and four speed changes; about
    6.83 km through the water. The water moves with a constant horizontal current (speed
    ``current_speed``, direction ``current_direction_deg``, uniform on [0, 360) per run by
    default). Streams: imu (100 Hz), speed_log (``rpm``, 10 Hz), depth (1 Hz), truth.

Models
------
Truth (§3.2), with ``C_bv = exp([m x])`` and ``m = [0, m_y, m_z]``::

    C_nb = Rz(psi) Ry(theta)                       roll 0
    v_n  = C_nb (C_bv [u, 0, 0] + [0, s_y, s_z]) + v_c_n     ground velocity (sim.trajectory)
    s_y, s_z: sway and heave through the water, second-order Gauss-Markov, 1-sigma
              sway_heave_sigma (2 mm/s), time constant sway_heave_tau (0.15 s)
    (lat, lon, h) integrated from v_n, IMU = exact inverse of the strapdown mechanization

Sensors (1-sigma random constants per run, Tables 1 and 2 of the paper)::

    IMU      omega = (I + S_g + M_g) omega_ib_b + b_g + n_g      0.1 deg/h, 100 ppm, 5 arcsec,
             f     = (I + S_a + M_a) f_b + b_a + n_a              ARW 0.01 deg/sqrt(h);
                                                                  100 ug, 100 ppm, 5 arcsec,
                                                                  VRW 1 ug/sqrt(Hz) (erratum E11)
    RPM      rpm   = (1 + k) u / c_rpm + n_rpm                    k 2 %, m_y, m_z 0.1 deg,
                                                                  c_rpm 0.01 (m/s)/rpm, 5 rpm
    depth    d_meas = d + b_d + n_d                               0.1 m; b_d = 0 unless
                                                                  depth_error_source = sensor

Depth is positive down with the sea surface on the ellipsoid: ``d = -h``.

Initial solution (``metadata.initial_nav``), as an external alignment hands it over: the truth
at t = 0 plus errors drawn per run (Table 2): level attitude 1 mil as the RSS of both axes
(0.694 mrad per axis; 1 mil per axis with ``level_mil_per_axis``), azimuth 3 mil, velocity
0.1 m/s per axis, depth 2 m (the INS's initial depth error; with ``depth_error_source =
sensor`` a depth-sensor bias of the same sigma instead), horizontal position 0. Attitude
error sign: ``C_nb_hat = exp(-[phi x]) C_nb``. ``initial_nav["sigma"]`` holds the 1-sigma of
those draws (``pos_ned``, ``v_n``, ``phi``) for a filter's P0; the filter never sees the truth.

Metadata
--------
``true_errors``: ``imu`` (:class:`~navreplay.sensors.ImuErrors`), ``speed_log`` (k and m),
``depth`` (sensor bias), flat copies ``rpm_scale_factor`` (k [-]), ``rpm_misalignment``
(m = [0, m_y, m_z] [rad]), ``current_n`` (v_c, NED [m/s]), ``current_speed`` [m/s],
``current_direction`` [rad, clockwise from north, the direction the water flows to], and
``initial_nav`` (the realised initial errors, estimate minus truth: ``pos_ned`` [m], ``v_n``
[m/s], ``phi`` [rad]).
``extra``: ``site``, ``date``, ``rates`` [Hz], ``truth_columns``, ``path_length`` (the true 3-D
path length over the recording, the paper's distance travelled DT [m]).

Truth columns (at ``truth_rate``): ``pos``, ``v_n``, ``q_nb``, ``euler`` (roll, pitch, yaw),
``speed`` (u, water-relative speed along the RPM axis [m/s]), ``sway_heave`` (s_y, s_z
[m/s]), ``current_n`` [m/s],
``gyro_bias`` [rad/s], ``accel_bias`` [m/s^2] (the true total IMU biases).
``t0_ns`` is the scenario date (UTC) in UNIX nanoseconds; the streams start there.

Examples
--------
>>> from navreplay.sim.scenario import simulate
>>> rec = simulate("underwater-rpm", {"duration": 20.0}, seed=1)
>>> sorted(str(k) for k in rec.kinds())
['depth', 'imu', 'speed_log', 'truth']
>>> len(rec["imu"]), len(rec["speed_log"]), len(rec["depth"])
(2000, 201, 21)
"""

from __future__ import annotations

import dataclasses
import enum
import math
from typing import ClassVar

import numpy as np
import scipy.linalg
import scipy.signal

from navreplay.core.params import (
    check_divides,
    check_nonnegative,
    check_positive,
    check_whole_intervals,
)
from navreplay.core.streams import Recording, Stream, StreamKind, nanoseconds
from navreplay.core.units import (
    ARCSEC,
    DEG,
    DEG_PER_HOUR,
    DEG_PER_SQRT_HOUR,
    MICRO_G,
    MICRO_G_PER_SQRT_HZ,
    MIL,
    PPM,
)
from navreplay.sensors.depth import DepthModel
from navreplay.sensors.imu import ImuModel
from navreplay.sensors.specs import SensorSpecs
from navreplay.sensors.speed_log import SpeedLogModel
from navreplay.sim.scenario import (
    Scenario,
    check_sensor_rate,
    imu_stream,
    register_scenario,
    truth_stream,
)
from navreplay.sim.trajectory import (
    Channel,
    Manoeuvre,
    Ramp,
    Route,
    generate,
    initial_nav,
    parse_utc,
    sample_indices,
    time_grid,
    utc_ns,
)

ROUTE: tuple[tuple[float, float, Channel, float], ...] = (
    # (start [s], duration [s], channel, change [m/s or rad]), docs/methods/rpm-aided-ins.md §3.2
    (0.0, 10.0, Channel.SPEED, 2.0),             # u 12 -> 14 m/s
    (15.0, 5.0, Channel.PITCH, -5.0 * DEG),      # nose down: the dive
    (60.0, 5.0, Channel.PITCH, 5.0 * DEG),       # level again (depth about 105 m)
    (60.0, 30.0, Channel.HEADING, 90.0 * DEG),   # psi 000 -> 090 at +3 deg/s
    (120.0, 10.0, Channel.SPEED, 2.0),           # u 14 -> 16 m/s
    (180.0, 30.0, Channel.HEADING, -90.0 * DEG),  # psi 090 -> 000
    (240.0, 10.0, Channel.SPEED, -3.0),          # u 16 -> 13 m/s
    (300.0, 30.0, Channel.HEADING, 90.0 * DEG),  # psi 000 -> 090
    (360.0, 10.0, Channel.SPEED, 1.0),           # u 13 -> 14 m/s
    (420.0, 30.0, Channel.HEADING, -90.0 * DEG),  # psi 090 -> 000
)
"""The course of docs/methods/rpm-aided-ins.md §3.2; every change is a linear ramp."""

START_SPEED = 12.0
"""Water-relative speed at t = 0 [m/s]."""

_TRUTH_COLUMNS = {
    "pos": "true latitude [rad], longitude [rad], ellipsoidal height [m] (depth = -h)",
    "v_n": "true ground velocity NED [m/s]",
    "q_nb": "true attitude quaternion b->n, Hamilton, scalar first",
    "euler": "true roll, pitch, yaw (ZYX) [rad], yaw in [-pi, pi)",
    "speed": "true water-relative speed u along the RPM axis [m/s]",
    "sway_heave": "true sway and heave: velocity through the water along body y and z [m/s]",
    "current_n": "true sea-current velocity NED [m/s] (constant)",
    "gyro_bias": "true total gyro bias, FRD [rad/s]",
    "accel_bias": "true total accelerometer bias, FRD [m/s^2]",
    "gyro_bias_eff": "effective gyro bias: + (S + M) w_ie^b + K_g f_0^b, FRD [rad/s]",
    "accel_bias_eff": "effective accelerometer bias: + (S + M) f_0^b (gravity reaction),"
                      " FRD [m/s^2]",
}


class DepthErrorSource(enum.StrEnum):
    """What the paper's "depth bias 2 m" (Table 2) is drawn into (docs/methods/rpm-aided-ins.md
    §3.2)."""

    INS = "ins"
    """The initial depth error of the INS (default; the 24 states hold no sensor bias)."""
    SENSOR = "sensor"
    """A constant depth-sensor bias; the INS starts with the true depth."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class UnderwaterRpmParams:
    """Parameters of ``underwater-rpm`` (SI unless the name says otherwise;
    docs/methods/rpm-aided-ins.md §3)."""

    duration: float = 480.0
    """Length of the recording [s] (the course of :data:`ROUTE` ends at 480 s)."""
    lat_deg: float = 36.0
    """Start latitude [deg]."""
    lon_deg: float = 130.0
    """Start longitude [deg]."""
    depth: float = 50.0
    """Start depth [m], positive down (h = -depth)."""
    heading_deg: float = 0.0
    """Initial heading [deg]."""
    date: str = "2019-06-01T00:00:00"
    """Start date-time, ISO 8601, UTC: the recording's t0."""
    imu_rate: float = 100.0
    """IMU rate [Hz]."""
    speed_log_rate: float = 10.0
    """RPM speed-log rate [Hz]; must divide imu_rate."""
    depth_rate: float = 1.0
    """Depth-sensor rate [Hz]; must divide imu_rate."""
    truth_rate: float = 10.0
    """Rate of the truth stream [Hz]; must divide imu_rate."""
    # Table 1: IMU (1-sigma random constants per run)
    accel_bias: float = 100.0 * MICRO_G
    """Accelerometer bias [m/s^2] (100 ug)."""
    accel_scale_factor: float = 100.0 * PPM
    """Accelerometer scale-factor error [-] (100 ppm)."""
    accel_vrw: float = 1.0 * MICRO_G_PER_SQRT_HZ
    """Accelerometer velocity random walk [(m/s)/sqrt(s)] (1 ug/sqrt(Hz); Table 1 prints
    "1 ug/sqrt(hr)": erratum E11 in docs/methods/rpm-aided-ins.md)."""
    accel_misalignment: float = 5.0 * ARCSEC
    """Accelerometer misalignment, each of six off-diagonal terms [rad] (5 arcsec)."""
    gyro_bias: float = 0.1 * DEG_PER_HOUR
    """Gyro bias [rad/s] (0.1 deg/h)."""
    gyro_scale_factor: float = 100.0 * PPM
    """Gyro scale-factor error [-] (100 ppm)."""
    gyro_arw: float = 0.01 * DEG_PER_SQRT_HOUR
    """Gyro angle random walk [rad/sqrt(s)] (0.01 deg/sqrt(h))."""
    gyro_misalignment: float = 5.0 * ARCSEC
    """Gyro misalignment, each of six off-diagonal terms [rad] (5 arcsec)."""
    # Table 2: initial errors (1-sigma)
    init_level_error: float = 1.0 * MIL
    """Level attitude error [rad] (1 mil): the RSS of phi_N and phi_E, or per axis with
    ``level_mil_per_axis``."""
    level_mil_per_axis: bool = False
    """Read ``init_level_error`` per axis instead of as the RSS of both
    (docs/methods/rpm-aided-ins.md §3.2)."""
    init_azimuth_error: float = 3.0 * MIL
    """Azimuth error phi_D [rad] (3 mil)."""
    init_vel_error: float = 0.1
    """Velocity error per NED axis [m/s]."""
    init_depth_error: float = 2.0
    """The paper's "depth bias" [m]: drawn into ``depth_error_source``."""
    depth_error_source: DepthErrorSource = DepthErrorSource.INS
    """Whether the depth bias is the INS's initial depth error or a depth-sensor bias."""
    init_horizontal_error: float = 0.0
    """Initial horizontal position error per axis N, E [m] (0: launch point known)."""
    # RPM speed log
    rpm_scale_factor: float = 0.02
    """RPM scale-factor error k [-] (2 %)."""
    rpm_misalignment: float = 0.1 * DEG
    """RPM-axis misalignment m_y, m_z [rad] (0.1 deg)."""
    rpm_noise: float = 5.0
    """RPM white noise per sample [rev/min]."""
    speed_per_rpm: float = 0.01
    """Nominal propeller law c_rpm [(m/s)/(rev/min)]."""
    # sway and heave through the water
    sway_heave_sigma: float = 0.002
    """1-sigma of the vehicle's lateral (sway) and vertical (heave) velocity through the
    water, per body axis y and z [m/s]: ambient turbulence and the autopilot's rudder and
    hydroplane action (docs/methods/rpm-aided-ins.md §3.2). 0: the vehicle moves exactly
    along its RPM axis."""
    sway_heave_tau: float = 0.15
    """Time constant of the sway and heave (second-order Gauss-Markov, :func:`sway_heave`)
    [s]. At 0.15 s, samples 1 s apart are correlated by 0.01, so a filter updating at 1 Hz
    may treat them as white measurement noise."""
    # sea current
    current_speed: float = 0.25
    """Horizontal sea-current speed [m/s], constant in time and depth."""
    current_direction_deg: float | None = None
    """Direction the current flows to [deg clockwise from north]; None draws it uniformly on
    [0, 360) per run."""
    # depth sensor
    depth_noise: float = 0.1
    """Depth-sensor white noise per sample [m]."""

    def __post_init__(self) -> None:
        check_positive(self, "duration", "imu_rate", "speed_log_rate", "depth_rate",
                       "truth_rate", "speed_per_rpm")
        check_nonnegative(self, "depth", "accel_bias", "accel_scale_factor", "accel_vrw",
                          "accel_misalignment", "gyro_bias", "gyro_scale_factor", "gyro_arw",
                          "gyro_misalignment", "init_level_error", "init_azimuth_error",
                          "init_vel_error", "init_depth_error", "init_horizontal_error",
                          "rpm_scale_factor", "rpm_misalignment", "rpm_noise", "current_speed",
                          "depth_noise", "sway_heave_sigma")
        check_positive(self, "sway_heave_tau")
        check_whole_intervals(self, "duration", "imu_rate")
        for slow in ("speed_log_rate", "depth_rate", "truth_rate"):
            check_divides(self, "imu_rate", slow)
        if not -80.0 <= self.lat_deg <= 80.0:
            raise ValueError(f"lat_deg must be within [-80, 80], got {self.lat_deg!r}")
        for name in ("lon_deg", "heading_deg"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)!r}")
        if self.depth > 11_000.0:
            raise ValueError(f"depth must be <= 11000 m, got {self.depth!r}")
        if self.current_speed > 5.0:
            raise ValueError(f"current_speed must be <= 5 m/s, got {self.current_speed!r}")
        if self.current_direction_deg is not None and not math.isfinite(
                self.current_direction_deg):
            raise ValueError(
                f"current_direction_deg must be finite or None, got {self.current_direction_deg!r}")
        object.__setattr__(self, "depth_error_source", DepthErrorSource(self.depth_error_source))
        parse_utc(self.date)

    def level_sigma(self) -> float:
        """1-sigma of phi_N and of phi_E [rad]."""
        return self.init_level_error if self.level_mil_per_axis else (
            self.init_level_error / math.sqrt(2.0))

    def imu_model(self) -> ImuModel:
        """The Table 1 IMU error model."""
        return ImuModel(
            gyro_bias=self.gyro_bias, gyro_scale_factor=self.gyro_scale_factor,
            gyro_misalignment=self.gyro_misalignment, gyro_arw=self.gyro_arw,
            accel_bias=self.accel_bias, accel_scale_factor=self.accel_scale_factor,
            accel_misalignment=self.accel_misalignment, accel_vrw=self.accel_vrw,
        )


def route_manoeuvres() -> tuple[Manoeuvre, ...]:
    """The manoeuvres of :data:`ROUTE` (linear ramps)."""
    return tuple(
        Manoeuvre(channel=ch, start=start, duration=length, change=change, ramp=Ramp.LINEAR)
        for start, length, ch, change in ROUTE
    )


def sway_heave(n: int, rate: float, sigma: float, tau: float,
               rng: np.random.Generator) -> np.ndarray:
    """Sway and heave through the water, body FRD [m/s], shape (n, 3) (x is 0): per axis y
    and z, an independent stationary second-order Gauss-Markov process, white noise through
    two first-order lags of time constant ``tau`` [s] (autocorrelation
    ``(1 + t/tau) e^(-t/tau)``), scaled to the 1-sigma ``sigma`` [m/s] and sampled exactly at
    ``rate`` [Hz]. Two lags, not one: the vehicle's mass bounds its sway acceleration (about
    ``sigma / tau`` RMS), where one lag would give a white acceleration::

        x_k+1 = a x_k + n_k,   s_k+1 = a s_k + (1 - a) x_k,   a = e^(-1/(rate tau))
    """
    out = np.zeros((n, 3))
    if sigma == 0.0 or n == 0:
        return out
    a = math.exp(-1.0 / (rate * tau))
    A = np.array([[a, 0.0], [1.0 - a, a]])  # state (x, s)
    B = np.array([1.0, 0.0])
    P = scipy.linalg.solve_discrete_lyapunov(A, np.outer(B, B))  # stationary, unit drive
    scale = sigma / math.sqrt(P[1, 1])
    L = np.linalg.cholesky(P)
    for axis in (1, 2):
        drive = rng.standard_normal(n)
        state = L @ rng.standard_normal(2)
        x = scipy.signal.lfilter([1.0], [1.0, -a], drive[:-1], zi=[a * state[0]])[0]
        x = np.r_[state[0], x]
        s = scipy.signal.lfilter([0.0, 1.0 - a], [1.0, -a], x, zi=[state[1]])[0]
        out[:, axis] = scale * s
    return out


def current_velocity(speed: float, direction: float) -> np.ndarray:
    """Horizontal current NED [m/s], shape (3,), flowing towards ``direction`` [rad, clockwise
    from north]."""
    return np.array([speed * math.cos(direction), speed * math.sin(direction), 0.0])


def path_length(t: np.ndarray, v_n: np.ndarray) -> float:
    """Length of the 3-D path ``integral |v_n| dt`` by the trapezoid rule [m]."""
    speed = np.linalg.norm(v_n, axis=1)
    return float(np.sum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t)))


@register_scenario
class UnderwaterRpm(Scenario):
    """Underwater vehicle, RPM speed log and depth sensor in a sea current (see the module)."""

    name: ClassVar[str] = "underwater-rpm"
    summary: ClassVar[str] = (
        "underwater vehicle, 480 s / 6.8 km with turns, speed changes and a dive in a sea"
        " current; IMU 100 Hz, RPM speed log 10 Hz, depth 1 Hz (Choi 2019)"
    )
    streams: ClassVar[tuple[StreamKind, ...]] = (
        StreamKind.IMU, StreamKind.SPEED_LOG, StreamKind.DEPTH, StreamKind.TRUTH,
    )
    Params: ClassVar[type] = UnderwaterRpmParams

    def sensor_specs(self, params: UnderwaterRpmParams) -> SensorSpecs:
        p = params
        sensor_bias = p.init_depth_error if p.depth_error_source is DepthErrorSource.SENSOR else 0.0
        source = f"scenario {self.name} (Table 1)"
        return SensorSpecs(
            {"imu": p.imu_model(),
             "speed_log": SpeedLogModel(
                 scale_factor=p.rpm_scale_factor, misalignment=p.rpm_misalignment,
                 noise=p.rpm_noise, speed_per_rpm=p.speed_per_rpm, rate=p.speed_log_rate),
             "depth": DepthModel(bias=sensor_bias, noise=p.depth_noise, rate=p.depth_rate)},
            sources={"imu": source, "speed_log": f"scenario {self.name}",
                     "depth": f"scenario {self.name}"},
        )

    def simulate(self, params: UnderwaterRpmParams, rng: np.random.Generator,
                 seed: int, sensors: SensorSpecs) -> Recording:
        p = params
        for kind in ("speed_log", "depth"):
            check_sensor_rate(kind, sensors.get(kind).rate, p.imu_rate)
        rng_imu, rng_log, rng_depth, rng_init, rng_current, rng_sway = rng.spawn(6)
        start = parse_utc(p.date)
        t0_ns = utc_ns(start)

        # random constants of the run
        if p.current_direction_deg is None:
            direction = float(rng_current.uniform(0.0, 2.0 * math.pi))
        else:
            direction = math.radians(p.current_direction_deg) % (2.0 * math.pi)
        v_c = current_velocity(p.current_speed, direction)
        log_model = sensors.require(SpeedLogModel)
        depth_model, imu_model = sensors.require(DepthModel), sensors.require(ImuModel)
        log_errors = log_model.draw(rng_log)
        depth_errors = depth_model.draw(rng_depth)
        imu_errors = imu_model.draw(rng_imu)

        # truth: C_nb = Rz Ry, v_n = C_nb C_bv [u, 0, 0] + v_c_n
        route = Route(
            lat=p.lat_deg * DEG, lon=p.lon_deg * DEG, h=-p.depth, heading=p.heading_deg * DEG,
            speed=START_SPEED, manoeuvres=route_manoeuvres(),
            velocity_misalignment=tuple(log_errors.misalignment), current_n=tuple(v_c),
        )
        n = time_grid(p.duration, p.imu_rate).size
        v_sway = sway_heave(n, p.imu_rate, p.sway_heave_sigma, p.sway_heave_tau, rng_sway)
        traj = generate(route, p.duration, p.imu_rate, body_velocity=v_sway)
        assert traj.omega_ib_b is not None and traj.f_b is not None  # generate's ideal IMU
        imu_meas = imu_model.measure(imu_errors, traj.omega_ib_b, traj.f_b, 1.0 / p.imu_rate,
                                     rng_imu)

        li = sample_indices(n, p.imu_rate, log_model.rate)
        rpm_cols = log_model.measure(log_errors, traj.speed[li], rng_log)
        di = sample_indices(n, p.imu_rate, depth_model.rate)
        depth_cols = depth_model.measure(depth_errors, -traj.pos[di, 2], rng_depth)
        ti = sample_indices(n, p.imu_rate, p.truth_rate)

        depth_sigma = p.init_depth_error if p.depth_error_source is DepthErrorSource.INS else 0.0
        level = p.level_sigma()
        nav0, init_errors = initial_nav(
            traj, t0_ns, rng_init,
            pos_sigma_ned=(p.init_horizontal_error, p.init_horizontal_error, depth_sigma),
            vel_sigma_n=(p.init_vel_error,) * 3,
            phi_sigma=(level, level, p.init_azimuth_error),
        )
        streams = {
            StreamKind.IMU: imu_stream(traj.t, imu_meas, t0_ns),
            StreamKind.SPEED_LOG: Stream(StreamKind.SPEED_LOG, nanoseconds(traj.t[li], t0_ns),
                                         rpm_cols, "rpm_log"),
            StreamKind.DEPTH: Stream(StreamKind.DEPTH, nanoseconds(traj.t[di], t0_ns),
                                     depth_cols, "depth"),
            StreamKind.TRUTH: truth_stream(traj, imu_meas, t0_ns, ti, imu_errors,
                                           speed=traj.speed, sway_heave=v_sway[:, 1:],
                                           current_n=np.broadcast_to(v_c, (n, 3))),
        }
        meta = self.metadata(
            p, seed,
            true_errors={
                "imu": imu_errors.as_dict(),
                "speed_log": log_errors.as_dict(),
                "depth": depth_errors.as_dict(),
                "rpm_scale_factor": log_errors.scale_factor,
                "rpm_misalignment": log_errors.misalignment,
                "current_n": v_c,
                "current_speed": p.current_speed,
                "current_direction": direction,
                "initial_nav": init_errors,
            },
            initial_nav=nav0,
            sensors=sensors,
            extra={
                "site": {"lat_deg": p.lat_deg, "lon_deg": p.lon_deg, "depth": p.depth},
                "date": start.isoformat(),
                "rates": {"imu": p.imu_rate, "speed_log": log_model.rate,
                          "depth": depth_model.rate, "truth": p.truth_rate},
                "truth_columns": _TRUTH_COLUMNS,
                "path_length": path_length(traj.t, traj.v_n),
            },
        )
        return Recording(streams=streams, metadata=meta, t0_ns=t0_ns)
