"""The 3D world (NED, metres from the reference point: trajectories, body axes, 3-sigma position
ellipsoids capped against the extent of the true track) and the map (tracks and positions),
both kept as bounded, decimated point sets written on close."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

from navreplay.filters.base import Nav, NavError
from navreplay.filters.result import RunResult
from navreplay.geo import ned_offset_to_lla, quat_wxyz_to_xyzw
from navreplay.metrics import outages as _outages
from navreplay.viz import convert
from navreplay.viz.channel import Channel
from navreplay.viz.naming import entity_path, legend_name
from navreplay.viz.style import AXIS_COLORS, N_SIGMA, OUTAGE_COLOR

if TYPE_CHECKING:
    from navreplay.viz.runs import RunState


WORLD_RATE_HZ = 10.0
"""Starting rate of the points of the trajectory strips and map tracks [Hz]."""


BODY_RATE_HZ = 2.0
"""Rate of the body transforms (position and attitude) in /world [Hz]."""


COVARIANCE_RATE_HZ = 1.0
"""Rate of the position-covariance ellipsoids and map positions [Hz]."""


MAX_STRIP_POINTS = 20_000
"""Trajectory strips are decimated to at most this many points."""


ELLIPSOID_CAP = 0.25
"""A 3-sigma ellipsoid whose largest semi-axis exceeds this fraction of the trajectory's extent
is drawn scaled down to it (labelled with the factor), so that it does not hide the trajectory;
its true size is in the error plots."""


class Track:
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


class WorldView(Channel):
    """The 3D world and the map of a sink."""

    def _set_world(self) -> None:
        if not self._world_coords:
            self._rec.log(
                "/world", rr.ViewCoordinates.FRD, static=True
            )  # NED = x fwd, y right, z down
            self._world_coords = True

    def _axes(self, path: str, size: float) -> None:
        self._rec.log(
            path,
            # no x/y/z badges: those of every filter would pile up where the tracks meet
            rr.Arrows3D(vectors=np.eye(3) * size, colors=AXIS_COLORS),
            static=True,
        )

    def _log_legend(self) -> None:
        """The key of the trajectory views and the map (``/legend``: a dot per track in its
        colour, named) and a scale bar of :func:`scale_length` metres, white, east from below
        the south-west corner of the tracks (``/world/scale``, ``/map/scale``)."""
        if not self.catalog.legend:
            return
        entries = list(self.catalog.legend)
        box = self.catalog.world
        if box is not None:
            lo, hi = box
            length = scale_length(float(np.max(hi[:2] - lo[:2])))
            self.catalog.scale_bar = length
            n = lo[0] - 0.06 * max(float(hi[0] - lo[0]), length)
            bar = np.array([[n, lo[1], 0.5 * (lo[2] + hi[2])],
                            [n, lo[1] + length, 0.5 * (lo[2] + hi[2])]])
            self._rec.log("/world/scale", rr.LineStrips3D([bar], colors=[SCALE_COLOR],
                                                          radii=[-1.5],
                                                          labels=[f"{length:g} m"]),
                          static=True)
            if self._ref is not None:
                ref = self._ref
                lat, lon, _ = ned_offset_to_lla(ref[0], ref[1], ref[2], bar)
                self._rec.log("/map/scale",
                              rr.GeoLineStrings(lat_lon=[np.degrees(np.stack([lat, lon], 1))],
                                                colors=[SCALE_COLOR],
                                                radii=rr.Radius.ui_points(1.5)),
                              static=True)
            entries.append((f"white bar: {length:g} m", SCALE_COLOR))
        self._rec.log("/legend", rr.Points2D(
            positions=[(LEGEND_STEP * i, 0.0) for i in range(len(entries))],
            radii=[0.4] * len(entries), colors=[c for _, c in entries],
            labels=[name for name, _ in entries], show_labels=True), static=True)

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
        finite = convert.finite_rows(pos[:, :2])
        if not finite.any():
            return
        if finite.all():
            k = convert.decimate(t, COVARIANCE_RATE_HZ, after=after)
        else:
            ok = np.flatnonzero(finite)
            k = ok[convert.decimate(t[ok], COVARIANCE_RATE_HZ, after=after)]
        root = entity_path("map", label)
        if k.shape[0]:
            self._send_rows(f"{root}/position", t[k], t0_ns, rr.GeoPoints.columns,
                            positions=np.degrees(pos[k, :2]))
            if f"{root}/position" not in self._styled:
                self._styled.add(f"{root}/position")
                self._rec.log(
                    f"{root}/position",
                    rr.GeoPoints.from_fields(colors=[color], radii=rr.Radius.ui_points(6.0)),
                    static=True,
                )
        self.catalog.geo = True

    def _log_track(self, label: str, track: Track, color: tuple[int, int, int],
                   width: float, map_width: float) -> None:
        """The static lines of a trajectory: the 3D strip and the map track (once)."""
        if track.logged:
            return
        track.logged = True
        self._strip(entity_path("world", label, "trajectory"), track.ned, color, width=width)
        if np.isfinite(track.ned).all(axis=1).sum() >= 2:
            self.catalog.legend.append((legend_name(label), color))
        ok = np.isfinite(track.pos[:, :2]).all(axis=1)
        if ok.sum() >= 2:
            self._rec.log(
                f"{entity_path('map', label)}/track",
                rr.GeoLineStrings(lat_lon=[_thin(np.degrees(track.pos[ok, :2]))], colors=[color],
                                  radii=rr.Radius.ui_points(map_width / 2)),
                static=True,
            )
            self.catalog.geo = True

    def _track_extent(self, truth: convert.NavColumns, box: tuple[np.ndarray, np.ndarray] | None,
                      first: float) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """The NED box of the true track [m] up to each row of ``truth`` (rows from before
        ``first`` [s] on, the box grown from ``box``, that of the rows before): in consecutive
        parts, their times, and the box's low and high corners row by row; those of the truth
        logged (:meth:`_add_track_rows`) when they reach back far enough."""
        kept = self._track_box
        if kept and (self._track_box_whole or kept[0][0][0] <= first):
            return kept
        ned = convert.local_ned(truth.pos, self._ref) if self._ref is not None else truth.pos
        return [(truth.t, *_box_rows(ned, box, convert.finite_rows(ned)))]

    def _add_track_rows(self, t: np.ndarray, ned: np.ndarray, finite: np.ndarray) -> None:
        """The true track's box row by row over the rows logged (times [s], NED [m], which
        rows are finite), those of this window and the last kept: the times of a block of
        estimates lie in them."""
        kept = self._track_box
        box = (kept[-1][1][-1], kept[-1][2][-1]) if kept and kept[-1][0].shape[0] else None
        self._track_box = [*kept[-1:], (t, *_box_rows(ned, box, finite))]
        self._track_box_whole = self._track_box_whole and len(kept) < 2

    def _extent_at(self, t: np.ndarray) -> np.ndarray | float:
        """Extent of the true track up to times ``t`` [m] (ellipsoids are capped relative to
        the track drawn so far); the whole extent without a truth."""
        if self._extent_curve is None:
            return self._extent
        lo, hi, found = box_at(self._extent_curve, t)
        with np.errstate(invalid="ignore"):
            ext = np.max(hi - lo, axis=1)
        return np.where(found & np.isfinite(ext), ext, 0.0)

    def _log_world(
        self,
        run: RunState,
        result: RunResult,
        nav: convert.NavColumns,
        a: int,
        b: int,
        values: Mapping[str, np.ndarray],
    ) -> None:
        L = run.label
        ned = np.stack([values["p_N"], values["p_E"], values["p_D"]], axis=1)
        w = convert.decimate(nav.t, BODY_RATE_HZ, after=run.world_t)
        w = w[np.isfinite(ned[w]).all(axis=1) & np.isfinite(nav.q_nb[w]).all(axis=1)]
        if w.shape[0]:
            self._set_world()
            self.catalog.frame(ned[w].min(axis=0), ned[w].max(axis=0))
            self._send_rows(entity_path("world", L, "body"), nav.t[w], result.t0_ns,
                            rr.Transform3D.columns, translation=ned[w],
                            quaternion=xyzw(nav.q_nb[w]))
            run.world_t = float(nav.t[w[-1]])
        c = convert.decimate(nav.t, COVARIANCE_RATE_HZ, after=run.cov_t)
        P_ned = _position_cov(run, result, a + c)  # of the rows drawn only
        if P_ned is None:
            return
        drawn = np.isfinite(ned[c]).all(axis=1) & np.isfinite(P_ned).all(axis=(1, 2))
        c, P_ned = c[drawn], P_ned[drawn]
        if not c.shape[0]:
            return
        half, q = convert.ellipsoids(P_ned, N_SIGMA)
        cap = ELLIPSOID_CAP * np.maximum(self._extent_at(nav.t[c]), 10.0)
        factor = np.minimum(1.0, cap / np.maximum(half.max(axis=1), 1e-12))
        labels = ["" if f >= 1.0 else f"{L} 3σ drawn × {f:.2g}" for f in factor]
        cov_path = entity_path("world", L, "covariance")
        if cov_path not in self.catalog.covariances:
            self.catalog.covariances.append(cov_path)
        self._send_rows(cov_path, nav.t[c], result.t0_ns, rr.Ellipsoids3D.columns,
                        centers=ned[c], half_sizes=half * factor[:, None], quaternions=q,
                        colors=np.tile((*run.color, 90), (c.shape[0], 1)), labels=labels)
        run.cov_t = float(nav.t[c[-1]])

    def _log_outage_track(self, root: str, track: Track) -> None:
        """The true track inside the GNSS outages, over the trajectory (3D) and the map
        track."""
        parts = [k for k in (np.flatnonzero(_outages.inside(track.t, o)) for o in self._outages)
                 if k.shape[0] >= 2]
        if not parts:
            return
        strips = [_thin(track.ned[k]) for k in parts]
        self.catalog.legend.append(("GNSS outage (truth)", OUTAGE_COLOR))
        self._rec.log(f"/world{root}/gnss_outages",
                      rr.LineStrips3D(strips, colors=[OUTAGE_COLOR], radii=[-2.5]), static=True)
        geo = [np.degrees(track.pos[k, :2]) for k in parts]
        geo = [g[np.isfinite(g).all(axis=1)] for g in geo]
        geo = [g for g in geo if g.shape[0] >= 2]
        if geo:
            self._rec.log(f"/map{root}/gnss_outages",
                          rr.GeoLineStrings(lat_lon=geo, colors=[OUTAGE_COLOR],
                                            radii=rr.Radius.ui_points(2.5)), static=True)


def _thin(pts: np.ndarray) -> np.ndarray:
    """At most :data:`MAX_STRIP_POINTS` of ``pts``, keeping the last."""
    step = max(1, int(np.ceil(pts.shape[0] / MAX_STRIP_POINTS)))
    return np.concatenate([pts[::step], pts[-1:]]) if (pts.shape[0] - 1) % step else pts[::step]


def xyzw(q_nb: np.ndarray) -> np.ndarray:
    return quat_wxyz_to_xyzw(q_nb)


def axis_size(extent: float) -> float:
    return max(1.0, 0.03 * extent)


SCALE_COLOR = (255, 255, 255)


LEGEND_STEP = 7.0
"""Spacing of the legend's entries, left to right (a dot with its name under it)."""


