"""rosbag2 folders and sqlite3 (``.db3``) bags, read with ``rosbags`` into the same streams.

An MCAP file is read in bulk by :mod:`navreplay.io.mcapread`. A rosbag2 folder (``metadata.yaml``
with MCAP or sqlite3 storage, one or several split files) is read with ``rosbags``' AnyReader,
which also brings the message definitions stored in the bag; a ``.db3`` file is read from its
folder when that has a ``metadata.yaml``, else straight from its sqlite tables with rosbags'
standard type store. Messages are deserialised one by one (rosbags), their fields gathered by the
same leaf paths as the bulk decoder (:mod:`navreplay.io.schemas`), and then decoded, converted
and checked exactly like an MCAP topic (:func:`navreplay.io.topics.build_stream`). A bag is
one window (:class:`BagSource`).

Times: ``header.stamp`` is the sample time, or the log (receive) time with ``--time log``; a
topic whose stamps are zero or do not increase takes the log times, with a warning
(:func:`navreplay.io.topics.sample_times`).
"""

from __future__ import annotations

import os
import sqlite3
import warnings
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.io.cdr import fields_of_messages
from navreplay.io.convert import REDUCE, Convention
from navreplay.io.errors import RecordingError, RecordingWarning
from navreplay.io.schemas import SPECS, normalize_type_name
from navreplay.io.source import COMPLETE, Source, Window
from navreplay.io.topics import build_stream, candidate, choose_topics, sample_times, topic_map
from navreplay.streams import Metadata, Stream, StreamKind


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

    def __enter__(self) -> _Bag:
        folder = bag_folder(self.path)
        if not self.path.exists():
            raise RecordingError(f"{self.where}: no such file or folder")
        try:
            if folder is not None:
                from rosbags.highlevel import AnyReader

                self._reader = AnyReader([folder])
                self._reader.open()
            else:
                from rosbags.typesys import Stores, get_typestore

                self._db = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True)
                self._db.execute("SELECT name, type, serialization_format FROM topics").fetchall()
                self._store = get_typestore(Stores.LATEST)
        except RecordingError:
            raise
        except Exception as exc:  # rosbags and sqlite raise many types on foreign data
            raise RecordingError(f"{self.where}: not a readable rosbag2 bag ({exc})") from None
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
                row = out.setdefault(c.topic, [c.topic, normalize_type_name(c.msgtype),
                                               c.ext.serialization_format, 0])
                row[3] += c.msgcount
            return sorted(tuple(r) for r in out.values())
        assert self._db is not None
        rows = self._db.execute(
            "SELECT t.name, t.type, t.serialization_format, COUNT(m.id) FROM topics t "
            "LEFT JOIN messages m ON m.topic_id = t.id GROUP BY t.id ORDER BY t.name"
        ).fetchall()
        return [(n, normalize_type_name(t), f, int(c)) for n, t, f, c in rows]

    def messages(self, topics: list[str]) -> Iterator[tuple[int, Any]]:
        try:
            if self._reader is not None:
                conns = [c for c in self._reader.connections if c.topic in topics]
                for conn, t, raw in self._reader.messages(connections=conns):
                    yield int(t), self._reader.deserialize(raw, conn.msgtype)
                return
            assert self._db is not None
            marks = ",".join("?" * len(topics))
            query = (f"SELECT m.timestamp, t.type, m.data FROM messages m JOIN topics t "
                     f"ON m.topic_id = t.id WHERE t.name IN ({marks}) ORDER BY m.timestamp")
            for t, msgtype, raw in self._db.execute(query, topics):
                yield int(t), self._store.deserialize_cdr(bytes(raw), msgtype)
        except RecordingError:
            raise
        except Exception as exc:
            raise RecordingError(
                f"{self.where}: messages of {', '.join(topics)} cannot be read ({exc!r})"
            ) from None


def _open(path: Path) -> _Bag:
    return _Bag(path)


def accepts(path: Path) -> bool:
    """Whether ``path`` is a rosbag2 folder, its metadata.yaml, or a sqlite3 ``.db3`` file."""
    return path.is_dir() or path.suffix == ".db3" or path.name == "metadata.yaml"


