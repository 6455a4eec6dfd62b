"""A recording's table of contents (``navreplay info``): topics, counts, rates, times, metadata.

An intact file is summarised from its summary section and message indexes without decompressing
any chunk; a damaged one is walked like :func:`~navreplay.io.read_recording` does, and the damage
is reported in :attr:`RecordingInfo.damage` instead of a warning.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import os
import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np
from mcap.opcode import Opcode

from navreplay.core.streams import Metadata, StreamKind
from navreplay.io.checks import when
from navreplay.io.convert import AuxColumn
from navreplay.io.errors import RecordingError
from navreplay.io.integrity import contents_problems
from navreplay.io.mcapfile import DAMAGE_ERRORS, FileContents, walk
from navreplay.io.metadata import decode_metadata
from navreplay.io.schemas import KIND_BY_TYPE, METADATA_NAME, SPECS, normalize_type_name

_INDEX_HEAD = struct.Struct("<BQHI")


def _span_s(start_ns: int | None, end_ns: int | None) -> float:
    """Seconds from ``start_ns`` to ``end_ns`` (0 when either is unknown)."""
    if start_ns is None or end_ns is None:
        return 0.0
    return (end_ns - start_ns) * 1e-9


@dataclasses.dataclass(frozen=True)
class TopicInfo:
    """One topic of a recording.

    Attributes
    ----------
    topic : str
    schema : str
        Message type (``pkg/msg/Type``), ``""`` without a schema.
    kind : StreamKind | None
        Stream the topic is read into by default, None when it is not read.
    count : int
        Messages.
    start_ns, end_ns : int | None
        First and last log time [ns], None without messages.
    """

    topic: str
    schema: str
    kind: StreamKind | None
    count: int
    start_ns: int | None
    end_ns: int | None

    @property
    def duration_s(self) -> float:
        """Time from first to last message [s]."""
        return _span_s(self.start_ns, self.end_ns)

    @property
    def rate_hz(self) -> float:
        """Mean message rate [Hz] (0 for fewer than two messages)."""
        d = self.duration_s
        return (self.count - 1) / d if self.count > 1 and d > 0 else 0.0


@dataclasses.dataclass(frozen=True)
class RecordingInfo:
    """What :func:`recording_info` tells about a file.

    Attributes
    ----------
    path : Path
    size_bytes : int
    profile, library : str
        From the MCAP header.
    topics : tuple[TopicInfo, ...]
        Sorted by topic name.
    start_ns, end_ns : int | None
        First and last log time over all topics [ns].
    t0_ns : int
        Recording start (metadata ``t0_ns``, else the first message time) [ns].
    metadata : Metadata
    has_metadata : bool
        Whether the file has a ``navreplay`` metadata record.
    truth_columns : tuple[tuple[str, tuple[int, ...]], ...]
        Names and shapes of the truth message's extra columns.
    damage : str | None
        Why the file could only be partly read, None for an intact file.
    """

    path: Path
    size_bytes: int
    profile: str
    library: str
    topics: tuple[TopicInfo, ...]
    start_ns: int | None
    end_ns: int | None
    t0_ns: int
    metadata: Metadata
    has_metadata: bool
    truth_columns: tuple[tuple[str, tuple[int, ...]], ...]
    damage: str | None = None

    @property
    def duration_s(self) -> float:
        """Time from the first to the last message [s]."""
        return _span_s(self.start_ns, self.end_ns)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics)


class _Counts:
    def __init__(self) -> None:
        self.count: dict[int, int] = {}
        self.lo: dict[int, int] = {}
        self.hi: dict[int, int] = {}

    def add(self, cid: int, times: np.ndarray) -> None:
        if not len(times):
            return
        lo, hi = int(times.min()), int(times.max())
        self.count[cid] = self.count.get(cid, 0) + len(times)
        self.lo[cid] = min(lo, self.lo.get(cid, lo))
        self.hi[cid] = max(hi, self.hi.get(cid, hi))


def _from_indexes(f: BinaryIO, contents: FileContents, where: str) -> _Counts | None:
    """Per-channel counts and times from the message indexes of an intact file."""
    from mcap.reader import SeekingReader

    f.seek(0)
    summary = SeekingReader(f, record_size_limit=contents.size).get_summary()
    if summary is None:
        return None
    counts = _Counts()
    for index in summary.chunk_indexes:
        if not index.message_index_offsets:
            return None
        for cid, offset in index.message_index_offsets.items():
            f.seek(offset)
            head = f.read(_INDEX_HEAD.size)
            opcode, _, channel, nbytes = _INDEX_HEAD.unpack(head)
            if opcode != Opcode.MESSAGE_INDEX or channel != cid:
                raise RecordingError(f"{where}: message index at byte {offset} is corrupt")
            entries = np.frombuffer(f.read(nbytes), dtype="<u8").reshape(-1, 2)
            counts.add(cid, entries[:, 0].astype(np.int64))
    return counts


def recording_info(path: str | os.PathLike[str]) -> RecordingInfo:
    """Summarise a recording: topics with type, count, rate and times; metadata; damage.

    Parameters
    ----------
    path : path-like

    Raises
    ------
    RecordingError
        Not an MCAP file, a CRC mismatch, or nothing readable.
    """
    path = Path(path)
    where = str(path)
    try:
        f = open(path, "rb")  # noqa: SIM115 - closed below
    except FileNotFoundError:
        raise RecordingError(f"{where}: no such file") from None
    with f:
        contents = FileContents(size=os.fstat(f.fileno()).st_size)
        counts = _Counts()
        blocks = walk(f, where, contents, lambda c, ids: False)
        for block in blocks:
            for cid in np.unique(block.channel):
                counts.add(int(cid), block.log_time[block.channel == cid])
        if contents.intact:
            try:
                indexed = _from_indexes(f, contents, where)
            except DAMAGE_ERRORS:
                indexed = None
            if indexed is None:  # no message indexes: read every chunk
                contents = FileContents(size=contents.size)
                counts = _Counts()
                for block in walk(f, where, contents):
                    for cid in np.unique(block.channel):
                        counts.add(int(cid), block.log_time[block.channel == cid])
            else:
                counts = indexed
    records = [m for m in contents.metadata if m.name == METADATA_NAME]
    meta, t0_ns, aux = Metadata(), None, list[AuxColumn]()
    if records:
        meta, t0_ns, aux = decode_metadata(records[-1].metadata, where)
    topics = []
    for cid, channel in contents.channels.items():
        schema = contents.schemas.get(channel.schema_id)
        type_name = normalize_type_name(schema.name) if schema is not None else ""
        kind = next((k for k, s in SPECS.items() if s.topic == channel.topic), None)
        if kind is None:
            by_type = KIND_BY_TYPE.get(type_name)
            kind = by_type if by_type is not None and SPECS[by_type].by_schema else None
        topics.append(
            TopicInfo(
                channel.topic,
                type_name,
                kind,
                counts.count.get(cid, 0),
                counts.lo.get(cid),
                counts.hi.get(cid),
            )
        )
    topics.sort(key=lambda t: t.topic)
    starts = [t.start_ns for t in topics if t.start_ns is not None]
    ends = [t.end_ns for t in topics if t.end_ns is not None]
    start = min(starts) if starts else None
    damage = None
    if contents.damage is not None:
        d = contents.damage
        what = "summary or footer" if d.data_complete else "file"
        damage = f"{what} truncated or damaged at byte {d.offset} of {contents.size} ({d.reason})"
    duration = meta.params.get("duration") if records else None
    problems = contents_problems(
        counts.count, counts.lo, counts.hi, {c: ch.topic for c, ch in contents.channels.items()},
        contents.statistics if contents.intact else None, t0_ns,
        float(duration) if isinstance(duration, int | float) else None,
    )
    if problems:
        damage = "; ".join(([damage] if damage else []) + problems)
    return RecordingInfo(
        path=path,
        size_bytes=contents.size,
        profile=contents.profile,
        library=contents.library,
        topics=tuple(topics),
        start_ns=start,
        end_ns=max(ends) if ends else None,
        t0_ns=t0_ns if t0_ns is not None else (start or 0),
        metadata=meta,
        has_metadata=bool(records),
        truth_columns=tuple((c.name, c.shape) for c in aux),
        damage=damage,
    )


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"


def _utc(t_ns: int) -> str:
    stamp = dt.datetime.fromtimestamp(t_ns // 1_000_000_000, tz=dt.UTC)
    return stamp.strftime("%Y-%m-%d %H:%M:%S UTC")


def _json_lines(title: str, obj: dict) -> list[str]:
    if not obj:
        return []
    lines = [f"{title}:"]
    for key, value in obj.items():
        lines.append(f"  {key} = {json.dumps(value)}")
    return lines


def format_info(info: RecordingInfo, topic_table: bool = True) -> str:
    """A human-readable, multi-line summary of :func:`recording_info`'s result (without the
    per-topic table when ``topic_table`` is False: ``navreplay info`` prints its own)."""
    meta = info.metadata
    lines = [
        f"{info.path}  ({_size(info.size_bytes)}, profile {info.profile or '-'!r}, "
        f"{info.message_count} messages)"
    ]
    if info.damage:
        lines.append(f"DAMAGED: {info.damage}; read_recording salvages what comes before")
    if info.has_metadata:
        seed = "-" if meta.seed is None else str(meta.seed)
        lines.append(
            f"scenario: {meta.scenario or '-'}   seed: {seed}   navreplay: "
            f"{meta.navreplay_version or '-'}"
        )
    else:
        lines.append("no navreplay metadata (a recording from elsewhere)")
    if info.start_ns is not None:
        lines.append(
            f"start: {_utc(info.t0_ns)} (t0 = {info.t0_ns} ns)   duration: {info.duration_s:.3f} s"
        )
    header = ("topic", "type", "stream", "count", "rate [Hz]", "start [s]", "end [s]")
    rows = [header]
    for t in info.topics if topic_table else ():
        rows.append(
            (
                t.topic,
                t.schema or "-",
                t.kind.value if t.kind is not None else "-",
                str(t.count),
                f"{t.rate_hz:.3f}" if t.count > 1 else "-",
                f"{(t.start_ns - info.t0_ns) * 1e-9:.3f}" if t.start_ns is not None else "-",
                f"{(t.end_ns - info.t0_ns) * 1e-9:.3f}" if t.end_ns is not None else "-",
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    for r in rows if topic_table else ():
        cells = [
            c.ljust(w) if i < 3 else c.rjust(w)
            for i, (c, w) in enumerate(zip(r, widths, strict=True))
        ]
        lines.append("  ".join(cells).rstrip())
    if info.truth_columns:
        cols = ", ".join(f"{n}{list(s) if s else ''}" for n, s in info.truth_columns)
        lines.append(f"truth extra columns: {cols}")
    lines += _json_lines("params", meta.params)
    lines += _json_lines("true_errors", meta.true_errors)
    lines += _json_lines("initial_nav", meta.initial_nav)
    lines += _json_lines("extra", meta.extra)
    if info.end_ns is not None and info.start_ns is not None and info.damage:
        lines.append(f"last message at {when(info.end_ns, info.t0_ns)}")
    return "\n".join(lines)
