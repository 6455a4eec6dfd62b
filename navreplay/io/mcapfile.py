"""Low-level MCAP access for bulk reading: file probing, integrity checks and chunk scanning.

The python ``mcap`` package reads one message at a time (tens of thousands per second). A
recording is read faster by taking whole chunks: each chunk is decompressed and CRC-checked with
mcap's own routines, its record offsets are found in one pass over the record headers, and the
payloads of a topic are then gathered with numpy. Two ways through a file:

* intact (both magics, a footer, a summary whose CRC holds): mcap's ``SeekingReader`` gives the
  summary (schemas, channels, statistics, chunk and metadata indexes); the chunks are read through
  the chunk index; the data-section CRC is checked in one sequential pass;
* anything else: mcap's ``StreamReader`` walks the records from the start (the engine under
  ``NonSeekingReader``) and stops at the first record that cannot be read, so a truncated or
  unfinished file yields every complete chunk before the damage.
"""

from __future__ import annotations

import dataclasses
import struct
import threading
import zlib
from collections.abc import Callable, Iterator
from io import BytesIO
from typing import BinaryIO

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError, RecordLengthLimitExceeded
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    Metadata,
    Schema,
    Statistics,
)
from mcap.stream_reader import CRCValidationError, StreamReader, get_chunk_data_stream

from navreplay.core.jit import kernel
from navreplay.io.errors import RecordingError

MAGIC = b"\x89MCAP0\r\n"
_FOOTER = struct.Struct("<BQQQI")
_DATA_END = struct.Struct("<BQI")
_RECORD = struct.Struct("<BQ")
_MESSAGE_HEADER = 1 + 8 + 2 + 4 + 8 + 8
"""Bytes of a Message record before its payload: opcode, length, channel, sequence, 2 times."""
_CRC_BLOCK = 8 << 20

DAMAGE_ERRORS: tuple[type[BaseException], ...] = (
    McapError,
    struct.error,
    ValueError,
    UnicodeDecodeError,
    EOFError,
    KeyError,
)
"""Exceptions of mcap's record reader that mean "this record cannot be read"."""


@dataclasses.dataclass
class Tail:
    """What the end of an intact file says.

    Attributes
    ----------
    summary_start : int
        Byte offset of the summary section, 0 when there is none.
    data_end : int
        Byte offset of the DataEnd record.
    data_crc : int
        CRC-32 of the data section stored in DataEnd (0: not computed by the writer).
    """

    summary_start: int
    data_end: int
    data_crc: int


def probe(f: BinaryIO, size: int, where: str) -> Tail | None:
    """Check the leading magic and, if the file ends properly, verify the summary CRC.

    Returns
    -------
    Tail | None
        None when the file does not end with a valid footer and magic (truncated, unfinished).

    Raises
    ------
    RecordingError
        If the file is not an MCAP file, or its summary CRC does not match.
    """
    f.seek(0)
    head = f.read(len(MAGIC))
    if head != MAGIC:
        if len(head) < len(MAGIC) and MAGIC.startswith(head):
            raise RecordingError(f"{where}: file is truncated to {size} bytes, nothing to read")
        raise RecordingError(f"{where}: not an MCAP file (bad magic {head!r})")
    end = size - len(MAGIC) - _FOOTER.size
    if end < len(MAGIC):
        return None
    f.seek(end)
    tail = f.read(_FOOTER.size + len(MAGIC))
    if tail[_FOOTER.size :] != MAGIC:
        return None
    opcode, length, summary_start, _, summary_crc = _FOOTER.unpack(tail[: _FOOTER.size])
    if opcode != Opcode.FOOTER or length != _FOOTER.size - 9 or summary_start > end:
        return None
    if summary_start and summary_crc:
        crc = crc_of_range(f, summary_start, end)
        crc = zlib.crc32(tail[: _FOOTER.size - 4], crc)
        if crc != summary_crc:
            raise RecordingError(
                f"{where}: summary section CRC mismatch (stored {summary_crc:#010x}, computed "
                f"{crc:#010x}): the file is corrupt"
            )
    data_end = (summary_start or end) - _DATA_END.size
    data_crc = 0
    f.seek(data_end)
    raw = f.read(_DATA_END.size)
    opcode, length, data_crc = _DATA_END.unpack(raw) if len(raw) == _DATA_END.size else (0, 0, 0)
    if opcode != Opcode.DATA_END or length != 4:
        raise RecordingError(
            f"{where}: no valid DataEnd record at byte {data_end} before the "
            f"{'summary' if summary_start else 'footer'}: the file is corrupt"
        )
    return Tail(summary_start, data_end, data_crc)


