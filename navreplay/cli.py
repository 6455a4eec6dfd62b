"""The ``navreplay`` command: parse arguments into a typed job, make one library call, print.

Each command builds a configuration of :mod:`navreplay.jobs` (or calls a registry) and prints
the report it gets back. Expected failures (bad input, missing streams, unknown names, an
unreachable viewer, a diverging filter) print one line on stderr and exit with status 1; usage
errors exit with 2. ``navreplay --debug COMMAND`` shows the traceback instead.
"""

from __future__ import annotations

import contextlib
import gc
import os
import sys
import traceback
import warnings
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import Any

import click

from navreplay import __version__

EXPECTED_ERRORS: tuple[type[BaseException], ...] = ()
"""Error types reported as one line (filled lazily: importing them loads the package)."""


def _expected_errors() -> tuple[type[BaseException], ...]:
    global EXPECTED_ERRORS
    if not EXPECTED_ERRORS:
        from navreplay.campaign.ensemble import RunFailedError
        from navreplay.filters.kalman import FilterDivergedError
        from navreplay.filters.registry import FilterLoadError
        from navreplay.io import RecordingError
        from navreplay.outputs import OutputError
        from navreplay.params import ParamError
        from navreplay.replay.errors import ReplayError
        from navreplay.viz import VizUnavailableError

        EXPECTED_ERRORS = (
            RecordingError, OutputError, ParamError, FilterLoadError, FilterDivergedError,
            ReplayError, RunFailedError, VizUnavailableError, KeyError, FileExistsError,
            FileNotFoundError, IsADirectoryError, PermissionError,
        )
    return EXPECTED_ERRORS


def _expected(e: BaseException) -> bool:
    """One of the project's expected errors, or a device error (a full disk)."""
    from navreplay.outputs import DISK_ERRORS

    return isinstance(e, _expected_errors()) or (isinstance(e, OSError)
                                                 and e.errno in DISK_ERRORS)


def _message(e: BaseException) -> str:
    if isinstance(e, KeyError) and e.args:
        return str(e.args[0])
    if isinstance(e, OSError) and e.filename and e.strerror:
        return f"{e.filename}: {e.strerror}"
    if isinstance(e, OSError) and e.strerror and _expected(e) and type(e) is OSError:
        return f"{e.strerror}; nothing was written"
    return str(e) or type(e).__name__


class _Group(click.Group):
    """Turns the project's expected errors into one line and shows warnings as one line."""

    def invoke(self, ctx: click.Context) -> Any:
        from navreplay.lifecycle import Terminated, handle_signals, interrupted_by
        from navreplay.outputs import release_locks

        debug = bool(ctx.params.get("debug"))
        with (warnings.catch_warnings(), handle_signals(),
              contextlib.ExitStack() as stack):
            stack.callback(release_locks)
            warnings.showwarning = _show_warning  # type: ignore[assignment]
            try:
                return super().invoke(ctx)
            except click.exceptions.Exit:
                raise
            except (click.ClickException, click.Abort):
                raise
            except (Exception, KeyboardInterrupt, Terminated) as e:
                stop = interrupted_by(e)
                if stop is not None:  # also when a compiled function was hit by the signal
                    click.echo(str(stop) or "interrupted", err=True)
                    global _STOPPED
                    _STOPPED = True
                    raise click.exceptions.Exit(getattr(stop, "exit_code", 130)) from None
                if debug or not _expected(e):
                    raise
                # a reader left open by the error (a generator of windows) reports its
                # warnings when collected: now, as warnings, not as sys:1 lines at exit
                traceback.clear_frames(e.__traceback__)
                gc.collect()
                raise click.ClickException(_message(e)) from None


def _show_warning(message: Any, category: Any, filename: str, lineno: int,
                  file: Any = None, line: Any = None) -> None:
    click.echo(f"warning: {message}", err=True)


