"""Logs whose topics are read straight into streams: text files (:mod:`navreplay.io.gins`) and
PX4 ULog files (:mod:`navreplay.io.ulog`).

Such a log lists its topics (:class:`Topic`: a name, a type, a count and the stream it can
feed) and reads one topic into a stream's columns, already in navreplay's conventions (SI,
NED/FRD). :class:`DirectSource` does the rest as every reader does: the topic of each stream
(the first candidate, or the one ``--topic`` names; every named topic must be in the log with
a type its stream reads), the sample checks, and one window.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

import numpy as np

from navreplay.core.streams import Metadata, Stream, StreamKind
from navreplay.io.checks import first_problem, gap_report
from navreplay.io.convert import Convention
from navreplay.io.errors import RecordingError
from navreplay.io.source import COMPLETE, Source, Window
from navreplay.io.topics import TopicSource, warn


@dataclasses.dataclass(frozen=True)
class Topic:
    """A topic of a log: its name, type, message count and the stream it can feed (None: it
    feeds none, e.g. a reference); the times of its first and last message [ns] when listing
    them is cheap (None: not listed)."""

    name: str
    type_name: str
    count: int
    kind: StreamKind | None = None
    start_ns: int | None = None
    end_ns: int | None = None


@dataclasses.dataclass
class Columns:
    """One topic read: sample times [ns], the stream's columns, and how its axes were read."""

    t_ns: np.ndarray
    columns: dict[str, np.ndarray]
    frame_id: str
    convention: Convention | None = None
    reason: str = ""
    notes: list[str] = dataclasses.field(default_factory=list)


class DirectSource(Source):
    """A log read straight into streams, one window (arguments as
    :class:`navreplay.io.mcapread.McapSource`; ``time`` is not used: these logs have one time
    per sample)."""

    what = "log"
    item = "topic"
    """What the log's topics are (``navreplay info`` names its first column so)."""
    time_base = "each message's own time"
    """Where the sample times come from (``navreplay info``)."""

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
        self._wanted = None if kinds is None else {StreamKind(k) for k in kinds}
        self._explicit = explicit
        self._named = {StreamKind(k): v for k, v in (topics or {}).items()}
        self._declared = {StreamKind(k): Convention(str(v).lower())
                          for k, v in (frames or {}).items()}
        self._validate = validate

    # -- what a kind of log provides ---------------------------------------------------------

    def topics(self) -> list[Topic]:
        """Every topic of the log, candidates first for each stream."""
        raise NotImplementedError

    def read(self, topic: Topic, kind: StreamKind, declared: Convention | None) -> Columns:
        """One topic as the columns of stream ``kind``."""
        raise NotImplementedError

    def metadata(self) -> Metadata:
        return Metadata()

    def info_lines(self, listing: list[Topic]) -> list[str]:
        """What ``navreplay info`` says of the log above its table of topics."""
        return [f"{self.name}  ({self.kind}, {sum(t.count for t in listing)} messages)"]

    # -- the window --------------------------------------------------------------------------

    def choose(self, listing: list[Topic]) -> dict[StreamKind, tuple[Topic, tuple[str, ...]]]:
        """The topic of each stream and the others that could have fed it; every named topic
        must be in the log and feed its stream."""
        where = self.name
        by_name = {t.name: t for t in listing}
        available = ", ".join(f"{t.name} ({t.type_name})" for t in listing) or "no topics"
        for kind, name in self._named.items():
            t = by_name.get(name)
            if t is None:
                raise RecordingError(f"{where}: topic {name} named for stream {kind.value} is "
                                     f"not in the {self.what}; it has {available}")
            if t.kind is not kind:
                readers = sorted({c.type_name for c in listing if c.kind is kind})
                raise RecordingError(
                    f"{where}: topic {name} has type {t.type_name}; stream {kind.value} "
                    f"needs {' or '.join(readers) or 'a type this log does not have'}")
        chosen: dict[StreamKind, tuple[Topic, tuple[str, ...]]] = {}
        for kind in StreamKind:
            cands = [t for t in listing if t.kind is kind and t.count]
            if kind in self._named:
                pick = by_name[self._named[kind]]
            elif cands:
                pick = cands[0]
            else:
                continue
            chosen[kind] = (pick, tuple(t.name for t in cands if t.name != pick.name))
        if self._explicit and self._wanted is not None:
            missing = [k.value for k in StreamKind if k in self._wanted and k not in chosen]
            if missing:
                raise RecordingError(f"{where}: no topic for stream(s) {', '.join(missing)}; "
                                     f"the {self.what} has {available}")
        return chosen

    def _windows(self) -> Iterator[Window]:
        listing = self.topics()
        chosen = self.choose(listing)
        read = {k: v for k, v in chosen.items() if self._wanted is None or k in self._wanted}
        got: dict[StreamKind, tuple[Columns, Topic, tuple[str, ...]]] = {}
        for kind, (topic, others) in read.items():
            got[kind] = (self.read(topic, kind, self._declared.get(kind)), topic, others)
        firsts = [int(c.t_ns[0]) for c, _, _ in got.values() if len(c.t_ns)]
        t0_ns = min(firsts) if firsts else 0
        streams: dict[StreamKind, Stream] = {}
        for kind, (cols, topic, others) in got.items():
            label = f"{self.name}: topic {topic.name} ({topic.type_name})"
            for note in cols.notes:
                warn(f"{label}: {note}")
            stream = Stream(kind, np.asarray(cols.t_ns, dtype=np.int64), cols.columns,
                            cols.frame_id)
            if self._validate:
                problem = first_problem(stream, t0_ns)
                if problem:
                    raise RecordingError(f"{label}: {problem}")
                gaps = gap_report(stream, t0_ns)
                if gaps:
                    warn(f"{label}: {gaps}")
            streams[kind] = stream
            self.sources[kind] = TopicSource(topic.name, topic.type_name, cols.frame_id,
                                             cols.convention, cols.reason, others)
        yield Window(streams, dict.fromkeys(streams, COMPLETE), self.metadata(), t0_ns,
                     frozenset(chosen), final=True)


def body_axes(vectors: np.ndarray, native: Convention, declared: Convention | None,
              what: str) -> tuple[np.ndarray, Convention, str]:
    """Body vectors (N, 3) in FRD, from the format's own axes or those ``--frame`` declares."""
    conv = declared or native
    if conv not in (Convention.FLU, Convention.FRD):
        raise RecordingError(f"--frame {conv.value}: a body frame is flu or frd")
    reason = f"declared {conv.value}" if declared else f"{what} is {native.value.upper()}"
    out = np.asarray(vectors, dtype=float)
    if conv is Convention.FLU:
        out = out * np.array([1.0, -1.0, -1.0])
    return out, conv, reason