def scale_length(span: float) -> float:
    """A round length [m] (1, 2 or 5 times a power of ten) near a fifth of ``span`` [m]: the
    scale bar and the grid spacing of the trajectory views.

    >>> scale_length(2300.0), scale_length(40.0), scale_length(0.0)
    (200.0, 5.0, 1.0)
    """
    target = max(span / 5.0, 1.0)
    k = 10.0 ** np.floor(np.log10(target))
    return float(max(m * k for m in (1.0, 2.0, 5.0) if m * k <= target))


_POSITION_STATES = ((Nav.LAT, Nav.LON, Nav.H, -1.0), (Nav.LAT, Nav.LON, Nav.DEPTH, 1.0))


def _position_cov(run: RunState, result: RunResult, rows: np.ndarray) -> np.ndarray | None:
    """Position-error covariance in NED metres of ``rows`` from the declared latitude,
    longitude and height (or depth) error states, or None."""
    where = {
        s.truth.q: i for i, s in enumerate(result.states) if isinstance(s.truth, NavError)
    }
    if result.nav_pos is None:
        return None
    for lat, lon, vert, sign in _POSITION_STATES:
        if lat in where and lon in where and vert in where:
            states = convert.PositionStates((where[lat], where[lon], where[vert]), True, sign)
            return convert.position_cov_ned(result.P[rows], states, result.nav_pos[rows])
    return None


