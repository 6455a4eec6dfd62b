"""Comparing filters: the error magnitudes every filter is drawn with side by side, their
distributions in bounded memory, and the headline metrics of run summaries as one table (a
row per metric, a column per filter or run).

The magnitudes are those the summary scores (:mod:`navreplay.metrics.summary`): horizontal
position error ``hypot(e_N, e_E)``, vertical ``|e_D|``, velocity ``|dv|`` and heading
``|phi_D|``, so a CDF's RMS is the table's.

Examples
--------
>>> import numpy as np
>>> q = Quantiles()
>>> q.add(np.array([1.0, 2.0, 3.0, 4.0]))
>>> round(float(q.quantile(0.5)), 1)
2.0
>>> print(format_comparison({"ins": {"pos_rms_h": 812.0}, "gps-ins": {"pos_rms_h": 0.9}}))
metric                       ins  gps-ins
horizontal position RMS [m]  812  0.9 *
(* the best of each row)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

COMPARED: tuple[tuple[str, str, str], ...] = (
    ("pos_h", "horizontal position error", "m"),
    ("pos_v", "vertical position error", "m"),
    ("vel", "velocity error", "m/s"),
    ("heading", "heading error", "rad"),
)
"""Key, title and SI unit of each error magnitude compared across filters."""


def compared_errors(pos_ned: np.ndarray, v_n: np.ndarray, phi: np.ndarray) -> dict[str, np.ndarray]:
    """The error magnitudes of :data:`COMPARED` from navigation errors (arrays (M, 3), SI:
    :class:`navreplay.metrics.NavErrors` ``pos_ned``, ``v_n``, ``phi``); NaN where a part is
    not output or not scored."""
    return {
        "pos_h": np.hypot(pos_ned[:, 0], pos_ned[:, 1]),
        "pos_v": np.abs(pos_ned[:, 2]),
        "vel": np.linalg.norm(v_n, axis=1),
        "heading": np.abs(phi[:, 2]),
    }


class Quantiles:
    """The distribution of a non-negative quantity in bounded memory: a histogram on
    logarithmically spaced bins (relative resolution ``10**(decades / bins)``, 2.3 % by
    default) from ``lo`` to ``hi``, values below ``lo`` counted as ``lo``, above ``hi`` as
    ``hi``; NaN ignored. Quantiles are read at the bins' geometric centres."""

    def __init__(self, lo: float = 1e-7, hi: float = 1e7, bins: int = 1400) -> None:
        self.edges = np.geomspace(lo, hi, bins + 1)
        self.counts = np.zeros(bins + 2, dtype=np.int64)  # [below lo, bins..., above hi]
        self.sum_sq = 0.0

    @property
    def n(self) -> int:
        return int(self.counts.sum())

    def add(self, values: np.ndarray) -> None:
        v = np.asarray(values, dtype=np.float64).ravel()
        v = np.abs(v[np.isfinite(v)])
        if v.size:
            k = np.searchsorted(self.edges, v, side="right")
            self.counts += np.bincount(k, minlength=self.counts.size)
            self.sum_sq += float(np.dot(v, v))

    def rms(self) -> float:
        return math.sqrt(self.sum_sq / self.n) if self.n else math.nan

    def _centres(self) -> np.ndarray:
        e = self.edges
        return np.concatenate([[e[0]], np.sqrt(e[:-1] * e[1:]), [e[-1]]])

    def quantile(self, p: float | np.ndarray) -> np.ndarray:
        """The value below which a fraction ``p`` of the samples lie (NaN without samples)."""
        p = np.asarray(p, dtype=np.float64)
        if not self.n:
            return np.full(p.shape, np.nan)
        cum = np.cumsum(self.counts)
        k = np.searchsorted(cum, np.clip(p, 0.0, 1.0) * cum[-1], side="left")
        return self._centres()[np.clip(k, 0, cum.size - 1)]

    def cdf(self, points: int = 200) -> tuple[np.ndarray, np.ndarray]:
        """``(value, fraction)``: the empirical CDF at ``points`` evenly spaced fractions."""
        frac = np.linspace(1.0 / points, 1.0, points)
        return self.quantile(frac), frac


