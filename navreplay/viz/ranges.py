"""What a time-series pane draws and the ranges it opens on: the rows kept of a long series (a
min/max envelope per time bin, so no peak is lost), and the y and time ranges that make a pane
readable (a minimum span for values that can be all zero, the start-up transient left out of
the y range when it would flatten the result, headroom above the data for the legend).

No rerun import here: the blueprint turns the ranges into axes.

Examples
--------
>>> import numpy as np
>>> t = np.arange(1000) * 0.01                       # 100 Hz for 10 s
>>> v = np.sin(t); v[537] = 5.0                      # a one-sample peak
>>> k = envelope_rows(t, v[:, None], 2.0)            # bins of 0.5 s
>>> len(k) <= 2 * 20 + 1, 537 in k
(True, True)
"""

from __future__ import annotations

import dataclasses

import numpy as np

DRAWN_RATE_HZ = 0.5
"""Default bins per second of a drawn series: each 2 s bin keeps the rows of the smallest and
the largest value (and of a ±3σ bound's largest), so a 10 Hz or a 100 Hz output draws at
about one row per second, a pane holds about a bin per pixel of its width even for an hour,
and every peak stays. Scores, summaries and exports use every row."""


def envelope_rows(t: np.ndarray, values: np.ndarray, rate_hz: float,
                  columns: tuple[int, ...] | None = None,
                  maxima: tuple[int, ...] = ()) -> np.ndarray:
    """Indices of the rows of ``values`` (M, k) at times ``t`` [s] to draw: per bin of
    ``1 / rate_hz`` seconds, the row of the smallest and of the largest value of each of
    ``columns`` (all by default), the row of the largest value of each of ``maxima`` (a +3σ
    bound: its peaks): rows of whole bins give the same rows however they were split. NaN
    values are never a minimum or maximum; rows where column 0 is NaN between finite ones
    are kept once per bin (a gap stays a gap)."""
    M = t.shape[0]
    if M <= 2:
        return np.arange(M)
    bins = np.floor(np.asarray(t, dtype=np.float64) * rate_hz)
    starts = _changes(bins)
    if starts.shape[0] * 3 >= M:  # already sparse: everything
        return np.arange(M)
    seg = np.repeat(np.arange(starts.shape[0]), np.diff(starts, append=M))
    keep = np.zeros(M, dtype=bool)
    cols = range(values.shape[1]) if columns is None else columns
    for j, signs in [*((j, (1.0, -1.0)) for j in cols), *((j, (-1.0,)) for j in maxima)]:
        v = values[:, j]
        for sign in signs:  # the first row of a bin holding its smallest (largest) value
            extreme = (np.fmin if sign > 0 else np.fmax).reduceat(v, starts)  # NaN: none
            hit = np.flatnonzero((v == extreme[seg]) & np.isfinite(v))
            keep[hit[_changes(seg[hit])]] = True
    gap = np.isnan(values[:, 0])
    if gap.any():
        first_gap = np.flatnonzero(gap & np.r_[True, ~gap[:-1]])
        keep[first_gap] = True
        keep[np.flatnonzero(gap[:-1] & ~gap[1:]) + 1] = True  # first finite after a gap
    return np.flatnonzero(keep)


