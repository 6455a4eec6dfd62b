"""Write a :class:`~navreplay.core.streams.Recording` as an MCAP file, atomically and in bulk.

Messages of all streams are merged by time (ties in :class:`StreamKind` order) and written in
windows of about :data:`WINDOW` messages: each window's messages are CDR-encoded per stream as one
numpy structured array and handed to :class:`~navreplay.io.mcapwrite.BulkWriter` (mcap's file
layout, the records assembled in bulk). Memory stays bounded by the window, not
the recording; a recording too long to hold is written from pieces in time order (``more``).
The file is written under a temporary name beside the target, fsynced, and renamed only once
complete, so the target name never shows a partial file.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
from collections.abc import Iterable
from pathlib import Path
from typing import BinaryIO

import numpy as np
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType

from navreplay import __version__
from navreplay.core.streams import Recording, Stream, StreamKind
from navreplay.io import cdr
from navreplay.io.checks import first_problem
from navreplay.io.convert import ENCODERS, AuxColumn, aux_columns, check_columns
from navreplay.io.errors import RecordingError, RecordingExistsError
from navreplay.io.mcapwrite import BulkWriter
from navreplay.io.metadata import encode_metadata
from navreplay.io.outputs import fsync_path, release, temporary_path
from navreplay.io.schemas import (
    MESSAGE_ENCODING,
    METADATA_NAME,
    PROFILE,
    SCHEMA_ENCODING,
    SPECS,
    TopicSpec,
)

WINDOW = 16_384
"""Messages encoded per window."""
CHUNK_SIZE = 1 << 20
"""Uncompressed MCAP chunk size [bytes]."""
LIBRARY = f"navreplay {__version__}; {LIBRARY_IDENTIFIER}"
"""Library string in the MCAP header."""


@dataclasses.dataclass
class _Topic:
    spec: TopicSpec
    stream: Stream
    frame_id: bytes
    layout: cdr.Layout
    aux: list[AuxColumn]


def _plan(recording: Recording, where: str, validate: bool) -> list[_Topic]:
    """Check the streams and choose their layouts, before any file is touched."""
    plan = []
    for kind, spec in SPECS.items():
        stream = recording.streams.get(kind)
        if stream is None:
            continue
        label = f"{where}: stream {kind.value} (topic {spec.topic})"
        if stream.kind is not kind:
            raise RecordingError(f"{label}: the stream's kind is {stream.kind.value}")
        try:
            check_columns(stream)
        except ValueError as exc:
            raise RecordingError(f"{where}: {exc}") from None
        if len(stream) and int(stream.t_ns.min()) < 0:
            raise RecordingError(f"{label}: negative timestamp {int(stream.t_ns.min())} ns")
        try:
            cdr.split_time(stream.t_ns[[0, -1]] if len(stream) else stream.t_ns)
        except ValueError as exc:
            raise RecordingError(f"{label}: {exc}") from None
        if validate:
            problem = first_problem(stream, recording.t0_ns)
            if problem:
                raise RecordingError(f"{label}: {problem}")
        frame_id = (stream.frame_id or spec.frame_id).encode("utf-8")
        if b"\0" in frame_id:
            raise RecordingError(f"{label}: frame_id contains a NUL character")
        aux = aux_columns(stream) if kind is StreamKind.TRUTH else []
        width = sum(c.width for c in aux)
        lay = cdr.layout(spec.message, len(frame_id) + 1, width)
        plan.append(_Topic(spec, stream, frame_id, lay, aux))
    unknown = [str(k) for k in recording.streams if StreamKind(k) not in SPECS]
    if unknown:
        raise RecordingError(f"{where}: no topic for streams {unknown}")
    return plan


def _encode(topic: _Topic, start: int, stop: int) -> np.ndarray:
    """CDR payloads of rows [start, stop) of a topic's stream, one row of bytes each."""
    part = topic.stream.slice(start, stop)
    fields = ENCODERS[topic.spec.kind](part, topic.aux)
    rec = cdr.encode(topic.layout, part.t_ns, topic.frame_id, fields)
    return rec.view(np.uint8).reshape(len(rec), topic.layout.itemsize)


