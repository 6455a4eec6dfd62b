"""The Rerun sink: how run results, truth and Monte Carlo statistics become entities of a
recording stream (opened on a target by :func:`navreplay.viz.connect.open_sink`).

Entity tree
-----------
::

    /truth/nav/{roll,pitch,yaw}          [deg]   true attitude (ZYX Euler, yaw unwrapped)
    /truth/nav/{v_N,v_E,v_D}             [m/s]
    /truth/nav/{p_N,p_E,p_D}             [m]     local NED from the reference point
    /truth/extra/<column>                        other truth columns (<= 3 components)
    /<label>/state/<name>                        state estimate, display units
    /<label>/sigma/<name>                        1-sigma from the diagonal of P
    /<label>/error/<name>                        estimate - truth, +3 sigma, -3 sigma
    /<label>/error/{p_N..p_D,v_N..v_D,phi_N..phi_D}   navigation errors (metrics.nav_errors)
    /<label>/error/{p_N,p_E,p_D}/gnss_outage/<k>  the ±3σ band shaded in the k-th GNSS outage
    /<label>/nav/<roll..p_D>                     navigation solution (as /truth/nav)
    /<label>/extra/<key>[_<i>]                   RunResult.extras
    /<label>/nees, /<label>/nees/band            NEES of the declared NEES states, 95 % band
    /<label>/innovation/<meas>/<i>               nu_i, +3 sqrt(S_ii), -3 sqrt(S_ii)
    /<label>/innovation/<meas>/nis[/band]        NIS, 95 % chi-square band
    /world                                       NED, metres from the reference point
    /world/truth/trajectory, /world/<label>/trajectory    LineStrips3D (static)
    /world/truth/gnss_outages, /map/truth/gnss_outages    the true track in the GNSS outages
    /world/{truth,<label>}/body                  Transform3D over time (q_nb as xyzw)
    /world/{truth,<label>}/body/axes             body FRD axes (Arrows3D, static)
    /world/<label>/covariance                    3-sigma position Ellipsoids3D, 1 Hz
    /map/{truth,<label>}/track, .../position     GeoLineStrings (static), GeoPoints (1 Hz)
    /ensemble/<plot>/<series>                    Monte Carlo statistics

Every series is a column send on the timelines ``time`` (duration since the recording start)
and ``timestamp`` (absolute, from ``t0_ns``); style (names, colours) is static per entity.
Each filter label keeps one colour in every plot and tab (:meth:`Sink.color_of`); truth is grey.

Examples
--------
>>> import tempfile, pathlib, numpy as np
>>> from navreplay.filters.result import RunResult
>>> t = np.arange(5) * 0.1
>>> from navreplay.filters.base import Quantity, State
>>> b_g = (State("b_g_x", "rad/s", Quantity.GYRO_BIAS),)
>>> r = RunResult("f", "f", "demo", 0, t, b_g, np.zeros((5, 1)), np.ones((5, 1, 1)))
>>> out = pathlib.Path(tempfile.mkdtemp()) / "demo.rrd"
>>> from navreplay.viz import Save, open_sink
>>> with open_sink(Save(out)) as sink:
...     sink.rows(r)
>>> out.exists()
True
"""

from __future__ import annotations

import copy
import dataclasses
import os
import time
import weakref
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from navreplay import metrics as _metrics
from navreplay.filters.base import Nav, NavError, State, TruthColumn
from navreplay.filters.result import RunResult
from navreplay.geo import quat_wxyz_to_xyzw, radii
from navreplay.metrics import RunMetrics, nav_errors
from navreplay.metrics import outages as _outages
from navreplay.outputs import OutputError, release
from navreplay.streams import Stream
from navreplay.viz import convert
from navreplay.viz.blueprint import Catalog, build_blueprint
from navreplay.viz.naming import (
    NAV_ERROR_NAMES,
    NAV_UNITS,
    display_unit,
    entity_path,
    group_of,
    innovation_rows,
    nav_part,
    quantity_of,
    resolve_unit,
    tab_of,
    title,
)
from navreplay.viz.targets import (
    Save,
    Serve,
    Target,
    VizUnavailableError,
    rrd_problem,
)

APPLICATION_ID = "navreplay"
TIMELINE = "time"
"""Duration since the recording start."""
TIMESTAMP = "timestamp"
"""Absolute time (UNIX epoch)."""

WORLD_RATE_HZ = 10.0
"""Rate of attitude transforms in /world [Hz]."""
COVARIANCE_RATE_HZ = 1.0
"""Rate of the position-covariance ellipsoids and map positions [Hz]."""
TRUTH_RATE_HZ = 20.0
"""Default rate of the truth time series [Hz]; None in :meth:`Sink.log_truth` keeps all rows."""
MAX_STRIP_POINTS = 20_000
"""Trajectory strips are decimated to at most this many points."""
N_SIGMA = 3.0
ELLIPSOID_CAP = 0.25
"""A 3-sigma ellipsoid whose largest semi-axis exceeds this fraction of the trajectory's extent
is drawn scaled down to it (labelled with the factor), so that it does not hide the trajectory;
its true size is in the error plots."""
BAND_LINES = 48
"""A shaded band (NEES/NIS 95 % interval) is drawn as this many dim lines between its bounds:
Rerun 0.41's time-series view has no fill between two series."""
BAND_WIDTH = 8.0
"""Width of each band line [px]."""

TRUTH_COLOR = (150, 150, 150)
OUTAGE_COLOR = (235, 160, 40)
"""GNSS outages: the true track inside them, and (dimmed) the bands that shade them."""
PALETTE = (
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (188, 189, 34), (23, 190, 207),
)  # fmt: skip
"""Filter colours in order of first appearance (grey is reserved for the truth)."""
AXIS_COLORS = ((230, 60, 60), (60, 200, 60), (70, 110, 240))
SIGMA_SHADE = 0.5
"""A predicted sigma beside its RMS is drawn in the same colour this much lighter, and thinner."""
_BACKGROUND = (18, 18, 18)
"""The viewer's dark plot background, that band colours are blended towards."""

# plot ranks (order inside a tab): overlays first, then per-filter rows
_RANK_NAV, _RANK_ERROR, _RANK_STATE, _RANK_SIGMA, _RANK_EXTRA, _RANK_TRUTH = (
    0, 100, 300, 400, 500, 600
)


def _remove(path: Path) -> None:
    release(path)


def lighter(color: tuple[int, ...], f: float) -> tuple[int, int, int]:
    """``color`` moved a fraction ``f`` towards white."""
    r, g, b = (int(round(c + (255 - c) * f)) for c in color[:3])
    return r, g, b


def dimmer(color: tuple[int, ...], f: float) -> tuple[int, int, int]:
    """``color`` moved a fraction ``f`` towards the plot background (an opaque 'transparent'
    colour: Rerun's plot lines ignore alpha)."""
    r, g, b = (int(round(c + (bg - c) * f)) for c, bg in zip(color[:3], _BACKGROUND, strict=True))
    return r, g, b


