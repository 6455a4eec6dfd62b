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
from collections.abc import Iterator

import numpy as np

from navreplay.core.streams import Metadata, Stream, StreamKind
from navreplay.io.checks import declared_outages, first_problem, gap_report
from navreplay.io.convert import Convention
from navreplay.io.errors import RecordingError
from navreplay.io.source import COMPLETE, FileSource, Window
from navreplay.io.topics import TopicSource, warn


@dataclasses.dataclass(frozen=True)
class Topic:
    """A topic of a log: its name, type, message count and the streams it can feed (none: a
    reference, say; a GNSS receiver's topic can feed both position and velocity); the times of
    its first and last message [ns] when listing them is cheap (None: not listed)."""

    name: str
    type_name: str
    count: int
    kinds: tuple[StreamKind, ...] = ()
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


class DirectSource(FileSource):
    """A log read straight into streams, one window (arguments as
    :class:`navreplay.io.source.FileSource`; ``time`` and ``window`` are not used: these logs
    have one time per sample, and are read whole)."""

    what = "log"
    item = "topic"
    """What the log's topics are (``navreplay info`` names its first column so)."""
    time_base = "each message's own time"
    """Where the sample times come from (``navreplay info``)."""

    # -- what a kind of log provides ---------------------------------------------------------

    def topics(self) -> list[Topic]:
        """Every topic of the log, candidates first for each stream."""
        raise NotImplementedError

    def read(self, topic: Topic, kind: StreamKind, declared: Convention | None) -> Columns:
        """One topic as the columns of stream ``kind``."""
        raise NotImplementedError

    def listing(self) -> list[Topic]:
        """Every topic of the log (``navreplay info``; :meth:`topics` may list only those a
        read parses)."""
        return self.topics()

    def readers(self, kind: StreamKind) -> tuple[str, ...]:
        """The topic types of this kind of log that feed stream ``kind`` (for messages)."""
        return ()

    def metadata(self) -> Metadata:
        return Metadata()

    def info_lines(self, listing: list[Topic]) -> list[str]:
        """What ``navreplay info`` says of the log above its table of topics."""
        return [f"{self.name}  ({self.kind}, {sum(t.count for t in listing)} messages)"]

    # -- the window --------------------------------------------------------------------------

    def choose(self, listing: list[Topic]) -> dict[StreamKind, tuple[Topic, tuple[str, ...]]]:
        """The topic of each stream and the others that could have fed it; every named topic
        must be in the log and feed its stream."""
        where, opts = self.name, self.options
        by_name = {t.name: t for t in listing}
        available = ", ".join(f"{t.name} ({t.type_name})" for t in listing) or "no topics"
        for kind, name in opts.topics.items():
            t = by_name.get(name)
            if t is None:
                raise RecordingError(f"{where}: topic {name} named for stream {kind.value} is "
                                     f"not in the {self.what}; it has {available}")
            if kind not in t.kinds:
                readers = sorted({c.type_name for c in listing if kind in c.kinds}
                                 | set(self.readers(kind)))
                raise RecordingError(
                    f"{where}: topic {name} has type {t.type_name}; stream {kind.value} "
                    f"needs {' or '.join(readers) or 'a type this log does not have'}")
        chosen: dict[StreamKind, tuple[Topic, tuple[str, ...]]] = {}
        for kind in StreamKind:
            cands = [t for t in listing if kind in t.kinds and t.count]
            if kind in opts.topics:
                pick = by_name[opts.topics[kind]]
            elif cands:
                pick = cands[0]
            else:
                continue
            chosen[kind] = (pick, tuple(t.name for t in cands if t.name != pick.name))
        if opts.explicit and opts.kinds is not None:
            missing = [k.value for k in StreamKind if k in opts.kinds and k not in chosen]
            if missing:
                raise RecordingError(f"{where}: no topic for stream(s) {', '.join(missing)}; "
                                     f"the {self.what} has {available}")
        return chosen

    def _windows(self) -> Iterator[Window]:
        listing = self.topics()
        chosen = self.choose(listing)
        opts = self.options
        read = {k: v for k, v in chosen.items() if k in opts.wanted()}
        got: dict[StreamKind, tuple[Columns, Topic, tuple[str, ...]]] = {}
        for kind, (topic, others) in read.items():
            got[kind] = (self.read(topic, kind, opts.frames.get(kind)), topic, others)
        firsts = [int(c.t_ns[0]) for c, _, _ in got.values() if len(c.t_ns)]
        t0_ns = min(firsts) if firsts else 0
        streams: dict[StreamKind, Stream] = {}
        metadata = self.metadata()
        for kind, (cols, topic, others) in got.items():
            label = f"{self.name}: topic {topic.name} ({topic.type_name})"
            for note in cols.notes:
                warn(f"{label}: {note}")
            stream = Stream(kind, np.asarray(cols.t_ns, dtype=np.int64), cols.columns,
                            cols.frame_id)
            if opts.validate:
                problem = first_problem(stream, t0_ns)
                if problem:
                    raise RecordingError(f"{label}: {problem}")
                gaps = gap_report(stream, t0_ns,
                                  declared=declared_outages(kind, metadata.extra, t0_ns))
                if gaps:
                    warn(f"{label}: {gaps}")
            streams[kind] = stream
            self.sources[kind] = TopicSource(topic.name, topic.type_name, cols.frame_id,
                                             cols.convention, cols.reason, others)
        yield Window(streams, dict.fromkeys(streams, COMPLETE), metadata, t0_ns,
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
