"""BulkWriter writes the bytes mcap's own Writer writes for the same messages, and its files
read back through mcap's reader with every CRC checked."""

from __future__ import annotations

import io

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from navreplay.io.mcapwrite import BulkWriter


def _batches(rng: np.random.Generator, widths: list[int], n: int, t0: int):
    """Batches of random payloads on channels 1.. with times that tie across channels."""
    out = []
    for k, w in enumerate(widths):
        m = int(rng.integers(0, n))
        t = np.sort(t0 + rng.integers(0, 50, m) * 1000)
        out.append((k + 1, t.astype(np.int64), rng.integers(0, 256, (m, w), dtype=np.uint8)))
    return out


def _write(cls, calls, chunk_size: int, compression: CompressionType, single: bool,
           **options) -> bytes:
    buf = io.BytesIO()
    w = cls(buf, chunk_size=chunk_size, compression=compression, enable_crcs=True,
            enable_data_crcs=True, **options)
    w.start(profile="ros2", library="test")
    w.add_metadata("meta", {"a": "1", "b": "two"})
    sid = w.register_schema("pkg/msg/A", "ros2msg", b"float64 x\n")
    sid2 = w.register_schema("pkg/msg/B", "ros2msg", b"uint8 y\n")
    for k in range(3):
        w.register_channel(f"/topic{k}", "cdr", sid if k < 2 else sid2)
    for batches in calls:
        if single or cls is Writer:  # one add_message per message, merged by time
            t = np.concatenate([b[1] for b in batches])
            order = np.argsort(t, kind="stable")
            msgs = [(cid, int(ti), row.tobytes()) for cid, tt, rows in batches
                    for ti, row in zip(tt, rows, strict=True)]
            for i in order:
                cid, ti, data = msgs[i]
                w.add_message(cid, ti, data, ti)
        else:
            w.add_messages(batches)
    w.finish()
    return buf.getvalue()


@pytest.mark.parametrize("widths", [[40, 40, 40], [40, 17, 300]])
@pytest.mark.parametrize("chunk_size", [1 << 20, 700, 1])
@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4,
                                         CompressionType.NONE])
def test_same_bytes_as_mcaps_writer(widths, chunk_size, compression) -> None:
    rng = np.random.default_rng(7)
    calls = [_batches(rng, widths, 60, 100_000 * i) for i in range(5)]
    reference = _write(Writer, calls, chunk_size, compression, single=True)
    assert _write(BulkWriter, calls, chunk_size, compression, single=False) == reference
    assert _write(BulkWriter, calls, chunk_size, compression, single=True) == reference


def _shared(rng: np.random.Generator, widths: list[int], n: int, t0: int, repeat: bool):
    """Batches at the same times (strictly increasing, or with a repeated time)."""
    t = t0 + np.cumsum(rng.integers(1, 5, n)) * 1000
    if repeat and n > 2:
        t[n // 2] = t[n // 2 - 1]
    return [(k + 1, t.astype(np.int64), rng.integers(0, 256, (n, w), dtype=np.uint8))
            for k, w in enumerate(widths)]


@pytest.mark.parametrize("repeat", [False, True])
@pytest.mark.parametrize("chunk_size", [1 << 20, 700, 1])
def test_batches_at_shared_times_as_mcaps_writer(repeat, chunk_size) -> None:
    """Batches of one set of times (the streams of a filter and the reference at an output
    rate) are placed side by side without a gather: the bytes of mcap's Writer, chunks cut
    at the same messages; a repeated time takes the general path."""
    rng = np.random.default_rng(9)
    calls = [_shared(rng, [40, 17, 300], n, 10**9 * i, repeat) for i, n in
             enumerate((50, 1, 120))]
    for compression in (CompressionType.ZSTD, CompressionType.NONE):
        reference = _write(Writer, calls, chunk_size, compression, single=True)
        assert _write(BulkWriter, calls, chunk_size, compression, single=False) == reference


@pytest.mark.parametrize("level", [3, -1])
def test_reads_back_with_crcs(level) -> None:
    rng = np.random.default_rng(8)
    calls = [_batches(rng, [24, 56], 2000, 10**9 * i) for i in range(3)]
    data = _write(BulkWriter, calls, 4096, CompressionType.ZSTD, single=False, zstd_level=level)
    if level != 3:  # the level is the compressor's: the same records, other compressed bytes
        assert data != _write(Writer, calls, 4096, CompressionType.ZSTD, single=True)
    got = [(ch.topic, m.log_time, m.data) for _, ch, m in
           make_reader(io.BytesIO(data), validate_crcs=True).iter_messages(log_time_order=False)]
    want = []
    for batches in calls:
        rows = [(int(ti), f"/topic{cid - 1}", k, row.tobytes())
                for k, (cid, tt, rr) in enumerate(batches) for ti, row in zip(tt, rr, strict=True)]
        want += [(topic, ti, d) for ti, topic, _, d in sorted(rows, key=lambda r: r[:1] + r[2:3])]
    assert got == want
    summary = make_reader(io.BytesIO(data)).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == len(want)


def test_refuses_bad_batches() -> None:
    w = BulkWriter(io.BytesIO())
    w.start()
    with pytest.raises(ValueError, match="rows"):
        w.add_messages([(1, np.array([1, 2]), np.zeros((3, 4), np.uint8))])
    with pytest.raises(ValueError, match="negative"):
        w.add_messages([(1, np.array([-1]), np.zeros((1, 4), np.uint8))])
