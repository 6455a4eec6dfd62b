"""Reproductions of the published methods: Monte Carlo campaigns that print paper-vs-navreplay.

Each module defines one :class:`Reproduction` as ``REPRODUCTION``; ``navreplay reproduce NAME``
runs it. A reproduction implements :meth:`Reproduction.campaign` (simulate, replay, evaluate
the acceptance bands of its method document, tabulate) and :meth:`Reproduction.log_view` (its
figures as Rerun ensemble plots); :meth:`Reproduction.run` adds the common parts: the number
of runs and the optional .rrd file.

Each method is described in ``docs/methods/<name>.md`` (:attr:`Reproduction.method_doc`): the
paper's equations in navreplay's frames, the scenario, navreplay's choices, the errata of the
printed paper (E1, E2, ... in its section 7) and, in its section 6, the published results, the
reference values and the acceptance bands that the campaign checks.
"""

from __future__ import annotations

import abc
import dataclasses
import importlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from navreplay.replay.session import Progress

if TYPE_CHECKING:
    from navreplay.replay.spec import FilterSpec

__all__ = ["Check", "Progress", "Report", "Reproduction", "available", "get", "save_view",
           "slashed", "warm_up"]

_MODULES = {
    "transfer-alignment": "navreplay.reproduce.transfer_alignment",
    "vector-matching": "navreplay.reproduce.vector_matching",
    "rpm-aided-ins": "navreplay.reproduce.rpm_aided_ins",
}


@dataclasses.dataclass(frozen=True)
class Check:
    """One acceptance band of a method: the measured value and whether it lies in the band."""

    name: str
    value: float
    band: str
    passed: bool

    def __post_init__(self) -> None:
        # numpy scalars from the statistics become plain numbers
        object.__setattr__(self, "value", float(self.value))
        object.__setattr__(self, "passed", bool(self.passed))


@dataclasses.dataclass
class Report:
    """Result of a reproduction: a printable table, the acceptance checks and raw figures."""

    title: str
    table: str
    checks: list[Check]
    figures: dict[str, Any] = dataclasses.field(default_factory=dict)
    bands: str = ""
    """Where the bands are defined, e.g. ``docs/methods/rpm-aided-ins.md §6`` (for the heading)."""

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    def format(self) -> str:
        heading = f"Acceptance bands ({self.bands}):" if self.bands else "Acceptance bands:"
        lines = [self.title, "", self.table, "", heading]
        for c in self.checks:
            mark = "pass" if c.passed else "FAIL"
            lines.append(f"  [{mark}] {c.name}: {c.value:.4g}  (band {c.band})")
        return "\n".join(lines)


class Reproduction(abc.ABC):
    """A paper's Monte Carlo campaign with its acceptance bands (section 6 of
    :attr:`method_doc`)."""

    name: ClassVar[str]
    summary: ClassVar[str]
    method_doc: ClassVar[str]
    """The method document in the repository, e.g. ``docs/methods/rpm-aided-ins.md``."""
    default_runs: ClassVar[int]
    """Runs of the full campaign (the paper's Monte Carlo size)."""
    quick_runs: ClassVar[int]
    """Runs for a quick look (``navreplay demo``, ``navreplay reproduce --quick``)."""

    def run(
        self,
        *,
        runs: int | None = None,
        seed: int = 0,
        workers: int = 1,
        rrd: Path | None = None,
        progress: Progress | None = None,
        **options: Any,
    ) -> Report:
        """Run the campaign, evaluate the bands, optionally save the Rerun view.

        Parameters
        ----------
        runs : int, optional
            Campaign size (default :attr:`default_runs`; what a run is, the module says).
        seed : int
            Base seed: run i uses ``seed + i``.
        workers : int
            Processes.
        rrd : path, optional
            Save the Rerun view of the figures here.
        progress : callable, optional
            ``progress(done, total)``.
        **options
            Reproduction-specific options of :meth:`campaign`.
        """
        runs = self.default_runs if runs is None else int(runs)
        if runs < 1:
            raise ValueError(f"runs must be at least 1, got {runs}")
        report = self.campaign(runs, seed=seed, workers=workers, progress=progress, **options)
        if rrd is not None:
            save_view(rrd, f"{self.name} reproduction", self.log_view, report.figures)
        return report

    @abc.abstractmethod
    def campaign(
        self, runs: int, *, seed: int, workers: int, progress: Progress | None
    ) -> Report:
        """Simulate, replay and evaluate ``runs`` runs; the report's figures feed
        :meth:`log_view`."""

    @staticmethod
    @abc.abstractmethod
    def log_view(sink: Any, figures: Mapping[str, Any]) -> None:
        """Log the figures into an open :class:`navreplay.viz.Sink` (``/ensemble/...``)."""


def available() -> list[str]:
    return list(_MODULES)


def get(name: str) -> Reproduction:
    if name not in _MODULES:
        raise KeyError(f"unknown reproduction {name!r}; available: {', '.join(_MODULES)}")
    return importlib.import_module(_MODULES[name]).REPRODUCTION


# --------------------------------------------------------------------------------------------
# helpers of the campaigns


def save_view(
    path: Path | str,
    recording_name: str,
    log: Callable[[Any, Mapping[str, Any]], None],
    figures: Mapping[str, Any],
) -> Path:
    """Save ``log(sink, figures)`` as an .rrd file (overwriting it); returns the path."""
    from navreplay.viz import Save, open_sink

    with open_sink(Save(Path(path), overwrite=True), recording_name=recording_name) as sink:
        log(sink, figures)
    return Path(path)


def warm_up(scenario: str, duration: float, filters: Iterable[FilterSpec]) -> None:
    """Replay the filters over a short recording once, so that the numba kernels are compiled
    before a process pool forks its workers."""
    from navreplay.replay.pipeline import replay
    from navreplay.sim.scenario import simulate

    recording = simulate(scenario, {"duration": duration}, seed=0)
    for spec in filters:
        replay(recording, spec)


def slashed(values: Sequence[float] | Any) -> str:
    """``"a / b / c"`` with three significant digits each (a row of per-axis values)."""
    return " / ".join(f"{x:.3g}" for x in values)
