"""``nav_msgs/msg/Odometry`` messages encoded in bulk (CDR, one numpy record per message) and
the MCAP that holds them, written in time order across topics."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.export.frames import BODY_FRAME, WORLD_FRAME, Poses

ODOMETRY_TYPE = "nav_msgs/msg/Odometry"


_SEP = "=" * 80


_ODOMETRY_SCHEMA = "\n".join([
    "std_msgs/Header header",
    "string child_frame_id",
    "geometry_msgs/PoseWithCovariance pose",
    "geometry_msgs/TwistWithCovariance twist",
    _SEP, "MSG: std_msgs/Header",
    "builtin_interfaces/Time stamp",
    "string frame_id",
    _SEP, "MSG: builtin_interfaces/Time",
    "int32 sec",
    "uint32 nanosec",
    _SEP, "MSG: geometry_msgs/PoseWithCovariance",
    "geometry_msgs/Pose pose",
    "float64[36] covariance",
    _SEP, "MSG: geometry_msgs/Pose",
    "geometry_msgs/Point position",
    "geometry_msgs/Quaternion orientation",
    _SEP, "MSG: geometry_msgs/Point",
    "float64 x", "float64 y", "float64 z",
    _SEP, "MSG: geometry_msgs/Quaternion",
    "float64 x", "float64 y", "float64 z", "float64 w",
    _SEP, "MSG: geometry_msgs/TwistWithCovariance",
    "geometry_msgs/Twist twist",
    "float64[36] covariance",
    _SEP, "MSG: geometry_msgs/Twist",
    "geometry_msgs/Vector3 linear",
    "geometry_msgs/Vector3 angular",
    _SEP, "MSG: geometry_msgs/Vector3",
    "float64 x", "float64 y", "float64 z",
]) + "\n"
"""ros2msg schema text of nav_msgs/msg/Odometry with its dependencies."""


def _aligned(pos: int, size: int) -> int:
    """Next offset aligned to ``size``, counted after the 4-byte encapsulation header."""
    return 4 + -(-(pos - 4) // size) * size


def odometry_dtype(frame_len: int, child_len: int) -> np.dtype:
    """Fixed CDR layout of nav_msgs/msg/Odometry for frame ids of the given byte lengths (NUL
    included): one numpy record per message (see :mod:`navreplay.io.cdr`)."""
    names = ["encap", "sec", "nanosec", "frame_len", "frame_id"]
    formats: list[Any] = [("u1", (4,)), "<i4", "<u4", "<u4", f"S{frame_len}"]
    offsets = [0, 4, 8, 12, 16]
    pos = _aligned(16 + frame_len, 4)
    names += ["child_len", "child_frame_id"]
    formats += ["<u4", f"S{child_len}"]
    offsets += [pos, pos + 4]
    pos = _aligned(pos + 4 + child_len, 8)
    for name, count in (("position", 3), ("orientation", 4), ("pose_covariance", 36),
                        ("linear", 3), ("angular", 3), ("twist_covariance", 36)):
        names.append(name)
        formats.append(("<f8", (count,)))
        offsets.append(pos)
        pos += 8 * count
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": pos})


def encode_odometry(poses: Poses, frame_id: str = WORLD_FRAME,
                    child_frame_id: str = BODY_FRAME) -> np.ndarray:
    """CDR records (M,) of nav_msgs/msg/Odometry; ``rec[i].tobytes()`` is message i."""
    from navreplay.io.cdr import ENCAPSULATION_LE, split_time

    f, c = frame_id.encode(), child_frame_id.encode()
    rec = np.zeros(len(poses.stamps_ns), dtype=odometry_dtype(len(f) + 1, len(c) + 1))
    rec["encap"] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)
    rec["sec"], rec["nanosec"] = split_time(poses.stamps_ns)
    rec["frame_len"], rec["frame_id"] = len(f) + 1, f
    rec["child_len"], rec["child_frame_id"] = len(c) + 1, c
    rec["position"] = poses.p_enu
    rec["orientation"] = poses.q_xyzw
    rec["pose_covariance"] = poses.pose_cov.reshape(-1, 36)
    rec["linear"] = poses.v_flu
    rec["twist_covariance"] = poses.twist_cov.reshape(-1, 36)
    return rec


COMPRESSIONS = ("zstd", "lz4", "none")
"""Chunk compressions of the estimates MCAP (``--export-compression``): zstd by default;
``none`` for readers without a decompressor (Foxglove's npm MCAP reader needs one passed)."""

ZSTD_LEVEL = -1
"""zstd level of the estimates MCAP: the first of zstd's fast levels (every zstd decoder reads
them). On the Odometry, NavSatFix and /tf messages of a drive at 100 Hz it compresses in 0.55x
the time of zstd's default level 3 (0.78x that of level 1) into 5 % more bytes (2 % more than
level 1), and decompresses faster."""


class OdometryWriter:
    """The estimates MCAP, written as the poses come: messages of all streams in time order
    (ties in the order the streams were registered), each stream's poses handed over in time
    order.

    A stream is an Odometry topic (a name) or a :class:`navreplay.export.foxglove.Topic`
    (NavSatFix, the /tf of one filter: several streams may share a topic). A message is written
    once every stream has poses later than it; the rest wait (a window's worth), :meth:`finish`
    writes them all. The ``late`` streams (of runs whose poses all come after the others', the
    smoothed runs) are written as they come, after the others' up to then: nothing waits for
    them.
    """

    def __init__(self, path: Path, topics: Sequence[Any], late: Sequence[str] = (),
                 compression: str = "zstd") -> None:
        from mcap.writer import CompressionType

        from navreplay.io.mcapwrite import BulkWriter
        from navreplay.io.schemas import MESSAGE_ENCODING, PROFILE, SCHEMA_ENCODING
        from navreplay.io.writer import LIBRARY

        self._file = open(path, "wb")  # noqa: SIM115 (closed by finish or close)
        self._w = BulkWriter(self._file, compression=CompressionType[compression.upper()],
                             zstd_level=ZSTD_LEVEL)
        self._w.start(profile=PROFILE, library=LIBRARY)
        schemas: dict[str, int] = {}
        channels: dict[str, int] = {}
        self._ids: dict[str, int] = {}
        self._encode: dict[str, Any] = {}
        for t in topics:
            key, name, kind, text, encode = ((t, t, ODOMETRY_TYPE, _ODOMETRY_SCHEMA,
                                              encode_odometry) if isinstance(t, str)
                                             else (t.key, t.name, t.type, t.schema, t.encode))
            if kind not in schemas:
                schemas[kind] = self._w.register_schema(kind, SCHEMA_ENCODING, text.encode())
            if name not in channels:
                channels[name] = self._w.register_channel(name, MESSAGE_ENCODING, schemas[kind])
            self._ids[key] = channels[name]
            self._encode[key] = encode
        topics = list(self._ids)
        # per topic: (stamps, CDR messages as rows of bytes) not yet written
        self._queue: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {t: [] for t in topics}
        self._late = frozenset(late)
        self._last: dict[str, int | None] = dict.fromkeys(t for t in topics if t not in late)

    def add(self, topic: str, poses: Poses) -> None:
        if not len(poses.stamps_ns):
            return
        rec = self._encode[topic](poses)  # as rows of bytes (concatenating records repacks them)
        rows = rec.view(np.uint8).reshape(len(rec), rec.dtype.itemsize)
        if topic in self._late:
            self._w.add_messages([(self._ids[topic], poses.stamps_ns, rows)])
            return
        self._queue[topic].append((poses.stamps_ns, rows))
        self._last[topic] = int(poses.stamps_ns[-1])
        stamps = [v for v in self._last.values() if v is not None]
        if len(stamps) == len(self._last):
            self._write(min(stamps))

    def _write(self, limit: int | None) -> None:
        """Write the queued messages earlier than ``limit`` (all with None)."""
        batches = []  # in the order of the topics, one per topic
        for topic, queue in self._queue.items():
            kept, ready = [], []
            for t, rows in queue:
                n = t.shape[0] if limit is None else int(np.searchsorted(t, limit, side="left"))
                if n:
                    ready.append((t[:n], rows[:n]))
                if n < t.shape[0]:
                    kept.append((t[n:], rows[n:]))
            self._queue[topic] = kept
            if ready:  # one batch: streams at the same times are then merged without a gather
                batches.append((self._ids[topic],
                                *((ready[0][0], ready[0][1]) if len(ready) == 1 else
                                  (np.concatenate([t for t, _ in ready]),
                                   np.concatenate([r for _, r in ready])))))
        self._w.add_messages(batches)

    def finish(self) -> None:
        self._write(None)
        self._w.finish()
        self._file.close()

    def close(self) -> None:
        self._file.close()