def _windows(plan: list[_Topic]) -> list[tuple[int, ...]]:
    """Row boundaries per topic splitting the time-merged messages into windows."""
    total = sum(len(t.stream) for t in plan)
    if total == 0:
        return [tuple(0 for _ in plan)]
    lo = min(int(t.stream.t_ns[0]) for t in plan if len(t.stream))
    hi = max(int(t.stream.t_ns[-1]) for t in plan if len(t.stream))
    count = max(1, -(-total // WINDOW))
    edges = np.linspace(lo, hi, count + 1)[1:-1].astype(np.int64)
    bounds = [tuple(0 for _ in plan)]
    for edge in edges:
        bounds.append(tuple(int(np.searchsorted(t.stream.t_ns, edge, "left")) for t in plan))
    bounds.append(tuple(len(t.stream) for t in plan))
    return bounds


def _continued(piece: Recording, first: Recording, plan: list[_Topic], last: dict[StreamKind, int],
               where: str, validate: bool, index: int) -> list[_Topic]:
    """The plan of piece ``index`` (from 1) of a recording written in pieces: the streams,
    frame ids and columns of the first piece, on its clock, each stream after its last sample
    so far (``last``)."""
    label = f"{where}: piece {index + 1} of the recording"
    kinds = sorted(k.value for k in piece.streams)
    firsts = sorted(t.spec.kind.value for t in plan)
    if kinds != firsts:
        raise RecordingError(f"{label} has the streams {', '.join(kinds)}; the first piece has "
                             f"{', '.join(firsts)}")
    if piece.t0_ns != first.t0_ns:
        raise RecordingError(f"{label} starts its clock at {piece.t0_ns} ns, the first piece at "
                             f"{first.t0_ns} ns")
    out = _plan(piece, where, validate)
    for new, old in zip(out, plan, strict=True):
        what = f"{label}: stream {new.spec.kind.value}"
        if (new.frame_id, new.layout, [(c.name, c.shape) for c in new.aux]) != (
                old.frame_id, old.layout, [(c.name, c.shape) for c in old.aux]):
            raise RecordingError(f"{what} has another frame id or other columns than in the "
                                 "first piece")
        previous = last.get(new.spec.kind)
        if len(new.stream) and previous is not None and int(new.stream.t_ns[0]) <= previous:
            raise RecordingError(f"{what} starts at {int(new.stream.t_ns[0])} ns, not after the "
                                 f"previous piece's last sample ({previous} ns)")
    return out


def _write_mcap(out: BinaryIO, recording: Recording, plan: list[_Topic],
                more: Iterable[Recording] = (), where: str = "", validate: bool = True) -> None:
    writer = BulkWriter(
        out,
        chunk_size=CHUNK_SIZE,
        compression=CompressionType.ZSTD,
        enable_crcs=True,
        enable_data_crcs=True,
    )
    writer.start(profile=PROFILE, library=LIBRARY)
    aux = next((t.aux for t in plan if t.spec.kind is StreamKind.TRUTH), [])
    writer.add_metadata(METADATA_NAME, encode_metadata(recording.metadata, recording.t0_ns, aux))
    channel_ids = []
    for topic in plan:
        message = topic.spec.message
        schema_id = writer.register_schema(
            message.name, SCHEMA_ENCODING, message.schema_text.encode("utf-8")
        )
        channel_ids.append(writer.register_channel(topic.spec.topic, MESSAGE_ENCODING, schema_id))
    last: dict[StreamKind, int] = {}
    for index, piece in enumerate(itertools.chain([recording], more)):
        part = plan if index == 0 else _continued(piece, recording, plan, last, where, validate,
                                                   index)
        bounds = _windows(part)
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            writer.add_messages([(cid, topic.stream.t_ns[a:b], _encode(topic, a, b))
                                 for topic, cid, a, b in zip(part, channel_ids, lo, hi,
                                                             strict=True)
                                 if b > a])
        last.update((t.spec.kind, int(t.stream.t_ns[-1])) for t in part if len(t.stream))
    writer.finish()


def write_recording(
    path: str | os.PathLike[str],
    recording: Recording,
    *,
    force: bool = False,
    validate: bool = True,
    more: Iterable[Recording] = (),
) -> Path:
    """Write a recording as an MCAP file (ROS 2 profile, CDR), atomically.

    Parameters
    ----------
    path : path-like
        Target file; missing parent directories are created.
    recording : Recording
        Streams of the kinds in :data:`~navreplay.io.schemas.TOPICS`, with their standard columns
        (``omega_ib_b`` of the IMU, ``pos_sigma`` and ``vel_sigma`` are optional); the truth stream
        may carry extra columns. An empty ``metadata.navreplay_version`` is written as the running
        version.
    force : bool
        Replace an existing file.
    validate : bool
        Refuse non-finite samples and timestamps that repeat or go backwards (a file with them
        would not read back with validation on).
    more : iterable of Recording
        Further pieces of the recording, in time order, made one at a time while the file is
        written (a recording too long to hold at once): the streams, frame ids and columns of
        ``recording``, on its clock (``t0_ns``), each stream's samples after its previous
        piece's; their metadata is not written.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    RecordingExistsError
        If the target exists and ``force`` is False.
    RecordingError
        If a stream cannot be written (missing columns, bad samples, times outside the message
        range, a piece that does not continue the recording). Nothing is written then; a
        failure while writing leaves no file under the target name and an existing one
        untouched.
    """
    target = Path(path)
    where = str(target)
    plan = _plan(recording, where, validate)
    if target.exists() and not force:
        raise RecordingExistsError(
            f"{where}: file exists; use --force (force=True) to replace it")
    tmp = temporary_path(target)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0),
                     0o666)
        with os.fdopen(fd, "wb") as out:
            _write_mcap(out, recording, plan, more, where, validate)
            out.flush()
            os.fsync(out.fileno())
        _commit(tmp, target, force)
    finally:
        release(tmp)
    fsync_path(target.parent)
    return target


def _commit(tmp: Path, target: Path, force: bool) -> None:
    """Move the finished temporary file to the target name."""
    if force:
        os.replace(tmp, target)
        return
    try:
        os.link(tmp, target)  # fails if the target appeared meanwhile, unlike rename
    except FileExistsError:
        raise RecordingExistsError(
            f"{target}: file exists; use --force (force=True) to replace it"
        ) from None
    except OSError:  # no hard links on this file system
        if target.exists():
            raise RecordingExistsError(
                f"{target}: file exists; use --force (force=True) to replace it"
            ) from None
        os.replace(tmp, target)
        return
    tmp.unlink()
