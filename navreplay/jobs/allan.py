"""``navreplay allan``: the Allan deviation of a still IMU segment, the noise terms fitted to it,
and a ``[sensors.imu]`` specification that ``simulate --config`` and ``run --config`` read.

The analysis is :mod:`navreplay.sensors.allan`; this module reads the segment, refuses one
that is not still, uniformly sampled or long enough, and writes the specification, the
figure and the Rerun view (each through a temporary file).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.core import units
from navreplay.core.streams import StreamKind
from navreplay.io import RecordingError
from navreplay.io.files import read_streams
from navreplay.io.outputs import atomic_path
from navreplay.io.source import ReadOptions
from navreplay.io.span import TimeSpan, TimeSpanError
from navreplay.sensors import allan
from navreplay.sensors.imu import ImuModel
from navreplay.sensors.specs import SensorSpecs, specs_toml

MAX_GAP = 1.0
"""Longest gap in the IMU samples of a segment [s]: the Allan variance needs them contiguous."""
MAX_MISSING = 1e-3
"""Largest fraction of missing samples in a segment."""


@dataclasses.dataclass(frozen=True)
class Triad:
    """How one triad of the IMU is read, shown and written into the specification."""

    name: str
    column: str
    """Column of the IMU stream [SI]."""
    unit: str
    """SI unit of the samples."""
    shown: str
    """Unit of the ADEV in tables and figures."""
    fields: dict[str, str]
    """Fit parameter (``white``, ``gm_sigma``, ``gm_tau``, ``walk``) -> ImuModel field."""
    labels: dict[str, str]


TRIADS = (
    Triad("gyro", "omega_ib_b", "rad/s", "deg/h",
          {"white": "gyro_arw", "gm_sigma": "gyro_bias_instability", "gm_tau": "gyro_bias_tau",
           "walk": "gyro_rrw"},
          {"white": "angle random walk", "gm_sigma": "bias instability (Gauss-Markov sigma)",
           "gm_tau": "correlation time", "walk": "rate random walk"}),
    Triad("accel", "f_b", "m/s^2", "ug",
          {"white": "accel_vrw", "gm_sigma": "accel_bias_instability",
           "gm_tau": "accel_bias_tau", "walk": "accel_rw"},
          {"white": "velocity random walk", "gm_sigma": "bias instability (Gauss-Markov sigma)",
           "gm_tau": "correlation time", "walk": "acceleration random walk"}),
)


@dataclasses.dataclass(frozen=True)
class AllanJob:
    """``navreplay allan``.

    Attributes
    ----------
    recording : Path
        MCAP file or rosbag2 folder.
    topic : str or None
        The IMU topic (default: the one the reader picks for the IMU stream).
    start, end : float or str or None
        Segment: seconds from the recording start, UNIX seconds or a UTC date and time
        (:func:`navreplay.io.span.parse_time`); default: all of it.
    spec_path, plot_path, view_path : Path or None
        The ``[sensors.imu]`` TOML, the figure (PNG or SVG by suffix), the .rrd view.
    bootstrap : int
        Synthetic records for the parameter intervals (0: none).
    time : str
        ``header`` or ``log`` sample times (``--time``).
    """

    recording: Path
    topic: str | None = None
    start: float | str | None = None
    end: float | str | None = None
    spec_path: Path | None = None
    plot_path: Path | None = None
    view_path: Path | None = None
    bootstrap: int = 40
    time: str = "header"


@dataclasses.dataclass(frozen=True)
class Segment:
    """The still IMU samples analysed.

    Attributes
    ----------
    where : str
        ``FILE: topic T, t = a to b s``, the prefix of every message about it.
    t0, t1 : float
        [s from the recording start].
    rate : float
        [Hz].
    columns : dict[str, ndarray]
        ``omega_ib_b`` and ``f_b``, shape (N, 3), SI.
    missing : int
        Samples missing in short gaps.
    """

    where: str
    t0: float
    t1: float
    rate: float
    columns: dict[str, np.ndarray]
    missing: int = 0


@dataclasses.dataclass(frozen=True)
class AllanReport:
    """What ``navreplay allan`` found and wrote."""

    segment: Segment
    triads: dict[str, allan.TriadAnalysis]
    specs: SensorSpecs
    written: tuple[tuple[str, Path], ...] = ()

    def format(self) -> str:
        s = self.segment
        n = next(iter(self.triads.values())).samples
        lines = [f"{s.where} ({s.t1 - s.t0:.6g} s, {s.rate:.6g} Hz, {n} samples): still"]
        if s.missing:
            lines.append(f"  {s.missing} samples missing in short gaps (ignored)")
        for triad in TRIADS:
            a = self.triads.get(triad.name)
            if a is not None:
                lines += [""] + triad_table(triad, a)
        for what, path in self.written:
            lines.append(f"wrote {what}: {path}")
        return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# the job


def run_allan(job: AllanJob) -> AllanReport:
    """Read the segment, check it, fit each triad, write the requested outputs.

    Raises
    ------
    RecordingError
        The file cannot be read, the segment is empty, not still, not uniformly sampled or too
        short: one line naming the file, topic and time span.
    """
    segment = read_segment(job)
    triads: dict[str, allan.TriadAnalysis] = {}
    rng = np.random.default_rng(0)
    for triad in TRIADS:
        try:
            triads[triad.name] = allan.analyse_triad(
                segment.columns[triad.column], segment.rate, bootstrap=job.bootstrap, rng=rng)
        except allan.AllanError as e:
            raise RecordingError(f"{segment.where}: {e}") from None
    specs = spec_of(triads, segment)
    report = AllanReport(segment, triads, specs)
    panels = figure_panels(triads) if job.plot_path or job.view_path else []
    written: list[tuple[str, Path]] = []
    if job.spec_path is not None:
        with atomic_path(job.spec_path) as tmp:
            tmp.write_text(spec_text(specs, triads, segment), encoding="utf-8")
        written.append(("sensor specification", job.spec_path))
    if job.plot_path is not None:
        from navreplay.viz import figures

        fig = figures.allan_deviation(panels, title=segment.where)
        with atomic_path(job.plot_path) as tmp:
            figures.save(fig, str(tmp), plot_format(job.plot_path))
        written.append(("figure", job.plot_path))
    if job.view_path is not None:
        from navreplay.viz.allan import save_allan_view

        save_allan_view(job.view_path, panels, f"```\n{report.format()}\n```",
                        name=segment.where)
        written.append(("Rerun view", job.view_path))
    return dataclasses.replace(report, written=tuple(written))


PLOT_FORMATS = ("png", "svg")


def plot_format(path: Path) -> str:
    """``png`` or ``svg``, from the suffix of ``--plot``."""
    fmt = path.suffix.lstrip(".").lower()
    if fmt not in PLOT_FORMATS:
        raise ValueError(f"--plot {path}: the figure is written as .png or .svg, not "
                         f"{path.suffix or 'without a suffix'}")
    return fmt


def read_segment(job: AllanJob) -> Segment:
    """The IMU samples of ``job``'s segment, checked (still, contiguous)."""
    path = Path(job.recording)
    recording, sources = read_streams(path, ReadOptions(
        kinds=[StreamKind.IMU], time=job.time,
        topics={StreamKind.IMU: job.topic} if job.topic else None))
    imu = recording[StreamKind.IMU]
    topic = sources[StreamKind.IMU].topic
    t = (imu.t_ns - recording.t0_ns) * 1e-9
    try:
        span = TimeSpan.parse(None if job.start is None else str(job.start),
                              None if job.end is None else str(job.end))
        lo, hi = span.bounds(recording.t0_ns) if span is not None else (None, None)
    except TimeSpanError as e:
        raise RecordingError(f"{path}: topic {topic}: {e}") from None
    start = t[0] if lo is None else (lo - recording.t0_ns) * 1e-9
    end = t[-1] if hi is None else (hi - recording.t0_ns) * 1e-9
    covered = f"t = {t[0]:.6g} to {t[-1]:.6g} s"
    sel = (t >= start) & (t <= end)
    if sel.sum() < 2:
        raise RecordingError(f"{path}: topic {topic}: no IMU samples in t = {start:g} to "
                             f"{end:g} s (the topic covers {covered})")
    ts = t[sel]
    where = f"{path}: topic {topic}, t = {ts[0]:.6g} to {ts[-1]:.6g} s"
    dt = np.diff(ts)
    step = float(np.median(dt))
    if not step > 0.0:
        raise RecordingError(f"{where}: the IMU samples do not advance in time")
    gaps = np.flatnonzero(dt > 1.5 * step)
    missing = int(np.sum(np.round(dt[gaps] / step) - 1)) if gaps.size else 0
    if gaps.size:
        k = gaps[np.argmax(dt[gaps])]
        if dt[k] > MAX_GAP or missing > MAX_MISSING * ts.size:
            raise RecordingError(
                f"{where}: the IMU samples have gaps ({missing} samples missing, the longest "
                f"{dt[k]:.3g} s at t = {ts[k]:.6g} s): the Allan variance needs contiguous "
                "samples; choose a segment without them with --start/--end")
    columns = {"omega_ib_b": imu["omega_ib_b"][sel], "f_b": imu["f_b"][sel]}
    rate = 1.0 / step
    moving = allan.motion(columns["f_b"], columns["omega_ib_b"], rate)
    if moving is not None:
        when, what = moving
        raise RecordingError(f"{where}: not still at t = {ts[0] + when:.6g} s: {what}; choose "
                             "a still segment with --start/--end")
    return Segment(where, float(ts[0]), float(ts[-1]), rate, columns, missing)


