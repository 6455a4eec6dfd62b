"""GINS text logs (KF-GINS's IMU increment and GNSS position files, and its 11-column
navigation file) written from the format's description, of rosbag_maker's drive."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from rosbag_maker import TACTICAL, trajectory

from navreplay.geo import earth
from navreplay.geo.rotations import quat_to_euler

SOW0 = 456_000.0
"""GPS seconds of the week at the start of the drive."""
WEEK = 2370


def write_gins(folder: Path, *, duration: float = 90.0, rate: float = 100.0, seed: int = 3,
               gnss_sigma: tuple[float, float, float] = (1.5, 1.5, 3.0),
               gnss_offset: float = 0.0) -> Path:
    """Write ``IMU.txt`` (time, gyro and velocity increments FRD), ``GNSS-RTK.txt`` (time, lat,
    lon, h, std N/E/U; 1 Hz, noise of the stated std) and ``truth.nav`` (10 Hz) into
    ``folder``; the IMU is of the tactical grade of rosbag_maker (seeded). ``gnss_offset`` [s]:
    the fixes are that much after the IMU samples (a receiver not synchronised to the IMU; the
    position is the truth's at the fix time, linearly between the samples)."""
    rng = np.random.default_rng(seed)
    tr = trajectory(duration, rate)
    dt = 1.0 / rate
    w, f = tr.omega_ib_b.copy(), tr.f_b.copy()
    w += np.radians(TACTICAL[0] * rng.standard_normal(3)) / 3600
    w += math.radians(TACTICAL[1]) / 60 / math.sqrt(dt) * rng.standard_normal(w.shape)
    f += TACTICAL[2] * rng.standard_normal(3)
    f += TACTICAL[3] / math.sqrt(dt) * rng.standard_normal(f.shape)
    folder.mkdir(parents=True, exist_ok=True)
    sow = SOW0 + tr.t
    with open(folder / "IMU.txt", "w") as out:
        for k in range(1, len(sow)):  # the row at t_k holds the increments over (t_k-1, t_k]
            out.write(f"{sow[k]:.6f} " + " ".join(f"{x:.12e}" for x in w[k - 1] * dt) + " "
                      + " ".join(f"{x:.12e}" for x in f[k - 1] * dt) + "\n")
    sigma = np.array(gnss_sigma)
    with open(folder / "GNSS-RTK.txt", "w") as out:
        for k in range(0, len(sow), int(rate)):
            noise = sigma[[0, 1, 2]] * rng.standard_normal(3) * np.array([1.0, 1.0, -1.0])
            w = gnss_offset * rate  # between samples k and k + 1
            pos = (1.0 - w) * tr.pos[k] + w * tr.pos[min(k + 1, len(sow) - 1)]
            lat, lon, h = (float(np.ravel(v)[0]) for v in
                           earth.ned_offset_to_lla(*pos, noise))
            out.write(f"{sow[k] + gnss_offset:.3f} {math.degrees(lat):.10f} "
                      f"{math.degrees(lon):.10f} "
                      f"{h:.4f} {sigma[0]:.4f} {sigma[1]:.4f} {sigma[2]:.4f}\n")
    euler = np.degrees(quat_to_euler(tr.q_nb))
    with open(folder / "truth.nav", "w") as out:
        for k in range(0, len(sow), int(rate) // 10):
            out.write(f"{WEEK} {sow[k]:.3f} {math.degrees(tr.pos[k, 0]):.10f} "
                      f"{math.degrees(tr.pos[k, 1]):.10f} {tr.pos[k, 2]:.4f} "
                      + " ".join(f"{v:.6f}" for v in tr.v_n[k]) + " "
                      + " ".join(f"{a:.8f}" for a in euler[k]) + "\n")
    return folder
