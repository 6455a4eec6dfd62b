"""The errors of a replay: each names the filter, the recording and, where it applies, the
stream and the time."""

from __future__ import annotations

from navreplay.filters.kalman import FilterDivergedError
from navreplay.io.errors import RecordingError


class ReplayError(RuntimeError):
    """A replay that cannot start or cannot go on (base of the replay errors)."""


class FilterOutputError(ReplayError):
    """A filter handed back an estimate or innovation that breaks the contract of
    :mod:`navreplay.filters.base` (wrong length, covariance not symmetric PSD, non-finite)."""


class FilterFailedError(ReplayError):
    """A filter raised inside ``propagate``, ``update`` or ``estimate``; the
    message names the filter, the recording and the time, the original is the ``__cause__``."""


class FilterInitError(ReplayError, ValueError):
    """A filter raised in ``__init__`` (a parameter it rejects, a missing initial solution,
    ...); the message names the filter and the recording, the original is the ``__cause__``.
    A ValueError too: the filter could not start from what it was given."""


class BadOutput(Exception):
    """An invalid estimate, before the engine names the filter, recording and time."""


class MissingStreamError(ReplayError):
    """The recording lacks a stream (or a stream lacks a column) that the filter requires."""


class InvalidRecordingError(ReplayError, RecordingError):
    """An in-memory recording with non-finite samples or timestamps that do not increase."""



def invalid(label: str, source: str, t: float, why: str) -> FilterOutputError:
    """An estimate or innovation of filter ``label`` that breaks the contract, at ``t`` [s]."""
    return FilterOutputError(f"filter {label!r} on {source} at t = {t:.3f} s: {why}")


def one_line(e: BaseException) -> str:
    """An exception as one line: its type and the first line of its message."""
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


def diverged(label: str, source: str, t: float, why: str) -> FilterDivergedError:
    """Filter ``label`` diverged at ``t`` [s] (the error keeps the time)."""
    err = FilterDivergedError(f"filter {label!r} diverged on {source} at t = {t:.3f} s: {why}")
    err.t = t
    return err