# --------------------------------------------------------------------------------------------
# the specification


def spec_of(triads: dict[str, allan.TriadAnalysis], segment: Segment) -> SensorSpecs:
    """An IMU record with the fitted terms stated (the others unstated)."""
    values: dict[str, float] = {}
    for triad in TRIADS:
        a = triads.get(triad.name)
        if a is None:
            continue
        for key, value in a.fit.values().items():
            if value > 0.0 and math.isfinite(value):
                values[triad.fields[key]] = value
    return SensorSpecs({"imu": ImuModel(**values)}, known={"imu": frozenset(values)},
                       sources={"imu": f"Allan fit of {segment.where}"})


def spec_text(specs: SensorSpecs, triads: dict[str, allan.TriadAnalysis],
              segment: Segment) -> str:
    """The ``[sensors.imu]`` table with the fit's intervals and what it could not see as
    comments."""
    lines = ["# navreplay allan: noise terms fitted to the overlapping Allan deviation",
             f"# of {segment.where} ({segment.t1 - segment.t0:.6g} s at {segment.rate:.6g} Hz).",
             "# Values are triad (three-axis) values; intervals in the table below are "
             f"{allan.CONFIDENCE:.1%} bootstrap intervals."]
    for triad in TRIADS:
        a = triads.get(triad.name)
        if a is None:
            continue
        for key, field in triad.fields.items():
            value = a.fit.values()[key]
            if value > 0.0 and key in a.intervals:
                lo, hi = a.intervals[key]
                lines.append(f"#   {field}: {_show(field, lo)} to {_show(field, hi)}")
        lines += [f"#   {triad.name} {note}" for note in a.fit.notes]
        if allan.Term.RANDOM_WALK not in a.fit.terms and math.isfinite(a.fit.walk_bound):
            lines.append(f"#   {triad.fields['walk']} <= "
                         f"{_show(triad.fields['walk'], a.fit.walk_bound)} (95 %)")
    lines.append("# Not observable in a still record: turn-on bias, scale factor, misalignment,"
                 " g-sensitivity")
    lines.append("# (add them from the datasheet, or `grade = \"...\"` to start from a grade).")
    return "\n".join(lines) + "\n" + specs_toml(specs)


