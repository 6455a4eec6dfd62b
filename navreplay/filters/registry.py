"""Filter registry: built-ins, the ``navreplay.filters`` entry-point group, ``module:Class``."""

from __future__ import annotations

import importlib
from importlib import metadata as _md

from navreplay.filters.base import Filter

ENTRY_POINT_GROUP = "navreplay.filters"
_REGISTRY: dict[str, type[Filter]] = {}


def register_filter(cls: type[Filter]) -> type[Filter]:
    """Class decorator adding a filter to the registry under ``cls.name``."""
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise ValueError(f"filter {cls.name!r} registered twice")
    _REGISTRY[cls.name] = cls
    return cls


class FilterLoadError(LookupError):
    """A filter name or ``module:Class`` reference that cannot be resolved."""


def _load_entry_points() -> dict[str, type[Filter]]:
    found: dict[str, type[Filter]] = {}
    for ep in _md.entry_points(group=ENTRY_POINT_GROUP):
        try:
            cls = ep.load()
        except Exception as e:  # a broken plug-in must not hide the others
            raise FilterLoadError(f"filter plug-in {ep.name!r} ({ep.value}) failed to load: {e}") from e
        if not (isinstance(cls, type) and issubclass(cls, Filter)):
            raise FilterLoadError(f"filter plug-in {ep.name!r} ({ep.value}) is not a Filter class")
        found[ep.name] = cls
    return found


def filters() -> dict[str, type[Filter]]:
    """Built-in and plug-in filters by name."""
    import navreplay.filters.builtins  # noqa: F401  (registers the built-ins)

    table = dict(_REGISTRY)
    for name, cls in _load_entry_points().items():
        table.setdefault(name, cls)
    return dict(sorted(table.items()))


def load_filter(ref: str) -> type[Filter]:
    """Resolve a registry name or a ``package.module:Class`` reference."""
    if ":" in ref:
        mod_name, _, attr = ref.partition(":")
        try:
            mod = importlib.import_module(mod_name)
        except ImportError as e:
            raise FilterLoadError(f"cannot import filter module {mod_name!r}: {e}") from None
        cls = getattr(mod, attr, None)
        if not (isinstance(cls, type) and issubclass(cls, Filter)):
            raise FilterLoadError(f"{ref!r} is not a navreplay Filter class")
        return cls
    table = filters()
    if ref not in table:
        raise FilterLoadError(f"unknown filter {ref!r}; available: {', '.join(table)}")
    return table[ref]
