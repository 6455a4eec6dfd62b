"""Stream columns <-> message fields, per stream kind (units, frames and conventions of the wire).

Encoding turns a :class:`~navreplay.core.streams.Stream` into the leaf arrays of its message type
(:mod:`navreplay.io.schemas`); decoding turns decoded leaf arrays back into the standard columns of
:data:`navreplay.core.streams.FIELDS`. Both sides are vectorised over all messages of a block.

Conventions on the wire (see docs/recording-format.md):

* NavSatFix latitude/longitude are in degrees (ROS), columns in radians; the conversion is
  ``np.degrees`` / ``np.radians`` and round-trips within one unit in the last place.
* NavSatFix ``position_covariance`` is ENU (ROS): ``diag(sigma_E^2, sigma_N^2, sigma_D^2)`` from
  ``pos_sigma`` (N, E, D), type DIAGONAL_KNOWN; a stream without ``pos_sigma`` writes type UNKNOWN.
* A covariance of zero means "unknown" (ROS); an IMU without gyros writes zero rates with
  ``angular_velocity_covariance[0] = -1`` ("not provided").

Foreign recordings: REP-103 says frames are FLU / ENU unless their name ends in ``_frd`` /
``_ned``. IMU and magnetometer data in a frame not ending in ``_frd`` are turned to FRD
(y and z negated), a twist in a frame not named ``ned`` / ``*_ned`` is taken as ENU and turned to
NED; each such conversion is reported as a note. A declared convention (``--frame imu=frd``,
:class:`Convention`) replaces the guess from the name; :func:`assumed_convention` says which one
applies and why.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable, Mapping

import numpy as np

from navreplay.core.streams import FIELDS, Stream, StreamKind
from navreplay.io.errors import RecordingError

NAV_SAT_STATUS_NO_FIX = -1
NAV_SAT_STATUS_FIX = 0
NAV_SAT_SERVICE_GPS = 1
COVARIANCE_TYPE_UNKNOWN = 0
COVARIANCE_TYPE_DIAGONAL_KNOWN = 2
NOT_PROVIDED = -1.0
"""``covariance[0]`` value marking a quantity as not provided (ROS sensor_msgs convention)."""

_ENU_FROM_NED = np.array([1, 0, 2])
"""Indices taking (N, E, D) components to (E, N, .) order; the third is U = -D."""


@dataclasses.dataclass(frozen=True)
class AuxColumn:
    """One scenario-specific truth column stored in the truth message's ``aux`` array.

    Attributes
    ----------
    name : str
        Column name.
    shape : tuple[int, ...]
        Trailing shape of one row (``()`` for a scalar).
    """

    name: str
    shape: tuple[int, ...]

    @property
    def width(self) -> int:
        """Values per message."""
        return int(np.prod(self.shape, dtype=np.int64))

    def to_json(self) -> dict[str, object]:
        return {"name": self.name, "shape": list(self.shape)}

    @staticmethod
    def from_json(obj: Mapping[str, object]) -> AuxColumn:
        shape = obj["shape"]
        if not isinstance(shape, list):
            raise ValueError(f"shape of {obj.get('name')!r} is not a list")
        return AuxColumn(str(obj["name"]), tuple(int(s) for s in shape))


def aux_columns(stream: Stream) -> list[AuxColumn]:
    """The extra (non-standard) columns of a truth stream, in the stream's order."""
    standard = FIELDS[StreamKind.TRUTH]
    return [
        AuxColumn(k, tuple(v.shape[1:])) for k, v in stream.columns.items() if k not in standard
    ]


def check_columns(stream: Stream) -> None:
    """Raise ValueError unless the stream has what its message needs, in the standard shapes."""
    standard = FIELDS[stream.kind]
    optional = _OPTIONAL.get(stream.kind, ())
    missing = [f for f in standard if f not in stream.columns and f not in optional]
    if missing:
        raise ValueError(f"stream {stream.kind} lacks the columns {missing}")
    for name, col in stream.columns.items():
        if name in standard:
            want = (len(stream), *standard[name].shape)
            if col.shape != want:
                raise ValueError(
                    f"stream {stream.kind}: column {name!r} has shape {col.shape}, expected {want}"
                )
        elif stream.kind is not StreamKind.TRUTH:
            raise ValueError(
                f"stream {stream.kind}: column {name!r} has no place in its message; only the "
                "truth stream carries extra columns"
            )


