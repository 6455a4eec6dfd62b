"""The published methods and the tour: ``reproduce``, ``demo``, ``warm-up``."""

from __future__ import annotations

from pathlib import Path

import click

from navreplay.cli.group import cli
from navreplay.cli.options import (
    FORCE_HELP,
    Progress,
    check_command_outputs,
    checks_failed,
    output_of,
)


@cli.command()
@click.argument("name", required=False)
@click.option("--runs", type=click.IntRange(min=1), help="Runs (default: the paper's).")
@click.option("--quick", is_flag=True, help="The quick version (fewer runs).")
@click.option("--seed", type=int, default=0, show_default=True, help="Base seed.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes.")
@click.option("--save", "save", type=click.Path(dir_okay=False), metavar="OUT.rrd",
              help="Save the Rerun view of the figures.")
@click.option("--force", is_flag=True, help=FORCE_HELP)
@click.option("--strict/--no-strict", default=True, show_default=True,
              help="Exit with status 1 if an acceptance check fails.")
def reproduce(name: str | None, runs: int | None, quick: bool, seed: int, workers: int,
              save: str | None, force: bool, strict: bool) -> None:
    """Reproduce a paper's results (NAME; without it, list them) and check the bands."""
    from navreplay import reproduce as registry

    if name is None:
        for n in registry.available():
            try:
                summary = registry.get(n).summary
            except ImportError:
                summary = "(not available in this build)"
            click.echo(f"{n:<20}  {summary}")
        return
    rep = registry.get(name)
    check_command_outputs(force, [], output_of(save, "--save"))
    if quick and runs is None:
        runs = getattr(rep, "quick_runs", None)
    with Progress(f"reproduce {name}") as progress:
        report = rep.run(runs=runs, seed=seed, workers=workers,
                         rrd=Path(save) if save else None, progress=progress)
    click.echo(report.format())
    if save:
        click.echo(f"\nRerun view saved to {save}; open it with: rerun {save}")
    if strict and not report.passed:
        checks_failed(sum(not c.passed for c in report.checks))


@cli.command()
@click.option("--out", "out", type=click.Path(file_okay=False), default="out", show_default=True,
              help="Directory for the recording, the .rrd files and the summary.")
@click.option("--no-reproductions", is_flag=True, help="Skip the paper reproductions.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes for the reproductions.")
@click.option("--view/--no-view", default=None,
              help="Open the Rerun viewer (default: only if one can be shown here).")
@click.option("--strict/--no-strict", default=True, show_default=True,
              help="Exit with status 1 if an acceptance check fails.")
def demo(out: str, no_reproductions: bool, workers: int, view: bool | None,
         strict: bool) -> None:
    """Simulate a drive, replay ins and gps-ins, run the quick paper reproductions, save .rrd."""
    from navreplay import jobs

    check_command_outputs(False, [], output_of(out, "--out", directory=True))
    job = jobs.DemoJob(out_dir=Path(out), reproductions=not no_reproductions, workers=workers,
                       view=view)
    bars: dict[str, Progress] = {}

    def progress(stage: str, done: int, total: int) -> None:
        for other in [s for s in bars if s != stage]:
            bars.pop(other).close()
        bars.setdefault(stage, Progress(stage))(done, total)

    try:
        report = jobs.demo(job, progress)
    finally:
        for bar in bars.values():
            bar.close()
    click.echo(report.format())
    if strict and report.failed_checks:
        checks_failed(report.failed_checks)


@cli.command("warm-up")
@click.argument("filters", nargs=-1)
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Processes at once (default: one per core).")
def warm_up(filters: tuple[str, ...], workers: int | None) -> None:
    """Compile the built-in filters' kernels into numba's cache (all, or FILTERS), so that
    the first run is as fast as the next ones; `make install` runs it."""
    from navreplay.jobs import warmup

    try:
        wall = warmup.warm_up(filters or None, workers,
                              lambda name, cpu: click.echo(f"{name:<20} {cpu:6.1f} s CPU"))
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    click.echo(f"numba cache warm ({wall:.1f} s)")