HEADLINE: tuple[tuple[str, str, str, float, str], ...] = (
    ("pos_rms_h", "horizontal position RMS", "m", 1.0, "min"),
    ("pos_rms_v", "vertical position RMS", "m", 1.0, "min"),
    ("pos_err_final_h", "final horizontal error", "m", 1.0, "min"),
    ("pos_err_final_dt", "final error / distance", "%", 1.0, "min"),
    ("cep50_final", "final CEP50", "m", 1.0, "min"),
    ("vel_rms", "velocity RMS", "m/s", 1.0, "min"),
    ("att_rms_level", "level attitude RMS", "mrad", 1e3, "min"),
    ("att_rms_heading", "heading RMS", "mrad", 1e3, "min"),
    ("nees_mean", "NEES mean / dof", "", 1.0, "one"),
    ("nees_in_bounds", "NEES in 95 % bounds", "%", 100.0, "max"),
)
"""Summary key, title, display unit, factor from SI and which value is best (``min``,
``max``, or ``one``: closest to 1) of the headline metrics, in display order."""


def headline_rows(
    summaries: Mapping[str, Mapping[str, Any]],
) -> list[tuple[str, list[float], int | None]]:
    """The headline metrics present in any summary: ``(title [unit], values in display units
    (NaN where absent), index of the best or None)``; NEES as its mean over its dof."""
    rows = []
    labels = list(summaries)
    for key, name, unit, factor, best in HEADLINE:
        if not any(key in s for s in summaries.values()):
            continue
        values = []
        for label in labels:
            v = _number(summaries[label].get(key))
            if key == "nees_mean":
                dof = _number(summaries[label].get("nees_dof"))
                v = v / dof if dof > 0 else math.nan
            values.append(v * factor)
        finite = [i for i, v in enumerate(values) if math.isfinite(v)]
        pick = None
        if len(finite) > 1:
            score = {"min": lambda v: v, "max": lambda v: -v, "one": lambda v: abs(math.log(v))
                     if v > 0 else math.inf}[best]
            pick = min(finite, key=lambda i: score(values[i]))
        rows.append((f"{name} [{unit}]" if unit else name, values, pick))
    return rows


def _number(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        return math.nan
    return float(v)


def _cell(v: float) -> str:
    return f"{v:.3g}" if math.isfinite(v) else "-"


def format_comparison(summaries: Mapping[str, Mapping[str, Any]]) -> str:
    """The headline metrics as a text table: a row per metric, a column per label, the best
    of each row marked ``*``."""
    rows = headline_rows(summaries)
    if not rows:
        return "(no headline metrics: nothing was scored against a truth or reference)"
    table = [["metric", *summaries]]
    for name, values, pick in rows:
        table.append([name, *(_cell(v) + (" *" if i == pick else "")
                              for i, v in enumerate(values))])
    widths = [max(len(r[i]) for r in table) for i in range(len(table[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
             for r in table]
    return "\n".join([*lines, "(* the best of each row)"])


def markdown_comparison(summaries: Mapping[str, Mapping[str, Any]]) -> str:
    """The headline metrics as a markdown table (best of each row in bold)."""
    rows = headline_rows(summaries)
    if not rows:
        return "*No headline metrics: nothing was scored against a truth or reference.*"
    out = ["| metric | " + " | ".join(_escape(s) for s in summaries) + " |",
           "|---|" + "---:|" * len(summaries)]
    for name, values, pick in rows:
        cells = [f"**{_cell(v)}**" if i == pick else _cell(v) for i, v in enumerate(values)]
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def _escape(text: str) -> str:
    return text.replace("|", "\\|").replace("[", "\\[").replace("]", "\\]")


def labelled(named: Sequence[tuple[str, Mapping[str, Any]]]) -> dict[str, Mapping[str, Any]]:
    """Summaries of several sources keyed by ``source/label``, or by ``label`` alone when every
    source's label is distinct (``named``: ``(source, {label: summary})`` pairs)."""
    labels = [label for _, filters in named for label in filters]
    plain = len(set(labels)) == len(labels)
    out: dict[str, Mapping[str, Any]] = {}
    for source, filters in named:
        for label, s in filters.items():
            out[label if plain else f"{source}/{label}"] = s
    return out
