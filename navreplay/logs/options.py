"""What the user says about a log: ``--topic``, ``--frame``, ``--init``, ``--reference`` and the
``[topics]``, ``[frames]``, ``[initial]``, ``[sensors.*]`` TOML tables (the command line wins over
the file)."""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from navreplay.core.params import ParamError
from navreplay.core.streams import StreamKind
from navreplay.io.checks import STANDARD_GRAVITY, ImuRange, ReadPolicy
from navreplay.io.convert import Convention
from navreplay.io.source import ReadOptions
from navreplay.io.span import TimeSpan, TimeSpanError

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


INITIAL_RANGES: dict[str, tuple[float, float, tuple[int, ...]]] = {
    "lat_deg": (-90.0, 90.0, (1,)),
    "lon_deg": (-180.0, 360.0, (1,)),
    "h": (-2e4, 1e8, (1,)),
    "v_n": (-2e4, 2e4, (3,)),
    "roll_deg": (-180.0, 180.0, (1,)),
    "pitch_deg": (-90.0, 90.0, (1,)),
    "yaw_deg": (-360.0, 360.0, (1,)),
    "pos_sigma": (0.0, 1e7, (1, 3)),
    "vel_sigma": (0.0, 2e4, (1, 3)),
    "att_sigma_deg": (0.0, 180.0, (1, 3)),
    "accel_bias": (-200.0, 200.0, (3,)),
    "gyro_bias_dph": (-1e6, 1e6, (3,)),
    "accel_bias_sigma": (0.0, 200.0, (1,)),
    "gyro_bias_sigma_dph": (0.0, 1e6, (1,)),
}
"""Allowed values of the ``[initial]`` keys: (low, high, numbers of values allowed); the
covariances' sigmas (``pos_sigma``, ``vel_sigma``, ``att_sigma_deg``) must be positive."""

IMU_RANGE_UNITS = {"gyro": ("deg/s", math.pi / 180.0), "accel": ("g", STANDARD_GRAVITY)}
"""``--imu-range`` / ``[imu_range]`` keys: their datasheet unit and its value in SI."""

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
    imu_range : ImuRange
        The IMU's measurement range: a sample beyond it stops the run (``--imu-range``).
    force_frames : bool
        ``--force-frame``: ``--frame`` wins over frame ids that name other axes.
    span : TimeSpan or None
        ``--start`` / ``--end``: the part of the log read (:mod:`navreplay.io.span`).
    onboard : tuple of str
        ``--onboard``: recorded navigation solutions shown, scored and exported beside the
        filters (:mod:`navreplay.logs.onboard`).
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
    imu_range: ImuRange = ImuRange()
    force_frames: bool = False
    span: TimeSpan | None = None
    onboard: tuple[str, ...] = ()

    @property
    def stream_frames(self) -> dict[StreamKind, Convention]:
        return {StreamKind(k): v for k, v in self.frames.items() if k != REFERENCE}

    def read_options(self, kinds: Iterable[StreamKind] | None = None, *,
                     validate: bool = True, window: int | None = None) -> ReadOptions:
        """The options of the log's reader (:class:`~navreplay.io.source.ReadOptions`):
        ``kinds`` (all when None), the topics, the streams' frames and the time source;
        ``window``: messages of a stream per window (None: the reader's default)."""
        options = ReadOptions(kinds=kinds, topics=self.topics, frames=self.stream_frames,
                              time=self.time, validate=validate)
        return options if window is None else dataclasses.replace(options, window=window)

    @property
    def policy(self) -> ReadPolicy:
        """How the log's samples and frame ids are checked (:mod:`navreplay.io.checks`)."""
        return ReadPolicy(self.imu_range, self.force_frames)


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


def _strings(name: str, table: Any, what: str) -> dict[str, str]:
    """A ``[topics]`` / ``[frames]`` table: keys and values strings (a number, a boolean or a
    table is a mistake, not a name)."""
    if not isinstance(table, Mapping):
        raise ParamError(f"[{name}] must be a table of KIND = {what}")
    for key, value in table.items():
        if not isinstance(value, str) or not value.strip():
            raise ParamError(f"[{name}] {key} = {value!r}: expected {what} as a string "
                             f"(e.g. {key} = \"{'/imu/data' if name == 'topics' else 'frd'}\")")
    return {str(k): v for k, v in table.items()}


