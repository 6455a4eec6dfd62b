"""ROS 2 CDR in bulk: fixed message layouts as numpy structured dtypes.

A message whose every field has a fixed size once its ``header.frame_id`` length (and, for a
trailing ``float64[]``, that length) is fixed, is one numpy record: encoding N messages is filling
an (N,) structured array and taking its bytes; decoding is viewing N equally long payloads as that
dtype. The bytes equal those of the generic ROS 2 serializer:

* a 4-byte encapsulation header ``00 01 00 00`` (CDR, little endian);
* every primitive aligned to its size, counted from *after* the encapsulation header, with zero
  padding;
* strings as uint32 length (including the terminating NUL), the bytes, NUL;
* sequences as uint32 element count, then the elements (no padding when empty).

Messages that do not fit a fixed layout (another frame_id length, big-endian data, a foreign
variant) go through :func:`decode_generic`, which uses mcap-ros2-support's dynamic decoder.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from mcap.records import Schema

from navreplay.io.errors import RecordingError
from navreplay.io.schemas import MessageType

ENCAPSULATION_LE = bytes((0, 1, 0, 0))
"""CDR encapsulation header: plain CDR, little endian."""
_NS_PER_S = 1_000_000_000
_INT32_MIN = -(2**31)
_INT32_MAX = 2**31 - 1


def _align(pos: int, size: int) -> int:
    """Offset of the next value of ``size`` bytes at or after ``pos`` (header excluded)."""
    rel = pos - 4
    return 4 + -(-rel // size) * size


@dataclasses.dataclass(frozen=True)
class Layout:
    """The fixed byte layout of one message type for one frame_id length and sequence length.

    Attributes
    ----------
    message : MessageType
    frame_len : int
        Bytes of ``header.frame_id`` on the wire, including the terminating NUL.
    seq_len : int
        Elements of the trailing ``float64[]`` (0 when the type has none).
    dtype : numpy.dtype
        Structured dtype of one whole message (encapsulation header included). Fields:
        ``encap`` (u1, 4), ``sec`` (i4), ``nanosec`` (u4), ``frame_len`` (u4), ``frame_id``
        (S<frame_len>), one per leaf, and ``seq_len`` (u4) / ``<sequence name>`` for a sequence.
    """

    message: MessageType
    frame_len: int
    seq_len: int
    dtype: np.dtype

    @property
    def itemsize(self) -> int:
        """Bytes of one message."""
        return int(self.dtype.itemsize)


@functools.lru_cache(maxsize=256)
def layout(message: MessageType, frame_len: int, seq_len: int = 0) -> Layout:
    """The fixed layout of ``message`` with a frame_id of ``frame_len`` bytes (NUL included).

    Parameters
    ----------
    message : MessageType
    frame_len : int
        ``len(frame_id.encode()) + 1``.
    seq_len : int
        Length of the trailing sequence (must be 0 for a type without one).
    """
    if frame_len < 1:
        raise ValueError("frame_len counts the terminating NUL and is at least 1")
    if seq_len and message.sequence is None:
        raise ValueError(f"{message.name} has no sequence field")
    names: list[str] = ["encap", "sec", "nanosec", "frame_len", "frame_id"]
    formats: list[Any] = [("u1", (4,)), "<i4", "<u4", "<u4", f"S{frame_len}"]
    offsets: list[int] = [0, 4, 8, 12, 16]
    pos = 16 + frame_len
    for leaf in message.leaves:
        pos = _align(pos, leaf.size)
        names.append(leaf.name)
        fmt = f"<{leaf.ctype}" if leaf.size > 1 else leaf.ctype
        formats.append(fmt if leaf.count == 1 else (fmt, (leaf.count,)))
        offsets.append(pos)
        pos += leaf.size * leaf.count
    if message.sequence is not None:
        pos = _align(pos, 4)
        names.append("seq_len")
        formats.append("<u4")
        offsets.append(pos)
        pos += 4
        if seq_len:
            seq = message.sequence
            pos = _align(pos, seq.size)
            names.append(seq.name)
            formats.append((f"<{seq.ctype}", (seq_len,)))
            offsets.append(pos)
            pos += seq.size * seq_len
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": pos})
    return Layout(message, frame_len, seq_len, dtype)


def split_time(t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``builtin_interfaces/Time`` (sec, nanosec) of int64 nanoseconds.

    Raises
    ------
    ValueError
        If a time does not fit the int32 seconds of the message.
    """
    t_ns = np.asarray(t_ns, dtype=np.int64)
    sec = np.floor_divide(t_ns, _NS_PER_S)
    if sec.size and (sec.min() < _INT32_MIN or sec.max() > _INT32_MAX):
        raise ValueError("time outside the int32 seconds of builtin_interfaces/Time")
    return sec.astype(np.int32), (t_ns - sec * _NS_PER_S).astype(np.uint32)


def join_time(sec: np.ndarray, nanosec: np.ndarray) -> np.ndarray:
    """int64 nanoseconds of ``builtin_interfaces/Time`` (sec, nanosec)."""
    return np.asarray(sec, dtype=np.int64) * _NS_PER_S + np.asarray(nanosec, dtype=np.int64)


