"""Which topic feeds which stream, and how a topic's decoded fields become a checked stream:
what every kind of recording file shares (:mod:`navreplay.io.mcapread` for MCAP files,
:mod:`navreplay.io.rosbag` for rosbag2 bags).

Topics map to stream kinds by name (:data:`~navreplay.io.schemas.TOPICS`, replaced kind by
kind with ``--topic KIND=TOPIC``), or, in a recording from elsewhere, by message type when
exactly one topic carries it (:func:`choose_topics`). Sample times are the header stamps or
the log times (:func:`sample_times`); :func:`build_stream` converts the fields of one topic
into a :class:`~navreplay.core.streams.Stream` in navreplay's conventions and checks it.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Iterable, Mapping

import numpy as np

from navreplay.core.streams import Stream, StreamKind
from navreplay.io.checks import first_problem, gap_report
from navreplay.io.convert import DECODERS, AuxColumn, Convention
from navreplay.io.errors import RecordingError, RecordingWarning
from navreplay.io.schemas import KIND_BY_TYPE, MESSAGE_ENCODING, SPECS

TopicNames = Mapping[StreamKind, str] | Mapping[str, str] | Mapping[StreamKind | str, str]
"""The topic chosen for a stream, by its kind or the kind's name (``--topic``)."""
FrameNames = (Mapping[StreamKind, Convention] | Mapping[str, Convention | str]
              | Mapping[StreamKind | str, Convention | str])
"""The axes convention of a stream (``--frame``), by its kind or the kind's name."""

TIME_SOURCES = ("header", "log")
"""``--time``: sample times from the header stamps (default) or the log (receive) times."""


def warn(message: str) -> None:
    """A :class:`RecordingWarning` (conversions, gaps, skipped topics, ...)."""
    warnings.warn(RecordingWarning(message), stacklevel=3)


@dataclasses.dataclass(frozen=True)
class TopicSource:
    """Where a stream came from and how its vectors were read.

    Attributes
    ----------
    topic : str
    type_name : str
        Message type (``pkg/msg/Type``).
    frame_id : str
        ``header.frame_id`` on the wire (of the first message).
    convention : Convention or None
        Axis convention the vectors were read in (None: no frame-dependent vectors).
    reason : str
        Why (declared by the user, or the frame id's REP-103 meaning).
    picked_from : tuple of str
        Other topics that could have fed the stream (empty when it was the only one).
    """

    topic: str
    type_name: str
    frame_id: str
    convention: Convention | None
    reason: str
    picked_from: tuple[str, ...] = ()


# --------------------------------------------------------------------------------------------
# choosing topics


@dataclasses.dataclass(frozen=True)
class Candidate:
    """A topic that could feed stream ``kind``.

    Attributes
    ----------
    topic, type_name, encoding : str
        The topic, its message type (``pkg/msg/Type``) and message encoding.
    kind : StreamKind
    named : bool
        Named for the kind (the canonical topic, or one given with ``--topic``) rather than
        found by its message type.
    """

    topic: str
    type_name: str
    encoding: str
    kind: StreamKind
    named: bool


def topic_map(topics: TopicNames | None) -> dict[str, StreamKind]:
    """Topic -> stream kind: the canonical topics, with ``topics`` (kind -> topic) replacing
    them kind by kind."""
    topic_kinds = {spec.topic: kind for kind, spec in SPECS.items()}
    for kind, topic in (topics or {}).items():
        kind = StreamKind(kind)
        topic_kinds = {t: k for t, k in topic_kinds.items() if k is not kind}
        topic_kinds[topic] = kind
    return topic_kinds


def candidate(topic: str, type_name: str, encoding: str,
              topic_kinds: Mapping[str, StreamKind]) -> Candidate | None:
    """The stream a topic could feed: the one it is named for, else the one its message type
    stands for (types that several streams share, such as a twist, are matched by name only);
    None for neither."""
    kind = topic_kinds.get(topic)
    if kind is not None:
        return Candidate(topic, type_name, encoding, kind, True)
    kind = KIND_BY_TYPE.get(type_name)
    if kind is not None and SPECS[kind].by_schema and encoding == MESSAGE_ENCODING:
        return Candidate(topic, type_name, encoding, kind, False)
    return None


def decodable(c: Candidate) -> bool:
    """Whether the candidate's messages are those of its stream (type and encoding)."""
    return c.type_name == SPECS[c.kind].message.name and c.encoding == MESSAGE_ENCODING


def pick_topic(where: str, kind: StreamKind, cands: list[Candidate],
               explicit: bool) -> Candidate | None:
    """The topic that feeds stream ``kind`` among its candidates, or None; several equally good
    ones are an error when ``explicit``, else a warning (the stream is skipped). A topic named
    for the kind with another message type is an error."""
    spec = SPECS[kind]
    for c in cands:
        if c.named and not decodable(c):
            raise RecordingError(
                f"{where}: topic {c.topic} has schema {c.type_name or None!r} in {c.encoding!r} "
                f"encoding; stream {kind.value} needs {spec.message.name} in "
                f"{MESSAGE_ENCODING!r} encoding"
            )
    pick = [c for c in cands if c.named] or cands
    if len(pick) == 1:
        return pick[0]
    if len(pick) > 1:
        names = ", ".join(sorted(c.topic for c in pick))
        message = (f"{where}: several topics could be stream {kind.value} ({names}); "
                   f"name one with --topic {kind.value}=TOPIC (or a [topics] table)")
        if explicit:
            raise RecordingError(message)
        warnings.warn(RecordingWarning(message + "; stream skipped"), stacklevel=3)
    return None