class _Progress:
    """A ``progress(done, total)`` callback drawing a click progress bar on stderr."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.bar: Any = None
        self.done = 0

    def __call__(self, done: int, total: int) -> None:
        if not _stderr_is_tty():
            return
        if self.bar is None:
            self.bar = click.progressbar(length=max(total, 1), label=self.label, file=sys.stderr)
            self.bar.__enter__()
        if done > self.done:
            self.bar.update(done - self.done)
            self.done = done

    def close(self) -> None:
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
            self.bar = None

    def __enter__(self) -> _Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _stderr_is_tty() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def _load_config(path: str | None, *tables: str) -> dict[str, Any] | None:
    """The TOML file, strict: only ``tables`` (``scenario``, ``filter``, ``topics``, ``frames``,
    ``initial``, ``sensors``, ``imu_range``) may appear; its ``[sensors.*]`` tables are checked
    here, so that a mistake names the file."""
    if path is None:
        return None
    from navreplay.params import load_toml
    from navreplay.sensors.specs import SPEC_KINDS, specs_from_tables

    allowed: dict[str, Any] = {"scenario": None, "topics": None, "frames": None,
                               "initial": None, "sensors": list(SPEC_KINDS), "imu_range": None}
    if "filter" in tables:
        from navreplay.filters.registry import filters

        allowed["filter"] = list(filters())
    config = load_toml(path, tables={t: allowed[t] for t in tables})
    specs_from_tables(config.get("sensors"), where=path)
    return config


def _sensor_config(path: str | None, config: dict[str, Any] | None) -> Any:
    """The ``[sensors.*]`` tables of the config file as sensor specifications (or None)."""
    if not config or not config.get("sensors"):
        return None
    from navreplay.sensors.specs import specs_from_tables

    return specs_from_tables(config["sensors"], where=Path(path).name if path else "")


def _viz_options(save: str | None, spawn: bool, connect: str | None, serve: bool,
                 no_viz: bool, bind: str | None = None, web_port: int | None = None,
                 grpc_port: int | None = None) -> Any:
    from navreplay.jobs import VizMode, VizOptions

    chosen = [name for name, on in (("--save", save is not None), ("--spawn", spawn),
                                    ("--connect", connect is not None), ("--serve", serve),
                                    ("--no-viz", no_viz)) if on]
    if len(chosen) > 1:
        raise click.UsageError(f"{' and '.join(chosen)} exclude each other")
    served = [name for name, v in (("--bind", bind), ("--web-port", web_port),
                                   ("--grpc-port", grpc_port)) if v is not None]
    if served and not serve:
        raise click.UsageError(f"{', '.join(served)} only go with --serve")
    if spawn:
        return VizOptions(VizMode.SPAWN)
    if connect is not None:
        return VizOptions(VizMode.CONNECT, url=connect)
    if serve:
        from navreplay.viz.targets import Serve, bind_address, exposure

        try:
            target = Serve(grpc_port=grpc_port or 9876, web_port=web_port or 9090,
                           bind=bind_address(bind or "127.0.0.1"))
        except ValueError as e:
            raise click.BadParameter(str(e)) from None
        warning = exposure(target)
        if warning is not None:  # said once, before anything is served
            click.echo(f"warning: {warning}", err=True)
        return VizOptions(VizMode.SERVE, bind=target.bind, web_port=target.web_port,
                          grpc_port=target.grpc_port)
    if no_viz:
        return VizOptions(VizMode.NONE)
    return VizOptions(VizMode.SAVE, Path(save) if save else None)


def _viz_flags(fn: Callable[..., Any]) -> Callable[..., Any]:
    opts = [
        click.option("--save", "save", metavar="OUT.rrd",
                     help="Save the Rerun view to this file (default: under out/)."),
        click.option("--spawn", is_flag=True, help="Open a local Rerun viewer and stream to it."),
        click.option("--connect", metavar="URL",
                     help="Stream to a running Rerun viewer (rerun+http://host:9876/proxy)."),
        click.option("--serve", is_flag=True,
                     help="Serve the view to a web browser until Ctrl-C (on this machine "
                          "only, unless --bind)."),
        click.option("--bind", "bind", metavar="ADDR",
                     help="With --serve: the address to listen on (default 127.0.0.1; "
                          "0.0.0.0 or :: for every interface: the viewer and its data are "
                          "then open to every host that reaches this machine, unauthenticated)."),
        click.option("--web-port", "web_port", type=click.IntRange(1, 65535), metavar="PORT",
                     help="With --serve: the web viewer's port [default: 9090]."),
        click.option("--grpc-port", "grpc_port", type=click.IntRange(1, 65535), metavar="PORT",
                     help="With --serve: the data's (gRPC) port [default: 9876]."),
        click.option("--no-viz", is_flag=True, help="No Rerun output."),
    ]
    for opt in reversed(opts):
        fn = opt(fn)
    return fn


_PARAM_HELP = ("Parameter as key=value (repeatable); sensors.KIND.FIELD=VALUE sets a sensor "
               "specification, e.g. sensors.imu.grade=mems or "
               "sensors.imu.gyro_arw='0.2 deg/sqrt(h)'.")
_FORCE_HELP = "Overwrite existing output files (never an input of the command)."


def _check_outputs(force: bool, inputs: Sequence[str | Path | None], *items: Any) -> None:
    """Refuse, before any work, outputs that would lose a file or fail late, and lock them
    against other commands (:func:`navreplay.outputs.check_outputs`); ``items`` are Outputs or
    None. A rosbag2 input (its folder, metadata.yaml or a data file) protects its folder."""
    from navreplay.io.rosbag import bag_folder
    from navreplay.outputs import check_outputs

    paths = [Path(p) for p in inputs if p is not None]
    folders = [bag_folder(p) for p in paths if p.exists()]
    check_outputs(items, paths + [f for f in folders if f is not None], force=force, lock=True)


def _out(path: str | Path | None, option: str, **kw: Any) -> Any:
    """An :class:`navreplay.outputs.Output`, or None without a path."""
    from navreplay.outputs import Output

    return None if path is None else Output(Path(path), option, **kw)


def _export_out(path: str | None, specs: Sequence[Any]) -> Any:
    """The ``--export DIR`` output, with the names of the files it writes for these filters."""
    from navreplay.jobs.results import export_names

    return _out(path, "--export", directory=True,
                writes=export_names([spec.label for spec in specs]))


def _viz_out(save: str | None, no_viz: bool, live: bool) -> Any:
    """The .rrd output: --save, or the default directory (its files are regenerated)."""
    if save is not None:
        return _out(save, "--save")
    if no_viz or live:
        return None
    from navreplay.jobs import DEFAULT_OUT

    return _out(DEFAULT_OUT, "--save (default)", directory=True, writes=("*.rrd",))


def _result_flags(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--export DIR and --report FILE.html (navreplay.jobs.results)."""
    fn = click.option("--report", "report", type=click.Path(dir_okay=False),
                      metavar="OUT.html", help="Write a self-contained HTML report.")(fn)
    return click.option("--export", "export", type=click.Path(file_okay=False), metavar="DIR",
                        help="Write CSV, TUM and Odometry MCAP (run) or ensemble CSV "
                             "(several recordings, montecarlo) into DIR.")(fn)