_OPTIONAL: dict[StreamKind, tuple[str, ...]] = {
    StreamKind.IMU: ("omega_ib_b",),
    StreamKind.GPS: ("pos_sigma",),
    StreamKind.GPS_VEL: ("vel_sigma",),
}


# ---------------------------------------------------------------------------------------------
# Encoding: columns -> leaf arrays


def _zeros(n: int, count: int) -> np.ndarray:
    return np.zeros((n, count))


def _imu_fields(s: Stream, aux: list[AuxColumn]) -> dict[str, np.ndarray]:
    n = len(s)
    orientation_cov = _zeros(n, 9)
    orientation_cov[:, 0] = NOT_PROVIDED
    gyro_cov = _zeros(n, 9)
    if "omega_ib_b" in s.columns:
        omega = s["omega_ib_b"]
    else:
        omega = _zeros(n, 3)
        gyro_cov[:, 0] = NOT_PROVIDED
    return {
        "orientation": np.array([0.0, 0.0, 0.0, 1.0]),
        "orientation_covariance": orientation_cov,
        "angular_velocity": omega,
        "angular_velocity_covariance": gyro_cov,
        "linear_acceleration": s["f_b"],
        "linear_acceleration_covariance": _zeros(n, 9),
    }


def _gps_fields(s: Stream, aux: list[AuxColumn]) -> dict[str, np.ndarray]:
    n = len(s)
    cov = _zeros(n, 9)
    if "pos_sigma" in s.columns:
        var_enu = s["pos_sigma"][:, _ENU_FROM_NED] ** 2
        cov[:, [0, 4, 8]] = var_enu
        cov_type = COVARIANCE_TYPE_DIAGONAL_KNOWN
    else:
        cov_type = COVARIANCE_TYPE_UNKNOWN
    pos = s["pos"]
    return {
        "status": np.int8(NAV_SAT_STATUS_FIX),
        "service": np.uint16(NAV_SAT_SERVICE_GPS),
        "latitude": np.degrees(pos[:, 0]),
        "longitude": np.degrees(pos[:, 1]),
        "altitude": pos[:, 2],
        "position_covariance": cov,
        "position_covariance_type": np.uint8(cov_type),
    }


def _gps_vel_fields(s: Stream, aux: list[AuxColumn]) -> dict[str, np.ndarray]:
    n = len(s)
    cov = _zeros(n, 36)
    if "vel_sigma" in s.columns:
        cov[:, [0, 7, 14]] = s["vel_sigma"] ** 2
    return {"linear": s["v_n"], "angular": _zeros(n, 3), "covariance": cov}


def _mag_fields(s: Stream, aux: list[AuxColumn]) -> dict[str, np.ndarray]:
    return {"magnetic_field": s["m_b"], "magnetic_field_covariance": _zeros(len(s), 9)}


def _master_ins_fields(s: Stream, aux: list[AuxColumn]) -> dict[str, np.ndarray]:
    return {"euler": s["euler"], "v_n": s["v_n"], "pos": s["pos"]}


def _speed_log_fields(s: Stream, aux: list[AuxColumn]) -> dict[str, np.ndarray]:
    return {"rpm": s["rpm"]}


def _depth_fields(s: Stream, aux: list[AuxColumn]) -> dict[str, np.ndarray]:
    return {"depth": s["depth"]}


def _truth_fields(s: Stream, aux: list[AuxColumn]) -> dict[str, np.ndarray]:
    n = len(s)
    parts = [s[c.name].reshape(n, c.width) for c in aux]
    flat = np.concatenate(parts, axis=1) if parts else _zeros(n, 0)
    return {"pos": s["pos"], "v_n": s["v_n"], "q_nb": s["q_nb"], "aux": flat}


