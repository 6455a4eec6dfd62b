"""The jobs behind the command line: one typed configuration and one function per command.

``navreplay.cli`` parses arguments into these configurations and makes one call; everything
else — reading recordings, replaying filters, metrics, Rerun output, summaries — happens here,
so the same jobs run from Python::

    from navreplay.jobs import RunJob, VizOptions, run
    from navreplay.replay.ensemble import FilterSpec

    report = run(RunJob(filters=(FilterSpec("gps-ins"),), recordings=(Path("x.mcap"),)))
    print(report.format())

Jobs never print; they return reports with a ``format()`` method and report progress through
a ``progress(done, total)`` callback.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import os
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from navreplay import params as _params
from navreplay.filters.registry import FilterLoadError, load_filter
from navreplay.replay.engine import build_params, check_streams, replay
from navreplay.replay.ensemble import (
    FilterSpec,
    RunOutput,
    RunTask,
    file_tasks,
    monte_carlo_tasks,
    run_ensemble,
)
from navreplay.replay.result import RunResult
from navreplay.streams import Recording, StreamKind

Progress = Callable[[int, int], None]

DEFAULT_OUT = Path("out")
"""Where derived outputs (.rrd, summaries, demo recordings) go by default."""


# --------------------------------------------------------------------------------------------
# parsing helpers shared by the commands


def split_filter_list(text: str) -> list[str]:
    """Split ``a,b[k=v,k2=1,2],c`` on the commas outside brackets.

    >>> split_filter_list("ins,gps-ins[gps_pos_sigma_scale=2,lever_arm_b=0.1,0,0]")
    ['ins', 'gps-ins[gps_pos_sigma_scale=2,lever_arm_b=0.1,0,0]']
    """
    items, depth, cur = [], 0, []
    for ch in text:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
            if depth < 0:
                raise _params.ParamError(f"filter list {text!r}: unbalanced ']'")
        if ch == "," and depth == 0:
            items.append("".join(cur).strip())
            cur = []
        else:
            cur.append(ch)
    if depth:
        raise _params.ParamError(f"filter list {text!r}: unbalanced '['")
    items.append("".join(cur).strip())
    if any(not it for it in items):
        raise _params.ParamError(f"filter list {text!r} has an empty entry")
    return items


def _inline_params(item: str) -> tuple[str, dict[str, str]]:
    """``name[k=v,k2=1,2,3]`` -> (name, {k: v, k2: "1,2,3"}): a comma-separated piece without
    ``=`` continues the previous value (a vector)."""
    if "[" not in item:
        return item, {}
    if not item.endswith("]"):
        raise _params.ParamError(f"filter {item!r}: text after ']'")
    ref, _, inner = item[:-1].partition("[")
    values: dict[str, str] = {}
    last: str | None = None
    for piece in inner.split(","):
        if "=" in piece:
            key, _, val = piece.partition("=")
            last = key.strip()
            values[last] = val.strip()
        elif last is not None:
            values[last] += "," + piece.strip()
        elif piece.strip():
            raise _params.ParamError(f"filter {item!r}: {piece!r} is not key=value")
    return ref.strip(), values


def filter_specs(
    names: str | None = None,
    refs: Sequence[str] = (),
    assignments: Sequence[str] = (),
    config: Mapping[str, Any] | None = None,
) -> tuple[FilterSpec, ...]:
    """Filter specs from the command line.

    Parameters
    ----------
    names : str, optional
        ``FILTER[,FILTER...]``; each may carry inline parameters, ``gps-ins[key=value,...]``,
        and is labelled by its text (so one filter can run in several variants).
    refs : sequence of str
        ``--filter package.module:Class`` references (labelled by the class's ``name``).
    assignments : sequence of str
        ``-p key=value`` items. With several filters, ``label.key=value`` or
        ``name.key=value`` targets one; a plain ``key=value`` goes to every filter that has
        the parameter (an error if none has it).
    config : mapping, optional
        A TOML document: ``[filter.<label or name>]`` tables of parameter values.

    Precedence: inline > ``-p`` > config > the filter's defaults. Every filter is loaded and its
    parameters are validated here, so mistakes surface before any work.
    """
    items = split_filter_list(names) if names else []
    parsed: list[tuple[str, str, dict[str, Any], type]] = []  # label, ref, inline, cls
    for item in items:
        ref, inline = _inline_params(item)
        parsed.append((item, ref, inline, load_filter(ref)))
    for ref in refs:
        cls = load_filter(ref)
        parsed.append((getattr(cls, "name", "") or ref.rpartition(":")[2], ref, {}, cls))
    if not parsed:
        raise _params.ParamError("no filter given (see `navreplay filters`)")
    labels = [p[0] for p in parsed]
    dupes = sorted({x for x in labels if labels.count(x) > 1})
    if dupes:
        raise _params.ParamError(
            f"filter {', '.join(dupes)} given twice; give variants their own parameters, "
            "e.g. gps-ins[gps_pos_sigma_scale=1],gps-ins[gps_pos_sigma_scale=2]"
        )
    values: list[dict[str, Any]] = [{} for _ in parsed]
    tables = dict((config or {}).get("filter", {}) or {})
    for i, (label, ref, _, cls) in enumerate(parsed):
        for key in (cls.name, ref, label):
            table = tables.get(key)
            if isinstance(table, Mapping):
                values[i].update(table)
    fields = [{f.name for f in dataclasses.fields(p[3].Params)} for p in parsed]
    for key, val in _params.parse_assignments(assignments).items():
        prefix, dot, name = key.rpartition(".")
        if dot:
            hit = [i for i, p in enumerate(parsed) if prefix in (p[0], p[1], p[3].name)]
            if not hit:
                raise _params.ParamError(
                    f"-p {key}: no filter {prefix!r} in this run (filters: {', '.join(labels)})"
                )
        elif len(parsed) == 1:
            hit = [0]
        else:
            hit = [i for i in range(len(parsed)) if name in fields[i]]
            if not hit:
                raise _params.ParamError(
                    f"-p {key}: none of the filters {', '.join(labels)} has a parameter {name!r}"
                )
        for i in hit:
            values[i][name] = val
    specs = []
    for (label, ref, inline, cls), vals in zip(parsed, values, strict=True):
        vals.update(inline)
        build_params(cls, vals)  # validate now
        specs.append(FilterSpec(ref, vals, label))
    return tuple(specs)


def scenario_values(
    assignments: Sequence[str] = (),
    config: Mapping[str, Any] | None = None,
    duration: float | None = None,
) -> dict[str, Any]:
    """Scenario parameter values: ``[scenario]`` table of a TOML config < ``-p`` < --duration."""
    values: dict[str, Any] = {}
    if config:
        table = config.get("scenario")
        if isinstance(table, Mapping):
            values.update(table)
    values.update(_params.parse_assignments(assignments))
    if duration is not None:
        values["duration"] = duration
    return values


def _check_scenario(scenario: str, values: Mapping[str, Any]) -> None:
    from navreplay.sim.scenario import get_scenario

    cls = get_scenario(scenario)
    _params.build(cls.Params, values, where=f"scenario {scenario}")


@contextmanager
def _atomic_path(path: Path) -> Iterator[Path]:
    """A temporary path beside ``path``, renamed onto it when the block succeeds."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}.part")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_json(path: Path, data: Any) -> None:
    """Write JSON atomically (NaN and infinities as null)."""
    with _atomic_path(path) as tmp:
        tmp.write_text(json.dumps(_jsonable(data), indent=2) + "\n")