def envelope_rows_of(t: np.ndarray, series: list[tuple[np.ndarray, tuple[int, ...] | None,
                                                       tuple[int, ...]]],
                     rate_hz: float) -> list[np.ndarray | None]:
    """:func:`envelope_rows` of several series at the same times ``t`` [s], computed together:
    ``series`` holds each one's ``(values (M, k), columns, maxima)``; returns the rows of each
    (None: every row). The same rows as a call per series, in a few array operations over all
    of them (bins of as many rows each, as a steady output rate gives, as a reshaped array)."""
    M, S = t.shape[0], len(series)
    if M <= 2 or not S:
        return [None] * S
    starts = _changes(np.floor(np.asarray(t, dtype=np.float64) * rate_hz))
    nb = starts.shape[0]
    if nb * 3 >= M:  # already sparse: everything
        return [None] * S
    # the columns whose smallest and largest rows are kept, a row each, then the maxima's
    lows: list[np.ndarray] = []
    highs: list[np.ndarray] = []
    low_of: list[int] = []
    high_of: list[int] = []
    zero: list[int] = []  # the row of each series' column 0 among the lows (-1: not there)
    for s, (v, columns, maxima) in enumerate(series):
        cols = list(range(v.shape[1])) if columns is None else list(columns)
        zero.append(len(low_of) + cols.index(0) if 0 in cols else -1)
        lows.append(v.T if columns is None else v.T[cols])
        low_of += [s] * len(cols)
        if maxima:
            highs.append(v.T[list(maxima)])
            high_of += [s] * len(maxima)
    low = np.concatenate(lows) if len(lows) > 1 else np.ascontiguousarray(lows[0])
    parts: list[tuple[np.ndarray, tuple[bool, ...], np.ndarray]] = [
        (low, (True, False), np.asarray(low_of))]
    if highs:
        parts.append((np.concatenate(highs), (False,), np.asarray(high_of)))
    keep = np.zeros((S, M), dtype=bool)
    n = M // nb
    regular = M == nb * n and np.array_equal(starts, np.arange(0, M, n))
    low_nan = None
    for v, kinds, owner in parts:
        finite = np.isfinite(v)
        whole = bool(finite.all())  # then every bin's extremes are rows of the series
        nan = None if whole else np.isnan(v)
        if v is low:
            low_nan = nan
        for smallest in kinds:
            # per bin, the first row holding its smallest (largest) finite value, if any
            if regular:
                w = v.reshape(v.shape[0], nb, n)
                if nan is not None and nan.any():
                    w = np.where(nan.reshape(w.shape), np.inf if smallest else -np.inf, w)
                at = w.argmin(axis=2) if smallest else w.argmax(axis=2)
                found = (None if whole else
                         np.isfinite(np.take_along_axis(w, at[:, :, None], axis=2)[:, :, 0]))
                at += starts
            else:
                seg = np.repeat(np.arange(nb), np.diff(starts, append=M))
                extreme = (np.fmin if smallest else np.fmax).reduceat(v, starts, axis=1)
                hit = (v == extreme[:, seg]) & finite
                at = np.minimum.reduceat(np.where(hit, np.arange(M), M), starts, axis=1)
                found = at < M
            series_of = np.broadcast_to(owner[:, None], at.shape)
            if found is None:
                keep[series_of, at] = True
            else:
                keep[series_of[found], at[found]] = True
    if (low_nan is not None and low_nan.any()) or min(zero) < 0:
        # the first row of a gap and the first finite row after it
        gap = np.stack([np.isnan(v[:, 0]) if z < 0 or low_nan is None else low_nan[z]
                        for z, (v, _, _) in zip(zero, series, strict=True)])
        keep[:, 0] |= gap[:, 0]
        keep[:, 1:] |= gap[:, 1:] & ~gap[:, :-1]
        keep[:, 1:] |= gap[:, :-1] & ~gap[:, 1:]
    of, rows = np.nonzero(keep)
    ends = np.cumsum(np.bincount(of, minlength=S)).tolist()
    return [rows[a:b] for a, b in zip([0, *ends[:-1]], ends, strict=True)]


def _changes(a: np.ndarray) -> np.ndarray:
    """Indices where a run of equal values of ``a`` starts (0 first, if ``a`` is not empty)."""
    if not a.shape[0]:
        return np.zeros(0, dtype=np.intp)
    d = np.empty(a.shape[0], dtype=bool)
    d[0] = True
    np.not_equal(a[1:], a[:-1], out=d[1:])
    return np.flatnonzero(d)


