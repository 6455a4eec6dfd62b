"""A self-contained HTML report of a run or a Monte Carlo campaign (``--report out.html``).

One page, no network: how it was made (the command, the recording's scenario, seed and initial
state, the versions), the headline metrics (a row per metric, a column per filter, the best in
bold) and the full summary, then the figures an engineer puts in a paper, drawn by
:mod:`navreplay.viz.figures` and embedded as SVG (a ``.pdf`` path writes the same figures and
tables as the pages of a PDF):

* a run: the filters' horizontal and vertical position, velocity and heading errors overlaid
  and their CDFs; per filter, navigation errors with +-3 sigma (each at its own scale), the
  other scored states' errors with +-3 sigma, NEES and NIS with their shaded chi-square bands,
  the innovations with +-3 sqrt(S) and their settings with the source of each;
* a campaign: RMS error vs mean predicted sigma per filter, NEES and NIS averaged over the runs
  with their bands.

The run's estimates are read through :func:`navreplay.export.filter_output`, block by block
as a streamed run produces them, into :class:`RunSeries`: min/max envelopes of every plotted
series, so the report of a day-long log takes the memory of a short one.
"""

from __future__ import annotations

import contextvars
import dataclasses
import html
import math
import platform
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay import __version__
from navreplay.export import FilterOutput, check_targets, write_text
from navreplay.metrics import chi2_bounds, chi2_bounds_per_count
from navreplay.metrics.compare import COMPARED, Quantiles, compared_errors, headline_rows
from navreplay.metrics.initial import format_initial_state, initial_state
from navreplay.metrics.tables import format_summaries, outage_cells, summary_unit
from navreplay.report.envelope import Envelope

_DEG = 180.0 / math.pi
_NAV = (("pos_ned", "position error", ("N", "E", "D"), "m", 1.0, 0),
        ("v_n", "velocity error", ("N", "E", "D"), "m/s", 1.0, 3),
        ("phi", "attitude error φ", ("N", "E", "D"), "deg", _DEG, 6))
"""Navigation error groups: key, title, axes, unit, scale from SI, first row in nav_cov."""
_NAV_PART = {"pos_ned": "pos", "v_n": "v_n", "phi": "q_nb"}
"""The part of the navigation solution each group is an error of (a filter that does not
output a part has no panels for it)."""
_NAV_CAPTION = {"pos_ned": "position north/east/down", "v_n": "velocity NED",
                "phi": "attitude error φ (NED)"}

_CSS = """
body { font-family: sans-serif; margin: 2em auto; max-width: 1400px; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.25em; margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.9em; margin: 1em 0; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
th { background: #f2f2f2; }
figure { margin: 1em 0; } figure img { max-width: 100%; }
figcaption { font-size: 0.9em; color: #555; }
.note { color: #555; }
"""


# --------------------------------------------------------------------------------------------
# HTML pieces


def summary_table(summaries: Mapping[str, Mapping[str, Any]]) -> str:
    """The headline metrics (a row per metric, a column per filter, the best of a row in bold),
    then every numeric entry of the summaries the same way, folded."""
    keys: list[str] = []
    for s in summaries.values():
        for k, v in s.items():
            if k not in keys and isinstance(v, int | float) and not isinstance(v, bool):
                keys.append(k)
    if not keys:
        return "<p class='note'>(nothing to score)</p>"
    head = "".join(f"<th>{html.escape(label)}</th>" for label in summaries)
    rows = []
    for name, values, pick in headline_rows(summaries):
        cells = "".join(f"<td>{'<b>' if i == pick else ''}{_num(v)}{'</b>' if i == pick else ''}"
                        "</td>" for i, v in enumerate(values))
        rows.append(f"<tr><td>{html.escape(name)}</td>{cells}</tr>")
    all_rows: list[str] = []
    for k in keys:
        unit, factor = summary_unit(k)
        entries = []
        for s in summaries.values():
            v = s.get(k)
            if isinstance(v, int | float) and not isinstance(v, bool):
                entries.append(f"<td>{_num(float(v) * factor)}</td>")
            else:
                entries.append("<td>–</td>")
        all_rows.append(f"<tr><td>{html.escape(k)}{html.escape(f' [{unit}]' if unit else '')}"
                        f"</td>{''.join(entries)}</tr>")
    out = []
    if rows:
        out.append(f"<table><tr><th>metric</th>{head}</tr>{''.join(rows)}</table>")
    out.append(f"<details><summary>Every entry of the summary ({len(keys)})</summary><table>"
               f"<tr><th>key [unit]</th>{head}</tr>{''.join(all_rows)}</table></details>")
    return "".join(out)


