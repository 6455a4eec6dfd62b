"""Envelopes: a time series in bounded memory for a figure, the same whatever blocks it came in."""

from __future__ import annotations

import numpy as np

from navreplay.report.envelope import Envelope


def test_envelope_keeps_every_extreme_in_bounded_memory() -> None:
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 86_400.0, 0.1)  # a day at 10 Hz
    v = np.cumsum(rng.normal(size=t.size))
    v[123_456] = np.nan
    whole = Envelope(bins=500)
    whole.add(t, v)
    split = Envelope(bins=500)
    cuts = np.sort(rng.choice(t.size, size=300, replace=False))
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, t.size], strict=True):
        split.add(t[a:b], v[a:b])
    tw, vw = whole.points()
    ts, vs = split.points()
    np.testing.assert_array_equal(tw, ts)
    np.testing.assert_array_equal(vw, vs)
    assert 1000 <= len(tw) <= 2000 and whole.count == t.size - 1
    assert np.all(np.diff(tw) > 0)
    # per bin of the final width: its minimum and maximum, at the time they occurred
    ok = np.isfinite(v)
    idx = np.floor(t[ok] / whole.width).astype(int)
    lo = np.full(idx.max() + 1, np.inf)
    hi = np.full(idx.max() + 1, -np.inf)
    np.minimum.at(lo, idx, v[ok])
    np.maximum.at(hi, idx, v[ok])
    assert set(vw) == set(lo) | set(hi)
    at = dict(zip(t[ok], v[ok], strict=True))
    assert all(at[ti] == vi for ti, vi in zip(tw, vw, strict=True))


def test_envelope_of_a_short_series_is_the_series() -> None:
    t = np.arange(0.0, 100.0, 0.1)
    v = np.sin(t)
    e = Envelope()
    e.add(t[:400], v[:400])
    e.add(t[400:], v[400:])
    got_t, got_v = e.points()
    np.testing.assert_array_equal(got_t, t)
    np.testing.assert_array_equal(got_v, v)


def _counted(source, seen):
    """The source, each window it hands out passed to ``seen`` first."""
    windows = source._windows

    def counting():
        for w in windows():
            seen(w)
            yield w

    source._windows = counting
    return source
