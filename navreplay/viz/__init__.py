"""Rerun output: the only package of navreplay that imports rerun.

Open a sink, log truth, runs and ensembles, close::

    from navreplay.viz import Save, open_sink

    with open_sink(Save("out.rrd"), recording_name="ship.mcap") as sink:
        for result in results:                      # RunResult per filter label
            sink.log_run(result, truth=recording)   # overlays in the same plots
    # out.rrd appears only now, complete; the default blueprint is inside

Targets: :class:`Save` (default, headless, atomic), :class:`Spawn`, :class:`Connect`,
:class:`Serve`; the last three check that the viewer is reachable first and raise
:class:`VizUnavailableError`. The entity tree is described in :mod:`navreplay.viz.sink` and
docs/rerun-view.md.
"""

from navreplay.viz.blueprint import Catalog, build_blueprint
from navreplay.viz.convert import chi2_bounds
from navreplay.viz.sink import (
    APPLICATION_ID,
    Connect,
    Save,
    Serve,
    Sink,
    Spawn,
    Target,
    VizUnavailableError,
    open_sink,
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