def _num(v: float) -> str:
    return f"{v:.4g}" if math.isfinite(v) else "–"


def context_section(context: Mapping[str, Any]) -> str:
    """How the results were made: the command, the recording, its scenario, seed and initial
    state, the versions (``context``: :func:`run_context` and the job's ``command``)."""
    rows = []
    for key, value in context.items():
        if value in (None, "", {}):
            continue
        shown = (f"<code>{html.escape(str(value))}</code>" if key == "command"
                 else html.escape(str(value)))
        rows.append(f"<tr><td>{html.escape(key)}</td><td style='text-align:left'>{shown}</td></tr>")
    return f"<table>{''.join(rows)}</table>" if rows else ""


def run_context(metadata: Any, source: str, t0_ns: int = 0) -> dict[str, Any]:
    """The recording's part of a report's context: file, scenario, seed, scenario parameters,
    initial state (where it came from, its time from ``t0_ns``, the recording's start, and its
    values: :func:`navreplay.metrics.initial.format_initial_state`) and the version that wrote
    it, with this one's versions."""
    out: dict[str, Any] = {"recording": source}
    if metadata is not None:
        out["scenario"] = metadata.scenario or None
        out["seed"] = metadata.seed
        out["scenario parameters"] = ", ".join(
            f"{k}={_short(v)}" for k, v in (metadata.params or {}).items()) or None
        state = initial_state(metadata.initial_nav or {}, t0_ns)
        out["initial state"] = format_initial_state(state) or None
        out["recorded by"] = (f"navreplay {metadata.navreplay_version}"
                              if metadata.navreplay_version else None)
    out["versions"] = versions()
    return out


def versions() -> str:
    """navreplay, Python, numpy and matplotlib versions."""
    import matplotlib

    return (f"navreplay {__version__}, Python {platform.python_version()}, numpy "
            f"{np.__version__}, matplotlib {matplotlib.__version__}")


def _short(v: Any) -> str:
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def outage_table(summaries: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """The GNSS outages of the recording scored one by one
    (:func:`navreplay.metrics.tables.outage_cells`), as a heading and an HTML table; nothing without
    outages."""
    rows = outage_cells(summaries)
    if not rows:
        return []
    head = "".join(f"<th>{html.escape(c)}</th>" for c in rows[0])
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>"
                   for r in rows[1:])
    return ["<h3>GNSS outages</h3>", f"<table><tr>{head}</tr>{body}</table>"]


def settings_section(summary: Mapping[str, Any] | None) -> list[str]:
    """The filter's settings and where each came from (the ``settings`` entries of its summary,
    :func:`navreplay.filters.settings.summary_entries`): a note, then a folded table."""
    summary = summary or {}
    settings = summary.get("settings")
    if not settings:
        return []
    parts = []
    if summary.get("settings_note"):
        parts.append(f"<p class='note'>{html.escape(summary['settings_note'])}</p>")
    counts: dict[str, int] = {}
    rows = []
    for name, entry in settings.items():
        value = entry.get("value")
        shown = (", ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in value)
                 if isinstance(value, list) else
                 f"{value:.4g}" if isinstance(value, float) else str(value))
        source = str(entry.get("source", ""))
        counts[source] = counts.get(source, 0) + 1
        rows.append(f"<tr><td>{html.escape(name)}</td><td>{html.escape(shown)}</td>"
                    f"<td>{html.escape(str(entry.get('unit', '')))}</td>"
                    f"<td>{html.escape(source)}</td></tr>")
    tally = ", ".join(f"{n} {src}" for src, n in counts.items())
    sensors = summary.get("settings_sensors")
    origin = f"; sensor specifications: {sensors}" if sensors else ""
    parts.append(f"<details><summary>Settings ({html.escape(tally)}{html.escape(origin)})"
                 "</summary><table><tr><th>setting</th><th>value (SI)</th><th>unit</th>"
                 f"<th>source</th></tr>{''.join(rows)}</table></details>")
    return parts


