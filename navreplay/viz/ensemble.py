"""Layout of Monte Carlo statistics in the Rerun view.

Per filter, in the filter's colour (the same as in the single-run tabs): the RMS over runs of
each error component (solid) and the mean predicted sigma (thinner, lighter), one pane per
filter and component so that each filter is read at its own scale; the run-averaged NEES and
NIS with their 95 % band; the GNSS outages shaded under the position errors; per axis the
ratio RMS/sigma of the normalised errors over the runs at each epoch, in its 95 % band for
that many runs, titled with the ensemble's check (docs/methods/consistency.md §7). Tabs:
"Ensemble position", "... velocity", "... attitude", "... states" (the scored states that are
not navigation errors), "Ensemble NEES / NIS", "Ensemble RMS/σ" (the NEES states and any axis
that fails).
With the runs' metrics (``navreplay montecarlo --keep``), "Ensemble runs" shows every run's
navigation errors, one thin line per run, to find the runs behind an RMS.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

from navreplay.filters.base import NavError, State
from navreplay.metrics import EnsembleResult, RunMetrics, chi2_bounds_per_count
from navreplay.metrics import outages as _outages
from navreplay.viz.channel import TIMELINE, Channel, Index, TimeIndex
from navreplay.viz.naming import Tab, display_unit, entity_path, quantity_of, resolve_unit
from navreplay.viz.style import OUTAGE_COLOR, SIGMA_SHADE, TRUTH_COLOR, lighter

if TYPE_CHECKING:
    from navreplay.viz.sink import Sink

_ENSEMBLE_NAV = (
    ("pos_ned", "position", ("N", "E", "D"), "m", 1.0),
    ("v_n", "velocity", ("N", "E", "D"), "m/s", 1.0),
    ("phi", "attitude", ("phi_N", "phi_E", "phi_D"), "deg", 180.0 / math.pi),
)


def _tab(group: str) -> tuple[str, str]:
    return f"ensemble:{group}", f"Ensemble {group}"


def log_ensemble(
    sink: Sink,
    label: str,
    ens: EnsembleResult,
    states: Sequence[State] | None = None,
) -> None:
    """Log one filter's Monte Carlo statistics: RMS error vs mean predicted sigma over time for
    the navigation errors and the scored states, average NEES and NIS with their 95 % bands.

    Parameters
    ----------
    sink : Sink
    label : str
        Filter label (its colour is :meth:`Sink.color_of`).
    ens : EnsembleResult
    states : sequence of State, optional
        The filter's declarations: units of the scored states, and which of them are
        navigation errors (shown once, as the navigation errors). Without them the units and
        the navigation-error states are guessed from the names.
    """
    color = sink.color_of(label)
    order = sink.order_of(label)
    rms_style = (color, 2.0)
    sigma_style = (lighter(color, SIGMA_SHADE), 1.0)
    t = ens.t
    for key, what, axes, unit, scale in _ENSEMBLE_NAV:
        if key not in ens.rms:
            continue
        tab, tab_title = _tab(what)
        for i, axis in enumerate(axes):
            sigma = ens.sigma.get(key)
            series = {f"{label} RMS": ens.rms[key][:, i] * scale}
            styles = {f"{label} RMS": rms_style}
            if sigma is not None and np.isfinite(sigma[:, i]).any():
                series[f"{label} σ"] = sigma[:, i] * scale
                styles[f"{label} σ"] = sigma_style
            sink.log_ensemble(f"{label}: {what} error {axis}, RMS and σ", t, series, unit=unit,
                              styles=styles, tab=tab, tab_title=tab_title, rank=order,
                              shaded=ens.outages if key == "pos_ned" else ())
    declared = {s.name: s for s in states or ()}
    tab, tab_title = _tab("states")
    for j, name in enumerate(ens.state_names):
        st = declared.get(name)
        if st is not None:
            if isinstance(st.truth, NavError):
                continue  # the same error as the navigation error above
            u = display_unit(st.unit)
        else:
            if quantity_of(name) is not Tab.SENSOR:
                continue
            u = resolve_unit(name)
        sink.log_ensemble(
            f"{label}: {name} error, RMS and σ", t,
            {f"{label} RMS": ens.state_rms[:, j] * u.scale,
             f"{label} σ": ens.state_sigma[:, j] * u.scale},
            unit=u.label, styles={f"{label} RMS": rms_style, f"{label} σ": sigma_style},
            tab=tab, tab_title=tab_title, rank=order,
        )
    tab, tab_title = _tab("NEES / NIS")
    if ens.nees_dof and np.isfinite(ens.nees_mean).any():
        sink.log_ensemble(f"{label}: NEES ({ens.nees_dof} states, {ens.runs} runs), 95 % band",
                          t, {f"{label} NEES": ens.nees_mean}, unit="-", bounds=ens.nees_bounds,
                          styles={f"{label} NEES": rms_style}, tab=tab, tab_title=tab_title,
                          rank=order)
    for meas, (t_k, mean, count, dof) in ens.nis_mean.items():
        lo, hi = chi2_bounds_per_count(dof, count)
        sink.log_ensemble(f"{label}: {meas} NIS ({dof} dof, {ens.runs} runs), 95 % band",
                          t_k[: mean.shape[0]], {f"{label} NIS": mean}, unit="-",
                          bounds=(lo, hi), styles={f"{label} NIS": rms_style}, tab=tab,
                          tab_title=tab_title, rank=order)
    _log_scale(sink, label, ens, rms_style, order)


def _log_scale(sink: Sink, label: str, ens: EnsembleResult,
               style: tuple[tuple[int, int, int], float], order: int) -> None:
    """RMS/sigma per axis over time with its band, titled with the ensemble's check (the
    ratio and its interval are in the summary table)."""
    c = ens.consistency
    if c is None:
        return
    tab, tab_title = _tab("RMS/σ")
    for j, name in enumerate(c.names):
        check = c.scale.get(name)
        if check is None or (name not in c.nees_names and check.passed):
            continue
        count = c.z2_count[:, j]
        lo, hi = chi2_bounds_per_count(1, count)
        verdict = "ok" if check.passed else "INCONSISTENT"
        sink.log_ensemble(
            f"{label}: RMS/σ of {name} ({verdict})", ens.t[: count.shape[0]],
            {f"{label} RMS/σ": np.sqrt(c.z2_mean[:, j])}, unit="-",
            bounds=(np.sqrt(lo), np.sqrt(hi)), styles={f"{label} RMS/σ": style}, tab=tab,
            tab_title=tab_title, rank=order)


def log_runs(sink: Sink, runs: Mapping[int, Mapping[str, RunMetrics]]) -> None:
    """Every run's navigation errors, one thin line per run in its filter's colour (a pane per
    filter and quantity, tab "Ensemble runs"): the drill-down behind the RMS.

    Parameters
    ----------
    sink : Sink
    runs : mapping run number -> (filter label -> RunMetrics)
    """
    tab, tab_title = "ensemble:runs", "Ensemble runs"
    for k, per_filter in sorted(runs.items()):
        for label, m in per_filter.items():
            if m.nav is None:
                continue
            color = lighter(sink.color_of(label), 0.25 * (k % 3))
            order = sink.order_of(label)
            h = np.hypot(m.nav.pos_ned[:, 0], m.nav.pos_ned[:, 1])
            for what, values, unit in (
                ("horizontal position error", h, "m"),
                ("vertical position error", m.nav.pos_ned[:, 2], "m"),
                ("heading error phi_D", np.degrees(m.nav.phi[:, 2]), "deg"),
            ):
                if not np.isfinite(values).any():
                    continue
                sink.log_ensemble(f"{label}: {what}, every run", m.t,
                                  {f"{label} run {k}": values}, unit=unit,
                                  styles={f"{label} run {k}": (color, 1.0)},
                                  tab=tab, tab_title=tab_title, rank=order, legend=False)


class EnsemblePlots(Channel):
    """The Monte Carlo plots of a sink (``/ensemble/<plot>/<series>``)."""

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

        def index(tt: np.ndarray) -> Index:
            if timeline is None:
                return TimeIndex(tt, None)
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
        self._draw_queued()

    def log_sweep(
        self,
        name: str,
        x: np.ndarray,
        series: Mapping[str, np.ndarray],
        *,
        unit: str,
        x_name: str,
        x_unit: str,
        tab: str = "ensemble",
        tab_title: str | None = None,
        rank: int = 0,
    ) -> None:
        """A sweep (a result against a parameter, not time) as a bar chart on the parameter's
        own axis: at each ``x`` a bar per series, side by side in the series' colours
        (``/ensemble/<name>/<series>``), titled ``<name> [unit] vs <x_name> [x_unit]``."""
        x = np.asarray(x, dtype=np.float64)
        step = float(np.min(np.diff(np.unique(x)))) if np.unique(x).shape[0] > 1 else 1.0
        width = 0.8 * step / max(len(series), 1)
        title = f"{name} [{unit}] vs {x_name} [{x_unit}]"
        for j, (key, values) in enumerate(series.items()):
            values = np.asarray(values, dtype=np.float64)
            if values.shape != x.shape:
                raise ValueError(
                    f"sweep {name!r}: series {key!r} has shape {values.shape}, x {x.shape}")
            path = f"{entity_path('ensemble', name)}/{entity_path(key)[1:]}"
            color, _ = self._variant_style(key)
            offset = (j - 0.5 * (len(series) - 1)) * width
            self._rec.log(path, rr.BarChart(values, abscissa=x + offset, color=color,
                                            widths=np.full(x.shape, width)), static=True)
            self.catalog.add(tab, f"ensemble:{name}", title, path, rank=rank, kind="bars",
                             tab_title=tab_title)

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
