"""Reproduction of shipboard transfer alignment by velocity + quaternion partial matching.

The published results and acceptance bands of docs/methods/transfer-alignment.md §6 (Song,
Jeon and Lyou; Figs. 2 and 3). The campaign replays the ``transfer-alignment`` filter over
``runs`` seeded recordings of the ``ship-transfer-alignment`` scenario in three conditions:

============  ==============================  =========================================
condition     scenario parameters             filter variants (``match``)
============  ==============================  =========================================
flexure       defaults (wn = 2 pi rad/s)      vel_quat_partial, vel_quat_full, vel_only;
                                              partial and full with the flexure states
no flexure    ``flexure_sigma = 0``           vel_quat_partial, vel_quat_full
wn 1 rad/s    ``flexure_wn = 1``              vel_quat_partial, vel_quat_full
============  ==============================  =========================================

The paper's three variants run without the filter's flexure states (``flexure_sigma = 0``):
the bands are the paper's claims about its filters, which model no flexure. The two variants
``+flexure`` are navreplay's filter with the Y-axis flexure as states (the default), whose
sigma is compared with the error (:func:`consistency`).

Run i of every condition simulates with seed ``seed + i`` (the convention of
:func:`navreplay.campaign.tasks.monte_carlo_tasks`): the conditions share every random draw
except the flexure, so they compare like with like, and
``navreplay simulate ship-transfer-alignment --seed S+i`` reproduces any single run.

The metric is the alignment error phi (:func:`navreplay.geo.attitude_error`,
``C_nb_hat C_nb^T = I - [phi x]``) of the filter's navigation solution against the truth, at
every GINS sample; the filter's predicted 1 sigma of phi (extras ``attitude_sigma_n``,
``Sigma_phi = 4 R^T P_qq R``) is averaged as the root mean of the variances. Everything runs
in memory over a process pool (:func:`navreplay.campaign.ensemble.run_ensemble`).

Examples
--------
>>> from navreplay.reproduce import get
>>> report = get("transfer-alignment").run(runs=6)       # doctest: +SKIP
>>> print(report.format())                               # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay.campaign.ensemble import run_ensemble
from navreplay.campaign.executors import make_executor
from navreplay.campaign.tasks import RunOutput, RunTask, monte_carlo_tasks
from navreplay.core.streams import Recording
from navreplay.core.units import DEG
from navreplay.filters.result import RunResult
from navreplay.filters.transfer_alignment_model import flexure_rate_sigma
from navreplay.geo.rotations import attitude_error, quat_to_dcm
from navreplay.metrics import rms, truth_at
from navreplay.replay.spec import FilterSpec
from navreplay.reproduce import Check, Progress, Report, Reproduction, slashed, warm_up
from navreplay.sim.scenarios.ship_transfer_alignment import ShipTransferAlignmentParams

SCENARIO = "ship-transfer-alignment"
FILTER = "transfer-alignment"
PARTIAL, FULL, VEL_ONLY = "vel_quat_partial", "vel_quat_full", "vel_only"
PARTIAL_FLEX, FULL_FLEX = f"{PARTIAL}+flexure", f"{FULL}+flexure"
VARIANTS: dict[str, dict[str, object]] = {
    PARTIAL: {"match": PARTIAL, "flexure_sigma": 0.0, "quat_model": "paper"},
    FULL: {"match": FULL, "flexure_sigma": 0.0, "quat_model": "paper"},
    VEL_ONLY: {"match": VEL_ONLY, "quat_model": "paper"},
    PARTIAL_FLEX: {"match": PARTIAL},
    FULL_FLEX: {"match": FULL},
}
"""Filter parameters of each variant label: the paper's filters model no flexure and keep the
paper's quaternion rows and R; the ``+flexure`` variants are navreplay's filters (the
defaults): the flexure states at the scenario's values and the quaternion rows of the GINS
noise (docs/methods/transfer-alignment.md §4.4, §4.9)."""
AXES = ("N", "E", "D")
T_EVAL = (30.0, 100.0)
"""Times of the table [s]."""
MRAD = 1e-3


@dataclasses.dataclass(frozen=True)
class Condition:
    """One scenario condition of the campaign and the filter variants replayed over it."""

    name: str
    key: str
    values: Mapping[str, Any]
    variants: tuple[str, ...]
    filter_values: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    """Filter parameters of the condition: the flexure rate its lever-arm term misses."""


CONDITIONS = (
    Condition("flexure", "flexure", {}, (PARTIAL, FULL, VEL_ONLY, PARTIAL_FLEX, FULL_FLEX)),
    Condition("no flexure", "no_flexure", {"flexure_sigma": 0.0}, (PARTIAL, FULL),
              {"flexure_rate_sigma": 0.0}),
    Condition("wn 1 rad/s", "wn_1", {"flexure_wn": 1.0}, (PARTIAL, FULL),
              {"flexure_rate_sigma": flexure_rate_sigma(0.5 * DEG, 0.7, 1.0, 100.0)}),
)

PAPER = {
    (PARTIAL, "flexure", 100.0): "< 1 / < 1 / ~3",
    (FULL, "flexure", 100.0): "D markedly worse",
    (VEL_ONLY, "flexure", 100.0): "D unobservable",
}
"""The paper's statements about its Figs. 2 and 3 (docs/methods/transfer-alignment.md §6)
[mrad]."""

REFERENCE = {
    (PARTIAL, "flexure", 30.0): "0.46 / 0.42 / 3.4 (max D 12)",
    (PARTIAL, "flexure", 100.0): "0.43 / 0.41 / 2.36 (max 1.0 / 1.0 / 5.5)",
    (FULL, "flexure", 30.0): "0.84 / 1.43 / 22.6",
    (FULL, "flexure", 100.0): "0.94 / 1.45 / 14.2 (max 2.6 / 4.0 / 46)",
    (VEL_ONLY, "flexure", 100.0): "~0.45 / ~0.45 / > 100 (12 runs)",
    (FULL, "no flexure", 100.0): "0.45 / 0.46 / 1.66 (12 runs)",
    (PARTIAL, "wn 1 rad/s", 100.0): "0.46 / 0.46 / 2.5 (12 runs)",
    (FULL, "wn 1 rad/s", 100.0): "2.1 / 3.2 / 28.9 (12 runs)",
}
"""An independent reference implementation (36 runs, 50 Hz IMU unless noted) [mrad]
(docs/methods/transfer-alignment.md §6)."""
REFERENCE_SIGMA = "0.08 / 0.11 / 0.47"
"""The reference's predicted 1 sigma of phi at 100 s, partial matching [mrad]."""


