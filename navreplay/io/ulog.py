"""PX4 ULog files (``.ulg``), read with pyulog (the optional extra ``navreplay[ulog]``).

A ULog file holds uORB topics, each logged under its name and an instance (``multi_id``); a
topic of instance 0 is named by its name (``sensor_gps``), another instance by its name and
number (``sensor_gps/1``). Times are UTC where a GNSS topic logs it: the autopilot's clock
(microseconds since boot) plus the offset the receiver's ``time_utc_usec`` gives
(:func:`utc_offset_ns`), so that a reference in UNIX time lines up and the magnetic model has
the date; without it, the autopilot's clock. The recording starts at its first sample read.

The streams, in navreplay's conventions (PX4's body frame is FRD and its local frame NED, as
navreplay's: no axis is changed unless ``--frame`` declares otherwise):

==========  =========================================  =========================================
stream      topics, the first present feeds it          read as
==========  =========================================  =========================================
imu         ``sensor_combined``, ``vehicle_imu``        ``gyro_rad`` [rad/s] and
                                                        ``accelerometer_m_s2`` [m/s^2] at
                                                        ``timestamp``; or ``delta_angle``
                                                        [rad] / ``delta_angle_dt`` [us] and
                                                        ``delta_velocity`` [m/s] /
                                                        ``delta_velocity_dt`` at
                                                        ``timestamp_sample`` (the mean rate and
                                                        specific force over the interval that
                                                        ends there)
gps         ``vehicle_gps_position``, ``sensor_gps``   rows with a 3D fix (``fix_type`` >= 3):
                                                        latitude, longitude (``lat``/``lon``
                                                        [1e-7 deg] or ``latitude_deg``/
                                                        ``longitude_deg``), ellipsoidal height
                                                        (``alt_ellipsoid`` [mm] or
                                                        ``altitude_ellipsoid_m``); 1-sigma
                                                        north and east ``eph``, down ``epv``
                                                        [m], as PX4's EKF2 uses them
gps_vel     the same topic                              rows with a 3D fix and
                                                        ``vel_ned_valid``: ``vel_n_m_s``,
                                                        ``vel_e_m_s``, ``vel_d_m_s`` [m/s];
                                                        1-sigma ``s_variance_m_s`` per axis
                                                        (a speed accuracy, despite its name)
mag         ``vehicle_magnetometer``, ``sensor_mag``    ``magnetometer_ga`` (calibrated) or
                                                        ``x, y, z`` (the driver's, rotated to the
                                                        body, not calibrated) [gauss] -> T
==========  =========================================  =========================================

A GNSS topic's ``timestamp_sample`` is its time where logged (else ``timestamp``). The topics
of PX4's own estimate (``vehicle_local_position``, ``vehicle_global_position``,
``vehicle_attitude``) are read by :meth:`ULogSource.estimate` as a recorded navigation
solution. A read parses only these topics and those of the streams (:data:`READ`); ``info``
lists every topic (:meth:`ULogSource.listing`).

A file cut short (a log whose writing stopped) yields the messages before the cut with a
:class:`~navreplay.io.errors.SalvagedWarning`; a file pyulog finds corrupt inside is read past
the damage, with a warning; a file that is not ULog is one :class:`RecordingError` line.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.core.streams import Metadata, StreamKind
from navreplay.core.units import GAUSS
from navreplay.io.convert import Convention
from navreplay.io.direct import Columns, DirectSource, Topic, body_axes
from navreplay.io.errors import RecordingError, RecordingWarning, SalvagedWarning
from navreplay.io.solution import RecordedSolution
from navreplay.io.source import ReadOptions

MAGIC = b"ULog\x01\x12\x35"
"""The first bytes of a ULog file (its version byte follows)."""

EXTRA = "ulog"
"""The optional extra that installs pyulog."""

FEEDS: dict[str, tuple[StreamKind, ...]] = {
    "sensor_combined": (StreamKind.IMU,),
    "vehicle_imu": (StreamKind.IMU,),
    "vehicle_gps_position": (StreamKind.GPS, StreamKind.GPS_VEL),
    "sensor_gps": (StreamKind.GPS, StreamKind.GPS_VEL),
    "vehicle_magnetometer": (StreamKind.MAG,),
    "sensor_mag": (StreamKind.MAG,),
}
"""The streams each topic can feed; candidates in this order (then by instance)."""

EKF2_TOPICS = ("vehicle_local_position", "vehicle_global_position", "vehicle_attitude")
"""PX4's estimate (EKF2, or whichever estimator the vehicle ran), read by
:func:`ekf2_solution`."""

ONBOARD = "ekf2"
"""The name of PX4's own solution as a recorded estimator (``--onboard ekf2``)."""

