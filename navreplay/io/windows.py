"""Read an MCAP recording in time windows, in one pass over the file.

A day of 100 Hz IMU and truth does not need to be in memory at once: :func:`read_windows`
walks the file's chunks in order and hands out the decoded rows of the kinds asked for every
``window`` messages of one kind, as a :class:`Window`: a checked
:class:`~navreplay.streams.Stream` per kind (the conversions and checks of
:func:`navreplay.io.reader.read_streams`, time increasing across windows) and, per kind, the
time up to which the kind is complete. Only the topics of the kinds asked for are decoded.

Only intact files (with a summary and chunk index) are streamed; :class:`NotStreamable` says
that a file must be read whole (damaged or unfinished files are salvaged by the whole reader).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

from navreplay.io.checks import when
from navreplay.io.convert import AuxColumn, Convention
from navreplay.io.errors import RecordingError
from navreplay.io.mcapfile import FileContents, probe, walk
from navreplay.io.reader import (
    TopicSource,
    _metadata,
    _Plan,
    _Topic,
    build_stream,
    sample_times,
    topic_map,
)
from navreplay.io.schemas import SPECS
from navreplay.streams import Metadata, Stream, StreamKind

COMPLETE = 2**63 - 1
"""The time [ns] a kind whose every message has been read is complete up to."""


class Window(dict[StreamKind, Stream]):
    """The rows of each kind decoded since the previous window (a kind without new rows is
    left out).

    Attributes
    ----------
    known : dict[StreamKind, int]
        For every kind the file holds among those asked for: every sample at or before this
        time [ns] has been handed out (:data:`COMPLETE` once all of the kind's messages have
        been read; the sample times of a kind increase, so its last sample so far otherwise).
    metadata : Metadata
        The recording's metadata.
    t0_ns : int
        The recording's start [ns].
    present : frozenset[StreamKind]
        Every kind the file holds a topic for (decoded or not).
    """

    def __init__(self, streams: dict[StreamKind, Stream], known: dict[StreamKind, int],
                 metadata: Metadata, t0_ns: int, present: frozenset[StreamKind]) -> None:
        super().__init__(streams)
        self.known = known
        self.metadata = metadata
        self.t0_ns = t0_ns
        self.present = present

WINDOW_MESSAGES = 60_000
"""Messages of one streamed kind per window (10 minutes of 100 Hz samples)."""


class NotStreamable(Exception):
    """The file cannot be read in windows (no summary or chunk index): read it whole."""


def streamable(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is an MCAP file that ends with a summary (cheap: reads its ends)."""
    try:
        with open(path, "rb") as f:
            tail = probe(f, os.fstat(f.fileno()).st_size, str(path))
    except (OSError, RecordingError):
        return False
    return tail is not None and tail.summary_start > 0


def read_windows(
    path: str | os.PathLike[str],
    kinds: Iterable[StreamKind],
    *,
    topics: Mapping[StreamKind | str, str] | None = None,
    frames: Mapping[StreamKind | str, Convention | str] | None = None,
    time: str = "header",
    validate: bool = True,
    window: int | None = None,
    sources: dict[StreamKind, TopicSource] | None = None,
) -> Iterator[dict[StreamKind, Stream]]:
    """Yield the streams ``kinds`` of an MCAP file window by window.

    Parameters
    ----------
    path : path-like
        An intact MCAP file.
    kinds : iterable of StreamKind
        Streams to read (those the file lacks are left out of the windows).
    topics, frames, time, validate
        As for :func:`navreplay.io.reader.read_streams`.
    window : int, optional
        Decoded messages of a kind that close a window (default :data:`WINDOW_MESSAGES`).
    sources : dict, optional
        Filled with the topic, frame and convention of each kind, as it first appears.

    Yields
    ------
    Window
        The rows of each kind decoded since the previous window, later than every row of the
        kind yielded before, and how far each kind is complete. A file without messages of
        the kinds yields one empty window.

    Raises
    ------
    NotStreamable
        Before any window: the file has no usable summary (read it whole).
    RecordingError
        Bad samples (with ``validate``), time that goes back across windows, a schema that does
        not fit; the message names the file, topic and time.
    """
    path = Path(path)
    where = str(path)
    window = WINDOW_MESSAGES if window is None else int(window)
    plan = _Plan(where, {StreamKind(k) for k in kinds}, topic_map(topics))
    declared = {StreamKind(k): Convention(str(v).lower()) for k, v in (frames or {}).items()}
    with open(path, "rb") as f:
        contents = FileContents(size=os.fstat(f.fileno()).st_size)
        state: _State | None = None
        for block in walk(f, where, contents, plan.wants_chunk):
            if state is None:
                state = _State.start(plan, contents, where, topics, declared, time, validate,
                                     sources)
            plan.feed(contents, block)
            if any(t.rows() >= window for t in state.chosen.values()):
                yield state.window()
        if state is None:  # no chunk holds a kind asked for
            state = _State.start(plan, contents, where, topics, declared, time, validate,
                                 sources)
        yield state.window()


