"""Text tables of summaries: errors with display units, NEES and NIS against their bounds.

Summary dicts hold SI values (:meth:`navreplay.metrics.RunMetrics.summary`,
:meth:`navreplay.metrics.EnsembleResult.summary`); :data:`SUMMARY_UNITS` converts them for
display.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

SUMMARY_UNITS: dict[str, tuple[str, float]] = {
    "runs": ("", 1.0),
    "duration": ("s", 1.0),
    "distance": ("km", 1e-3),
    "pos_err_final_h": ("m", 1.0),
    "pos_err_final_dt": ("%DT", 1.0),
    "pos_rms_h": ("m", 1.0),
    "pos_rms_v": ("m", 1.0),
    "vel_rms": ("m/s", 1.0),
    "att_rms_level": ("mrad", 1e3),
    "att_rms_heading": ("mrad", 1e3),
    "lat_rms_final": ("m", 1.0),
    "long_rms_final": ("m", 1.0),
    "cep50_final": ("m", 1.0),
    "dt_cep50_final": ("%", 1.0),
    "nees_mean": ("", 1.0),
    "nees_dof": ("", 1.0),
    "nees_in_bounds": ("%", 100.0),
}
"""Display unit and factor from SI for each summary key (``nis_*`` keys like ``nees_*``)."""


def summary_unit(key: str) -> tuple[str, float]:
    """Display unit and factor from SI of a summary key."""
    if key in SUMMARY_UNITS:
        return SUMMARY_UNITS[key]
    for prefix in ("nis_mean_", "nis_dof_", "nis_in_bounds_"):
        if key.startswith(prefix):
            return SUMMARY_UNITS[prefix.replace("nis", "nees").rstrip("_")]
    return ("", 1.0)


def format_table(
    summaries: Mapping[str, Mapping[str, Any]], keys: Sequence[str] | None = None
) -> str:
    """A compact text table of summary dicts, one row per label.

    Parameters
    ----------
    summaries : mapping
        Label -> summary dict (:meth:`RunMetrics.summary`, :meth:`EnsembleResult.summary`).
    keys : sequence of str, optional
        Columns; default: every numeric key present in any summary, in first-seen order.

    Returns
    -------
    str

    Examples
    --------
    >>> print(format_table({"ins": {"pos_rms_h": 812.0, "att_rms_level": 0.00123},
    ...                     "gps-ins": {"pos_rms_h": 0.9}}))
    label    pos_rms_h  att_rms_level
             [m]        [mrad]
    ins      812        1.23
    gps-ins  0.9        -
    """
    if keys is None:
        keys = []
        for s in summaries.values():
            for k, v in s.items():
                if k not in keys and isinstance(v, int | float) and not isinstance(v, bool):
                    keys.append(k)
    header = ["label", *keys]
    units = ["", *(f"[{summary_unit(k)[0]}]" if summary_unit(k)[0] else "" for k in keys)]
    rows = []
    for label, s in summaries.items():
        row = [label]
        for k in keys:
            v = s.get(k)
            if v is None or (isinstance(v, float) and not math.isfinite(v)):
                row.append("-")
            else:
                row.append(f"{float(v) * summary_unit(k)[1]:.3g}")
        rows.append(row)
    return _align([header, units, *rows])


def _align(rows: Sequence[Sequence[str]]) -> str:
    """Rows of cells as left-aligned columns two spaces apart (empty lines dropped)."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
             for r in rows]
    return "\n".join(line for line in lines if line)


ERROR_KEYS = ("runs", "distance", "pos_rms_h", "pos_rms_v", "pos_err_final_h", "pos_err_final_dt",
              "lat_rms_final", "long_rms_final", "cep50_final", "dt_cep50_final", "vel_rms",
              "att_rms_level", "att_rms_heading")
"""Columns of the error table (those present in a summary)."""


def format_summaries(summaries: Mapping[str, Mapping[str, Any]]) -> str:
    """Two tables of summary dicts: errors, then consistency (NEES and NIS against their 95 %
    chi-square bounds)."""
    if not summaries:
        return "(nothing to score)"
    keys = [k for k in ERROR_KEYS if any(k in s for s in summaries.values())]
    out = [format_table(summaries, keys)]
    rows = [("consistency", "dof", "mean", "in 95% bounds")]
    for label, s in summaries.items():
        if "nees_mean" in s:
            rows.append((f"{label} NEES", str(s["nees_dof"]), f"{s['nees_mean']:.3g}",
                         f"{100 * s['nees_in_bounds']:.0f} %"))
        for key in s:
            if key.startswith("nis_mean_"):
                meas = key.removeprefix("nis_mean_")
                rows.append((f"{label} NIS {meas}", str(s.get(f"nis_dof_{meas}", "")),
                             f"{s[key]:.3g}",
                             f"{100 * s.get(f'nis_in_bounds_{meas}', math.nan):.0f} %"))
    if len(rows) > 1:
        out.append(_align(rows))
    scale = scale_rows(summaries)
    if scale:
        out.append(scale)
    outages = outage_rows(summaries)
    if outages:
        out.append(outages)
    return "\n\n".join(out)


