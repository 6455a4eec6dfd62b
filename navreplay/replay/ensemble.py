"""Many runs in parallel: Monte Carlo campaigns and filters over many recordings.

A campaign is a list of :class:`RunTask` (a recording file, or a scenario + parameters + seed to
simulate in memory) and a list of :class:`FilterSpec`. Each task runs in a worker process:
load or simulate the recording, replay every filter (:func:`navreplay.replay.engine.replay`),
and reduce the results to compact metrics with an *extractor*. Only those metrics travel back;
the parent hands them, in task order, to a *sink* that accumulates statistics (for instance
:class:`navreplay.metrics.EnsembleStats`), so memory does not grow with the number of runs.

Parallelism is behind a small seam, :class:`Executor`: anything with the
``concurrent.futures.Executor`` methods ``submit`` and ``shutdown`` whose futures have
``result()``. The default is a :class:`concurrent.futures.ProcessPoolExecutor` (or
:class:`InlineExecutor` for one worker); a Dask cluster, local or remote, through
:class:`navreplay.replay.dask_executor.DaskExecutor` (``--executor dask[://host:port]``), other
engines through a thin adapter of the same two methods.

The extractor and the sink are the campaign-specific parts (the paper reproductions supply
their own). An extractor is a module-level function (it is pickled to the workers)::

    def extract(recording: Recording, results: dict[str, RunResult], task: RunTask) -> Any

Seeds: run ``i`` of a Monte Carlo with base seed ``s`` simulates with seed ``s + i``, so
``navreplay simulate SCENARIO --seed s+i`` reproduces any single run.

Examples
--------
>>> from navreplay.replay.ensemble import FilterSpec, monte_carlo_tasks
>>> [t.seed for t in monte_carlo_tasks("stationary", runs=3, seed=10)]
[10, 11, 12]
>>> FilterSpec("gps-ins", {"gps_pos_sigma_scale": "2"}).label
'gps-ins'
"""

from __future__ import annotations

import collections
import concurrent.futures as cf
import dataclasses
import os
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

from navreplay import lifecycle
from navreplay.filters.base import Filter
from navreplay.filters.registry import load_filter
from navreplay.filters.settings import ParamValues
from navreplay.replay.engine import build_params, check_streams, replay
from navreplay.replay.result import RunResult
from navreplay.streams import Recording

# --------------------------------------------------------------------------------------------
# what to run


@dataclasses.dataclass(frozen=True)
class FilterSpec:
    """One filter of a campaign: a registry name or ``package.module:Class``, its parameter
    values and a display label.

    Attributes
    ----------
    ref : str
        Registry name (``navreplay filters``) or ``package.module:Class``.
    params : mapping
        Parameter values by name (strings as from ``-p key=value``, or typed values).
    label : str
        Display label, unique within a campaign (default: the name, or the class name for a
        ``module:Class`` reference).
    """

    ref: str
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    label: str = ""

    def __post_init__(self) -> None:
        if not self.label:
            default = self.ref.rpartition(":")[2] if ":" in self.ref else self.ref
            object.__setattr__(self, "label", default)
        object.__setattr__(self, "params", ParamValues(self.params))  # keeps the sources

    def load(self) -> type[Filter]:
        """The filter class (raises :class:`~navreplay.filters.registry.FilterLoadError`)."""
        return load_filter(self.ref)


@dataclasses.dataclass(frozen=True)
class RunTask:
    """One run: a recording file, or a scenario to simulate in memory.

    Attributes
    ----------
    index : int
        Position in the campaign (0-based); outputs reach the sink in this order.
    path : str, optional
        Recording file to read.
    scenario : str, optional
        Scenario to simulate (when ``path`` is None).
    values : mapping
        Scenario parameter values.
    seed : int, optional
        Simulation seed.
    keep : str, optional
        Write the simulated recording to this file (never overwritten unless ``force``).
    force : bool
        Overwrite ``keep`` if it exists.
    log : LogOptions, optional
        Topics, frames, time source, initialisation and reference applied to ``path``.
    max_imu_gap : float, optional
        Longest IMU gap a filter bridges [s] (``--max-imu-gap``, :mod:`navreplay.replay.gaps`).
    """

    index: int
    path: str | None = None
    scenario: str | None = None
    values: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    seed: int | None = None
    keep: str | None = None
    force: bool = False
    log: Any = None
    """How to read a log from elsewhere (:class:`navreplay.logs.options.LogOptions`)."""
    max_imu_gap: float | None = None

    @property
    def source(self) -> str:
        """Name of the run's recording in messages and results."""
        if self.path is not None:
            return self.path
        if self.keep is not None:
            return self.keep
        return f"{self.scenario}#seed={self.seed}"


