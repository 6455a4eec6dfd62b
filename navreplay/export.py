"""Results that leave navreplay: CSV tables, TUM trajectories and an MCAP of
``nav_msgs/msg/Odometry`` estimates (docs/exports.md describes every file and column).

``navreplay run ... --export DIR`` writes, per filter label ``L`` (made file-safe):

``L.csv``
    One row per estimate: time, navigation solution, its predicted 1-sigma, the state vector and
    its 1-sigma, and with a reference the errors (estimate minus reference) and the NEES. Column
    names carry their unit, ``name [unit]``.
``L.tum``
    ``timestamp tx ty tz qx qy qz qw`` (evo's TUM format): absolute time [s], position [m] in
    the local ENU frame of :class:`LocalFrame`, orientation of base_link (FLU) in that frame.
``L.innovations.<measurement>.csv``
    One row per update of each measurement: time, the innovation of each row and its predicted
    1-sigma ``sqrt(S_ii)``, the NIS and its dof (the rows the filter declares, with their units;
    rows numbered ``0..m-1`` of unknown unit for a filter that declares none).
``reference.tum``
    The reference (truth) in the same frame, when the recording has one.
``estimates.mcap``
    One ``nav_msgs/msg/Odometry`` topic per filter (``/estimates/<L>/odom``) and the reference
    (``/reference/odom``), ROS 2 profile, CDR: header.frame_id ``map`` (ENU about the origin,
    REP-103/105), child_frame_id ``base_link`` (FLU), pose and twist with covariance.
``manifest.json``
    The origin, the frames, the files and every column with its unit and meaning.

``navreplay montecarlo ... --export DIR`` writes ``L.ensemble.csv`` (RMS, mean predicted sigma,
NEES mean and bounds over time) and ``L.nis.<measurement>.csv`` per filter.

Frames. navreplay works in NED / FRD; ROS in ENU / FLU. With ``T = [[0,1,0],[1,0,0],[0,0,-1]]``
(NED <-> ENU, a proper rotation, its own inverse) and ``F = diag(1,-1,-1)`` (FRD <-> FLU), an
estimate at (lat, lon, h) maps to the ENU frame at the origin through
``R = C_enu0<-ecef C_ecef<-ned(lat, lon)`` (``R = T`` at the origin itself):

    position   p_enu = C_enu0<-ecef (r_ecef - r0_ecef)
    attitude   C_enu0<-flu = R C_nb F
    covariance Sigma_pose  = blkdiag(R, R) Sigma_(pos_ned, phi) blkdiag(R, R)^T
               Sigma_twist = J Sigma_(v_n, phi) J^T,  J = F C_nb^T [I, -[v_n x]]
               (the body velocity v_b = C_nb^T v_n to first order in the attitude error phi,
               ``C_hat = (I - [phi x]) C``).

The twist's angular part is not estimated: zeros, with -1 on its covariance diagonal (the
sensor_msgs convention for "not available"); the same marks any pose or linear-velocity element
whose variance the filter does not hold.

Everything is read from the run through :func:`filter_output`, the one adapter between
:class:`~navreplay.filters.result.RunResult` and the exports and the report.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.filters.base import NAV_PARTS, MeasurementKind, Nav, NavError, State
from navreplay.filters.result import InnovationSeries, RunResult
from navreplay.geo import earth
from navreplay.geo.rotations import dcm_to_quat, quat_to_dcm, quat_to_euler, skew
from navreplay.outputs import Output, atomic_path, check_outputs
from navreplay.streams import Stream

MANIFEST = "manifest.json"
ODOMETRY_FILE = "estimates.mcap"
REFERENCE_LABEL = "reference"
WORLD_FRAME = "map"
BODY_FRAME = "base_link"
UNKNOWN_UNIT = "unknown"
"""Unit of the innovation rows of a measurement the filter does not declare."""
UNKNOWN_VARIANCE = -1.0
"""Covariance diagonal of an element the filter does not estimate (sensor_msgs convention)."""

T_NED_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
"""NED <-> ENU (its own inverse)."""
F_FRD_FLU = np.diag([1.0, -1.0, -1.0])
"""FRD <-> FLU (its own inverse)."""

NAV_AXES = ("north", "east", "down")
NAV_ROWS = (*NAV_AXES, "v_N", "v_E", "v_D", "phi_N", "phi_E", "phi_D")
"""Order of :attr:`FilterOutput.nav_cov`: position error NED [m], velocity error [m/s],
attitude error phi [rad]."""

_NAV_ROWS: dict[Nav, int] = {
    Nav.LAT: 0, Nav.LON: 1, Nav.H: 2, Nav.DEPTH: 2,
    Nav.V_N: 3, Nav.V_E: 4, Nav.V_D: 5,
    Nav.PHI_N: 6, Nav.PHI_E: 7, Nav.PHI_D: 8,
}
"""Row of each navigation quantity in the 9x9 navigation covariance (north, east, down
position; velocity NED; attitude error phi)."""


# --------------------------------------------------------------------------------------------
# the adapter


@dataclasses.dataclass
class FilterOutput:
    """What leaves navreplay of one filter run (built by :func:`filter_output`).

    Attributes
    ----------
    label : str
    t0_ns : int
        Recording start [ns].
    t : ndarray, shape (M,)
        Estimate times [s since t0_ns].
    state_names, state_units : tuple of str
    x, sigma : ndarray, shape (M, n)
        State vector and its 1-sigma.
    nav_pos, nav_v_n, nav_q_nb : ndarray (M, 3), (M, 3), (M, 4) or None
        Navigation solution (lat, lon [rad], h [m]; NED velocity; q_nb scalar first).
    nav_cov : ndarray, shape (M, 9, 9) or None
        Covariance of the navigation errors in the order of :data:`NAV_ROWS`; NaN rows and
        columns where the filter has no state for a quantity.
    metrics : RunMetrics or None
        Errors against the reference (None without one).
    nis : dict[str, tuple[ndarray (K,), ndarray (K,), int]]
        Per measurement: update times [s], NIS, dof.
    nav_states : tuple of str
        The states that are errors of the navigation solution (they make ``nav_cov``).
    navigation : tuple of str
        The parts of the solution the filter outputs (``pos``, ``v_n``, ``q_nb``;
        ``RunResult.navigation``): the CSV carries their columns only.
    innovations : dict[str, InnovationSeries]
        The updates of each measurement (``RunResult.innovations``).
    measurements : tuple of MeasurementKind
        The filter's declarations of its measurements (empty when it declares none).
    """

    label: str
    t0_ns: int
    t: np.ndarray
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    x: np.ndarray
    sigma: np.ndarray
    nav_pos: np.ndarray | None
    nav_v_n: np.ndarray | None
    nav_q_nb: np.ndarray | None
    nav_cov: np.ndarray | None
    metrics: Any
    nis: dict[str, tuple[np.ndarray, np.ndarray, int]]
    nav_states: tuple[str, ...] = ()
    navigation: tuple[str, ...] = ("pos", "v_n", "q_nb")
    innovations: dict[str, InnovationSeries] = dataclasses.field(default_factory=dict)
    measurements: tuple[MeasurementKind, ...] = ()

    def has(self, part: str) -> bool:
        """Whether the output holds part ``part`` (``pos``, ``v_n``, ``q_nb``) of a solution."""
        return part in self.navigation and getattr(self, f"nav_{part}") is not None

    @property
    def has_nav(self) -> bool:
        """A whole navigation solution (a pose: what TUM and odometry need)."""
        return self.has("pos") and self.has("v_n") and self.has("q_nb")

    @property
    def stamps_ns(self) -> np.ndarray:
        """Absolute estimate times [ns]."""
        return np.int64(self.t0_ns) + np.rint(self.t * 1e9).astype(np.int64)


def filter_output(result: RunResult, metrics: Any = None) -> FilterOutput:
    """The one place that reads a run's estimates for exports and reports (a block of them,
    or a whole run: one block).

    Parameters
    ----------
    result : RunResult
    metrics : RunMetrics, optional
        The rows' scores (:func:`navreplay.metrics.run_metrics`); None without a reference.
    """
    return FilterOutput(
        label=result.label,
        t0_ns=int(result.t0_ns),
        t=np.asarray(result.t, dtype=float),
        state_names=tuple(result.state_names),
        state_units=tuple(st.unit for st in result.states),
        x=np.asarray(result.x, dtype=float),
        sigma=result.sigma,
        nav_pos=result.nav_pos,
        nav_v_n=result.nav_v_n,
        nav_q_nb=result.nav_q_nb,
        nav_cov=_nav_covariance(result) if result.nav_pos is not None else None,
        metrics=metrics,
        nis={name: (s.t, s.nis, int(s.nu.shape[1])) for name, s in result.innovations.items()},
        nav_states=nav_state_names(result.states),
        navigation=result.navigation,
        innovations=dict(result.innovations),
        measurements=tuple(result.measurements),
    )


def nav_state_names(states: Sequence[State]) -> tuple[str, ...]:
    """The declared states that are errors of the navigation solution."""
    return tuple(st.name for st in states if isinstance(st.truth, NavError))


def _nav_covariance(result: RunResult) -> np.ndarray:
    """Covariance (M, 9, 9) of the navigation errors from the states declared as navigation
    errors (lat/lon scaled to metres, height negated to down); NaN where none is."""
    M = result.t.shape[0]
    lat, h = result.nav_pos[:, 0], result.nav_pos[:, 2]
    R_M, R_N = earth.radii(lat)
    scale_of = {Nav.LAT: R_M + h, Nav.LON: (R_N + h) * np.cos(lat), Nav.H: -np.ones(M)}
    idx, rows, scales = [], [], []
    for i, st in enumerate(result.states):
        if not isinstance(st.truth, NavError):
            continue
        q = st.truth.q
        if _NAV_ROWS[q] not in rows:
            idx.append(i)
            rows.append(_NAV_ROWS[q])
            scales.append(scale_of.get(q, np.ones(M)))
    out = np.full((M, 9, 9), np.nan)
    if idx:
        ix, r = np.array(idx), np.array(rows)
        s = np.stack(scales, axis=1)
        sub = result.P[:, ix[:, None], ix[None, :]] * s[:, :, None] * s[:, None, :]
        out[:, r[:, None], r[None, :]] = sub
    return out


# --------------------------------------------------------------------------------------------
# output files: refuse to overwrite, write atomically


def check_targets(paths: Iterable[Path], force: bool, option: str = "--export") -> None:
    """Refuse targets that exist (unless ``force``), are directories or cannot be written
    (:func:`navreplay.outputs.check_outputs`), before anything is written."""
    unique = dict.fromkeys(Path(p) for p in paths)
    check_outputs([Output(p, option) for p in unique], force=force)


def write_text(path: Path, text: str) -> None:
    """Write a text file atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def file_stem(label: str) -> str:
    """A file-safe name for a filter label: ``gps-ins[k=2]`` -> ``gps-ins_k_2``."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", label).strip("._") or "filter"
    return stem


def _stems(labels: Sequence[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for label in labels:
        stem, k = file_stem(label), 2
        base = stem
        while stem in out.values() or stem == REFERENCE_LABEL:
            stem, k = f"{base}_{k}", k + 1
        out[label] = stem
    return out


def topic_name(label: str) -> str:
    """A valid ROS 2 topic segment for a filter label (letters, digits, underscores)."""
    seg = re.sub(r"[^A-Za-z0-9_]+", "_", label).strip("_") or "filter"
    return seg if not seg[0].isdigit() else f"f_{seg}"


def run_targets(out_dir: Path, labels: Sequence[str], has_reference: bool) -> list[Path]:
    """Every file ``--export DIR`` of a single run writes (for the overwrite check)."""
    out_dir = Path(out_dir)
    stems = _stems(labels)
    paths = [out_dir / MANIFEST, out_dir / ODOMETRY_FILE]
    for stem in stems.values():
        paths += [out_dir / f"{stem}.csv", out_dir / f"{stem}.tum"]
        # the measurements are known once the filters run: refuse those there are already
        paths += sorted(out_dir.glob(f"{stem}{INNOVATIONS}*.csv"))  # no glob characters
    if has_reference:
        paths.append(out_dir / f"{REFERENCE_LABEL}.tum")
    return paths


INNOVATIONS = ".innovations."
"""Between a filter's file stem and a measurement's in the name of an innovation file."""


def innovation_file(stem: str, measurement_stem: str) -> str:
    """``L.innovations.<measurement>.csv``."""
    return f"{stem}{INNOVATIONS}{measurement_stem}.csv"


def ensemble_targets(out_dir: Path, labels: Sequence[str]) -> list[Path]:
    """The ensemble CSVs ``--export DIR`` of a campaign writes, before their NIS files."""
    return [Path(out_dir) / MANIFEST] + [Path(out_dir) / f"{s}.ensemble.csv"
                                         for s in _stems(labels).values()]


# --------------------------------------------------------------------------------------------
# local frame


@dataclasses.dataclass(frozen=True)
class LocalFrame:
    """The ENU (``map``) frame of the exports: origin on the WGS84 ellipsoid and its axes.

    Attributes
    ----------
    lat, lon, h : float
        Origin [rad, rad, m]: the reference's first sample, else the first filter's first
        navigation estimate.
    source : str
        Where the origin comes from.
    """

    lat: float
    lon: float
    h: float
    source: str

    @property
    def C_enu_e(self) -> np.ndarray:
        """ECEF -> ENU at the origin, (3, 3)."""
        return T_NED_ENU @ earth.C_en(self.lat, self.lon).T

    def position(self, pos: np.ndarray) -> np.ndarray:
        """ENU position [m] (M, 3) of lat, lon, h (M, 3)."""
        dr = earth.lla_to_ecef(pos[:, 0], pos[:, 1], pos[:, 2]) - earth.lla_to_ecef(
            self.lat, self.lon, self.h)
        C = self.C_enu_e  # row by row (the same bits whatever the number of rows)
        return dr[:, 0:1] * C[:, 0] + dr[:, 1:2] * C[:, 1] + dr[:, 2:3] * C[:, 2]

    def rotation(self, pos: np.ndarray) -> np.ndarray:
        """``R = C_enu0<-ned``, (M, 3, 3), the local NED frame at each position to ENU."""
        return np.einsum("ij,mjk->mik", self.C_enu_e, earth.C_en(pos[:, 0], pos[:, 1]))

    def to_json(self) -> dict[str, Any]:
        return {"lat_deg": math.degrees(self.lat), "lon_deg": math.degrees(self.lon),
                "h_m": self.h, "source": self.source}


@dataclasses.dataclass
class Poses:
    """Poses in ROS frames: ENU position [m], q (base_link FLU -> map ENU) xyzw, ENU-frame
    pose covariance (M, 6, 6), body velocity FLU [m/s] and twist covariance (M, 6, 6)."""

    stamps_ns: np.ndarray
    p_enu: np.ndarray
    q_xyzw: np.ndarray
    pose_cov: np.ndarray
    v_flu: np.ndarray
    twist_cov: np.ndarray


def ros_poses(frame: LocalFrame, stamps_ns: np.ndarray, pos: np.ndarray, v_n: np.ndarray,
              q_nb: np.ndarray, nav_cov: np.ndarray | None) -> Poses:
    """Convert a NED/FRD navigation solution and its error covariance to ROS frames
    (see the module docstring for the formulas)."""
    M = len(stamps_ns)
    R = frame.rotation(pos)
    C_nb = quat_to_dcm(q_nb)
    C = R @ C_nb @ F_FRD_FLU
    q = dcm_to_quat(C)
    v_b = np.einsum("mji,mj->mi", C_nb, v_n)
    cov = np.full((M, 9, 9), np.nan) if nav_cov is None else nav_cov
    B = np.zeros((M, 6, 6))
    B[:, :3, :3] = R
    B[:, 3:, 3:] = R
    pose_cov = B @ cov[:, [0, 1, 2, 6, 7, 8]][:, :, [0, 1, 2, 6, 7, 8]] @ B.transpose(0, 2, 1)
    J = np.concatenate([np.broadcast_to(np.eye(3), (M, 3, 3)), -skew(v_n)], axis=2)
    J = F_FRD_FLU @ C_nb.transpose(0, 2, 1) @ J
    lin = J @ cov[:, 3:9, 3:9] @ J.transpose(0, 2, 1)
    twist_cov = np.zeros((M, 6, 6))
    twist_cov[:, :3, :3] = lin
    twist_cov[:, 3:, 3:] = np.full((M, 3, 3), np.nan)  # angular rate: not estimated
    return Poses(np.asarray(stamps_ns, dtype=np.int64), frame.position(pos),
                 np.concatenate([q[:, 1:], q[:, :1]], axis=1), _mark_unknown(pose_cov),
                 v_b * np.diagonal(F_FRD_FLU), _mark_unknown(twist_cov))


def _mark_unknown(cov: np.ndarray) -> np.ndarray:
    """Rows/columns whose variance is not finite: 0, and UNKNOWN_VARIANCE on the diagonal."""
    cov = cov.copy()
    bad = ~np.isfinite(np.diagonal(cov, axis1=1, axis2=2))
    cov[np.broadcast_to(bad[:, :, None], cov.shape) | np.broadcast_to(bad[:, None, :], cov.shape)] = 0.0
    cov[~np.isfinite(cov)] = 0.0
    d = np.arange(cov.shape[1])
    cov[:, d, d] = np.where(bad, UNKNOWN_VARIANCE, cov[:, d, d])
    return cov


def _reference_poses(frame: LocalFrame, truth: Stream) -> Poses:
    zero = np.zeros((len(truth), 9, 9))
    n = len(truth)  # parts a reference lacks (a position-only one) are NaN
    pos, v_n, q_nb = (truth.columns.get(c, np.full((n, w), np.nan))
                      for c, w in (("pos", 3), ("v_n", 3), ("q_nb", 4)))
    return ros_poses(frame, truth.t_ns, pos, v_n, q_nb, zero)


# --------------------------------------------------------------------------------------------
# TUM


TUM_HEADER = ("# timestamp tx ty tz qx qy qz qw\n"
              f"# position [m] in the local ENU frame '{WORLD_FRAME}' (see manifest.json);"
              f" orientation of '{BODY_FRAME}' (FLU) in it\n")
"""The comment lines that open a TUM file."""


def tum_lines(poses: Poses) -> str:
    """evo's TUM format: one ``timestamp tx ty tz qx qy qz qw`` line per pose, single spaces,
    no trailing delimiter. Timestamps are absolute seconds with nanosecond digits."""
    s, ns = np.divmod(poses.stamps_ns, 1_000_000_000)
    return "".join(f"{si}.{ni:09d} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} "
                   f"{q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}\n"
                   for si, ni, p, q in zip(s.tolist(), ns.tolist(), poses.p_enu.tolist(),
                                           poses.q_xyzw.tolist(), strict=True))


# --------------------------------------------------------------------------------------------
# CSV


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
        cols += [Column("lat", "deg", "geodetic latitude (WGS84)", out.nav_pos[:, 0] * _RAD_TO_DEG,
                        "%.10f"),
                 Column("lon", "deg", "longitude", out.nav_pos[:, 1] * _RAD_TO_DEG, "%.10f"),
                 Column("h", "m", "height above the ellipsoid", out.nav_pos[:, 2], "%.4f")]
        if frame is not None:
            p = frame.position(out.nav_pos)
            cols += [Column(a, "m", f"position {a} in the local ENU frame", p[:, i], "%.4f")
                     for i, a in enumerate(("east", "north", "up"))]
    if out.has("v_n"):
        cols += [Column(f"v_{a}", "m/s", f"velocity {a} (NED)", out.nav_v_n[:, i])
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
        units = dict(zip(out.state_names, out.state_units, strict=True))
        for j, name in enumerate(m.state_names):
            cols.append(Column(f"error.{name}", units.get(name, "-"),
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
    """The rows of the columns' values, comma-separated."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    rows = [[c.fmt % v for v in np.asarray(c.values).tolist()] for c in cols]
    w.writerows(zip(*rows, strict=True))
    return buf.getvalue()


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
    return kind.rows, kind.units


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


