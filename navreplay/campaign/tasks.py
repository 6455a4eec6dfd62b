"""What one run of a campaign is and what it does in its worker.

A :class:`RunTask` is a recording file, or a scenario + parameters + seed to simulate in memory
(:func:`monte_carlo_tasks`: run ``i`` of a Monte Carlo with base seed ``s`` simulates with seed
``s + i``, so ``navreplay simulate SCENARIO --seed s+i`` reproduces any single run).
:func:`run_task` loads or simulates the recording, replays every filter and reduces the results
to compact metrics with an *extractor*, a module-level function (it is pickled to the
workers)::

    def extract(recording: Recording, results: dict[str, RunResult], task: RunTask) -> Any

Only the extractor's value travels back (:class:`RunOutput`).

Examples
--------
>>> [t.seed for t in monte_carlo_tasks("stationary", runs=3, seed=10)]
[10, 11, 12]
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from navreplay.core.streams import Recording
from navreplay.filters.result import RunResult
from navreplay.io.source import MemorySource
from navreplay.replay.checks import validate_recording
from navreplay.replay.pipeline import Collect, replay_file
from navreplay.replay.spec import FilterSpec


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
    smooth : bool
        Also smooth the filters that can be (``--smooth``): their smoothed runs come back as
        ``LABEL/rts`` (:mod:`navreplay.replay.smoothing`; the forward pass is stored in the
        worker's temporary directory meanwhile and removed after the run).
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
    smooth: bool = False

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
        Fraction of the recording replayed (:meth:`navreplay.io.source.Source.coverage`).
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


def _load_task(task: RunTask) -> tuple[Recording, bool, float | None]:
    """The task's recording, whether it was salvaged from a damaged file and the fraction of
    it that was (1 for a whole recording)."""
    if task.path is not None:
        from navreplay.logs.prepare import open_log

        with open_log(task.path, task.log, whole=True) as source:
            recording = next(source).recording()
        return recording, source.salvaged, source.coverage()
    if task.scenario is None:
        raise ValueError(f"run {task.index}: neither a recording path nor a scenario")
    from navreplay.sim.scenario import simulate

    recording = simulate(task.scenario, dict(task.values), task.seed or 0)
    if task.keep is not None:
        from navreplay.io import write_recording

        Path(task.keep).parent.mkdir(parents=True, exist_ok=True)
        write_recording(task.keep, recording, force=task.force)
    return recording, False, 1.0


def replay_filters(
    recording: Recording,
    filters: Sequence[FilterSpec],
    *,
    source: str,
    output_rate: float | None = 10.0,
    validate: bool = True,
    max_imu_gap: float | None = None,
    smooth: bool = False,
) -> dict[str, RunResult]:
    """Replay each filter over one recording in memory (:func:`navreplay.replay.replay_file`
    over it as one window); results by label (with ``smooth``, each smoothable filter's
    smoothed run too, labelled ``LABEL/rts``).

    Every filter's streams are checked, and every filter built, before the first one runs, so a
    missing stream fails the whole command before any work.
    """
    src = MemorySource(recording, source)
    if validate:
        validate_recording(recording, src.name)
    collect = Collect(whole=not smooth)
    replay_file(src, filters, stages=[collect], output_rate=output_rate,
                max_imu_gap=max_imu_gap, score=False, smooth=smooth)
    return collect.results()


def run_task(
    task: RunTask,
    filters: Sequence[FilterSpec],
    extract: Extractor,
    output_rate: float | None = 10.0,
) -> RunOutput:
    """Load or simulate one recording, replay the filters, extract the metrics."""
    t0 = time.perf_counter()
    recording, salvaged, covered = _load_task(task)
    results = replay_filters(
        recording, filters, source=task.source, output_rate=output_rate,
        validate=task.path is None,  # files are validated by the reader
        max_imu_gap=task.max_imu_gap, smooth=task.smooth,
    )
    metrics = extract(recording, results, task)
    return RunOutput(task.index, task.source, task.seed, metrics, time.perf_counter() - t0,
                     salvaged, covered)


def default_extract(
    recording: Recording, results: dict[str, RunResult], task: RunTask
) -> dict[str, Any]:
    """Per-filter metrics against the recording's truth (:func:`navreplay.metrics.run_metrics`)."""
    from navreplay import metrics

    return {label: metrics.run_metrics(res, recording) for label, res in results.items()}