def _show(field: str, value: float) -> str:
    unit = ImuModel.field_units[field]
    return units.format_quantity(value, unit.si, unit.datasheet, digits=4)


def triad_table(triad: Triad, a: allan.TriadAnalysis) -> list[str]:
    """The fitted terms of one triad: per axis, the triad value and its interval."""
    rows: list[tuple[str, ...]] = [
        (f"{triad.name}", "x", "y", "z", "triad", f"{allan.CONFIDENCE:.0%} interval")]
    for key, field in triad.fields.items():
        unit = ImuModel.field_units[field].datasheet
        shown = [_value(f.values()[key], field, f, key) for f in a.axis_fits]
        value = a.fit.values()[key]
        iv = a.intervals.get(key)
        interval = (f"{_value(iv[0], field)} to {_value(iv[1], field)}" if iv else "")
        rows.append((f"  {triad.labels[key]} [{unit}]", *shown, _value(value, field, a.fit, key),
                     interval))
    def floor(f: allan.NoiseFit) -> str:
        b = units.convert(f.bias_instability, triad.unit, triad.shown)
        return f"{b:.4g}" if math.isfinite(b) else "-"

    rows.append((f"  IEEE bias instability, floor / {allan.FLICKER_FLOOR:.3f} [{triad.shown}]",
                 *(floor(f) for f in a.axis_fits), floor(a.fit),
                 f"floor at tau = {a.fit.floor_tau:.4g} s" if math.isfinite(a.fit.floor_tau)
                 else "no floor"))
    widths = [max(len(r[i]) for r in rows) for i in range(6)]
    out = ["  ".join(c.ljust(w) if i in (0, 5) else c.rjust(w)
                     for i, (c, w) in enumerate(zip(r, widths, strict=True))).rstrip()
           for r in rows]
    out += [f"  {note}" for note in a.fit.notes]
    if math.isfinite(a.fit.walk_bound):
        out.append(f"  {triad.labels['walk']} <= {_value(a.fit.walk_bound, triad.fields['walk'])} "
                   f"{ImuModel.field_units[triad.fields['walk']].datasheet} (95 %)")
    return out