_max_imu_gap = click.option(
    "--max-imu-gap", type=float, metavar="S",
    help="Longest IMU gap [s] a filter bridges; a longer one, or any gap for a filter that "
         "cannot bridge, stops the run (default: 6 s).")


# --------------------------------------------------------------------------------------------
# the group



def _check_executor(ctx: click.Context, param: click.Parameter, value: str) -> str:
    from navreplay.campaign.dask_executor import is_address

    if value in ("process", "dask") or is_address(value):
        return value
    raise click.BadParameter(f"{value!r}: use process, dask or dask://HOST:PORT")

@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="navreplay")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
def cli(debug: bool) -> None:
    """Simulate navigation sensor recordings (MCAP) and replay estimation filters over them.

    \b
    Typical loop:
      navreplay scenarios
      navreplay simulate vehicle-drive -o recordings/drive.mcap --seed 1
      navreplay info recordings/drive.mcap
      navreplay filters
      navreplay run ins,gps-ins recordings/drive.mcap     # -> out/drive.rrd
      navreplay montecarlo vehicle-drive gps-ins --runs 20 --workers 2

    \b
    Outputs (-o, --save, --summary, --keep) never replace an existing file without --force
    and never an input of the command; they are checked before the work starts and written
    under a temporary name that is renamed only when complete.

    \b
    Exit status:
      0    success
      1    an error (one line on stderr); an acceptance check that failed in `reproduce` or
           `demo` (unless --no-strict); a DAMAGED recording or bag in `info`, or one whose
           streams cannot be read as asked
      2    usage error
      130  interrupted by Ctrl-C (SIGINT)
      129, 143  stopped by SIGHUP, SIGTERM
    A stopped command deletes its temporary files; those of a killed one (kill -9) are
    deleted by the next command writing into the same directory.
    """


# --------------------------------------------------------------------------------------------
# scenarios, simulate, info


