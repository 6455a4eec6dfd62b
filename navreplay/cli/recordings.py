"""Commands about recordings and sensors: ``scenarios``, ``simulate``, ``info``, ``allan``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import click

from navreplay.cli.group import cli
from navreplay.cli.options import (
    FORCE_HELP,
    PARAM_HELP,
    Progress,
    check_command_outputs,
    load_config,
    log_flags,
    output_of,
    param_lines,
)


@cli.command()
@click.option("-v", "--verbose", is_flag=True, help="Also list each scenario's parameters.")
def scenarios(verbose: bool) -> None:
    """List the built-in scenarios."""
    from navreplay.core.params import describe
    from navreplay.sim.scenario import scenarios as table

    items = table()
    width = max((len(n) for n in items), default=0)
    for name, cls in items.items():
        click.echo(f"{name:<{width}}  {cls.summary}")
        if verbose:
            click.echo(f"{'':<{width}}  streams: {', '.join(str(s) for s in cls.streams)}")
            for line in param_lines(describe(cls.Params)):
                click.echo(f"{'':<{width}}  {line}")
    if not verbose:
        click.echo("\n(`navreplay scenarios -v` lists their parameters.)")


@cli.command()
@click.argument("scenario")
@click.option("-o", "--output", required=True, metavar="FILE.mcap|DIR",
              help="Recording to write; with --runs, NAME_0001.mcap... or "
                   "DIR/SCENARIO_0001.mcap...")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed (run i of --runs uses seed + i).")
@click.option("--duration", type=float, help="Length [s] (same as -p duration=...).")
@click.option("-p", "--param", "params", multiple=True, metavar="KEY=VALUE", help=PARAM_HELP)
@click.option("--config", type=click.Path(dir_okay=False), metavar="FILE.toml",
              help="TOML file; its [scenario] table sets parameters (-p wins), its "
                   "[sensors.imu|gps|mag|speed_log|depth] tables the sensors (datasheet units).")
@click.option("--runs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Number of recordings (seeds seed, seed+1, ...).")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes for --runs.")
@click.option("--force", is_flag=True, help=FORCE_HELP)
def simulate(scenario: str, output: str, seed: int, duration: float | None,
             params: Sequence[str], config: str | None, runs: int, workers: int,
             force: bool) -> None:
    """Simulate SCENARIO into an MCAP recording (or --runs of them)."""
    from navreplay import jobs

    job = jobs.SimulateJob(
        scenario=scenario,
        output=Path(output),
        values=jobs.scenario_values(params, load_config(config, "scenario", "sensors"),
                                    duration),
        seed=seed, runs=runs, force=force, workers=workers,
    )
    check_command_outputs(force, [config], *(output_of(p, "-o") for p in job.paths()))
    with Progress(f"simulate {scenario}") as progress:
        paths = jobs.simulate(job, progress if runs > 1 else None)
    if len(paths) <= 3:
        for p in paths:
            click.echo(f"wrote {p}")
    else:
        click.echo(f"wrote {len(paths)} recordings: {paths[0]} ... {paths[-1]}")


@cli.command()
@click.argument("recording", type=click.Path())
@log_flags
@click.option("--config", type=click.Path(dir_okay=False), metavar="FILE.toml",
              help="TOML file with [topics] and [frames] tables.")
def info(recording: str, topics: Sequence[str], frames: Sequence[str], force_frame: bool,
         time: str, start: str | None, end: str | None, imu_range: str | None,
         config: str | None) -> None:
    """Topics, types, frames, rates, gaps and metadata of a RECORDING (MCAP file, rosbag2
    folder or .db3), and which stream each topic feeds.

    Exits with status 1 after the report when the file is DAMAGED (for a rosbag2 folder: its
    data files disagree with its metadata.yaml), holds no message, or its streams cannot be
    read as asked.
    """
    from navreplay.io import recording_info
    from navreplay.io.files import file_kind
    from navreplay.logs.describe import describe_log
    from navreplay.logs.options import log_options

    described = describe_log(recording, log_options(
        topics, frames, config=load_config(config, "topics", "frames", "imu_range"),
        time=time, imu_range_text=imu_range, force_frames=force_frame, start=start,
        end=end))
    click.echo(described.text)
    report = recording_info(recording) if file_kind(recording).name == "mcap" else None
    if described.damage:
        count = f"{report.message_count} messages readable; " if report is not None else ""
        raise click.ClickException(f"{recording}: DAMAGED ({count}see above)")
    if report is not None and not report.message_count:
        raise click.ClickException(f"{recording}: no message")
    if described.problem:
        raise click.ClickException(described.problem)


@cli.command()
@click.argument("recording", type=click.Path())
@click.option("--topic", metavar="TOPIC", help="The IMU topic (default: the recording's IMU).")
@click.option("--start", metavar="T", help="Segment start: s from the recording start, UNIX s, "
              "or a UTC time (2025-06-15T14:02:00Z).")
@click.option("--end", metavar="T", help="Segment end (as --start).")
@click.option("-o", "--output", "spec", type=click.Path(dir_okay=False), metavar="SPEC.toml",
              help="Write the fitted noise as a [sensors.imu] table (for simulate/run --config).")
@click.option("--plot", type=click.Path(dir_okay=False), metavar="FIG.png|FIG.svg",
              help="Write the Allan-deviation figure.")
@click.option("--save", type=click.Path(dir_okay=False), metavar="OUT.rrd",
              help="Write the Rerun view.")
@click.option("--bootstrap", type=click.IntRange(min=0), default=40, show_default=True,
              metavar="N", help="Synthetic records for the intervals of the fitted terms "
                                "(0: none).")
@click.option("--time", "time", type=click.Choice(["header", "log"]), default="header",
              show_default=True, help="Sample times: header stamps or log (receive) times.")
@click.option("--force", is_flag=True, help=FORCE_HELP)
def allan(recording: str, topic: str | None, start: str | None, end: str | None,
          spec: str | None, plot: str | None, save: str | None, bootstrap: int, time: str,
          force: bool) -> None:
    """Allan deviation of a still IMU segment and the noise terms fitted to it.

    Fits white noise (angle/velocity random walk), a Gauss-Markov bias instability (sigma and
    correlation time) and a rate/acceleration random walk to the overlapping Allan deviation
    of each triad, with intervals; refuses a segment that is not still or too short.

    \b
    Examples:
      navreplay simulate stationary -o still.mcap -p duration=7200 -p imu_grade=consumer
      navreplay allan still.mcap -o imu.toml --plot allan.png
      navreplay run gps-ins drive.mcap --config imu.toml
    """
    from navreplay.jobs.allan import AllanJob, plot_format, run_allan

    if plot is not None:
        try:
            plot_format(Path(plot))
        except ValueError as e:
            raise click.BadParameter(str(e), param_hint="--plot") from None
    check_command_outputs(force, [recording], output_of(spec, "-o"), output_of(plot, "--plot"),
                          output_of(save, "--save"))
    job = AllanJob(recording=Path(recording), topic=topic, start=start, end=end,
                   spec_path=Path(spec) if spec else None, plot_path=Path(plot) if plot else None,
                   view_path=Path(save) if save else None, bootstrap=bootstrap, time=time)
    try:
        report = run_allan(job)
    except ImportError as e:
        raise click.ClickException(str(e)) from None
    click.echo(report.format())
