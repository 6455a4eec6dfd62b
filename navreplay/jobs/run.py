"""``navreplay run``: replay filters over one recording (Rerun view and summary table) or over
several (in parallel: per-recording summaries and ensemble statistics)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from navreplay.campaign.ensemble import run_ensemble
from navreplay.campaign.tasks import RunOutput, RunTask, default_extract, file_tasks
from navreplay.core import params as _params
from navreplay.core.streams import Recording, StreamKind, seconds
from navreplay.filters.result import RunResult
from navreplay.filters.settings import setting_notes, summary_entries
from navreplay.io.checks import read_policy
from navreplay.jobs.report import DEFAULT_OUT, RunReport, write_json
from navreplay.jobs.results import Outputs
from navreplay.jobs.smooth import output_labels, partners, scratch_dir, unsmoothed_notes
from navreplay.metrics import tables
from navreplay.metrics.initial import format_initial_state, initial_state
from navreplay.replay.pipeline import replay_file
from navreplay.replay.session import Progress
from navreplay.replay.spec import FilterSpec
from navreplay.viz.options import (
    DRAWN_WINDOW_MESSAGES,
    VizMode,
    VizOptions,
    close_output,
    open_output,
)


@dataclasses.dataclass
class PerRun:
    """What a worker returns for one recording: per-filter metrics and scalar summaries."""

    metrics: dict[str, Any]
    summaries: dict[str, dict[str, Any]]
    initial: dict[str, Any] | None = None
    """The initial state the run started from (:func:`navreplay.metrics.initial.initial_state`)."""


def campaign_extract(
    recording: Recording, results: dict[str, RunResult], task: RunTask
) -> PerRun:
    """Extractor of ``navreplay run`` over several recordings and ``navreplay montecarlo``."""
    from navreplay.metrics.coverage import add_coverage, reference_coverage

    scored = default_extract(recording, results, task)
    summaries = {label: {**m.summary(), **summary_entries(results[label].settings)}
                 for label, m in scored.items()}
    if StreamKind.TRUTH in recording:
        t_ref = seconds(recording[StreamKind.TRUTH].t_ns, recording.t0_ns)
        for label, result in results.items():
            if label in summaries:
                add_coverage(summaries[label], label, reference_coverage(result.t, t_ref),
                             f"the reference of {task.source}")
    return PerRun(scored, summaries,
                  initial_state(recording.metadata.initial_nav, recording.t0_ns))


def salvaged_note(source: str, covered: float | None) -> str:
    """The note of a run over a recording salvaged from a damaged file."""
    part = "an unknown part" if covered is None else f"{100 * covered:.1f} %"
    return f"SALVAGED: {source} is damaged; replayed {part} of it"


MAX_OUTPUT_RATE = 1000.0
"""Highest ``--output-rate`` [Hz]: estimates between aiding samples faster than an IMU's rate
add nothing, and a run allocates its output rows at this rate times its length."""


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
        (:func:`navreplay.campaign.executors.make_executor`).
    command : str, optional
        The command line (shown in the report).
    smooth : bool
        Also smooth the filters that can be (``LABEL/rts``; :mod:`navreplay.jobs.smooth`).
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
    export_compression: str = "zstd"
    """Chunk compression of the estimates MCAP (``zstd``, ``lz4``, ``none``)."""
    export_reference: str = "output"
    """The reference exported at the output rate (``output``) or at its own (``full``)."""
    report_path: Path | None = None
    force: bool = False
    max_imu_gap: float | None = None
    executor: str = "process"
    command: str | None = None
    smooth: bool = False


def outputs_of(job: Any) -> Outputs:
    """The ``--export`` / ``--report`` outputs of a run or Monte Carlo job."""
    return Outputs(job.export_dir, job.report_path, job.force,
                   command=getattr(job, "command", None),
                   compression=getattr(job, "export_compression", "zstd"),
                   reference_rate=(job.output_rate if getattr(job, "export_reference", "full")
                                   == "output" else None))


def _check_files(paths: Sequence[Path]) -> None:
    for p in paths:
        if not Path(p).exists():
            raise FileNotFoundError(f"{p}: no such recording")


def run(job: RunJob, progress: Progress | None = None) -> RunReport:
    """Replay the filters over one recording (in this process, with Rerun output and a summary
    table) or over several (in parallel, per-recording summaries and ensemble statistics)."""
    if not job.recordings:
        raise _params.ParamError("no recording given")
    _check_files(job.recordings)
    if job.pacing is not None and not (0 < job.pacing < math.inf):
        raise _params.ParamError(f"--rate must be positive, got {job.pacing}")
    if not (0 < job.output_rate <= MAX_OUTPUT_RATE):
        raise _params.ParamError(f"--output-rate must be positive and at most "
                                 f"{MAX_OUTPUT_RATE:g} Hz, got {job.output_rate:g}")
    job = _with_needs(job)
    if len(job.recordings) == 1:
        with read_policy(job.log.policy):  # the IMU's range, --force-frame
            return _run_one(job, progress)
    if job.pacing is not None:
        raise _params.ParamError("--rate (paced replay) needs a single recording")
    if job.log is not None and job.log.onboard:
        raise _params.ParamError("--onboard needs a single recording")
    tasks = file_tasks(job.recordings, job.log)
    default = DEFAULT_OUT / "ensemble.rrd"
    title = (f"{', '.join(s.label for s in job.filters)} over {len(tasks)} recordings")
    return campaign(tasks, job.filters, job.viz, default, job.summary_path, job.workers,
                     progress, title, job.output_rate, per_run_table=True,
                     outputs=outputs_of(job), executor=job.executor,
                     max_imu_gap=job.max_imu_gap, smooth=job.smooth)


def _with_needs(job: RunJob) -> RunJob:
    """The job with its log options asking only for the initial solution its filters need."""
    from navreplay.filters.base import initial_parts
    from navreplay.logs.options import LogOptions

    needs = initial_parts([spec.filter_cls for spec in job.filters])
    return dataclasses.replace(job, log=dataclasses.replace(job.log or LogOptions(), needs=needs))


def _run_one(job: RunJob, progress: Progress | None) -> RunReport:
    """Replay the filters over one recording, window by window (memory flat in its length):
    the .rrd or the live view, the exports and the report's series fed block by block
    (:func:`navreplay.replay.replay_file`)."""
    from navreplay.logs.onboard import onboard_label
    from navreplay.logs.prepare import open_log, streams_needed
    from navreplay.metrics.coverage import add_coverage

    path = Path(job.recordings[0])
    classes = [spec.filter_cls for spec in job.filters]
    labels = [spec.label for spec in job.filters]
    labels += [onboard_label(s) for s in (job.log.onboard if job.log is not None else ())]
    source = open_log(path, job.log, kinds=streams_needed(classes, job.log),
                      window=DRAWN_WINDOW_MESSAGES if job.viz.draws else None)
    try:
        first = source.peek()  # read and made ready: the log's problems raised before output
    except BaseException:
        source.close()
        raise
    initial = initial_state(first.metadata.initial_nav, first.t0_ns)
    outputs = outputs_of(job)
    sink = open_output(job.viz, DEFAULT_OUT / f"{path.stem}.rrd", path.name)
    stages = [st for st in (sink, outputs) if st is not None]
    title = f"{', '.join(labels)} over {path.name}"
    try:
        done = replay_file(source, job.filters, stages=stages, output_rate=job.output_rate,
                           pacing=job.pacing, max_imu_gap=job.max_imu_gap,
                           live=job.viz.live or job.pacing is not None, progress=progress,
                           smooth=job.smooth, scratch=scratch_dir(job.export_dir))
        if done.has_truth:
            ref = getattr(job.log, "reference", None)
            for label, fraction in done.reference_coverage.items():
                add_coverage(done.summaries[label], label, fraction,
                             f"reference {ref}" if ref else "the truth")
        started = [f"initial state {format_initial_state(initial)}"] if initial else []
        notes = (list(source.notes) + started + setting_notes(done.summaries.values())
                 + (unsmoothed_notes(job.filters) if job.smooth else []))
        if done.salvaged:
            notes.append(salvaged_note(str(path), done.coverage))
        notes += outputs.write_run(done.summaries, title=title, log_notes=source.notes)
        if sink is not None and done.has_truth:
            sink.summaries(done.summaries)
        hint = close_output(sink, job.viz)
    except BaseException:
        outputs.abort()
        if sink is not None:
            sink.abort()
        raise
    summary = {"recording": str(path), "coverage": done.coverage, "salvaged": done.salvaged,
               "initial": initial, "filters": done.summaries}
    has_truth = done.has_truth
    if job.summary_path is not None:
        write_json(job.summary_path, summary)
        notes.append(f"Summary written to {job.summary_path}")
    table = tables.format_summaries(done.summaries)
    if not has_truth:
        table = "(no truth or reference: innovation statistics only)\n\n" + table
    return RunReport(title=f"{', '.join(labels)} over {path}", table=table, summary=summary,
                     viz=hint, notes=notes, sink=sink if job.viz.mode is VizMode.SERVE else None)


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
    smooth: bool = False,
) -> RunReport:
    """Run the tasks over the filters (:func:`navreplay.campaign.run_ensemble`) and report
    each filter's ensemble statistics (with ``smooth``, each smoothed run's beside its filter's,
    labelled ``LABEL/rts``): the text tables, the summary, the view, the exports and the
    report."""
    from navreplay import metrics
    from navreplay.replay.gaps import check_max_gap

    labels = output_labels(filters, smooth)
    outputs = outputs or Outputs()
    outputs.check(labels, ensemble=True)
    try:
        check_max_gap(max_imu_gap)
    except ValueError as e:
        raise _params.ParamError(str(e)) from None
    given: dict[str, Any] = {"max_imu_gap": max_imu_gap} if max_imu_gap is not None else {}
    if smooth:
        given["smooth"] = True
    if given:
        tasks = [dataclasses.replace(t, **given) for t in tasks]

    stats: dict[str, Any] = {label: metrics.EnsembleStats(label) for label in labels}
    rows: list[dict[str, Any]] = []
    notes: list[str] = unsmoothed_notes(filters) if smooth else []
    settings: dict[str, dict[str, Any]] = {}  # each filter's, from its first run

    drill: dict[int, Any] = {}  # per-run metrics for the view when the runs are kept

    def collect(out: RunOutput) -> None:
        per: PerRun = out.metrics
        if tasks[out.index].keep:
            drill[out.index + 1] = per.metrics
        rows.append({"run": out.index + 1, "recording": out.source, "seed": out.seed,
                     "seconds": out.seconds, "coverage": out.coverage,
                     "salvaged": out.salvaged, "initial": per.initial,
                     "filters": per.summaries})
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

            declared = {spec.label: getattr(spec.filter_cls, "states", None) for spec in filters}
            of = partners(filters, smooth)
            for label, result in ens.items():
                states = declared.get(of.get(label, label))
                log_ensemble(sink, label, result, states if isinstance(states, tuple) else None)
            log_runs(sink, drill)
        hint = close_output(sink, viz_options)
    except BaseException:
        if sink is not None:
            sink.abort()
        raise
    ensemble = {label: {**e.summary(), **settings.get(label, {})} for label, e in ens.items()}
    summary = {"runs": rows, "ensemble": ensemble, "wall_seconds": done.seconds}
    notes += outputs.write_ensemble(ens, ensemble, title=title)
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