ENCODERS: dict[StreamKind, Callable[[Stream, list[AuxColumn]], dict[str, np.ndarray]]] = {
    StreamKind.IMU: _imu_fields,
    StreamKind.MASTER_INS: _master_ins_fields,
    StreamKind.GPS: _gps_fields,
    StreamKind.GPS_VEL: _gps_vel_fields,
    StreamKind.MAG: _mag_fields,
    StreamKind.SPEED_LOG: _speed_log_fields,
    StreamKind.DEPTH: _depth_fields,
    StreamKind.TRUTH: _truth_fields,
}
"""Stream -> leaf arrays (of :mod:`navreplay.io.schemas`) per kind."""


# ---------------------------------------------------------------------------------------------
# Decoding: leaf arrays -> columns


@dataclasses.dataclass
class Decoded:
    """Columns decoded from one topic, with what the reader should tell the user.

    Attributes
    ----------
    columns : dict[str, ndarray]
    keep : ndarray of bool, shape (N,), or None
        Rows to keep (None: all).
    frame_id : str
        Frame of the decoded columns.
    notes : list[str]
        Conversions or drops worth a warning.
    convention : Convention or None
        Convention the wire vectors were read in (None: no frame-dependent vectors).
    reason : str
        Why that convention (declared, or the frame id's REP-103 meaning).
    """

    columns: dict[str, np.ndarray]
    keep: np.ndarray | None = None
    frame_id: str = ""
    notes: list[str] = dataclasses.field(default_factory=list)
    convention: Convention | None = None
    reason: str = ""


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _is_frd(frame_id: str) -> bool:
    return frame_id.lower().endswith("_frd") or frame_id.lower() == "frd"


def _is_ned(frame_id: str) -> bool:
    return frame_id.lower().endswith("_ned") or frame_id.lower() == "ned"


_FLU_TO_FRD = np.array([1.0, -1.0, -1.0])


class Convention(enum.StrEnum):
    """Axis convention of a topic's vectors: body FLU / FRD, or navigation ENU / NED."""

    FLU = "flu"
    FRD = "frd"
    ENU = "enu"
    NED = "ned"


BODY_KINDS = (StreamKind.IMU, StreamKind.MAG)
"""Streams whose vectors are in a body frame (FLU or FRD on the wire)."""
NAV_KINDS = (StreamKind.GPS_VEL,)
"""Streams whose vectors are in a local-level frame (ENU or NED on the wire)."""


def assumed_convention(
    kind: StreamKind, frame_id: str, declared: Convention | str | None = None
) -> tuple[Convention | None, str]:
    """The convention a topic's vectors are read in, and why.

    Parameters
    ----------
    kind : StreamKind
    frame_id : str
        ``header.frame_id`` of the topic.
    declared : Convention or str, optional
        The user's declaration (``--frame`` or ``[frames]``).

    Returns
    -------
    convention : Convention or None
        None for a stream without frame-dependent vectors.
    reason : str

    Raises
    ------
    ValueError
        A declaration that does not fit the stream (a body stream declared ENU, ...).

    >>> assumed_convention(StreamKind.IMU, "imu_link")
    (<Convention.FLU: 'flu'>, "frame id 'imu_link' has no _frd suffix: FLU by REP-103")
    >>> assumed_convention(StreamKind.IMU, "imu_link", "frd")[1]
    'declared frd'
    """
    if kind in BODY_KINDS:
        default, named, suffix, is_named = (Convention.FLU, Convention.FRD, "_frd",
                                            _is_frd(frame_id))
    elif kind in NAV_KINDS:
        default, named, suffix, is_named = (Convention.ENU, Convention.NED, "_ned",
                                            _is_ned(frame_id))
    else:
        if declared is not None:
            raise ValueError(f"stream {kind.value} has no frame-dependent vectors to declare")
        return None, "no frame-dependent vectors"
    if declared is not None:
        conv = Convention(str(declared).lower())
        if conv not in (default, named):
            raise ValueError(
                f"stream {kind.value} can be {default.value} or {named.value}, not {conv.value}"
            )
        return conv, f"declared {conv.value}"
    if is_named:
        return named, f"frame id {frame_id!r} ends in {suffix} (REP-103)"
    return default, (f"frame id {frame_id!r} has no {suffix} suffix: "
                     f"{default.value.upper()} by REP-103")


