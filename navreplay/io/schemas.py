"""Topics and message schemas of a navreplay recording.

One topic per :class:`~navreplay.core.streams.StreamKind`. Standard ROS 2 messages are used where
their meaning matches exactly; project messages (package ``navreplay_msgs``) carry what none fits.
Every message starts with a ``std_msgs/Header`` whose stamp is the sample time (equal to the MCAP
log time) and whose ``frame_id`` names the frame (REP-103 ``_frd`` / ``_ned`` suffixes).

The definitions below are the exact ``ros2msg`` schema texts written to the file (the message
definition followed by its dependencies, each after a line of 80 ``=`` and ``MSG: pkg/Type``), and
the flat field layouts (:class:`Leaf`) that :mod:`navreplay.io.cdr` turns into numpy structured
dtypes. docs/recording-format.md documents them for people.
"""

from __future__ import annotations

import dataclasses

from navreplay.core.streams import StreamKind

PROFILE = "ros2"
"""MCAP profile of a recording."""
MESSAGE_ENCODING = "cdr"
"""MCAP message encoding (ROS 2 CDR, little endian)."""
SCHEMA_ENCODING = "ros2msg"
"""MCAP schema encoding."""
METADATA_NAME = "navreplay"
"""Name of the MCAP metadata record holding :class:`~navreplay.core.streams.Metadata`."""
FORMAT_VERSION = "1"
"""Version of this layout, stored in the metadata record under ``format_version``."""

_SEPARATOR = "=" * 80

# ---------------------------------------------------------------------------------------------
# Message definitions (ros2msg text). Standard ROS 2 types are written without comments; the
# project types carry their units and frames in comments so that viewers show them.

_TIME = """\
int32 sec
uint32 nanosec
"""

_HEADER = """\
builtin_interfaces/Time stamp
string frame_id
"""

_VECTOR3 = """\
float64 x
float64 y
float64 z
"""

_QUATERNION = """\
float64 x
float64 y
float64 z
float64 w
"""

_IMU = """\
std_msgs/Header header
geometry_msgs/Quaternion orientation
float64[9] orientation_covariance
geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance
geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance
"""

_NAV_SAT_STATUS = """\
int8 STATUS_NO_FIX = -1
int8 STATUS_FIX = 0
int8 STATUS_SBAS_FIX = 1
int8 STATUS_GBAS_FIX = 2
int8 status
uint16 SERVICE_GPS = 1
uint16 SERVICE_GLONASS = 2
uint16 SERVICE_COMPASS = 4
uint16 SERVICE_GALILEO = 8
uint16 service
"""

_NAV_SAT_FIX = """\
std_msgs/Header header
sensor_msgs/NavSatStatus status
float64 latitude
float64 longitude
float64 altitude
float64[9] position_covariance
uint8 COVARIANCE_TYPE_UNKNOWN = 0
uint8 COVARIANCE_TYPE_APPROXIMATED = 1
uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN = 2
uint8 COVARIANCE_TYPE_KNOWN = 3
uint8 position_covariance_type
"""

_MAGNETIC_FIELD = """\
std_msgs/Header header
geometry_msgs/Vector3 magnetic_field
float64[9] magnetic_field_covariance
"""

_TWIST = """\
geometry_msgs/Vector3 linear
geometry_msgs/Vector3 angular
"""

_TWIST_WITH_COVARIANCE = """\
geometry_msgs/Twist twist
float64[36] covariance
"""

_TWIST_WITH_COVARIANCE_STAMPED = """\
std_msgs/Header header
geometry_msgs/TwistWithCovariance twist
"""

MASTER_INS_MSG = """\
# Navigation solution of a master (reference) INS.
# header.stamp: time of validity; header.frame_id: "ned" (v_n is resolved in the local NED frame).
std_msgs/Header header
float64[3] euler   # roll, pitch, yaw (ZYX) of the master's body frame (FRD) w.r.t. NED [rad]
float64[3] v_n     # velocity north, east, down [m/s]
float64 latitude   # geodetic latitude, WGS84 [rad]
float64 longitude  # longitude, WGS84 [rad]
float64 height     # height above the WGS84 ellipsoid [m]
"""

SPEED_LOG_MSG = """\
# Propeller shaft speed from a speed log.
# header.frame_id: "speed_log".
std_msgs/Header header
float64 rpm  # shaft speed [rev/min]
"""

DEPTH_MSG = """\
# Depth of the vehicle below the water surface.
# header.frame_id: "depth".
std_msgs/Header header
float64 depth  # depth below the surface, positive down [m]
"""

