"""A Rerun recording stream and what navreplay's entity tree keeps about it: the time columns,
the series and their static style, the colours of the labels, and the live layout (the
blueprint sent ahead of the data it lays out)."""

from __future__ import annotations

import copy
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from navreplay.io.outputs import release
from navreplay.viz import convert
from navreplay.viz.blueprint import Catalog, build_blueprint
from navreplay.viz.naming import legend_name
from navreplay.viz.ranges import (
    DRAWN_RATE_HZ,
    Envelope,
    add_rows,
    envelope_rows,
    envelope_rows_of,
)
from navreplay.viz.style import (
    BAND_LINES,
    BAND_WIDTH,
    N_SIGMA,
    TRUTH_COLOR,
    LabelColors,
    dimmer,
    lighter,
)
from navreplay.viz.targets import (
    Save,
    Target,
)

if TYPE_CHECKING:
    from navreplay.viz.runs import RunState
    from navreplay.viz.truth import TruthLog


TIMELINE = "time"
"""Duration since the recording start."""


TIMESTAMP = "timestamp"
"""Absolute time (UNIX epoch)."""


PENDING_ROWS = 4096
"""Rows of a series a file's sink holds before sending them as one chunk: the blocks of a
long run (a window each) would otherwise each be a chunk per series, and a chunk's overhead
(about a kilobyte) would outweigh its rows at 100 Hz outputs."""


def _remove(path: Path) -> None:
    release(path)


class TimeIndex:
    """The times [s] of a block of rows and the recording start: the time columns of a send
    (``time`` and, with ``t0_ns``, ``timestamp``) are made when it is sent."""

    def __init__(self, t: np.ndarray, t0_ns: int | None) -> None:
        self.t = np.asarray(t, dtype=np.float64)
        self.t0_ns = t0_ns

    @property
    def columns(self) -> list[rr.TimeColumn]:
        dt_ns = np.rint(self.t * 1e9).astype(np.int64)
        cols = [rr.TimeColumn(TIMELINE, duration=dt_ns.astype("timedelta64[ns]"))]
        if self.t0_ns is not None:
            cols.append(rr.TimeColumn(
                TIMESTAMP, timestamp=(dt_ns + np.int64(self.t0_ns)).astype("datetime64[ns]")))
        return cols


Index = TimeIndex | list[rr.TimeColumn]
"""The times of a series: a :class:`TimeIndex` (drawn as its envelope) or the time columns
themselves (sent as they are: a sequence timeline)."""


class _Queued(NamedTuple):
    """A series waiting to be drawn (:meth:`Channel._scalars`)."""

    path: str
    idx: TimeIndex
    values: np.ndarray
    columns: tuple[int, ...] | None
    maxima: tuple[int, ...]
    band: bool


class _Held(NamedTuple):
    """What a file's sink holds of a series: the times and rows of its unfinished bin, the
    rows drawn not yet sent (a chunk's worth is sent at once) and their number, the recording
    start, and how the series is drawn."""

    tail: tuple[np.ndarray, np.ndarray] | None
    ready: list[tuple[np.ndarray, np.ndarray]]
    n_ready: int
    t0_ns: int | None
    columns: tuple[int, ...] | None
    maxima: tuple[int, ...]
    band: bool


BAND_FRACTIONS = np.linspace(0.0, 1.0, BAND_LINES)
"""Where the lines of a band lie between its bounds (0: the lower, 1: the upper)."""


def _band_lines(values: np.ndarray) -> np.ndarray:
    """The :data:`BAND_LINES` lines of band rows held as (first, last, lower bound, span)."""
    return values[:, 2:3] + values[:, 3:4] * BAND_FRACTIONS[None, :]