@cli.command()
@click.option("-v", "--verbose", is_flag=True, help="Also list each scenario's parameters.")
def scenarios(verbose: bool) -> None:
    """List the built-in scenarios."""
    from navreplay.params import describe
    from navreplay.sim.scenario import scenarios as table

    items = table()
    width = max((len(n) for n in items), default=0)
    for name, cls in items.items():
        click.echo(f"{name:<{width}}  {cls.summary}")
        if verbose:
            click.echo(f"{'':<{width}}  streams: {', '.join(str(s) for s in cls.streams)}")
            for line in _param_lines(describe(cls.Params)):
                click.echo(f"{'':<{width}}  {line}")
    if not verbose:
        click.echo("\n(`navreplay scenarios -v` lists their parameters.)")


@cli.command()
@click.argument("scenario")
@click.option("-o", "--output", required=True, metavar="FILE.mcap|DIR",
              help="Recording to write; with --runs, NAME_0001.mcap... or DIR/SCENARIO_0001.mcap...")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed (run i of --runs uses seed + i).")
@click.option("--duration", type=float, help="Length [s] (same as -p duration=...).")
@click.option("-p", "--param", "params", multiple=True, metavar="KEY=VALUE", help=_PARAM_HELP)
@click.option("--config", type=click.Path(dir_okay=False), metavar="FILE.toml",
              help="TOML file; its [scenario] table sets parameters (-p wins), its "
                   "[sensors.imu|gps|mag|speed_log|depth] tables the sensors (datasheet units).")
@click.option("--runs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Number of recordings (seeds seed, seed+1, ...).")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes for --runs.")
@click.option("--force", is_flag=True, help=_FORCE_HELP)
def simulate(scenario: str, output: str, seed: int, duration: float | None,
             params: Sequence[str], config: str | None, runs: int, workers: int,
             force: bool) -> None:
    """Simulate SCENARIO into an MCAP recording (or --runs of them)."""
    from navreplay import jobs

    job = jobs.SimulateJob(
        scenario=scenario,
        output=Path(output),
        values=jobs.scenario_values(params, _load_config(config, "scenario", "sensors"),
                                    duration),
        seed=seed, runs=runs, force=force, workers=workers,
    )
    _check_outputs(force, [config], *(_out(p, "-o") for p in job.paths()))
    with _Progress(f"simulate {scenario}") as progress:
        paths = jobs.simulate(job, progress if runs > 1 else None)
    if len(paths) <= 3:
        for p in paths:
            click.echo(f"wrote {p}")
    else:
        click.echo(f"wrote {len(paths)} recordings: {paths[0]} ... {paths[-1]}")


def _log_flags(fn: Callable[..., Any]) -> Callable[..., Any]:
    opts = [
        click.option("--topic", "topics", multiple=True, metavar="KIND=/TOPIC",
                     help="Topic that feeds a stream (imu, gps, gps_vel, mag, ...); repeatable."),
        click.option("--frame", "frames", multiple=True, metavar="KIND=flu|frd|enu|ned",
                     help="Axis convention of a stream's topic, or reference=enu|ned; "
                          "repeatable."),
        click.option("--force-frame", "force_frame", is_flag=True,
                     help="Read topics in the axes --frame declares even where their frame "
                          "ids name other axes (else an error)."),
        click.option("--time", "time", type=click.Choice(["header", "log"]), default="header",
                     show_default=True,
                     help="Sample times: header stamps (log times where the stamps are zero "
                          "or do not increase, with a warning), or the log (receive) times."),
        click.option("--imu-range", "imu_range", metavar="gyro=DEG_PER_S,accel=G",
                     help="The IMU's measurement range per axis (datasheet); a sample beyond "
                          "it stops the run [default: gyro=20000,accel=200; or an [imu_range] "
                          "table]."),
    ]
    for opt in reversed(opts):
        fn = opt(fn)
    return fn


@cli.command()
@click.argument("recording", type=click.Path())
@_log_flags
@click.option("--config", type=click.Path(dir_okay=False), metavar="FILE.toml",
              help="TOML file with [topics] and [frames] tables.")
def info(recording: str, topics: Sequence[str], frames: Sequence[str], force_frame: bool,
         time: str, imu_range: str | None, config: str | None) -> None:
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
        topics, frames, config=_load_config(config, "topics", "frames", "imu_range"),
        time=time, imu_range_text=imu_range, force_frames=force_frame))
    click.echo(described.text)
    report = None if file_kind(recording).name == "rosbag2" else recording_info(recording)
    if described.damage:
        count = f"{report.message_count} messages readable; " if report is not None else ""
        raise click.ClickException(f"{recording}: DAMAGED ({count}see above)")
    if report is not None and not report.message_count:
        raise click.ClickException(f"{recording}: no message")
    if described.problem:
        raise click.ClickException(described.problem)


