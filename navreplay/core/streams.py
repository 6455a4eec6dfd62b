"""Sensor streams as columns: the one in-memory form shared by sim/, io/ and replay/.

A :class:`Stream` is a set of equally long columns with int64 nanosecond timestamps; a
:class:`Recording` is the streams of one run plus its :class:`Metadata`. Simulators produce
recordings, io/ writes and reads them, and the replay engine merges their streams by time.

Standard columns per stream kind (``FIELDS``) fix names, shapes and units; a stream may carry
extra columns (the truth stream does, per scenario), which io/ stores generically.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np


class StreamKind(enum.StrEnum):
    """Kinds of streams a recording can hold; the value is the stream's name."""

    IMU = "imu"
    """Strapdown IMU: body rate and specific force, mean over the preceding sample interval."""
    MASTER_INS = "master_ins"
    """Master (gimballed) INS output: Euler attitude, NED velocity, position."""
    GPS = "gps"
    """GNSS position fix."""
    GPS_VEL = "gps_vel"
    """GNSS velocity in NED."""
    MAG = "mag"
    """Three-axis magnetometer."""
    SPEED_LOG = "speed_log"
    """Propeller RPM speed log."""
    DEPTH = "depth"
    """Depth sensor (positive down)."""
    TRUTH = "truth"
    """Simulated true navigation state (and scenario-specific true quantities)."""


@dataclasses.dataclass(frozen=True)
class Field:
    """One standard column: trailing shape, unit and meaning."""

    shape: tuple[int, ...]
    unit: str
    doc: str


FIELDS: dict[StreamKind, dict[str, Field]] = {
    StreamKind.IMU: {
        "omega_ib_b": Field((3,), "rad/s", "angular rate of b w.r.t. inertial space, FRD"),
        "f_b": Field((3,), "m/s^2", "specific force, FRD"),
    },
    StreamKind.MASTER_INS: {
        "euler": Field((3,), "rad", "roll, pitch, yaw (ZYX) of the master's body frame"),
        "v_n": Field((3,), "m/s", "velocity NED"),
        "pos": Field((3,), "rad, rad, m", "latitude, longitude, ellipsoidal height"),
    },
    StreamKind.GPS: {
        "pos": Field((3,), "rad, rad, m", "latitude, longitude, ellipsoidal height"),
        "pos_sigma": Field((3,), "m", "1-sigma position error N, E, D"),
    },
    StreamKind.GPS_VEL: {
        "v_n": Field((3,), "m/s", "velocity NED"),
        "vel_sigma": Field((3,), "m/s", "1-sigma velocity error N, E, D"),
    },
    StreamKind.MAG: {
        "m_b": Field((3,), "T", "magnetic flux density, FRD"),
    },
    StreamKind.SPEED_LOG: {
        "rpm": Field((), "rev/min", "propeller shaft speed"),
    },
    StreamKind.DEPTH: {
        "depth": Field((), "m", "depth below the surface, positive down"),
    },
    StreamKind.TRUTH: {
        "pos": Field((3,), "rad, rad, m", "true latitude, longitude, ellipsoidal height"),
        "v_n": Field((3,), "m/s", "true ground velocity NED"),
        "q_nb": Field((4,), "-", "true attitude quaternion b->n, scalar first"),
    },
}


@dataclasses.dataclass
class Stream:
    """Equally long columns with timestamps.

    Attributes
    ----------
    kind : StreamKind
    t_ns : ndarray, shape (N,), int64
        Sample times [ns since the UNIX epoch], strictly increasing.
    columns : dict[str, ndarray]
        Each column has shape (N, ...) and dtype float64.
    frame_id : str
        Frame of the data (``"imu_frd"``, ``"ned"``, ...), as written to the message header.
    """

    kind: StreamKind
    t_ns: np.ndarray
    columns: dict[str, np.ndarray]
    frame_id: str = ""

    def __post_init__(self) -> None:
        self.kind = StreamKind(self.kind)
        self.t_ns = np.ascontiguousarray(self.t_ns, dtype=np.int64)
        n = self.t_ns.shape[0]
        for name, col in list(self.columns.items()):
            col = np.ascontiguousarray(col, dtype=np.float64)
            if col.shape[:1] != (n,):
                raise ValueError(
                    f"stream {self.kind}: column {name!r} has {col.shape[0] if col.ndim else 0}"
                    f" rows, timestamps have {n}"
                )
            self.columns[name] = col

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def slice(self, start: int, stop: int) -> Stream:
        """Rows [start, stop) as a new stream sharing memory."""
        return Stream(
            self.kind,
            self.t_ns[start:stop],
            {k: v[start:stop] for k, v in self.columns.items()},
            self.frame_id,
        )

    def missing_fields(self) -> list[str]:
        """Standard columns of this kind that the stream lacks."""
        return [f for f in FIELDS.get(self.kind, {}) if f not in self.columns]


