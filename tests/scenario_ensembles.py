"""Ensembles of ``ins`` and ``gps-ins`` where ``vehicle-drive`` goes beyond a level car drive
with a white-noise receiver: a time-correlated GNSS position error, banked (coordinated) turns
at aircraft speeds, GNSS outages on a MEMS IMU (docs/methods/ins.md §5).

Each case is a set of ``vehicle-drive`` parameters and the filters run over it with the
settings they derive from the recordings. An ensemble passes when

- its NEES / dof and the nine navigation RMS / sigma lie in the bands of
  tests/grade_ensembles.py (each run one sample; false alarm 0.001 for the NEES and for the
  nine together);
- the time-averaged NEES and the RMS / sigma of every scored state (biases, scale factors,
  misalignments, GNSS errors) pass the checks of docs/methods/consistency.md §7 (effective
  samples over correlated epochs; false alarm 0.001 for the NEES and for all states together,
  0.001 / k each);
- with outages, the horizontal error at the end of each outage: its RMS over the runs over the
  RMS predicted sigma lies in the band of one sample per run (false alarm 0.001 over the
  outages together).

Seeds: 7000-7999 were used to explore and to choose the models; 8100 (default suite) and 9300
(slow) to validate them. (9200 was validated once, with ``ins`` still without the roll, pitch
and load-factor states; its NEES / dof of 1.15 at 60 m/s, near the band's edge, led to
exploring them on 7000-7299, so it is no longer a validation seed.)

Run as a script to print the table of docs/methods/ins.md §5::

    python tests/scenario_ensembles.py [RUNS] [SEED] [CASE ...]
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Any

import grade_ensembles as ge

from navreplay.metrics import consistency

FAST_SEED = 8100
SLOW_SEED = 9300


@dataclasses.dataclass(frozen=True)
class Case:
    """A ``vehicle-drive`` configuration and the filters checked on it."""

    name: str
    scenario: dict[str, Any]
    filters: tuple[str, ...] = ("gps-ins",)
    grade: str = "tactical"
    fast: tuple[int, float] = (20, 120.0)
    """Runs and drive length [s] of the default-suite ensemble."""
    slow_length: float = 300.0
    fast_scenario: dict[str, Any] = dataclasses.field(default_factory=dict)
    """Parameters that differ on the default-suite's shorter drive (its outages)."""

    def values(self, fast: bool) -> dict[str, Any]:
        return {**self.scenario, **(self.fast_scenario if fast else {})}


CASES = {c.name: c for c in (
    Case("gnss-gm-0.5", {"gps_pos_gm_sigma": 0.5}),
    Case("gnss-gm-2", {"gps_pos_gm_sigma": 2.0}),
    Case("gnss-gm-5-tau-60", {"gps_pos_gm_sigma": 5.0, "gps_pos_gm_tau": 60.0}),
    Case("gnss-gm-5-tau-600", {"gps_pos_gm_sigma": 5.0, "gps_pos_gm_tau": 600.0}),
    Case("coordinated-40", {"turn_mode": "coordinated", "cruise_speed": 40.0},
         ("ins", "gps-ins"), fast=(20, 300.0)),
    Case("coordinated-60", {"turn_mode": "coordinated", "cruise_speed": 60.0},
         ("ins", "gps-ins"), fast=(20, 300.0)),
    Case("mems-outages", {"gps_outages": "100:30,200:60"}, grade="mems", fast=(20, 150.0),
         fast_scenario={"gps_outages": "30:30,80:60"}),
)}
"""The cases of docs/methods/ins.md §5. The coordinated turns bank at most 45 deg (the drive's
``max_bank_deg``): at 60 m/s the 90-deg turn is flown over 19.2 s instead of 16 s."""

REQUIRED = ("gnss-gm-0.5", "gnss-gm-2", "coordinated-40", "coordinated-60", "mems-outages")
"""The cases the default suite checks (the others are measured in the slow suite)."""

OLD_MODEL = {"gyro_roll_pitch_states": False, "accel_load_states": False,
             "gps_pos_gm_sigma": 0.0}
