"""References to score against: a topic of the log or a TUM / CSV file, as a truth-like stream.

The result is a :class:`~navreplay.core.streams.Stream` of kind ``truth`` holding whichever of
``pos`` (lat, lon, h), ``v_n`` (NED) and ``q_nb`` (FRD -> NED) the reference has; scoring uses
what is there (docs/real-logs.md).

Sources
-------
``nav_msgs/msg/Odometry``
    pose in ``header.frame_id`` (a local world frame: ENU, or NED when its name ends in ``_ned``
    or ``--frame reference=ned``), twist in ``child_frame_id`` (the body: FLU, or FRD when its
    name ends in ``_frd``). Gives pos, v_n, q_nb.
``geometry_msgs/msg/PoseStamped``, ``PoseWithCovarianceStamped``
    pose as above (body FLU with an ENU world, FRD with a NED one). Gives pos, q_nb.
``sensor_msgs/msg/NavSatFix``
    Gives pos (fixes with status NO_FIX dropped).
``navreplay_msgs/msg/Truth``
    A navreplay truth topic: pos, v_n, q_nb as they are.
TUM file (``.tum``, ``.txt``)
    Lines ``t x y z qx qy qz qw`` (``#`` comments): t [s] UNIX time (values below 1e9 are
    seconds since the log's start), position in a local world frame (ENU unless
    ``--frame reference=ned``), orientation body -> world (FLU body with ENU, FRD with NED).
CSV file (``.csv``)
    A header row naming the columns; ``t`` [s, UNIX or since the start as for TUM] or ``t_ns``
    [ns UNIX]; position as ``lat_deg, lon_deg, h`` or local ``x, y, z``; optional velocity
    ``v_N, v_E, v_D`` [m/s]; optional attitude ``roll_deg, pitch_deg, yaw_deg`` (FRD -> NED) or
    ``qw, qx, qy, qz`` (body -> world, as for TUM). Names with their unit in brackets, as
    ``navreplay run --export`` writes them (``stamp [ns]``, ``lat [deg]``, ``v_N [m/s]``), are
    read as ``t_ns``, ``lat_deg``, ``v_N``: an exported run (a smoothed one) is a reference.

Local positions need the geodetic position of the world origin: ``lat_deg``/``lon_deg``/``h``
of the ``[initial]`` table when given, else a fit to the log's NavSatFix stream: the origin is the
mean over all fixes inside the reference's time span of (fix - reference position at the fix
time), which averages the GNSS noise (the antenna lever arm is neglected).
"""

from __future__ import annotations

import csv
import dataclasses
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.core.streams import Recording, Stream, StreamKind, seconds
from navreplay.geo import earth
from navreplay.geo.rotations import euler_to_quat, quat_mult, quat_normalize
from navreplay.io.checks import current_policy, named_convention
from navreplay.io.convert import Convention
from navreplay.io.errors import RecordingError
from navreplay.io.files import BAGS, file_kind
from navreplay.io.gins import NAV_TYPE, file_type, read_table, seconds_to_ns
from navreplay.io.schemas import normalize_type_name
from navreplay.io.topics import sample_times
from navreplay.metrics.coverage import (  # noqa: F401  (their home is the scoring)
    COVERAGE_WARNING,
    CoverageCount,
    add_coverage,
    coverage_warning,
    reference_coverage,
)

ODOMETRY = "nav_msgs/msg/Odometry"
POSE = "geometry_msgs/msg/PoseStamped"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
NAV_SAT_FIX = "sensor_msgs/msg/NavSatFix"
TRUTH = "navreplay_msgs/msg/Truth"
REFERENCE_TYPES = (ODOMETRY, POSE, POSE_COV, NAV_SAT_FIX, TRUTH)

_NED_FROM_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_Q_NED_ENU = np.array([0.0, math.sqrt(0.5), math.sqrt(0.5), 0.0])
"""q rotating ENU vectors into NED (C = _NED_FROM_ENU), scalar first."""
_Q_FLU_FRD = np.array([0.0, 1.0, 0.0, 0.0])
"""q rotating FRD vectors into FLU (a half turn about x), scalar first."""


class ReferenceError(RecordingError):
    """A reference cannot be read or used; raised before any replay."""


