"""Recording files: which kind a path is, decided once, and the file opened once.

:func:`open_recording` asks each kind of :data:`FILE_KINDS` in turn whether it takes the path
and opens it as that kind's :class:`~navreplay.io.source.FileSource`, with the
:class:`~navreplay.io.source.ReadOptions` every reader takes: a ROS 1 bag
(:mod:`navreplay.io.rosbag1`), a GINS text log (:mod:`navreplay.io.gins`), a PX4 ULog file
(:mod:`navreplay.io.ulog`), a rosbag2 folder, its ``metadata.yaml`` or a ``.db3`` file
(:mod:`navreplay.io.rosbag`), else an MCAP file
(:mod:`navreplay.io.mcapread`, the last, which takes any file). Another kind of log is one
module with an ``accepts(path)`` function and a ``FileSource`` class, and one line in
:data:`FILE_KINDS`.

:func:`read_recording` and :func:`read_streams` read a file whole, in one window.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from pathlib import Path

from navreplay.core.streams import Recording, StreamKind
from navreplay.io import gins, mcapread, rosbag, rosbag1, ulog
from navreplay.io.errors import RecordingError
from navreplay.io.source import ReadOptions, Source
from navreplay.io.topics import TopicSource


@dataclasses.dataclass(frozen=True)
class FileKind:
    """A kind of recording file: its name, whether it takes a path, and its source."""

    name: str
    accepts: Callable[[Path], bool]
    source: Callable[[str | os.PathLike[str], ReadOptions | None], Source]


FILE_KINDS: tuple[FileKind, ...] = (
    FileKind("rosbag1", rosbag1.accepts, rosbag1.Bag1Source),
    FileKind("gins", gins.accepts, gins.GinsSource),
    FileKind("ulog", ulog.accepts, ulog.ULogSource),
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


def open_recording(path: str | os.PathLike[str], options: ReadOptions | None = None
                   ) -> Source:
    """Open a recording file as a source of windows of its streams.

    Parameters
    ----------
    path : path-like
        A file or folder of one of the :data:`FILE_KINDS`: an MCAP file (ROS 2 profile, CDR
        messages), read in bulk, in time windows when it is intact; a rosbag2 folder (its
        ``metadata.yaml``; MCAP or sqlite3 storage, split files), a ``.db3`` file or a ROS 1
        bag, read with ``rosbags``; a GINS text log; a PX4 ULog file, read with pyulog; each of
        the last in one window.
    options : ReadOptions, optional
        Streams, topics, frames, time source, checks and window size
        (:class:`~navreplay.io.source.ReadOptions`; its defaults when None).

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
    return file_kind(path).source(path, options)


def read_streams(path: str | os.PathLike[str], options: ReadOptions | None = None
                 ) -> tuple[Recording, dict[StreamKind, TopicSource]]:
    """Read a recording whole into columnar streams (see :func:`open_recording`; in one
    window, and a kind of ``options.kinds`` absent is an error).

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
    options = options if options is not None else ReadOptions()
    options = dataclasses.replace(options, explicit=options.kinds is not None, window=None)
    with open_recording(path, options) as source:
        window = next(source)
        if not window.final:
            raise RecordingError(f"{path}: read in several windows")  # (window=None: never)
        return window.recording(), dict(source.sources)


def read_recording(path: str | os.PathLike[str], options: ReadOptions | None = None
                   ) -> Recording:
    """Read a recording whole into columnar streams (see :func:`read_streams`)."""
    return read_streams(path, options)[0]
