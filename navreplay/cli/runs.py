"""Replaying filters: ``run`` (recordings, rosbag2 bags) and ``montecarlo`` (simulated
campaigns)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import click

from navreplay.cli.group import cli
from navreplay.cli.options import (
    FORCE_HELP,
    Progress,
    check_command_outputs,
    check_executor,
    command_line,
    export_output,
    finish,
    is_file,
    load_config,
    log_flags,
    looks_like_recording,
    max_imu_gap_option,
    output_of,
    result_flags,
    sensor_config,
    smooth_option,
    viz_flags,
    viz_options,
    viz_output,
)


@cli.command()
@click.argument("args", nargs=-1, required=True, metavar="[FILTER[,FILTER...]] RECORDING...")
@click.option("--filter", "refs", multiple=True, metavar="MODULE:CLASS",
              help="Add a filter class by import path (repeatable).")
@click.option("-p", "--param", "params", multiple=True, metavar="[FILTER.]KEY=VALUE",
              help="Filter parameter; FILTER.KEY targets one filter (repeatable).")
@click.option("--config", type=click.Path(dir_okay=False), metavar="FILE.toml",
              help="TOML file with [filter.NAME] tables (-p wins), [sensors.KIND] tables of "
                   "sensor specifications (datasheet units; over the recording's own), "
                   "[topics], [frames], [initial].")
@viz_flags
@click.option("--summary", "summary", type=click.Path(dir_okay=False), metavar="OUT.json",
              help="Write the summary figures as JSON.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes (for several recordings).")
@click.option("--executor", default="process", show_default=True,
              metavar="process|dask|dask://HOST:PORT", callback=check_executor,
              help="Where the runs go: a process pool of --workers, a Dask LocalCluster of "
                   "--workers processes, or a running Dask scheduler.")
@click.option("--rate", type=float, metavar="X",
              help="Replay at X times real time (1.0 = real time), for live viewing.")
@click.option("--output-rate", type=float, default=10.0, show_default=True, metavar="HZ",
              help="Estimate output grid [Hz] (at most 1000); every aiding sample adds its "
                   "row, one row per time (docs/exports.md).")
@log_flags
@click.option("--init", "init", type=click.Choice(["metadata", "reference", "align", "table"]),
              help="Initial solution: the recording's metadata (default when present), the "
                   "reference's first sample, self-alignment, or the [initial] table.")
@click.option("--reference", "reference", metavar="TOPIC|FILE",
              help="Score against a topic (Odometry, PoseStamped, PoseWithCovarianceStamped, "
                   "NavSatFix, navreplay truth) or a TUM / CSV file.")
@click.option("--onboard", "onboard", multiple=True, metavar="ekf2|master_ins|TOPIC|FILE",
              help="A navigation solution the log recorded, shown, scored and exported as a "
                   "row beside the filters: PX4's estimate in a ULog file (ekf2), the master "
                   "INS, or a topic / file as --reference reads it; repeatable.")
@click.option("--no-frame-check", is_flag=True,
              help="Skip the gravity and magnetic-dip checks of the frames.")
@result_flags
@max_imu_gap_option
@click.option("--export-compression", "export_compression", default="zstd", show_default=True,
              type=click.Choice(["zstd", "lz4", "none"]),
              help="Chunk compression of the estimates MCAP of --export (none: readable "
                   "without a decompressor, e.g. by Foxglove's npm MCAP reader).")
@click.option("--export-reference", "export_reference", default="output", show_default=True,
              type=click.Choice(["output", "full"]),
              help="The reference (truth) in --export at the output rate (its first sample of "
                   "each output interval: beside every grid estimate) or at its own rate.")
@smooth_option
@click.option("--force", is_flag=True, help=FORCE_HELP)
def run(args: Sequence[str], refs: Sequence[str], params: Sequence[str], config: str | None,
        save: str | None, spawn: bool, connect: str | None, serve: bool, bind: str | None,
        web_port: int | None, grpc_port: int | None, no_viz: bool, full_rate: bool,
        summary: str | None, workers: int, executor: str, rate: float | None,
        output_rate: float,
        topics: Sequence[str], frames: Sequence[str], force_frame: bool, time: str,
        start: str | None, end: str | None,
        imu_range: str | None, init: str | None, reference: str | None,
        onboard: Sequence[str], no_frame_check: bool, export: str | None, report: str | None,
        max_imu_gap: float | None, export_compression: str, export_reference: str, smooth: bool,
        force: bool) -> None:
    """Replay FILTER(s) over RECORDING(s); several filters overlay in one Rerun view.

    \b
    Examples:
      navreplay run gps-ins drive.mcap
      navreplay run ins,gps-ins drive.mcap -p gps-ins.gps_pos_sigma_scale=2 --summary s.json
      navreplay run 'gps-ins[gps_pos_sigma_scale=1],gps-ins[gps_pos_sigma_scale=3]' drive.mcap
      navreplay run --filter mypkg.myfilter:MyFilter drive.mcap
      navreplay run gps-ins runs/*.mcap --workers 2      # ensemble statistics
      navreplay run ins,gps-ins drive.mcap --export out/drive --report out/drive.html
      navreplay run gps-ins drive.mcap --smooth --export out/drive   # + gps-ins/rts
      navreplay run gps-ins flight.ulg --onboard ekf2    # beside PX4's own estimate

    Variants: FILTER[KEY=VALUE,KEY=VALUE,...] runs a filter with its own parameters, labelled
    by that text (one filter several times side by side). Pairs are separated by ',' (not
    ';'); a vector goes on with commas; quote the list for the shell:

    \b
      navreplay run 'gps-ins,gps-ins[use_gps_vel=false,lever_arm_b=0.5,0,-1.2]' drive.mcap
    """
    from navreplay import jobs

    args = list(args)
    names: str | None = None
    if not ((refs or onboard) and looks_like_recording(args[0])):
        names = args.pop(0)
    if not args:
        raise click.UsageError("no RECORDING given")
    from navreplay.logs.options import log_options

    cfg = load_config(config, "filter", "topics", "frames", "initial", "sensors", "imu_range")
    # a recorded solution alone (--onboard without a filter) is a run of no filter
    specs = jobs.filter_specs(names, refs, params, cfg) if names or refs or not onboard else ()
    log = log_options(topics, frames, init, reference, cfg, not no_frame_check, time,
                      sensors=sensor_config(config, cfg), imu_range_text=imu_range,
                      force_frames=force_frame, start=start, end=end, onboard=onboard)
    check_command_outputs(force, [*args, config, reference if is_file(reference) else None,
                                  *(s for s in onboard if is_file(s))],
                          viz_output(save, no_viz, spawn or serve or bool(connect)),
                          output_of(summary, "--summary"),
                          export_output(export, specs, smooth, log.onboard),
                          output_of(report, "--report"))
    job = jobs.RunJob(
        filters=specs,
        recordings=tuple(Path(a) for a in args),
        viz=viz_options(save, spawn, connect, serve, no_viz, bind, web_port, grpc_port,
                        full_rate),
        summary_path=Path(summary) if summary else None,
        workers=workers, executor=executor, pacing=rate, output_rate=output_rate,
        max_imu_gap=max_imu_gap,
        log=log,
        export_dir=Path(export) if export else None, export_compression=export_compression,
        export_reference=export_reference,
        report_path=Path(report) if report else None, force=force, smooth=smooth,
        command=command_line(),
    )
    label = "replay" if len(args) == 1 else f"replay {len(args)} recordings"
    with Progress(label) as progress:
        done = jobs.run(job, progress)
    finish(done)


@cli.command()
@click.argument("scenario")
@click.argument("filter_names", metavar="FILTER[,FILTER...]", required=False)
@click.option("--runs", type=click.IntRange(min=1), required=True, help="Number of runs.")
@click.option("--seed", type=int, default=0, show_default=True, help="Run i uses seed + i.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes.")
@click.option("--executor", default="process", show_default=True,
              metavar="process|dask|dask://HOST:PORT", callback=check_executor,
              help="Where the runs go: a process pool of --workers, a Dask LocalCluster of "
                   "--workers processes, or a running Dask scheduler.")
@click.option("--filter", "refs", multiple=True, metavar="MODULE:CLASS",
              help="Add a filter class by import path (repeatable).")
@click.option("-p", "--param", "params", multiple=True, metavar="[FILTER.|scenario.]KEY=VALUE",
              help="Filter parameter, or scenario.KEY=VALUE for the scenario (repeatable).")
@click.option("--duration", type=float, help="Scenario length [s].")
@click.option("--config", type=click.Path(dir_okay=False), metavar="FILE.toml",
              help="TOML file with [scenario], [sensors.KIND] and [filter.NAME] tables "
                   "(-p wins).")
@click.option("--keep", "keep", type=click.Path(file_okay=False), metavar="DIR",
              help="Also write every run's recording into DIR.")
@click.option("--force", is_flag=True, help=FORCE_HELP)
@viz_flags
@click.option("--summary", "summary", type=click.Path(dir_okay=False), metavar="OUT.json",
              help="Write per-run and ensemble figures as JSON.")
@result_flags
@max_imu_gap_option
@smooth_option
def montecarlo(scenario: str, filter_names: str | None, runs: int, seed: int, workers: int,
               executor: str, refs: Sequence[str], params: Sequence[str], duration: float | None,
               config: str | None, keep: str | None, force: bool, save: str | None,
               spawn: bool, connect: str | None, serve: bool, bind: str | None,
               web_port: int | None, grpc_port: int | None, no_viz: bool, full_rate: bool,
               summary: str | None, export: str | None, report: str | None,
               max_imu_gap: float | None, smooth: bool) -> None:
    """Monte Carlo: simulate SCENARIO with --runs seeds and replay FILTER(s) on each, in memory.

    Prints per-filter ensemble statistics (RMS error vs mean filter sigma, NEES with its
    chi-square bounds) and saves them to a Rerun view.

    \b
    Example:
      navreplay montecarlo vehicle-drive ins,gps-ins --runs 50 --workers 2 -p scenario.duration=300
      navreplay montecarlo vehicle-drive gps-ins --runs 1000 --executor dask://scheduler:8786
      navreplay montecarlo vehicle-drive gps-ins --runs 50 --smooth   # + gps-ins/rts

    Variants: FILTER[KEY=VALUE,KEY=VALUE,...] runs a filter with its own parameters, labelled
    by that text (one filter several times side by side). Pairs are separated by ',' (not
    ';'); a vector goes on with commas; quote the list for the shell:

    \b
      navreplay montecarlo vehicle-drive 'gps-ins,gps-ins[use_gps_vel=false,lever_arm_b=1,0,-1]' \\
          --runs 20
    """
    from navreplay import jobs

    scenario_items = [p.partition(".")[2] for p in params if p.startswith("scenario.")]
    filter_items = [p for p in params if not p.startswith("scenario.")]
    cfg = load_config(config, "scenario", "filter", "sensors")
    specs = jobs.filter_specs(filter_names, refs, filter_items, cfg)
    check_command_outputs(force, [config],
                          output_of(keep, "--keep", directory=True, writes=("*.mcap",)),
                          viz_output(save, no_viz, spawn or serve or bool(connect)),
                          output_of(summary, "--summary"), export_output(export, specs, smooth),
                          output_of(report, "--report"))
    job = jobs.MonteCarloJob(
        scenario=scenario,
        filters=specs,
        runs=runs,
        values=jobs.scenario_values(scenario_items, cfg, duration),
        seed=seed, workers=workers, executor=executor,
        keep_dir=Path(keep) if keep else None, force=force,
        viz=viz_options(save, spawn, connect, serve, no_viz, bind, web_port, grpc_port,
                        full_rate),
        summary_path=Path(summary) if summary else None,
        export_dir=Path(export) if export else None,
        report_path=Path(report) if report else None,
        max_imu_gap=max_imu_gap, smooth=smooth,
    )
    with Progress(f"montecarlo {scenario}") as progress:
        done = jobs.montecarlo(job, progress)
    finish(done)


@cli.command()
@click.argument("summaries", nargs=-1, required=True, metavar="SUMMARY.json...",
                type=click.Path(dir_okay=False))
@viz_flags
@click.option("--report", "report", type=click.Path(dir_okay=False), metavar="OUT.html|OUT.pdf",
              help="Write the comparison as a self-contained HTML report (or a PDF).")
@click.option("--force", is_flag=True, help=FORCE_HELP)
def compare(summaries: Sequence[str], save: str | None, spawn: bool, connect: str | None,
            serve: bool, bind: str | None, web_port: int | None, grpc_port: int | None,
            no_viz: bool, full_rate: bool, report: str | None, force: bool) -> None:
    """Compare the headline metrics of saved summaries (``run``/``montecarlo --summary``):
    a row per metric, a column per filter (``FILE/label`` when labels repeat), the best marked.

    \b
    Examples:
      navreplay compare day1.json day2.json
      navreplay compare day1.json day2.json --save cmp.rrd --report cmp.html
    """
    from navreplay import jobs

    view = save is not None or spawn or serve or connect is not None
    check_command_outputs(force, list(summaries),
                          output_of(save, "--save") if save is not None else None,
                          output_of(report, "--report"))
    job = jobs.CompareJob(
        summaries=tuple(Path(s) for s in summaries),
        viz=viz_options(save, spawn, connect, serve, no_viz or not view, bind, web_port,
                        grpc_port, full_rate and view),
        report_path=Path(report) if report else None, force=force)
    finish(jobs.compare(job))
