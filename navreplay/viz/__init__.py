"""Rerun output: the only package of navreplay that imports rerun.

Open a sink, log truth, runs and ensembles, close::

    from navreplay.viz import Save, open_sink

    with open_sink(Save("out.rrd"), recording_name="ship.mcap") as sink:
        for result in results:                      # a RunResult per filter label
            sink.log_run(result, truth=recording)   # overlaid in the same plots
    # out.rrd appears only now, complete, with the default blueprint inside

Targets (:mod:`navreplay.viz.targets`): :class:`Save` (default, headless, atomic),
:class:`Spawn`, :class:`Connect`, :class:`Serve`; the last three check that the viewer can be
reached first and raise :class:`VizUnavailableError`. Entity tree, units and blueprint:
:mod:`navreplay.viz.sink` and docs/rerun-view.md.
"""

from navreplay.viz.blueprint import Catalog, build_blueprint
from navreplay.viz.convert import chi2_bounds
from navreplay.viz.sink import APPLICATION_ID, Sink, open_sink
from navreplay.viz.targets import (
    Connect,
    Save,
    Serve,
    Spawn,
    Target,
    VizUnavailableError,
)

__all__ = [
    "APPLICATION_ID",
    "Catalog",
    "Connect",
    "Save",
    "Serve",
    "Sink",
    "Spawn",
    "Target",
    "VizUnavailableError",
    "build_blueprint",
    "chi2_bounds",
    "open_sink",
]
