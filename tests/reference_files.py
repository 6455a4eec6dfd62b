"""Reference files as other tools write them, for tests that pass ``--reference``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def write_reference_csv(path: Path, t_ns: np.ndarray, lla: np.ndarray, v_n: np.ndarray,
                        euler: np.ndarray, *, t0_ns: int | None = None) -> Path:
    """A geodetic reference CSV: ``t_ns`` (absolute), or ``t`` [s] since ``t0_ns`` when given;
    latitude and longitude in degrees, h [m], NED velocity [m/s], roll, pitch and yaw [deg]
    (``lla`` and ``euler`` in radians)."""
    time = "t_ns" if t0_ns is None else "t"
    rows = [f"{time},lat_deg,lon_deg,h,v_N,v_E,v_D,roll_deg,pitch_deg,yaw_deg"]
    for t, p, v, e in zip(t_ns, lla, v_n, euler, strict=True):
        stamp = str(int(t)) if t0_ns is None else f"{(int(t) - t0_ns) * 1e-9:.3f}"
        rows.append(f"{stamp},{math.degrees(p[0]):.10f},{math.degrees(p[1]):.10f},{p[2]:.4f},"
                    + ",".join(f"{x:.6f}" for x in v) + ","
                    + ",".join(f"{math.degrees(x):.7f}" for x in e))
    path.write_text("\n".join(rows) + "\n")
    return path
