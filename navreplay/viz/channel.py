"""A Rerun recording stream and what navreplay's entity tree keeps about it: the time columns,
the series and their static style, the colours of the labels, and the live layout (the
blueprint sent ahead of the data it lays out)."""

from __future__ import annotations

import copy
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from navreplay.io.outputs import release
from navreplay.viz import convert
from navreplay.viz.blueprint import Catalog, build_blueprint
from navreplay.viz.naming import legend_name
from navreplay.viz.ranges import DRAWN_RATE_HZ, Envelope, envelope_rows
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


class TimeIndex(list):
    """The time columns of a send (``time`` and, with ``t0_ns``, ``timestamp``) and the times
    [s] they were made of, so a series can be thinned to what is drawn."""

    def __init__(self, t: np.ndarray, t0_ns: int | None) -> None:
        self.t = np.asarray(t, dtype=np.float64)
        self.t0_ns = t0_ns
        dt_ns = np.rint(self.t * 1e9).astype(np.int64)
        cols = [rr.TimeColumn(TIMELINE, duration=dt_ns.astype("timedelta64[ns]"))]
        if t0_ns is not None:
            cols.append(rr.TimeColumn(
                TIMESTAMP, timestamp=(dt_ns + np.int64(t0_ns)).astype("datetime64[ns]")))
        super().__init__(cols)

    def take(self, k: np.ndarray) -> TimeIndex:
        return TimeIndex(self.t[k], self.t0_ns)


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
        self._pending: dict[str, tuple[Any, list[tuple[np.ndarray, np.ndarray]],
                                       int | None]] = {}
        """Per series of a file (not a live view): the times and rows of its unfinished bin,
        those drawn not yet sent (a chunk's worth is sent at once) and the recording start."""
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
        # extent of the true track up to each time (ellipsoid caps): times [s], extents [m]
        self._extent_curve: tuple[np.ndarray, np.ndarray] | None = None
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
            return
        if plan:
            saved = (self._rec, copy.deepcopy(self._runs), set(self._styled), self._ref,
                     self._extent, self._truth, self._truth_yaw, self._world_coords,
                     set(self._truth_columns), self._box, copy.deepcopy(self._truth_log),
                     copy.deepcopy(self._truth_names), copy.deepcopy(self._pending))
            self._rec = _NullStream()  # type: ignore[assignment]
            try:
                log()
            finally:
                (self._rec, self._runs, self._styled, self._ref, self._extent, self._truth,
                 self._truth_yaw, self._world_coords, self._truth_columns, self._box,
                 self._truth_log, self._truth_names, self._pending) = saved
            if self.catalog.signature() != self._sent:
                self.send_blueprint(final=False)
        log()
        if self.catalog.signature() != self._sent:
            self.send_blueprint(final=False)

    @staticmethod
    def _indexes(t: np.ndarray, t0_ns: int) -> TimeIndex:
        return TimeIndex(t, t0_ns)

    def _scalars(self, path: str, idx: list[rr.TimeColumn], values: np.ndarray,
                 columns: tuple[int, ...] | None = None, maxima: tuple[int, ...] = ()) -> None:
        """Send a series; of a :class:`TimeIndex` only the rows of its min/max envelope
        (:func:`~navreplay.viz.ranges.envelope_rows` of ``columns`` and ``maxima``, at
        :attr:`drawn_rate`), whose extent the pane's y range is made from."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        if not values.shape[0]:
            return
        if isinstance(idx, TimeIndex):
            flat = values.reshape(values.shape[0], -1)
            self.catalog.envelopes.setdefault(path, Envelope()).add(idx.t, flat)
            # whole bins drawn (a live view's as they complete, a file's in chunks)
            self._hold(path, idx, values, columns, maxima)
            return
        self._rec.send_columns(path, indexes=idx, columns=rr.Scalars.columns(scalars=values))

    def _drawn(self, t: np.ndarray, values: np.ndarray, columns: tuple[int, ...] | None,
               maxima: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """The times [s] and rows of a series drawn: its min/max envelope at
        :attr:`drawn_rate`."""
        if self.drawn_rate is None:
            return t, values
        k = envelope_rows(t, values.reshape(values.shape[0], -1), self.drawn_rate, columns,
                          maxima)
        return (t[k], values[k]) if k.shape[0] < values.shape[0] else (t, values)

    def _hold(self, path: str, idx: TimeIndex, values: np.ndarray,
              columns: tuple[int, ...] | None, maxima: tuple[int, ...]) -> None:
        """Draw the whole bins of a file's series as they complete (the rows of the last,
        unfinished bin held, so the rows drawn do not depend on how the rows came) and send
        them once :data:`PENDING_ROWS` are drawn (the time columns made once, at the send)."""
        tail, ready, _ = self._pending.get(path, (None, [], idx.t0_ns))
        t = idx.t
        if tail is not None:
            t = np.concatenate([tail[0], t])
            values = np.concatenate([tail[1], values])
        cut = values.shape[0]
        if self.drawn_rate is not None:
            bins = np.floor(t * self.drawn_rate)
            cut = int(np.searchsorted(bins, bins[-1], side="left"))
        if cut:
            ready.append(self._drawn(t[:cut], values[:cut], columns, maxima))
        tail = (t[cut:], values[cut:], columns, maxima) if cut < values.shape[0] else None
        self._pending[path] = (tail, ready, idx.t0_ns)
        if self.live or sum(v.shape[0] for _, v in ready) >= PENDING_ROWS:
            self._send_ready(path, ready, idx.t0_ns)
            self._pending[path] = (tail, [], idx.t0_ns)

    def _send_ready(self, path: str, ready: list[tuple[np.ndarray, np.ndarray]],
                    t0_ns: int | None) -> None:
        if ready:
            idx = TimeIndex(np.concatenate([t for t, _ in ready]), t0_ns)
            values = np.concatenate([v for _, v in ready])
            self._rec.send_columns(path, indexes=idx, columns=rr.Scalars.columns(scalars=values))

    def _send_pending(self) -> None:
        """Draw and send every series' rows held (their last bins too)."""
        for path, (tail, ready, t0_ns) in list(self._pending.items()):
            if tail is not None:
                ready.append(self._drawn(*tail))
            self._send_ready(path, ready, t0_ns)
        self._pending.clear()

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
        idx: list[rr.TimeColumn],
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
        idx: list[rr.TimeColumn],
        lo: np.ndarray,
        hi: np.ndarray,
        color: tuple[int, ...] = TRUTH_COLOR,
        name: str = "95 % band",
    ) -> None:
        """A shaded band between ``lo`` and ``hi`` (arrays on ``idx``): Rerun 0.41 cannot fill
        between series, so :data:`BAND_LINES` wide dim lines fill it."""
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        f = np.linspace(0.0, 1.0, BAND_LINES)
        lines = lo[:, None] + (hi - lo)[:, None] * f[None, :]
        shade = dimmer(color, 0.8)
        self._style(path, [name] * BAND_LINES, [shade] * BAND_LINES, [BAND_WIDTH] * BAND_LINES)
        self._scalars(path, idx, lines, columns=(0, BAND_LINES - 1))

    def blueprint(self, *, final: bool = True) -> rrb.Blueprint:
        """The default blueprint for what has been logged so far; ``final``: the panes open on
        the y and time ranges of their data (a live view's blueprint before the end leaves
        them to the viewer, which follows the data as it comes)."""
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