@dataclasses.dataclass
class Reference:
    """A reference as columns, before it is placed on the earth.

    Attributes
    ----------
    source : str
        Topic or file, for messages.
    t_ns : ndarray (N,)
    pos : ndarray (N, 3) or None
        lat, lon [rad], h [m] (geodetic references).
    local_ned : ndarray (N, 3) or None
        Position in the local world frame, resolved NED [m] (needs an origin).
    v_n : ndarray (N, 3) or None
    q_nb : ndarray (N, 4) or None
    world : Convention or None
        The axes a local reference was read in (ENU or NED), and ``world_reason`` why.
    pos_sigma, vel_sigma, att_sigma : ndarray (N, 3) or None
        1-sigma north, east, down of position [m], velocity [m/s] and attitude [rad], where
        the messages carry a covariance (NavSatFix, Odometry, PoseWithCovarianceStamped; a
        covariance of zeros, or of unknown type, is none): what a recorded solution
        (``--onboard``) is scored against for its NEES.
    """

    source: str
    t_ns: np.ndarray
    pos: np.ndarray | None = None
    local_ned: np.ndarray | None = None
    v_n: np.ndarray | None = None
    q_nb: np.ndarray | None = None
    world: Convention | None = None
    world_reason: str = ""
    pos_sigma: np.ndarray | None = None
    vel_sigma: np.ndarray | None = None
    att_sigma: np.ndarray | None = None

    @property
    def has(self) -> tuple[str, ...]:
        """Which of pos, v_n, q_nb the reference gives."""
        have = ["pos"] if self.pos is not None or self.local_ned is not None else []
        return tuple(have + [k for k in ("v_n", "q_nb") if getattr(self, k) is not None])


def _world(frame_id: str, declared: Convention | None, source: str = ""
           ) -> tuple[Convention, str]:
    """The world axes of a local reference, and why: ``--frame reference=``, else the frame
    id (``_ned`` / ``_enu`` suffix, else ENU by REP-103). A declaration that contradicts a
    frame id naming its axes is an error unless the read policy forces frames."""
    named = named_convention(StreamKind.GPS_VEL, frame_id)  # the local-level axes it names
    if declared is not None:
        if declared not in (Convention.ENU, Convention.NED):
            raise ReferenceError(f"--frame reference={declared.value}: use enu or ned")
        if named is not None and named is not declared and not current_policy().force_frames:
            raise ReferenceError(
                f"reference {source}: --frame reference={declared.value} contradicts frame id "
                f"{frame_id!r}, which names {named.value.upper()} axes; drop the declaration, "
                "or add --force-frame to read it as declared")
        return declared, f"declared {declared.value}"
    if named is not None:
        return named, f"frame id {frame_id!r} names {named.value.upper()} axes"
    return Convention.ENU, f"frame id {frame_id!r} has no _ned suffix: ENU by REP-103"


def _body_is_frd(child: str, world: Convention) -> bool:
    name = child.lower()
    if name.endswith("_frd") or name == "frd":
        return True
    if name.endswith("_flu") or name == "flu":
        return False
    return world is Convention.NED


def to_ned(world: Convention, xyz: np.ndarray, q_wb_xyzw: np.ndarray | None, body_frd: bool
           ) -> tuple[np.ndarray, np.ndarray | None]:
    """Local positions (N, 3) and orientations (N, 4 xyzw, body -> world) to NED and q_nb
    (FRD -> NED, scalar first)."""
    xyz = np.asarray(xyz, dtype=float)
    ned = xyz @ _NED_FROM_ENU.T if world is Convention.ENU else xyz.copy()
    if q_wb_xyzw is None:
        return ned, None
    q = quat_normalize(np.asarray(q_wb_xyzw, dtype=float)[:, [3, 0, 1, 2]])
    if world is Convention.ENU:
        q = quat_mult(_Q_NED_ENU, q)
    if not body_frd:
        q = quat_mult(q, _Q_FLU_FRD)
    return ned, quat_normalize(q)


def _xyzw(o: Any) -> list[float]:
    return [o.x, o.y, o.z, o.w]


def _xyz(v: Any) -> list[float]:
    return [v.x, v.y, v.z]


