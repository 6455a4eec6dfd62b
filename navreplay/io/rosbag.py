"""rosbag2 folders and sqlite3 (``.db3``) bags, read into the same streams as an MCAP file.

An MCAP file is read in bulk by :mod:`navreplay.io.mcapread`. A rosbag2 folder (``metadata.yaml``
with MCAP or sqlite3 storage, one or several split files) whose data files agree with its
``metadata.yaml`` (:func:`check_bag`), are not compressed and hold CDR messages is read from
its data files directly: MCAP files chunk by chunk through
:class:`navreplay.io.decode.ChannelDecoder` as an MCAP recording's topics, sqlite3 files from their
``messages`` table, the payloads of a fixed layout viewed as numpy records
(:func:`navreplay.io.cdr.decode_payloads`). Any other bag
(compressed, damaged, ROS 1, a lone ``.db3``) goes through ``rosbags``' AnyReader, which also
brings the message definitions stored in the bag; a ``.db3`` file is read from its folder when
that has a ``metadata.yaml``, else straight from its sqlite tables with rosbags' standard type
store. Its CDR messages of a fixed layout are decoded in bulk the same way; the others (and a
message of no fixed layout in a bag read directly) are deserialised one by one by rosbags and
gathered by the same leaf paths (:mod:`navreplay.io.schemas`). Either way the fields are
converted and checked exactly like an MCAP topic (:func:`navreplay.io.topics.build_stream`). A
bag is one window (:class:`BagSource`).

Times: ``header.stamp`` is the sample time, or the log (receive) time with ``--time log``; a
topic whose stamps are zero or do not increase takes the log times, with a warning
(:func:`navreplay.io.topics.sample_times`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import sqlite3
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.core.streams import Metadata, Stream, StreamKind
from navreplay.io.cdr import decode_payloads, fields_of_messages
from navreplay.io.checks import check_frame_ids
from navreplay.io.convert import REDUCE
from navreplay.io.errors import RecordingError, RecordingWarning, SalvagedWarning
from navreplay.io.schemas import MESSAGE_ENCODING, SPECS, normalize_type_name
from navreplay.io.source import COMPLETE, FileSource, Window
from navreplay.io.topics import (
    build_stream,
    candidate,
    choose_topics,
    sample_times,
    topic_map,
)

ROS1_FORMAT = "ros1"
"""The serialisation of a ROS 1 bag's messages."""


def bag_folder(path: Path) -> Path | None:
    """The rosbag2 folder of ``path`` (itself, or the folder of its metadata.yaml / .db3), or
    None for a lone ``.db3`` without metadata."""
    if path.is_dir():
        return path
    if (path.parent / "metadata.yaml").is_file():
        return path.parent
    return None


def bag_topics(path: Path) -> list[tuple[str, str, str, int]]:
    """(topic, type ``pkg/msg/Type``, serialisation format, message count) of a bag."""
    with _open(path) as bag:
        return bag.topics()


def iter_messages(path: Path, topic: str) -> Iterator[tuple[int, Any]]:
    """(log time [ns], deserialised message) of one topic, in log-time order."""
    with _open(path) as bag:
        yield from bag.messages([topic])


