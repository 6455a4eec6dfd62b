"""``navreplay run``: replay filters over one recording (Rerun view and summary table) or over
several (in parallel: per-recording summaries and ensemble statistics)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay import params as _params
from navreplay import tables
from navreplay.filters.settings import setting_notes, summary_entries
from navreplay.jobs.report import DEFAULT_OUT, RunReport, write_json
from navreplay.jobs.results import Outputs
from navreplay.replay.engine import Progress, check_streams, replay
from navreplay.replay.ensemble import (
    FilterSpec,
    RunOutput,
    RunTask,
    default_extract,
    file_tasks,
    run_ensemble,
)
from navreplay.replay.result import RunResult
from navreplay.streams import Recording, StreamKind
from navreplay.viz.options import VizMode, VizOptions, close_output, open_output


@dataclasses.dataclass
class PerRun:
    """What a worker returns for one recording: per-filter metrics and scalar summaries."""

    metrics: dict[str, Any]
    summaries: dict[str, dict[str, Any]]


def campaign_extract(
    recording: Recording, results: dict[str, RunResult], task: RunTask
) -> PerRun:
    """Extractor of ``navreplay run`` over several recordings and ``navreplay montecarlo``."""
    scored = default_extract(recording, results, task)
    return PerRun(scored, {label: {**m.summary(), **summary_entries(results[label].settings)}
                           for label, m in scored.items()})


def salvaged_note(source: str, covered: float | None) -> str:
    """The note of a run over a recording salvaged from a damaged file."""
    part = "an unknown part" if covered is None else f"{100 * covered:.1f} %"
    return f"SALVAGED: {source} is damaged; replayed {part} of it"


@dataclasses.dataclass(frozen=True)
class RunJob:
    """``navreplay run``.

    Attributes
    ----------
    filters : tuple of FilterSpec
    recordings : tuple of Path
    viz : VizOptions
        Default: save ``out/<recording>.rrd`` (``out/ensemble.rrd`` for several recordings).
    summary_path : Path, optional
        Write the summary as JSON.
    workers : int
        Processes for several recordings.
    pacing : float, optional
        Replay at this multiple of real time (live viewing of one recording).
    output_rate : float
        Output rate where no aiding sample falls [Hz].
    log : LogOptions, optional
        Topics, frames, ``--init`` and ``--reference`` (:mod:`navreplay.logs.options`).
    export_dir, report_path : Path, optional
        ``--export DIR`` and ``--report FILE.html`` (:mod:`navreplay.jobs.results`).
    force : bool
        Overwrite existing export and report files.
    max_imu_gap : float, optional
        Longest IMU gap a filter bridges [s] (:mod:`navreplay.replay.gaps`).
    executor : str
        Where several recordings run: ``process``, ``dask`` or ``dask://HOST:PORT``
        (:func:`navreplay.replay.ensemble.make_executor`).
    """

    filters: tuple[FilterSpec, ...]
    recordings: tuple[Path, ...]
    viz: VizOptions = VizOptions()
    summary_path: Path | None = None
    workers: int = 1
    pacing: float | None = None
    output_rate: float = 10.0
    log: Any = None
    export_dir: Path | None = None
    report_path: Path | None = None
    force: bool = False
    max_imu_gap: float | None = None
    executor: str = "process"


def outputs_of(job: Any) -> Outputs:
    """The ``--export`` / ``--report`` outputs of a run or Monte Carlo job."""
    return Outputs(job.export_dir, job.report_path, job.force)


def _check_files(paths: Sequence[Path]) -> None:
    from navreplay.io.reader import is_rosbag

    for p in paths:
        if not (Path(p).is_file() or (Path(p).is_dir() and is_rosbag(Path(p)))):
            what = ("is a directory, not a recording or rosbag2 folder" if Path(p).is_dir()
                    else "no such recording")
            raise FileNotFoundError(f"{p}: {what}")


def run(job: RunJob, progress: Progress | None = None) -> RunReport:
    """Replay the filters over one recording (in this process, with Rerun output and a summary
    table) or over several (in parallel, per-recording summaries and ensemble statistics)."""
    if not job.recordings:
        raise _params.ParamError("no recording given")
    _check_files(job.recordings)
    if job.pacing is not None and not (0 < job.pacing < math.inf):
        raise _params.ParamError(f"--rate must be positive, got {job.pacing}")
    if not (0 < job.output_rate < math.inf):
        raise _params.ParamError(f"--output-rate must be positive, got {job.output_rate}")
    job = _with_needs(job)
    if len(job.recordings) == 1:
        return _run_streamed(job, progress) or _run_one(job, progress)
    if job.pacing is not None:
        raise _params.ParamError("--rate (paced replay) needs a single recording")
    tasks = file_tasks(job.recordings, job.log)
    default = DEFAULT_OUT / "ensemble.rrd"
    title = (f"{', '.join(s.label for s in job.filters)} over {len(tasks)} recordings")
    return campaign(tasks, job.filters, job.viz, default, job.summary_path, job.workers,
                     progress, title, job.output_rate, per_run_table=True,
                     outputs=outputs_of(job), executor=job.executor,
                     max_imu_gap=job.max_imu_gap)


def _with_needs(job: RunJob) -> RunJob:
    """The job with its log options asking only for the initial solution its filters need."""
    from navreplay.filters.base import initial_parts
    from navreplay.logs.options import LogOptions

    needs = initial_parts([spec.load() for spec in job.filters])
    return dataclasses.replace(job, log=dataclasses.replace(job.log or LogOptions(), needs=needs))


def _run_streamed(job: RunJob, progress: Progress | None) -> RunReport | None:
    """Replay one intact MCAP file window by window (memory flat in its length): the .rrd or
    the live view logged, the exports written and the report's series kept block by block;
    None when the run needs the whole recording (a reference, paced replay, a rosbag2 folder
    or a damaged file): :func:`_run_one` then reads it whole."""
    from navreplay.filters.base import TruthColumn
    from navreplay.io.reader import is_rosbag
    from navreplay.io.windows import COMPLETE, NotStreamable, Window, read_windows, streamable
    from navreplay.logs.options import LogOptions
    from navreplay.logs.prepare import make_ready
    from navreplay.replay.engine import ReplaySession
    from navreplay.replay.streaming import RunningSummary
    from navreplay.streams import FIELDS, Stream

    path = Path(job.recordings[0])
    options = job.log or LogOptions()
    if (job.pacing is not None or options.reference is not None or is_rosbag(path)
            or not streamable(path)):
        return None
    classes = [spec.load() for spec in job.filters]
    sources: dict[StreamKind, Any] = {}
    windows = read_windows(path, decoded_kinds(classes, options), topics=options.topics,
                           frames=options.stream_frames, time=options.time, sources=sources)
    try:
        window: Window = next(windows)
    except NotStreamable:
        return None
    metadata = window.metadata
    metadata.extra.setdefault("source", str(path))
    # every kind the file holds (empty if not decoded or not in the first window): the filters
    # see the streams of the whole recording
    empty = {k: Stream(k, np.zeros(0, np.int64),
                       {c: np.zeros((0, *f.shape)) for c, f in FIELDS.get(k, {}).items()})
             for k in window.present}
    merged = {**empty, **window}
    head = Recording({k: merged[k] for k in StreamKind if k in merged}, metadata,
                     window.t0_ns)
    notes = make_ready(head, sources, options)
    has_truth = StreamKind.TRUTH in head
    labels = [spec.label for spec in job.filters]
    outputs = outputs_of(job)
    outputs.check(labels, ensemble=False, has_reference=has_truth)
    sessions = [ReplaySession(head, cls, spec.params, label=spec.label, source=str(path),
                              output_rate=job.output_rate, validate=False,
                              max_imu_gap=job.max_imu_gap)
                for spec, cls in zip(job.filters, classes, strict=True)]
    t0_ns = head.t0_ns
    del head
    sink = open_output(job.viz, DEFAULT_OUT / f"{path.stem}.rrd", path.name)

    def scored(rows: RunResult, m: Any, truth: Any) -> None:
        if sink is not None:
            sink.log_block(rows, m, truth)
        outputs.rows(rows, m)

    scores = [RunningSummary(spec.label, t0_ns, metadata.true_errors, has_truth,
                             scored=scored)
              for spec in job.filters]
    columns = {st.truth.column: st.unit for session in sessions for st in session.states
               if isinstance(st.truth, TruthColumn)}
    duration = float(metadata.params.get("duration") or 0.0)
    title = f"{', '.join(labels)} over {path.name}"
    try:
        outputs.start_run(labels, has_reference=has_truth, source=str(path))
        aiding: dict[StreamKind, Stream] = {}  # the first window's are in the sessions
        while True:
            following = next(windows, None)
            final = following is None
            imu, truth = window.get(StreamKind.IMU), window.get(StreamKind.TRUTH)
            known = {k: (COMPLETE if final else t) for k, t in window.known.items()}
            if sink is not None and truth is not None and len(truth):
                sink.log_truth_window(truth, t0_ns, columns)
            for session, score in zip(sessions, scores, strict=True):
                block = session.feed(imu, final=final, aiding=aiding, known=known)
                if sink is not None:
                    sink.log_innovations(block)
                outputs.innovations(block)
                score.add(block)
                score.add_truth(truth, final=final)
                if final and not score.rows:  # no estimate at all: the files' headers
                    outputs.rows(dataclasses.replace(block, innovations={}))
            if truth is not None and len(truth):  # after the estimates it covers: written
                outputs.truth(truth)              # at once, not queued behind them
            if progress is not None and imu is not None and len(imu) and duration > 0:
                done = (int(imu.t_ns[-1]) - t0_ns) * 1e-9
                progress(min(int(done), int(duration)), int(duration))
            if final:
                break
            window = following
            aiding = window
        summaries = {spec.label: {**score.summary(), **summary_entries(session.settings)}
                     for spec, score, session in zip(job.filters, scores, sessions, strict=True)}
        notes += setting_notes(summaries.values())
        notes += outputs.write_run(summaries, title=title)
        hint = close_output(sink, job.viz)
    except BaseException:
        windows.close()  # the reader's warnings so far, before the error
        outputs.abort()
        if sink is not None:
            sink.abort()
        raise
    summary = {"recording": str(path), "coverage": 1.0, "salvaged": False,
               "filters": summaries}
    if job.summary_path is not None:
        write_json(job.summary_path, summary)
        notes.append(f"Summary written to {job.summary_path}")
    table = tables.format_summaries(summaries)
    if not has_truth:
        table = "(no truth or reference: innovation statistics only)\n\n" + table
    return RunReport(title=f"{', '.join(labels)} over {path}", table=table, summary=summary,
                     viz=hint, notes=notes, sink=sink if job.viz.mode is VizMode.SERVE else None)


def decoded_kinds(classes: Sequence[type], options: Any) -> set[StreamKind]:
    """The streams a streamed run decodes: IMU and truth, those the filters consume (all for
    a filter that declares none) and those the frame checks and the initialisation read."""
    from navreplay.replay.engine import consumed_streams

    kinds = {StreamKind.IMU, StreamKind.TRUTH}
    for cls in classes:
        consumed = consumed_streams(cls)
        kinds |= set(StreamKind) if consumed is None else set(consumed)
    if options.check_frames or options.init is not None or options.initial:
        kinds |= {StreamKind.GPS, StreamKind.GPS_VEL, StreamKind.MAG}
    return kinds


def _run_one(job: RunJob, progress: Progress | None) -> RunReport:
    from navreplay import metrics
    from navreplay.io.integrity import coverage
    from navreplay.logs.prepare import open_log

    path = Path(job.recordings[0])
    classes = [spec.load() for spec in job.filters]
    prepared = open_log(path, job.log)
    recording = prepared.recording
    for cls in classes:
        check_streams(recording, cls, str(path))
    has_truth = StreamKind.TRUTH in recording
    outputs = outputs_of(job)
    outputs.check([s.label for s in job.filters], ensemble=False, has_reference=has_truth)
    n_filters = len(classes)
    summaries: dict[str, dict[str, Any]] = {}
    sink = open_output(job.viz, DEFAULT_OUT / f"{path.stem}.rrd", path.name)
    try:
        outputs.start_run([s.label for s in job.filters], has_reference=has_truth,
                          source=str(path))
        if has_truth:
            outputs.truth(recording[StreamKind.TRUTH])
        if sink is not None and has_truth:
            sink.log_truth(recording)
        for k, (spec, cls) in enumerate(zip(job.filters, classes, strict=True)):
            def prog(done: int, total: int, k: int = k) -> None:
                if progress is not None:
                    progress(k * total + done, n_filters * total)

            observer = None
            if sink is not None and (job.viz.live or job.pacing is not None):
                observer = sink.observer(recording if has_truth else None)
            result = replay(
                recording, cls, spec.params, label=spec.label, source=str(path),
                output_rate=job.output_rate, pacing=job.pacing, validate=False,
                progress=prog, observer=observer, max_imu_gap=job.max_imu_gap,
            )
            scored = metrics.run_metrics(result, recording)  # NIS only without a reference
            summaries[spec.label] = {**scored.summary(), **summary_entries(result.settings)}
            outputs.rows(result, scored if has_truth else None)  # with its innovations
            if sink is not None:
                sink.log_run(result, truth=recording if has_truth else None,
                             metrics=scored if has_truth else None)
        hint = close_output(sink, job.viz)
    except BaseException:
        outputs.abort()
        if sink is not None:
            sink.abort()
        raise
    covered = coverage(recording, prepared.salvaged)
    summary = {"recording": str(path), "coverage": covered, "salvaged": prepared.salvaged,
               "filters": summaries}
    notes = list(prepared.notes) + setting_notes(summaries.values())
    if prepared.salvaged:
        notes.append(salvaged_note(str(path), covered))
    notes += outputs.write_run(summaries,
                               title=f"{', '.join(s.label for s in job.filters)} over {path.name}")
    if job.summary_path is not None:
        write_json(job.summary_path, summary)
        notes.append(f"Summary written to {job.summary_path}")
    table = tables.format_summaries(summaries)
    if not has_truth:
        table = "(no truth or reference: innovation statistics only)\n\n" + table
    return RunReport(
        title=f"{', '.join(s.label for s in job.filters)} over {path}",
        table=table, summary=summary, viz=hint, notes=notes,
        sink=sink if job.viz.mode is VizMode.SERVE else None,
    )


def campaign(
    tasks: Sequence[RunTask],
    filters: Sequence[FilterSpec],
    viz_options: VizOptions,
    default_rrd: Path,
    summary_path: Path | None,
    workers: int,
    progress: Progress | None,
    title: str,
    output_rate: float,
    per_run_table: bool,
    outputs: Outputs | None = None,
    executor: str = "process",
    max_imu_gap: float | None = None,
) -> RunReport:
    from navreplay import metrics
    from navreplay.replay.gaps import check_max_gap

    outputs = outputs or Outputs()
    outputs.check([spec.label for spec in filters], ensemble=True)
    try:
        check_max_gap(max_imu_gap)
    except ValueError as e:
        raise _params.ParamError(str(e)) from None
    if max_imu_gap is not None:
        tasks = [dataclasses.replace(t, max_imu_gap=max_imu_gap) for t in tasks]

    stats: dict[str, Any] = {spec.label: metrics.EnsembleStats(spec.label) for spec in filters}
    rows: list[dict[str, Any]] = []
    notes: list[str] = []
    settings: dict[str, dict[str, Any]] = {}  # each filter's, from its first run

    drill: dict[int, Any] = {}  # per-run metrics for the view when the runs are kept

    def collect(out: RunOutput) -> None:
        per: PerRun = out.metrics
        if tasks[out.index].keep:
            drill[out.index + 1] = per.metrics
        rows.append({"run": out.index + 1, "recording": out.source, "seed": out.seed,
                     "seconds": out.seconds, "coverage": out.coverage,
                     "salvaged": out.salvaged, "filters": per.summaries})
        if out.salvaged:
            notes.append(salvaged_note(out.source, out.coverage))
        notes.extend(n for n in setting_notes(per.summaries.values()) if n not in notes)
        for label, s in per.summaries.items():
            settings.setdefault(label, {k: v for k, v in s.items() if k.startswith("settings")})
        for label, m in per.metrics.items():
            if label in stats:
                try:
                    stats[label].add(m)
                except ValueError as e:  # recordings of different lengths or rates
                    del stats[label]
                    notes.append(f"no ensemble statistics for {label}: {e}")

    sink = open_output(viz_options, default_rrd, title)
    try:
        done = run_ensemble(tasks, filters, collect, extract=campaign_extract,
                            workers=workers, executor=executor, progress=progress,
                            output_rate=output_rate)
        ens = {label: s.result() for label, s in stats.items() if s.runs}
        if sink is not None:
            from navreplay.viz.ensemble import log_ensemble, log_runs

            declared = {spec.label: getattr(spec.load(), "states", None) for spec in filters}
            for label, e in ens.items():
                states = declared.get(label)
                log_ensemble(sink, label, e, states if isinstance(states, tuple) else None)
            log_runs(sink, drill)
        hint = close_output(sink, viz_options)
    except BaseException:
        if sink is not None:
            sink.abort()
        raise
    summary = {
        "runs": rows,
        "ensemble": {label: {**e.summary(), **settings.get(label, {})}
                     for label, e in ens.items()},
        "wall_seconds": done.seconds,
    }
    notes += outputs.write_ensemble(ens, summary["ensemble"], title=title)
    if summary_path is not None:
        write_json(summary_path, summary)
    parts = []
    if per_run_table:
        names = [Path(r["recording"]).name for r in rows]
        if len(set(names)) < len(names):
            names = [f"{n} (run {r['run']})" for n, r in zip(names, rows, strict=True)]
        per_run = {f"{label} @ {name}": s
                   for name, r in zip(names, rows, strict=True)
                   for label, s in r["filters"].items()}
        keys = [k for k in tables.ERROR_KEYS if any(k in s for s in per_run.values())]
        parts.append("Per recording:\n" + tables.format_table(per_run, keys))
    if ens:
        parts.append(f"Ensemble over {done.runs} runs:\n"
                     + tables.format_summaries({label: e.summary() for label, e in ens.items()}))
    notes += [
        f"{done.runs} runs in {done.seconds:.1f} s wall ({done.run_seconds:.1f} s of run time, "
        f"{workers} worker(s)" + ("" if executor == "process" else f" on {executor}") + ")",
    ]
    if summary_path is not None:
        notes.append(f"Summary written to {summary_path}")
    return RunReport(title=title, table="\n\n".join(parts), summary=summary, viz=hint,
                     notes=notes, sink=sink if viz_options.mode is VizMode.SERVE else None)
