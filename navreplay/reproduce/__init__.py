"""Reproductions of the published methods: Monte Carlo campaigns that print paper-vs-navreplay.

Each module registers one :class:`Reproduction` with :func:`register_reproduction`;
``navreplay reproduce NAME`` runs it.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

_MODULES = {
    "transfer-alignment": "navreplay.reproduce.transfer_alignment",
    "vector-matching": "navreplay.reproduce.vector_matching",
    "rpm-aided-ins": "navreplay.reproduce.rpm_aided_ins",
}


@dataclasses.dataclass(frozen=True)
class Check:
    """One acceptance band of a spec: the measured value and whether it lies in the band."""

    name: str
    value: float
    band: str
    passed: bool


@dataclasses.dataclass
class Report:
    """Result of a reproduction: a printable table, the acceptance checks and raw figures."""

    title: str
    table: str
    checks: list[Check]
    figures: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    def format(self) -> str:
        lines = [self.title, "", self.table, "", "Acceptance (spec section 6):"]
        for c in self.checks:
            mark = "pass" if c.passed else "FAIL"
            lines.append(f"  [{mark}] {c.name}: {c.value:.4g}  (band {c.band})")
        return "\n".join(lines)


class Progress(Protocol):
    def __call__(self, done: int, total: int) -> None: ...


class Reproduction(Protocol):
    """What a reproduction module exposes as ``REPRODUCTION``."""

    name: str
    summary: str
    default_runs: int

    def run(
        self,
        *,
        runs: int | None = None,
        seed: int = 0,
        workers: int = 1,
        rrd: Path | None = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> Report: ...


def available() -> list[str]:
    return list(_MODULES)


def get(name: str) -> Reproduction:
    if name not in _MODULES:
        raise KeyError(f"unknown reproduction {name!r}; available: {', '.join(_MODULES)}")
    return importlib.import_module(_MODULES[name]).REPRODUCTION
