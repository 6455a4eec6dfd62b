"""The default Rerun blueprint, built from what a sink has logged.

A :class:`Catalog` records every plotted series (entity path, tab, plot, title); the sink fills
it while logging. :func:`build_blueprint` turns it into tabs of grids of time-series views, one
view per plot. Plots of one quantity that several filters share (the navigation solution with
the truth, state estimates) overlay the filters; errors, NEES and NIS are one pane per filter,
each at its own scale, so that a filter with small errors is not flattened by one with large
ones (a row per filter, a column per component):

=================  =====================================================================
tab                views
=================  =====================================================================
Compare            horizontal and vertical position, velocity and heading error of every
                   filter overlaid (one colour per filter, by name); their CDFs; the
                   headline metrics of the summaries as a table
Attitude           roll, pitch, yaw [deg] (yaw unwrapped); per filter phi_N, phi_E, phi_D
                   errors with +-3 sigma; attitude states
Velocity           velocity N/E/D [m/s]; per filter their errors with +-3 sigma
Position           position N/E/D [m] (local NED); per filter their errors [m] with +-3 sigma
Sensor errors      a column per filter: the other states' errors with +-3 sigma, a row per
                   group of components (frozen states, of zero sigma, left out)
State estimates    a column per filter: states that move, with the truth column they
                   estimate, sigmas of unscored states, extras
NEES / NIS         per filter the NEES and each measurement's NIS with the 95 % band
Innovations        per filter, measurement and component: nu with +-3 sqrt(S_ii)
Trajectory         top-down N/E (north up) and the 3D view, both framed on the trajectory
Map                latitude/longitude on a map (tiles need a network)
Ensemble ...       Monte Carlo statistics, one tab per group (position, velocity, ...)
=================  =====================================================================

Empty tabs are left out. Legends are shown only where several series share a view and take
little space (top right, filter labels only); a per-filter pane names its filter in its title
(after what it shows in the tabs of a column per filter, where panes are narrow).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from navreplay.viz.ranges import Envelope, YRange, time_range, y_range

TABS: tuple[tuple[str, str], ...] = (
    ("compare", "Compare"),
    ("attitude", "Attitude"),
    ("velocity", "Velocity"),
    ("position", "Position"),
    ("sensor", "Sensor errors"),
    ("states", "State estimates"),
    ("consistency", "NEES / NIS"),
    ("innovation", "Innovations"),
    ("world", "Trajectory"),
    ("map", "Map"),
    ("ensemble", "Ensemble"),
)
"""Tab keys in display order and their titles; other tabs (ensemble groups) follow in the order
they were first used."""


@dataclasses.dataclass
class Plot:
    """One time-series view.

    Attributes
    ----------
    title : str
        View name, with the unit.
    paths : list[str]
        Entities shown.
    rank : int
        Order within the tab (lower first); ties keep the order of first use.
    legend : bool
        Whether the view shows its legend.
    """

    title: str
    paths: list[str]
    rank: int = 0
    legend: bool = True
    kind: str = "series"
    """``series`` (a time-series view), ``bars`` (a bar chart: the CDFs) or ``text``."""
    column: str | None = None
    """The filter whose column of the tab the plot is in (tabs laid out a column per filter);
    None for plots the filters share."""
    row: str | None = None
    """Plots of one column with the same row (a group of components) share a row."""


@dataclasses.dataclass
class Catalog:
    """What has been logged, grouped into plots.

    Attributes
    ----------
    plots : dict[str, dict[str, Plot]]
        Per tab key: plot key -> plot, in insertion order.
    tab_titles : dict[str, str]
        Titles of the tabs not in :data:`TABS`.
    world : tuple[ndarray, ndarray] or None
        Lower and upper NED corner [m] of the trajectories under ``/world`` (frames the views).
    geo : bool
        Whether anything was logged under ``/map``.
    timeline : str
        Timeline selected in the time panel.
    """

    plots: dict[str, dict[str, Plot]] = dataclasses.field(
        default_factory=lambda: {key: {} for key, _ in TABS}
    )
    tab_titles: dict[str, str] = dataclasses.field(default_factory=dict)
    world: tuple[np.ndarray, np.ndarray] | None = None
    geo: bool = False
    timeline: str = "time"
    covariances: list[str] = dataclasses.field(default_factory=list)
    """Ellipsoid entities under ``/world`` (left out of the top-down view)."""
    envelopes: dict[str, Envelope] = dataclasses.field(default_factory=dict)
    """Per series on the ``time`` timeline, the extent of its values over time (the y range
    its pane opens on)."""
    names: dict[str, list[str]] = dataclasses.field(default_factory=dict)
    """Per series, the names its legend shows."""
    legend: list[tuple[str, tuple[int, int, int]]] = dataclasses.field(default_factory=list)
    """The filters drawn in the trajectory views and on the map, with their colours."""
    scale_bar: float | None = None
    """Length [m] of the scale bar drawn in the trajectory views and on the map."""
    _paths: set[str] = dataclasses.field(default_factory=set, repr=False)

    def add(
        self,
        tab: str,
        plot: str,
        title: str,
        path: str,
        *,
        rank: int = 0,
        legend: bool = True,
        tab_title: str | None = None,
        kind: str = "series",
        column: str | None = None,
        row: str | None = None,
        behind: bool = False,
    ) -> None:
        """Put the series at ``path`` into plot ``plot`` (created with ``title``, ``rank``,
        ``legend``, ``kind``, ``column`` and ``row``) of ``tab`` (created with ``tab_title`` if
        it is not one of :data:`TABS`); ``behind``: before the series already there (drawn
        under them, as a shaded band)."""
        if tab not in self.plots:
            self.plots[tab] = {}
            self.tab_titles[tab] = tab_title or tab
        plots = self.plots[tab]
        if plot not in plots:
            plots[plot] = Plot(title, [], rank, legend, kind, column, row)
        paths = plots[plot].paths
        if path not in paths:
            paths.insert(0 if behind else len(paths), path)
            self._paths.add(path)

    def discard(self, tab: str, plot: str, path: str) -> None:
        """Take ``path`` out of a plot; a plot left empty disappears."""
        if path not in self._paths:  # in no plot
            return
        plots = self.plots.get(tab, {})
        if plot in plots and path in plots[plot].paths:
            plots[plot].paths.remove(path)
            if not plots[plot].paths:
                del plots[plot]
        if not any(path in p.paths
                   for tab_plots in self.plots.values() for p in tab_plots.values()):
            self._paths.discard(path)

    def has(self, path: str) -> bool:
        """Whether ``path`` is in some plot."""
        return path in self._paths

    def paths(self) -> list[str]:
        """Every catalogued entity path, in plot order."""
        return [p for plots in self.plots.values() for plot in plots.values() for p in plot.paths]

    def frame(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Grow the NED box [m] that the trajectory views are framed on."""
        if self.world is None:
            self.world = (np.array(lo, dtype=float), np.array(hi, dtype=float))
        else:
            self.world = (np.minimum(self.world[0], lo), np.maximum(self.world[1], hi))

    def signature(self) -> tuple:
        """What the blueprint depends on (to resend it only when this changes)."""
        world = (None if self.world is None
                 else tuple(float(v) for v in np.round(np.concatenate(self.world), 1)))
        return (
            tuple((t, k, len(p.paths))
                  for t, plots in self.plots.items() for k, p in plots.items()),
            world,
            len(self.covariances),
            self.geo,
            self.timeline,
        )


