"""The built-in filters: each name and the module that defines (and registers) it.

A module is imported when its filter is first asked for by name
(:func:`navreplay.filters.registry.load_filter`), all of them when the whole table is
(:func:`navreplay.filters.registry.filters`): a run of one filter does not import the others.
"""

from __future__ import annotations

import importlib

MODULES = {
    "transfer-alignment": "navreplay.filters.transfer_alignment",
    "vector-matching": "navreplay.filters.vector_matching",
    "rpm-aided-ins": "navreplay.filters.rpm_aided_ins",
    "ins": "navreplay.filters.ins",
    "gps-ins": "navreplay.filters.gps_ins",
}
"""Built-in filter name -> the module defining it."""


def load(name: str) -> None:
    """Import the module of built-in filter ``name`` (it registers the filter)."""
    importlib.import_module(MODULES[name])


def load_all() -> None:
    """Import every built-in filter's module."""
    for name in MODULES:
        load(name)
