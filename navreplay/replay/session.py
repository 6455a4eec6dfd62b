"""One filter replayed over a recording that arrives in time windows: the replay loop.

A :class:`ReplaySession` is made from the first window of a recording
(:class:`~navreplay.io.source.Window`: every stream read, the metadata and the start time) and
fed its windows one by one (:meth:`ReplaySession.feed`); each call applies the events whose
samples are all at hand and hands back their estimates and innovations. The filter sees
exactly the calls of one window holding the whole recording: an event is applied once every
IMU sample up to its time and every aiding sample before it is at hand, and the IMU samples
after a window's last event wait for the next window, so they reach the filter in the same
blocks.

For each event at time ``t_e`` (the event plan of :mod:`navreplay.replay.plan`) the filter

1. is handed the IMU samples with ``t_prev < t <= t_e`` as one block
   (:meth:`~navreplay.filters.base.Filter.propagate`; skipped when the block is empty),
2. is handed the aiding sample (:meth:`~navreplay.filters.base.Filter.update`; not for ticks),
   whose innovations are collected,
3. gives :meth:`~navreplay.filters.base.Filter.estimate`, stored in preallocated columns
   (skipped while the filter returns None), once per distinct event time, and not for an
   output tick followed by an aiding sample before the next IMU sample: an IMU-propagated
   filter's state is at its last IMU sample for both, and the row there is the one after the
   update (the tick at the next IMU sample stays).

IMU samples after the last event are handed over at the end, followed by a last estimate.
Every IMU sample is thus delivered exactly once and in order. The events go to the filter in
runs without IMU gaps (:meth:`~navreplay.filters.base.Filter.run_events`: one call, compiled
for ``ins`` and ``gps-ins``); the engine bridges the gaps between runs
(:mod:`navreplay.replay.gaps`). The work per event is slicing views and one call per step;
everything else (planning, innovation statistics, checks) is vectorised.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from navreplay.core.streams import Stream, StreamKind
from navreplay.filters.base import (
    TICK,
    Estimate,
    EventRun,
    Filter,
    FilterContext,
    Innovation,
    State,
    check_measurements,
    check_states,
    consumed_streams,
    navigation_parts,
)
from navreplay.filters.kalman import FilterDivergedError
from navreplay.filters.result import RunResult
from navreplay.filters.settings import FilterSettings, build_params
from navreplay.filters.smoothable import Smoothable, SmoothingSteps
from navreplay.io.errors import RecordingError
from navreplay.io.lifecycle import from_signal
from navreplay.io.source import COMPLETE, Window
from navreplay.replay.checks import check_streams
from navreplay.replay.columns import Columns, innovation_series, undeclared
from navreplay.replay.errors import (
    BadOutput,
    FilterFailedError,
    FilterInitError,
    FilterOutputError,
    InvalidRecordingError,
    ReplayError,
    diverged,
    invalid,
    one_line,
)
from navreplay.replay.gaps import MIN_IMU_SAMPLES, ImuFeeder, find_gaps
from navreplay.replay.plan import EventPlan, aiding_kinds, merge_streams, window_plan
from navreplay.replay.smoothing import ForwardStore
from navreplay.replay.spec import FilterSpec
from navreplay.sensors.specs import SensorSpecs

CHECK_EVERY = 1024
"""Estimates between divergence (non-finite) checks; events between live views and progress
reports."""

Rows = Callable[[RunResult], None]
"""Called with estimates as they come during a feed (views, valid only during the call)."""

Progress = Callable[[int, int], None]
"""Called with (done, total)."""


class ReplaySession:
    """One filter replayed over a recording whose samples arrive in time windows (see the
    module docstring).

    Parameters
    ----------
    first : Window
        The recording's first window: every stream read (each at least empty, with its
        columns), the metadata and the start; its samples come through :meth:`feed` like
        every window's.
    spec : FilterSpec
        The filter and its parameter values; the filter's parameters are built here, for this
        recording (:func:`navreplay.filters.settings.build_params`, from the recording's sensor
        specifications and the spec's values).
    source : str
        The recording in messages and in the result.
    output_rate : float or None
        Output tick rate [Hz] where no aiding sample falls; None or 0 for outputs at aiding
        samples only.
    pacing : float, optional
        Replay at this multiple of real time (1.0 = real time); None: as fast as possible.
    max_imu_gap : float, optional
        Longest IMU gap [s] the filter may bridge (:mod:`navreplay.replay.gaps`).
    live : callable, optional
        Called with the estimates as they come, about every ``observe_interval`` seconds of
        wall time (:data:`Rows`); :meth:`feed` then hands back the rows not handed yet.
    observe_interval : float
        Wall time between ``live`` calls [s].
    progress : callable, optional
        ``progress(done, total)`` in events of a feed, every few thousand events and at its
        end.

    Raises
    ------
    MissingStreamError
        The recording lacks a required stream or column (before the filter is built).
    navreplay.core.params.ParamError
        Parameters that do not fit the filter's.
    FilterInitError
        The filter raised while it was built.
    """

    def __init__(
        self,
        first: Window,
        spec: FilterSpec,
        *,
        source: str,
        output_rate: float | None = 10.0,
        pacing: float | None = None,
        max_imu_gap: float | None = None,
        live: Rows | None = None,
        observe_interval: float = 0.25,
        progress: Progress | None = None,
        smoothing: ForwardStore | None = None,
    ) -> None:
        filter_cls = spec.filter_cls
        label = spec.label
        check_streams(first, filter_cls, source)
        try:
            sensors = SensorSpecs.from_metadata(first.metadata.sensors, source)
        except ValueError as e:
            raise RecordingError(str(e)) from None
        self.settings: FilterSettings = build_params(filter_cls, spec.values, sensors,
                                                     label=label)
        p = self.settings.params
        context = FilterContext(metadata=first.metadata, t0_ns=first.t0_ns,
                                streams=frozenset(first.present | set(first)))
        try:
            filt = filter_cls(p, context)
        except Exception as e:
            raise FilterInitError(
                f"filter {label!r} cannot start on {source}: {one_line(e)}"
            ) from e
        except BaseException as e:
            if from_signal(e):
                raise
            raise FilterInitError(f"filter {label!r} cannot start on {source}: "
                                  f"{one_line(e)} (a filter raises an Exception; it never "
                                  "ends the process)") from None
        self.filter: Filter = filt
        self.smoothing = smoothing
        """Where the forward pass is stored for the smoother (None: not smoothed)."""
        if smoothing is not None:
            if not isinstance(filt, Smoothable):
                raise ReplayError(f"filter {label!r} cannot be smoothed (it does not declare "
                                  "navreplay.filters.smoothable.Smoothable)")
            filt.start_smoothing()
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
        kinds = aiding_kinds(list(first), consumed_streams(filter_cls))
        # the aiding samples arrive window by window: each kind is known up to a time, events
        # wait until every kind is known up to theirs
        self._aiding: list[Stream] = [first[k].slice(0, 0) for k in kinds]
        self._merged = merge_streams(kinds, self._aiding)
        self._known: dict[StreamKind, int] = {}
        self._output_rate = output_rate
        self._t0_ns = first.t0_ns
        self._max_imu_gap = max_imu_gap
        self._imu_required = StreamKind.IMU in filter_cls.requires
        self._pacing, self._progress, self._live = pacing, progress, live
        self._observe_interval = observe_interval
        self._meta: dict[str, Any] = dict(
            filter_name=filter_cls.name,
            label=label,
            recording=source,
            t0_ns=first.t0_ns,
            states=self.states,
            scored_extras=scored_extras,
            measurements=measurements or (),
            settings=self.settings,
        )
        # IMU state between windows: samples not yet handed over, the last one handed over,
        # the tick range and the nominal sample interval
        self._pending: tuple[np.ndarray, dict[str, np.ndarray]] | None = None
        self._last: tuple[np.ndarray, dict[str, np.ndarray]] | None = None
        self._first_imu_ns: int | None = None
        self._nominal: float | None = None
        self._done_to_ns: int | None = None  # events up to this time are applied
        # the filter starts at its initial solution's time: the samples before it are not its
        start_ns = first.metadata.initial_nav.get("t_ns")
        self._start_ns: int | None = int(start_ns) if start_ns is not None else None
        self._filter_start_ns = self._start_ns  # kept: the output ticks begin there
        self._events = 0
        self._wall0 = time.perf_counter()
        self._t_first: float | None = None
        self.live_rows = 0
        """Estimates handed to ``live`` by the last :meth:`feed` (not in the block it returned)."""
        self.finished = False

    # -- windows -----------------------------------------------------------------------------

    def feed(self, window: Mapping[StreamKind, Stream], final: bool = False,
             known: Mapping[StreamKind, int] | None = None) -> RunResult:
        """Apply the events up to the last IMU sample at hand and up to the time every aiding
        stream is known to (all of them when ``final``).

        Parameters
        ----------
        window : mapping of StreamKind to Stream
            The next samples of the streams (later than those fed before; streams the filter
            does not consume are ignored).
        final : bool
            No samples follow: apply every remaining event and hand over the remaining IMU
            samples before a last estimate.
        known : mapping, optional
            Time [ns] up to which each aiding stream is complete (every sample at or before it
            has been fed; :data:`~navreplay.io.source.COMPLETE` or left out: all of it).

        Returns
        -------
        RunResult
            The estimates (those not handed to ``live`` yet) and innovations of the events
            applied by this call.
        """
        if self.finished:
            raise ReplayError(f"{self.source}: the replay of {self.label!r} is finished")
        self.live_rows = 0
        t0_ns = self._t0_ns
        self._add_aiding(window, known or {})
        imu_t_ns, imu_columns, start = self._window_imu(window.get(StreamKind.IMU))
        if self._start_ns is not None and len(imu_t_ns):
            imu_t_ns, imu_columns, start = self._skip_to_start(imu_t_ns, imu_columns, start)
        if self._first_imu_ns is None and len(imu_t_ns) and self._start_ns is None:
            # the output ticks from the first sample, or from the filter's start when the
            # samples began before it (no tick before the start: its estimate would repeat
            # the start's, once per tick)
            self._first_imu_ns = max(int(imu_t_ns[0]), self._filter_start_ns or 0)
        hi = None if final else (int(imu_t_ns[-1]) if len(imu_t_ns) > start else None)
        if hi is not None and self._known:
            hi = min(hi, *self._known.values())
        if hi is not None:
            # the events after the last IMU sample up to hi share its estimate time with those
            # after hi (the filter's state is at that sample): they wait for the next window
            hi = int(imu_t_ns[max(int(np.searchsorted(imu_t_ns, hi, side="right")) - 1, 0)]) - 1
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
        feeder = self._feeder(imu_t, list(imu_columns.items()), start)
        block = self._run(plan, feeder, imu_t, final)
        self._done_to_ns = hi
        if hi is not None:
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

    def _skip_to_start(self, t_ns: np.ndarray, cols: dict[str, np.ndarray], start: int
                       ) -> tuple[np.ndarray, dict[str, np.ndarray], int]:
        """The IMU samples from the last one before the filter's start on (that one handed
        over), so that neither the propagation nor the output ticks run before the start;
        until a sample at or after the start arrives, the last one is kept as handed over."""
        assert self._start_ns is not None
        k = int(np.searchsorted(t_ns, self._start_ns, side="left"))
        if k == 0:  # no sample before the start: nothing to skip, now or after
            self._start_ns = None
            return t_ns, cols, start
        t_ns, cols = t_ns[k - 1:], {name: v[k - 1:] for name, v in cols.items()}
        if len(t_ns) == 1:
            self._last, self._pending = (t_ns, cols), None
        else:
            self._start_ns = None
        return t_ns, cols, 1

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

    def _add_aiding(self, window: Mapping[StreamKind, Stream],
                    known: Mapping[StreamKind, int]) -> None:
        """Append the samples of a window to the aiding streams and note how far each kind
        is known."""
        kinds = self._merged.kinds
        for c, kind in enumerate(kinds):
            self._known[kind] = int(known.get(kind, COMPLETE))
            new = window.get(kind)
            if new is not None and len(new) and self._start_ns is not None:
                new = new.slice(int(np.searchsorted(new.t_ns, self._start_ns)), len(new))
            if new is not None and len(new):
                self._aiding[c] = _join(self._aiding[c], new)
        self._known = {k: t for k, t in self._known.items() if t < COMPLETE}
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
        """Apply the events of a window in runs without IMU gaps (see the module docstring)."""
        label, source = self.label, self.source
        pacing, progress, live = self._pacing, self._progress, self._live
        filt = self.filter
        n_events = len(plan)
        t_ev = (plan.t_ns - np.int64(self._t0_ns)).astype(np.float64) * 1e-9
        codes, rows, ends = plan.code, plan.row, plan.imu_end
        # one estimate per distinct time, after every sample of that time; none for a tick
        # followed by an aiding sample before the next IMU sample (the state is at the IMU
        # sample for both: the row there is the one after the update)
        n_imu = len(imu_t)
        record = np.append(plan.t_ns[1:] != plan.t_ns[:-1], True)
        if n_imu:
            record[:-1] &= ~((codes[:-1] == TICK) & (ends[1:] == ends[:-1]))
        done_imu = max(feeder.start, int(ends[-1]) if n_events else 0)
        if final and n_imu > done_imu:  # the IMU samples after the last event, an estimate
            t_ev = np.append(t_ev, imu_t[-1])
            codes = np.append(codes, TICK)
            rows = np.append(rows, 0)
            ends = np.append(ends, n_imu)
            record = np.append(record, True)
        n = t_ev.shape[0]
        events = _Events(self, plan.kinds, [s.columns for s in self._aiding], n_events + 1)
        if self._t_first is None and n_events:
            self._t_first = float(t_ev[0])
        t_first = self._t_first if self._t_first is not None else 0.0
        done0 = self._events
        next_observe = time.perf_counter() + self._observe_interval
        # live views and progress between runs of at most this many events; the clock of a
        # paced replay between events
        run_cap = 1 if pacing is not None else (
            CHECK_EVERY if live is not None or progress is not None else n)
        ends_list = ends.tolist()
        slow_at = -1  # an event a fast path did not apply: through the reference
        reference = Filter.run_events
        hook = reference if pacing is not None else type(filt).run_events
        i = 0
        run: EventRun | None = None
        try:
            while i < n:
                j = _clean_end(feeder, ends_list, i, min(n, i + run_cap))
                if j == i:  # an IMU gap before event i: bridged, then the event alone
                    feeder.advance(ends_list[i], float(t_ev[i]))
                    run = events.run(feeder, i, i + 1, t_ev, codes, rows, ends, record,
                                     take=False)
                    done = reference(filt, run)
                else:
                    if i == slow_at:
                        j = i + 1
                    run = events.run(feeder, i, j, t_ev, codes, rows, ends, record)
                    done = (reference if i == slow_at else hook)(filt, run)
                    events.give_back(feeder, run, done)
                    if done < j - i:
                        slow_at = i + done
                i += done
                if pacing is not None and done:
                    delay = (float(t_ev[i - 1]) - t_first) / pacing - (
                        time.perf_counter() - self._wall0)
                    if delay > 0:
                        time.sleep(delay)
                if live is not None and time.perf_counter() >= next_observe:
                    events.emit()
                    next_observe = time.perf_counter() + self._observe_interval
                if progress is not None:
                    progress(done0 + min(i, n_events), done0 + n_events)
        except FilterDivergedError as e:
            raise diverged(label, source, e.t if e.t is not None else _time(run, t_ev, i),
                           str(e)) from e
        except (np.linalg.LinAlgError, FloatingPointError) as e:
            raise diverged(label, source, _time(run, t_ev, i),
                           f"{type(e).__name__}: {e}") from e
        except FilterOutputError:
            raise
        except BadOutput as e:
            raise invalid(label, source, _time(run, t_ev, i), str(e)) from None
        except Exception as e:
            raise FilterFailedError(
                f"filter {label!r} failed on {source} at t = {_time(run, t_ev, i):.3f} s: "
                f"{one_line(e)}"
            ) from e
        except BaseException as e:
            if from_signal(e):
                raise
            raise FilterFailedError(  # sys.exit(), an interrupt raised by code: its error
                f"filter {label!r} failed on {source} at t = {_time(run, t_ev, i):.3f} s: "
                f"{one_line(e)} (a filter raises an Exception; it never ends the process)"
            ) from None
        self._events = done0 + n_events
        events.finish()
        if progress is not None:
            progress(self._events, self._events)
        return events.block()


class _Events:
    """The estimates and innovations of one feed, and the runs of events it hands out."""

    def __init__(self, session: ReplaySession, kinds: tuple[StreamKind, ...],
                 samples: list[Mapping[str, np.ndarray]], upper: int) -> None:
        self.session = session
        self.kinds, self.samples, self.upper = kinds, samples, upper
        self.columns: Columns | None = None
        self.checked = 0  # rows checked for non-finite values and covariances
        self.emitted = 0  # rows handed to the session's live view
        self.innovations: dict[str, list[tuple[float, np.ndarray, np.ndarray]]] = {}

    def run(self, feeder: ImuFeeder, i: int, j: int, t_ev: np.ndarray, codes: np.ndarray,
            rows: np.ndarray, ends: np.ndarray, record: np.ndarray, take: bool = True
            ) -> _Run:
        """Events [i, j) as a run: their IMU samples taken from the feeder (none with
        ``take=False``: the feeder handed them over already)."""
        if take:
            a = feeder.start
            t, imu, _ = feeder.take(int(ends[j - 1]))
            rel = np.maximum(ends[i:j] - a, 0)
        else:
            a, t, imu, rel = feeder.start, _NO_T, _NO_IMU, np.zeros(1, np.int64)
        return _Run(self, a, t, imu, rel, self.kinds, codes[i:j], rows[i:j], t_ev[i:j],
                    record[i:j], self.samples)

    def give_back(self, feeder: ImuFeeder, run: _Run, done: int) -> None:
        """The IMU samples of the events a run did not apply go back to the feeder."""
        feeder.start = run.first + int(run.ends[done - 1]) if done else run.first

    def add(self, est: Estimate) -> None:
        s = self.session
        if self.columns is None:
            n = len(s.states)
            if np.shape(est.x) != (n,):
                raise BadOutput(f"x has shape {np.shape(est.x)}; the filter declares {n} states "
                                f"({', '.join(s._names) or 'none'}; set Filter.states)")
            self.columns = Columns(est, self.upper, navigation=s.navigation)
        columns = self.columns
        columns.add(est)
        if s.smoothing is not None:
            s.smoothing.add(est, s.filter.smoothing_step())  # type: ignore[attr-defined]
        if columns.m - self.checked >= CHECK_EVERY:
            columns.check(self.checked, s.label, s.source, s._names)
            self.checked = columns.m

    def free(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s = self.session
        if self.columns is None:
            self.columns = Columns(None, self.upper, len(s.states), s.navigation)
        return self.columns.free(k)

    def written(self, m: int, nav: np.ndarray, checked: bool,
                steps: SmoothingSteps | None) -> None:
        s = self.session
        if s.smoothing is not None and steps is None:
            raise ReplayError(f"filter {s.label!r}: a compiled run wrote estimates while "
                              "smoothing without their smoothing steps (EventRun.add_rows' "
                              "steps)")
        columns = self.columns
        assert columns is not None
        m0 = columns.m
        columns.written(m, nav)
        if s.smoothing is not None and steps is not None:
            if not steps.phi.shape[0] == steps.P_prior.shape[0] == steps.dx.shape[0] == m:
                raise BadOutput(f"{m} rows written with {steps.phi.shape[0]} smoothing steps")
            s.smoothing.add_rows(columns.t[m0:m0 + m], columns.x[m0:m0 + m],
                                 columns.P[m0:m0 + m], nav[:m] if columns.has_nav else None,
                                 steps)
        if checked:
            if self.checked == m0:  # the kernel checked its estimates
                self.checked = columns.m
        elif columns.m - self.checked >= CHECK_EVERY:
            columns.check(self.checked, s.label, s.source, s._names)
            self.checked = columns.m

    def emit(self) -> None:
        """The rows since the last call to the session's live view."""
        s = self.session
        columns = self.columns
        if s._live is None or columns is None or columns.m == self.emitted:
            return
        s._live(columns.view(self.emitted, **s._meta))
        s.live_rows += columns.m - self.emitted
        self.emitted = columns.m

    def finish(self) -> None:
        """Check the rows not checked yet."""
        s = self.session
        if self.columns is not None:
            self.columns.check(self.checked, s.label, s.source, s._names)
            self.checked = self.columns.m

    def block(self) -> RunResult:
        """The rows not handed to the live view, and the innovations of the feed (checked
        against the filter's declarations)."""
        s = self.session
        inn_series = {}
        for name, items in self.innovations.items():
            bad = undeclared(name, items, s._rows_of)
            if bad is not None:
                raise invalid(s.label, s.source, bad[0], bad[1])
            series, problem = innovation_series(items)
            if problem is not None:
                raise invalid(s.label, s.source, float(series.t[problem[0]]),
                              f"innovation {name!r}: {problem[1]}")
            inn_series[name] = series
        if self.columns is None:
            block = s._empty_block()
            block.innovations = inn_series
            return block
        return self.columns.view(self.emitted, innovations=inn_series, **s._meta)


