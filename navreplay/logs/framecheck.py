"""Check a log's data against the frames it is read in, before any replay.

The checks read the samples at hand: the whole log when it is read whole, the first window of
it (200 s of a 100 Hz IMU) when it is replayed in windows; their notes give the span averaged.

Accelerometer: over the still window at the start (:func:`still_window`), else averaged over the
samples at hand, the specific force in FRD must point up, i.e. its z component must be negative
(gravity reads -g on a z-down axis), and at rest its magnitude must be gravity within 10 %. An
FRD IMU read as FLU (its frame named ``imu_link``) shows +g on z: the run stops and says which
``--frame`` fixes it. Magnetometer: the component of the field along the accelerometer's down
direction must have the sign of the World Magnetic Model's vertical component at the position
(the dip), where the field is not nearly horizontal.
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np

from navreplay.core.streams import Recording, StreamKind, seconds
from navreplay.io.checks import named_convention
from navreplay.io.convert import Convention
from navreplay.io.errors import RecordingError
from navreplay.io.topics import TopicSource

STILL_BLOCK = 1.0
"""Block length of the stillness test [s]."""
STILL_ACCEL = 0.1
"""Largest change of a block's mean specific force from the first block's while still [m/s^2]."""
STILL_GYRO = 0.01
"""Largest block-mean angular rate while still [rad/s] (0.6 deg/s)."""


class FrameError(RecordingError):
    """The data contradict the frame convention they are read in."""


def still_window(recording: Recording, limit_s: float = 300.0) -> tuple[int, int]:
    """IMU rows [0, stop) during which the vehicle is still from the start (stop = 0: not still).

    Still: every 1 s block's mean specific force stays within 0.1 m/s^2 of the first block's and
    its mean rate below 0.01 rad/s; at most ``limit_s``.
    """
    imu = recording[StreamKind.IMU]
    t = seconds(imu.t_ns, imu.t_ns[0])
    f = imu["f_b"]
    w = imu.columns.get("omega_ib_b")
    edges = np.searchsorted(t, np.arange(0.0, min(t[-1], limit_s) + 1e-9, STILL_BLOCK))
    stop = 0
    f0 = None
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        if b <= a:
            break
        fm = f[a:b].mean(axis=0)
        f0 = fm if f0 is None else f0
        moving = np.linalg.norm(fm - f0) > STILL_ACCEL
        if w is not None:
            moving |= np.linalg.norm(w[a:b].mean(axis=0)) > STILL_GYRO
        if moving:
            break
        stop = int(b)
    return 0, stop


def _where(source: TopicSource | None, kind: str) -> str:
    if source is None:
        return kind
    return (f"{kind} topic {source.topic} (frame id {source.frame_id!r}, read as "
            f"{source.convention.value.upper() if source.convention else '-'}: {source.reason})")


def _advice(kind: StreamKind, source: TopicSource | None, other: str) -> str:
    """``--frame KIND=OTHER``, with ``--force-frame`` when the topic's frame id names the axes
    the data contradict (a mislabelled topic: the declaration must win over its name)."""
    named = named_convention(kind, source.frame_id) if source is not None else None
    force = " --force-frame" if named is not None and named.value != other else ""
    return f"--frame {kind.value}={other}{force}"


def check_accelerometer(recording: Recording, source: TopicSource | None) -> str:
    """Raise :class:`FrameError` on a contradiction; return what the check saw."""
    imu = recording[StreamKind.IMU]
    _, stop = still_window(recording)
    window = slice(0, stop) if stop >= 2 else slice(None)
    what = (f"the still start (first {stop} samples)" if stop >= 2
            else f"{span(imu.t_ns, recording.t0_ns)} (averaged)")
    f = imu["f_b"][window].mean(axis=0)
    g = 9.80665
    other = ({Convention.FLU: "frd", Convention.FRD: "flu"}.get(source.convention, "frd")
             if source and source.convention else "frd")
    if f[2] > 0.5 * g:
        raise FrameError(
            f"{recording_where(recording)}: {_where(source, 'IMU')}: over {what} the "
            f"accelerometer reads {f[2]:+.2f} m/s^2 along z after conversion to FRD, i.e. +g "
            f"on a z-down axis: the data are in the other convention; use "
            f"{_advice(StreamKind.IMU, source, other)} (or [frames] imu = \"{other}\")")
    if stop >= 2:
        mag = float(np.linalg.norm(f))
        if abs(mag - g) > 0.1 * g:
            raise FrameError(
                f"{recording_where(recording)}: {_where(source, 'IMU')}: at rest the "
                f"accelerometer reads |f| = {mag:.3f} m/s^2, not gravity ({g:.2f}): it does "
                "not give specific force in m/s^2 (gravity removed, or in g); the INS cannot "
                "use it")
    return f"accelerometer over {what}: f = [{f[0]:.2f}, {f[1]:.2f}, {f[2]:.2f}] m/s^2 (FRD)"


def recording_where(recording: Recording) -> str:
    return str(recording.metadata.extra.get("source", "log"))


def wmm_field_ned(lat: float, lon: float, h: float, t_ns: int) -> np.ndarray:
    """World Magnetic Model field NED [T] at a position and time."""
    from pygeomag import GeoMag

    when = dt.datetime.fromtimestamp(t_ns * 1e-9, tz=dt.UTC)
    year = when.year + (when.timetuple().tm_yday - 1) / 365.25
    for coeffs in ("wmm/WMM_2025.COF", "wmm/WMM_2020.COF", "wmm/WMM_2015.COF"):
        try:
            r = GeoMag(coefficients_file=coeffs).calculate(
                glat=math.degrees(lat), glon=math.degrees(lon), alt=h / 1000.0, time=year)
            return np.array([r.x, r.y, r.z]) * 1e-9
        except Exception:  # outside the model's years: try the previous model
            continue
    raise FrameError(f"no World Magnetic Model covers {when:%Y-%m-%d}")


def check_magnetometer(recording: Recording, source: TopicSource | None,
                       pos: np.ndarray | None) -> str:
    """Raise :class:`FrameError` when the measured dip has the wrong sign."""
    if pos is None:
        return "magnetometer: not checked (no position for the earth's field)"
    m = recording[StreamKind.MAG]["m_b"].mean(axis=0)
    f = recording[StreamKind.IMU]["f_b"].mean(axis=0)
    down = -f / np.linalg.norm(f)
    field = wmm_field_ned(pos[0], pos[1], pos[2], int(recording.t0_ns))
    expected, measured = field[2], float(m @ down)
    if abs(expected) < 0.2 * np.linalg.norm(field):
        return "magnetometer: not checked (the field is nearly horizontal here)"
    if np.sign(measured) != np.sign(expected):
        other = ({Convention.FLU: "frd", Convention.FRD: "flu"}.get(source.convention, "frd")
                 if source and source.convention else "frd")
        raise FrameError(
            f"{recording_where(recording)}: {_where(source, 'magnetometer')}: the field along "
            f"down is {measured * 1e9:+.0f} nT but the World Magnetic Model gives "
            f"{expected * 1e9:+.0f} nT here (dip sign): use "
            f"{_advice(StreamKind.MAG, source, other)}")
    return (f"magnetometer dip sign agrees with the WMM ({measured * 1e9:+.0f} nT down, "
            f"averaged over {span(recording[StreamKind.MAG].t_ns, recording.t0_ns)})")


def span(t_ns: np.ndarray, t0_ns: int) -> str:
    """``t = a to b s``: the samples a check averaged (a streamed run checks the first window
    of the log, not all of it)."""
    a, b = seconds(np.array([t_ns[0], t_ns[-1]]), t0_ns)
    return f"t = {a:.1f} to {b:.1f} s"


def check_frames(recording: Recording, sources: dict[StreamKind, TopicSource],
                 pos: np.ndarray | None) -> list[str]:
    """Run the checks that apply; raise :class:`FrameError` on a contradiction."""
    notes = []
    if StreamKind.IMU in recording and len(recording[StreamKind.IMU]) > 1:
        notes.append(check_accelerometer(recording, sources.get(StreamKind.IMU)))
        if StreamKind.MAG in recording and len(recording[StreamKind.MAG]):
            notes.append(check_magnetometer(recording, sources.get(StreamKind.MAG), pos))
    return notes

