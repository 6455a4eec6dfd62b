"""Draw the figures of docs/reproduction.md from the reproduction campaigns.

Each figure is drawn from the ``figures`` of the :class:`navreplay.reproduce.Report` that
``navreplay reproduce NAME`` computes, with the same campaign sizes and seed as the tables of
docs/reproduction.md (matplotlib comes with navreplay)::

    python docs/plots.py                          # all three, into docs/img/
    python docs/plots.py vector-matching --workers 2

The campaigns take from about 10 s (vector-matching) to a minute or two (rpm-aided-ins).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from navreplay.reproduce import get  # noqa: E402

IMG = Path(__file__).resolve().parent / "img"
DPI = 100
GRAVITY_COLOR, SF_COLOR = "tab:red", "tab:blue"
MODEL_STYLE = {
    "gravity": (GRAVITY_COLOR, "gravity model (eq. 14)"),
    "specific-force": (SF_COLOR, "specific-force model (eqs. 28-29)"),
}


def _style(ax: plt.Axes) -> None:
    ax.grid(True, which="major", color="0.85", linewidth=0.8)
    ax.grid(True, which="minor", color="0.93", linewidth=0.5)
    ax.set_axisbelow(True)


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.savefig(path, dpi=DPI, metadata={"Software": None})
    plt.close(fig)
    return path


# --------------------------------------------------------------------------------------------
# vector matching (Choe & Park 2017, Figs. 1-5)


def vector_matching(figs: Mapping[str, Any], path: Path) -> Path:
    """Sweeps (max RMS attitude error at 10 s vs acceleration) and yaw cases (RMS yaw vs t)."""
    sweep, yaw = figs["sweep"], figs["yaw"]
    a = np.asarray(sweep["accel_g"], dtype=float)
    models = list(sweep["models"])
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.6), layout="constrained")
    fig.suptitle("Gyro-free attitude by vector matching: RMS attitude error "
                 f"(seed 0, {_runs_label(figs)})")
    for ax, axis, tag in zip(axes.flat[:3], ("N", "E", "D"), ("(a)", "(b)", "(c)"), strict=True):
        r = np.asarray(sweep["rms_deg"][axis])           # (accel, model, angle) [deg]
        for j, model in enumerate(models):
            ax.semilogy(a, r[:, j, :].max(axis=1), "o-", color=MODEL_STYLE[model][0],
                        markersize=3, linewidth=1.5)
        ax.set_title(f"{tag} {axis} sweep: 5 s at rest, then 5 s at a along {axis}", fontsize=10)
        ax.set_xlabel("acceleration a [g]")
        ax.set_ylabel("max of RMS roll, pitch, yaw at 10 s [deg]")
        ax.set_xlim(-1.55, 1.55)
        ax.set_ylim(0.2, 300.0)
        _style(ax)

    ax = axes[1, 1]
    t = np.asarray(yaw["t"], dtype=float)
    for case, dash in (("x", "-"), ("y", "--")):
        r = np.asarray(yaw["rms_deg"][case])              # (model, time, angle) [deg]
        for j, model in enumerate(models):
            ax.plot(t, r[j, :, 2], dash, color=MODEL_STYLE[model][0], linewidth=1.5)
    for t0, text in ((10.0, "+0.5 g, yaw +90°"), (20.0, "-0.5 g, yaw -90°")):
        ax.axvspan(t0, t0 + 5.0, color="0.92", zorder=0)
        ax.text(t0 + 2.5, 0.98, text, transform=ax.get_xaxis_transform(), ha="center",
                va="top", fontsize=8)
    ax.set_title("(d) yaw cases: acceleration along body x or y while turning", fontsize=10)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("RMS yaw error [deg]")
    ax.set_xlim(0.0, float(t[-1]))
    ax.set_ylim(0.0, 8.0)
    _style(ax)
    handles = [Line2D([], [], color=c, linewidth=4, label=lbl) for c, lbl in MODEL_STYLE.values()]
    handles += [Line2D([], [], color="0.3", linestyle="-", label="(d) case x: a along body x"),
                Line2D([], [], color="0.3", linestyle="--", label="(d) case y: a along body y")]
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=9)
    return _save(fig, path)


def _runs_label(figs: Mapping[str, Any]) -> str:
    n = figs.get("timing", {}).get("recordings")
    return f"{n:,} recordings" if n else "Monte Carlo"


# --------------------------------------------------------------------------------------------
# transfer alignment (Song, Jeon & Lyou, Figs. 2-3)

TA_VARIANTS = {
    "vel_quat_partial": ("tab:blue", "velocity + partial quaternion (proposed)"),
    "vel_quat_full": ("tab:red", "velocity + full quaternion"),
    "vel_only": ("tab:gray", "velocity only"),
    "vel_quat_partial+flexure": ("tab:cyan", "partial, with the flexure states"),
    "vel_quat_full+flexure": ("tab:green", "full, with the flexure states"),
}


def transfer_alignment(figs: Mapping[str, Any], path: Path) -> Path:
    """RMS level and azimuth alignment errors vs time with the filter's predicted sigma."""
    t = np.asarray(figs["t"], dtype=float)
    plots = figs["plots"]
    runs = figs.get("timing", {}).get("recordings")
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.6), layout="constrained")
    fig.suptitle("Shipboard transfer alignment: RMS over "
                 f"{runs // 3 if runs else 'the'} runs; (a)-(c) with the Y-axis flexure "
                 "ωn = 2π rad/s (seed 0)")

    def draw(ax: plt.Axes, series: Mapping[str, np.ndarray]) -> None:
        for name, values in series.items():
            variant, kind = name.rsplit(" ", 1)
            ax.plot(t, values, "-" if kind == "RMS" else "--", color=TA_VARIANTS[variant][0],
                    linewidth=1.5 if kind == "RMS" else 1.0)

    for ax, axis, tag in zip(axes[0], ("N", "E"), ("(a)", "(b)"), strict=True):
        draw(ax, plots[f"fig2 level error phi_{axis}"])
        ax.set_title(f"{tag} level error φ_{axis} (cf. paper Fig. 2)")
        ax.set_ylabel(f"RMS φ_{axis} [mrad]")
        ax.set_ylim(0.0, 3.0)

    ax = axes[1, 0]
    draw(ax, plots["fig3 azimuth error phi_D"])
    draw(ax, plots["azimuth error phi_D vel_only"])
    ax.set_yscale("log")
    ax.set_ylim(0.1, 1000.0)
    ax.set_title("(c) azimuth error φ_D (cf. paper Fig. 3)")
    ax.set_ylabel("RMS φ_D [mrad]")

    ax = axes[1, 1]
    for key, dash in (("fig3 azimuth error phi_D", "-"), ("fig3 azimuth error phi_D wn_1", ":"),
                      ("fig3 azimuth error phi_D no_flexure", "-.")):
        for name, values in plots[key].items():
            variant, kind = name.rsplit(" ", 1)
            if kind == "RMS":
                ax.plot(t, values, dash, color=TA_VARIANTS[variant][0], linewidth=1.5)
    ax.set_yscale("log")
    ax.set_ylim(0.5, 300.0)
    ax.set_title("(d) azimuth error φ_D by flexure condition, RMS")
    ax.set_ylabel("RMS φ_D [mrad]")
    ax.legend(handles=[Line2D([], [], color="0.3", linestyle=d, label=c)
                       for d, c in (("-", "flexure ωn = 2π rad/s"), (":", "flexure ωn = 1 rad/s"),
                                    ("-.", "no flexure"))],
              loc="upper right", fontsize=8)
    for ax in axes.flat:
        ax.set_xlabel("time [s]")
        ax.set_xlim(0.0, float(t[-1]))
        _style(ax)
    handles = [Line2D([], [], color=c, linewidth=4, label=lbl) for c, lbl in TA_VARIANTS.values()]
    handles += [Line2D([], [], color="0.3", label="RMS error over the runs"),
                Line2D([], [], color="0.3", linestyle="--", linewidth=1.0,
                       label="filter's predicted 1σ (run average)")]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=9)
    return _save(fig, path)


