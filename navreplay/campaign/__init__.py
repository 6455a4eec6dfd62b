"""Campaigns: many runs of filters, over recording files or Monte Carlo seeds simulated in
memory, in parallel, reduced to ensemble statistics.

:mod:`~navreplay.campaign.tasks` says what one run is and does in its worker,
:mod:`~navreplay.campaign.ensemble` runs them and hands their outputs over in order,
:mod:`~navreplay.campaign.executors` is the seam to a process pool or
:mod:`~navreplay.campaign.dask_executor` a Dask cluster.
"""

from navreplay.campaign.ensemble import EnsembleRun, RunFailedError, run_ensemble
from navreplay.campaign.executors import Executor, InlineExecutor, make_executor
from navreplay.campaign.tasks import (
    RunOutput,
    RunTask,
    default_extract,
    file_tasks,
    monte_carlo_tasks,
    run_task,
)

__all__ = [
    "EnsembleRun",
    "Executor",
    "InlineExecutor",
    "RunFailedError",
    "RunOutput",
    "RunTask",
    "default_extract",
    "file_tasks",
    "make_executor",
    "monte_carlo_tasks",
    "run_ensemble",
    "run_task",
]
