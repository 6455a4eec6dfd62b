"""The replay loop: merge a recording's streams by time and drive one filter over them.

Event order
-----------
Every aiding stream (every stream except ``imu`` and ``truth``) that the filter consumes
(``requires`` + ``optional``; a filter that declares no stream at all consumes every aiding
stream) contributes one event per sample; IMU samples reach the filter in blocks whenever the
recording has an IMU, whether declared or not, and the truth never does. Events are ordered by timestamp; samples with equal timestamps are ordered by stream
priority, :data:`STREAM_PRIORITY` (master INS, GNSS position, GNSS velocity, magnetometer, speed
log, depth, then any other kind by name), then by row. When the recording has an IMU stream, an
output tick at ``output_rate`` [Hz] (on the grid ``t = k / output_rate`` since the recording
start) is added in every tick interval ``(t_k-1, t_k]`` that holds no aiding sample, so that a
free-inertial run still has outputs; ticks at a time equal to an event's come after it. The
estimate is recorded once per distinct event time, after every sample of that time is applied.

For each event at time ``t_e`` the engine

1. hands the filter the IMU samples with ``t_prev < t <= t_e`` as one block
   (:meth:`~navreplay.filters.base.Filter.propagate`; skipped when the block is empty),
2. hands it the aiding sample (:meth:`~navreplay.filters.base.Filter.update`; not for ticks) and
   collects the innovations it returns,
3. stores :meth:`~navreplay.filters.base.Filter.estimate` in preallocated columns (skipped while
   the filter returns None).

IMU samples after the last event are handed over at the end, followed by a last estimate. Every
IMU sample is thus delivered exactly once and in order. A filter may take runs of output ticks
(``propagate_outputs``) or runs of events (``replay_events``) in one call that does the same
(:func:`_batch_hook`, :func:`_events_hook`). The work per event is slicing views and
one call per step; everything else (planning, innovation statistics, checks) is vectorised.

Examples
--------
>>> import numpy as np
>>> from navreplay.streams import Metadata, Recording, Stream, StreamKind
>>> from navreplay.filters.base import Estimate, Filter, Quantity, State
>>> class Count(Filter):
...     name = "count"
...     requires = (StreamKind.IMU,)
...     states = (State("n", "-", Quantity.OTHER),)
...     def __init__(self, params, context):
...         super().__init__(params, context)
...         self.n, self.t = 0, 0.0
...     def propagate(self, t, imu):
...         self.n += len(t)
...         self.t = float(t[-1])
...     def update(self, kind, t, sample):
...         return None
...     def estimate(self):
...         return Estimate(self.t, np.array([float(self.n)]), np.zeros((1, 1)))
>>> t_ns = np.arange(1, 201) * 10_000_000  # 100 Hz for 2 s
>>> imu = Stream(StreamKind.IMU, t_ns, {"omega_ib_b": np.zeros((200, 3)),
...                                     "f_b": np.zeros((200, 3))})
>>> rec = Recording({StreamKind.IMU: imu}, Metadata())
>>> result = replay(rec, Count, output_rate=1.0)
>>> result.t.tolist(), result.x[:, 0].tolist()
([1.0, 2.0], [100.0, 200.0])
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from navreplay.filters.base import (
    NAV_PARTS,
    Estimate,
    Filter,
    FilterContext,
    FilterParams,
    NavSolution,
    State,
    check_measurements,
    check_states,
    navigation_parts,
)
from navreplay.filters.kalman import FilterDivergedError
from navreplay.filters.settings import build_params  # noqa: F401  (the one place it is built)
from navreplay.io.checks import first_problem
from navreplay.io.errors import RecordingError
from navreplay.replay.gaps import MIN_IMU_SAMPLES, ImuFeeder, find_gaps
from navreplay.replay.result import InnovationSeries, RunResult
from navreplay.sensors.specs import SensorSpecs
from navreplay.streams import Recording, Stream, StreamKind

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

TICK = -1
"""Event code of an output tick (aiding events carry the index of their stream)."""

_CHECK_EVERY = 1024
"""Outputs between divergence (non-finite) checks and progress reports."""


class ReplayError(RuntimeError):
    """A replay that cannot start or cannot go on (base of the replay errors)."""


class FilterOutputError(ReplayError):
    """A filter handed back an estimate or innovation that breaks the contract of
    :mod:`navreplay.filters.base` (wrong length, covariance not symmetric PSD, non-finite)."""


class FilterFailedError(ReplayError):
    """A filter raised inside ``propagate``, ``update`` or ``estimate``; the
    message names the filter, the recording and the time, the original is the ``__cause__``."""


class FilterInitError(ReplayError, ValueError):
    """A filter raised in ``__init__`` (a parameter it rejects, a missing initial solution,
    ...); the message names the filter and the recording, the original is the ``__cause__``.
    A ValueError too: the filter could not start from what it was given."""


class _BadOutput(Exception):
    """An invalid estimate, before the engine names the filter, recording and time."""


class MissingStreamError(ReplayError):
    """The recording lacks a stream (or a stream lacks a column) that the filter requires."""


class InvalidRecordingError(ReplayError, RecordingError):
    """An in-memory recording with non-finite samples or timestamps that do not increase."""


# --------------------------------------------------------------------------------------------
# checks before running


def recording_name(recording: Recording) -> str:
    """A display name for an in-memory recording: ``scenario#seed`` or ``recording``."""
    md = recording.metadata
    if md.scenario:
        return md.scenario if md.seed is None else f"{md.scenario}#seed={md.seed}"
    return "recording"