def _jsonable(x: Any) -> Any:
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.generic):
        return _jsonable(x.item())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, enum.Enum):
        return x.value
    if isinstance(x, Path):
        return str(x)
    return x


# --------------------------------------------------------------------------------------------
# viewer options


class VizMode(enum.StrEnum):
    """Where the Rerun output goes."""

    SAVE = "save"
    SPAWN = "spawn"
    CONNECT = "connect"
    SERVE = "serve"
    NONE = "none"


@dataclasses.dataclass(frozen=True)
class VizOptions:
    """Rerun output of a job.

    Attributes
    ----------
    mode : VizMode
    path : Path, optional
        The .rrd file (SAVE); default chosen by the job (under ``out/``).
    url : str, optional
        Viewer address (CONNECT).
    """

    mode: VizMode = VizMode.SAVE
    path: Path | None = None
    url: str | None = None

    def target(self, default: Path) -> Any:
        """The :mod:`navreplay.viz` target, or None for no output."""
        from navreplay import viz

        if self.mode is VizMode.NONE:
            return None
        if self.mode is VizMode.SAVE:
            return viz.Save(self.path or default)
        if self.mode is VizMode.SPAWN:
            return viz.Spawn()
        if self.mode is VizMode.CONNECT:
            return viz.Connect(self.url) if self.url else viz.Connect()
        return viz.Serve()

    @property
    def live(self) -> bool:
        return self.mode in (VizMode.SPAWN, VizMode.CONNECT, VizMode.SERVE)