def _no_updates(dim: int) -> InnovationSeries:
    return InnovationSeries(t=np.zeros(0), nu=np.zeros((0, dim)), S=np.zeros((0, dim, dim)),
                            nis=np.zeros(0))


# --------------------------------------------------------------------------------------------
# Odometry MCAP

ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
_SEP = "=" * 80
_ODOMETRY_SCHEMA = "\n".join([
    "std_msgs/Header header",
    "string child_frame_id",
    "geometry_msgs/PoseWithCovariance pose",
    "geometry_msgs/TwistWithCovariance twist",
    _SEP, "MSG: std_msgs/Header",
    "builtin_interfaces/Time stamp",
    "string frame_id",
    _SEP, "MSG: builtin_interfaces/Time",
    "int32 sec",
    "uint32 nanosec",
    _SEP, "MSG: geometry_msgs/PoseWithCovariance",
    "geometry_msgs/Pose pose",
    "float64[36] covariance",
    _SEP, "MSG: geometry_msgs/Pose",
    "geometry_msgs/Point position",
    "geometry_msgs/Quaternion orientation",
    _SEP, "MSG: geometry_msgs/Point",
    "float64 x", "float64 y", "float64 z",
    _SEP, "MSG: geometry_msgs/Quaternion",
    "float64 x", "float64 y", "float64 z", "float64 w",
    _SEP, "MSG: geometry_msgs/TwistWithCovariance",
    "geometry_msgs/Twist twist",
    "float64[36] covariance",
    _SEP, "MSG: geometry_msgs/Twist",
    "geometry_msgs/Vector3 linear",
    "geometry_msgs/Vector3 angular",
    _SEP, "MSG: geometry_msgs/Vector3",
    "float64 x", "float64 y", "float64 z",
]) + "\n"
"""ros2msg schema text of nav_msgs/msg/Odometry with its dependencies."""


