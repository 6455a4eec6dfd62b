"""Replaying filters over recordings: the event loop (:mod:`~navreplay.replay.engine`), many
runs in parallel (:mod:`~navreplay.replay.ensemble`) and the columnar result
(:mod:`~navreplay.replay.result`).
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
from navreplay.replay.ensemble import (
    EnsembleRun,
    Executor,
    FilterSpec,
    InlineExecutor,
    RunFailedError,
    RunOutput,
    RunTask,
    file_tasks,
    make_executor,
    monte_carlo_tasks,
    replay_filters,
    run_ensemble,
)
from navreplay.replay.result import InnovationSeries, RunResult

__all__ = [
    "STREAM_PRIORITY",
    "EnsembleRun",
    "Executor",
    "FilterFailedError",
    "FilterInitError",
    "FilterOutputError",
    "FilterSpec",
    "InlineExecutor",
    "InnovationSeries",
    "InvalidRecordingError",
    "MissingStreamError",
    "ReplayError",
    "RunFailedError",
    "RunOutput",
    "RunResult",
    "RunTask",
    "check_streams",
    "file_tasks",
    "make_executor",
    "monte_carlo_tasks",
    "plan_events",
    "replay",
    "replay_filters",
    "run_ensemble",
    "validate_recording",
]
