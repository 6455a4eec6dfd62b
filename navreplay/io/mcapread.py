"""An MCAP file (ROS 2 profile, CDR messages) read in one pass, as windows of its streams.

A day of 100 Hz IMU and truth does not need to be in memory at once: :class:`McapSource`
walks an intact file's chunks in order and hands out the decoded rows of the streams asked for
every ``window`` messages of one stream, as a :class:`~navreplay.io.source.Window`: a checked
:class:`~navreplay.core.streams.Stream` per stream (the conversions and checks of
:func:`navreplay.io.topics.build_stream`, time increasing across windows) and, per stream, the
time up to which it is complete. Only the topics of the streams asked for are decoded
(:mod:`navreplay.io.decode`).

A stream whose next message is far ahead (an aiding stream that pauses) is not left lagging:
the chunk index says which chunk holds the topic's next message, whose time is read ahead from
that chunk, so that the stream is known to be complete up to just before it. A replay then need
not hold the IMU samples of the pause.

A file without a summary and chunk index (truncated, unfinished, or written without one) is
read to its end and handed out as one window: a damaged file yields the messages before the
damage with a :class:`~navreplay.io.errors.SalvagedWarning` telling the time of the last one.
So is any file read with a ``window`` of None (:class:`~navreplay.io.source.ReadOptions`).

The warnings of the read (header stamps replaced by log times, conversions, gaps, frame ids
that change) are given once, when it ends, each with the number of windows it concerns; gaps
are counted over the whole stream, those between the last sample of a window and the first of
the next included, against the median interval of the first samples: the line of a read in
one window.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np

from navreplay.core.streams import Metadata, Stream, StreamKind
from navreplay.io.checks import check_frame_ids, declared_outages, gap_steps, gap_text, when
from navreplay.io.convert import AuxColumn
from navreplay.io.decode import ChannelDecoder, Decoding, describe_topics, file_metadata
from navreplay.io.errors import RecordingError, RecordingWarning, SalvagedWarning
from navreplay.io.mcapfile import FileContents, read_chunk, walk
from navreplay.io.schemas import SPECS
from navreplay.io.source import COMPLETE, FileSource, ReadOptions, Window
from navreplay.io.topics import (
    build_stream,
    choose_topics,
    sample_times,
    topic_map,
)


def accepts(path: Path) -> bool:
    """Any file that is not of another kind is read as MCAP (its magic is checked on reading)."""
    return True


class McapSource(FileSource):
    """The streams of an MCAP file, window by window (see the module docstring). The file is
    opened here, once, and closed when the windows are read or :meth:`close` is called.

    Parameters
    ----------
    path : path-like
    options : ReadOptions, optional
        Streams, topics, frames, time source, checks; ``window`` decoded messages of a stream
        close a window (None: the whole file in one window).

    Raises
    ------
    RecordingError
        No such file (here); while reading: not an MCAP file, a CRC mismatch or corrupt
        chunk, a damaged file with nothing to salvage, a topic whose schema does not fit its
        stream, a stream asked for and absent (``explicit``), bad samples (``validate``), time
        that goes back across windows. The message names the file, and the topic and time
        where it applies.
    """

    kind = "mcap"

    def __init__(self, path: str | os.PathLike[str], options: ReadOptions | None = None
                 ) -> None:
        super().__init__(path, options)
        try:
            self._file: BinaryIO = open(self.path, "rb")  # noqa: SIM115 (closed by the read)
        except FileNotFoundError:
            raise RecordingError(f"{self.name}: no such file") from None
        except IsADirectoryError:
            raise RecordingError(f"{self.name}: is a directory, not an MCAP file") from None

    def close(self) -> None:
        super().close()
        self._file.close()

    def _windows(self) -> Iterator[Window]:
        where, f = self.name, self._file
        opts = self.options
        plan = Decoding(where, opts.wanted(), topic_map(opts.topics))
        reading: _Reading | None = None
        try:
            with f:
                contents = FileContents(size=os.fstat(f.fileno()).st_size)
                for block in walk(f, where, contents, plan.wants_chunk):
                    if opts.window is not None and contents.intact and reading is None:
                        reading = self._start(plan, contents)
                    plan.feed(contents, block)
                    size = opts.window  # reading: windows of this many rows
                    if reading is not None and size is not None and any(
                            d.rows() >= size for d in reading.chosen.values()):
                        yield reading.window()
                if reading is None:  # read whole: every channel is known now
                    self._check_damage(contents)
                    reading = self._start(plan, contents)
                yield reading.window(final=True)
        finally:
            if reading is not None:
                reading.report()

    def _start(self, plan: Decoding, contents: FileContents) -> _Reading:
        where, opts = self.name, self.options
        available = describe_topics(contents)
        chosen = choose_topics(where, plan.all_candidates(contents), opts.wanted(),
                               explicit=opts.explicit, named=opts.topics, available=available)
        every = Decoding(where, set(SPECS), topic_map(opts.topics))
        with warnings.catch_warnings():  # (said once, for the streams read)
            warnings.simplefilter("ignore", RecordingWarning)
            present = choose_topics(where, every.all_candidates(contents), set(SPECS),
                                    explicit=False, named=opts.topics, available=available)
        counts = contents.statistics.channel_message_counts if contents.statistics else {}
        decoders = {k: plan.decoder_of(c) for k, (c, _) in chosen.items()}
        totals = {k: counts.get(d.channel.id) if contents.intact else None
                  for k, d in decoders.items()}
        metadata, t0_ns, aux = file_metadata(contents, where)
        return _Reading(self, decoders, {k: o for k, (_, o) in chosen.items()}, totals,
                        frozenset(present), metadata, t0_ns, aux, contents)

    def _check_damage(self, contents: FileContents) -> None:
        """A damaged file: nothing to salvage is an error, else a warning of what was lost."""
        where = self.name
        damage = contents.damage
        if damage is None:
            return
        if contents.message_count == 0:
            raise RecordingError(
                f"{where}: file is damaged at byte {damage.offset} of {contents.size} "
                f"({damage.reason}) before any complete message; nothing to salvage"
            )
        _, t0_ns, _ = file_metadata(contents, where)
        last = contents.last_log_time
        assert last is not None  # a complete message was read
        if damage.data_complete:
            message = (f"{where}: summary or footer missing or damaged at byte {damage.offset} "
                       f"of {contents.size} ({damage.reason}); all {contents.message_count} "
                       f"messages were recovered, the last at {when(last, t0_ns)}")
        else:
            self._salvaged = True
            message = (f"{where}: file is truncated or damaged at byte {damage.offset} of "
                       f"{contents.size} ({damage.reason}); salvaged {contents.message_count} "
                       f"messages, the last good one at {when(last, t0_ns)}; anything after is "
                       "lost")
        warnings.warn(SalvagedWarning(message, data_complete=damage.data_complete), stacklevel=4)


class _Reading:
    """What carries from window to window: the topics read, the last time of each stream."""

    def __init__(self, source: McapSource, chosen: dict[StreamKind, ChannelDecoder],
                 others: dict[StreamKind, tuple[str, ...]], totals: dict[StreamKind, int | None],
                 present: frozenset[StreamKind], metadata: Metadata, t0_ns: int,
                 aux: list[AuxColumn], contents: FileContents) -> None:
        self.source = source
        self.chosen, self.others, self.totals, self.present = chosen, others, totals, present
        self.metadata, self.t0_ns, self.aux = metadata, t0_ns, aux
        self.contents = contents
        self.last: dict[StreamKind, int] = {}
        self.frame: dict[StreamKind, str] = {}
        self.notes: dict[StreamKind, str] = {}  # frame ids that change, the latest note
        self.ahead: dict[StreamKind, tuple[int, int]] = {}  # kind -> (chunk, first time)
        self.floor: dict[StreamKind, int] = {}  # no sample of the kind may come before
        self.base: dict[StreamKind, str] = {}  # kind -> "header" or "log", as first chosen
        self.gaps = {kind: _Gaps(declared_outages(kind, metadata.extra, t0_ns))
                     for kind in chosen}
        self.warnings = _Warnings()
        self.windows = 0
        self.newest = -COMPLETE  # the latest sample of any kind in the previous windows

    def window(self, final: bool = False) -> Window:
        self.windows += 1
        out = {}
        for kind, decoder in self.chosen.items():
            first = self.windows == 1  # every stream read is in it, with its columns
            if decoder.rows() or first:
                with self.warnings.collect(self.windows):
                    stream = self._stream(kind, decoder)
                if len(stream) or first:
                    out[kind] = stream
        known = {}
        for kind, decoder in self.chosen.items():
            total = self.totals[kind]
            last = self.last.get(kind, -COMPLETE)
            if final or (total is not None and decoder.count >= total):
                known[kind] = COMPLETE
            elif last <= self.newest:  # no sample in this window: where is the next?
                known[kind] = max(last, self._before_next(kind, decoder))
            else:
                known[kind] = last
        self.newest = max(self.last.values(), default=self.newest)
        stats = self.contents.statistics
        end = int(stats.message_end_time) if self.contents.intact and stats else None
        return Window(out, known, self.metadata, self.t0_ns, self.present, final=final,
                      end_ns=end)

    def _before_next(self, kind: StreamKind, decoder: ChannelDecoder) -> int:
        """The time just before the stream's next sample, read ahead in the chunk that holds it
        (the chunk index names it); :data:`COMPLETE` when no chunk to come holds the topic,
        -:data:`COMPLETE` when the index cannot tell."""
        contents = self.contents
        if not contents.chunk_indexes:
            return -COMPLETE
        cid = decoder.channel.id
        indexes = contents.chunk_indexes
        k, t = self.ahead.get(kind, (-1, -COMPLETE))
        if k < contents.chunks_walked:
            for k in range(contents.chunks_walked, len(indexes)):
                held = indexes[k].message_index_offsets
                if not held:
                    return -COMPLETE  # a chunk without a message index: unknown
                if cid in held:
                    break
            else:
                return COMPLETE
            t = self._first_time(decoder, indexes[k].chunk_start_offset)
            self.ahead[kind] = (k, t)
            self.floor[kind] = t
        return t - 1

    def _first_time(self, decoder: ChannelDecoder, offset: int) -> int:
        """The earliest time a sample of the topic in the chunk at ``offset`` can have: its
        least log time, or header stamp where those are used."""
        block = read_chunk(self.source._file, offset, decoder.where, lambda opcode, body: None)
        rows = np.flatnonzero(block.channel == decoder.channel.id)
        log = block.log_time[rows]
        first = int(log.min())
        if self.source.options.time == "header":
            ahead = ChannelDecoder(decoder.channel, decoder.schema, decoder.message,
                                   decoder.where)
            ahead.add(block, rows)
            stamps = ahead.finish()["t_ns"]
            if stamps.size and stamps.all():
                first = min(first, int(stamps.min()))
        return first

    def _stream(self, kind: StreamKind, decoder: ChannelDecoder) -> Stream:
        src, opts = self.source, self.source.options
        fields = decoder.drain()
        fields["t_ns"] = self._times(kind, decoder, fields["t_ns"])
        self.frame.setdefault(kind, decoder.first_frame_id or SPECS[kind].frame_id)
        note = check_frame_ids(kind, decoder.label, decoder.frame_ids, opts.frames.get(kind),
                               self.frame[kind])  # an error stops the read at this window
        if note:
            self.notes[kind] = f"{decoder.label}: {note}"  # said once, by report()
        stream, topic_source = build_stream(
            kind, fields, self.frame[kind], decoder.label, self.aux, self.t0_ns, opts.validate,
            opts.frames.get(kind), decoder.channel.topic, self.others[kind],
            report_gaps=False)
        src.sources.setdefault(kind, topic_source)
        if len(stream):
            first = int(stream.t_ns[0])
            last = self.last.get(kind)
            if last is not None and first <= last:
                raise RecordingError(
                    f"{decoder.label}: timestamp at {when(first, self.t0_ns)} does "
                    f"not follow the one at {when(last, self.t0_ns)}"
                )
            floor = self.floor.get(kind)
            if floor is not None and first < floor:
                raise RecordingError(
                    f"{decoder.label}: timestamp at {when(first, self.t0_ns)} is earlier than "
                    f"the first of the chunk that follows the previous samples "
                    f"({when(floor, self.t0_ns)}): the topic's messages are out of order"
                )
            self.last[kind] = int(stream.t_ns[-1])
            if opts.validate:
                self.gaps[kind].add(stream.t_ns)
        return stream

    def _times(self, kind: StreamKind, decoder: ChannelDecoder, stamps: np.ndarray
               ) -> np.ndarray:
        """The window's sample times on the time base the topic's first window chose: header
        stamps, or log times once the stamps were unusable there (as a read in one window
        chooses for the whole topic). Stamps that turn unusable after windows that used them
        are refused: the windows already replayed cannot move to log times."""
        t = sample_times(stamps, decoder.log_ns, self.source.options.time, decoder.label)
        used = "header" if t is stamps else "log"
        base = self.base.setdefault(kind, used)
        if used == base:
            return t
        log = np.asarray(decoder.log_ns if decoder.log_ns is not None else stamps,
                         dtype=np.int64)
        if base == "log":
            return log.copy()
        zero = np.flatnonzero(stamps == 0)
        k = int(zero[0]) if zero.size else int(np.argmax(np.diff(stamps) <= 0)) + 1
        raise RecordingError(
            f"{decoder.label}: header stamps are unusable (zero or not increasing) from the "
            f"message logged at {when(int(log[k]), self.t0_ns)}, after windows before it used "
            f"them: replay with --time log, so the whole topic takes its log times")

    def report(self) -> None:
        """Give the warnings of the read, each once (gaps over the whole stream)."""
        for note in self.notes.values():
            self.warnings.add(note, self.windows)
        for kind, gaps in self.gaps.items():
            line = gaps.line(self.t0_ns)
            if line:
                self.warnings.add(f"{self.chosen[kind].label}: {line}", self.windows)
        self.warnings.emit(self.windows)


class _Gaps:
    """The gaps of one stream read in windows: counted against the median interval of the
    first samples (at least three), across window boundaries too; those the recording's
    ``declared`` outages explain are not (:func:`navreplay.io.checks.gap_steps`)."""

    def __init__(self, declared: np.ndarray) -> None:
        self.declared = declared
        self.median = 0.0
        self.head = np.zeros(0, np.int64)  # samples until the median is known
        self.prev: int | None = None
        self.count = 0
        self.longest = 0
        self.start = 0

    def add(self, t_ns: np.ndarray) -> None:
        if not self.median:
            self.head = np.concatenate([self.head, t_ns])
            if len(self.head) < 3:
                return
            t_ns, self.head = self.head, self.head[:0]
            self.median = float(np.median(np.diff(t_ns))) or -1.0  # -1: no gap can be told
        if self.median < 0:
            return
        t = t_ns if self.prev is None else np.concatenate([[self.prev], t_ns])
        self.prev = int(t_ns[-1])
        gaps = gap_steps(t, self.median, declared=self.declared)
        if gaps.size:
            step = t[gaps + 1] - t[gaps]
            self.count += gaps.size
            worst = int(np.argmax(step))
            if step[worst] > self.longest:
                self.longest, self.start = int(step[worst]), int(t[gaps[worst]])

    def line(self, t0_ns: int) -> str | None:
        if not self.count:
            return None
        return gap_text(self.count, self.median, self.longest, self.start, t0_ns)


_NUMBER = re.compile(r"[-+]?\d[\d.]*(?:e[-+]?\d+)?")


class _Warnings:
    """The reader's warnings over the windows of a read, each given once: the first, with the
    number of windows it came in (numbers aside, the same line)."""

    def __init__(self) -> None:
        self.seen: dict[str, list] = {}  # key -> [first message, windows, last window]

    def collect(self, window: int) -> _Collect:
        return _Collect(self, window)

    def add(self, message: str, window: int) -> None:
        entry = self.seen.setdefault(_NUMBER.sub("#", message), [message, 0, -1])
        if entry[2] != window:
            entry[1] += 1
            entry[2] = window

    def emit(self, windows: int) -> None:
        """Warn once per line; ``windows``: how many the read had."""
        for message, count, _ in self.seen.values():
            if count > 1:
                message += (f" (the same in {count} of the {windows} windows of the read; "
                            "the first is shown)")
            warnings.warn(RecordingWarning(message), stacklevel=4)
        self.seen.clear()


class _Collect(warnings.catch_warnings):
    """Gather the reader's warnings (:class:`RecordingWarning`) of one window into a
    :class:`_Warnings`; others pass."""

    def __init__(self, tally: _Warnings, window: int) -> None:
        super().__init__(record=True)
        self.tally, self.window = tally, window

    def __enter__(self):
        self.caught = super().__enter__()
        warnings.simplefilter("always")
        return self.caught

    def __exit__(self, *exc) -> None:
        super().__exit__(*exc)
        for w in self.caught or []:
            if isinstance(w.message, RecordingWarning):
                self.tally.add(str(w.message), self.window)
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
