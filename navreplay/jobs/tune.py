"""``navreplay tune``: a filter's parameters searched by an optimiser, scored on runs and
validated on runs (or windows) the search never saw.

Two objectives (docs/tuning.md):

``truth`` (a scenario, or recordings with a truth stream)
    ``J = mean_i (ln r_i)^2 + (ln NEES/dof)^2 + 0.1 mean_i ln RMS_i`` over the NEES states i of
    the ensemble: ``r_i`` the ratio RMS/sigma of the normalised errors and NEES/dof the
    time-averaged NEES (:mod:`navreplay.metrics.consistency`), then accuracy (the RMS errors, whose
    logarithms make the weight independent of units) among consistent settings.
``held-out`` (recordings without truth, or asked for)
    GNSS fixes are dropped in windows (``--outage`` seconds every ``--outage-period``,
    :mod:`navreplay.replay.holdout`); ``J = ln RMS_h + mean_m (ln NIS_m/dof_m)^2``: the
    horizontal distance between the filter's position and the dropped fixes, and the NIS of the
    measurements it used.

The search is optuna's TPE sampler (seeded), started from the filter's settings on the data
(``-p`` values, else those derived from the recordings' sensor specifications, else its
defaults), which are the first trial. Validation: a scenario's tuning runs use seeds
``seed .. seed + runs - 1`` and its validation runs ``seed + VALIDATION_SEEDS ..``; recordings
with truth alternate between tuning and validation; held-out windows alternate too, each
recording replayed once with the tuning windows dropped and once with the validation windows.
The study lives in a journal file (``--storage``): a command stopped half-way, run again with
the same arguments, continues where it stopped.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import json
import math
import tempfile
import typing
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.campaign.ensemble import RunFailedError, run_ensemble
from navreplay.campaign.tasks import RunOutput, file_tasks
from navreplay.core import params as _params
from navreplay.core.streams import Recording, StreamKind, seconds
from navreplay.io import RecordingWarning
from navreplay.io.outputs import atomic_path
from navreplay.replay.holdout import (
    held_out_errors,
    held_out_truth_errors,
    hold_out,
    outage_windows,
)
from navreplay.replay.spec import FilterSpec
from navreplay.sensors.specs import SensorSpecs

VALIDATION_SEEDS = 1000
"""Offset of a scenario's validation seeds from its tuning seeds."""
ACCURACY_WEIGHT = 0.1
"""Weight of ``mean_i ln RMS_i`` against the consistency terms in the ``truth`` objective."""
STUDY = "navreplay-tune"


class Objective(enum.StrEnum):
    """What a trial is scored on."""

    TRUTH = "truth"
    """Ensemble consistency (per-axis RMS/sigma, time-averaged NEES) and accuracy."""
    HELD_OUT = "held-out"
    """Prediction of dropped GNSS fixes, and the NIS of the others."""


@dataclasses.dataclass(frozen=True)
class SearchRange:
    """One ``--param NAME=LOW:HIGH[:log|:linear]``."""

    name: str
    low: float
    high: float
    log: bool

    def text(self) -> str:
        return f"{self.low:g}..{self.high:g}" + (" (log)" if self.log else "")


