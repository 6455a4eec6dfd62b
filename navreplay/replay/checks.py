"""Checks before a replay: the streams a filter requires, and the samples of a recording built
in memory."""

from __future__ import annotations

from collections.abc import Mapping

from navreplay.core.streams import Recording, Stream, StreamKind
from navreplay.filters.base import Filter
from navreplay.io.checks import first_problem
from navreplay.io.source import recording_name
from navreplay.replay.errors import InvalidRecordingError, MissingStreamError


def check_streams(recording: Recording | Mapping[StreamKind, Stream], filter_cls: type[Filter],
                  source: str = "") -> None:
    """Raise :class:`MissingStreamError` unless the recording (or the first window of one, which
    holds every stream read) has what the filter requires.

    The message names the missing streams (or columns) and what the recording holds.
    """
    if isinstance(recording, Recording):
        source = source or recording_name(recording)
        recording = recording.streams
    have = [str(k) for k in recording]
    missing = [str(k) for k in filter_cls.requires if k not in recording]
    if missing:
        raise MissingStreamError(
            f"filter {filter_cls.name!r} needs stream(s) {', '.join(missing)} that "
            f"{source} does not have (it has: {', '.join(have) or 'no streams'})"
        )
    for kind in filter_cls.requires:
        stream = recording[kind]
        needed = filter_cls.required_columns.get(kind)
        lacking = (
            stream.missing_fields()
            if needed is None
            else [c for c in needed if c not in stream.columns]
        )
        if lacking:
            raise MissingStreamError(
                f"{source}: stream {kind} lacks column(s) {', '.join(lacking)} that filter "
                f"{filter_cls.name!r} needs (it has: {', '.join(recording[kind].columns)})"
            )


def validate_recording(recording: Recording, source: str = "") -> None:
    """Raise :class:`InvalidRecordingError` on non-finite samples, negative sigmas or time that
    does not increase (the checks of :func:`navreplay.io.checks.first_problem`, which the
    reader and the writer apply to files).

    Files are validated by the reader; call this for recordings built in memory. The message
    names the recording, the stream, the column and the time of the first bad sample.
    """
    source = source or recording_name(recording)
    for kind, stream in recording.streams.items():
        problem = first_problem(stream, recording.t0_ns, ranges=False)
        if problem is not None:
            raise InvalidRecordingError(f"{source}: stream {kind}: {problem}")

