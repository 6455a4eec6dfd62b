"""Vector-matching Monte Carlo: per-run cost of each stage, reference path vs fast path.

The baseline is the reference path, measured in the same run on the same seeds:
scenario -> Recording (streams, metadata) -> replay engine -> ``VectorMatchingFilter`` ->
Euler errors. The fast path is what ``REPRODUCTION.run`` uses: ``simulate_runs`` (the
scenario's own sensor calls, no containers) -> ``run_batch`` (all runs as one stack) -> Euler
errors. Per stage it prints microseconds per run (a run = one recording; the filter stage is
per model) and the ratio reference / fast. ``--campaign`` also times the full reproduction
(11,300 recordings, 22,600 filter runs) and projects the reference path onto it.

    python -m benchmarks.bench_vector_matching [--ref-runs 20] [--fast-runs 1000] [--campaign]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from navreplay.filters.vector_matching import (
    Variant,
    VectorMatchingFilter,
    VectorMatchingParams,
    reference,
    run_batch,
)
from navreplay.metrics import rms
from navreplay.replay import replay
from navreplay.reproduce.vector_matching import ACCEL_G, MODELS, REPRODUCTION, euler_errors
from navreplay.sim.scenario import get_scenario, simulate

CASES = {
    "sweep (41 samples)": ("gimpo-accel-sweep", {"axis": "N", "accel_g": -0.8}),
    "yaw (121 samples)": ("gimpo-accel-yaw", {"case": "x"}),
}


def _last_per_epoch(t: np.ndarray) -> np.ndarray:
    return np.r_[np.flatnonzero(np.diff(t)), len(t) - 1]


def reference_path(name: str, values: dict, seeds: range) -> dict[str, float]:
    """Seconds per run of each stage of the reference path."""
    t_sim = t_filter = t_metrics = 0.0
    for seed in seeds:
        t0 = time.perf_counter()
        rec = simulate(name, values, seed)
        t1 = time.perf_counter()
        results = [replay(rec, VectorMatchingFilter, {"variant": "paper", "model": str(m)},
                          output_rate=None) for m in MODELS]
        t2 = time.perf_counter()
        q_true = rec["truth"]["q_nb"]
        for res in results:
            k = _last_per_epoch(res.t)
            euler_errors(res.extras["q_nb"][k], q_true)
        t3 = time.perf_counter()
        t_sim += t1 - t0
        t_filter += t2 - t1
        t_metrics += t3 - t2
    n = len(seeds)
    return {"simulate": t_sim / n, "filter (per model)": t_filter / n / len(MODELS),
            "metrics": t_metrics / n}


def fast_path(name: str, values: dict, seeds: range) -> dict[str, float]:
    """Seconds per run of each stage of the fast path (one stack of len(seeds) runs)."""
    from navreplay.sim.scenarios.gimpo import simulate_runs

    sc = get_scenario(name)()
    p = sc.Params(**values)
    t0 = time.perf_counter()
    truth = sc.truth(p)
    data = simulate_runs(p, truth, seeds)
    t1 = time.perf_counter()
    estimates = []
    for m in MODELS:
        fp = VectorMatchingParams(variant=Variant.PAPER, model=m)
        ref = reference(fp, {"earth_field_n": truth.h_n}, {"pos": [p.lat, p.lon, p.height]})
        estimates.append(run_batch(fp, ref, truth.t, data.f_b, data.m_b, data.v_n,
                                   data.vel_sigma))
    t2 = time.perf_counter()
    for est in estimates:
        rms(euler_errors(est.q_nb, truth.q_nb[None]), axis=0)
    t3 = time.perf_counter()
    n = len(seeds)
    return {"simulate": (t1 - t0) / n, "filter (per model)": (t2 - t1) / n / len(MODELS),
            "metrics": (t3 - t2) / n}


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # quick: the same paths on a few runs
    ap.add_argument("--ref-runs", type=int, default=2 if quick else 20,
                    help="runs of the reference path")
    ap.add_argument("--fast-runs", type=int, default=10 if quick else 1000,
                    help="runs stacked in the fast path")
    ap.add_argument("--campaign", action="store_true", help="also time the full reproduction")
    args = ap.parse_args([] if argv is None else argv)

    per_run: dict[str, tuple[dict[str, float], dict[str, float]]] = {}
    for label, (name, values) in CASES.items():
        simulate(name, values, 0)  # warm caches (field model, imports)
        ref = reference_path(name, values, range(args.ref_runs))
        fast = fast_path(name, values, range(args.fast_runs))
        per_run[label] = (ref, fast)
        print(f"{label}: reference {args.ref_runs} runs, fast path stack of {args.fast_runs}")
        print(f"  {'stage':<20}{'reference [us/run]':>20}{'fast [us/run]':>16}{'ratio':>9}")
        for stage in ref:
            r, f = ref[stage] * 1e6, fast[stage] * 1e6
            print(f"  {stage:<20}{r:>20.1f}{f:>16.1f}{r / f:>8.1f}x")
        r_tot = ref["simulate"] + 2 * ref["filter (per model)"] + ref["metrics"]
        f_tot = fast["simulate"] + 2 * fast["filter (per model)"] + fast["metrics"]
        print(f"  {'run, both models':<20}{r_tot * 1e6:>20.1f}{f_tot * 1e6:>16.1f}"
              f"{r_tot / f_tot:>8.1f}x")

    # the campaign: 3 x 31 x 100 sweep runs and 2 x 1000 yaw runs
    n_sweep, n_yaw = 3 * len(ACCEL_G) * 100, 2 * 1000

    def total(i: int) -> float:
        s = [per_run[k][i] for k in CASES]
        return sum(n * (d["simulate"] + 2 * d["filter (per model)"] + d["metrics"])
                   for n, d in zip((n_sweep, n_yaw), s, strict=True))

    print(f"projected campaign ({n_sweep + n_yaw} recordings, both models): reference "
          f"{total(0):.0f} s, fast path {total(1):.1f} s ({total(0) / total(1):.0f}x)")
    if args.campaign:
        t0 = time.perf_counter()
        report = REPRODUCTION.run()
        wall = time.perf_counter() - t0
        print(f"measured campaign: {wall:.1f} s wall, {report.figures['timing']['filter_runs']} "
              f"filter runs, bands {'all pass' if report.passed else 'FAIL'}; "
              f"reference path projected {total(0) / wall:.0f}x slower")


if __name__ == "__main__":
    main(sys.argv[1:])
