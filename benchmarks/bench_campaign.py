"""Campaign throughput: one process against a process pool and a Dask LocalCluster of two
workers, measured in one run.

- cost per run: many very short runs (``stationary``, 1 s, ``ins``), so the time is the
  executor's own per-run cost (pickling, scheduling, moving the compact metrics back); it sets
  how finely a large campaign can be cut into tasks;
- speed-up: a Monte Carlo of ``gps-ins`` on 300 s ``vehicle-drive`` runs on 2 workers against 1
  (wall time, workers started and warm; their start-up is printed apart).

    python -m benchmarks campaign
"""

from __future__ import annotations

import time
from typing import Any

from navreplay.replay.ensemble import (
    FilterSpec,
    make_executor,
    monte_carlo_tasks,
    run_ensemble,
)


def _campaign(scenario: str, filt: str, runs: int, duration: float, executor: Any) -> float:
    tasks = monte_carlo_tasks(scenario, runs, values={"duration": duration}, seed=0)
    start = time.perf_counter()
    run_ensemble(tasks, (FilterSpec(filt),), lambda out: None, executor=executor)
    return time.perf_counter() - start


def main(short_runs: int = 60, runs: int = 16) -> None:
    executors = {"one process": make_executor(1)}
    for name, spec in (("process pool, 2 workers", "process"), ("Dask LocalCluster, 2", "dask")):
        start = time.perf_counter()
        executors[name] = make_executor(2, spec)
        _campaign("stationary", "ins", 4, 1.0, executors[name])  # workers up and warm
        print(f"{name}: started and warm in {time.perf_counter() - start:.1f} s wall")
    _campaign("stationary", "ins", 2, 1.0, executors["one process"])
    print(f"cost per run ({short_runs} runs of 1 s 'stationary' with 'ins'; workers started), "
          "wall:")
    for name, ex in executors.items():
        t = _campaign("stationary", "ins", short_runs, 1.0, ex)
        print(f"  {name:24s} {t / short_runs * 1e3:7.1f} ms per run")
    print(f"Monte Carlo ({runs} runs of 300 s 'vehicle-drive' with 'gps-ins'; workers started), "
          "wall:")
    one = _campaign("vehicle-drive", "gps-ins", runs, 300.0, executors["one process"])
    print(f"  one process              {one:6.1f} s")
    for name, ex in list(executors.items())[1:]:
        t = _campaign("vehicle-drive", "gps-ins", runs, 300.0, ex)
        print(f"  {name:24s} {t:6.1f} s = {one / t:.2f}x one process (target 1.8x)")
    for ex in executors.values():
        ex.shutdown()


if __name__ == "__main__":
    main()