# --------------------------------------------------------------------------------------------
# per run (in the workers)


@dataclasses.dataclass
class RunErrors:
    """Alignment errors of one run of one variant.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Estimate times [s].
    phi : ndarray, shape (K, 3)
        Alignment error phi N, E, D [rad] against the truth.
    sigma : ndarray, shape (K, 3)
        The filter's predicted 1 sigma of phi [rad].
    """

    t: np.ndarray
    phi: np.ndarray
    sigma: np.ndarray


def alignment_errors(result: RunResult, recording: Recording) -> RunErrors:
    """phi of a run's navigation solution against the recording's truth, and its sigma."""
    truth = truth_at(recording, result.t)
    phi = attitude_error(quat_to_dcm(result.nav_q_nb), quat_to_dcm(truth["q_nb"]))
    return RunErrors(result.t, phi, result.extras["attitude_sigma_n"])


def extract(
    recording: Recording, results: dict[str, RunResult], task: RunTask
) -> dict[str, RunErrors]:
    """Extractor of :func:`navreplay.campaign.ensemble.run_ensemble`: errors per variant label."""
    return {label: alignment_errors(res, recording) for label, res in results.items()}


# --------------------------------------------------------------------------------------------
# statistics over runs


@dataclasses.dataclass
class VariantStats:
    """Statistics over the runs of one variant in one condition.

    Attributes
    ----------
    t : ndarray, shape (K,)
        [s]
    phi : ndarray, shape (runs, K, 3)
        Errors of every run [rad].
    sigma : ndarray, shape (runs, K, 3)
        Predicted 1 sigma of every run [rad].
    """

    t: np.ndarray
    phi: np.ndarray
    sigma: np.ndarray

    @property
    def rms(self) -> np.ndarray:
        """RMS over runs versus time, (K, 3) [rad]."""
        return rms(self.phi, axis=0)

    @property
    def sigma_rms(self) -> np.ndarray:
        """Root mean predicted variance over runs versus time, (K, 3) [rad]."""
        return rms(self.sigma, axis=0)

    def index(self, t: float) -> int:
        """Row of the estimate nearest to t [s]."""
        return int(np.argmin(np.abs(self.t - t)))

    def rms_at(self, t: float) -> np.ndarray:
        """RMS over runs at t, (3,) [rad]."""
        return self.rms[self.index(t)]

    def max_at(self, t: float) -> np.ndarray:
        """Largest absolute error over runs at t, (3,) [rad]."""
        return np.max(np.abs(self.phi[:, self.index(t)]), axis=0)


