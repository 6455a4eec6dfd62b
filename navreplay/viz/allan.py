"""The Rerun view of ``navreplay allan``: the Allan deviation of each triad on log-log axes.

Rerun's time-series views plot against a timeline on linear axes, so the curves are drawn in a
2D view in decades: x = log10(tau [s]), y = log10(ADEV [unit]) (drawn upwards), with a grid
line and a label at every decade. Entity tree::

    /allan/<triad>/axis/x|y|z      ADEV of each axis
    /allan/<triad>/triad           ADEV of the triad (mean Allan variance)
    /allan/<triad>/interval        its confidence interval (lower and upper curve)
    /allan/<triad>/fit             the fitted model
    /allan/<triad>/term/<k>        each fitted term's asymptote, with a point where it is read
    /allan/<triad>/floor           the smallest ADEV of the fitted range
    /allan/<triad>/grid            decade lines and their labels
    /allan/summary                 the report (text)
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from navreplay.io.outputs import atomic_path
from navreplay.viz.sink import APPLICATION_ID

if TYPE_CHECKING:  # the figure's data classes; importing figures would load matplotlib
    from navreplay.viz.figures import AllanPanel

_AXIS_COLORS = ((214, 39, 40), (44, 160, 44), (31, 119, 180))
"""x, y, z (the figure's tab:red, tab:green, tab:blue)."""
_TERM_COLORS = ((148, 103, 189), (140, 86, 75), (227, 119, 194), (188, 189, 34))
_GREY = (150, 150, 150)


def _xy(tau: np.ndarray, adev: np.ndarray) -> np.ndarray:
    """Points of a curve in decades (y negated: a 2D view's y axis points down)."""
    ok = (adev > 0) & np.isfinite(adev)
    return np.column_stack([np.log10(tau[ok]), -np.log10(adev[ok])])


def _grid(rec: rr.RecordingStream, path: str, p: AllanPanel) -> None:
    x0, x1 = math.floor(math.log10(p.tau[0])), math.ceil(math.log10(p.tau[-1]))
    values = np.concatenate([p.lo[p.lo > 0], p.hi, p.triad])
    y0, y1 = math.floor(math.log10(values.min())), math.ceil(math.log10(values.max()))
    strips = [[[x, -y0], [x, -y1]] for x in range(x0, x1 + 1)]
    strips += [[[x0, -y], [x1, -y]] for y in range(y0, y1 + 1)]
    rec.log(f"{path}/grid", rr.LineStrips2D(strips, colors=[(220, 220, 220)], radii=0.004),
            static=True)
    labels = [f"{10.0**x:g} s" for x in range(x0, x1 + 1)]
    labels += [f"{10.0**y:g} {p.unit}" for y in range(y0, y1 + 1)]
    points = [[x, -y0 + 0.12] for x in range(x0, x1 + 1)]
    points += [[x0 - 0.05, -y] for y in range(y0, y1 + 1)]
    rec.log(f"{path}/grid/labels", rr.Points2D(points, labels=labels, radii=0.01,
                                               colors=[_GREY], show_labels=True), static=True)


def log_panel(rec: rr.RecordingStream, name: str, p: AllanPanel) -> None:
    """Log one triad's curves under ``/allan/<name>``."""
    path = f"/allan/{name}"
    for axis, adev, color in zip("xyz", p.axes, _AXIS_COLORS, strict=True):
        rec.log(f"{path}/axis/{axis}", rr.LineStrips2D([_xy(p.tau, adev)], colors=[color],
                                                        radii=0.006, labels=[axis]), static=True)
    rec.log(f"{path}/interval", rr.LineStrips2D([_xy(p.tau, p.lo), _xy(p.tau, p.hi)],
                                                colors=[_GREY], radii=0.004), static=True)
    rec.log(f"{path}/triad", rr.LineStrips2D([_xy(p.tau, p.triad)], colors=[(40, 40, 40)],
                                             radii=0.012, labels=["triad"]), static=True)
    rec.log(f"{path}/fit", rr.LineStrips2D([_xy(p.tau, p.model)], colors=[(0, 0, 0)],
                                           radii=0.006, labels=["fit"]), static=True)
    for k, term in enumerate(p.terms):
        color = _TERM_COLORS[k % len(_TERM_COLORS)]
        rec.log(f"{path}/term/{k}", rr.LineStrips2D([_xy(term.tau, term.adev)], colors=[color],
                                                    radii=0.006), static=True)
        rec.log(f"{path}/term/{k}/read", rr.Points2D(
            _xy(np.array([term.at_tau]), np.array([term.at_adev])), colors=[color], radii=0.03,
            labels=[term.label], show_labels=True), static=True)
    if p.floor is not None:
        rec.log(f"{path}/floor", rr.Points2D(
            _xy(np.array([p.floor[0]]), np.array([p.floor[1]])), colors=[(0, 0, 0)],
            radii=0.03, labels=[f"floor {p.floor[1]:.3g} {p.unit}"], show_labels=True),
            static=True)
    _grid(rec, path, p)


def blueprint(panels: Sequence[AllanPanel], names: Sequence[str]) -> rrb.Blueprint:
    views = [rrb.Spatial2DView(origin=f"/allan/{name}",
                               name=f"{name}: ADEV [{p.unit}] vs tau [s], log-log")
             for name, p in zip(names, panels, strict=True)]
    return rrb.Blueprint(
        rrb.Vertical(rrb.Horizontal(*views), rrb.TextDocumentView(origin="/allan/summary",
                                                                  name="fit"),
                     row_shares=[3, 1]),
        collapse_panels=True,
    )


def save_allan_view(path: str | Path, panels: Sequence[AllanPanel], text: str,
                    name: str = "allan") -> Path:
    """Write the .rrd of an Allan analysis (atomically): one 2D view per triad and the
    report as markdown."""
    names = [p.title.split(":")[0] for p in panels]
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=str(uuid.uuid4()))
    rec.send_recording_name(name)
    with atomic_path(path) as tmp:
        rec.save(tmp, default_blueprint=blueprint(panels, names))
        try:
            for n, p in zip(names, panels, strict=True):
                log_panel(rec, n, p)
            rec.log("/allan/summary", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN),
                    static=True)
            rec.flush()
        finally:
            rec.disconnect()
    return Path(path)