@contextmanager
def _sink(viz_options: VizOptions, default: Path, name: str) -> Iterator[Any]:
    """Open the Rerun sink (checking a viewer is reachable) or yield None."""
    target = viz_options.target(default)
    if target is None:
        yield None
        return
    from navreplay.viz import open_sink

    with open_sink(target, recording_name=name) as sink:
        yield sink


def _viz_hint(sink: Any, where: Any) -> str:
    if sink is None:
        return ""
    if getattr(sink, "web_url", None):
        return f"Rerun web viewer: {sink.web_url} (Ctrl-C to stop serving)"
    if getattr(sink, "path", None) is not None:
        return f"Rerun view saved to {where}; open it with: rerun {where}"
    return f"Rerun view sent to {where}"


# --------------------------------------------------------------------------------------------
# metrics (per run and over runs)


def run_summary(result: RunResult, recording: Recording) -> dict[str, Any]:
    """Scalar figures of one run against the recording's truth."""
    from navreplay import metrics

    return metrics.summarize(metrics.run_metrics(result, recording))


def run_errors(result: RunResult, recording: Recording) -> dict[str, Any]:
    """Error series for the Rerun view (``name -> (error, sigma)``)."""
    from navreplay import metrics

    return metrics.error_series(metrics.run_metrics(result, recording))


def summary_table(rows: Mapping[str, Mapping[str, Any]]) -> str:
    from navreplay import metrics

    return metrics.format_summary(rows)


@dataclasses.dataclass
class _PerRun:
    """What a worker returns for one recording: scalar summaries and the ensemble input."""

    summaries: dict[str, dict[str, Any]]
    ensemble: dict[str, Any]


def campaign_extract(
    recording: Recording, results: dict[str, RunResult], task: RunTask
) -> _PerRun:
    """Ensemble extractor of ``navreplay run``/``montecarlo``: summaries + time series input."""
    from navreplay import metrics

    summaries, ensemble = {}, {}
    for label, res in results.items():
        m = metrics.run_metrics(res, recording)
        summaries[label] = metrics.summarize(m)
        ensemble[label] = metrics.ensemble_input(m)
    return _PerRun(summaries, ensemble)


# --------------------------------------------------------------------------------------------
# reports


@dataclasses.dataclass
class RunReport:
    """Outcome of ``run``, ``montecarlo`` and the demo's replay.

    Attributes
    ----------
    title : str
    table : str
        Summary table(s).
    summary : dict
        JSON-ready figures (what ``--summary`` writes).
    viz : str
        Where the Rerun output went and how to open it ("" for none).
    notes : list[str]
        Further lines (failed runs, timing).
    sink : Any
        The Rerun sink when it must stay alive (``--serve``).
    """

    title: str
    table: str
    summary: dict[str, Any]
    viz: str = ""
    notes: list[str] = dataclasses.field(default_factory=list)
    sink: Any = None

    def format(self) -> str:
        parts = [self.title, "", self.table]
        parts += [n for n in self.notes if n]
        if self.viz:
            parts += ["", self.viz]
        return "\n".join(parts)


# --------------------------------------------------------------------------------------------
# simulate


@dataclasses.dataclass(frozen=True)
class SimulateJob:
    """``navreplay simulate``.

    Attributes
    ----------
    scenario : str
    output : Path
        The recording (``--runs 1``); with several runs, ``NAME_0001.mcap``... beside it, or
        ``<scenario>_0001.mcap``... inside it when it is a directory (or ends with ``/``).
    values : dict
        Scenario parameter values.
    seed : int
        Seed of the first run; run i uses ``seed + i``.
    runs : int
    force : bool
        Overwrite existing files.
    workers : int
    """

    scenario: str
    output: Path
    values: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    seed: int = 0
    runs: int = 1
    force: bool = False
    workers: int = 1

    def paths(self) -> list[Path]:
        out = Path(self.output)
        as_dir = out.is_dir() or str(self.output).endswith(("/", os.sep)) or not out.suffix
        if self.runs == 1 and not as_dir:
            return [out]
        if as_dir:
            return [out / f"{self.scenario}_{i + 1:04d}.mcap" for i in range(self.runs)]
        return [out.with_name(f"{out.stem}_{i + 1:04d}{out.suffix}") for i in range(self.runs)]


