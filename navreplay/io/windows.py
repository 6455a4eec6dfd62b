"""Read the long streams of an MCAP recording (IMU, truth) in time windows.

A day of 100 Hz IMU and truth does not need to be in memory at once: :func:`read_windows`
walks the file's chunks in order and hands out the decoded rows of the streamed kinds every
``window`` messages, each window a checked :class:`~navreplay.streams.Stream` per kind (the
conversions and checks of :func:`navreplay.io.reader.read_streams`, and time increasing across
windows). The aiding streams are small; :func:`navreplay.io.reader.read_streams` with ``skip``
reads them whole.

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
from navreplay.streams import Stream, StreamKind

STREAMED: tuple[StreamKind, ...] = (StreamKind.IMU, StreamKind.TRUTH)
"""Kinds read in windows by a streaming replay."""

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
    dict[StreamKind, Stream]
        The rows of each kind decoded since the previous window (a kind without new rows is
        left out), later than every row yielded before.

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
        chosen: dict[StreamKind, _Topic] | None = None
        last: dict[StreamKind, int] = {}
        frame: dict[StreamKind, str] = {}
        for block in walk(f, where, contents, plan.wants_chunk):
            if chosen is None:
                if not contents.intact:
                    raise NotStreamable(f"{where}: no summary to read the file in windows")
                chosen = plan.resolve(contents, explicit=False)
                _, t0_ns, aux = _metadata(contents, where)
            plan.feed(contents, block)
            if any(t.rows() >= window for t in chosen.values()):
                yield _window(chosen, last, frame, declared, aux, t0_ns, time, validate,
                              sources)
        if chosen is None:  # no chunk holds a streamed kind
            if not contents.intact:
                raise NotStreamable(f"{where}: no summary to read the file in windows")
            return
        out = _window(chosen, last, frame, declared, aux, t0_ns, time, validate, sources)
        if out:
            yield out


def _window(chosen: Mapping[StreamKind, _Topic], last: dict[StreamKind, int],
            frame: dict[StreamKind, str], declared: Mapping[StreamKind, Convention],
            aux: list[AuxColumn], t0_ns: int, time: str, validate: bool,
            sources: dict[StreamKind, TopicSource] | None) -> dict[StreamKind, Stream]:
    out: dict[StreamKind, Stream] = {}
    for kind, topic in chosen.items():
        if not topic.rows():
            continue
        fields = topic.drain()
        fields["t_ns"] = sample_times(fields["t_ns"], topic.log_ns, time, topic.label)
        frame.setdefault(kind, topic.first_frame_id or SPECS[kind].frame_id)
        stream, source = build_stream(kind, fields, frame[kind], topic.label, aux, t0_ns,
                                      validate, declared.get(kind), topic.channel.topic)
        if sources is not None:
            sources.setdefault(kind, source)
        if not len(stream):
            continue
        if kind in last and int(stream.t_ns[0]) <= last[kind]:
            raise RecordingError(
                f"{topic.label}: timestamp at {when(int(stream.t_ns[0]), t0_ns)} does not "
                f"follow the one at {when(last[kind], t0_ns)}"
            )
        last[kind] = int(stream.t_ns[-1])
        out[kind] = stream
    return out