def _aligned(pos: int, size: int) -> int:
    """Next offset aligned to ``size``, counted after the 4-byte encapsulation header."""
    return 4 + -(-(pos - 4) // size) * size


def odometry_dtype(frame_len: int, child_len: int) -> np.dtype:
    """Fixed CDR layout of nav_msgs/msg/Odometry for frame ids of the given byte lengths (NUL
    included): one numpy record per message (see :mod:`navreplay.io.cdr`)."""
    names = ["encap", "sec", "nanosec", "frame_len", "frame_id"]
    formats: list[Any] = [("u1", (4,)), "<i4", "<u4", "<u4", f"S{frame_len}"]
    offsets = [0, 4, 8, 12, 16]
    pos = _aligned(16 + frame_len, 4)
    names += ["child_len", "child_frame_id"]
    formats += ["<u4", f"S{child_len}"]
    offsets += [pos, pos + 4]
    pos = _aligned(pos + 4 + child_len, 8)
    for name, count in (("position", 3), ("orientation", 4), ("pose_covariance", 36),
                        ("linear", 3), ("angular", 3), ("twist_covariance", 36)):
        names.append(name)
        formats.append(("<f8", (count,)))
        offsets.append(pos)
        pos += 8 * count
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": pos})


def encode_odometry(poses: Poses, frame_id: str = WORLD_FRAME,
                    child_frame_id: str = BODY_FRAME) -> np.ndarray:
    """CDR records (M,) of nav_msgs/msg/Odometry; ``rec[i].tobytes()`` is message i."""
    from navreplay.io.cdr import ENCAPSULATION_LE, split_time

    f, c = frame_id.encode(), child_frame_id.encode()
    rec = np.zeros(len(poses.stamps_ns), dtype=odometry_dtype(len(f) + 1, len(c) + 1))
    rec["encap"] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)
    rec["sec"], rec["nanosec"] = split_time(poses.stamps_ns)
    rec["frame_len"], rec["frame_id"] = len(f) + 1, f
    rec["child_len"], rec["child_frame_id"] = len(c) + 1, c
    rec["position"] = poses.p_enu
    rec["orientation"] = poses.q_xyzw
    rec["pose_covariance"] = poses.pose_cov.reshape(-1, 36)
    rec["linear"] = poses.v_flu
    rec["twist_covariance"] = poses.twist_cov.reshape(-1, 36)
    return rec