class _State:
    """What carries from window to window: the topics read, the last time of each kind."""

    def __init__(self, chosen: dict[StreamKind, _Topic], totals: dict[StreamKind, int | None],
                 present: frozenset[StreamKind], metadata: Metadata, t0_ns: int,
                 aux: list[AuxColumn], declared: Mapping[StreamKind, Convention], time: str,
                 validate: bool, sources: dict[StreamKind, TopicSource] | None) -> None:
        self.chosen, self.totals, self.present = chosen, totals, present
        self.metadata, self.t0_ns, self.aux = metadata, t0_ns, aux
        self.declared, self.time, self.validate, self.sources = declared, time, validate, sources
        self.last: dict[StreamKind, int] = {}
        self.frame: dict[StreamKind, str] = {}

    @classmethod
    def start(cls, plan: _Plan, contents: FileContents, where: str,
              topics: Mapping[StreamKind | str, str] | None,
              declared: Mapping[StreamKind, Convention], time: str, validate: bool,
              sources: dict[StreamKind, TopicSource] | None) -> _State:
        if not contents.intact:
            raise NotStreamable(f"{where}: no summary to read the file in windows")
        chosen = plan.resolve(contents, explicit=False)
        every = _Plan(where, set(SPECS), topic_map(topics)).resolve(contents, explicit=False)
        counts = contents.statistics.channel_message_counts if contents.statistics else {}
        totals = {k: counts.get(t.channel.id) for k, t in chosen.items()}
        metadata, t0_ns, aux = _metadata(contents, where)
        return cls(chosen, totals, frozenset(every), metadata, t0_ns, aux, declared, time,
                   validate, sources)

    def window(self) -> Window:
        out: dict[StreamKind, Stream] = {}
        for kind, topic in self.chosen.items():
            if topic.rows():
                stream = self._stream(kind, topic)
                if len(stream):
                    out[kind] = stream
        known = {}
        for kind, topic in self.chosen.items():
            total = self.totals[kind]
            if total is not None and topic._count >= total:
                known[kind] = COMPLETE
            else:
                known[kind] = self.last.get(kind, -COMPLETE)
        return Window(out, known, self.metadata, self.t0_ns, self.present)

    def _stream(self, kind: StreamKind, topic: _Topic) -> Stream:
        fields = topic.drain()
        fields["t_ns"] = sample_times(fields["t_ns"], topic.log_ns, self.time, topic.label)
        self.frame.setdefault(kind, topic.first_frame_id or SPECS[kind].frame_id)
        stream, source = build_stream(kind, fields, self.frame[kind], topic.label, self.aux,
                                      self.t0_ns, self.validate, self.declared.get(kind),
                                      topic.channel.topic)
        if self.sources is not None:
            self.sources.setdefault(kind, source)
        if len(stream):
            last = self.last.get(kind)
            if last is not None and int(stream.t_ns[0]) <= last:
                raise RecordingError(
                    f"{topic.label}: timestamp at {when(int(stream.t_ns[0]), self.t0_ns)} does "
                    f"not follow the one at {when(last, self.t0_ns)}"
                )
            self.last[kind] = int(stream.t_ns[-1])
        return stream
