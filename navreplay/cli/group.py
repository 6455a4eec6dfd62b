"""The ``navreplay`` group and its entry point: expected errors as one line on stderr (status 1),
usage errors with 2, ``--debug`` for the traceback, warnings as ``warning:`` lines, and a
command stopped by a signal ending at once."""

from __future__ import annotations

import contextlib
import gc
import os
import sys
import traceback
import warnings
from collections.abc import Sequence
from typing import Any

import click

from navreplay import __version__

EXPECTED_ERRORS: tuple[type[BaseException], ...] = ()
"""Error types reported as one line (filled lazily: importing them loads the package)."""


def _expected_errors() -> tuple[type[BaseException], ...]:
    global EXPECTED_ERRORS
    if not EXPECTED_ERRORS:
        from navreplay.campaign.ensemble import RunFailedError
        from navreplay.core.params import ParamError
        from navreplay.filters.kalman import FilterDivergedError
        from navreplay.filters.registry import FilterLoadError
        from navreplay.io import RecordingError
        from navreplay.io.outputs import OutputError
        from navreplay.jobs.compare import SummaryError
        from navreplay.replay.errors import ReplayError
        from navreplay.viz import VizUnavailableError

        EXPECTED_ERRORS = (
            RecordingError, OutputError, ParamError, FilterLoadError, FilterDivergedError,
            ReplayError, RunFailedError, VizUnavailableError, SummaryError, KeyError,
            FileExistsError, FileNotFoundError, IsADirectoryError, PermissionError,
        )
    return EXPECTED_ERRORS


def _expected(e: BaseException) -> bool:
    """One of the project's expected errors, or a device error (a full disk)."""
    from navreplay.io.outputs import DISK_ERRORS

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
    """Turns the project's expected errors into one line and shows warnings as one line; keeps
    the arguments as typed (``ctx.meta["argv"]``, the command line of reports)."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        ctx.meta["argv"] = list(args)
        return super().parse_args(ctx, args)

    def invoke(self, ctx: click.Context) -> Any:
        from navreplay.io.lifecycle import Terminated, handle_signals, interrupted_by
        from navreplay.io.outputs import release_locks

        debug = bool(ctx.params.get("debug"))
        with (warnings.catch_warnings(), handle_signals(),
              contextlib.ExitStack() as stack):
            stack.callback(release_locks)
            warnings.showwarning = _show_warning
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


_STOPPED = False
"""A signal stopped the command (its temporaries are gone, its workers stopped)."""


def main(argv: Sequence[str] | None = None) -> None:
    """Console-script entry point. A command stopped by a signal ends at once: the
    interpreter's teardown (freeing a loaded process, joining pools) could take longer than
    the second a stop may take, and nothing is left to save. Warnings are ``warning:`` lines
    for the whole process: one given after the command (a reader collected at exit reporting
    its warnings) is not a raw ``sys:1: RecordingWarning`` line."""
    warnings.showwarning = _show_warning
    try:
        cli.main(args=list(argv) if argv is not None else None, prog_name="navreplay")
    except SystemExit as e:
        if not _STOPPED:
            raise
        from navreplay.io import lifecycle

        lifecycle.release_children()  # a served viewer
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(e.code if isinstance(e.code, int) else 1)

