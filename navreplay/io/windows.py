"""Read an MCAP recording in time windows, in one pass over the file.

A day of 100 Hz IMU and truth does not need to be in memory at once: :func:`read_windows`
walks the file's chunks in order and hands out the decoded rows of the kinds asked for every
``window`` messages of one kind, as a :class:`Window`: a checked
:class:`~navreplay.streams.Stream` per kind (the conversions and checks of
:func:`navreplay.io.reader.read_streams`, time increasing across windows) and, per kind, the
time up to which the kind is complete. Only the topics of the kinds asked for are decoded.

A kind whose next message is far ahead (an aiding stream that pauses) is not left lagging:
the chunk index says which chunk holds the topic's next message, whose time is read ahead from
that chunk, so that the kind is known to be complete up to just before it. A replay then need
not hold the IMU samples of the pause.

The warnings of the reader (header stamps replaced by log times, conversions, gaps) are given
once per read, when it ends, each with the number of windows it concerns; gaps are counted over
the whole stream, those between the last sample of a window and the first of the next included,
against the median interval of the first window: the line of the whole reader.

Only intact files (with a summary and chunk index) are streamed; :class:`NotStreamable` says
that a file must be read whole (damaged or unfinished files are salvaged by the whole reader).
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import BinaryIO

import numpy as np

from navreplay.io.checks import GAP_FACTOR, check_frame_ids, gap_text, when
from navreplay.io.convert import AuxColumn, Convention
from navreplay.io.errors import RecordingError, RecordingWarning
from navreplay.io.mcapfile import FileContents, probe, read_chunk, walk
from navreplay.io.reader import (
    TopicSource,
    _describe_topics,
    _metadata,
    _Plan,
    _Topic,
    build_stream,
    check_named_topics,
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
        try:
            for block in walk(f, where, contents, plan.wants_chunk):
                if state is None:
                    state = _State.start(plan, contents, where, topics, declared, time,
                                         validate, sources, f)
                plan.feed(contents, block)
                if any(t.rows() >= window for t in state.chosen.values()):
                    yield state.window()
            if state is None:  # no chunk holds a kind asked for
                state = _State.start(plan, contents, where, topics, declared, time, validate,
                                     sources, f)
            yield state.window(final=True)
        finally:
            if state is not None:
                state.report()


class _State:
    """What carries from window to window: the topics read, the last time of each kind."""

    def __init__(self, chosen: dict[StreamKind, _Topic], totals: dict[StreamKind, int | None],
                 present: frozenset[StreamKind], metadata: Metadata, t0_ns: int,
                 aux: list[AuxColumn], declared: Mapping[StreamKind, Convention], time: str,
                 validate: bool, sources: dict[StreamKind, TopicSource] | None,
                 f: BinaryIO | None = None, contents: FileContents | None = None) -> None:
        self.chosen, self.totals, self.present = chosen, totals, present
        self.metadata, self.t0_ns, self.aux = metadata, t0_ns, aux
        self.declared, self.time, self.validate, self.sources = declared, time, validate, sources
        self.f, self.contents = f, contents
        self.last: dict[StreamKind, int] = {}
        self.frame: dict[StreamKind, str] = {}
        self.ahead: dict[StreamKind, tuple[int, int]] = {}  # kind -> (chunk, first time)
        self.floor: dict[StreamKind, int] = {}  # no sample of the kind may come before
        self.base: dict[StreamKind, str] = {}  # kind -> "header" or "log", as first chosen
        self.gaps = {kind: _Gaps() for kind in chosen}
        self.warnings = _Warnings()
        self.windows = 0
        self.newest = -COMPLETE  # the latest sample of any kind in the previous windows

    @classmethod
    def start(cls, plan: _Plan, contents: FileContents, where: str,
              topics: Mapping[StreamKind | str, str] | None,
              declared: Mapping[StreamKind, Convention], time: str, validate: bool,
              sources: dict[StreamKind, TopicSource] | None,
              f: BinaryIO | None = None) -> _State:
        if not contents.intact:
            raise NotStreamable(f"{where}: no summary to read the file in windows")
        chosen = plan.resolve(contents, explicit=False)
        every = _Plan(where, set(SPECS), topic_map(topics)).resolve(contents, explicit=False)
        check_named_topics(where, topics, {k: t.channel.topic for k, t in every.items()},
                           _describe_topics(contents))
        counts = contents.statistics.channel_message_counts if contents.statistics else {}
        totals = {k: counts.get(t.channel.id) for k, t in chosen.items()}
        metadata, t0_ns, aux = _metadata(contents, where)
        return cls(chosen, totals, frozenset(every), metadata, t0_ns, aux, declared, time,
                   validate, sources, f, contents)

    def window(self, final: bool = False) -> Window:
        self.windows += 1
        out: dict[StreamKind, Stream] = {}
        for kind, topic in self.chosen.items():
            if topic.rows():
                with self.warnings.collect(self.windows):
                    stream = self._stream(kind, topic)
                if len(stream):
                    out[kind] = stream
        known = {}
        for kind, topic in self.chosen.items():
            total = self.totals[kind]
            last = self.last.get(kind, -COMPLETE)
            if final or (total is not None and topic._count >= total):
                known[kind] = COMPLETE
            elif last <= self.newest:  # no sample in this window: where is the next?
                known[kind] = max(last, self._before_next(kind, topic))
            else:
                known[kind] = last
        self.newest = max(self.last.values(), default=self.newest)
        return Window(out, known, self.metadata, self.t0_ns, self.present)

    def _before_next(self, kind: StreamKind, topic: _Topic) -> int:
        """The time just before the kind's next sample, read ahead in the chunk that holds it
        (the chunk index names it); :data:`COMPLETE` when no chunk to come holds the topic,
        -:data:`COMPLETE` when the index cannot tell."""
        contents = self.contents
        if self.f is None or contents is None or not contents.chunk_indexes:
            return -COMPLETE
        cid = topic.channel.id
        indexes = contents.chunk_indexes
        k, t = self.ahead.get(kind, (-1, -COMPLETE))
        if k < contents.chunks_walked:
            for k in range(contents.chunks_walked, len(indexes)):
                held = indexes[k].message_index_offsets
                if not held:
                    return -COMPLETE  # a chunk without a message index: unknown
                if cid in held:
                    break
            else:
                return COMPLETE
            t = self._first_time(topic, indexes[k].chunk_start_offset)
            self.ahead[kind] = (k, t)
            self.floor[kind] = t
        return t - 1

    def _first_time(self, topic: _Topic, offset: int) -> int:
        """The earliest time a sample of the topic in the chunk at ``offset`` can have: its
        least log time, or header stamp where those are used."""
        assert self.f is not None
        block = read_chunk(self.f, offset, str(topic.where), lambda opcode, body: None)
        rows = np.flatnonzero(block.channel == topic.channel.id)
        log = block.log_time[rows]
        first = int(log.min())
        if self.time == "header":
            ahead = _Topic(topic.channel, topic.schema, topic.message, topic.where)
            ahead.add(block, rows)
            stamps = ahead.finish()["t_ns"]
            if stamps.size and stamps.all():
                first = min(first, int(stamps.min()))
        return first

    def _stream(self, kind: StreamKind, topic: _Topic) -> Stream:
        fields = topic.drain()
        fields["t_ns"] = self._times(kind, topic, fields["t_ns"])
        self.frame.setdefault(kind, topic.first_frame_id or SPECS[kind].frame_id)
        note = check_frame_ids(kind, topic.label, topic.frame_ids, self.declared.get(kind),
                               self.frame[kind])
        if note:
            warnings.warn(RecordingWarning(f"{topic.label}: {note}"), stacklevel=2)
        stream, source = build_stream(kind, fields, self.frame[kind], topic.label, self.aux,
                                      self.t0_ns, self.validate, self.declared.get(kind),
                                      topic.channel.topic, report_gaps=False)
        if self.sources is not None:
            self.sources.setdefault(kind, source)
        if len(stream):
            first = int(stream.t_ns[0])
            last = self.last.get(kind)
            if last is not None and first <= last:
                raise RecordingError(
                    f"{topic.label}: timestamp at {when(first, self.t0_ns)} does "
                    f"not follow the one at {when(last, self.t0_ns)}"
                )
            floor = self.floor.get(kind)
            if floor is not None and first < floor:
                raise RecordingError(
                    f"{topic.label}: timestamp at {when(first, self.t0_ns)} is earlier than "
                    f"the first of the chunk that follows the previous samples "
                    f"({when(floor, self.t0_ns)}): the topic's messages are out of order"
                )
            self.last[kind] = int(stream.t_ns[-1])
            if self.validate:
                self.gaps[kind].add(stream.t_ns)
        return stream

    def _times(self, kind: StreamKind, topic: _Topic, stamps: np.ndarray) -> np.ndarray:
        """The window's sample times on the time base the topic's first window chose: header
        stamps, or log times once the stamps were unusable there (as the whole reader chooses
        for the whole topic). Stamps that turn unusable after windows that used them are
        refused: the windows already replayed cannot move to log times."""
        t = sample_times(stamps, topic.log_ns, self.time, topic.label)
        used = "header" if t is stamps else "log"
        base = self.base.setdefault(kind, used)
        if used == base:
            return t
        log = np.asarray(topic.log_ns if topic.log_ns is not None else stamps, dtype=np.int64)
        if base == "log":
            return log.copy()
        zero = np.flatnonzero(stamps == 0)
        k = int(zero[0]) if zero.size else int(np.argmax(np.diff(stamps) <= 0)) + 1
        raise RecordingError(
            f"{topic.label}: header stamps are unusable (zero or not increasing) from the "
            f"message logged at {when(int(log[k]), self.t0_ns)}, after windows before it used "
            f"them: replay with --time log, so the whole topic takes its log times")

    def report(self) -> None:
        """Give the warnings of the read, each once (gaps over the whole stream)."""
        for kind, gaps in self.gaps.items():
            line = gaps.line(self.t0_ns)
            if line:
                self.warnings.add(f"{self.chosen[kind].label}: {line}", self.windows)
        self.warnings.emit(self.windows)


class _Gaps:
    """The gaps of one stream read in windows: counted against the median interval of the
    first samples (at least three), across window boundaries too."""

    def __init__(self) -> None:
        self.median = 0.0
        self.head = np.zeros(0, np.int64)  # samples until the median is known
        self.prev: int | None = None
        self.count = 0
        self.longest = 0
        self.start = 0

    def add(self, t_ns: np.ndarray) -> None:
        if not self.median:
            self.head = np.concatenate([self.head, t_ns])
            if len(self.head) < 3:
                return
            t_ns, self.head = self.head, self.head[:0]
            self.median = float(np.median(np.diff(t_ns))) or -1.0  # -1: no gap can be told
        if self.median < 0:
            return
        t = t_ns if self.prev is None else np.concatenate([[self.prev], t_ns])
        self.prev = int(t_ns[-1])
        step = np.diff(t)
        gaps = np.flatnonzero(step > GAP_FACTOR * self.median)
        if gaps.size:
            self.count += gaps.size
            worst = int(gaps[np.argmax(step[gaps])])
            if step[worst] > self.longest:
                self.longest, self.start = int(step[worst]), int(t[worst])

    def line(self, t0_ns: int) -> str | None:
        if not self.count:
            return None
        return gap_text(self.count, self.median, self.longest, self.start, t0_ns)


_NUMBER = re.compile(r"[-+]?\d[\d.]*(?:e[-+]?\d+)?")


class _Warnings:
    """The reader's warnings over the windows of a read, each given once: the first, with the
    number of windows it came in (numbers aside, the same line)."""

    def __init__(self) -> None:
        self.seen: dict[str, list] = {}  # key -> [first message, windows, last window]

    def collect(self, window: int) -> _Collect:
        return _Collect(self, window)

    def add(self, message: str, window: int) -> None:
        entry = self.seen.setdefault(_NUMBER.sub("#", message), [message, 0, -1])
        if entry[2] != window:
            entry[1] += 1
            entry[2] = window

    def emit(self, windows: int) -> None:
        """Warn once per line; ``windows``: how many the read had."""
        for message, count, _ in self.seen.values():
            if count > 1:
                message += (f" (the same in {count} of the {windows} windows of the read; "
                            "the first is shown)")
            warnings.warn(RecordingWarning(message), stacklevel=4)
        self.seen.clear()


class _Collect(warnings.catch_warnings):
    """Gather the reader's warnings (:class:`RecordingWarning`) of one window into a
    :class:`_Warnings`; others pass."""

    def __init__(self, tally: _Warnings, window: int) -> None:
        super().__init__(record=True)
        self.tally, self.window = tally, window

    def __enter__(self):  # type: ignore[no-untyped-def]
        self.caught = super().__enter__()
        warnings.simplefilter("always")
        return self.caught

    def __exit__(self, *exc) -> None:  # type: ignore[no-untyped-def]
        super().__exit__(*exc)
        for w in self.caught or []:
            if isinstance(w.message, RecordingWarning):
                self.tally.add(str(w.message), self.window)
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