class _OdometryWriter:
    """The Odometry MCAP, written as the poses come: messages of all topics in time order (ties
    in the order the topics were registered), each topic's poses handed over in time order.

    A message is written once every topic has poses later than it; the rest wait (a window's
    worth), :meth:`finish` writes them all.
    """

    def __init__(self, path: Path, topics: Sequence[str]) -> None:
        from mcap.writer import CompressionType, Writer

        from navreplay.io.schemas import MESSAGE_ENCODING, PROFILE, SCHEMA_ENCODING
        from navreplay.io.writer import LIBRARY

        self._file = open(path, "wb")  # noqa: SIM115 (closed by finish or close)
        self._w = Writer(self._file, compression=CompressionType.ZSTD, enable_crcs=True)
        self._w.start(profile=PROFILE, library=LIBRARY)
        sid = self._w.register_schema(ODOMETRY_TYPE, SCHEMA_ENCODING, _ODOMETRY_SCHEMA.encode())
        self._ids = {topic: self._w.register_channel(topic, MESSAGE_ENCODING, sid)
                     for topic in topics}
        # per topic: (stamps, CDR messages as rows of bytes) not yet written
        self._queue: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {t: [] for t in topics}
        self._last: dict[str, int | None] = dict.fromkeys(topics)

    def add(self, topic: str, poses: Poses) -> None:
        if not len(poses.stamps_ns):
            return
        rec = encode_odometry(poses)  # as rows of bytes (concatenating records repacks them)
        self._queue[topic].append((poses.stamps_ns,
                                   rec.view(np.uint8).reshape(len(rec), rec.dtype.itemsize)))
        self._last[topic] = int(poses.stamps_ns[-1])
        if all(v is not None for v in self._last.values()):
            self._write(min(self._last.values()))

    def _write(self, limit: int | None) -> None:
        """Write the queued messages earlier than ``limit`` (all with None)."""
        times, rows = [], []  # per message: time; (queued piece, row in it)
        pieces: list[np.ndarray] = []
        for topic, queue in self._queue.items():
            cid = self._ids[topic]
            kept = []
            for t, rec in queue:
                n = t.shape[0] if limit is None else int(np.searchsorted(t, limit, side="left"))
                if n:
                    times.append(t[:n])
                    rows.append(np.stack([np.full(n, len(pieces)), np.arange(n),
                                          np.full(n, cid)], axis=1))
                    pieces.append(rec)
                if n < t.shape[0]:
                    kept.append((t[n:], rec[n:]))
            self._queue[topic] = kept
        if not times:
            return
        t = np.concatenate(times)
        where = np.concatenate(rows)
        add = self._w.add_message
        for i in np.argsort(t, kind="stable").tolist():
            ti = int(t[i])
            k, j, cid = where[i].tolist()
            add(cid, ti, pieces[k][j].tobytes(), ti)

    def finish(self) -> None:
        self._write(None)
        self._w.finish()
        self._file.close()

    def close(self) -> None:
        self._file.close()


