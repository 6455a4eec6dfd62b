"""What the commands share: option groups (the view, the log options, the results), the
overwrite check of their outputs before the work, TOML configurations, the progress line and
the tables they print."""

from __future__ import annotations

import sys
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import Any

import click


class Progress:
    """A ``progress(done, total)`` callback drawing a click progress bar on stderr (a total
    that changes, as the events of each filter become known, resizes it)."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.bar: Any = None
        self.done = 0

    def __call__(self, done: int, total: int) -> None:
        if not stderr_is_tty():
            return
        if self.bar is None:
            self.bar = click.progressbar(length=max(total, 1), label=self.label, file=sys.stderr)
            self.bar.__enter__()
        self.bar.length = max(total, 1)
        if done > self.done:
            self.bar.update(done - self.done)
            self.done = done

    def close(self) -> None:
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
            self.bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def stderr_is_tty() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def load_config(path: str | None, *tables: str) -> dict[str, Any] | None:
    """The TOML file, strict: only ``tables`` (``scenario``, ``filter``, ``topics``, ``frames``,
    ``initial``, ``sensors``, ``imu_range``) may appear; its ``[sensors.*]`` tables are checked
    here, so that a mistake names the file."""
    if path is None:
        return None
    from navreplay.core.params import load_toml
    from navreplay.sensors.specs import SPEC_KINDS, specs_from_tables

    allowed: dict[str, Any] = {"scenario": None, "topics": None, "frames": None,
                               "initial": None, "sensors": list(SPEC_KINDS), "imu_range": None}
    if "filter" in tables:
        from navreplay.filters.registry import names

        allowed["filter"] = names()
    config = load_toml(path, tables={t: allowed[t] for t in tables})
    specs_from_tables(config.get("sensors"), where=path)
    return config


def sensor_config(path: str | None, config: dict[str, Any] | None) -> Any:
    """The ``[sensors.*]`` tables of the config file as sensor specifications (or None)."""
    if not config or not config.get("sensors"):
        return None
    from navreplay.sensors.specs import specs_from_tables

    return specs_from_tables(config["sensors"], where=Path(path).name if path else "")


def viz_options(save: str | None, spawn: bool, connect: str | None, serve: bool,
                 no_viz: bool, bind: str | None = None, web_port: int | None = None,
                 grpc_port: int | None = None, full_rate: bool = False) -> Any:
    import dataclasses


    if full_rate and no_viz:
        raise click.UsageError("--full-rate and --no-viz exclude each other")
    options = _viz_target(save, spawn, connect, serve, no_viz, bind, web_port, grpc_port)
    return dataclasses.replace(options, full_rate=full_rate) if full_rate else options


def _viz_target(save: str | None, spawn: bool, connect: str | None, serve: bool,
                no_viz: bool, bind: str | None, web_port: int | None,
                grpc_port: int | None) -> Any:
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


def viz_flags(fn: Callable[..., Any]) -> Callable[..., Any]:
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
        click.option("--full-rate", "full_rate", is_flag=True,
                     help="Draw every estimate in the Rerun view (default: each series as "
                          "its smallest and largest value every 2 s, every peak kept, about "
                          "5x smaller .rrd; scores always use every estimate)."),
    ]
    for opt in reversed(opts):
        fn = opt(fn)
    return fn


PARAM_HELP = ("Parameter as key=value (repeatable); sensors.KIND.FIELD=VALUE sets a sensor "
               "specification, e.g. sensors.imu.grade=mems or "
               "sensors.imu.gyro_arw='0.2 deg/sqrt(h)'.")


FORCE_HELP = "Overwrite existing output files (never an input of the command)."


def check_command_outputs(force: bool, inputs: Sequence[str | Path | None], *items: Any) -> None:
    """Refuse, before any work, outputs that would lose a file or fail late, and lock them
    against other commands (:func:`navreplay.io.outputs.check_outputs`); ``items`` are Outputs or
    None. A rosbag2 input (its folder, metadata.yaml or a data file) protects its folder."""
    from navreplay.io.outputs import check_outputs
    from navreplay.io.rosbag import bag_folder

    paths = [Path(p) for p in inputs if p is not None]
    folders = [bag_folder(p) for p in paths if p.exists()]
    check_outputs(items, paths + [f for f in folders if f is not None], force=force, lock=True)


def output_of(path: str | Path | None, option: str, **kw: Any) -> Any:
    """An :class:`navreplay.io.outputs.Output`, or None without a path."""
    from navreplay.io.outputs import Output

    return None if path is None else Output(Path(path), option, **kw)


def export_output(path: str | None, specs: Sequence[Any], smooth: bool = False,
                  onboard: Sequence[str] = ()) -> Any:
    """The ``--export DIR`` output, with the names of the files it writes for these filters
    (and their smoothed runs with ``smooth``, and the rows of the recorded solutions
    ``onboard``)."""
    from navreplay.jobs.results import export_names
    from navreplay.jobs.smooth import output_labels
    from navreplay.logs.onboard import onboard_label

    labels = [*output_labels(specs, smooth), *(onboard_label(s) for s in onboard)]
    return output_of(path, "--export", directory=True, writes=export_names(labels))


def viz_output(save: str | None, no_viz: bool, live: bool) -> Any:
    """The .rrd output: --save, or the default directory (its files are regenerated)."""
    if save is not None:
        return output_of(save, "--save")
    if no_viz or live:
        return None
    from navreplay.jobs import DEFAULT_OUT

    return output_of(DEFAULT_OUT, "--save (default)", directory=True, writes=("*.rrd",))


def result_flags(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--export DIR and --report FILE.html (navreplay.jobs.results)."""
    fn = click.option("--report", "report", type=click.Path(dir_okay=False),
                      metavar="OUT.html", help="Write a self-contained HTML report.")(fn)
    return click.option("--export", "export", type=click.Path(file_okay=False), metavar="DIR",
                        help="Write CSV, TUM and Odometry MCAP (run) or ensemble CSV "
                             "(several recordings, montecarlo) into DIR.")(fn)


