"""Truth trajectories of path-following vehicles, from a list of manoeuvres.

A vehicle starts at a site with a heading, pitch, roll and speed. Its motion is described per
channel (:class:`Channel`: speed along the path, heading, pitch, roll) by manoeuvres: a change
of one channel over a time window with a ramp shape (:class:`Ramp`). Manoeuvres of different
channels may overlap; every channel is the initial value plus the sum of its ramps, in closed
form, so the truth is evaluated at all sample times at once (vectorised, no stepping).

Kinematics
    Euler angles ZYX: ``C_nb = Rz(heading) Ry(pitch) Rx(roll)``. The vehicle moves through the
    medium along its velocity axis, the body x axis rotated by the fixed misalignment m
    (``C_bv = exp([m x])``; 0 for a car or an aircraft without sideslip or angle of attack),
    and the medium moves with a constant current:

        v_n = C_nb C_bv [u, 0, 0] + v_c_n

    so pitch sets the climb (v_D = -u sin(pitch) without misalignment). Turns are flat
    (roll only from ROLL manoeuvres: cars, ships) or coordinated (:class:`TurnMode`): the
    bank ``atan(u psi_dot / g)`` is added, so the turn is flown without lateral specific force.
    Position follows from :func:`navreplay.sim.kinematics.integrate_position` and the ideal IMU
    (mean body rate and specific force over each interval, consistent with the strapdown
    integrator on the rotating WGS84 earth) from :func:`navreplay.sim.kinematics.imu_from_truth`.

Sequential :class:`Segment` lists (each segment a duration with simultaneous changes) are
converted to manoeuvres by :func:`segments_to_manoeuvres`.

Examples
--------
A 90 deg right turn at 10 m/s, 20 s long, between two straight legs, sampled at 10 Hz:

>>> import numpy as np
>>> route = Route(lat=np.radians(37.0), lon=np.radians(127.0), h=50.0, speed=10.0,
...               manoeuvres=segments_to_manoeuvres(
...                   [Segment(duration=5.0), Segment(duration=20.0, heading_change=np.pi / 2),
...                    Segment(duration=5.0)]))
>>> speed, euler, _ = route.profile(np.array([0.0, 30.0]))
>>> np.degrees(euler[:, 2]).round(6).tolist()
[0.0, 90.0]
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import enum
import math
from collections.abc import Iterable, Sequence

import numpy as np

from navreplay.geo.earth import gravity, radii
from navreplay.geo.rotations import (
    euler_to_quat,
    quat_mult,
    quat_normalize,
    quat_to_dcm,
    rotvec_to_dcm,
    rotvec_to_quat,
    wrap_angle,
)
from navreplay.sim import kinematics


class Channel(enum.StrEnum):
    """What a manoeuvre changes."""

    SPEED = "speed"
    """Speed through the medium along the velocity axis [m/s]."""
    HEADING = "heading"
    """Heading (yaw) [rad], positive turning right (clockwise seen from above)."""
    PITCH = "pitch"
    """Pitch [rad], positive nose up."""
    ROLL = "roll"
    """Roll [rad], positive right wing / starboard down."""


class Ramp(enum.StrEnum):
    """Shape of a manoeuvre's change over its window."""

    LINEAR = "linear"
    """Constant rate over the window: the rate steps at both ends."""
    SMOOTH = "smooth"
    """Cosine-ramped rate ``(1 - cos(2 pi x))`` (x = fraction of the window): the rate and its
    derivative are continuous; the peak rate is twice the mean."""


class TurnMode(enum.StrEnum):
    """How the vehicle rolls in a turn."""

    FLAT = "flat"
    """No automatic roll (ground vehicle, ship)."""
    COORDINATED = "coordinated"
    """Bank ``atan(u psi_dot / g)`` added to the roll channel (aircraft)."""


def _set_enum(owner: object, name: str, cls: type[enum.StrEnum]) -> None:
    """Coerce field ``name`` of a frozen dataclass to enum ``cls``; ValueError naming the field."""
    value = getattr(owner, name)
    try:
        object.__setattr__(owner, name, cls(value))
    except ValueError:
        choices = ", ".join(m.value for m in cls)
        raise ValueError(
            f"{type(owner).__name__}.{name} must be one of {choices}, got {value!r}"
        ) from None


