"""The channels of an MCAP file decoded block by block into the fields of their streams.

Payloads are decoded chunk by chunk: equally long payloads with one fixed layout are viewed as a
numpy structured array; anything else goes through mcap-ros2-support's generic decoder. Decoded
fields are reduced at once to what the columns need, so memory stays close to the size of the
resulting columns. :class:`Decoding` decides which channels to decode as they become known
(:func:`navreplay.io.topics.candidate`); a :class:`ChannelDecoder` accumulates one channel's
fields until they are taken as a window (:meth:`ChannelDecoder.drain`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from mcap.records import Channel, Schema

from navreplay.core.streams import Metadata, StreamKind
from navreplay.io import cdr
from navreplay.io.convert import REDUCE, AuxColumn
from navreplay.io.errors import RecordingError
from navreplay.io.mcapfile import FileContents, MessageBlock
from navreplay.io.metadata import decode_metadata
from navreplay.io.schemas import (
    KIND_BY_TYPE,
    METADATA_NAME,
    SPECS,
    MessageType,
    normalize_type_name,
)
from navreplay.io.topics import Candidate, candidate, decodable


class ChannelDecoder:
    """Decoded fields of one channel, accumulated block by block."""

    def __init__(self, channel: Channel, schema: Schema | None, message: MessageType, where: str):
        self.channel = channel
        self.schema = schema
        self.message = message
        self.where = where
        self.reduce = REDUCE[KIND_BY_TYPE[message.name]]
        self.parts: list[dict[str, np.ndarray]] = []
        self.frame_ids: set[str] = set()
        self.first_frame_id: str | None = None  # of the earliest message in file order
        self._first_ordinal = -1
        self._generic: cdr.GenericDecoder | None = None
        self.ordinals: list[int | np.ndarray] = []
        self.log_times: list[np.ndarray | None] = []
        self.in_order = True
        self._next = 0
        self._count = 0
        self.log_ns: np.ndarray | None = None  # log times of finish()'s rows

    @property
    def label(self) -> str:
        return f"{self.where}: topic {self.channel.topic} ({self.message.name})"

    @property
    def count(self) -> int:
        """Messages decoded so far."""
        return self._count

    def add(self, block: MessageBlock, index: np.ndarray) -> None:
        """Decode messages ``index`` of a block (all of this channel)."""
        ordinal = self._count + np.arange(len(index), dtype=np.int64)
        self._count += len(index)
        lengths = block.length[index]
        if not lengths.size:
            return
        if lengths.min() == lengths.max():  # the usual case: one fixed layout
            self._add_equal(block, index, ordinal, int(lengths[0]))
            return
        for width in np.unique(lengths):
            sel = np.flatnonzero(lengths == width)
            self._add_equal(block, index[sel], ordinal[sel], int(width))

    def _add_equal(self, block: MessageBlock, index: np.ndarray, ordinal: np.ndarray, width: int):
        groups, rest = cdr.decode_fixed(block.rows(index, width), self.message)
        for take, fields in groups:
            self._keep(fields, block, index[take], ordinal[take])
        if rest.size:
            payloads = [block.payload(int(i)) for i in index[rest]]
            self._keep(self._decode_generic(payloads), block, index[rest], ordinal[rest])

    def _decode_generic(self, payloads: list[bytes]) -> dict[str, np.ndarray]:
        try:
            if self._generic is None:
                if self.schema is None:
                    raise RecordingError("the channel has no schema")
                self._generic = cdr.GenericDecoder(self.schema)
            return self._generic.decode(payloads, self.message)
        except RecordingError as exc:
            raise RecordingError(f"{self.label}: {exc}") from None
        except Exception as exc:  # the generic decoder raises many types on foreign data
            raise RecordingError(
                f"{self.label}: messages do not decode with schema "
                f"{self.schema.name if self.schema else None!r} ({exc!r})"
            ) from None

    def _keep(
        self,
        fields: dict[str, np.ndarray],
        block: MessageBlock,
        index: np.ndarray,
        ordinal: np.ndarray,
    ) -> None:
        frames = fields["frame_id"]
        if len(frames):
            if self.first_frame_id is None or ordinal[0] < self._first_ordinal:
                self.first_frame_id, self._first_ordinal = str(frames[0]), int(ordinal[0])
            if (frames == frames[0]).all():
                self.frame_ids.add(frames[0])
            else:
                self.frame_ids.update(frames.tolist())
        t_ns = np.asarray(fields["t_ns"], dtype=np.int64)
        part = {"t_ns": t_ns}
        for name, columns in self.reduce.items():
            value = np.asarray(fields[name])
            part[name] = np.array(value if columns is None else value[:, columns])
        self.parts.append(part)
        m = len(ordinal)
        if m and ordinal[0] == self._next and ordinal[-1] == self._next + m - 1:
            self.ordinals.append(int(ordinal[0]))
        else:
            self.ordinals.append(ordinal)
            self.in_order = False
        if m:
            self._next = int(ordinal[-1]) + 1
        log_time = block.log_time[index]
        if np.array_equal(log_time, t_ns):
            self.log_times.append(None)
        else:
            self.log_times.append(log_time)

    def drain(self) -> dict[str, np.ndarray]:
        """:meth:`finish` the rows so far and start afresh (a time window of the topic)."""
        out = self.finish()
        self.ordinals.clear()
        self.log_times.clear()
        self.in_order = True
        return out

    def rows(self) -> int:
        """Rows decoded and not yet finished."""
        return sum(len(p["t_ns"]) for p in self.parts)

    def finish(self) -> dict[str, np.ndarray]:
        """Concatenated fields in log-time order (file order among equal log times)."""
        if not self.parts:
            return {
                "t_ns": np.zeros(0, np.int64),
                **{
                    name: empty_leaf(self.message, name, columns)
                    for name, columns in self.reduce.items()
                },
            }
        log_time = None
        if any(lt is not None for lt in self.log_times):
            log_time = np.concatenate(
                [
                    p["t_ns"] if lt is None else lt
                    for p, lt in zip(self.parts, self.log_times, strict=True)
                ]
            )
        ordinal = None
        if not self.in_order:
            ordinal = np.concatenate(
                [
                    np.arange(o, o + len(p["t_ns"])) if isinstance(o, int) else o
                    for p, o in zip(self.parts, self.ordinals, strict=True)
                ]
            )
        out: dict[str, np.ndarray] = {}
        try:
            for key in list(self.parts[0]):  # concatenate key by key, freeing the parts
                out[key] = np.concatenate([p.pop(key) for p in self.parts])
        except (KeyError, ValueError) as exc:
            raise RecordingError(f"{self.label}: message layout changes ({exc!r})") from None
        self.parts.clear()
        if log_time is None:
            log_time = out["t_ns"]
        order = None
        if ordinal is not None:
            order = np.argsort(ordinal, kind="stable")
            log_time = log_time[order]
        if np.any(np.diff(log_time) < 0):
            by_time = np.argsort(log_time, kind="stable")
            order = by_time if order is None else order[by_time]
        if order is not None:
            out = {k: v[order] for k, v in out.items()}
        self.log_ns = log_time
        return out


def empty_leaf(message: MessageType, name: str, columns: list[int] | None) -> np.ndarray:
    leaves = {leaf.name: leaf for leaf in message.leaves}
    if message.sequence is not None:
        leaves[message.sequence.name] = dataclasses.replace(message.sequence, count=0)
    leaf = leaves[name]
    width = leaf.count if columns is None else len(columns)
    shape = (0,) if leaf.count == 1 and columns is None else (0, width)
    return np.zeros(shape, dtype=np.dtype(leaf.ctype))


class Decoding:
    """Which channels of a file to decode (those that could feed a wanted stream), decided as
    channels become known, and their decoders."""

    def __init__(self, where: str, wanted: set[StreamKind], topic_kinds: dict[str, StreamKind]):
        self.where = where
        self.wanted = wanted
        self.topic_kinds = topic_kinds
        self.candidates: dict[int, Candidate | None] = {}
        self.decoders: dict[int, ChannelDecoder] = {}

    def decoder(self, contents: FileContents, channel_id: int) -> ChannelDecoder | None:
        """The decoder of a channel (None: not decoded)."""
        channel = contents.channels.get(channel_id)
        if channel_id not in self.candidates and channel is not None:
            schema = contents.schemas.get(channel.schema_id)
            type_name = normalize_type_name(schema.name) if schema is not None else ""
            cand = candidate(channel.topic, type_name, channel.message_encoding,
                             self.topic_kinds)
            if cand is not None and cand.kind not in self.wanted:
                cand = None
            self.candidates[channel_id] = cand
            if cand is not None and decodable(cand):
                self.decoders[channel_id] = ChannelDecoder(channel, schema,
                                                           SPECS[cand.kind].message, self.where)
        return self.decoders.get(channel_id)

    def wants_chunk(self, contents: FileContents, channel_ids: set[int]) -> bool:
        return any(self.decoder(contents, c) is not None for c in channel_ids)

    def feed(self, contents: FileContents, block: MessageBlock) -> None:
        if not len(block):
            return
        channels = block.channel
        for cid in np.unique(channels):
            decoder = self.decoder(contents, int(cid))
            if decoder is not None:
                decoder.add(block, np.flatnonzero(channels == cid))

    def all_candidates(self, contents: FileContents) -> list[Candidate]:
        """The candidates among every channel the file has shown so far."""
        for cid in contents.channels:
            self.decoder(contents, cid)
        return [c for c in self.candidates.values() if c is not None]

    def decoder_of(self, c: Candidate) -> ChannelDecoder:
        """The decoder of a chosen candidate."""
        return next(self.decoders[cid] for cid, cand in self.candidates.items() if cand is c)


def describe_topics(contents: FileContents) -> str:
    """The file's topics and their types, for messages."""
    items = []
    for ch in sorted(contents.channels.values(), key=lambda c: c.topic):
        schema = contents.schemas.get(ch.schema_id)
        items.append(f"{ch.topic} ({schema.name if schema else 'no schema'})")
    return ", ".join(items) or "no topics"


def file_metadata(contents: FileContents, where: str) -> tuple[Metadata, int, list[AuxColumn]]:
    """The recording's metadata, start [ns] and auxiliary columns: the ``navreplay`` record,
    else ``Metadata()`` starting at the first message (by the statistics of an intact file)."""
    records = [m for m in contents.metadata if m.name == METADATA_NAME]
    meta, t0_ns, aux = Metadata(), None, list[AuxColumn]()
    if records:
        meta, t0_ns, aux = decode_metadata(records[-1].metadata, where)
    if t0_ns is None:
        stats = contents.statistics
        if contents.intact and stats is not None and stats.message_count:
            t0_ns = int(stats.message_start_time)
        else:
            t0_ns = contents.first_log_time or 0
    return meta, t0_ns, aux
