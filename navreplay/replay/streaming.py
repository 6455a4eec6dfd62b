"""Replay files in time windows, so that memory stays flat in the length of the log.

``navreplay run`` (:mod:`navreplay.jobs.run`) reads an intact file window by window
(:func:`navreplay.io.windows.read_windows`: every stream it needs, each known up to a time);
each :class:`~navreplay.replay.engine.ReplaySession` consumes the windows and hands back the
estimates of the events it could apply, which go straight to a :class:`RunningSummary` (the
scalar scores of :meth:`navreplay.metrics.RunMetrics.summary`, NIS per measurement and per row
included, accumulated block by block) and are then dropped. Nothing grows with the log.

:func:`navreplay.replay.engine.replay` keeps working on recordings in memory; both make the
same filter calls, so the estimates are the same bits.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from navreplay import metrics
from navreplay.replay.result import InnovationSeries, RunResult
from navreplay.streams import Stream

# --------------------------------------------------------------------------------------------
# result blocks


def concat_results(blocks: Sequence[RunResult]) -> RunResult:
    """The blocks of one run (from :meth:`ReplaySession.feed`) as one result."""
    full = [b for b in blocks if b.t.size] or [blocks[0]]
    first = full[0]

    def cat(name: str) -> np.ndarray | None:
        if getattr(first, name) is None:
            return None
        return np.concatenate([getattr(b, name) for b in full])

    names = dict.fromkeys(n for b in blocks for n in b.innovations)
    innovations = {
        name: InnovationSeries(*(np.concatenate([getattr(b.innovations[name], f)
                                                 for b in blocks if name in b.innovations])
                                 for f in ("t", "nu", "S", "nis")))
        for name in names
    }
    return dataclasses.replace(
        first, t=cat("t"), x=cat("x"), P=cat("P"), nav_pos=cat("nav_pos"),
        nav_v_n=cat("nav_v_n"), nav_q_nb=cat("nav_q_nb"),
        extras={k: np.concatenate([b.extras[k] for b in full]) for k in first.extras},
        innovations=innovations,
    )


def _rows(result: RunResult, a: int, b: int) -> RunResult:
    """Rows [a, b) of a result, without innovations (views)."""
    def cut(v: np.ndarray | None) -> np.ndarray | None:
        return None if v is None else v[a:b]

    return dataclasses.replace(
        result, t=result.t[a:b], x=result.x[a:b], P=result.P[a:b],
        nav_pos=cut(result.nav_pos), nav_v_n=cut(result.nav_v_n),
        nav_q_nb=cut(result.nav_q_nb), extras={k: v[a:b] for k, v in result.extras.items()},
        innovations={},
    )


def _join_streams(a: Stream | None, b: Stream) -> Stream:
    if a is None or not len(a):
        return b
    return dataclasses.replace(
        a, t_ns=np.concatenate([a.t_ns, b.t_ns]),
        columns={k: np.concatenate([a.columns[k], b.columns[k]]) for k in a.columns},
    )


# --------------------------------------------------------------------------------------------
# running scores


class _Sum:
    """Sum of squares and count of the finite values seen (an RMS), and whether any was."""

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
        self.lo, self.hi = metrics.chi2_bounds(dof, 1, probability) if dof else (0.0, 0.0)
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


class RunningSummary:
    """The scalar scores of one run (:meth:`navreplay.metrics.RunMetrics.summary`), from its
    estimates block by block and the truth window by window; memory independent of the length.

    Estimates are scored once the truth around them is at hand (the errors are those of
    :func:`navreplay.metrics.run_metrics` on each block, the truth interpolated the same way);
    the truth is kept from the sample before the next estimate on.

    Parameters
    ----------
    label : str
    t0_ns : int
        Recording start [ns].
    true_errors : mapping
        ``metadata.true_errors`` (constants that states are scored against).
    has_truth : bool
        Whether a truth stream follows (else: innovation statistics only).
    probability : float
        Of the chi-square bounds.
    scored : callable, optional
        Called with each block of rows as it is scored, its metrics
        (:func:`navreplay.metrics.run_metrics`; None without truth) and the truth rows around
        it (None without truth): what a Rerun sink logs block by block.
    """

    def __init__(self, label: str, t0_ns: int, true_errors: Mapping[str, Any],
                 has_truth: bool, probability: float = 0.95,
                 scored: Callable[[RunResult, metrics.RunMetrics | None, Stream | None], None]
                 | None = None) -> None:
        self.label = label
        self.scored = scored
        self.t0_ns = t0_ns
        self.true_errors = true_errors
        self.has_truth = has_truth
        self.probability = probability
        self._truth: Stream | None = None
        self._truth_done = False
        self._pending: list[RunResult] = []
        self._offset = 0.0  # true distance up to the first kept truth sample [m]
        self.rows = 0
        self._t = (math.nan, math.nan)
        self._distance = math.nan
        self._h_final = math.nan
        self._h, self._v, self._vel = _Sum(), _Sum(), _Sum()
        self._level, self._heading = _Sum(), _Sum()
        self._has_pos = self._has_vel = self._has_att = False
        self._nees: _Chi2 | None = None
        self._nis: dict[str, _Chi2] = {}

    def add_truth(self, truth: Stream | None, final: bool = False) -> None:
        """More truth samples (later than those before); ``final``: no more follow."""
        if truth is not None and len(truth):
            self._truth = _join_streams(self._truth, truth)
        self._truth_done = self._truth_done or final
        self._score()

    def add(self, block: RunResult) -> None:
        """A block of estimates and innovations (later than those before)."""
        for name, s in block.innovations.items():
            acc = self._nis.get(name)
            if acc is None:
                acc = self._nis[name] = _Chi2(int(s.nu.shape[1]), self.probability)
            acc.add(s.nis)
            for row, v in metrics.row_nis(block, name).items():
                acc = self._nis.get(f"{name}.{row}")
                if acc is None:
                    acc = self._nis[f"{name}.{row}"] = _Chi2(1, self.probability)
                acc.add(v)
        if block.t.size:
            self._pending.append(block)
            self._score()

    def _score(self) -> None:
        if not self._pending:
            return
        pending = (self._pending[0] if len(self._pending) == 1
                   else concat_results(self._pending))
        pending.innovations = {}
        if not self.has_truth or self._truth_done or self._truth is None:
            if self.has_truth and self._truth is None and not self._truth_done:
                return
            ready = pending.t.shape[0]
        else:
            limit = (int(self._truth.t_ns[-1]) - self.t0_ns) * 1e-9
            ready = int(np.searchsorted(pending.t, limit, side="right"))
        if ready:
            self._score_rows(_rows(pending, 0, ready))
        self._pending = [] if ready == pending.t.shape[0] else [
            _rows(pending, ready, pending.t.shape[0])]

    def _score_rows(self, rows: RunResult) -> None:
        t = rows.t
        self._t = (t[0] if self.rows == 0 else self._t[0], t[-1])
        self.rows += t.shape[0]
        if not self.has_truth or self._truth is None:
            if self.scored is not None:
                self.scored(rows, None, None)
            return
        ref = metrics.Reference(self._truth, self.t0_ns, self.true_errors)
        m = metrics.run_metrics(rows, ref)
        if self.scored is not None:
            self.scored(rows, m, self._truth)
        self._distance = self._offset + float(m.distance[-1])
        if m.nav is not None:
            p = m.nav.pos_ned
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
        # keep the truth from the sample at or before the last estimate on
        ts = self._truth.t_ns
        keep = max(int(np.searchsorted(ts, self.t0_ns + round(t[-1] * 1e9), side="right")) - 1,
                   0)
        if keep:
            self._offset += float(ref.distance(np.array([(int(ts[keep]) - self.t0_ns) * 1e-9]))[0])
            self._truth = self._truth.slice(keep, len(self._truth))

    def summary(self) -> dict[str, Any]:
        """The scores of :meth:`navreplay.metrics.RunMetrics.summary` (SI)."""
        self._truth_done = True
        self._score()
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
