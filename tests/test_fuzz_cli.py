"""Fuzzing `info` and `run` with damaged recordings, compressed (CRC-protected chunks) and
uncompressed without CRCs: never a traceback, never a hang, never a partial output, and never
exit 0 with a result other than the intact file's unless the output says SALVAGED."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_robustness import uncompressed_copy

from navreplay.cli import cli
from navreplay.io import write_recording
from navreplay.sim.scenario import simulate

TIMEOUT_S = 20


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    compressed = d / "z.mcap"
    write_recording(compressed, simulate("vehicle-drive", {"duration": 8.0}, seed=2))
    plain = d / "u.mcap"
    uncompressed_copy(compressed, plain, chunk_size=1 << 13)
    base = {}
    for name, path in (("z", compressed), ("u", plain)):
        out = d / f"{name}.json"
        res = invoke("run", "gps-ins", path, "--no-viz", "--summary", out)
        assert res.exit_code == 0, res.output
        base[name] = json.loads(out.read_text())["filters"]
    return {"z": compressed.read_bytes(), "u": plain.read_bytes(), "base": base, "dir": d}


def _mutate(data: bytes, kind: str, frac: float, flips: list[tuple[float, int]],
            tail: bytes) -> bytes:
    n = len(data)
    if kind == "truncate":
        return data[: int(frac * n)]
    if kind == "append":
        return data + tail
    out = bytearray(data)
    for where, bit in flips:
        out[min(int(where * n), n - 1)] ^= 1 << bit
    return bytes(out)


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang


@settings(max_examples=200, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(
    which=st.sampled_from(["z", "u"]),
    kind=st.sampled_from(["truncate", "flip", "append"]),
    frac=st.floats(0.0, 1.0),
    flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 7)), min_size=1, max_size=4),
    tail=st.binary(min_size=1, max_size=64),
)
def test_damaged_recordings(corpus, which, kind, frac, flips, tail):
    if which == "u" and kind == "flip":
        kind = "truncate"  # without CRCs a flipped sample value cannot be told from a real one
    d: Path = corpus["dir"]
    path = d / "case.mcap"
    path.write_bytes(_mutate(corpus[which], kind, frac, flips, tail))
    summary = d / "case.json"
    summary.unlink(missing_ok=True)
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(TIMEOUT_S)
    try:
        info = invoke("info", path)
        run = invoke("run", "gps-ins", path, "--no-viz", "--summary", summary)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    for res in (info, run):
        assert res.exit_code in (0, 1), (res.exit_code, res.output)
        assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
        assert "Traceback" not in res.output
        if res.exit_code:
            assert res.stderr.strip().splitlines()[-1].startswith("Error: "), res.stderr
    if info.exit_code == 0:
        assert "DAMAGED" not in info.output
    assert not list(d.glob(".*.part"))
    if run.exit_code:
        assert not summary.exists()  # no partial output
        return
    got = json.loads(summary.read_text())
    if got["salvaged"]:
        assert "SALVAGED" in run.output
        if got["coverage"] is not None and got["coverage"] >= 1.0:
            # the damage took no message the replay used (e.g. only the summary section):
            # the result must then be the intact file's
            assert got["filters"] == corpus["base"][which], "full coverage, another result"
    else:
        assert got["filters"] == corpus["base"][which], "exit 0 with a different result"
