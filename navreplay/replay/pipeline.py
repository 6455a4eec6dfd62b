"""The one pipeline of a replay: a recording's windows through the filters, the scoring and
every output stage, block by block.

:func:`replay_file` reads a :class:`~navreplay.io.source.Source` window by window (an intact
MCAP file is many windows; a damaged file, a rosbag2 bag or a recording in memory is one),
feeds each window to one :class:`~navreplay.replay.session.ReplaySession` per filter, scores
each block of estimates as the truth around it arrives
(:class:`~navreplay.metrics.RunScorer`) and hands truth, scored rows and innovations to the
output stages (:class:`Stage`: the Rerun view, the exports, the report's series, or
:class:`Collect`), which keep nothing that grows with the recording unless they mean to. A
whole run is one block. The navigation solutions the log recorded (``source.recorded``,
``run --onboard``) are rows beside the filters'
(:class:`~navreplay.replay.recorded.RecordedSession`), scored and handed to the stages the same
way. :func:`replay` is the same over a recording in memory, collected into a
:class:`~navreplay.filters.result.RunResult`.

Examples
--------
>>> import numpy as np
>>> from navreplay.sim.scenario import simulate
>>> rec = simulate("vehicle-drive", {"duration": 20.0}, seed=1)
>>> result = replay(rec, FilterSpec("gps-ins"))
>>> result.label, result.x.shape[1], sorted(result.innovations)
('gps-ins', 33, ['gps_pos', 'gps_vel'])
"""

from __future__ import annotations

import contextlib
import dataclasses
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from navreplay.core.outages import recorded_outages
from navreplay.core.streams import Metadata, Recording, Stream, StreamKind
from navreplay.filters.base import Filter, FilterParams, TruthColumn
from navreplay.filters.result import RunResult, concat, concat_innovations
from navreplay.filters.settings import summary_entries
from navreplay.filters.smoothable import is_smoothable
from navreplay.io.errors import RecordingError
from navreplay.io.source import COMPLETE, MemorySource, Source, Window
from navreplay.metrics import RunMetrics, RunScorer
from navreplay.replay.checks import validate_recording
from navreplay.replay.recorded import RecordedSession
from navreplay.replay.session import Progress, ReplaySession
from navreplay.replay.smoothing import (
    BACKWARD_COST,
    SCORING_COST,
    ForwardStore,
    TruthStore,
    backward,
    smoothed_blocks,
    smoothed_label,
)
from navreplay.replay.spec import FilterSpec


@dataclasses.dataclass(frozen=True)
class RunStart:
    """What the stages know before the first block.

    Attributes
    ----------
    source : str
        The recording, in messages.
    labels : tuple of str
        The filters' labels, in order.
    t0_ns : int
        Recording start [ns].
    has_truth : bool
        A truth (or reference) stream comes with the windows.
    metadata : Metadata
    truth_columns : dict[str, str]
        Truth columns that declared states are scored against, with their SI units.
    late : dict[str, str]
        Labels whose rows all come after the last window (the smoothed runs), each with the
        label of the run it follows (the same states and parts of the solution): a stage must
        not hold the other labels' rows until they come.
    gnss_outages : tuple of (start, end)
        The recording's GNSS outages [s since its start] (``metadata.extra["gnss_outages"]``).
    """

    source: str
    labels: tuple[str, ...]
    t0_ns: int
    has_truth: bool
    metadata: Metadata
    truth_columns: dict[str, str] = dataclasses.field(default_factory=dict)
    late: dict[str, str] = dataclasses.field(default_factory=dict)
    gnss_outages: tuple[tuple[float, float], ...] = ()