LOCAL_ORIGIN = "local_origin"
"""``Metadata.extra`` key of the origin the view's local NED frame and the exports' ENU frame take
when the user gave one (``[initial]``'s position of a log): ``{"pos": [lat, lon, h] (rad, rad,
m), "source": str}``; without it, the first reference sample or the first estimate."""


@dataclasses.dataclass
class Metadata:
    """What a recording says about itself (stored as an MCAP metadata record).

    ``params``, ``true_errors``, ``initial_nav`` and ``extra`` are made plain JSON values on
    construction (:func:`jsonable`: numpy arrays and tuples become lists), so an in-memory
    recording carries the same metadata as the file it is written to.

    Attributes
    ----------
    scenario : str
        Scenario name (``navreplay scenarios``), or ``""`` for a recording not simulated here.
    seed : int | None
        Seed of the numpy Generator the recording was simulated with.
    params : dict
        All scenario parameters, SI units.
    sensors : dict
        The sensor specifications, SI: per kind (``imu``, ``gps``, ...) the stated fields of
        its error-model record and a ``source``
        (:meth:`navreplay.sensors.specs.SensorSpecs.to_metadata`); empty when unknown.
    true_errors : dict
        True values of the simulated error states (biases, scale factors, misalignments, lever
        arm, current, ...), SI, lists for vectors.
    initial_nav : dict
        Initial navigation solution handed to a filter that cannot self-initialise, as an
        external alignment would: ``{"t_ns", "pos", "v_n", "q_nb", "sigma": {...}}``. It carries
        the scenario's initial errors, never the truth.
    navreplay_version : str
    extra : dict
        Anything else (site, date, truth column descriptions; :data:`LOCAL_ORIGIN`).
    """

    scenario: str = ""
    seed: int | None = None
    params: dict[str, Any] = dataclasses.field(default_factory=dict)
    true_errors: dict[str, Any] = dataclasses.field(default_factory=dict)
    initial_nav: dict[str, Any] = dataclasses.field(default_factory=dict)
    navreplay_version: str = ""
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)
    sensors: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("params", "true_errors", "initial_nav", "extra", "sensors"):
            setattr(self, name, jsonable(getattr(self, name)))


@dataclasses.dataclass
class Recording:
    """The streams of one run and its metadata.

    ``t0_ns`` is the recording start: filters see ``t = (t_ns - t0_ns) / 1e9`` seconds.
    """

    streams: dict[StreamKind, Stream]
    metadata: Metadata
    t0_ns: int = 0

    def __getitem__(self, kind: str | StreamKind) -> Stream:
        return self.streams[StreamKind(kind)]

    def __contains__(self, kind: object) -> bool:
        if not isinstance(kind, str):
            return False
        try:
            return StreamKind(kind) in self.streams
        except ValueError:
            return False

    def kinds(self) -> list[StreamKind]:
        return list(self.streams)


def jsonable(value: Any, *, strict: bool = False) -> Any:
    """Plain JSON values of nested data (what :class:`Metadata` and JSON summaries hold).

    Mappings become dicts with string keys, lists and tuples lists, numpy arrays nested lists,
    numpy scalars Python numbers, enums their value and paths strings; anything else is
    returned as it is.

    Parameters
    ----------
    value : Any
    strict : bool
        Also turn NaN and infinities, which JSON cannot represent, into None.

    Examples
    --------
    >>> jsonable({"b": np.array([1.0, np.nan]), "k": (StreamKind.IMU, np.int64(2))})
    {'b': [1.0, nan], 'k': ['imu', 2]}
    >>> jsonable([np.inf], strict=True)
    [None]
    """
    if isinstance(value, Mapping):
        return {str(k): jsonable(v, strict=strict) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v, strict=strict) for v in value]
    if isinstance(value, np.ndarray | np.generic):
        return jsonable(value.tolist(), strict=strict)
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if strict and isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def seconds(t_ns: np.ndarray | int, t0_ns: int) -> np.ndarray:
    """Float seconds since ``t0_ns`` (exact for recordings up to ~100 days at ns resolution)."""
    return (np.asarray(t_ns, dtype=np.int64) - np.int64(t0_ns)).astype(np.float64) * 1e-9


def nanoseconds(t: np.ndarray | float, t0_ns: int) -> np.ndarray:
    """Inverse of :func:`seconds`, rounded to the nearest nanosecond."""
    return np.int64(t0_ns) + np.rint(np.asarray(t, dtype=np.float64) * 1e9).astype(np.int64)


