"""The Rerun sink: how run results, truth and Monte Carlo statistics become entities of a
recording stream (opened on a target by :func:`navreplay.viz.connect.open_sink`).

Entity tree
-----------
::

    /truth/nav/{roll,pitch,yaw}          [deg]   true attitude (ZYX Euler)
    /truth/nav/{v_N,v_E,v_D}             [m/s]
    /truth/nav/{p_N,p_E,p_D}             [m]     local NED from the reference point
    /truth/extra/<column>                        other truth columns (<= 3 components)
    /<label>/state/<name>                        state estimate, display units
    /<label>/sigma/<name>                        1-sigma from the diagonal of P
    /<label>/error/<name>                        estimate - truth, +3 sigma, -3 sigma
    /<label>/nav/<roll..p_D>                     navigation solution (as /truth/nav)
    /<label>/extra/<key>[_<i>]                   RunResult.extras
    /<label>/innovation/<meas>/<i>               nu_i, +3 sqrt(S_ii), -3 sqrt(S_ii)
    /<label>/innovation/<meas>/nis               NIS, 95 % chi-square bounds
    /world                                       NED, metres from the reference point
    /world/truth/trajectory, /world/<label>/trajectory    LineStrips3D (static)
    /world/{truth,<label>}/body                  Transform3D over time (q_nb as xyzw)
    /world/{truth,<label>}/body/axes             body FRD axes (Arrows3D, static)
    /world/<label>/covariance                    3-sigma position Ellipsoids3D, 1 Hz
    /ensemble/<plot>/<series>                    Monte Carlo statistics

Every series is a column send on the timelines ``time`` (duration since the recording start)
and ``timestamp`` (absolute, from ``t0_ns``); style (names, colours) is static per entity.

Examples
--------
>>> import tempfile, pathlib, numpy as np
>>> from navreplay.replay.result import RunResult
>>> t = np.arange(5) * 0.1
>>> from navreplay.filters.base import Quantity, State
>>> b_g = (State("b_g_x", "rad/s", Quantity.GYRO_BIAS),)
>>> r = RunResult("f", "f", "demo", 0, t, b_g, np.zeros((5, 1)), np.ones((5, 1, 1)))
>>> out = pathlib.Path(tempfile.mkdtemp()) / "demo.rrd"
>>> from navreplay.viz import Save, open_sink
>>> with open_sink(Save(out)) as sink:
...     sink.log_run(r)
>>> out.exists()
True
"""

from __future__ import annotations

import dataclasses
import os
import time
import warnings
import weakref
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from navreplay.geo import quat_wxyz_to_xyzw
from navreplay.metrics import nav_errors
from navreplay.outputs import release
from navreplay.replay.result import RunResult
from navreplay.streams import Recording, Stream, StreamKind
from navreplay.viz import convert
from navreplay.viz.blueprint import Catalog, build_blueprint
from navreplay.viz.naming import (
    NAV_NAMES,
    NAV_UNITS,
    Quantity,
    display_unit,
    entity_path,
    group_of,
    quantity_of,
    resolve_unit,
    title,
)
from navreplay.viz.targets import (
    Serve,
    Target,
    VizUnavailableError,
)

APPLICATION_ID = "navreplay"
TIMELINE = "time"
"""Duration since the recording start."""
TIMESTAMP = "timestamp"
"""Absolute time (UNIX epoch)."""

WORLD_RATE_HZ = 10.0
"""Rate of attitude transforms in /world [Hz]."""
COVARIANCE_RATE_HZ = 1.0
"""Rate of the position-covariance ellipsoids [Hz]."""
TRUTH_RATE_HZ = 20.0
"""Default rate of the truth time series [Hz]; None in :meth:`Sink.log_truth` keeps all rows."""
MAX_STRIP_POINTS = 20_000
"""Trajectory strips are decimated to at most this many points."""
N_SIGMA = 3.0

TRUTH_COLOR = (200, 200, 200)
PALETTE = (
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (188, 189, 34), (23, 190, 207), (127, 127, 127),
)  # fmt: skip
AXIS_COLORS = ((230, 60, 60), (60, 200, 60), (70, 110, 240))


def _remove(path: Path) -> None:
    release(path)


# ------------------------------------------------------------------------------------------
# the sink