def monte_carlo_tasks(
    scenario: str,
    runs: int,
    *,
    values: Mapping[str, Any] | None = None,
    seed: int = 0,
    keep_dir: str | Path | None = None,
    force: bool = False,
) -> list[RunTask]:
    """Tasks of a Monte Carlo campaign: run ``i`` simulates ``scenario`` with seed ``seed + i``.

    With ``keep_dir``, run ``i`` also writes ``keep_dir/<scenario>_<i+1:04d>.mcap``.
    """
    if runs < 1:
        raise ValueError(f"runs must be at least 1, got {runs}")
    values = dict(values or {})
    tasks = []
    for i in range(runs):
        keep = None
        if keep_dir is not None:
            keep = str(Path(keep_dir) / f"{scenario}_{i + 1:04d}.mcap")
        tasks.append(RunTask(i, scenario=scenario, values=values, seed=seed + i, keep=keep,
                             force=force))
    return tasks


def file_tasks(paths: Iterable[str | Path], log: Any = None) -> list[RunTask]:
    """Tasks replaying over recording files, one per path, each read with the same ``log``
    options (:class:`navreplay.logs.options.LogOptions`)."""
    return [RunTask(i, path=str(p), log=log) for i, p in enumerate(paths)]


# --------------------------------------------------------------------------------------------
# one run (executes in a worker)

Extractor = Callable[[Recording, dict[str, RunResult], RunTask], Any]
"""Reduces one run's results to compact, picklable metrics (a module-level function)."""


@dataclasses.dataclass
class RunOutput:
    """What a worker returns for one task.

    Attributes
    ----------
    index : int
    source : str
        The recording's name.
    seed : int or None
    metrics : Any
        The extractor's value.
    seconds : float
        Wall time of the run in the worker (load or simulate, replay, extract) [s].
    salvaged : bool
        The recording was salvaged from a damaged file.
    coverage : float or None
        Fraction of the recording replayed (:func:`navreplay.io.integrity.coverage`).
    """

    index: int
    source: str
    seed: int | None
    metrics: Any
    seconds: float
    salvaged: bool = False
    coverage: float | None = 1.0


def load_task(task: RunTask) -> Recording:
    """Read or simulate the task's recording (writing it to ``task.keep`` if asked)."""
    return _load_task(task)[0]


def _load_task(task: RunTask) -> tuple[Recording, bool]:
    """The task's recording and whether it was salvaged from a damaged file."""
    if task.path is not None:
        from navreplay.logs.prepare import open_log

        prepared = open_log(task.path, task.log)
        return prepared.recording, prepared.salvaged
    if task.scenario is None:
        raise ValueError(f"run {task.index}: neither a recording path nor a scenario")
    from navreplay.sim.scenario import simulate

    recording = simulate(task.scenario, dict(task.values), task.seed or 0)
    if task.keep is not None:
        from navreplay.io import write_recording

        Path(task.keep).parent.mkdir(parents=True, exist_ok=True)
        write_recording(task.keep, recording, force=task.force)
    return recording, False


