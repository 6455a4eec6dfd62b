"""The jobs behind the command line: one typed configuration and one function per command.

``navreplay.cli`` parses arguments into these configurations and makes one call; everything
else — reading recordings, replaying filters, metrics, Rerun output, summaries — happens here,
so the same jobs run from Python::

    from pathlib import Path
    from navreplay.jobs import RunJob, VizMode, VizOptions, run
    from navreplay.replay.ensemble import FilterSpec

    job = RunJob(filters=(FilterSpec("gps-ins"),), recordings=(Path("x.mcap"),),
                 viz=VizOptions(VizMode.SAVE, Path("out/x.rrd")))
    print(run(job).format())

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
from navreplay.filters.registry import load_filter
from navreplay.replay.engine import (
    MissingStreamError,
    Progress,
    build_params,
    check_streams,
    replay,
)
from navreplay.replay.ensemble import (
    FilterSpec,
    RunOutput,
    RunTask,
    default_extract,
    file_tasks,
    monte_carlo_tasks,
    run_ensemble,
)
from navreplay.replay.result import RunResult
from navreplay.streams import Recording, StreamKind, jsonable

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
        tmp.write_text(json.dumps(jsonable(data, strict=True), indent=2) + "\n")


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


def _open_sink(viz_options: VizOptions, default: Path, name: str) -> Any:
    """Open the Rerun sink (checking first that a viewer is reachable), or None."""
    target = viz_options.target(default)
    if target is None:
        return None
    from navreplay.viz import open_sink

    return open_sink(target, recording_name=name)


def _close_sink(sink: Any, viz_options: VizOptions) -> str:
    """Finish the sink (a served one stays up) and say where the view is."""
    if sink is None:
        return ""
    if viz_options.mode is VizMode.SERVE:
        sink.send_blueprint()
        sink.flush()
        return f"Rerun web viewer: {sink.web_url} (serving until Ctrl-C)"
    where = sink.close()
    if sink.path is not None:
        return f"Rerun view saved to {where}; open it with: rerun {where}"
    return f"Rerun view sent to the viewer at {where}"


# --------------------------------------------------------------------------------------------
# metrics (per run and over runs)


def state_errors(m: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Estimation errors and predicted sigmas of the scored states, for the Rerun view."""
    return {
        name: (m.state_error[:, j], np.sqrt(np.clip(m.state_var[:, j], 0.0, None)))
        for j, name in enumerate(m.state_names)
    }


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
    return PerRun(scored, {label: m.summary() for label, m in scored.items()})


ERROR_KEYS = ("runs", "distance", "pos_rms_h", "pos_rms_v", "pos_err_final_h", "pos_err_final_dt",
              "lat_rms_final", "long_rms_final", "cep50_final", "dt_cep50_final", "vel_rms",
              "att_rms_level", "att_rms_heading")
"""Columns of the error table (those present in a summary)."""


def format_summaries(summaries: Mapping[str, Mapping[str, Any]]) -> str:
    """Two tables of summary dicts: errors, then consistency (NEES and NIS against their 95 %
    chi-square bounds)."""
    from navreplay import metrics

    if not summaries:
        return "(nothing to score)"
    keys = [k for k in ERROR_KEYS if any(k in s for s in summaries.values())]
    out = [metrics.format_table(summaries, keys)]
    rows = [("consistency", "dof", "mean", "in 95% bounds")]
    for label, s in summaries.items():
        if "nees_mean" in s:
            rows.append((f"{label} NEES", str(s["nees_dof"]), f"{s['nees_mean']:.3g}",
                         f"{100 * s['nees_in_bounds']:.0f} %"))
        for key in s:
            if key.startswith("nis_mean_"):
                meas = key.removeprefix("nis_mean_")
                rows.append((f"{label} NIS {meas}", str(s.get(f"nis_dof_{meas}", "")),
                             f"{s[key]:.3g}",
                             f"{100 * s.get(f'nis_in_bounds_{meas}', math.nan):.0f} %"))
    if len(rows) > 1:
        widths = [max(len(r[i]) for r in rows) for i in range(4)]
        out.append("\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
                             for r in rows))
    return "\n\n".join(out)


_ENSEMBLE_NAV = (("pos_ned", "position", ("N", "E", "D"), "m", 1.0),
                 ("v_n", "velocity", ("N", "E", "D"), "m/s", 1.0),
                 ("phi", "attitude", ("phi_N", "phi_E", "phi_D"), "deg", 180.0 / math.pi))


