"""TUM trajectories (evo's format): ``timestamp tx ty tz qx qy qz qw``."""

from __future__ import annotations

import numpy as np

from navreplay.export.frames import BODY_FRAME, WORLD_FRAME, Poses

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
