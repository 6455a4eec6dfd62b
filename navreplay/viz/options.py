"""Where a job's Rerun output goes (file, local viewer, remote viewer, served web viewer), and
opening a viewer on a saved file.

Importing this module does not import rerun: the command line builds :class:`VizOptions` for
every job, and only a job that logs something opens a sink.
"""

from __future__ import annotations

import dataclasses
import enum
from pathlib import Path
from typing import Any


class VizMode(enum.StrEnum):
    """Where the Rerun output goes."""

    SAVE = "save"
    SPAWN = "spawn"
    CONNECT = "connect"
    SERVE = "serve"
    NONE = "none"


DRAWN_WINDOW_MESSAGES = 60_000
"""Messages of a stream per window of the log when a run draws the view (a run without one
reads :data:`navreplay.io.source.WINDOW_MESSAGES`): part of the view's work is per window (its
sensor streams and the truth are drawn window by window), and 60 000 (10 minutes of 100 Hz)
cost it a seventh less than 20 000 on an hour, for a peak set by Rerun's own buffers anyway."""


@dataclasses.dataclass(frozen=True)
class VizOptions:
    """Rerun output of a job.

    Attributes
    ----------
    mode : VizMode
    path : Path, optional
        The .rrd file (SAVE); default chosen by the job (under ``out/``).
    url : str, optional
        Viewer address (CONNECT).
    bind : str
        The address a served viewer listens on (SERVE): the loopback interface unless told
        otherwise (:class:`navreplay.viz.targets.Serve`).
    web_port, grpc_port : int
        The served viewer's ports (SERVE).
    full_rate : bool
        Draw every row of every series (default: each series drawn as its min/max envelope,
        :data:`navreplay.viz.ranges.DRAWN_RATE_HZ` bins per second; scores use every row).
    """

    mode: VizMode = VizMode.SAVE
    path: Path | None = None
    url: str | None = None
    bind: str = "127.0.0.1"
    web_port: int = 9090
    grpc_port: int = 9876
    full_rate: bool = False

    @property
    def draws(self) -> bool:
        """The run draws a view (into a file or a viewer)."""
        return self.mode is not VizMode.NONE

    def target(self, default: Path) -> Any:
        """The :mod:`navreplay.viz` target, or None for no output."""
        from navreplay import viz

        if self.mode is VizMode.NONE:
            return None
        if self.mode is VizMode.SAVE:
            return viz.Save(self.path or default)
        if self.mode is VizMode.SPAWN:
            return viz.Spawn()
        if self.mode is VizMode.CONNECT:
            return viz.Connect(self.url) if self.url else viz.Connect()
        return viz.Serve(grpc_port=self.grpc_port, web_port=self.web_port, bind=self.bind)

    @property
    def live(self) -> bool:
        return self.mode in (VizMode.SPAWN, VizMode.CONNECT, VizMode.SERVE)


def open_output(viz_options: VizOptions, default: Path, name: str) -> Any:
    """Open the Rerun sink (checking first that a viewer is reachable), or None."""
    target = viz_options.target(default)
    if target is None:
        return None
    from navreplay.viz import open_sink
    from navreplay.viz.ranges import DRAWN_RATE_HZ

    return open_sink(target, recording_name=name,
                     drawn_rate=None if viz_options.full_rate else DRAWN_RATE_HZ)


def close_output(sink: Any, viz_options: VizOptions) -> str:
    """Finish the sink (a served one stays up) and say where the view is."""
    if sink is None:
        return ""
    if viz_options.mode is VizMode.SERVE:
        sink.send_blueprint()
        sink.flush()
        return f"Rerun web viewer: {sink.web_url} (serving until Ctrl-C)"
    where = sink.close()
    if sink.path is not None:
        return f"Rerun view saved to {where}; open it with: rerun {where}"
    return f"Rerun view sent to the viewer at {where}"


def open_viewer(rrd: Path, *, required: bool) -> str:
    """Open the Rerun viewer on ``rrd`` when a display is available; say what happened."""
    import subprocess

    from navreplay.viz.targets import display_problem, find_viewer

    exe = find_viewer()
    problem = "no `rerun` viewer executable" if exe is None else display_problem()
    if problem is not None:
        if required:
            from navreplay.viz import VizUnavailableError

            raise VizUnavailableError(f"cannot open the Rerun viewer: {problem}")
        return f"(No viewer opened: {problem}. Open the view elsewhere with `rerun {rrd}`.)"
    assert exe is not None  # else a problem above
    subprocess.Popen([exe, str(rrd)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                     start_new_session=True)
    return f"Opened the Rerun viewer on {rrd}."
