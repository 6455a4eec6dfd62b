"""What to replay: a filter of a run, named by the user, with its parameter values, resolved
once.

A :class:`FilterSpec` is made from the command line (:func:`navreplay.jobs.config.filter_specs`)
or in code, and passed along to every recording it runs over (pickled to campaign workers with
its class and values). :meth:`FilterSpec.resolve` loads the class (once) and parses the values
into typed values (once: the strings of ``-p key=value`` become floats, tuples, enums),
checking them against the filter's parameters, so mistakes surface before any work. The
values keep where each came from (:class:`~navreplay.filters.settings.ParamValues`). The
filter's parameter instance is built per recording from them and the recording's sensor
specifications, in one place (:func:`navreplay.filters.settings.build_params`, called by the
replay session).

Examples
--------
>>> from navreplay.filters.settings import build_params
>>> spec = FilterSpec("gps-ins", {"gps_pos_sigma_scale": "2"}).resolve()
>>> spec.label, spec.values, spec.cls.__name__
('gps-ins', {'gps_pos_sigma_scale': 2.0}, 'GpsInsFilter')
>>> build_params(spec.cls, spec.values).params.gps_pos_sigma_scale
2.0
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from navreplay.filters.base import Filter, FilterParams
from navreplay.filters.registry import load_filter
from navreplay.filters.settings import ParamValues, build_params


@dataclasses.dataclass(frozen=True)
class FilterSpec:
    """One filter of a run or campaign: a registry name or ``package.module:Class``, its
    parameter values and a display label.

    Attributes
    ----------
    ref : str
        Registry name (``navreplay filters``) or ``package.module:Class``.
    params : mapping
        Parameter values by name (strings as from ``-p key=value``, or typed values; a
        :class:`~navreplay.filters.settings.ParamValues` says where each came from).
    label : str
        Display label, unique within a campaign (default: the name, or the class name for a
        ``module:Class`` reference).
    cls : type[Filter], optional
        The filter class when the caller has it already (else loaded from ``ref`` once, at
        the first use).
    """

    ref: str
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    label: str = ""
    cls: type[Filter] | None = dataclasses.field(default=None, compare=False, repr=False)
    _values: ParamValues | FilterParams | None = dataclasses.field(
        default=None, init=False, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not self.label:
            default = self.ref.rpartition(":")[2] if ":" in self.ref else self.ref
            object.__setattr__(self, "label", default)
        object.__setattr__(self, "params", ParamValues(self.params))  # keeps the sources

    @classmethod
    def of(cls, filter_cls: type[Filter],
           params: Mapping[str, Any] | FilterParams | None = None,
           label: str | None = None) -> FilterSpec:
        """The spec of a filter class in hand, with parameter values (or a parameter
        instance)."""
        ref = f"{filter_cls.__module__}:{filter_cls.__qualname__}"
        if not isinstance(params, FilterParams):
            return cls(ref, params or {}, label or filter_cls.name, cls=filter_cls)
        spec = cls(ref, {}, label or filter_cls.name, cls=filter_cls)
        object.__setattr__(spec, "_values", params)  # used as it is
        return spec

    def resolve(self) -> FilterSpec:
        """Load the class and parse the values (each once; raises
        :class:`~navreplay.filters.registry.FilterLoadError` or
        :class:`~navreplay.core.params.ParamError`); returns the spec."""
        if self.cls is None:
            object.__setattr__(self, "cls", load_filter(self.ref))
        if self._values is None:
            assert self.cls is not None
            checked = build_params(self.cls, self.params).params  # no sensors: the values only
            assert isinstance(self.params, ParamValues)  # made one on creation
            object.__setattr__(self, "_values", ParamValues(
                {k: getattr(checked, k) for k in self.params}, self.params.sources))
        return self

    @property
    def filter_cls(self) -> type[Filter]:
        """The filter class (loaded once)."""
        return self.resolve().cls  # type: ignore[return-value]

    @property
    def values(self) -> ParamValues | FilterParams:
        """The parameter values, typed (parsed once), with their sources; or the parameter
        instance the spec was made with (:meth:`of`)."""
        values = self.resolve()._values
        if isinstance(values, FilterParams):
            return values
        return ParamValues(values)

