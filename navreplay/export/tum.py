"""TUM trajectories (evo's format): ``timestamp tx ty tz qx qy qz qw``."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from navreplay.export.frames import BODY_FRAME, WORLD_FRAME, Poses
from navreplay.export.numbers import SECONDS_NS, format_rows, row_blocks

TUM_HEADER = ("# timestamp tx ty tz qx qy qz qw\n"
              f"# position [m] in the local ENU frame '{WORLD_FRAME}' (see manifest.json);"
              f" orientation of '{BODY_FRAME}' (FLU) in it\n")
"""The comment lines that open a TUM file."""


def tum_lines(poses: Poses) -> str:
    """evo's TUM format: one ``timestamp tx ty tz qx qy qz qw`` line per pose, single spaces,
    no trailing delimiter. Timestamps are absolute seconds with nanosecond digits."""
    return format_rows(_tum_columns(poses), sep=" ")


def tum_blocks(poses: Poses) -> Iterator[bytes | memoryview]:
    """:func:`tum_lines` as ASCII bytes, a block of lines at a time (for a binary file)."""
    return row_blocks(_tum_columns(poses), sep=" ")


def _tum_columns(poses: Poses) -> list[tuple[np.ndarray, str]]:
    return ([(np.asarray(poses.stamps_ns, dtype=np.int64), SECONDS_NS)]
            + [(poses.p_enu[:, i], "%.6f") for i in range(3)]
            + [(poses.q_xyzw[:, i], "%.9f") for i in range(4)])