def build_blueprint(catalog: Catalog, *, grid_columns: int = 3,
                    ranges: bool = True) -> rrb.Blueprint:
    """Tabs of grids of time-series views for the catalogued plots, the trajectory views and
    the map.

    Parameters
    ----------
    catalog : Catalog
    grid_columns : int
        Views per grid row (a row per filter for the per-filter panes of N, E, D components).
    ranges : bool
        Open each time-series pane on the y range of its data (:func:`ranges.y_range`: a
        minimum span, the start-up left out where it would flatten the result, room for the
        legend) and every pane on the run's time span with a margin; else the viewer's
        automatic ranges.
    """
    rg = _Ranges(catalog.envelopes, catalog.names) if ranges else None
    tabs: list[rrb.Container] = []
    order = [k for k, _ in TABS] + [k for k in catalog.plots if k not in dict(TABS)]
    titles = {**dict(TABS), **catalog.tab_titles}
    for key in order:
        if key == "world":
            if catalog.world is not None:
                tabs.append(_trajectory_tab(catalog.world, catalog.covariances, titles[key],
                                            catalog))
            continue
        if key == "map":
            if catalog.geo:
                views: list[rrb.View] = [rrb.MapView(origin="/map", name="latitude / longitude")]
                if catalog.legend:
                    views.append(_legend_view(catalog))
                tabs.append(rrb.Vertical(*views, row_shares=[12.0, 1.0][:len(views)],
                                         name=titles[key]))
            continue
        plots = catalog.plots.get(key, {})
        if not plots:
            continue
        ordered = sorted(plots.values(), key=lambda p: p.rank)  # stable: first use breaks ties
        if key == "compare":
            tabs.append(_compare_tab(ordered, titles[key], rg))
        elif any(p.column is not None for p in ordered):
            tabs.extend(_column_tabs(ordered, titles[key], grid_columns, rg))
        else:
            views = [_view(p, rg) for p in ordered]
            cols = min(grid_columns, len(views))
            per_page = cols * GRID_ROWS_PER_PAGE if key.startswith("ensemble") else len(views)
            pages = [views[i:i + per_page] for i in range(0, len(views), per_page)]
            for k, page in enumerate(pages):
                title = titles[key] if len(pages) == 1 else f"{titles[key]} ({k + 1}/{len(pages)})"
                tabs.append(rrb.Grid(*page, grid_columns=cols, name=title))
    # side panels collapsed: the plots get the whole window (each panel opens with one click)
    panels = (
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        # the time cursor at the last time: the 3D view and the map show the whole run
        rrb.TimePanel(timeline=catalog.timeline, state="collapsed", play_state="following"),
    )
    if not tabs:
        return rrb.Blueprint(rrb.TimeSeriesView(origin="/", name="all", axis_x=_WHOLE_RUN),
                             *panels)
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), *panels)