# --------------------------------------------------------------------------------------------
# RPM-aided INS (Choi 2019, Figs. 3-5)

RPM_MODES = {
    "pure": ("tab:gray", "pure navigation"),
    "rpm": ("tab:orange", "RPM + depth aided"),
    "rpm-current": ("tab:blue", "RPM + depth aided, current estimated"),
}


def rpm_aided_ins(figs: Mapping[str, Any], path: Path) -> Path:
    """Current estimate of run 1 and its RMS error; RMS east / north error of the three modes."""
    t = np.asarray(figs["t"], dtype=float)
    runs = figs.get("timing", {}).get("recordings")
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.6), layout="constrained")
    fig.suptitle("RPM-aided underwater INS: 480 s, 6.8 km, 0.25 m/s current in a random "
                 f"direction; {runs if runs else 'all'} runs (seed 0)")
    axis_colors = (("N", "tab:purple"), ("E", "tab:green"))

    ax = axes[0, 0]
    if "current_run1" in figs:
        c = figs["current_run1"]
        ct = np.asarray(c["t"], dtype=float)
        for j, (axis, color) in enumerate(axis_colors):
            ax.plot(ct, c["estimate"][:, j], color=color, linewidth=1.5,
                    label=f"estimate {axis}")
            ax.axhline(c["truth"][j], color=color, linestyle="--", linewidth=1.0,
                       label=f"truth {axis}")
        ax.legend(loc="lower right", fontsize=8, ncol=2)
    ax.set_title("(a) current estimate of run 1, RPM + depth + current (cf. paper Fig. 3)",
                 fontsize=10)
    ax.set_ylabel("sea current [m/s]")

    ax = axes[0, 1]
    for j, (axis, color) in enumerate(axis_colors):
        ax.plot(t, figs["current_rms"][:, j], color=color, linewidth=1.5,
                label=f"{axis}: RMS error over the runs")
        ax.plot(t, figs["current_sigma"][:, j], "--", color=color, linewidth=1.0,
                label=f"{axis}: filter's predicted 1σ")
    ax.set_ylim(0.0, 0.25)
    ax.set_title("(b) current-estimate error, RPM + depth + current", fontsize=10)
    ax.set_ylabel("RMS current error [m/s]")
    ax.legend(loc="upper right", fontsize=8)

    for ax, key, what, tag, fig_no in ((axes[1, 0], "long", "east", "(c)", 4),
                                       (axes[1, 1], "lat", "north", "(d)", 5)):
        for label, (color, _text) in RPM_MODES.items():
            ax.plot(t, figs[f"{key}_rms"][label], color=color, linewidth=1.5)
            ax.plot(t, figs[f"{key}_sigma"][label], "--", color=color, linewidth=1.0)
        ax.set_yscale("log")
        ax.set_ylim(1.0, 3000.0)
        name = "longitude" if key == "long" else "latitude"
        ax.set_title(f"{tag} {what} ({name}) position error (cf. paper Fig. {fig_no})",
                     fontsize=10)
        ax.set_ylabel(f"RMS {what} error [m]")
    for ax in axes.flat:
        ax.set_xlabel("time [s]")
        ax.set_xlim(0.0, float(t[-1]))
        _style(ax)
    handles = [Line2D([], [], color=c, linewidth=4, label=lbl) for c, lbl in RPM_MODES.values()]
    handles += [Line2D([], [], color="0.3", label="(c), (d): RMS error over the runs"),
                Line2D([], [], color="0.3", linestyle="--", linewidth=1.0,
                       label="(c), (d): filter's predicted 1σ (run average)")]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=9)
    return _save(fig, path)


