"""What the estimates MCAP holds beside the Odometry topics, for Foxglove and ROS tools: a
``sensor_msgs/msg/NavSatFix`` per filter (the Map panel), ``tf2_msgs/msg/TFMessage`` on
``/tf`` (``map`` -> ``<filter>/base_link`` per filter, the 3D panel), each encoded in bulk as
CDR like the Odometry messages; and a Foxglove layout (3D, Map and Plot panels of the filters)
written beside the MCAP."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from navreplay.export.frames import BODY_FRAME, WORLD_FRAME, Poses
from navreplay.export.odometry import _SEP, _aligned

NAVSATFIX_TYPE = "sensor_msgs/msg/NavSatFix"
TF_TYPE = "tf2_msgs/msg/TFMessage"
TF_TOPIC = "/tf"

COVARIANCE_TYPE_UNKNOWN = 0
COVARIANCE_TYPE_KNOWN = 3
STATUS_FIX = 0
SERVICE_GPS = 1

_HEADER = [_SEP, "MSG: std_msgs/Header", "builtin_interfaces/Time stamp", "string frame_id",
           _SEP, "MSG: builtin_interfaces/Time", "int32 sec", "uint32 nanosec"]

NAVSATFIX_SCHEMA = "\n".join([
    "std_msgs/Header header",
    "sensor_msgs/NavSatStatus status",
    "float64 latitude", "float64 longitude", "float64 altitude",
    "float64[9] position_covariance",
    "uint8 position_covariance_type",
    *_HEADER,
    _SEP, "MSG: sensor_msgs/NavSatStatus",
    "int8 status", "uint16 service",
]) + "\n"
"""ros2msg schema text of sensor_msgs/msg/NavSatFix with its dependencies."""

TF_SCHEMA = "\n".join([
    "geometry_msgs/TransformStamped[] transforms",
    _SEP, "MSG: geometry_msgs/TransformStamped",
    "std_msgs/Header header", "string child_frame_id", "geometry_msgs/Transform transform",
    *_HEADER,
    _SEP, "MSG: geometry_msgs/Transform",
    "geometry_msgs/Vector3 translation", "geometry_msgs/Quaternion rotation",
    _SEP, "MSG: geometry_msgs/Vector3", "float64 x", "float64 y", "float64 z",
    _SEP, "MSG: geometry_msgs/Quaternion", "float64 x", "float64 y", "float64 z", "float64 w",
]) + "\n"
"""ros2msg schema text of tf2_msgs/msg/TFMessage with its dependencies."""


@dataclasses.dataclass(frozen=True)
class Topic:
    """A stream of messages of the estimates MCAP, made from one source's poses.

    ``key`` names the stream (unique), ``name`` the MCAP channel's topic: the /tf streams of
    several filters share one topic."""

    key: str
    name: str
    type: str
    schema: str
    encode: Callable[[Poses], np.ndarray]


def _header(frame_len: int) -> tuple[list[str], list[Any], list[int], int]:
    names = ["encap", "sec", "nanosec", "frame_len", "frame_id"]
    formats: list[Any] = [("u1", (4,)), "<i4", "<u4", "<u4", f"S{frame_len}"]
    return names, formats, [0, 4, 8, 12, 16], 16 + frame_len


def navsatfix_dtype(frame_len: int) -> np.dtype:
    """Fixed CDR layout of sensor_msgs/msg/NavSatFix for a frame id of ``frame_len`` bytes
    (NUL included)."""
    names, formats, offsets, pos = _header(frame_len)
    names += ["status", "service"]
    formats += ["i1", "<u2"]
    offsets += [pos, _aligned(pos + 1, 2)]
    pos = _aligned(_aligned(pos + 1, 2) + 2, 8)
    for name, count in (("lla", 3), ("covariance", 9)):
        names.append(name)
        formats.append(("<f8", (count,)))
        offsets.append(pos)
        pos += 8 * count
    names.append("covariance_type")
    formats.append("u1")
    offsets.append(pos)
    return np.dtype({"names": names, "formats": formats, "offsets": offsets,
                     "itemsize": pos + 1})


def encode_navsatfix(poses: Poses, frame_id: str) -> np.ndarray:
    """CDR records (M,) of NavSatFix: latitude and longitude [deg], height above the WGS84
    ellipsoid [m], the position covariance in the ENU frame at the vehicle [m^2] (known, or
    unknown and zero where the filter holds no variance)."""
    from navreplay.io.cdr import ENCAPSULATION_LE, split_time

    assert poses.lla is not None and poses.fix_cov is not None
    f = frame_id.encode()
    rec = np.zeros(len(poses.stamps_ns), dtype=navsatfix_dtype(len(f) + 1))
    rec["encap"] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)
    rec["sec"], rec["nanosec"] = split_time(poses.stamps_ns)
    rec["frame_len"], rec["frame_id"] = len(f) + 1, f
    rec["status"], rec["service"] = STATUS_FIX, SERVICE_GPS
    rec["lla"] = np.column_stack([np.degrees(poses.lla[:, 0]), np.degrees(poses.lla[:, 1]),
                                  poses.lla[:, 2]])
    known = np.isfinite(poses.fix_cov).all(axis=(1, 2))
    rec["covariance"] = np.where(known[:, None], np.nan_to_num(poses.fix_cov).reshape(-1, 9),
                                 0.0)
    rec["covariance_type"] = np.where(known, COVARIANCE_TYPE_KNOWN, COVARIANCE_TYPE_UNKNOWN)
    return rec


def tf_dtype(frame_len: int, child_len: int) -> np.dtype:
    """Fixed CDR layout of a TFMessage holding one TransformStamped."""
    names = ["encap", "count", "sec", "nanosec", "frame_len", "frame_id"]
    formats: list[Any] = [("u1", (4,)), "<u4", "<i4", "<u4", "<u4", f"S{frame_len}"]
    offsets = [0, 4, 8, 12, 16, 20]
    pos = _aligned(20 + frame_len, 4)
    names += ["child_len", "child_frame_id"]
    formats += ["<u4", f"S{child_len}"]
    offsets += [pos, pos + 4]
    pos = _aligned(pos + 4 + child_len, 8)
    names += ["translation", "rotation"]
    formats += [("<f8", (3,)), ("<f8", (4,))]
    offsets += [pos, pos + 24]
    return np.dtype({"names": names, "formats": formats, "offsets": offsets,
                     "itemsize": pos + 56})


def encode_tf(poses: Poses, parent: str, child: str) -> np.ndarray:
    """CDR records (M,) of TFMessage, each one transform ``parent`` -> ``child`` (the pose)."""
    from navreplay.io.cdr import ENCAPSULATION_LE, split_time

    f, c = parent.encode(), child.encode()
    rec = np.zeros(len(poses.stamps_ns), dtype=tf_dtype(len(f) + 1, len(c) + 1))
    rec["encap"] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)
    rec["count"] = 1
    rec["sec"], rec["nanosec"] = split_time(poses.stamps_ns)
    rec["frame_len"], rec["frame_id"] = len(f) + 1, f
    rec["child_len"], rec["child_frame_id"] = len(c) + 1, c
    rec["translation"] = poses.p_enu
    rec["rotation"] = poses.q_xyzw
    return rec


def body_frame(segment: str) -> str:
    """A filter's body frame in /tf: ``<segment>/base_link`` (``gps_ins/base_link``)."""
    return f"{segment}/{BODY_FRAME}"


