"""A part of a recording in time: ``--start`` / ``--end``.

A time is seconds from the recording's start (``--start 120``), UNIX seconds (``--start
1750000120.5``: any value of 1e9 s or more) or a UTC date and time in ISO 8601 (``--start
2025-06-15T14:02:00Z``; without a zone, UTC). :class:`TimeSpan` resolves both ends against a
recording's start, and :func:`cut_windows` cuts a source's windows to the span: windows wholly
before it are skipped (their streams kept, empty, in the first window handed out), and reading
stops at the first window that reaches the end.

Examples
--------
>>> span = TimeSpan.parse("10", "2025-01-01T00:00:30Z")
>>> span.bounds(t0_ns=1_735_689_600_000_000_000)
(1735689610000000000, 1735689630000000000)
>>> span.describe(1_735_689_600_000_000_000)
't = 10.000 to 30.000 s'
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import math
from collections.abc import Iterator

import numpy as np

from navreplay.core.streams import Stream, StreamKind
from navreplay.io.errors import RecordingError
from navreplay.io.source import COMPLETE, Window

UNIX_FROM = 1e9
"""A number of seconds from this value on is a UNIX time, below it a time since the start."""


class TimeSpanError(ValueError):
    """A ``--start`` / ``--end`` that is not a time, or a span that is empty."""


@dataclasses.dataclass(frozen=True)
class TimeValue:
    """One end: seconds since the recording start (``absolute`` False) or UNIX ns."""

    text: str
    absolute: bool
    value: float | int

    def ns(self, t0_ns: int) -> int:
        return int(self.value) if self.absolute else int(t0_ns) + round(self.value * 1e9)


def parse_time(text: str, option: str) -> TimeValue:
    """A ``--start`` / ``--end`` value (module docstring)."""
    s = str(text).strip()
    try:
        x = float(s)
    except ValueError:
        x = None
    if x is not None:
        if not math.isfinite(x):
            raise TimeSpanError(f"{option} {text}: not a finite time")
        if abs(x) >= UNIX_FROM:
            return TimeValue(s, True, round(x * 1e9))
        if x < 0:
            raise TimeSpanError(f"{option} {text}: seconds from the recording start are >= 0")
        return TimeValue(s, False, x)
    try:
        when = dt.datetime.fromisoformat(s.replace("Z", "+00:00"))
    except ValueError:
        raise TimeSpanError(f"{option} {text}: use seconds from the recording start, UNIX "
                            "seconds, or a UTC date and time (2025-06-15T14:02:00Z)") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=dt.UTC)
    delta = when - dt.datetime(1970, 1, 1, tzinfo=dt.UTC)
    return TimeValue(s, True, (delta.days * 86400 + delta.seconds) * 10**9
                     + delta.microseconds * 1000)


@dataclasses.dataclass(frozen=True)
class TimeSpan:
    """``--start`` and ``--end`` (either may be None: from the start, to the end)."""

    start: TimeValue | None = None
    end: TimeValue | None = None

    @classmethod
    def parse(cls, start: str | None, end: str | None) -> TimeSpan | None:
        """The span of the options, or None when neither is given."""
        if start is None and end is None:
            return None
        return cls(None if start is None else parse_time(start, "--start"),
                   None if end is None else parse_time(end, "--end"))

    def bounds(self, t0_ns: int) -> tuple[int | None, int | None]:
        """Both ends [ns] for a recording starting at ``t0_ns``."""
        lo = self.start.ns(t0_ns) if self.start is not None else None
        hi = self.end.ns(t0_ns) if self.end is not None else None
        if (self.start is not None and self.end is not None and lo is not None and hi is not None
                and not lo < hi):
            raise TimeSpanError(f"--start {self.start.text} is not before --end {self.end.text}"
                                f" (t = {(lo - t0_ns) * 1e-9:.3f} and {(hi - t0_ns) * 1e-9:.3f}"
                                " s from the recording start)")
        return lo, hi

    def describe(self, t0_ns: int) -> str:
        """``t = a to b s`` (from the recording start) for messages."""
        lo, hi = self.bounds(t0_ns)
        a = "start" if lo is None else f"{(lo - t0_ns) * 1e-9:.3f}"
        b = "end" if hi is None else f"{(hi - t0_ns) * 1e-9:.3f}"
        return f"t = {a} to {b} s"


def cut_window(window: Window, lo: int | None, hi: int | None) -> Window:
    """The rows of a window within ``[lo, hi]`` [ns] (every stream kept, maybe empty)."""
    streams = {}
    for kind, s in window.items():
        a = 0 if lo is None else int(np.searchsorted(s.t_ns, lo, side="left"))
        b = len(s) if hi is None else int(np.searchsorted(s.t_ns, hi, side="right"))
        streams[kind] = s.slice(a, max(a, b))
    return Window(streams, dict(window.known), window.metadata, window.t0_ns, window.present,
                  final=window.final, end_ns=window.end_ns)


def cut_windows(windows: Iterator[Window], span: TimeSpan, name: str) -> Iterator[Window]:
    """A source's windows cut to ``span`` (module docstring). A span the recording's IMU does
    not reach is one :class:`RecordingError` naming the recording and the span."""
    empty: dict[StreamKind, Stream] = {}
    handed = False
    bounds = None
    for window in windows:
        if bounds is None:
            try:
                bounds = span.bounds(window.t0_ns)
            except TimeSpanError as e:
                raise RecordingError(f"{name}: {e}") from None
        lo, hi = bounds
        cut = cut_window(window, lo, hi)
        reached = hi is not None and all(t >= hi for t in window.known.values())
        imu = cut.get(StreamKind.IMU)
        if not handed and not window.final and not reached and (imu is None or not len(imu)):
            empty.update({k: s for k, s in cut.items()})
            continue
        for kind, s in empty.items():
            cut.setdefault(kind, s)
        if not handed and StreamKind.IMU in window and not len(cut[StreamKind.IMU]):
            raise RecordingError(f"{name}: no IMU sample in {span.describe(window.t0_ns)} "
                                 "(--start / --end)")
        handed = True
        if reached and not cut.final:
            cut.final = True
            cut.known = dict.fromkeys(cut.known, COMPLETE)
        yield cut
        if cut.final:
            return
