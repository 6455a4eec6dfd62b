"""The part of a run that a reference scores: the fraction of a filter's outputs within the
reference's span (``reference_coverage`` in a run's summary, with a warning below
:data:`COVERAGE_WARNING`), counted as outputs and reference samples arrive."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

COVERAGE_WARNING = 0.9
"""Below this fraction of a filter's outputs scored by the reference, the run warns that its
scores describe only part of it."""


class CoverageCount:
    """The fraction of a filter's outputs that a reference scores, fed piece by piece.

    An output is scored when it lies within the reference's span, widened by half its median
    sample interval at each end (the rule of :meth:`navreplay.metrics.Reference.at`; times
    further outside are not scored). Outputs and reference samples arrive in increasing time,
    window by window; only the outputs after the reference's last sample so far are kept, so
    memory stays flat when the reference covers the run.
    """

    def __init__(self) -> None:
        self.total = 0
        self.covered = 0
        self._first: float | None = None
        self._last = -math.inf
        self._half = 0.0
        self._pending: list[np.ndarray] = []  # outputs after the reference's end so far

    def reference(self, t: np.ndarray) -> None:
        """More reference sample times [s since the recording start], later than before."""
        t = np.asarray(t, dtype=float)
        if not t.size:
            return
        if self._first is None:
            self._first = float(t[0])
            self._half = 0.5 * float(np.median(np.diff(t))) if t.size > 1 else 0.0
        self._last = max(self._last, float(t[-1]))
        self._settle()

    def outputs(self, t: np.ndarray) -> None:
        """More output times [s since the recording start], later than before."""
        t = np.asarray(t, dtype=float)
        self.total += t.size
        if t.size:
            self._pending.append(t)
            self._settle()

    def _settle(self) -> None:
        if self._first is None or not self._pending:
            return
        t = np.concatenate(self._pending)
        lo, hi = self._first - self._half, self._last + self._half
        inside = (t >= lo) & (t <= hi)
        self.covered += int(inside.sum())
        self._pending = [t[t > hi]]

    def fraction(self) -> float:
        """Outputs scored over outputs (1.0 for a run without outputs)."""
        return self.covered / self.total if self.total else 1.0


def reference_coverage(t: np.ndarray, t_ref: np.ndarray) -> float:
    """The fraction of outputs at times ``t`` that a reference sampled at ``t_ref`` scores
    (both [s since the recording start]; :class:`CoverageCount`)."""
    count = CoverageCount()
    count.reference(t_ref)
    count.outputs(t)
    return count.fraction()


def coverage_warning(label: str, fraction: float, source: str = "the reference") -> str | None:
    """The warning for a filter whose outputs ``source`` scores only in part, or None."""
    if fraction >= COVERAGE_WARNING:
        return None
    return (f"{source} covers {100 * fraction:.1f} % of the outputs of {label} (below "
            f"{100 * COVERAGE_WARNING:.0f} %): its scores describe that part of the run only "
            "(reference_coverage in the summary)")


def add_coverage(summary: dict[str, Any], label: str, fraction: float,
                 source: str = "the reference") -> None:
    """Put ``reference_coverage`` into a filter's summary and warn below
    :data:`COVERAGE_WARNING` (:func:`coverage_warning`)."""
    import warnings

    summary["reference_coverage"] = fraction
    text = coverage_warning(label, fraction, source)
    if text is not None:
        warnings.warn(text, stacklevel=2)
