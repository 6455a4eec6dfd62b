"""``--export DIR`` and ``--report FILE.html`` of ``navreplay run`` and ``navreplay montecarlo``.

The jobs call :meth:`Outputs.check` before any work (existing files are refused unless
``force``, so a long run does not end in a refusal), :meth:`Outputs.collect` per filter run,
then :meth:`Outputs.write_run` or :meth:`Outputs.write_ensemble`, which return the lines to
print. matplotlib is imported only when a report is asked for.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from navreplay import export


@dataclasses.dataclass
class Outputs:
    """Where a job's exports and report go.

    Attributes
    ----------
    export_dir : Path, optional
    report_path : Path, optional
    force : bool
        Overwrite existing files.
    """

    export_dir: Path | None = None
    report_path: Path | None = None
    force: bool = False
    _runs: list[export.FilterOutput] = dataclasses.field(default_factory=list)

    @property
    def wanted(self) -> bool:
        return self.export_dir is not None or self.report_path is not None

    def check(self, labels: Sequence[str], *, ensemble: bool, has_reference: bool = True) -> None:
        """Refuse existing targets (unless force) before the job starts."""
        paths = [self.report_path] if self.report_path is not None else []
        if self.export_dir is not None:
            paths += (export.ensemble_targets(self.export_dir, labels) if ensemble
                      else export.run_targets(self.export_dir, labels, has_reference))
        export.check_targets(paths, self.force)

    def collect(self, result: Any, recording: Any, metrics: Any = None) -> None:
        """Keep one filter run (a RunResult) for the exports and the report."""
        if self.wanted:
            self._runs.append(export.filter_output(result, recording, metrics))

    def write_run(self, recording: Any, summaries: Mapping[str, Mapping[str, Any]], *,
                  title: str, source: str) -> list[str]:
        """Write the exports and the report of filters replayed over one recording."""
        notes = []
        if self.export_dir is not None:
            written = export.export_run(self.export_dir, self._runs, recording, source=source,
                                        force=self.force)
            notes.append(f"Exported {len(written)} files to {self.export_dir} "
                         f"(see {self.export_dir / export.MANIFEST})")
        if self.report_path is not None:
            from navreplay import report

            report.write_run_report(self.report_path, self._runs, summaries, title=title,
                                    force=self.force)
            notes.append(f"Report written to {self.report_path}")
        return notes

    def write_ensemble(self, ensembles: Mapping[str, Any], summaries: Mapping[str, Any], *,
                       title: str) -> list[str]:
        """Write the ensemble statistics and the report of a campaign."""
        notes = []
        if self.export_dir is not None:
            written = export.export_ensemble(self.export_dir, ensembles, title=title,
                                             force=self.force)
            notes.append(f"Exported {len(written)} files to {self.export_dir}")
        if self.report_path is not None:
            from navreplay import report

            report.write_ensemble_report(self.report_path, ensembles, summaries, title=title,
                                         force=self.force)
            notes.append(f"Report written to {self.report_path}")
        return notes
