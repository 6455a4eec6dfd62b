"""Recordings as MCAP files: ROS 2 profile, CDR messages, ros2msg schemas.

One topic per stream kind (:data:`TOPICS`), standard ROS 2 messages where the meaning matches and
``navreplay_msgs`` messages otherwise, plus a ``navreplay`` metadata record with the scenario,
parameters, seed and true error states. docs/recording-format.md describes every topic, field,
unit and frame.

>>> import numpy as np
>>> from navreplay.streams import Metadata, Recording, Stream
>>> imu = Stream("imu", np.arange(1, 4) * 5_000_000, {"f_b": np.zeros((3, 3))})
>>> TOPICS["imu"]
'/imu'

Writing is atomic and refuses to replace a file unless ``force=True``; reading is bulk (numpy) for
the fixed-layout messages, salvages truncated files with a :class:`RecordingWarning`, and reports
CRC mismatches and bad samples as :class:`RecordingError` naming the file, topic and time.
"""

from navreplay.io.errors import RecordingError, RecordingExistsError, RecordingWarning
from navreplay.io.info import RecordingInfo, TopicInfo, format_info, recording_info
from navreplay.io.reader import read_recording
from navreplay.io.schemas import TOPICS
from navreplay.io.writer import write_recording

__all__ = [
    "TOPICS",
    "RecordingError",
    "RecordingExistsError",
    "RecordingInfo",
    "RecordingWarning",
    "TopicInfo",
    "format_info",
    "read_recording",
    "recording_info",
    "write_recording",
]
