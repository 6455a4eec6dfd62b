"""Run every benchmarks/bench_*.py module's main(), or those named on the command line.

``python -m benchmarks`` runs them all; ``python -m benchmarks io viz`` runs bench_io.py and
bench_viz.py. ``--quick`` calls ``main(quick=True)``: the same code paths at tiny sizes, one or
two repeats and temporary files only, in seconds per module (a check that the benchmarks still
run, not a measurement). A new module only needs a ``main(quick=False)`` that prints its
figures.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import time

import benchmarks


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    argv = [a for a in argv if a != "--quick"]
    names = sorted(
        m.name for m in pkgutil.iter_modules(benchmarks.__path__) if m.name.startswith("bench_")
    )
    if argv:
        wanted = {a if a.startswith("bench_") else f"bench_{a}" for a in argv}
        unknown = wanted - set(names)
        if unknown:
            print(f"unknown benchmark(s): {', '.join(sorted(unknown))}; have {', '.join(names)}")
            return 2
        names = [n for n in names if n in wanted]
    for name in names:
        print(f"== {name}{' (quick)' if quick else ''}", flush=True)
        start = time.perf_counter()
        bench = importlib.import_module(f"benchmarks.{name}")
        bench.main(quick=quick)
        print(f"== {name} done in {time.perf_counter() - start:.1f} s\n", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
