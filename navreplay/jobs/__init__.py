"""The jobs behind the command line: one typed configuration and one function per command.

``navreplay.cli`` parses arguments into these configurations and makes one call; everything
else — reading recordings, replaying filters, metrics, Rerun output, summaries — happens here,
so the same jobs run from Python::

    from pathlib import Path
    from navreplay.jobs import RunJob, VizMode, VizOptions, run
    from navreplay.replay.spec import FilterSpec

    job = RunJob(filters=(FilterSpec("gps-ins"),), recordings=(Path("x.mcap"),),
                 viz=VizOptions(VizMode.SAVE, Path("out/x.rrd")))
    print(run(job).format())

One module per command (:mod:`~navreplay.jobs.simulate`, :mod:`~navreplay.jobs.run`,
:mod:`~navreplay.jobs.montecarlo`, :mod:`~navreplay.jobs.demo`), the filter-list grammar in
:mod:`~navreplay.jobs.config` and reports in :mod:`~navreplay.jobs.report`. Jobs never print; they
return reports with a ``format()`` method and report progress through a ``progress(done, total)``
callback.
"""

from navreplay.jobs.compare import CompareJob, compare
from navreplay.jobs.config import check_scenario, filter_specs, scenario_values, split_filter_list
from navreplay.jobs.demo import DemoJob, DemoReport, demo
from navreplay.jobs.montecarlo import MonteCarloJob, montecarlo
from navreplay.jobs.report import DEFAULT_OUT, RunReport, write_json
from navreplay.jobs.run import RunJob, run
from navreplay.jobs.simulate import SimulateJob, simulate
from navreplay.viz.options import VizMode, VizOptions

__all__ = [
    "CompareJob", "DEFAULT_OUT", "DemoJob", "DemoReport", "MonteCarloJob", "RunJob", "RunReport",
    "SimulateJob", "VizMode", "VizOptions", "check_scenario", "compare", "demo", "filter_specs",
    "montecarlo", "run", "scenario_values", "simulate", "split_filter_list", "write_json",
]