def log_ensemble(sink: Any, label: str, ens: Any) -> None:
    """Log one filter's Monte Carlo statistics: RMS error vs mean predicted sigma over time for
    the navigation errors and scored states, average NEES and NIS with their 95 % bounds."""
    from navreplay.viz.naming import resolve_unit

    t = ens.t
    for key, what, axes, unit, scale in _ENSEMBLE_NAV:
        if key not in ens.rms:
            continue
        for i, axis in enumerate(axes):
            sigma = ens.sigma.get(key)
            series = {f"{label} RMS": ens.rms[key][:, i] * scale}
            if sigma is not None and np.isfinite(sigma[:, i]).any():
                series[f"{label} σ"] = sigma[:, i] * scale
            sink.log_ensemble(f"{what} error {axis}", t, series, unit=unit)
    for j, name in enumerate(ens.state_names):
        u = resolve_unit(name)
        sink.log_ensemble(
            f"{name} error", t,
            {f"{label} RMS": ens.state_rms[:, j] * u.scale,
             f"{label} σ": ens.state_sigma[:, j] * u.scale},
            unit=u.label,
        )
    if ens.nees_dof and np.isfinite(ens.nees_mean).any():
        sink.log_ensemble(f"{label} NEES (dof {ens.nees_dof}, {ens.runs} runs)", t,
                          {f"{label} NEES": ens.nees_mean}, unit="-", bounds=ens.nees_bounds)
    from navreplay.metrics import chi2_bounds_per_count

    for meas, (t_k, mean, count, dof) in ens.nis_mean.items():
        lo, hi = chi2_bounds_per_count(dof, count)
        sink.log_ensemble(f"{label} NIS {meas} (dof {dof})", t_k[: mean.shape[0]],
                          {f"{label} NIS": mean}, unit="-", bounds=(lo, hi))


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
        if self.notes:
            parts += [""] + [n for n in self.notes if n]
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
    log: Any = None
    """:class:`navreplay.logs.options.LogOptions` (topics, frames, --init, --reference)."""


def _check_files(paths: Sequence[Path]) -> None:
    from navreplay.io.reader import is_rosbag

    for p in paths:
        if not (Path(p).is_file() or (Path(p).is_dir() and is_rosbag(Path(p)))):
            raise FileNotFoundError(f"{p}: no such recording")


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
    tasks = file_tasks(job.recordings, job.log)
    default = DEFAULT_OUT / "ensemble.rrd"
    title = (f"{', '.join(s.label for s in job.filters)} over {len(tasks)} recordings")
    return _campaign(tasks, job.filters, job.viz, default, job.summary_path, job.workers,
                     progress, title, job.output_rate, per_run_table=True)


