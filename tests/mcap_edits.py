"""MCAP files for the reader and pipeline tests: written in small chunks (many windows in a short
file), and copies with the IMU header stamps zeroed (a driver that never sets them), and
uncompressed copies (to damage a file at a known place)."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from navreplay.core.streams import Recording
from navreplay.io import writer as writer_module
from navreplay.io.writer import write_recording

CHUNK = 1 << 17
"""Chunk size [bytes]: about 2 s of a vehicle drive per chunk."""


def write_small_chunks(rec: Recording, path: Path) -> Path:
    """Write ``rec`` in chunks of :data:`CHUNK` bytes."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(writer_module, "CHUNK_SIZE", CHUNK)
        write_recording(path, rec)
    return path


def zero_imu_stamps(src: Path, dst: Path, *, at: int | None = None, latency: int = 0) -> None:
    """A copy of ``src`` whose IMU messages have zero header stamps (a driver that never sets
    them; with ``at``: from log time ``at`` [ns] on, or before ``-at`` when negative): the stamp
    is the first 8 bytes after the CDR encapsulation header. ``latency`` [ns] is added to the
    IMU log times (a receiver's delay)."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(out, chunk_size=CHUNK, compression=CompressionType.ZSTD)
        w.start()
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        schemas = {s.id: w.register_schema(s.name, s.encoding, s.data)
                   for s in summary.schemas.values()}
        channels = {c.id: w.register_channel(c.topic, c.message_encoding,
                                             schemas.get(c.schema_id, 0), c.metadata)
                    for c in summary.channels.values()}
        for _, channel, m in reader.iter_messages(log_time_order=False):
            data = m.data
            log = m.log_time
            if channel.topic == "/imu":
                if at is None or (log >= at if at >= 0 else log < -at):
                    data = data[:4] + bytes(8) + data[12:]
                log += latency
            w.add_message(channels[channel.id], log, data, m.publish_time, m.sequence)
        w.finish()


def uncompressed_copy(src: Path, dst: Path, chunk_size: int = 1 << 15, *, crcs: bool = False,
                      data_crc: bool = False) -> None:
    """The recording rewritten uncompressed, metadata first; without CRCs unless ``crcs``
    (chunk CRCs) and ``data_crc`` (the data-section CRC) ask for them."""
    with src.open("rb") as f, dst.open("wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(out, compression=CompressionType.NONE, enable_crcs=crcs,
                   enable_data_crcs=data_crc, chunk_size=chunk_size)
        w.start(profile=reader.get_header().profile, library="test")
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        ids = {sid: w.register_schema(s.name, s.encoding, s.data)
               for sid, s in summary.schemas.items()}
        cids = {cid: w.register_channel(c.topic, c.message_encoding, ids[c.schema_id])
                for cid, c in summary.channels.items()}
        for _, channel, msg in reader.iter_messages(log_time_order=False):
            w.add_message(cids[channel.id], msg.log_time, msg.data, msg.publish_time)
        w.finish()
