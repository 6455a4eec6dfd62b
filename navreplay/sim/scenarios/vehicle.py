"""Land-vehicle scenarios: a drive with GPS and magnetometer aiding, and a stationary IMU.

``vehicle-drive``
    A deterministic route (it does not depend on the seed) made of 150-s blocks repeated up to
    the duration: stand still 10 s, accelerate to the cruise speed, turn right 90 deg, climb a
    2 deg slope, speed up by a third, turn left 45 deg while going down a 1.5 deg slope, slow
    down, turn right 45 deg and stop.
    Each block turns the vehicle by +90 deg, so four blocks drive a loop. Turns are flat (car)
    or coordinated (``turn_mode``, aircraft-like: the vehicle banks by ``atan(u psi_dot / g)``
    and its load factor rises to ``1 / cos(bank)``); a coordinated turn banks at most
    ``max_bank_deg`` and is flown longer where it would bank more
    (:func:`navreplay.sim.trajectory.bank_limited`). ``gps_outages`` drops every GNSS fix and
    velocity inside the given spans (:func:`navreplay.sensors.gps.check_outages`). Streams: imu,
    gps, gps_vel, mag, truth.

``stationary``
    A level IMU at rest at a chosen site and heading, for free-inertial tests, gyro-compassing
    and the Schuler oscillation from an initial tilt. Streams: imu, truth.

Both record the truth at the IMU rate with the extra columns ``euler`` (roll, pitch, yaw [rad]),
``gyro_bias`` [rad/s] and ``accel_bias`` [m/s^2] (the true total IMU biases, including the
Gauss-Markov instability, at each truth sample; see :class:`navreplay.sensors.ImuMeasurement`),
the effective biases ``gyro_bias_eff`` and ``accel_bias_eff`` of the IMU at rest in the level
attitude of the current heading (:func:`navreplay.sensors.imu.effective_biases`: a land
vehicle's or a coordinated turn's specific force stays along the body z axis), and for the drive
``gps_pos_gm``, the Gauss-Markov part of the GNSS position error; all described in
``metadata.extra["truth_columns"]``.

Sensors
    ``sensor_specs``: the IMU of grade ``imu_grade``; for the drive the GNSS and magnetometer
    of the ``gps_*`` and ``mag_*`` parameters. ``[sensors.KIND]`` tables may replace any field
    (:func:`navreplay.sim.scenario.scenario_inputs`); a GNSS or magnetometer rate must still
    divide ``imu_rate``.

Metadata
    ``true_errors``: ``imu`` (:class:`~navreplay.sensors.ImuErrors`), ``gps``, ``mag``, and
    ``initial_nav`` (the realised initial errors, estimate minus truth: ``pos_ned`` [m],
    ``v_n`` [m/s], ``phi`` [rad] with ``C_nb_hat = exp(-[phi x]) C_nb``).
    ``initial_nav``: truth at t0 plus those errors, with ``sigma`` = {``pos_ned``, ``v_n``,
    ``phi``} (1-sigma per axis) for a filter's P0. ``extra``: ``site``, ``date``,
    ``decimal_year``, ``rates`` [Hz], ``truth_columns``, and for the drive ``mag_field_n``
    [T, NED] (the WMM field at the start, used for every magnetometer sample), ``wmm`` and
    ``gnss_outages`` (``[[start, end], ...]`` [s], :data:`navreplay.core.outages.OUTAGES_KEY`).
``t0_ns`` is the scenario date (UTC) in UNIX nanoseconds; the streams start there.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar

import numpy as np

from navreplay.core.outages import OUTAGES_KEY
from navreplay.core.params import (
    check_divides,
    check_nonnegative,
    check_positive,
    check_whole_intervals,
)
from navreplay.core.streams import Recording, Stream, StreamKind, nanoseconds
from navreplay.core.units import DEG
from navreplay.sensors.gps import (
    GpsModel,
    check_outages,
    outage_mask,
    outages_extra,
)
from navreplay.sensors.imu import ImuErrors, ImuGrade, ImuMeasurement, ImuModel, imu_grade
from navreplay.sensors.magnetometer import (
    MagnetometerModel,
    WmmEpoch,
    decimal_year,
    earth_field_n,
)
from navreplay.sensors.specs import SensorSpecs
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
    Trajectory,
    TurnMode,
    bank_limited,
    generate,
    initial_nav,
    parse_utc,
    sample_indices,
    utc_ns,
)

_TRUTH_COLUMNS = {
    "pos": "true latitude [rad], longitude [rad], ellipsoidal height [m]",
    "v_n": "true ground velocity NED [m/s]",
    "q_nb": "true attitude quaternion b->n, Hamilton, scalar first",
    "euler": "true roll, pitch, yaw (ZYX) [rad], yaw in [-pi, pi)",
    "gyro_bias": "true total gyro bias (constant + Gauss-Markov + random walk), FRD [rad/s]",
    "accel_bias": "true total accelerometer bias, FRD [m/s^2]",
    "gyro_bias_eff": "effective gyro bias: + (S + M) w_ie^b + K_g f_0^b at rest in the level"
                     " attitude of the current heading, FRD [rad/s]",
    "accel_bias_eff": "effective accelerometer bias: + (S + M) f_0^b (gravity reaction, 1 g"
                      " along z: the level attitude of the current heading), FRD [m/s^2]",
}
_GNSS_TRUTH_COLUMNS = {
    "gps_pos_gm": "Gauss-Markov part of the GNSS position error N, E, D [m] (at the GNSS"
                  " epochs, also inside outages; linear between them)",
}


def _check_common(p: Any) -> None:
    """Validation shared by both scenarios' parameters."""
    check_positive(p, "duration", "imu_rate")
    check_whole_intervals(p, "duration", "imu_rate")
    if not -90.0 <= p.lat_deg <= 90.0:
        raise ValueError(f"lat_deg must be within [-90, 90], got {p.lat_deg!r}")
    parse_utc(p.date)
    check_nonnegative(p, "init_pos_sigma", "init_vel_sigma", "init_tilt_sigma",
                      "init_heading_sigma")


