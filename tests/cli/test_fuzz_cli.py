"""Fuzzing `info` and `run` with damaged recordings, compressed (CRC-protected chunks) and
uncompressed without CRCs, and with damaged rosbag2 folders (metadata.yaml flipped, cut, edited
or gone; data files cut, extended or flipped): never a traceback, never a hang, never a partial
output, and never exit 0 with a result other than the intact file's unless the output says
SALVAGED (or a flipped byte of a sample changed it where no checksum can tell)."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap_edits import uncompressed_copy

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


# --------------------------------------------------------------------------------------------
# rosbag2 folders: damaged metadata.yaml, data files cut, emptied or flipped

BAG_RUN = ("--init", "reference", "--reference", "/ground_truth/odom", "--no-viz")


@pytest.fixture(scope="module")
def bag_corpus(tmp_path_factory):
    from rosbag_maker import write_bag

    d = tmp_path_factory.mktemp("bagfuzz")
    out = {"dir": d, "base": {}, "files": {}}
    for storage in ("mcap", "sqlite3"):
        bag = write_bag(d / f"src_{storage}", storage=storage, duration=8.0)
        s = d / f"{storage}.json"
        res = invoke("run", "ins", bag, *BAG_RUN, "--summary", s)
        assert res.exit_code == 0, res.output
        out["base"][storage] = json.loads(s.read_text())["filters"]
        out["files"][storage] = {p.name: p.read_bytes() for p in bag.iterdir()}
    return out


def _mutate_bag(files: dict[str, bytes], kind: str, frac: float,
                flips: list[tuple[float, int]], tail: bytes) -> dict[str, bytes | None]:
    """A copy of the bag's files with one kind of damage; None deletes a file."""
    out: dict[str, bytes | None] = dict(files)
    data_name = next(n for n in files if n != "metadata.yaml")
    target = "metadata.yaml" if kind.startswith("meta") else data_name
    blob = files[target]
    n = len(blob)
    if kind.endswith("truncate"):
        out[target] = blob[: int(frac * n)]
    elif kind.endswith("append"):
        out[target] = blob + tail
    elif kind.endswith("flip"):
        b = bytearray(blob)
        for where, bit in flips:
            b[min(int(where * n), n - 1)] ^= 1 << bit
        out[target] = bytes(b)
    elif kind == "meta_number":  # one number of metadata.yaml changed, the YAML still valid
        text = blob.decode()
        numbers = [m for m in __import__("re").finditer(r"\d+", text)]
        m = numbers[min(int(frac * len(numbers)), len(numbers) - 1)]
        value = max(int(m.group()) + int((flips[0][0] - 0.5) * 2000), 0)
        out[target] = (text[: m.start()] + str(value) + text[m.end():]).encode()
    elif kind == "meta_delete":
        out[target] = None
    return out


# the kinds whose answer may change without a checksum to tell (a flipped byte of a sample)
SILENT_POSSIBLE = {"data_flip"}


@settings(max_examples=60, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(
    storage=st.sampled_from(["mcap", "sqlite3"]),
    kind=st.sampled_from(["meta_flip", "meta_truncate", "meta_append", "meta_number",
                          "meta_delete", "data_truncate", "data_append", "data_flip"]),
    frac=st.floats(0.0, 1.0),
    flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 7)), min_size=1, max_size=3),
    tail=st.binary(min_size=1, max_size=64),
)
def test_damaged_bags(bag_corpus, storage, kind, frac, flips, tail):
    """Never a traceback, a hang or a partial output; exit 0 only with the intact bag's answer
    or a SALVAGED note, except where a flipped byte of a sample without a checksum changes the
    answer within the physical ranges (then only the rest is asserted)."""
    import shutil

    d: Path = bag_corpus["dir"]
    bag = d / "case"
    shutil.rmtree(bag, ignore_errors=True)
    bag.mkdir()
    for name, data in _mutate_bag(bag_corpus["files"][storage], kind, frac, flips,
                                  tail).items():
        if data is not None:
            (bag / name).write_bytes(data)
    summary = d / "case.json"
    summary.unlink(missing_ok=True)
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(TIMEOUT_S)
    try:
        info = invoke("info", bag)
        run = invoke("run", "ins", bag, *BAG_RUN, "--summary", summary)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    for res in (info, run):
        assert res.exit_code in (0, 1), (res.exit_code, res.output)
        assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
        assert "Traceback" not in res.output
        if res.exit_code:
            lines = res.stderr.strip().splitlines()
            assert lines[-1].startswith("Error: ") and len(lines[-1]) < 2000, res.stderr
            assert all(ln.startswith("warning: ") for ln in lines[:-1]), lines
    if info.exit_code == 0:
        assert "DAMAGED" not in info.output
    assert not list(d.glob(".*.part")) and not list(bag.glob(".*.part"))
    if run.exit_code:
        assert not summary.exists()  # no partial output
        return
    got = json.loads(summary.read_text())
    if got["salvaged"]:
        assert "SALVAGED" in run.output
    elif kind not in SILENT_POSSIBLE:
        assert got["filters"] == bag_corpus["base"][storage], "exit 0 with a different result"