TRUTH_MSG = """\
# Simulated true navigation state.
# header.frame_id: "ned" (v_n is resolved in the local NED frame).
std_msgs/Header header
float64 latitude   # geodetic latitude, WGS84 [rad]
float64 longitude  # longitude, WGS84 [rad]
float64 height     # height above the WGS84 ellipsoid [m]
float64[3] v_n     # ground velocity north, east, down [m/s]
float64[4] q_nb    # attitude quaternion body (FRD) -> NED, Hamilton, scalar first [w, x, y, z]
float64[] aux      # scenario-specific true quantities, flattened row-major in the order and
                   # with the shapes listed in the "truth_columns" metadata key (SI units);
                   # every message of a recording has the same length
"""

_DEFINITIONS: dict[str, str] = {
    "builtin_interfaces/Time": _TIME,
    "std_msgs/Header": _HEADER,
    "geometry_msgs/Vector3": _VECTOR3,
    "geometry_msgs/Quaternion": _QUATERNION,
    "geometry_msgs/Twist": _TWIST,
    "geometry_msgs/TwistWithCovariance": _TWIST_WITH_COVARIANCE,
    "geometry_msgs/TwistWithCovarianceStamped": _TWIST_WITH_COVARIANCE_STAMPED,
    "sensor_msgs/Imu": _IMU,
    "sensor_msgs/NavSatStatus": _NAV_SAT_STATUS,
    "sensor_msgs/NavSatFix": _NAV_SAT_FIX,
    "sensor_msgs/MagneticField": _MAGNETIC_FIELD,
    "navreplay_msgs/MasterIns": MASTER_INS_MSG,
    "navreplay_msgs/SpeedLog": SPEED_LOG_MSG,
    "navreplay_msgs/Depth": DEPTH_MSG,
    "navreplay_msgs/Truth": TRUTH_MSG,
}

_DEPENDENCIES: dict[str, tuple[str, ...]] = {
    "sensor_msgs/Imu": (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Quaternion",
        "geometry_msgs/Vector3",
    ),
    "sensor_msgs/NavSatFix": (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "sensor_msgs/NavSatStatus",
    ),
    "sensor_msgs/MagneticField": (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Vector3",
    ),
    "geometry_msgs/TwistWithCovarianceStamped": (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3",
    ),
    "navreplay_msgs/MasterIns": ("std_msgs/Header", "builtin_interfaces/Time"),
    "navreplay_msgs/SpeedLog": ("std_msgs/Header", "builtin_interfaces/Time"),
    "navreplay_msgs/Depth": ("std_msgs/Header", "builtin_interfaces/Time"),
    "navreplay_msgs/Truth": ("std_msgs/Header", "builtin_interfaces/Time"),
}


def normalize_type_name(name: str) -> str:
    """``pkg/msg/Type`` for ``pkg/Type`` or ``pkg/msg/Type``; other names unchanged."""
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name


def _short(name: str) -> str:
    pkg, _, typ = name.split("/")
    return f"{pkg}/{typ}"


def schema_text(type_name: str) -> str:
    """The ``ros2msg`` schema text of a message type, with its dependencies appended.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type`` (or ``pkg/Type``) of one of the recording's message types.
    """
    short = _short(normalize_type_name(type_name))
    parts = [_DEFINITIONS[short]]
    for dep in _DEPENDENCIES[short]:
        parts.append(f"{_SEPARATOR}\nMSG: {dep}\n{_DEFINITIONS[dep]}")
    return "".join(parts)


# ---------------------------------------------------------------------------------------------
# Flat layouts. Every message starts with std_msgs/Header (stamp.sec int32, stamp.nanosec uint32,
# frame_id string), handled by navreplay.io.cdr; the leaves list the fields after it, in wire
# order. A leaf groups `count` consecutive values of one primitive type.


@dataclasses.dataclass(frozen=True)
class Leaf:
    """Consecutive primitive values of one message, seen as one column of a structured dtype.

    Attributes
    ----------
    name : str
        Field name in the structured dtype.
    ctype : str
        numpy type code of one value: ``"f8"``, ``"i1"``, ``"u1"``, ``"u2"``, ``"i4"``, ``"u4"``.
    paths : tuple[str, ...]
        Attribute paths in a decoded message: ``count`` scalar paths, or one path to a fixed-size
        array of ``count`` values.
    count : int
        Number of values (1 for a scalar).
    """

    name: str
    ctype: str
    paths: tuple[str, ...]
    count: int = 1

    @property
    def size(self) -> int:
        """Bytes of one value (also its CDR alignment)."""
        return int(self.ctype[1])


def _vec(name: str, path: str, axes: str = "xyz") -> Leaf:
    return Leaf(name, "f8", tuple(f"{path}.{a}" for a in axes), len(axes))


def _arr(name: str, path: str, count: int) -> Leaf:
    return Leaf(name, "f8", (path,), count)


def _f8(name: str, path: str) -> Leaf:
    return Leaf(name, "f8", (path,))


