"""Static figures of filter runs and ensembles (matplotlib, Agg backend), as a paper shows them.

Each function takes plain arrays and returns a matplotlib Figure, so the HTML report
(:mod:`navreplay.report`) and scripts draw the same pictures:

* :func:`bounded_errors` — estimation errors with their shaded +-3 sigma, one panel per quantity;
* :func:`consistency` — NEES and NIS (log scale) inside their shaded chi-square band;
* :func:`rms_vs_sigma` — ensemble RMS error (solid) against the mean predicted sigma (dashed);
* :func:`allan_deviation` — Allan deviation per axis (log-log) with the fitted noise terms.

A filter keeps its colour (:func:`filter_colors`, by its name) in every
figure. Importing this module loads matplotlib: import it only when figures are wanted.
"""

from __future__ import annotations

import dataclasses
import io
import re
from collections.abc import Sequence

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown",
          "tab:pink", "tab:olive", "tab:cyan")
BAND_COLOR = "0.82"
DPI = 100
PANEL_SIZE = (4.2, 2.4)
"""Width and height of one panel [in]."""


def filter_colors(labels: Sequence[str]) -> dict[str, str]:
    """The colours of the labels drawn together in a figure: the Rerun view's, by name
    (:class:`navreplay.core.colors.LabelColors`; distinct while the palette lasts)."""
    from navreplay.core.colors import LabelColors

    colors = LabelColors()
    return {label: COLORS[colors.index(label)] for label in labels}


@dataclasses.dataclass(frozen=True)
class Curve:
    """One filter's line in an overlay: ``x`` (time [s], or the error of a CDF), ``y``."""

    label: str
    x: np.ndarray
    y: np.ndarray
    color: str


def overlay(title: str, panels: Sequence[tuple[str, str, Sequence[Curve]]],
            cols: int = 2) -> plt.Figure:
    """Several filters' errors in one panel per quantity (``(title, unit, curves)``), each
    filter in its colour; the legend below the panels, off the data."""
    fig, axes = _grid(len(panels), cols, title)
    for k, (ax, (name, unit, curves)) in enumerate(zip(axes, panels, strict=True)):
        for c in curves:
            ax.plot(c.x, c.y, color=c.color, linewidth=1.0, label=c.label)
        _robust_ylim(ax, [c.y for c in curves])
        _style(ax, Panel(name, unit, np.empty(0), np.empty(0)), k >= len(panels) - cols)
    _legend_below(fig, axes)
    return fig


def cdfs(title: str, panels: Sequence[tuple[str, str, Sequence[Curve]]],
         cols: int = 2) -> plt.Figure:
    """Empirical CDFs (``x`` the error, ``y`` the fraction) of several filters in one panel
    per quantity; the error axis logarithmic when the filters differ by more than 30 times."""
    fig, axes = _grid(len(panels), cols, title)
    for ax, (name, unit, curves) in zip(axes, panels, strict=True):
        for c in curves:
            ax.step(c.x, 100.0 * c.y, where="post", color=c.color, linewidth=1.2, label=c.label)
        pos = np.concatenate([c.x[np.isfinite(c.x) & (c.x > 0)] for c in curves] or [[]])
        if pos.size and pos.max() > 30.0 * np.percentile(pos, 5):
            ax.set_xscale("log")
        ax.set_title(f"CDF of the {name}", fontsize=10)
        ax.set_xlabel(f"[{unit}]")
        ax.set_ylabel("[%]")
        ax.set_ylim(0, 100)
        ax.grid(True, which="both", color="0.9", linewidth=0.8)
        ax.set_axisbelow(True)
    _legend_below(fig, axes)
    return fig


def metric_bars(rows: Sequence[tuple[str, Sequence[float]]], labels: Sequence[str],
                colors: Sequence[str], cols: int = 3) -> plt.Figure:
    """One bar chart per metric (``(title [unit], values)``), a bar per label in its colour."""
    fig, axes = _grid(len(rows), cols, "")
    x = np.arange(len(labels))
    for ax, (name, values) in zip(axes, rows, strict=True):
        v = np.asarray(values, dtype=float)
        ax.bar(x, np.where(np.isfinite(v), v, 0.0), color=colors)
        ax.set_title(name, fontsize=10)
        ax.set_xticks(x, labels, rotation=20, ha="right", fontsize=8)
        ax.grid(True, axis="y", color="0.9", linewidth=0.8)
        ax.set_axisbelow(True)
    return fig


