"""Reproduction of gyro-free attitude by specific-force vs gravity vector matching.

The published results and acceptance bands of docs/methods/vector-matching.md §6 (Choe &
Park, JKSAS 45(2), 2017, Figs. 1-5). The campaign:

- sweeps (``gimpo-accel-sweep``): axes N, E, D x 31 accelerations -1.5 g .. +1.5 g x ``runs``
  runs (100 in the paper: 9300 runs), metric the RMS over runs of the roll, pitch and yaw
  errors at t = 10 s (the last sample);
- yaw cases (``gimpo-accel-yaw``): cases x and y x ``10 runs`` runs (1000 in the full
  campaign), metric the RMS over runs versus time;

each replayed with both filter models (``gravity`` and ``specific-force``) on the same
recordings. Attitude errors are ZYX Euler-angle differences, estimate minus truth, with roll
and yaw wrapped to +-180 deg (:func:`euler_errors`).

Seeds: run i of every sweep point and of every yaw case uses seed ``seed + i`` (the convention
of :func:`navreplay.campaign.tasks.monte_carlo_tasks`), so
``navreplay simulate gimpo-accel-sweep --seed S+i -p axis=N -p accel_g=-0.8`` reproduces any
single run, and the points of a sweep share their sensor-error draws (common random numbers:
the curves over acceleration are smooth).

Fast path: a campaign of ~11,300 runs x 2 models goes through
:func:`navreplay.sim.scenarios.gimpo.simulate_runs` (the scenario's own sensor calls per seed,
no stream containers) and :func:`navreplay.filters.vector_matching.run_batch` (all runs of an
axis or a case as one stack). The tests show that it reproduces the reference path (scenario
-> Recording -> replay engine -> :class:`~navreplay.filters.vector_matching.VectorMatchingFilter`)
run for run; ``benchmarks/bench_vector_matching.py`` measures both.

Examples
--------
>>> from navreplay.reproduce import get
>>> report = get("vector-matching").run(runs=3)          # doctest: +SKIP
>>> print(report.format())                               # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from navreplay.campaign.executors import make_executor
from navreplay.core.units import DEG
from navreplay.filters.vector_matching import (
    MatchModel,
    Variant,
    VectorMatchingParams,
    reference,
    run_batch,
)
from navreplay.geo.earth import gravity
from navreplay.geo.rotations import quat_to_euler, wrap_angle
from navreplay.metrics import rms
from navreplay.reproduce import Check, Progress, Report, Reproduction, slashed
from navreplay.sim.scenarios.gimpo import (
    Axis,
    BodyAxis,
    GimpoAccelSweep,
    GimpoAccelSweepParams,
    GimpoAccelYaw,
    GimpoAccelYawParams,
    simulate_runs,
)

AXES: tuple[Axis, ...] = (Axis.N, Axis.E, Axis.D)
ACCEL_G: tuple[float, ...] = tuple(round(k / 10.0, 1) for k in range(-15, 16))
"""The 31 sweep accelerations [g]."""
MODELS: tuple[MatchModel, ...] = (MatchModel.GRAVITY, MatchModel.SPECIFIC_FORCE)
CASES: tuple[BodyAxis, ...] = (BodyAxis.X, BodyAxis.Y)
YAW_RUNS_PER_SWEEP_RUN = 10
"""Yaw-case runs per sweep-point run (1000 vs 100 in the full campaign)."""
ANGLES = ("roll", "pitch", "yaw")

# An independent reference implementation (30 runs per point), roll / pitch / yaw RMS [deg] at
# t = 10 s, (gravity, specific-force); docs/methods/vector-matching.md §6.
REFERENCE_SWEEP: dict[tuple[str, float], tuple[tuple[float, ...], tuple[float, ...]]] = {
    ("0", 0.0): ((1.24, 0.40, 1.73), (1.19, 0.40, 1.68)),
    ("N", -1.0): ((36.7, 47.6, 90.7), (2.3, 0.44, 3.1)),
    ("N", -0.8): ((18.3, 9.2, 28.8), (3.0, 0.44, 4.1)),
    ("N", 0.8): ((2.5, 0.56, 3.5), (0.77, 0.37, 0.98)),
    ("N", 1.0): ((5.0, 0.92, 6.9), (0.72, 0.36, 0.88)),
    ("N", 1.5): ((20.7, 7.3, 30.1), (0.62, 0.36, 0.70)),
    ("D", 1.0): ((2.6, 0.53, 3.6), (1.5, 0.34, 2.2)),
    ("D", 1.2): ((18.6, 8.1, 27.9), (2.1, 0.50, 3.0)),
    ("D", 1.5): ((30.2, 63.2, 146.0), (1.8, 0.46, 2.6)),
    ("D", -1.5): ((7.5, 1.5, 10.6), (0.6, 0.36, 0.9)),
}
REFERENCE_E_SWEEP = ("1.1-1.4 / 0.4 / 1.7-1.9", "0.6-1.3 / 0.3-0.4 / 0.8-1.8")
REFERENCE_YAW_PEAK: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {
    "x": ((4.1, 1.8, 6.0), (1.8, 1.5, 2.9)),
    "y": ((1.8, 4.9, 7.1), (1.6, 2.4, 3.7)),
}
REFERENCE_YAW_END = (1.3, 0.4, 1.9)
PAPER_CLAIMS = (
    "1. conventional errors larger for N- and D-axis acceleration than for E",
    "2. N axis: conventional error grows sharply beyond +-0.8 g (f near the field direction)",
    "3. D axis: conventional filter breaks down beyond +1 g (f vanishes, then reverses)",
    "4. the proposed model reduces all of these errors",
    "5. +-0.5 g without rotation: little effect; with the 90 deg yaw the conventional filter "
    "shows large errors and the proposed does not",
)


# --------------------------------------------------------------------------------------------
# metrics


def euler_errors(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """ZYX Euler-angle errors, estimate minus truth, roll and yaw wrapped to [-pi, pi).

    Parameters
    ----------
    q_est, q_true : ndarray, shape (..., 4)

    Returns
    -------
    ndarray, shape (..., 3)
        [rad].
    """
    d = quat_to_euler(q_est) - quat_to_euler(q_true)
    d[..., 0] = wrap_angle(d[..., 0])
    d[..., 2] = wrap_angle(d[..., 2])
    return d


# --------------------------------------------------------------------------------------------
# campaign pieces (module-level so that a process pool can run them)


@dataclasses.dataclass
class SweepAxisResult:
    """RMS errors of one sweep axis: ``rms`` (31, 2 models, 3 angles) [rad] at the last sample;
    ``runs`` per point; ``seconds`` of wall time split into simulation and filtering."""

    axis: str
    rms: np.ndarray
    runs: int
    sim_seconds: float
    filter_seconds: float


@dataclasses.dataclass
class YawCaseResult:
    """RMS errors of one yaw case versus time: ``t`` (K,) [s], ``rms`` (2 models, K, 3) [rad]."""

    case: str
    t: np.ndarray
    rms: np.ndarray
    runs: int
    sim_seconds: float
    filter_seconds: float


def _filter_params() -> list[VectorMatchingParams]:
    return [VectorMatchingParams(variant=Variant.PAPER, model=m) for m in MODELS]


def run_sweep_axis(axis: str, runs: int, seed: int) -> SweepAxisResult:
    """All 31 accelerations of one sweep axis, ``runs`` runs each, both models.

    The runs of all points are stacked and filtered as one batch per model.
    """
    scenario = GimpoAccelSweep()
    seeds = range(seed, seed + runs)
    t0 = time.perf_counter()
    parts, q_true = [], []
    for a in ACCEL_G:
        p = GimpoAccelSweepParams(axis=Axis(axis), accel_g=a)
        truth = scenario.truth(p)
        parts.append(simulate_runs(p, truth, seeds))
        q_true.append(truth.q_nb[-1])
    t_sim = time.perf_counter() - t0
    stack = {k: np.concatenate([getattr(d, k) for d in parts])
             for k in ("f_b", "m_b", "v_n", "vel_sigma")}
    out = np.empty((len(ACCEL_G), len(MODELS), 3))
    q_true_runs = np.repeat(np.array(q_true), runs, axis=0)
    t0 = time.perf_counter()
    for j, fp in enumerate(_filter_params()):
        ref = reference(fp, {"earth_field_n": truth.h_n}, {"pos": [p.lat, p.lon, p.height]})
        est = run_batch(fp, ref, truth.t, stack["f_b"], stack["m_b"], stack["v_n"],
                        stack["vel_sigma"])
        err = euler_errors(est.q_nb[:, -1], q_true_runs).reshape(len(ACCEL_G), runs, 3)
        out[:, j] = rms(err, axis=1)
    return SweepAxisResult(axis, out, runs, t_sim, time.perf_counter() - t0)


def run_yaw_case(case: str, runs: int, seed: int) -> YawCaseResult:
    """One yaw case, ``runs`` runs, both models: RMS errors versus time."""
    scenario = GimpoAccelYaw()
    p = GimpoAccelYawParams(case=BodyAxis(case))
    t0 = time.perf_counter()
    truth = scenario.truth(p)
    data = simulate_runs(p, truth, range(seed, seed + runs))
    t_sim = time.perf_counter() - t0
    out = np.empty((len(MODELS), truth.t.shape[0], 3))
    t0 = time.perf_counter()
    for j, fp in enumerate(_filter_params()):
        ref = reference(fp, {"earth_field_n": truth.h_n}, {"pos": [p.lat, p.lon, p.height]})
        est = run_batch(fp, ref, truth.t, data.f_b, data.m_b, data.v_n, data.vel_sigma)
        out[j] = rms(euler_errors(est.q_nb, truth.q_nb[None]), axis=0)
    return YawCaseResult(case, truth.t, out, runs, t_sim, time.perf_counter() - t0)


# --------------------------------------------------------------------------------------------
# acceptance (docs/methods/vector-matching.md §6)


def acceptance(sweep: dict[str, np.ndarray], yaw: dict[str, np.ndarray],
               yaw_t: np.ndarray) -> list[Check]:
    """Every acceptance band of docs/methods/vector-matching.md §6 (plus paper claim 1) as
    checks.

    Parameters
    ----------
    sweep : dict axis -> ndarray (31, 2, 3)
        RMS at t = 10 s [deg], models in :data:`MODELS` order.
    yaw : dict case -> ndarray (2, K, 3)
        RMS versus time [deg].
    yaw_t : ndarray (K,)
        [s].
    """
    g, s = 0, 1
    i0 = ACCEL_G.index(0.0)

    def at(axis: str, a: float) -> np.ndarray:
        return sweep[axis][ACCEL_G.index(a)]

    checks: list[Check] = []
    # a = 0, both models (the three axes share the 0 g runs; N is used)
    zero = at("N", 0.0)
    for j, m in enumerate(MODELS):
        for k, (angle, lim) in enumerate(zip(ANGLES, (2.0, 1.0, 3.0), strict=True)):
            checks.append(Check(f"a = 0, {m}: RMS {angle} at 10 s [deg]", zero[j, k],
                                 f"<= {lim}", zero[j, k] <= lim))
    # D sweep
    dmax = lambda a, j=g: float(np.max(at("D", a)[j]))  # noqa: E731
    checks += [
        Check("D sweep, gravity: max(r,p,y) RMS at +1.2 g [deg]", dmax(1.2), ">= 10",
               dmax(1.2) >= 10.0),
        Check("D sweep, gravity: max(r,p,y) RMS at +1.5 g [deg]", dmax(1.5), ">= 20",
               dmax(1.5) >= 20.0),
        Check("D sweep, gravity: max(r,p,y) RMS at +1.5 g / at +1.0 g", dmax(1.5) / dmax(1.0),
               ">= 5", dmax(1.5) >= 5.0 * dmax(1.0)),
    ]
    v = float(np.max(sweep["D"][:, s]))
    checks.append(Check("D sweep, specific-force: max RMS over r/p/y and all a [deg]", v,
                         "<= 5", v <= 5.0))
    # N sweep
    n0 = float(np.max(sweep["N"][i0, g]))
    for a in (-1.0, 1.2):
        v = float(np.max(at("N", a)[g]))
        checks.append(Check(f"N sweep, gravity: max(r,p,y) RMS at {a:+.1f} g / at 0 g",
                             v / n0, ">= 3", v >= 3.0 * n0))
    v = float(np.max(at("N", -0.8)[g]))
    checks.append(Check("N sweep, gravity: max(r,p,y) RMS at -0.8 g [deg]", v, ">= 10",
                         v >= 10.0))
    v = float(np.max(sweep["N"][:, s]))
    checks.append(Check("N sweep, specific-force: max RMS over r/p/y and all a [deg]", v,
                         "<= 6", v <= 6.0))
    # E sweep
    for j, m in enumerate(MODELS):
        v = float(np.max(sweep["E"][:, j]))
        checks.append(Check(f"E sweep, {m}: max RMS over r/p/y and all a [deg]", v, "<= 3",
                             v <= 3.0))
    v = float(np.max(np.abs(sweep["E"][:, g] - sweep["E"][:, s])))
    checks.append(Check("E sweep: max |gravity - specific-force| per point [deg]", v,
                         "<= 1.5", v <= 1.5))
    # |a| <= 0.5 g
    small = [i for i, a in enumerate(ACCEL_G) if abs(a) <= 0.5]
    v = max(float(np.max(np.abs(sweep[ax][small, g] - sweep[ax][small, s]))) for ax in sweep)
    checks.append(Check("|a| <= 0.5 g, all axes: max |gravity - specific-force| [deg]", v,
                         "<= 1.5", v <= 1.5))
    # yaw cases
    k30 = int(np.argmin(np.abs(yaw_t - 30.0)))
    for case, r in yaw.items():
        peak_g, peak_s = float(np.max(r[g, :, 2])), float(np.max(r[s, :, 2]))
        checks += [
            Check(f"yaw case {case}: peak RMS yaw gravity / specific-force", peak_g / peak_s,
                   ">= 1.5", peak_g >= 1.5 * peak_s),
            Check(f"yaw case {case}: specific-force peak RMS yaw [deg]", peak_s, "<= 6",
                   peak_s <= 6.0),
            Check(f"yaw case {case}: max over models of RMS yaw at 30 s [deg]",
                   float(np.max(r[:, k30, 2])), "<= 3", float(np.max(r[:, k30, 2])) <= 3.0),
        ]
    # paper claim 1 (not one of the method's bands; robust by a wide margin)
    e_max = float(np.max(sweep["E"][:, g]))
    v = min(float(np.max(sweep["N"][:, g])), float(np.max(sweep["D"][:, g]))) / e_max
    checks.append(Check("claim 1, gravity: min(N, D) / E of the max RMS over the sweep", v,
                         "> 1", v > 1.0))
    return checks


# --------------------------------------------------------------------------------------------
# table


def _range(v: np.ndarray) -> str:
    """min-max per angle of (n, 3) values."""
    parts = []
    for k in range(3):
        lo, hi = float(np.min(v[:, k])), float(np.max(v[:, k]))
        parts.append(f"{lo:.2g}" if f"{lo:.2g}" == f"{hi:.2g}" else f"{lo:.2g}-{hi:.2g}")
    return " / ".join(parts)


def format_table(sweep: dict[str, np.ndarray], yaw: dict[str, np.ndarray], yaw_t: np.ndarray,
                 runs: int, yaw_runs: int) -> str:
    """The table of docs/methods/vector-matching.md §6: reference (30 runs) next to
    navreplay."""
    w = 32
    head = (f"{'axis, a':<12}| {'gravity: reference':<{w}}{'navreplay':<{w}}"
            f"| {'specific-force: reference':<{w}}{'navreplay':<{w}}")
    lines = [
        f"Sweeps: RMS roll / pitch / yaw [deg] at t = 10 s; reference 30 runs per point, "
        f"navreplay {runs}",
        head,
        "-" * len(head),
    ]
    for (axis, a), (ref_g, ref_s) in REFERENCE_SWEEP.items():
        ours = sweep["N" if axis == "0" else axis][ACCEL_G.index(a)]
        label = "any, 0 g" if axis == "0" else f"{axis} {a:+.1f} g"
        lines.append(f"{label:<12}| {slashed(ref_g):<{w}}{slashed(ours[0]):<{w}}"
                     f"| {slashed(ref_s):<{w}}{slashed(ours[1]):<{w}}")
    lines.append(f"{'E, sweep':<12}| {REFERENCE_E_SWEEP[0]:<{w}}{_range(sweep['E'][:, 0]):<{w}}"
                 f"| {REFERENCE_E_SWEEP[1]:<{w}}{_range(sweep['E'][:, 1]):<{w}}")
    k30 = int(np.argmin(np.abs(yaw_t - 30.0)))
    lines += [
        "",
        f"Yaw cases: peak over time of the RMS roll / pitch / yaw [deg]; reference 30 runs, "
        f"navreplay {yaw_runs}",
        f"{'case':<12}| {'gravity: reference':<{w}}{'navreplay':<{w}}"
        f"| {'specific-force: reference':<{w}}{'navreplay':<{w}}",
    ]
    for case, r in yaw.items():
        ref_g, ref_s = REFERENCE_YAW_PEAK[case]
        lines.append(f"{case:<12}| {slashed(ref_g):<{w}}{slashed(r[0].max(axis=0)):<{w}}"
                     f"| {slashed(ref_s):<{w}}{slashed(r[1].max(axis=0)):<{w}}")
    for case, r in yaw.items():
        lines.append(f"{case + ' at 30 s':<12}| {slashed(REFERENCE_YAW_END):<{w}}"
                     f"{slashed(r[0, k30]):<{w}}| {slashed(REFERENCE_YAW_END):<{w}}"
                     f"{slashed(r[1, k30]):<{w}}")
    lines += ["", "Paper claims (checked by the bands below):"]
    lines += [f"  {c}" for c in PAPER_CLAIMS]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# the reproduction


class VectorMatchingReproduction(Reproduction):
    """``navreplay reproduce vector-matching``: the campaign of docs/methods/vector-matching.md
    §6.

    ``runs`` counts runs per sweep point; the yaw cases get ``10 runs`` each. ``progress``
    counts runs (one run = one recording, both models); the five tasks (three sweep axes, two
    yaw cases) are spread over the ``workers`` processes.
    """

    name = "vector-matching"
    method_doc = "docs/methods/vector-matching.md"
    summary = ("Gyro-free attitude: specific-force vs gravity vector matching "
               "(Choe & Park 2017, Figs. 1-5)")
    default_runs = 100
    """Runs per sweep point (the yaw cases get 10 times as many)."""
    quick_runs = 20
    """Runs per sweep point for a quick look (``navreplay demo``)."""

    def campaign(
        self, runs: int, *, seed: int, workers: int, progress: Progress | None
    ) -> Report:
        yaw_runs = YAW_RUNS_PER_SWEEP_RUN * runs
        tasks: list[tuple[Callable[..., Any], str, int]] = (
            [(run_sweep_axis, str(a), runs) for a in AXES]
            + [(run_yaw_case, str(c), yaw_runs) for c in CASES]
        )
        total = len(AXES) * len(ACCEL_G) * runs + len(CASES) * yaw_runs
        wall0 = time.perf_counter()
        executor = make_executor(workers, batch=False)  # a few long tasks
        try:
            futures = [executor.submit(fn, key, n, seed) for fn, key, n in tasks]
            results, done = [], 0
            for fut in futures:
                res = fut.result()
                results.append(res)
                done += res.runs * (len(ACCEL_G) if isinstance(res, SweepAxisResult) else 1)
                if progress is not None:
                    progress(done, total)
        finally:
            executor.shutdown(wait=True)
        wall = time.perf_counter() - wall0

        sweep = {r.axis: r.rms / DEG for r in results if isinstance(r, SweepAxisResult)}
        yaw_res = [r for r in results if isinstance(r, YawCaseResult)]
        yaw = {r.case: r.rms / DEG for r in yaw_res}
        yaw_t = yaw_res[0].t
        checks = acceptance(sweep, yaw, yaw_t)
        site = GimpoAccelSweepParams()
        sim_s = sum(r.sim_seconds for r in results)
        filt_s = sum(r.filter_seconds for r in results)
        table = format_table(sweep, yaw, yaw_t, runs, yaw_runs)
        table += (
            f"\n\nCampaign: {total} recordings x {len(MODELS)} models = {total * len(MODELS)} "
            f"filter runs in {wall:.1f} s wall ({workers} worker(s); simulation {sim_s:.1f} s, "
            f"filters {filt_s:.1f} s of worker time)"
        )
        figures: dict[str, Any] = {
            "sweep": {
                "accel_g": list(ACCEL_G),
                "models": [str(m) for m in MODELS],
                "angles": list(ANGLES),
                "rms_deg": sweep,
            },
            "yaw": {
                "t": yaw_t,
                "models": [str(m) for m in MODELS],
                "angles": list(ANGLES),
                "rms_deg": yaw,
            },
            "timing": {"wall_s": wall, "simulation_s": sim_s, "filter_s": filt_s,
                       "recordings": total, "filter_runs": total * len(MODELS)},
            "site_gravity": float(gravity(site.lat, site.height)),
        }
        return Report(
            title=(f"Gyro-free attitude by vector matching (Choe & Park 2017): {runs} runs per "
                   f"sweep point, {yaw_runs} per yaw case, seed {seed}"),
            table=table,
            checks=checks,
            figures=figures,
            bands=f"{self.method_doc} §6",
        )

    @staticmethod
    def log_view(sink: Any, figures: Mapping[str, Any]) -> None:
        """Log the Figs. 1-5 equivalents into an open :class:`navreplay.viz.Sink`.

        Sweeps: one bar chart per axis and angle, ``/ensemble/fig<1..3> <axis> sweep: RMS
        <angle> at 10 s/<model>``, in tab "Sweeps": at each acceleration [mg] a bar per model
        (a sweep has no time). Yaw cases: ``/ensemble/fig<4..5> case <x|y>: RMS
        <angle>/<model>`` versus time [s], tab "Yaw cases". Each model keeps its colour in
        every plot.
        """
        a_mg = 1000.0 * np.asarray(figures["sweep"]["accel_g"], dtype=float)
        for fig, axis in enumerate(AXES, start=1):
            r = np.asarray(figures["sweep"]["rms_deg"][axis])
            for k, angle in enumerate(ANGLES):
                sink.log_sweep(
                    f"fig{fig} {axis} sweep: RMS {angle} at 10 s", a_mg,
                    {str(m): r[:, j, k] for j, m in enumerate(MODELS)}, unit="deg",
                    x_name="acceleration", x_unit="mg", tab="sweeps", tab_title="Sweeps",
                )
        t = np.asarray(figures["yaw"]["t"], dtype=float)
        for fig, case in enumerate(CASES, start=4):
            r = np.asarray(figures["yaw"]["rms_deg"][case])
            for k, angle in enumerate(ANGLES):
                sink.log_ensemble(
                    f"fig{fig} case {case}: RMS {angle}", t,
                    {str(m): r[j, :, k] for j, m in enumerate(MODELS)}, unit="deg",
                    tab="yaw", tab_title="Yaw cases (x: time)",
                )


REPRODUCTION = VectorMatchingReproduction()