def _run_one(job: RunJob, progress: Progress | None) -> RunReport:
    from navreplay import metrics
    from navreplay.logs.prepare import open_log

    path = Path(job.recordings[0])
    classes = [spec.load() for spec in job.filters]
    prepared = open_log(path, job.log)
    recording = prepared.recording
    for cls in classes:
        check_streams(recording, cls, str(path))
    has_truth = StreamKind.TRUTH in recording
    n_filters = len(classes)
    summaries: dict[str, dict[str, Any]] = {}
    sink = _open_sink(job.viz, DEFAULT_OUT / f"{path.stem}.rrd", path.name)
    try:
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
                progress=prog, observer=observer,
            )
            errors = None
            scored = metrics.run_metrics(result, recording)  # NIS only without a reference
            summaries[spec.label] = scored.summary()
            if has_truth:
                errors = state_errors(scored)
            if sink is not None:
                sink.log_run(result, truth=recording if has_truth else None, metrics=errors)
        hint = _close_sink(sink, job.viz)
    except BaseException:
        if sink is not None:
            sink.abort()
        raise
    summary = {"recording": str(path), "filters": summaries}
    notes = list(prepared.notes)
    if job.summary_path is not None:
        write_json(job.summary_path, summary)
        notes.append(f"Summary written to {job.summary_path}")
    table = format_summaries(summaries)
    if not has_truth:
        table = "(no truth or reference: innovation statistics only)\n\n" + table
    return RunReport(
        title=f"{', '.join(s.label for s in job.filters)} over {path}",
        table=table, summary=summary, viz=hint, notes=notes,
        sink=sink if job.viz.mode is VizMode.SERVE else None,
    )


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
    per_run_table: bool,
) -> RunReport:
    from navreplay import metrics

    stats: dict[str, Any] = {spec.label: metrics.EnsembleStats(spec.label) for spec in filters}
    rows: list[dict[str, Any]] = []
    notes: list[str] = []

    def collect(out: RunOutput) -> None:
        per: PerRun = out.metrics
        rows.append({"run": out.index + 1, "recording": out.source, "seed": out.seed,
                     "seconds": out.seconds, "filters": per.summaries})
        for label, m in per.metrics.items():
            if label in stats:
                try:
                    stats[label].add(m)
                except ValueError as e:  # recordings of different lengths or rates
                    del stats[label]
                    notes.append(f"no ensemble statistics for {label}: {e}")

    sink = _open_sink(viz_options, default_rrd, title)
    try:
        done = run_ensemble(tasks, filters, collect, extract=campaign_extract,
                            workers=workers, progress=progress, output_rate=output_rate)
        ens = {label: s.result() for label, s in stats.items() if s.runs}
        if sink is not None:
            for label, e in ens.items():
                log_ensemble(sink, label, e)
        hint = _close_sink(sink, viz_options)
    except BaseException:
        if sink is not None:
            sink.abort()
        raise
    summary = {
        "runs": rows,
        "ensemble": {label: e.summary() for label, e in ens.items()},
        "wall_seconds": done.seconds,
    }
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
        keys = [k for k in ERROR_KEYS if any(k in s for s in per_run.values())]
        parts.append("Per recording:\n" + metrics.format_table(per_run, keys))
    if ens:
        parts.append(f"Ensemble over {done.runs} runs:\n"
                     + format_summaries({label: e.summary() for label, e in ens.items()}))
    notes += [
        f"{done.runs} runs in {done.seconds:.1f} s wall ({done.run_seconds:.1f} s of run time, "
        f"{workers} worker(s))",
    ]
    if summary_path is not None:
        notes.append(f"Summary written to {summary_path}")
    return RunReport(title=title, table="\n\n".join(parts), summary=summary, viz=hint,
                     notes=notes, sink=sink if viz_options.mode is VizMode.SERVE else None)


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
            raise MissingStreamError(
                f"filter {spec.label!r} needs stream(s) {', '.join(missing)} that scenario "
                f"{job.scenario} does not simulate (it has: "
                f"{', '.join(str(k) for k in get_scenario(job.scenario).streams)})"
            )
    tasks = monte_carlo_tasks(job.scenario, job.runs, values=job.values, seed=job.seed,
                              keep_dir=job.keep_dir, force=job.force)
    if job.keep_dir is not None:
        Path(job.keep_dir).mkdir(parents=True, exist_ok=True)
    if job.keep_dir is not None and not job.force:
        existing = [t.keep for t in tasks if t.keep and Path(t.keep).exists()]
        if existing:
            raise FileExistsError(f"{existing[0]} exists; use --force to overwrite")
    title = (f"Monte Carlo: {', '.join(s.label for s in job.filters)} on {job.scenario}, "
             f"{job.runs} runs, seeds {job.seed}..{job.seed + job.runs - 1}")
    return _campaign(tasks, job.filters, job.viz, DEFAULT_OUT / f"montecarlo-{job.scenario}.rrd",
                     job.summary_path, job.workers, progress, title, job.output_rate,
                     per_run_table=False)


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
        _heading("Land vehicle: free inertial (ins) vs loosely coupled GPS/INS (gps-ins)"),
        f"Recording: {rec_path} ({DEMO_SCENARIO}, seed {DEMO_SEED}); inspect it with "
        f"`navreplay info {rec_path}`",
        report.format(),
    ]
    failed = 0
    if job.reproductions:
        from navreplay import reproduce

        for name in reproduce.available():
            rep = reproduce.get(name)
            sections.append(_heading(f"Paper reproduction (quick): {name}"))
            result = rep.run(runs=rep.quick_runs, seed=0, workers=job.workers,
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


def _heading(text: str) -> str:
    return f"{'=' * len(text)}\n{text}\n{'=' * len(text)}"


def _open_viewer(rrd: Path, *, required: bool) -> str:
    """Open the Rerun viewer on ``rrd`` when a display is available; say what happened."""
    import subprocess

    from navreplay.viz.targets import display_problem, find_viewer

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