def box_at(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], t: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box of :meth:`WorldView._track_extent` (its parts in time order) at its last row at
    or before each of times ``t`` [s]: low and high corners, and whether there is one."""
    lo = np.full((t.shape[0], 3), np.inf)
    hi = np.full((t.shape[0], 3), -np.inf)
    found = np.zeros(t.shape[0], dtype=bool)
    for times, low, high in parts:  # a later part holds the later rows
        k = np.searchsorted(times, t, side="right") - 1
        inside = k >= 0
        lo[inside], hi[inside] = low[k[inside]], high[k[inside]]
        found |= inside
    return lo, hi, found


def _box_rows(ned: np.ndarray, box: tuple[np.ndarray, np.ndarray] | None,
              finite: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box of the ``finite`` rows of ``ned`` (N, 3) up to each row, grown from ``box``:
    its low and high corners row by row (+-inf before any)."""
    if finite.all():
        lo, hi = ned.copy(), ned.copy()
    else:
        lo = np.where(finite[:, None], ned, np.inf)
        hi = np.where(finite[:, None], ned, -np.inf)
    if box is not None and lo.shape[0]:
        lo[0], hi[0] = np.minimum(lo[0], box[0]), np.maximum(hi[0], box[1])
    np.minimum.accumulate(lo, axis=0, out=lo)
    np.maximum.accumulate(hi, axis=0, out=hi)
    return lo, hi
