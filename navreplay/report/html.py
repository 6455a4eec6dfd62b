"""A self-contained HTML report of a run or a Monte Carlo campaign (``--report out.html``).

One page, no network: the summary table, then per filter the figures an engineer puts in a
paper, drawn by :mod:`navreplay.viz.figures` and embedded as base64 PNG:

* a run: navigation errors with +-3 sigma (one figure per filter, each at its own scale), the
  other scored states' errors with +-3 sigma, NEES and NIS with their shaded chi-square bands;
* a campaign: RMS error vs mean predicted sigma per filter, NEES and NIS averaged over the runs
  with their bands.

The run's estimates are read through :func:`navreplay.export.filter_output`, block by block
as a streamed run produces them, into :class:`RunSeries`: min/max envelopes of every plotted
series, so the report of a day-long log takes the memory of a short one.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay import __version__
from navreplay.export import FilterOutput, check_targets, write_text
from navreplay.metrics import chi2_bounds, chi2_bounds_per_count
from navreplay.metrics.tables import outage_cells, summary_unit
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
    """An HTML table of summary dicts (one row per filter; units under the names)."""
    keys: list[str] = []
    for s in summaries.values():
        for k, v in s.items():
            if k not in keys and isinstance(v, int | float) and not isinstance(v, bool):
                keys.append(k)
    if not keys:
        return "<p class='note'>(nothing to score)</p>"
    head = "".join(f"<th>{html.escape(k)}<br>{html.escape(summary_unit(k)[0] and f'[{summary_unit(k)[0]}]')}"
                   "</th>" for k in keys)
    rows = []
    for label, s in summaries.items():
        cells = []
        for k in keys:
            v = s.get(k)
            if isinstance(v, int | float) and math.isfinite(float(v)):
                cells.append(f"<td>{float(v) * summary_unit(k)[1]:.4g}</td>")
            else:
                cells.append("<td>–</td>")
        rows.append(f"<tr><td>{html.escape(label)}</td>{''.join(cells)}</tr>")
    return f"<table><tr><th>filter</th>{head}</tr>{''.join(rows)}</table>"


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


def _figure(fig: Any, caption: str) -> str:
    from navreplay.viz import figures

    data = base64.b64encode(figures.png(fig)).decode("ascii")
    alt = html.escape(caption, quote=True)
    return (f"<figure><img alt=\"{alt}\" src=\"data:image/png;base64,{data}\">"
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
    if not parts:
        parts.append("<p class='note'>No reference and no measurement updates: nothing to "
                     "plot.</p>")
    return parts


def write_run_report(path: Path, runs: Sequence[RunSeries],
                     summaries: Mapping[str, Mapping[str, Any]], *, title: str,
                     force: bool = False, log_notes: Sequence[str] = ()) -> Path:
    """Write the HTML report of filters replayed over one recording (their series);
    ``log_notes``: what the log's preparation said (reference, frame checks, the initial
    state and its source), one line each."""
    from navreplay.viz import figures

    check_targets([Path(path)], force, "--report")
    body = ["<h2>Summary</h2>"]
    if log_notes:
        body.insert(0, "<h2>The log</h2><ul>" + "".join(
            f"<li>{html.escape(n)}</li>" for n in log_notes) + "</ul>")
    if summaries:
        body.append(summary_table(summaries))
        body += outage_table(summaries)
    else:
        body.append("<p class='note'>The recording has no reference: no errors to score; "
                    "the NIS below needs none.</p>")
    for i, series in enumerate(runs):
        body.append(f"<h2>{html.escape(series.label)}</h2>")
        body += settings_section(summaries.get(series.label))
        body += run_figures(series, figures.filter_color(i), summaries.get(series.label))
    return _write(path, _page(title, "filter run report", body), force)


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

    check_targets([Path(path)], force, "--report")
    body = ["<h2>Ensemble summary</h2>", summary_table(summaries), *outage_table(summaries)]
    for i, (label, ens) in enumerate(ensembles.items()):
        body.append(f"<h2>{html.escape(label)}</h2>")
        body += settings_section(summaries.get(label))
        body += ensemble_figures(ens, figures.filter_color(i))
    return _write(path, _page(title, "Monte Carlo report", body), force)
