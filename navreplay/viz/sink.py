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

The sink is composed of one module per part of the view: :mod:`~navreplay.viz.channel`
(the stream, time columns, live layout), :mod:`~navreplay.viz.style`, :mod:`~navreplay.viz.world`
(3D and map), :mod:`~navreplay.viz.truth`, :mod:`~navreplay.viz.runs` (a filter's series) and
:mod:`~navreplay.viz.ensemble` (Monte Carlo plots).
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from navreplay.core.streams import LOCAL_ORIGIN, Stream
from navreplay.filters.result import RunResult
from navreplay.io.outputs import OutputError
from navreplay.metrics import RunMetrics
from navreplay.metrics.compare import headline_rows, markdown_comparison
from navreplay.viz.ensemble import EnsemblePlots
from navreplay.viz.naming import entity_path
from navreplay.viz.runs import RunView
from navreplay.viz.targets import (
    Serve,
    VizUnavailableError,
    rrd_problem,
)
from navreplay.viz.truth import TRUTH_RATE_HZ, truth_nav
from navreplay.viz.world import box_at

APPLICATION_ID = "navreplay"


class Sink(RunView, EnsemblePlots):
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

    def __enter__(self) -> Sink:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def start(self, run: Any) -> None:
        """A replay over one recording starts (a :class:`navreplay.replay.RunStart`: its start
        time, the truth columns the declared states are scored against, and the local frame's
        origin when the user gave one: :data:`navreplay.core.streams.LOCAL_ORIGIN`)."""
        self._t0_ns = int(run.t0_ns)
        self._truth_wanted = dict(run.truth_columns)
        self._outages = tuple(run.gnss_outages)
        metadata = getattr(run, "metadata", None)
        origin = metadata.extra.get(LOCAL_ORIGIN) if metadata is not None else None
        if origin is not None and self._ref is None:  # the local NED frame's, given by the user
            self._ref = np.asarray(origin["pos"], dtype=float)

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
            self._truth = None if truth is None else truth_nav(truth, rows.t0_ns)
            box = r.extent_box
            if self._truth is not None and rows.t.shape[0]:
                self._extent_curve = self._track_extent(self._truth, box, float(rows.t[0]))
                lo, hi, found = box_at(self._extent_curve, rows.t[-1:])
                if found[0]:
                    box = (lo[0], hi[0])
            self._log_rows(r, rows, 0, rows.t.shape[0], frozenset(errors), metrics)
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

    def summaries(self, summaries: Mapping[str, Mapping[str, Any]]) -> None:
        """Log the headline metrics of the filters' summaries (label -> summary dict, SI) as a
        table in the Compare tab (a row per metric, a column per filter, the best in bold)."""
        text = markdown_comparison(summaries)
        self._rec.log("/compare/summary", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN),
                      static=True)
        self.catalog.add("compare", "summary", "headline metrics", "/compare/summary",
                         rank=10_000, kind="text")

    def comparison(self, summaries: Mapping[str, Mapping[str, Any]]) -> None:
        """Saved summaries side by side (``navreplay compare``): the table of headline metrics
        and a bar chart per metric, a bar per label in its colour."""
        self.summaries(summaries)
        for rank, (name, values, _) in enumerate(headline_rows(summaries)):
            for i, (label, v) in enumerate(zip(summaries, values, strict=True)):
                if not np.isfinite(v):
                    continue
                path = entity_path("compare", "metric", name, label)
                self._rec.log(path, rr.BarChart([v], abscissa=[float(i)],
                                                color=self.color_of(label)), static=True)
                self.catalog.add("compare", f"metric:{name}", name, path, rank=rank,
                                 kind="bars")

    def flush(self, timeout: float = 30.0) -> None:
        """Wait until the logged data has left the process (raises VizUnavailableError)."""
        self._send_pending()
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
            self._log_legend()
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
