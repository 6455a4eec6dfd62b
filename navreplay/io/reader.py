"""Read an MCAP recording into a :class:`~navreplay.streams.Recording`, bulk-decoded.

Topics map to stream kinds by name (:data:`~navreplay.io.schemas.TOPICS`), or, in a recording from
elsewhere, by message type when exactly one topic carries it. Payloads are decoded chunk by chunk:
equally long payloads with one fixed layout are viewed as a numpy structured array; anything else
goes through mcap-ros2-support's generic decoder. Decoded fields are reduced at once to what the
columns need, so memory stays close to the size of the resulting columns.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
from mcap.records import Channel, Schema

from navreplay.io import cdr
from navreplay.io.checks import check_frame_ids, first_problem, gap_report, when
from navreplay.io.convert import DECODERS, REDUCE, AuxColumn, Convention
from navreplay.io.errors import RecordingError, RecordingWarning, SalvagedWarning
from navreplay.io.mcapfile import FileContents, MessageBlock, walk
from navreplay.io.metadata import decode_metadata
from navreplay.io.schemas import (
    KIND_BY_TYPE,
    MESSAGE_ENCODING,
    METADATA_NAME,
    SPECS,
    MessageType,
    normalize_type_name,
)
from navreplay.streams import Metadata, Recording, Stream, StreamKind


def _warn(message: str) -> None:
    warnings.warn(RecordingWarning(message), stacklevel=3)


def _salvaged(data_complete: bool, message: str) -> None:
    warnings.warn(SalvagedWarning(message, data_complete=data_complete), stacklevel=3)


class _Topic:
    """Decoded fields of one channel, accumulated block by block."""

    def __init__(self, channel: Channel, schema: Schema | None, message: MessageType, where: str):
        self.channel = channel
        self.schema = schema
        self.message = message
        self.where = where
        self.reduce = REDUCE[KIND_BY_TYPE[message.name]]
        self.parts: list[dict[str, np.ndarray]] = []
        self.frame_ids: set[str] = set()
        self.first_frame_id: str | None = None  # of the earliest message in file order
        self._first_ordinal = -1
        self._generic: cdr.GenericDecoder | None = None
        self.ordinals: list[int | np.ndarray] = []
        self.log_times: list[np.ndarray | None] = []
        self.in_order = True
        self._next = 0
        self._count = 0
        self.log_ns: np.ndarray | None = None  # log times of finish()'s rows

    @property
    def label(self) -> str:
        return f"{self.where}: topic {self.channel.topic} ({self.message.name})"

    def add(self, block: MessageBlock, index: np.ndarray) -> None:
        """Decode messages ``index`` of a block (all of this channel)."""
        ordinal = self._count + np.arange(len(index), dtype=np.int64)
        self._count += len(index)
        lengths = block.length[index]
        if not lengths.size:
            return
        if lengths.min() == lengths.max():  # the usual case: one fixed layout
            self._add_equal(block, index, ordinal, int(lengths[0]))
            return
        for width in np.unique(lengths):
            sel = np.flatnonzero(lengths == width)
            self._add_equal(block, index[sel], ordinal[sel], int(width))

    def _add_equal(self, block: MessageBlock, index: np.ndarray, ordinal: np.ndarray, width: int):
        rows = block.rows(index, width)
        remaining = np.arange(len(index))
        while remaining.size:
            lay = cdr.peek_layout(rows[remaining[:1]], self.message)
            if lay is None:
                payloads = [block.payload(int(i)) for i in index[remaining]]
                self._keep(
                    self._decode_generic(payloads), block, index[remaining], ordinal[remaining]
                )
                return
            sub = rows if remaining.size == len(rows) else rows[remaining]
            ok = cdr.matches_layout(sub, lay)  # true for the first row, which defined `lay`
            take = remaining[ok]
            records = cdr.view_records(rows[take] if take.size != len(rows) else rows, lay)
            fields = cdr.records_to_fields(records, self.message)
            self._keep(fields, block, index[take], ordinal[take])
            remaining = remaining[~ok]

    def _decode_generic(self, payloads: list[bytes]) -> dict[str, np.ndarray]:
        try:
            if self._generic is None:
                if self.schema is None:
                    raise RecordingError("the channel has no schema")
                self._generic = cdr.GenericDecoder(self.schema)
            return self._generic.decode(payloads, self.message)
        except RecordingError as exc:
            raise RecordingError(f"{self.label}: {exc}") from None
        except Exception as exc:  # the generic decoder raises many types on foreign data
            raise RecordingError(
                f"{self.label}: messages do not decode with schema "
                f"{self.schema.name if self.schema else None!r} ({exc!r})"
            ) from None

    def _keep(
        self,
        fields: dict[str, np.ndarray],
        block: MessageBlock,
        index: np.ndarray,
        ordinal: np.ndarray,
    ) -> None:
        frames = fields["frame_id"]
        if len(frames):
            if self.first_frame_id is None or ordinal[0] < self._first_ordinal:
                self.first_frame_id, self._first_ordinal = str(frames[0]), int(ordinal[0])
            if (frames == frames[0]).all():
                self.frame_ids.add(frames[0])
            else:
                self.frame_ids.update(frames.tolist())
        t_ns = np.asarray(fields["t_ns"], dtype=np.int64)
        part = {"t_ns": t_ns}
        for name, columns in self.reduce.items():
            value = np.asarray(fields[name])
            part[name] = np.array(value if columns is None else value[:, columns])
        self.parts.append(part)
        m = len(ordinal)
        if m and ordinal[0] == self._next and ordinal[-1] == self._next + m - 1:
            self.ordinals.append(int(ordinal[0]))
        else:
            self.ordinals.append(ordinal)
            self.in_order = False
        if m:
            self._next = int(ordinal[-1]) + 1
        log_time = block.log_time[index]
        if np.array_equal(log_time, t_ns):
            self.log_times.append(None)
        else:
            self.log_times.append(log_time)

    def drain(self) -> dict[str, np.ndarray]:
        """:meth:`finish` the rows so far and start afresh (a time window of the topic)."""
        out = self.finish()
        self.ordinals.clear()
        self.log_times.clear()
        self.in_order = True
        return out

    def rows(self) -> int:
        """Rows decoded and not yet finished."""
        return sum(len(p["t_ns"]) for p in self.parts)

    def finish(self) -> dict[str, np.ndarray]:
        """Concatenated fields in log-time order (file order among equal log times)."""
        if not self.parts:
            return {
                "t_ns": np.zeros(0, np.int64),
                **{
                    name: _empty_leaf(self.message, name, columns)
                    for name, columns in self.reduce.items()
                },
            }
        log_time = None
        if any(lt is not None for lt in self.log_times):
            log_time = np.concatenate(
                [
                    p["t_ns"] if lt is None else lt
                    for p, lt in zip(self.parts, self.log_times, strict=True)
                ]
            )
        ordinal = None
        if not self.in_order:
            ordinal = np.concatenate(
                [
                    np.arange(o, o + len(p["t_ns"])) if isinstance(o, int) else o
                    for p, o in zip(self.parts, self.ordinals, strict=True)
                ]
            )
        out: dict[str, np.ndarray] = {}
        try:
            for key in list(self.parts[0]):  # concatenate key by key, freeing the parts
                out[key] = np.concatenate([p.pop(key) for p in self.parts])
        except (KeyError, ValueError) as exc:
            raise RecordingError(f"{self.label}: message layout changes ({exc!r})") from None
        self.parts.clear()
        if log_time is None:
            log_time = out["t_ns"]
        order = None
        if ordinal is not None:
            order = np.argsort(ordinal, kind="stable")
            log_time = log_time[order]
        if np.any(np.diff(log_time) < 0):
            by_time = np.argsort(log_time, kind="stable")
            order = by_time if order is None else order[by_time]
        if order is not None:
            out = {k: v[order] for k, v in out.items()}
        self.log_ns = log_time
        return out


def _empty_leaf(message: MessageType, name: str, columns: list[int] | None) -> np.ndarray:
    leaves = {leaf.name: leaf for leaf in message.leaves}
    if message.sequence is not None:
        leaves[message.sequence.name] = dataclasses.replace(message.sequence, count=0)
    leaf = leaves[name]
    width = leaf.count if columns is None else len(columns)
    shape = (0,) if leaf.count == 1 and columns is None else (0, width)
    return np.zeros(shape, dtype=np.dtype(leaf.ctype))


@dataclasses.dataclass
class _Candidate:
    channel: Channel
    schema: Schema | None
    kind: StreamKind
    canonical: bool
    type_name: str
    encoding: str


def _candidate(
    channel: Channel,
    schemas: Mapping[int, Schema],
    topic_kinds: Mapping[str, StreamKind],
) -> _Candidate | None:
    schema = schemas.get(channel.schema_id)
    type_name = normalize_type_name(schema.name) if schema is not None else ""
    kind = topic_kinds.get(channel.topic)
    encoding = channel.message_encoding
    if kind is not None:
        return _Candidate(channel, schema, kind, True, type_name, encoding)
    kind = KIND_BY_TYPE.get(type_name)
    if kind is not None and SPECS[kind].by_schema and encoding == MESSAGE_ENCODING:
        return _Candidate(channel, schema, kind, False, type_name, encoding)
    return None


class _Plan:
    """Which channels to decode, decided as channels become known."""

    def __init__(self, where: str, wanted: set[StreamKind], topic_kinds: dict[str, StreamKind]):
        self.where = where
        self.wanted = wanted
        self.topic_kinds = topic_kinds
        self.candidates: dict[int, _Candidate | None] = {}
        self.topics: dict[int, _Topic] = {}

    def topic_of(self, contents: FileContents, channel_id: int) -> _Topic | None:
        channel = contents.channels.get(channel_id)
        if channel_id not in self.candidates and channel is not None:
            cand = _candidate(channel, contents.schemas, self.topic_kinds)
            if cand is not None and cand.kind not in self.wanted:
                cand = None
            self.candidates[channel_id] = cand
            spec = SPECS[cand.kind] if cand is not None else None
            if (
                cand is not None
                and spec is not None
                and cand.type_name == spec.message.name
                and cand.encoding == MESSAGE_ENCODING
            ):
                self.topics[channel_id] = _Topic(
                    cand.channel, cand.schema, spec.message, self.where
                )
        return self.topics.get(channel_id)

    def wants_chunk(self, contents: FileContents, channel_ids: set[int]) -> bool:
        return any(self.topic_of(contents, c) is not None for c in channel_ids)

    def feed(self, contents: FileContents, block: MessageBlock) -> None:
        if not len(block):
            return
        channels = block.channel
        for cid in np.unique(channels):
            topic = self.topic_of(contents, int(cid))
            if topic is not None:
                topic.add(block, np.flatnonzero(channels == cid))

    def others(self, kind: StreamKind, topic: str) -> tuple[str, ...]:
        """The other topics that could have been stream ``kind``."""
        return tuple(sorted(c.channel.topic for c in self.candidates.values()
                            if c is not None and c.kind is kind and c.channel.topic != topic))

    def resolve(self, contents: FileContents, explicit: bool) -> dict[StreamKind, _Topic]:
        """Pick one topic per wanted kind; raise for a kind that cannot be mapped."""
        for cid in contents.channels:
            self.topic_of(contents, cid)
        chosen: dict[StreamKind, _Topic] = {}
        for kind in SPECS:
            if kind not in self.wanted:
                continue
            cands = [c for c in self.candidates.values() if c is not None and c.kind is kind]
            i = pick_topic(self.where, kind, [(c.channel.topic, c.type_name, c.encoding,
                                               c.canonical) for c in cands], explicit)
            if i is not None:
                chosen[kind] = self.topics[cands[i].channel.id]
        return chosen


def pick_topic(where: str, kind: StreamKind, cands: list[tuple[str, str, str, bool]],
               explicit: bool) -> int | None:
    """Index of the topic that feeds stream ``kind`` among candidates (topic, type, encoding,
    named-for-it), or None; several equally good ones are an error when ``explicit``, else a
    warning (the stream is skipped)."""
    spec = SPECS[kind]
    for topic, type_name, encoding, canonical in cands:
        if canonical and (type_name != spec.message.name or encoding != MESSAGE_ENCODING):
            raise RecordingError(
                f"{where}: topic {topic} has schema {type_name or None!r} in {encoding!r} "
                f"encoding; stream {kind.value} needs {spec.message.name} in "
                f"{MESSAGE_ENCODING!r} encoding"
            )
    pick = [i for i, c in enumerate(cands) if c[3]] or list(range(len(cands)))
    if len(pick) == 1:
        return pick[0]
    if len(pick) > 1:
        names = ", ".join(sorted(cands[i][0] for i in pick))
        message = (f"{where}: several topics could be stream {kind.value} ({names}); "
                   f"name one with --topic {kind.value}=TOPIC (or a [topics] table)")
        if explicit:
            raise RecordingError(message)
        _warn(message + "; stream skipped")
    return None


def _describe_topics(contents: FileContents) -> str:
    items = []
    for ch in sorted(contents.channels.values(), key=lambda c: c.topic):
        schema = contents.schemas.get(ch.schema_id)
        items.append(f"{ch.topic} ({schema.name if schema else 'no schema'})")
    return ", ".join(items) or "no topics"


@dataclasses.dataclass(frozen=True)
class TopicSource:
    """Where a stream came from and how its vectors were read.

    Attributes
    ----------
    topic : str
    type_name : str
        Message type (``pkg/msg/Type``).
    frame_id : str
        ``header.frame_id`` on the wire (of the first message).
    convention : Convention or None
        Axis convention the vectors were read in (None: no frame-dependent vectors).
    reason : str
        Why (declared by the user, or the frame id's REP-103 meaning).
    picked_from : tuple of str
        Other topics that could have fed the stream (empty when it was the only one).
    """

    topic: str
    type_name: str
    frame_id: str
    convention: Convention | None
    reason: str
    picked_from: tuple[str, ...] = ()


def read_recording(
    path: str | os.PathLike[str],
    *,
    kinds: Iterable[StreamKind | str] | None = None,
    validate: bool = True,
    topics: Mapping[StreamKind | str, str] | None = None,
    frames: Mapping[StreamKind | str, Convention | str] | None = None,
    time: str = "header",
) -> Recording:
    """Read a recording into columnar streams (see :func:`read_streams`)."""
    return read_streams(path, kinds=kinds, validate=validate, topics=topics, frames=frames,
                        time=time)[0]


def read_streams(
    path: str | os.PathLike[str],
    *,
    kinds: Iterable[StreamKind | str] | None = None,
    validate: bool = True,
    topics: Mapping[StreamKind | str, str] | None = None,
    frames: Mapping[StreamKind | str, Convention | str] | None = None,
    time: str = "header",
    skip: Iterable[StreamKind] = (),
) -> tuple[Recording, dict[StreamKind, TopicSource]]:
    """Read a recording into columnar streams.

    Parameters
    ----------
    path : path-like
        An MCAP file (ROS 2 profile, CDR messages), read in bulk; or a rosbag2 folder (its
        ``metadata.yaml``; MCAP or sqlite3 storage, split files) or a ``.db3`` file, read with
        ``rosbags`` (:mod:`navreplay.io.rosbag`).
    kinds : iterable of StreamKind or str, optional
        Streams to read (all known ones when None). A kind asked for and absent is an error.
    validate : bool
        Check every stream: a non-finite value or a timestamp that repeats or goes backwards raises
        :class:`RecordingError`; gaps longer than 5x the median interval give a
        :class:`RecordingWarning`.
    topics : mapping of StreamKind or str to str, optional
        Topic to read for a kind, overriding :data:`~navreplay.io.schemas.TOPICS` (for recordings
        from elsewhere).
    frames : mapping of StreamKind or str to Convention or str, optional
        Declared axis convention of a stream's topic (``flu``/``frd`` for imu and mag,
        ``enu``/``ned`` for gps_vel), replacing the guess from the frame id.
    time : {"header", "log"}
        Sample times: the messages' ``header.stamp`` (falling back to the log times, with a
        warning, for a topic whose stamps are zero or do not increase), or the log (receive)
        times (:func:`sample_times`).
    skip : iterable of StreamKind
        Streams not to read (read in time windows by :mod:`navreplay.io.windows`).

    Returns
    -------
    Recording
        Streams in :class:`StreamKind` order; ``t_ns`` as ``time`` says [ns]. The metadata is
        the file's ``navreplay`` record, or ``Metadata()`` for a recording without one, whose
        ``t0_ns`` is then its first message's log time.
    sources : dict[StreamKind, TopicSource]
        Topic, frame id and convention of each stream.

    Raises
    ------
    RecordingError
        Not an MCAP file, a CRC mismatch or corrupt chunk, a damaged file with nothing to salvage,
        a topic whose schema does not fit its stream, a stream asked for and absent, or (with
        ``validate``) bad samples. The message names the file, and the topic and time where it
        applies.

    Warns
    -----
    RecordingWarning
        The file is truncated or unfinished (the messages before the damage are returned and the
        warning tells the time of the last one), conversions of a foreign frame convention, gaps.
    """
    path = Path(path)
    where = str(path)
    explicit = kinds is not None
    wanted = set(SPECS) if kinds is None else {StreamKind(k) for k in kinds}
    wanted -= set(skip)
    topic_kinds = topic_map(topics)
    declared = {StreamKind(k): Convention(str(v).lower()) for k, v in (frames or {}).items()}
    if is_rosbag(path):
        from navreplay.io.rosbag import read_rosbag

        return read_rosbag(path, wanted, explicit, topic_kinds, declared, validate, topics,
                           time)
    plan = _Plan(where, wanted, topic_kinds)
    try:
        f = open(path, "rb")  # noqa: SIM115 - closed below
    except FileNotFoundError:
        raise RecordingError(f"{where}: no such file") from None
    with f:
        contents = FileContents(size=os.fstat(f.fileno()).st_size)
        for block in walk(f, where, contents, plan.wants_chunk):
            plan.feed(contents, block)
    damage = contents.damage
    if damage is not None and contents.message_count == 0:
        raise RecordingError(
            f"{where}: file is damaged at byte {damage.offset} of {contents.size} "
            f"({damage.reason}) before any complete message; nothing to salvage"
        )
    meta, t0_ns, aux = _metadata(contents, where)
    if damage is not None:
        last = contents.last_log_time
        if damage.data_complete:
            _salvaged(
                True, f"{where}: summary or footer missing or damaged at byte {damage.offset} of "
                f"{contents.size} ({damage.reason}); all {contents.message_count} messages "
                f"were recovered, the last at {when(last, t0_ns)}"
            )
        else:
            _salvaged(
                False, f"{where}: file is truncated or damaged at byte {damage.offset} of "
                f"{contents.size} ({damage.reason}); salvaged {contents.message_count} messages, "
                f"the last good one at {when(last, t0_ns)}; anything after is lost"
            )
    chosen = plan.resolve(contents, explicit)
    check_named_topics(where, topics, {k: t.channel.topic for k, t in chosen.items()},
                       _describe_topics(contents))
    if explicit:
        missing = [k.value for k in SPECS if k in wanted and k not in chosen]
        if missing:
            raise RecordingError(
                f"{where}: no topic for stream(s) {', '.join(missing)}; the file has "
                f"{_describe_topics(contents)}"
            )
    streams: dict[StreamKind, Stream] = {}
    sources: dict[StreamKind, TopicSource] = {}
    for kind, topic in chosen.items():
        frame_id = topic.first_frame_id or SPECS[kind].frame_id
        note = check_frame_ids(kind, topic.label, topic.frame_ids, declared.get(kind), frame_id)
        if note:
            _warn(f"{topic.label}: {note}")
        fields = topic.finish()
        fields["t_ns"] = sample_times(fields["t_ns"], topic.log_ns, time, topic.label)
        streams[kind], sources[kind] = build_stream(
            kind, fields, frame_id, topic.label, aux, t0_ns, validate,
            declared.get(kind), topic.channel.topic, plan.others(kind, topic.channel.topic))
    return Recording(streams=streams, metadata=meta, t0_ns=t0_ns), sources


TIME_SOURCES = ("header", "log")
"""``--time``: sample times from the header stamps (default) or the log (receive) times."""


def sample_times(stamps: np.ndarray, log_ns: np.ndarray | None, time: str, label: str
                 ) -> np.ndarray:
    """A topic's sample times [ns], rows in log-time order.

    ``time="log"``: the log times. ``"header"``: the header stamps, unless any is zero or they
    do not increase (a driver that never sets them, or stamps that jump back): then the log
    times, with a warning that says why.
    """
    if time not in TIME_SOURCES:
        raise ValueError(f"time source {time!r}: use header or log")
    log = stamps if log_ns is None else np.asarray(log_ns, dtype=np.int64)
    if time == "log" or not stamps.size:
        return log.copy()
    why = ""
    if not stamps.all():
        why = f"{int(np.sum(stamps == 0))} header stamps are zero"
    elif np.any(np.diff(stamps) <= 0):
        k = int(np.argmax(np.diff(stamps) <= 0)) + 1
        why = (f"header stamps do not increase (message {k}, stamp {int(stamps[k])} ns after "
               f"{int(stamps[k - 1])} ns)")
    if why and not np.array_equal(log, stamps):
        _warn(f"{label}: {why}; the log times are used (--time log says so explicitly)")
        return log.copy()
    return stamps


def topic_map(topics: Mapping[StreamKind | str, str] | None) -> dict[str, StreamKind]:
    """Topic -> stream kind: the canonical topics, with ``topics`` (kind -> topic) replacing
    them kind by kind."""
    topic_kinds = {spec.topic: kind for kind, spec in SPECS.items()}
    for kind, topic in (topics or {}).items():
        kind = StreamKind(kind)
        topic_kinds = {t: k for t, k in topic_kinds.items() if k is not kind}
        topic_kinds[topic] = kind
    return topic_kinds


def check_named_topics(where: str, topics: Mapping[StreamKind | str, str] | None,
                       chosen: Mapping[StreamKind, str], available: str) -> None:
    """Raise when a topic named for a stream was not found (or not usable)."""
    for kind, topic in (topics or {}).items():
        if chosen.get(StreamKind(kind)) != topic:
            raise RecordingError(
                f"{where}: topic {topic} named for stream {StreamKind(kind).value} is not in "
                f"the file; it has {available}"
            )


def is_rosbag(path: Path) -> bool:
    """Whether ``path`` is a rosbag2 folder, its metadata.yaml, or a sqlite3 ``.db3`` file."""
    return path.is_dir() or path.suffix == ".db3" or path.name == "metadata.yaml"


def _metadata(contents: FileContents, where: str) -> tuple[Metadata, int, list[AuxColumn]]:
    records = [m for m in contents.metadata if m.name == METADATA_NAME]
    meta, t0_ns, aux = Metadata(), None, []
    if records:
        meta, t0_ns, aux = decode_metadata(records[-1].metadata, where)
    if t0_ns is None:
        stats = contents.statistics
        if contents.intact and stats is not None and stats.message_count:
            t0_ns = int(stats.message_start_time)
        else:
            t0_ns = contents.first_log_time or 0
    return meta, t0_ns, aux


def build_stream(
    kind: StreamKind,
    fields: Mapping[str, np.ndarray],
    frame_id: str,
    label: str,
    aux: list[AuxColumn],
    t0_ns: int,
    validate: bool,
    convention: Convention | None = None,
    topic: str = "",
    others: tuple[str, ...] = (),
    report_gaps: bool = True,
) -> tuple[Stream, TopicSource]:
    """Decoded message fields of one topic -> a checked stream (conversions reported; gaps
    too with ``validate`` and ``report_gaps``)."""
    try:
        decoded = DECODERS[kind](fields, frame_id, aux, convention)
    except (RecordingError, ValueError) as exc:
        raise RecordingError(f"{label}: {exc}") from None
    t_ns = fields["t_ns"]
    columns = decoded.columns
    if decoded.keep is not None:
        t_ns = t_ns[decoded.keep]
        columns = {k: v[decoded.keep] for k, v in columns.items()}
    for note in decoded.notes:
        _warn(f"{label}: {note}")
    stream = Stream(kind, t_ns, columns, decoded.frame_id or frame_id)
    if validate:
        problem = first_problem(stream, t0_ns)
        if problem:
            raise RecordingError(f"{label}: {problem}")
        gaps = gap_report(stream, t0_ns) if report_gaps else None
        if gaps:
            _warn(f"{label}: {gaps}")
    source = TopicSource(topic, SPECS[kind].message.name, frame_id, decoded.convention,
                         decoded.reason, others)
    return stream, source
