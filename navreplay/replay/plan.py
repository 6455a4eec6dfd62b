"""The event plan of a replay: a recording's aiding streams merged by time, with output ticks.

Every aiding stream (every stream except ``imu`` and ``truth``) that the filter consumes
(``requires`` + ``optional``; a filter that declares no stream at all consumes every aiding
stream) contributes one event per sample; IMU samples reach the filter in blocks whenever the
recording has an IMU, whether declared or not, and the truth never does. Events are ordered by
timestamp; samples with equal timestamps are ordered by stream priority,
:data:`STREAM_PRIORITY` (master INS, GNSS position, GNSS velocity, magnetometer, speed log,
depth, then any other kind by name), then by row. When the recording has an IMU stream, an
output tick at ``output_rate`` [Hz] is added at every time of the grid ``t = k / output_rate``
since the recording start (from the first IMU sample, or from the filter's start) that is not
the time of an aiding sample: the estimates are on the whole grid, and at every aiding sample
besides (one estimate per time, after every sample of that time is applied).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence

import numpy as np

from navreplay.core.streams import Recording, Stream, StreamKind
from navreplay.filters.base import TICK

STREAM_PRIORITY: tuple[StreamKind, ...] = (
    StreamKind.MASTER_INS,
    StreamKind.GPS,
    StreamKind.GPS_VEL,
    StreamKind.MAG,
    StreamKind.SPEED_LOG,
    StreamKind.DEPTH,
)
"""Order of aiding samples that share a timestamp (earlier in the tuple = handed over first)."""

NOT_AIDING: frozenset[StreamKind] = frozenset({StreamKind.IMU, StreamKind.TRUTH})
"""Streams that never produce events: the IMU is propagated in blocks, the truth is for scoring."""


@dataclasses.dataclass(frozen=True)
class EventPlan:
    """The merged event sequence of a recording, in columns.

    Attributes
    ----------
    kinds : tuple[StreamKind, ...]
        Aiding streams in priority order; ``code`` indexes this tuple.
    t_ns : ndarray, shape (E,), int64
        Event times [ns].
    code : ndarray, shape (E,), int64
        Index into ``kinds``, or :data:`TICK` for an output tick.
    row : ndarray, shape (E,), int64
        Row of the sample in its stream (0 for ticks).
    imu_end : ndarray, shape (E,), int64
        Number of IMU samples with ``t <= t_ns`` (end of the block handed over before the event).
    """

    kinds: tuple[StreamKind, ...]
    t_ns: np.ndarray
    code: np.ndarray
    row: np.ndarray
    imu_end: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])


def aiding_kinds(
    kinds: Iterable[StreamKind], consumes: Iterable[StreamKind] | None = None
) -> tuple[StreamKind, ...]:
    """The aiding streams among a recording's ``kinds`` (those in ``consumes``, if given) in
    priority order."""
    wanted = None if consumes is None else {StreamKind(k) for k in consumes}
    present = [k for k in kinds
               if k not in NOT_AIDING and (wanted is None or k in wanted)]
    known = [k for k in STREAM_PRIORITY if k in present]
    return tuple(known + sorted(k for k in present if k not in STREAM_PRIORITY))


def plan_events(
    recording: Recording,
    output_rate: float | None = 10.0,
    consumes: Iterable[StreamKind] | None = None,
) -> EventPlan:
    """Merge the aiding streams by time and add output ticks (see the module docstring).

    Parameters
    ----------
    recording : Recording
    output_rate : float or None
        Output tick rate [Hz] for intervals without aiding samples; None or 0 for none.
    consumes : iterable of StreamKind, optional
        Aiding streams to merge (default: all of the recording's).

    Returns
    -------
    EventPlan
    """
    imu = recording.streams.get(StreamKind.IMU)
    imu_t = imu.t_ns if imu is not None else np.zeros(0, np.int64)
    return window_plan(merge_aiding(recording, consumes), imu_t, recording.t0_ns, output_rate,
                       first_imu_ns=int(imu_t[0]) if len(imu_t) else None)


def merge_aiding(recording: Recording, consumes: Iterable[StreamKind] | None = None
                 ) -> EventPlan:
    """The aiding samples of a recording merged by (time, priority, row), without output
    ticks (``imu_end`` empty)."""
    kinds = aiding_kinds(recording.kinds(), consumes)
    return merge_streams(kinds, [recording[k] for k in kinds])


def merge_streams(kinds: tuple[StreamKind, ...], streams: Sequence[Stream]) -> EventPlan:
    """Aiding streams (in priority order ``kinds``) merged by (time, priority, row)."""
    t_all = np.concatenate([s.t_ns for s in streams] + [np.zeros(0, np.int64)])
    code = np.concatenate(
        [np.full(len(s), i, np.int64) for i, s in enumerate(streams)] + [np.zeros(0, np.int64)]
    )
    row = np.concatenate([np.arange(len(s), dtype=np.int64) for s in streams]
                         + [np.zeros(0, np.int64)])
    # concatenated in priority order, rows increasing: a stable sort by time gives
    # (time, priority, row) order
    order = np.argsort(t_all, kind="stable")
    return EventPlan(kinds, t_all[order], code[order], row[order], np.zeros(0, np.int64))


def window_plan(
    merged: EventPlan,
    imu_t: np.ndarray,
    t0_ns: int,
    output_rate: float | None,
    *,
    lo: int | None = None,
    hi: int | None = None,
    first_imu_ns: int | None = None,
) -> EventPlan:
    """The events with ``lo < t <= hi`` [ns] (open ends when None): the merged aiding samples
    and the output ticks on the grid between ``first_imu_ns`` and the last of ``imu_t`` (the
    IMU samples at hand, ordered), with ``imu_end`` counted in ``imu_t``."""
    t_all, code, row = merged.t_ns, merged.code, merged.row
    a = 0 if lo is None else int(np.searchsorted(t_all, lo, side="right"))
    b = len(t_all) if hi is None else int(np.searchsorted(t_all, hi, side="right"))
    t_ev, code, row = t_all[a:b], code[a:b], row[a:b]
    if output_rate and len(imu_t) and first_imu_ns is not None:
        last = int(imu_t[-1]) if hi is None else min(int(hi), int(imu_t[-1]))
        period_ns = round(1e9 / float(output_rate))
        first = first_imu_ns if lo is None else max(first_imu_ns, int(lo) - 2 * period_ns)
        ticks = _ticks(first, last, t0_ns, float(output_rate))
        if lo is not None:
            ticks = ticks[ticks > lo]
        # every grid time but those of an aiding sample (its estimate is the one there)
        if len(t_all):
            at = np.minimum(np.searchsorted(t_all, ticks), len(t_all) - 1)
            ticks = ticks[t_all[at] != ticks]
        t_ev = np.concatenate([t_ev, ticks])
        code = np.concatenate([code, np.full(len(ticks), TICK, np.int64)])
        row = np.concatenate([row, np.zeros(len(ticks), np.int64)])
        order = np.argsort(t_ev, kind="stable")
        t_ev, code, row = t_ev[order], code[order], row[order]
    imu_end = np.searchsorted(imu_t, t_ev, side="right").astype(np.int64)
    return EventPlan(merged.kinds, t_ev, code, row, imu_end)


def _ticks(first_ns: int, last_ns: int, t0_ns: int, rate: float) -> np.ndarray:
    """Tick times on the grid ``t0 + k / rate`` within [first, last] [ns]."""
    if rate <= 0 or not np.isfinite(rate):
        raise ValueError(f"output_rate must be positive, got {rate}")
    period_s = 1.0 / rate
    k0 = int(np.ceil((int(first_ns) - int(t0_ns)) * 1e-9 / period_s - 1e-9))
    k1 = int(np.floor((int(last_ns) - int(t0_ns)) * 1e-9 / period_s + 1e-9))
    k = np.arange(k0, k1 + 1, dtype=np.int64)
    return np.int64(t0_ns) + np.rint(k * (period_s * 1e9)).astype(np.int64)