@dataclasses.dataclass
class _Run:
    """Logging state of one filter label."""

    label: str
    color: tuple[int, int, int]
    units: Mapping[str, str] | None
    rows: int = 0
    world_t: float = -np.inf
    cov_t: float = -np.inf
    axes: bool = False
    finished: bool = False


Truth = Recording | Stream
Metrics = Mapping[str, np.ndarray | tuple[np.ndarray, np.ndarray | None]]


class Sink:
    """A Rerun recording stream with navreplay's entity tree; make one with :func:`open_sink`.

    Use as a context manager (closes on success, aborts on an exception) or call
    :meth:`close` / :meth:`abort`.

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
        self._runs: dict[str, _Run] = {}
        self._styled: set[str] = set()
        self._ref: np.ndarray | None = None
        self._truth: convert.NavColumns | None = None
        self._truth_stream: Stream | None = None
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
        """A value with +-N_SIGMA bounds as three series (value, +3 sigma, -3 sigma)."""
        if sigma is None:
            self._style(path, [name], [color], [1.5])
            self._scalars(path, idx, value)
            return
        faint = (*color, 140)
        self._style(
            path,
            [name, f"{name} +3σ", f"{name} -3σ"],
            [color, faint, faint],
            [1.5, 1.0, 1.0],
        )
        self._scalars(path, idx, np.stack([value, N_SIGMA * sigma, -N_SIGMA * sigma], axis=1))

    def _run(self, label: str, units: Mapping[str, str] | None) -> _Run:
        run = self._runs.get(label)
        if run is None:
            run = _Run(label, PALETTE[len(self._runs) % len(PALETTE)], units)
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
            self.catalog.world = True

    def _axes(self, path: str, size: float) -> None:
        self._rec.log(
            path,
            rr.Arrows3D(vectors=np.eye(3) * size, colors=AXIS_COLORS, labels=["x", "y", "z"]),
            static=True,
        )

    def _strip(self, path: str, ned: np.ndarray, color: tuple[int, int, int]) -> None:
        ned = ned[np.isfinite(ned).all(axis=1)]
        if ned.shape[0] < 2:
            return
        step = max(1, int(np.ceil(ned.shape[0] / MAX_STRIP_POINTS)))
        pts = np.concatenate([ned[::step], ned[-1:]]) if (ned.shape[0] - 1) % step else ned[::step]
        self._set_world()
        self._rec.log(path, rr.LineStrips3D([pts], colors=[color], radii=[-1.5]), static=True)

    # -- truth ---------------------------------------------------------------------------

    def log_truth(
        self,
        truth: Truth,
        t0_ns: int | None = None,
        entity: str = "/truth",
        *,
        rate_hz: float | None = TRUTH_RATE_HZ,
    ) -> None:
        """Log the true navigation state (and other truth columns) once per sink.

        Parameters
        ----------
        truth : Recording or Stream
            A recording with a truth stream, or the truth stream itself (columns ``pos``
            [lat, lon rad, h m], ``v_n`` [m/s], ``q_nb`` scalar first).
        t0_ns : int, optional
            Recording start [ns]; default ``Recording.t0_ns`` or the stream's first timestamp.
        entity : str
            Root of the truth entities (the 3D trajectory goes to ``/world/<root name>``).
        rate_hz : float or None
            Decimate the time series to this rate [Hz]; None keeps every row. Errors are always
            computed against the full-rate truth.
        """
        stream, t0 = _truth_stream(truth, t0_ns)
        if self._truth_stream is not None:
            raise ValueError("truth is already logged in this sink (one recording per sink)")
        nav = _truth_nav(stream, t0)
        self._truth = nav
        self._truth_stream = stream
        if self._ref is None and nav.t.shape[0]:
            self._ref = nav.pos[0].copy()
        keep = convert.decimate(nav.t, rate_hz) if rate_hz else np.arange(nav.t.shape[0])
        sub = convert.NavColumns(nav.t[keep], nav.pos[keep], nav.v_n[keep], nav.q_nb[keep])
        idx = self._indexes(sub.t, t0)
        root = "/" + entity.strip("/")
        for name, values in convert.nav_values(sub, self._ref).items():
            u = display_unit(NAV_UNITS[name])
            path = f"{root}/nav/{name}"
            self._style(path, ["truth"], [TRUTH_COLOR], [2.0])
            self._scalars(path, idx, values * u.scale)
            self.catalog.add(quantity_of(name).value, f"nav:{name}", title(name, u), path)
        for col, values in stream.columns.items():
            if col in ("pos", "v_n", "q_nb"):
                continue
            flat = values[keep].reshape(
                keep.shape[0], int(np.prod(values.shape[1:], dtype=np.int64))
            )
            if flat.shape[1] > 3:
                continue
            u = resolve_unit(col)
            path = f"{root}/extra/{entity_path(col)[1:]}"
            names = [col] if flat.shape[1] == 1 else [f"{col}[{j}]" for j in range(flat.shape[1])]
            self._style(path, [f"truth {n}" for n in names], [TRUTH_COLOR] * len(names))
            self._scalars(path, idx, flat * u.scale)
            self.catalog.add(Quantity.SENSOR.value, f"truth:{col}", f"true {col} [{u.label}]", path)
        # 3D
        ned = convert.local_ned(nav.pos, self._ref)
        world = f"/world{root}"
        self._strip(f"{world}/trajectory", ned, TRUTH_COLOR)
        w = convert.decimate(nav.t, WORLD_RATE_HZ)
        if w.shape[0]:
            self._rec.send_columns(
                f"{world}/body",
                indexes=self._indexes(nav.t[w], t0),
                columns=rr.Transform3D.columns(translation=ned[w], quaternion=_xyzw(nav.q_nb[w])),
            )
            self._axes(f"{world}/body/axes", _axis_size(ned))

    def _ensure_truth(self, truth: Truth, t0_ns: int) -> None:
        """Log ``truth`` unless this sink already holds it; refuse a different recording's."""
        stream, _ = _truth_stream(truth, t0_ns)
        if self._truth_stream is None:
            self.log_truth(truth, t0_ns)
        elif stream is not self._truth_stream and not np.array_equal(
            stream.t_ns, self._truth_stream.t_ns
        ):
            raise ValueError(
                "this sink already holds another recording's truth; open one sink per recording"
            )

    # -- runs ----------------------------------------------------------------------------

    def observer(
        self, truth: Truth | None = None, *, units: Mapping[str, str] | None = None
    ) -> Callable[[RunResult], None]:
        """A live observer for :func:`navreplay.replay.engine.replay`: logs the rows added
        since its previous call (states, sigmas, navigation, errors vs truth, 3D).

        Finish each run with :meth:`log_run` (innovations, metrics, trajectories), which logs
        only the rows the observer has not.
        """

        def observe(result: RunResult) -> None:
            if truth is not None:
                self._ensure_truth(truth, result.t0_ns)
            run = self._run(result.label, units)
            if run.finished:
                raise ValueError(f"run {result.label!r} is already logged in this sink")
            self._log_rows(run, result, run.rows, result.t.shape[0])

        return observe

    def log_run(
        self,
        result: RunResult,
        truth: Truth | None = None,
        metrics: Metrics | None = None,
        *,
        units: Mapping[str, str] | None = None,
    ) -> None:
        """Log one filter's results; several runs (labels) overlay in the same plots.

        Parameters
        ----------
        result : RunResult
            Entities go under ``/<result.label>``.
        truth : Recording or truth Stream, optional
            Logged under /truth (once per sink) and used for the navigation errors
            (roll/pitch/yaw, velocity and position N/E/D) of a result with a nav solution.
        metrics : mapping, optional
            Errors (estimate minus truth, SI) of named outputs at ``result.t``:
            ``name -> error`` or ``name -> (error, sigma)``, arrays (M,) or (M, k). A state name
            takes its sigma from P; the navigation names above replace the computed errors.
        units : mapping, optional
            SI unit per state, extra or measurement name (``"rad"``, ``"rad/s"``, ``"m/s^2"``,
            ``"m"``, ``"m/s"``, ``"-"``...); names not given are guessed from the naming
            conventions, else titled ``[SI]``.
        """
        if truth is not None:
            self._ensure_truth(truth, result.t0_ns)
        run = self._run(result.label, units)
        if run.finished:
            raise ValueError(f"run {result.label!r} is already logged in this sink")
        errors = _metric_columns(result, metrics or {})
        nav_override = {n: errors.pop(n) for n in _NAV_ALL if n in errors}
        if nav_override and run.rows:
            warnings.warn(
                f"{result.label}: navigation errors were already logged live from the truth; "
                f"metrics {sorted(nav_override)} ignored",
                stacklevel=2,
            )
            nav_override = {}
        self._log_rows(run, result, run.rows, result.t.shape[0], nav_override)
        self._log_errors(run, result, errors)
        self._log_innovations(run, result)
        if result.nav_pos is not None and self._ref is not None:
            ned = convert.local_ned(result.nav_pos, self._ref)
            self._strip(entity_path("world", run.label, "trajectory"), ned, run.color)
        run.finished = True

    def _log_rows(
        self,
        run: _Run,
        result: RunResult,
        a: int,
        b: int,
        nav_override: Mapping[str, Any] | None = None,
    ) -> None:
        if b <= a:
            return
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
            u = resolve_unit(n, run.units)
            g = group_of(n)
            shade = _shade(run.color, groups[g].index(n))
            tab = quantity_of(n).value
            legend = L if len(groups[g]) == 1 else f"{L} {n}"
            p_state = entity_path(L, "state", n)
            self._style(p_state, [legend], [shade], [1.5])
            self._scalars(p_state, idx, result.x[a:b, i] * u.scale)
            # an error state that feedback keeps at zero is logged but gets no plot of its own
            # (its error against the truth and its sigma are what is worth looking at)
            if np.any(result.x[a:b, i] != 0.0):
                self.catalog.add(tab, f"state:{g}", title(g, u), p_state)
            p_sig = entity_path(L, "sigma", n)
            self._style(p_sig, [f"σ {legend}"], [shade], [1.5])
            self._scalars(p_sig, idx, sigma[:, i] * u.scale)
            if not self.catalog.has(entity_path(L, "error", n)):
                self.catalog.add(tab, f"sigma:{g}", f"σ {title(g, u)}", p_sig)
        for key, arr in result.extras.items():
            arr = np.asarray(arr[a:b], dtype=np.float64)
            flat = arr.reshape(b - a, int(np.prod(arr.shape[1:], dtype=np.int64)))
            u = resolve_unit(key, run.units)
            path = entity_path(L, "extra", key)
            k = flat.shape[1]
            legend = [L] if k == 1 else [f"{L} {key}[{j}]" for j in range(k)]
            self._style(path, legend, [_shade(run.color, j) for j in range(k)])
            self._scalars(path, idx, flat * u.scale)
            self.catalog.add(quantity_of(key).value, f"extra:{key}", title(key, u), path)
        if (
            result.nav_pos is not None
            and result.nav_v_n is not None
            and result.nav_q_nb is not None
        ):
            self._log_nav(run, result, a, b, idx, nav_override or {})
        run.rows = b

    def _log_nav(
        self,
        run: _Run,
        result: RunResult,
        a: int,
        b: int,
        idx: list[rr.TimeColumn],
        nav_override: Mapping[str, tuple[np.ndarray, np.ndarray | None, str]],
    ) -> None:
        """Navigation solution rows [a, b): values, errors vs truth, 3D."""
        L = run.label
        t = result.t[a:b]
        nav = convert.NavColumns(t, result.nav_pos[a:b], result.nav_v_n[a:b], result.nav_q_nb[a:b])
        if self._ref is None:
            finite = np.flatnonzero(np.isfinite(nav.pos).all(axis=1))
            if finite.shape[0] == 0:
                return
            self._ref = nav.pos[finite[0]].copy()
        values = convert.nav_values(nav, self._ref)
        for n, v in values.items():
            u = display_unit(NAV_UNITS[n])
            path = entity_path(L, "nav", n)
            self._style(path, [L], [run.color], [1.5])
            self._scalars(path, idx, v * u.scale)
            self.catalog.add(quantity_of(n).value, f"nav:{n}", title(n, u), path)
        nav_sigma = _nav_sigma(result, a, b)
        errors: dict[str, tuple[np.ndarray, np.ndarray | None]] = {}
        if self._truth is not None:
            tr = self._truth.at(t)
            ne = nav_errors(nav.pos, nav.v_n, nav.q_nb,
                            {"pos": tr.pos, "v_n": tr.v_n, "q_nb": tr.q_nb})
            cols = {n: c for n, c in ne.columns().items() if not n.startswith("phi")}
            cols.update(roll=ne.euler[:, 0], pitch=ne.euler[:, 1], yaw=ne.euler[:, 2])
            for n, e in cols.items():
                errors[n] = (e, nav_sigma.get(n))
        for n, (e, s, _) in nav_override.items():
            errors[n] = (e[a:b], nav_sigma.get(n) if s is None else s[a:b])
        for n, (e, s) in errors.items():
            u = display_unit(NAV_UNITS[n])
            path = entity_path(L, "error", n)
            self._bounded(path, idx, e * u.scale, None if s is None else s * u.scale, L, run.color)
            self.catalog.add(quantity_of(n).value, f"error:{n}", title(n, u, "error"), path)
        self._log_world(run, result, nav, a, b, values)

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
            self._rec.send_columns(
                entity_path("world", L, "body"),
                indexes=self._indexes(nav.t[w], result.t0_ns),
                columns=rr.Transform3D.columns(translation=ned[w], quaternion=_xyzw(nav.q_nb[w])),
            )
            run.world_t = float(nav.t[w[-1]])
            if not run.axes:
                ref_ned = (
                    ned if self._truth is None else convert.local_ned(self._truth.pos, self._ref)
                )
                self._axes(entity_path("world", L, "body", "axes"), _axis_size(ref_ned))
                run.axes = True
        P_ned = _position_cov(result, a, b)
        if P_ned is None:
            return
        c = convert.decimate(nav.t, COVARIANCE_RATE_HZ, after=run.cov_t)
        c = c[np.isfinite(ned[c]).all(axis=1) & np.isfinite(P_ned[c]).all(axis=(1, 2))]
        if not c.shape[0]:
            return
        half, q = convert.ellipsoids(P_ned[c], N_SIGMA)
        self._rec.send_columns(
            entity_path("world", L, "covariance"),
            indexes=self._indexes(nav.t[c], result.t0_ns),
            columns=rr.Ellipsoids3D.columns(
                centers=ned[c],
                half_sizes=half,
                quaternions=q,
                colors=np.tile((*run.color, 90), (c.shape[0], 1)),
            ),
        )
        run.cov_t = float(nav.t[c[-1]])

    def _log_errors(
        self,
        run: _Run,
        result: RunResult,
        errors: Mapping[str, tuple[np.ndarray, np.ndarray | None, str]],
    ) -> None:
        """Whole-run error series of states and extras, with 3-sigma bounds when known."""
        if not errors:
            return
        L = run.label
        idx = self._indexes(result.t, result.t0_ns)
        states = set(result.state_names)
        for n, (e, s, key) in errors.items():
            u = resolve_unit(key, run.units)
            tab = quantity_of(key).value
            path = entity_path(L, "error", n)
            sig = None if s is None else s * u.scale
            self._bounded(path, idx, e * u.scale, sig, L, run.color)
            self.catalog.add(tab, f"error:{n}", title(n, u, "error"), path)
            if n in states:
                self.catalog.discard(tab, f"sigma:{group_of(n)}", entity_path(L, "sigma", n))

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
            u = resolve_unit(meas, run.units)
            for i in range(dim):
                path = entity_path(L, "innovation", meas, str(i))
                self._bounded(path, idx, nu[:, i] * u.scale, sd[:, i] * u.scale, L, run.color)
                self.catalog.add(
                    "innovation", f"nu:{meas}:{i}", f"{meas} innovation [{i}] [{u.label}]", path
                )
            lo, hi = convert.chi2_bounds(dim)
            path = entity_path(L, "innovation", meas, "nis")
            faint = (*run.color, 140)
            self._style(
                path,
                [f"{L} NIS", "95% low", "95% high"],
                [run.color, faint, faint],
                [1.5, 1.0, 1.0],
            )
            nis = np.asarray(s.nis, dtype=np.float64)
            self._scalars(path, idx, np.stack([nis, np.full(k, lo), np.full(k, hi)], axis=1))
            self.catalog.add("innovation", f"nis:{meas}", f"{meas} NIS (dof {dim}) [-]", path)

    # -- ensembles -----------------------------------------------------------------------

    def log_ensemble(
        self,
        name: str,
        t: np.ndarray,
        series: Mapping[str, np.ndarray],
        *,
        unit: str = "",
        bounds: tuple[np.ndarray | float, np.ndarray | float] | None = None,
        bounds_name: str = "95% bounds",
    ) -> None:
        """Log one Monte Carlo plot under ``/ensemble/<name>/<series>``.

        Parameters
        ----------
        name : str
            Plot name, e.g. ``"roll error"`` or ``"NEES"``.
        t : ndarray, shape (K,)
            Time [s since the recording start].
        series : mapping str -> ndarray (K,)
            Overlaid series in display units, e.g. ``{"rpm RMS": ..., "rpm mean σ": ...,
            "pure RMS": ...}``; one colour per series in order.
        unit : str
            Unit of every series, shown in the title (``"deg"``, ``"m"``, ``"-"``).
        bounds : (lower, upper), optional
            Scalars or arrays (K,), e.g. :func:`navreplay.viz.chi2_bounds` for the average
            NEES; drawn as two grey series.
        """
        t = np.asarray(t, dtype=np.float64)
        idx = [rr.TimeColumn(TIMELINE, duration=np.rint(t * 1e9).astype("timedelta64[ns]"))]
        root = entity_path("ensemble", name)
        plot_title = f"{name} [{unit}]" if unit else name
        for i, (key, values) in enumerate(series.items()):
            values = np.asarray(values, dtype=np.float64)
            if values.shape != t.shape:
                raise ValueError(
                    f"ensemble {name!r}: series {key!r} has shape {values.shape}, t {t.shape}"
                )
            path = f"{root}/{entity_path(key)[1:]}"
            self._style(path, [key], [PALETTE[i % len(PALETTE)]], [1.5])
            self._scalars(path, idx, values)
            self.catalog.add("ensemble", f"ensemble:{name}", plot_title, path)
        if bounds is not None:
            lo = np.broadcast_to(np.asarray(bounds[0], dtype=np.float64), t.shape)
            hi = np.broadcast_to(np.asarray(bounds[1], dtype=np.float64), t.shape)
            path = f"{root}/bounds"
            self._style(
                path, [f"{bounds_name} low", f"{bounds_name} high"], [TRUTH_COLOR] * 2, [1.0, 1.0]
            )
            self._scalars(path, idx, np.stack([lo, hi], axis=1))
            self.catalog.add("ensemble", f"ensemble:{name}", plot_title, path)

    # -- blueprint and lifecycle ---------------------------------------------------------

    def blueprint(self) -> rrb.Blueprint:
        """The default blueprint for what has been logged so far."""
        return build_blueprint(self.catalog)

    def send_blueprint(self) -> None:
        """Send the default blueprint now (also done by :meth:`close`)."""
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
            self.send_blueprint()
            self.flush(timeout)
            if not self._keep_alive:  # a served stream keeps its server up for late browsers
                self._rec.disconnect()
        except BaseException:
            self.abort()
            raise
        self._closed = True
        if self._tmp is not None and self.path is not None:
            if not self._tmp.is_file() or self._tmp.stat().st_size == 0:
                raise OSError(f"Rerun did not write {self._tmp}")
            os.replace(self._tmp, self.path)
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