class Stage(Protocol):
    """An output of a replay, fed block by block (the Rerun view
    :class:`navreplay.viz.Sink`, the exports and report :class:`navreplay.jobs.results.Outputs`,
    :class:`Collect`). Calls come in this order: :meth:`start`; per window, :meth:`truth`, then
    per filter :meth:`innovations` and :meth:`rows` as the estimates are scored; :meth:`abort`
    when the replay fails. Finishing (closing files) is the caller's.

    A stage whose work is partly per block may ask for longer pieces of the windows with an
    attribute ``piece_outputs`` (output ticks; :data:`PIECE_OUTPUTS` is the least)."""

    def start(self, run: RunStart) -> None: ...

    def truth(self, truth: Stream) -> None:
        """A window of the truth stream (later than before)."""

    def rows(self, rows: RunResult, metrics: RunMetrics | None, truth: Stream | None) -> None:
        """A block of one filter's estimates (later than its rows before), without its
        innovations, with its scores and the truth around it (None without a truth)."""

    def innovations(self, block: RunResult) -> None:
        """The innovations of a block of one filter's run."""

    def abort(self) -> None: ...


class Collect:
    """A stage that keeps every filter's blocks: :meth:`results` joins them per label.

    It holds the whole run anyway, so it asks for pieces of whole windows (``whole``): the
    estimates of a window land in one set of columns, handed back without a copy. Not with a
    smoother, whose forward pass keeps two more covariances per output for each piece (a
    window's would be three times the run).
    """

    WHOLE = 100_000_000
    """Output ticks of a piece asked for whole windows."""

    def __init__(self, whole: bool = True) -> None:
        self.piece_outputs = self.WHOLE if whole else 0
        self._rows: dict[str, list[RunResult]] = {}
        self._innovations: dict[str, list[RunResult]] = {}

    def start(self, run: RunStart) -> None:
        self._rows = {label: [] for label in run.labels}
        self._innovations = {label: [] for label in run.labels}

    def truth(self, truth: Stream) -> None:
        return None

    def rows(self, rows: RunResult, metrics: RunMetrics | None, truth: Stream | None) -> None:
        if rows.t.size or not self._rows[rows.label]:
            self._rows[rows.label].append(rows)

    def innovations(self, block: RunResult) -> None:
        if block.innovations:
            self._innovations[block.label].append(block)

    def abort(self) -> None:
        return None

    def results(self) -> dict[str, RunResult]:
        """The whole run of each filter (its blocks' estimates and innovations)."""
        out = {}
        for label in list(self._rows):
            blocks = self._rows.pop(label)  # let go of as they are joined
            full = [b for b in blocks if b.t.size] or blocks[:1]
            del blocks
            rows = full[0] if len(full) == 1 else concat(full, consume=True)
            del full
            out[label] = dataclasses.replace(
                rows, innovations=concat_innovations(self._innovations[label]))
        return out


@dataclasses.dataclass
class FileRun:
    """What :func:`replay_file` hands back.

    Attributes
    ----------
    summaries : dict[str, dict]
        Each filter's summary (:meth:`navreplay.metrics.RunSummary.result`, then its settings:
        :func:`navreplay.filters.settings.summary_entries`), by label; empty without scoring.
    has_truth : bool
        A truth (or reference) stream was scored against.
    salvaged : bool
        Messages were lost to damage.
    coverage : float or None
        Fraction of the recording replayed (:meth:`navreplay.io.source.Source.coverage`).
    reference_coverage : dict[str, float]
        With a truth: the fraction of each filter's outputs that it scores, by label
        (:func:`navreplay.metrics.coverage.add_coverage` puts it into a summary).
    """

    summaries: dict[str, dict[str, Any]]
    has_truth: bool
    salvaged: bool
    coverage: float | None
    reference_coverage: dict[str, float] = dataclasses.field(default_factory=dict)