def _display(unit: str) -> tuple[str, float]:
    """The unit an engineer reads a state in (deg, deg/h, mg; SI otherwise) and its scale."""
    from navreplay.viz.naming import display_unit

    u = display_unit(unit)
    return (unit, 1.0) if u.label == "SI" else (u.label, u.scale)


_PDF_PAGES: contextvars.ContextVar[list[Any] | None] = contextvars.ContextVar(
    "_PDF_PAGES", default=None)
"""The figures of a PDF report being drawn (None while an HTML page is)."""


def _figure(fig: Any, caption: str) -> str:
    """A figure as inline SVG with its caption (or kept as a page of the PDF being drawn)."""
    from navreplay.viz import figures

    pages = _PDF_PAGES.get()
    if pages is not None:
        fig.text(0.01, 0.002, caption, fontsize=7, va="bottom", wrap=True)
        pages.append(fig)
        return ""
    svg = figures.svg(fig)
    return (f"<figure role='img' aria-label=\"{html.escape(caption, quote=True)}\">{svg}"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def _page(title: str, subtitle: str, body: Sequence[str]) -> str:
    return "\n".join([
        "<!DOCTYPE html>", "<html lang='en'><head><meta charset='utf-8'>",
        f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        f"<p class='note'>{html.escape(subtitle)} — navreplay {__version__}</p>",
        *body, "</body></html>", ""])


def _write(path: Path, text: str, force: bool) -> Path:
    path = Path(path)
    check_targets([path], force, "--report")
    write_text(path, text)
    return path


def _publish(path: Path, title: str, subtitle: str, draw: Any, text: Sequence[str],
             force: bool) -> Path:
    """Write a report: ``draw()`` returns the HTML body (its figures inline SVG); for a
    ``.pdf`` path the same figures are drawn as pages after a page of ``text`` (the tables)."""
    path = Path(path)
    check_targets([path], force, "--report")
    if path.suffix.lower() != ".pdf":
        return _write(path, _page(title, subtitle, draw()), force)
    from navreplay.io.outputs import atomic_path
    from navreplay.viz import figures

    pages: list[Any] = [figures.text_page(f"{title} ({subtitle})", text)]
    token = _PDF_PAGES.set(pages)
    try:
        draw()
    finally:
        _PDF_PAGES.reset(token)
    with atomic_path(path) as tmp:
        figures.pdf(pages, str(tmp), title)
    return path


# --------------------------------------------------------------------------------------------
# a run


@dataclasses.dataclass
class _Trace:
    """One panel of a run's figure: an error (or NEES, NIS) and its 1-sigma, as envelopes."""

    title: str
    unit: str
    scale: float
    value: Envelope = dataclasses.field(default_factory=Envelope)
    sigma: Envelope | None = None

    def panel(self, band: tuple[float, float] | None = None,
              inside: float | None = None) -> Any:
        from navreplay.viz import figures

        t, v = self.value.points()
        bound_t = bound = None
        if self.sigma is not None:
            bound_t, bound = self.sigma.points()
            bound = bound * self.scale
        lohi = None if band is None else (np.full_like(t, band[0]), np.full_like(t, band[1]))
        return figures.Panel(self.title, self.unit, t, v * self.scale, bound, lohi,
                             bound_t=bound_t, inside=inside)


class RunSeries:
    """What the report draws of one filter run, kept block by block in memory independent of
    the run's length: each error, sigma, NEES and NIS series as a min/max envelope
    (:class:`navreplay.report.envelope.Envelope`, at most a few thousand points per panel).

    Feed it :meth:`add` with :func:`navreplay.export.filter_output` of each block of rows (with
    its metrics) and :meth:`add_nis` with each block's innovations (a whole run is one block).
    The numbers on the figures (the fraction inside a chi-square band) are the summary's.
    """

    def __init__(self, label: str) -> None:
        self.label = label
        self.nav: list[_Trace] = []
        self.nav_groups: tuple[str, ...] = ()
        self.states: list[_Trace] = []
        self.nees: _Trace | None = None
        self.nees_dof = 0
        self.nis: dict[str, tuple[_Trace, int]] = {}
        self.compare: dict[str, Envelope] = {}
        """Envelopes of the compared error magnitudes (:data:`COMPARED`), SI."""
        self.quantiles: dict[str, Quantiles] = {}
        """Their distributions over the whole run (the CDFs)."""
        self.innovations: dict[tuple[str, int], _Trace] = {}
        """Per measurement and row: nu with sqrt(S_ii) as its sigma."""

    def add(self, out: FilterOutput) -> None:
        """A block of rows (later than before) with its metrics, and its NIS if it has any."""
        for name, (t, nis, dof) in out.nis.items():
            self.add_nis(name, t, nis, dof)
        m = out.metrics
        if m is None or not len(m.t):
            return
        groups = [g for g in _NAV if out.has(_NAV_PART[g[0]])]
        if m.nav is not None and groups:
            if not self.nav:
                self.nav = [_Trace(f"{title} {a}", unit, scale, sigma=Envelope())
                            for _, title, axes, unit, scale, _ in groups for a in axes]
                self.nav_groups = tuple(g[0] for g in groups)
            sig = (np.sqrt(np.clip(np.diagonal(out.nav_cov, axis1=1, axis2=2), 0.0, None))
                   if out.nav_cov is not None else np.full((len(m.t), 9), np.nan))
            k = 0
            for key, _, axes, _, _, row in groups:
                for i in range(len(axes)):
                    trace = self.nav[k]
                    assert trace.sigma is not None  # made with one
                    trace.value.add(m.t, getattr(m.nav, key)[:, i])
                    trace.sigma.add(m.t, sig[:, row + i])
                    k += 1
            for key, v in compared_errors(m.nav.pos_ned, m.nav.v_n, m.nav.phi).items():
                if np.isfinite(v).any():
                    self.compare.setdefault(key, Envelope()).add(m.t, v)
                    self.quantiles.setdefault(key, Quantiles()).add(v)
        others = [(j, name) for j, name in enumerate(m.state_names) if name not in out.nav_states]
        if not self.states and others:
            units = dict(zip(out.state_names, out.state_units, strict=True))
            self.states = [_Trace(name, *_display(units.get(name, "-")), sigma=Envelope())
                           for _, name in others]
        for trace, (j, _) in zip(self.states, others, strict=True):
            assert trace.sigma is not None  # made with one
            trace.value.add(m.t, m.state_error[:, j])
            trace.sigma.add(m.t, np.sqrt(np.clip(m.state_var[:, j], 0.0, None)))
        if m.nees_states:
            if self.nees is None:
                self.nees_dof = len(m.nees_states)
                self.nees = _Trace(f"NEES ({self.nees_dof} dof)", "-", 1.0)
            self.nees.value.add(m.t, m.nees)

    def add_innovations(self, name: str, t: np.ndarray, nu: np.ndarray, S: np.ndarray,
                        rows: Sequence[tuple[str, Any]]) -> None:
        """The innovations of one measurement at its update times [s] (later than before):
        ``nu`` (K, m), ``S`` (K, m, m), ``rows`` the title and display unit of each row
        (:func:`navreplay.viz.naming.innovation_rows`)."""
        k = len(t)
        if not k:
            return
        nu = np.asarray(nu, dtype=np.float64).reshape(k, -1)
        sd = np.sqrt(np.clip(np.diagonal(np.asarray(S).reshape(k, nu.shape[1], nu.shape[1]),
                                         axis1=1, axis2=2), 0.0, None))
        for i, (row, u) in enumerate(rows):
            key = (name, i)
            if key not in self.innovations:
                self.innovations[key] = _Trace(f"{name} {row}", u.label, u.scale,
                                               sigma=Envelope())
            trace = self.innovations[key]
            assert trace.sigma is not None  # made with one
            trace.value.add(t, nu[:, i])
            trace.sigma.add(t, sd[:, i])

    def add_nis(self, name: str, t: np.ndarray, nis: np.ndarray, dof: int) -> None:
        """NIS of one measurement at its update times [s] (later than before)."""
        if name not in self.nis:
            self.nis[name] = (_Trace(f"NIS {name} ({dof} dof)", "-", 1.0), dof)
        self.nis[name][0].value.add(t, nis)


def run_figures(series: RunSeries, color: str,
                summary: Mapping[str, Any] | None = None) -> list[str]:
    """The HTML figures of one filter run; ``summary`` (its scores) gives the fractions inside
    the chi-square bands."""
    from navreplay.viz import figures

    summary = summary or {}
    label = series.label
    parts = []
    if series.nav and series.nav[0].value.count:
        parts.append(_figure(
            figures.bounded_errors(f"{label}: navigation errors",
                                   [tr.panel() for tr in series.nav], color),
            f"{label}: navigation errors (estimate minus reference) and their predicted "
            f"±3σ: {', '.join(_NAV_CAPTION[g] for g in series.nav_groups)}."))
    if series.states:
        parts.append(_figure(
            figures.bounded_errors(f"{label}: state errors",
                                   [tr.panel() for tr in series.states], color),
            f"{label}: estimation errors of the other scored states and their ±3σ."))
    cons = []
    if series.nees is not None and series.nees.value.count:
        cons.append(series.nees.panel(chi2_bounds(series.nees_dof),
                                      summary.get("nees_in_bounds")))
    for name, (trace, dof) in series.nis.items():
        if trace.value.count:
            cons.append(trace.panel(chi2_bounds(dof), summary.get(f"nis_in_bounds_{name}")))
    if cons:
        parts.append(_figure(
            figures.consistency(f"{label}: consistency", cons, color),
            f"{label}: NEES and NIS per epoch with the 95 % chi-square band of one sample."))
    if series.innovations:
        parts.append(_figure(
            figures.bounded_errors(f"{label}: innovations",
                                   [tr.panel() for tr in series.innovations.values()], color),
            f"{label}: innovations of each measurement row with ±3√S_ii (the bounds the "
            "filter predicts)."))
    if not parts:
        parts.append("<p class='note'>No reference and no measurement updates: nothing to "
                     "plot.</p>")
    return parts


def comparison_figures(runs: Sequence[RunSeries], colors: Mapping[str, str]) -> list[str]:
    """The filters' error magnitudes overlaid over time and their CDFs (with truth only)."""
    from navreplay.viz import figures
    from navreplay.viz.naming import display_unit

    over, dist = [], []
    for key, name, unit in COMPARED:
        u = display_unit(unit)
        curves, cdf = [], []
        for r in runs:
            if key in r.compare and r.compare[key].count:
                t, v = r.compare[key].points()
                curves.append(figures.Curve(r.label, t, v * u.scale, colors[r.label]))
                x, frac = r.quantiles[key].cdf()
                cdf.append(figures.Curve(r.label, x * u.scale, frac, colors[r.label]))
        if curves:
            over.append((name, u.label, curves))
            dist.append((name, u.label, cdf))
    if not over:
        return []
    return [
        _figure(figures.overlay("errors of every filter", over),
                "Horizontal and vertical position, velocity and heading error magnitudes of "
                "every filter (y range set by the last 90 % of the run when a start-up "
                "transient would flatten it)."),
        _figure(figures.cdfs("error distributions", dist),
                "Cumulative distributions of the same errors over the whole run: the curve "
                "further left and higher is the better filter."),
    ]


def write_run_report(path: Path, runs: Sequence[RunSeries],
                     summaries: Mapping[str, Mapping[str, Any]], *, title: str,
                     context: Mapping[str, Any] | None = None, force: bool = False,
                     log_notes: Sequence[str] = ()) -> Path:
    """Write the report of filters replayed over one recording (their series): HTML, or PDF
    for a ``.pdf`` path. ``context``: the command and :func:`run_context`; ``log_notes``: what
    the log's preparation said (reference, frame checks, the initial state and its source),
    one line each."""
    from navreplay.viz import figures

    colors = figures.filter_colors([r.label for r in runs])

    def draw() -> list[str]:
        body = [context_section(context or {})]
        if log_notes:
            body.append("<h2>The log</h2><ul>" + "".join(
                f"<li>{html.escape(n)}</li>" for n in log_notes) + "</ul>")
        body.append("<h2>Summary</h2>")
        if summaries:
            body.append(summary_table(summaries))
            body += outage_table(summaries)
        else:
            body.append("<p class='note'>The recording has no reference: no errors to score; "
                        "the NIS below needs none.</p>")
        cmp = comparison_figures(runs, colors)
        if cmp:
            body += ["<h2>Comparison</h2>", *cmp]
        for series in runs:
            body.append(f"<h2>{html.escape(series.label)}</h2>")
            body += settings_section(summaries.get(series.label))
            body += run_figures(series, colors[series.label], summaries.get(series.label))
        return body

    text = [f"{k}: {v}" for k, v in (context or {}).items() if v not in (None, "", {})]
    text += list(log_notes)
    text += ["", format_summaries(summaries) if summaries else "(no reference)"]
    return _publish(path, title, "filter run report", draw, text, force)


def write_compare_report(path: Path, summaries: Mapping[str, Mapping[str, Any]], *,
                         sources: Sequence[str], force: bool = False) -> Path:
    """Write the comparison of saved summaries (``navreplay compare``): the headline table and
    a bar chart per metric; HTML, or PDF for a ``.pdf`` path."""
    from navreplay.metrics.compare import format_comparison
    from navreplay.viz import figures

    colors = figures.filter_colors(list(summaries))
    rows = headline_rows(summaries)

    def draw() -> list[str]:
        body = [context_section({"summaries": ", ".join(sources), "versions": versions()}),
                "<h2>Headline metrics</h2>", summary_table(summaries)]
        if rows:
            body.append(_figure(
                figures.metric_bars([(n, v) for n, v, _ in rows], list(summaries),
                                    [colors[label] for label in summaries]),
                "The headline metrics of each filter (a missing bar: not in its summary)."))
        for label, s in summaries.items():
            if s.get("settings"):
                body.append(f"<h2>{html.escape(label)}</h2>")
                body += settings_section(s)
        return body

    return _publish(path, "Comparison of saved runs", "comparison report", draw,
                    [f"summaries: {', '.join(sources)}", "", format_comparison(summaries)],
                    force)


# --------------------------------------------------------------------------------------------
# a campaign


def ensemble_figures(ens: Any, color: str) -> list[str]:
    """The HTML figures of one filter's ensemble statistics (an EnsembleResult)."""
    from navreplay.export import nav_state_names
    from navreplay.viz import figures

    nav_states = nav_state_names(ens.states)
    units = {st.name: st.unit for st in ens.states}
    parts = []
    runs = f"{ens.runs} runs"
    panels = [figures.Panel(f"{title} {a}", unit, ens.t, ens.rms[key][:, i] * scale,
                            ens.sigma[key][:, i] * scale)
              for key, title, axes, unit, scale, _ in _NAV if key in ens.rms
              for i, a in enumerate(axes)]
    for j, name in enumerate(ens.state_names):
        if name not in nav_states:
            unit, scale = _display(units.get(name, "-"))
            panels.append(figures.Panel(name, unit, ens.t, ens.state_rms[:, j] * scale,
                                        ens.state_sigma[:, j] * scale))
    if panels:
        parts.append(_figure(
            figures.rms_vs_sigma(f"{ens.label}: RMS over {runs} vs predicted σ", panels, color),
            f"{ens.label}: RMS error over {runs} (solid) against the square root of the mean "
            "predicted variance (dashed)."))
    cons = []
    if ens.nees_dof and np.isfinite(ens.nees_mean).any():
        cons.append(figures.Panel(f"mean NEES ({ens.nees_dof} dof)", "-", ens.t, ens.nees_mean,
                                  band=ens.nees_bounds))
    for name, (t, mean, count, dof) in ens.nis_mean.items():
        n = mean.shape[0]
        cons.append(figures.Panel(f"mean NIS {name} ({dof} dof)", "-", t[:n], mean,
                                  band=chi2_bounds_per_count(dof, count[:n])))
    if cons:
        parts.append(_figure(
            figures.consistency(f"{ens.label}: consistency over {runs}", cons, color),
            f"{ens.label}: NEES and NIS averaged over {runs} with the 95 % chi-square band of "
            "the mean."))
    return parts


def write_ensemble_report(path: Path, ensembles: Mapping[str, Any],
                          summaries: Mapping[str, Mapping[str, Any]], *, title: str,
                          force: bool = False) -> Path:
    """Write the HTML report of a Monte Carlo campaign (EnsembleResult per filter label)."""
    from navreplay.viz import figures

    colors = figures.filter_colors(list(ensembles))

    def draw() -> list[str]:
        body = [context_section({"versions": versions()}), "<h2>Ensemble summary</h2>",
                summary_table(summaries), *outage_table(summaries)]
        for label, ens in ensembles.items():
            body.append(f"<h2>{html.escape(label)}</h2>")
            body += settings_section(summaries.get(label))
            body += ensemble_figures(ens, colors[label])
        return body

    return _publish(path, title, "Monte Carlo report", draw, [format_summaries(summaries)],
                    force)