def choose_topics(
    where: str,
    candidates: Iterable[Candidate],
    wanted: Iterable[StreamKind],
    *,
    explicit: bool,
    named: TopicNames | None,
    available: str,
    what: str = "file",
) -> dict[StreamKind, tuple[Candidate, tuple[str, ...]]]:
    """One topic per wanted stream, and the other topics that could have fed it.

    Parameters
    ----------
    where : str
        The recording, for messages.
    candidates : iterable of Candidate
    wanted : iterable of StreamKind
    explicit : bool
        The streams were asked for: one without a topic, or with several, is an error.
    named : mapping, optional
        Topics named for streams (``--topic``); each of a wanted stream must be found (the
        readers check them all against a choice over every stream).
    available : str
        The recording's topics, for messages.
    what : str
        What the recording is, for messages (``file``, ``bag``).

    Raises
    ------
    RecordingError
        A named topic absent or of the wrong type; with ``explicit``, a stream without a topic
        or with several.
    """
    cands = list(candidates)
    wanted = set(wanted)
    chosen: dict[StreamKind, tuple[Candidate, tuple[str, ...]]] = {}
    for kind in SPECS:
        if kind not in wanted:
            continue
        of_kind = [c for c in cands if c.kind is kind]
        c = pick_topic(where, kind, of_kind, explicit)
        if c is not None:
            others = tuple(sorted(o.topic for o in of_kind if o.topic != c.topic))
            chosen[kind] = (c, others)
    for key, topic in (named or {}).items():
        if StreamKind(key) not in wanted:
            continue
        got = chosen.get(StreamKind(key))
        if got is None or got[0].topic != topic:
            raise RecordingError(
                f"{where}: topic {topic} named for stream {StreamKind(key).value} is not in "
                f"the {what}; it has {available}"
            )
    if explicit:
        missing = [k.value for k in SPECS if k in wanted and k not in chosen]
        if missing:
            raise RecordingError(f"{where}: no topic for stream(s) {', '.join(missing)}; the "
                                 f"{what} has {available}")
    return chosen


# --------------------------------------------------------------------------------------------
# times and streams


def sample_times(stamps: np.ndarray, log_ns: np.ndarray | None, time: str, label: str
                 ) -> np.ndarray:
    """A topic's sample times [ns], rows in log-time order.

    ``time="log"``: the log times. ``"header"``: the header stamps, unless any is zero or they
    do not increase (a driver that never sets them, or stamps that jump back): then the log
    times, with a warning that says why.
    """
    if time not in TIME_SOURCES:
        raise ValueError(f"time source {time!r}: use header or log")
    log = stamps if log_ns is None else np.asarray(log_ns, dtype=np.int64)
    if time == "log" or not stamps.size:
        return log.copy()
    why = ""
    if not stamps.all():
        why = f"{int(np.sum(stamps == 0))} header stamps are zero"
    elif np.any(np.diff(stamps) <= 0):
        k = int(np.argmax(np.diff(stamps) <= 0)) + 1
        why = (f"header stamps do not increase (message {k}, stamp {int(stamps[k])} ns after "
               f"{int(stamps[k - 1])} ns)")
    if why and not np.array_equal(log, stamps):
        warn(f"{label}: {why}; the log times are used (--time log says so explicitly)")
        return log.copy()
    return stamps


def build_stream(
    kind: StreamKind,
    fields: Mapping[str, np.ndarray],
    frame_id: str,
    label: str,
    aux: list[AuxColumn],
    t0_ns: int,
    validate: bool,
    convention: Convention | None = None,
    topic: str = "",
    others: tuple[str, ...] = (),
    report_gaps: bool = True,
) -> tuple[Stream, TopicSource]:
    """Decoded message fields of one topic -> a checked stream (conversions reported; gaps
    too with ``validate`` and ``report_gaps``)."""
    try:
        decoded = DECODERS[kind](fields, frame_id, aux, convention)
    except (RecordingError, ValueError) as exc:
        raise RecordingError(f"{label}: {exc}") from None
    t_ns = fields["t_ns"]
    columns = decoded.columns
    if decoded.keep is not None:
        t_ns = t_ns[decoded.keep]
        columns = {k: v[decoded.keep] for k, v in columns.items()}
    for note in decoded.notes:
        warn(f"{label}: {note}")
    stream = Stream(kind, t_ns, columns, decoded.frame_id or frame_id)
    if validate:
        problem = first_problem(stream, t0_ns)
        if problem:
            raise RecordingError(f"{label}: {problem}")
        gaps = gap_report(stream, t0_ns) if report_gaps else None
        if gaps:
            warn(f"{label}: {gaps}")
    source = TopicSource(topic, SPECS[kind].message.name, frame_id, decoded.convention,
                         decoded.reason, others)
    return stream, source