def replay_file(
    source: Source,
    specs: Sequence[FilterSpec],
    *,
    stages: Sequence[Stage] = (),
    output_rate: float | None = 10.0,
    pacing: float | None = None,
    max_imu_gap: float | None = None,
    live: bool = False,
    observe_interval: float = 0.25,
    progress: Progress | None = None,
    score: bool = True,
    smooth: bool = False,
    scratch: Path | None = None,
) -> FileRun:
    """Replay every filter over a recording, window by window, feeding the stages.

    Parameters
    ----------
    source : Source
        The recording (:func:`navreplay.io.open_recording`,
        :func:`navreplay.logs.prepare.open_log`, :class:`~navreplay.io.source.MemorySource`);
        read here, once, and closed.
    specs : sequence of FilterSpec
        The filters (labels unique); each filter is built, and its streams checked, before
        any replays.
    stages : sequence of Stage
        The outputs, fed block by block.
    output_rate : float or None
        Output tick rate [Hz] where no aiding sample falls.
    pacing : float, optional
        Replay at this multiple of real time (live viewing).
    max_imu_gap : float, optional
        Longest IMU gap [s] a filter bridges.
    live : bool
        Hand the estimates to the stages as they come (about every ``observe_interval``
        seconds of wall time), not only window by window.
    progress : callable, optional
        ``progress(done, total)``: seconds of the recording replayed by all filters so far,
        over their total (events when the recording's length is not known).
    score : bool
        Score the estimates against the truth (without: the stages get the rows unscored and
        there is no summary).
    smooth : bool
        Also smooth every filter that declares
        :class:`~navreplay.filters.smoothable.Smoothable` (a fixed-interval RTS smoother,
        :mod:`navreplay.replay.smoothing`): its smoothed run, labelled ``LABEL/rts``, follows
        its forward run through the scoring and the stages once the last window is replayed.
        The forward pass is stored on disk in chunks, in a temporary directory under
        ``scratch`` (the system's temporary directory by default), removed at the end.

    Returns
    -------
    FileRun

    Raises
    ------
    RecordingError, ReplayError, FilterDivergedError, ParamError
        As the source and :class:`~navreplay.replay.session.ReplaySession` raise them; the
        stages are aborted first and the source closed.
    """
    labels = [s.label for s in specs]
    smoothed = [k for k, spec in enumerate(specs)
                if smooth and is_smoothable(spec.filter_cls)] if smooth else []
    all_labels = [x for k, label in enumerate(labels)
                  for x in ((label, smoothed_label(label)) if k in smoothed else (label,))]
    dupes = sorted({x for x in all_labels if all_labels.count(x) > 1})
    if dupes:
        raise ValueError(f"filter labels must be unique; repeated: {', '.join(dupes)}")
    with contextlib.ExitStack() as temporary:
        stores: dict[int, ForwardStore] = {}
        truth_store: TruthStore | None = None
        if smoothed:
            tmp = Path(temporary.enter_context(tempfile.TemporaryDirectory(
                prefix="navreplay-rts-", dir=scratch)))
            truth_store = TruthStore(tmp)
            for k in smoothed:
                (tmp / str(k)).mkdir()
                stores[k] = ForwardStore(tmp / str(k))
        return _replay_file(source, specs, all_labels, stages, stores, truth_store,
                            output_rate=output_rate, pacing=pacing, max_imu_gap=max_imu_gap,
                            live=live, observe_interval=observe_interval, progress=progress,
                            score=score)
    raise AssertionError("unreachable")


