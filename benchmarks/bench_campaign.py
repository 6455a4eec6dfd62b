"""Campaign throughput: one process against a process pool and a Dask LocalCluster of two
workers, measured in one run.

- cost per run: many very short runs (``stationary``, 1 s, ``ins``), so the time is the
  executor's own per-run cost (pickling, scheduling, moving the compact metrics back); it sets
  how finely a large campaign can be cut into tasks;
- speed-up: the wall time of one Monte Carlo of ``gps-ins`` on 300 s ``vehicle-drive`` runs
  on one process divided by that of the same tasks on 2 workers (workers started and warm;
  their start-up is printed apart).

Both executors group consecutive runs into one task by their measured cost
(:class:`navreplay.campaign.batching.Batching`). Targets: the process pool of 2 at least 1.8x
one process on an idle machine; Dask never slower than one process (at least 1x), short runs
included.

What the speed-up measures, and how: the wall time of a 2-worker campaign depends on what
else the two cores do, so a single pair of timings taken minutes apart measures the
neighbours as much as the executor. Each repeat therefore times the same campaign on one
process and on each executor back to back (a pair, in alternating order), the ratio is taken
within the pair, and the median over the repeats is reported with the range. The campaign has
many more runs than workers (default 40 on 2), so that the last, unbalanced round of tasks is a
small part of the wall time; the load average before and after is printed: a speed-up near
2x needs two idle cores.

    python -m benchmarks campaign
"""

from __future__ import annotations

import os
import pickle
import statistics
import time
from typing import Any

from navreplay.campaign.ensemble import run_ensemble
from navreplay.campaign.executors import make_executor
from navreplay.campaign.tasks import monte_carlo_tasks
from navreplay.replay.spec import FilterSpec


def _campaign(scenario: str, filt: str, runs: int, duration: float, executor: Any) -> float:
    tasks = monte_carlo_tasks(scenario, runs, values={"duration": duration}, seed=0)
    start = time.perf_counter()
    run_ensemble(tasks, (FilterSpec(filt),), lambda out: None, executor=executor)
    return time.perf_counter() - start


def _one_run(duration: float) -> tuple[float, int]:
    """(wall time in the worker [s], size of its pickled output [bytes]) of one run of the
    Monte Carlo, in this process."""
    outs: list[Any] = []
    tasks = monte_carlo_tasks("vehicle-drive", 1, values={"duration": duration}, seed=0)
    run_ensemble(tasks, (FilterSpec("gps-ins"),), outs.append, workers=1)
    return outs[0].seconds, len(pickle.dumps(outs[0]))


def _tree_cpu() -> float:
    """CPU seconds (user + system) of this process and all its descendants alive (the
    workers, Dask's scheduler and nannies), from /proc (Linux)."""
    stats = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            stats[int(entry)] = (int(fields[1]), int(fields[11]) + int(fields[12]))
    tree, total = {os.getpid()}, 0
    for _ in range(4):  # children, grandchildren, ...
        tree |= {pid for pid, (ppid, _) in stats.items() if ppid in tree}
    for pid in tree:
        total += stats.get(pid, (0, 0))[1]
    return total / os.sysconf("SC_CLK_TCK")


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} cores"