def _value(value: float, field: str, fit: allan.NoiseFit | None = None,
           key: str | None = None) -> str:
    if fit is not None and key is not None and not (fit.values()[key] > 0.0):
        return "-"
    if math.isinf(value):
        return "inf"
    unit = ImuModel.field_units[field]
    return f"{units.convert(value, unit.si, unit.datasheet):.4g}"


# --------------------------------------------------------------------------------------------
# figure and view


def figure_panels(triads: dict[str, allan.TriadAnalysis]) -> list[Any]:
    """One :class:`navreplay.viz.figures.AllanPanel` per triad, in display units."""
    from navreplay.viz.figures import AllanPanel, AllanTerm

    panels = []
    for triad in TRIADS:
        a = triads.get(triad.name)
        if a is None:
            continue
        k = units.convert(1.0, triad.unit, triad.shown)
        fit = a.fit
        tau = a.curve.tau
        terms = [AllanTerm(f"white: {triad.labels['white']} "
                           f"{_value(fit.white, triad.fields['white'])}"
                           f" {ImuModel.field_units[triad.fields['white']].datasheet}",
                           tau, k * fit.white / np.sqrt(tau), 1.0, k * fit.white)]
        if allan.Term.GAUSS_MARKOV in fit.terms:
            peak = allan.GM_PEAK_X * fit.gm_tau
            terms.append(AllanTerm(
                f"Gauss-Markov: sigma {_value(fit.gm_sigma, triad.fields['gm_sigma'])} "
                f"{ImuModel.field_units[triad.fields['gm_sigma']].datasheet}, "
                f"T {fit.gm_tau:.4g} s", tau,
                k * np.sqrt(allan.gm_avar(tau, fit.gm_sigma, fit.gm_tau)),
                peak, k * allan.GM_PEAK_ADEV * fit.gm_sigma))
        if allan.Term.RANDOM_WALK in fit.terms:
            terms.append(AllanTerm(
                f"random walk: {_value(fit.walk, triad.fields['walk'])} "
                f"{ImuModel.field_units[triad.fields['walk']].datasheet}", tau,
                k * fit.walk * np.sqrt(tau / 3.0), 3.0, k * fit.walk))
        panels.append(AllanPanel(
            title=f"{triad.name}: overlapping Allan deviation", unit=triad.shown, tau=tau,
            axes=tuple(k * c.adev for c in a.axes), triad=k * a.curve.adev,
            lo=k * a.curve.lo, hi=k * a.curve.hi, model=k * np.sqrt(fit.avar(tau)),
            terms=tuple(terms),
            floor=(fit.floor_tau, k * fit.floor) if math.isfinite(fit.floor) else None))
    return panels
