"""The exports of a campaign: each filter's ensemble statistics and NIS, and the manifest."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from navreplay.export.columns import csv_text, ensemble_columns, nis_columns
from navreplay.export.files import (
    MANIFEST,
    check_targets,
    ensemble_targets,
    file_stem,
    file_stems,
    write_text,
)


def export_ensemble(out_dir: Path, ensembles: Mapping[str, Any], *, title: str = "",
                    force: bool = False) -> list[Path]:
    """Write each filter's ensemble statistics (``L.ensemble.csv``, ``L.nis.<meas>.csv``) and
    the manifest; refuses to overwrite unless ``force``."""
    out_dir = Path(out_dir)
    stems = file_stems(list(ensembles))
    targets = ensemble_targets(out_dir, list(ensembles))
    nis_paths = {(label, meas): out_dir / f"{stems[label]}.nis.{file_stem(meas)}.csv"
                 for label, ens in ensembles.items() for meas in ens.nis_mean}
    check_targets(targets + list(nis_paths.values()), force)
    written: list[Path] = []
    manifest: dict[str, Any] = {"campaign": title, "filters": {}}
    for label, ens in ensembles.items():
        cols = ensemble_columns(ens)
        path = out_dir / f"{stems[label]}.ensemble.csv"
        write_text(path, csv_text(cols))
        written.append(path)
        entry: dict[str, Any] = {"runs": ens.runs, "csv": path.name,
                                 "columns": [c.to_json() for c in cols], "nis": {}}
        for meas, (t, mean, count, dof) in ens.nis_mean.items():
            ncols = nis_columns(t, mean, count, dof, ens.nis_rows_mean.get(meas))
            p = nis_paths[(label, meas)]
            write_text(p, csv_text(ncols))
            written.append(p)
            entry["nis"][meas] = {"csv": p.name, "columns": [c.to_json() for c in ncols]}
        manifest["filters"][label] = entry
    write_text(out_dir / MANIFEST, json.dumps(manifest, indent=2) + "\n")
    written.append(out_dir / MANIFEST)
    return written
