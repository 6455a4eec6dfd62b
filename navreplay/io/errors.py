"""Errors and warnings raised while writing and reading recordings."""

from __future__ import annotations


class RecordingError(Exception):
    """A recording cannot be written or read as asked.

    The message names the file and, where it applies, the topic and the time of the offending
    message (seconds since the recording start and absolute nanoseconds).
    """


class RecordingExistsError(RecordingError, FileExistsError):
    """The target file exists and overwriting was not requested (``force=False``)."""


class RecordingWarning(UserWarning):
    """A recording was read, but not all of it is as expected (salvaged tail, gaps, ...)."""
