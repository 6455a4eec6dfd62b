"""A recording as a source of time windows of its streams.

Whatever the recording is, a replay reads it the same way: as :class:`Window` objects, each
with the rows of every stream since the previous window and, per stream, the time up to which
the stream is complete. An intact MCAP file is many windows (memory flat in the log's length,
:mod:`navreplay.io.mcapread`); a damaged MCAP file, a rosbag2 bag (:mod:`navreplay.io.rosbag`)
or a :class:`~navreplay.core.streams.Recording` in memory (:class:`MemorySource`) is one. Files are
opened by :func:`navreplay.io.files.open_recording`.

Examples
--------
>>> import numpy as np
>>> from navreplay.io.synthetic import random_recording
>>> rec = random_recording(np.random.default_rng(0), duration_s=1.0, kinds=["imu", "gps"])
>>> windows = list(MemorySource(rec))
>>> len(windows), windows[0].final, sorted(str(k) for k in windows[0])
(1, True, ['gps', 'imu'])
"""

from __future__ import annotations

import dataclasses
import enum
import os
import types
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Self

from navreplay.core.streams import Metadata, Recording, Stream, StreamKind
from navreplay.io.convert import Convention
from navreplay.io.solution import RecordedSolution
from navreplay.io.topics import TIME_SOURCES, FrameNames, TopicNames, TopicSource

COMPLETE = 2**63 - 1
"""The time [ns] a stream whose every sample has been read is complete up to."""

WINDOW_MESSAGES = 20_000
"""Messages of one stream per window of a reader that reads in windows (200 s of 100 Hz
samples; :mod:`navreplay.io.mcapread`). A window's decoded columns and their truth are what a
run holds of the log: 20 000 hold a streamed hour of 100 Hz 40-50 MB below 60 000, for the
same CPU time (``python -m benchmarks memory``). A run that draws the view reads longer ones
(:data:`navreplay.viz.options.DRAWN_WINDOW_MESSAGES`)."""


class _Default(enum.Enum):
    WINDOW = "the reader's window"


@dataclasses.dataclass(frozen=True, init=False)
class ReadOptions:
    """How a recording is read: the same for every kind of recording file
    (:func:`navreplay.io.files.open_recording` hands them to the file's reader).

    Keys may be given as stream kinds or their names; they are stored as
    :class:`~navreplay.core.streams.StreamKind` (and frames as
    :class:`~navreplay.io.convert.Convention`).

    Attributes
    ----------
    kinds : frozenset of StreamKind, optional
        Streams to read (every stream the recording holds when None).
    explicit : bool
        A stream of ``kinds`` that the recording lacks, or holds on several topics, is an error
        (else it is left out, or skipped with a warning).
    topics : mapping of StreamKind to str
        Topic to read for a stream (``--topic``), overriding the recording's canonical topics
        and the choice by message type; each must be in the recording with a usable type.
    frames : mapping of StreamKind to Convention
        Declared axis convention of a stream's topic (``--frame``: ``flu``/``frd`` for imu and
        mag, ``enu``/``ned`` for gps_vel), replacing the guess from the frame id.
    time : {"header", "log"}
        Sample times: the messages' ``header.stamp`` (falling back to the log times, with a
        warning, for a topic whose stamps are zero or do not increase), or the log (receive)
        times (:func:`navreplay.io.topics.sample_times`). Logs with one time per sample (text
        logs, ULog) ignore it.
    validate : bool
        Check every stream: a non-finite value or a timestamp that repeats or goes backwards
        raises :class:`~navreplay.io.errors.RecordingError`; gaps longer than 5x the median
        interval give a :class:`~navreplay.io.errors.RecordingWarning`.
    window : int or None
        Messages of one stream that close a window, for a reader that reads in windows
        (default :data:`WINDOW_MESSAGES`); None: the whole recording in one window.

    Examples
    --------
    >>> opts = ReadOptions(kinds=["imu"], topics={"imu": "/imu/data"}, frames={"imu": "FLU"})
    >>> [str(k) for k in opts.kinds], opts.topics[StreamKind.IMU], opts.frames[StreamKind.IMU].value
    (['imu'], '/imu/data', 'flu')
    >>> opts.whole().window is None
    True
    """

    kinds: frozenset[StreamKind] | None
    explicit: bool
    topics: Mapping[StreamKind, str]
    frames: Mapping[StreamKind, Convention]
    time: str
    validate: bool
    window: int | None

    def __init__(self, *, kinds: Iterable[StreamKind | str] | None = None,
                 explicit: bool = False, topics: TopicNames | None = None,
                 frames: FrameNames | None = None, time: str = "header",
                 validate: bool = True, window: int | None | _Default = _Default.WINDOW
                 ) -> None:
        if time not in TIME_SOURCES:
            raise ValueError(f"time source {time!r}: use {' or '.join(TIME_SOURCES)}")
        if isinstance(window, _Default):
            window = WINDOW_MESSAGES  # read now: a test may set a smaller window
        if window is not None and not (isinstance(window, int) and window > 0):
            raise ValueError(f"window {window!r}: a positive number of messages, or None")
        put = object.__setattr__
        put(self, "kinds", None if kinds is None else frozenset(StreamKind(k) for k in kinds))
        put(self, "explicit", explicit)
        put(self, "topics", types.MappingProxyType(
            {StreamKind(k): str(v) for k, v in (topics or {}).items()}))
        put(self, "frames", types.MappingProxyType(
            {StreamKind(k): Convention(str(v).lower()) for k, v in (frames or {}).items()}))
        put(self, "time", time)
        put(self, "validate", validate)
        put(self, "window", window)

    def whole(self) -> ReadOptions:
        """The same options, the recording read in one window."""
        return dataclasses.replace(self, window=None)

    def wanted(self) -> set[StreamKind]:
        """The streams to read (every kind when :attr:`kinds` is None)."""
        return set(StreamKind) if self.kinds is None else set(self.kinds)