class BagSource(Source):
    """The streams of a rosbag2 folder or ``.db3`` as one window (arguments as
    :class:`navreplay.io.mcapread.McapSource`; bags are read whole)."""

    kind = "rosbag2"

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        kinds: Iterable[StreamKind | str] | None = None,
        explicit: bool = False,
        topics: Mapping[StreamKind | str, str] | None = None,
        frames: Mapping[StreamKind | str, Convention | str] | None = None,
        time: str = "header",
        validate: bool = True,
        window: int | None = None,
    ) -> None:
        super().__init__(str(path))
        self.path = Path(path)
        self._wanted = set(SPECS) if kinds is None else {StreamKind(k) for k in kinds}
        self._explicit = explicit
        self._topics = topics
        self._declared = {StreamKind(k): Convention(str(v).lower())
                          for k, v in (frames or {}).items()}
        self._time = time
        self._validate = validate

    def _windows(self) -> Iterator[Window]:
        where = self.name
        topic_kinds = topic_map(self._topics)
        with _open(self.path) as bag:
            listing = bag.topics()
            available = ", ".join(f"{t} ({ty})" for t, ty, _, _ in listing) or "no topics"
            cands = [c for t, ty, fmt, _ in listing
                     if (c := candidate(t, ty, fmt, topic_kinds)) is not None]
            chosen = choose_topics(where, cands, self._wanted, explicit=self._explicit,
                                   named=self._topics, available=available, what="bag")
            with warnings.catch_warnings():  # (said once, for the streams read)
                warnings.simplefilter("ignore", RecordingWarning)
                present = choose_topics(where, cands, set(SPECS), explicit=False, named=None,
                                        available=available, what="bag")
            gathered: dict[StreamKind, tuple[list[Any], list[int]]] = {}
            for kind, (c, _) in chosen.items():
                msgs, times = [], []
                for t, msg in bag.messages([c.topic]):
                    times.append(t)
                    msgs.append(msg)
                gathered[kind] = (msgs, times)
        # t0: first log time over the chosen topics
        firsts = [min(ts) for _, ts in gathered.values() if ts]
        t0_ns = min(firsts) if firsts else 0
        streams: dict[StreamKind, Stream] = {}
        for kind, (msgs, log_t) in gathered.items():
            topic, others = chosen[kind][0].topic, chosen[kind][1]
            label = f"{where}: topic {topic} ({SPECS[kind].message.name})"
            fields = _fields(msgs, kind, label)
            log_ns = np.asarray(log_t, dtype=np.int64)
            order = np.argsort(log_ns, kind="stable")
            if np.any(order != np.arange(order.size)):
                fields = {k: v[order] for k, v in fields.items()}
                log_ns = log_ns[order]
            fields["t_ns"] = sample_times(fields["t_ns"], log_ns, self._time, label)
            frames = {m.header.frame_id for m in msgs}
            frame_id = msgs[0].header.frame_id if msgs else SPECS[kind].frame_id
            if len(frames) > 1:
                warnings.warn(RecordingWarning(
                    f"{label}: frame_id changes between messages ({sorted(frames)}); using "
                    f"{frame_id!r}"), stacklevel=2)
            streams[kind], self.sources[kind] = build_stream(
                kind, fields, frame_id, label, [], t0_ns, self._validate,
                self._declared.get(kind), topic, others)
        yield Window(streams, dict.fromkeys(streams, COMPLETE), Metadata(), t0_ns,
                     frozenset(present), final=True)


def _fields(msgs: list[Any], kind: StreamKind, label: str) -> dict[str, np.ndarray]:
    try:
        fields = fields_of_messages(msgs, SPECS[kind].message)
    except (AttributeError, TypeError, ValueError) as exc:
        raise RecordingError(f"{label}: messages lack a field of "
                             f"{SPECS[kind].message.name} ({exc})") from None
    out: dict[str, np.ndarray] = {"frame_id": fields["frame_id"], "t_ns": fields["t_ns"]}
    for name, columns in REDUCE[kind].items():
        value = np.asarray(fields[name])
        out[name] = np.array(value if columns is None else value[:, columns])
    return out