class _Collector:
    """Sink of :func:`run_ensemble`: keeps each run's errors per label, in run order."""

    def __init__(self) -> None:
        self.runs: dict[str, list[RunErrors]] = {}

    def __call__(self, out: RunOutput) -> None:
        for label, err in out.metrics.items():
            self.runs.setdefault(label, []).append(err)

    def stats(self) -> dict[str, VariantStats]:
        out = {}
        for label, errs in self.runs.items():
            t = errs[0].t
            if any(e.t.shape != t.shape or not np.allclose(e.t, t) for e in errs):
                raise ValueError(f"{label}: runs have different estimate times")
            out[label] = VariantStats(t, np.stack([e.phi for e in errs]),
                                      np.stack([e.sigma for e in errs]))
        return out


def run_campaign(
    runs: int,
    seed: int = 0,
    workers: int = 1,
    conditions: tuple[Condition, ...] = CONDITIONS,
    progress: Progress | None = None,
) -> tuple[dict[tuple[str, str], VariantStats], float]:
    """Run every condition of the campaign in memory over one process pool.

    Returns
    -------
    stats : dict (variant, condition name) -> VariantStats
    seconds : float
        Wall time [s].
    """
    warm_up(SCENARIO, 0.3, [FilterSpec(FILTER)])
    total = runs * len(conditions)
    done = 0

    def step(_d: int, _t: int) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    wall0 = time.perf_counter()
    executor = make_executor(workers)
    out: dict[tuple[str, str], VariantStats] = {}
    try:
        for cond in conditions:
            tasks = monte_carlo_tasks(SCENARIO, runs, values=cond.values, seed=seed)
            filters = [FilterSpec(FILTER, {**VARIANTS[v], **cond.filter_values}, label=v)
                       for v in cond.variants]
            sink = _Collector()
            run_ensemble(tasks, filters, sink, extract=extract, workers=workers,
                         executor=executor, progress=step)
            for label, st in sink.stats().items():
                out[(label, cond.name)] = st
    finally:
        executor.shutdown(wait=True)
    return out, time.perf_counter() - wall0


# --------------------------------------------------------------------------------------------
# acceptance (docs/methods/transfer-alignment.md §6)


