"""A log ready to replay: streams in NED/FRD, frames checked, reference and initial solution."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from navreplay.io.checks import read_policy
from navreplay.io.integrity import salvage_watch
from navreplay.io.reader import TopicSource, read_streams
from navreplay.logs.framecheck import check_frames
from navreplay.logs.initial import initial_nav
from navreplay.logs.options import REFERENCE, LogOptions
from navreplay.logs.reference import read_reference, reference_stream
from navreplay.streams import Recording, StreamKind


@dataclasses.dataclass
class PreparedLog:
    """What :func:`open_log` returns.

    Attributes
    ----------
    recording : Recording
        Its truth stream is the reference (if any); ``metadata.initial_nav`` the chosen start.
    sources : dict[StreamKind, TopicSource]
    notes : list[str]
        One line per check, reference and initialisation, for the report.
    salvaged : bool
        Messages were lost to damage (the file was salvaged).
    """

    recording: Recording
    sources: dict[StreamKind, TopicSource]
    notes: list[str]
    salvaged: bool = False


def open_log(path: str | Path, options: LogOptions | None = None) -> PreparedLog:
    """Read a log and make it ready to replay; every problem is raised before any replay."""
    options = options or LogOptions()
    path = Path(path)
    with read_policy(options.policy):
        with salvage_watch() as lost:
            recording, sources = read_streams(path, topics=options.topics,
                                              frames=options.stream_frames, time=options.time)
        recording.metadata.extra.setdefault("source", str(path))
        notes: list[str] = []
        if options.reference is not None:
            ref = read_reference(options.reference, path, recording,
                                 options.frames.get(REFERENCE), options.time)
            stream, note = reference_stream(ref, recording, options.initial)
            recording.streams[StreamKind.TRUTH] = stream
            notes.append(note)
        notes += make_ready(recording, sources, options)
    return PreparedLog(recording, sources, notes, salvaged=lost[0])


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
