"""Draw the figures of docs/sensors.md: ``ins`` and ``gps-ins`` on ``vehicle-drive``
recordings of each IMU grade, with the settings derived from the recording's IMU specification
and with the tactical defaults (the ensembles of tests/grade_ensembles.py)::

    python docs/sensor_figures.py [RUNS] [SEED]      # 40 runs at seed 0, into docs/img/

About a minute on one core.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import grade_ensembles as ge  # noqa: E402

from navreplay.filters.gps_ins import GpsInsParams  # noqa: E402
from navreplay.filters.ins import InsParams  # noqa: E402

IMG = ROOT / "docs" / "img"
DPI = 100
DERIVED, TACTICAL = "tab:blue", "tab:red"


def _style(ax: plt.Axes) -> None:
    ax.grid(True, color="0.88", linewidth=0.8)
    ax.set_axisbelow(True)


def rms_vs_sigma(runs: int, seed: int, path: Path) -> tuple[Path, dict]:
    """Per grade (columns): the horizontal position of ins and the heading of gps-ins, RMS over
    the runs (solid) against the predicted sigma (dashed), derived settings and tactical
    defaults."""
    tactical = {"ins": InsParams(), "gps-ins": GpsInsParams()}
    rows = (("ins", "pos_ned", 0, 1.0, "ins: north position [m]"),
            ("gps-ins", "phi", 2, 180.0 / np.pi, "gps-ins: heading [deg]"))
    fig, axes = plt.subplots(2, len(ge.GRADES), figsize=(13, 6.2), constrained_layout=True)
    results = {}
    for j, grade in enumerate(ge.GRADES):
        derived = ge.ensembles(grade, seed, runs)
        fixed = ge.ensembles(grade, seed, runs, params=tactical)
        results[grade] = (derived, fixed)
        for i, (name, key, axis, scale, title) in enumerate(rows):
            ax = axes[i, j]
            for ens, color, label in ((derived[name], DERIVED, "derived"),
                                      (fixed[name], TACTICAL, "tactical defaults")):
                e = ens.stats
                ax.plot(e.t, e.rms[key][:, axis] * scale, color=color, lw=1.6,
                        label=f"RMS, {label}")
                ax.plot(e.t, e.sigma[key][:, axis] * scale, color=color, lw=1.2, ls="--",
                        label=f"σ, {label}")
            ax.set_yscale("log")
            ax.set_title(f"{grade}: {title}", fontsize=10)
            if i == 1:
                ax.set_xlabel("time [s]")
            _style(ax)
    axes[0, 0].legend(fontsize=8, loc="lower right")
    fig.suptitle(f"RMS error over {runs} runs (solid) and predicted σ (dashed), seed {seed}",
                 fontsize=11)
    fig.savefig(path, dpi=DPI, metadata={"Software": None})
    plt.close(fig)
    return path, results


def nees_by_grade(results: dict, runs: int, seed: int, path: Path) -> Path:
    """NEES / dof per grade and filter, derived settings and tactical defaults, in the band."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6), constrained_layout=True)
    x = np.arange(len(ge.GRADES))
    for ax, name in zip(axes, ge.FILTERS, strict=True):
        derived = [results[g][0][name].nees_dof for g in ge.GRADES]
        fixed = [results[g][1][name].nees_dof for g in ge.GRADES]
        ax.bar(x - 0.2, derived, 0.38, color=DERIVED, label="derived from the IMU spec")
        ax.bar(x + 0.2, fixed, 0.38, color=TACTICAL, label="tactical defaults")
        lo, hi = results[ge.GRADES[0]][0][name].nees_band
        ax.axhspan(lo, hi, color="0.85", zorder=0, label=f"band, {runs} runs")
        ax.set_yscale("log")
        ax.set_xticks(x, [f"{g}\n({results[g][0][name].duration:.0f} s)" for g in ge.GRADES])
        ax.set_title(f"{name}: mean NEES / dof (9 navigation errors)", fontsize=10)
        _style(ax)
    axes[1].legend(fontsize=8, loc="upper right")
    fig.suptitle(f"vehicle-drive, {runs} runs per grade, seed {seed}", fontsize=11)
    fig.savefig(path, dpi=DPI, metadata={"Software": None})
    plt.close(fig)
    return path


def main(argv: list[str]) -> int:
    runs = int(argv[0]) if argv else 40
    seed = int(argv[1]) if len(argv) > 1 else 0
    IMG.mkdir(exist_ok=True)
    path, results = rms_vs_sigma(runs, seed, IMG / "grades_rms_sigma.png")
    print(f"wrote {path}")
    print(f"wrote {nees_by_grade(results, runs, seed, IMG / 'grades_nees.png')}")
    for grade in ge.GRADES:
        for which, ens in zip(("derived", "tactical"), results[grade], strict=True):
            for e in ens.values():
                print(which, e.row())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