def main(short_runs: int = 60, runs: int = 40, repeats: int = 3, duration: float = 300.0,
         *, quick: bool = False) -> None:
    if quick:  # the same executors and campaigns, a few short runs
        short_runs, runs, repeats, duration = 4, 4, 1, 5.0
    print(_load())
    executors = {"one process": make_executor(1)}
    for name, spec in (("process pool, 2 workers", "process"), ("Dask LocalCluster, 2", "dask")):
        start = time.perf_counter()
        executors[name] = make_executor(2, spec)
        _campaign("stationary", "ins", 4, 1.0, executors[name])  # workers up and warm
        print(f"{name}: started and warm in {time.perf_counter() - start:.1f} s wall")
    _campaign("stationary", "ins", 2, 1.0, executors["one process"])
    print(f"cost per run ({short_runs} runs of 1 s 'stationary' with 'ins'; workers started), "
          f"wall, {repeats} paired repeats (medians):")
    per_run: dict[str, list[float]] = {name: [] for name in executors}
    short: dict[str, list[float]] = {name: [] for name in list(executors)[1:]}
    cpu_ratio: dict[str, list[float]] = {name: [] for name in short}
    for r in range(repeats):
        for name in short:
            order = ("one process", name) if r % 2 == 0 else (name, "one process")
            pair, cpu = {}, {}
            for who in order:
                c0 = _tree_cpu()
                pair[who] = _campaign("stationary", "ins", short_runs, 1.0,
                                      executors[who]) / short_runs
                cpu[who] = (_tree_cpu() - c0) / short_runs
            per_run["one process"].append(pair["one process"])
            per_run[name].append(pair[name])
            short[name].append(pair["one process"] / pair[name])
            cpu_ratio[name].append(cpu["one process"] / cpu[name])
    for name, values in per_run.items():
        print(f"  {name:24s} {statistics.median(values) * 1e3:7.1f} ms per run")
    for name, values in short.items():
        med = statistics.median(values)
        print(f"  {name:24s} {med:.2f}x one process on 1-s runs (range {min(values):.2f}-"
              f"{max(values):.2f}; target >= 1x, never slower: "
              f"{'met' if med >= 1.0 else 'NOT met'})")
    print("  CPU per run, all processes (this one, the workers, Dask's scheduler and nannies), "
          "one process over each executor (1: no cost of its own; x2 bounds the speed-up of "
          "2 workers on idle cores):")
    for name, values in cpu_ratio.items():
        print(f"  {name:24s} {statistics.median(values):.2f} (range {min(values):.2f}-"
              f"{max(values):.2f})")
    seconds, size = _one_run(duration)
    print(f"one run of the Monte Carlo below: {seconds * 1e3:.0f} ms in its worker (simulate, "
          f"replay, metrics), its output pickled {size / 1e6:.2f} MB")
    print(f"Monte Carlo ({runs} runs of {duration:g} s 'vehicle-drive' with 'gps-ins'; "
          f"workers started), wall, {repeats} paired repeats:")
    one_times: list[float] = []
    ratios: dict[str, list[float]] = {name: [] for name in list(executors)[1:]}
    mc_ratio: dict[str, list[float]] = {name: [] for name in ratios}
    for r in range(repeats):
        for name in ratios:
            pair = {}
            order = ("one process", name) if r % 2 == 0 else (name, "one process")
            mc_cpu = {}
            for who in order:
                c0 = _tree_cpu()
                pair[who] = _campaign("vehicle-drive", "gps-ins", runs, duration, executors[who])
                mc_cpu[who] = _tree_cpu() - c0
            one_times.append(pair["one process"])
            ratios[name].append(pair["one process"] / pair[name])
            mc_ratio[name].append(mc_cpu["one process"] / mc_cpu[name])
            print(f"  repeat {r + 1}: one process {pair['one process']:6.1f} s, {name} "
                  f"{pair[name]:6.1f} s = {ratios[name][-1]:.2f}x")
    print(f"  one process: median {statistics.median(one_times):.1f} s "
          f"({min(one_times):.1f}-{max(one_times):.1f})")
    for name, values in ratios.items():
        med = statistics.median(values)
        target = 1.8 if name.startswith("process") else 1.0
        print(f"  {name:24s} speed-up median {med:.2f}x (range {min(values):.2f}-"
              f"{max(values):.2f}; target >= {target:g}x on an idle machine: "
              f"{'met' if med >= target else 'NOT met'})")
    for name, values in mc_ratio.items():
        print(f"  {name:24s} CPU of one process over all of its processes: "
              f"{statistics.median(values):.2f} (range {min(values):.2f}-{max(values):.2f})")
    print(_load())
    for ex in executors.values():
        ex.shutdown()


if __name__ == "__main__":
    main()