class _Ranges:
    """The ranges the panes open on, from the series' envelopes."""

    def __init__(self, envelopes: dict[str, Envelope], names: dict[str, list[str]]) -> None:
        self.envelopes = envelopes
        self.names = names
        spans = [(e.t_first, e.t_last) for e in envelopes.values() if np.isfinite(e.t_first)]
        self.time = (time_range(min(a for a, _ in spans), max(b for _, b in spans))
                     if spans else None)

    def y(self, plot: Plot) -> YRange | None:
        envs = [self.envelopes[p] for p in plot.paths if p in self.envelopes]
        entries = len({n for p in plot.paths for n in self.names.get(p, ())})
        return y_range(envs, legend=entries if plot.legend else 0) if envs else None

    def time_axis(self) -> rrb.TimeAxis:
        if self.time is None:
            return _WHOLE_RUN
        lo, hi = self.time
        return rrb.TimeAxis(view_range=rr.TimeRange(
            start=rrb.TimeRangeBoundary.absolute(seconds=lo),
            end=rrb.TimeRangeBoundary.absolute(seconds=hi)))


SETTLED_NOTE = " (y: after start-up)"
"""Appended to the title of a pane whose y range leaves out the start-up transient."""


def _view(plot: Plot, rg: _Ranges | None = None) -> rrb.View:
    contents = [f"+ {p}" for p in plot.paths]
    if plot.kind == "text":
        return rrb.TextDocumentView(origin="/", contents=contents, name=plot.title)
    if plot.kind == "bars":
        return rrb.BarChartView(
            origin="/", contents=contents, name=plot.title,
            plot_legend=rrb.PlotLegend(rrb.Corner2D.RightBottom, visible=plot.legend),
        )
    y = rg.y(plot) if rg is not None else None
    on_time = y is not None  # a series of the time timeline (not a sweep's sequence)
    return rrb.TimeSeriesView(
        origin="/",
        contents=contents,
        name=plot.title + (SETTLED_NOTE if y is not None and y.settled else ""),
        plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftTop, visible=plot.legend),
        axis_x=rg.time_axis() if on_time and rg is not None else _WHOLE_RUN,
        axis_y=rrb.ScalarAxis(range=(y.lo, y.hi)) if y is not None else None,
    )


