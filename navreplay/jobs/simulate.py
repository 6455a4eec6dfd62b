"""``navreplay simulate``: scenario recordings, in parallel, written atomically."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from navreplay.campaign.ensemble import run_ensemble
from navreplay.campaign.tasks import RunTask
from navreplay.core import params as _params
from navreplay.core.streams import Recording
from navreplay.filters.result import RunResult
from navreplay.jobs.config import check_scenario
from navreplay.replay.session import Progress


@dataclasses.dataclass(frozen=True)
class SimulateJob:
    """``navreplay simulate``.

    Attributes
    ----------
    scenario : str
    output : Path
        The recording (``--runs 1``); with several runs, ``NAME_0001.mcap``... beside it, or
        ``<scenario>_0001.mcap``... inside it when it is a directory (or ends with ``/``).
    values : dict
        Scenario parameter values.
    seed : int
        Seed of the first run; run i uses ``seed + i``.
    runs : int
    force : bool
        Overwrite existing files.
    workers : int
    """

    scenario: str
    output: Path
    values: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    seed: int = 0
    runs: int = 1
    force: bool = False
    workers: int = 1

    def paths(self) -> list[Path]:
        out = Path(self.output)
        as_dir = out.is_dir() or str(self.output).endswith(("/", os.sep)) or not out.suffix
        if self.runs == 1 and not as_dir:
            return [out]
        if as_dir:
            return [out / f"{self.scenario}_{i + 1:04d}.mcap" for i in range(self.runs)]
        return [out.with_name(f"{out.stem}_{i + 1:04d}{out.suffix}") for i in range(self.runs)]


def _none_extract(recording: Recording, results: dict[str, RunResult], task: RunTask) -> None:
    return None


PROBE_S = 60.0
"""Length of the probe simulated to estimate a longer recording's size [s]."""
HEADROOM = 0.9
"""Fraction of the free disk space and available memory a simulation may plan to use."""
STOP_GRACE_S = 0.5
"""How long stopped workers get to clean up before they are killed [s]."""


@dataclasses.dataclass(frozen=True)
class SizeEstimate:
    """What a simulation will need, scaled from a short probe of the same scenario.

    Attributes
    ----------
    disk_bytes : float
        All the recordings' files.
    memory_bytes : float
        Peak memory of the runs simulated at once (one per worker).
    probe_s : float
        Length of the probe it was scaled from [s].
    """

    disk_bytes: float
    memory_bytes: float
    probe_s: float


def estimate_size(job: SimulateJob) -> SizeEstimate | None:
    """Disk and memory a simulation needs, from a probe of :data:`PROBE_S` (the arrays it
    allocates, traced, and the file it writes, both per second of recording, times the
    duration); None for a recording no longer than the probe, or a scenario that cannot
    simulate one that short."""
    import tempfile
    import tracemalloc

    from navreplay.io import write_recording
    from navreplay.sim.scenario import get_scenario, scenario_inputs, simulate

    duration = getattr(scenario_inputs(get_scenario(job.scenario), job.values)[0],
                       "duration", None)
    if not isinstance(duration, int | float) or not duration > PROBE_S:
        return None
    probe = {**job.values, "duration": PROBE_S}
    try:
        check_scenario(job.scenario, probe)
    except _params.ParamError:
        return None
    with tempfile.TemporaryDirectory(prefix="navreplay-probe-") as tmp:
        tracemalloc.start()
        try:
            recording = simulate(job.scenario, probe, seed=job.seed)
            path = write_recording(Path(tmp) / "probe.mcap", recording)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        size = path.stat().st_size
    scale = duration / PROBE_S
    at_once = min(job.workers, job.runs)
    return SizeEstimate(size * scale * job.runs, peak * scale * at_once, PROBE_S)


def available_memory() -> int | None:
    """Memory available to a new allocation [bytes] (Linux MemAvailable, else the free
    physical pages), None when unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _gib(n: float) -> str:
    return f"{n / 2**30:.3g} GiB"


def check_size(job: SimulateJob) -> None:
    """Refuse, before any work, a simulation whose recordings would not fit on the disk of
    their directory or in memory (:func:`estimate_size`)."""
    import shutil

    est = estimate_size(job)
    if est is None:
        return
    folder = job.paths()[0].parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    free = shutil.disk_usage(folder).free
    memory = available_memory()
    what = (f"simulate {job.scenario}" + (f" --runs {job.runs}" if job.runs > 1 else ""))
    if est.disk_bytes > HEADROOM * free:
        raise _params.ParamError(
            f"{what}: the recordings would take about {_gib(est.disk_bytes)} on disk and "
            f"{folder} has {_gib(free)} free (estimated from a {est.probe_s:g} s probe); "
            "simulate a shorter duration or fewer runs")
    if memory is not None and est.memory_bytes > HEADROOM * memory:
        raise _params.ParamError(
            f"{what}: simulating would need about {_gib(est.memory_bytes)} of memory and "
            f"{_gib(memory)} is available (estimated from a {est.probe_s:g} s probe); "
            "simulate a shorter duration or fewer workers")


def simulate(job: SimulateJob, progress: Progress | None = None) -> list[Path]:
    """Simulate ``runs`` recordings and write them (atomically); returns their paths.

    Raises ``FileExistsError`` naming the first existing target, and
    :class:`~navreplay.core.params.ParamError` for recordings that would not fit on disk or in
    memory (:func:`check_size`), before simulating anything (unless ``force``).

    The runs go to worker processes (one at least): a stop signal reaches this process at
    once, wherever the workers are (a compiled kernel over a day of samples does not look at
    signals for seconds), and the workers are stopped and, after :data:`STOP_GRACE_S`,
    killed; their temporaries are removed.
    """
    import concurrent.futures as cf

    from navreplay.io import lifecycle, outputs

    if job.runs < 1:
        raise _params.ParamError(f"--runs must be at least 1, got {job.runs}")
    check_scenario(job.scenario, job.values)
    paths = job.paths()
    if not job.force:
        existing = [p for p in paths if p.exists()]
        if existing:
            more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
            raise FileExistsError(f"{existing[0]} exists{more}; use --force to overwrite")
    check_size(job)
    for folder in {p.parent for p in paths}:  # here, where the warnings are seen
        outputs.clean_stale(folder)
    tasks = [
        RunTask(i, scenario=job.scenario, values=dict(job.values), seed=job.seed + i,
                keep=str(p), force=job.force)
        for i, p in enumerate(paths)
    ]
    pool = cf.ProcessPoolExecutor(max_workers=min(job.workers, len(tasks)),
                                  initializer=lifecycle.worker_init, initargs=(os.getpid(),))
    try:
        run_ensemble(tasks, (), lambda out: None, extract=_none_extract, executor=pool,
                     progress=progress)
    except BaseException:
        lifecycle.stop_workers(pool, grace=STOP_GRACE_S)  # before shutdown forgets them
        pool.shutdown(wait=False, cancel_futures=True)
        for folder in {p.parent for p in paths}:  # the killed workers' temporaries
            outputs.clean_stale(folder, warn=False)
        raise
    pool.shutdown(wait=True)
    return paths