def parse_ranges(items: Sequence[str], filter_ref: str) -> tuple[SearchRange, ...]:
    """``NAME=LOW:HIGH[:log|:linear]`` items for the float parameters of a filter (log scale by
    default when ``0 < LOW`` and ``HIGH >= 10 LOW``); one-line errors."""
    from navreplay.filters.registry import load_filter

    cls = load_filter(filter_ref)
    hints = typing.get_type_hints(cls.Params)
    out = []
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        parts = [p.strip() for p in text.split(":")]
        if not sep or len(parts) not in (2, 3):
            raise _params.ParamError(f"--param {item!r}: write NAME=LOW:HIGH[:log|:linear]")
        if name not in hints:
            raise _params.ParamError(f"--param {name}: {filter_ref} has no such parameter "
                                     f"(`navreplay filters {filter_ref}` lists them)")
        if hints[name] is not float and float not in typing.get_args(hints[name]):
            raise _params.ParamError(f"--param {name}: only real-valued parameters can be "
                                     f"tuned ({name} is {hints[name]})")
        try:
            low, high = float(parts[0]), float(parts[1])
        except ValueError:
            raise _params.ParamError(f"--param {item!r}: LOW and HIGH must be numbers") from None
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise _params.ParamError(f"--param {item!r}: need finite LOW < HIGH")
        scale = parts[2].lower() if len(parts) == 3 else ("log" if 0 < low and high >= 10 * low
                                                          else "linear")
        if scale not in ("log", "linear"):
            raise _params.ParamError(f"--param {item!r}: the scale is log or linear")
        if scale == "log" and not low > 0:
            raise _params.ParamError(f"--param {item!r}: a log scale needs LOW > 0")
        out.append(SearchRange(name, low, high, scale == "log"))
    if not out:
        raise _params.ParamError("give at least one --param NAME=LOW:HIGH to tune")
    names = [r.name for r in out]
    if len(set(names)) < len(names):
        raise _params.ParamError(
            f"--param: {', '.join(sorted(n for n in set(names) if names.count(n) > 1))}"
            " given twice"
        )
    return tuple(out)


@dataclasses.dataclass(frozen=True)
class TuneJob:
    """``navreplay tune``.

    Attributes
    ----------
    filter : str
        Registry name or ``package.module:Class``.
    scenario : str or None
        Scenario to simulate (its runs carry truth); or ``recordings``.
    recordings : tuple of Path
    ranges : tuple of SearchRange
    fixed : mapping
        Other filter parameter values (``-p``): the start, and kept.
    values : mapping
        Scenario parameter values.
    runs, validation_runs : int
        Scenario runs for the search and for the validation.
    seed : int
        First tuning seed.
    trials : int
        Trials in all (a resumed study counts those it already has).
    objective : Objective or None
        None: ``truth`` when every run has truth, else ``held-out``.
    outage, outage_period : float
        Held-out windows: length and period [s].
    storage : Path or None
        Journal file of the study (resumable); None: in memory.
    output : Path or None
        The ``[filter.NAME]`` TOML of the chosen values.
    workers : int
    sampler_seed : int
    """

    filter: str
    scenario: str | None = None
    recordings: tuple[Path, ...] = ()
    ranges: tuple[SearchRange, ...] = ()
    fixed: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    values: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    runs: int = 8
    validation_runs: int = 8
    seed: int = 0
    trials: int = 40
    objective: Objective | None = None
    outage: float = 30.0
    outage_period: float = 120.0
    storage: Path | None = None
    output: Path | None = None
    workers: int = 1
    sampler_seed: int = 0

    def fingerprint(self) -> dict[str, Any]:
        """What a resumed study must agree on (as stored: plain JSON)."""
        return json.loads(json.dumps({"filter": self.filter, "scenario": self.scenario,
                "recordings": [str(p) for p in self.recordings],
                "ranges": [dataclasses.astuple(r) for r in self.ranges],
                "fixed": {k: str(v) for k, v in self.fixed.items()},
                "values": {k: str(v) for k, v in self.values.items()},
                "runs": self.runs, "validation_runs": self.validation_runs, "seed": self.seed,
                "objective": str(self.objective), "outage": [self.outage, self.outage_period]}))


@dataclasses.dataclass(frozen=True)
class Score:
    """One evaluation of a parameter set.

    Attributes
    ----------
    value : float
        The objective (smaller is better).
    parts : dict[str, float]
        What it is made of, for the report: ``NEES/dof`` (time-averaged), ``NEES in band``
        (1 or 0, :mod:`navreplay.metrics.consistency` at its false alarm), ``worst RMS/σ`` (the NEES
        state's ratio furthest from 1) and the ensemble summary's ``pos_rms_h`` [m],
        ``att_rms_level`` and ``att_rms_heading`` [rad] (truth); ``held-out RMS [m]`` and
        ``NIS/dof <name>`` per measurement (held-out).
    """

    value: float
    parts: dict[str, float]


