"""Many runs in parallel: Monte Carlo campaigns and filters over many recordings.

A campaign is a list of :class:`~navreplay.campaign.tasks.RunTask` and a list of
:class:`~navreplay.replay.spec.FilterSpec`. Each task runs in a worker
(:func:`navreplay.campaign.tasks.run_task`); only the extractor's compact metrics travel back,
and the parent hands them, in task order, to a *sink* that accumulates statistics (for instance
:class:`navreplay.metrics.EnsembleStats`), so memory does not grow with the number of runs and
the statistics do not depend on the number of workers. Parallelism is behind the executor seam
of :mod:`navreplay.campaign.executors`.
"""

from __future__ import annotations

import collections
import concurrent.futures as cf
import dataclasses
import time
from collections.abc import Callable, Sequence

from navreplay.campaign.executors import Executor, Future, InlineExecutor, make_executor
from navreplay.campaign.tasks import Extractor, RunOutput, RunTask, default_extract, run_task
from navreplay.io import lifecycle
from navreplay.replay.spec import FilterSpec


class RunFailedError(RuntimeError):
    """A run of a campaign failed; the message names the run, its recording and the cause."""

    def __init__(self, task: RunTask, cause: BaseException) -> None:
        self.task = task
        seed = ""
        if task.seed is not None and task.path is None and task.keep is not None:
            seed = f", seed {task.seed}"
        super().__init__(f"run {task.index + 1} ({task.source}{seed}): {cause}")


@dataclasses.dataclass
class EnsembleRun:
    """Bookkeeping of a finished campaign (the statistics live in the sink).

    Attributes
    ----------
    runs : int
        Runs that completed.
    failed : list[tuple[int, str]]
        (index, message) of runs that failed (only with ``keep_going``).
    seconds : float
        Wall time [s].
    run_seconds : float
        Sum of the runs' own wall times [s] (over ``seconds``: the parallel speed-up).
    """

    runs: int
    failed: list[tuple[int, str]]
    seconds: float
    run_seconds: float


def run_ensemble(
    tasks: Sequence[RunTask],
    filters: Sequence[FilterSpec],
    sink: Callable[[RunOutput], None],
    *,
    extract: Extractor = default_extract,
    workers: int = 1,
    executor: Executor | str | None = None,
    progress: Callable[[int, int], None] | None = None,
    output_rate: float | None = 10.0,
    keep_going: bool = False,
) -> EnsembleRun:
    """Run every task over the filters in parallel and feed the outputs to ``sink`` in order.

    Parameters
    ----------
    tasks : sequence of RunTask
    filters : sequence of FilterSpec
        Labels must be unique.
    sink : callable
        Called in the parent with each :class:`RunOutput`, in task order (so statistics do not
        depend on the number of workers).
    extract : Extractor
        Reduces a run to compact metrics in the worker (a module-level function).
    workers : int
        Worker processes (1 = in this process); ignored when ``executor`` is given.
    executor : Executor or str, optional
        An executor to use instead of a new process pool (left running afterwards), or an
        ``--executor`` value for :func:`make_executor` (shut down afterwards).
    progress : callable, optional
        ``progress(done, total)`` after each run.
    output_rate : float or None
        Output tick rate of the replays [Hz].
    keep_going : bool
        Record failed runs in :attr:`EnsembleRun.failed` and go on, instead of stopping at the
        first failure with :class:`RunFailedError`.

    Returns
    -------
    EnsembleRun
    """
    labels = [f.label for f in filters]
    dupes = sorted({x for x in labels if labels.count(x) > 1})
    if dupes:
        raise ValueError(f"filter labels must be unique; repeated: {', '.join(dupes)}")
    for spec in filters:  # fail on an unknown filter or bad parameters before any work
        spec.resolve()
    own = executor is None or isinstance(executor, str)
    ex = (make_executor(workers, executor or "process")
          if executor is None or isinstance(executor, str) else executor)
    parallelism = getattr(ex, "parallelism", workers)
    window = 1 if isinstance(ex, InlineExecutor) else 2 * max(parallelism, 1)
    total = len(tasks)
    pending: collections.deque[tuple[RunTask, Future]] = collections.deque()
    queue = iter(tasks)
    failed: list[tuple[int, str]] = []
    done = 0
    run_seconds = 0.0
    t0 = time.perf_counter()
    ok = False
    try:
        while True:
            while len(pending) < window:
                task = next(queue, None)
                if task is None:
                    break
                pending.append((task, ex.submit(run_task, task, filters, extract, output_rate)))
            if not pending:
                break
            task, fut = pending.popleft()
            try:
                out = fut.result()
            except Exception as e:
                if not keep_going:
                    raise RunFailedError(task, e) from e
                failed.append((task.index, str(RunFailedError(task, e))))
            else:
                run_seconds += out.seconds
                sink(out)
            done += 1
            if progress is not None:
                progress(done, total)
        ok = True
    finally:
        if own:
            if ok:
                ex.shutdown(wait=True)
            elif isinstance(ex, cf.Executor):
                lifecycle.stop_workers(ex)  # before shutdown, which forgets the processes
                ex.shutdown(wait=False, cancel_futures=True)
            else:
                ex.shutdown(wait=False)
    return EnsembleRun(done - len(failed), failed, time.perf_counter() - t0, run_seconds)
