"""``navreplay simulate``: scenario recordings, in parallel, written atomically."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from navreplay import params as _params
from navreplay.campaign.ensemble import run_ensemble
from navreplay.campaign.tasks import RunTask
from navreplay.filters.result import RunResult
from navreplay.jobs.config import check_scenario
from navreplay.replay.session import Progress
from navreplay.streams import Recording


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


def simulate(job: SimulateJob, progress: Progress | None = None) -> list[Path]:
    """Simulate ``runs`` recordings and write them (atomically); returns their paths.

    Raises ``FileExistsError`` naming the first existing target before simulating anything
    (unless ``force``).
    """
    if job.runs < 1:
        raise _params.ParamError(f"--runs must be at least 1, got {job.runs}")
    check_scenario(job.scenario, job.values)
    paths = job.paths()
    if not job.force:
        existing = [p for p in paths if p.exists()]
        if existing:
            more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
            raise FileExistsError(f"{existing[0]} exists{more}; use --force to overwrite")
    tasks = [
        RunTask(i, scenario=job.scenario, values=dict(job.values), seed=job.seed + i,
                keep=str(p), force=job.force)
        for i, p in enumerate(paths)
    ]
    run_ensemble(tasks, (), lambda out: None, extract=_none_extract,
                 workers=min(job.workers, len(tasks)), progress=progress)
    return paths