READ = (*FEEDS, *EKF2_TOPICS)
"""The topics a read parses (a flight log holds a hundred more, skipped)."""


def accepts(path: Path) -> bool:
    """Whether ``path`` is a ULog file (by its first bytes; a ``.ulg`` name otherwise)."""
    if not path.is_file():
        return path.suffix.lower() == ".ulg"
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return path.suffix.lower() == ".ulg"


def topic_name(name: str, multi_id: int) -> str:
    """A topic's name in navreplay: ``name`` for instance 0, ``name/N`` for instance N."""
    return name if multi_id == 0 else f"{name}/{multi_id}"


class _Reads:
    """A file object that notes a read cut short (the file ends inside a message)."""

    def __init__(self, f: io.BufferedReader) -> None:
        self._f = f
        self.cut_at: int | None = None

    def read(self, n: int = -1) -> bytes:
        at = self._f.tell()
        data = self._f.read(n)
        # pyulog reads a message header (3 bytes), then its body: nothing at a header is the
        # end of the file; anything less than asked for otherwise is a cut
        if 0 <= n != len(data) and not (n == 3 and not data):
            self.cut_at = at + len(data)
        return data

    def __getattr__(self, name: str) -> Any:
        return getattr(self._f, name)


def _pyulog() -> Any:
    try:
        import pyulog
    except ImportError:
        raise RecordingError(f"reading PX4 ULog files needs pyulog: pip install "
                             f"'navreplay[{EXTRA}]'") from None
    return pyulog


def parse(path: Path, names: list[str] | None = None) -> tuple[Any, bool]:
    """The file parsed by pyulog (only the topics ``names`` when given), and whether messages
    were lost; a cut or a corrupt file is a warning, a file that is not ULog a
    :class:`RecordingError`."""
    pyulog = _pyulog()
    try:
        f = open(path, "rb")  # noqa: SIM115 (pyulog closes it)
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such file") from None
    except OSError as exc:
        raise RecordingError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    reads = _Reads(f)
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # pyulog prints what it finds
            log = pyulog.ULog(reads, names, True)
    except Exception as exc:  # pyulog raises its own and struct/index errors on bad headers
        f.close()
        raise RecordingError(f"{path}: not a readable ULog file ({type(exc).__name__}: "
                             f"{' '.join(str(exc).split())})") from None
    size = path.stat().st_size
    last = max((int(d.data["timestamp"][-1]) for d in log.data_list
                if len(d.data["timestamp"])), default=None)
    at = "" if last is None else f", the last at {(last - log.start_timestamp) * 1e-6:.6f} s " \
        "after the log's start"
    if reads.cut_at is not None:
        warnings.warn(SalvagedWarning(
            f"{path}: file is cut short inside a message at byte {reads.cut_at} of {size}; "
            f"the messages before it are read{at}; anything after is lost",
            data_complete=False), stacklevel=3)
    if log.file_corruption:
        warnings.warn(RecordingWarning(
            f"{path}: pyulog finds the file corrupt inside and reads on past the damage (at "
            f"the next sync marker); messages in the damaged part are lost{at}"), stacklevel=3)
    return log, reads.cut_at is not None or bool(log.file_corruption)


@dataclasses.dataclass(frozen=True)
class _Data:
    """One topic's columns (pyulog's ``data``: field name -> array; ``x[0]`` for arrays)."""

    name: str
    data: dict[str, np.ndarray]

    def has(self, field: str) -> bool:
        return field in self.data or f"{field}[0]" in self.data

    def get(self, field: str) -> np.ndarray:
        if field in self.data:
            return np.asarray(self.data[field], dtype=float)
        try:
            return np.column_stack([np.asarray(self.data[f"{field}[{i}]"], dtype=float)
                                    for i in range(3)])
        except KeyError:
            raise RecordingError(f"topic {self.name} has no field {field}") from None

    def times(self, prefer_sample: bool = True) -> np.ndarray:
        """``timestamp_sample`` where logged and set, else ``timestamp`` [us] -> [ns]."""
        t = np.asarray(self.data["timestamp"], dtype=np.int64)
        if prefer_sample and "timestamp_sample" in self.data:
            s = np.asarray(self.data["timestamp_sample"], dtype=np.int64)
            if s.size and s.all():
                t = s
        return t * 1000


