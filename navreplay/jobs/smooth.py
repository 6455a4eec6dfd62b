"""``--smooth`` of ``navreplay run`` and ``navreplay montecarlo``: which filters get a smoothed
run, the notes for those that cannot, and where the forward pass is stored meanwhile
(docs/smoothing.md)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from navreplay.filters.smoothable import is_smoothable
from navreplay.replay.smoothing import smoothed_label


def output_labels(specs: Sequence[Any], smooth: bool) -> list[str]:
    """The labels of a run's results: each filter's, followed by its smoothed run's when
    ``smooth`` and the filter can be smoothed."""
    out = []
    for spec in specs:
        out.append(spec.label)
        if smooth and is_smoothable(spec.filter_cls):
            out.append(smoothed_label(spec.label))
    return out


def partners(specs: Sequence[Any], smooth: bool) -> dict[str, str]:
    """The label of each smoothed run's filter, by the smoothed run's label."""
    return {smoothed_label(spec.label): spec.label for spec in specs
            if smooth and is_smoothable(spec.filter_cls)}


def unsmoothed_notes(specs: Sequence[Any]) -> list[str]:
    """One line per filter that ``--smooth`` leaves as it is."""
    return [f"{spec.label}: not smoothed ({spec.filter_cls.name} does not declare "
            "navreplay.filters.smoothable.Smoothable)"
            for spec in specs if not is_smoothable(spec.filter_cls)]


def scratch_dir(export_dir: Path | None) -> Path | None:
    """Where the forward pass's chunks go: beside the exports when there are (a directory
    that is known to be writable and to have room for outputs), else the system's temporary
    directory."""
    return export_dir if export_dir is not None and export_dir.is_dir() else None