def check_streams(recording: Recording, filter_cls: type[Filter], source: str = "") -> None:
    """Raise :class:`MissingStreamError` unless the recording has what the filter requires.

    The message names the missing streams (or columns) and what the recording holds.
    """
    source = source or recording_name(recording)
    have = [str(k) for k in recording.kinds()]
    missing = [str(k) for k in filter_cls.requires if k not in recording]
    if missing:
        raise MissingStreamError(
            f"filter {filter_cls.name!r} needs stream(s) {', '.join(missing)} that "
            f"{source} does not have (it has: {', '.join(have) or 'no streams'})"
        )
    for kind in filter_cls.requires:
        stream = recording[kind]
        needed = filter_cls.required_columns.get(kind)
        lacking = (
            stream.missing_fields()
            if needed is None
            else [c for c in needed if c not in stream.columns]
        )
        if lacking:
            raise MissingStreamError(
                f"{source}: stream {kind} lacks column(s) {', '.join(lacking)} that filter "
                f"{filter_cls.name!r} needs (it has: {', '.join(recording[kind].columns)})"
            )


def consumed_streams(filter_cls: type[Filter]) -> tuple[StreamKind, ...] | None:
    """Aiding streams the filter is handed: ``requires`` + ``optional``, or None (all) when it
    declares no stream at all."""
    declared = tuple(filter_cls.requires) + tuple(filter_cls.optional)
    return declared or None


def validate_recording(recording: Recording, source: str = "") -> None:
    """Raise :class:`InvalidRecordingError` on non-finite samples, negative sigmas or time that
    does not increase (the checks of :func:`navreplay.io.checks.first_problem`, which the
    reader and the writer apply to files).

    Files are validated by the reader; call this for recordings built in memory. The message
    names the recording, the stream, the column and the time of the first bad sample.
    """
    source = source or recording_name(recording)
    for kind, stream in recording.streams.items():
        problem = first_problem(stream, recording.t0_ns)
        if problem is not None:
            raise InvalidRecordingError(f"{source}: stream {kind}: {problem}")