_NAV_ALL = tuple(n for names in NAV_NAMES.values() for n in names)


def _truth_stream(truth: Truth, t0_ns: int | None) -> tuple[Stream, int]:
    if isinstance(truth, Recording):
        if StreamKind.TRUTH not in truth:
            raise ValueError(f"the recording has no truth stream (streams: {truth.kinds()})")
        return truth[StreamKind.TRUTH], truth.t0_ns if t0_ns is None else int(t0_ns)
    if isinstance(truth, Stream):
        if t0_ns is None:
            t0_ns = int(truth.t_ns[0]) if len(truth) else 0
        return truth, int(t0_ns)
    raise TypeError(f"truth must be a Recording or a truth Stream, not {type(truth).__name__}")


def _truth_nav(stream: Stream, t0_ns: int) -> convert.NavColumns:
    missing = [c for c in ("pos", "v_n", "q_nb") if c not in stream.columns]
    if missing:
        raise ValueError(f"truth stream lacks columns {missing} (has {sorted(stream.columns)})")
    t = (stream.t_ns - np.int64(t0_ns)).astype(np.float64) * 1e-9
    return convert.NavColumns(t, stream["pos"], stream["v_n"], stream["q_nb"])


def _xyzw(q_nb: np.ndarray) -> np.ndarray:
    return quat_wxyz_to_xyzw(q_nb)