def _compare_tab(plots: list[Plot], name: str, rg: _Ranges | None) -> rrb.Container:
    """The overlaid errors in a row, their CDFs in a row below, the table of headline metrics
    at the bottom."""
    rows = []
    shares = []
    for kind, share in (("series", 3.0), ("bars", 3.0), ("text", 2.6)):
        views = [_view(p, rg) for p in plots if p.kind == kind]
        if views:
            rows.append(rrb.Grid(*views, grid_columns=min(4, len(views))))
            shares.append(share * max(1, -(-len(views) // 4)))
    return rrb.Vertical(*rows, row_shares=shares, name=name)


GRID_ROWS_PER_PAGE = 4
"""Rows of panes per tab in the tabs laid out as a grid (the Monte Carlo tabs): more go to
further tabs, ``Ensemble states (2/4)``."""


ROWS_PER_PAGE = 3
"""Rows of panes per tab in the tabs laid out a column per filter: more rows go to further
tabs (``Sensor errors: m_a, b_a, b_g``), so a pane keeps the height its tick labels need."""


def _column_tabs(plots: list[Plot], name: str, grid_columns: int,
                 rg: _Ranges | None) -> list[rrb.Container]:
    """A column per filter (its plots one row per group of components, so the same state of
    two filters sits side by side), after a grid of the plots the filters share; at most
    :data:`ROWS_PER_PAGE` rows per tab, each further tab titled by its rows."""
    shared = [_view(p, rg) for p in plots if p.column is None]
    columns: dict[str, dict[str, list[Plot]]] = {}
    for p in plots:
        if p.column is not None:
            columns.setdefault(p.column, {}).setdefault(p.row or p.title, []).append(p)
    rows = sorted({r for col in columns.values() for r in col},  # by rank, then by name
                  key=lambda r: (min(p.rank for col in columns.values() for p in col.get(r, [])),
                                 r))
    width = max((len(ps) for col in columns.values() for ps in col.values()), default=1)
    pages = [rows[i:i + ROWS_PER_PAGE] for i in range(0, len(rows), ROWS_PER_PAGE)] or [[]]
    tabs: list[rrb.Container] = []
    for k, page in enumerate(pages):
        title = name if len(pages) == 1 else f"{name}: {', '.join(page)}"
        cols = []
        for label, col in columns.items():
            cells: list[rrb.Container | rrb.View] = []
            for r in page:
                views = [_view(p, rg) for p in col.get(r, [])]
                cells.append(rrb.Horizontal(*views) if len(views) > 1 else views[0] if views
                             else rrb.Horizontal())
            cols.append(rrb.Vertical(*cells, name=label))
        if not shared or k:
            tabs.append(rrb.Horizontal(*cols, name=title))
            continue
        top = rrb.Grid(*shared, grid_columns=min(max(grid_columns, width), len(shared)))
        tabs.append(rrb.Vertical(top, rrb.Horizontal(*cols), row_shares=[1.0, float(len(page))],
                                 name=title))
    return tabs


def _legend_view(catalog: Catalog) -> rrb.View:
    """The key of the trajectory views and the map: a dot per track in its colour (and the
    scale bar's length)."""
    n = len(catalog.legend) + (catalog.scale_bar is not None)
    return rrb.Spatial2DView(origin="/legend", name="legend",
                             visual_bounds=rrb.VisualBounds2D(x_range=[-3.0, 7.0 * n],
                                                              y_range=[-1.0, 1.6]))


def _trajectory_tab(
    box: tuple[np.ndarray, np.ndarray], covariances: list[str], name: str,
    catalog: Catalog | None = None,
) -> rrb.Container:
    """Top-down N/E view (camera above the trajectory, north up) beside the 3D view, both
    framed on the NED box [m] of the trajectories, with a grid of the scale bar's length and
    the legend."""
    lo, hi = box
    centre = 0.5 * (lo + hi)
    span = float(max(np.max(hi[:2] - lo[:2]), 10.0))
    bar = catalog.scale_bar if catalog is not None else None
    grid = f", grid {bar:g} m" if bar else ""
    top = rrb.Spatial3DView(
        origin="/world",
        name=f"top-down N/E [m] (north up){grid}",
        contents=["+ /world/**", *(f"- {p}" for p in covariances)],
        eye_controls=rrb.EyeControls3D(
            position=(centre[0], centre[1], centre[2] - 1.25 * span),
            look_target=tuple(centre),
            eye_up=(1.0, 0.0, 0.0),  # north at the top of the screen
        ),
        line_grid=(rrb.LineGrid3D(visible=True, spacing=bar, plane=rr.components.Plane3D.XY)
                   if bar else rrb.LineGrid3D(visible=False)),
    )
    persp = rrb.Spatial3DView(
        origin="/world",
        name=f"3D NED [m], 3-sigma position ellipsoids{grid}",
        eye_controls=rrb.EyeControls3D(
            position=(centre[0] - 0.8 * span, centre[1] - 0.8 * span, centre[2] - 0.6 * span),
            look_target=tuple(centre),
            eye_up=(0.0, 0.0, -1.0),
        ),
        line_grid=(rrb.LineGrid3D(visible=True, spacing=bar, plane=rr.components.Plane3D.XY)
                   if bar else None),
    )
    if catalog is None or not catalog.legend:
        return rrb.Horizontal(top, persp, name=name)
    return rrb.Vertical(rrb.Horizontal(top, persp), _legend_view(catalog),
                        row_shares=[12.0, 1.0], name=name)


# Plots show the whole run (the viewer's default is a window around the time cursor).
_WHOLE_RUN = rrb.TimeAxis(
    view_range=rr.TimeRange(
        start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
    )
)
