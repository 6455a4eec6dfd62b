"""An MCAP writer that takes messages in bulk: :class:`BulkWriter`.

mcap's ``Writer`` builds each message record in Python (a dataclass, five ``struct.pack`` calls
and an index entry per message: about 25 us each, more than the filter's own step at 100 Hz).
:class:`BulkWriter` has the same methods and writes the same bytes for the same calls (chunks cut
at the same places, the same indexes, statistics, summary and CRCs), but
:meth:`~BulkWriter.add_messages` takes whole arrays of already encoded messages: their record
headers, the chunks' contents and message indexes are assembled by numpy, and only the chunk,
index and summary records (a few per megabyte) go through mcap's record classes.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from typing import IO, Any

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.writer import LIBRARY_IDENTIFIER, MCAP0_MAGIC, CompressionType

__all__ = ["BulkWriter", "MessageBatch"]

MessageBatch = tuple[int, np.ndarray, np.ndarray]
"""(channel id, log times [ns] (n,) int64, payloads (n, size) uint8: row i is message i)."""

_PREFIX = 1 + 8 + 2 + 4 + 8 + 8
"""Bytes of a message record before its payload: opcode, record length, channel id, sequence,
log time and publish time."""


def _record_header(log_time: np.ndarray, channel_id: int, size: int) -> np.ndarray:
    """Message record prefixes (n, :data:`_PREFIX`) uint8 of payloads of ``size`` bytes
    (sequence 0, publish time = log time)."""
    head = np.zeros(len(log_time), dtype=np.dtype(
        {"names": ["op", "length", "channel", "log", "publish"],
         "formats": ["u1", "<u8", "<u2", "<u8", "<u8"],
         "offsets": [0, 1, 9, 15, 23], "itemsize": _PREFIX}))
    head["op"] = Opcode.MESSAGE
    head["length"] = _PREFIX - 9 + size
    head["channel"] = channel_id
    head["log"] = log_time
    head["publish"] = log_time
    return head.view(np.uint8).reshape(len(log_time), _PREFIX)


class BulkWriter:
    """Writes an MCAP file (chunked, every index, statistics and summary offsets, as mcap's
    ``Writer`` with its defaults): the methods of mcap's ``Writer``, plus
    :meth:`add_messages`.

    Parameters
    ----------
    output : binary file
        Written sequentially from its current position (not closed by :meth:`finish`).
    chunk_size : int
        A chunk is closed once its uncompressed records pass this many bytes.
    compression : CompressionType
        Of the chunks: ZSTD (default), LZ4 or NONE.
    zstd_level : int
        zstd's compression level (3: zstd's default, as mcap's ``Writer``; negative levels
        are zstd's fast ones).
    enable_crcs, enable_data_crcs : bool
        CRCs of the chunks and the summary; of the data section.
    """

    def __init__(self, output: IO[bytes], chunk_size: int = 1024 * 1024,
                 compression: CompressionType = CompressionType.ZSTD,
                 enable_crcs: bool = True, enable_data_crcs: bool = False,
                 zstd_level: int = 3) -> None:
        if compression is CompressionType.ZSTD:
            import zstandard

            self._compress: Any = zstandard.ZstdCompressor(level=zstd_level).compress
            self._compression = "zstd"
        elif compression is CompressionType.LZ4:
            import lz4.frame  # type: ignore[import-untyped]

            self._compress = lz4.frame.compress
            self._compression = "lz4"
        else:
            self._compress, self._compression = None, ""
        self._out = output
        self._chunk_size = chunk_size
        self._crcs = enable_crcs
        self._data_crcs = enable_data_crcs
        self._data_crc = 0
        self._pos = output.tell()
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._counts: dict[int, int] = {}  # channel -> messages, in order of the first
        self._messages = 0
        self._start_time = 0
        self._end_time = 0
        # the open chunk: its records, their size, and per message its channel, time, offset
        self._parts: list[bytes | memoryview] = []  # views of numpy's records: not copied
        self._size = 0
        self._index: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    # -- the methods of mcap's Writer ----------------------------------------------------

    def start(self, profile: str = "", library: str = LIBRARY_IDENTIFIER) -> None:
        self._emit(MCAP0_MAGIC)
        self._emit(_record(Header(profile, library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, data=data, encoding=encoding, name=name)
        self._schemas.append(schema)
        self._add_to_chunk(_record(schema))
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        channel = Channel(id=len(self._channels) + 1, topic=topic,
                          message_encoding=message_encoding, schema_id=schema_id,
                          metadata=dict(metadata or {}))
        self._channels.append(channel)
        self._add_to_chunk(_record(channel))
        return channel.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        record = _record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=self._pos, length=len(record),
                                                    name=name))
        self._emit(record)

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        """One message (as mcap's ``Writer.add_message``)."""
        record = struct.pack("<BQHIQQ", Opcode.MESSAGE, _PREFIX - 9 + len(data), channel_id,
                             sequence, log_time, publish_time) + data
        self._add_chunk_messages(np.array([channel_id]), np.array([log_time], np.int64),
                                 np.array([0], np.int64), [record], len(record))

    # -- in bulk ---------------------------------------------------------------------------

    def add_messages(self, batches: Sequence[MessageBatch]) -> None:
        """The messages of ``batches`` merged by log time (ties in the order of the batches,
        then of their rows), as as many :meth:`add_message` calls in that order would write
        them (sequence 0, publish time = log time), after the messages added before.

        Each batch's payloads are rows of one 2-D uint8 array (a numpy structured array of
        fixed-size CDR messages viewed as bytes)."""
        batches = [b for b in batches if len(b[1])]
        if not batches:
            return
        for cid, t, data in batches:
            if data.ndim != 2 or data.shape[0] != len(t):
                raise ValueError(f"channel {cid}: payloads must be {len(t)} rows of bytes")
        t = np.concatenate([np.asarray(b[1], np.int64) for b in batches])
        if np.any(t < 0):
            raise ValueError("message times must not be negative")
        t0 = np.asarray(batches[0][1], np.int64)
        widths = np.array([_PREFIX + b[2].shape[1] for b in batches], np.int64)
        if (len(batches) > 1 and np.all(t0[1:] > t0[:-1])
                and all(np.array_equal(b[1], t0) for b in batches[1:])):
            # the batches share their times (the streams of a filter and the reference at
            # one output rate), none repeated: the merged order is row by row, batch by batch,
            # which the records placed side by side are already (no gather)
            table = np.empty((len(t0), int(widths.sum())), np.uint8)
            at = 0
            for (cid, _, data), w in zip(batches, widths.tolist(), strict=True):
                table[:, at:at + _PREFIX] = _record_header(t0, cid, w - _PREFIX)
                table[:, at + _PREFIX:at + w] = data
                at += w
            self._add_records(np.tile([b[0] for b in batches], len(t0)),
                              np.repeat(t0, len(batches)), np.tile(widths, len(t0)),
                              table.reshape(-1))
            return
        rows = [np.concatenate([_record_header(np.asarray(t), cid, data.shape[1]),
                                np.asarray(data, np.uint8)], axis=1) for cid, t, data in batches]
        order = np.argsort(t, kind="stable")
        t = t[order]
        which = np.repeat(np.arange(len(batches)), [len(b[1]) for b in batches])[order]
        cids = np.array([b[0] for b in batches])[which]
        sizes = widths[which]
        if np.all(widths == widths[0]):  # records of one size: rows gathered
            self._add_records(cids, t, sizes, np.concatenate(rows)[order].reshape(-1))
            return
        # else each record's bytes gathered from its batch's block
        table = np.concatenate([r.reshape(-1) for r in rows])
        starts = np.concatenate([[0], np.cumsum([r.size for r in rows])[:-1]])
        first = np.concatenate([[0], np.cumsum([len(b[1]) for b in batches])[:-1]])
        src = starts[which] + (order - first[which]) * sizes
        ends = np.cumsum(sizes)
        a = 0
        while a < len(t):
            lo = int(ends[a - 1]) if a else 0
            b = self._chunk_end(ends, a)
            offsets = ends[a:b] - sizes[a:b] - lo
            records = table[np.repeat(src[a:b] - offsets, sizes[a:b])
                            + np.arange(int(ends[b - 1]) - lo)]
            self._add_chunk_messages(cids[a:b], t[a:b], offsets, [records.data],
                                     int(ends[b - 1]) - lo)
            a = b

    def _chunk_end(self, ends: np.ndarray, a: int) -> int:
        """The end of the messages from ``a`` that go into the open chunk: it closes after
        the message that takes it past chunk_size (``ends``: the records' cumulative ends)."""
        lo = int(ends[a - 1]) if a else 0
        return min(len(ends), int(np.searchsorted(ends, self._chunk_size - self._size + lo,
                                                  side="right")) + 1)

    def _add_records(self, cids: np.ndarray, t: np.ndarray, sizes: np.ndarray,
                     records: np.ndarray) -> None:
        """Messages whose records lie one after the other in ``records`` (uint8), in the
        order they are written, cut into chunks."""
        ends = np.cumsum(sizes)
        a = 0
        while a < len(t):
            lo = int(ends[a - 1]) if a else 0
            b = self._chunk_end(ends, a)
            self._add_chunk_messages(cids[a:b], t[a:b], ends[a:b] - sizes[a:b] - lo,
                                     [records[lo:int(ends[b - 1])].data],
                                     int(ends[b - 1]) - lo)
            a = b

    # -- chunks ----------------------------------------------------------------------------

    def _add_to_chunk(self, record: bytes) -> None:
        self._parts.append(record)
        self._size += len(record)
        if self._size > self._chunk_size:
            self._close_chunk()

    def _add_chunk_messages(self, cids: np.ndarray, t: np.ndarray, offsets: np.ndarray,
                            parts: list[bytes | memoryview], size: int) -> None:
        """Messages (channel, time, offset within ``parts``) whose records are ``parts``,
        appended to the open chunk, which then closes if it is past chunk_size."""
        self._index.append((cids, t, offsets + self._size))
        self._parts += parts
        self._size += size
        if not self._messages:
            self._start_time = int(t.min())
        self._start_time = min(self._start_time, int(t.min()))
        self._end_time = max(self._end_time, int(t.max()))
        self._messages += len(t)
        ids, first, counts = np.unique(cids, return_index=True, return_counts=True)
        for k in np.argsort(first, kind="stable"):
            cid = int(ids[k])
            self._counts[cid] = self._counts.get(cid, 0) + int(counts[k])
        if self._size > self._chunk_size:
            self._close_chunk()

    def _close_chunk(self) -> None:
        if not self._index:
            return
        cids = np.concatenate([i[0] for i in self._index])
        t = np.concatenate([i[1] for i in self._index])
        offsets = np.concatenate([i[2] for i in self._index])
        # the compressors and the CRC read the records' buffer: one part is not copied
        data = self._parts[0] if len(self._parts) == 1 else b"".join(self._parts)
        compressed = bytes(data) if self._compress is None else self._compress(data)
        chunk = Chunk(compression=self._compression, data=compressed,
                      message_start_time=int(t.min()), message_end_time=int(t.max()),
                      uncompressed_crc=zlib.crc32(data) if self._crcs else 0,
                      uncompressed_size=len(data))
        start = self._pos
        record = _record(chunk)
        self._emit(record)
        index = ChunkIndex(message_start_time=chunk.message_start_time,
                           message_end_time=chunk.message_end_time,
                           chunk_start_offset=start, chunk_length=len(record),
                           message_index_offsets={}, message_index_length=0,
                           compression=self._compression, compressed_size=len(compressed),
                           uncompressed_size=len(data))
        ids, first = np.unique(cids, return_index=True)
        pieces = []
        at = self._pos
        for k in np.argsort(first, kind="stable"):
            cid = int(ids[k])
            mine = cids == cid
            entries = np.empty((int(mine.sum()), 2), dtype="<u8")
            entries[:, 0], entries[:, 1] = t[mine], offsets[mine]
            body = entries.tobytes()
            index.message_index_offsets[cid] = at
            piece = struct.pack("<BQHI", Opcode.MESSAGE_INDEX, 6 + len(body), cid,
                                len(body)) + body
            pieces.append(piece)
            at += len(piece)
        index.message_index_length = at - self._pos
        self._emit(b"".join(pieces))
        self._chunk_indexes.append(index)
        self._parts, self._size, self._index = [], 0, []

    def _emit(self, data: bytes) -> None:
        if self._data_crcs:
            self._data_crc = zlib.crc32(data, self._data_crc)
        self._out.write(data)
        self._pos += len(data)

    # -- the end ---------------------------------------------------------------------------

    def finish(self) -> None:
        """Close the open chunk and write the summary and the footer (the output stays
        open)."""
        self._close_chunk()
        self._emit(_record(DataEnd(self._data_crc)))
        start = self._pos
        groups: list[tuple[int, list[Any]]] = [
            (Opcode.SCHEMA, self._schemas), (Opcode.CHANNEL, self._channels),
            (Opcode.STATISTICS, [Statistics(
                attachment_count=0, channel_count=len(self._channels),
                channel_message_counts=self._counts, chunk_count=len(self._chunk_indexes),
                message_count=self._messages, message_end_time=self._end_time,
                message_start_time=self._start_time,
                metadata_count=len(self._metadata_indexes),
                schema_count=len(self._schemas))]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes), (Opcode.ATTACHMENT_INDEX, []),
            (Opcode.METADATA_INDEX, self._metadata_indexes)]
        summary = RecordBuilder()
        offsets = []
        for opcode, records in groups:
            group_start = summary.count
            for r in records:
                r.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=start + group_start,
                                         group_length=summary.count - group_start))
        offset_start = start + summary.count
        for o in offsets:
            o.write(summary)
        data = summary.end()
        crc = 0
        if self._crcs:
            crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, start, offset_start),
                             zlib.crc32(data))
        self._out.write(data)
        self._out.write(_record(Footer(summary_start=start, summary_offset_start=offset_start,
                                       summary_crc=crc)))
        self._out.write(MCAP0_MAGIC)


def _record(record: Any) -> bytes:
    """The bytes of one of mcap's records."""
    builder = RecordBuilder()
    record.write(builder)
    return builder.end()
