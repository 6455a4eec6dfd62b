"""Replaying filters over recordings.

:func:`replay_file` (:mod:`~navreplay.replay.pipeline`) is the one pipeline: a recording's
windows through one :class:`ReplaySession` per filter (:mod:`~navreplay.replay.session`, the
event loop over the plan of :mod:`~navreplay.replay.plan`), the scoring and the output stages,
block by block; :func:`replay` the same over a recording in memory. What to replay is a
:class:`FilterSpec` (:mod:`~navreplay.replay.spec`); checks before a replay are in
:mod:`~navreplay.replay.checks`, the estimates' columns and their checks in
:mod:`~navreplay.replay.columns`, IMU gaps in :mod:`~navreplay.replay.gaps`, the errors in
:mod:`~navreplay.replay.errors`. Campaigns of many runs are :mod:`navreplay.campaign`.
"""

from navreplay.filters.result import InnovationSeries, RunResult
from navreplay.replay.checks import check_streams, validate_recording
from navreplay.replay.errors import (
    FilterFailedError,
    FilterInitError,
    FilterOutputError,
    InvalidRecordingError,
    MissingStreamError,
    ReplayError,
)
from navreplay.replay.pipeline import Collect, FileRun, RunStart, Stage, replay, replay_file
from navreplay.replay.plan import STREAM_PRIORITY, plan_events
from navreplay.replay.session import Progress, ReplaySession
from navreplay.replay.spec import FilterSpec

__all__ = [
    "STREAM_PRIORITY",
    "Collect",
    "FileRun",
    "FilterFailedError",
    "FilterInitError",
    "FilterOutputError",
    "FilterSpec",
    "InnovationSeries",
    "InvalidRecordingError",
    "MissingStreamError",
    "Progress",
    "ReplayError",
    "ReplaySession",
    "RunResult",
    "RunStart",
    "Stage",
    "check_streams",
    "plan_events",
    "replay",
    "replay_file",
    "validate_recording",
]