def _axis_size(ned: np.ndarray) -> float:
    finite = ned[np.isfinite(ned).all(axis=1)]
    if finite.shape[0] == 0:
        return 1.0
    extent = float(np.max(np.ptp(finite, axis=0)))
    return max(1.0, 0.03 * extent)


def _shade(color: tuple[int, int, int], j: int) -> tuple[int, int, int]:
    """Component j of a group: the run's colour, lightened for j > 0."""
    f = min(0.3 * j, 0.75)
    r, g, b = (int(round(c + (255 - c) * f)) for c in color)
    return r, g, b


def _metric_columns(
    result: RunResult, metrics: Metrics
) -> dict[str, tuple[np.ndarray, np.ndarray | None, str]]:
    """Validate metrics and split them into columns: ``name -> (error, sigma or None, key)``.

    An (M, k) entry ``key`` becomes ``key_0 .. key_{k-1}``; a state name without a sigma takes
    it from P. Raises before anything is logged if a shape does not match ``result.t``.
    """
    m = result.t.shape[0]
    state_index = {n: i for i, n in enumerate(result.state_names)}
    out: dict[str, tuple[np.ndarray, np.ndarray | None, str]] = {}
    sigma_all: np.ndarray | None = None
    for key, val in metrics.items():
        if isinstance(val, tuple):
            if len(val) != 2:
                raise ValueError(f"{result.label}: metric {key!r} is not an (error, sigma) pair")
            err, sig = val
        else:
            err, sig = val, None
        err = np.asarray(err, dtype=np.float64)
        if err.ndim == 0 or err.shape[0] != m:
            raise ValueError(
                f"{result.label}: metric {key!r} has shape {err.shape}, the result has {m} rows"
            )
        cols = err.reshape(m, int(np.prod(err.shape[1:], dtype=np.int64)))
        sig_cols = None
        if sig is not None:
            sig = np.asarray(sig, dtype=np.float64)
            if sig.size != err.size:
                raise ValueError(
                    f"{result.label}: sigma of metric {key!r} has shape {sig.shape}, "
                    f"the error {err.shape}"
                )
            sig_cols = sig.reshape(cols.shape)
        k = cols.shape[1]
        for j in range(k):
            name = key if k == 1 else f"{key}_{j}"
            s = None if sig_cols is None else sig_cols[:, j]
            if s is None and name in state_index:
                sigma_all = result.sigma if sigma_all is None else sigma_all
                s = sigma_all[:, state_index[name]]
            out[name] = (cols[:, j], s, name if name in state_index else key)
    return out