def from_messages(source: str, type_name: str, items: list[tuple[int, Any]],
                  declared: Convention | None, time: str = "header") -> Reference:
    """A reference from decoded messages (log time, message) of one topic, in log-time order;
    times as ``--time`` says (:func:`navreplay.io.topics.sample_times`)."""
    _check_type(source, type_name)
    if not items:
        raise ReferenceError(f"reference {source}: the topic has no messages")
    items = sorted(items, key=lambda item: item[0])
    msgs = [m for _, m in items]
    stamps = np.array([int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec)
                       for m in msgs], dtype=np.int64)
    t_ns = sample_times(stamps, np.array([t for t, _ in items], dtype=np.int64), time,
                        f"reference {source}")
    if type_name == NAV_SAT_FIX:
        keep = np.array([m.status.status >= 0 for m in msgs])
        pos = np.array([[math.radians(m.latitude), math.radians(m.longitude), m.altitude]
                        for m in msgs])
        cov = np.array([np.asarray(m.position_covariance, dtype=float).reshape(3, 3)
                        if m.position_covariance_type > 0 else np.zeros((3, 3)) for m in msgs])
        return Reference(source, t_ns[keep], pos=pos[keep],
                         pos_sigma=_sigmas(cov[keep], Convention.ENU))
    if type_name == TRUTH:
        return Reference(source, t_ns, pos=np.array([list(m.pos) for m in msgs]),
                         v_n=np.array([list(m.v_n) for m in msgs]),
                         q_nb=np.array([list(m.q_nb) for m in msgs]))
    pose = {ODOMETRY: lambda m: m.pose.pose, POSE_COV: lambda m: m.pose.pose,
            POSE: lambda m: m.pose}[type_name]
    world, why = _world(msgs[0].header.frame_id, declared, source)
    child = getattr(msgs[0], "child_frame_id", "")
    frd = _body_is_frd(child, world)
    xyz = np.array([_xyz(pose(m).position) for m in msgs])
    q_raw = np.array([_xyzw(pose(m).orientation) for m in msgs])
    q_given = bool(np.any(np.abs(q_raw) > 0))
    local, q_nb = to_ned(world, xyz, q_raw if q_given else None, frd)
    ref = Reference(source, t_ns, local_ned=local, q_nb=q_nb, world=world, world_reason=why)
    if type_name in (ODOMETRY, POSE_COV):
        cov = np.array([np.asarray(m.pose.covariance, dtype=float).reshape(6, 6)
                        for m in msgs])
        ref.pos_sigma = _sigmas(cov[:, :3, :3], world)
        ref.att_sigma = _sigmas(cov[:, 3:, 3:], world) if q_nb is not None else None
    if type_name == ODOMETRY and q_nb is not None:
        v_b = np.array([_xyz(m.twist.twist.linear) for m in msgs])
        flip = np.diag([1.0, 1.0, 1.0] if frd else [1.0, -1.0, -1.0])
        v_b = v_b @ flip
        from navreplay.geo.rotations import quat_to_dcm

        C = quat_to_dcm(q_nb)
        ref.v_n = np.einsum("kij,kj->ki", C, v_b)
        cov_b = np.array([np.asarray(m.twist.covariance, dtype=float).reshape(6, 6)[:3, :3]
                          for m in msgs])
        cov_n = np.einsum("kij,jl,klm,mn,kpn->kip", C, flip, cov_b, flip, C)
        ref.vel_sigma = _sigmas(cov_n, Convention.NED)
    return ref


def _sigmas(cov: np.ndarray, world: Convention) -> np.ndarray | None:
    """1-sigma N, E, D of (N, 3, 3) covariances in ``world`` axes; None when none is given
    (all zeros, as ROS messages say "unknown")."""
    var = np.diagonal(cov, axis1=1, axis2=2)
    if not np.any(var > 0):
        return None
    if world is Convention.ENU:
        var = var[:, [1, 0, 2]]
    return np.sqrt(np.where(var > 0, var, np.nan))


def _check_type(source: str, type_name: str) -> None:
    if type_name not in REFERENCE_TYPES:
        raise ReferenceError(f"reference {source}: type {type_name or 'unknown'} cannot be a "
                             f"reference (use one of {', '.join(REFERENCE_TYPES)})")


