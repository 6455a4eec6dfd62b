"""Filter registry: built-ins, the ``navreplay.filters`` entry-point group, ``module:Class``.

A built-in name imports only its own module (:mod:`navreplay.filters.builtins`; a built-in
wins over a plug-in of the same name). The entry points of the installed packages are scanned
once per process, when a name is not a built-in or the whole table is asked for
(:func:`refresh` scans them again, for a package installed while the process runs).
"""

from __future__ import annotations

import functools
import importlib
import warnings
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


class FilterPluginWarning(UserWarning):
    """A plug-in of the ``navreplay.filters`` group that cannot be loaded (the others still are)."""


@functools.cache
def _load_entry_points() -> tuple[dict[str, type[Filter]], dict[str, str]]:
    """Plug-in filters by name, and the reason each broken plug-in could not be loaded (once
    per process)."""
    found: dict[str, type[Filter]] = {}
    broken: dict[str, str] = {}
    for ep in _md.entry_points(group=ENTRY_POINT_GROUP):
        try:
            cls = ep.load()
        except Exception as e:  # a broken plug-in must not hide the others
            broken[ep.name] = f"filter plug-in {ep.name!r} ({ep.value}) failed to load: {e}"
            continue
        if not (isinstance(cls, type) and issubclass(cls, Filter)):
            broken[ep.name] = f"filter plug-in {ep.name!r} ({ep.value}) is not a Filter class"
            continue
        found[ep.name] = cls
    return found, broken


def refresh() -> None:
    """Forget the plug-ins found so far: the next lookup scans the entry points again."""
    _load_entry_points.cache_clear()


def filters() -> dict[str, type[Filter]]:
    """Built-in and plug-in filters by name.

    A plug-in that fails to load is left out with a :class:`FilterPluginWarning`.
    """
    from navreplay.filters import builtins

    builtins.load_all()
    table = dict(_REGISTRY)
    plugins, broken = _load_entry_points()
    for message in broken.values():
        warnings.warn(message, FilterPluginWarning, stacklevel=2)
    for name, cls in plugins.items():
        table.setdefault(name, cls)
    return dict(sorted(table.items()))


def names() -> list[str]:
    """The names of the built-in and plug-in filters (and of any other registered one),
    sorted, without importing their modules (a broken plug-in is named too)."""
    from navreplay.filters import builtins

    plugins = {ep.name for ep in _md.entry_points(group=ENTRY_POINT_GROUP)}
    return sorted(set(builtins.MODULES) | set(_REGISTRY) | plugins)


def load_filter(ref: str) -> type[Filter]:
    """Resolve a registry name or a ``package.module:Class`` reference."""
    if ":" in ref:
        mod_name, _, attr = ref.partition(":")
        try:
            mod = importlib.import_module(mod_name)
        except ImportError as e:
            raise FilterLoadError(f"cannot import filter module {mod_name!r}: {e}") from None
        except Exception as e:  # e.g. a declaration of its filter refused at class definition
            raise FilterLoadError(
                f"cannot import filter module {mod_name!r}: {type(e).__name__}: {e}") from e
        cls = getattr(mod, attr, None)
        if not (isinstance(cls, type) and issubclass(cls, Filter)):
            raise FilterLoadError(f"{ref!r} is not a navreplay Filter class")
        return cls
    from navreplay.filters import builtins

    if ref in builtins.MODULES:  # only its module: a built-in wins over a plug-in's name
        builtins.load(ref)
        return _REGISTRY[ref]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FilterPluginWarning)
        table = filters()
    if ref not in table:
        _, broken = _load_entry_points()
        if ref in broken:
            raise FilterLoadError(broken[ref])
        raise FilterLoadError(f"unknown filter {ref!r}; available: {', '.join(table)}")
    return table[ref]