def outage_rows(summaries: Mapping[str, Mapping[str, Any]]) -> str:
    """The table of :func:`outage_cells` as text ("" without outages)."""
    rows = outage_cells(summaries)
    return _align(rows) if rows else ""


def outage_cells(summaries: Mapping[str, Mapping[str, Any]]) -> list[tuple[str, ...]]:
    """Each GNSS outage of each filter (``gnss_outages``,
    :mod:`navreplay.metrics.outages`): the horizontal and vertical position error at its end
    with the predicted sigmas, the RMS over it, and for an ensemble the end error over its sigma
    against the band; a header row first (no rows without outages). The rows of a run derived
    from a filter's, labelled ``LABEL/...`` (its smoothed run ``LABEL/rts``), follow the
    filter's row of each outage, so that the two read side by side."""
    rows: list[tuple[str, ...]] = [("GNSS outage [s]", "end error H [m]", "σ H [m]",
                                    "end error V [m]", "σ V [m]", "RMS H [m]", "RMS V [m]",
                                    "check")]
    order: list[tuple[str, dict[str, Any]]] = []
    for label in summaries:
        if label.rpartition("/")[0] in summaries:
            continue  # with its filter's rows
        group = [label, *(x for x in summaries if x.rpartition("/")[0] == label)]
        outages = [list(summaries[x].get("gnss_outages") or ()) for x in group]
        for i in range(max(map(len, outages))):
            order += [(x, o[i]) for x, o in zip(group, outages, strict=True) if i < len(o)]
    for label, o in order:
        name = f"{label} {o['start']:g}-{o['end']:g}"
        if "t_end" not in o:
            rows.append((name, *("-",) * 6, "no estimate inside"))
            continue
        check = ""
        if "ratio_end_h" in o:
            lo, hi = o["band"]
            check = (f"H/σ {o['ratio_end_h']:.3g} in {lo:.3g}-{hi:.3g}: "
                     + ("ok" if o["passed"] else "INCONSISTENT"))
        rows.append((name, *(f"{o[k]:.3g}" for k in (
            "err_end_h", "sigma_end_h", "err_end_v", "sigma_end_v", "rms_h", "rms_v")),
            check))
    if len(rows) == 1:
        return []
    if not any(r[-1] for r in rows[1:]):  # single runs: no check
        rows = [r[:-1] for r in rows]
    return rows


def scale_rows(summaries: Mapping[str, Mapping[str, Any]]) -> str:
    """The ensemble's per-axis RMS/sigma with 95 % intervals against their bands, and the
    time-averaged NEES with its effective samples (docs/methods/consistency.md §7): the NEES
    states of each filter, and any other axis that fails its check."""
    rows = [("RMS/σ of normalised errors", "ratio", "95% interval", "samples", "band",
             "check")]
    alpha = None
    for label, s in summaries.items():
        alpha = s.get("consistency_false_alarm", alpha)
        for name, c in (s.get("rms_over_sigma") or {}).items():
            if c["nees"] or not c["passed"]:
                rows.append((f"{label} {name}", f"{c['ratio']:.3g}",
                             f"{c['interval_95'][0]:.3g}-{c['interval_95'][1]:.3g}",
                             f"{c['samples']:.0f}", f"{c['band'][0]:.3g}-{c['band'][1]:.3g}",
                             "ok" if c["passed"] else "INCONSISTENT"))
        nees = s.get("nees_time_averaged")
        if nees is not None:
            rows.append((f"{label} NEES, time-averaged ({nees['dof']} dof)",
                         f"{nees['mean']:.3g}", "", f"{nees['samples']:.0f}",
                         f"{nees['band'][0]:.3g}-{nees['band'][1]:.3g}",
                         ("ok" if nees["passed"] else "INCONSISTENT")
                         + f"; {nees['runs_failed']} of {nees['runs']} runs fail their own"))
    if len(rows) == 1:
        return ""
    return _align(rows) + f"\n(bands at false alarm {alpha:g})"