def crc_of_range(f: BinaryIO, start: int, stop: int, crc: int = 0) -> int:
    """CRC-32 of bytes [start, stop) of a file."""
    f.seek(start)
    left = stop - start
    while left > 0:
        block = f.read(min(left, _CRC_BLOCK))
        if not block:
            break
        crc = zlib.crc32(block, crc)
        left -= len(block)
    return crc


def check_data_crc(f: BinaryIO, tail: Tail, where: str) -> None:
    """Verify the data-section CRC of an intact file (when the writer stored one)."""
    if tail.data_crc == 0:
        return
    crc = crc_of_range(f, 0, tail.data_end)
    if crc != tail.data_crc:
        raise RecordingError(
            f"{where}: data section CRC mismatch (stored {tail.data_crc:#010x}, computed "
            f"{crc:#010x}): the file is corrupt"
        )


def chunk_bytes(chunk: Chunk, where: str, offset: int, check_crc: bool = True) -> bytes:
    """Decompressed records of a chunk, CRC-checked unless ``check_crc`` is False.

    The chunk CRC is over the decompressed records; a caller that has verified the data-section
    CRC (which covers the compressed bytes as written) passes ``check_crc=False``: damage in the
    file is then already excluded, and the CRC pass over the (3 to 4 times larger) decompressed
    data would add nothing.

    Raises
    ------
    RecordingError
        On a CRC mismatch or data that does not decompress.
    """
    try:
        if chunk.compression == "zstd":
            data = _zstd().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
            length = chunk.uncompressed_size
            if check_crc and chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
                raise CRCValidationError(chunk.uncompressed_crc, zlib.crc32(data), chunk)
        else:
            stream, length = get_chunk_data_stream(chunk, validate_crc=check_crc)
            data = stream.read(length)
    except CRCValidationError as exc:
        raise RecordingError(
            f"{where}: chunk at byte {offset}: CRC mismatch (stored {exc.expected:#010x}, "
            f"computed {exc.actual:#010x}): the file is corrupt"
        ) from None
    except Exception as exc:  # zstd/lz4 raise their own types
        raise RecordingError(
            f"{where}: chunk at byte {offset} does not decompress ({exc}): the file is corrupt"
        ) from None
    if len(data) != length:
        raise RecordingError(f"{where}: chunk at byte {offset} is shorter than it claims")
    return data


_local = threading.local()


def _zstd() -> zstandard.ZstdDecompressor:
    """This thread's zstd decompressor (one context reused for every chunk)."""
    dctx = getattr(_local, "zstd", None)
    if dctx is None:
        dctx = _local.zstd = zstandard.ZstdDecompressor()
    return dctx


@dataclasses.dataclass
class MessageBlock:
    """Messages of one chunk (or of loose records), columnar.

    Attributes
    ----------
    data : bytes
        Buffer holding the payloads.
    channel : ndarray (N,), uint16
    log_time : ndarray (N,), int64
        MCAP log times [ns].
    start : ndarray (N,), int64
        Payload offsets in ``data``.
    length : ndarray (N,), int64
        Payload lengths [bytes].
    """

    data: bytes
    channel: np.ndarray
    log_time: np.ndarray
    start: np.ndarray
    length: np.ndarray

    def __len__(self) -> int:
        return len(self.channel)

    def rows(self, index: np.ndarray, width: int) -> np.ndarray:
        """Payloads ``index`` (all ``width`` bytes long) as an (n, width) uint8 array."""
        u8 = np.frombuffer(self.data, dtype=np.uint8)
        if width == 0 or len(u8) < width:
            return np.zeros((len(index), width), dtype=np.uint8)
        view = np.lib.stride_tricks.as_strided(u8, (len(u8) - width + 1, width), (1, 1))
        return view[self.start[index]]

    def payload(self, i: int) -> bytes:
        s = int(self.start[i])
        return self.data[s : s + int(self.length[i])]