def topics_of(segment: str, root: str) -> list[Topic]:
    """The Odometry, NavSatFix and /tf streams of one source (a filter's topic segment under
    ``/estimates``, or the reference at ``/reference``)."""
    from navreplay.export.odometry import _ODOMETRY_SCHEMA, ODOMETRY_TYPE, encode_odometry

    child = body_frame(segment)
    return [
        Topic(f"{root}/odom", f"{root}/odom", ODOMETRY_TYPE, _ODOMETRY_SCHEMA, encode_odometry),
        Topic(f"{root}/fix", f"{root}/fix", NAVSATFIX_TYPE, NAVSATFIX_SCHEMA,
              lambda p: encode_navsatfix(p, child)),
        Topic(f"{TF_TOPIC} {child}", TF_TOPIC, TF_TYPE, TF_SCHEMA,
              lambda p: encode_tf(p, WORLD_FRAME, child)),
    ]


def layout(mcap_name: str, sources: Sequence[tuple[str, str, tuple[int, int, int]]]
           ) -> dict[str, Any]:
    """A Foxglove layout for the estimates MCAP: a 3D panel (``map`` frame, the filters' body
    frames and Odometry poses), a Map panel (each NavSatFix in its filter's colour) and Plot
    panels of the positions east and north and of the horizontal position sigma.

    ``sources``: (label, topic root, colour) per filter and the reference."""
    def hex_color(c: tuple[int, int, int]) -> str:
        return "#{:02x}{:02x}{:02x}".format(*c)

    topics3d = {f"{root}/odom": {"visible": True, "color": hex_color(color) + "ff",
                                 "type": "arrow"} for _, root, color in sources}
    plots = {
        f"Plot!{name}": {
            "title": f"position {axis} ({name}) in map [m]",
            "paths": [{"value": f"{root}/odom.pose.pose.position.{axis}", "enabled": True,
                       "timestampMethod": "headerStamp", "color": hex_color(color),
                       "label": label} for label, root, color in sources],
            "showLegend": True, "legendDisplay": "top", "isSynced": True,
        }
        for axis, name in (("x", "east"), ("y", "north"))
    }
    configs: dict[str, Any] = {
        "3D!estimates": {
            "followTf": WORLD_FRAME,
            "scene": {"transforms": {"showLabel": True}},
            "topics": topics3d,
            "layers": {"grid": {"layerId": "foxglove.Grid", "frameId": WORLD_FRAME,
                                "size": 1000, "divisions": 20, "visible": True}},
        },
        "map!estimates": {
            "layer": "map",
            "topicColors": {f"{root}/fix": hex_color(color) for _, root, color in sources},
            "disabledTopics": [],
        },
        **plots,
    }
    return {
        "configById": configs,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": {
            "direction": "row",
            "first": {"direction": "column", "first": "3D!estimates",
                      "second": "map!estimates", "splitPercentage": 60},
            "second": {"direction": "column", "first": "Plot!east", "second": "Plot!north"},
            "splitPercentage": 60,
        },
        "navreplay": {"mcap": mcap_name,
                      "note": "open the MCAP, then import this layout (Layouts > Import)"},
    }
