"""Scenario interface and registry.

A scenario turns (parameters, seed) into a :class:`~navreplay.streams.Recording`: truth
trajectory, sensor streams and metadata. It is a pure function of its inputs: the same
parameters and seed give byte-identical recordings.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import numpy as np

from navreplay import params as _params
from navreplay.streams import Recording, StreamKind

_REGISTRY: dict[str, type[Scenario]] = {}


class Scenario(abc.ABC):
    """Base class: subclasses set ``name``, ``summary``, ``streams``, ``Params`` and implement
    :meth:`simulate`.

    ``Params`` is a frozen keyword-only dataclass in SI (datasheet units converted with
    :mod:`navreplay.units`) with a ``duration`` field [s] where the length is free.
    """

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    streams: ClassVar[tuple[StreamKind, ...]] = ()
    Params: ClassVar[type]

    @abc.abstractmethod
    def simulate(self, params: Any, rng: np.random.Generator, seed: int) -> Recording:
        """Simulate one run. ``seed`` is recorded in the metadata; draw only from ``rng``."""


def register_scenario(cls: type[Scenario]) -> type[Scenario]:
    """Class decorator adding a scenario to the registry under ``cls.name``."""
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise ValueError(f"scenario {cls.name!r} registered twice")
    _REGISTRY[cls.name] = cls
    return cls


def scenarios() -> dict[str, type[Scenario]]:
    """All registered scenarios by name (imports the built-ins)."""
    import navreplay.sim.scenarios  # noqa: F401  (registers the built-ins)

    return dict(sorted(_REGISTRY.items()))


def get_scenario(name: str) -> type[Scenario]:
    table = scenarios()
    if name not in table:
        raise KeyError(f"unknown scenario {name!r}; available: {', '.join(table)}")
    return table[name]


def simulate(
    name: str, values: dict[str, Any] | None = None, seed: int = 0
) -> Recording:
    """Simulate scenario ``name`` with parameter overrides ``values`` (strings or values)."""
    cls = get_scenario(name)
    p = _params.build(cls.Params, values, where=f"scenario {name}")
    rng = np.random.default_rng(seed)
    return cls().simulate(p, rng, seed)