class Envelope:
    """The smallest and largest value of a series per time bin, in bounded memory (at most
    :data:`BINS` bins, their width doubled as the series grows): what the y range of its pane
    is computed from."""

    BINS = 256

    def __init__(self) -> None:
        self.width = 1.0
        self.lo = np.full(self.BINS, np.inf)
        self.hi = np.full(self.BINS, -np.inf)
        self.t_first = np.inf
        self.t_last = -np.inf

    def add(self, t: np.ndarray, values: np.ndarray) -> None:
        """Rows at times ``t`` [s, >= 0 after the recording start] of ``values`` (M, k)."""
        v = np.asarray(values, dtype=np.float64).reshape(t.shape[0], -1)
        ok = np.isfinite(v)
        if ok.all():
            lo, hi = _across(np.minimum, v), _across(np.maximum, v)
            rows = np.isfinite(t)
        else:  # of each row's finite values
            lo = _across(np.minimum, np.where(ok, v, np.inf))
            hi = _across(np.maximum, np.where(ok, v, -np.inf))
            rows = np.isfinite(lo) & np.isfinite(t)  # rows with one at least
        if not rows.all():
            if not rows.any():
                return
            t, lo, hi = t[rows], lo[rows], hi[rows]
        self._grow(float(t[0]), float(t[-1]))
        b = np.clip((np.maximum(t, 0.0) // self.width).astype(np.int64), 0, self.BINS - 1)
        np.minimum.at(self.lo, b, lo)
        np.maximum.at(self.hi, b, hi)

    def _grow(self, t_first: float, t_last: float) -> None:
        """Rows from ``t_first`` to ``t_last`` [s] come: the bins widened to hold them."""
        if t_first < self.t_first:
            self.t_first = t_first
        if t_last > self.t_last:
            self.t_last = t_last
        while self.t_last >= self.width * self.BINS:
            half = self.BINS // 2
            lo, hi = np.full(self.BINS, np.inf), np.full(self.BINS, -np.inf)
            np.minimum(self.lo[0::2], self.lo[1::2], out=lo[:half])
            np.maximum(self.hi[0::2], self.hi[1::2], out=hi[:half])
            self.lo, self.hi = lo, hi
            self.width *= 2.0

    def extent(self, after: float = -np.inf) -> tuple[float, float] | None:
        """Smallest and largest value of the bins that start at or after ``after`` [s]."""
        start = np.arange(self.BINS) * self.width
        sel = (start >= after) & np.isfinite(self.lo)
        if not sel.any():
            return None
        return float(self.lo[sel].min()), float(self.hi[sel].max())


def add_rows(envelopes: list[Envelope], t: np.ndarray, values: list[np.ndarray]) -> None:
    """:meth:`Envelope.add` of several series at the same times ``t`` [s]: ``values[i]``
    (M, k_i) to ``envelopes[i]``, the bins of the times found once for all (times increasing:
    a bin's rows are consecutive, reduced at once)."""
    M = t.shape[0]
    if not M or not np.isfinite(t).all() or (M > 1 and not (t[1:] >= t[:-1]).all()):
        for e, v in zip(envelopes, values, strict=True):
            e.add(t, v)
        return
    bins: dict[float, tuple[np.ndarray, np.ndarray]] = {}
    after0 = np.maximum(t, 0.0)
    for e, v in zip(envelopes, values, strict=True):
        ok = np.isfinite(v)
        if ok.all():
            lo = hi = v[:, 0]
            if v.shape[1] > 1:
                lo, hi = _across(np.minimum, v), _across(np.maximum, v)
            first, last = 0, M - 1
        else:  # of each row's finite values (a row without any holds inf, which changes nothing)
            lo = _across(np.minimum, np.where(ok, v, np.inf))
            hi = _across(np.maximum, np.where(ok, v, -np.inf))
            rows = np.flatnonzero(np.isfinite(lo))
            if not rows.shape[0]:
                continue
            first, last = int(rows[0]), int(rows[-1])
        e._grow(float(t[first]), float(t[last]))
        found = bins.get(e.width)
        if found is None:
            b = np.minimum((after0 // e.width).astype(np.int64), Envelope.BINS - 1)
            starts = _changes(b)
            found = bins[e.width] = (b[starts], starts)
        at, starts = found
        e.lo[at] = np.minimum(e.lo[at], np.minimum.reduceat(lo, starts))
        e.hi[at] = np.maximum(e.hi[at], np.maximum.reduceat(hi, starts))


def _across(op: np.ufunc, v: np.ndarray) -> np.ndarray:
    """``op`` reduced across the columns of ``v`` (M, k), column by column (a reduction along
    the short axis of each row costs ten times as much)."""
    out = v[:, 0].copy()
    for j in range(1, v.shape[1]):
        op(out, v[:, j], out=out)
    return out


@dataclasses.dataclass(frozen=True)
class YRange:
    """The y range a pane opens on; ``settled``: the start-up transient is left out (it
    would flatten the result under it)."""

    lo: float
    hi: float
    settled: bool = False


START_UP = 0.2
"""The first fraction of a pane's time span that counts as start-up."""


TRANSIENT = 5.0
"""The start-up is left out of the y range when the whole span exceeds the span after it by
this factor."""


LEGEND_ENTRY = 0.09
"""The height of a legend entry as a fraction of a pane's (about 20 px of about 220)."""


def legend_headroom(entries: int) -> float:
    """Space above the data of a pane whose legend has ``entries`` entries, as a fraction of
    the data's span: the legend (top corner) sits over it, off the data (0.3 for two
    entries, 1.4 for six)."""
    share = min(0.7, 0.05 + LEGEND_ENTRY * max(entries, 1))
    return share / (1.0 - share)


def y_range(envelopes: list[Envelope], *, legend: int = 0) -> YRange | None:
    """The y range of a pane drawing these series: the data's extent padded by 5 %; values
    that never vary (all zero) get a span of 2 (or 20 % of their magnitude) instead of a lone
    tick; a start-up transient that makes the span :data:`TRANSIENT` times that of the rest is
    left out; with a legend of ``legend`` entries, :func:`legend_headroom` above."""
    envs = [e for e in envelopes if np.isfinite(e.t_first)]
    if not envs:
        return None
    t0 = min(e.t_first for e in envs)
    t1 = max(e.t_last for e in envs)
    full = _union([e.extent() for e in envs])
    if full is None:
        return None
    lo, hi = full
    settled = False
    if t1 > t0:
        after = _union([e.extent(t0 + START_UP * (t1 - t0)) for e in envs])
        if after is not None and after[1] > after[0] and (hi - lo) > TRANSIENT * (
                after[1] - after[0]):
            lo, hi, settled = after[0], after[1], True
    span = hi - lo
    mag = max(abs(lo), abs(hi))
    if span <= 1e-9 * max(mag, 1.0):
        half = 0.1 * mag if mag > 0.0 else 1.0
        return YRange(lo - half, hi + half, settled)
    pad = 0.05 * span
    lo, hi = labelled(lo - pad, hi + pad)
    return YRange(lo, hi + (legend_headroom(legend) * span if legend else 0.0), settled)


LABELLED_INTERVALS = 7
"""The most tick intervals a pane of the default layout labels (its axis labels only powers of
ten, each at least about 28 px apart)."""


def labelled(lo: float, hi: float) -> tuple[float, float]:
    """``[lo, hi]`` grown, on the side that costs less, until it holds two labelled ticks: the
    viewer labels multiples of one power of ten ``S``, the finest with at most
    :data:`LABELLED_INTERVALS` intervals in the range; a range holding one multiple of ``S``
    (often just "0") shows a lone tick.

    >>> labelled(-0.06, 0.06)          # ticks at -0.1 and 0 (or 0 and 0.1) instead of 0 alone
    (-0.1, 0.06)
    >>> labelled(-1.5, 1.5)            # -1, 0, 1: unchanged
    (-1.5, 1.5)
    """
    for _ in range(4):  # a grown range may call for a coarser step: again
        span = hi - lo
        if not (np.isfinite(span) and span > 0.0):
            return lo, hi
        step = 10.0 ** np.ceil(np.log10(span / LABELLED_INTERVALS))
        first, last = np.ceil(lo / step - 1e-6), np.floor(hi / step + 1e-6)
        if last - first >= 1:
            break
        if last == first:  # one multiple inside: add the nearer of its neighbours
            down, up = (first - 1) * step, (first + 1) * step
            lo, hi = (float(down), hi) if lo - down <= up - hi else (lo, float(up))
        else:
            lo, hi = float(np.floor(lo / step) * step), float(np.ceil(hi / step) * step)
    return lo, hi


def _union(parts: list[tuple[float, float] | None]) -> tuple[float, float] | None:
    found = [p for p in parts if p is not None]
    if not found:
        return None
    return min(p[0] for p in found), max(p[1] for p in found)


TIME_STEPS = (1.0, 10.0, 60.0, 600.0, 3600.0, 36000.0, 86400.0)
"""The steps [s] of the viewer's duration ticks (``+10s``, ``+1m``, ``+10m``, ``+1h``)."""


TIME_INTERVALS = 5
"""The most tick intervals a pane of the default layout labels on its time axis (four panes
side by side, ``+1m``-wide labels)."""


def time_range(t_first: float, t_last: float) -> tuple[float, float]:
    """The time span [s] a pane shows: the run, up to the next labelled tick if only one
    would be labelled (a 480 s run up to +10m: ``+0s`` and ``+10m``, never ``+0s`` alone), with
    margins (2 % before, 7 % after) so the first and the last tick labels are not clipped by
    the pane's edges.

    >>> [round(v) for v in time_range(0.0, 480.0)], [round(v) for v in time_range(0.0, 240.0)]
    ([-12, 642], [-5, 257])
    """
    span = max(t_last - t_first, 1e-3)
    step = next((s for s in TIME_STEPS if span / s <= TIME_INTERVALS), TIME_STEPS[-1])
    if np.floor(t_last / step + 1e-6) - np.ceil(t_first / step - 1e-6) < 1:
        t_last = float(np.ceil(t_last / step - 1e-6) * step)
        span = t_last - t_first
    return t_first - 0.02 * span, t_last + 0.07 * span
