"""`--serve` listens on the loopback interface only, unless `--bind` says otherwise (and then
it says once that the viewer and its data are unauthenticated); the printed URL works. Checked
on the listening sockets of a real process (/proc/net/tcp)."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
import time
import urllib.parse
import urllib.request
from pathlib import Path

import pytest
from click.testing import CliRunner
from commands import NAVREPLAY

from navreplay.cli import cli
from navreplay.io import write_recording
from navreplay.sim.scenario import simulate
from navreplay.viz.targets import Serve, bind_address, exposure

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/net/tcp")


@pytest.fixture(scope="module")
def drive(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("serve") / "drive.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 10.0}, seed=3))
    return path


def _free_ports(n: int) -> list[int]:
    socks = []
    for _ in range(n):
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        socks.append(s)
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def listening(ports: set[int]) -> dict[int, set[str]]:
    """Port -> the addresses sockets listen on, from /proc/net/tcp and tcp6."""
    out: dict[int, set[str]] = {}
    for table, width in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            local, state = row.split()[1], row.split()[3]
            if state != "0A":  # LISTEN
                continue
            addr, port = local.split(":")
            port = int(port, 16)
            if port in ports:
                out.setdefault(port, set()).add(_address(addr, width))
    return out


def _address(hexaddr: str, width: int) -> str:
    raw = bytes.fromhex(hexaddr)
    if width == 8:
        return socket.inet_ntop(socket.AF_INET, raw[::-1])
    words = b"".join(raw[i:i + 4][::-1] for i in range(0, 16, 4))
    return socket.inet_ntop(socket.AF_INET6, words)


def _serve(drive: Path, tmp_path: Path, *args: str):
    web, grpc = _free_ports(2)
    proc = subprocess.Popen(NAVREPLAY + ["run", "ins", str(drive), "--serve", "--web-port",
                                         str(web), "--grpc-port", str(grpc), *args],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    url = None
    end = time.monotonic() + 120
    while url is None and time.monotonic() < end:
        line = proc.stdout.readline()
        if not line:
            break
        m = re.search(r"Rerun web viewer: (\S+)", line)
        url = m.group(1) if m else None
    if url is None:
        proc.kill()
        pytest.fail(f"no URL printed: {proc.communicate()}")
    return proc, url, web, grpc


def _stop(proc: subprocess.Popen) -> str:
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    return err


def _get(url: str) -> int:
    with urllib.request.urlopen(url, timeout=10) as r:
        return r.status


def test_serve_listens_on_loopback_only_and_its_url_works(drive, tmp_path):
    proc, url, web, grpc = _serve(drive, tmp_path)
    try:
        socks = listening({web, grpc})
        assert socks == {web: {"127.0.0.1"}, grpc: {"127.0.0.1"}}, socks
        parts = urllib.parse.urlsplit(url)
        assert (parts.hostname, parts.port) == ("127.0.0.1", web)
        data = urllib.parse.parse_qs(parts.query)["url"][0]
        assert data == f"rerun+http://127.0.0.1:{grpc}/proxy"
        assert _get(url) == 200  # the printed URL is the one that works
        with socket.create_connection(("127.0.0.1", grpc), timeout=5):
            pass
    finally:
        err = _stop(proc)
    assert "unauthenticated" not in err and "without authentication" not in err, err
    assert not listening({web, grpc}), "the served viewer ends with the command"


def test_bind_opens_it_to_the_network_and_says_so_once(drive, tmp_path):
    proc, url, web, grpc = _serve(drive, tmp_path, "--bind", "0.0.0.0")
    try:
        socks = listening({web, grpc})
        assert socks == {web: {"0.0.0.0"}, grpc: {"0.0.0.0"}}, socks
        parts = urllib.parse.urlsplit(url)
        assert parts.hostname == socket.gethostname() and parts.port == web
        try:
            socket.getaddrinfo(parts.hostname, web)
            assert _get(url) == 200
        except socket.gaierror:  # a machine whose name does not resolve here
            assert _get(url.replace(parts.hostname, "127.0.0.1", 1)) == 200
    finally:
        err = _stop(proc)
    warnings = [ln for ln in err.splitlines() if "without authentication" in ln]
    assert len(warnings) == 1 and warnings[0].startswith("warning: --bind 0.0.0.0"), err
    assert not listening({web, grpc})


def test_serve_options_are_checked():
    runner = CliRunner()
    res = runner.invoke(cli, ["run", "ins", "x.mcap", "--bind", "0.0.0.0"])
    assert res.exit_code == 2 and "only go with --serve" in res.output
    res = runner.invoke(cli, ["run", "ins", "x.mcap", "--serve", "--bind", "example.com"])
    assert res.exit_code == 2 and "not an IP address" in res.output
    assert bind_address("localhost") == "127.0.0.1" and bind_address("[::1]") == "::1"
    assert exposure(Serve()) is None and exposure(Serve(bind="::1")) is None
    assert "every host" in exposure(Serve(bind="::"))
    assert Serve(bind="0.0.0.0").host == "127.0.0.1" and Serve(bind="::").host == "::1"
