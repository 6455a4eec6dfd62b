"""The names of the exported files (file-safe stems, ROS topic names, the targets of the
overwrite check) and writing one atomically."""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from pathlib import Path

from navreplay.io.outputs import Output, atomic_path, check_outputs

MANIFEST = "manifest.json"


ODOMETRY_FILE = "estimates.mcap"


FOXGLOVE_LAYOUT = "estimates.foxglove-layout.json"
"""The Foxglove layout of the estimates MCAP, beside it."""


REFERENCE_LABEL = "reference"


def check_targets(paths: Iterable[Path], force: bool, option: str = "--export") -> None:
    """Refuse targets that exist (unless ``force``), are directories or cannot be written
    (:func:`navreplay.io.outputs.check_outputs`), before anything is written."""
    unique = dict.fromkeys(Path(p) for p in paths)
    check_outputs([Output(p, option) for p in unique], force=force)


def write_text(path: Path, text: str) -> None:
    """Write a text file atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def file_stem(label: str) -> str:
    """A file-safe name for a filter label: ``gps-ins[k=2]`` -> ``gps-ins_k_2``."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", label).strip("._") or "filter"
    return stem


def file_stems(labels: Sequence[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for label in labels:
        stem, k = file_stem(label), 2
        base = stem
        while stem in out.values() or stem == REFERENCE_LABEL:
            stem, k = f"{base}_{k}", k + 1
        out[label] = stem
    return out


def topic_name(label: str) -> str:
    """A valid ROS 2 topic segment for a filter label (letters, digits, underscores)."""
    seg = re.sub(r"[^A-Za-z0-9_]+", "_", label).strip("_") or "filter"
    return seg if not seg[0].isdigit() else f"f_{seg}"


def run_targets(out_dir: Path, labels: Sequence[str], has_reference: bool) -> list[Path]:
    """Every file ``--export DIR`` of a single run writes (for the overwrite check)."""
    out_dir = Path(out_dir)
    stems = file_stems(labels)
    paths = [out_dir / MANIFEST, out_dir / ODOMETRY_FILE, out_dir / FOXGLOVE_LAYOUT]
    for stem in stems.values():
        paths += [out_dir / f"{stem}.csv", out_dir / f"{stem}.tum"]
        # the measurements are known once the filters run: refuse those there are already
        paths += sorted(out_dir.glob(f"{stem}{INNOVATIONS}*.csv"))  # no glob characters
    if has_reference:
        paths.append(out_dir / f"{REFERENCE_LABEL}.tum")
    return paths


INNOVATIONS = ".innovations."
"""Between a filter's file stem and a measurement's in the name of an innovation file."""


def innovation_file(stem: str, measurement_stem: str) -> str:
    """``L.innovations.<measurement>.csv``."""
    return f"{stem}{INNOVATIONS}{measurement_stem}.csv"


def ensemble_targets(out_dir: Path, labels: Sequence[str]) -> list[Path]:
    """The ensemble CSVs ``--export DIR`` of a campaign writes, before their NIS files."""
    return [Path(out_dir) / MANIFEST] + [Path(out_dir) / f"{s}.ensemble.csv"
                                         for s in file_stems(labels).values()]
