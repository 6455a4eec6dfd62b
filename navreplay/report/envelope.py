"""A time series kept for a figure in bounded memory: min/max per time bin.

A day of 10 Hz estimates is 864 k rows per plotted quantity; a figure panel is a few hundred
pixels wide. :class:`Envelope` takes a series block by block (times increasing) and keeps, per
time bin, the smallest and the largest value and when they occurred. Drawn as a line through
those points in time order, the series looks as it does at full resolution: every excursion
reaches its extreme, every bin is covered.

Bins are ``width`` seconds long and aligned to multiples of it. The width starts at
:data:`FIRST_WIDTH` (finer than any output rate, so a short run keeps every sample) and
doubles, merging bins pairwise, whenever the series would span more than ``2 * bins`` of them:
memory stays between ``bins`` and ``2 * bins`` bins whatever the length of the log. The result
depends only on the samples, not on how they were split into blocks.
"""

from __future__ import annotations

import math

import numpy as np

FIRST_WIDTH = 2.0**-10
"""Initial bin width [s] (about 1 ms)."""

BINS = 1000
"""Default number of bins a series is kept in (at least; at most twice as many)."""


class Envelope:
    """Min/max of a time series per time bin, in memory independent of its length.

    Parameters
    ----------
    bins : int
        The series is kept in ``bins`` to ``2 * bins`` bins.
    """

    def __init__(self, bins: int = BINS) -> None:
        if bins < 1:
            raise ValueError(f"bins must be at least 1, got {bins}")
        self.cap = 2 * int(bins)
        self.width = FIRST_WIDTH
        self.base: int | None = None  # index of the first bin (multiples of width)
        self.lo = np.full(self.cap, np.nan)
        self.hi = np.full(self.cap, np.nan)
        self.t_lo = np.full(self.cap, np.nan)
        self.t_hi = np.full(self.cap, np.nan)
        self.count = 0

    def add(self, t: np.ndarray, v: np.ndarray) -> None:
        """More samples: times [s] increasing (and later than before), values; non-finite
        values are skipped."""
        t = np.asarray(t, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        ok = np.isfinite(v) & np.isfinite(t)
        if not ok.all():
            t, v = t[ok], v[ok]
        if not t.size:
            return
        self.count += t.size
        if self.base is None:
            self.base = math.floor(t[0] / self.width)
        while math.floor(t[-1] / self.width) - self.base >= self.cap:
            self._coarsen()
        idx = np.floor(t / self.width).astype(np.int64) - self.base
        starts = np.flatnonzero(np.r_[True, idx[1:] != idx[:-1]])
        bins = idx[starts]
        counts = np.diff(np.r_[starts, t.size])
        seg = np.repeat(np.arange(starts.size), counts)
        # extremes of each segment and the first sample reaching them
        for ext, vals, times in ((np.minimum, self.lo, self.t_lo),
                                 (np.maximum, self.hi, self.t_hi)):
            best = ext.reduceat(v, starts)
            first = np.flatnonzero(v == best[seg])
            first = first[np.r_[True, seg[first][1:] != seg[first][:-1]]]
            old = vals[bins]
            better = ~(ext(old, best) == old)  # strictly beyond, or an empty (NaN) bin
            vals[bins[better]] = best[better]
            times[bins[better]] = t[first][better]

    def _coarsen(self) -> None:
        """Double the bin width: merge bins pairwise."""
        assert self.base is not None
        shift = self.base % 2  # the first bin is the odd half of a merged bin
        n = self.cap
        lo: np.ndarray = np.full(n + 2, np.nan)
        hi: np.ndarray = np.full(n + 2, np.nan)
        t_lo: np.ndarray = np.full(n + 2, np.nan)
        t_hi: np.ndarray = np.full(n + 2, np.nan)
        lo[shift:shift + n], hi[shift:shift + n] = self.lo, self.hi
        t_lo[shift:shift + n], t_hi[shift:shift + n] = self.t_lo, self.t_hi
        lo, hi = lo.reshape(-1, 2), hi.reshape(-1, 2)
        t_lo, t_hi = t_lo.reshape(-1, 2), t_hi.reshape(-1, 2)
        # the earlier half wins ties (its extreme came first)
        pick_lo = np.where(np.isnan(lo[:, 0]) | (lo[:, 1] < lo[:, 0]), 1, 0)
        pick_hi = np.where(np.isnan(hi[:, 0]) | (hi[:, 1] > hi[:, 0]), 1, 0)
        rows = np.arange(lo.shape[0])
        m = lo.shape[0]
        self.lo, self.t_lo = np.full(n, np.nan), np.full(n, np.nan)
        self.hi, self.t_hi = np.full(n, np.nan), np.full(n, np.nan)
        self.lo[:m] = lo[rows, pick_lo]
        self.t_lo[:m] = t_lo[rows, pick_lo]
        self.hi[:m] = hi[rows, pick_hi]
        self.t_hi[:m] = t_hi[rows, pick_hi]
        self.base = (self.base - shift) // 2
        self.width *= 2.0

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """The kept samples in time order: per bin its minimum and maximum (one point when
        they are the same sample). Times [s], values."""
        ok = ~np.isnan(self.lo)
        t = np.stack([self.t_lo[ok], self.t_hi[ok]], axis=1)
        v = np.stack([self.lo[ok], self.hi[ok]], axis=1)
        swap = t[:, 1] < t[:, 0]
        t[swap] = t[swap][:, ::-1]
        v[swap] = v[swap][:, ::-1]
        same = t[:, 0] == t[:, 1]
        keep = np.ones(t.shape, dtype=bool)
        keep[same, 1] = False
        return t[keep], v[keep]