def _iter_topic(path: Path, topic: str) -> tuple[str, list[tuple[int, Any]]]:
    """Type name and (log time, decoded message) of one topic of a bag or MCAP file."""
    if file_kind(path).name in BAGS:
        from navreplay.io.rosbag import bag_topics, iter_messages

        types = {t: ty for t, ty, _, _ in bag_topics(path)}
        if topic not in types:
            raise ReferenceError(f"reference {topic}: no such topic in {path} (it has "
                                 f"{', '.join(sorted(types)) or 'no topics'})")
        _check_type(topic, types[topic])
        return types[topic], list(iter_messages(path, topic))
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    items: list[tuple[int, Any]] = []
    type_name = ""
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            topics = {c.topic: normalize_type_name(summary.schemas[c.schema_id].name)
                      for c in summary.channels.values()} if summary else {}
            if topic not in topics:
                raise ReferenceError(f"reference {topic}: no such topic in {path} (it has "
                                     f"{', '.join(sorted(topics)) or 'no topics'})")
            type_name = topics[topic]
            _check_type(topic, type_name)
            for _, _, message, decoded in reader.iter_decoded_messages(topics=[topic]):
                items.append((message.log_time, decoded))
    except ReferenceError:
        raise
    except Exception as exc:
        raise ReferenceError(f"reference {topic} in {path}: cannot be read ({exc!r})") from None
    return type_name, items


def _table(path: Path, csv_header: bool
           ) -> tuple[list[str] | None, np.ndarray, np.ndarray | None]:
    """Rows of numbers of a TUM (whitespace) or CSV (a header row, commas) file; blank lines
    and ``#`` comments skipped. Every row must have the header's (or the first row's) number
    of fields, all finite numbers, and the time (``t_ns``, ``t`` or the first column) must
    increase: anything else raises :class:`ReferenceError` naming the file and line.

    Returns the header (CSV), the values and, for a ``t_ns`` column, its exact integers."""
    where = f"reference {path}"
    try:
        with open(path, newline="") as f:
            text = [(n, line.strip()) for n, line in enumerate(f, start=1) if line.strip()]
        lines = [(n, line) for n, line in text if not line.startswith("#")]
        start = lines[0][0] if lines else math.inf
        comments = [line for n, line in text if line.startswith("#") and n < start]
    except (OSError, UnicodeDecodeError) as exc:
        raise ReferenceError(f"{where}: cannot be read ({exc})") from None
    header = None
    if csv_header:
        if not lines:
            raise ReferenceError(f"{where}: no header row")
        first = lines[0][1]
        names = [c.strip() for c in next(csv.reader([first]))]
        if _numeric(names) and comments:
            # the header is the last comment line before the data (``# t, lat, lon, h``)
            names = [c.strip() for c in next(csv.reader([comments[-1].lstrip("#% ")]))]
        else:
            lines.pop(0)
        header = column_names(names, where)
    rows = (csv.reader(line for _, line in lines) if csv_header
            else (line.split() for _, line in lines))
    width = len(header) if header is not None else None
    ti = next((header.index(k) for k in ("t_ns", "t") if header and k in header), 0)
    exact = header is not None and "t_ns" in header
    out: list[list[float]] = []
    t_ns: list[int] = []
    for (n, _), fields in zip(lines, rows, strict=True):
        here = f"{where}, line {n}"
        if width is None:
            width = len(fields)
            if width != 8:
                raise ReferenceError(f"{here}: {width} columns; a TUM file has 8 "
                                     "(t x y z qx qy qz qw)")
        if len(fields) != width:
            raise ReferenceError(f"{here}: {len(fields)} columns, expected {width}")
        try:
            values = [float(v) for v in fields]
            if exact:
                t_ns.append(int(fields[ti].strip()))
                values[ti] = t_ns[-1]
        except ValueError:
            raise ReferenceError(f"{here}: not a number in {','.join(fields)!r}") from None
        bad = [header[i] if header else f"column {i + 1}"
               for i, v in enumerate(values) if not math.isfinite(v)]
        if bad:
            raise ReferenceError(f"{here}: non-finite {', '.join(bad)}")
        if out and values[ti] <= out[-1][ti]:
            raise ReferenceError(f"{here}: time {fields[ti].strip()} does not increase "
                                 "(it must, row after row)")
        out.append(values)
    if len(out) < 2:
        raise ReferenceError(f"{where}: fewer than 2 rows")
    return header, np.array(out), np.array(t_ns, dtype=np.int64) if exact else None