def _check_initial(initial: Mapping[str, Any]) -> None:
    """Types, counts and ranges of the ``[initial]`` values (:data:`INITIAL_RANGES`)."""
    for key, value in initial.items():
        lo, hi, counts = INITIAL_RANGES[key]
        values = value if isinstance(value, list) else [value]
        if not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                   for v in values):
            raise ParamError(f"[initial] {key} = {value!r}: expected finite numbers "
                             f"({INITIAL_KEYS[key]})")
        if len(values) not in counts or (isinstance(value, list) and counts == (1,)):
            n = " or ".join(str(c) for c in counts)
            raise ParamError(f"[initial] {key} = {value!r}: expected {n} value(s) "
                             f"({INITIAL_KEYS[key]})")
        positive = key in ("pos_sigma", "vel_sigma", "att_sigma_deg")  # covariances
        bad = [v for v in values if not (lo <= v <= hi) or (positive and v <= 0)]
        if bad:
            span = f"{'0 <' if positive else f'{lo:g} <='} value <= {hi:g}"
            raise ParamError(f"[initial] {key} = {value!r}: out of range ({span}; "
                             f"{INITIAL_KEYS[key]})")


def imu_range(text: str | None = None, table: Mapping[str, Any] | None = None) -> ImuRange:
    """The IMU's measurement range from ``--imu-range gyro=DPS,accel=G`` and/or an
    ``[imu_range]`` table (``gyro = 2000``, ``accel = 16``; the option wins); the defaults of
    :class:`~navreplay.io.checks.ImuRange` for what neither gives."""
    values: dict[str, Any] = {}
    if table is not None:
        if not isinstance(table, Mapping):
            raise ParamError("[imu_range] must be a table (gyro = DEG_PER_S, accel = G)")
        values.update(table)
    if text:
        values.update(_pairs([p for p in text.split(",") if p.strip()], "--imu-range"))
    unknown = sorted(set(values) - set(IMU_RANGE_UNITS))
    if unknown:
        raise ParamError(f"--imu-range / [imu_range]: unknown key(s) {', '.join(unknown)}; "
                         "use gyro=DEG_PER_S and accel=G")
    si: dict[str, float] = {}
    for key, value in values.items():
        unit, scale = IMU_RANGE_UNITS[key]
        number = value
        if isinstance(value, str):
            try:
                number = float(value)
            except ValueError:
                number = None
        if (isinstance(number, bool) or not isinstance(number, int | float)
                or not 0 < number < math.inf):
            raise ParamError(f"--imu-range {key}={value}: expected a positive number of {unit} "
                             "(the datasheet's measurement range)")
        si[key] = float(number) * scale
    return ImuRange(**si)


def log_options(
    topics: Sequence[str] = (),
    frames: Sequence[str] = (),
    init: str | None = None,
    reference: str | None = None,
    config: Mapping[str, Any] | None = None,
    check_frames: bool = True,
    time: str | None = None,
    sensors: Any = None,
    imu_range_text: str | None = None,
    force_frames: bool = False,
    start: str | None = None,
    end: str | None = None,
    onboard: Sequence[str] = (),
) -> LogOptions:
    """Parse ``--topic``/``--frame``/``--imu-range`` items and the TOML tables into
    :class:`LogOptions`; every value is checked for its type and range here (``sensors``: the
    config's ``[sensors.*]`` tables already read,
    :func:`navreplay.sensors.specs.specs_from_tables`)."""
    config = config or {}
    topic_items = _strings("topics", config.get("topics", {}), "a topic")
    frame_items = _strings("frames", config.get("frames", {}), "axes")
    topic_items.update(_pairs(topics, "--topic"))
    frame_items.update(_pairs(frames, "--frame"))
    topic_map = {_kind(k, "--topic"): v.strip() for k, v in topic_items.items()}
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
    _check_initial(initial)
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
    try:
        span = TimeSpan.parse(start, end)
    except TimeSpanError as e:
        raise ParamError(str(e)) from None
    return LogOptions(topic_map, frame_map, method, dict(initial), reference, check_frames,
                      time, sensors=sensors or None,
                      imu_range=imu_range(imu_range_text, config.get("imu_range")),
                      force_frames=force_frames, span=span, onboard=_onboard(onboard))


def _onboard(sources: Sequence[str]) -> tuple[str, ...]:
    """``--onboard`` sources, each once (a repeated one is read once), their labels
    distinct."""
    from navreplay.logs.onboard import onboard_label

    out = tuple(dict.fromkeys(s.strip() for s in sources))
    if "" in out:
        raise ParamError("--onboard: an empty source")
    labels = [onboard_label(s) for s in out]
    for label in labels:
        if labels.count(label) > 1:
            twins = " and ".join(s for s in out if onboard_label(s) == label)
            raise ParamError(f"--onboard {twins}: two recorded solutions would be named "
                             f"{label}")
    return out