def _body_vectors(d: Decoded, names: tuple[str, ...], frame_id: str, kind: StreamKind,
                  convention: Convention | None) -> None:
    what = "IMU" if kind is StreamKind.IMU else "magnetometer"
    conv, reason = assumed_convention(kind, frame_id, convention)
    d.convention, d.reason = conv, reason
    if conv is Convention.FRD:
        d.frame_id = frame_id
        return
    for name in names:
        if name in d.columns:
            d.columns[name] = d.columns[name] * _FLU_TO_FRD
    d.frame_id = f"{frame_id}_frd" if frame_id else "frd"
    d.notes.append(
        f"{what} frame {frame_id!r} taken as FLU ({reason}) and converted to FRD "
        f"(y and z negated); frame_id is now {d.frame_id!r}"
    )


def _imu_columns(f: Mapping[str, np.ndarray], frame_id: str, aux: list[AuxColumn],
        convention: Convention | None = None) -> Decoded:
    flag = np.asarray(f["angular_velocity_covariance"])[:, 0] == NOT_PROVIDED
    d = Decoded({"f_b": _f64(f["linear_acceleration"])})
    if flag.size and flag.all():
        pass  # an accelerometer-only IMU: no omega_ib_b column
    elif flag.any():
        raise RecordingError(
            "angular velocity is marked 'not provided' in some messages only "
            f"({int(flag.sum())} of {flag.size})"
        )
    else:
        d.columns = {"omega_ib_b": _f64(f["angular_velocity"]), **d.columns}
    _body_vectors(d, ("omega_ib_b", "f_b"), frame_id, StreamKind.IMU, convention)
    return d


def _gps_columns(f: Mapping[str, np.ndarray], frame_id: str, aux: list[AuxColumn],
        convention: Convention | None = None) -> Decoded:
    pos = np.stack(
        [np.radians(f["latitude"]), np.radians(f["longitude"]), np.asarray(f["altitude"])],
        axis=1,
    )
    d = Decoded({"pos": _f64(pos)}, frame_id=frame_id)
    status = np.asarray(f["status"])
    no_fix = status <= NAV_SAT_STATUS_NO_FIX
    if no_fix.any():
        d.keep = ~no_fix
        d.notes.append(f"{int(no_fix.sum())} fixes with status NO_FIX dropped")
    cov_type = np.asarray(f["position_covariance_type"])[~no_fix]
    if (cov_type != COVARIANCE_TYPE_UNKNOWN).all():  # (also for no messages)
        var_enu = np.asarray(f["position_covariance"])
        var_ned = var_enu[:, [1, 0, 2]]
        d.columns["pos_sigma"] = _f64(np.sqrt(var_ned))
    elif cov_type.size and (cov_type != COVARIANCE_TYPE_UNKNOWN).any():
        d.notes.append("position covariance known for some fixes only: pos_sigma omitted")
    return d


def _gps_vel_columns(f: Mapping[str, np.ndarray], frame_id: str, aux: list[AuxColumn],
        convention: Convention | None = None) -> Decoded:
    v = _f64(f["linear"])
    var = np.asarray(f["covariance"])
    d = Decoded({"v_n": v}, frame_id=frame_id)
    if var.size == 0 or (var != 0.0).any():
        d.columns["vel_sigma"] = _f64(np.sqrt(var))
    d.convention, d.reason = assumed_convention(StreamKind.GPS_VEL, frame_id, convention)
    if d.convention is Convention.ENU:
        d.columns["v_n"] = np.stack([v[:, 1], v[:, 0], -v[:, 2]], axis=1)
        if "vel_sigma" in d.columns:
            d.columns["vel_sigma"] = d.columns["vel_sigma"][:, [1, 0, 2]].copy()
        d.frame_id = "ned"
        d.notes.append(f"velocity frame {frame_id!r} taken as ENU ({d.reason}) and converted "
                       "to NED")
    return d


