"""``navreplay demo``: simulate the demo recording, replay its filters, run the quick paper
reproductions, save one .rrd."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

from navreplay.jobs.report import DEFAULT_OUT
from navreplay.jobs.run import RunJob, run
from navreplay.jobs.simulate import SimulateJob, simulate
from navreplay.replay.session import Progress
from navreplay.replay.spec import FilterSpec
from navreplay.viz.options import VizMode, VizOptions, open_viewer

DEMO_SCENARIO = "vehicle-drive"
DEMO_FILTERS = ("ins", "gps-ins")
DEMO_SEED = 1


@dataclasses.dataclass(frozen=True)
class DemoJob:
    """``navreplay demo``: the README's main job.

    Attributes
    ----------
    out_dir : Path
        Recordings, the .rrd and the summary go here (regenerated on every run).
    reproductions : bool
        Also run the quick versions of the paper reproductions.
    workers : int
    view : bool or None
        Open a Rerun viewer on the saved file: None = only if one can be shown here.
    """

    out_dir: Path = DEFAULT_OUT
    reproductions: bool = True
    workers: int = 1
    view: bool | None = None


@dataclasses.dataclass
class DemoReport:
    """Sections of the demo's output, in order."""

    sections: list[str]
    rrd: Path | None
    viewer: str = ""
    failed_checks: int = 0

    def format(self) -> str:
        return "\n\n".join(self.sections)


def demo(
    job: DemoJob,
    progress: Callable[[str, int, int], None] | None = None,
) -> DemoReport:
    """Simulate the demo recording, replay its filters, run the quick reproductions, save one
    .rrd; ``progress(stage, done, total)``."""
    out = Path(job.out_dir)
    out.mkdir(parents=True, exist_ok=True)

    def stage(name: str) -> Progress | None:
        if progress is None:
            return None
        return lambda d, n: progress(name, d, n)

    rec_path = out / f"{DEMO_SCENARIO}.mcap"
    simulate(SimulateJob(DEMO_SCENARIO, rec_path, seed=DEMO_SEED, force=True),
             stage(f"simulate {DEMO_SCENARIO}"))
    rrd = out / "demo.rrd"
    report = run(
        RunJob(
            filters=tuple(FilterSpec(f) for f in DEMO_FILTERS),
            recordings=(rec_path,),
            viz=VizOptions(VizMode.SAVE, rrd),
            summary_path=out / "demo-summary.json",
        ),
        stage("replay " + ", ".join(DEMO_FILTERS)),
    )
    sections = [
        _heading("Land vehicle: free inertial (ins) vs loosely coupled GPS/INS (gps-ins)"),
        f"Recording: {rec_path} ({DEMO_SCENARIO}, seed {DEMO_SEED}); inspect it with "
        f"`navreplay info {rec_path}`",
        report.format(),
    ]
    failed = 0
    if job.reproductions:
        from navreplay import reproduce

        for name in reproduce.available():
            rep = reproduce.get(name)
            sections.append(_heading(f"Paper reproduction (quick): {name}"))
            result = rep.run(runs=rep.quick_runs, seed=0, workers=job.workers,
                             rrd=out / f"{name}.rrd", progress=stage(f"reproduce {name}"))
            failed += sum(not c.passed for c in result.checks)
            sections.append(
                f"{result.format()}\n\nRerun view: rerun {out / f'{name}.rrd'}"
            )
    viewer = ""
    if job.view is not False:
        viewer = open_viewer(rrd, required=job.view is True)
    if viewer:
        sections.append(viewer)
    return DemoReport(sections, rrd, viewer, failed)


def _heading(text: str) -> str:
    return f"{'=' * len(text)}\n{text}\n{'=' * len(text)}"
