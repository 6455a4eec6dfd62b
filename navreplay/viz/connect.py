"""Opening a Rerun sink on a target: an .rrd file, a local viewer, a remote viewer or a served
web viewer.

Targets
-------
:class:`Save` (the default) writes an .rrd atomically: into a temporary file beside the target,
renamed on :meth:`Sink.close`; a failed or aborted run leaves the target untouched.
:class:`Spawn`, :class:`Connect` and :class:`Serve` check first that a viewer can be reached
(a TCP connect with a short timeout; for Spawn, a viewer executable and a display) and raise
:class:`VizUnavailableError` with a one-line reason, instead of Rerun's silent loss of all data
after ~12 s.

"""

from __future__ import annotations

import os
import urllib.parse
import uuid
from pathlib import Path

import rerun as rr

from navreplay.outputs import temporary_path
from navreplay.viz import targets
from navreplay.viz.sink import APPLICATION_ID, Sink
from navreplay.viz.targets import (
    Connect,
    Save,
    Serve,
    Spawn,
    Target,
    VizUnavailableError,
    display_problem,
    parse_url,
    port_error,
    port_free,
)


def _new_stream(recording_id: str | None, recording_name: str | None) -> rr.RecordingStream:
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id or str(uuid.uuid4()))
    if recording_name:
        rec.send_recording_name(recording_name)
    return rec


_WEB_VIEWERS: set[int] = set()
"""Web-viewer ports served by this process."""
_SERVERS: dict[int, rr.RecordingStream] = {}
"""gRPC servers of this process by port: the serving stream stays alive (not disconnected) so
that browsers can still connect after its sink is closed; they stop when the process exits."""


def open_sink(
    target: Target | str | os.PathLike[str],
    *,
    recording_name: str | None = None,
    recording_id: str | None = None,
) -> Sink:
    """Open a Rerun sink; checks that the viewer is reachable before anything is logged.

    Parameters
    ----------
    target : Save, Spawn, Connect, Serve, or a path (same as ``Save(path)``)
    recording_name : str, optional
        Name shown in the viewer (e.g. the recording file's name).
    recording_id : str, optional
        Rerun recording id; a fresh UUID by default, so every sink is its own recording.

    Returns
    -------
    Sink

    Raises
    ------
    VizUnavailableError
        Spawn: no viewer executable, no display, or the viewer did not start listening;
        Connect: nothing answers at the URL; Serve: the web port is taken.
    FileExistsError
        Save with ``overwrite=False`` and the file exists.
    """
    if isinstance(target, str | os.PathLike):
        target = Save(target)
    if isinstance(target, Save):
        return _open_save(target, recording_name, recording_id)
    if isinstance(target, Connect):
        url, host, port = parse_url(target.url)
        err = port_error(host, port, target.timeout)
        if err is not None:
            raise VizUnavailableError(
                f"no Rerun viewer reachable at {url} ({err}); start one with `rerun` or use --save"
            )
        rec = _new_stream(recording_id, recording_name)
        rec.connect_grpc(url)
        return Sink(rec, target, url=url)
    if isinstance(target, Spawn):
        return _open_spawn(target, recording_name, recording_id)
    if isinstance(target, Serve):
        return _open_serve(target, recording_name, recording_id)
    raise TypeError(f"unknown Rerun target {target!r}")


def _open_spawn(target: Spawn, name: str | None, rid: str | None) -> Sink:
    url, _, _ = parse_url(target.port)
    if port_error("127.0.0.1", target.port, 0.5) is None:  # a viewer is already up
        rec = _new_stream(rid, name)
        rec.connect_grpc(url)
        return Sink(rec, target, url=url)
    exe = targets.find_viewer()
    if exe is None:
        raise VizUnavailableError(
            "no `rerun` viewer executable on PATH (pip install rerun-sdk); use --save"
        )
    problem = display_problem() if target.check_display else None
    if problem is not None:
        raise VizUnavailableError(f"cannot spawn a Rerun viewer: {problem}; use --save or --serve")
    rec = _new_stream(rid, name)
    try:
        rr.spawn(
            port=target.port, connect=False, memory_limit=target.memory_limit,
            executable_path=exe, recording=rec,
        )  # fmt: skip
    except RuntimeError as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise VizUnavailableError(f"cannot spawn a Rerun viewer ({exe}): {first}") from None
    err = port_error("127.0.0.1", target.port, 1.0)
    if err is not None:
        raise VizUnavailableError(
            f"the Rerun viewer ({exe}) did not start listening on port {target.port} ({err})"
        )
    rec.connect_grpc(url)
    return Sink(rec, target, url=url)


def _open_serve(target: Serve, name: str | None, rid: str | None) -> Sink:
    url, _, _ = parse_url(target.grpc_port)
    start_web = target.web_port not in _WEB_VIEWERS
    if start_web and not port_free(target.web_port):
        raise VizUnavailableError(f"cannot serve the web viewer: port {target.web_port} is in use")
    rec = _new_stream(rid, name)
    owner = False
    if port_error("127.0.0.1", target.grpc_port, 0.5) is None:
        rec.connect_grpc(url)  # the server of an earlier sink (or of another process)
    else:
        url = rec.serve_grpc(
            grpc_port=target.grpc_port, server_memory_limit=target.server_memory_limit
        )
        _SERVERS[target.grpc_port] = rec
        owner = True
    if start_web:
        rr.serve_web_viewer(
            web_port=target.web_port, open_browser=target.open_browser, connect_to=url
        )
        _WEB_VIEWERS.add(target.web_port)
    web = f"http://localhost:{target.web_port}/?url={urllib.parse.quote(url, safe='')}"
    return Sink(rec, target, url=url, web_url=web, keep_alive=owner)


def _open_save(target: Save, name: str | None, rid: str | None) -> Sink:
    path = Path(target.path)
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a directory, not an .rrd file")
    if path.exists() and not target.overwrite:
        raise FileExistsError(f"{path} exists (overwrite it explicitly)")
    tmp = temporary_path(path)
    rec = _new_stream(rid, name)
    try:
        rec.save(tmp)
    except BaseException:
        rec.disconnect()
        tmp.unlink(missing_ok=True)
        raise
    return Sink(rec, target, path=path, tmp=tmp)
