"""A log ready to replay: streams in NED/FRD, frames checked, reference and initial solution.

:func:`open_log` opens a recording file (:func:`navreplay.io.files.open_recording`) as a
:class:`LogSource`: the same windows, the first made ready before it is handed out (frames
checked, the initial solution set in ``metadata.initial_nav`` (and the ``[initial]`` position, when
given, as ``metadata.extra["local_origin"]``), the ``[sensors.*]`` tables of
the configuration written over the sensor specifications, and with ``--reference`` the
reference as its truth stream: a log with a reference is read in one window). Every window is
read under the options' :class:`~navreplay.io.checks.ReadPolicy`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from navreplay.core.streams import LOCAL_ORIGIN, Recording, StreamKind
from navreplay.filters.base import Filter, consumed_streams
from navreplay.io.checks import read_policy
from navreplay.io.files import open_recording
from navreplay.io.source import COMPLETE, Source, Window
from navreplay.io.span import cut_windows
from navreplay.io.topics import TopicSource
from navreplay.logs.framecheck import check_frames
from navreplay.logs.initial import initial_nav
from navreplay.logs.onboard import read_onboard
from navreplay.logs.options import REFERENCE, LogOptions
from navreplay.logs.reference import read_reference, reference_stream


class LogSource(Source):
    """The windows of a log, the first made ready to replay (see the module docstring).

    Attributes
    ----------
    notes : list[str]
        One line per check, reference and initialisation, for the report (filled when the
        first window is read: every problem is raised then, before any replay).
    """

    def __init__(self, inner: Source, path: Path, options: LogOptions) -> None:
        super().__init__(inner.name)
        self.kind = inner.kind
        self.inner = inner
        self.path = path
        self.options = options
        self.sources = inner.sources
        self.notes: list[str] = []

    @property
    def salvaged(self) -> bool:
        return self.inner.salvaged

    def coverage(self) -> float | None:
        return self.inner.coverage()

    def close(self) -> None:
        super().close()
        self.inner.close()

    def _windows(self) -> Iterator[Window]:
        """Each window read under the log's :class:`~navreplay.io.checks.ReadPolicy` (the
        IMU's range, ``--force-frame``), which the reader's checks consult."""
        windows = self._ready()
        while True:
            with read_policy(self.options.policy):
                window = next(windows, None)
            if window is None:
                return
            yield window

    def _ready(self) -> Iterator[Window]:
        inner: Iterator[Window] = self.inner
        if self.options.span is not None:
            inner = cut_windows(inner, self.options.span, self.name)
        first = next(inner)
        first.metadata.extra.setdefault("source", str(self.path))
        if self.options.reference is not None:
            recording = first.recording()
            ref = read_reference(self.options.reference, self.path, recording,
                                 self.options.frames.get(REFERENCE), self.options.time)
            stream, note = reference_stream(ref, recording, self.options.initial)
            first[StreamKind.TRUTH] = stream
            first.known[StreamKind.TRUTH] = COMPLETE
            first.present = first.present | {StreamKind.TRUTH}
            self.notes.append(note)
        self.notes += make_ready(first.recording(), self.sources, self.options)
        for spec in self.options.onboard:
            solution, note = read_onboard(spec, self.path, first.recording(), self.inner,
                                          frames=self.options.frames, time=self.options.time,
                                          initial=self.options.initial)
            if self.options.span is not None:
                solution = solution.cut(*self.options.span.bounds(first.t0_ns))
            self.recorded.append(solution)
            self.notes.append(note)
        if self.options.span is not None:
            self.notes.append(f"replayed {self.options.span.describe(first.t0_ns)}")
        yield first
        yield from inner


def open_log(path: str | Path, options: LogOptions | None = None, *,
             kinds: Iterable[StreamKind] | None = None, whole: bool = False,
             window: int | None = None) -> LogSource:
    """Open a log to replay it (see the module docstring).

    Parameters
    ----------
    path : path-like
    options : LogOptions, optional
        Topics, frames, time source, initialisation, reference and recorded solutions.
    kinds : iterable of StreamKind, optional
        Streams to read (all when None; those the log lacks are left out).
    whole : bool
        Read it in one window (always so with a reference or a recorded solution).
    window : int, optional
        Messages of a stream per window otherwise (None: the reader's default).
    """
    options = options or LogOptions()
    path = Path(path)
    read = options.read_options(kinds, window=window)
    one = whole or options.reference is not None or bool(options.onboard)
    inner = open_recording(path, read.whole() if one else read)
    return LogSource(inner, path, options)


def streams_needed(classes: Iterable[type[Filter]], options: LogOptions | None = None
                   ) -> set[StreamKind]:
    """The streams a replay of ``classes`` reads: IMU and truth, those the filters consume (all
    for a filter that declares none) and those the frame checks and the initialisation read."""
    options = options or LogOptions()
    kinds = {StreamKind.IMU, StreamKind.TRUTH}
    for cls in classes:
        consumed = consumed_streams(cls)
        kinds |= set(StreamKind) if consumed is None else set(consumed)
    if options.check_frames or options.init is not None or options.initial:
        kinds |= {StreamKind.GPS, StreamKind.GPS_VEL, StreamKind.MAG}
    if options.onboard:  # a recorded solution: the master INS, or a local one placed by GNSS
        kinds |= {StreamKind.GPS, StreamKind.MASTER_INS}
    return kinds


def read_log(path: str | Path, options: LogOptions | None = None, *,
             kinds: Iterable[StreamKind] | None = None) -> tuple[Recording, list[str]]:
    """A log read whole (one window) and made ready, with its notes."""
    with open_log(path, options, kinds=kinds, whole=True) as source:
        return next(source).recording(), source.notes


def make_ready(recording: Recording, sources: dict[StreamKind, TopicSource],
               options: LogOptions) -> list[str]:
    """Check the frames, set the initial solution (``metadata.initial_nav``) and write the
    ``[sensors.*]`` tables over the sensor specifications (``metadata.sensors``) of a log read
    (for a log read in windows: its aiding streams and first window); one note per line."""
    notes: list[str] = []
    if options.sensors:
        from navreplay.sensors.specs import SensorSpecs

        own = SensorSpecs.from_metadata(recording.metadata.sensors,
                                        str(recording.metadata.extra.get("source", "")))
        recording.metadata.sensors = own.overridden_by(options.sensors).to_metadata()
    if options.check_frames and StreamKind.IMU in recording:
        notes += check_frames(recording, sources, _position(recording, options))
    nav, note = initial_nav(options.init, recording, options.initial, options.needs)
    if nav:
        recording.metadata.initial_nav = nav
    if "lat_deg" in options.initial and "lon_deg" in options.initial:
        # the user's position at the start: the origin of the view's and the exports' frame
        recording.metadata.extra[LOCAL_ORIGIN] = {
            "pos": [math.radians(options.initial["lat_deg"]),
                    math.radians(options.initial["lon_deg"]), float(options.initial.get("h", 0.0))],
            "source": "[initial] lat_deg, lon_deg, h (the position at the start)"}
    if note:
        notes.append(note)
    return notes


def _position(recording: Recording, options: LogOptions) -> np.ndarray | None:
    if StreamKind.GPS in recording and len(recording[StreamKind.GPS]):
        return recording[StreamKind.GPS]["pos"][0]
    if "lat_deg" in options.initial and "lon_deg" in options.initial:
        return np.radians([options.initial["lat_deg"], options.initial["lon_deg"], 0.0]) + \
            np.array([0.0, 0.0, float(options.initial.get("h", 0.0))])
    pos = recording.metadata.initial_nav.get("pos")
    return np.asarray(pos, dtype=float) if pos is not None else None