def _replay_file(
    source: Source, specs: Sequence[FilterSpec], all_labels: list[str],
    stages: Sequence[Stage], stores: dict[int, ForwardStore], truth_store: TruthStore | None,
    *, output_rate: float | None, pacing: float | None, max_imu_gap: float | None,
    live: bool, observe_interval: float, progress: Progress | None, score: bool,
) -> FileRun:
    try:
        first = next(source)
        t0_ns, metadata = first.t0_ns, first.metadata
        has_truth = StreamKind.TRUTH in first
        try:
            outages = recorded_outages(metadata.extra)
        except ValueError as e:
            raise RecordingError(f"{source.name}: {e}") from None
        tracker = _Progress(progress, len(specs) + len(source.recorded), first, len(stores))
        scorers: list[RunScorer | None] = []
        sessions = []
        for k, spec in enumerate(specs):
            scorer = (RunScorer(spec.label, t0_ns, metadata.true_errors, has_truth,
                                outages=outages, scored=_fan_out(stages)) if score else None)
            scorers.append(scorer)
            sessions.append(ReplaySession(
                first, spec, source=source.name, output_rate=output_rate, pacing=pacing,
                max_imu_gap=max_imu_gap, observe_interval=observe_interval,
                live=_live(scorer, stages) if live else None,
                progress=tracker.of(k) if progress is not None else None,
                smoothing=stores.get(k)))
        columns = {st.truth.column: st.unit for s in sessions for st in s.states
                   if isinstance(st.truth, TruthColumn)}
        late = {smoothed_label(sessions[k].label): sessions[k].label for k in stores}
        runs: list[ReplaySession | RecordedSession] = list(sessions)
        for solution in source.recorded:  # the log's own solutions, rows beside the filters
            if solution.label in all_labels:
                raise ValueError(f"filter labels must be unique; {solution.label} is a filter's "
                                 "and a recorded solution's")
            runs.append(RecordedSession(solution, source=source.name, t0_ns=t0_ns))
            scorers.append(RunScorer(solution.label, t0_ns, metadata.true_errors, has_truth,
                                     outages=outages, scored=_fan_out(stages))
                           if score else None)
        labels = [*all_labels, *(r.label for r in runs[len(sessions):])]
        start = RunStart(source.name, tuple(labels), t0_ns, has_truth, metadata, columns,
                         late, outages)
        for stage in stages:
            stage.start(start)
        piece_outputs = max([PIECE_OUTPUTS, *(getattr(s, "piece_outputs", 0) for s in stages)])
        estimates = [0] * len(runs)
        window: Window | None = first
        del first  # each window goes once it is replayed
        keep_empty = True
        while window is not None:
            known = {k: (COMPLETE if window.final else t) for k, t in window.known.items()}
            for piece, piece_known, final in _pieces(window, known, output_rate, piece_outputs,
                                                     keep_empty=keep_empty):
                truth = piece.get(StreamKind.TRUTH)
                if truth is not None and len(truth):
                    for stage in stages:
                        stage.truth(truth)
                    if truth_store is not None:
                        truth_store.add(truth)
                for k, (session, scorer) in enumerate(zip(runs, scorers, strict=True)):
                    if scorer is not None:
                        scorer.add_truth(truth, final=final)
                    block = session.feed(piece, final=final, known=piece_known)
                    estimates[k] += block.t.shape[0] + session.live_rows
                    for stage in stages:
                        stage.innovations(block)
                    if scorer is not None:
                        scorer.add(block)
                    else:
                        rows = block.rows(0, block.t.shape[0])
                        for stage in stages:
                            stage.rows(rows, None, None)
                    if final and estimates[k] == 0:
                        empty = block.rows(0, 0)  # no estimate at all: the outputs' headers
                        for stage in stages:
                            stage.rows(empty, None, None)
                    del block  # handed over: not held while the next run replays its piece
                del piece, truth  # the piece's estimates go before the next is replayed
            keep_empty = False
            tracker.window(window)
            window = None if window.final else next(source)
        summaries = {run.label: {**scorer.result(), **_row_entries(run)}
                     for scorer, run in zip(scorers, runs, strict=True) if scorer is not None}
        covered = {run.label: scorer.coverage() for scorer, run in zip(scorers, runs, strict=True)
                   if scorer is not None and has_truth}
        for i, (k, store) in enumerate(stores.items()):
            session = sessions[k]
            label = smoothed_label(session.label)
            scorer = (RunScorer(label, t0_ns, metadata.true_errors, has_truth,
                                outages=outages, scored=_fan_out(stages)) if score else None)
            paths = backward(store, session.filter,  # type: ignore[arg-type]
                             tracker.smoothed(i, store.epochs, scoring=False))
            meta = {**session._meta, "label": label, "scored_extras": (), "measurements": (),
                    "navigation": session.navigation}
            _feed_smoothed(smoothed_blocks(paths, meta), truth_store, scorer, stages,
                           has_truth, tracker.smoothed(i, store.epochs, scoring=True))
            if scorer is not None:
                summaries[label] = {**scorer.result(), **summary_entries(session.settings)}
                if has_truth:
                    covered[label] = scorer.coverage()
        summaries = {x: summaries[x] for x in labels if x in summaries}
    except BaseException:
        source.close()  # the reader's warnings so far, before the error
        for stage in stages:
            stage.abort()
        raise
    source.close()
    return FileRun(summaries, has_truth, source.salvaged, source.coverage(), covered)


