"""Reproduction of the RPM velocity-aided underwater INS with sea-current estimation.

The published results and acceptance bands of docs/methods/rpm-aided-ins.md §6 (Choi, JANT
23(3), 2019; Table 3, Figs. 3-5). The campaign simulates ``runs`` recordings of the
``underwater-rpm`` scenario (run i with seed ``seed + i``, the convention of
:func:`navreplay.campaign.tasks.monte_carlo_tasks`, so ``navreplay simulate underwater-rpm
--seed S+i`` reproduces any single run) and replays the ``rpm-aided-ins`` filter over each in
its three modes:

==============  ======================  ==============================================
label           filter ``mode``         paper
==============  ======================  ==============================================
pure            ``pure``                "Pure navigation" (free inertial)
rpm             ``rpm``                 "Aided Navi." (RPM + depth, no current)
rpm-current     ``rpm_current``         "Aided Navi. est Current" (33 states)
==============  ======================  ==============================================

Metrics (eqs. 28-30, :mod:`navreplay.metrics`), at the 1-Hz update epochs (the estimate after
the depth update): north and east errors ``x_lat = (L_hat - L)(R_M - d)``,
``x_long = (lambda_hat - lambda)(R_N - d) cos L``; LatRMS, LongRMS over the runs;
``CEP50 = 0.5887 (LatRMS + LongRMS)``; ``DT CEP50 = CEP50 / DT x 100 %`` with DT the mean
true 3-D path length; the run-averaged 2-dof position NEES with its 95 % chi-square band;
the RMS of the current-estimate error per axis. Table 3 is evaluated at t = 480 s.

Everything runs in memory over a process pool (:func:`navreplay.campaign.ensemble.run_ensemble`);
each worker reduces its run to 1-Hz metrics before sending them back.

Examples
--------
>>> from navreplay.reproduce import get
>>> report = get("rpm-aided-ins").run(runs=10, workers=2)   # doctest: +SKIP
>>> print(report.format())                                  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay.campaign.ensemble import run_ensemble
from navreplay.campaign.tasks import RunOutput, RunTask, monte_carlo_tasks
from navreplay.core.params import build
from navreplay.core.streams import Recording
from navreplay.filters.result import RunResult
from navreplay.filters.rpm_aided_ins import Mode
from navreplay.metrics import EnsembleResult, EnsembleStats, RunMetrics, consistency, run_metrics
from navreplay.replay.spec import FilterSpec
from navreplay.reproduce import Check, Progress, Report, Reproduction, warm_up
from navreplay.sim.scenarios.underwater import UnderwaterRpmParams

SCENARIO = "underwater-rpm"
FILTER = "rpm-aided-ins"
MODES: dict[str, Mode] = {"pure": Mode.PURE, "rpm": Mode.RPM, "rpm-current": Mode.RPM_CURRENT}
"""Campaign label -> filter mode."""
PAPER_LABELS = {
    "pure": "Pure navigation",
    "rpm": "Aided Navi.",
    "rpm-current": "Aided Navi. est Current",
}
PAPER_DT_CEP50 = {"pure": 12.572, "rpm": 1.581, "rpm-current": 0.957}
"""Table 3 of the paper: DT CEP50 [%] (1 sigma), 100 runs."""
PAPER_IMPROVEMENT = 39.4
"""Improvement of rpm-current over rpm claimed by the paper [%]."""
PREDICTION = {
    "pure": "814 / 805 m, 13.9 %",
    "rpm": "83 / 85 m, 1.44 %",
    "rpm-current": "44-48 / 43-48 m, 0.75-0.78 %",
}
"""Reference prediction: a linear error-state Monte Carlo of the same scenario, by an independent
reference implementation (LatRMS / LongRMS, DT CEP50; docs/methods/rpm-aided-ins.md §6)."""
PREDICTION_PER_AXIS = "1143 / 1135 m, 19.6 %"
"""The same for pure navigation with ``level_mil_per_axis``."""
T_CURRENT = 90.0
"""The current-estimate band holds from the end of the first turn [s]."""
T_NEES = 30.0
"""The NEES band is evaluated from this time on [s] (before it the horizontal position
error is still dominated by the 1-cm launch sigma of P0, not by the current)."""
UPDATE_RATE = 1.0
"""Rate of the evaluation epochs [Hz] (the filter's update rate)."""


# --------------------------------------------------------------------------------------------
# worker side


def at_update_epochs(result: RunResult, rate: float = UPDATE_RATE) -> RunResult:
    """The rows of a run at the update epochs ``k / rate``: the last estimate at each (after
    all of that epoch's updates)."""
    t = result.t
    grid = np.arange(0.0, t[-1] + 1e-9, 1.0 / rate)
    last = np.searchsorted(t, grid + 1e-6, side="right") - 1
    keep = (last >= 0) & (np.abs(t[np.clip(last, 0, None)] - grid) < 1e-6)
    i = last[keep]
    return dataclasses.replace(
        result, t=t[i], x=result.x[i], P=result.P[i],
        nav_pos=None if result.nav_pos is None else result.nav_pos[i],
        nav_v_n=None if result.nav_v_n is None else result.nav_v_n[i],
        nav_q_nb=None if result.nav_q_nb is None else result.nav_q_nb[i],
        extras={k: v[i] for k, v in result.extras.items()},
        innovations={},
    )


@dataclasses.dataclass
class RunScores:
    """One run of the campaign: metrics per label at the update epochs; for the first run also
    the current estimate of ``rpm-current`` (t (K,), estimate (K, 2), truth (2,), sigma (K, 2))
    for Fig. 3."""

    metrics: dict[str, RunMetrics]
    current: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None


def extract(recording: Recording, results: dict[str, RunResult], task: RunTask) -> RunScores:
    """Extractor of :func:`navreplay.campaign.ensemble.run_ensemble` (runs in the worker)."""
    out = RunScores({label: run_metrics(at_update_epochs(res), recording)
                     for label, res in results.items()})
    if task.index == 0 and "rpm-current" in results:
        res = at_update_epochs(results["rpm-current"])
        i = [res.state_names.index(n) for n in ("vc_N", "vc_E")]
        truth = np.asarray(recording.metadata.true_errors["current_n"], dtype=float)[:2]
        out.current = (res.t, res.x[:, i], truth, np.sqrt(res.P[:, i, i]))
    return out


class _Collector:
    """Sink of :func:`run_ensemble`: ensemble statistics per label, the Fig. 3 example run."""

    def __init__(self) -> None:
        self.stats = {label: EnsembleStats(label) for label in MODES}
        self.current: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self.seconds = 0.0

    def __call__(self, out: RunOutput) -> None:
        scores: RunScores = out.metrics
        for label, m in scores.metrics.items():
            self.stats[label].add(m)
        if scores.current is not None:
            self.current = scores.current
        self.seconds += out.seconds


def run_campaign(
    runs: int,
    seed: int = 0,
    workers: int = 1,
    values: Mapping[str, Any] | None = None,
    progress: Progress | None = None,
) -> tuple[dict[str, EnsembleResult], tuple | None, float, float]:
    """Simulate ``runs`` recordings and replay the three modes over each.

    Returns
    -------
    stats : dict label -> EnsembleResult
    current : (t, estimate (K, 2), truth (2,), sigma (K, 2)) of run 1, or None
    wall : float
        Wall time [s], simulation included.
    worker_seconds : float
        Sum of the runs' own wall times [s].
    """
    filters = [FilterSpec(FILTER, {"mode": mode.value}, label=label)
               for label, mode in MODES.items()]
    warm_up(SCENARIO, 2.0, filters)
    wall0 = time.perf_counter()
    tasks = monte_carlo_tasks(SCENARIO, runs, values=dict(values or {}), seed=seed)
    sink = _Collector()
    run_ensemble(tasks, filters, sink, extract=extract, workers=workers, progress=progress)
    wall = time.perf_counter() - wall0
    return ({label: st.result() for label, st in sink.stats.items()}, sink.current, wall,
            sink.seconds)


# --------------------------------------------------------------------------------------------
# evaluation


@dataclasses.dataclass(frozen=True)
class ModeResult:
    """Table 3 row of one mode: final-epoch LatRMS, LongRMS, CEP50 [m], DT [m], DT CEP50 [%]."""

    lat_rms: float
    long_rms: float
    cep50: float
    distance: float
    dt_cep50: float


def table3(stats: Mapping[str, EnsembleResult]) -> dict[str, ModeResult]:
    """The final-epoch numbers of eqs. (28)-(30) per label."""
    out = {}
    for label, r in stats.items():
        lat, lon = (float(v) for v in r.rms["pos_ned"][-1, :2])
        out[label] = ModeResult(lat, lon, float(r.cep50[-1]), float(r.distance[-1]),
                                float(r.dt_cep50[-1]))
    return out


def _state(r: EnsembleResult, name: str) -> int:
    return r.state_names.index(name)


def current_rms(r: EnsembleResult) -> np.ndarray:
    """RMS over runs of the current-estimate error, N and E [m/s], shape (K, 2)."""
    return r.state_rms[:, [_state(r, "vc_N"), _state(r, "vc_E")]]


def nees_inside(r: EnsembleResult, t_from: float = T_NEES) -> tuple[float, float]:
    """Fraction of epochs from ``t_from`` whose run-averaged NEES lies in its pointwise 95 %
    band (information only: the curve is flat, so this is one test, not many), and the mean
    NEES over those epochs."""
    sel = (r.t >= t_from - 1e-9) & (r.nees_count > 0)
    lo, hi = r.nees_bounds
    v = r.nees_mean[sel]
    inside = (v >= lo[sel]) & (v <= hi[sel])
    return float(np.mean(inside)), float(np.mean(v))


def nees_check(mean: float, runs: int, dof: int, what: str) -> Check:
    """The position-consistency check (docs/methods/consistency.md): the mean over ``runs``
    runs of each run's time-averaged ``dof``-dof NEES inside the band of ``runs``
    chi-square(dof) draws at the false-alarm probability
    :data:`navreplay.metrics.consistency.CHECK_FALSE_ALARM`."""
    lo, hi = consistency.mean_band(dof, runs)
    return Check(f"{what}: {dof}-dof position NEES, mean over runs and t >= {T_NEES:g} s "
                 f"({runs} runs as {runs} chi-square samples, false alarm "
                 f"{consistency.CHECK_FALSE_ALARM:g})",
                 mean, f"{lo:.2f} to {hi:.2f}", bool(lo <= mean <= hi))


def run_nees(recording: Recording, results: dict[str, RunResult], task: RunTask) -> float:
    """Extractor: the time-averaged position NEES of one ``rpm-current`` run over the
    update epochs from :data:`T_NEES`."""
    m = run_metrics(at_update_epochs(results["rpm-current"]), recording)
    return float(np.nanmean(m.nees[m.t >= T_NEES - 1e-9]))


def position_nees_per_run(runs: int, seed: int = 0, workers: int = 1) -> np.ndarray:
    """Time-averaged position NEES of ``runs`` ``rpm-current`` runs (seeds ``seed + i``),
    shape (runs,): the samples of the pooled consistency check of
    docs/methods/consistency.md."""
    out: list[float] = []
    run_ensemble(monte_carlo_tasks(SCENARIO, runs, seed=seed),
                 [FilterSpec(FILTER, {"mode": Mode.RPM_CURRENT.value}, label="rpm-current")],
                 lambda o: out.append(o.metrics), extract=run_nees, workers=workers,
                 output_rate=None)
    return np.asarray(out)


def acceptance(stats: Mapping[str, EnsembleResult], per_axis: bool = False) -> list[Check]:
    """Every acceptance band of docs/methods/rpm-aided-ins.md §6 as checks.

    Parameters
    ----------
    stats : mapping label -> EnsembleResult
        At the update epochs, labels of :data:`MODES`.
    per_axis : bool
        The campaign ran with ``level_mil_per_axis`` (other pure-navigation band).
    """
    t3 = table3(stats)
    pure, rpm, cur = (t3[k].dt_cep50 for k in ("pure", "rpm", "rpm-current"))
    lo, hi = (15.0, 24.0) if per_axis else (9.0, 18.0)
    improvement = 100.0 * (rpm - cur) / rpm
    checks = [
        Check("pure DT CEP50 [%]", pure, f"{lo:g} to {hi:g}", lo <= pure <= hi),
        Check("rpm DT CEP50 [%]", rpm, "0.9 to 2.5", 0.9 <= rpm <= 2.5),
        Check("rpm-current DT CEP50 [%]", cur, "0.5 to 1.3", 0.5 <= cur <= 1.3),
        Check("pure / rpm DT CEP50", pure / rpm, ">= 5", pure >= 5.0 * rpm),
        Check("rpm-current < rpm: improvement [%]", improvement, ">= 25 (paper 39.4)",
               cur < rpm and improvement >= 25.0),
    ]
    r = stats["rpm-current"]
    late = r.t >= T_CURRENT - 1e-9
    c = current_rms(r)
    for j, axis in enumerate("NE"):
        v = float(np.max(c[late, j])) if late.any() else np.nan  # fails: run too short
        checks.append(Check(f"rpm-current: max RMS current error {axis} for t >= 90 s [m/s]",
                             v, "<= 0.15", v <= 0.15))
    frac, mean = nees_inside(r)
    checks.append(nees_check(mean, int(np.max(r.nees_count)), r.nees_dof,
                             f"rpm-current ({frac:.0%} of epochs in the pointwise 95 % band)"))
    return checks


def format_table(stats: Mapping[str, EnsembleResult], runs: int, per_axis: bool = False) -> str:
    """Table 3 (DT CEP50, paper vs navreplay) with LatRMS / LongRMS and the reference
    prediction (:data:`PREDICTION`)."""
    t3 = table3(stats)
    head = (f"{'mode':<26}{'paper':>9}{'navreplay':>11}{'LatRMS':>9}{'LongRMS':>9}"
            f"{'CEP50':>8}   reference prediction (Lat / Long RMS, DT CEP50)")
    lines = [
        f"Table 3: DT CEP50 (1 sigma) at t = {stats['pure'].t[-1]:.0f} s; paper 100 runs, "
        f"navreplay {runs}",
        head,
        f"{'':<26}{'[%]':>9}{'[%]':>11}{'[m]':>9}{'[m]':>9}{'[m]':>8}",
        "-" * len(head),
    ]
    for label, row in t3.items():
        pred = PREDICTION_PER_AXIS if (per_axis and label == "pure") else PREDICTION[label]
        lines.append(
            f"{PAPER_LABELS[label]:<26}{PAPER_DT_CEP50[label]:>9.3f}{row.dt_cep50:>11.3f}"
            f"{row.lat_rms:>9.1f}{row.long_rms:>9.1f}{row.cep50:>8.1f}   {pred}"
        )
    rpm, cur = t3["rpm"].dt_cep50, t3["rpm-current"].dt_cep50
    lines += [
        f"{'improvement by the current':<26}{PAPER_IMPROVEMENT:>8.1f}%"
        f"{100.0 * (rpm - cur) / rpm:>10.1f}%{'':>26}   40-50 %",
        f"DT (mean true 3-D path length) = {t3['pure'].distance / 1e3:.3f} km",
    ]
    r = stats["rpm-current"]
    c = current_rms(r)
    k = [_state(r, n) for n in ("k_rpm", "m_y", "m_z")]
    lines.append(
        f"rpm-current at {r.t[-1]:.0f} s: current error RMS N / E {c[-1, 0]:.3f} / "
        f"{c[-1, 1]:.3f} m/s (reference about 0.09); RPM scale-factor residual RMS "
        f"{100 * r.state_rms[-1, k[0]]:.3f} % (reference about 0.05 %); misalignment residual RMS "
        f"y / z {np.degrees(r.state_rms[-1, k[1]]):.4f} / {np.degrees(r.state_rms[-1, k[2]]):.4f}"
        " deg"
    )
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# figures and the Rerun view


def figures(stats: Mapping[str, EnsembleResult], current: tuple | None) -> dict[str, Any]:
    """The data of Figs. 3-5 (plus the NEES) as plain arrays."""
    r = stats["rpm-current"]
    figs: dict[str, Any] = {
        "t": r.t,
        "lat_rms": {label: s.rms["pos_ned"][:, 0] for label, s in stats.items()},
        "long_rms": {label: s.rms["pos_ned"][:, 1] for label, s in stats.items()},
        "lat_sigma": {label: s.sigma["pos_ned"][:, 0] for label, s in stats.items()},
        "long_sigma": {label: s.sigma["pos_ned"][:, 1] for label, s in stats.items()},
        "current_rms": current_rms(r),
        "current_sigma": r.state_sigma[:, [_state(r, "vc_N"), _state(r, "vc_E")]],
        "nees": {label: s.nees_mean for label, s in stats.items() if label != "pure"},
        "nees_bounds": r.nees_bounds,
        "dt_cep50": {label: s.dt_cep50 for label, s in stats.items()},
    }
    if current is not None:
        figs["current_run1"] = {"t": current[0], "estimate": current[1], "truth": current[2],
                                "sigma": current[3]}
    return figs


# --------------------------------------------------------------------------------------------
# the reproduction


class RpmAidedInsReproduction(Reproduction):
    """``navreplay reproduce rpm-aided-ins``: the campaign of docs/methods/rpm-aided-ins.md §6.

    ``runs`` counts recordings (each replayed in the three modes), and so does ``progress``.
    The option ``values`` holds scenario parameter overrides (e.g.
    ``{"level_mil_per_axis": True}``, which also selects the other pure-navigation band).
    """

    name = "rpm-aided-ins"
    method_doc = "docs/methods/rpm-aided-ins.md"
    summary = ("Underwater INS aided by propeller RPM with sea-current estimation "
               "(Choi 2019; Table 3, Figs. 3-5)")
    default_runs = 100
    """Runs (recordings; each is replayed in the three modes), as in the paper."""
    quick_runs = 10
    """Runs for a quick look (``navreplay demo``); the bands are meant for 100."""

    def campaign(
        self, runs: int, *, seed: int, workers: int, progress: Progress | None,
        values: Mapping[str, Any] | None = None,
    ) -> Report:
        values = dict(values or {})
        p = build(UnderwaterRpmParams, values, where=f"scenario {SCENARIO}")
        stats, current, wall, worker_s = run_campaign(runs, seed, workers, values, progress)
        n_imu = 3 * runs * round(p.duration * p.imu_rate)
        table = format_table(stats, runs, p.level_mil_per_axis) + (
            f"\n\nCampaign: {runs} recordings simulated, {3 * runs} filter runs "
            f"({n_imu / 1e6:.1f} M IMU samples) in {wall:.1f} s wall, {workers} worker(s) "
            f"({worker_s:.1f} s of worker time)"
        )
        figs = figures(stats, current)
        figs["timing"] = {"wall_s": wall, "worker_s": worker_s, "recordings": runs,
                          "filter_runs": 3 * runs}
        return Report(
            title=(f"RPM velocity-aided underwater INS with sea-current estimation (Choi 2019): "
                   f"{runs} runs, seed {seed}"),
            table=table,
            checks=acceptance(stats, p.level_mil_per_axis),
            figures=figs,
            bands=f"{self.method_doc} §6",
        )

    @staticmethod
    def log_view(sink: Any, figs: Mapping[str, Any]) -> None:
        """Log the Figs. 3-5 equivalents into an open :class:`navreplay.viz.Sink`.

        ``/ensemble/fig3 current ...`` (current estimate of run 1 with its 1-sigma bounds
        against the truth: it ends within them, not on the truth, docs/methods/rpm-aided-ins.md
        §4.8; and the
        RMS of the current error with the filter's sigma), ``/ensemble/fig4 longitude error RMS``
        and ``/ensemble/fig5 latitude error RMS`` (the three modes overlaid, each with its mean
        predicted sigma), the run-averaged position NEES with its 95 % band, and DT CEP50 over time.
        """
        t = np.asarray(figs["t"], dtype=float)
        if "current_run1" in figs:
            c = figs["current_run1"]
            ct = np.asarray(c["t"], dtype=float)
            for j, axis in enumerate("NE"):
                sink.log_ensemble(
                    f"fig3 current {axis} (run 1)", ct,
                    {"estimate": c["estimate"][:, j],
                     "estimate + sigma": c["estimate"][:, j] + c["sigma"][:, j],
                     "estimate - sigma": c["estimate"][:, j] - c["sigma"][:, j],
                     "truth": np.full(ct.shape, c["truth"][j])},
                    unit="m/s",
                )
        for j, axis in enumerate("NE"):
            sink.log_ensemble(
                f"fig3 current error {axis} RMS", t,
                {"filter RMS": figs["current_rms"][:, j],
                 "filter sigma": figs["current_sigma"][:, j]},
                unit="m/s",
            )
        for fig, key, what in (("fig4", "long", "longitude (east)"), ("fig5", "lat", "latitude "
                                                                                  "(north)")):
            series: dict[str, np.ndarray] = {}
            for label in MODES:
                series[f"{label} RMS"] = figs[f"{key}_rms"][label]
                series[f"{label} sigma"] = figs[f"{key}_sigma"][label]
            sink.log_ensemble(f"{fig} {what} error RMS", t, series, unit="m")
        lo, hi = figs["nees_bounds"]
        for label, nees in figs["nees"].items():  # one plot per mode: each at its own scale
            sink.log_ensemble(f"{label} position NEES (2 dof, run average)", t, {label: nees},
                              unit="-", bounds=(lo, hi))
        sink.log_ensemble("DT CEP50", t, dict(figs["dt_cep50"]), unit="%")


REPRODUCTION = RpmAidedInsReproduction()
