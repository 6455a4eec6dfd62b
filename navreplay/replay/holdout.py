"""Held-out aiding: GNSS fixes removed in time windows, and the filter's position scored
against them.

Without truth, a filter can still be judged on the aiding it did not see: drop the GNSS fixes
(and velocities) in a few windows, replay, and compare the position the filter predicts
through each gap with the fixes that were dropped. What the filter coasts on there (its IMU
noise and bias model) is what a real outage tests. :func:`hold_out` makes the recording with
the gaps and keeps the dropped fixes in its metadata (``extra["held_out"]``, so the copy can be
written and read like any recording); :func:`held_out_errors` scores a run over it.

Examples
--------
>>> outage_windows(0.0, 600.0, length=30.0, period=120.0)
[(120.0, 150.0), (240.0, 270.0), (360.0, 390.0), (480.0, 510.0)]
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from navreplay.core.streams import Recording, Stream, StreamKind, seconds
from navreplay.filters.result import RunResult

HELD_OUT = "held_out"
"""Key of ``metadata.extra`` holding the dropped fixes: ``t_ns`` and ``pos`` (lat, lon [rad],
h [m])."""
DROPPED_KINDS = (StreamKind.GPS, StreamKind.GPS_VEL)


def outage_windows(t0: float, t1: float, *, length: float, period: float,
                   start: float | None = None) -> list[tuple[float, float]]:
    """Windows ``[a, a + length)`` every ``period`` seconds from ``start`` (default: one
    period after ``t0``) that end before ``t1`` [s]."""
    if not 0.0 < length < period:
        raise ValueError(f"outage length must be > 0 and shorter than its period, got "
                         f"{length:g} s every {period:g} s")
    a = t0 + period if start is None else start
    out = []
    while a + length <= t1:
        out.append((a, a + length))
        a += period
    return out


def hold_out(recording: Recording, windows: Sequence[tuple[float, float]]) -> Recording:
    """A copy of ``recording`` without its GNSS fixes and velocities inside ``windows``
    [s from ``t0_ns``], the dropped fixes in ``metadata.extra["held_out"]``.

    Raises
    ------
    ValueError
        The recording has no GNSS fixes, or none falls inside the windows.
    """
    if StreamKind.GPS not in recording:
        raise ValueError("the recording has no GNSS fixes (stream gps) to hold out")
    streams = dict(recording.streams)
    held = None
    for kind in DROPPED_KINDS:
        if kind not in streams:
            continue
        s = streams[kind]
        t = seconds(s.t_ns, recording.t0_ns)
        inside = np.zeros(t.shape, dtype=bool)
        for a, b in windows:
            inside |= (t >= a) & (t < b)
        streams[kind] = Stream(kind, s.t_ns[~inside], {k: v[~inside] for k, v in s.columns.items()},
                               s.frame_id)
        if kind is StreamKind.GPS:
            held = {"t_ns": s.t_ns[inside].tolist(), "pos": s["pos"][inside].tolist(),
                    "windows": [list(w) for w in windows]}
    if held is None or not held["t_ns"]:
        raise ValueError("no GNSS fix falls inside the held-out windows")
    meta = dataclasses.replace(recording.metadata,
                               extra={**recording.metadata.extra, HELD_OUT: held})
    return Recording(streams=streams, metadata=meta, t0_ns=recording.t0_ns)


def held_out_errors(result: RunResult, recording: Recording) -> np.ndarray:
    """Horizontal distance [m] between the filter's position and each held-out fix, the
    estimate interpolated linearly to the fix's time (an outage ends with a fix, so the last
    output before it is always close).

    Returns
    -------
    ndarray, shape (K,)
        One per held-out fix inside the run's output times (empty when the recording holds
        none).
    """
    held = recording.metadata.extra.get(HELD_OUT)
    if not held or result.nav_pos is None:
        return np.zeros(0)
    t = seconds(np.asarray(held["t_ns"], dtype=np.int64), recording.t0_ns)
    pos = np.asarray(held["pos"], dtype=float).reshape(-1, 3)
    ok = (t >= result.t[0]) & (t <= result.t[-1])
    return _horizontal(result, t[ok], pos[ok])


def held_out_truth_errors(result: RunResult, recording: Recording) -> np.ndarray:
    """The same at the held-out fixes' times, against the truth stream instead of the fixes
    (what the outages really cost; a simulated recording only)."""
    held = recording.metadata.extra.get(HELD_OUT)
    if not held or result.nav_pos is None or StreamKind.TRUTH not in recording:
        return np.zeros(0)
    truth = recording[StreamKind.TRUTH]
    t = seconds(np.asarray(held["t_ns"], dtype=np.int64), recording.t0_ns)
    tt = seconds(truth.t_ns, recording.t0_ns)
    ok = (t >= max(result.t[0], tt[0])) & (t <= min(result.t[-1], tt[-1]))
    pos = np.column_stack([np.interp(t[ok], tt, truth["pos"][:, i]) for i in range(3)])
    return _horizontal(result, t[ok], pos)


def _horizontal(result: RunResult, t: np.ndarray, pos: np.ndarray) -> np.ndarray:
    from navreplay.metrics import position_error_ned

    assert result.nav_pos is not None  # held-out fixes score a position
    est = np.column_stack([np.interp(t, result.t, result.nav_pos[:, i]) for i in range(3)])
    d = position_error_ned(est, pos)
    return np.hypot(d[:, 0], d[:, 1])
