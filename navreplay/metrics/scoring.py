"""Scoring a run block by block as its estimates and its truth arrive (a replay fed in time
windows): each block of estimates is scored once the truth around it is at hand, with the
errors of :func:`navreplay.metrics.run_metrics` on the block, and its scores accumulate in a
:class:`~navreplay.metrics.summary.RunSummary`; the truth is kept from the sample before the next
estimate on. Memory does not grow with the run's length. The scorer also counts the part of
the outputs the truth covers (:class:`~navreplay.metrics.coverage.CoverageCount`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from navreplay.core.streams import Stream, seconds
from navreplay.filters.result import RunResult, concat
from navreplay.metrics.coverage import CoverageCount
from navreplay.metrics.reference import Reference
from navreplay.metrics.run import RunMetrics, row_nis, run_metrics
from navreplay.metrics.summary import RunSummary

Scored = Callable[[RunResult, RunMetrics | None, Stream | None], None]
"""Called with each block of rows as it is scored, its metrics (None without truth) and the
truth rows around it (None without truth)."""


class RunScorer:
    """The scores of one run from its estimates block by block and the truth window by window.

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
    outages : tuple of (start, end)
        The recording's GNSS outages [s] (:attr:`Reference.outages`), scored one by one.
    scored : callable, optional
        Called with each block of rows as it is scored (:data:`Scored`): what the view, the
        exports and the report take block by block.
    """

    def __init__(self, label: str, t0_ns: int, true_errors: Mapping[str, Any],
                 has_truth: bool, probability: float = 0.95,
                 outages: tuple[tuple[float, float], ...] = (),
                 scored: Scored | None = None) -> None:
        self.label = label
        self.scored = scored
        self.t0_ns = t0_ns
        self.true_errors = true_errors
        self.has_truth = has_truth
        self.outages = outages
        self.summary = RunSummary(probability)
        self._truth: Stream | None = None
        self._truth_done = False
        self._pending: list[RunResult] = []
        self._offset = 0.0  # true distance up to the first kept truth sample [m]
        self._coverage = CoverageCount()

    @property
    def rows(self) -> int:
        """Estimates scored so far."""
        return self.summary.rows

    def add_truth(self, truth: Stream | None, final: bool = False) -> None:
        """More truth samples (later than those before); ``final``: no more follow."""
        if truth is not None and len(truth):
            self._truth = _join_streams(self._truth, truth)
            self._coverage.reference(seconds(truth.t_ns, self.t0_ns))
        self._truth_done = self._truth_done or final
        self._score()

    def add(self, block: RunResult) -> None:
        """A block of estimates and innovations (later than those before)."""
        for name, s in block.innovations.items():
            self.summary.add_nis(name, s.nis, int(s.nu.shape[1]), row_nis(block, name))
        self._coverage.outputs(block.t)
        if block.t.size:
            self._pending.append(block)
            self._score()

    def _score(self) -> None:
        if not self._pending:
            return
        pending = (self._pending[0] if len(self._pending) == 1
                   else concat(self._pending))
        pending.innovations = {}
        if not self.has_truth or self._truth_done or self._truth is None:
            if self.has_truth and self._truth is None and not self._truth_done:
                return
            ready = pending.t.shape[0]
        else:
            limit = (int(self._truth.t_ns[-1]) - self.t0_ns) * 1e-9
            ready = int(np.searchsorted(pending.t, limit, side="right"))
        if ready:
            self._score_rows(pending.rows(0, ready))
        self._pending = [] if ready == pending.t.shape[0] else [
            pending.rows(ready, pending.t.shape[0])]

    def _score_rows(self, rows: RunResult) -> None:
        if not self.has_truth or self._truth is None:
            self.summary.count(rows.t)
            if self.scored is not None:
                self.scored(rows, None, None)
            return
        ref = Reference(self._truth, self.t0_ns, self.true_errors, self.outages)
        m = run_metrics(rows, ref)
        if self.scored is not None:
            self.scored(rows, m, self._truth)
        self.summary.add(m, self._offset)
        # keep the truth from the sample at or before the last estimate on
        ts = self._truth.t_ns
        t = rows.t
        keep = max(int(np.searchsorted(ts, self.t0_ns + round(t[-1] * 1e9), side="right")) - 1,
                   0)
        if keep:
            self._offset += float(np.asarray(
                ref.distance(np.array([(int(ts[keep]) - self.t0_ns) * 1e-9])))[0])
            self._truth = self._truth.slice(keep, len(self._truth))

    def coverage(self) -> float:
        """The fraction of the outputs so far that the truth scores
        (``reference_coverage``)."""
        return self._coverage.fraction()

    def result(self) -> dict[str, Any]:
        """The summary of the run (:meth:`RunSummary.result`), the rows still waiting for
        their truth scored first."""
        self._truth_done = True
        self._score()
        return self.summary.result()


def _join_streams(a: Stream | None, b: Stream) -> Stream:
    if a is None or not len(a):
        return b
    return dataclasses.replace(
        a, t_ns=np.concatenate([a.t_ns, b.t_ns]),
        columns={k: np.concatenate([a.columns[k], b.columns[k]]) for k in a.columns},
    )
