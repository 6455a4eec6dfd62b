"""Damaged recordings: truncated files are salvaged up to the damage with a warning; CRC errors are
reported; nothing else escapes."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap_edits import uncompressed_copy

from navreplay.core.streams import Recording
from navreplay.io import RecordingError, RecordingWarning, read_recording, write_recording
from navreplay.io import writer as writer_module
from navreplay.io.synthetic import random_recording

SMALL_CHUNK = 8 << 10


@pytest.fixture(scope="module")
def original(tmp_path_factory: pytest.TempPathFactory) -> tuple[Recording, Path]:
    """A 4 s recording of every stream kind, in many small chunks."""
    rec = random_recording(np.random.default_rng(99), duration_s=4.0)
    path = tmp_path_factory.mktemp("damage") / "rec.mcap"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(writer_module, "CHUNK_SIZE", SMALL_CHUNK)
        write_recording(path, rec)
    return rec, path


def assert_prefix(back: Recording, rec: Recording) -> int:
    """Every stream read is a prefix of the original one; return the messages read."""
    assert back.metadata == rec.metadata and back.t0_ns == rec.t0_ns
    total = 0
    for kind, stream in back.streams.items():
        full = rec[kind]
        n = len(stream)
        assert n <= len(full)
        np.testing.assert_array_equal(stream.t_ns, full.t_ns[:n])
        for name, col in stream.columns.items():
            if name == "pos" and kind.value == "gps":
                np.testing.assert_array_max_ulp(col, full[name][:n], maxulp=1)
            else:
                np.testing.assert_array_equal(col, full[name][:n])
        total += n
    return total


def _chunk_offsets(path: Path) -> list[int]:
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return sorted(c.chunk_start_offset for c in summary.chunk_indexes)


def test_truncated_file_is_salvaged_with_a_warning(
    original: tuple[Recording, Path], tmp_path: Path
) -> None:
    rec, path = original
    data = path.read_bytes()
    offsets = _chunk_offsets(path)
    assert len(offsets) > 10
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: offsets[len(offsets) // 2] + 100])  # inside a chunk
    with pytest.warns(RecordingWarning) as caught:
        back = read_recording(cut)
    messages = [str(w.message) for w in caught if issubclass(w.category, RecordingWarning)]
    assert len(messages) == 1, messages
    msg = messages[0]
    assert msg.startswith(
        f"{cut}: file is truncated or damaged at byte {offsets[len(offsets) // 2]}"
    )
    read = assert_prefix(back, rec)
    last = max(int(s.t_ns[-1]) for s in back.streams.values())
    assert f"the last good one at t = {(last - rec.t0_ns) * 1e-9:.9f} s ({last} ns)" in msg
    assert f"salvaged {read} messages" in msg
    assert 0 < read < sum(len(s) for s in rec.streams.values())


def test_missing_summary_recovers_everything(
    original: tuple[Recording, Path], tmp_path: Path
) -> None:
    rec, path = original
    data = path.read_bytes()
    cut = tmp_path / "nosummary.mcap"
    cut.write_bytes(data[:-40])  # inside the footer
    with pytest.warns(
        RecordingWarning,
        match=r"summary or footer missing or damaged.*all \d+ messages were recovered",
    ):
        back = read_recording(cut)
    assert assert_prefix(back, rec) == sum(len(s) for s in rec.streams.values())


def test_unfinished_file(
    original: tuple[Recording, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A writer that died before finish(): complete chunks are salvaged."""
    rec, _ = original
    path = tmp_path / "unfinished.mcap"
    monkeypatch.setattr(writer_module, "CHUNK_SIZE", SMALL_CHUNK)
    monkeypatch.setattr(writer_module.BulkWriter, "finish", lambda self: None)
    write_recording(path, rec)
    with pytest.warns(RecordingWarning, match="unfinished.mcap: file is truncated or damaged"):
        back = read_recording(path)
    assert 0 < assert_prefix(back, rec)