max_imu_gap_option = click.option(
    "--max-imu-gap", type=float, metavar="S",
    help="Longest IMU gap [s] a filter bridges; a longer one, or any gap for a filter that "
         "cannot bridge, stops the run (default: 6 s).")

smooth_option = click.option(
    "--smooth", is_flag=True,
    help="Also smooth every filter that can be (fixed-interval RTS smoother, "
         "docs/smoothing.md): its result LABEL/rts is scored, shown, exported and reported "
         "as a filter's (per run, and its ensemble statistics).")


def check_executor(ctx: click.Context, param: click.Parameter, value: str) -> str:
    if value in ("process", "dask"):
        return value
    from navreplay.campaign.dask_executor import is_address

    if is_address(value):
        return value
    raise click.BadParameter(f"{value!r}: use process, dask or dask://HOST:PORT")


def log_flags(fn: Callable[..., Any]) -> Callable[..., Any]:
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
        click.option("--start", "start", metavar="T",
                     help="Read from this time on: s from the recording start, UNIX s, or a "
                          "UTC time (2025-06-15T14:02:00Z); the filters start there."),
        click.option("--end", "end", metavar="T", help="Read up to this time (as --start)."),
        click.option("--imu-range", "imu_range", metavar="gyro=DEG_PER_S,accel=G",
                     help="The IMU's measurement range per axis (datasheet); a sample beyond "
                          "it stops the run [default: gyro=20000,accel=200; or an [imu_range] "
                          "table]."),
    ]
    for opt in reversed(opts):
        fn = opt(fn)
    return fn


def param_lines(rows: Sequence[tuple[str, str, Any, str]],
                 marked: Collection[str] = ()) -> list[str]:
    if not rows:
        return ["(no parameters)"]
    width = max(len(r[0]) for r in rows) + (1 if marked else 0)
    out = []
    for name, tp, default, doc in rows:
        shown = f"{name}*" if name in marked else name
        out.append(f"{shown:<{width}}  {tp} = {show_value(default)}  {doc}".rstrip())
    return out


def show_value(value: Any) -> str:
    """A default value as a user would type it after ``-p key=``."""
    if hasattr(value, "value"):  # enum
        return str(value.value)
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, tuple | list):
        return ",".join(show_value(v) for v in value)
    return str(value)


def command_line() -> str:
    """The command as typed (``navreplay ARGS``, shell-quoted), for reports."""
    import shlex

    return shlex.join(["navreplay", *click.get_current_context().meta.get("argv", [])])


def is_file(path: str | None) -> bool:
    return path is not None and Path(path).is_file()


def looks_like_recording(arg: str) -> bool:
    return arg.endswith((".mcap", ".db3")) or Path(arg).is_file() or Path(arg).is_dir()


def finish(report: Any) -> None:
    click.echo(report.format())
    sink = getattr(report, "sink", None)
    if sink is not None:  # --serve: keep the server up
        sink.wait()
        sink.close()


def checks_failed(count: int) -> None:
    raise click.ClickException(f"{count} acceptance check(s) failed (--no-strict: exit 0 anyway)")
