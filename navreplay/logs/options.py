"""What the user says about a log: ``--topic``, ``--frame``, ``--init``, ``--reference`` and the
``[topics]``, ``[frames]``, ``[initial]``, ``[sensors.*]`` TOML tables (the command line wins over
the file)."""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping, Sequence
from typing import Any

from navreplay.io.convert import Convention
from navreplay.params import ParamError
from navreplay.streams import StreamKind

REFERENCE = "reference"
"""The key of ``--frame`` for a reference's world frame (``reference=enu|ned``)."""


class InitMethod(enum.StrEnum):
    """Where a filter's initial solution comes from (``--init``)."""

    METADATA = "metadata"
    """The recording's ``initial_nav`` (navreplay recordings; the default when present)."""
    REFERENCE = "reference"
    """The reference's first sample (``--reference``), interpolated to the first IMU sample."""
    ALIGN = "align"
    """Self-alignment from the data: levelling, then gyrocompass, magnetometer or GNSS course."""
    TABLE = "table"
    """Only the ``[initial]`` table (complete: position and attitude)."""


INITIAL_KEYS: dict[str, str] = {
    "lat_deg": "latitude [deg]",
    "lon_deg": "longitude [deg]",
    "h": "ellipsoidal height [m]",
    "v_n": "velocity north, east, down [m/s] (3 values)",
    "roll_deg": "roll [deg]",
    "pitch_deg": "pitch [deg]",
    "yaw_deg": "yaw (heading, ZYX) [deg]",
    "pos_sigma": "position 1-sigma [m] (1 or 3 values N, E, D)",
    "vel_sigma": "velocity 1-sigma [m/s] (1 or 3 values)",
    "att_sigma_deg": "attitude 1-sigma [deg] (1 or 3 values roll/pitch/yaw axes)",
    "accel_bias": "initial accelerometer bias estimate, FRD [m/s^2] (3 values)",
    "gyro_bias_dph": "initial gyro bias estimate, FRD [deg/h] (3 values)",
    "accel_bias_sigma": "accelerometer bias assumed by --init align for levelling [m/s^2]",
    "gyro_bias_sigma_dph": "gyro bias assumed by --init align for gyrocompassing [deg/h]",
}
"""Keys of the ``[initial]`` table and their units."""


@dataclasses.dataclass(frozen=True)
class LogOptions:
    """How to read one log.

    Attributes
    ----------
    topics : mapping StreamKind -> topic
    frames : mapping str -> Convention
        Stream kind value (``imu``, ``mag``, ``gps_vel``) or ``reference`` -> convention.
    init : InitMethod or None
        None: the recording's metadata if it has an initial solution, else the ``[initial]``
        table if it is complete, else nothing (a filter that needs a start says so).
    initial : mapping
        The ``[initial]`` table (:data:`INITIAL_KEYS`).
    reference : str or None
        A topic of the log or a TUM / CSV file.
    check_frames : bool
        Check the data against the frames before replaying.
    time : str
        ``header`` (stamps, falling back to log times when unusable) or ``log`` (``--time``).
    needs : tuple[str, ...]
        The parts of the initial solution the filters start from (``pos``, ``v_n``, ``q_nb``;
        :func:`navreplay.filters.base.initial_parts`).
    sensors : SensorSpecs or None
        The ``[sensors.*]`` tables (:mod:`navreplay.sensors.specs`): written over the
        recording's own sensor specifications (``Metadata.sensors``) before the filters are
        built.
    """

    topics: Mapping[StreamKind, str] = dataclasses.field(default_factory=dict)
    frames: Mapping[str, Convention] = dataclasses.field(default_factory=dict)
    init: InitMethod | None = None
    initial: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    reference: str | None = None
    check_frames: bool = True
    time: str = "header"
    needs: tuple[str, ...] = ("pos", "v_n", "q_nb")
    sensors: Any = None

    @property
    def stream_frames(self) -> dict[StreamKind, Convention]:
        return {StreamKind(k): v for k, v in self.frames.items() if k != REFERENCE}


def _pairs(items: Sequence[str], option: str) -> dict[str, str]:
    out = {}
    for item in items:
        key, eq, value = item.partition("=")
        if not eq or not key.strip() or not value.strip():
            raise ParamError(f"{option} {item!r}: expected KIND=VALUE")
        out[key.strip()] = value.strip()
    return out


def _kind(key: str, where: str) -> StreamKind:
    try:
        return StreamKind(key)
    except ValueError:
        raise ParamError(f"{where}: unknown stream {key!r} (streams: "
                         f"{', '.join(k.value for k in StreamKind)})") from None


def log_options(
    topics: Sequence[str] = (),
    frames: Sequence[str] = (),
    init: str | None = None,
    reference: str | None = None,
    config: Mapping[str, Any] | None = None,
    check_frames: bool = True,
    time: str | None = None,
    sensors: Any = None,
) -> LogOptions:
    """Parse ``--topic``/``--frame`` items and the TOML tables into :class:`LogOptions`
    (``sensors``: the config's ``[sensors.*]`` tables already read,
    :func:`navreplay.sensors.specs.specs_from_tables`)."""
    config = config or {}
    topic_items: dict[str, str] = {}
    frame_items: dict[str, str] = {}
    for name, target in (("topics", topic_items), ("frames", frame_items)):
        table = config.get(name, {})
        if not isinstance(table, Mapping):
            raise ParamError(f"[{name}] must be a table of KIND = VALUE")
        target.update({str(k): str(v) for k, v in table.items()})
    topic_items.update(_pairs(topics, "--topic"))
    frame_items.update(_pairs(frames, "--frame"))
    topic_map = {_kind(k, "--topic"): v for k, v in topic_items.items()}
    frame_map: dict[str, Convention] = {}
    for key, value in frame_items.items():
        if key != REFERENCE:
            _kind(key, "--frame")
        try:
            frame_map[key] = Convention(value.lower())
        except ValueError:
            raise ParamError(f"--frame {key}={value}: use flu, frd, enu or ned") from None
    initial = config.get("initial", {})
    if not isinstance(initial, Mapping):
        raise ParamError("[initial] must be a table")
    unknown = sorted(set(initial) - set(INITIAL_KEYS))
    if unknown:
        raise ParamError(f"[initial]: unknown key(s) {', '.join(unknown)}; known: "
                         f"{', '.join(INITIAL_KEYS)}")
    for key, value in initial.items():
        values = value if isinstance(value, list) else [value]
        if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
            raise ParamError(f"[initial] {key} = {value!r}: expected finite numbers")
    ref_table = config.get("reference", {})
    if reference is None and isinstance(ref_table, Mapping):
        reference = ref_table.get("source")
    method = None
    if init is not None:
        try:
            method = InitMethod(init)
        except ValueError:
            raise ParamError(f"--init {init}: use metadata, reference, align or table") from None
    if method is InitMethod.REFERENCE and reference is None:
        raise ParamError("--init reference needs --reference TOPIC|FILE")
    time = time or "header"
    if time not in ("header", "log"):
        raise ParamError(f"--time {time}: use header or log")
    return LogOptions(topic_map, frame_map, method, dict(initial), reference, check_frames,
                      time, sensors=sensors or None)
