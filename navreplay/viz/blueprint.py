"""The default Rerun blueprint, built from what a sink has logged.

A :class:`Catalog` records every plotted series (entity path, tab, plot, title); the sink fills
it while logging. :func:`build_blueprint` turns it into tabs of grids of time-series views, one
view per plot, in which every filter's series overlay the truth:

=================  =====================================================================
tab                views
=================  =====================================================================
Attitude           roll, pitch, yaw [deg]; their errors; attitude-error states
Velocity           velocity N/E/D [m/s]; their errors; velocity-error states
Position           position N/E/D [m] (local NED); their errors; position-error states
Sensor errors      the other states grouped by prefix (``db_g_x..z`` in one view), their
                   errors with +-3 sigma, extras
Innovations        per measurement: components with +-3 sqrt(S_ii), NIS with 95 % bounds
3D                 /world: trajectories, body axes, 3-sigma position ellipsoids (NED)
Ensemble           one view per :meth:`~navreplay.viz.Sink.log_ensemble` plot
=================  =====================================================================

Empty tabs are left out.
"""

from __future__ import annotations

import dataclasses

import rerun as rr
import rerun.blueprint as rrb

TABS: tuple[tuple[str, str], ...] = (
    ("attitude", "Attitude"),
    ("velocity", "Velocity"),
    ("position", "Position"),
    ("sensor", "Sensor errors"),
    ("innovation", "Innovations"),
    ("world", "3D"),
    ("ensemble", "Ensemble"),
)
"""Tab keys in display order and their titles."""


@dataclasses.dataclass
class Catalog:
    """What has been logged, grouped into plots.

    Attributes
    ----------
    plots : dict[str, dict[str, tuple[str, list[str]]]]
        Per tab key: plot key -> (title, entity paths), in insertion order.
    world : bool
        Whether anything was logged under ``/world``.
    """

    plots: dict[str, dict[str, tuple[str, list[str]]]] = dataclasses.field(
        default_factory=lambda: {key: {} for key, _ in TABS}
    )
    world: bool = False
    _paths: set[str] = dataclasses.field(default_factory=set, repr=False)

    def add(self, tab: str, plot: str, title: str, path: str) -> None:
        """Put the series at ``path`` into plot ``plot`` (created with ``title``) of ``tab``."""
        plots = self.plots[tab]
        if plot not in plots:
            plots[plot] = (title, [])
        paths = plots[plot][1]
        if path not in paths:
            paths.append(path)
            self._paths.add(path)

    def discard(self, tab: str, plot: str, path: str) -> None:
        """Take ``path`` out of a plot; a plot left empty disappears."""
        plots = self.plots[tab]
        if plot in plots and path in plots[plot][1]:
            plots[plot][1].remove(path)
            if not plots[plot][1]:
                del plots[plot]
        if not any(path in ps for tab_plots in self.plots.values() for _, ps in tab_plots.values()):
            self._paths.discard(path)

    def has(self, path: str) -> bool:
        """Whether ``path`` is in some plot."""
        return path in self._paths

    def paths(self) -> list[str]:
        """Every catalogued entity path, in plot order."""
        return [p for plots in self.plots.values() for _, ps in plots.values() for p in ps]


def build_blueprint(catalog: Catalog, *, grid_columns: int = 3) -> rrb.Blueprint:
    """Tabs of grids of time-series views for the catalogued plots, and the 3D view.

    Parameters
    ----------
    catalog : Catalog
    grid_columns : int
        Views per grid row.
    """
    tabs: list[rrb.Container] = []
    for key, name in TABS:
        if key == "world":
            if catalog.world:
                tabs.append(
                    rrb.Horizontal(
                        rrb.Spatial3DView(origin="/world", name="3D (NED) [m]"), name=name
                    )
                )
            continue
        plots = catalog.plots[key]
        if not plots:
            continue
        ordered = sorted(plots.items(), key=lambda kv: _rank(kv[0]))
        views = [
            rrb.TimeSeriesView(
                origin="/",
                contents=[f"+ {p}" for p in paths],
                name=title,
                plot_legend=rrb.Corner2D.LeftTop,
                axis_x=_WHOLE_RUN,
            )
            for _, (title, paths) in ordered
        ]
        tabs.append(rrb.Grid(*views, grid_columns=min(grid_columns, len(views)), name=name))
    if not tabs:
        return rrb.Blueprint(
            rrb.TimeSeriesView(origin="/", name="all", axis_x=_WHOLE_RUN),
            rrb.TimePanel(timeline="time"),
            collapse_panels=False,
        )
    return rrb.Blueprint(
        rrb.Tabs(*tabs, active_tab=0), rrb.TimePanel(timeline="time"), collapse_panels=False
    )


# Plots show the whole run (the viewer's default is a window around the time cursor).
_WHOLE_RUN = rrb.TimeAxis(
    view_range=rr.TimeRange(
        start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
    )
)


_RANK = {"nav": 0, "error": 3, "state": 2, "sigma": 4, "extra": 5, "truth": 6}
_NAV_PLOTS = {"roll", "pitch", "yaw", "v_N", "v_E", "v_D", "p_N", "p_E", "p_D"}


def _rank(plot: str) -> int:
    """Order within a tab: solution, its errors, states, state errors, sigmas, extras, truth."""
    kind, _, name = plot.partition(":")
    if kind == "error" and name in _NAV_PLOTS:
        return 1
    return _RANK.get(kind, 7)