# --------------------------------------------------------------------------------------------
# filters


def _param_lines(rows: Sequence[tuple[str, str, Any, str]],
                 marked: Collection[str] = ()) -> list[str]:
    if not rows:
        return ["(no parameters)"]
    width = max(len(r[0]) for r in rows) + (1 if marked else 0)
    out = []
    for name, tp, default, doc in rows:
        shown = f"{name}*" if name in marked else name
        out.append(f"{shown:<{width}}  {tp} = {_show(default)}  {doc}".rstrip())
    return out


def _show(value: Any) -> str:
    """A default value as a user would type it after ``-p key=``."""
    if hasattr(value, "value"):  # enum
        return str(value.value)
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, tuple | list):
        return ",".join(_show(v) for v in value)
    return str(value)


@cli.command()
@click.argument("name", required=False)
def filters(name: str | None) -> None:
    """List the filters (built-in and plug-ins) with their streams and parameters."""
    from navreplay.filters.registry import filters as table
    from navreplay.filters.registry import load_filter
    from navreplay.params import describe

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
        for line in _param_lines(describe(cls.Params), derived):
            click.echo(f"    {line}")


@cli.command()
@click.argument("recording", type=click.Path())
@click.option("--topic", metavar="TOPIC", help="The IMU topic (default: the recording's IMU).")
@click.option("--start", type=float, metavar="S", help="Segment start [s from the recording "
              "start].")