class Window(dict[StreamKind, Stream]):
    """The rows of each stream read since the previous window (a stream without new rows is
    left out, but from the first window, which holds every stream read).

    Attributes
    ----------
    known : dict[StreamKind, int]
        For every stream read: every sample at or before this time [ns] has been handed out
        (:data:`COMPLETE` once all of the stream has been read; the sample times of a stream
        increase, so its last sample so far otherwise).
    metadata : Metadata
        The recording's metadata.
    t0_ns : int
        The recording's start [ns].
    present : frozenset[StreamKind]
        Every stream the recording holds (read or not).
    final : bool
        No window follows.
    end_ns : int or None
        The recording's last time [ns], when the reader knows it (the file's statistics; the
        last sample of a recording in one window).
    """

    def __init__(self, streams: dict[StreamKind, Stream], known: dict[StreamKind, int],
                 metadata: Metadata, t0_ns: int, present: frozenset[StreamKind],
                 final: bool = False, end_ns: int | None = None) -> None:
        super().__init__(streams)
        self.known = known
        self.metadata = metadata
        self.t0_ns = t0_ns
        self.present = present
        self.final = final
        ends = [int(s.t_ns[-1]) for s in streams.values() if len(s)]
        self.end_ns = end_ns if end_ns is not None or not (final and ends) else max(ends)

    def recording(self) -> Recording:
        """The window's streams as a recording (of the whole recording for a final first
        window)."""
        return Recording({k: self[k] for k in StreamKind if k in self}, self.metadata,
                         self.t0_ns)


