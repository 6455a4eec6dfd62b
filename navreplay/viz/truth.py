"""The truth in the view: its navigation solution (attitude with the yaw unwrapped, velocity,
local NED position), the extra truth columns a filter's states are scored against, its 3D
track and map, logged window by window."""

from __future__ import annotations

import dataclasses

import numpy as np
import rerun as rr

from navreplay.core.streams import Stream
from navreplay.viz import convert
from navreplay.viz.naming import (
    NAV_UNITS,
    display_unit,
    entity_path,
    quantity_of,
    title,
)
from navreplay.viz.style import RANK_NAV, TRUTH_COLOR, TRUTH_COMPONENT_COLORS
from navreplay.viz.world import BODY_RATE_HZ, Track, WorldView, axis_size, xyzw

TRUTH_RATE_HZ = 20.0
"""Default rate of the truth time series [Hz]; None in :meth:`Sink.log_truth` keeps all rows."""


@dataclasses.dataclass
class TruthLog:
    """Progress of the truth logged so far (whole, or window by window)."""

    root: str
    t0_ns: int
    rate_hz: float | None
    last: float = -np.inf  # time of the last truth row seen [s]
    yaw: tuple[float, float] | None = None  # last raw and unwrapped yaw [rad]
    track: Track = dataclasses.field(default_factory=lambda: Track())
    axes: bool = False


class TruthView(WorldView):
    """The truth of a sink, window by window."""

    def _log_truth_rows(
        self, stream: Stream, t0: int, entity: str, rate_hz: float | None
    ) -> np.ndarray:
        """Log truth rows later than those before; returns the indices of the rows kept in the
        time series."""
        root = "/" + entity.strip("/")
        log = self._truth_log
        if log is None:
            log = self._truth_log = TruthLog(root, t0, rate_hz)
        nav = truth_nav(stream, t0)
        if self._ref is None and nav.t.shape[0]:
            self._ref = nav.pos[0].copy()
        assert self._ref is not None, "the first truth window has rows"
        ned = convert.local_ned(nav.pos, self._ref)
        finite = convert.finite_rows(ned)
        if finite.any():
            inside = ned if finite.all() else ned[finite]
            lo, hi = inside.min(axis=0), inside.max(axis=0)
            if self._box is not None:
                lo, hi = np.minimum(self._box[0], lo), np.maximum(self._box[1], hi)
            self._box = (lo, hi)
            self._extent = max(self._extent, float(np.max(hi - lo)))
        self._add_track_rows(nav.t, ned, finite)
        keep = (convert.decimate(nav.t, rate_hz, after=log.last) if rate_hz
                else np.flatnonzero(nav.t > log.last))
        # the plotted rows only (the yaw unwrapped along them, continuing the rows before)
        kept = convert.NavColumns(nav.t[keep], nav.pos[keep], nav.v_n[keep], nav.q_nb[keep])
        values = convert.nav_values(kept, self._ref, ned[keep])
        raw = values["yaw"]
        values["yaw"] = _unwrap_after(raw, log.yaw)
        if raw.shape[0]:
            log.yaw = (float(raw[-1]), float(values["yaw"][-1]))
        if self._truth_yaw is None:
            self._truth_yaw = (kept.t, values["yaw"])
        idx = self._indexes(kept.t, t0)
        for name, v in values.items():
            u = display_unit(NAV_UNITS[name])
            path = f"{root}/nav/{name}"
            self._style(path, ["truth"], [TRUTH_COLOR], [2.0])
            self._scalars(path, idx, v * u.scale)
            self.catalog.add(quantity_of(name).value, f"nav:{name}", title(name, u), path,
                             rank=RANK_NAV)
        # 3D and map
        world = f"/world{root}"
        w = convert.decimate(nav.t, BODY_RATE_HZ, after=log.last)
        if w.shape[0]:
            self._send_rows(f"{world}/body", nav.t[w], t0, rr.Transform3D.columns,
                            translation=ned[w], quaternion=xyzw(nav.q_nb[w]))
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
            self._axes(f"{world}/body/axes", axis_size(self._extent))
        self._log_track(log.root.strip("/"), log.track, TRUTH_COLOR, 1.5, 1.5)
        self._log_outage_track(log.root, log.track)

    def _truth_style(self, column: str) -> tuple[list[str], list[tuple[int, ...]],
                                                 list[float]]:
        """Names, colours and widths of a truth column's components: named after the states
        that estimate them (``b_a_x (truth)``) once a filter has declared them, else
        ``truth <column>[j]``; one component grey, three the greyed axis colours."""
        k = self._truth_widths.get(column, 1)
        named = self._truth_names.get(column, {})
        names = [named.get(j, "truth" if k == 1 else f"truth {column}[{j}]") for j in range(k)]
        colors: list[tuple[int, ...]] = (
            [TRUTH_COLOR] if k == 1
            else [TRUTH_COMPONENT_COLORS[j % len(TRUTH_COMPONENT_COLORS)] for j in range(k)])
        return names, colors, [2.0] * k

    def _name_truth(self, column: str, index: tuple[int, ...], state: str) -> None:
        """A state estimates component ``index`` of truth ``column``: the component takes its
        name (``<state> (truth)``) in the legends."""
        j = index[0] if len(index) == 1 else 0
        named = self._truth_names.setdefault(column, {})
        if named.get(j) == f"{state} (truth)":
            return
        named[j] = f"{state} (truth)"
        path = self._truth_column(column, "")
        if path is not None:
            names, colors, widths = self._truth_style(column)
            self._styled.discard(path)
            self._style(path, names, colors, widths)

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
        self._truth_widths[column] = k
        self._style(path, *self._truth_style(column))
        u = display_unit(unit)
        t = (stream.t_ns[keep] - np.int64(t0)).astype(np.float64) * 1e-9
        self._scalars(path, self._indexes(t, t0), flat * u.scale)
        return True


def truth_nav(stream: Stream, t0_ns: int) -> convert.NavColumns:
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