# --------------------------------------------------------------------------------------------
# the event plan


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
    recording: Recording, consumes: Iterable[StreamKind] | None = None
) -> tuple[StreamKind, ...]:
    """The recording's aiding streams (those in ``consumes``, if given) in priority order."""
    wanted = None if consumes is None else {StreamKind(k) for k in consumes}
    present = [k for k in recording.kinds()
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
    kinds = aiding_kinds(recording, consumes)
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
        grid = ticks if lo is None else _ticks(first_imu_ns, first_imu_ns + 3 * period_ns,
                                               t0_ns, float(output_rate))
        period = grid[1] - grid[0] if len(grid) > 1 else np.int64(period_ns)
        # ticks only in intervals without an aiding sample (of the whole recording)
        before = np.searchsorted(t_all, ticks - period, side="right")
        upto = np.searchsorted(t_all, ticks, side="right")
        ticks = ticks[upto == before]
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


KNOWN_ALL = np.iinfo(np.int64).max
"""The time [ns] a complete aiding stream is known up to (:meth:`ReplaySession.feed`)."""


def _join(a: Stream, b: Stream) -> Stream:
    """Stream ``a`` followed by the later samples ``b`` (columns of ``a``)."""
    if not len(a):
        return b
    return dataclasses.replace(
        a, t_ns=np.concatenate([a.t_ns, b.t_ns]),
        columns={k: np.concatenate([a.columns[k], b.columns[k]]) for k in a.columns},
    )


# --------------------------------------------------------------------------------------------
# output columns


_NAV_COLUMN = {"pos": "position", "v_n": "velocity", "q_nb": "attitude"}
"""The name of each part of the navigation solution in messages."""


class _Columns:
    """Estimate columns allocated at a known upper bound of rows (the operating system backs
    only the rows written with memory, so they are neither grown nor copied)."""

    def __init__(self, first: Estimate | None, upper: int, n: int = 0,
                 navigation: tuple[str, ...] = NAV_PARTS) -> None:
        self.navigation = navigation
        self.upper = max(upper, 1)
        self.cap = self.upper
        self.m = 0
        n = first.x.shape[0] if first is not None else n
        self.t = np.empty(self.cap)
        self.x = np.empty((self.cap, n))
        self.P = np.empty((self.cap, n, n))
        self.has_nav = first is None or first.nav is not None
        if self.has_nav:
            self.pos = np.empty((self.cap, 3))
            self.v_n = np.empty((self.cap, 3))
            self.q_nb = np.empty((self.cap, 4))
        extras = first.extras.items() if first is not None else ()
        self.extras = {k: np.empty((self.cap, *np.shape(v))) for k, v in extras}

    def _grow(self) -> None:
        cap = min(self.upper, 2 * self.cap)
        if cap <= self.cap:  # more outputs than events: cannot happen, but never lose data
            cap = 2 * self.cap
        names = ["t", "x", "P"] + (["pos", "v_n", "q_nb"] if self.has_nav else [])
        for name in names:
            old = getattr(self, name)
            new = np.empty((cap, *old.shape[1:]))
            new[: self.m] = old[: self.m]
            setattr(self, name, new)
        for k, old in self.extras.items():
            new = np.empty((cap, *old.shape[1:]))
            new[: self.m] = old[: self.m]
            self.extras[k] = new
        self.cap = cap

    def add(self, est: Estimate) -> None:
        m = self.m
        n = self.x.shape[1]
        if np.shape(est.x) != (n,) or np.shape(est.P) != (n, n):
            raise _BadOutput(
                f"x has shape {np.shape(est.x)} and P {np.shape(est.P)}; the filter declares "
                f"{n} states"
            )
        if m == self.cap:
            self._grow()
        self.t[m] = est.t
        self.x[m] = est.x
        self.P[m] = est.P
        if self.has_nav:
            nav = est.nav
            self.pos[m] = nav.pos
            self.v_n[m] = nav.v_n
            self.q_nb[m] = nav.q_nb
        for k, col in self.extras.items():
            col[m] = est.extras[k]
        self.m = m + 1

    def add_rows(self, t: np.ndarray, x: np.ndarray, P: np.ndarray, nav: np.ndarray) -> None:
        """Append a batch of estimates (columns of m rows; nav as navigation vectors)."""
        k = t.shape[0]
        n = self.x.shape[1]
        if x.shape != (k, n) or P.shape != (k, n, n):
            raise _BadOutput(f"x has shape {x.shape[1:]} and P {P.shape[1:]}; the filter "
                             f"declares {n} states")
        while self.m + k > self.cap:
            self._grow()
        m = self.m
        self.t[m:m + k] = t
        self.x[m:m + k] = x
        self.P[m:m + k] = P
        if self.has_nav:
            self.pos[m:m + k] = nav[:, 0:3]
            self.v_n[m:m + k] = nav[:, 3:6]
            self.q_nb[m:m + k] = nav[:, 6:10]
        self.m = m + k

    def first_nonfinite(self, start: int) -> tuple[int, str] | None:
        """First row >= start with a non-finite entry, and the column's name."""
        stop = self.m
        if stop <= start:
            return None
        cols: list[tuple[str, np.ndarray]] = [("state", self.x), ("covariance", self.P)]
        if self.has_nav:
            cols += [(what, getattr(self, part)) for part, what in _NAV_COLUMN.items()
                     if part in self.navigation]
        cols += [(k, v) for k, v in self.extras.items()]
        found: tuple[int, str] | None = None
        for name, col in cols:
            block = col[start:stop].reshape(stop - start, -1)
            ok = np.isfinite(block).all(axis=1)
            if not ok.all():
                i = start + int(np.argmin(ok))
                if found is None or i < found[0]:
                    found = (i, name)
        return found

    def result(self, **kw: Any) -> RunResult:
        """The rows written (views: the rows never written were never backed by memory)."""
        return self.view(**kw)

    def view(self, **kw: Any) -> RunResult:
        """The rows so far, without copying (for live observers)."""
        m = self.m
        return RunResult(
            t=self.t[:m],
            x=self.x[:m],
            P=self.P[:m],
            nav_pos=self.pos[:m] if self.has_nav else None,
            nav_v_n=self.v_n[:m] if self.has_nav else None,
            nav_q_nb=self.q_nb[:m] if self.has_nav else None,
            navigation=self.navigation if self.has_nav else (),
            extras={k: v[:m] for k, v in self.extras.items()},
            **kw,
        )


def _undeclared(name: str, items: list[tuple[float, np.ndarray, np.ndarray]],
                rows_of: Mapping[str, int] | None) -> tuple[float, str] | None:
    """The first update of measurement ``name`` that its declaration (``rows_of``: rows by
    declared name; None when the filter declares nothing) does not allow, as (t, why)."""
    if rows_of is None:
        return None
    if name not in rows_of:
        return items[0][0], (f"innovation {name!r} is not a declared measurement (declared: "
                             f"{', '.join(rows_of) or 'none'}; set Filter.measurements)")
    m = rows_of[name]
    k = next((k for k, it in enumerate(items) if np.shape(it[1]) != (m,)), None)
    if k is None:
        return None
    return items[k][0], (f"innovation {name!r} has shape {np.shape(items[k][1])}; the filter "
                         f"declares {m} rows")


def _innovation_series(
    items: list[tuple[float, np.ndarray, np.ndarray]],
) -> tuple[InnovationSeries, tuple[int, str] | None]:
    """The series of one measurement and its first invalid update (index, what), if any:
    nu (m,) and S (m, m) finite, S symmetric positive semi-definite and not singular."""
    t = np.array([it[0] for it in items], dtype=np.float64)
    m = np.shape(items[0][1])
    bad_shape = next((k for k, it in enumerate(items)
                      if np.shape(it[1]) != m or np.shape(it[2]) != m + m), None)
    if len(m) != 1 or bad_shape is not None:
        k = bad_shape or 0
        empty = InnovationSeries(t=t, nu=np.zeros((len(t), 0)), S=np.zeros((len(t), 0, 0)),
                                 nis=np.zeros(len(t)))
        return empty, (k, f"nu has shape {np.shape(items[k][1])} and S "
                          f"{np.shape(items[k][2])}; expected (m,) and (m, m)")
    nu = np.stack([np.asarray(it[1], dtype=np.float64) for it in items])
    S = np.stack([np.asarray(it[2], dtype=np.float64) for it in items])
    nan = np.full(len(t), np.nan)
    bad_nu = ~np.isfinite(nu).all(axis=1)
    problem = covariance_problem(S)
    first: tuple[int, str] | None = None
    if bad_nu.any():
        first = (int(np.argmax(bad_nu)), "nu is not finite")
    if problem is not None and (first is None or problem[0] < first[0]):
        first = (problem[0], problem[1].replace("covariance P", "S"))
    if first is not None:
        return InnovationSeries(t=t, nu=nu, S=S, nis=nan), first
    try:
        nis = np.einsum("ki,ki->k", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    except np.linalg.LinAlgError:
        k = int(np.argmin(np.abs(np.linalg.det(S))))
        return InnovationSeries(t=t, nu=nu, S=S, nis=nan), (k, "S is singular")
    return InnovationSeries(t=t, nu=nu, S=S, nis=nis), None


# --------------------------------------------------------------------------------------------
# the loop

Observer = Callable[[RunResult], None]
"""Called with the rows so far (views, valid only during the call) during a replay."""

Progress = Callable[[int, int], None]
"""Called with (events done, events in total)."""


def replay(
    recording: Recording,
    filter_cls: type[Filter],
    params: FilterParams | Mapping[str, Any] | None = None,
    *,
    label: str | None = None,
    source: str | None = None,
    output_rate: float | None = 10.0,
    pacing: float | None = None,
    validate: bool = True,
    progress: Progress | None = None,
    observer: Observer | None = None,
    observe_interval: float = 0.25,
    max_imu_gap: float | None = None,
) -> RunResult:
    """Replay one filter over one recording.

    Parameters
    ----------
    recording : Recording
        The streams; a file read with :func:`navreplay.io.read_recording` is already validated
        (pass ``validate=False`` to skip the second check).
    filter_cls : type[Filter]
        The filter class (see :func:`navreplay.filters.registry.load_filter`).
    params : FilterParams or mapping, optional
        Parameters: an instance of ``filter_cls.Params``, or ``{name: value}`` (strings as from
        ``-p key=value`` are converted), or None for the defaults.
    label : str, optional
        Display label of the run (default: the filter's name).
    source : str, optional
        Name of the recording in messages and in the result (default: its file name if the
        caller knows it, else ``scenario#seed=N``).
    output_rate : float or None
        Output tick rate [Hz] where no aiding sample falls (see the module docstring); None or 0
        for outputs at aiding samples only.
    pacing : float, optional
        Replay at this multiple of real time (1.0 = real time), for live viewing; None (the
        default) runs as fast as possible.
    validate : bool
        Check the recording for non-finite samples and non-increasing timestamps first.
    progress : callable, optional
        ``progress(done, total)`` in events, called every few thousand events and at the end.
    observer : callable, optional
        Called with the rows so far about every ``observe_interval`` seconds of wall time and at
        the end (for live sinks; the arrays are views valid during the call only).
    observe_interval : float
        Wall time between observer calls [s].
    max_imu_gap : float, optional
        Longest IMU gap [s] the filter may bridge (:mod:`navreplay.replay.gaps`); default
        :data:`navreplay.replay.gaps.MAX_IMU_GAP`.

    Returns
    -------
    RunResult
        Estimates at every event (times from :attr:`Estimate.t`), innovations per measurement
        with their NIS.

    Raises
    ------
    MissingStreamError
        The recording lacks a required stream or column (raised before the filter is built).
    InvalidRecordingError
        ``validate`` and a non-finite sample or a timestamp that repeats or goes backwards.
    navreplay.params.ParamError
        Parameters that do not fit ``filter_cls.Params``.
    FilterInitError
        The filter raised while it was built; the message names the filter and the recording.
    FilterFailedError
        The filter raised inside ``propagate``, ``update`` or ``estimate``.
    FilterOutputError
        An estimate or innovation that breaks the filter contract.
    navreplay.filters.kalman.FilterDivergedError
        The filter raised it, a linear-algebra error, or produced a non-finite estimate; the
        message names the filter, the recording and the time.
    """
    session = ReplaySession(
        recording, filter_cls, params, label=label, source=source, output_rate=output_rate,
        pacing=pacing, validate=validate, progress=progress, observer=observer,
        observe_interval=observe_interval, max_imu_gap=max_imu_gap,
    )
    return session.feed(recording.streams.get(StreamKind.IMU), final=True)


class ReplaySession:
    """One filter replayed over a recording whose IMU arrives in time windows.

    :func:`replay` feeds the whole IMU stream at once; a streaming replay
    (:mod:`navreplay.replay.streaming`) feeds it window by window, and each :meth:`feed`
    returns the estimates and innovations of the events it could apply. The filter sees exactly
    the calls of a replay of the whole recording: an event is applied once every IMU sample up to
    its time is at hand, and the samples after a window's last event wait for the next window,
    so they reach the filter in the same blocks.

    ``recording`` holds the aiding streams whole (they are small) and the metadata; its IMU
    stream, if any, is only checked for its columns (the samples come through :meth:`feed`).
    The parameters are those of :func:`replay`.
    """

    def __init__(
        self,
        recording: Recording,
        filter_cls: type[Filter],
        params: FilterParams | Mapping[str, Any] | None = None,
        *,
        label: str | None = None,
        source: str | None = None,
        output_rate: float | None = 10.0,
        pacing: float | None = None,
        validate: bool = True,
        progress: Progress | None = None,
        observer: Observer | None = None,
        observe_interval: float = 0.25,
        max_imu_gap: float | None = None,
    ) -> None:
        label = label or filter_cls.name
        source = source or recording_name(recording)
        check_streams(recording, filter_cls, source)
        if validate:
            validate_recording(recording, source)
        try:
            sensors = SensorSpecs.from_metadata(recording.metadata.sensors, source)
        except ValueError as e:
            raise RecordingError(str(e)) from None
        self.settings = build_params(filter_cls, params, sensors, label=label)
        p = self.settings.params
        context = FilterContext(
            metadata=recording.metadata,
            t0_ns=recording.t0_ns,
            streams=frozenset(recording.kinds()),
        )
        try:
            filt = filter_cls(p, context)
        except Exception as e:
            raise FilterInitError(
                f"filter {label!r} cannot start on {source}: {_one_line(e)}"
            ) from e
        self.filter = filt
        self.states: tuple[State, ...] = check_states(filt.states, f"filter {label!r}: states")
        try:
            self.navigation = navigation_parts(filter_cls, self.states)
        except (TypeError, ValueError) as e:
            raise FilterInitError(str(e)) from e
        self.label, self.source = label, source
        self._names = tuple(st.name for st in self.states)
        scored_extras = check_states(filt.scored_extras, f"filter {label!r}: scored_extras")
        measurements = check_measurements(filt.measurements, f"filter {label!r}: measurements")
        self._rows_of = None if measurements is None else {m.name: m.dim for m in measurements}
        self._merged = merge_aiding(recording, consumed_streams(filter_cls))
        self._aiding: list[Stream] = [recording[k] for k in self._merged.kinds]
        # aiding samples that arrive in windows (feed(aiding=...)): each kind is known up to
        # a time; events wait until every kind is known up to theirs
        self._known: dict[StreamKind, int] = {}
        self._windowed = False
        self._output_rate = output_rate
        self._t0_ns = recording.t0_ns
        self._max_imu_gap = max_imu_gap
        self._imu_required = StreamKind.IMU in filter_cls.requires
        self._pacing, self._progress, self._observer = pacing, progress, observer
        self._observe_interval = observe_interval
        self._meta = dict(
            filter_name=filter_cls.name,
            label=label,
            recording=source,
            t0_ns=recording.t0_ns,
            states=self.states,
            scored_extras=scored_extras,
            measurements=measurements or (),
            settings=self.settings,
        )
        self._batch = None if pacing is not None else _batch_hook(filt)
        self._events_hook = None if pacing is not None else _events_hook(filt)
        # IMU state between windows: samples not yet handed over, the last one handed over,
        # the tick range and the nominal sample interval
        self._pending: tuple[np.ndarray, dict[str, np.ndarray]] | None = None
        self._last: tuple[np.ndarray, dict[str, np.ndarray]] | None = None
        self._first_imu_ns: int | None = None
        self._nominal: float | None = None
        self._done_to_ns: int | None = None  # events up to this time are applied
        self._events = 0
        self._wall0 = time.perf_counter()
        self._t_first: float | None = None
        self.finished = False

    # -- windows -----------------------------------------------------------------------------

    def _window_imu(self, imu: Stream | None
                    ) -> tuple[np.ndarray, dict[str, np.ndarray], int]:
        """IMU samples of a window: the last one handed over (if any), those still pending,
        then the new ones; and the index of the first not handed over."""
        parts_t: list[np.ndarray] = []
        parts_c: list[dict[str, np.ndarray]] = []
        for part in (self._last, self._pending):
            if part is not None:
                parts_t.append(part[0])
                parts_c.append(part[1])
        if imu is not None and len(imu):
            parts_t.append(imu.t_ns)
            parts_c.append(imu.columns)
        start = 0 if self._last is None else 1
        if not parts_t:
            return np.zeros(0, np.int64), {}, start
        if len(parts_t) == 1:
            return parts_t[0], parts_c[0], start
        t_ns = np.concatenate(parts_t)
        cols = {k: np.concatenate([c[k] for c in parts_c]) for k in parts_c[-1]}
        if len(t_ns) > 1 and np.any(t_ns[1:] <= t_ns[:-1]):
            k = int(np.argmax(t_ns[1:] <= t_ns[:-1])) + 1
            raise InvalidRecordingError(
                f"{self.source}: stream {StreamKind.IMU}: timestamp {int(t_ns[k])} ns does not "
                f"follow {int(t_ns[k - 1])} ns"
            )
        return t_ns, cols, start

    def _feeder(self, imu_t: np.ndarray, imu_cols: list[tuple[str, np.ndarray]],
                start: int) -> ImuFeeder:
        """The IMU block feeder of a window; refuses IMU streams too short or with too long
        gaps (the nominal interval is that of the first window)."""
        where = f"{self.source}: stream {StreamKind.IMU}"
        gaps, nominal = np.zeros(0, np.int64), 0.0
        filt = self.filter
        bridge = getattr(filt, "bridge_imu_gap", None)
        if self._nominal is not None or self._imu_required or len(imu_t) >= MIN_IMU_SAMPLES:
            try:
                gaps, nominal = find_gaps(imu_t, self._max_imu_gap, where,
                                          None if callable(bridge) else type(filt).name,
                                          nominal=self._nominal)
            except ValueError as e:
                raise ReplayError(str(e)) from None
            self._nominal = nominal
        feeder = ImuFeeder(filt.propagate, bridge, imu_t, imu_cols, gaps, nominal)
        feeder.start = start
        return feeder

    def feed(self, imu: Stream | None, final: bool = False, *,
             aiding: Mapping[StreamKind, Stream] | None = None,
             known: Mapping[StreamKind, int] | None = None) -> RunResult:
        """Apply the events up to the last IMU sample at hand and up to the time every aiding
        stream is known to (all of them when ``final``).

        Parameters
        ----------
        imu : Stream or None
            The next IMU samples (later than those fed before).
        final : bool
            No samples follow: apply every remaining event and hand over the remaining
            IMU samples before a last estimate.
        aiding : mapping, optional
            The next samples of aiding streams (later than those of the kind before; kinds the
            filter does not consume are ignored). Without it, the recording's aiding streams
            are whole.
        known : mapping, optional
            Time [ns] up to which each aiding kind is complete (every sample at or before it
            has been fed); a kind left out is complete.

        Returns
        -------
        RunResult
            The estimates and innovations of the events applied by this call.
        """
        if self.finished:
            raise ReplayError(f"{self.source}: the replay of {self.label!r} is finished")
        t0_ns = self._t0_ns
        if aiding is not None or known is not None:
            self._add_aiding(aiding or {}, known or {})
        imu_t_ns, imu_columns, start = self._window_imu(imu)
        if self._first_imu_ns is None and len(imu_t_ns):
            self._first_imu_ns = int(imu_t_ns[0])
        hi = None if final else (int(imu_t_ns[-1]) if len(imu_t_ns) > start else None)
        if hi is not None and self._known:
            hi = min(hi, *self._known.values())
            if self._done_to_ns is not None and hi <= self._done_to_ns:
                hi = None
        if not final and hi is None:  # nothing to apply yet: the IMU samples wait
            if len(imu_t_ns) > start:
                self._pending = (imu_t_ns[start:],
                                 {k: v[start:] for k, v in imu_columns.items()})
            return self._empty_block()
        plan = window_plan(self._merged, imu_t_ns, t0_ns, self._output_rate,
                           lo=self._done_to_ns, hi=hi, first_imu_ns=self._first_imu_ns)
        imu_t = (imu_t_ns - np.int64(t0_ns)).astype(np.float64) * 1e-9
        imu_cols = list(imu_columns.items())
        feeder = self._feeder(imu_t, imu_cols, start)
        block = self._run(plan, feeder, imu_t, final)
        self._done_to_ns = hi
        if self._windowed and hi is not None:
            self._drop_aiding(hi)
        if final:
            self.finished = True
            self._pending = self._last = None
        elif len(imu_t_ns):
            s = feeder.start
            self._last = (imu_t_ns[s - 1:s], {k: v[s - 1:s] for k, v in imu_columns.items()}) \
                if s > 0 else self._last
            self._pending = ((imu_t_ns[s:], {k: v[s:] for k, v in imu_columns.items()})
                             if s < len(imu_t_ns) else None)
        return block

    def _add_aiding(self, aiding: Mapping[StreamKind, Stream],
                    known: Mapping[StreamKind, int]) -> None:
        """Append the samples of a window to the aiding streams and note how far each kind
        is known."""
        kinds = self._merged.kinds
        self._windowed = True
        for c, kind in enumerate(kinds):
            self._known[kind] = int(known.get(kind, KNOWN_ALL))
            new = aiding.get(kind)
            if new is not None and len(new):
                self._aiding[c] = _join(self._aiding[c], new)
        self._known = {k: t for k, t in self._known.items() if t < KNOWN_ALL}
        self._merged = merge_streams(kinds, self._aiding)

    def _drop_aiding(self, done_ns: int) -> None:
        """Forget the aiding samples applied before ``done_ns``, but those within two output
        periods of it (they decide which later output ticks fall)."""
        margin = 2 * round(1e9 / self._output_rate) if self._output_rate else 0
        cut = done_ns - margin
        self._aiding = [s.slice(int(np.searchsorted(s.t_ns, cut, side="right")), len(s))
                        for s in self._aiding]
        self._merged = merge_streams(self._merged.kinds, self._aiding)

    def _empty_block(self) -> RunResult:
        n = len(self.states)
        return RunResult(t=np.zeros(0), x=np.zeros((0, n)), P=np.zeros((0, n, n)),
                         **self._meta)

    # -- the loop ----------------------------------------------------------------------------

    def _run(self, plan: EventPlan, feeder: ImuFeeder, imu_t: np.ndarray,
             final: bool) -> RunResult:
        label, source, states, names = self.label, self.source, self.states, self._names
        meta = self._meta
        pacing, progress, observer = self._pacing, self._progress, self._observer
        observe_interval = self._observe_interval
        n_imu = len(imu_t)
        aiding = self._aiding
        sample_cols = [list(s.columns.items()) for s in aiding]
        ev_t = ((plan.t_ns - np.int64(self._t0_ns)).astype(np.float64) * 1e-9).tolist()
        ev_code = plan.code.tolist()
        ev_row = plan.row.tolist()
        ev_end = plan.imu_end.tolist()
        # one estimate per distinct time: samples sharing a timestamp are all applied first
        ev_record = np.append(plan.t_ns[1:] != plan.t_ns[:-1], True).tolist()
        kinds = plan.kinds

        filt = self.filter
        update = filt.update
        estimate = filt.estimate
        innovations: dict[str, list[tuple[float, np.ndarray, np.ndarray]]] = {}
        columns: _Columns | None = None
        checked = 0
        n_events = len(ev_t)
        n_loop = n_events if final else n_events - 1  # the last step hands over the rest
        upper = n_events + 1
        done0 = self._events

        wall0 = self._wall0
        if self._t_first is None and ev_t:
            self._t_first = ev_t[0]
        t_first = self._t_first if self._t_first is not None else 0.0
        next_observe = time.perf_counter() + observe_interval
        slow = pacing is not None or observer is not None or progress is not None

        batch = self._batch
        tick_run_end = _tick_runs(plan.code).tolist() if batch is not None else []
        events = self._events_hook
        if events is not None:
            ev_t_arr = np.asarray(ev_t, dtype=np.float64)
            ev_record_arr = np.asarray(ev_record, dtype=np.bool_)
            samples = [s.columns for s in aiding]
        slow_at = -1  # an event the hook undid: applied one by one
        # live views and progress reports between runs of at most this many events
        run_cap = _CHECK_EVERY if observer is not None or progress is not None else n_events
        i = -1
        t_now = 0.0
        try:
            while i < n_loop:
                i += 1
                if events is not None and i < n_events and i != slow_at:
                    j = _clean_run(feeder, ev_end, i, min(n_events, i + run_cap))
                    if j > i:  # events [i, j) in one call of the filter
                        if columns is None:
                            columns = _Columns(None, upper, len(states), self.navigation)
                        m0 = columns.m
                        done = _apply_run(events, columns, feeder, plan, ev_t_arr,
                                          ev_record_arr, samples, innovations, i, j)
                        if checked == m0:  # the hook's kernel checked its estimates
                            checked = columns.m
                        if done:
                            t_now = ev_t[i + done - 1]
                        if done < j - i:
                            slow_at = i + done
                        i += done - 1
                        if observer is not None and time.perf_counter() >= next_observe:
                            observer(columns.view(**meta))
                            next_observe = time.perf_counter() + observe_interval
                        if progress is not None:
                            progress(done0 + min(i + 1, n_events), done0 + n_events)
                        continue
                if batch is not None and i < n_events and ev_code[i] == TICK:
                    j = tick_run_end[i]
                    if feeder.clean(ev_end[j - 1]):  # outputs of a run of ticks in one call
                        t_now = ev_t[i]
                        block = feeder.take(ev_end[j - 1])
                        ends = plan.imu_end[i:j] - block[2]
                        rows = batch(block[0], block[1], ends)
                        if columns is None:
                            columns = _Columns(_first_estimate(rows, len(states), names), upper,
                                               navigation=self.navigation)
                        columns.add_rows(*rows)
                        t_now = ev_t[j - 1]
                        i = j - 1
                        if columns.m - checked >= _CHECK_EVERY:
                            _check_finite(columns, checked, label, source, names)
                            checked = columns.m
                        if observer is not None and time.perf_counter() >= next_observe:
                            observer(columns.view(**meta))
                            next_observe = time.perf_counter() + observe_interval
                        if progress is not None:
                            progress(done0 + min(i + 1, n_events), done0 + n_events)
                        continue
                if i < n_events:
                    t_now = ev_t[i]
                    end = ev_end[i]
                    c = ev_code[i]
                else:  # the IMU samples after the last event, then a last estimate
                    end = n_imu
                    c = TICK
                    if end == feeder.start:
                        break
                    t_now = float(imu_t[end - 1])
                feeder.advance(end, t_now)
                if c != TICK:
                    r = ev_row[i]
                    inn = update(kinds[c], t_now, {k: v[r] for k, v in sample_cols[c]})
                    if inn:
                        for it in inn:
                            innovations.setdefault(it.name, []).append((it.t, it.nu, it.S))
                est = estimate() if i == n_events or ev_record[i] else None
                if est is not None:
                    if columns is None:
                        if np.shape(est.x) != (len(states),):
                            raise _BadOutput(
                                f"x has shape {np.shape(est.x)}; the filter declares "
                                f"{len(states)} states ({', '.join(names) or 'none'}; set "
                                "Filter.states)"
                            )
                        columns = _Columns(est, upper, navigation=self.navigation)
                    columns.add(est)
                    if columns.m - checked >= _CHECK_EVERY:
                        _check_finite(columns, checked, label, source, names)
                        checked = columns.m
                if slow:
                    if pacing is not None:
                        delay = (t_now - t_first) / pacing - (time.perf_counter() - wall0)
                        if delay > 0:
                            time.sleep(delay)
                    if observer is not None and columns is not None:
                        now = time.perf_counter()
                        if now >= next_observe:
                            observer(columns.view(**meta))
                            next_observe = now + observe_interval
                    if progress is not None and i % _CHECK_EVERY == 0:
                        progress(done0 + min(i + 1, n_events), done0 + n_events)
        except FilterDivergedError as e:
            raise _diverged(label, source, e.t if e.t is not None else t_now, str(e)) from e
        except (np.linalg.LinAlgError, FloatingPointError) as e:
            raise _diverged(label, source, t_now, f"{type(e).__name__}: {e}") from e
        except FilterOutputError:
            raise
        except _BadOutput as e:
            raise _invalid(label, source, t_now, str(e)) from None
        except Exception as e:
            raise FilterFailedError(
                f"filter {label!r} failed on {source} at t = {t_now:.3f} s: {_one_line(e)}"
            ) from e
        self._events = done0 + n_events

        if columns is not None:
            _check_finite(columns, checked, label, source, names)
        if observer is not None and columns is not None:
            observer(columns.view(**meta))
        if progress is not None:
            progress(self._events, self._events)

        inn_series = {}
        for name, items in innovations.items():
            undeclared = _undeclared(name, items, self._rows_of)
            if undeclared is not None:
                raise _invalid(label, source, undeclared[0], undeclared[1])
            series, bad = _innovation_series(items)
            if bad is not None:
                raise _invalid(label, source, float(series.t[bad[0]]),
                               f"innovation {name!r}: {bad[1]}")
            inn_series[name] = series
        if columns is None:
            block = self._empty_block()
            block.innovations = inn_series
            return block
        return columns.result(innovations=inn_series, **meta)


def _batch_hook(filt: Filter) -> Callable[..., tuple[np.ndarray, ...]] | None:
    """The filter's ``propagate_outputs(t, imu, ends)``, when it has one that belongs with its
    ``propagate`` and ``estimate`` (defined by the same class or a subclass of theirs).

    ``propagate_outputs`` is equivalent to ``propagate`` over each segment
    ``[ends[j-1], ends[j])`` of the IMU block followed by ``estimate``, and returns the
    estimates' columns ``(t (m,), x (m, n), P (m, n, n), nav (m, 10))``; the engine hands it
    runs of output ticks (no aiding sample, no IMU gap) at once.
    """
    cls = type(filt)
    if getattr(cls, "propagate_outputs", None) is None:
        return None

    def owner(name: str) -> type:
        return next(c for c in cls.__mro__ if name in c.__dict__)

    hook = owner("propagate_outputs")
    if all(issubclass(hook, owner(n)) for n in ("propagate", "estimate")):
        return filt.propagate_outputs  # type: ignore[attr-defined]
    return None


def _events_hook(filt: Filter) -> Callable[..., tuple[int, int, dict]] | None:
    """The filter's ``replay_events``, when it belongs with its ``propagate``, ``update``
    and ``estimate`` (defined by the same class or a subclass of theirs).

    ``replay_events(t, imu, ends, kinds, codes, rows, t_ev, record, samples, out)`` applies
    a run of events without IMU gaps as the calls one by one would (propagate over the IMU
    segment ``[ends[e-1], ends[e])`` of the block, update with row ``rows[e]`` of
    ``samples[codes[e]]`` unless ``codes[e]`` is :data:`TICK`, and when ``record[e]`` an
    estimate into the next rows of ``out = (t, x, P, nav vectors)``), checks every estimate
    as :func:`navreplay.filters.kalman.check_covariance` does, and returns (events applied,
    estimates written, ``{name: (t, nu, S)}``); it stops before an event that fails, which
    the engine then applies one by one (and so names the problem).
    """
    cls = type(filt)
    if getattr(cls, "replay_events", None) is None:
        return None

    def owner(name: str) -> type:
        return next(c for c in cls.__mro__ if name in c.__dict__)

    hook = owner("replay_events")
    if all(issubclass(hook, owner(n)) for n in ("propagate", "update", "estimate")):
        return filt.replay_events  # type: ignore[attr-defined]
    return None


def _clean_run(feeder: ImuFeeder, ev_end: list[int], i: int, n_events: int) -> int:
    """The end j <= n_events of the run of events from i whose IMU samples hold no gap to
    bridge."""
    if feeder.clean(ev_end[n_events - 1]):
        return n_events
    lo, hi = i, n_events  # clean() holds before lo and fails at hi - 1 (it only turns false)
    while lo < hi:
        mid = (lo + hi) // 2
        if feeder.clean(ev_end[mid]):
            lo = mid + 1
        else:
            hi = mid
    return lo


def _apply_run(hook: Callable[..., tuple[int, int, dict]], columns: _Columns,
               feeder: ImuFeeder, plan: EventPlan, ev_t: np.ndarray, record: np.ndarray,
               samples: list[Mapping[str, np.ndarray]],
               innovations: dict[str, list[tuple[float, np.ndarray, np.ndarray]]],
               i: int, j: int) -> int:
    """Events [i, j) through the filter's ``replay_events``; the estimates go straight into
    the columns. Returns the number of events applied."""
    a = feeder.start
    end = int(plan.imu_end[j - 1])
    ends = np.maximum(plan.imu_end[i:j] - a, 0)
    while columns.m + (j - i) > columns.cap:
        columns._grow()
    m0 = columns.m
    nav = np.empty((j - i, 10))
    out = (columns.t[m0:], columns.x[m0:], columns.P[m0:], nav)
    block = feeder.take(end)  # handed over: those the hook did not use are given back
    done, m, inn = hook(block[0], block[1], ends, plan.kinds, plan.code[i:j], plan.row[i:j],
                        ev_t[i:j], record[i:j], samples, out)
    if columns.has_nav:
        columns.pos[m0:m0 + m] = nav[:m, 0:3]
        columns.v_n[m0:m0 + m] = nav[:m, 3:6]
        columns.q_nb[m0:m0 + m] = nav[:m, 6:10]
    columns.m = m0 + m
    feeder.start = a + int(ends[done - 1]) if done else a
    for name, (t, nu, S) in inn.items():
        innovations.setdefault(name, []).extend(zip(t.tolist(), nu, S, strict=True))
    return done


def _tick_runs(code: np.ndarray) -> np.ndarray:
    """For each event, the index after the run of output ticks that starts there."""
    n = code.shape[0]
    is_tick = code == TICK
    # index of the next non-tick event at or after each position
    nxt = np.where(~is_tick, np.arange(n), n)
    return np.minimum.accumulate(nxt[::-1])[::-1] if n else nxt


def _first_estimate(rows: tuple[np.ndarray, ...], n_states: int,
                    names: tuple[str, ...]) -> Estimate:
    """The first row of a batch as an Estimate (it sizes the output columns)."""
    t, x, P, nav = rows
    if np.shape(x)[1:] != (n_states,):
        raise _BadOutput(
            f"x has shape {np.shape(x)[1:]}; the filter declares {n_states} states "
            f"({', '.join(names) or 'none'}; set Filter.states)"
        )
    return Estimate(float(t[0]), x[0], P[0], NavSolution.from_vector(nav[0]))


PSD_TOLERANCE = 1e-6
"""Tolerance of the covariance checks, relative to the standard deviations: a covariance is
accepted as symmetric when ``|P_ij - P_ji| <= tol sqrt(P_ii P_jj)`` and as positive
semi-definite when the smallest eigenvalue of its correlation matrix is ``>= -tol``."""


def covariance_problem(P: np.ndarray, names: tuple[str, ...] | None = None
                       ) -> tuple[int, str] | None:
    """The first of a stack of covariances (K, n, n) that is not finite, symmetric and positive
    semi-definite within :data:`PSD_TOLERANCE`, and what is wrong; None if all are.

    ``names`` name the rows (states) in the message."""
    K = P.shape[0]
    if K == 0 or P.shape[1] == 0:
        return None
    what = (lambda j: names[j]) if names else (lambda j: f"[{j}]")
    flat = P.reshape(K, -1)
    finite = np.isfinite(flat).all(axis=1)
    d = np.diagonal(P, axis1=1, axis2=2)
    neg = (d < 0.0) & finite[:, None]
    scale = np.sqrt(np.where(d > 0.0, d, 1.0))
    with np.errstate(invalid="ignore", over="ignore"):
        C = P / (scale[:, :, None] * scale[:, None, :])
        asym = np.abs(C - C.transpose(0, 2, 1)).max(axis=(1, 2)) > PSD_TOLERANCE
    bad_rows = ~finite | neg.any(axis=1) | asym
    first: tuple[int, str] | None = None
    if bad_rows.any():
        k = int(np.argmax(bad_rows))
        if not finite[k]:
            first = (k, "covariance P is not finite")
        elif neg[k].any():
            j = int(np.argmax(neg[k]))
            first = (k, f"covariance P has a negative variance {P[k, j, j]:.3g} of state "
                        f"{what(j)}")
        else:
            first = (k, "covariance P is not symmetric")
    ok = ~bad_rows if first is None else ~bad_rows & (np.arange(K) < first[0])
    if ok.any():
        idx = np.flatnonzero(ok)
        sym = 0.5 * (C[idx] + C[idx].transpose(0, 2, 1))
        try:  # all positive definite after a shift of the tolerance: the common, cheap case
            np.linalg.cholesky(sym + PSD_TOLERANCE * np.eye(sym.shape[1]))
            return first
        except np.linalg.LinAlgError:
            pass
        lam = np.linalg.eigvalsh(sym)[:, 0]
        low = lam < -PSD_TOLERANCE
        if low.any():
            k = int(idx[np.argmax(low)])
            first = (k, f"covariance P is not positive semi-definite (smallest eigenvalue of "
                        f"its correlation matrix {lam[np.argmax(low)]:.3g})")
    return first


def _check_finite(columns: _Columns, start: int, label: str, source: str,
                  names: tuple[str, ...]) -> None:
    """Check rows [start, m) of the estimates: finite, P symmetric PSD."""
    bad = columns.first_nonfinite(start)
    stop = columns.m if bad is None else bad[0]
    cov = covariance_problem(columns.P[start:stop], names)
    if cov is not None:
        raise _invalid(label, source, float(columns.t[start + cov[0]]), cov[1])
    if bad is not None:
        raise _diverged(label, source, float(columns.t[bad[0]]), f"non-finite {bad[1]} estimate")


def _invalid(label: str, source: str, t: float, why: str) -> FilterOutputError:
    return FilterOutputError(f"filter {label!r} on {source} at t = {t:.3f} s: {why}")


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


def _diverged(label: str, source: str, t: float, why: str) -> FilterDivergedError:
    err = FilterDivergedError(f"filter {label!r} diverged on {source} at t = {t:.3f} s: {why}")
    err.t = t
    return err