@dataclasses.dataclass(frozen=True, kw_only=True)
class Manoeuvre:
    """A change of one channel over a time window."""

    channel: Channel
    """Channel changed."""
    start: float
    """Window start [s since the trajectory start]."""
    duration: float
    """Window length [s], > 0."""
    change: float
    """Total change [m/s for SPEED, rad otherwise]."""
    ramp: Ramp = Ramp.SMOOTH
    """Shape of the change."""

    def __post_init__(self) -> None:
        _set_enum(self, "channel", Channel)
        _set_enum(self, "ramp", Ramp)
        for name in ("start", "duration", "change"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"Manoeuvre.{name} must be finite, got {getattr(self, name)!r}")
        if self.start < 0.0:
            raise ValueError(f"Manoeuvre.start must be >= 0, got {self.start!r}")
        if not self.duration > 0.0:
            raise ValueError(f"Manoeuvre.duration must be > 0, got {self.duration!r}")

    @property
    def end(self) -> float:
        """Window end [s]."""
        return self.start + self.duration


@dataclasses.dataclass(frozen=True, kw_only=True)
class Segment:
    """A time span with simultaneous channel changes (all with the same ramp); zero changes make
    a straight, constant-speed leg. A constant turn rate r for T seconds is
    ``Segment(duration=T, heading_change=r * T, ramp=Ramp.LINEAR)``."""

    duration: float
    """Length [s], > 0."""
    speed_change: float = 0.0
    """Change of speed over the segment [m/s]."""
    heading_change: float = 0.0
    """Change of heading [rad]."""
    pitch_change: float = 0.0
    """Change of pitch [rad]."""
    roll_change: float = 0.0
    """Change of roll [rad]."""
    ramp: Ramp = Ramp.SMOOTH
    """Shape of the changes."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.duration) and self.duration > 0.0):
            raise ValueError(f"Segment.duration must be > 0, got {self.duration!r}")


def segments_to_manoeuvres(
    segments: Iterable[Segment], start: float = 0.0
) -> tuple[Manoeuvre, ...]:
    """Manoeuvres of back-to-back segments starting at ``start`` [s]."""
    out: list[Manoeuvre] = []
    t = start
    for seg in segments:
        for channel, change in (
            (Channel.SPEED, seg.speed_change),
            (Channel.HEADING, seg.heading_change),
            (Channel.PITCH, seg.pitch_change),
            (Channel.ROLL, seg.roll_change),
        ):
            if change != 0.0:
                out.append(Manoeuvre(channel=channel, start=t, duration=seg.duration,
                                     change=change, ramp=seg.ramp))
        t += seg.duration
    return tuple(out)


def _ramp(x: np.ndarray, ramp: Ramp) -> tuple[np.ndarray, np.ndarray]:
    """Normalised change s(x) and its derivative ds/dx for x in [0, 1]."""
    if ramp is Ramp.LINEAR:
        return x, np.ones_like(x)
    two_pi_x = 2.0 * np.pi * x
    return x - np.sin(two_pi_x) / (2.0 * np.pi), 1.0 - np.cos(two_pi_x)


def channel_profile(
    t: np.ndarray, initial: float, manoeuvres: Sequence[Manoeuvre]
) -> tuple[np.ndarray, np.ndarray]:
    """Value and rate of one channel at sorted times.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sorted times [s].
    initial : float
        Value at t = 0.
    manoeuvres : sequence of Manoeuvre
        The channel's manoeuvres (the channel field is not checked here).

    Returns
    -------
    value, rate : ndarray, shape (N,)
        [unit] and [unit/s].
    """
    value = np.full(t.shape, float(initial))
    rate = np.zeros(t.shape)
    for m in manoeuvres:
        i0 = int(np.searchsorted(t, m.start, side="right"))
        i1 = int(np.searchsorted(t, m.end, side="right"))
        if i0 < i1:
            x = (t[i0:i1] - m.start) / m.duration
            s, ds = _ramp(x, m.ramp)
            value[i0:i1] += m.change * s
            rate[i0:i1] += (m.change / m.duration) * ds
        value[i1:] += m.change
    return value, rate


@dataclasses.dataclass(frozen=True, kw_only=True)
class Route:
    """A vehicle's start state and manoeuvres."""

    lat: float
    """Start latitude [rad]."""
    lon: float
    """Start longitude [rad]."""
    h: float = 0.0
    """Start height above the WGS84 ellipsoid [m]."""
    heading: float = 0.0
    """Initial heading [rad]."""
    pitch: float = 0.0
    """Initial pitch [rad]."""
    roll: float = 0.0
    """Initial roll [rad] (in coordinated mode, the bank of the turn is added)."""
    speed: float = 0.0
    """Initial speed through the medium [m/s], >= 0."""
    manoeuvres: tuple[Manoeuvre, ...] = ()
    """Channel changes; overlaps allowed."""
    turn_mode: TurnMode = TurnMode.FLAT
    """Flat or coordinated turns."""
    velocity_misalignment: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Rotation vector m [rad] of the velocity axis from body x: ``C_bv = exp([m x])``."""
    current_n: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Constant velocity of the medium (sea current, wind) NED [m/s]."""

    def __post_init__(self) -> None:
        _set_enum(self, "turn_mode", TurnMode)
        object.__setattr__(self, "manoeuvres", tuple(self.manoeuvres))
        for name in ("velocity_misalignment", "current_n"):
            vec = tuple(float(v) for v in getattr(self, name))
            if len(vec) != 3 or not all(math.isfinite(v) for v in vec):
                raise ValueError(f"Route.{name} needs three finite values, got {vec!r}")
            object.__setattr__(self, name, vec)
        for name in ("lat", "lon", "h", "heading", "pitch", "roll", "speed"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"Route.{name} must be finite, got {getattr(self, name)!r}")
        if abs(self.lat) > 0.5 * math.pi:
            raise ValueError(f"Route.lat must be within +-pi/2 rad, got {self.lat!r}")
        if self.speed < 0.0:
            raise ValueError(f"Route.speed must be >= 0, got {self.speed!r}")

    def profile(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Speed and attitude at sorted times.

        Parameters
        ----------
        t : ndarray, shape (N,)
            Sorted times [s since the start].

        Returns
        -------
        speed : ndarray, shape (N,)
            Speed through the medium [m/s].
        euler : ndarray, shape (N, 3)
            Roll, pitch, heading [rad], heading wrapped to [-pi, pi).
        heading_rate : ndarray, shape (N,)
            [rad/s].

        Raises
        ------
        ValueError
            If the speed goes negative or the pitch reaches +-90 deg.
        """
        t = np.asarray(t, dtype=float)
        by = {c: [m for m in self.manoeuvres if m.channel is c] for c in Channel}
        speed, _ = channel_profile(t, self.speed, by[Channel.SPEED])
        k = int(np.argmin(speed)) if speed.size else 0
        if speed.size and speed[k] < -1e-9:
            raise ValueError(f"route speed becomes negative ({speed[k]:.3g} m/s at t = {t[k]} s)")
        np.maximum(speed, 0.0, out=speed)
        euler = np.empty(t.shape + (3,))
        heading, heading_rate = channel_profile(t, self.heading, by[Channel.HEADING])
        euler[:, 2] = wrap_angle(heading)
        del heading
        euler[:, 1], _ = channel_profile(t, self.pitch, by[Channel.PITCH])
        if euler.size and np.max(np.abs(euler[:, 1])) >= 0.5 * math.pi - 1e-6:
            raise ValueError("route pitch reaches +-90 deg, where heading is undefined")
        euler[:, 0], _ = channel_profile(t, self.roll, by[Channel.ROLL])
        if self.turn_mode is TurnMode.COORDINATED:
            g = float(gravity(self.lat, self.h))
            euler[:, 0] += np.arctan(speed * heading_rate / g)
        return speed, euler, heading_rate

    def velocity_n(self, speed: np.ndarray, euler: np.ndarray) -> np.ndarray:
        """Ground velocity ``C_nb C_bv [u, 0, 0] + v_c_n`` [m/s], shape (N, 3).

        Parameters
        ----------
        speed : ndarray, shape (N,)
            [m/s].
        euler : ndarray, shape (N, 3)
            Roll, pitch, heading [rad].
        """
        d = rotvec_to_dcm(np.asarray(self.velocity_misalignment))[:, 0]
        return _rotate_zyx(euler, d) * speed[:, None] + np.asarray(self.current_n)


_PEAK_RATE = {Ramp.LINEAR: 1.0, Ramp.SMOOTH: 2.0}
"""Peak rate of a ramp over its mean rate (change / duration)."""


def bank_limited(route: Route, max_bank: float) -> Route:
    """``route`` with each heading manoeuvre lengthened (same start, same change) so that a
    coordinated turn banks at most ``max_bank`` [rad]: a pilot flies a turn no steeper than
    the bank limit, and a sharp heading change simply takes longer.

    The peak bank of a turn of change dpsi over T seconds is at most
    ``atan(u_max k |dpsi| / (T g))`` with u_max the largest speed over the window, k the
    ramp's peak-to-mean rate (2 for :attr:`Ramp.SMOOTH`) and g the gravity at the start; a
    turn above the limit gets ``T = k |dpsi| u_max / (g tan(max_bank))``. Turns already within
    it, and every manoeuvre of a flat-turning route, are unchanged. Overlapping heading
    manoeuvres are limited one by one.

    >>> r = Route(lat=0.6, lon=2.2, speed=60.0, turn_mode=TurnMode.COORDINATED,
    ...           manoeuvres=(Manoeuvre(channel=Channel.HEADING, start=10.0, duration=16.0,
    ...                                 change=math.pi / 2),))
    >>> round(bank_limited(r, math.radians(45.0)).manoeuvres[0].duration, 2)
    19.24
    """
    if route.turn_mode is not TurnMode.COORDINATED:
        return route
    if not 0.0 < max_bank < 0.5 * math.pi:
        raise ValueError(f"max_bank must be within (0, 90) deg, got {math.degrees(max_bank)!r}")
    g = float(gravity(route.lat, route.h))
    speeds = [m for m in route.manoeuvres if m.channel is Channel.SPEED]
    out = []
    for m in route.manoeuvres:
        if m.channel is Channel.HEADING and m.change != 0.0:
            k = _PEAK_RATE[m.ramp] * abs(m.change)
            duration = m.duration
            for _ in range(20):  # the window grows, and with it perhaps its top speed
                grid = np.linspace(m.start, m.start + duration, 401)
                u = float(np.max(channel_profile(grid, route.speed, speeds)[0]))
                needed = k * u / (g * math.tan(max_bank))
                if needed <= duration * (1.0 + 1e-12):
                    break
                duration = needed
            m = dataclasses.replace(m, duration=duration)
        out.append(m)
    return dataclasses.replace(route, manoeuvres=tuple(out))


def _rotate_zyx(euler: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll) d`` for a fixed vector d, shape (N, 3), without (N, 3, 3)."""
    cr, sr = np.cos(euler[:, 0]), np.sin(euler[:, 0])
    x = np.full(cr.shape, d[0])
    y = cr * d[1] - sr * d[2]
    z = sr * d[1] + cr * d[2]
    cp, sp = np.cos(euler[:, 1]), np.sin(euler[:, 1])
    x, z = cp * x + sp * z, -sp * x + cp * z
    cy, sy = np.cos(euler[:, 2]), np.sin(euler[:, 2])
    out = np.empty(euler.shape)
    out[:, 0] = cy * x - sy * y
    out[:, 1] = sy * x + cy * y
    out[:, 2] = z
    return out


@dataclasses.dataclass(frozen=True, kw_only=True)
class Trajectory:
    """Truth at uniformly spaced samples.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times [s since the start], ``k / rate``.
    pos : ndarray, shape (N, 3)
        Latitude [rad], longitude [rad], height [m].
    v_n : ndarray, shape (N, 3)
        Ground velocity NED [m/s].
    q_nb : ndarray, shape (N, 4)
        Attitude, Hamilton scalar first, b -> n.
    euler : ndarray, shape (N, 3)
        Roll, pitch, heading [rad] (heading in [-pi, pi)).
    speed : ndarray, shape (N,)
        Speed through the medium along the velocity axis [m/s].
    omega_ib_b : ndarray, shape (N - 1, 3) or None
        Ideal IMU body rate, mean over (t[k-1], t[k]] for k = 1..N-1 [rad/s].
    f_b : ndarray, shape (N - 1, 3) or None
        Ideal IMU specific force, mean over the same intervals [m/s^2].
    """

    t: np.ndarray
    pos: np.ndarray
    v_n: np.ndarray
    q_nb: np.ndarray
    euler: np.ndarray
    speed: np.ndarray
    omega_ib_b: np.ndarray | None = None
    f_b: np.ndarray | None = None

    @property
    def rate(self) -> float:
        """Sample rate [Hz]."""
        return 1.0 / (self.t[1] - self.t[0])


def time_grid(duration: float, rate: float) -> np.ndarray:
    """Times ``k / rate`` for k = 0..duration*rate [s], shape (duration * rate + 1,).

    Raises ``ValueError`` unless ``duration`` is a positive whole number of sample intervals.
    """
    if not (math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"rate must be > 0 Hz, got {rate!r}")
    n = round(duration * rate)
    if not (math.isfinite(duration) and n >= 1 and abs(n - duration * rate) < 1e-6):
        raise ValueError(
            f"duration {duration!r} s is not a positive whole number of 1/{rate:g} s intervals"
        )
    return np.arange(n + 1) / rate


def sample_indices(n: int, truth_rate: float, rate: float) -> np.ndarray:
    """Indices of the truth samples (0, step, 2 step, ...) at which a sensor of ``rate`` samples.

    Parameters
    ----------
    n : int
        Number of truth samples.
    truth_rate, rate : float
        [Hz]; ``truth_rate / rate`` must be a whole number.

    Returns
    -------
    ndarray of int, shape (ceil(n / step),)
    """
    step = truth_rate / rate
    k = round(step)
    if k < 1 or abs(k - step) > 1e-9 * step:
        raise ValueError(
            f"sensor rate {rate:g} Hz must divide the truth rate {truth_rate:g} Hz"
        )
    return np.arange(0, n, k)


def generate(route: Route, duration: float, rate: float, *, ideal_imu: bool = True,
             body_velocity: np.ndarray | None = None) -> Trajectory:
    """Truth of a route at ``rate`` for ``duration``.

    Parameters
    ----------
    route : Route
    duration : float
        [s], a whole number of sample intervals.
    rate : float
        Truth (and ideal IMU) rate [Hz].
    ideal_imu : bool
        Also compute the ideal IMU samples (``omega_ib_b``, ``f_b``).
    body_velocity : ndarray, shape (N, 3), optional
        Velocity through the medium added to the route's, body FRD [m/s], one row per sample
        of the time grid (an underwater vehicle's sway and heave): the ground velocity becomes
        ``C_nb (C_bv [u, 0, 0] + body_velocity) + v_c_n``, and position and IMU follow it.

    Returns
    -------
    Trajectory
    """
    t = time_grid(duration, rate)
    speed, euler, _ = route.profile(t)
    v_n = route.velocity_n(speed, euler)
    q_nb = euler_to_quat(euler)
    if body_velocity is not None:
        body_velocity = np.asarray(body_velocity, dtype=float)
        if body_velocity.shape != v_n.shape:
            raise ValueError(f"body_velocity needs shape {v_n.shape}, got {body_velocity.shape}")
        v_n = v_n + np.einsum("nij,nj->ni", quat_to_dcm(q_nb), body_velocity)
    pos = kinematics.integrate_position(t, v_n, np.array([route.lat, route.lon, route.h]))
    omega = f = None
    if ideal_imu:
        omega, f = kinematics.imu_from_truth(t, pos, v_n, q_nb)
    return Trajectory(
        t=t, pos=pos, v_n=v_n, q_nb=q_nb, euler=euler, speed=speed, omega_ib_b=omega, f_b=f
    )


def parse_utc(date: str) -> _dt.datetime:
    """ISO 8601 date or date-time (``"2017-01-01"``, ``"2017-01-01T06:30:00"``) as naive UTC.

    A time-zone offset, if given, is converted to UTC. Raises ``ValueError`` on other text.
    """
    try:
        when = _dt.datetime.fromisoformat(date)
    except (TypeError, ValueError):
        raise ValueError(f"date {date!r} is not an ISO 8601 date or date-time") from None
    if when.tzinfo is not None:
        when = when.astimezone(_dt.UTC).replace(tzinfo=None)
    return when


def utc_ns(when: _dt.datetime) -> int:
    """Nanoseconds since the UNIX epoch of a naive UTC date-time, exact to the microsecond."""
    return ((when - _dt.datetime(1970, 1, 1)) // _dt.timedelta(microseconds=1)) * 1000


def initial_nav(
    traj: Trajectory,
    t0_ns: int,
    rng: np.random.Generator,
    *,
    pos_sigma_ned: Sequence[float] = (0.0, 0.0, 0.0),
    vel_sigma_n: Sequence[float] = (0.0, 0.0, 0.0),
    phi_sigma: Sequence[float] = (0.0, 0.0, 0.0),
    phi_offset: Sequence[float] = (0.0, 0.0, 0.0),
    index: int = 0,
) -> tuple[dict, dict]:
    """Initial navigation solution as an external alignment would hand it over: truth plus errors.

    Errors: position ``dp_ned ~ N(0, pos_sigma_ned^2)`` [m], velocity ``dv ~ N(0, vel_sigma^2)``
    [m/s], attitude ``phi = phi_offset + N(0, phi_sigma^2)`` [rad] with the project's phi-angle
    sign, ``C_nb_hat = exp(-[phi x]) C_nb`` (so ``attitude_error(C_hat, C) = phi`` to first
    order; a positive phi_D makes the heading smaller).

    Parameters
    ----------
    traj : Trajectory
    t0_ns : int
        UNIX time of ``traj.t[0]`` [ns].
    rng : numpy.random.Generator
    pos_sigma_ned, vel_sigma_n, phi_sigma : sequence of 3 floats
        1-sigma [m], [m/s], [rad].
    phi_offset : sequence of 3 floats
        Deterministic attitude error added to the draw [rad].
    index : int
        Truth sample to start from.

    Returns
    -------
    nav : dict
        ``Metadata.initial_nav``: ``t_ns``, ``pos`` [rad, rad, m], ``v_n`` [m/s], ``q_nb``,
        ``sigma`` = {``pos_ned`` [m], ``v_n`` [m/s], ``phi`` [rad]} (1-sigma per axis, for P0).
    true_errors : dict
        The realised errors: ``pos_ned`` [m], ``v_n`` [m/s], ``phi`` [rad] (estimate minus truth).
    """
    pos_sigma = np.asarray(pos_sigma_ned, dtype=float)
    vel_sigma = np.asarray(vel_sigma_n, dtype=float)
    att_sigma = np.asarray(phi_sigma, dtype=float)
    dp = rng.standard_normal(3) * pos_sigma
    dv = rng.standard_normal(3) * vel_sigma
    phi = np.asarray(phi_offset, dtype=float) + rng.standard_normal(3) * att_sigma
    pos = traj.pos[index].copy()
    R_M, R_N = radii(pos[0])
    pos += [dp[0] / (R_M + pos[2]), dp[1] / ((R_N + pos[2]) * math.cos(pos[0])), -dp[2]]
    q_nb = quat_normalize(quat_mult(rotvec_to_quat(-phi), traj.q_nb[index]))
    nav = {
        "t_ns": int(t0_ns + round(float(traj.t[index]) * 1e9)),
        "pos": pos.tolist(),
        "v_n": (traj.v_n[index] + dv).tolist(),
        "q_nb": q_nb.tolist(),
        "sigma": {
            "pos_ned": pos_sigma.tolist(),
            "v_n": vel_sigma.tolist(),
            "phi": att_sigma.tolist(),
        },
    }
    return nav, {"pos_ned": dp.tolist(), "v_n": dv.tolist(), "phi": phi.tolist()}
