"""Rerun output: the only package of navreplay that imports rerun.

Open a sink, log truth, runs and ensembles, close::

    from navreplay.replay import replay_file
    from navreplay.viz import Save, open_sink

    with open_sink(Save("out.rrd"), recording_name="ship.mcap") as sink:
        replay_file(source, specs, stages=[sink])   # truth, each filter's blocks, overlaid
    # out.rrd appears only now, complete, with the default blueprint inside

A sink is a stage of the replay pipeline (:class:`navreplay.replay.Stage`): ``start``, then the
truth window by window (``truth``), each filter's estimates with their scores (``rows``) and
innovations (``innovations``) block by block; a whole run is one block.

Modules: :mod:`~navreplay.viz.targets` (:class:`Save`, default, headless, atomic;
:class:`Spawn`, :class:`Connect`, :class:`Serve`, which check that the viewer can be reached
first and raise :class:`VizUnavailableError`), :mod:`~navreplay.viz.connect` (opening a sink on
a target), :mod:`~navreplay.viz.sink` (entity tree), :mod:`~navreplay.viz.ensemble` (Monte Carlo
plots), :mod:`~navreplay.viz.blueprint` (default layout), :mod:`~navreplay.viz.naming` (units
and tabs), :mod:`~navreplay.viz.options` (a job's output choice; imports no rerun) and
docs/rerun-view.md. The names below are imported (with rerun) on first use.
"""

from __future__ import annotations

import importlib
import os
from typing import Any

# rerun's own log lines (a failed file write, a lost connection) would come beside the one
# line navreplay reports for the same failure; RUST_LOG, when set, still decides
os.environ.setdefault("RUST_LOG", "off")

_EXPORTS = {
    "APPLICATION_ID": "navreplay.viz.sink",
    "Sink": "navreplay.viz.sink",
    "open_sink": "navreplay.viz.connect",
    "Catalog": "navreplay.viz.blueprint",
    "build_blueprint": "navreplay.viz.blueprint",
    "chi2_bounds": "navreplay.viz.convert",
    "Connect": "navreplay.viz.targets",
    "Save": "navreplay.viz.targets",
    "Serve": "navreplay.viz.targets",
    "Spawn": "navreplay.viz.targets",
    "Target": "navreplay.viz.targets",
    "VizUnavailableError": "navreplay.viz.targets",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'navreplay.viz' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
