"""``navreplay info``: one table of the topics — type, the stream each feeds (and which topic was
picked when several could; topics usable as ``--reference`` are marked), frame id, the axis
convention it is read in, count, rate, span and gaps — and below it why each convention was
assumed."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np

from navreplay.core.streams import StreamKind, seconds
from navreplay.io.checks import declared_outages, gap_report, read_policy
from navreplay.io.direct import DirectSource
from navreplay.io.errors import RecordingError
from navreplay.io.files import BAGS, file_kind, read_streams
from navreplay.io.gins import NAV_TYPE
from navreplay.io.info import format_info, recording_info
from navreplay.io.ulog import EKF2_TOPICS
from navreplay.logs.options import LogOptions
from navreplay.logs.reference import REFERENCE_TYPES


def _sensor_lines(sensors: dict, where: str) -> list[str]:
    """The recording's sensor specifications in datasheet units, or why they cannot be read."""
    from navreplay.sensors.specs import SensorSpecs, describe_specs

    if not sensors:
        return ["sensors: no specifications (give [sensors.imu] etc. in `run --config`; "
                "filters use their defaults)"]
    try:
        specs = SensorSpecs.from_metadata(sensors, where)
    except ValueError as e:
        return [f"sensors: cannot be read: {e}"]
    return ["sensors (datasheet units, as [sensors.*] tables take them):", *describe_specs(specs)]


@dataclasses.dataclass(frozen=True)
class LogDescription:
    """What ``navreplay info`` prints, and why it fails.

    Attributes
    ----------
    text : str
    damage : str or None
        The container is damaged (an MCAP file's DAMAGED line, or a rosbag2 folder whose data
        files disagree with its metadata.yaml).
    problem : str or None
        The streams cannot be read as asked (a named topic absent, frame ids that change...).
    """

    text: str
    damage: str | None = None
    problem: str | None = None

    def __str__(self) -> str:
        return self.text


def describe_log(path: str | Path, options: LogOptions | None = None) -> LogDescription:
    """The ``info`` text of a log: the container summary, the topic table, the conventions."""
    options = options or LogOptions()
    path = Path(path)
    damage = None
    listing: list[tuple[str, str, int, int | None, int | None]]
    item = "topic"
    time_base = f"{options.time} {'stamps' if options.time == 'header' else 'times'}"
    container = file_kind(path)
    if container.name in BAGS:
        from navreplay.io.rosbag import bag_topics, check_bag

        check = check_bag(path)
        found = check.found if check is not None and check.found is not None else {}
        listing = [(t, ty, found.get(t, n), None, None) for t, ty, _, n in bag_topics(path)]
        lines = [f"{path}  ({container.name}, {sum(r[2] for r in listing)} messages)"]
        if check is not None and check.problems:
            damage = "; ".join(check.problems)
            lines.append(f"DAMAGED: the data files disagree with metadata.yaml: {damage}")
    elif container.name != "mcap":  # a log read straight into streams (io.direct)
        direct = container.source(path, None)
        assert isinstance(direct, DirectSource)  # the kinds read straight into streams
        topics = direct.listing()
        listing = [(t.name, t.type_name, t.count, t.start_ns, t.end_ns) for t in topics]
        lines = direct.info_lines(topics)
        item, time_base = direct.item, direct.time_base
    else:
        info = recording_info(path)
        listing = [(t.topic, t.schema or "-", t.count, t.start_ns, t.end_ns)
                   for t in info.topics]
        lines = [format_info(info, topic_table=False)]
        lines += _sensor_lines(info.metadata.sensors, str(path))
        damage = info.damage
    problem = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            with read_policy(options.policy):
                recording, sources = read_streams(path, options.read_options(validate=False))
        except RecordingError as exc:
            recording, sources, problem = None, {}, str(exc)
    if recording is not None and options.span is not None:
        try:
            lo, hi = options.span.bounds(recording.t0_ns)
        except ValueError as exc:
            raise RecordingError(f"{path}: {exc}") from None
        lines.append("--start/--end: the streams below over "
                     f"{options.span.describe(recording.t0_ns)}")
        for stream_kind, s in list(recording.streams.items()):
            a = 0 if lo is None else int(s.t_ns.searchsorted(lo))
            b = len(s) if hi is None else int(s.t_ns.searchsorted(hi, side="right"))
            recording.streams[stream_kind] = s.slice(a, max(a, b))
    by_topic: dict[str, list[StreamKind]] = {}  # a GNSS topic can feed gps and gps_vel

    def declared(kind: StreamKind) -> np.ndarray:  # the recording's declared GNSS outages
        assert recording is not None
        return declared_outages(kind, recording.metadata.extra, recording.t0_ns)

    for stream_kind, src in sources.items():
        by_topic.setdefault(src.topic, []).append(stream_kind)
    rows = [(item, "type", "stream", "frame id", "axes", "count", "rate [Hz]", "start [s]",
             "end [s]", "gaps")]
    for topic, type_name, count, start, end in listing:
        fed = by_topic.get(topic, [])
        stream = ("(reference)" if type_name in (*REFERENCE_TYPES, NAV_TYPE)
                  else "(onboard ekf2)" if container.name == "ulog" and type_name in EKF2_TOPICS
                  else "-")
        frame, axes, gaps = "", "", ""
        if fed and recording is not None:
            kind = fed[0]
            s, src = recording[kind], sources[kind]
            stream, frame = ",".join(k.value for k in fed), src.frame_id
            axes = src.convention.value.upper() if src.convention else "-"
            gaps = "yes" if gap_report(s, recording.t0_ns, declared=declared(kind)) else "no"
            if len(s):  # the stream's sample times (header stamps or log times)
                start, end = int(s.t_ns[0]), int(s.t_ns[-1])
            if options.span is not None:
                count = len(s)
        t0 = recording.t0_ns if recording is not None else (start or 0)
        span = (end - start) * 1e-9 if start is not None and end is not None else 0.0
        rows.append((topic, type_name, stream, frame, axes, str(count),
                     f"{(count - 1) / span:.3f}" if count > 1 and span > 0 else "-",
                     f"{float(seconds(start, t0)):.3f}" if start is not None else "-",
                     f"{float(seconds(end, t0)):.3f}" if end is not None else "-", gaps))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines.append("")
    for r in rows:
        cells = [c.rjust(w) if 5 <= i <= 8 else c.ljust(w)
                 for i, (c, w) in enumerate(zip(r, widths, strict=True))]
        lines.append("  ".join(cells).rstrip())
    if problem is not None:
        return LogDescription("\n".join([*lines, "", f"streams: cannot be read: {problem}"]),
                              damage, problem)
    assert recording is not None  # read, or a problem above
    lines += ["", f"streams (what `navreplay run` replays; times from {time_base}):"]
    for kind, src in sources.items():
        picked = f"; picked over {', '.join(src.picked_from)}" if src.picked_from else ""
        axes = (f"{src.convention.value.upper()}: {src.reason}" if src.convention
                else "no axes to convert")
        lines.append(f"  {kind.value:<8} <- {src.topic}: {axes}{picked}")
        stream_gaps = gap_report(recording[kind], recording.t0_ns, declared=declared(kind))
        if stream_gaps:
            lines.append(f"  {'':<8}    {stream_gaps}")
    for w in caught:
        text = str(w.message)
        if "several topics" in text or "header stamps" in text:
            lines.append(f"  ! {text}")
    return LogDescription("\n".join(lines), damage)
