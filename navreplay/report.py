"""A self-contained HTML report of a run or a Monte Carlo campaign (``--report out.html``).

One page, no network: the summary table, then per filter the figures an engineer puts in a
paper, drawn by :mod:`navreplay.figures` and embedded as base64 PNG:

* a run: navigation errors with +-3 sigma (one figure per filter, each at its own scale), the
  other scored states' errors with +-3 sigma, NEES and NIS with their shaded chi-square bands;
* a campaign: RMS error vs mean predicted sigma per filter, NEES and NIS averaged over the runs
  with their bands.

The run's estimates are read through :func:`navreplay.export.filter_output`.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay import __version__
from navreplay.export import FilterOutput, check_targets, write_text
from navreplay.metrics import chi2_bounds, chi2_bounds_per_count
from navreplay.tables import summary_unit

_DEG = 180.0 / math.pi
_NAV = (("pos_ned", "position error", ("N", "E", "D"), "m", 1.0, 0),
        ("v_n", "velocity error", ("N", "E", "D"), "m/s", 1.0, 3),
        ("phi", "attitude error φ", ("N", "E", "D"), "deg", _DEG, 6))
"""Navigation error groups: key, title, axes, unit, scale from SI, first row in nav_cov."""

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
            ok = isinstance(v, int | float) and math.isfinite(float(v))
            cells.append(f"<td>{f'{float(v) * summary_unit(k)[1]:.4g}' if ok else '–'}</td>")
        rows.append(f"<tr><td>{html.escape(label)}</td>{''.join(cells)}</tr>")
    return f"<table><tr><th>filter</th>{head}</tr>{''.join(rows)}</table>"


def _state_panel(name: str, unit: str, t: np.ndarray, value: np.ndarray,
                 sigma: np.ndarray) -> Any:
    """A state's panel in the unit an engineer reads (deg, deg/h, mg; SI otherwise)."""
    from navreplay import figures
    from navreplay.viz.naming import display_unit

    u = display_unit(unit)
    if u.label == "SI":
        return figures.Panel(name, unit, t, value, sigma)
    return figures.Panel(name, u.label, t, value * u.scale, sigma * u.scale)


def _figure(fig: Any, caption: str) -> str:
    from navreplay import figures

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
    check_targets([path], force)
    write_text(path, text)
    return path


# --------------------------------------------------------------------------------------------
# a run


def run_figures(out: FilterOutput, color: str) -> list[str]:
    """The HTML figures of one filter run."""
    from navreplay import figures

    parts = []
    m = out.metrics
    if m is not None and m.nav is not None:
        sig = (np.sqrt(np.clip(np.diagonal(out.nav_cov, axis1=1, axis2=2), 0.0, None))
               if out.nav_cov is not None else np.full((len(m.t), 9), np.nan))
        panels = [figures.Panel(f"{title} {a}", unit, m.t, getattr(m.nav, key)[:, i] * scale,
                                sig[:, row + i] * scale)
                  for key, title, axes, unit, scale, row in _NAV for i, a in enumerate(axes)]
        parts.append(_figure(
            figures.bounded_errors(f"{out.label}: navigation errors", panels, color),
            f"{out.label}: navigation errors (estimate minus reference) and their predicted "
            "±3σ. Position north/east/down, velocity NED, attitude error φ (NED)."))
    if m is not None:
        units = dict(zip(out.state_names, out.state_units, strict=True))
        panels = [_state_panel(name, units.get(name, "-"), m.t, m.state_error[:, j],
                               np.sqrt(np.clip(m.state_var[:, j], 0.0, None)))
                  for j, name in enumerate(m.state_names) if name not in out.nav_states]
        if panels:
            parts.append(_figure(
                figures.bounded_errors(f"{out.label}: state errors", panels, color),
                f"{out.label}: estimation errors of the other scored states and their ±3σ."))
    cons = []
    if m is not None and m.nees_states and np.isfinite(m.nees).any():
        dof = len(m.nees_states)
        lo, hi = chi2_bounds(dof)
        cons.append(figures.Panel(f"NEES ({dof} dof)", "-", m.t, m.nees,
                                  band=(np.full_like(m.t, lo), np.full_like(m.t, hi))))
    for name, (t, nis, dof) in out.nis.items():
        if len(t):
            lo, hi = chi2_bounds(dof)
            cons.append(figures.Panel(f"NIS {name} ({dof} dof)", "-", t, nis,
                                      band=(np.full_like(t, lo), np.full_like(t, hi))))
    if cons:
        parts.append(_figure(
            figures.consistency(f"{out.label}: consistency", cons, color),
            f"{out.label}: NEES and NIS per epoch with the 95 % chi-square band of one sample."))
    if not parts:
        parts.append("<p class='note'>No reference and no measurement updates: nothing to "
                     "plot.</p>")
    return parts


def write_run_report(path: Path, outputs: Sequence[FilterOutput],
                     summaries: Mapping[str, Mapping[str, Any]], *, title: str,
                     force: bool = False) -> Path:
    """Write the HTML report of filters replayed over one recording."""
    from navreplay import figures

    check_targets([Path(path)], force)
    body = ["<h2>Summary</h2>"]
    if summaries:
        body.append(summary_table(summaries))
    else:
        body.append("<p class='note'>The recording has no reference: no errors to score; "
                    "the NIS below needs none.</p>")
    for i, out in enumerate(outputs):
        body.append(f"<h2>{html.escape(out.label)}</h2>")
        body += run_figures(out, figures.filter_color(i))
    return _write(path, _page(title, "filter run report", body), force)


# --------------------------------------------------------------------------------------------
# a campaign


def ensemble_figures(ens: Any, color: str) -> list[str]:
    """The HTML figures of one filter's ensemble statistics (an EnsembleResult)."""
    from navreplay import figures
    from navreplay.export import nav_state_names

    nav_states = nav_state_names(ens.states)
    units = {st.name: st.unit for st in ens.states}
    parts = []
    runs = f"{ens.runs} runs"
    panels = [figures.Panel(f"{title} {a}", unit, ens.t, ens.rms[key][:, i] * scale,
                            ens.sigma[key][:, i] * scale)
              for key, title, axes, unit, scale, _ in _NAV if key in ens.rms
              for i, a in enumerate(axes)]
    panels += [_state_panel(name, units.get(name, "-"), ens.t, ens.state_rms[:, j],
                            ens.state_sigma[:, j])
               for j, name in enumerate(ens.state_names) if name not in nav_states]
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
    from navreplay import figures

    check_targets([Path(path)], force)
    body = ["<h2>Ensemble summary</h2>", summary_table(summaries)]
    for i, (label, ens) in enumerate(ensembles.items()):
        body.append(f"<h2>{html.escape(label)}</h2>")
        body += ensemble_figures(ens, figures.filter_color(i))
    return _write(path, _page(title, "Monte Carlo report", body), force)