def acceptance(stats: Mapping[tuple[str, str], VariantStats]) -> list[Check]:
    """Every acceptance band of docs/methods/transfer-alignment.md §6 at t = 100 s, as checks
    (values in mrad)."""
    t = T_EVAL[-1]
    part = stats[(PARTIAL, "flexure")]
    full = stats[(FULL, "flexure")]
    rp = part.rms_at(t) / MRAD
    rf = full.rms_at(t) / MRAD
    level = np.abs(part.phi[:, part.index(t), 0:2]) < 1.0 * MRAD
    frac = float(np.mean(np.all(level, axis=1)))
    checks = [
        Check("partial: RMS phi_N at 100 s [mrad]", rp[0], "<= 1.0", rp[0] <= 1.0),
        Check("partial: RMS phi_E at 100 s [mrad]", rp[1], "<= 1.0", rp[1] <= 1.0),
        Check("partial: fraction of runs with |phi_N| and |phi_E| < 1 mrad at 100 s", frac,
               ">= 0.9", frac >= 0.9),
        Check("partial: RMS phi_D at 100 s [mrad]", rp[2], "1.5 .. 4.5",
               1.5 <= rp[2] <= 4.5),
        Check("full, flexure: RMS phi_D / partial RMS phi_D at 100 s", rf[2] / rp[2],
               ">= 2.5", rf[2] >= 2.5 * rp[2]),
        Check("full, flexure: RMS phi_D at 100 s [mrad]", rf[2], ">= 5", rf[2] >= 5.0),
    ]
    if (FULL, "no flexure") in stats and (PARTIAL, "no flexure") in stats:
        f0 = stats[(FULL, "no flexure")].rms_at(t)[2] / MRAD
        p0 = stats[(PARTIAL, "no flexure")].rms_at(t)[2] / MRAD
        checks.append(Check("full, no flexure: RMS phi_D / partial (no flexure) RMS phi_D",
                             f0 / p0, "<= 1.5", f0 <= 1.5 * p0))
    if (VEL_ONLY, "flexure") in stats:
        v = stats[(VEL_ONLY, "flexure")].rms_at(t)[2] / MRAD
        checks.append(Check("vel_only: RMS phi_D at 100 s [mrad]", v, ">= 10", v >= 10.0))
    return checks


# --------------------------------------------------------------------------------------------
# table


def format_table(stats: Mapping[tuple[str, str], VariantStats], runs: int) -> str:
    """The table of docs/methods/transfer-alignment.md §6: paper and reference next to
    navreplay [mrad]."""
    head = (f"{'variant':<25}{'condition':<12}{'t':>6}  {'paper':<17}"
            f"{'reference (36 runs, 50 Hz)':<42}navreplay ({runs} runs, 100 Hz)")
    lines = [
        "RMS over runs of phi_N / phi_E / phi_D [mrad] (max |phi| over runs in brackets)",
        head,
        "-" * len(head),
    ]
    for cond in CONDITIONS:
        for variant in cond.variants:
            st = stats.get((variant, cond.name))
            if st is None:
                continue
            for t in T_EVAL:
                ours = f"{slashed(st.rms_at(t) / MRAD)} (max {slashed(st.max_at(t) / MRAD)})"
                paper = PAPER.get((variant, cond.name, t), "")
                ref = REFERENCE.get((variant, cond.name, t), "")
                lines.append(f"{variant:<25}{cond.name:<12}{t:>5.0f}s  {paper:<17}{ref:<42}"
                             f"{ours}")
    part = stats[(PARTIAL, "flexure")]
    lines += [
        "",
        "Predicted 1 sigma of phi at 100 s, partial, flexure (with the consider terms of the "
        "accelerometer and GINS-heading constants):",
        f"  navreplay {slashed(part.sigma_rms[part.index(T_EVAL[-1])] / MRAD)} mrad; "
        f"from P alone, as in the paper: reference {REFERENCE_SIGMA}",
        "RMS / predicted sigma at 100 s, flexure, phi_N / phi_E / phi_D:",
    ]
    lines += [f"  {label:<25}{slashed(ratio)}" for label, ratio in consistency(stats).items()]
    return "\n".join(lines)


def consistency(stats: Mapping[tuple[str, str], VariantStats]) -> dict[str, np.ndarray]:
    """RMS error over predicted sigma at 100 s under flexure, N, E, D, per variant with
    quaternion matching (1: the reported sigma tells the truth)."""
    out = {}
    for (label, cond), st in stats.items():
        if cond == "flexure" and label != VEL_ONLY:
            k = st.index(T_EVAL[-1])
            out[label] = st.rms[k] / st.sigma_rms[k]
    return out


# --------------------------------------------------------------------------------------------
# figures (Figs. 2 and 3)