COLUMN_NAMES: dict[str, tuple[str, ...]] = {
    "t_ns": ("t_ns", "time_ns", "timestamp_ns", "stamp_ns", "%time"),
    "t": ("t", "time", "timestamp", "stamp", "t_s", "time_s"),
    "lat_deg": ("lat_deg", "lat", "latitude", "latitude_deg"),
    "lon_deg": ("lon_deg", "lon", "lng", "long", "longitude", "longitude_deg"),
    "h": ("h", "h_m", "alt", "alt_m", "altitude", "height", "height_m", "h_ell"),
    "x": ("x", "x_m", "pos_x", "px", "tx"),
    "y": ("y", "y_m", "pos_y", "py", "ty"),
    "z": ("z", "z_m", "pos_z", "pz", "tz"),
    "v_N": ("v_n", "vn", "vel_n", "vel_north", "v_north"),
    "v_E": ("v_e", "ve", "vel_e", "vel_east", "v_east"),
    "v_D": ("v_d", "vd", "vel_d", "vel_down", "v_down"),
    "roll_deg": ("roll_deg", "roll"),
    "pitch_deg": ("pitch_deg", "pitch"),
    "yaw_deg": ("yaw_deg", "yaw", "heading", "heading_deg"),
    "qw": ("qw", "q_w", "quat_w", "ori_w"),
    "qx": ("qx", "q_x", "quat_x", "ori_x"),
    "qy": ("qy", "q_y", "quat_y", "ori_y"),
    "qz": ("qz", "q_z", "quat_z", "ori_z"),
}
"""The CSV reference columns and the names each is recognised by (compared in lower case,
a trailing unit in brackets or parentheses dropped: ``lat [deg]``, ``Altitude(m)``; a time
in ``[ns]`` is ``t_ns``); other
columns are ignored."""

_ALIASES = {alias: name for name, aliases in COLUMN_NAMES.items() for alias in aliases}


def column_names(names: list[str], where: str) -> list[str]:
    """A CSV header's names as :data:`COLUMN_NAMES` (others kept as they are); two columns for
    the same quantity are an error."""
    out: list[str] = []
    seen: dict[str, str] = {}
    for raw in names:
        m = re.fullmatch(r"(.*?)\s*[\[(](.*)[\])]", raw.strip())
        key, unit = (m.group(1), m.group(2).strip().lower()) if m else (raw.strip(), "")
        name = _ALIASES.get(key.strip().lower(), raw.strip())
        if name == "t" and unit == "ns":  # ``stamp [ns]``, as navreplay's exports write it
            name = "t_ns"
        if name in seen:
            raise ReferenceError(f"{where}: columns {seen[name]!r} and {raw!r} both give {name}")
        seen[name] = raw
        out.append(name)
    return out


def _numeric(fields: list[str]) -> bool:
    try:
        [float(f) for f in fields]
    except ValueError:
        return False
    return True


def _times(t: np.ndarray, t0_ns: int) -> np.ndarray:
    """Seconds (UNIX, or since the log start when below 1e9) -> int64 ns."""
    if t.size and np.nanmax(np.abs(t)) < 1e9:
        return np.int64(t0_ns) + np.rint(t * 1e9).astype(np.int64)
    return np.rint(t * 1e9).astype(np.int64)


def from_file(path: Path, t0_ns: int, declared: Convention | None) -> Reference:
    """A reference from a TUM or CSV file (module docstring)."""
    is_csv = path.suffix.lower() == ".csv"
    header, data, t_ns = _table(path, is_csv)
    if header is not None:
        cols = {k: data[:, i] for i, k in enumerate(header)}
        if t_ns is not None:
            cols["t_ns"] = t_ns
        return _from_columns(f"reference {path}", cols, t0_ns, declared)
    world = declared or Convention.ENU
    local, q_nb = to_ned(world, data[:, 1:4], data[:, 4:8], world is Convention.NED)
    return Reference(str(path), _times(data[:, 0], t0_ns), local_ned=local, q_nb=q_nb,
                     world=world, world_reason=_file_world(declared))


def from_gins_nav(path: Path) -> Reference:
    """A reference from a GINS navigation file (week, seconds of week, lat, lon [deg], h [m],
    v north, east, down [m/s], roll, pitch, yaw [deg]: :mod:`navreplay.io.gins`), on the
    seconds of the week as the GINS logs are."""
    try:
        data = read_table(path, 11)
    except RecordingError as exc:
        raise ReferenceError(f"reference {exc}") from None
    if len(data) < 2:
        raise ReferenceError(f"reference {path}: fewer than 2 rows")
    return Reference(str(path), seconds_to_ns(data[:, 1]),
                     pos=np.column_stack([np.radians(data[:, 2]), np.radians(data[:, 3]),
                                          data[:, 4]]),
                     v_n=data[:, 5:8].copy(), q_nb=euler_to_quat(np.radians(data[:, 8:11])))


