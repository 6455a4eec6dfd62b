"""A filter's settings: its parameters built from the recording's sensor specifications and the
user's values, with where each one came from.

Precedence, highest first:

============  ================================================================================
source        where the value came from
============  ================================================================================
``inline``    ``run 'gps-ins[key=value]'``
``-p``        ``-p key=value``
``toml``      a ``[filter.NAME]`` table of ``--config``
``given``     a value handed to :func:`build_params` by a program (a mapping without sources
              or a ready ``Params`` instance)
``spec``      derived from the recording's sensor specifications by
              :meth:`Filter.settings_from_sensors
              <navreplay.filters.base.Filter.settings_from_sensors>`
``default``   the default of the filter's ``Params``
============  ================================================================================

A filter whose defaults stand for some sensors (:meth:`Filter.default_sensors
<navreplay.filters.base.Filter.default_sensors>`, e.g. a tactical IMU for ``ins``) and that
runs on a recording whose specifications do not give those settings gets a note saying so once
(:attr:`FilterSettings.note`). So does a filter that declares the error terms it models
(:meth:`Filter.modelled_terms <navreplay.filters.base.Filter.modelled_terms>`) when the
specifications of a sensor it consumes state one it leaves out (:func:`unmodelled_terms`).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import re
import typing
from collections.abc import Iterable, Mapping
from typing import Any

from navreplay.core import params as _params
from navreplay.core.streams import jsonable
from navreplay.filters.base import Filter, FilterParams
from navreplay.sensors.specs import SPEC_STREAMS, SensorSpecs


class Source(enum.StrEnum):
    """Where a setting came from (see the module docstring)."""

    INLINE = "inline"
    OPTION = "-p"
    TOML = "toml"
    GIVEN = "given"
    SPEC = "spec"
    DEFAULT = "default"


class ParamValues(dict[str, Any]):
    """Parameter values by name, with where each came from (``sources``: name ->
    :class:`Source`); a plain ``dict`` for everything else.

    >>> v = ParamValues({"gyro_arw": "1e-5"}, {"gyro_arw": Source.OPTION})
    >>> dict(v), v.sources["gyro_arw"].value
    ({'gyro_arw': '1e-5'}, '-p')
    >>> ParamValues(v).sources == v.sources
    True
    """

    def __init__(self, values: Mapping[str, Any] | None = None,
                 sources: Mapping[str, Source | str] | None = None) -> None:
        super().__init__(values or {})
        if sources is None:
            sources = getattr(values, "sources", {})
        self.sources: dict[str, Source] = {k: Source(v) for k, v in sources.items()}


@dataclasses.dataclass(frozen=True)
class FilterSettings:
    """A filter's parameters and where each came from.

    Attributes
    ----------
    params : FilterParams
    sources : dict[str, Source]
        Per field of ``params``.
    sensors : str
        The sensor specifications the ``spec`` values came from (kind: source; ``""`` none).
    note : str
        One line when settings that the recording's specifications should give are the
        defaults (none, or not all, of the sensors they need are stated); ``""`` otherwise.
    """

    params: FilterParams
    sources: Mapping[str, Source]
    sensors: str = ""
    note: str = ""

    def summary(self) -> dict[str, Any]:
        """The ``settings`` entry of a run summary: per field ``{"value", "source", "unit"}``
        (SI, JSON values), in the order of the ``Params`` fields."""
        units = field_units(typing.cast(type, type(self.params)))
        out = {}
        for f in dataclasses.fields(self.params):
            entry = {"value": jsonable(getattr(self.params, f.name)),
                     "source": str(self.sources.get(f.name, Source.DEFAULT))}
            if units.get(f.name):
                entry["unit"] = units[f.name]
            out[f.name] = entry
        return out

    def counts(self) -> dict[str, int]:
        """How many settings came from each source."""
        out: dict[str, int] = {}
        for s in self.sources.values():
            out[str(s)] = out.get(str(s), 0) + 1
        return out


def summary_entries(settings: FilterSettings | None) -> dict[str, Any]:
    """What a run summary gets from the settings: ``settings`` (:meth:`FilterSettings.summary`),
    ``settings_sensors`` and, when there is one, ``settings_note``."""
    if settings is None:
        return {}
    out: dict[str, Any] = {"settings": settings.summary()}
    if settings.sensors:
        out["settings_sensors"] = settings.sensors
    if settings.note:
        out["settings_note"] = settings.note
    return out


def setting_notes(summaries: Iterable[Mapping[str, Any]]) -> list[str]:
    """The ``settings_note`` of run summaries, each once, in order."""
    out: list[str] = []
    for s in summaries:
        note = s.get("settings_note")
        if note and note not in out:
            out.append(note)
    return out


_UNIT = re.compile(r"\[([^\[\]\s]+)\]")


@functools.cache
def field_units(cls: type) -> dict[str, str]:
    """The unit of each field of a parameter dataclass, from the first ``[unit]`` of its
    docstring (``""`` where none is given)."""
    out = {}
    for name, _, _, doc in _params.describe(cls):
        m = _UNIT.search(doc)
        out[name] = m.group(1) if m else ""
    return out


def build_params(
    filter_cls: type[Filter],
    params: FilterParams | Mapping[str, Any] | None = None,
    sensors: SensorSpecs | None = None,
    *,
    label: str | None = None,
) -> FilterSettings:
    """The settings of one filter run: its ``Params`` from the user's values over the values
    derived from ``sensors`` over the defaults, with the source of each.

    Parameters
    ----------
    filter_cls : type[Filter]
    params : FilterParams, mapping or None
        A ready instance (used as it is, every field ``given``), or values by name (a
        :class:`ParamValues` says where each came from; a plain mapping's are ``given``).
    sensors : SensorSpecs, optional
        The recording's sensor specifications.
    label : str, optional
        The filter's label in the note (default: its name).

    Raises
    ------
    navreplay.core.params.ParamError
        Values that do not fit ``filter_cls.Params``, or a derivation that fails, naming the
        filter.
    """
    name = label or filter_cls.name
    if isinstance(params, FilterParams):
        return FilterSettings(params, dict.fromkeys(_names(type(params)), Source.GIVEN))
    values = dict(params or {})
    given = getattr(params, "sources", {})
    sources = {k: Source(given.get(k, Source.GIVEN)) for k in values}
    sensors = sensors or SensorSpecs()
    derived: dict[str, Any] = {}
    if sensors:
        try:
            derived = dict(filter_cls.settings_from_sensors(sensors) or {})
        except (TypeError, ValueError, ArithmeticError) as e:
            raise _params.ParamError(f"filter {name}: cannot derive its settings from the "
                                     f"sensor specifications: {e}") from None
        unknown = sorted(set(derived) - set(_names(filter_cls.Params)))
        if unknown:
            raise _params.ParamError(f"filter {name}: settings_from_sensors gives unknown "
                                     f"parameter(s) {', '.join(unknown)}")
    refused = _invalid(filter_cls.Params, {k: v for k, v in derived.items() if k not in values})
    for k in refused:
        del derived[k]
    for k in derived:
        sources.setdefault(k, Source.SPEC)
    p = _params.build(filter_cls.Params, {**derived, **values}, where=f"filter {name}")
    for k in _names(type(p)):
        sources.setdefault(k, Source.DEFAULT)
    used = [k for k in sensors.models if derived and filter_cls.settings_from_sensors(
        SensorSpecs({k: sensors.get(k)}, {k: sensors.known_fields(k)}))]
    described = "; ".join(f"{k}: {sensors.source(k) or 'stated'}" for k in used)
    notes = [_note(filter_cls, name, sensors, sources),
             _unmodelled_note(name, unmodelled_terms(filter_cls, p, sensors))]
    if refused:
        notes.append(f"{name}: the sensor specifications give {'; '.join(refused.values())}: "
                     f"{', '.join(refused)} keep the defaults")
    return FilterSettings(p, sources, described, "; ".join(n for n in notes if n))


def unmodelled_terms(filter_cls: type[Filter], params: FilterParams,
                     sensors: SensorSpecs) -> dict[str, dict[str, str]]:
    """The error terms the specifications state (not zero) for the sensors whose streams
    ``filter_cls`` consumes and that it does not model with ``params``, by sensor kind: field
    -> what it is. Empty when the filter declares nothing (:meth:`Filter.modelled_terms
    <navreplay.filters.base.Filter.modelled_terms>` returns None)."""
    modelled = filter_cls.modelled_terms(params)
    if modelled is None:
        return {}
    consumed = set(filter_cls.requires) | set(filter_cls.optional)
    out: dict[str, dict[str, str]] = {}
    for kind in sensors.models:
        if not consumed & set(SPEC_STREAMS.get(kind, ())):
            continue
        left = {k: v for k, v in sensors.present_terms(kind).items()
                if k not in modelled.get(kind, ())}
        if left:
            out[kind] = left
    return out


def _unmodelled_note(name: str, terms: Mapping[str, Mapping[str, str]]) -> str:
    """``gps-ins does not model the gps time-correlated (Gauss-Markov) velocity error
    (vel_gm_sigma) that the sensor specifications state``, or ``""``."""
    parts = [f"the {kind} {what} ({field})" for kind, fields in terms.items()
             for field, what in fields.items()]
    if not parts:
        return ""
    listed = parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
    return f"{name} does not model {listed} that the sensor specifications state"


def _invalid(cls: type, derived: Mapping[str, Any]) -> dict[str, str]:
    """The derived values the parameter class refuses on their own (a zero noise of an ideal
    sensor where a measurement noise must be > 0), with the reason."""
    try:
        _params.build(cls, derived)
        return {}
    except _params.ParamError:
        pass
    out = {}
    for k, v in derived.items():
        try:
            _params.build(cls, {k: v})
        except _params.ParamError as e:
            out[k] = str(e)
    return out


def _names(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls) if f.init)


def _note(filter_cls: type[Filter], name: str, sensors: SensorSpecs,
          sources: Mapping[str, Source]) -> str:
    """The note when settings the specifications should give are the defaults."""
    reference = filter_cls.default_sensors()
    if not reference:
        return ""
    derivable = list(filter_cls.settings_from_sensors(reference))
    missing = [k for k in derivable if sources.get(k) is Source.DEFAULT]
    if not missing:
        return ""
    kinds = [k for k in reference.models if not sensors.has(k, *reference.known_fields(k))]
    partial = [k for k in kinds if k in sensors]
    what = (f"an incomplete {' and '.join(partial)} specification" if partial
            else f"no {' or '.join(kinds)} specification")
    tables = ", ".join(f"[sensors.{k}]" for k in kinds)
    shown = ", ".join(missing[:4]) + (f" and {len(missing) - 4} more" if len(missing) > 4 else "")
    defaults = "; ".join(f"{k}: {reference.source(k)}" for k in reference.models)
    return (f"{name}: {what} in the recording ({tables} of --config gives it): {shown} "
            f"keep the defaults, which are for {defaults}")
