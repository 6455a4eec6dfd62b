"""``--export DIR`` and ``--report FILE.html`` of ``navreplay run`` and ``navreplay montecarlo``.

The jobs call :meth:`Outputs.check` before any work (existing files are refused unless
``force``, so a long run does not end in a refusal). Over one recording, :class:`Outputs` is a
stage of the replay pipeline (:class:`navreplay.replay.Stage`): it is started, handed the truth
window by window and each filter's estimates and innovations block by block as they come (the
exports are written as they go, the report keeps envelopes), and ends with
:meth:`Outputs.write_run` (or :meth:`Outputs.abort`); a campaign calls
:meth:`Outputs.write_ensemble`. Both return the lines to print. matplotlib is imported only
when a report is asked for.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from navreplay import export
from navreplay.io.outputs import writing


def export_names(labels: Sequence[str]) -> tuple[str, ...]:
    """Names (glob patterns) of every file ``--export DIR`` may write for filters ``labels``,
    a run's or a campaign's: the manifest, the estimates MCAP and its Foxglove layout, the
    reference's TUM and
    ``STEM.*`` per filter (CSV, TUM, innovations, ensemble and NIS files; ``STEM_2.*``... for
    repeated labels). An input or another output there is refused before any work
    (:func:`navreplay.io.outputs.check_outputs`)."""
    names = [export.MANIFEST, export.ODOMETRY_FILE, export.FOXGLOVE_LAYOUT,
             f"{export.REFERENCE_LABEL}.tum"]
    for stem in dict.fromkeys(export.file_stem(label) for label in labels):
        names += [f"{stem}.*", f"{stem}_[0-9]*.*"]
    return tuple(names)


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
    command: str | None = None
    """The command line, for the report."""
    compression: str = "zstd"
    """Chunk compression of the estimates MCAP."""
    reference_rate: float | None = None
    """The rate [Hz] the reference is exported at (the run's output rate), None: its own."""
    _export: export.RunExport | None = None
    _context: dict[str, Any] = dataclasses.field(default_factory=dict)
    _series: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def wanted(self) -> bool:
        return self.export_dir is not None or self.report_path is not None

    def _writing(self) -> Any:
        """A full disk while exporting: one line naming ``--export DIR``."""
        return writing(f"--export {self.export_dir}")

    def check(self, labels: Sequence[str], *, ensemble: bool, has_reference: bool = True) -> None:
        """Refuse existing targets (unless force) before the job starts."""
        paths = [self.report_path] if self.report_path is not None else []
        if self.export_dir is not None:
            paths += (export.ensemble_targets(self.export_dir, labels) if ensemble
                      else export.run_targets(self.export_dir, labels, has_reference))
        export.check_targets(paths, self.force)

    def start(self, run: Any) -> None:
        """Open the exports and the report's series of filters replayed over one recording
        (a :class:`navreplay.replay.RunStart`), existing targets refused first."""
        self.check(run.labels, ensemble=False, has_reference=run.has_truth)
        if self.export_dir is not None:
            self._export = export.RunExport(self.export_dir, run.labels,
                                            has_reference=run.has_truth, source=run.source,
                                            force=self.force, late=getattr(run, "late", {}),
                                            origin=_origin(run), compression=self.compression,
                                            reference_rate=self.reference_rate,
                                            t0_ns=getattr(run, "t0_ns", 0))
        if self.report_path is not None:
            from navreplay.report import RunSeries, run_context

            self._series = {label: RunSeries(label) for label in run.labels}
            self._context = {"command": self.command,
                             **run_context(getattr(run, "metadata", None), run.source,
                                           getattr(run, "t0_ns", 0))}

    def truth(self, truth: Any) -> None:
        """A window of the truth stream (later than before)."""
        if self._export is not None:
            with self._writing():
                self._export.add_reference(truth)

    def rows(self, rows: Any, metrics: Any = None, truth: Any = None) -> None:
        """A block of one filter's estimates (a RunResult, later than its blocks before) with
        its metrics (None without a reference)."""
        if not self.wanted:
            return
        out = export.filter_output(rows, metrics)
        if self._export is not None:
            with self._writing():
                self._export.add(out)
        if rows.label in self._series:
            self._series[rows.label].add(out)

    def innovations(self, block: Any) -> None:
        """The innovations of a block of one filter's run (a RunResult)."""
        if self._export is not None:
            with self._writing():
                self._export.add_innovations(block.label, block.t0_ns, block.innovations,
                                             block.measurements)
        series = self._series.get(block.label)
        if series is not None:
            from navreplay.viz.naming import innovation_rows

            for name, s in block.innovations.items():
                dim = int(s.nu.shape[1])
                series.add_nis(name, s.t, s.nis, dim)
                series.add_innovations(name, s.t, s.nu, s.S,
                                       innovation_rows(name, dim, block.measurement(name)))

    def write_run(self, summaries: Mapping[str, Mapping[str, Any]], *, title: str,
                  log_notes: Sequence[str] = ()) -> list[str]:
        """Finish the exports and write the report of filters replayed over one recording
        (``log_notes``: the log's reference, checks and initial state, for the report)."""
        notes = []
        if self._export is not None:
            with self._writing():
                written = self._export.close()
            self._export = None
            assert self.export_dir is not None  # an export was asked for
            notes.append(f"Exported {len(written)} files to {self.export_dir} "
                         f"(see {self.export_dir / export.MANIFEST})")
        if self.report_path is not None:
            from navreplay import report

            report.write_run_report(self.report_path, list(self._series.values()), summaries,
                                    title=title, context=self._context, force=self.force,
                                    log_notes=log_notes)
            notes.append(f"Report written to {self.report_path}")
        return notes

    def abort(self) -> None:
        """Stop: the exports' temporaries are deleted, nothing is published."""
        if self._export is not None:
            self._export.abort()
            self._export = None

    def write_ensemble(self, ensembles: Mapping[str, Any], summaries: Mapping[str, Any], *,
                       title: str) -> list[str]:
        """Write the ensemble statistics and the report of a campaign."""
        notes = []
        if self.export_dir is not None:
            with self._writing():
                written = export.export_ensemble(self.export_dir, ensembles, title=title,
                                                 force=self.force)
            notes.append(f"Exported {len(written)} files to {self.export_dir}")
        if self.report_path is not None:
            from navreplay import report

            report.write_ensemble_report(self.report_path, ensembles, summaries, title=title,
                                         force=self.force)
            notes.append(f"Report written to {self.report_path}")
        return notes


def _origin(run: Any) -> Any:
    """The frame origin the user gave for a run (``Metadata.extra[LOCAL_ORIGIN]``), or None."""
    from navreplay.core.streams import LOCAL_ORIGIN

    metadata = getattr(run, "metadata", None)
    return metadata.extra.get(LOCAL_ORIGIN) if metadata is not None else None