@pytest.mark.parametrize("where", ["chunk", "metadata", "summary"])
def test_flipped_byte_is_reported(
    original: tuple[Recording, Path], tmp_path: Path, where: str
) -> None:
    _, path = original
    data = bytearray(path.read_bytes())
    offsets = _chunk_offsets(path)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    at = {
        "chunk": offsets[3] + 200,
        "metadata": summary.metadata_indexes[0].offset + 40,
        "summary": len(data) - 200,
    }[where]
    data[at] ^= 0x10
    bad = tmp_path / "flipped.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match=rf"{bad}: .*(CRC mismatch|corrupt)"):
        read_recording(bad)


def test_flipped_byte_in_chunk_of_truncated_file(
    original: tuple[Recording, Path], tmp_path: Path
) -> None:
    """The salvage path checks chunk CRCs too."""
    _, path = original
    data = bytearray(path.read_bytes())
    offsets = _chunk_offsets(path)
    data[offsets[2] + 300] ^= 0x01
    bad = tmp_path / "both.mcap"
    bad.write_bytes(bytes(data[: offsets[6]]))
    with pytest.raises(RecordingError, match=rf"{bad}: .*(CRC mismatch|corrupt)"):
        read_recording(bad)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("truncate") / "t.mcap"


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(fraction=st.floats(min_value=0.0, max_value=1.0))
def test_truncation_anywhere_gives_a_prefix_or_a_recording_error(
    original: tuple[Recording, Path], scratch: Path, fraction: float
) -> None:
    rec, path = original
    data = path.read_bytes()
    n = int(fraction * len(data))
    scratch.write_bytes(data[:n])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            back = read_recording(scratch)
        except RecordingError as exc:
            assert str(scratch) in str(exc)
            return
    assert all(issubclass(w.category, RecordingWarning) for w in caught), [
        str(w.message) for w in caught
    ]
    read = assert_prefix(back, rec)
    if n < len(data):
        assert caught, "a truncated file must warn"
    else:
        assert read == sum(len(s) for s in rec.streams.values())


@pytest.mark.parametrize("data_crc", [True, False])
def test_flipped_payload_byte_is_caught_by_one_crc_or_the_other(
    original: tuple[Recording, Path], tmp_path: Path, data_crc: bool
) -> None:
    """Chunks skip their own CRC only when the data-section CRC has covered them: a flipped
    payload byte in an uncompressed chunk is reported by whichever CRC the file stores."""
    rec, path = original
    good = tmp_path / "plain.mcap"
    uncompressed_copy(path, good, SMALL_CHUNK, crcs=True, data_crc=data_crc)
    assert assert_prefix(read_recording(good), rec) == sum(len(s) for s in rec.streams.values())
    data = bytearray(good.read_bytes())
    data[_chunk_offsets(good)[3] + 400] ^= 0x04
    bad = tmp_path / "flipped.mcap"
    bad.write_bytes(bytes(data))
    which = "data section CRC mismatch" if data_crc else r"chunk at byte \d+: CRC mismatch"
    with pytest.raises(RecordingError, match=rf"{bad}: {which}"):
        read_recording(bad)


def test_chunk_walk_columns_and_malformed_records() -> None:
    """The compiled walk of a chunk's records: message columns, and one clear line for a
    record that overruns the chunk or a message too short for its header."""
    import struct

    from navreplay.io.mcapfile import scan_chunk

    def message(channel: int, log_time: int, payload: bytes) -> bytes:
        body = struct.pack("<HIQQ", channel, 7, log_time, log_time + 1) + payload
        return struct.pack("<BQ", 0x05, len(body)) + body

    other = struct.pack("<BQ", 0x0F, 3) + b"abc"  # an unrelated record is stepped over
    data = message(3, 10, b"xy") + other + message(65535, 2**62, b"")
    block = scan_chunk(data, lambda *_: None, "f.mcap", 100)
    assert block.channel.tolist() == [3, 65535]
    assert block.log_time.tolist() == [10, 2**62]
    assert block.length.tolist() == [2, 0]
    assert block.payload(0) == b"xy" and block.payload(1) == b""
    with pytest.raises(RecordingError, match=r"^f.mcap: chunk at byte 100 has a malformed record"):
        scan_chunk(data[:-1], lambda *_: None, "f.mcap", 100)
    short = struct.pack("<BQ", 0x05, 4) + b"\0" * 4
    with pytest.raises(RecordingError, match=r"^f.mcap: chunk at byte 100 has a malformed message"):
        scan_chunk(short, lambda *_: None, "f.mcap", 100)