def replay_filters(
    recording: Recording,
    filters: Sequence[FilterSpec],
    *,
    source: str,
    output_rate: float | None = 10.0,
    validate: bool = True,
    max_imu_gap: float | None = None,
) -> dict[str, RunResult]:
    """Replay each filter over one recording; results by label.

    Every filter's streams are checked before the first one runs, so a missing stream fails
    the whole command before any work.
    """
    classes = [spec.load() for spec in filters]
    for cls in classes:
        check_streams(recording, cls, source)
    results: dict[str, RunResult] = {}
    for spec, cls in zip(filters, classes, strict=True):
        results[spec.label] = replay(
            recording, cls, spec.params, label=spec.label, source=source,
            output_rate=output_rate, validate=validate, max_imu_gap=max_imu_gap,
        )
        validate = False  # once per recording is enough
    return results


def run_task(
    task: RunTask,
    filters: Sequence[FilterSpec],
    extract: Extractor,
    output_rate: float | None = 10.0,
) -> RunOutput:
    """Load or simulate one recording, replay the filters, extract the metrics."""
    t0 = time.perf_counter()
    from navreplay.io.integrity import coverage

    recording, salvaged = _load_task(task)
    results = replay_filters(
        recording, filters, source=task.source, output_rate=output_rate,
        validate=task.path is None,  # files are validated by the reader
        max_imu_gap=task.max_imu_gap,
    )
    metrics = extract(recording, results, task)
    return RunOutput(task.index, task.source, task.seed, metrics, time.perf_counter() - t0,
                     salvaged, coverage(recording, salvaged))


def default_extract(
    recording: Recording, results: dict[str, RunResult], task: RunTask
) -> dict[str, Any]:
    """Per-filter metrics against the recording's truth (:func:`navreplay.metrics.run_metrics`)."""
    from navreplay import metrics

    return {label: metrics.run_metrics(res, recording) for label, res in results.items()}


# --------------------------------------------------------------------------------------------
# the executor seam


class Future(Protocol):
    """What the campaign needs of a future."""

    def result(self, timeout: float | None = None) -> Any: ...


class Executor(Protocol):
    """What the campaign needs of an executor (a subset of ``concurrent.futures.Executor``)."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future: ...

    def shutdown(self, wait: bool = True) -> None: ...


class InlineExecutor:
    """Runs each task in the calling process when its result is asked for (one worker).

    Exceptions surface from ``result()`` as they would from a process pool.
    """

    class _Lazy:
        def __init__(self, fn: Callable[..., Any], args: tuple, kwargs: dict) -> None:
            self._call = (fn, args, kwargs)

        def result(self, timeout: float | None = None) -> Any:
            fn, args, kwargs = self._call
            return fn(*args, **kwargs)

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        return self._Lazy(fn, args, kwargs)

    def shutdown(self, wait: bool = True) -> None:
        return None


EXECUTORS = ("process", "dask", "dask://HOST:PORT")
"""What ``--executor`` takes: a process pool on this machine (the default), a Dask
LocalCluster of ``--workers`` processes, or a running Dask scheduler."""


def make_executor(workers: int, spec: str = "process") -> Executor:
    """The executor of a campaign: for ``spec == "process"`` an :class:`InlineExecutor` for one
    worker, else a process pool of ``workers``; for ``"dask"`` a Dask LocalCluster of
    ``workers`` processes; for a scheduler address (``dask://host:port``, ``tcp://...``) a
    client of that cluster (:mod:`navreplay.replay.dask_executor`)."""
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    from navreplay.replay import dask_executor

    if spec == "dask" or dask_executor.is_address(spec):
        return dask_executor.DaskExecutor(None if spec == "dask" else spec, workers)
    if spec != "process":
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}; got {spec!r}")
    if workers == 1:
        return InlineExecutor()
    return cf.ProcessPoolExecutor(max_workers=workers, initializer=lifecycle.worker_init,
                                  initargs=(os.getpid(),))


# --------------------------------------------------------------------------------------------
# the campaign


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
        build_params(spec.load(), spec.params)
    own = executor is None or isinstance(executor, str)
    ex = make_executor(workers, executor or "process") if own else executor
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
                ex.shutdown(wait=False, cancel_futures=True)
                lifecycle.stop_workers(ex)
            else:
                ex.shutdown(wait=False)
    return EnsembleRun(done - len(failed), failed, time.perf_counter() - t0, run_seconds)
