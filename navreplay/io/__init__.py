"""Recordings as MCAP files: ROS 2 profile, CDR messages, ros2msg schemas.

One topic per stream kind (:data:`TOPICS`), standard ROS 2 messages where the meaning matches and
``navreplay_msgs`` messages otherwise, plus a ``navreplay`` metadata record with the scenario,
parameters, seed and true error states. docs/recording-format.md describes every topic, field,
unit and frame.

>>> import tempfile
>>> import numpy as np
>>> from navreplay.io import TOPICS, read_recording, recording_info, write_recording
>>> from navreplay.io.synthetic import random_recording
>>> rec = random_recording(np.random.default_rng(0), duration_s=1.0, kinds=["imu", "truth"])
>>> with tempfile.TemporaryDirectory() as tmp:
...     path = write_recording(f"{tmp}/demo.mcap", rec)
...     back = read_recording(path)
...     info = recording_info(path)
>>> np.array_equal(back["imu"]["f_b"], rec["imu"]["f_b"]), back.metadata == rec.metadata
(True, True)
>>> [(t.topic, t.count) for t in info.topics]
[('/imu', 200), ('/truth', 200)]
>>> TOPICS["gps"]
'/gps/fix'

Writing is atomic and refuses to replace a file unless ``force=True``; reading is bulk (numpy) for
the fixed-layout messages, salvages truncated files with a :class:`RecordingWarning`, and reports
CRC mismatches and bad samples as :class:`RecordingError` naming the file, topic and time.
:func:`open_recording` decides a file's kind once (MCAP file, rosbag2 bag) and reads it as time
windows of its streams (:mod:`navreplay.io.source`); :func:`read_recording` reads it whole.
"""

import importlib
from typing import TYPE_CHECKING, Any

from navreplay.io.errors import RecordingError, RecordingExistsError, RecordingWarning

if TYPE_CHECKING:
    from navreplay.io.files import open_recording, read_recording
    from navreplay.io.info import RecordingInfo, TopicInfo, format_info, recording_info
    from navreplay.io.schemas import TOPICS
    from navreplay.io.source import ReadOptions
    from navreplay.io.writer import write_recording

_LAZY = {
    "open_recording": "navreplay.io.files",
    "read_recording": "navreplay.io.files",
    "RecordingInfo": "navreplay.io.info",
    "TopicInfo": "navreplay.io.info",
    "format_info": "navreplay.io.info",
    "recording_info": "navreplay.io.info",
    "TOPICS": "navreplay.io.schemas",
    "ReadOptions": "navreplay.io.source",
    "write_recording": "navreplay.io.writer",
}
"""Names imported at their first use: the readers and writers load mcap and rosbags, which a
command that only writes files (:mod:`navreplay.io.outputs`) or handles signals
(:mod:`navreplay.io.lifecycle`) does not need."""


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'navreplay.io' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


__all__ = [
    "TOPICS",
    "RecordingError",
    "RecordingExistsError",
    "ReadOptions",
    "RecordingInfo",
    "RecordingWarning",
    "TopicInfo",
    "format_info",
    "open_recording",
    "read_recording",
    "recording_info",
    "write_recording",
]
