"""The command line as the tests drive it: in this process (``invoke``) or as a fresh
interpreter (``NAVREPLAY``); its one-line errors, leftover temporaries, and a recording with an
IMU gap cut into it."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from click.testing import CliRunner

from navreplay.cli import cli
from navreplay.core.streams import Recording, Stream, StreamKind

NAVREPLAY = [sys.executable, "-m", "navreplay"]


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_line_error(res, *fragments: str, code: int = 1) -> str:
    """Exit status 1, one 'Error: ' line (after any 'warning: ' lines), no traceback."""
    assert res.exit_code == code, f"exit {res.exit_code}\n{res.output}"
    lines = res.stderr.strip().splitlines()
    assert all(line.startswith("warning: ") for line in lines[:-1]), lines
    err = lines[-1]
    assert err.startswith("Error: "), err
    assert "Traceback" not in res.output
    for f in fragments:
        assert f in err, (f, err)
    return err


def parts(directory: Path) -> list[Path]:
    return sorted(directory.glob(".*.part"))


def cut_imu(rec: Recording, t_from: float, length: float) -> Recording:
    """The recording without its IMU samples in (t_from, t_from + length] [s]."""
    imu = rec[StreamKind.IMU]
    t = (imu.t_ns - rec.t0_ns) * 1e-9
    keep = ~((t > t_from) & (t <= t_from + length))
    streams = dict(rec.streams)
    streams[StreamKind.IMU] = Stream(imu.kind, imu.t_ns[keep],
                                     {k: v[keep] for k, v in imu.columns.items()}, imu.frame_id)
    return Recording(streams, rec.metadata, rec.t0_ns)


def wait_for(pred, timeout: float) -> bool:
    """Whether ``pred()`` came true within ``timeout`` seconds (polled every 50 ms)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.05)
    return False