def figures(stats: Mapping[tuple[str, str], VariantStats]) -> dict[str, Any]:
    """Ensemble series of the Figs. 2 and 3 equivalents [mrad], by plot then series name.

    Fig. 2: RMS level errors phi_N, phi_E of every variant under flexure with the partial
    filter's predicted sigma. Fig. 3: RMS azimuth error phi_D of partial and full matching with
    their predicted sigma, one plot per condition. vel_only's azimuth (tens of mrad) has its own.
    """
    part = stats[(PARTIAL, "flexure")]
    plots: dict[str, dict[str, np.ndarray]] = {}
    for k, axis in enumerate(AXES[:2]):
        series = {f"{variant} RMS": st.rms[:, k] / MRAD
                  for (variant, cond), st in stats.items() if cond == "flexure"}
        series[f"{PARTIAL} sigma"] = part.sigma_rms[:, k] / MRAD
        plots[f"fig2 level error phi_{axis}"] = series
    for cond in CONDITIONS:
        series = {}
        for variant in cond.variants:
            st = stats.get((variant, cond.name))
            if st is not None and variant != VEL_ONLY:
                series[f"{variant} RMS"] = st.rms[:, 2] / MRAD
                series[f"{variant} sigma"] = st.sigma_rms[:, 2] / MRAD
        if series:
            suffix = "" if cond.key == "flexure" else f" {cond.key}"
            plots[f"fig3 azimuth error phi_D{suffix}"] = series
    if (VEL_ONLY, "flexure") in stats:
        st = stats[(VEL_ONLY, "flexure")]
        plots["azimuth error phi_D vel_only"] = {
            f"{VEL_ONLY} RMS": st.rms[:, 2] / MRAD, f"{VEL_ONLY} sigma": st.sigma_rms[:, 2] / MRAD,
        }
    return {"t": part.t, "plots": plots}


# --------------------------------------------------------------------------------------------
# the reproduction


class TransferAlignmentReproduction(Reproduction):
    """``navreplay reproduce transfer-alignment``: the campaign of
    docs/methods/transfer-alignment.md §6.

    ``runs`` counts runs per condition; ``progress`` counts recordings.
    """

    name = "transfer-alignment"
    method_doc = "docs/methods/transfer-alignment.md"
    summary = ("Shipboard transfer alignment, velocity + quaternion partial matching "
               "(Song, Jeon & Lyou; Figs. 2-3)")
    default_runs = 36
    """Runs per condition (the paper's Monte Carlo size)."""
    quick_runs = 12
    """Runs per condition for a quick look (``navreplay demo``, ``--quick``); fewer runs leave
    the RMS azimuth too uncertain (about +-30 % at 6 runs) for the bands."""

    def campaign(
        self, runs: int, *, seed: int, workers: int, progress: Progress | None
    ) -> Report:
        stats, wall = run_campaign(runs, seed, workers, progress=progress)
        n_filter = runs * sum(len(c.variants) for c in CONDITIONS)
        p = ShipTransferAlignmentParams()
        n_imu = n_filter * round(p.duration * p.imu_rate)
        table = format_table(stats, runs) + (
            f"\n\nCampaign: {runs * len(CONDITIONS)} recordings, {n_filter} filter runs "
            f"({n_imu / 1e6:.2f} M IMU samples) in {wall:.1f} s wall, {workers} worker(s)"
        )
        figs = figures(stats)
        figs["timing"] = {"wall_s": wall, "recordings": runs * len(CONDITIONS),
                          "filter_runs": n_filter}
        return Report(
            title=(f"Transfer alignment, velocity + quaternion partial matching (Song, Jeon & "
                   f"Lyou): {runs} runs per condition, seed {seed}"),
            table=table,
            checks=acceptance(stats),
            figures=figs,
            bands=f"{self.method_doc} §6",
        )

    @staticmethod
    def log_view(sink: Any, figures: Mapping[str, Any]) -> None:
        """The Figs. 2 and 3 equivalents as ``/ensemble/<plot>/<series>`` in mrad versus
        time."""
        for name, series in figures["plots"].items():
            sink.log_ensemble(name, figures["t"], series, unit="mrad")


REPRODUCTION = TransferAlignmentReproduction()