class Source:
    """A recording read once, window by window: iterate it for its :class:`Window` objects.

    Attributes
    ----------
    name : str
        The recording in messages (a path, or ``scenario#seed=N``).
    kind : str
        What it is: ``mcap``, ``rosbag2``, ``memory``.
    sources : dict[StreamKind, TopicSource]
        The topic, frame and convention of each stream, as it first appears.
    salvaged : bool
        Messages were lost to damage (known once the windows are read).
    recorded : list of RecordedSolution
        Navigation solutions the log recorded, replayed as rows beside the filters
        (``run --onboard``; known once the first window is read).
    """

    kind = ""

    def __init__(self, name: str) -> None:
        self.name = name
        self.sources: dict[StreamKind, TopicSource] = {}
        self.recorded: list[RecordedSolution] = []
        self._salvaged = False
        self._metadata: Metadata | None = None
        self._t0_ns = 0
        self._last_ns: int | None = None
        self._iterator: Iterator[Window] | None = None
        self._peeked: Window | None = None

    @property
    def salvaged(self) -> bool:
        return self._salvaged

    def _windows(self) -> Iterator[Window]:
        raise NotImplementedError

    def __iter__(self) -> Iterator[Window]:
        return self

    def peek(self) -> Window:
        """The first window, read now (every problem of the recording up to it is raised
        here); iterating still starts with it."""
        if self._peeked is None and self._iterator is None:
            self._peeked = next(self)
        if self._peeked is None:
            raise ValueError(f"{self.name}: windows were read already")
        return self._peeked

    def __next__(self) -> Window:
        if self._peeked is not None:
            window, self._peeked = self._peeked, None
            return window
        if self._iterator is None:
            self._iterator = self._windows()
        window = next(self._iterator)
        self._metadata, self._t0_ns = window.metadata, window.t0_ns
        ends = [int(s.t_ns[-1]) for s in window.values() if len(s)]
        if ends:
            self._last_ns = max(max(ends), self._last_ns or max(ends))
        return window

    def coverage(self) -> float | None:
        """Fraction of the recording's duration that the windows read cover: 1 for a complete
        recording; for a salvaged one the last sample time over the metadata's duration (None
        when the file does not say how long it was), and at most the fraction of its messages
        kept (``metadata.extra["messages_kept"]``: a rosbag2 folder whose data files hold fewer
        messages than its metadata.yaml counts)."""
        if not self.salvaged:
            return 1.0
        duration = self._metadata.params.get("duration") if self._metadata else None
        if not isinstance(duration, int | float) or not duration > 0 or self._last_ns is None:
            return None
        covered = min(max((self._last_ns - self._t0_ns) * 1e-9 / float(duration), 0.0), 1.0)
        kept = self._metadata.extra.get("messages_kept") if self._metadata else None
        return min(covered, float(kept)) if isinstance(kept, int | float) else covered

    def close(self) -> None:
        """Stop reading (the reader's warnings so far are given, its file closed)."""
        if self._iterator is not None and hasattr(self._iterator, "close"):
            self._iterator.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class FileSource(Source):
    """A recording file read with :class:`ReadOptions` (the readers of
    :data:`navreplay.io.files.FILE_KINDS`).

    Parameters
    ----------
    path : path-like
    options : ReadOptions, optional
        How to read it (the defaults when None).
    """

    def __init__(self, path: str | os.PathLike[str], options: ReadOptions | None = None
                 ) -> None:
        super().__init__(str(path))
        self.path = Path(path)
        self.options = options if options is not None else ReadOptions()


class MemorySource(Source):
    """A :class:`~navreplay.core.streams.Recording` in memory: one window holding every stream.

    Parameters
    ----------
    recording : Recording
    name : str, optional
        The recording in messages (default: ``scenario#seed=N``, or ``recording``).
    """

    kind = "memory"

    def __init__(self, recording: Recording, name: str = "") -> None:
        super().__init__(name or recording_name(recording))
        self.recording = recording

    def _windows(self) -> Iterator[Window]:
        rec = self.recording
        yield Window(dict(rec.streams), dict.fromkeys(rec.streams, COMPLETE), rec.metadata,
                     rec.t0_ns, frozenset(rec.kinds()), final=True)


def recording_name(recording: Recording) -> str:
    """A display name for an in-memory recording: ``scenario#seed`` or ``recording``."""
    md = recording.metadata
    if md.scenario:
        return md.scenario if md.seed is None else f"{md.scenario}#seed={md.seed}"
    return "recording"