@click.option("--end", type=float, metavar="S", help="Segment end [s from the recording start].")
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
@click.option("--force", is_flag=True, help=_FORCE_HELP)
def allan(recording: str, topic: str | None, start: float | None, end: float | None,
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
    _check_outputs(force, [recording], _out(spec, "-o"), _out(plot, "--plot"),
                   _out(save, "--save"))
    job = AllanJob(recording=Path(recording), topic=topic, start=start, end=end,
                   spec_path=Path(spec) if spec else None, plot_path=Path(plot) if plot else None,
                   view_path=Path(save) if save else None, bootstrap=bootstrap, time=time)
    try:
        report = run_allan(job)
    except ImportError as e:
        raise click.ClickException(str(e)) from None
    click.echo(report.format())


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
@click.option("--force", is_flag=True, help=_FORCE_HELP)
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
    from navreplay.params import parse_assignments

    _check_outputs(force, [*recordings, storage], _out(output, "-o"))
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

    with _Progress(f"tune {filter_ref}") as progress:
        try:
            report = run_tune(job, progress)
        except ImportError as e:
            raise click.ClickException(str(e)) from None
    click.echo(report.format())


# --------------------------------------------------------------------------------------------
# run, montecarlo


def _is_file(path: str | None) -> bool:
    return path is not None and Path(path).is_file()


def _looks_like_recording(arg: str) -> bool:
    return arg.endswith((".mcap", ".db3")) or Path(arg).is_file() or Path(arg).is_dir()


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
@_viz_flags
@click.option("--summary", "summary", type=click.Path(dir_okay=False), metavar="OUT.json",
              help="Write the summary figures as JSON.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes (for several recordings).")
@click.option("--executor", default="process", show_default=True,
              metavar="process|dask|dask://HOST:PORT", callback=_check_executor,
              help="Where the runs go: a process pool of --workers, a Dask LocalCluster of "
                   "--workers processes, or a running Dask scheduler.")
@click.option("--rate", type=float, metavar="X",
              help="Replay at X times real time (1.0 = real time), for live viewing.")
@click.option("--output-rate", type=float, default=10.0, show_default=True, metavar="HZ",
              help="Estimate output rate between aiding samples [Hz] (at most 1000).")
@_log_flags
@click.option("--init", "init", type=click.Choice(["metadata", "reference", "align", "table"]),
              help="Initial solution: the recording's metadata (default when present), the "
                   "reference's first sample, self-alignment, or the [initial] table.")
@click.option("--reference", "reference", metavar="TOPIC|FILE",
              help="Score against a topic (Odometry, PoseStamped, PoseWithCovarianceStamped, "
                   "NavSatFix, navreplay truth) or a TUM / CSV file.")
@click.option("--no-frame-check", is_flag=True,
              help="Skip the gravity and magnetic-dip checks of the frames.")
@_result_flags
@_max_imu_gap
@click.option("--force", is_flag=True, help=_FORCE_HELP)
def run(args: Sequence[str], refs: Sequence[str], params: Sequence[str], config: str | None,
        save: str | None, spawn: bool, connect: str | None, serve: bool, bind: str | None,
        web_port: int | None, grpc_port: int | None, no_viz: bool,
        summary: str | None, workers: int, executor: str, rate: float | None,
        output_rate: float,
        topics: Sequence[str], frames: Sequence[str], force_frame: bool, time: str,
        imu_range: str | None, init: str | None, reference: str | None, no_frame_check: bool,
        export: str | None, report: str | None, max_imu_gap: float | None,
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
    """
    from navreplay import jobs

    args = list(args)
    names: str | None = None
    if not (refs and _looks_like_recording(args[0])):
        names = args.pop(0)
    if not args:
        raise click.UsageError("no RECORDING given")
    from navreplay.logs.options import log_options

    cfg = _load_config(config, "filter", "topics", "frames", "initial", "sensors", "imu_range")
    specs = jobs.filter_specs(names, refs, params, cfg)
    _check_outputs(force, [*args, config, reference if _is_file(reference) else None],
                   _viz_out(save, no_viz, spawn or serve or bool(connect)),
                   _out(summary, "--summary"), _export_out(export, specs),
                   _out(report, "--report"))
    job = jobs.RunJob(
        filters=specs,
        recordings=tuple(Path(a) for a in args),
        viz=_viz_options(save, spawn, connect, serve, no_viz, bind, web_port, grpc_port),
        summary_path=Path(summary) if summary else None,
        workers=workers, executor=executor, pacing=rate, output_rate=output_rate,
        max_imu_gap=max_imu_gap,
        log=log_options(topics, frames, init, reference, cfg, not no_frame_check, time,
                        sensors=_sensor_config(config, cfg), imu_range_text=imu_range,
                        force_frames=force_frame),
        export_dir=Path(export) if export else None,
        report_path=Path(report) if report else None, force=force,
    )
    label = "replay" if len(args) == 1 else f"replay {len(args)} recordings"
    with _Progress(label) as progress:
        report = jobs.run(job, progress)
    _finish(report)


def _finish(report: Any) -> None:
    click.echo(report.format())
    sink = getattr(report, "sink", None)
    if sink is not None:  # --serve: keep the server up
        sink.wait()
        sink.close()


@cli.command()
@click.argument("scenario")
@click.argument("filter_names", metavar="FILTER[,FILTER...]", required=False)
@click.option("--runs", type=click.IntRange(min=1), required=True, help="Number of runs.")
@click.option("--seed", type=int, default=0, show_default=True, help="Run i uses seed + i.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes.")
@click.option("--executor", default="process", show_default=True,
              metavar="process|dask|dask://HOST:PORT", callback=_check_executor,
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
@click.option("--force", is_flag=True, help=_FORCE_HELP)
@_viz_flags
@click.option("--summary", "summary", type=click.Path(dir_okay=False), metavar="OUT.json",
              help="Write per-run and ensemble figures as JSON.")
@_result_flags
@_max_imu_gap
def montecarlo(scenario: str, filter_names: str | None, runs: int, seed: int, workers: int,
               executor: str, refs: Sequence[str], params: Sequence[str], duration: float | None,
               config: str | None, keep: str | None, force: bool, save: str | None,
               spawn: bool, connect: str | None, serve: bool, bind: str | None,
               web_port: int | None, grpc_port: int | None, no_viz: bool,
               summary: str | None, export: str | None, report: str | None,
               max_imu_gap: float | None) -> None:
    """Monte Carlo: simulate SCENARIO with --runs seeds and replay FILTER(s) on each, in memory.

    Prints per-filter ensemble statistics (RMS error vs mean filter sigma, NEES with its
    chi-square bounds) and saves them to a Rerun view.

    \b
    Example:
      navreplay montecarlo vehicle-drive ins,gps-ins --runs 50 --workers 2 -p scenario.duration=300
      navreplay montecarlo vehicle-drive gps-ins --runs 1000 --executor dask://scheduler:8786
    """
    from navreplay import jobs

    scenario_items = [p.partition(".")[2] for p in params if p.startswith("scenario.")]
    filter_items = [p for p in params if not p.startswith("scenario.")]
    cfg = _load_config(config, "scenario", "filter", "sensors")
    specs = jobs.filter_specs(filter_names, refs, filter_items, cfg)
    _check_outputs(force, [config], _out(keep, "--keep", directory=True, writes=("*.mcap",)),
                   _viz_out(save, no_viz, spawn or serve or bool(connect)),
                   _out(summary, "--summary"), _export_out(export, specs),
                   _out(report, "--report"))
    job = jobs.MonteCarloJob(
        scenario=scenario,
        filters=specs,
        runs=runs,
        values=jobs.scenario_values(scenario_items, cfg, duration),
        seed=seed, workers=workers, executor=executor,
        keep_dir=Path(keep) if keep else None, force=force,
        viz=_viz_options(save, spawn, connect, serve, no_viz, bind, web_port, grpc_port),
        summary_path=Path(summary) if summary else None,
        export_dir=Path(export) if export else None,
        report_path=Path(report) if report else None,
        max_imu_gap=max_imu_gap,
    )
    with _Progress(f"montecarlo {scenario}") as progress:
        report = jobs.montecarlo(job, progress)
    _finish(report)


# --------------------------------------------------------------------------------------------
# reproduce, demo


@cli.command()
@click.argument("name", required=False)
@click.option("--runs", type=click.IntRange(min=1), help="Runs (default: the paper's).")
@click.option("--quick", is_flag=True, help="The quick version (fewer runs).")
@click.option("--seed", type=int, default=0, show_default=True, help="Base seed.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes.")
@click.option("--save", "save", type=click.Path(dir_okay=False), metavar="OUT.rrd",
              help="Save the Rerun view of the figures.")
@click.option("--force", is_flag=True, help=_FORCE_HELP)
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
    _check_outputs(force, [], _out(save, "--save"))
    if quick and runs is None:
        runs = getattr(rep, "quick_runs", None)
    with _Progress(f"reproduce {name}") as progress:
        report = rep.run(runs=runs, seed=seed, workers=workers,
                         rrd=Path(save) if save else None, progress=progress)
    click.echo(report.format())
    if save:
        click.echo(f"\nRerun view saved to {save}; open it with: rerun {save}")
    if strict and not report.passed:
        _checks_failed(sum(not c.passed for c in report.checks))


def _checks_failed(count: int) -> None:
    raise click.ClickException(f"{count} acceptance check(s) failed (--no-strict: exit 0 anyway)")


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

    _check_outputs(False, [], _out(out, "--out", directory=True))
    job = jobs.DemoJob(out_dir=Path(out), reproductions=not no_reproductions, workers=workers,
                       view=view)
    bars: dict[str, _Progress] = {}

    def progress(stage: str, done: int, total: int) -> None:
        for other in [s for s in bars if s != stage]:
            bars.pop(other).close()
        bars.setdefault(stage, _Progress(stage))(done, total)

    try:
        report = jobs.demo(job, progress)
    finally:
        for bar in bars.values():
            bar.close()
    click.echo(report.format())
    if strict and report.failed_checks:
        _checks_failed(report.failed_checks)



@cli.command("warm-up")
@click.argument("filters", nargs=-1)
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Processes at once (default: one per core).")
def warm_up(filters: tuple[str, ...], workers: int | None) -> None:
    """Compile the built-in filters' kernels into numba's cache (all, or FILTERS), so that
    the first run is as fast as the next ones; `make install` runs it."""
    from navreplay import warmup

    try:
        wall = warmup.warm_up(filters or None, workers,
                              lambda name, cpu: click.echo(f"{name:<20} {cpu:6.1f} s CPU"))
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    click.echo(f"numba cache warm ({wall:.1f} s)")

_STOPPED = False
"""A signal stopped the command (its temporaries are gone, its workers stopped)."""


def main(argv: Sequence[str] | None = None) -> None:
    """Console-script entry point. A command stopped by a signal ends at once: the
    interpreter's teardown (freeing a loaded process, joining pools) could take longer than
    the second a stop may take, and nothing is left to save."""
    try:
        cli.main(args=list(argv) if argv is not None else None, prog_name="navreplay")
    except SystemExit as e:
        if not _STOPPED:
            raise
        from navreplay import lifecycle

        lifecycle.release_children()  # a served viewer
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(e.code if isinstance(e.code, int) else 1)


if __name__ == "__main__":
    main()
