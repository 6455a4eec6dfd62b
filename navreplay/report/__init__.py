"""The self-contained HTML report of a run or a campaign (``--report out.html``):
:mod:`~navreplay.report.html` the page (context, summary tables, settings, figures as inline SVG; or
a PDF) and :class:`~navreplay.report.html.RunSeries` (a run's plotted series kept block by block),
:mod:`~navreplay.report.envelope` (a series in bounded memory: min/max per time bin). The
figures themselves are :mod:`navreplay.viz.figures`; matplotlib is imported only when a report
is drawn."""

from navreplay.report.html import (
    RunSeries,
    run_context,
    settings_section,
    summary_table,
    write_compare_report,
    write_ensemble_report,
    write_run_report,
)

__all__ = ["RunSeries", "run_context", "settings_section", "summary_table",
           "write_compare_report", "write_ensemble_report", "write_run_report"]