_WALK_OK, _WALK_BAD_RECORD, _WALK_BAD_MESSAGE = 0, 1, 2


@kernel
def _u64(u8: np.ndarray, at: int) -> int:
    value = 0
    for b in range(7, -1, -1):
        value = (value << 8) | int(u8[at + b])
    return value


@kernel
def _walk_records(u8: np.ndarray, message: int, schema: int, channel: int):  # noqa: ANN202
    """Walk the records (opcode u8, length u64 little-endian, body) of a decompressed chunk.

    Returns the Message records' channel ids, log times, payload offsets and payload lengths,
    the offsets of the Schema and Channel records, and a status (_WALK_OK, or the first
    malformed record or message)."""
    n = u8.shape[0]
    cap = n // _MESSAGE_HEADER + 1
    chan = np.empty(cap, dtype=np.uint16)
    log_time = np.empty(cap, dtype=np.int64)
    start = np.empty(cap, dtype=np.int64)
    size = np.empty(cap, dtype=np.int64)
    others = np.empty(n // 9 + 1, dtype=np.int64)
    k = 0
    o = 0
    pos = 0
    status = _WALK_OK
    while pos < n:
        if pos + 9 > n:
            status = _WALK_BAD_RECORD
            break
        length = _u64(u8, pos + 1)
        if length < 0 or length > n - pos - 9:
            status = _WALK_BAD_RECORD
            break
        op = u8[pos]
        if op == message:
            if length < _MESSAGE_HEADER - 9:
                status = _WALK_BAD_MESSAGE
                break
            chan[k] = np.uint16(u8[pos + 9]) | (np.uint16(u8[pos + 10]) << np.uint16(8))
            log_time[k] = _u64(u8, pos + 15)
            start[k] = pos + _MESSAGE_HEADER
            size[k] = length - (_MESSAGE_HEADER - 9)
            k += 1
        elif op == schema or op == channel:
            others[o] = pos
            o += 1
        pos += 9 + length
    return chan[:k].copy(), log_time[:k].copy(), start[:k].copy(), size[:k].copy(), \
        others[:o].copy(), status


def scan_chunk(
    data: bytes, on_record: Callable[[int, bytes], None], where: str, offset: int
) -> MessageBlock:
    """Find the messages of a decompressed chunk; hand its schema and channel records over.

    Parameters
    ----------
    data : bytes
        Decompressed chunk records.
    on_record : callable(opcode, body)
        Called for every Schema and Channel record inside the chunk.
    where, offset
        File and chunk offset for error messages.
    """
    u8 = np.frombuffer(data, dtype=np.uint8)
    channel, log_time, start, length, others, status = _walk_records(
        u8, int(Opcode.MESSAGE), int(Opcode.SCHEMA), int(Opcode.CHANNEL))
    for p in others.tolist():
        opcode, size = _RECORD.unpack_from(data, p)
        on_record(opcode, data[p + 9 : p + 9 + size])
    if status == _WALK_BAD_RECORD:
        raise RecordingError(f"{where}: chunk at byte {offset} has a malformed record")
    if status == _WALK_BAD_MESSAGE:
        raise RecordingError(f"{where}: chunk at byte {offset} has a malformed message")
    return MessageBlock(data, channel, log_time, start, length)


def loose_block(messages: list[Message]) -> MessageBlock:
    """A MessageBlock of Message records read outside chunks."""
    data = b"".join(m.data for m in messages)
    length = np.array([len(m.data) for m in messages], dtype=np.int64)
    start = np.concatenate([[0], np.cumsum(length)[:-1]]).astype(np.int64)
    return MessageBlock(
        data,
        np.array([m.channel_id for m in messages], dtype=np.uint16),
        np.array([m.log_time for m in messages], dtype=np.int64),
        start,
        length,
    )


def parse_schema(body: bytes) -> Schema:
    return Schema.read(ReadDataStream(BytesIO(body)))


def parse_channel(body: bytes) -> Channel:
    return Channel.read(ReadDataStream(BytesIO(body)))


# ---------------------------------------------------------------------------------------------
# Walking a file


class _StreamReader(StreamReader):
    """mcap's sequential record reader, skipping index records and tracking record offsets.

    Message and chunk indexes are not needed to read a file front to back; mcap's reader skips the
    body of a record whose parser returns None, so returning None here saves parsing one Python
    tuple per message. Everything else (CRCs, limits, chunk records) is mcap's own.
    """

    def __init__(self, f: BinaryIO, **kwargs) -> None:
        super().__init__(f, **kwargs)
        self._file = f
        self.record_start = 0
        self.record_end = len(MAGIC)

    def _read_record(self, opcode: int, length: int):
        body = self._file.tell()
        self.record_start, self.record_end = body - 9, body + length
        if opcode in (Opcode.MESSAGE_INDEX, Opcode.CHUNK_INDEX):
            return None
        return super()._read_record(opcode, length)

    def damage_offset(self) -> int:
        """Start of the record that could not be read (call after a read error)."""
        if self._file.tell() >= self.record_end:
            return self.record_end  # the next record's header was cut or invalid
        return self.record_start


@dataclasses.dataclass
class Damage:
    """Where and why sequential reading stopped early.

    Attributes
    ----------
    offset : int
        Byte offset of the first record that could not be read.
    reason : str
    data_complete : bool
        True when the whole data section was read (only the summary or footer is missing).
    """

    offset: int
    reason: str
    data_complete: bool


@dataclasses.dataclass
class FileContents:
    """Everything but the messages, gathered while walking a file.

    Attributes
    ----------
    size : int
    profile, library : str
        From the MCAP header.
    schemas : dict[int, Schema]
    channels : dict[int, Channel]
    metadata : list[Metadata]
    statistics : Statistics | None
    intact : bool
        Whether the seeking (summary) path was used.
    damage : Damage | None
    first_log_time, last_log_time : int | None
        Extremes of the log times of the messages read (all topics).
    message_count : int
        Messages read (all topics).
    chunk_indexes : list of ChunkIndex
        On the intact path: the summary's chunk indexes in file order.
    chunks_walked : int
        On the intact path: how many of ``chunk_indexes`` have been read or skipped (the
        chunks from there on are still to come).
    """

    size: int
    profile: str = ""
    library: str = ""
    schemas: dict[int, Schema] = dataclasses.field(default_factory=dict)
    channels: dict[int, Channel] = dataclasses.field(default_factory=dict)
    metadata: list[Metadata] = dataclasses.field(default_factory=list)
    statistics: Statistics | None = None
    intact: bool = False
    damage: Damage | None = None
    first_log_time: int | None = None
    last_log_time: int | None = None
    message_count: int = 0
    chunk_indexes: list[ChunkIndex] = dataclasses.field(default_factory=list)
    chunks_walked: int = 0

    def on_record(self, opcode: int, body: bytes) -> None:
        if opcode == Opcode.SCHEMA:
            schema = parse_schema(body)
            self.schemas.setdefault(schema.id, schema)
        elif opcode == Opcode.CHANNEL:
            channel = parse_channel(body)
            self.channels.setdefault(channel.id, channel)

    def saw(self, block: MessageBlock) -> None:
        if not len(block):
            return
        lo, hi = int(block.log_time.min()), int(block.log_time.max())
        self.first_log_time = lo if self.first_log_time is None else min(lo, self.first_log_time)
        self.last_log_time = hi if self.last_log_time is None else max(hi, self.last_log_time)
        self.message_count += len(block)


def walk(
    f: BinaryIO,
    where: str,
    contents: FileContents,
    wanted: Callable[[FileContents, set[int]], bool] | None = None,
) -> Iterator[MessageBlock]:
    """Yield the message blocks of a file, filling ``contents`` on the way.

    Parameters
    ----------
    f : binary file
    where : str
        The file, for messages.
    contents : FileContents
        Filled with header, schemas, channels, metadata, statistics, damage.
    wanted : callable(contents, channel ids) -> bool, optional
        On the intact path, whether a chunk holding these channels must be read (all when None).
        Chunks are always read on the sequential path.

    Raises
    ------
    RecordingError
        For a file that is not MCAP, a CRC mismatch, or a corrupt chunk.
    """
    tail = probe(f, contents.size, where)
    summary = None
    if tail is not None:
        check_data_crc(f, tail, where)
    if tail is not None and tail.summary_start:
        try:
            f.seek(0)
            reader = SeekingReader(f, validate_crcs=True, record_size_limit=contents.size)
            summary = reader.get_summary()
            header = reader.get_header()
            metadata = list(reader.iter_metadata())
        except DAMAGE_ERRORS:
            summary = None
    if tail is not None and summary is not None and summary.chunk_indexes:
        contents.intact = True
        contents.profile, contents.library = header.profile, header.library
        contents.schemas.update(summary.schemas)
        contents.channels.update(summary.channels)
        contents.statistics = summary.statistics
        contents.metadata.extend(metadata)
        contents.chunk_indexes = sorted(summary.chunk_indexes,
                                        key=lambda c: c.chunk_start_offset)
        for k, index in enumerate(contents.chunk_indexes):
            contents.chunks_walked = k + 1
            ids = set(index.message_index_offsets) or set(contents.channels)
            if wanted is not None and index.message_index_offsets and not wanted(contents, ids):
                continue
            # the data-section CRC, when stored, has covered this chunk's bytes already
            block = read_chunk(f, index.chunk_start_offset, where, contents.on_record,
                               check_crc=not tail.data_crc)
            contents.saw(block)
            yield block
        return
    yield from _walk_sequential(f, where, contents, expect_complete=tail is not None)


def read_chunk(f: BinaryIO, offset: int, where: str,
               on_record: Callable[[int, bytes], None], check_crc: bool = True) -> MessageBlock:
    """The messages of the chunk at byte ``offset`` of an intact file."""
    f.seek(offset)
    try:
        opcode, _ = _RECORD.unpack(f.read(9))
        if opcode != Opcode.CHUNK:
            raise ValueError(f"opcode {opcode:#x}")
        chunk = Chunk.read(ReadDataStream(f))
    except DAMAGE_ERRORS as exc:
        raise RecordingError(
            f"{where}: chunk at byte {offset} cannot be read ({exc!r}): the file is corrupt"
        ) from None
    return scan_chunk(chunk_bytes(chunk, where, offset, check_crc=check_crc), on_record, where,
                      offset)


def _walk_sequential(
    f: BinaryIO, where: str, contents: FileContents, expect_complete: bool
) -> Iterator[MessageBlock]:
    f.seek(0)
    stream = _StreamReader(f, emit_chunks=True, validate_crcs=True, record_size_limit=contents.size)
    records = stream.records
    loose: list[Message] = []
    data_complete = False
    while True:
        try:
            record = next(records)
        except StopIteration:
            break
        except CRCValidationError as exc:
            raise RecordingError(
                f"{where}: data section CRC mismatch (stored {exc.expected:#010x}, computed "
                f"{exc.actual:#010x}): the file is corrupt"
            ) from None
        except DAMAGE_ERRORS as exc:
            if isinstance(exc, RecordLengthLimitExceeded):
                reason = "a record runs past the end of the file"
            elif isinstance(exc, EndOfFile | struct.error):
                reason = "the file ends inside a record"
            else:
                reason = f"{type(exc).__name__}: {exc}"
            contents.damage = Damage(stream.damage_offset(), reason, data_complete)
            break
        if isinstance(record, Chunk):
            offset = stream.record_start
            block = scan_chunk(
                chunk_bytes(record, where, offset), contents.on_record, where, offset
            )
            contents.saw(block)
            yield block
        elif isinstance(record, Message):
            loose.append(record)
        elif isinstance(record, Header):
            contents.profile, contents.library = record.profile, record.library
        elif isinstance(record, Schema):
            contents.schemas.setdefault(record.id, record)
        elif isinstance(record, Channel):
            contents.channels.setdefault(record.id, record)
        elif isinstance(record, Metadata):
            contents.metadata.append(record)
        elif isinstance(record, Statistics):
            contents.statistics = record
        elif isinstance(record, DataEnd):
            data_complete = True
        elif isinstance(record, Footer):
            break
    if contents.damage is None and not expect_complete:
        contents.damage = Damage(
            stream.record_end, "the file does not end with a valid footer", data_complete
        )
    if loose:
        block = loose_block(loose)
        contents.saw(block)
        yield block