def utc_offset_ns(log: Any) -> int:
    """UTC at the autopilot's boot [ns since 1970]: the GNSS receiver's ``time_utc_usec``
    less its time on the autopilot's clock (``timestamp`` + ``timestamp_time_relative``), the
    median over the fixes; 0 when no GNSS topic logs UTC (times stay the autopilot's)."""
    for d in sorted(log.data_list, key=lambda d: (d.name != "vehicle_gps_position", d.name,
                                                  d.multi_id)):
        if FEEDS.get(d.name) != (StreamKind.GPS, StreamKind.GPS_VEL):
            continue
        if "time_utc_usec" not in d.data:
            continue
        utc = np.asarray(d.data["time_utc_usec"], dtype=np.int64)
        at = np.asarray(d.data["timestamp"], dtype=np.int64)
        if "timestamp_time_relative" in d.data:
            at = at + np.asarray(d.data["timestamp_time_relative"], dtype=np.int64)
        ok = utc > 0
        if "fix_type" in d.data:
            ok &= np.asarray(d.data["fix_type"]) >= 3
        if ok.any():
            return int(np.median(utc[ok] - at[ok])) * 1000
    return 0


class ULogSource(DirectSource):
    """A PX4 ULog file (module docstring) as one window."""

    kind = "ulog"
    what = "log"

    def __init__(self, path: str | os.PathLike[str], options: ReadOptions | None = None
                 ) -> None:
        super().__init__(path, options)
        named = {k: v.removesuffix("/0") for k, v in self.options.topics.items()}
        self.options = dataclasses.replace(self.options, topics=named)  # name/0 is name
        self._log: Any = None
        self._utc_ns = 0

    def _parsed(self) -> Any:
        """The topics navreplay reads (a log's other topics are skipped by the parser)."""
        if self._log is None:
            named = (t.partition("/")[0] for t in self.options.topics.values())
            self._log, self._salvaged = parse(self.path, list(dict.fromkeys([*READ, *named])))
            self._utc_ns = utc_offset_ns(self._log)
        return self._log

    def listing(self) -> list[Topic]:
        """Every topic of the log (the whole file parsed)."""
        log, _ = parse(self.path)
        return self._topics(log)

    def estimate(self, label: str = ONBOARD) -> RecordedSolution:
        """PX4's own estimate in the log (:func:`ekf2_solution`), on the streams' time base."""
        return ekf2_solution(self._parsed(), self._utc_ns, self.name, label)

    def metadata(self) -> Metadata:
        self._parsed()
        clock = ("UTC, from the GNSS receiver's time_utc_usec" if self._utc_ns
                 else "the autopilot's clock (time since boot; no GNSS logs UTC)")
        return Metadata(extra={"clock": clock})

    def _data(self, topic: Topic) -> _Data:
        name, _, instance = topic.name.partition("/")
        multi_id = int(instance or 0)
        for d in self._parsed().data_list:
            if d.name == name and d.multi_id == multi_id:
                return _Data(topic.name, d.data)
        raise RecordingError(f"{self.name}: no topic {topic.name}")  # listed: never

    def readers(self, kind: StreamKind) -> tuple[str, ...]:
        return tuple(name for name, kinds in FEEDS.items() if kind in kinds)

    def topics(self) -> list[Topic]:
        return self._topics(self._parsed())

    @staticmethod
    def _topics(log: Any) -> list[Topic]:
        order = list(FEEDS)
        found = sorted(log.data_list,
                       key=lambda d: (order.index(d.name) if d.name in order else len(order),
                                      d.name, d.multi_id))
        return [Topic(topic_name(d.name, d.multi_id), d.name, len(d.data["timestamp"]),
                      FEEDS.get(d.name, ())) for d in found]

    def read(self, topic: Topic, kind: StreamKind, declared: Convention | None) -> Columns:
        d = self._data(topic)
        label = f"{self.name}: topic {topic.name}"
        try:
            if kind is StreamKind.IMU:
                cols = _imu(d, declared)
            elif kind is StreamKind.MAG:
                cols = _mag(d, declared)
            else:
                cols = _gnss(d, kind)
            cols.t_ns = cols.t_ns + self._utc_ns
            return cols
        except RecordingError as exc:
            raise RecordingError(f"{self.name}: {exc}") from None
        except (ValueError, ZeroDivisionError) as exc:
            raise RecordingError(f"{label}: {exc}") from None


