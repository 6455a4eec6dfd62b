"""Whole runs through the block-wise outputs, each run one block (as the replay pipeline hands
over a recording read in one window): the exports of :class:`navreplay.export.RunExport` and
the report's :class:`navreplay.report.RunSeries`."""

from __future__ import annotations

from pathlib import Path

from navreplay import export
from navreplay.core.streams import Recording, StreamKind
from navreplay.filters.result import RunResult
from navreplay.metrics import run_metrics
from navreplay.report import RunSeries
from navreplay.viz.naming import innovation_rows


def export_runs(out_dir: Path, results: list[RunResult], rec: Recording | None, *,
                source: str = "", force: bool = False,
                compression: str = "zstd") -> list[Path]:
    """Export whole runs (scored against the recording's truth, if any); the files written."""
    has_ref = rec is not None and StreamKind.TRUTH in rec
    writer = export.RunExport(out_dir, [r.label for r in results], has_reference=has_ref,
                              source=source, force=force, compression=compression)
    try:
        if has_ref:
            writer.add_reference(rec[StreamKind.TRUTH])
        for r in results:
            writer.add_innovations(r.label, r.t0_ns, r.innovations, r.measurements)
            rows = r.rows(0, r.t.shape[0])
            writer.add(export.filter_output(rows, run_metrics(rows, rec) if has_ref else None))
    except BaseException:
        writer.abort()
        raise
    return writer.close()


def run_series(result: RunResult, rec: Recording | None) -> RunSeries:
    """The report's series of a whole run."""
    series = RunSeries(result.label)
    rows = result.rows(0, result.t.shape[0])
    has_ref = rec is not None and StreamKind.TRUTH in rec
    series.add(export.filter_output(rows, run_metrics(rows, rec) if has_ref else None))
    for name, s in result.innovations.items():
        dim = int(s.nu.shape[1])
        series.add_nis(name, s.t, s.nis, dim)
        series.add_innovations(name, s.t, s.nu, s.S,
                               innovation_rows(name, dim, result.measurement(name)))
    return series
