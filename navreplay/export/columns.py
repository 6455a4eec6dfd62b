"""CSV tables with units: the columns of a run (navigation, sigmas, states, errors, NEES), of
an ensemble, of the innovations of each measurement and of the NIS averaged over runs; every
column named ``name [unit]``."""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from navreplay.export.frames import LocalFrame
from navreplay.export.numbers import format_rows, row_blocks
from navreplay.export.output import NAV_AXES, NAV_ROWS, FilterOutput
from navreplay.filters.base import NAV_PARTS, MeasurementKind
from navreplay.filters.result import InnovationSeries
from navreplay.geo.rotations import quat_to_euler

UNKNOWN_UNIT = "unknown"
"""Unit of the innovation rows of a measurement the filter does not declare."""


@dataclasses.dataclass(frozen=True)
class Column:
    """One CSV column: its name, unit, meaning and values."""

    name: str
    unit: str
    description: str
    values: np.ndarray
    fmt: str = "%.9g"

    @property
    def header(self) -> str:
        return f"{self.name} [{self.unit}]"

    def to_json(self) -> dict[str, str]:
        return {"name": self.header, "unit": self.unit, "description": self.description}


_RAD_TO_DEG = 180.0 / math.pi


def run_columns(out: FilterOutput, frame: LocalFrame | None) -> list[Column]:
    """The columns of one filter's CSV (see docs/exports.md)."""
    cols = [Column("stamp", "ns", "absolute estimate time", out.stamps_ns, "%d"),
            Column("t", "s", "time since the recording start", out.t)]
    if out.has("pos"):
        pos = out.nav_pos
        assert pos is not None  # has("pos")
        cols += [Column("lat", "deg", "geodetic latitude (WGS84)", pos[:, 0] * _RAD_TO_DEG,
                        "%.10f"),
                 Column("lon", "deg", "longitude", pos[:, 1] * _RAD_TO_DEG, "%.10f"),
                 Column("h", "m", "height above the ellipsoid", pos[:, 2], "%.4f")]
        if frame is not None:
            p = frame.position(pos)
            cols += [Column(a, "m", f"position {a} in the local ENU frame", p[:, i], "%.4f")
                     for i, a in enumerate(("east", "north", "up"))]
    if out.has("v_n"):
        v_n = out.nav_v_n
        assert v_n is not None  # has("v_n")
        cols += [Column(f"v_{a}", "m/s", f"velocity {a} (NED)", v_n[:, i])
                 for i, a in enumerate("NED")]
    if out.has("q_nb"):
        euler = quat_to_euler(out.nav_q_nb) * _RAD_TO_DEG
        cols += [Column(a, "deg", f"{a} (ZYX Euler angles of body FRD to NED)", euler[:, i])
                 for i, a in enumerate(("roll", "pitch", "yaw"))]
    if out.nav_cov is not None:
        sig = np.sqrt(np.clip(np.diagonal(out.nav_cov, axis1=1, axis2=2), 0.0, None))
        units = ("m",) * 3 + ("m/s",) * 3 + ("deg",) * 3
        for i, (name, unit) in enumerate(zip(NAV_ROWS, units, strict=True)):
            if not out.has(NAV_PARTS[i // 3]):  # blocks of three rows per part
                continue
            scale = _RAD_TO_DEG if unit == "deg" else 1.0
            cols.append(Column(f"sigma_{name}", unit, f"predicted 1-sigma of the {name} error",
                               sig[:, i] * scale))
    for j, (name, unit) in enumerate(zip(out.state_names, out.state_units, strict=True)):
        cols.append(Column(f"x.{name}", unit, f"state {name}", out.x[:, j]))
        cols.append(Column(f"sigma.{name}", unit, f"predicted 1-sigma of state {name}",
                           out.sigma[:, j]))
    m = out.metrics
    if m is not None:
        if m.nav is not None:
            for key, part, names, unit, scale, what in (
                ("pos_ned", "pos", NAV_AXES, "m", 1.0, "position error"),
                ("v_n", "v_n", ("v_N", "v_E", "v_D"), "m/s", 1.0, "velocity error"),
                ("phi", "q_nb", ("phi_N", "phi_E", "phi_D"), "deg", _RAD_TO_DEG,
                 "attitude error phi (C_hat = (I - [phi x]) C)"),
                ("euler", "q_nb", ("roll", "pitch", "yaw"), "deg", _RAD_TO_DEG,
                 "Euler angle error"),
            ):
                if not out.has(part):
                    continue
                v = getattr(m.nav, key)
                cols += [Column(f"error_{n}", unit, f"{what} {n}, estimate minus reference",
                                v[:, i] * scale) for i, n in enumerate(names)]
        state_units = dict(zip(out.state_names, out.state_units, strict=True))
        for j, name in enumerate(m.state_names):
            cols.append(Column(f"error.{name}", state_units.get(name, "-"),
                               f"estimation error of state {name} against the reference",
                               m.state_error[:, j]))
        if m.nees_states:
            cols.append(Column("nees", "-", f"NEES over {', '.join(m.nees_states)} "
                               f"({len(m.nees_states)} dof)", m.nees))
    return cols


def csv_header(cols: Sequence[Column]) -> str:
    """The header line of a CSV: ``name [unit],...``."""
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([c.header for c in cols])
    return buf.getvalue()


def csv_rows(cols: Sequence[Column]) -> str:
    """The rows of the columns' values, comma-separated (numbers need no quoting)."""
    return format_rows([(np.asarray(c.values), c.fmt) for c in cols])


def csv_blocks(cols: Sequence[Column]) -> Iterator[bytes | memoryview]:
    """:func:`csv_rows` as ASCII bytes, a block of rows at a time (for a binary file)."""
    return row_blocks([(np.asarray(c.values), c.fmt) for c in cols])


def csv_text(cols: Sequence[Column]) -> str:
    """Comma-separated values with a one-line header ``name [unit],...``."""
    return csv_header(cols) + (csv_rows(cols) if cols else "")


def ensemble_columns(ens: Any) -> list[Column]:
    """The columns of one filter's ensemble CSV (an :class:`~navreplay.metrics.EnsembleResult`)."""
    runs = f"over {ens.runs} runs"
    cols = [Column("t", "s", "time since the recording start", ens.t)]
    for key, names, unit, scale, what in (
        ("pos_ned", NAV_AXES, "m", 1.0, "position error"),
        ("v_n", ("v_N", "v_E", "v_D"), "m/s", 1.0, "velocity error"),
        ("phi", ("phi_N", "phi_E", "phi_D"), "deg", _RAD_TO_DEG, "attitude error phi"),
    ):
        if key not in ens.rms:
            continue
        for i, n in enumerate(names):
            cols.append(Column(f"rms_{n}", unit, f"RMS {runs} of the {what} {n}",
                               ens.rms[key][:, i] * scale))
            cols.append(Column(f"sigma_{n}", unit, f"sqrt(mean predicted variance) of the "
                               f"{what} {n}", ens.sigma[key][:, i] * scale))
    if "pos_ned" in ens.rms:
        cols.append(Column("cep50", "m", "0.5887 (LatRMS + LongRMS)", ens.cep50))
    units = {st.name: st.unit for st in ens.states}
    for j, name in enumerate(ens.state_names):
        unit = units.get(name, "-")
        cols.append(Column(f"rms.{name}", unit, f"RMS {runs} of the error of state {name}",
                           ens.state_rms[:, j]))
        cols.append(Column(f"sigma.{name}", unit, f"sqrt(mean predicted variance) of state "
                           f"{name}", ens.state_sigma[:, j]))
    if ens.nees_dof:
        lo, hi = ens.nees_bounds
        cols += [Column("nees_mean", "-", f"NEES averaged {runs} ({ens.nees_dof} dof)",
                        ens.nees_mean),
                 Column("nees_lo", "-", "lower 95 % chi-square bound of the mean", lo),
                 Column("nees_hi", "-", "upper 95 % chi-square bound of the mean", hi),
                 Column("nees_runs", "-", "runs with a finite NEES", ens.nees_count, "%d")]
    return cols


def nis_columns(t: np.ndarray, mean: np.ndarray, count: np.ndarray, dof: int,
                rows: Mapping[str, np.ndarray] | None = None) -> list[Column]:
    """Columns of a run-averaged NIS series with its 95 % chi-square bounds, and of the NIS of
    each row of the measurement (``rows``, by row name) with theirs (one dof)."""
    from navreplay.metrics import chi2_bounds_per_count

    n = mean.shape[0]
    lo, hi = chi2_bounds_per_count(dof, count[:n])
    cols = [Column("t", "s", "update time since the recording start", t[:n]),
            Column("nis_mean", "-", f"NIS averaged over runs ({dof} dof)", mean),
            Column("nis_lo", "-", "lower 95 % chi-square bound of the mean", lo),
            Column("nis_hi", "-", "upper 95 % chi-square bound of the mean", hi),
            Column("nis_runs", "-", "runs with this update", count[:n], "%d")]
    if rows:
        cols += [Column(f"nis_mean.{row}", "-", f"NIS of row {row} (nu^2 / S of the row) "
                        "averaged over runs (1 dof)", v[:n]) for row, v in rows.items()]
        lo, hi = chi2_bounds_per_count(1, count[:n])
        cols += [Column("nis_row_lo", "-", "lower 95 % chi-square bound of a row's mean", lo),
                 Column("nis_row_hi", "-", "upper 95 % chi-square bound of a row's mean", hi)]
    return cols


def innovation_rows(kind: MeasurementKind | None, dim: int) -> tuple[tuple[str, ...],
                                                                     tuple[str, ...]]:
    """The row names and units of a measurement's innovation: the declared ones, else
    ``0..dim-1`` of :data:`UNKNOWN_UNIT`."""
    if kind is None:
        return tuple(str(i) for i in range(dim)), (UNKNOWN_UNIT,) * dim
    if kind.dim != dim:
        raise ValueError(f"measurement {kind.name}: {dim} innovation rows, {kind.dim} declared")
    units = kind.units  # a tuple once the declaration is made
    return kind.rows, ((units,) * dim if isinstance(units, str) else units)


def innovation_columns(t0_ns: int, series: InnovationSeries, rows: Sequence[str],
                       units: Sequence[str]) -> list[Column]:
    """The columns of one measurement's innovation file: update time, ``nu`` and
    ``sqrt(S_ii)`` of each row, the NIS ``nu^T S^-1 nu`` and its dof (see docs/exports.md)."""
    t = np.asarray(series.t, dtype=float)
    m = len(rows)
    with np.errstate(invalid="ignore"):  # a negative S_ii (a broken filter) shows as nan
        sd = np.sqrt(np.diagonal(series.S, axis1=1, axis2=2))
    cols = [Column("stamp", "ns", "absolute update time",
                   np.int64(t0_ns) + np.rint(t * 1e9).astype(np.int64), "%d"),
            Column("t", "s", "update time since the recording start", t)]
    cols += [Column(f"nu.{r}", u, f"innovation z - h(x) of row {r}", series.nu[:, i])
             for i, (r, u) in enumerate(zip(rows, units, strict=True))]
    cols += [Column(f"sigma.{r}", u, f"predicted 1-sigma of the innovation of row {r}, "
                    "sqrt(S_ii)", sd[:, i]) for i, (r, u) in enumerate(zip(rows, units,
                                                                           strict=True))]
    cols += [Column("nis", "-", f"NIS nu^T S^-1 nu of the update ({m} dof)", series.nis),
             Column("dof", "-", "degrees of freedom of the NIS (the rows of the update)",
                    np.full(t.shape[0], m, dtype=np.int64), "%d")]
    return cols


def no_updates(dim: int) -> InnovationSeries:
    return InnovationSeries(t=np.zeros(0), nu=np.zeros((0, dim)), S=np.zeros((0, dim, dim)),
                            nis=np.zeros(0))
