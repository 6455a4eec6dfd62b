"""Benchmarks: each ``bench_*.py`` module has a ``main()`` that prints ratios against a baseline
measured in the same run. Run them all with ``python -m benchmarks`` (or one with
``python -m benchmarks.bench_io``)."""