def _file_world(declared: Convention | None) -> str:
    return (f"declared {declared.value}" if declared is not None
            else "a file's local frame is ENU unless --frame reference=ned")


def _from_columns(where: str, c: Mapping[str, np.ndarray], t0_ns: int,
                  declared: Convention | None) -> Reference:
    if "t_ns" in c:
        t_ns = np.asarray(c["t_ns"]).astype(np.int64)
    elif "t" in c:
        t_ns = _times(c["t"], t0_ns)
    else:
        raise ReferenceError(f"{where}: needs a column t [s] or t_ns [ns]; has {', '.join(c)}")
    ref = Reference(where.removeprefix("reference "), t_ns)
    world = declared or Convention.ENU
    if {"lat_deg", "lon_deg", "h"} <= set(c):
        ref.pos = np.stack([np.radians(c["lat_deg"]), np.radians(c["lon_deg"]), c["h"]], axis=1)
    elif {"x", "y", "z"} <= set(c):
        ref.local_ned = to_ned(world, np.stack([c["x"], c["y"], c["z"]], axis=1), None,
                               False)[0]
        ref.world, ref.world_reason = world, _file_world(declared)
    if {"v_N", "v_E", "v_D"} <= set(c):
        ref.v_n = np.stack([c["v_N"], c["v_E"], c["v_D"]], axis=1)
    if {"roll_deg", "pitch_deg", "yaw_deg"} <= set(c):
        ref.q_nb = euler_to_quat(np.radians(np.stack(
            [c["roll_deg"], c["pitch_deg"], c["yaw_deg"]], axis=1)))
    elif {"qw", "qx", "qy", "qz"} <= set(c):
        q = np.stack([c["qx"], c["qy"], c["qz"], c["qw"]], axis=1)
        ref.q_nb = to_ned(world, np.zeros((len(q), 3)), q, world is Convention.NED)[1]
    if not ref.has:
        raise ReferenceError(f"{where}: no position, velocity or attitude columns (see "
                             "docs/real-logs.md); has " + ", ".join(c))
    return ref


def read_reference(spec: str, log: Path, recording: Recording,
                   declared: Convention | None, time: str = "header") -> Reference:
    """Read ``spec`` (a file when one exists by that name, else a topic of ``log``)."""
    path = Path(spec)
    folder = log if log.is_dir() else log.parent
    if not path.exists() and not spec.startswith("/") and (folder / spec).is_file():
        path = folder / spec  # a file of the log's folder (a GINS truth file), by its name
    if path.is_file() and file_type(path) == NAV_TYPE:
        return from_gins_nav(path)
    if path.is_file() and path.suffix.lower() in (".csv", ".tum", ".txt"):
        return from_file(path, recording.t0_ns, declared)
    if not spec.startswith("/") and not path.exists():
        raise ReferenceError(f"reference {spec}: no such file, and not a topic (topics start "
                             "with '/')")
    type_name, items = _iter_topic(log, spec)
    return from_messages(spec, type_name, items, declared, time)


def origin_from_gnss(ref: Reference, recording: Recording) -> np.ndarray:
    """Geodetic origin (lat, lon, h) of a local reference fitted to the GNSS fixes."""
    assert ref.local_ned is not None  # a local reference
    return _gnss_fit(ref, ref.local_ned, recording)[0]


def _gnss_fit(ref: Reference, local_ned: np.ndarray, recording: Recording
              ) -> tuple[np.ndarray, float]:
    """The origin fitted to the GNSS fixes inside the reference's span, and the RMS [m] of
    what the fixes and the placed reference still differ by."""
    gps = recording[StreamKind.GPS]
    t_ref = seconds(ref.t_ns, recording.t0_ns)
    t_fix = seconds(gps.t_ns, recording.t0_ns)
    inside = (t_fix >= t_ref[0]) & (t_fix <= t_ref[-1])
    if not inside.any():
        raise ReferenceError(f"reference {ref.source}: no GNSS fix inside its time span to "
                             "place its local origin; give lat_deg, lon_deg, h in [initial]")
    d = np.stack([np.interp(t_fix[inside], t_ref, local_ned[:, i]) for i in range(3)], 1)
    fixes = gps["pos"][inside]
    origin = fixes[0] - 0.0
    r = earth.lla_to_ecef(*fixes.T)
    for _ in range(3):
        C = earth.C_en(origin[0], origin[1])
        r0 = r - d @ C.T
        origin = np.array(earth.ecef_to_lla(r0.mean(axis=0)))
    residual = r0 - r0.mean(axis=0)
    return origin, float(np.sqrt(np.mean(np.sum(residual**2, axis=1))))


