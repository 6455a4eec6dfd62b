"""A filter's series in the view, block by block: its states and sigmas, navigation solution,
errors with their +-3 sigma bounds, NEES with its band, innovations and NIS, and its track in
the 3D world and on the map."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
import rerun as rr

from navreplay import metrics as _metrics
from navreplay.filters.base import Nav, NavError, State, TruthColumn
from navreplay.filters.result import RunResult
from navreplay.geo import radii
from navreplay.metrics import RunMetrics, nav_errors
from navreplay.metrics import outages as _outages
from navreplay.metrics.compare import COMPARED, Quantiles, compared_errors
from navreplay.viz import convert
from navreplay.viz.channel import TimeIndex
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
from navreplay.viz.style import (
    N_SIGMA,
    OUTAGE_COLOR,
    RANK_ERROR,
    RANK_EXTRA,
    RANK_NAV,
    RANK_SIGMA,
    RANK_STATE,
    lighter,
)
from navreplay.viz.truth import TruthView
from navreplay.viz.world import Track, axis_size


@dataclasses.dataclass
class RunState:
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
    track: Track = dataclasses.field(default_factory=lambda: Track())
    extent_box: tuple[np.ndarray, np.ndarray] | None = None
    """NED box of the true track up to this run's last block (its ellipsoids' caps)."""
    quantiles: dict[str, Quantiles] = dataclasses.field(default_factory=dict)
    """The distributions of the compared error magnitudes (the Compare tab's CDFs)."""


_NAV_ERRORS = tuple(n for names in NAV_ERROR_NAMES.values() for n in names)

def _row(name: str) -> str:
    """The row of a state's pane in a per-filter column: its name without the last
    ``_part`` (``b_a_x``, ``b_a_y`` -> ``b_a``; ``m_a_xy``, ``m_a_zx`` -> ``m_a``)."""
    return name.rsplit("_", 1)[0] if "_" in name.strip("_") else name


CDF_POINTS = 200
"""Percentiles drawn per CDF."""


class RunView(TruthView):
    """The runs of a sink, one colour per filter label."""

    def _run(self, label: str, units: Mapping[str, str] | None) -> RunState:
        run = self._runs.get(label)
        if run is None:
            run = RunState(label, self.color_of(label), self.order_of(label), units)
            self._runs[label] = run
        elif units is not None:
            run.units = units
        return run

    def _finish_run(self, run: RunState) -> None:
        """The static parts of a run: trajectory, map track (and body axes when streamed)."""
        if run.track.logged:
            return
        if not run.axes and run.track.t.shape[0]:
            ned = run.track.ned[np.isfinite(run.track.ned).all(axis=1)]
            if ned.shape[0]:
                extent = self._extent or float(np.max(np.ptp(ned, axis=0)))
                self._axes(entity_path("world", run.label, "body", "axes"), axis_size(extent))
                run.axes = True
        self._log_track(run.label, run.track, run.color, 2.5, 3.0)
        self._log_cdfs(run)

    def _log_compare(self, run: RunState, idx: TimeIndex, errors: Any) -> None:
        """The run's error magnitudes in the Compare tab, overlaid with the other filters'
        (one plot per quantity), and into the distributions of its CDFs."""
        mags = compared_errors(errors.pos_ned, errors.v_n, errors.phi)
        for rank, (key, name, unit) in enumerate(COMPARED):
            v = mags[key]
            if not np.isfinite(v).any():
                continue
            run.quantiles.setdefault(key, Quantiles()).add(v)
            u = display_unit(unit)
            path = entity_path("compare", key, run.label)
            self._style(path, [run.label], [run.color], [1.5])
            self._scalars(path, idx, v * u.scale)
            self.catalog.add("compare", f"compare:{key}", f"{name} [{u.label}]", path,
                             rank=rank)

    def _log_cdfs(self, run: RunState) -> None:
        """The CDF of each compared error magnitude over the whole run: a bar per percentile
        (its height) at the error value below which that fraction of the run lies."""
        for rank, (key, name, unit) in enumerate(COMPARED):
            q = run.quantiles.get(key)
            if q is None or not q.n:
                continue
            u = display_unit(unit)
            value, frac = q.cdf(CDF_POINTS)
            path = entity_path("compare", "cdf", key, run.label)
            span = float(value[-1] - value[0]) or float(value[-1]) or 1.0
            self._rec.log(path, rr.BarChart(100.0 * frac, abscissa=value * u.scale,
                                            color=run.color,
                                            widths=np.full(frac.shape, 0.004 * span * u.scale)),
                          static=True)
            # no legend (a bar chart's names its entity paths): the colours are those above
            self.catalog.add("compare", f"cdf:{key}", f"CDF of the {name} [%] vs [{u.label}]",
                             path, rank=len(COMPARED) + rank, kind="bars", legend=False)

    def _declare(self, run: RunState, result: RunResult) -> None:
        run.states = {s.name: s for s in (*result.states, *result.scored_extras)}

    def _unit(
        self, run: RunState, name: str, result: RunResult, a: int, b: int
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

    def _tab(self, run: RunState, name: str) -> str:
        st = run.states.get(name)
        return (tab_of(st.quantity) if st is not None else quantity_of(name)).value

    def _log_rows(
        self,
        run: RunState,
        result: RunResult,
        a: int,
        b: int,
        scored: frozenset[str] = frozenset(),
        scores: RunMetrics | None = None,
    ) -> None:
        """Rows [a, b) of a run: states, sigmas (of the states not in ``scored``, whose
        sigma is their error pane's ±3σ), extras and the navigation solution (its errors those
        of ``scores`` when given)."""
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
            step = min(0.3, 0.75 / max(len(groups[g]) - 1, 1))  # up to six components apart
            shade = lighter(run.color, step * groups[g].index(n))
            legend = L if len(groups[g]) == 1 else f"{L} {n}"
            p_state = entity_path(L, "state", n)
            st = run.states.get(n)
            # an error state that feedback keeps at zero is not drawn (its error against the
            # truth and its sigma are what is worth looking at); the others get a column per
            # filter in the State estimates tab, a row per group
            if np.any(result.x[a:b, i] != 0.0):
                self._style(p_state, [legend], [shade], [1.5])
                self._scalars(p_state, idx, result.x[a:b, i] * scale)
                self.catalog.add("states", f"state:{g}@{L}", _in_column(f"{g} [{label}]", L),
                                 p_state, rank=RANK_STATE, column=L, row=g)
                if st is not None and isinstance(st.truth, TruthColumn):
                    p_true = self._truth_column(st.truth.column, st.unit)
                    if p_true is not None:
                        self._name_truth(st.truth.column, st.truth.index, n)
                        self.catalog.add("states", f"state:{g}@{L}",
                                         _in_column(f"{g} [{label}]", L), p_true,
                                         rank=RANK_STATE, column=L, row=g)
            nav_state = st is not None and isinstance(st.truth, NavError)
            frozen = not np.any(sigma[:, i] > 0.0)  # a disabled or frozen state: left out
            p_sig = entity_path(L, "sigma", n)
            if not (nav_state or frozen or n in scored
                    or self.catalog.has(entity_path(L, "error", n))):
                # sigma of an unscored state; a scored state's is the ±3σ of its error pane,
                # a navigation-error state's that of the navigation errors
                self._style(p_sig, [f"σ {legend}"], [shade], [1.5])
                self._scalars(p_sig, idx, sigma[:, i] * scale)
                self.catalog.add("states", f"sigma:{g}@{L}", _in_column(f"σ {g} [{label}]", L),
                                 p_sig, rank=RANK_SIGMA, column=L, row=f"σ {g}")
        for key, arr in result.extras.items():
            arr = np.asarray(arr[a:b], dtype=np.float64)
            flat = arr.reshape(b - a, int(np.prod(arr.shape[1:], dtype=np.int64)))
            label, scale = self._unit(run, key, result, a, b)
            path = entity_path(L, "extra", key)
            k = flat.shape[1]
            names = [L] if k == 1 else [f"{L} {key}[{j}]" for j in range(k)]
            self._style(path, names, [lighter(run.color, min(0.3 * j, 0.75)) for j in range(k)])
            self._scalars(path, idx, flat * scale)
            self.catalog.add("states", f"extra:{key}@{L}", _in_column(f"{key} [{label}]", L),
                             path, rank=RANK_EXTRA, column=L, row=key)
        if any(result.has(part) for part in ("pos", "v_n", "q_nb")):
            self._log_nav(run, result, a, b, idx, scores)
        run.rows = b

    def _log_nav(
        self,
        run: RunState,
        result: RunResult,
        a: int,
        b: int,
        idx: TimeIndex,
        scores: RunMetrics | None = None,
    ) -> None:
        """Navigation solution rows [a, b): values, errors vs truth (those of ``scores``, the
        rows' :func:`~navreplay.metrics.run_metrics`, when given), 3D; of the parts the filter
        outputs only (an attitude-only filter has no position, velocity or 3D trajectory)."""
        L = run.label
        t = result.t[a:b]
        parts = result.navigation
        assert result.nav_pos is not None and result.nav_v_n is not None
        assert result.nav_q_nb is not None  # logged for a result with a navigation solution
        nav = convert.NavColumns(t, result.nav_pos[a:b], result.nav_v_n[a:b], result.nav_q_nb[a:b])
        if self._ref is None and "pos" in parts:
            finite = np.flatnonzero(convert.finite_rows(nav.pos))
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
            self.catalog.add(quantity_of(n).value, f"nav:{n}", title(n, u), path, rank=RANK_NAV)
        errors: dict[str, tuple[np.ndarray, np.ndarray | None]] = {}
        ne = None
        if scores is not None and scores.nav is not None and scores.t.shape[0] == b - a:
            ne, sig = scores.nav, scores.nav_sigma  # the errors the rows were scored with
        elif self._truth is not None:
            tr = self._truth.at(t)
            ne = nav_errors(nav.pos, nav.v_n, nav.q_nb,
                            {"pos": tr.pos, "v_n": tr.v_n, "q_nb": tr.q_nb}, parts)
            sig = _metrics.nav_sigma(result.rows(a, b))
        if ne is not None:
            nav_sigma = {f"{p}_{ax}": sig[k][:, i]
                         for k, p in (("pos_ned", "p"), ("v_n", "v"), ("phi", "phi"))
                         for i, ax in enumerate("NED")}
            for n, e in ne.columns().items():
                if nav_part(n) not in parts:
                    continue
                s = nav_sigma[n]
                errors[n] = (e, s if np.isfinite(s).any() else None)
            self._log_compare(run, idx, ne)
        for n, (e, sd) in errors.items():
            u = display_unit(NAV_UNITS[n])
            path = entity_path(L, "error", n)
            self._bounded(path, idx, e * u.scale, None if sd is None else sd * u.scale, L,
                          run.color)
            bounds = "" if sd is None else ", ±3σ"
            plot = (quantity_of(n).value, f"error:{n}@{L}", f"{L}: {title(n, u, 'error')}{bounds}")
            self.catalog.add(*plot, path, rank=RANK_ERROR + run.order, legend=False)
            if sd is not None and nav_part(n) == "pos":
                self._shade_outages(path, plot, t, result.t0_ns, N_SIGMA * sd * u.scale)
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

    def _unwrap_yaw(self, run: RunState, t: np.ndarray, yaw: np.ndarray) -> np.ndarray:
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

    def _log_errors(
        self,
        run: RunState,
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
            if s is not None and not np.any(s > 0.0) and not self.catalog.has(
                    entity_path(L, "error", n)):
                continue  # a disabled or frozen state (zero sigma) gets no pane
            label, scale = self._unit(run, key, result, 0, M)
            tab = self._tab(run, key)
            # a state named like a navigation error (phi_N) keeps its own entity
            path = entity_path(L, "error", f"{n} state" if n in _NAV_ERRORS else n)
            sig = None if s is None else s * scale
            self._bounded(path, idx, e * scale, sig, L, run.color)
            bounds = "" if s is None else ", ±3σ"
            # Sensor errors: a column per filter, a row per group of components
            what = f"{n} error [{label}]{bounds}"
            column = L if tab == "sensor" else None
            self.catalog.add(tab, f"error:{n}@{L}",
                             _in_column(what, L) if column else f"{L}: {what}", path,
                             rank=RANK_ERROR + run.order, legend=False, column=column,
                             row=_row(key))
            if n in states:
                self.catalog.discard("states", f"sigma:{group_of(n)}@{L}",
                                     entity_path(L, "sigma", n))

    def _log_nees(self, run: RunState, result: RunResult, t: np.ndarray, nees: np.ndarray,
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

    def _log_innovations(self, run: RunState, result: RunResult) -> None:
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


def _in_column(what: str, label: str) -> str:
    """The title of a pane in a filter's column (the Sensor errors and State estimates tabs):
    what it shows first, its filter after, so that a narrow pane cut at its width still says
    which state it is (the column and the colour say which filter)."""
    return f"{what} ({label})"