# ------------------------------------------------------------------------------------------
# the sink


class _Track:
    """The points of a trajectory's static lines (3D strip, map track), collected as its rows
    come: the first row of each time slot, the slot doubled whenever more than twice
    :data:`MAX_STRIP_POINTS` are held. Memory is bounded, and the points kept do not depend on
    how the rows were split (a coarser slot's first row is the first row of a finer slot)."""

    def __init__(self) -> None:
        self.rate = WORLD_RATE_HZ
        self.last = -np.inf
        self.t = np.empty(0)
        self.ned = np.empty((0, 3))
        self.pos = np.empty((0, 3))
        self.logged = False

    def add(self, t: np.ndarray, ned: np.ndarray, pos: np.ndarray) -> None:
        """Rows later than those before: times [s], local NED [m], lat/lon [rad], h."""
        if not t.shape[0]:
            return
        k = convert.decimate(t, self.rate, after=self.last)
        self.last = float(t[-1])
        self.t = np.concatenate([self.t, t[k]])
        self.ned = np.concatenate([self.ned, ned[k]])
        self.pos = np.concatenate([self.pos, pos[k]])
        while self.t.shape[0] > 2 * MAX_STRIP_POINTS:
            self.rate /= 2.0
            k = convert.decimate(self.t, self.rate)
            self.t, self.ned, self.pos = self.t[k], self.ned[k], self.pos[k]


@dataclasses.dataclass
class _TruthLog:
    """Progress of the truth logged so far (whole, or window by window)."""

    root: str
    t0_ns: int
    rate_hz: float | None
    last: float = -np.inf  # time of the last truth row seen [s]
    yaw: tuple[float, float] | None = None  # last raw and unwrapped yaw [rad]
    track: _Track = dataclasses.field(default_factory=lambda: _Track())
    axes: bool = False


@dataclasses.dataclass
class _Run:
    """Logging state of one filter label."""

    label: str
    color: tuple[int, int, int]
    order: int
    units: Mapping[str, str] | None
    states: dict[str, State] = dataclasses.field(default_factory=dict)
    rows: int = 0
    world_t: float = -np.inf
    cov_t: float = -np.inf
    axes: bool = False
    yaw: float | None = None
    geo_t: float = -np.inf
    track: _Track = dataclasses.field(default_factory=lambda: _Track())
    extent_box: tuple[np.ndarray, np.ndarray] | None = None
    """NED box of the true track up to this run's last block (its ellipsoids' caps)."""