def _none_extract(recording: Recording, results: dict[str, RunResult], task: RunTask) -> None:
    return None


def simulate(job: SimulateJob, progress: Progress | None = None) -> list[Path]:
    """Simulate ``runs`` recordings and write them (atomically); returns their paths.

    Raises ``FileExistsError`` naming the first existing target before simulating anything
    (unless ``force``).
    """
    if job.runs < 1:
        raise _params.ParamError(f"--runs must be at least 1, got {job.runs}")
    _check_scenario(job.scenario, job.values)
    paths = job.paths()
    if not job.force:
        existing = [p for p in paths if p.exists()]
        if existing:
            more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
            raise FileExistsError(f"{existing[0]} exists{more}; use --force to overwrite")
    tasks = [
        RunTask(i, scenario=job.scenario, values=dict(job.values), seed=job.seed + i,
                keep=str(p), force=job.force)
        for i, p in enumerate(paths)
    ]
    run_ensemble(tasks, (), lambda out: None, extract=_none_extract,
                 workers=min(job.workers, len(tasks)), progress=progress)
    return paths


# --------------------------------------------------------------------------------------------
# run


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
    """

    filters: tuple[FilterSpec, ...]
    recordings: tuple[Path, ...]
    viz: VizOptions = VizOptions()
    summary_path: Path | None = None
    workers: int = 1
    pacing: float | None = None
    output_rate: float = 10.0


def _check_files(paths: Sequence[Path]) -> None:
    for p in paths:
        if not Path(p).is_file():
            what = "is a directory, not a recording" if Path(p).is_dir() else "no such recording"
            raise FileNotFoundError(f"{p}: {what}")


def run(job: RunJob, progress: Progress | None = None) -> RunReport:
    """Replay the filters over one recording (in this process, with Rerun output and a summary
    table) or over several (in parallel, per-recording summaries and ensemble statistics)."""
    if not job.recordings:
        raise _params.ParamError("no recording given")
    _check_files(job.recordings)
    if job.pacing is not None and not (job.pacing > 0):
        raise _params.ParamError(f"--rate must be positive, got {job.pacing}")
    if len(job.recordings) == 1:
        return _run_one(job, progress)
    if job.pacing is not None:
        raise _params.ParamError("--rate (paced replay) needs a single recording")
    tasks = file_tasks(job.recordings)
    default = DEFAULT_OUT / "ensemble.rrd"
    title = (f"{', '.join(s.label for s in job.filters)} over {len(tasks)} recordings")
    return _campaign(tasks, job.filters, job.viz, default, job.summary_path, job.workers,
                     progress, title, job.output_rate)


def _run_one(job: RunJob, progress: Progress | None) -> RunReport:
    from navreplay.io import read_recording

    path = Path(job.recordings[0])
    classes = [spec.load() for spec in job.filters]
    recording = read_recording(path)
    for cls in classes:
        check_streams(recording, cls, str(path))
    has_truth = StreamKind.TRUTH in recording
    default = DEFAULT_OUT / f"{path.stem}.rrd"
    n_filters = len(classes)
    summaries: dict[str, dict[str, Any]] = {}
    with _sink(job.viz, default, path.name) as sink:
        if sink is not None and has_truth:
            sink.log_truth(recording)
        for k, (spec, cls) in enumerate(zip(job.filters, classes, strict=True)):
            def prog(done: int, total: int, k: int = k) -> None:
                if progress is not None:
                    progress(k * total + done, n_filters * total)

            observer = None
            if sink is not None and job.viz.live:
                observer = sink.observer(recording if has_truth else None)
            result = replay(
                recording, cls, spec.params, label=spec.label, source=str(path),
                output_rate=job.output_rate, pacing=job.pacing, validate=False,
                progress=prog, observer=observer,
            )
            summaries[spec.label] = run_summary(result, recording) if has_truth else {}
            if sink is not None:
                errors = run_errors(result, recording) if has_truth else None
                sink.log_run(result, truth=recording if has_truth else None, metrics=errors)
            del result
        where = sink.close() if sink is not None and not isinstance(
            getattr(sink, "target", None), _serve_type()) else (sink.url if sink else None)
        hint = _viz_hint(sink, where)
    summary = {"recording": str(path), "filters": summaries}
    if job.summary_path is not None:
        write_json(job.summary_path, summary)
    table = summary_table(summaries) if has_truth else "(no truth in the recording: no errors)"
    notes = [f"Summary written to {job.summary_path}"] if job.summary_path else []
    return RunReport(
        title=f"{', '.join(s.label for s in job.filters)} over {path}",
        table=table, summary=summary, viz=hint, notes=notes,
        sink=sink if job.viz.mode is VizMode.SERVE else None,
    )


def _serve_type() -> type:
    from navreplay.viz import Serve

    return Serve


def _campaign(
    tasks: Sequence[RunTask],
    filters: Sequence[FilterSpec],
    viz_options: VizOptions,
    default_rrd: Path,
    summary_path: Path | None,
    workers: int,
    progress: Progress | None,
    title: str,
    output_rate: float,
) -> RunReport:
    from navreplay import metrics

    stats = {spec.label: metrics.EnsembleStats() for spec in filters}
    rows: list[dict[str, Any]] = []

    def sink_fn(out: RunOutput) -> None:
        per: _PerRun = out.metrics
        rows.append({"run": out.index + 1, "recording": out.source, "seed": out.seed,
                     "seconds": out.seconds, "filters": per.summaries})
        for label, item in per.ensemble.items():
            stats[label].add(item)

    with _sink(viz_options, default_rrd, title) as sink:
        done = run_ensemble(tasks, filters, sink_fn, extract=campaign_extract, workers=workers,
                            progress=progress, output_rate=output_rate)
        ens = {label: s.result() for label, s in stats.items()}
        if sink is not None:
            for label, e in ens.items():
                metrics.log_ensemble(sink, label, e)
        where = sink.close() if sink is not None else None
        hint = _viz_hint(sink, where)
    summary = {
        "runs": rows,
        "ensemble": {label: metrics.summarize_ensemble(e) for label, e in ens.items()},
        "wall_seconds": done.seconds,
        "failed": done.failed,
    }
    if summary_path is not None:
        write_json(summary_path, summary)
    table = metrics.format_ensemble({label: e for label, e in ens.items()})
    notes = [
        "",
        f"{done.runs} runs in {done.seconds:.1f} s wall ({done.run_seconds:.1f} s of worker "
        f"time, {workers} worker(s))",
    ]
    if summary_path is not None:
        notes.append(f"Summary written to {summary_path}")
    return RunReport(title=title, table=table, summary=summary, viz=hint, notes=notes)


# --------------------------------------------------------------------------------------------
# montecarlo


@dataclasses.dataclass(frozen=True)
class MonteCarloJob:
    """``navreplay montecarlo``: simulate and replay ``runs`` seeds in memory.

    Attributes
    ----------
    scenario : str
    filters : tuple of FilterSpec
    runs : int
    values : dict
        Scenario parameter values.
    seed : int
        Run i uses ``seed + i``.
    workers : int
    keep_dir : Path, optional
        Also write each run's recording here (``<scenario>_0001.mcap``, ...).
    force : bool
        Overwrite kept recordings.
    viz : VizOptions
        Default: save ``out/montecarlo-<scenario>.rrd`` (ensemble statistics).
    summary_path : Path, optional
    output_rate : float
    """

    scenario: str
    filters: tuple[FilterSpec, ...]
    runs: int
    values: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    seed: int = 0
    workers: int = 1
    keep_dir: Path | None = None
    force: bool = False
    viz: VizOptions = VizOptions()
    summary_path: Path | None = None
    output_rate: float = 10.0


def montecarlo(job: MonteCarloJob, progress: Progress | None = None) -> RunReport:
    """Run a Monte Carlo campaign and report per-filter ensemble statistics."""
    if job.runs < 1:
        raise _params.ParamError(f"--runs must be at least 1, got {job.runs}")
    _check_scenario(job.scenario, job.values)
    from navreplay.sim.scenario import get_scenario

    streams = set(get_scenario(job.scenario).streams)
    for spec in job.filters:
        cls = spec.load()
        missing = [str(k) for k in cls.requires if k not in streams]
        if missing:
            raise FilterLoadError(
                f"filter {spec.label!r} needs stream(s) {', '.join(missing)} that scenario "
                f"{job.scenario} does not simulate (it has: "
                f"{', '.join(str(k) for k in get_scenario(job.scenario).streams)})"
            )
    tasks = monte_carlo_tasks(job.scenario, job.runs, values=job.values, seed=job.seed,
                              keep_dir=job.keep_dir, force=job.force)
    if job.keep_dir is not None and not job.force:
        existing = [t.keep for t in tasks if t.keep and Path(t.keep).exists()]
        if existing:
            raise FileExistsError(f"{existing[0]} exists; use --force to overwrite")
    title = (f"Monte Carlo: {', '.join(s.label for s in job.filters)} on {job.scenario}, "
             f"{job.runs} runs, seeds {job.seed}..{job.seed + job.runs - 1}")
    return _campaign(tasks, job.filters, job.viz, DEFAULT_OUT / f"montecarlo-{job.scenario}.rrd",
                     job.summary_path, job.workers, progress, title, job.output_rate)


# --------------------------------------------------------------------------------------------
# demo

DEMO_SCENARIO = "vehicle-drive"
DEMO_FILTERS = ("ins", "gps-ins")
DEMO_SEED = 1


@dataclasses.dataclass(frozen=True)
class DemoJob:
    """``navreplay demo``: the README's main job.

    Attributes
    ----------
    out_dir : Path
        Recordings, the .rrd and the summary go here (regenerated on every run).
    reproductions : bool
        Also run the quick versions of the paper reproductions.
    workers : int
    view : bool or None
        Open a Rerun viewer on the saved file: None = only if one can be shown here.
    """

    out_dir: Path = DEFAULT_OUT
    reproductions: bool = True
    workers: int = 1
    view: bool | None = None


@dataclasses.dataclass
class DemoReport:
    """Sections of the demo's output, in order."""

    sections: list[str]
    rrd: Path | None
    viewer: str = ""
    failed_checks: int = 0

    def format(self) -> str:
        return "\n\n".join(self.sections)


