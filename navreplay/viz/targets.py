"""Where Rerun output goes, and whether it can get there.

:class:`Save` writes an .rrd file (headless; atomic in :func:`navreplay.viz.open_sink`);
:class:`Spawn` starts a local viewer, :class:`Connect` streams to a running one and
:class:`Serve` serves gRPC and the web viewer from this process. The checks here run before
anything is logged: Rerun itself would silently drop all data after ~12 s when no viewer
answers.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import os
import shutil
import socket
import struct
import sys
import urllib.parse
from pathlib import Path

DEFAULT_PORT = 9876
DEFAULT_URL = f"rerun+http://127.0.0.1:{DEFAULT_PORT}/proxy"


class VizUnavailableError(RuntimeError):
    """The requested viewer cannot be reached (nothing was logged)."""


@dataclasses.dataclass(frozen=True)
class Save:
    """Write an .rrd file (headless). Atomic: temporary file beside it, renamed on close.

    Attributes
    ----------
    path : str or PathLike
    overwrite : bool
        Replace an existing file (on success only); False raises ``FileExistsError`` at open.
    """

    path: str | os.PathLike[str]
    overwrite: bool = True


@dataclasses.dataclass(frozen=True)
class Spawn:
    """Start a local Rerun viewer (or use the one already listening on ``port``).

    Attributes
    ----------
    port : int
        gRPC port of the viewer.
    memory_limit : str
        Viewer memory limit, e.g. ``"75%"`` or ``"8GB"``; the oldest data is dropped beyond it.
    check_display : bool
        Refuse to start without a display (X11 socket or Wayland socket on Linux).
    """

    port: int = DEFAULT_PORT
    memory_limit: str = "75%"
    check_display: bool = True


@dataclasses.dataclass(frozen=True)
class Connect:
    """Stream to a running viewer.

    Attributes
    ----------
    url : str
        ``rerun+http://host:port/proxy`` (also ``rerun://``, ``rerun+https://``, ``host:port``
        or a bare port).
    timeout : float
        Reachability check timeout [s].
    """

    url: str = DEFAULT_URL
    timeout: float = 1.0


LOOPBACK = "127.0.0.1"
"""Where :class:`Serve` listens unless told otherwise: this machine only."""


@dataclasses.dataclass(frozen=True)
class Serve:
    """Serve gRPC and the web viewer for a browser, on ``bind`` only.

    A ``rerun --serve-web --bind ADDR`` server process (rerun's own server, whose viewer and
    gRPC ports both listen on ``bind``) is started beside this one and fed by it; it lives as
    long as this process: call :meth:`Sink.wait` to keep it up. A second sink with the same
    ``grpc_port`` streams into the first one's server. Neither port asks who connects: with a
    ``bind`` other than the loopback interface, the viewer and the recording's data are open to
    every host that reaches this machine (:func:`exposure`).

    Attributes
    ----------
    grpc_port, web_port : int
    open_browser : bool
    server_memory_limit : str
        Data buffered for late browsers, e.g. ``"1GiB"``.
    bind : str
        The IP address both ports listen on: ``127.0.0.1`` (default, this machine only),
        ``0.0.0.0`` or ``::`` (every interface) or one interface's address.
    """

    grpc_port: int = DEFAULT_PORT
    web_port: int = 9090
    open_browser: bool = False
    server_memory_limit: str = "1GiB"
    bind: str = LOOPBACK

    def __post_init__(self) -> None:
        object.__setattr__(self, "bind", bind_address(self.bind))
        for name in ("grpc_port", "web_port"):
            port = getattr(self, name)
            if isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536:
                raise ValueError(f"{name} must be a port number 1..65535, got {port!r}")

    @property
    def host(self) -> str:
        """The host of the URLs this process connects to: the bound address, or the loopback
        one when every interface is bound."""
        ip = ipaddress.ip_address(self.bind)
        if ip.is_unspecified:
            return "::1" if ip.version == 6 else LOOPBACK
        return self.bind

    @property
    def public_host(self) -> str:
        """The host of the URL printed for a browser: the bound address, or this machine's
        name when every interface is bound (the loopback address only when that is bound)."""
        return socket.gethostname() if ipaddress.ip_address(self.bind).is_unspecified \
            else self.bind


def bind_address(text: str) -> str:
    """An IP address to listen on (``localhost`` means ``127.0.0.1``); ValueError otherwise."""
    value = str(text).strip()
    if value.lower() == "localhost":
        return LOOPBACK
    try:
        return str(ipaddress.ip_address(value.strip("[]")))
    except ValueError:
        raise ValueError(f"--bind {text!r}: not an IP address (127.0.0.1, 0.0.0.0, ::, or one "
                         "of this machine's addresses)") from None


def exposure(target: Serve) -> str | None:
    """The warning for a served viewer that hosts other than this one can reach, or None."""
    if ipaddress.ip_address(target.bind).is_loopback:
        return None
    where = ("every host that can reach this machine"
             if ipaddress.ip_address(target.bind).is_unspecified
             else f"every host that can reach {target.bind}")
    return (f"--bind {target.bind}: the web viewer (port {target.web_port}) and the "
            f"recording's data (gRPC port {target.grpc_port}) are served without "
            f"authentication to {where}")


def url_host(host: str) -> str:
    """``host`` as it goes into a URL (IPv6 addresses in brackets)."""
    return f"[{host}]" if ":" in host else host


Target = Save | Spawn | Connect | Serve


def parse_url(url: str | int) -> tuple[str, str, int]:
    """Normalise a viewer address to ``(url, host, port)``.

    Examples
    --------
    >>> parse_url("localhost:9000")
    ('rerun+http://localhost:9000/proxy', 'localhost', 9000)
    >>> parse_url(9877)[0]
    'rerun+http://127.0.0.1:9877/proxy'
    """
    text = str(url).strip()
    if text.isdigit():
        text = f"127.0.0.1:{text}"
    if "://" not in text:
        text = f"rerun+http://{text}"
    parts = urllib.parse.urlsplit(text)
    schemes = {"rerun": 443, "rerun+https": 443, "rerun+http": 80}
    if parts.scheme not in schemes:
        raise ValueError(
            f"viewer URL {url!r}: scheme must be rerun+http://, rerun+https:// or rerun://"
        )
    try:
        port = parts.port or schemes[parts.scheme]
    except ValueError:
        raise ValueError(f"viewer URL {url!r}: invalid port") from None
    host = parts.hostname or "127.0.0.1"
    netloc = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    return urllib.parse.urlunsplit((parts.scheme, netloc, "/proxy", "", "")), host, port


def port_error(host: str, port: int, timeout: float) -> str | None:
    """None if a TCP connection to host:port succeeds within ``timeout`` [s], else why not."""
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return None
    except TimeoutError:
        return f"no answer within {timeout:g} s"
    except OSError as e:
        return e.strerror or str(e)


def find_viewer() -> str | None:
    """Path of the ``rerun`` viewer executable: on PATH, else beside the Python interpreter."""
    found = shutil.which("rerun")
    if found:
        return found
    for name in ("rerun", "rerun.exe"):
        candidate = Path(sys.executable).parent / name
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return str(candidate)
    return None


def find_server() -> str | None:
    """The ``rerun`` binary itself for a server process: the one rerun-sdk ships in its
    ``rerun_cli`` package (the ``rerun`` command on PATH is a Python launcher that would leave
    the binary running when it is stopped), else :func:`find_viewer`."""
    try:
        import rerun_cli
    except ImportError:
        return find_viewer()
    folder = Path(rerun_cli.__file__).parent
    for candidate in (folder / "rerun", folder / "rerun.exe"):
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return str(candidate)
    return find_viewer()


def display_problem() -> str | None:
    """Why a native viewer window cannot open here, or None (always None off Linux/BSD)."""
    if sys.platform in ("darwin", "win32", "cygwin"):
        return None
    wayland = os.environ.get("WAYLAND_DISPLAY")
    if wayland:
        sock = Path(wayland)
        if not sock.is_absolute():
            sock = Path(os.environ.get("XDG_RUNTIME_DIR", f"/run/user/{os.getuid()}")) / wayland
        if sock.exists():
            return None
    display = os.environ.get("DISPLAY")
    if not display:
        return "no display (DISPLAY and WAYLAND_DISPLAY are unset)"
    host, _, rest = display.rpartition(":")
    number = rest.split(".")[0]
    if not number.isdigit():
        return f"cannot parse DISPLAY={display!r}"
    if host in ("", "unix"):
        if Path(f"/tmp/.X11-unix/X{number}").exists():
            return None
        return f"no X server socket for DISPLAY={display}"
    err = port_error(host, 6000 + int(number), 0.5)
    return None if err is None else f"X server for DISPLAY={display} unreachable ({err})"


def port_free(port: int, host: str = "0.0.0.0") -> bool:  # noqa: S104 - a test, not a server
    """Whether this process could listen on ``port`` at ``host`` (all interfaces by default)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