class RunExport:
    """``--export DIR`` of one run, written as the estimates come (see the module docstring
    for the files).

    Feed it the truth window by window (:meth:`add_reference`), each filter's estimates
    block by block (:meth:`add`, blocks of one label in time order) and its updates
    (:meth:`add_innovations`, or with the estimates), then :meth:`close`; or :meth:`abort`. Every file goes to a temporary beside its target, renamed when complete, so
    an interrupted run leaves the directory as it was. The files are those of one call with the
    whole run: what is written depends on the rows, not on how they were split into blocks.

    The first rows are held until the export frame's origin (the reference's first sample, else
    the first filter's first navigation estimate) and which filters have a navigation solution
    are known (usually the first window).

    Parameters
    ----------
    out_dir : Path
    labels : sequence of str
        The filters' labels, in the command's order.
    has_reference : bool
        A truth / reference stream follows.
    source : str
        The recording, for the manifest.
    force : bool
        Overwrite existing files (checked here, before anything is written).
    """

    def __init__(self, out_dir: Path, labels: Sequence[str], *, has_reference: bool,
                 source: str = "", force: bool = False) -> None:
        self.out_dir = Path(out_dir)
        self.labels = tuple(labels)
        self.has_reference = has_reference
        self.source = source
        self.force = force
        check_targets(run_targets(self.out_dir, self.labels, has_reference), force)
        self._stems = _stems(self.labels)
        self._frame: LocalFrame | None = None
        self._started = False
        self._held: list[tuple[str, Any]] = []  # ("ref", Stream) / ("out", FilterOutput)
        self._nav: dict[str, bool] = {}  # label -> has a navigation solution (from its rows)
        self._empty: dict[str, FilterOutput] = {}  # a block without rows per label
        self._tmp: dict[Path, tuple[Path, Any]] = {}  # target -> (temporary, open file)
        self._entries: dict[str, dict[str, Any]] = {}
        self._odometry: _OdometryWriter | None = None
        self._topics: dict[str, str] = {}  # label (or the reference) -> odometry topic
        # label -> measurement -> its file's manifest entry; the rows and units of its columns
        self._innovations: dict[str, dict[str, dict[str, Any]]] = {}
        self._rows: dict[tuple[str, str], tuple[tuple[str, ...], tuple[str, ...]]] = {}
        self._declared: dict[str, dict[str, MeasurementKind]] = {}
        self._done = False

    # -- feeding -------------------------------------------------------------------------

    def add_reference(self, truth: Stream) -> None:
        """A window of the truth stream (``pos``, ``v_n``, ``q_nb``), later than before."""
        if not len(truth):
            return
        if self._frame is None:
            p = truth["pos"][0]
            self._frame = LocalFrame(float(p[0]), float(p[1]), float(p[2]),
                                     "first reference sample")
        self._feed("ref", truth)

    def add(self, out: FilterOutput) -> None:
        """A block of one filter's estimates (:func:`filter_output` of its rows) and the
        innovations it carries."""
        self.add_innovations(out.label, out.t0_ns, out.innovations, out.measurements)
        if not len(out.t):
            self._empty.setdefault(out.label, out)
            return
        self._nav.setdefault(out.label, out.has_nav)
        if (self._frame is None and not self.has_reference and out.has_nav
                and self._first_nav() == out.label):
            p = out.nav_pos[0]
            self._frame = LocalFrame(float(p[0]), float(p[1]), float(p[2]),
                                     f"first navigation estimate of {out.label}")
        self._feed("out", out)

    def add_innovations(self, label: str, t0_ns: int,
                        innovations: Mapping[str, InnovationSeries],
                        measurements: Sequence[MeasurementKind] = ()) -> None:
        """A block of one filter's updates (later than its updates before), per measurement;
        ``measurements``: the filter's declarations (each gets a file, updates or not)."""
        if label not in self._stems:
            raise ValueError(f"{label!r} is not one of the exported filters")
        if label not in self._declared:
            self._declared[label] = {m.name: m for m in measurements}
            self._innovations[label] = {}
            for m in measurements:
                self._innovation_file(label, m.name, m.dim)
        for name, series in innovations.items():
            f = self._innovation_file(label, name, int(series.nu.shape[1]))
            if len(series.t):
                f.write(csv_rows(innovation_columns(t0_ns, series, *self._rows[label, name])))

    def _innovation_file(self, label: str, name: str, dim: int) -> Any:
        """The open file of a measurement's innovations (opened with its header at first)."""
        entry = self._innovations[label].get(name)
        if entry is not None:
            return self._file(entry["csv"])
        rows, units = self._rows[label, name] = innovation_rows(
            self._declared[label].get(name), dim)
        taken = {e["csv"] for e in self._innovations[label].values()}
        stem = base = file_stem(name)
        k = 2
        while innovation_file(self._stems[label], stem) in taken:
            stem, k = f"{base}_{k}", k + 1
        csv_name = innovation_file(self._stems[label], stem)
        check_targets([self.out_dir / csv_name], self.force)  # a name known only now
        cols = innovation_columns(0, _no_updates(dim), rows, units)
        self._innovations[label][name] = {"csv": csv_name, "dof": dim,
                                          "columns": [c.to_json() for c in cols]}
        f = self._open(csv_name)
        f.write(csv_header(cols))
        return f

    def _first_nav(self) -> str | None:
        """The first label (in order) whose rows may carry a navigation solution."""
        for label in self.labels:
            if self._nav.get(label, True):
                return label
        return None

    def _held_frame(self) -> LocalFrame | None:
        """At the end, before anything is written: the frame of the first filter (in order)
        with a navigation solution, when the filters before it never had an estimate."""
        firsts = {out.label: out for kind, out in reversed(self._held) if kind == "out"}
        for label in self.labels:
            out = firsts.get(label)
            if out is not None and out.has_nav:
                p = out.nav_pos[0]
                return LocalFrame(float(p[0]), float(p[1]), float(p[2]),
                                  f"first navigation estimate of {label}")
        return None

    def _feed(self, kind: str, item: Any) -> None:
        if not self._started:
            self._held.append((kind, item))
            # the frame comes from the reference when there is one (else from the first
            # filter with a position): wait for it, whatever the filters output
            if len(self._nav) == len(self.labels) and (
                    self._frame is not None
                    or (self._first_nav() is None and not self.has_reference)):
                self._start()
            return
        self._write(kind, item)

    # -- writing -------------------------------------------------------------------------

    def _open(self, name: str) -> Any:
        from navreplay.outputs import temporary_path

        target = self.out_dir / name
        tmp = temporary_path(target)
        f = open(tmp, "w", encoding="utf-8", newline="")  # noqa: SIM115 (closed on close/abort)
        self._tmp[target] = (tmp, f)
        return f

    def _start(self) -> None:
        """The frame and the filters' solutions are known: open the files, write the rows held."""
        from navreplay.outputs import temporary_path

        self._started = True
        topics = []
        for label in self.labels:
            entry: dict[str, Any] = {"csv": f"{self._stems[label]}.csv"}
            if self._nav.get(label) and self._frame is not None:
                entry["tum"] = f"{self._stems[label]}.tum"
                entry["odometry_topic"] = f"/estimates/{topic_name(label)}/odom"
                self._open(entry["tum"]).write(TUM_HEADER)
                topics.append(entry["odometry_topic"])
                self._topics[label] = entry["odometry_topic"]
            self._entries[label] = entry
        if self.has_reference and self._frame is not None:
            self._open(f"{REFERENCE_LABEL}.tum").write(TUM_HEADER)
            topics.append("/reference/odom")
            self._topics[REFERENCE_LABEL] = "/reference/odom"
        if topics:
            target = self.out_dir / ODOMETRY_FILE
            tmp = temporary_path(target)
            self._odometry = _OdometryWriter(tmp, topics)
            self._tmp[target] = (tmp, self._odometry)
        held, self._held = self._held, []
        # estimates first: the reference then goes out piece by piece instead of queueing
        # behind them (the files do not depend on the order of the topics' pieces)
        for kind, item in sorted(held, key=lambda h: h[0] == "ref"):
            self._write(kind, item)

    def _write(self, kind: str, item: Any) -> None:
        frame = self._frame
        if kind == "ref":
            if frame is None:
                return
            for a in range(0, len(item), _REFERENCE_ROWS):  # bounded temporaries
                truth = item.slice(a, min(a + _REFERENCE_ROWS, len(item)))
                poses = _reference_poses(frame, truth)
                self._file(f"{REFERENCE_LABEL}.tum").write(tum_lines(poses))
                self._odometry.add(self._topics[REFERENCE_LABEL], poses)
            return
        out: FilterOutput = item
        entry = self._entries[out.label]
        cols = run_columns(out, frame)
        if "columns" not in entry:
            entry["columns"] = [c.to_json() for c in cols]
            self._open(entry["csv"]).write(csv_header(cols))
        self._file(entry["csv"]).write(csv_rows(cols))
        if "tum" in entry and out.has_nav:
            poses = ros_poses(frame, out.stamps_ns, out.nav_pos, out.nav_v_n, out.nav_q_nb,
                              out.nav_cov)
            self._file(entry["tum"]).write(tum_lines(poses))
            self._odometry.add(entry["odometry_topic"], poses)

    def _file(self, name: str) -> Any:
        return self._tmp[self.out_dir / name][1]

    # -- finishing -----------------------------------------------------------------------

    def close(self) -> list[Path]:
        """Write what is held, finish every file and rename it onto its target; returns the
        files written (the manifest last)."""
        from navreplay.outputs import fsync_path, release

        if self._done:
            raise ValueError("the export is already closed")
        try:
            if not self._started:
                if self._frame is None and not self.has_reference:
                    self._frame = self._held_frame()
                self._start()
            for label in self.labels:  # filters without a single estimate: a header
                entry = self._entries[label]
                if "columns" not in entry:
                    empty = self._empty.get(label)
                    cols = run_columns(empty, self._frame) if empty is not None else [
                        Column("stamp", "ns", "absolute estimate time", np.zeros(0, np.int64),
                               "%d"),
                        Column("t", "s", "time since the recording start", np.zeros(0))]
                    entry["columns"] = [c.to_json() for c in cols]
                    self._open(entry["csv"]).write(csv_header(cols))
            if self._odometry is not None:
                self._odometry.finish()
            for _, f in self._tmp.values():
                f.close()
        except BaseException:
            self.abort()
            raise
        self._done = True
        written = []
        order = [self.out_dir / e[k] for e in self._entries.values() for k in ("csv", "tum")
                 if k in e]
        order += [self.out_dir / e["csv"] for files in self._innovations.values()
                  for e in files.values()]
        order += [p for p in self._tmp if p not in order]
        for target in order:
            tmp, _ = self._tmp[target]
            fsync_path(tmp)
            os.replace(tmp, target)
            release(tmp, remove=False)
            written.append(target)
        manifest = self._manifest()
        write_text(self.out_dir / MANIFEST, json.dumps(manifest, indent=2) + "\n")
        written.append(self.out_dir / MANIFEST)
        return written

    def _manifest(self) -> dict[str, Any]:
        manifest: dict[str, Any] = {
            "recording": self.source,
            "frames": {
                "map": "local ENU (east, north, up) about the origin, metres (REP-103/105); "
                       "TUM positions and Odometry poses",
                "base_link": "vehicle body FLU (forward, left, up); Odometry twist",
                "nav": "navreplay's NED / FRD: CSV velocities, attitudes and errors",
            },
            "origin": self._frame.to_json() if self._frame is not None else None,
            "filters": {label: {k: e[k] for k in ("csv", "columns", "tum", "odometry_topic")
                                if k in e}
                        for label, e in self._entries.items()},
        }
        for label, files in self._innovations.items():
            if files:  # the declared measurements in order, then the others by name
                declared = list(self._declared[label])
                names = declared + sorted(set(files) - set(declared))
                manifest["filters"][label]["innovations"] = {n: files[n] for n in names}
        if REFERENCE_LABEL in self._topics:
            manifest["reference"] = {"tum": f"{REFERENCE_LABEL}.tum",
                                     "odometry_topic": "/reference/odom"}
        if self._topics:
            manifest["odometry"] = {"file": ODOMETRY_FILE, "type": ODOMETRY_TYPE,
                                    "frame_id": WORLD_FRAME, "child_frame_id": BODY_FRAME,
                                    "topics": sorted(self._topics.values())}
        return manifest

    def abort(self) -> None:
        """Stop without publishing: the temporaries are deleted, the targets untouched."""
        from navreplay.outputs import release

        self._done = True
        for tmp, f in self._tmp.values():
            with contextlib.suppress(OSError):
                f.close()
            release(tmp)
        self._tmp.clear()