def demo(
    job: DemoJob,
    progress: Callable[[str, int, int], None] | None = None,
) -> DemoReport:
    """Simulate the demo recording, replay its filters, run the quick reproductions, save one
    .rrd; ``progress(stage, done, total)``."""
    out = Path(job.out_dir)
    out.mkdir(parents=True, exist_ok=True)

    def stage(name: str) -> Progress | None:
        if progress is None:
            return None
        return lambda d, n: progress(name, d, n)

    rec_path = out / f"{DEMO_SCENARIO}.mcap"
    simulate(SimulateJob(DEMO_SCENARIO, rec_path, seed=DEMO_SEED, force=True),
             stage(f"simulate {DEMO_SCENARIO}"))
    rrd = out / "demo.rrd"
    report = run(
        RunJob(
            filters=tuple(FilterSpec(f) for f in DEMO_FILTERS),
            recordings=(rec_path,),
            viz=VizOptions(VizMode.SAVE, rrd),
            summary_path=out / "demo-summary.json",
        ),
        stage("replay " + ", ".join(DEMO_FILTERS)),
    )
    sections = [
        f"Recording: {rec_path} ({DEMO_SCENARIO}, seed {DEMO_SEED}); inspect it with "
        f"`navreplay info {rec_path}`",
        report.format(),
    ]
    failed = 0
    if job.reproductions:
        from navreplay import reproduce

        for name in reproduce.available():
            try:
                rep = reproduce.get(name)
            except ImportError:
                continue  # not built yet
            runs = getattr(rep, "quick_runs", None)
            result = rep.run(runs=runs, seed=0, workers=job.workers,
                             rrd=out / f"{name}.rrd", progress=stage(f"reproduce {name}"))
            failed += sum(not c.passed for c in result.checks)
            sections.append(
                f"{result.format()}\n\nRerun view: rerun {out / f'{name}.rrd'}"
            )
    viewer = ""
    if job.view is not False:
        viewer = _open_viewer(rrd, required=job.view is True)
    if viewer:
        sections.append(viewer)
    return DemoReport(sections, rrd, viewer, failed)


def _open_viewer(rrd: Path, *, required: bool) -> str:
    """Open the Rerun viewer on ``rrd`` when a display is available; say what happened."""
    import subprocess

    from navreplay.viz.sink import display_problem, find_viewer

    exe = find_viewer()
    problem = "no `rerun` viewer executable" if exe is None else display_problem()
    if problem is not None:
        if required:
            from navreplay.viz import VizUnavailableError

            raise VizUnavailableError(f"cannot open the Rerun viewer: {problem}")
        return f"(No viewer opened: {problem}. Open the view elsewhere with `rerun {rrd}`.)"
    subprocess.Popen([exe, str(rrd)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                     start_new_session=True)
    return f"Opened the Rerun viewer on {rrd}."