def _robust_ylim(ax: plt.Axes, series: Sequence[np.ndarray]) -> None:
    """A y range that a start-up transient does not set: up to 1.2 x the 99th percentile of
    the last 90 % of each series (the whole series when short)."""
    tails = [y[len(y) // 10:] for y in series if y.size]
    v = np.concatenate(tails) if tails else np.empty(0)
    v = v[np.isfinite(v)]
    if v.size >= 10:
        hi = float(np.percentile(np.abs(v), 99))
        if hi > 0 and np.nanmax(np.abs(np.concatenate(series))) > 1.5 * hi:
            lo = float(np.min(v))
            ax.set_ylim(min(0.0, 1.2 * lo) if lo < 0 else 0.0, 1.2 * hi)


def _legend_below(fig: plt.Figure, axes: Sequence[plt.Axes]) -> None:
    if not axes:
        return
    handles, names = axes[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, names, loc="outside lower center", ncols=min(len(names), 6),
                   fontsize=8, frameon=False)


@dataclasses.dataclass(frozen=True)
class Panel:
    """One time series of a figure.

    Attributes
    ----------
    title : str
    unit : str
        Shown on the y axis.
    t : ndarray, shape (M,)
        Time [s].
    value : ndarray, shape (M,)
        Error (bounded_errors), RMS (rms_vs_sigma) or NEES/NIS (consistency).
    bound : ndarray (M,) or None
        1-sigma (bounded_errors), mean predicted sigma (rms_vs_sigma).
    band : tuple of ndarray (M,) or None
        Lower and upper chi-square bounds (consistency).
    bound_t : ndarray or None
        Times of ``bound`` when they are not ``t`` (decimated series).
    inside : float or None
        Fraction of the values inside ``band``, when ``value`` does not hold them all
        (decimated series); computed from ``value`` otherwise.
    """

    title: str
    unit: str
    t: np.ndarray
    value: np.ndarray
    bound: np.ndarray | None = None
    band: tuple[np.ndarray, np.ndarray] | None = None
    bound_t: np.ndarray | None = None
    inside: float | None = None

    @property
    def tb(self) -> np.ndarray:
        """The times of ``bound``."""
        return self.t if self.bound_t is None else self.bound_t


def _grid(n: int, cols: int, title: str) -> tuple[plt.Figure, list[plt.Axes]]:
    cols = max(1, min(cols, n))
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(PANEL_SIZE[0] * cols, PANEL_SIZE[1] * rows + 0.5),
                             squeeze=False, layout="constrained")
    fig.suptitle(title)
    flat = list(axes.ravel())
    for ax in flat[n:]:
        ax.set_visible(False)
    return fig, flat[:n]


def _style(ax: plt.Axes, p: Panel, last_row: bool) -> None:
    ax.set_title(p.title, fontsize=10)
    ax.set_ylabel(f"[{p.unit}]" if p.unit else "")
    if last_row:
        ax.set_xlabel("time [s]")
    ax.grid(True, color="0.9", linewidth=0.8)
    ax.set_axisbelow(True)
    ax.margins(x=0)


def bounded_errors(title: str, panels: Sequence[Panel], color: str = COLORS[0],
                   cols: int = 3) -> plt.Figure:
    """Errors (solid) inside their shaded +-3 sigma, each panel at its own scale."""
    fig, axes = _grid(len(panels), cols, title)
    for k, (ax, p) in enumerate(zip(axes, panels, strict=True)):
        if p.bound is not None and np.isfinite(p.bound).any():
            b = 3.0 * p.bound
            ax.fill_between(p.tb, -b, b, color=color, alpha=0.15, linewidth=0, label="±3σ")
            ax.plot(p.tb, b, color=color, linewidth=0.6, alpha=0.6)
            ax.plot(p.tb, -b, color=color, linewidth=0.6, alpha=0.6)
        ax.plot(p.t, p.value, color=color, linewidth=1.1, label="error")
        ax.axhline(0.0, color="0.5", linewidth=0.6)
        _style(ax, p, k >= len(panels) - cols)
    if axes:
        axes[0].legend(loc="upper left", fontsize=8, frameon=False)
    return fig


def consistency(title: str, panels: Sequence[Panel], color: str = COLORS[0]) -> plt.Figure:
    """NEES / NIS series (log scale) with their 95 % chi-square band shaded."""
    fig, axes = _grid(len(panels), 1, title)
    fig.set_size_inches(2.2 * PANEL_SIZE[0], PANEL_SIZE[1] * len(panels) + 0.5)
    for k, (ax, p) in enumerate(zip(axes, panels, strict=True)):
        value = np.where(p.value > 0, p.value, np.nan)
        if p.band is not None:
            lo, hi = p.band
            ax.fill_between(p.t, lo, hi, color=BAND_COLOR, alpha=0.8, linewidth=0,
                            label="95 % χ² band")
        ax.plot(p.t, value, color=color, linewidth=0.9, marker="." if len(p.t) < 200 else None,
                markersize=3, label=p.title)
        ax.set_yscale("log")
        _style(ax, p, k == len(panels) - 1)
        if p.band is not None:
            inside = p.inside if p.inside is not None else np.mean(
                (p.value >= p.band[0]) & (p.value <= p.band[1]))
            ax.set_title(f"{p.title}: {100 * inside:.0f} % inside the band", fontsize=10)
        ax.legend(loc="upper right", fontsize=8, frameon=False)
    return fig


def rms_vs_sigma(title: str, panels: Sequence[Panel], color: str = COLORS[0],
                 cols: int = 3) -> plt.Figure:
    """Ensemble RMS error (solid) against the mean predicted sigma (dashed), same colour."""
    fig, axes = _grid(len(panels), cols, title)
    for k, (ax, p) in enumerate(zip(axes, panels, strict=True)):
        ax.plot(p.t, p.value, color=color, linewidth=1.3, label="RMS")
        if p.bound is not None and np.isfinite(p.bound).any():
            ax.plot(p.tb, p.bound, color=color, linewidth=1.3, linestyle="--", label="σ")
        ax.set_ylim(bottom=0.0)
        _style(ax, p, k >= len(panels) - cols)
    if axes:
        axes[0].legend(loc="upper left", fontsize=8, frameon=False)
    return fig


@dataclasses.dataclass(frozen=True)
class AllanTerm:
    """One fitted noise term of an Allan-deviation panel.

    Attributes
    ----------
    label : str
        Name and value, for the legend.
    tau, adev : ndarray, shape (K,)
        The term's own ADEV (its asymptote) [s], [unit].
    at_tau, at_adev : float
        Where the term is read (tau = 1 s for white noise, 3 s for a random walk, the peak
        of a Gauss-Markov hump), marked on the asymptote.
    """

    label: str
    tau: np.ndarray
    adev: np.ndarray
    at_tau: float
    at_adev: float


@dataclasses.dataclass(frozen=True)
class AllanPanel:
    """One triad of an Allan-deviation figure (all ADEVs in ``unit``).

    Attributes
    ----------
    title, unit : str
    tau : ndarray, shape (K,)
        Cluster times [s].
    axes : tuple of three ndarray (K,)
        ADEV of the x, y and z axes.
    triad, lo, hi : ndarray, shape (K,)
        ADEV of the triad (mean Allan variance) and its confidence interval.
    model : ndarray, shape (K,)
        ADEV of the fitted model (the sum of the terms).
    terms : tuple of AllanTerm
    floor : (tau, adev) or None
        The flat part of the fitted curve (the IEEE bias instability is adev / 0.664).
    """

    title: str
    unit: str
    tau: np.ndarray
    axes: tuple[np.ndarray, ...]
    triad: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    model: np.ndarray
    terms: tuple[AllanTerm, ...]
    floor: tuple[float, float] | None


AXIS_COLORS = ("tab:red", "tab:green", "tab:blue")
"""x, y, z."""


def allan_deviation(panels: Sequence[AllanPanel], title: str = "") -> plt.Figure:
    """Allan deviation (log-log): the axes (thin), the triad with its shaded confidence
    interval, the fitted model (black dashed) and each term's asymptote (dotted) marked where
    it is read."""
    fig, axes = plt.subplots(1, len(panels), figsize=(6.0 * len(panels), 4.6), squeeze=False,
                             layout="constrained")
    if title:
        fig.suptitle(title, fontsize=10)
    for ax, p in zip(axes[0], panels, strict=True):
        for name, adev, color in zip("xyz", p.axes, AXIS_COLORS, strict=True):
            ax.loglog(p.tau, adev, color=color, linewidth=0.8, alpha=0.7, label=name)
        ax.fill_between(p.tau, p.lo, p.hi, color=BAND_COLOR, alpha=0.9, linewidth=0,
                        label="triad, 68 % interval")
        ax.loglog(p.tau, p.triad, color="0.2", linewidth=1.4, label="triad")
        ax.loglog(p.tau, p.model, color="black", linewidth=1.2, linestyle="--", label="fit")
        top = 3.0 * max(np.max(p.hi), np.max(p.triad))
        bottom = 0.3 * np.min(p.lo[p.lo > 0]) if np.any(p.lo > 0) else None
        for k, term in enumerate(p.terms):
            color = COLORS[(k + 4) % len(COLORS)]
            ax.loglog(term.tau, term.adev, color=color, linewidth=1.0, linestyle=":",
                      label=term.label)
            ax.plot([term.at_tau], [term.at_adev], marker="o", color=color, markersize=5)
        if p.floor is not None:
            ax.plot([p.floor[0]], [p.floor[1]], marker="v", color="black", markersize=6,
                    linestyle="none", label=f"floor {p.floor[1]:.3g} {p.unit}")
        ax.set_ylim(bottom, top)
        ax.set_xlim(p.tau[0], p.tau[-1])
        ax.set_title(p.title, fontsize=10)
        ax.set_xlabel("cluster time τ [s]")
        ax.set_ylabel(f"Allan deviation [{p.unit}]")
        ax.grid(True, which="both", color="0.92", linewidth=0.6)
        ax.set_axisbelow(True)
        ax.legend(loc="lower left", fontsize=7, frameon=False)
    return fig


def save(fig: plt.Figure, path: str, fmt: str) -> None:
    """Write the figure (``png`` or ``svg``, no metadata) and close it."""
    fig.savefig(path, format=fmt, dpi=DPI, metadata={"Software": None} if fmt == "png"
                else {"Date": None})
    plt.close(fig)


def svg(fig: plt.Figure) -> str:
    """The figure as an ``<svg>`` element to put inside an HTML page: no XML header, no
    metadata, no namespace URLs (the HTML parser supplies them), text kept as text."""
    buf = io.StringIO()
    with plt.rc_context({"svg.fonttype": "none"}):
        fig.savefig(buf, format="svg", metadata={"Date": None})
    plt.close(fig)
    text = buf.getvalue()
    text = text[text.index("<svg"):]
    text = re.sub(r"<metadata>.*?</metadata>\s*", "", text, flags=re.S)
    return re.sub(r'\s+xmlns(:\w+)?="[^"]*"', "", text)


def pdf(figs: Sequence[plt.Figure], path: str, title: str) -> None:
    """Write figures as the pages of one PDF (matplotlib's PDF backend) and close them."""
    from matplotlib.backends.backend_pdf import PdfPages

    with PdfPages(path, metadata={"Title": title, "CreationDate": None}) as out:
        for fig in figs:
            out.savefig(fig)
            plt.close(fig)


def text_page(title: str, lines: Sequence[str]) -> plt.Figure:
    """A page of monospaced text (the tables of a PDF report)."""
    fig = plt.figure(figsize=(8.27, 11.69))
    fig.text(0.05, 0.97, title, fontsize=13, va="top")
    fig.text(0.05, 0.93, "\n".join(lines), family="monospace", fontsize=7, va="top")
    return fig


def png(fig: plt.Figure) -> bytes:
    """The figure as PNG bytes (no metadata), and close it."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()