class _Bag:
    """A bag opened with rosbags: a folder through AnyReader, a lone .db3 through sqlite."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.where = str(path)
        self._reader: Any = None
        self._db: sqlite3.Connection | None = None
        self._store: Any = None

    def __enter__(self) -> _Bag:
        folder = bag_folder(self.path) if self.path.suffix != ".bag" else None
        if not self.path.exists():
            raise RecordingError(f"{self.where}: no such file or folder")
        if folder is not None:
            bag_metadata(folder)  # a garbled metadata.yaml: one line that says where
        from navreplay.io.rosbag1 import is_rosbag1

        try:
            if folder is not None or is_rosbag1(self.path):
                from rosbags.highlevel import AnyReader

                self._reader = AnyReader([folder or self.path])
                self._reader.open()
            else:
                from rosbags.typesys import Stores, get_typestore

                self._db = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True)
                self._db.execute("SELECT name, type, serialization_format FROM topics").fetchall()
                self._store = get_typestore(Stores.LATEST)
        except RecordingError:
            raise
        except Exception as exc:  # rosbags and sqlite raise many types on foreign data
            what = "ROS 1 bag" if is_rosbag1(self.path) else "rosbag2 bag"
            raise RecordingError(f"{self.where}: not a readable {what} "
                                 f"({' '.join(str(exc).split()) or type(exc).__name__})") from None
        return self

    def __exit__(self, *exc: object) -> None:
        if self._reader is not None:
            self._reader.close()
        if self._db is not None:
            self._db.close()

    def topics(self) -> list[tuple[str, str, str, int]]:
        if self._reader is not None:
            out: dict[str, list[Any]] = {}
            for c in self._reader.connections:
                fmt = getattr(c.ext, "serialization_format", ROS1_FORMAT)
                row = out.setdefault(c.topic, [c.topic, normalize_type_name(c.msgtype), fmt, 0])
                row[3] += c.msgcount
            return sorted(tuple(r) for r in out.values())
        assert self._db is not None
        rows = self._db.execute(
            "SELECT t.name, t.type, t.serialization_format, COUNT(m.id) FROM topics t "
            "LEFT JOIN messages m ON m.topic_id = t.id GROUP BY t.id ORDER BY t.name"
        ).fetchall()
        return [(n, normalize_type_name(t), f, int(c)) for n, t, f, c in rows]

    def messages(self, topics: list[str]) -> Iterator[tuple[int, Any]]:
        """(log time [ns], deserialised message) of ``topics``, in log-time order."""
        for t, raw, msgtype, fmt in self.raw(topics):
            yield t, self.deserialize(raw, msgtype, fmt)

    def raw(self, topics: list[str]) -> Iterator[tuple[int, bytes, str, str]]:
        """(log time [ns], serialised message, type, serialisation format) of ``topics``, in
        log-time order."""
        try:
            if self._reader is not None:
                conns = [c for c in self._reader.connections if c.topic in topics]
                for conn, t, raw in self._reader.messages(connections=conns):
                    fmt = getattr(conn.ext, "serialization_format", ROS1_FORMAT)
                    yield int(t), raw, conn.msgtype, fmt
                return
            assert self._db is not None
            marks = ",".join("?" * len(topics))
            query = (f"SELECT m.timestamp, t.type, t.serialization_format, m.data FROM "
                     f"messages m JOIN topics t ON m.topic_id = t.id WHERE t.name IN ({marks}) "
                     "ORDER BY m.timestamp")
            for t, msgtype, fmt, raw in self._db.execute(query, topics):
                yield int(t), bytes(raw), msgtype, fmt
        except RecordingError:
            raise
        except Exception as exc:
            raise self._unreadable(topics, exc) from None

    def deserialize(self, raw: bytes, msgtype: str, fmt: str) -> Any:
        """A message of :meth:`raw` as rosbags' message object (a ROS 1 one in the types of
        the ROS 2 one)."""
        try:
            if self._reader is not None:
                return self._reader.deserialize(raw, msgtype)
            return self._store.deserialize_cdr(raw, msgtype)
        except Exception as exc:
            raise self._unreadable([msgtype], exc) from None

    def _unreadable(self, topics: list[str], exc: Exception) -> RecordingError:
        return RecordingError(
            f"{self.where}: messages of {', '.join(topics)} cannot be read "
            f"({type(exc).__name__}: {' '.join(str(exc).split())})")


def _open(path: Path) -> _Bag:
    return _Bag(path)


def accepts(path: Path) -> bool:
    """Whether ``path`` is a rosbag2 folder, its metadata.yaml, or a sqlite3 ``.db3`` file."""
    return path.is_dir() or path.suffix == ".db3" or path.name == "metadata.yaml"


class BagSource(FileSource):
    """The streams of a rosbag2 folder or ``.db3`` as one window (arguments as
    :class:`navreplay.io.source.FileSource`; bags are read whole, whatever the options'
    ``window``)."""

    kind = "rosbag2"

    def _windows(self) -> Iterator[Window]:
        where, opts = self.name, self.options
        topic_kinds = topic_map(opts.topics)
        metadata, check = self._check()
        data = _bulk_data(self.path, check)
        with contextlib.ExitStack() as stack:
            bag: _Bag | None = None
            if data is None:  # through rosbags' reader
                bag = stack.enter_context(_open(self.path))
                listing = bag.topics()
            else:
                listing = data[2]
            available = ", ".join(f"{t} ({ty})" for t, ty, _, _ in listing) or "no topics"
            # rosbags deserialises ROS 1 messages into the types of the ROS 2 ones
            cands = [c for t, ty, fmt, _ in listing
                     if (c := candidate(t, ty, MESSAGE_ENCODING if fmt == ROS1_FORMAT else fmt,
                                        topic_kinds)) is not None]
            chosen = choose_topics(where, cands, opts.wanted(), explicit=opts.explicit,
                                   named=opts.topics, available=available, what="bag")
            with warnings.catch_warnings():  # (said once, for the streams read)
                warnings.simplefilter("ignore", RecordingWarning)
                present = choose_topics(where, cands, set(SPECS), explicit=False,
                                        named=opts.topics, available=available, what="bag")
            topics = {kind: c.topic for kind, (c, _) in chosen.items()}
            if data is not None and data[0] == "mcap":
                gathered = _read_mcap_topics(data[1], topics, where)
            elif data is not None:
                gathered = _read_sqlite_topics(self.path, data[1], topics, where)
            else:
                assert bag is not None
                gathered = {kind: _read_topic(bag, topic, kind, _label(where, topic, kind))
                            for kind, topic in topics.items()}
        # t0: first log time over the chosen topics
        firsts = [int(log_ns.min()) for _, log_ns, _ in gathered.values() if log_ns.size]
        t0_ns = min(firsts) if firsts else 0
        streams: dict[StreamKind, Stream] = {}
        for kind, (fields, log_ns, frames) in gathered.items():
            topic, others = chosen[kind][0].topic, chosen[kind][1]
            label = _label(where, topic, kind)
            order = np.argsort(log_ns, kind="stable")
            if np.any(order != np.arange(order.size)):
                fields = {k: v[order] for k, v in fields.items()}
                log_ns = log_ns[order]
            fields["t_ns"] = sample_times(fields["t_ns"], log_ns, opts.time, label)
            frame_id = frames[0] if frames else SPECS[kind].frame_id
            note = check_frame_ids(kind, label, set(frames), opts.frames.get(kind), frame_id)
            if note:
                warnings.warn(RecordingWarning(f"{label}: {note}"), stacklevel=2)
            streams[kind], self.sources[kind] = build_stream(
                kind, fields, frame_id, label, [], t0_ns, opts.validate,
                opts.frames.get(kind), topic, others)
        yield Window(streams, dict.fromkeys(streams, COMPLETE), metadata, t0_ns,
                     frozenset(present), final=True)

    def _check(self) -> tuple[Metadata, BagCheck | None]:
        """The data files against metadata.yaml (:func:`check_bag`): a disagreement is a
        warning, data lost a salvage (the part kept goes into the metadata:
        :attr:`Source.coverage`)."""
        check = check_bag(self.path)
        metadata = Metadata()
        if check is not None and check.problems:
            text = (f"{self.name}: the data disagree with metadata.yaml: "
                    f"{'; '.join(check.problems)}")
            if check.lost:
                self._salvaged = True
                warnings.warn(SalvagedWarning(f"{text}; replaying what the data files hold",
                                              data_complete=False), stacklevel=4)
                if check.declared_duration_s:  # the part replayed (Source.coverage)
                    metadata.params["duration"] = check.declared_duration_s
                metadata.extra["messages_kept"] = check.kept
            else:
                warnings.warn(RecordingWarning(text), stacklevel=4)
        return metadata, check


def _label(where: str, topic: str, kind: StreamKind) -> str:
    return f"{where}: topic {topic} ({SPECS[kind].message.name})"


Gathered = tuple[dict[str, np.ndarray], np.ndarray, list[str]]
"""A topic's fields (``t_ns`` and the stream's reduced columns), their log times [ns] and its
frame ids (the first message's first)."""


def _bulk_data(path: Path, check: BagCheck | None
               ) -> tuple[str, list[Path], list[tuple[str, str, str, int]]] | None:
    """The storage (``mcap``, ``sqlite3``) and data files of a rosbag2 folder whose messages
    are read without rosbags' reader, and its topics as :meth:`_Bag.topics` lists them (from
    metadata.yaml); None unless the files are uncompressed, every topic CDR and the data agree
    with metadata.yaml."""
    folder = bag_folder(path)
    if folder is None or check is None or check.problems or check.found is None:
        return None
    info = bag_metadata(folder)
    storage = info.get("storage_identifier")
    if storage not in ("mcap", "sqlite3") or info.get("compression_mode"):
        return None
    listing = []
    for item in info.get("topics_with_message_count") or []:
        topic = item["topic_metadata"]
        if topic.get("serialization_format") != MESSAGE_ENCODING or "type" not in topic:
            return None  # rosbags' reader says what it makes of it
        listing.append((str(topic["name"]), normalize_type_name(str(topic["type"])),
                        MESSAGE_ENCODING, int(item["message_count"])))
    files = [folder / str(f) for f in info.get("relative_file_paths") or []]
    return str(storage), files, sorted(listing)


def _read_sqlite_topics(path: Path, files: list[Path], topics: dict[StreamKind, str],
                        where: str) -> dict[StreamKind, Gathered]:
    """The chosen topics of a rosbag2 folder's sqlite3 data files, their messages taken from
    the files' tables (the files one after another) and decoded in bulk
    (:func:`navreplay.io.cdr.decode_payloads`); a message of no fixed layout is deserialised
    by rosbags with the bag's own message definitions."""
    out: dict[StreamKind, Gathered] = {}
    with contextlib.ExitStack() as stack:
        dbs = [stack.enter_context(contextlib.closing(
            sqlite3.connect(f"file:{f}?mode=ro", uri=True))) for f in files]
        bag: list[_Bag] = []  # opened for the first message that needs rosbags

        def one_by_one(payloads: list[bytes], types: list[str], label: str, message: Any,
                       index: np.ndarray) -> dict[str, np.ndarray]:
            if not bag:
                bag.append(stack.enter_context(_open(path)))
            msgs = [bag[0].deserialize(payloads[i], types[i], MESSAGE_ENCODING)
                    for i in index.tolist()]
            return _fields_of(msgs, label, message)

        for kind, topic in topics.items():
            label = _label(where, topic, kind)
            rows: list[tuple[int, str, bytes]] = []
            try:
                for db in dbs:
                    rows += db.execute(
                        "SELECT m.timestamp, t.type, m.data FROM messages m JOIN topics t ON "
                        "m.topic_id = t.id WHERE t.name = ? ORDER BY m.timestamp", (topic,))
            except sqlite3.Error as exc:
                raise RecordingError(f"{label}: messages cannot be read ({exc})") from None
            times = np.fromiter((r[0] for r in rows), dtype=np.int64, count=len(rows))
            types = [r[1] for r in rows]
            payloads = [bytes(r[2]) for r in rows]
            del rows
            message = SPECS[kind].message
            fields = decode_payloads(payloads, message, functools.partial(
                one_by_one, payloads, types, label, message))
            out[kind] = _gathered(fields, times, kind)
    return out


def _fields_of(msgs: list[Any], label: str, message: Any) -> dict[str, np.ndarray]:
    """:func:`navreplay.io.cdr.fields_of_messages`, a message lacking a field one line."""
    try:
        return fields_of_messages(msgs, message)
    except (AttributeError, TypeError, ValueError) as exc:
        raise RecordingError(f"{label}: messages lack a field of {message.name} ({exc})"
                             ) from None


def _gathered(fields: dict[str, np.ndarray], times: np.ndarray, kind: StreamKind) -> Gathered:
    """Decoded fields reduced to the stream's columns, with their log times and frame ids."""
    out: dict[str, np.ndarray] = {"t_ns": fields["t_ns"]}
    for name, columns in REDUCE[kind].items():
        value = np.asarray(fields[name])
        out[name] = np.array(value if columns is None else value[:, columns])
    return out, times, list(dict.fromkeys(fields["frame_id"].tolist()))


def _read_mcap_topics(files: list[Path], topics: dict[StreamKind, str], where: str
                      ) -> dict[StreamKind, Gathered]:
    """The chosen topics of a rosbag2 folder's MCAP data files, decoded in bulk chunk by
    chunk as an MCAP recording's (:class:`navreplay.io.decode.ChannelDecoder`: fixed layouts
    viewed as records, others through the file's own schema), the files one after another."""
    from navreplay.io.decode import empty_leaf

    kinds = {topic: kind for kind, topic in topics.items()}
    parts: dict[StreamKind, list[Gathered]] = {kind: [] for kind in topics}
    for path in files:
        for kind, topic_part in _read_mcap_file(path, kinds, where):
            parts[kind].append(topic_part)
    out: dict[StreamKind, Gathered] = {}
    for kind, got in parts.items():
        if not got:  # a topic without messages
            message = SPECS[kind].message
            empty = {"t_ns": np.zeros(0, np.int64), **{
                name: empty_leaf(message, name, columns) for name, columns in REDUCE[kind].items()}}
            out[kind] = (empty, np.zeros(0, np.int64), [])
        elif len(got) == 1:
            out[kind] = got[0]
        else:
            out[kind] = ({k: np.concatenate([g[0][k] for g in got]) for k in got[0][0]},
                         np.concatenate([g[1] for g in got]),
                         list(dict.fromkeys(f for g in got for f in g[2])))
    return out


def _read_mcap_file(path: Path, kinds: dict[str, StreamKind], where: str
                    ) -> list[tuple[StreamKind, Gathered]]:
    """The topics ``kinds`` (topic -> stream) of one MCAP data file (see
    :func:`_read_mcap_topics`)."""
    from navreplay.io.decode import ChannelDecoder
    from navreplay.io.mcapfile import FileContents, walk

    contents = FileContents(size=path.stat().st_size)
    decoders: dict[int, tuple[StreamKind, ChannelDecoder] | None] = {}

    def decoder(cid: int) -> tuple[StreamKind, ChannelDecoder] | None:
        if cid not in decoders:
            ch = contents.channels.get(cid)
            kind = kinds.get(ch.topic) if ch is not None else None
            decoders[cid] = None if ch is None or kind is None else (kind, ChannelDecoder(
                ch, contents.schemas.get(ch.schema_id), SPECS[kind].message, where))
        return decoders[cid]

    with open(path, "rb") as f:
        for block in walk(f, str(path), contents,
                          lambda _, ids: any(decoder(c) is not None for c in ids)):
            for cid in set(block.channel.tolist()):
                if (found := decoder(cid)) is not None:
                    found[1].add(block, np.flatnonzero(block.channel == cid))
    out = []
    for found in decoders.values():
        if found is not None:
            kind, dec = found
            fields = dec.finish()
            assert dec.log_ns is not None
            first = [] if dec.first_frame_id is None else [dec.first_frame_id]
            out.append((kind, (fields, dec.log_ns, [*first, *sorted(dec.frame_ids - set(first))])))
    return out


def _read_topic(bag: _Bag, topic: str, kind: StreamKind, label: str) -> Gathered:
    """One topic's messages read with rosbags' reader: CDR messages of a fixed layout decoded
    in bulk (:func:`navreplay.io.cdr.decode_payloads`, as an MCAP file's); the others, and ROS 1
    messages, deserialised one by one by rosbags."""
    message = SPECS[kind].message
    times: list[int] = []
    payloads: list[bytes] = []
    types: list[str] = []
    formats: set[str] = set()
    for t, raw, msgtype, fmt in bag.raw([topic]):
        times.append(t)
        payloads.append(raw)
        types.append(msgtype)
        formats.add(fmt)

    def one_by_one(index: Sequence[int]) -> dict[str, np.ndarray]:
        fmt = next(iter(formats), MESSAGE_ENCODING)
        return _fields_of([bag.deserialize(payloads[i], types[i], fmt) for i in index], label,
                          message)

    if formats == {MESSAGE_ENCODING}:
        fields = decode_payloads(payloads, message, lambda index: one_by_one(index.tolist()))
    else:
        fields = one_by_one(range(len(payloads)))
    return _gathered(fields, np.asarray(times, dtype=np.int64), kind)


# --------------------------------------------------------------------------------------------
# integrity: the data files against metadata.yaml

BAG_TIME_SLACK_NS = 1_000_000
"""The data may end this much before the end metadata.yaml declares [ns] (rounding)."""


def bag_metadata(folder: Path) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` of a folder's metadata.yaml; a file that is not
    YAML, or not rosbag2 metadata, is one :class:`RecordingError` line."""
    from ruamel.yaml import YAML
    from ruamel.yaml.error import MarkedYAMLError, YAMLError

    path = folder / "metadata.yaml"
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RecordingError(f"{folder}: no metadata.yaml (not a rosbag2 folder)") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: cannot be read ({exc})") from None
    try:
        doc = YAML(typ="safe", pure=True).load(text)
    except MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise RecordingError(f"{path}: not valid YAML{at} ({exc.problem or exc.context})"
                             ) from None
    except YAMLError as exc:
        raise RecordingError(f"{path}: not valid YAML ({' '.join(str(exc).split())})"
                             ) from None
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        raise RecordingError(f"{path}: no rosbag2_bagfile_information (not rosbag2 metadata)")
    return info


@dataclasses.dataclass(frozen=True)
class BagCheck:
    """The data files of a rosbag2 folder against its metadata.yaml.

    Attributes
    ----------
    declared : dict[str, int]
        Messages per topic that metadata.yaml counts.
    found : dict[str, int] or None
        Messages per topic the data files hold (None: not counted, e.g. compressed files).
    start_ns, end_ns : int or None
        First and last log time in the data files.
    declared_start_ns, declared_end_ns : int or None
        What metadata.yaml declares.
    problems : tuple of str
        Each disagreement, one phrase (the ``DAMAGED`` line of ``navreplay info``).
    lost : bool
        The data files hold less than metadata.yaml declares: messages were lost.
    """

    declared: dict[str, int]
    found: dict[str, int] | None
    start_ns: int | None
    end_ns: int | None
    declared_start_ns: int | None
    declared_end_ns: int | None
    problems: tuple[str, ...] = ()
    lost: bool = False

    @property
    def kept(self) -> float:
        """The fraction of the declared messages the data files hold (at most 1)."""
        total = sum(self.declared.values())
        if self.found is None or not total:
            return 1.0
        return min(sum(self.found.values()) / total, 1.0)

    @property
    def declared_duration_s(self) -> float | None:
        if self.declared_start_ns is None or self.declared_end_ns is None:
            return None
        return (self.declared_end_ns - self.declared_start_ns) * 1e-9


def _int(value: Any) -> int | None:
    if isinstance(value, dict):
        value = value.get("nanoseconds", value.get("nanoseconds_since_epoch"))
    return int(value) if isinstance(value, int) and not isinstance(value, bool) else None


def check_bag(path: Path) -> BagCheck | None:
    """Count the messages of a rosbag2 folder's data files (per topic, and their first and
    last log times) and compare them with its metadata.yaml; None for a lone ``.db3``
    (nothing declares what it should hold).

    MCAP data files are summarised from their own indexes (and walked when damaged, as
    ``navreplay info`` does); sqlite3 ones are counted by SQL. Compressed files are not
    counted.

    Raises
    ------
    RecordingError
        A metadata.yaml that is not YAML or not rosbag2 metadata, a data file that is not
        there or cannot be opened.
    """
    folder = bag_folder(path)
    if folder is None:
        return None
    info = bag_metadata(folder)
    declared: dict[str, int] = {}
    for item in info.get("topics_with_message_count") or []:
        try:
            declared[str(item["topic_metadata"]["name"])] = int(item["message_count"])
        except (KeyError, TypeError, ValueError):
            raise RecordingError(f"{folder / 'metadata.yaml'}: a topics_with_message_count "
                                 f"entry lacks its name or count ({item!r:.80})") from None
    start = _int(info.get("starting_time"))
    duration = _int(info.get("duration"))
    declared_end = start + duration if start is not None and duration is not None else None
    files = [folder / str(f) for f in info.get("relative_file_paths") or []]
    problems: list[str] = []
    for f in files:
        if not f.is_file():
            raise RecordingError(f"{folder}: data file {f.name} named in metadata.yaml is "
                                 "missing")
    if info.get("compression_mode"):
        return BagCheck(declared, None, None, None, start, declared_end)
    found: dict[str, int] = {}
    lo: list[int] = []
    hi: list[int] = []
    lost = False
    for f in files:
        counts, first, last, damage = _count_file(f, str(info.get("storage_identifier", "")))
        for topic, n in counts.items():
            found[topic] = found.get(topic, 0) + n
        lo += [first] if first is not None else []
        hi += [last] if last is not None else []
        if damage:
            problems.append(f"data file {f.name}: {damage}")
            lost = True
    first_ns, last_ns = (min(lo) if lo else None), (max(hi) if hi else None)
    for topic in sorted(set(declared) | set(found)):
        d, n = declared.get(topic, 0), found.get(topic, 0)
        if d != n:
            problems.append(f"topic {topic}: metadata.yaml counts {d} messages, the data files "
                            f"hold {n}")
            lost |= n < d
    total = info.get("message_count")
    if isinstance(total, int) and total != sum(found.values()):
        problems.append(f"metadata.yaml counts {total} messages in all, the data files hold "
                        f"{sum(found.values())}")
        lost |= sum(found.values()) < total
    if declared_end is not None and start is not None and duration is not None:
        if last_ns is None or last_ns < declared_end - BAG_TIME_SLACK_NS:
            end = "no message" if last_ns is None else f"{(last_ns - start) * 1e-9:.3f} s"
            problems.append(f"the data end at {end} of the {duration * 1e-9:.3f} s "
                            "metadata.yaml declares")
            lost = True
        elif last_ns > declared_end + BAG_TIME_SLACK_NS:
            problems.append(f"the data end at {(last_ns - start) * 1e-9:.3f} s, after the "
                            f"{duration * 1e-9:.3f} s metadata.yaml declares")
    if start is not None and first_ns is not None and abs(first_ns - start) > BAG_TIME_SLACK_NS:
        problems.append(f"the data start {(first_ns - start) * 1e-9:+.3f} s from the start "
                        "metadata.yaml declares")
        lost |= first_ns > start
    return BagCheck(declared, found, first_ns, last_ns, start, declared_end, tuple(problems),
                    lost)


def _count_file(path: Path, storage: str) -> tuple[dict[str, int], int | None, int | None,
                                                     str | None]:
    """Messages per topic of one data file, its first and last log time, and its damage."""
    if storage == "sqlite3" or path.suffix == ".db3":
        try:
            db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
            try:
                rows = db.execute(
                    "SELECT t.name, COUNT(m.id), MIN(m.timestamp), MAX(m.timestamp) FROM topics t "
                    "LEFT JOIN messages m ON m.topic_id = t.id GROUP BY t.id").fetchall()
                verdict = db.execute("PRAGMA quick_check").fetchall()
            finally:
                db.close()
        except sqlite3.Error as exc:
            raise RecordingError(f"{path}: not a readable sqlite3 bag file ({exc})") from None
        counts = {str(n): int(c) for n, c, _, _ in rows}
        firsts = [int(a) for _, _, a, _ in rows if a is not None]
        lasts = [int(b) for _, _, _, b in rows if b is not None]
        damage = None if verdict == [("ok",)] else f"sqlite finds it damaged ({verdict[0][0]})"
        return counts, min(firsts, default=None), max(lasts, default=None), damage
    from navreplay.io.info import recording_info

    info = recording_info(path)
    per_topic: dict[str, int] = {}
    for t in info.topics:
        per_topic[t.topic] = per_topic.get(t.topic, 0) + t.count
    return per_topic, info.start_ns, info.end_ns, info.damage
