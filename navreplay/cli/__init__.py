"""The ``navreplay`` command: parse arguments into a typed job, make one library call, print.

Each command builds a configuration of :mod:`navreplay.jobs` (or calls a registry) and prints
the report it gets back. Expected failures (bad input, missing streams, unknown names, an
unreachable viewer, a diverging filter) print one line on stderr and exit with status 1; usage
errors exit with 2. ``navreplay --debug COMMAND`` shows the traceback instead.

:mod:`~navreplay.cli.group` the group and the entry point :func:`main`,
:mod:`~navreplay.cli.options` what the commands share, and one module per family of commands:
:mod:`~navreplay.cli.recordings` (``scenarios``, ``simulate``, ``info``, ``allan``),
:mod:`~navreplay.cli.filters` (``filters``, ``tune``), :mod:`~navreplay.cli.runs` (``run``,
``montecarlo``), :mod:`~navreplay.cli.demo` (``reproduce``, ``demo``, ``warm-up``).
"""

# the commands register themselves on the group when their module is imported
from navreplay.cli import demo, filters, recordings, runs  # noqa: E402, F401, I001
from navreplay.cli.group import cli, main

__all__ = ["cli", "main"]
