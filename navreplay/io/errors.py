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


class SalvagedWarning(RecordingWarning):
    """A damaged file was read up to the damage: ``data_complete`` tells whether every message
    survived (only the summary was lost) or the messages after ``offset`` are lost."""

    def __init__(self, message: str, *, data_complete: bool = False) -> None:
        super().__init__(message)
        self.data_complete = data_complete