@dataclasses.dataclass(frozen=True)
class MessageType:
    """A message type of a recording: its name, schema text and flat layout.

    Attributes
    ----------
    name : str
        ``pkg/msg/Type``.
    leaves : tuple[Leaf, ...]
        Fields after the header, in wire order.
    sequence : Leaf | None
        A trailing unbounded ``float64[]`` (its length is fixed per layout), or None.
    """

    name: str
    leaves: tuple[Leaf, ...]
    sequence: Leaf | None = None

    @property
    def schema_text(self) -> str:
        """The ``ros2msg`` schema text written to the file."""
        return schema_text(self.name)


IMU_TYPE = MessageType(
    "sensor_msgs/msg/Imu",
    (
        _vec("orientation", "orientation", "xyzw"),
        _arr("orientation_covariance", "orientation_covariance", 9),
        _vec("angular_velocity", "angular_velocity"),
        _arr("angular_velocity_covariance", "angular_velocity_covariance", 9),
        _vec("linear_acceleration", "linear_acceleration"),
        _arr("linear_acceleration_covariance", "linear_acceleration_covariance", 9),
    ),
)
NAV_SAT_FIX_TYPE = MessageType(
    "sensor_msgs/msg/NavSatFix",
    (
        Leaf("status", "i1", ("status.status",)),
        Leaf("service", "u2", ("status.service",)),
        _f8("latitude", "latitude"),
        _f8("longitude", "longitude"),
        _f8("altitude", "altitude"),
        _arr("position_covariance", "position_covariance", 9),
        Leaf("position_covariance_type", "u1", ("position_covariance_type",)),
    ),
)
TWIST_TYPE = MessageType(
    "geometry_msgs/msg/TwistWithCovarianceStamped",
    (
        _vec("linear", "twist.twist.linear"),
        _vec("angular", "twist.twist.angular"),
        _arr("covariance", "twist.covariance", 36),
    ),
)
MAGNETIC_FIELD_TYPE = MessageType(
    "sensor_msgs/msg/MagneticField",
    (
        _vec("magnetic_field", "magnetic_field"),
        _arr("magnetic_field_covariance", "magnetic_field_covariance", 9),
    ),
)
MASTER_INS_TYPE = MessageType(
    "navreplay_msgs/msg/MasterIns",
    (
        _arr("euler", "euler", 3),
        _arr("v_n", "v_n", 3),
        Leaf("pos", "f8", ("latitude", "longitude", "height"), 3),
    ),
)
SPEED_LOG_TYPE = MessageType("navreplay_msgs/msg/SpeedLog", (_f8("rpm", "rpm"),))
DEPTH_TYPE = MessageType("navreplay_msgs/msg/Depth", (_f8("depth", "depth"),))
TRUTH_TYPE = MessageType(
    "navreplay_msgs/msg/Truth",
    (
        Leaf("pos", "f8", ("latitude", "longitude", "height"), 3),
        _arr("v_n", "v_n", 3),
        _arr("q_nb", "q_nb", 4),
    ),
    sequence=Leaf("aux", "f8", ("aux",)),
)


@dataclasses.dataclass(frozen=True)
class TopicSpec:
    """Where and how one stream kind is written.

    Attributes
    ----------
    kind : StreamKind
    topic : str
        MCAP channel topic.
    message : MessageType
    frame_id : str
        ``header.frame_id`` written when the stream's own ``frame_id`` is empty.
    by_schema : bool
        Whether a foreign file's topic of this message type may be taken for this kind when the
        canonical topic is absent (False where the type is too generic to tell, e.g. a twist).
    """

    kind: StreamKind
    topic: str
    message: MessageType
    frame_id: str
    by_schema: bool = True


SPECS: dict[StreamKind, TopicSpec] = {
    s.kind: s
    for s in (
        TopicSpec(StreamKind.IMU, "/imu", IMU_TYPE, "imu_frd"),
        TopicSpec(StreamKind.MASTER_INS, "/master_ins", MASTER_INS_TYPE, "ned"),
        TopicSpec(StreamKind.GPS, "/gps/fix", NAV_SAT_FIX_TYPE, "gps_antenna"),
        TopicSpec(StreamKind.GPS_VEL, "/gps/vel", TWIST_TYPE, "ned", by_schema=False),
        TopicSpec(StreamKind.MAG, "/mag", MAGNETIC_FIELD_TYPE, "mag_frd"),
        TopicSpec(StreamKind.SPEED_LOG, "/speed_log", SPEED_LOG_TYPE, "speed_log"),
        TopicSpec(StreamKind.DEPTH, "/depth", DEPTH_TYPE, "depth"),
        TopicSpec(StreamKind.TRUTH, "/truth", TRUTH_TYPE, "ned"),
    )
}
"""Topic, message type and default frame per stream kind, in StreamKind order."""

TOPICS: dict[StreamKind, str] = {kind: spec.topic for kind, spec in SPECS.items()}
"""Topic name per stream kind."""

KIND_BY_TYPE: dict[str, StreamKind] = {spec.message.name: kind for kind, spec in SPECS.items()}
"""Stream kind per message type name (``pkg/msg/Type``)."""