def _imu(d: _Data, declared: Convention | None) -> Columns:
    notes = []
    if d.has("delta_angle"):  # vehicle_imu: increments over the interval ending at the sample
        dt_g = d.get("delta_angle_dt") * 1e-6
        dt_a = d.get("delta_velocity_dt") * 1e-6
        keep = (dt_g > 0) & (dt_a > 0)
        w = d.get("delta_angle")[keep] / dt_g[keep, None]
        f = d.get("delta_velocity")[keep] / dt_a[keep, None]
        t = d.times()[keep]
        if not keep.all():
            notes.append(f"{int((~keep).sum())} samples with a zero interval left out")
    else:  # sensor_combined: mean rate and specific force, the accelerometer's time relative
        t = d.times(prefer_sample=False)
        w, f = d.get("gyro_rad"), d.get("accelerometer_m_s2")
        if "accelerometer_timestamp_relative" in d.data:
            rel = np.asarray(d.data["accelerometer_timestamp_relative"], dtype=np.int64)
            keep = rel != 0x7FFFFFFF  # PX4's RELATIVE_TIMESTAMP_INVALID: no accelerometer
            if not keep.all():
                notes.append(f"{int((~keep).sum())} samples without an accelerometer sample "
                             "left out")
                t, w, f = t[keep], w[keep], f[keep]
    w, conv, reason = body_axes(w, Convention.FRD, declared, "PX4's body frame")
    f, _, _ = body_axes(f, Convention.FRD, declared, "PX4's body frame")
    return Columns(t, {"omega_ib_b": w, "f_b": f}, f"imu_{conv.value}", conv, reason, notes)


def _mag(d: _Data, declared: Convention | None) -> Columns:
    notes = []
    if d.has("magnetometer_ga"):
        m = d.get("magnetometer_ga")
    else:
        m = np.column_stack([d.get("x"), d.get("y"), d.get("z")])
        notes.append("sensor_mag is the driver's field, not calibrated (vehicle_magnetometer "
                     "is, when logged)")
    m, conv, reason = body_axes(m * GAUSS, Convention.FRD, declared, "PX4's body frame")
    return Columns(d.times(), {"m_b": m}, f"mag_{conv.value}", conv, reason, notes)


def _gnss(d: _Data, kind: StreamKind) -> Columns:
    t = d.times()
    fix = d.get("fix_type") if "fix_type" in d.data else np.full(t.shape, 3.0)
    keep = fix >= 3
    notes = []
    if kind is StreamKind.GPS_VEL:
        if "vel_ned_valid" in d.data:
            keep &= np.asarray(d.data["vel_ned_valid"]).astype(bool)
        v = np.column_stack([d.get(f"vel_{a}_m_s") for a in "ned"])
        sigma = np.repeat(d.get("s_variance_m_s")[:, None], 3, axis=1)
        keep &= _accuracy(sigma)
        cols = {"v_n": v[keep], "vel_sigma": sigma[keep]}
        frame = "ned"
    else:
        if "latitude_deg" in d.data:
            lat, lon = d.get("latitude_deg"), d.get("longitude_deg")
        else:
            lat, lon = d.get("lat") * 1e-7, d.get("lon") * 1e-7
        if d.has("altitude_ellipsoid_m"):
            h = d.get("altitude_ellipsoid_m")
        elif d.has("alt_ellipsoid"):
            h = d.get("alt_ellipsoid") * 1e-3
        else:
            raise ValueError("no ellipsoidal height (alt_ellipsoid)")
        pos = np.column_stack([np.radians(lat), np.radians(lon), h])
        sigma = np.column_stack([d.get("eph"), d.get("eph"), d.get("epv")])
        keep &= _accuracy(sigma)
        cols = {"pos": pos[keep], "pos_sigma": sigma[keep]}
        frame = "gnss"
    if not keep.all():
        notes.append(f"{int((~keep).sum())} of {keep.size} messages without a 3D fix"
                     f"{' or a valid velocity' if kind is StreamKind.GPS_VEL else ''} or "
                     "without a positive accuracy left out")
    conv = Convention.NED if kind is StreamKind.GPS_VEL else None
    return Columns(t[keep], cols, frame, conv, "PX4's local frame is NED" if conv else "",
                   notes)


def _accuracy(sigma: np.ndarray) -> np.ndarray:
    """Rows whose accuracies are positive numbers (a receiver that reports none says 0)."""
    return np.all(np.isfinite(sigma) & (sigma > 0), axis=1)