# --------------------------------------------------------------------------------------------

FIGURES: dict[str, tuple[Callable[[Mapping[str, Any], Path], Path], str]] = {
    "transfer-alignment": (transfer_alignment, "transfer_alignment_errors.png"),
    "vector-matching": (vector_matching, "vector_matching_sweeps.png"),
    "rpm-aided-ins": (rpm_aided_ins, "rpm_aided_ins_errors.png"),
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", metavar="NAME",
                        help=f"reproductions to draw (default: all of {', '.join(FIGURES)})")
    parser.add_argument("--workers", type=int, default=2, help="processes per campaign")
    parser.add_argument("--seed", type=int, default=0, help="base seed of the campaigns")
    parser.add_argument("--out", type=Path, default=IMG, help="output directory")
    args = parser.parse_args(argv)
    unknown = [n for n in args.names if n not in FIGURES]
    if unknown:
        parser.error(f"unknown reproduction {unknown[0]!r}; choose from {', '.join(FIGURES)}")
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.names or list(FIGURES):
        draw, filename = FIGURES[name]
        report = get(name).run(seed=args.seed, workers=args.workers)
        path = draw(report.figures, args.out / filename)
        print(f"{name}: {'all bands pass' if report.passed else 'BANDS FAIL'}; wrote {path} "
              f"({path.stat().st_size / 1024:.0f} KiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