def encode(
    lay: Layout, t_ns: np.ndarray, frame_id: bytes, fields: Mapping[str, np.ndarray]
) -> np.ndarray:
    """Encode messages into an (N,) structured array of ``lay.dtype``; ``.tobytes()`` is the CDR.

    Parameters
    ----------
    lay : Layout
        Its ``frame_len`` must equal ``len(frame_id) + 1``.
    t_ns : ndarray, shape (N,), int64
        Header stamps [ns].
    frame_id : bytes
        UTF-8 ``header.frame_id`` without NUL.
    fields : mapping of str to ndarray
        One array per leaf (and the sequence), shape (N, count) or broadcastable to it.
    """
    n = len(t_ns)
    rec = np.zeros(n, dtype=lay.dtype)
    rec["encap"] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)
    rec["sec"], rec["nanosec"] = split_time(t_ns)
    rec["frame_len"] = lay.frame_len
    rec["frame_id"] = frame_id
    for leaf in lay.message.leaves:
        rec[leaf.name] = fields[leaf.name]
    seq = lay.message.sequence
    if seq is not None:
        rec["seq_len"] = lay.seq_len
        if lay.seq_len:
            rec[seq.name] = fields[seq.name]
    return rec


def records_to_fields(rec: np.ndarray, message: MessageType) -> dict[str, np.ndarray]:
    """Fields of bulk-decoded records, in the form :func:`decode_generic` returns.

    Returns
    -------
    dict of str to ndarray
        ``t_ns`` (N,) int64, ``frame_id`` (N,) object (str), and one array per leaf, shape (N,) or
        (N, count); the sequence, shape (N, seq_len), when the type has one.
    """
    out: dict[str, np.ndarray] = {"t_ns": join_time(rec["sec"], rec["nanosec"])}
    out["frame_id"] = _frame_ids(rec["frame_id"])
    for leaf in message.leaves:
        out[leaf.name] = rec[leaf.name]
    seq = message.sequence
    if seq is not None:
        if seq.name in (rec.dtype.names or ()):
            out[seq.name] = rec[seq.name]
        else:
            out[seq.name] = np.zeros((len(rec), 0))
    return out


def _frame_ids(raw: np.ndarray) -> np.ndarray:
    out = np.empty(len(raw), dtype=object)
    if len(raw) and (raw == raw[0]).all():  # one frame id throughout: no sort
        out[:] = raw[0].decode("utf-8", "replace")
    elif len(raw):
        uniq, inverse = np.unique(raw, return_inverse=True)
        out[:] = np.array([u.decode("utf-8", "replace") for u in uniq], dtype=object)[inverse]
    return out


def peek_layout(rows: np.ndarray, message: MessageType) -> Layout | None:
    """The layout the first of equally long payloads claims, if it is a fixed one.

    Parameters
    ----------
    rows : ndarray, shape (N, L), uint8
        N message payloads of L bytes each.
    message : MessageType

    Returns
    -------
    Layout | None
        None when the payload is not little-endian CDR or its claimed lengths do not add up to L.
    """
    n, size = rows.shape
    if n == 0 or size < 16 or rows[0, 0] != 0 or rows[0, 1] != 1:
        return None
    frame_len = int(rows[0, 12:16].view("<u4")[0])
    if frame_len < 1 or 16 + frame_len > size:
        return None
    seq_len = 0
    if message.sequence is not None:
        base = layout(message, frame_len, 0)
        at = base.dtype.fields["seq_len"][1]  # type: ignore[index]
        if at + 4 > size:
            return None
        seq_len = int(rows[0, at : at + 4].view("<u4")[0])
    if seq_len > size:
        return None
    lay = layout(message, frame_len, seq_len)
    return lay if lay.itemsize == size else None


def matches_layout(rows: np.ndarray, lay: Layout) -> np.ndarray:
    """Which payloads (N, L) uint8 share ``lay``'s encapsulation, frame_id length and sequence
    length.

    Returns
    -------
    ndarray, shape (N,), bool
    """
    ok = (rows[:, 0] == 0) & (rows[:, 1] == 1)
    ok &= np.ascontiguousarray(rows[:, 12:16]).view("<u4")[:, 0] == lay.frame_len
    if lay.message.sequence is not None:
        at = lay.dtype.fields["seq_len"][1]  # type: ignore[index]
        ok &= np.ascontiguousarray(rows[:, at : at + 4]).view("<u4")[:, 0] == lay.seq_len
    return ok


def view_records(rows: np.ndarray, lay: Layout) -> np.ndarray:
    """(N,) records of ``lay.dtype`` over N contiguous payloads (N, lay.itemsize) uint8."""
    rows = np.ascontiguousarray(rows)
    return rows.view(lay.dtype).reshape(len(rows))