RRD_FOOTER = struct.Struct("<QQI8sI")
"""The end of a finished .rrd file (rerun 0.41): manifest offset and length [bytes], manifest
checksum, the magic ``RRF2FOOT`` and the footer version."""
RRD_FOOTER_MAGIC = b"RRF2FOOT"


def rrd_problem(path: str | os.PathLike[str]) -> str | None:
    """Why the .rrd file at ``path`` is not a finished recording, or None.

    Rerun writes an .rrd in a background thread and reports a failed write (a full disk) only
    in its own log; a file cut short lacks the footer that ends a finished one (the manifest's
    offset and length, which must end where the footer starts). The free space of the disk is
    named when it is (nearly) full.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
        with path.open("rb") as f:
            f.seek(max(size - RRD_FOOTER.size, 0))
            tail = f.read(RRD_FOOTER.size)
    except OSError as e:
        return f"cannot be read back ({e.strerror or e})"
    why = None
    if size < RRD_FOOTER.size:
        why = f"only {size} bytes"
    else:
        offset, length, _, magic, _ = RRD_FOOTER.unpack(tail)
        if magic != RRD_FOOTER_MAGIC:
            why = "it ends without the footer of a finished recording"
        elif offset + length != size - RRD_FOOTER.size:
            why = "its footer does not match its length"
    if why is None:
        return None
    try:
        free = shutil.disk_usage(path.parent).free
    except OSError:
        free = None
    if free is not None and free < (1 << 20):
        why += f"; the disk is full ({free} bytes free)"
    return f"incomplete: {why}"