@dataclasses.dataclass(frozen=True, kw_only=True)
class VehicleDriveParams:
    """Parameters of ``vehicle-drive`` (SI unless the name says otherwise)."""

    duration: float = 600.0
    """Length of the recording [s]."""
    lat_deg: float = 37.55
    """Start latitude [deg]."""
    lon_deg: float = 126.80
    """Start longitude [deg]."""
    h: float = 40.0
    """Start height above the WGS84 ellipsoid [m]."""
    heading_deg: float = 0.0
    """Initial heading [deg]."""
    date: str = "2017-01-01T00:00:00"
    """Start date-time, ISO 8601, UTC: the recording's t0 and the magnetic-model epoch."""
    cruise_speed: float = 15.0
    """Cruise speed of the route [m/s]."""
    turn_mode: TurnMode = TurnMode.FLAT
    """Flat turns (car) or coordinated, banked turns (aircraft-like)."""
    max_bank_deg: float = 45.0
    """Largest bank of a coordinated turn [deg]: a turn that would bank more is flown over a
    longer time (the same heading change)."""
    imu_grade: ImuGrade = ImuGrade.TACTICAL
    """IMU error level (see :func:`navreplay.sensors.imu_grade`)."""
    imu_rate: float = 100.0
    """IMU and truth rate [Hz]."""
    gps_rate: float = 1.0
    """GPS fix and velocity rate [Hz]; must divide imu_rate."""
    gps_pos_sigma_h: float = 2.5
    """GPS white position noise, north and east [m]."""
    gps_pos_sigma_v: float = 5.0
    """GPS white position noise, down [m]."""
    gps_pos_gm_sigma: float = 0.0
    """GPS Gauss-Markov position error, each axis [m] (0: white noise only)."""
    gps_pos_gm_tau: float = 300.0
    """GPS Gauss-Markov correlation time [s]."""
    gps_vel_sigma: float = 0.05
    """GPS velocity noise per axis [m/s]."""
    gps_outages: tuple[tuple[float, float], ...] = ()
    """GNSS outages, (start, length) pairs [s]: no fix and no velocity inside each (``-p
    gps_outages=120:30,300:60``; TOML ``[[120, 30], [300, 60]]``)."""
    mag_rate: float = 10.0
    """Magnetometer rate [Hz]; must divide imu_rate."""
    mag_noise: float = 100e-9
    """Magnetometer white noise per sample and axis [T]."""
    mag_bias: float = 300e-9
    """Magnetometer hard-iron bias, random constant per axis [T]."""
    mag_scale_factor: float = 0.005
    """Magnetometer scale-factor error, random constant per axis [-]."""
    init_pos_sigma: float = 3.0
    """Initial position error handed to filters, per N, E, D axis [m]."""
    init_vel_sigma: float = 0.05
    """Initial velocity error per axis [m/s]."""
    init_tilt_sigma: float = 2e-3
    """Initial level attitude error phi_N, phi_E [rad]."""
    init_heading_sigma: float = 2e-2
    """Initial heading error phi_D [rad]."""

    def __post_init__(self) -> None:
        _check_common(self)
        check_positive(self, "cruise_speed", "gps_rate", "mag_rate", "gps_pos_gm_tau")
        check_nonnegative(self, "gps_pos_sigma_h", "gps_pos_sigma_v", "gps_pos_gm_sigma",
                          "gps_vel_sigma", "mag_noise", "mag_bias", "mag_scale_factor")
        check_divides(self, "imu_rate", "gps_rate")
        check_divides(self, "imu_rate", "mag_rate")
        if not 0.0 < self.max_bank_deg < 90.0:
            raise ValueError(f"max_bank_deg must be within (0, 90), got {self.max_bank_deg!r}")
        object.__setattr__(self, "gps_outages", check_outages(self.gps_outages, self.duration))
        try:
            WmmEpoch.for_year(decimal_year(parse_utc(self.date)))
        except ValueError as e:
            raise ValueError(f"date {self.date!r}: {e}") from None


