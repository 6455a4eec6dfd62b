"""ROS 1 bag files (``.bag``), read with ``rosbags`` into the same streams as a rosbag2 bag.

rosbags' AnyReader opens a ROS 1 bag with the message definitions stored in its connection
records and deserialises its messages into the same types as a ROS 2 bag's (``header.stamp``
with ``sec`` / ``nanosec``; the header's ``seq`` is not read), so the gathering, conversion and
checks are those of :mod:`navreplay.io.rosbag`: a ROS 1 bag is one window
(:class:`Bag1Source`). A ROS 1 bag has no metadata file to check its data against; a bag cut
short or with a damaged chunk stops with rosbags' reason, in one line naming the file.
"""

from __future__ import annotations

from pathlib import Path

from navreplay.core.streams import Metadata
from navreplay.io.rosbag import BagCheck, BagSource

MAGIC = b"#ROSBAG V2.0"
"""The first bytes of a ROS 1 bag (format 2.0, every ROS 1 release since 2010)."""


def is_rosbag1(path: Path) -> bool:
    """Whether ``path`` is a ROS 1 bag file (by its first bytes; a ``.bag`` name otherwise)."""
    if not path.is_file():
        return path.suffix == ".bag"
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return path.suffix == ".bag"


def accepts(path: Path) -> bool:
    """Whether ``path`` is a ROS 1 bag."""
    return is_rosbag1(path)


class Bag1Source(BagSource):
    """The streams of a ROS 1 bag as one window (arguments as
    :class:`navreplay.io.rosbag.BagSource`)."""

    kind = "rosbag1"

    def _check(self) -> tuple[Metadata, BagCheck | None]:
        return Metadata(), None  # nothing declares what the file should hold
