"""Replaying filters over recordings: the event loop (:mod:`~navreplay.replay.engine`), what
to replay (:mod:`~navreplay.replay.spec`) and the columnar result
(:mod:`~navreplay.replay.result`). Campaigns of many runs are :mod:`navreplay.campaign`.
"""

from navreplay.replay.engine import (
    STREAM_PRIORITY,
    FilterFailedError,
    FilterInitError,
    FilterOutputError,
    InvalidRecordingError,
    MissingStreamError,
    ReplayError,
    check_streams,
    plan_events,
    replay,
    validate_recording,
)
from navreplay.replay.result import InnovationSeries, RunResult
from navreplay.replay.spec import FilterSpec

__all__ = [
    "STREAM_PRIORITY",
    "FilterFailedError",
    "FilterInitError",
    "FilterOutputError",
    "FilterSpec",
    "InnovationSeries",
    "InvalidRecordingError",
    "MissingStreamError",
    "ReplayError",
    "RunResult",
    "check_streams",
    "plan_events",
    "replay",
    "validate_recording",
]