FRAME_FIT_MIN = 10.0
"""A local reference fitted to the GNSS fixes with a residual RMS above this [m], and above
:data:`FRAME_FIT_RATIO` times the residual in the other world axes, is read in the wrong axes."""
FRAME_FIT_RATIO = 5.0


def _check_world(ref: Reference, recording: Recording, rms: float) -> None:
    """Raise when the reference's positions fit the GNSS fixes in the other world axes and not
    in those it was read in (ENU data read as NED, or the reverse), unless frames are forced."""
    if ref.world is None or ref.local_ned is None or rms <= FRAME_FIT_MIN:
        return
    other = Convention.NED if ref.world is Convention.ENU else Convention.ENU
    swapped = ref.local_ned[:, [1, 0, 2]] * np.array([1.0, 1.0, -1.0])  # the other reading
    rms_other = _gnss_fit(ref, swapped, recording)[1]
    if rms > FRAME_FIT_RATIO * rms_other and not current_policy().force_frames:
        raise ReferenceError(
            f"reference {ref.source}: read as {ref.world.value.upper()} ({ref.world_reason}) "
            f"its positions miss the GNSS fixes by {rms:.1f} m RMS, read as "
            f"{other.value.upper()} by {rms_other:.1f} m: use --frame reference={other.value} "
            "(or --force-frame to keep the reading)")


def reference_stream(ref: Reference, recording: Recording, initial: Mapping[str, Any]
                     ) -> tuple[Stream, str]:
    """The reference as a truth stream, and one line saying what it holds and how it was
    placed."""
    note = ""
    pos = ref.pos
    if ref.local_ned is not None:
        if "lat_deg" in initial and "lon_deg" in initial:
            origin = np.array([math.radians(initial["lat_deg"]), math.radians(initial["lon_deg"]),
                               float(initial.get("h", 0.0))])
            how = "[initial] lat_deg, lon_deg, h"
        elif StreamKind.GPS in recording:
            origin, rms = _gnss_fit(ref, ref.local_ned, recording)
            _check_world(ref, recording, rms)
            how = (f"a fit to {len(recording[StreamKind.GPS])} GNSS fixes, {rms:.1f} m RMS "
                   "apart")
        else:
            raise ReferenceError(
                f"reference {ref.source}: local positions need an origin: a NavSatFix topic "
                "in the log, or lat_deg, lon_deg, h in [initial]")
        lat, lon, h = earth.ned_offset_to_lla(origin[0], origin[1], origin[2], ref.local_ned)
        pos = np.stack([lat, lon, h], axis=1)
        note = (f" (local origin {math.degrees(origin[0]):.7f} deg, "
                f"{math.degrees(origin[1]):.7f} deg, {origin[2]:.2f} m from {how})")
    cols = {k: v for k, v in (("pos", pos), ("v_n", ref.v_n), ("q_nb", ref.q_nb))
            if v is not None}
    order = np.argsort(ref.t_ns, kind="stable")
    t_ns = ref.t_ns[order]
    keep = np.append(True, np.diff(t_ns) > 0)
    stream = Stream(StreamKind.TRUTH, t_ns[keep], {k: v[order][keep] for k, v in cols.items()},
                    "ned")
    bad = [k for k, v in stream.columns.items() if not np.isfinite(v).all()]
    if bad or len(stream) < 2:
        raise ReferenceError(f"reference {ref.source}: "
                             + (f"non-finite {', '.join(bad)}" if bad else "fewer than 2 samples"))
    lacks = [PARTS[k] for k in PARTS if k not in ref.has]
    said = f"; no {' or '.join(lacks)}: not scored, not drawn" if lacks else ""
    return stream, f"reference {ref.source}: {', '.join(ref.has)}{note}{said}"


PARTS = {"pos": "position", "v_n": "velocity", "q_nb": "attitude"}
"""The parts a reference may give, by column."""
