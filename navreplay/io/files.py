"""Recording files: which kind a path is, decided once, and the file opened once.

:func:`open_recording` asks each kind of :data:`FILE_KINDS` in turn whether it takes the path
and opens it as that kind's :class:`~navreplay.io.source.Source`: a ROS 1 bag
(:mod:`navreplay.io.rosbag1`), a rosbag2 folder, its ``metadata.yaml`` or a ``.db3`` file
(:mod:`navreplay.io.rosbag`), else an MCAP file
(:mod:`navreplay.io.mcapread`, the last, which takes any file). Another kind of log is one
module with an ``accepts(path)`` function and a ``Source`` class, and one line in
:data:`FILE_KINDS`.

:func:`read_recording` and :func:`read_streams` read a file whole, in one window.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Iterable
from pathlib import Path

from navreplay.core.streams import Recording, StreamKind
from navreplay.io import gins, mcapread, rosbag, rosbag1
from navreplay.io.errors import RecordingError
from navreplay.io.source import Source
from navreplay.io.topics import FrameNames, TopicNames, TopicSource


@dataclasses.dataclass(frozen=True)
class FileKind:
    """A kind of recording file: its name, whether it takes a path, and its source."""

    name: str
    accepts: Callable[[Path], bool]
    source: Callable[..., Source]


FILE_KINDS: tuple[FileKind, ...] = (
    FileKind("rosbag1", rosbag1.accepts, rosbag1.Bag1Source),
    FileKind("gins", gins.accepts, gins.GinsSource),
    FileKind("rosbag2", rosbag.accepts, rosbag.BagSource),
    FileKind("mcap", mcapread.accepts, mcapread.McapSource),
)
"""The kinds of recording file, asked in this order (the first that accepts a path reads it)."""

BAGS = ("rosbag1", "rosbag2")
"""The kinds read through rosbags (:mod:`navreplay.io.rosbag`)."""


def file_kind(path: str | os.PathLike[str]) -> FileKind:
    """The kind of recording file ``path`` is."""
    p = Path(path)
    return next(k for k in FILE_KINDS if k.accepts(p))


def open_recording(
    path: str | os.PathLike[str],
    *,
    kinds: Iterable[StreamKind | str] | None = None,
    explicit: bool = False,
    topics: TopicNames | None = None,
    frames: FrameNames | None = None,
    time: str = "header",
    validate: bool = True,
    whole: bool = False,
) -> Source:
    """Open a recording file as a source of windows of its streams.

    Parameters
    ----------
    path : path-like
        An MCAP file (ROS 2 profile, CDR messages), read in bulk, in time windows when it is
        intact; or a rosbag2 folder (its ``metadata.yaml``; MCAP or sqlite3 storage, split
        files) or a ``.db3`` file, read with ``rosbags`` in one window.
    kinds : iterable of StreamKind or str, optional
        Streams to read (all known ones when None).
    explicit : bool
        A stream of ``kinds`` that the file lacks is an error (else it is left out).
    topics : mapping of StreamKind or str to str, optional
        Topic to read for a stream, overriding :data:`~navreplay.io.schemas.TOPICS` (for
        recordings from elsewhere).
    frames : mapping of StreamKind or str to Convention or str, optional
        Declared axis convention of a stream's topic (``flu``/``frd`` for imu and mag,
        ``enu``/``ned`` for gps_vel), replacing the guess from the frame id.
    time : {"header", "log"}
        Sample times: the messages' ``header.stamp`` (falling back to the log times, with a
        warning, for a topic whose stamps are zero or do not increase), or the log (receive)
        times (:func:`navreplay.io.topics.sample_times`).
    validate : bool
        Check every stream: a non-finite value or a timestamp that repeats or goes backwards
        raises :class:`RecordingError`; gaps longer than 5x the median interval give a
        :class:`RecordingWarning`.
    whole : bool
        Read the file in one window.

    Returns
    -------
    Source
        Iterate it for its windows (:class:`~navreplay.io.source.Window`); close it (or use it
        as a context manager) to stop early.

    Raises
    ------
    RecordingError
        As :class:`navreplay.io.mcapread.McapSource` (no such file here; the rest while
        reading).
    """
    return file_kind(path).source(
        path, kinds=kinds, explicit=explicit, topics=topics, frames=frames, time=time,
        validate=validate, window=None if whole else mcapread.WINDOW_MESSAGES)


def read_streams(
    path: str | os.PathLike[str],
    *,
    kinds: Iterable[StreamKind | str] | None = None,
    validate: bool = True,
    topics: TopicNames | None = None,
    frames: FrameNames | None = None,
    time: str = "header",
) -> tuple[Recording, dict[StreamKind, TopicSource]]:
    """Read a recording whole into columnar streams (see :func:`open_recording`; a kind asked
    for and absent is an error).

    Returns
    -------
    Recording
        Streams in :class:`StreamKind` order; ``t_ns`` as ``time`` says [ns]. The metadata is
        the file's ``navreplay`` record, or ``Metadata()`` for a recording without one, whose
        ``t0_ns`` is then its first message's log time.
    sources : dict[StreamKind, TopicSource]
        Topic, frame id and convention of each stream.

    Warns
    -----
    RecordingWarning
        The file is truncated or unfinished (the messages before the damage are returned and the
        warning tells the time of the last one), conversions of a foreign frame convention, gaps.
    """
    with open_recording(path, kinds=kinds, explicit=kinds is not None, topics=topics,
                        frames=frames, time=time, validate=validate, whole=True) as source:
        window = next(source)
        if not window.final:
            raise RecordingError(f"{path}: read in several windows")  # (whole=True: never)
        return window.recording(), dict(source.sources)


def read_recording(
    path: str | os.PathLike[str],
    *,
    kinds: Iterable[StreamKind | str] | None = None,
    validate: bool = True,
    topics: TopicNames | None = None,
    frames: FrameNames | None = None,
    time: str = "header",
) -> Recording:
    """Read a recording whole into columnar streams (see :func:`read_streams`)."""
    return read_streams(path, kinds=kinds, validate=validate, topics=topics, frames=frames,
                        time=time)[0]