"""``gps-ins`` as it was: gyro scale factor and misalignment of the column z only,
accelerometer columns x and y only, the GNSS error taken as white."""


def run(case: Case, seed: int, runs: int, length: float, *, fast: bool = False,
        variants: tuple[ge.Variant, ...] = ()) -> dict[str, ge.Ensemble]:
    """The ensembles of ``case`` (and of ``variants``, on the same recordings)."""
    return ge.ensembles(case.grade, seed, runs, case.filters + variants, length=length,
                        lengths={}, scenario=case.values(fast))


def outages(e: ge.Ensemble) -> list[dict]:
    """The ensemble's scores of each GNSS outage of the drive (the summary's ``gnss_outages``,
    :func:`navreplay.metrics.outages.ensemble_outages`): the RMS over the runs of the
    horizontal error at the end over the RMS predicted horizontal sigma there, in its band."""
    return e.stats.summary().get("gnss_outages", [])


def problems(e: ge.Ensemble) -> list[str]:
    """What fails in ensemble ``e`` (empty: consistent)."""
    out = []
    if not e.nees_inside:
        out.append(f"NEES / dof {e.nees_dof:.3f} outside {e.nees_band}")
    out += [f"RMS / sigma {k} {v} outside {e.ratio_band}" for k, v in e.ratios_outside().items()]
    c = e.stats.consistency
    if c.nees is not None and not c.nees.passed:
        out.append(f"time-averaged NEES {c.nees.mean / c.nees.dof:.3f} outside "
                   f"{c.nees.band[0] / c.nees.dof:.3f}-{c.nees.band[1] / c.nees.dof:.3f}")
    fa = consistency.CHECK_FALSE_ALARM / max(len(c.scale), 1)
    for name, s in c.scale.items():
        check = consistency.scale_check(s.ratio**2, s.samples, fa)
        if not check.passed:
            out.append(f"{name}: RMS / sigma {s.ratio:.2f} outside "
                       f"{check.band[0]:.2f}-{check.band[1]:.2f}")
    for o in outages(e):
        if "t_end" not in o:
            out.append(f"outage {o['start']:g}-{o['end']:g} s: no estimate inside")
        elif not o["passed"]:
            out.append(f"outage ending at {o['end']:g} s: horizontal RMS / sigma "
                       f"{o['ratio_end_h']:.2f} outside {o['band'][0]:.2f}-{o['band'][1]:.2f}")
    return out


def row(case: Case, e: ge.Ensemble) -> str:
    """A row of the table in docs/methods/ins.md §5."""
    r = " | ".join(" ".join(f"{x:.2f}" for x in e.ratios[k]) for k in ge.AXES)
    c = e.stats.consistency
    others = {k: v.ratio for k, v in c.scale.items() if k not in c.nees_names}
    gm = " ".join(f"{others[k]:.2f}" for k in ("gm_N", "gm_E", "gm_D") if k in others)
    rest = {k: v for k, v in others.items() if not k.startswith("gm_")}
    span = f"{min(rest.values()):.2f}-{max(rest.values()):.2f}" if rest else ""
    ends = " ".join(f"{o['ratio_end_h']:.2f}" for o in outages(e) if "t_end" in o)
    return (f"| {case.name} | {e.filter} | {e.runs} x {e.duration:.0f} s | {e.seed}-"
            f"{e.seed + e.runs - 1} | {e.nees_dof:.3f} | {e.nees_band[0]:.3f}-"
            f"{e.nees_band[1]:.3f} | {r} | {span} | {gm} | {ends} |")


def main(argv: list[str]) -> int:
    runs = int(argv[0]) if argv else 100
    seed = int(argv[1]) if len(argv) > 1 else SLOW_SEED
    names = argv[2:] or list(CASES)
    print("| case | filter | runs | seeds | NEES / dof | band | RMS / sigma pos N E D | "
          "vel N E D | att N E D | other states | GNSS GM N E D | outage ends (H) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        case = CASES[name]
        for e in run(case, seed, runs, case.slow_length).values():
            print(row(case, e), flush=True)
            for p in problems(e):
                print(f"  ! {p}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