def _row_entries(row: ReplaySession | RecordedSession) -> dict[str, Any]:
    """A row's entries of the summary beside its scores: a filter's settings, or what a
    recorded solution is."""
    if isinstance(row, RecordedSession):
        return {"recorded": row.solution.source}
    return summary_entries(row.settings)


PIECE_OUTPUTS = 1_000
"""Output ticks (at the output rate) of the longest piece of a window fed to the filters at
once: a block of estimates carries a covariance per row, so at high output rates a reader's
window (about 20 000 IMU samples) is replayed in pieces of bounded memory. A stage may ask
for longer ones (:class:`Stage`: the view, whose work is partly per block)."""


def _pieces(window: Window, known: dict[StreamKind, int], output_rate: float | None,
            piece_outputs: int = PIECE_OUTPUTS, *, keep_empty: bool
            ) -> Iterator[tuple[dict[StreamKind, Stream], dict[StreamKind, int], bool]]:
    """A window as consecutive pieces of at most ``piece_outputs`` output ticks of the
    IMU's time: (streams, the time each is known to, final). The pieces are what a reader of
    shorter windows would hand over; the estimates do not depend on where the cuts fall.
    ``keep_empty``: the first piece keeps every stream (the first window holds every stream
    read), later ones only those with rows."""
    imu = window.get(StreamKind.IMU)
    span = int(piece_outputs / output_rate * 1e9) if output_rate else 0
    if not span or imu is None or len(imu) < 2 or int(imu.t_ns[-1] - imu.t_ns[0]) <= span:
        yield window, known, window.final
        return
    cuts = np.arange(int(imu.t_ns[0]) + span, int(imu.t_ns[-1]), span, dtype=np.int64)
    lo = dict.fromkeys(window, 0)
    for i, cut in enumerate([*cuts.tolist(), None]):
        streams = {}
        for kind, s in window.items():
            hi = len(s) if cut is None else int(np.searchsorted(s.t_ns, cut, side="right"))
            if hi > lo[kind] or (keep_empty and i == 0):
                streams[kind] = s.slice(lo[kind], hi)
            lo[kind] = hi
        if cut is None:
            yield streams, known, window.final
        else:
            yield streams, {k: min(t, cut) for k, t in known.items()}, False


def _feed_smoothed(blocks: Iterator[RunResult], truth: TruthStore | None,
                   scorer: RunScorer | None, stages: Sequence[Stage], has_truth: bool,
                   progress: Callable[[int], None] | None = None) -> None:
    """A smoothed run through its scorer and the stages, its blocks interleaved with the truth
    windows stored by the forward pass (so that the scorer keeps only the truth around them);
    ``progress(rows)`` after each block."""
    def add(block: RunResult) -> None:
        for stage in stages:
            stage.innovations(block)
        if scorer is not None:
            scorer.add(block)
        else:
            for stage in stages:
                stage.rows(block, None, None)
        if progress is not None:
            progress(block.t.shape[0])

    pending = next(blocks, None)
    if pending is None:
        return
    if scorer is not None and has_truth and truth is not None:
        t0_ns = pending.t0_ns
        for window in truth:
            scorer.add_truth(window)
            limit = (int(window.t_ns[-1]) - t0_ns) * 1e-9
            while pending is not None and (not pending.t.size or pending.t[0] <= limit):
                add(pending)
                pending = next(blocks, None)
        scorer.add_truth(None, final=True)
    while pending is not None:
        add(pending)
        pending = next(blocks, None)


