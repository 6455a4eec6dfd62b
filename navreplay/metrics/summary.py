"""The scalar scores of one run, accumulated block by block in memory independent of its length:
what the summary table and JSON of ``navreplay run`` show (SI; units in
:data:`navreplay.metrics.tables.SUMMARY_UNITS`). A whole run is one block
(:meth:`navreplay.metrics.RunMetrics.summary`).

Examples
--------
>>> import numpy as np
>>> s = RunSummary()
>>> s.add_nis("gps_pos", np.array([2.0, 4.0]), 3)
>>> {k: round(v, 3) for k, v in s.result().items()}  # doctest: +NORMALIZE_WHITESPACE
{'duration': 0.0, 'distance': 0.0, 'nis_dof_gps_pos': 3, 'nis_mean_gps_pos': 3.0,
 'nis_in_bounds_gps_pos': 1.0}
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from navreplay.metrics.outages import OutageScores
from navreplay.metrics.stats import chi2_bounds

if TYPE_CHECKING:
    from navreplay.metrics.run import RunMetrics


class _Sum:
    """Sum of squares and count of the finite values seen (an RMS)."""

    def __init__(self) -> None:
        self.sq = 0.0
        self.n = 0

    def add(self, v: np.ndarray) -> None:
        ok = np.isfinite(v)
        self.sq += float(np.sum(np.square(v[ok])))
        self.n += int(ok.sum())

    def rms(self) -> float:
        return math.sqrt(self.sq / self.n) if self.n else math.nan


class _Chi2:
    """Mean and in-bounds fraction of NEES or NIS values of one degree of freedom."""

    def __init__(self, dof: int, probability: float) -> None:
        self.dof = dof
        self.lo, self.hi = chi2_bounds(dof, 1, probability) if dof else (0.0, 0.0)
        self.total = 0.0
        self.n = 0
        self.inside = 0

    def add(self, v: np.ndarray) -> None:
        self.total += float(np.sum(v))
        self.n += v.shape[0]
        self.inside += int(np.sum((v >= self.lo) & (v <= self.hi)))

    def put(self, out: dict[str, Any], kind: str, suffix: str) -> None:
        if self.dof == 0 or not self.n:
            return
        out[f"{kind}_dof{suffix}"] = self.dof
        out[f"{kind}_mean{suffix}"] = self.total / self.n
        out[f"{kind}_in_bounds{suffix}"] = self.inside / self.n


class RunSummary:
    """The scalar scores of one run from its scores block by block.

    Feed it each block's :class:`~navreplay.metrics.RunMetrics` (:meth:`add`, rows later than
    before) and the NIS of each block's updates (:meth:`add_nis`, or within the metrics);
    :meth:`result` gives the summary.

    Parameters
    ----------
    probability : float
        Of the chi-square bounds.
    """

    def __init__(self, probability: float = 0.95) -> None:
        self.probability = probability
        self.rows = 0
        self._t = (math.nan, math.nan)
        self._distance = math.nan
        self._h_final = math.nan
        self._h, self._v, self._vel = _Sum(), _Sum(), _Sum()
        self._level, self._heading = _Sum(), _Sum()
        self._has_pos = self._has_vel = self._has_att = False
        self._nees: _Chi2 | None = None
        self._nis: dict[str, _Chi2] = {}
        self._outages: OutageScores | None = None

    def add_nis(self, name: str, nis: np.ndarray, dof: int,
                rows: Mapping[str, np.ndarray] | None = None) -> None:
        """The NIS of a block of updates of measurement ``name``, and of each of its rows
        (:func:`navreplay.metrics.row_nis`)."""
        acc = self._nis.get(name)
        if acc is None:
            acc = self._nis[name] = _Chi2(dof, self.probability)
        acc.add(nis)
        for row, v in (rows or {}).items():
            acc = self._nis.get(f"{name}.{row}")
            if acc is None:
                acc = self._nis[f"{name}.{row}"] = _Chi2(1, self.probability)
            acc.add(v)

    def count(self, t: np.ndarray) -> None:
        """Estimates at times ``t`` [s] (later than before), whether scored or not (a run
        without a reference)."""
        if t.shape[0]:
            self._t = (t[0] if self.rows == 0 else self._t[0], t[-1])
            self.rows += t.shape[0]

    def add(self, m: RunMetrics, distance_offset: float = 0.0) -> None:
        """The scores of a block of estimates (later than those before), and the NIS they
        carry; ``distance_offset``: the true distance before the reference of this block [m]."""
        for name, (_, v, dof) in m.nis.items():
            self.add_nis(name, v, dof, m.nis_rows.get(name))
        if not m.t.shape[0]:
            return
        self.count(m.t)
        self._distance = distance_offset + float(m.distance[-1])
        if m.nav is not None:
            p = m.nav.pos_ned
            if m.outages:
                if self._outages is None:
                    self._outages = OutageScores(m.outages)
                self._outages.add(m.t, p, m.nav_sigma["pos_ned"])
            if np.isfinite(p).any():
                self._has_pos = True
                h = np.hypot(p[:, 0], p[:, 1])
                if np.isfinite(h).any():
                    self._h_final = float(h[np.isfinite(h)][-1])
                self._h.add(h)
                self._v.add(p[:, 2])
            if np.isfinite(m.nav.v_n).any():
                self._has_vel = True
                self._vel.add(np.linalg.norm(m.nav.v_n, axis=1))
            if np.isfinite(m.nav.phi).any():
                self._has_att = True
                self._level.add(m.nav.phi[:, :2])
                self._heading.add(m.nav.phi[:, 2])
        if self._nees is None:
            self._nees = _Chi2(len(m.nees_states), self.probability)
        ok = np.isfinite(m.nees)
        self._nees.add(m.nees[ok])

    def result(self) -> dict[str, Any]:
        """The summary: duration, distance, position, velocity and attitude RMS, final position
        error (and per cent of the distance), NEES and NIS with the fraction inside their
        chi-square bounds, and with GNSS outages in the recording each outage's scores
        (``gnss_outages``, :meth:`navreplay.metrics.outages.OutageScores.result`) (SI)."""
        out: dict[str, Any] = {"duration": float(self._t[1] - self._t[0]) if self.rows else 0.0}
        if not self.rows:
            out["distance"] = 0.0
        elif math.isfinite(self._distance):
            out["distance"] = self._distance
        if self._has_pos:
            out["pos_err_final_h"] = self._h_final
            out["pos_rms_h"] = self._h.rms()
            out["pos_rms_v"] = self._v.rms()
            if out.get("distance", 0.0) > 0.0:
                out["pos_err_final_dt"] = 100.0 * out["pos_err_final_h"] / out["distance"]
            if self._outages is not None:
                out["gnss_outages"] = self._outages.result()
        if self._has_vel:
            out["vel_rms"] = self._vel.rms()
        if self._has_att:
            out["att_rms_level"] = self._level.rms()
            out["att_rms_heading"] = self._heading.rms()
        if self._nees is not None:
            self._nees.put(out, "nees", "")
        for name, acc in self._nis.items():
            acc.put(out, "nis", f"_{name}")
        return out
