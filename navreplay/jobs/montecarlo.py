"""``navreplay montecarlo``: simulate and replay many seeds in memory; ensemble statistics."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from navreplay.campaign.tasks import monte_carlo_tasks
from navreplay.core import params as _params
from navreplay.jobs.config import check_scenario
from navreplay.jobs.report import DEFAULT_OUT, RunReport
from navreplay.jobs.run import campaign, outputs_of
from navreplay.replay.errors import MissingStreamError
from navreplay.replay.session import Progress
from navreplay.replay.spec import FilterSpec
from navreplay.viz.options import VizOptions


@dataclasses.dataclass(frozen=True)
class MonteCarloJob:
    """``navreplay montecarlo``: simulate and replay ``runs`` seeds in memory.

    Attributes
    ----------
    scenario : str
    filters : tuple of FilterSpec
    runs : int
    values : dict
        Scenario parameter values.
    seed : int
        Run i uses ``seed + i``.
    workers : int
    keep_dir : Path, optional
        Also write each run's recording here (``<scenario>_0001.mcap``, ...).
    force : bool
        Overwrite kept recordings.
    viz : VizOptions
        Default: save ``out/montecarlo-<scenario>.rrd`` (ensemble statistics).
    summary_path : Path, optional
    output_rate : float
    export_dir, report_path : Path, optional
        ``--export DIR`` (ensemble statistics as CSV) and ``--report FILE.html``.
    executor : str
        ``process``, ``dask`` or ``dask://HOST:PORT``
        (:func:`navreplay.campaign.executors.make_executor`).
    max_imu_gap : float, optional
        Longest IMU gap a filter bridges [s] (:mod:`navreplay.replay.gaps`).
    smooth : bool
        Also smooth every run of the filters that can be: their ensemble statistics come
        beside the forward ones, labelled ``LABEL/rts`` (:mod:`navreplay.jobs.smooth`).
    """

    scenario: str
    filters: tuple[FilterSpec, ...]
    runs: int
    values: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    seed: int = 0
    workers: int = 1
    keep_dir: Path | None = None
    force: bool = False
    viz: VizOptions = VizOptions()
    summary_path: Path | None = None
    output_rate: float = 10.0
    export_dir: Path | None = None
    report_path: Path | None = None
    executor: str = "process"
    max_imu_gap: float | None = None
    smooth: bool = False


def montecarlo(job: MonteCarloJob, progress: Progress | None = None) -> RunReport:
    """Run a Monte Carlo campaign and report per-filter ensemble statistics."""
    if job.runs < 1:
        raise _params.ParamError(f"--runs must be at least 1, got {job.runs}")
    check_scenario(job.scenario, job.values)
    from navreplay.sim.scenario import get_scenario

    streams = set(get_scenario(job.scenario).streams)
    for spec in job.filters:
        cls = spec.filter_cls
        missing = [str(k) for k in cls.requires if k not in streams]
        if missing:
            raise MissingStreamError(
                f"filter {spec.label!r} needs stream(s) {', '.join(missing)} that scenario "
                f"{job.scenario} does not simulate (it has: "
                f"{', '.join(str(k) for k in get_scenario(job.scenario).streams)})"
            )
    tasks = monte_carlo_tasks(job.scenario, job.runs, values=job.values, seed=job.seed,
                              keep_dir=job.keep_dir, force=job.force)
    if job.keep_dir is not None:
        Path(job.keep_dir).mkdir(parents=True, exist_ok=True)
    if job.keep_dir is not None and not job.force:
        existing = [t.keep for t in tasks if t.keep and Path(t.keep).exists()]
        if existing:
            raise FileExistsError(f"{existing[0]} exists; use --force to overwrite")
    title = (f"Monte Carlo: {', '.join(s.label for s in job.filters)} on {job.scenario}, "
             f"{job.runs} runs, seeds {job.seed}..{job.seed + job.runs - 1}")
    return campaign(tasks, job.filters, job.viz, DEFAULT_OUT / f"montecarlo-{job.scenario}.rrd",
                     job.summary_path, job.workers, progress, title, job.output_rate,
                     per_run_table=False, outputs=outputs_of(job), executor=job.executor,
                     max_imu_gap=job.max_imu_gap, smooth=job.smooth)