class Sink:
    """A Rerun recording stream with navreplay's entity tree; make one with :func:`open_sink`.

    Use as a context manager (closes on success, aborts on an exception) or call
    :meth:`close` / :meth:`abort`.

    A live sink (Spawn, Connect, Serve) sends the default blueprint before the data it lays
    out, and again whenever a plot is added, so a viewer shows navreplay's layout from the
    first sample.

    Attributes
    ----------
    target : Save | Spawn | Connect | Serve
    path : Path or None
        Final .rrd path (Save).
    url : str or None
        gRPC URL (Spawn, Connect, Serve).
    web_url : str or None
        Browser URL (Serve).
    recording_id : str
    catalog : Catalog
        The plots logged so far (the default blueprint is built from it).
    """

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
        self.live = not isinstance(target, Save)
        self._sent: tuple | None = None
        self._colors: dict[str, tuple[int, int, int]] = {}
        self._runs: dict[str, _Run] = {}
        self._styled: set[str] = set()
        self._ref: np.ndarray | None = None
        self._extent = 0.0
        self._box: tuple[np.ndarray, np.ndarray] | None = None  # NED extremes of the truth
        self._truth: convert.NavColumns | None = None
        self._truth_yaw: tuple[np.ndarray, np.ndarray] | None = None  # t [s], unwrapped yaw
        self._truth_log: _TruthLog | None = None
        # extent of the true track up to each time (ellipsoid caps): times [s], extents [m]
        self._extent_curve: tuple[np.ndarray, np.ndarray] | None = None
        self._t0_ns = 0
        self._truth_wanted: dict[str, str] = {}
        self._outages: tuple[tuple[float, float], ...] = ()
        self._truth_columns: set[str] = set()
        self._closed = False
        self._world_coords = False
        self._cleanup = weakref.finalize(self, _remove, tmp) if tmp is not None else None

    # -- context manager -----------------------------------------------------------------

    def __enter__(self) -> Sink:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # -- colours -------------------------------------------------------------------------

    def color_of(self, label: str) -> tuple[int, int, int]:
        """The colour of a filter label (or an ensemble variant) in every plot of this sink:
        :data:`PALETTE` in order of first use."""
        if label not in self._colors:
            self._colors[label] = PALETTE[len(self._colors) % len(PALETTE)]
        return self._colors[label]

    def order_of(self, label: str) -> int:
        """Position of a label in first-use order (the row of its panes)."""
        self.color_of(label)
        return list(self._colors).index(label)

    # -- live layout ---------------------------------------------------------------------

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
                     set(self._truth_columns), self._box, copy.deepcopy(self._truth_log))
            self._rec = _NullStream()  # type: ignore[assignment]
            try:
                log()
            finally:
                (self._rec, self._runs, self._styled, self._ref, self._extent, self._truth,
                 self._truth_yaw, self._world_coords, self._truth_columns, self._box,
                 self._truth_log) = saved
            if self.catalog.signature() != self._sent:
                self.send_blueprint()
        log()
        if self.catalog.signature() != self._sent:
            self.send_blueprint()

    # -- low-level helpers ---------------------------------------------------------------

    @staticmethod
    def _indexes(t: np.ndarray, t0_ns: int) -> list[rr.TimeColumn]:
        dt_ns = np.rint(np.asarray(t, dtype=np.float64) * 1e9).astype(np.int64)
        return [
            rr.TimeColumn(TIMELINE, duration=dt_ns.astype("timedelta64[ns]")),
            rr.TimeColumn(TIMESTAMP, timestamp=(dt_ns + np.int64(t0_ns)).astype("datetime64[ns]")),
        ]

    def _scalars(self, path: str, idx: list[rr.TimeColumn], values: np.ndarray) -> None:
        values = np.ascontiguousarray(values, dtype=np.float64)
        if values.shape[0]:
            self._rec.send_columns(path, indexes=idx, columns=rr.Scalars.columns(scalars=values))

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
        self._rec.log(path, rr.SeriesLines(names=names, colors=colors, widths=widths), static=True)

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
        self._scalars(path, idx, np.stack([value, N_SIGMA * sigma, -N_SIGMA * sigma], axis=1))

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
        self._scalars(path, idx, lines)

    def _run(self, label: str, units: Mapping[str, str] | None) -> _Run:
        run = self._runs.get(label)
        if run is None:
            run = _Run(label, self.color_of(label), self.order_of(label), units)
            self._runs[label] = run
        elif units is not None:
            run.units = units
        return run

    def _set_world(self) -> None:
        if not self._world_coords:
            self._rec.log(
                "/world", rr.ViewCoordinates.FRD, static=True
            )  # NED = x fwd, y right, z down
            self._world_coords = True

    def _axes(self, path: str, size: float) -> None:
        self._rec.log(
            path,
            rr.Arrows3D(vectors=np.eye(3) * size, colors=AXIS_COLORS, labels=["x", "y", "z"]),
            static=True,
        )

    def _strip(
        self, path: str, ned: np.ndarray, color: tuple[int, int, int], width: float = 2.5
    ) -> None:
        ned = ned[np.isfinite(ned).all(axis=1)]
        if ned.shape[0] < 2:
            return
        pts = _thin(ned)
        self._set_world()
        self.catalog.frame(pts.min(axis=0), pts.max(axis=0))
        self._rec.log(path, rr.LineStrips3D([pts], colors=[color], radii=[-width / 2]), static=True)

    def _geo(
        self,
        label: str,
        t: np.ndarray,
        pos: np.ndarray,
        t0_ns: int,
        color: tuple[int, int, int],
        after: float = -np.inf,
    ) -> None:
        """Latitude/longitude for the map view at :data:`COVARIANCE_RATE_HZ` over time (rows
        later than ``after`` [s])."""
        ok = np.isfinite(pos[:, :2]).all(axis=1)
        if not ok.any():
            return
        deg = np.degrees(pos[ok, :2])
        root = entity_path("map", label)
        k = convert.decimate(t[ok], COVARIANCE_RATE_HZ, after=after)
        if k.shape[0]:
            self._rec.send_columns(
                f"{root}/position",
                indexes=self._indexes(t[ok][k], t0_ns),
                columns=rr.GeoPoints.columns(positions=deg[k]),
            )
            if f"{root}/position" not in self._styled:
                self._styled.add(f"{root}/position")
                self._rec.log(
                    f"{root}/position",
                    rr.GeoPoints.from_fields(colors=[color], radii=rr.Radius.ui_points(6.0)),
                    static=True,
                )
        self.catalog.geo = True

    def _log_track(self, label: str, track: _Track, color: tuple[int, int, int],
                   width: float, map_width: float) -> None:
        """The static lines of a trajectory: the 3D strip and the map track (once)."""
        if track.logged:
            return
        track.logged = True
        self._strip(entity_path("world", label, "trajectory"), track.ned, color, width=width)
        ok = np.isfinite(track.pos[:, :2]).all(axis=1)
        if ok.sum() >= 2:
            self._rec.log(
                f"{entity_path('map', label)}/track",
                rr.GeoLineStrings(lat_lon=[_thin(np.degrees(track.pos[ok, :2]))], colors=[color],
                                  radii=rr.Radius.ui_points(map_width / 2)),
                static=True,
            )
            self.catalog.geo = True

    # -- truth ---------------------------------------------------------------------------

    def _log_truth_rows(
        self, stream: Stream, t0: int, entity: str, rate_hz: float | None
    ) -> np.ndarray:
        """Log truth rows later than those before; returns the indices of the rows kept in the
        time series."""
        root = "/" + entity.strip("/")
        log = self._truth_log
        if log is None:
            log = self._truth_log = _TruthLog(root, t0, rate_hz)
        nav = _truth_nav(stream, t0)
        if self._ref is None and nav.t.shape[0]:
            self._ref = nav.pos[0].copy()
        ned = convert.local_ned(nav.pos, self._ref)
        finite = ned[np.isfinite(ned).all(axis=1)]
        if finite.shape[0]:
            lo, hi = finite.min(axis=0), finite.max(axis=0)
            if self._box is not None:
                lo, hi = np.minimum(self._box[0], lo), np.maximum(self._box[1], hi)
            self._box = (lo, hi)
            self._extent = max(self._extent, float(np.max(hi - lo)))
        values = convert.nav_values(nav, self._ref)
        raw = values["yaw"]
        values["yaw"] = _unwrap_after(raw, log.yaw)
        if raw.shape[0]:
            log.yaw = (float(raw[-1]), float(values["yaw"][-1]))
        if self._truth_yaw is None:
            self._truth_yaw = (nav.t, values["yaw"])
        keep = (convert.decimate(nav.t, rate_hz, after=log.last) if rate_hz
                else np.flatnonzero(nav.t > log.last))
        idx = self._indexes(nav.t[keep], t0)
        for name, v in values.items():
            u = display_unit(NAV_UNITS[name])
            path = f"{root}/nav/{name}"
            self._style(path, ["truth"], [TRUTH_COLOR], [2.0])
            self._scalars(path, idx, v[keep] * u.scale)
            self.catalog.add(quantity_of(name).value, f"nav:{name}", title(name, u), path,
                             rank=_RANK_NAV)
        # 3D and map
        world = f"/world{root}"
        w = convert.decimate(nav.t, WORLD_RATE_HZ, after=log.last)
        if w.shape[0]:
            self._rec.send_columns(
                f"{world}/body",
                indexes=self._indexes(nav.t[w], t0),
                columns=rr.Transform3D.columns(translation=ned[w], quaternion=_xyzw(nav.q_nb[w])),
            )
        log.track.add(nav.t, ned, nav.pos)
        self._geo(root.strip("/"), nav.t, nav.pos, t0, TRUTH_COLOR, after=log.last)
        if nav.t.shape[0]:
            log.last = float(nav.t[-1])
        return keep

    def _finish_truth(self) -> None:
        """The static parts of the truth: trajectory, map track and body axes."""
        log = self._truth_log
        if log is None or log.track.logged:
            return
        world = f"/world{log.root}"
        if log.track.t.shape[0]:
            self._axes(f"{world}/body/axes", _axis_size(self._extent))
        self._log_track(log.root.strip("/"), log.track, TRUTH_COLOR, 1.5, 1.5)
        self._log_outage_track(log.root, log.track)

    def _truth_column(self, column: str, unit: str) -> str | None:
        """Entity of a truth column logged with the truth (:meth:`start` named it), or None
        when the truth lacks it or it has more than 3 components."""
        if column in self._truth_columns and self._truth_log is not None:
            return f"{self._truth_log.root}/extra/{entity_path(column)[1:]}"
        return None

    def _truth_column_rows(self, stream: Stream, keep: np.ndarray, t0: int, root: str,
                           column: str, unit: str) -> bool:
        """Log the rows ``keep`` of a truth column; False when the stream lacks it or it has
        more than 3 components."""
        if column not in stream.columns:
            return False
        values = stream.columns[column][keep]
        flat = values.reshape(keep.shape[0], int(np.prod(values.shape[1:], dtype=np.int64)))
        if flat.shape[1] > 3:
            return False
        k = flat.shape[1]
        path = f"{root}/extra/{entity_path(column)[1:]}"
        names = ["truth"] if k == 1 else [f"truth {column}[{j}]" for j in range(k)]
        self._style(path, names, [lighter(TRUTH_COLOR, 0.3 * j) for j in range(k)], [2.0] * k)
        u = display_unit(unit)
        t = (stream.t_ns[keep] - np.int64(t0)).astype(np.float64) * 1e-9
        self._scalars(path, self._indexes(t, t0), flat * u.scale)
        return True

    # -- a replay's stage -----------------------------------------------------------------

    def start(self, run: Any) -> None:
        """A replay over one recording starts (a :class:`navreplay.replay.RunStart`: its start
        time and the truth columns the declared states are scored against)."""
        self._t0_ns = int(run.t0_ns)
        self._truth_wanted = dict(run.truth_columns)
        self._outages = tuple(run.gnss_outages)

    def truth(self, truth: Stream) -> None:
        """Log a window of the truth stream (rows later than those logged before; columns
        ``pos``, ``v_n``, ``q_nb``, and those :meth:`start` named, of up to 3 components); the
        trajectory and map track follow on :meth:`close`."""
        t0_ns = self._t0_ns

        def log() -> None:
            keep = self._log_truth_rows(truth, t0_ns, "/truth", TRUTH_RATE_HZ)
            root = self._truth_log.root if self._truth_log is not None else "/truth"
            for column, unit in self._truth_wanted.items():
                if self._truth_column_rows(truth, keep, t0_ns, root, column, unit):
                    self._truth_columns.add(column)

        self._layout_first(log, plan=self._truth_log is None)

    def rows(self, rows: RunResult, metrics: RunMetrics | None = None,
             truth: Stream | None = None) -> None:
        """Log a block of one run's estimates, later than its blocks before: states, sigmas,
        the navigation solution, errors with their ±3σ and the NEES (a whole run is one block).
        Several runs (labels) share the tabs, each label with its own colour and its own error
        panes.

        Parameters
        ----------
        rows : RunResult
            The block's rows (its innovations go to :meth:`innovations`); entities go under
            ``/<rows.label>``, units, tabs and groups come from ``rows.states`` and
            ``rows.scored_extras``.
        metrics : RunMetrics, optional
            The scores of these rows (:func:`navreplay.metrics.run_metrics`): the errors of the
            scored states with their sigmas, the errors of the scored extras, the NEES with its
            95 % band.
        truth : Stream, optional
            Truth rows around the block (for the navigation errors).
        """
        if not rows.t.shape[0]:
            return
        run = self._run(rows.label, None)
        errors, nees = _from_run_metrics(rows, metrics) if metrics is not None else ({}, None)
        if metrics is not None and metrics.outages:
            self._outages = metrics.outages

        def log() -> None:
            r = self._runs[rows.label]
            self._truth = None if truth is None else _truth_nav(truth, rows.t0_ns)
            box = r.extent_box
            if self._truth is not None and rows.t.shape[0]:
                t, ext, lo, hi = self._track_extent(self._truth, box)
                self._extent_curve = (t, ext)
                k = int(np.searchsorted(t, rows.t[-1], side="right")) - 1
                if k >= 0:
                    box = (lo[k], hi[k])
            self._log_rows(r, rows, 0, rows.t.shape[0])
            r.extent_box = box
            self._log_errors(r, rows, errors)
            if nees is not None:
                self._log_nees(r, rows, *nees)

        self._layout_first(log, plan=run.rows == 0)

    def innovations(self, block: RunResult) -> None:
        """Log the innovations of a block of one run: ``nu`` with ``±3 sqrt(S_ii)`` per row
        and the NIS in its chi-square band, per measurement."""
        self._run(block.label, None)
        if any(s.t.shape[0] for s in block.innovations.values()):
            self._layout_first(lambda: self._log_innovations(self._runs[block.label], block))

    def _finish_run(self, run: _Run) -> None:
        """The static parts of a run: trajectory, map track (and body axes when streamed)."""
        if run.track.logged:
            return
        if not run.axes and run.track.t.shape[0]:
            ned = run.track.ned[np.isfinite(run.track.ned).all(axis=1)]
            if ned.shape[0]:
                extent = self._extent or float(np.max(np.ptp(ned, axis=0)))
                self._axes(entity_path("world", run.label, "body", "axes"), _axis_size(extent))
                run.axes = True
        self._log_track(run.label, run.track, run.color, 2.5, 3.0)

    def _track_extent(
        self, truth: convert.NavColumns, box: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Extent of the true track [m] up to each of its rows (the NED box grown from
        ``box``): times, extents, and the box's low and high corners row by row."""
        ned = convert.local_ned(truth.pos, self._ref) if self._ref is not None else truth.pos
        ok = np.isfinite(ned).all(axis=1)[:, None]
        lo = np.where(ok, ned, np.inf)
        hi = np.where(ok, ned, -np.inf)
        if box is not None and lo.shape[0]:
            lo[0], hi[0] = np.minimum(lo[0], box[0]), np.maximum(hi[0], box[1])
        lo = np.minimum.accumulate(lo, axis=0)
        hi = np.maximum.accumulate(hi, axis=0)
        with np.errstate(invalid="ignore"):
            ext = np.max(hi - lo, axis=1) if lo.shape[0] else np.empty(0)
        return truth.t, np.where(np.isfinite(ext), ext, 0.0), lo, hi

    def _extent_at(self, t: np.ndarray) -> np.ndarray | float:
        """Extent of the true track up to times ``t`` [m] (ellipsoids are capped relative to
        the track drawn so far); the whole extent without a truth."""
        if self._extent_curve is None or not self._extent_curve[0].shape[0]:
            return self._extent
        tt, ext = self._extent_curve
        k = np.searchsorted(tt, t, side="right") - 1
        return np.where(k >= 0, ext[np.clip(k, 0, None)], 0.0)

    def _declare(self, run: _Run, result: RunResult) -> None:
        run.states = {s.name: s for s in (*result.states, *result.scored_extras)}

    def _unit(
        self, run: _Run, name: str, result: RunResult, a: int, b: int
    ) -> tuple[str, float | np.ndarray]:
        """Display unit label and scale of a state or extra: latitude and longitude error
        states in metres north and east, others by their declared (else guessed) SI unit."""
        st = run.states.get(name)
        if st is None:
            u = resolve_unit(name, run.units)
            return u.label, u.scale
        if (
            isinstance(st.truth, NavError)
            and st.truth.q in (Nav.LAT, Nav.LON)
            and result.nav_pos is not None
        ):
            lat, h = result.nav_pos[a:b, 0], result.nav_pos[a:b, 2]
            R_M, R_N = radii(lat)
            return "m", (R_M + h) if st.truth.q is Nav.LAT else (R_N + h) * np.cos(lat)
        u = display_unit(st.unit)
        return u.label, u.scale

    def _tab(self, run: _Run, name: str) -> str:
        st = run.states.get(name)
        return (tab_of(st.quantity) if st is not None else quantity_of(name)).value

    def _log_rows(
        self,
        run: _Run,
        result: RunResult,
        a: int,
        b: int,
    ) -> None:
        if b <= a:
            return
        self._declare(run, result)
        L = run.label
        t = result.t[a:b]
        idx = self._indexes(t, result.t0_ns)
        P = result.P[a:b]
        sigma = np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2), 0.0, None))
        names = list(result.state_names)
        if result.x.shape[1] != len(names) or P.shape[1:] != (len(names), len(names)):
            raise ValueError(
                f"{L}: {len(names)} state names, x has {result.x.shape[1]} columns, P is "
                f"{P.shape[1:]}"
            )
        groups: dict[str, list[str]] = {}
        for n in names:
            groups.setdefault(group_of(n), []).append(n)
        for i, n in enumerate(names):
            label, scale = self._unit(run, n, result, a, b)
            g = group_of(n)
            shade = lighter(run.color, min(0.3 * groups[g].index(n), 0.75))
            legend = L if len(groups[g]) == 1 else f"{L} {n}"
            p_state = entity_path(L, "state", n)
            self._style(p_state, [legend], [shade], [1.5])
            self._scalars(p_state, idx, result.x[a:b, i] * scale)
            # an error state that feedback keeps at zero is logged but gets no plot of its own
            # (its error against the truth and its sigma are what is worth looking at)
            st = run.states.get(n)
            if np.any(result.x[a:b, i] != 0.0):
                self.catalog.add("states", f"state:{g}", f"{g} [{label}]", p_state,
                                 rank=_RANK_STATE)
                if st is not None and isinstance(st.truth, TruthColumn):
                    p_true = self._truth_column(st.truth.column, st.unit)
                    if p_true is not None:
                        self.catalog.add("states", f"state:{g}", f"{g} [{label}]", p_true,
                                         rank=_RANK_STATE)
            p_sig = entity_path(L, "sigma", n)
            self._style(p_sig, [f"σ {legend}"], [shade], [1.5])
            self._scalars(p_sig, idx, sigma[:, i] * scale)
            nav_state = st is not None and isinstance(st.truth, NavError)
            if not nav_state and not self.catalog.has(entity_path(L, "error", n)):
                # sigma of an unscored state; a navigation-error state's is in the nav bounds
                self.catalog.add("states", f"sigma:{g}@{L}", f"{L}: σ {g} [{label}]", p_sig,
                                 rank=_RANK_SIGMA + run.order)
        for key, arr in result.extras.items():
            arr = np.asarray(arr[a:b], dtype=np.float64)
            flat = arr.reshape(b - a, int(np.prod(arr.shape[1:], dtype=np.int64)))
            label, scale = self._unit(run, key, result, a, b)
            path = entity_path(L, "extra", key)
            k = flat.shape[1]
            legend = [L] if k == 1 else [f"{L} {key}[{j}]" for j in range(k)]
            self._style(path, legend, [lighter(run.color, min(0.3 * j, 0.75)) for j in range(k)])
            self._scalars(path, idx, flat * scale)
            self.catalog.add("states", f"extra:{key}", f"{key} [{label}]", path,
                             rank=_RANK_EXTRA)
        if any(result.has(part) for part in ("pos", "v_n", "q_nb")):
            self._log_nav(run, result, a, b, idx)
        run.rows = b

    def _log_nav(
        self,
        run: _Run,
        result: RunResult,
        a: int,
        b: int,
        idx: list[rr.TimeColumn],
    ) -> None:
        """Navigation solution rows [a, b): values, errors vs truth, 3D; of the parts the filter
        outputs only (an attitude-only filter has no position, velocity or 3D trajectory)."""
        L = run.label
        t = result.t[a:b]
        parts = result.navigation
        nav = convert.NavColumns(t, result.nav_pos[a:b], result.nav_v_n[a:b], result.nav_q_nb[a:b])
        if self._ref is None and "pos" in parts:
            finite = np.flatnonzero(np.isfinite(nav.pos).all(axis=1))
            if finite.shape[0] == 0:
                return
            self._ref = nav.pos[finite[0]].copy()
        ref = self._ref if self._ref is not None else np.zeros(3)
        values = {n: v for n, v in convert.nav_values(nav, ref).items()
                  if nav_part(n) in parts}
        if "yaw" in values:
            values["yaw"] = self._unwrap_yaw(run, t, values["yaw"])
        for n, v in values.items():
            u = display_unit(NAV_UNITS[n])
            path = entity_path(L, "nav", n)
            self._style(path, [L], [run.color], [1.5])
            self._scalars(path, idx, v * u.scale)
            self.catalog.add(quantity_of(n).value, f"nav:{n}", title(n, u), path, rank=_RANK_NAV)
        part = result.rows(a, b)
        sig = _metrics.nav_sigma(part)
        nav_sigma = {f"{p}_{ax}": sig[k][:, i]
                     for k, p in (("pos_ned", "p"), ("v_n", "v"), ("phi", "phi"))
                     for i, ax in enumerate("NED")}
        errors: dict[str, tuple[np.ndarray, np.ndarray | None]] = {}
        if self._truth is not None:
            tr = self._truth.at(t)
            ne = nav_errors(nav.pos, nav.v_n, nav.q_nb,
                            {"pos": tr.pos, "v_n": tr.v_n, "q_nb": tr.q_nb}, parts)
            for n, e in ne.columns().items():
                if nav_part(n) not in parts:
                    continue
                s = nav_sigma[n]
                errors[n] = (e, s if np.isfinite(s).any() else None)
        for n, (e, s) in errors.items():
            u = display_unit(NAV_UNITS[n])
            path = entity_path(L, "error", n)
            self._bounded(path, idx, e * u.scale, None if s is None else s * u.scale, L, run.color)
            bounds = "" if s is None else ", ±3σ"
            plot = (quantity_of(n).value, f"error:{n}@{L}", f"{L}: {title(n, u, 'error')}{bounds}")
            self.catalog.add(*plot, path, rank=_RANK_ERROR + run.order, legend=False)
            if s is not None and nav_part(n) == "pos":
                self._shade_outages(path, plot, t, result.t0_ns, N_SIGMA * s * u.scale)
        if "pos" not in parts:
            return
        self._log_world(run, result, nav, a, b, values)
        run.track.add(t, np.stack([values["p_N"], values["p_E"], values["p_D"]], axis=1),
                      nav.pos)
        self._geo(L, t, nav.pos, result.t0_ns, run.color, after=run.geo_t)
        run.geo_t = float(t[-1])

    def _shade_outages(self, path: str, plot: tuple[str, str, str], t: np.ndarray, t0_ns: int,
                       bound: np.ndarray) -> None:
        """Shade each GNSS outage in a plot of rows at times ``t`` [s]: a band between
        ``-bound`` and ``bound`` (the ±3σ of the error) under the series, one entity per
        outage (``<path>/gnss_outage/<k>``, k from 1)."""
        for k, outage in enumerate(self._outages):
            inside = _outages.inside(t, outage)
            if not inside.any():
                continue
            band = f"{path}/gnss_outage/{k + 1}"
            self.band(band, self._indexes(t[inside], t0_ns), -bound[inside], bound[inside],
                      OUTAGE_COLOR, "GNSS outage")
            self.catalog.add(*plot, band, legend=False, behind=True)

    def _log_outage_track(self, root: str, track: _Track) -> None:
        """The true track inside the GNSS outages, over the trajectory (3D) and the map
        track."""
        parts = [k for k in (np.flatnonzero(_outages.inside(track.t, o)) for o in self._outages)
                 if k.shape[0] >= 2]
        if not parts:
            return
        strips = [_thin(track.ned[k]) for k in parts]
        self._rec.log(f"/world{root}/gnss_outages",
                      rr.LineStrips3D(strips, colors=[OUTAGE_COLOR], radii=[-2.5]), static=True)
        geo = [np.degrees(track.pos[k, :2]) for k in parts]
        geo = [g[np.isfinite(g).all(axis=1)] for g in geo]
        geo = [g for g in geo if g.shape[0] >= 2]
        if geo:
            self._rec.log(f"/map{root}/gnss_outages",
                          rr.GeoLineStrings(lat_lon=geo, colors=[OUTAGE_COLOR],
                                            radii=rr.Radius.ui_points(2.5)), static=True)

    def _unwrap_yaw(self, run: _Run, t: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        """Yaw without +-180 deg jumps, continuing the previous rows, on the truth's branch."""
        ok = np.isfinite(yaw)
        if not ok.any():
            return yaw
        out = yaw.copy()
        out[ok] = np.unwrap(yaw[ok])
        first = out[ok][0]
        if run.yaw is not None:
            target = run.yaw
        elif self._truth_yaw is not None and self._truth_yaw[0].size:
            target = float(np.interp(t[ok][0], *self._truth_yaw))
        else:
            target = first
        out += 2.0 * np.pi * np.round((target - first) / (2.0 * np.pi))
        run.yaw = float(out[ok][-1])
        return out

    def _log_world(
        self,
        run: _Run,
        result: RunResult,
        nav: convert.NavColumns,
        a: int,
        b: int,
        values: Mapping[str, np.ndarray],
    ) -> None:
        L = run.label
        ned = np.stack([values["p_N"], values["p_E"], values["p_D"]], axis=1)
        w = convert.decimate(nav.t, WORLD_RATE_HZ, after=run.world_t)
        w = w[np.isfinite(ned[w]).all(axis=1) & np.isfinite(nav.q_nb[w]).all(axis=1)]
        if w.shape[0]:
            self._set_world()
            self.catalog.frame(ned[w].min(axis=0), ned[w].max(axis=0))
            self._rec.send_columns(
                entity_path("world", L, "body"),
                indexes=self._indexes(nav.t[w], result.t0_ns),
                columns=rr.Transform3D.columns(translation=ned[w], quaternion=_xyzw(nav.q_nb[w])),
            )
            run.world_t = float(nav.t[w[-1]])
        P_ned = _position_cov(run, result, a, b)
        if P_ned is None:
            return
        c = convert.decimate(nav.t, COVARIANCE_RATE_HZ, after=run.cov_t)
        c = c[np.isfinite(ned[c]).all(axis=1) & np.isfinite(P_ned[c]).all(axis=(1, 2))]
        if not c.shape[0]:
            return
        half, q = convert.ellipsoids(P_ned[c], N_SIGMA)
        cap = ELLIPSOID_CAP * np.maximum(self._extent_at(nav.t[c]), 10.0)
        factor = np.minimum(1.0, cap / np.maximum(half.max(axis=1), 1e-12))
        labels = ["" if f >= 1.0 else f"{L} 3σ drawn × {f:.2g}" for f in factor]
        cov_path = entity_path("world", L, "covariance")
        if cov_path not in self.catalog.covariances:
            self.catalog.covariances.append(cov_path)
        self._rec.send_columns(
            cov_path,
            indexes=self._indexes(nav.t[c], result.t0_ns),
            columns=rr.Ellipsoids3D.columns(
                centers=ned[c],
                half_sizes=half * factor[:, None],
                quaternions=q,
                colors=np.tile((*run.color, 90), (c.shape[0], 1)),
                labels=labels,
            ),
        )
        run.cov_t = float(nav.t[c[-1]])

    def _log_errors(
        self,
        run: _Run,
        result: RunResult,
        errors: Mapping[str, tuple[np.ndarray, np.ndarray | None, str]],
    ) -> None:
        """Whole-run error series of states and extras, with 3-sigma bounds when known; a
        navigation-error state that feedback keeps at zero is left out (its error is the
        navigation error, plotted already)."""
        if not errors:
            return
        L = run.label
        idx = self._indexes(result.t, result.t0_ns)
        states = {n: i for i, n in enumerate(result.state_names)}
        M = result.t.shape[0]
        for n, (e, s, key) in errors.items():
            st = run.states.get(key)
            if (
                st is not None and isinstance(st.truth, NavError) and n in states
                and result.nav_pos is not None and not np.any(result.x[:, states[n]] != 0.0)
            ):
                continue
            label, scale = self._unit(run, key, result, 0, M)
            tab = self._tab(run, key)
            # a state named like a navigation error (phi_N) keeps its own entity
            path = entity_path(L, "error", f"{n} state" if n in _NAV_ERRORS else n)
            sig = None if s is None else s * scale
            self._bounded(path, idx, e * scale, sig, L, run.color)
            bounds = "" if s is None else ", ±3σ"
            self.catalog.add(tab, f"error:{n}@{L}", f"{L}: {n} error [{label}]{bounds}", path,
                             rank=_RANK_ERROR + run.order, legend=False)
            if n in states:
                self.catalog.discard("states", f"sigma:{group_of(n)}@{L}",
                                     entity_path(L, "sigma", n))

    def _log_nees(self, run: _Run, result: RunResult, t: np.ndarray, nees: np.ndarray,
                  dof: int) -> None:
        """The run's NEES over its declared NEES states, with the 95 % chi-square band."""
        if dof == 0 or not np.isfinite(nees).any():
            return
        L = run.label
        idx = self._indexes(t, result.t0_ns)
        lo, hi = convert.chi2_bounds(dof)
        root = entity_path(L, "nees")
        plot = f"nees@{L}"
        ttl = f"{L}: NEES ({dof} states), 95 % band [-]"
        self.band(f"{root}/band", idx, np.full(t.shape, lo), np.full(t.shape, hi), run.color)
        self.catalog.add("consistency", plot, ttl, f"{root}/band", rank=run.order, legend=False)
        self._style(root, [f"{L} NEES"], [run.color], [1.5])
        self._scalars(root, idx, nees)
        self.catalog.add("consistency", plot, ttl, root, rank=run.order, legend=False)

    def _log_innovations(self, run: _Run, result: RunResult) -> None:
        L = run.label
        for meas, s in result.innovations.items():
            k = s.t.shape[0]
            if k == 0:
                continue
            nu = np.asarray(s.nu, dtype=np.float64).reshape(k, -1)
            dim = nu.shape[1]
            sd = np.sqrt(
                np.clip(
                    np.diagonal(np.asarray(s.S).reshape(k, dim, dim), axis1=1, axis2=2), 0.0, None
                )
            )
            idx = self._indexes(s.t, result.t0_ns)
            rows = innovation_rows(meas, dim, result.measurement(meas), run.units)
            for i, (row, u) in enumerate(rows):
                path = entity_path(L, "innovation", meas, str(i))
                self._bounded(path, idx, nu[:, i] * u.scale, sd[:, i] * u.scale, L, run.color)
                self.catalog.add(
                    "innovation", f"nu:{meas}:{i}@{L}",
                    f"{L}: {meas} innovation {row}, ±3√S [{u.label}]", path,
                    rank=run.order, legend=False,
                )
            lo, hi = convert.chi2_bounds(dim)
            root = entity_path(L, "innovation", meas, "nis")
            plot = f"nis:{meas}@{L}"
            ttl = f"{L}: {meas} NIS ({dim} dof), 95 % band [-]"
            self.band(f"{root}/band", idx, np.full(k, lo), np.full(k, hi), run.color)
            self.catalog.add("consistency", plot, ttl, f"{root}/band", rank=run.order,
                             legend=False)
            self._style(root, [f"{L} NIS"], [run.color], [1.5])
            self._scalars(root, idx, np.asarray(s.nis, dtype=np.float64))
            self.catalog.add("consistency", plot, ttl, root, rank=run.order, legend=False)

    # -- ensembles -----------------------------------------------------------------------

    def log_ensemble(
        self,
        name: str,
        t: np.ndarray,
        series: Mapping[str, np.ndarray],
        *,
        unit: str = "",
        bounds: tuple[np.ndarray | float, np.ndarray | float] | None = None,
        bounds_name: str = "95 % band",
        styles: Mapping[str, tuple[tuple[int, int, int], float]] | None = None,
        tab: str = "ensemble",
        tab_title: str | None = None,
        timeline: str | None = None,
        rank: int = 0,
        legend: bool = True,
        shaded: Sequence[tuple[float, float]] = (),
    ) -> None:
        """Log one Monte Carlo plot under ``/ensemble/<name>/<series>``.

        Parameters
        ----------
        name : str
            Plot name, e.g. ``"roll error"`` or ``"NEES"``.
        t : ndarray, shape (K,)
            Time [s since the recording start], or the abscissa on ``timeline``.
        series : mapping str -> ndarray (K,)
            Overlaid series in display units, e.g. ``{"rpm RMS": ..., "rpm mean σ": ...,
            "pure RMS": ...}``.
        unit : str
            Unit of every series, shown in the title (``"deg"``, ``"m"``, ``"-"``).
        bounds : (lower, upper), optional
            Scalars or arrays (K,), e.g. :func:`navreplay.viz.chi2_bounds` for the average
            NEES; drawn as a shaded band (:meth:`band`).
        styles : mapping, optional
            Colour and width per series; a series without one takes the colour of its name
            (:meth:`color_of`), so a variant keeps its colour in every plot.
        tab, tab_title : str, optional
            Tab key and title (default: one "Ensemble" tab).
        timeline : str, optional
            Put ``t`` on this sequence timeline instead of ``time`` (e.g. an acceleration
            sweep in mg): ``t`` is rounded to integers.
        rank : int
            Order of the plot in its tab.
        legend : bool
            Whether the plot shows its legend.
        shaded : sequence of (start, end)
            Spans of ``t`` (GNSS outages) shaded under the series, each
            ``/ensemble/<name>/gnss_outage/<k>``.
        """
        t = np.asarray(t, dtype=np.float64)

        def index(tt: np.ndarray) -> list[rr.TimeColumn]:
            if timeline is None:
                return [rr.TimeColumn(TIMELINE,
                                      duration=np.rint(tt * 1e9).astype("timedelta64[ns]"))]
            return [rr.TimeColumn(timeline, sequence=np.rint(tt).astype(np.int64))]

        idx = index(t)
        if timeline is not None and self.catalog.timeline == TIMELINE and not any(
            p for k, plots in self.catalog.plots.items() for p in plots
        ):
            self.catalog.timeline = timeline
        root = entity_path("ensemble", name)
        plot_title = f"{name} [{unit}]" if unit else name
        styles = styles or {}
        if bounds is not None:
            path = f"{root}/bounds"
            lo = np.broadcast_to(np.asarray(bounds[0], dtype=np.float64), t.shape)
            hi = np.broadcast_to(np.asarray(bounds[1], dtype=np.float64), t.shape)
            self.band(path, idx, lo, hi, TRUTH_COLOR, bounds_name)
            self.catalog.add(tab, f"ensemble:{name}", plot_title, path, rank=rank,
                             legend=legend, tab_title=tab_title)
        for key, values in series.items():
            values = np.asarray(values, dtype=np.float64)
            if values.shape != t.shape:
                raise ValueError(
                    f"ensemble {name!r}: series {key!r} has shape {values.shape}, t {t.shape}"
                )
            path = f"{root}/{entity_path(key)[1:]}"
            color, width = styles[key] if key in styles else self._variant_style(key)
            self._style(path, [key], [color], [width])
            self._scalars(path, idx, values)
            self.catalog.add(tab, f"ensemble:{name}", plot_title, path, rank=rank,
                             legend=legend, tab_title=tab_title)
        if shaded and series:
            top = np.fmax.reduce([np.asarray(v, dtype=np.float64) for v in series.values()])
            for k, span in enumerate(shaded):
                inside = _outages.inside(t, span) & np.isfinite(top)
                if not inside.any():
                    continue
                path = f"{root}/gnss_outage/{k + 1}"
                self.band(path, index(t[inside]), np.zeros(int(inside.sum())), top[inside],
                          OUTAGE_COLOR, "GNSS outage")
                self.catalog.add(tab, f"ensemble:{name}", plot_title, path, rank=rank,
                                 legend=legend, tab_title=tab_title, behind=True)

    def _variant_style(self, key: str) -> tuple[tuple[int, int, int], float]:
        """Colour and width of an ensemble series named ``"<variant>[ RMS| sigma| σ]"``: the
        variant's colour; a sigma lighter and thinner than its RMS; ``"truth"`` grey."""
        if key == "truth":
            return TRUTH_COLOR, 2.0
        for suffix, sigma in ((" RMS", False), (" mean σ", True), (" sigma", True), (" σ", True)):
            if key.endswith(suffix) and len(key) > len(suffix):
                color = self.color_of(key[: -len(suffix)])
                return (lighter(color, SIGMA_SHADE), 1.0) if sigma else (color, 2.0)
        return self.color_of(key), 1.5

    # -- blueprint and lifecycle ---------------------------------------------------------

    def blueprint(self) -> rrb.Blueprint:
        """The default blueprint for what has been logged so far."""
        return build_blueprint(self.catalog)

    def send_blueprint(self) -> None:
        """Send the default blueprint now (also done by :meth:`close`, and by a live sink
        before the data of every new plot)."""
        self._sent = self.catalog.signature()
        self._rec.send_blueprint(self.blueprint(), make_active=True, make_default=True)

    def flush(self, timeout: float = 30.0) -> None:
        """Wait until the logged data has left the process (raises VizUnavailableError)."""
        try:
            self._rec.flush(timeout_sec=timeout)
        except RuntimeError as e:
            raise VizUnavailableError(f"Rerun sink {self.url or self.path}: {e}") from None

    def close(self, timeout: float = 30.0) -> Path | str | None:
        """Send the blueprint, flush and finish; a Save renames its temporary file onto the
        target. Returns the .rrd path or the viewer URL."""
        if self._closed:
            return self.path or self.url
        try:
            self._finish_truth()
            for run in self._runs.values():
                self._finish_run(run)
            self.send_blueprint()
            self.flush(timeout)
            if not self._keep_alive:  # a served stream keeps its server up for late browsers
                self._rec.disconnect()
        except BaseException as e:
            problem = rrd_problem(self._tmp) if self._tmp is not None else None
            self.abort()
            if problem is not None and isinstance(e, VizUnavailableError):
                raise OutputError(f"{self.path}: the Rerun view is {problem}; nothing was "
                                  "saved") from None
            raise
        if self._tmp is not None and self.path is not None:
            problem = rrd_problem(self._tmp)  # rerun reports a failed write only in its log
            if problem is not None:
                self.abort()
                raise OutputError(f"{self.path}: the Rerun view is {problem}; nothing was "
                                  "saved")
            os.replace(self._tmp, self.path)
        self._closed = True
        return self.path or self.url

    def abort(self) -> None:
        """Stop without publishing: a Save's temporary file is deleted, the target untouched."""
        if self._closed:
            return
        self._closed = True
        try:
            self._rec.disconnect()
        finally:
            if self._tmp is not None:
                self._tmp.unlink(missing_ok=True)

    def wait(self) -> None:
        """Keep this process (and so a served viewer) up until Ctrl-C; returns at once for the
        other targets."""
        if not isinstance(self.target, Serve):
            return
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass


# ------------------------------------------------------------------------------------------
# helpers

_NAV_ERRORS = tuple(n for names in NAV_ERROR_NAMES.values() for n in names)


class _NullStream:
    """Stands in for the recording stream while a live sink lays out what it will log."""

    def send_columns(self, *args: Any, **kwargs: Any) -> None:
        pass

    def log(self, *args: Any, **kwargs: Any) -> None:
        pass


def _thin(pts: np.ndarray) -> np.ndarray:
    """At most :data:`MAX_STRIP_POINTS` of ``pts``, keeping the last."""
    step = max(1, int(np.ceil(pts.shape[0] / MAX_STRIP_POINTS)))
    return np.concatenate([pts[::step], pts[-1:]]) if (pts.shape[0] - 1) % step else pts[::step]


def _truth_nav(stream: Stream, t0_ns: int) -> convert.NavColumns:
    """The truth's solution; parts a reference lacks (a position-only one) are NaN."""
    n = len(stream)
    parts = [stream.columns.get(c, np.full((n, w), np.nan))
             for c, w in (("pos", 3), ("v_n", 3), ("q_nb", 4))]
    t = (stream.t_ns - np.int64(t0_ns)).astype(np.float64) * 1e-9
    return convert.NavColumns(t, *parts)


def _unwrap_after(yaw: np.ndarray, previous: tuple[float, float] | None) -> np.ndarray:
    """``yaw`` unwrapped, continuing rows whose last raw and unwrapped values are
    ``previous``."""
    if previous is None:
        return np.unwrap(yaw)
    return np.unwrap(np.concatenate([[previous[0]], yaw]))[1:] + (previous[1] - previous[0])


def _xyzw(q_nb: np.ndarray) -> np.ndarray:
    return quat_wxyz_to_xyzw(q_nb)


def _axis_size(extent: float) -> float:
    return max(1.0, 0.03 * extent)


def _from_run_metrics(
    result: RunResult, m: RunMetrics
) -> tuple[dict[str, tuple[np.ndarray, np.ndarray | None, str]], tuple | None]:
    """Error columns (scored states with their sigmas, scored extras) and the NEES of a run's
    metrics."""
    out: dict[str, tuple[np.ndarray, np.ndarray | None, str]] = {}
    for j, name in enumerate(m.state_names):
        out[name] = (m.state_error[:, j], np.sqrt(np.clip(m.state_var[:, j], 0.0, None)), name)
    M = result.t.shape[0]
    for key, err in m.extra_error.items():
        err = np.asarray(err, dtype=np.float64)
        cols = err.reshape(M, int(np.prod(err.shape[1:], dtype=np.int64)))
        for j in range(cols.shape[1]):
            out[key if cols.shape[1] == 1 else f"{key}_{j}"] = (cols[:, j], None, key)
    nees = (m.t, m.nees, len(m.nees_states)) if m.nees_states else None
    return out, nees


_POSITION_STATES = ((Nav.LAT, Nav.LON, Nav.H, -1.0), (Nav.LAT, Nav.LON, Nav.DEPTH, 1.0))


def _position_cov(run: _Run, result: RunResult, a: int, b: int) -> np.ndarray | None:
    """Position-error covariance in NED metres for rows [a, b) from the declared latitude,
    longitude and height (or depth) error states, or None."""
    where = {
        s.truth.q: i for i, s in enumerate(result.states) if isinstance(s.truth, NavError)
    }
    if result.nav_pos is None:
        return None
    for lat, lon, vert, sign in _POSITION_STATES:
        if lat in where and lon in where and vert in where:
            states = convert.PositionStates((where[lat], where[lon], where[vert]), True, sign)
            return convert.position_cov_ned(result.P[a:b], states, result.nav_pos[a:b])
    return None