def drive_manoeuvres(duration: float, cruise_speed: float) -> tuple[Manoeuvre, ...]:
    """The ``vehicle-drive`` route: 150-s blocks repeated while they start before ``duration``.

    Parameters
    ----------
    duration : float
        [s].
    cruise_speed : float
        [m/s].

    Returns
    -------
    tuple of Manoeuvre
    """
    v = cruise_speed
    # (start [s], duration [s], channel, change [m/s or rad]) within one block; all smooth ramps
    block = (
        (10.0, 15.0, Channel.SPEED, v),            # pull away
        (40.0, 16.0, Channel.HEADING, 90.0 * DEG),  # right turn
        (60.0, 6.0, Channel.PITCH, 2.0 * DEG),      # up a slope
        (72.0, 6.0, Channel.PITCH, -2.0 * DEG),     # level again
        (75.0, 10.0, Channel.SPEED, v / 3.0),       # speed up
        (90.0, 12.0, Channel.HEADING, -45.0 * DEG),  # left turn
        (92.0, 6.0, Channel.PITCH, -1.5 * DEG),     # down a slope
        (104.0, 6.0, Channel.PITCH, 1.5 * DEG),     # level again
        (110.0, 10.0, Channel.SPEED, -v / 3.0),     # slow down
        (115.0, 10.0, Channel.HEADING, 45.0 * DEG),  # right turn
        (130.0, 15.0, Channel.SPEED, -v),           # stop (stand still 145-160 s)
    )
    period = 150.0
    out = []
    k = 0
    while k * period < duration:
        for start, length, channel, change in block:
            t = k * period + start
            if t < duration:
                out.append(Manoeuvre(channel=channel, start=t, duration=length, change=change,
                                     ramp=Ramp.SMOOTH))
        k += 1
    return tuple(out)


def _imu(
    p: VehicleDriveParams | StationaryParams, model: ImuModel, route: Route,
    rng: np.random.Generator,
) -> tuple[Trajectory, ImuErrors, ImuMeasurement]:
    """Truth at the IMU rate and the IMU ``model`` on it."""
    traj = generate(route, p.duration, p.imu_rate)
    assert traj.omega_ib_b is not None and traj.f_b is not None  # generate's ideal IMU
    errors = model.draw(rng)
    return traj, errors, model.measure(errors, traj.omega_ib_b, traj.f_b, 1.0 / p.imu_rate, rng)