_REFERENCE_ROWS = 5_000
"""Reference rows converted and queued at once (a window's 9x9 covariances and messages are
not all held)."""


# --------------------------------------------------------------------------------------------
# the exports of a run and of an ensemble


def export_ensemble(out_dir: Path, ensembles: Mapping[str, Any], *, title: str = "",
                    force: bool = False) -> list[Path]:
    """Write each filter's ensemble statistics (``L.ensemble.csv``, ``L.nis.<meas>.csv``) and
    the manifest; refuses to overwrite unless ``force``."""
    out_dir = Path(out_dir)
    stems = _stems(list(ensembles))
    targets = ensemble_targets(out_dir, list(ensembles))
    nis_paths = {(label, meas): out_dir / f"{stems[label]}.nis.{file_stem(meas)}.csv"
                 for label, ens in ensembles.items() for meas in ens.nis_mean}
    check_targets(targets + list(nis_paths.values()), force)
    written: list[Path] = []
    manifest: dict[str, Any] = {"campaign": title, "filters": {}}
    for label, ens in ensembles.items():
        cols = ensemble_columns(ens)
        path = out_dir / f"{stems[label]}.ensemble.csv"
        write_text(path, csv_text(cols))
        written.append(path)
        entry: dict[str, Any] = {"runs": ens.runs, "csv": path.name,
                                 "columns": [c.to_json() for c in cols], "nis": {}}
        for meas, (t, mean, count, dof) in ens.nis_mean.items():
            ncols = nis_columns(t, mean, count, dof, ens.nis_rows_mean.get(meas))
            p = nis_paths[(label, meas)]
            write_text(p, csv_text(ncols))
            written.append(p)
            entry["nis"][meas] = {"csv": p.name, "columns": [c.to_json() for c in ncols]}
        manifest["filters"][label] = entry
    write_text(out_dir / MANIFEST, json.dumps(manifest, indent=2) + "\n")
    written.append(out_dir / MANIFEST)
    return written