@dataclasses.dataclass(frozen=True)
class TuneReport:
    """What ``navreplay tune`` found."""

    job: TuneJob
    objective: Objective
    start: dict[str, float]
    best: dict[str, float]
    trials: int
    resumed: int
    tuning: tuple[Score, Score]
    validation: tuple[Score, Score]
    where: tuple[str, str]
    written: Path | None = None

    def format(self) -> str:
        j = self.job
        source = j.scenario or ", ".join(p.name for p in j.recordings)
        lines = [f"tune {j.filter} on {source}, objective {self.objective}: {self.trials} trials"
                 + (f" ({self.resumed} resumed from {j.storage})" if self.resumed else "")]
        rows: list[tuple[str, ...]] = [("parameter", "start", "chosen", "range")]
        for r in j.ranges:
            rows.append((r.name, f"{self.start[r.name]:.4g}", f"{self.best[r.name]:.4g}",
                         r.text()))
        lines += ["", *_align(rows)]
        keys = sorted({k for s in (*self.tuning, *self.validation) for k in s.parts})
        rows = [("", "objective", *keys)]
        for label, pair in (("search", self.tuning), ("validation", self.validation)):
            for name, s in zip(("start", "chosen"), pair, strict=True):
                rows.append((f"{label} {name}", f"{s.value:.4g}",
                             *(f"{s.parts[k]:.4g}" if k in s.parts else "-" for k in keys)))
        lines += ["", *_align(rows), f"search on {self.where[0]}; validation on {self.where[1]}"]
        if self.written is not None:
            lines.append(f"wrote {self.written} (navreplay run {j.filter} ... --config "
                         f"{self.written})")
        return "\n".join(lines)