class Channel:
    """The recording stream of a :class:`~navreplay.viz.sink.Sink` and the state of what it has
    logged: the base of the views of the truth, the runs, the 3D world and the map, and the
    ensembles."""

    def __init__(
        self,
        rec: rr.RecordingStream,
        target: Target,
        *,
        path: Path | None = None,
        tmp: Path | None = None,
        url: str | None = None,
        web_url: str | None = None,
        keep_alive: bool = False,
        drawn_rate: float | None = DRAWN_RATE_HZ,
    ) -> None:
        self._rec = rec
        self._keep_alive = keep_alive
        self.target = target
        self.path = path
        self._tmp = tmp
        self.url = url
        self.web_url = web_url
        self.recording_id = str(rec.get_recording_id())
        self.catalog = Catalog()
        self.drawn_rate = drawn_rate
        """Bins per second of a drawn series' min/max envelope (None: every row drawn)."""
        self._pending: dict[str, _Held] = {}
        """What is held of each series (a live view's: its unfinished bin only)."""
        self._rows_held: dict[str, tuple[Callable[..., Any], int, list[np.ndarray],
                                         dict[str, list[Any]]]] = {}
        """The rows of each entity that is not a drawn series not sent yet (a file's)."""
        self._queued: list[_Queued] = []
        """Series logged and not yet drawn (:meth:`_scalars`): a live view's in the current
        call of the sink, a file's until one holds :data:`PENDING_ROWS` rows."""
        self._queued_rows: dict[str, int] = {}
        self._queued_most = 0
        self.live = not isinstance(target, Save)
        self._sent: tuple | None = None
        self._colors = LabelColors()
        self._runs: dict[str, RunState] = {}
        self._styled: set[str] = set()
        self._ref: np.ndarray | None = None
        self._extent = 0.0
        self._box: tuple[np.ndarray, np.ndarray] | None = None  # NED extremes of the truth
        self._truth: convert.NavColumns | None = None
        self._truth_yaw: tuple[np.ndarray, np.ndarray] | None = None  # t [s], unwrapped yaw
        self._truth_log: TruthLog | None = None
        # the box of the true track up to each time of a block (its ellipsoids' caps), in
        # parts: times [s], low and high NED corners [m]
        self._extent_curve: list[tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        # the box of the true track row by row over the last truth windows logged (times,
        # low and high corners), and whether they hold every row logged
        self._track_box: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._track_box_whole = True
        self._t0_ns = 0
        self._truth_wanted: dict[str, str] = {}
        self._outages: tuple[tuple[float, float], ...] = ()
        self._truth_columns: set[str] = set()
        self._truth_widths: dict[str, int] = {}  # components of each truth column logged
        self._truth_names: dict[str, dict[int, str]] = {}  # their names, from the states
        self._closed = False
        self._world_coords = False
        self._cleanup = weakref.finalize(self, _remove, tmp) if tmp is not None else None

    def color_of(self, label: str) -> tuple[int, int, int]:
        """The colour of a filter label (or an ensemble variant) in every plot of this sink:
        picked from the palette by its name (:class:`~navreplay.core.colors.LabelColors`), the
        same in every run."""
        return self._colors.rgb(label)

    def order_of(self, label: str) -> int:
        """Position of a label in first-use order (the row of its panes)."""
        return self._colors.order(label)

    def _layout_first(self, log: Callable[[], None], *, plan: bool = True) -> None:
        """Run ``log``; on a live sink, first send the blueprint for what it will log: with
        ``plan``, ``log`` runs once against a stream that drops everything (filling the
        catalog), the blueprint goes out if the catalog changed, then ``log`` runs for real.
        Without ``plan`` (later rows of a run already laid out) a plot that appears anyway is
        announced right after its first rows."""
        if not self.live:
            log()
            if self._queued_most >= PENDING_ROWS:
                self._draw_queued()
            return
        if plan:
            saved = (self._rec, copy.deepcopy(self._runs), set(self._styled), self._ref,
                     self._extent, self._truth, self._truth_yaw, self._world_coords,
                     set(self._truth_columns), self._box, copy.deepcopy(self._truth_log),
                     copy.deepcopy(self._truth_names), copy.deepcopy(self._pending),
                     list(self._track_box), self._track_box_whole)
            self._rec = _NullStream()  # type: ignore[assignment]
            try:
                log()
                self._draw_queued()
            finally:
                self._queued, self._queued_rows, self._queued_most = [], {}, 0
                (self._rec, self._runs, self._styled, self._ref, self._extent, self._truth,
                 self._truth_yaw, self._world_coords, self._truth_columns, self._box,
                 self._truth_log, self._truth_names, self._pending, self._track_box,
                 self._track_box_whole) = saved
            if self.catalog.signature() != self._sent:
                self.send_blueprint(final=False)
        log()
        self._draw_queued()
        if self.catalog.signature() != self._sent:
            self.send_blueprint(final=False)

    @staticmethod
    def _indexes(t: np.ndarray, t0_ns: int) -> TimeIndex:
        return TimeIndex(t, t0_ns)

    def _scalars(self, path: str, idx: Index, values: np.ndarray,
                 columns: tuple[int, ...] | None = None, maxima: tuple[int, ...] = (),
                 band: bool = False) -> None:
        """Send a series; of a :class:`TimeIndex` only the rows of its min/max envelope
        (:func:`~navreplay.viz.ranges.envelope_rows` of ``columns`` and ``maxima``, at
        :attr:`drawn_rate`), whose extent the pane's y range is made from. The series of a
        :class:`TimeIndex` wait for :meth:`_draw_queued` (at the end of each call of the sink),
        which draws the series of each time index together. ``band``: the values are those
        of :meth:`band`, its lines made for the rows sent."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        if not values.shape[0]:
            return
        if isinstance(idx, TimeIndex):
            self._queued.append(_Queued(path, idx, values, columns, maxima, band))
            rows = self._queued_rows.get(path, 0) + values.shape[0]
            self._queued_rows[path] = rows
            self._queued_most = max(self._queued_most, rows)
            return
        self._rec.send_columns(path, indexes=idx, columns=rr.Scalars.columns(
            scalars=_band_lines(values) if band else values))

    def _draw_queued(self) -> None:
        """Draw the queued series (:meth:`_scalars`): each one's pieces as one, those that
        came on the same time indexes on one time index."""
        queue, self._queued = self._queued, []
        self._queued_rows, self._queued_most = {}, 0
        pieces: dict[str, list[_Queued]] = {}
        for item in queue:
            pieces.setdefault(item.path, []).append(item)
        merged: list[_Queued] = []
        joined: dict[tuple[int, ...], TimeIndex] = {}
        for items in pieces.values():
            if len(items) == 1:
                merged.append(items[0])
                continue
            key = tuple(id(q.idx) for q in items)
            idx = joined.get(key)
            if idx is None:
                idx = joined[key] = TimeIndex(np.concatenate([q.idx.t for q in items]),
                                              items[0].idx.t0_ns)
            merged.append(items[0]._replace(
                idx=idx, values=np.concatenate([q.values for q in items])))
        if merged:
            self._draw(merged)

    def _draw(self, queued: list[_Queued]) -> None:
        """Series of distinct entities into their panes' envelopes, their whole bins drawn (the
        rows of a series' last, unfinished bin held, so the rows drawn do not depend on how the
        rows came), and sent once :data:`PENDING_ROWS` are drawn (a live view's at once)."""
        by_index: dict[int, list[_Queued]] = {}
        for item in queued:
            by_index.setdefault(id(item.idx), []).append(item)
        envelopes = self.catalog.envelopes
        for items in by_index.values():
            add_rows([envelopes.setdefault(q.path, Envelope()) for q in items], items[0].idx.t,
                     [q.values[:, :2] if q.band else q.values.reshape(q.values.shape[0], -1)
                      for q in items])
        # the series at the same times (their held rows too) are drawn together
        groups: dict[tuple[int, bytes], list[_Queued]] = {}
        for item in queued:
            held = self._pending.get(item.path)
            tail = None if held is None else held.tail
            key = (id(item.idx), b"" if tail is None else tail[0].tobytes())
            groups.setdefault(key, []).append(item)
        for items in groups.values():
            self._draw_group(items)

    def _draw_group(self, items: list[_Queued]) -> None:
        idx = items[0].idx
        held = [self._pending.get(q.path) for q in items]
        tails = [None if h is None else h.tail for h in held]
        t = idx.t if tails[0] is None else np.concatenate([tails[0][0], idx.t])
        rows = [q.values if tail is None else np.concatenate([tail[1], q.values])
                for q, tail in zip(items, tails, strict=True)]
        cut = t.shape[0]
        if self.drawn_rate is not None:
            bins = np.floor(t * self.drawn_rate)
            cut = int(np.searchsorted(bins, bins[-1], side="left"))
        kept: list[np.ndarray | None] = [None] * len(items)
        if cut and self.drawn_rate is not None:
            kept = envelope_rows_of(t[:cut], [(v[:cut].reshape(cut, -1), q.columns, q.maxima)
                                              for v, q in zip(rows, items, strict=True)],
                                    self.drawn_rate)
        for q, h, values, k in zip(items, held, rows, kept, strict=True):
            ready = [] if h is None else h.ready
            if cut:
                ready.append((t[:cut], values[:cut]) if k is None or k.shape[0] >= cut
                             else (t[k], values[k]))
            tail = (t[cut:], values[cut:]) if cut < t.shape[0] else None
            count = (0 if h is None else h.n_ready) + (ready[-1][1].shape[0] if cut else 0)
            if self.live or count >= PENDING_ROWS:
                self._send_ready(q.path, ready, idx.t0_ns, q.band)
                ready, count = [], 0
            self._pending[q.path] = _Held(tail, ready, count, idx.t0_ns, q.columns, q.maxima,
                                          q.band)

    def _drawn(self, t: np.ndarray, values: np.ndarray, columns: tuple[int, ...] | None,
               maxima: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """The times [s] and rows of a series drawn: its min/max envelope at
        :attr:`drawn_rate`."""
        if self.drawn_rate is None:
            return t, values
        k = envelope_rows(t, values.reshape(values.shape[0], -1), self.drawn_rate, columns,
                          maxima)
        return (t[k], values[k]) if k.shape[0] < values.shape[0] else (t, values)

    def _send_ready(self, path: str, ready: list[tuple[np.ndarray, np.ndarray]],
                    t0_ns: int | None, band: bool = False) -> None:
        if ready:
            idx = TimeIndex(np.concatenate([t for t, _ in ready]), t0_ns)
            values = np.concatenate([v for _, v in ready])
            self._rec.send_columns(path, indexes=idx.columns, columns=rr.Scalars.columns(
                scalars=_band_lines(values) if band else values))

    def _send_pending(self) -> None:
        """Draw and send every series' rows held (their last bins too)."""
        self._draw_queued()
        for path, held in list(self._pending.items()):
            if held.tail is not None:
                held.ready.append(self._drawn(*held.tail, held.columns, held.maxima))
            self._send_ready(path, held.ready, held.t0_ns, held.band)
        self._pending.clear()
        for path in list(self._rows_held):
            self._send_rows_held(path)

    def _send_rows(self, path: str, t: np.ndarray, t0_ns: int,
                   make: Callable[..., Any], **fields: np.ndarray | list[str]) -> None:
        """Rows at times ``t`` [s] of an entity that is not a drawn series (body transforms,
        ellipsoids, map positions): ``make(**fields)`` gives their columns. A live view's are
        sent as they come, a file's in chunks of :data:`PENDING_ROWS` rows (the time columns
        and the archetype's made once per chunk)."""
        held = self._rows_held.setdefault(path, (make, t0_ns, [], {k: [] for k in fields}))
        held[2].append(t)
        for k, v in fields.items():
            held[3][k].append(v)
        if self.live or sum(x.shape[0] for x in held[2]) >= PENDING_ROWS:
            self._send_rows_held(path)

    def _send_rows_held(self, path: str) -> None:
        make, t0_ns, times, fields = self._rows_held.pop(path)
        columns = make(**{k: (sum(v, []) if isinstance(v[0], list) else np.concatenate(v))
                          for k, v in fields.items()})
        self._rec.send_columns(path, indexes=TimeIndex(np.concatenate(times), t0_ns).columns,
                               columns=columns)

    def _style(
        self,
        path: str,
        names: list[str],
        colors: list[tuple[int, ...]],
        widths: list[float] | None = None,
    ) -> None:
        if path in self._styled:
            return
        self._styled.add(path)
        shown = [legend_name(n) for n in names]
        self.catalog.names[path] = shown
        self._rec.log(path, rr.SeriesLines(names=shown, colors=colors, widths=widths),
                      static=True)

    def _bounded(
        self,
        path: str,
        idx: Index,
        value: np.ndarray,
        sigma: np.ndarray | None,
        name: str,
        color: tuple[int, int, int],
    ) -> None:
        """A value with +-N_SIGMA bounds as three series (value, +3 sigma, -3 sigma): the
        value in the filter's colour, the bounds thinner and lighter."""
        if sigma is None:
            self._style(path, [name], [color], [1.5])
            self._scalars(path, idx, value)
            return
        faint = lighter(color, 0.45)
        self._style(
            path,
            [name, "+3σ", "-3σ"],
            [color, faint, faint],
            [1.5, 1.0, 1.0],
        )
        # drawn: the value's smallest and largest per bin, the bounds' widest (-3σ mirrors +3σ)
        self._scalars(path, idx, np.stack([value, N_SIGMA * sigma, -N_SIGMA * sigma], axis=1),
                      columns=(0,), maxima=(1,))

    def band(
        self,
        path: str,
        idx: Index,
        lo: np.ndarray,
        hi: np.ndarray,
        color: tuple[int, ...] = TRUTH_COLOR,
        name: str = "95 % band",
    ) -> None:
        """A shaded band between ``lo`` and ``hi`` (arrays on ``idx``): Rerun 0.41 cannot fill
        between series, so :data:`BAND_LINES` wide dim lines fill it."""
        lo = np.asarray(lo, dtype=np.float64)
        span = np.asarray(hi, dtype=np.float64) - lo
        shade = dimmer(color, 0.8)
        self._style(path, [name] * BAND_LINES, [shade] * BAND_LINES, [BAND_WIDTH] * BAND_LINES)
        # drawn and ranged by its first and last lines, which every line lies between
        first, last = (lo + span * BAND_FRACTIONS[0], lo + span * BAND_FRACTIONS[-1])
        self._scalars(path, idx, np.stack([first, last, lo, span], axis=1), columns=(0, 1),
                      band=True)

    def blueprint(self, *, final: bool = True) -> rrb.Blueprint:
        """The default blueprint for what has been logged so far; ``final``: the panes open on
        the y and time ranges of their data (a live view's blueprint before the end leaves
        them to the viewer, which follows the data as it comes)."""
        self._draw_queued()  # the panes' ranges hold every row logged
        return build_blueprint(self.catalog, ranges=final)

    def send_blueprint(self, *, final: bool = True) -> None:
        """Send the default blueprint now (also done by :meth:`close`, and by a live sink
        before the data of every new plot, not ``final``)."""
        self._sent = self.catalog.signature()
        self._rec.send_blueprint(self.blueprint(final=final), make_active=True,
                                 make_default=True)


class _NullStream:
    """Stands in for the recording stream while a live sink lays out what it will log."""

    def send_columns(self, *args: Any, **kwargs: Any) -> None:
        pass

    def log(self, *args: Any, **kwargs: Any) -> None:
        pass
