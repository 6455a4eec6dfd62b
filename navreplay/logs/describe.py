"""``navreplay info``: per topic its type, frame id, the stream it feeds (and which topic was
picked when several could), the convention it is read in and why, rate and gaps."""

from __future__ import annotations

import warnings
from pathlib import Path

from navreplay.io.checks import gap_report
from navreplay.io.errors import RecordingError
from navreplay.io.info import format_info, recording_info
from navreplay.io.reader import is_rosbag, read_streams
from navreplay.logs.options import LogOptions


def describe_log(path: str | Path, options: LogOptions | None = None) -> str:
    """The ``info`` text of a log: the container summary, then how each stream is fed."""
    options = options or LogOptions()
    path = Path(path)
    lines = []
    if is_rosbag(path):
        from navreplay.io.rosbag import bag_topics

        lines.append(f"{path}  (rosbag2)")
        for topic, type_name, fmt, count in bag_topics(path):
            lines.append(f"  {topic}  {type_name}  {count} messages  ({fmt})")
    else:
        lines.append(format_info(recording_info(path)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            recording, sources = read_streams(path, topics=options.topics,
                                              frames=options.stream_frames, validate=False)
        except RecordingError as exc:
            return "\n".join([*lines, "", f"streams: cannot be read: {exc}"])
    lines += ["", "streams (what `navreplay run` replays):"]
    for kind, src in sources.items():
        s = recording[kind]
        dur = (s.t_ns[-1] - s.t_ns[0]) * 1e-9 if len(s) > 1 else 0.0
        rate = (len(s) - 1) / dur if dur > 0 else 0.0
        conv = src.convention.value.upper() if src.convention else "-"
        picked = f"; picked over {', '.join(src.picked_from)}" if src.picked_from else ""
        lines.append(f"  {kind.value:<10} <- {src.topic} ({src.type_name}), frame id "
                     f"{src.frame_id!r}{picked}")
        lines.append(f"  {'':<10}    convention {conv}: {src.reason}")
        gaps = gap_report(s, recording.t0_ns)
        lines.append(f"  {'':<10}    {len(s)} samples, {rate:.3f} Hz, "
                     f"{gaps or 'no gaps'}")
    for w in caught:
        if "several topics" in str(w.message):
            lines.append(f"  ! {w.message}")
    return "\n".join(lines)