def _align(rows: Sequence[Sequence[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]


# --------------------------------------------------------------------------------------------
# scoring (the extractor runs in the campaign's workers)


def tune_extract(recording: Recording, results: dict[str, Any], task: Any) -> dict[str, Any]:
    """One run reduced to what the objectives need: the metrics against the truth (when the
    recording has one), the held-out errors and the NIS sums per measurement."""
    from navreplay.metrics import run_metrics

    (result,) = results.values()
    out: dict[str, Any] = {
        "nis": {name: (float(np.sum(s.nis)), int(s.nis.size), int(s.nu.shape[1]))
                for name, s in result.innovations.items()},
        "held_out": held_out_errors(result, recording),
    }
    if StreamKind.TRUTH in recording:
        out["metrics"] = run_metrics(result, recording)
        out["outage_truth"] = held_out_truth_errors(result, recording)
    return out


def _campaign(paths: Sequence[Path], spec: FilterSpec, workers: int) -> list[dict[str, Any]]:
    """Every recording replayed with one parameter set: the extractor's outputs in order (the
    one use of the campaign API)."""
    outputs: list[RunOutput] = []
    with warnings.catch_warnings():  # the held-out gaps are ours: the reader need not warn
        warnings.simplefilter("ignore", RecordingWarning)
        run_ensemble(file_tasks(paths), [spec], outputs.append, extract=tune_extract,
                     workers=workers)
    return [o.metrics for o in outputs]


def score(outputs: Sequence[dict[str, Any]], objective: Objective) -> Score:
    """The objective of one parameter set's runs."""
    if objective is Objective.TRUTH:
        return _truth_score(outputs)
    errors = np.concatenate([o["held_out"] for o in outputs])
    if errors.size == 0:
        raise ValueError("no held-out fix was scored")
    rms = float(np.sqrt(np.mean(errors**2)))
    nis = _nis_ratios(outputs)
    value = math.log(rms) + (float(np.mean([math.log(r) ** 2 for r in nis.values()]))
                             if nis else 0.0)
    parts = {"held-out RMS [m]": rms}
    parts.update({f"NIS/dof {name}": r for name, r in nis.items()})
    truth = [o["outage_truth"] for o in outputs if "outage_truth" in o]
    if truth:  # a simulated drive: the error the outages really caused (not in the objective)
        e = np.concatenate(truth)
        parts["outage RMS vs truth [m]"] = float(np.sqrt(np.mean(e**2)))
    return Score(value, parts)


def _nis_ratios(outputs: Sequence[dict[str, Any]]) -> dict[str, float]:
    sums: dict[str, list[float]] = {}
    for o in outputs:
        for name, (total, count, dof) in o["nis"].items():
            acc = sums.setdefault(name, [0.0, 0, dof])
            acc[0] += total
            acc[1] += count
    return {name: total / count / dof for name, (total, count, dof) in sums.items() if count}


def _truth_score(outputs: Sequence[dict[str, Any]]) -> Score:
    from navreplay.metrics import EnsembleStats

    stats = EnsembleStats()
    for o in outputs:
        stats.add(o["metrics"])
    res = stats.result()
    c = res.consistency
    if c is None or c.nees is None:
        raise ValueError("the filter declares no NEES states: the truth objective needs them")
    names = [n for n in c.nees_names if n in c.scale]
    logs = np.array([math.log(c.scale[n].ratio) for n in names])
    idx = [res.state_names.index(n) for n in names]
    rms = np.sqrt(np.nanmean(res.state_rms[:, idx] ** 2, axis=0))
    nees_dof = c.nees.mean / c.nees.dof
    value = (float(np.mean(logs**2)) + math.log(nees_dof) ** 2
             + ACCURACY_WEIGHT * float(np.mean(np.log(rms))))
    worst = names[int(np.argmax(np.abs(logs)))]
    parts = {"NEES/dof": nees_dof, "NEES in band": float(c.nees.passed),
             "worst RMS/σ": c.scale[worst].ratio}
    summary = res.summary()
    for key in ("pos_rms_h", "att_rms_level", "att_rms_heading"):
        if key in summary:
            parts[key] = float(summary[key])
    return Score(value, parts)


def evaluate(paths: Sequence[Path], job: TuneJob, objective: Objective,
             values: Mapping[str, float]) -> Score:
    """Score one parameter set over ``paths``."""
    spec = FilterSpec(job.filter, {**job.fixed, **values})
    return score(_campaign(paths, spec, job.workers), objective)


# --------------------------------------------------------------------------------------------
# data


@dataclasses.dataclass(frozen=True)
class Data:
    """The recordings of the search and of the validation, and what they are."""

    objective: Objective
    search: tuple[Path, ...]
    validation: tuple[Path, ...]
    where: tuple[str, str]
    sensors: SensorSpecs | None = None
    """The first search recording's sensor specifications (what the filter starts from)."""


@contextlib.contextmanager
def prepared(job: TuneJob) -> Iterator[Data]:
    """The search and validation recordings (simulated or held-out copies in a temporary
    directory, removed afterwards)."""
    with tempfile.TemporaryDirectory(prefix="navreplay-tune-") as tmp:
        yield _prepare(job, Path(tmp))


def _prepare(job: TuneJob, tmp: Path) -> Data:
    from navreplay.io import read_recording, write_recording

    if job.scenario is not None:
        from navreplay.sim.scenario import simulate

        scenario = job.scenario

        def load(seed: int) -> Recording:
            return simulate(scenario, dict(job.values), seed)

        search_ids = [job.seed + i for i in range(job.runs)]
        valid_ids = [job.seed + VALIDATION_SEEDS + i for i in range(job.validation_runs)]
        recordings: list[Recording] = []
        truth = True
        where = (_seeds(job.seed, job.runs), _seeds(job.seed + VALIDATION_SEEDS,
                                                      job.validation_runs))
    else:
        recordings = [read_recording(p) for p in job.recordings]
        truth = all(StreamKind.TRUTH in r for r in recordings)
        where = ("", "")
    objective = job.objective or (Objective.TRUTH if truth else Objective.HELD_OUT)
    if objective is Objective.TRUTH and not truth:
        raise _params.ParamError("--objective truth: not every recording has a truth stream "
                                 "(use --objective held-out)")

    def write(name: str, rec: Recording) -> Path:
        path = tmp / f"{name}.mcap"
        write_recording(path, rec)
        return path

    if job.scenario is not None and objective is Objective.TRUTH:
        first = load(search_ids[0])
        search = tuple(write(f"search_{s}", first if k == 0 else load(s))
                       for k, s in enumerate(search_ids))
        validation = tuple(write(f"validation_{s}", load(s)) for s in valid_ids)
        return Data(objective, search, validation, where, _sensors(first))
    if job.scenario is None and objective is Objective.TRUTH:
        if len(job.recordings) < 2:
            raise _params.ParamError("tuning on recordings with truth needs at least two (they "
                                     "alternate between search and validation); or use "
                                     "--objective held-out")
        paths = tuple(job.recordings)
        return Data(objective, paths[0::2], paths[1::2],
                    (", ".join(p.name for p in paths[0::2]),
                     ", ".join(p.name for p in paths[1::2])), _sensors(recordings[0]))
    # held-out windows, alternating between search and validation
    items = [load(s) for s in search_ids] if job.scenario is not None else recordings
    names = ([f"seed {s}" for s in search_ids] if job.scenario is not None
             else [p.name for p in job.recordings])
    held_search: list[Path] = []
    held_validation: list[Path] = []
    counts = [0, 0]
    for k, (name, rec) in enumerate(zip(names, items, strict=True)):
        imu = rec[StreamKind.IMU]
        t = seconds(imu.t_ns[[0, -1]], rec.t0_ns)
        windows = outage_windows(float(t[0]), float(t[1]), length=job.outage,
                                 period=job.outage_period)
        if len(windows) < 2:
            raise _params.ParamError(
                f"{name}: {t[1] - t[0]:.0f} s hold fewer than two {job.outage:g} s outages "
                f"every {job.outage_period:g} s (one for the search, one for the validation); "
                "shorten --outage-period")
        try:
            held_search.append(write(f"search_{k}", hold_out(rec, windows[0::2])))
            held_validation.append(write(f"validation_{k}", hold_out(rec, windows[1::2])))
        except ValueError as e:
            raise _params.ParamError(f"{name}: {e}") from None
        counts[0] += len(windows[0::2])
        counts[1] += len(windows[1::2])
    return Data(objective, tuple(held_search), tuple(held_validation),
                (f"{counts[0]} GNSS outages of {job.outage:g} s (every "
                 f"{2 * job.outage_period:g} s) in {', '.join(names)}",
                 f"the {counts[1]} outages between them"), _sensors(items[0]))


def _sensors(recording: Recording) -> SensorSpecs:
    return SensorSpecs.from_metadata(recording.metadata.sensors)


def _seeds(first: int, count: int) -> str:
    return f"seeds {first}-{first + count - 1}" if count > 1 else f"seed {first}"


# --------------------------------------------------------------------------------------------
# the search


def start_values(job: TuneJob, sensors: SensorSpecs | None = None) -> dict[str, float]:
    """The filter's setting of each tuned parameter on the data (the ``-p`` value, else what
    the recording's sensor specifications give, else the default), clipped into its range."""
    from navreplay.filters.registry import load_filter
    from navreplay.filters.settings import build_params

    p = build_params(load_filter(job.filter), job.fixed, sensors).params
    out = {}
    for r in job.ranges:
        value = getattr(p, r.name)
        out[r.name] = float(min(max(value if value is not None else r.low, r.low), r.high))
    return out


def _study(job: TuneJob, start: Mapping[str, float]) -> Any:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    storage = None
    if job.storage is not None:
        from optuna.storages import JournalStorage
        from optuna.storages.journal import JournalFileBackend

        storage = JournalStorage(JournalFileBackend(str(job.storage)))
    sampler = optuna.samplers.TPESampler(seed=job.sampler_seed, multivariate=True,
                                         n_startup_trials=min(10, max(job.trials // 4, 1)))
    study = optuna.create_study(storage=storage, study_name=STUDY, direction="minimize",
                                sampler=sampler, load_if_exists=True)
    fingerprint = job.fingerprint()
    if not study.trials:
        study.set_user_attr("job", fingerprint)
        study.enqueue_trial(dict(start))
    elif study.user_attrs.get("job") != fingerprint:
        raise _params.ParamError(f"{job.storage} holds the study of another tuning (other "
                                 "filter, data, ranges or options); use another --storage")
    return study


def tune(job: TuneJob, progress: Callable[[int, int], None] | None = None) -> TuneReport:
    """Run (or resume) the search, validate the chosen values against the start, write the
    TOML."""
    try:
        import optuna
    except ImportError:
        raise ImportError("navreplay tune needs optuna: pip install 'navreplay[tune]'") from None
    if job.trials < 1:
        raise _params.ParamError(f"--trials must be at least 1, got {job.trials}")
    finished = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED,
                optuna.trial.TrialState.FAIL)
    with prepared(job) as data:
        start = start_values(job, data.sensors)
        study = _study(job, start)
        resumed = sum(t.state in finished for t in study.trials)

        def objective(trial: Any) -> float:
            values = {r.name: trial.suggest_float(r.name, r.low, r.high, log=r.log)
                      for r in job.ranges}
            try:
                s = evaluate(data.search, job, data.objective, values)
            except RunFailedError as e:  # e.g. a diverging filter: not a candidate
                trial.set_user_attr("failed", str(e))
                raise optuna.TrialPruned(str(e)) from None
            trial.set_user_attr("parts", s.parts)
            return s.value

        def report(study: Any, trial: Any) -> None:
            if progress is not None:
                progress(sum(t.state in finished for t in study.trials), job.trials)

        remaining = job.trials - resumed
        if remaining > 0:
            study.optimize(objective, n_trials=remaining, callbacks=[report])
        complete = [t for t in study.trials if t.state is optuna.trial.TrialState.COMPLETE]
        if not complete:
            raise RuntimeError("no trial completed (every parameter set failed)")
        best = {r.name: float(study.best_trial.params[r.name]) for r in job.ranges}
        first = next((t for t in complete if t.number == 0), None)
        tuning = (
            Score(first.value, first.user_attrs.get("parts", {})) if first is not None
            else evaluate(data.search, job, data.objective, start),
            Score(study.best_trial.value, study.best_trial.user_attrs.get("parts", {})),
        )
        validation = (evaluate(data.validation, job, data.objective, start),
                      evaluate(data.validation, job, data.objective, best))
        where = data.where
        objective_used = data.objective
    report_ = TuneReport(job, objective_used, start, best, sum(
        t.state in finished for t in study.trials), resumed, tuning, validation, where)
    if job.output is not None:
        with atomic_path(job.output) as tmp:
            tmp.write_text(tuned_toml(report_), encoding="utf-8")
        report_ = dataclasses.replace(report_, written=job.output)
    return report_


def tuned_toml(report: TuneReport) -> str:
    """The chosen values (and the other ``-p`` values) as a ``[filter.NAME]`` table, with the
    search and validation as comments."""
    j = report.job
    lines = [f"# navreplay tune {j.filter}: objective {report.objective}, {report.trials} "
             "trials",
             f"# search on {report.where[0]}; validation on {report.where[1]}:"]
    for name, s in zip(("start", "chosen"), report.validation, strict=True):
        parts = ", ".join(f"{k} {v:.4g}" for k, v in s.parts.items())
        lines.append(f"#   {name}: objective {s.value:.4g}; {parts}")
    lines.append(f'[filter."{j.filter}"]' if not j.filter.replace("-", "").isalnum()
                 else f"[filter.{j.filter}]")
    for key, value in j.fixed.items():
        if key not in report.best:
            lines.append(f"{key} = {_toml(value)}")
    for r in j.ranges:
        lines.append(f"{r.name} = {report.best[r.name]!r}  # searched {r.text()}, start "
                     f"{report.start[r.name]:.6g}")
    return "\n".join(lines) + "\n"


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    return '"' + str(value).replace("\\", "\\\\").replace('"', '\\"') + '"'
