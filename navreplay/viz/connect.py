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
from typing import Any

import rerun as rr

from navreplay.io.outputs import temporary_path
from navreplay.viz import targets
from navreplay.viz.ranges import DRAWN_RATE_HZ
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
    url_host,
)


def _new_stream(recording_id: str | None, recording_name: str | None) -> rr.RecordingStream:
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id or str(uuid.uuid4()))
    if recording_name:
        rec.send_recording_name(recording_name)
    return rec


_SERVERS: dict[tuple[str, int], Any] = {}
"""Server processes started by this process, by (bind address, gRPC port): they keep the data
for browsers after the sinks are closed, and stop when this process ends."""


def open_sink(
    target: Target | str | os.PathLike[str],
    *,
    recording_name: str | None = None,
    recording_id: str | None = None,
    drawn_rate: float | None = DRAWN_RATE_HZ,
) -> Sink:
    """Open a Rerun sink; checks that the viewer is reachable before anything is logged.

    Parameters
    ----------
    target : Save, Spawn, Connect, Serve, or a path (same as ``Save(path)``)
    recording_name : str, optional
        Name shown in the viewer (e.g. the recording file's name).
    recording_id : str, optional
        Rerun recording id; a fresh UUID by default, so every sink is its own recording.
    drawn_rate : float or None
        Bins per second of the min/max envelope a series is drawn with
        (:func:`navreplay.viz.ranges.envelope_rows`: every peak kept, the .rrd bounded per
        hour); None draws every row. Scores always use every row.

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
    sink = _open(target, recording_name, recording_id)
    sink.drawn_rate = drawn_rate
    return sink


def _open(target: Target | str | os.PathLike[str], recording_name: str | None,
          recording_id: str | None) -> Sink:
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


SERVER_START_S = 20.0
"""How long a started server may take to listen on its ports [s]."""


def _open_serve(target: Serve, name: str | None, rid: str | None) -> Sink:
    host = target.host
    url = f"rerun+http://{url_host(host)}:{target.grpc_port}/proxy"
    if port_error(host, target.grpc_port, 0.5) is not None:
        _start_server(target)  # else: the server of an earlier sink (or another process)
    rec = _new_stream(rid, name)
    rec.connect_grpc(url)
    public = url_host(target.public_host)
    grpc = f"rerun+http://{public}:{target.grpc_port}/proxy"
    web = f"http://{public}:{target.web_port}/?url={urllib.parse.quote(grpc, safe='')}"
    if target.open_browser:
        import webbrowser

        webbrowser.open(web)
    return Sink(rec, target, url=url, web_url=web)


def _start_server(target: Serve) -> None:
    """Start ``rerun --serve-web`` listening on ``target.bind`` only (rerun-sdk 0.41's
    ``serve_web_viewer`` takes no address and listens on every interface) and wait until both
    its ports answer; it ends with this process (:mod:`navreplay.io.lifecycle`)."""
    import subprocess
    import tempfile
    import time

    from navreplay.io import lifecycle

    exe = targets.find_server()
    if exe is None:
        raise VizUnavailableError("no `rerun` executable to serve the web viewer "
                                  "(pip install rerun-sdk); use --save")
    for port in (target.web_port, target.grpc_port):
        if not port_free(port, target.bind):
            raise VizUnavailableError(f"cannot serve the web viewer: port {port} is in use on "
                                      f"{target.bind}")
    log = tempfile.TemporaryFile()
    proc = subprocess.Popen(
        [exe, "--serve-web", "--bind", target.bind, "--port", str(target.grpc_port),
         "--web-viewer-port", str(target.web_port),
         "--server-memory-limit", target.server_memory_limit],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log,
        preexec_fn=lifecycle.child_init, env={**os.environ, "RUST_LOG": "warn"})
    lifecycle.adopt(proc)
    end = time.monotonic() + SERVER_START_S
    while any(port_error(target.host, p, 0.2) is not None
              for p in (target.grpc_port, target.web_port)):
        if proc.poll() is not None or time.monotonic() > end:
            lifecycle.release_child(proc)
            log.seek(0)
            lines = [ln for ln in log.read().decode(errors="replace").splitlines() if ln.strip()]
            why = lines[-1].strip() if lines else (
                f"exit status {proc.returncode}" if proc.returncode is not None
                else f"not listening after {SERVER_START_S:g} s")
            raise VizUnavailableError(f"cannot serve the web viewer on {target.bind} ({exe}): "
                                      f"{why}")
        time.sleep(0.1)
    _SERVERS[(target.bind, target.grpc_port)] = proc


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