# --------------------------------------------------------------------------------------------
# PX4's own estimate


def ekf2_solution(log: Any, utc_ns: int, where: str, label: str = ONBOARD
                  ) -> RecordedSolution:
    """PX4's estimate in a parsed ULog file (:func:`parse`), at the times of
    ``vehicle_local_position`` plus ``utc_ns`` [ns].

    Velocity NED from ``vehicle_local_position`` (``vx, vy, vz``); position from
    ``vehicle_global_position`` (``lat, lon``, ``alt_ellipsoid``) interpolated to those times
    (NaN without it: the local position's reference height is above mean sea level, not the
    ellipsoid); attitude from
    ``vehicle_attitude`` (``q``, FRD to NED, scalar first), normalised linear interpolation.
    The 1-sigma: EKF2 logs ``eph`` and ``evh`` as the square root of the sum of the north and
    east variances, so each of north and east is ``eph / sqrt(2)`` (``evh / sqrt(2)``), down
    ``epv`` (``evv``). Rows where the estimator flags the position or velocity invalid
    (``xy_valid``, ``v_xy_valid``...) are NaN in that part. The attitude's variance is not in
    these topics: the attitude is shown and scored, without a NEES.
    """
    data = {d.name: _Data(d.name, d.data) for d in log.data_list if d.multi_id == 0}
    if "vehicle_local_position" not in data:
        raise RecordingError(f"{where}: --onboard {ONBOARD}: no topic vehicle_local_position "
                             "(PX4's estimate) in the log")
    lp = data["vehicle_local_position"]
    t = lp.times() + utc_ns
    n = t.size
    nan3 = np.full((n, 3), np.nan)
    v = np.column_stack([lp.get("vx"), lp.get("vy"), lp.get("vz")])
    vel_sigma = nan3.copy()
    if lp.has("evh") and lp.has("evv"):
        evh = lp.get("evh") / math.sqrt(2.0)
        vel_sigma = np.column_stack([evh, evh, lp.get("evv")])
    for flag in ("v_xy_valid", "v_z_valid"):
        if flag in lp.data:
            bad = ~np.asarray(lp.data[flag]).astype(bool)
            v[bad] = np.nan
    pos = nan3.copy()
    pos_sigma = nan3.copy()
    gp = data.get("vehicle_global_position")
    read = ["vehicle_local_position"]
    if gp is not None and gp.has("alt_ellipsoid") and len(gp.data["timestamp"]) >= 2:
        tg = gp.times() + utc_ns
        lat_lon_h = np.column_stack([np.radians(gp.get("lat")), np.radians(gp.get("lon")),
                                     gp.get("alt_ellipsoid")])
        pos = np.column_stack([np.interp(t, tg, lat_lon_h[:, i], left=np.nan, right=np.nan)
                               for i in range(3)])
        if gp.has("eph") and gp.has("epv"):
            eph = np.interp(t, tg, gp.get("eph")) / math.sqrt(2.0)
            pos_sigma = np.column_stack([eph, eph, np.interp(t, tg, gp.get("epv"))])
        read.append("vehicle_global_position")
    for flag, cols in (("xy_valid", slice(0, 2)), ("z_valid", slice(2, 3))):
        if flag in lp.data:
            bad = ~np.asarray(lp.data[flag]).astype(bool)
            pos[bad, cols] = np.nan
    q = np.full((n, 4), np.nan)
    att = data.get("vehicle_attitude")
    if att is not None and len(att.data["timestamp"]) >= 2:
        ta = att.times() + utc_ns
        qa = np.column_stack([np.asarray(att.data[f"q[{i}]"], dtype=float) for i in range(4)])
        qa = _continuous(qa)
        q = np.column_stack([np.interp(t, ta, qa[:, i], left=np.nan, right=np.nan)
                             for i in range(4)])
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        read.append("vehicle_attitude")
    return RecordedSolution(label, f"{where}: {' + '.join(read)}", t, pos, v, q, pos_sigma,
                            vel_sigma, np.full((n, 3), np.nan))


def _continuous(q: np.ndarray) -> np.ndarray:
    """Quaternions with the sign of each chosen next to the previous one (q and -q are one
    rotation), so that interpolating between neighbours is meaningful."""
    out = q.copy()
    flip = np.sum(out[1:] * out[:-1], axis=1) < 0
    sign = np.cumprod(np.where(flip, -1.0, 1.0))
    out[1:] *= sign[:, None]
    return out