def decode_fixed(
    rows: np.ndarray, message: MessageType
) -> tuple[list[tuple[np.ndarray, dict[str, np.ndarray]]], np.ndarray]:
    """Decode equally long payloads by their fixed layouts, as far as they have one.

    Parameters
    ----------
    rows : ndarray, shape (N, L), uint8
        N message payloads of L bytes each.
    message : MessageType

    Returns
    -------
    groups : list of (ndarray, dict)
        The rows of each layout met (indices into ``rows``, in order) and their fields
        (:func:`records_to_fields`).
    rest : ndarray of int
        The rows left from the first one whose layout is not a fixed one (for the generic
        decoder), in order.
    """
    groups: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []
    remaining = np.arange(len(rows))
    while remaining.size:
        lay = peek_layout(rows[remaining[:1]], message)
        if lay is None:
            break
        sub = rows if remaining.size == len(rows) else rows[remaining]
        ok = matches_layout(sub, lay)  # true for the first row, which defined `lay`
        take = remaining[ok]
        records = view_records(rows[take] if take.size != len(rows) else rows, lay)
        groups.append((take, records_to_fields(records, message)))
        remaining = remaining[~ok]
    return groups, remaining


def decode_payloads(
    payloads: Sequence[bytes], message: MessageType,
    generic: Callable[[np.ndarray], dict[str, np.ndarray]],
) -> dict[str, np.ndarray]:
    """The fields (:func:`records_to_fields`) of CDR payloads in their order: those of a fixed
    layout viewed in bulk (:func:`decode_fixed`, per payload length), the others decoded by
    ``generic`` (the indices of those payloads, in order -> their fields)."""
    lengths = np.fromiter((len(p) for p in payloads), dtype=np.int64, count=len(payloads))
    parts: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []
    for width in np.unique(lengths).tolist():
        index = np.flatnonzero(lengths == width)
        data = b"".join(payloads[i] for i in index.tolist())
        rows = np.frombuffer(data, dtype=np.uint8).reshape(len(index), width)
        groups, rest = decode_fixed(rows, message)
        parts += [(index[take], fields) for take, fields in groups]
        if rest.size:
            parts.append((index[rest], generic(index[rest])))
    if len(parts) == 1:
        return parts[0][1]
    if not parts:
        return generic(np.zeros(0, dtype=np.int64))
    order = np.argsort(np.concatenate([i for i, _ in parts]), kind="stable")
    return {name: np.concatenate([f[name] for _, f in parts])[order] for name in parts[0][1]}


# ---------------------------------------------------------------------------------------------
# Generic path


class GenericDecoder:
    """Decode messages one by one through mcap-ros2-support, for payloads no fixed layout fits.

    Parameters
    ----------
    schema : mcap.records.Schema
        The file's schema of the channel (its own definition is used, not navreplay's).
    """

    def __init__(self, schema: Schema) -> None:
        from mcap_ros2.decoder import DecoderFactory

        decode = DecoderFactory().decoder_for("cdr", schema)
        if decode is None:
            raise RecordingError(f"no ROS 2 decoder for schema {schema.name!r}")
        self._decode = decode

    def decode(self, payloads: Sequence[bytes], message: MessageType) -> dict[str, np.ndarray]:
        """Decode payloads into the fields of :func:`records_to_fields`.

        Raises
        ------
        RecordingError
            If a message lacks a field of ``message`` or has sequences of different lengths.
        """
        return fields_of_messages([self._decode(p) for p in payloads], message)


def fields_of_messages(msgs: Sequence[Any], message: MessageType) -> dict[str, np.ndarray]:
    """The fields of :func:`records_to_fields` gathered from decoded message objects (of
    mcap-ros2-support or rosbags), by the leaf paths of ``message``.

    Raises
    ------
    RecordingError
        If the messages have sequences of different lengths; AttributeError if one lacks a
        field.
    """
    msgs = list(msgs)
    n = len(msgs)
    out: dict[str, np.ndarray] = {
        "t_ns": np.array(
            [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in msgs],
            dtype=np.int64,
        ),
        "frame_id": np.array([m.header.frame_id for m in msgs], dtype=object),
    }
    for leaf in message.leaves:
        out[leaf.name] = _gather(msgs, leaf.paths, leaf.count, leaf.ctype)
    seq = message.sequence
    if seq is not None:
        lengths = {len(_get(m, seq.paths[0])) for m in msgs}
        if len(lengths) > 1:
            raise RecordingError(
                f"{message.name}: field {seq.name!r} changes length between messages "
                f"({sorted(lengths)})"
            )
        width = lengths.pop() if lengths else 0
        out[seq.name] = np.array(
            [list(_get(m, seq.paths[0])) for m in msgs], dtype=np.float64
        ).reshape(n, width)
    return out


def _get(obj: Any, path: str) -> Any:
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def _gather(msgs: list[Any], paths: tuple[str, ...], count: int, ctype: str) -> np.ndarray:
    if len(paths) == count:
        values = [[_get(m, p) for p in paths] for m in msgs]
    else:
        values = [list(_get(m, paths[0])) for m in msgs]
    arr = np.array(values, dtype=np.dtype(ctype)).reshape(len(msgs), count)
    return arr[:, 0] if count == 1 else arr