def _position_cov(result: RunResult, a: int, b: int) -> np.ndarray | None:
    """Position-error covariance in NED metres for rows [a, b), or None if not known."""
    if "P_pos_n" in result.extras:
        return np.asarray(result.extras["P_pos_n"][a:b], dtype=np.float64).reshape(b - a, 3, 3)
    states = convert.find_position_states(result.state_names)
    if states is None:
        return None
    pos = None if result.nav_pos is None else result.nav_pos[a:b]
    if states.geodetic and pos is None:
        return None
    return convert.position_cov_ned(result.P[a:b], states, pos)


def _nav_sigma(result: RunResult, a: int, b: int) -> dict[str, np.ndarray]:
    """1-sigma of the navigation errors that the state covariance gives (position, velocity)."""
    out: dict[str, np.ndarray] = {}
    P_ned = _position_cov(result, a, b)
    if P_ned is not None:
        sd = np.sqrt(np.clip(np.diagonal(P_ned, axis1=1, axis2=2), 0.0, None))
        out.update(p_N=sd[:, 0], p_E=sd[:, 1], p_D=sd[:, 2])
    vel = convert.find_velocity_states(result.state_names)
    if vel is not None:
        i = np.asarray(vel)
        sd = np.sqrt(np.clip(result.P[a:b, i, i], 0.0, None))
        out.update(v_N=sd[:, 0], v_E=sd[:, 1], v_D=sd[:, 2])
    return out