def _mag_columns(f: Mapping[str, np.ndarray], frame_id: str, aux: list[AuxColumn],
        convention: Convention | None = None) -> Decoded:
    d = Decoded({"m_b": _f64(f["magnetic_field"])})
    _body_vectors(d, ("m_b",), frame_id, StreamKind.MAG, convention)
    return d


def _master_ins_columns(
    f: Mapping[str, np.ndarray], frame_id: str, aux: list[AuxColumn],
    convention: Convention | None = None,
) -> Decoded:
    cols = {"euler": _f64(f["euler"]), "v_n": _f64(f["v_n"]), "pos": _f64(f["pos"])}
    return Decoded(cols, frame_id=frame_id)


def _speed_log_columns(f: Mapping[str, np.ndarray], frame_id: str, aux: list[AuxColumn],
        convention: Convention | None = None) -> Decoded:
    return Decoded({"rpm": _f64(f["rpm"])}, frame_id=frame_id)


def _depth_columns(f: Mapping[str, np.ndarray], frame_id: str, aux: list[AuxColumn],
        convention: Convention | None = None) -> Decoded:
    return Decoded({"depth": _f64(f["depth"])}, frame_id=frame_id)


def _truth_columns(f: Mapping[str, np.ndarray], frame_id: str, aux: list[AuxColumn],
        convention: Convention | None = None) -> Decoded:
    cols = {"pos": _f64(f["pos"]), "v_n": _f64(f["v_n"]), "q_nb": _f64(f["q_nb"])}
    flat = np.asarray(f["aux"])
    n, width = flat.shape
    d = Decoded(cols, frame_id=frame_id)
    if n == 0:  # no message says how long aux is: trust the metadata
        flat = np.zeros((0, sum(c.width for c in aux)))
    elif sum(c.width for c in aux) != width:
        if width:
            cols["aux"] = _f64(flat)
            d.notes.append(
                f"truth aux has {width} values per message but the metadata describes "
                f"{sum(c.width for c in aux)}: kept as one column 'aux'"
            )
        return d
    start = 0
    for c in aux:
        cols[c.name] = _f64(flat[:, start : start + c.width].reshape(n, *c.shape))
        start += c.width
    return d


REDUCE: dict[StreamKind, dict[str, list[int] | None]] = {
    StreamKind.IMU: {
        "angular_velocity": None,
        "angular_velocity_covariance": [0],
        "linear_acceleration": None,
    },
    StreamKind.MASTER_INS: {"euler": None, "v_n": None, "pos": None},
    StreamKind.GPS: {
        "status": None,
        "latitude": None,
        "longitude": None,
        "altitude": None,
        "position_covariance": [0, 4, 8],
        "position_covariance_type": None,
    },
    StreamKind.GPS_VEL: {"linear": None, "covariance": [0, 7, 14]},
    StreamKind.MAG: {"magnetic_field": None},
    StreamKind.SPEED_LOG: {"rpm": None},
    StreamKind.DEPTH: {"depth": None},
    StreamKind.TRUTH: {"pos": None, "v_n": None, "q_nb": None, "aux": None},
}
"""Decoded fields kept per kind (all values, or these columns), the input of DECODERS.

The reader applies this right after decoding each block, so payload bytes are not kept: the
position covariance is reduced to its diagonal (E, N, U variances), the twist covariance to its
linear diagonal, the gyro covariance to its "not provided" flag.
"""

DECODERS: dict[StreamKind, Callable[..., Decoded]] = {
    StreamKind.IMU: _imu_columns,
    StreamKind.MASTER_INS: _master_ins_columns,
    StreamKind.GPS: _gps_columns,
    StreamKind.GPS_VEL: _gps_vel_columns,
    StreamKind.MAG: _mag_columns,
    StreamKind.SPEED_LOG: _speed_log_columns,
    StreamKind.DEPTH: _depth_columns,
    StreamKind.TRUTH: _truth_columns,
}
"""Leaf arrays -> stream columns per kind."""