class _Run(EventRun):
    """A run of events of one feed (:class:`~navreplay.filters.base.EventRun`)."""

    def __init__(self, events: _Events, first: int, t: np.ndarray,
                 imu: Mapping[str, np.ndarray], ends: np.ndarray, kinds: tuple[StreamKind, ...],
                 codes: np.ndarray, rows: np.ndarray, t_ev: np.ndarray, record: np.ndarray,
                 samples: Sequence[Mapping[str, np.ndarray]]) -> None:
        self.events, self.first = events, first
        self.t, self.imu, self.ends, self.kinds = t, imu, ends, kinds
        self.codes, self.rows, self.t_ev, self.record = codes, rows, t_ev, record
        self.samples = samples
        self.done = 0
        self._nav: np.ndarray | None = None

    def add_estimate(self, est: Estimate) -> None:
        self.events.add(est)

    def add_innovations(self, items: Sequence[Innovation]) -> None:
        innovations = self.events.innovations
        for it in items:
            innovations.setdefault(it.name, []).append((it.t, it.nu, it.S))

    def out(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        k = len(self)
        t, x, P = self.events.free(k)
        self._nav = np.empty((k, 10))
        return t, x, P, self._nav

    def add_rows(self, m: int, checked: bool = False,
                 steps: SmoothingSteps | None = None) -> None:
        if self._nav is None:
            raise BadOutput("add_rows before out(): no rows to add")
        self.events.written(m, self._nav, checked, steps)

    def add_innovation_rows(self, name: str, t: np.ndarray, nu: np.ndarray,
                            S: np.ndarray) -> None:
        self.events.innovations.setdefault(name, []).extend(zip(t.tolist(), nu, S, strict=True))


_NO_T = np.zeros(0)
_NO_IMU = {"omega_ib_b": np.zeros((0, 3)), "f_b": np.zeros((0, 3))}


def _clean_end(feeder: ImuFeeder, ends: list[int], i: int, stop: int) -> int:
    """The end j <= stop of the run of events from i whose IMU samples hold no gap to
    bridge (i when event i's do)."""
    if feeder.clean(ends[stop - 1]):
        return stop
    lo, hi = i, stop  # clean() holds before lo and fails at hi - 1 (it only turns false)
    while lo < hi:
        mid = (lo + hi) // 2
        if feeder.clean(ends[mid]):
            lo = mid + 1
        else:
            hi = mid
    return lo


def _time(run: EventRun | None, t_ev: np.ndarray, i: int) -> float:
    """The time [s] of the event being applied when an error came."""
    if run is not None and run.done < len(run):
        return float(run.t_ev[run.done])
    return float(t_ev[min(i, t_ev.shape[0] - 1)]) if t_ev.shape[0] else 0.0


def _join(a: Stream, b: Stream) -> Stream:
    """Stream ``a`` followed by the later samples ``b`` (columns of ``a``)."""
    if not len(a):
        return b
    return dataclasses.replace(
        a, t_ns=np.concatenate([a.t_ns, b.t_ns]),
        columns={k: np.concatenate([a.columns[k], b.columns[k]]) for k in a.columns},
    )
