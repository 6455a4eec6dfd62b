"""What to replay: a filter of a run, named by the user, with its parameter values.

Examples
--------
>>> FilterSpec("gps-ins", {"gps_pos_sigma_scale": "2"}).label
'gps-ins'
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from navreplay.filters.base import Filter
from navreplay.filters.registry import load_filter


@dataclasses.dataclass(frozen=True)
class FilterSpec:
    """One filter of a run or campaign: a registry name or ``package.module:Class``, its
    parameter values and a display label.

    Attributes
    ----------
    ref : str
        Registry name (``navreplay filters``) or ``package.module:Class``.
    params : mapping
        Parameter values by name (strings as from ``-p key=value``, or typed values).
    label : str
        Display label, unique within a campaign (default: the name, or the class name for a
        ``module:Class`` reference).
    """

    ref: str
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    label: str = ""

    def __post_init__(self) -> None:
        if not self.label:
            default = self.ref.rpartition(":")[2] if ":" in self.ref else self.ref
            object.__setattr__(self, "label", default)
        object.__setattr__(self, "params", dict(self.params))

    def load(self) -> type[Filter]:
        """The filter class (raises :class:`~navreplay.filters.registry.FilterLoadError`)."""
        return load_filter(self.ref)
