"""``navreplay compare``: the headline metrics of saved run summaries side by side (the
``--summary`` JSON of ``run`` and ``montecarlo``), as text, in a Rerun view (a bar chart per
metric, one colour per filter) and in an HTML report."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from navreplay.jobs.report import DEFAULT_OUT, RunReport
from navreplay.metrics.compare import format_comparison, headline_rows, labelled
from navreplay.viz.options import VizMode, VizOptions, close_output, open_output


class SummaryError(ValueError):
    """A file that is not a navreplay summary (one line naming it)."""


@dataclasses.dataclass(frozen=True)
class CompareJob:
    """Compare saved summaries.

    Attributes
    ----------
    summaries : tuple of Path
        ``--summary`` files of ``navreplay run`` (per filter) or ``montecarlo`` (per filter's
        ensemble).
    viz : VizOptions
        Where the Rerun view goes (none by default).
    report_path : Path, optional
        The HTML report (or PDF: ``.pdf``).
    force : bool
    """

    summaries: tuple[Path, ...]
    viz: VizOptions = VizOptions(VizMode.NONE)
    report_path: Path | None = None
    force: bool = False


def load_summary(path: Path) -> dict[str, Mapping[str, Any]]:
    """The per-filter summaries of a ``--summary`` file: ``filters`` of a run, ``ensemble``
    of a campaign (label -> summary, SI)."""
    try:
        data = json.loads(Path(path).read_text())
    except OSError as e:
        raise SummaryError(f"{path}: {e.strerror or e}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise SummaryError(f"{path}: not JSON ({e})") from None
    for key in ("filters", "ensemble"):
        block = data.get(key) if isinstance(data, dict) else None
        if isinstance(block, dict) and all(isinstance(v, dict) for v in block.values()):
            return block
    raise SummaryError(f"{path}: not a navreplay summary (no 'filters' or 'ensemble' table)")


def compare(job: CompareJob) -> RunReport:
    """The comparison table; the view and the report when asked for."""
    named = [(p.stem, load_summary(p)) for p in job.summaries]
    summaries = labelled(named)
    notes = []
    if job.report_path is not None:
        from navreplay.report import write_compare_report

        written = write_compare_report(job.report_path, summaries,
                                       sources=[str(p) for p in job.summaries],
                                       force=job.force)
        notes.append(f"Report written to {written}")
    sink = open_output(job.viz, DEFAULT_OUT / "compare.rrd", "compare")
    try:
        if sink is not None:
            sink.comparison(summaries)
        hint = close_output(sink, job.viz)
    except BaseException:
        if sink is not None:
            sink.abort()
        raise
    title = f"{len(summaries)} filters of {len(job.summaries)} summaries"
    return RunReport(title=title, table=format_comparison(summaries),
                     summary={"metrics": [{"metric": name, **dict(zip(summaries, values,
                                                                          strict=True))}
                                          for name, values, _ in headline_rows(summaries)]},
                     viz=hint, notes=notes,
                     sink=sink if job.viz.mode is VizMode.SERVE else None)