def _fan_out(stages: Sequence[Stage]
             ) -> Callable[[RunResult, RunMetrics | None, Stream | None], None]:
    def scored(rows: RunResult, m: RunMetrics | None, truth: Stream | None) -> None:
        for stage in stages:
            stage.rows(rows, m, truth)

    return scored


def _live(scorer: RunScorer | None, stages: Sequence[Stage]) -> Callable[[RunResult], None]:
    """The live view of a session: its rows, scored as far as the truth allows."""
    def rows(block: RunResult) -> None:
        if scorer is not None:
            scorer.add(block)
        else:
            for stage in stages:
                stage.rows(block, None, None)

    return rows


class _Progress:
    """Progress over the rows (the filters, and the recorded solutions, which follow the
    windows): seconds of the recording replayed, over the rows' total
    (events, when the recording's length is not known), then the smoothed runs: each one's
    backward pass and scoring count for :data:`~navreplay.replay.smoothing.BACKWARD_COST` and
    :data:`~navreplay.replay.smoothing.SCORING_COST` of a forward pass, by epochs done, so the
    bar reaches its end when the last smoothed run is scored."""

    def __init__(self, progress: Progress | None, n: int, first: Window,
                 smoothed: int = 0) -> None:
        self.progress, self.n, self.runs_smoothed = progress, n, smoothed
        duration = first.metadata.params.get("duration")
        if not isinstance(duration, int | float) or not duration > 0:
            duration = ((first.end_ns - first.t0_ns) * 1e-9 if first.end_ns is not None
                        else None)
        self.duration = duration
        self.t0_ns = first.t0_ns
        self.events = [(0, 0)] * n

    def _forward(self) -> float:
        """The forward passes' length in the bar's units."""
        if self.duration is not None:
            return self.n * self.duration
        return float(sum(e[1] for e in self.events))

    def _total(self, forward: float) -> int:
        smoothing = self.runs_smoothed * (BACKWARD_COST + SCORING_COST) / max(self.n, 1)
        return int(forward * (1.0 + smoothing) + 1e-6)

    def of(self, k: int) -> Progress:
        def report(done: int, total: int) -> None:
            self.events[k] = (done, total)
            if self.duration is None and self.progress is not None:
                d = sum(e[0] for e in self.events)
                forward = max(d, self._forward())
                self.progress(d, max(self._total(forward), 1))

        return report

    def window(self, window: Window) -> None:
        if self.progress is None or self.duration is None:
            return
        imu = window.get(StreamKind.IMU)
        if window.final:
            done = self.duration
        elif imu is not None and len(imu):
            done = min((int(imu.t_ns[-1]) - self.t0_ns) * 1e-9, self.duration)
        else:
            return
        total = self._total(self._forward())
        self.progress(min(int(self.n * done), total), total)

    def smoothed(self, i: int, epochs: int, *, scoring: bool) -> Callable[[int], None] | None:
        """The progress of the i-th smoothed run's backward pass (or, with ``scoring``, of its
        scoring and staging) over its ``epochs``: ``report(epochs done since the last call)``."""
        if self.progress is None or epochs <= 0:
            return None
        progress, forward = self.progress, self._forward()
        total = self._total(forward)
        one = forward / self.n  # one filter's forward pass
        start = forward + one * (i * (BACKWARD_COST + SCORING_COST)
                                 + (BACKWARD_COST if scoring else 0.0))
        width = one * (SCORING_COST if scoring else BACKWARD_COST)
        seen = [0]

        def report(done: int) -> None:
            seen[0] += done
            progress(min(int(start + width * min(seen[0] / epochs, 1.0) + 1e-6), total),
                     total)

        return report