def _initial_nav(
    p: VehicleDriveParams | StationaryParams, traj: Trajectory, t0_ns: int,
    rng: np.random.Generator, phi_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> tuple[dict, dict]:
    """Initial solution and its realised errors from the ``init_*`` sigmas."""
    return initial_nav(
        traj, t0_ns, rng,
        pos_sigma_ned=(p.init_pos_sigma,) * 3,
        vel_sigma_n=(p.init_vel_sigma,) * 3,
        phi_sigma=(p.init_tilt_sigma, p.init_tilt_sigma, p.init_heading_sigma),
        phi_offset=phi_offset,
    )


def _site(p: Any) -> dict[str, float]:
    return {"lat_deg": p.lat_deg, "lon_deg": p.lon_deg, "h": p.h}


def _imu_specs(p: VehicleDriveParams | StationaryParams) -> SensorSpecs:
    return SensorSpecs({"imu": imu_grade(p.imu_grade)}, sources={"imu": f"grade {p.imu_grade}"})



@register_scenario
class VehicleDrive(Scenario):
    """Car-like drive with turns, slopes, speed changes and stops; IMU, GPS and magnetometer."""

    name: ClassVar[str] = "vehicle-drive"
    summary: ClassVar[str] = (
        "land vehicle: turns, slopes, stops; IMU 100 Hz, GPS fix + velocity 1 Hz, magnetometer"
        " 10 Hz (WMM field)"
    )
    streams: ClassVar[tuple[StreamKind, ...]] = (
        StreamKind.IMU, StreamKind.GPS, StreamKind.GPS_VEL, StreamKind.MAG, StreamKind.TRUTH,
    )
    Params: ClassVar[type] = VehicleDriveParams

    def sensor_specs(self, params: VehicleDriveParams) -> SensorSpecs:
        p = params
        gps = GpsModel(
            pos_sigma=(p.gps_pos_sigma_h, p.gps_pos_sigma_h, p.gps_pos_sigma_v),
            pos_gm_sigma=p.gps_pos_gm_sigma, pos_gm_tau=p.gps_pos_gm_tau,
            vel_sigma=p.gps_vel_sigma, rate=p.gps_rate,
        )
        mag = MagnetometerModel(
            scale_factor=p.mag_scale_factor, bias=p.mag_bias, noise=p.mag_noise, rate=p.mag_rate
        )
        return _imu_specs(p).with_model("gps", gps, f"scenario {self.name}").with_model(
            "mag", mag, f"scenario {self.name}")

    def simulate(self, params: VehicleDriveParams, rng: np.random.Generator, seed: int,
                 sensors: SensorSpecs) -> Recording:
        p = params
        gps_model, mag_model = sensors.require(GpsModel), sensors.require(MagnetometerModel)
        check_sensor_rate("gps", gps_model.rate, p.imu_rate)
        check_sensor_rate("mag", mag_model.rate, p.imu_rate)
        rng_imu, rng_gps, rng_mag, rng_init = rng.spawn(4)
        start = parse_utc(p.date)
        t0_ns = utc_ns(start)
        year = decimal_year(start)
        route = bank_limited(Route(
            lat=p.lat_deg * DEG, lon=p.lon_deg * DEG, h=p.h, heading=p.heading_deg * DEG,
            speed=0.0, manoeuvres=drive_manoeuvres(p.duration, p.cruise_speed),
            turn_mode=p.turn_mode,
        ), p.max_bank_deg * DEG)
        traj, imu_errors, imu_meas = _imu(p, sensors.require(ImuModel), route, rng_imu)
        n = traj.t.shape[0]

        gi = sample_indices(n, p.imu_rate, gps_model.rate)
        gps_errors = gps_model.draw(rng_gps)
        gps_meas = gps_model.measure(gps_errors, traj.pos[gi], traj.v_n[gi], rng_gps)
        gm_truth = np.column_stack([np.interp(traj.t, traj.t[gi], gps_meas.pos_gm_ned[:, k])
                                    for k in range(3)])
        up = ~outage_mask(traj.t[gi], p.gps_outages)  # the receiver's epochs with a solution
        t_gps = nanoseconds(traj.t[gi][up], t0_ns)
        fix = {k: v[up] for k, v in gps_meas.fix_columns().items()}
        vel = {k: v[up] for k, v in gps_meas.velocity_columns().items()}

        h_n = earth_field_n(route.lat, route.lon, route.h, year)
        mi = sample_indices(n, p.imu_rate, mag_model.rate)
        mag_errors = mag_model.draw(rng_mag)
        mag_cols = mag_model.measure(mag_errors, traj.q_nb[mi], h_n, rng_mag)

        nav0, init_errors = _initial_nav(p, traj, t0_ns, rng_init)
        streams = {
            StreamKind.IMU: imu_stream(traj.t, imu_meas, t0_ns),
            StreamKind.GPS: Stream(StreamKind.GPS, t_gps, fix, "wgs84"),
            StreamKind.GPS_VEL: Stream(StreamKind.GPS_VEL, t_gps, vel, "ned"),
            StreamKind.MAG: Stream(StreamKind.MAG, nanoseconds(traj.t[mi], t0_ns), mag_cols,
                                   "mag_frd"),
            StreamKind.TRUTH: truth_stream(traj, imu_meas, t0_ns, errors=imu_errors,
                                           level_biases=True, gps_pos_gm=gm_truth),
        }
        meta = self.metadata(
            p, seed,
            true_errors={
                "imu": imu_errors.as_dict(),
                "gps": gps_errors.as_dict(),
                "mag": mag_errors.as_dict(),
                "initial_nav": init_errors,
            },
            initial_nav=nav0,
            sensors=sensors,
            extra={
                "site": _site(p),
                "date": start.isoformat(),
                "decimal_year": year,
                "wmm": WmmEpoch.for_year(year).value,
                "mag_field_n": h_n,
                "rates": {"imu": p.imu_rate, "gps": gps_model.rate, "gps_vel": gps_model.rate,
                          "mag": mag_model.rate, "truth": p.imu_rate},
                "truth_columns": {**_TRUTH_COLUMNS, **_GNSS_TRUTH_COLUMNS},
                OUTAGES_KEY: outages_extra(p.gps_outages),
            },
        )
        return Recording(streams=streams, metadata=meta, t0_ns=t0_ns)


@dataclasses.dataclass(frozen=True, kw_only=True)
class StationaryParams:
    """Parameters of ``stationary`` (SI unless the name says otherwise)."""

    duration: float = 600.0
    """Length of the recording [s]."""
    lat_deg: float = 37.0
    """Latitude [deg]."""
    lon_deg: float = 127.0
    """Longitude [deg]."""
    h: float = 0.0
    """Height above the WGS84 ellipsoid [m]."""
    heading_deg: float = 0.0
    """Heading [deg]; roll and pitch are 0."""
    date: str = "2017-01-01T00:00:00"
    """Start date-time, ISO 8601, UTC: the recording's t0."""
    imu_grade: ImuGrade = ImuGrade.TACTICAL
    """IMU error level (see :func:`navreplay.sensors.imu_grade`)."""
    imu_rate: float = 100.0
    """IMU and truth rate [Hz]."""
    init_pos_sigma: float = 0.0
    """Initial position error handed to filters, per N, E, D axis [m]."""
    init_vel_sigma: float = 0.0
    """Initial velocity error per axis [m/s]."""
    init_tilt_sigma: float = 0.0
    """Initial level attitude error phi_N, phi_E, random [rad]."""
    init_heading_sigma: float = 0.0
    """Initial heading error phi_D, random [rad]."""
    init_attitude_error: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Deterministic initial attitude error phi_N, phi_E, phi_D added to the random one [rad]
    (e.g. a tilt for the Schuler oscillation); not included in the reported sigma."""

    def __post_init__(self) -> None:
        _check_common(self)
        vec = tuple(float(v) for v in self.init_attitude_error)
        if len(vec) != 3 or not all(math.isfinite(v) for v in vec):
            raise ValueError(f"init_attitude_error needs three finite values, got {vec!r}")
        object.__setattr__(self, "init_attitude_error", vec)


@register_scenario
class Stationary(Scenario):
    """A level IMU at rest: free-inertial tests, gyro-compassing, Schuler oscillation."""

    name: ClassVar[str] = "stationary"
    summary: ClassVar[str] = (
        "IMU at rest at a chosen latitude (free inertial, Schuler); optional initial tilt"
    )
    streams: ClassVar[tuple[StreamKind, ...]] = (StreamKind.IMU, StreamKind.TRUTH)
    Params: ClassVar[type] = StationaryParams

    def sensor_specs(self, params: StationaryParams) -> SensorSpecs:
        return _imu_specs(params)

    def simulate(self, params: StationaryParams, rng: np.random.Generator, seed: int,
                 sensors: SensorSpecs) -> Recording:
        p = params
        rng_imu, rng_init = rng.spawn(2)
        start = parse_utc(p.date)
        t0_ns = utc_ns(start)
        route = Route(lat=p.lat_deg * DEG, lon=p.lon_deg * DEG, h=p.h, heading=p.heading_deg * DEG)
        traj, imu_errors, imu_meas = _imu(p, sensors.require(ImuModel), route, rng_imu)
        nav0, init_errors = _initial_nav(p, traj, t0_ns, rng_init, p.init_attitude_error)
        meta = self.metadata(
            p, seed,
            true_errors={"imu": imu_errors.as_dict(), "initial_nav": init_errors},
            initial_nav=nav0,
            sensors=sensors,
            extra={
                "site": _site(p),
                "date": start.isoformat(),
                "decimal_year": decimal_year(start),
                "rates": {"imu": p.imu_rate, "truth": p.imu_rate},
                "truth_columns": _TRUTH_COLUMNS,
            },
        )
        streams = {StreamKind.IMU: imu_stream(traj.t, imu_meas, t0_ns),
                   StreamKind.TRUTH: truth_stream(traj, imu_meas, t0_ns, errors=imu_errors,
                                                  level_biases=True)}
        return Recording(streams=streams, metadata=meta, t0_ns=t0_ns)
