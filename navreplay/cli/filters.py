"""Commands about filters: ``filters`` (the registry and each filter's parameters) and ``tune``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import click

from navreplay.cli.group import cli
from navreplay.cli.options import (
    FORCE_HELP,
    Progress,
    check_command_outputs,
    output_of,
    param_lines,
)


@cli.command()
@click.argument("name", required=False)
def filters(name: str | None) -> None:
    """List the filters (built-in and plug-ins) with their streams and parameters."""
    from navreplay.core.params import describe
    from navreplay.filters.registry import filters as table
    from navreplay.filters.registry import load_filter

    items = {name: load_filter(name)} if name else table()
    for i, (fname, cls) in enumerate(items.items()):
        if i:
            click.echo("")
        module = cls.__module__
        origin = "" if module.startswith("navreplay.") else f"  [plug-in: {module}]"
        click.echo(f"{fname}: {cls.summary}{origin}")
        click.echo(f"  requires: {', '.join(str(s) for s in cls.requires) or '-'}")
        if cls.optional:
            click.echo(f"  optional: {', '.join(str(s) for s in cls.optional)}")
        derived = set(cls.settings_from_sensors(cls.default_sensors()))
        reference = cls.default_sensors()
        click.echo("  parameters" + (" (* from the recording's sensor specifications; the "
                                     "defaults are for " + "; ".join(
                                         f"{k}: {reference.source(k)}" for k in reference.models)
                                     + ")" if derived else "") + ":")
        for line in param_lines(describe(cls.Params), derived):
            click.echo(f"    {line}")


@cli.command()
@click.argument("filter_ref", metavar="FILTER")
@click.argument("sources", nargs=-1, required=True, metavar="SCENARIO | RECORDING...")
@click.option("--param", "ranges", multiple=True, required=True,
              metavar="NAME=LOW:HIGH[:log|:linear]",
              help="A parameter to search and its range (repeatable).")
@click.option("-p", "--set", "params", multiple=True, metavar="[scenario.]KEY=VALUE",
              help="A fixed filter parameter (also the start), or scenario.KEY=VALUE.")
@click.option("--duration", type=float, help="Scenario length [s].")
@click.option("--trials", type=click.IntRange(min=1), default=40, show_default=True,
              help="Trials in all (a resumed study counts its own).")
@click.option("--runs", type=click.IntRange(min=1), default=8, show_default=True,
              help="Scenario runs scored per trial (seeds seed, seed+1, ...).")
@click.option("--validation-runs", type=click.IntRange(min=1), default=8, show_default=True,
              help="Scenario runs of the truth objective's validation (seeds seed+1000, ...); "
                   "the held-out objective validates on the other windows of the same runs.")
@click.option("--seed", type=int, default=0, show_default=True, help="First scenario seed.")
@click.option("--objective", type=click.Choice(["truth", "held-out"]),
              help="truth: ensemble consistency and accuracy (default with truth); held-out: "
                   "prediction of dropped GNSS fixes and NIS (default without).")
@click.option("--outage", type=float, default=30.0, show_default=True, metavar="S",
              help="Length of a held-out GNSS window [s].")
@click.option("--outage-period", type=float, default=120.0, show_default=True, metavar="S",
              help="One held-out window every S seconds (alternately search and validation).")
@click.option("--storage", type=click.Path(dir_okay=False), metavar="STUDY.journal",
              help="Keep the study in this file; the same command again resumes it.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), metavar="TUNED.toml",
              help="Write the chosen values as a [filter.NAME] table for run --config.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes.")
@click.option("--force", is_flag=True, help=FORCE_HELP)
def tune(filter_ref: str, sources: Sequence[str], ranges: Sequence[str],
         params: Sequence[str], duration: float | None, trials: int, runs: int,
         validation_runs: int, seed: int, objective: str | None, outage: float,
         outage_period: float, storage: str | None, output: str | None, workers: int,
         force: bool) -> None:
    """Search FILTER's parameters over a SCENARIO's runs or RECORDING(s) (optuna).

    With truth the objective is the ensemble's consistency (per-axis RMS/σ, time-averaged
    NEES) and accuracy; without, the prediction of GNSS fixes dropped in windows and the NIS.
    The chosen values are validated against the start on seeds (or windows) the search did
    not use.

    \b
    Examples:
      navreplay tune gps-ins vehicle-drive -p scenario.imu_grade=mems --duration 300 \\
          --param gyro_arw=1e-5:1e-3 --param gyro_bias_rw=1e-8:1e-5 -o tuned.toml
      navreplay tune gps-ins drive.mcap --param accel_bias_rw=1e-6:1e-3 --storage s.journal
    """
    from navreplay import jobs
    from navreplay.jobs.tune import Objective, TuneJob, parse_ranges
    from navreplay.sim.scenario import scenarios as table

    scenario = None
    recordings: tuple[Path, ...] = ()
    if len(sources) == 1 and sources[0] in table() and not Path(sources[0]).exists():
        scenario = sources[0]
    else:
        recordings = tuple(Path(s) for s in sources)
    scenario_items = [p.partition(".")[2] for p in params if p.startswith("scenario.")]
    filter_items = [p for p in params if not p.startswith("scenario.")]
    if scenario is None and (scenario_items or duration is not None):
        raise click.UsageError("scenario.KEY=VALUE and --duration apply to a SCENARIO")
    from navreplay.core.params import parse_assignments

    check_command_outputs(force, [*recordings, storage], output_of(output, "-o"))
    job = TuneJob(
        filter=filter_ref, scenario=scenario, recordings=recordings,
        ranges=parse_ranges(ranges, filter_ref), fixed=parse_assignments(filter_items),
        values=jobs.scenario_values(scenario_items, None, duration) if scenario else {},
        runs=runs, validation_runs=validation_runs, seed=seed, trials=trials,
        objective=Objective(objective) if objective else None, outage=outage,
        outage_period=outage_period, storage=Path(storage) if storage else None,
        output=Path(output) if output else None, workers=workers,
    )
    from navreplay.jobs.tune import tune as run_tune

    with Progress(f"tune {filter_ref}") as progress:
        try:
            report = run_tune(job, progress)
        except ImportError as e:
            raise click.ClickException(str(e)) from None
    click.echo(report.format())