def replay(
    recording: Recording,
    filter: FilterSpec | type[Filter],
    params: FilterParams | Mapping[str, Any] | None = None,
    *,
    label: str | None = None,
    source: str | None = None,
    output_rate: float | None = 10.0,
    pacing: float | None = None,
    validate: bool = True,
    progress: Progress | None = None,
    observer: Callable[[RunResult], None] | None = None,
    observe_interval: float = 0.25,
    max_imu_gap: float | None = None,
) -> RunResult:
    """Replay one filter over a recording in memory (the pipeline of :func:`replay_file` over
    one window, collected).

    Parameters
    ----------
    recording : Recording
        The streams; a file read with :func:`navreplay.io.read_recording` is already validated
        (pass ``validate=False`` to skip the second check).
    filter : FilterSpec or type[Filter]
        The filter: a spec, or a class (see :func:`navreplay.filters.registry.load_filter`).
    params : FilterParams or mapping, optional
        With a class: an instance of its ``Params``, or ``{name: value}`` (strings as from
        ``-p key=value`` are converted), or None for the defaults.
    label : str, optional
        Display label of the run (default: the filter's name).
    source : str, optional
        Name of the recording in messages and in the result (default: ``scenario#seed=N``).
    output_rate : float or None
        Output tick rate [Hz] where no aiding sample falls (:mod:`navreplay.replay.plan`);
        None or 0 for outputs at aiding samples only.
    pacing : float, optional
        Replay at this multiple of real time (1.0 = real time), for live viewing.
    validate : bool
        Check the recording for non-finite samples and non-increasing timestamps first.
    progress : callable, optional
        ``progress(done, total)``, every few thousand events and at the end.
    observer : callable, optional
        Called with the estimates as they come (views valid during the call), about every
        ``observe_interval`` seconds of wall time.
    max_imu_gap : float, optional
        Longest IMU gap [s] the filter may bridge (:mod:`navreplay.replay.gaps`).

    Returns
    -------
    RunResult
        Estimates at every event (times from :attr:`Estimate.t`), innovations per measurement
        with their NIS.

    Raises
    ------
    MissingStreamError, InvalidRecordingError, ParamError, FilterInitError, FilterFailedError,
    FilterOutputError, FilterDivergedError
        With one line naming the filter, the recording and the time
        (:mod:`navreplay.replay.errors`).
    """
    if isinstance(filter, FilterSpec):
        spec = filter if label is None else dataclasses.replace(filter, label=label)
    else:
        spec = FilterSpec.of(filter, params, label)
    name = source or ""
    src = MemorySource(recording, name)
    if validate:
        validate_recording(recording, src.name)
    stages: list[Stage] = [collect := Collect()]  # (no smoother here)
    if observer is not None:
        stages.append(_Observer(observer))
    replay_file(src, [spec], stages=stages, output_rate=output_rate, pacing=pacing,
                max_imu_gap=max_imu_gap, live=observer is not None,
                observe_interval=observe_interval, progress=progress, score=False)
    return collect.results()[spec.label]


class _Observer:
    """The rows of a replay handed to a callable as they come."""

    def __init__(self, fn: Callable[[RunResult], None]) -> None:
        self.fn = fn

    def start(self, run: RunStart) -> None:
        return None

    def truth(self, truth: Stream) -> None:
        return None

    def rows(self, rows: RunResult, metrics: RunMetrics | None, truth: Stream | None) -> None:
        if rows.t.size:
            self.fn(rows)

    def innovations(self, block: RunResult) -> None:
        return None

    def abort(self) -> None:
        return None
