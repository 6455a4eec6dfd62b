"""Logs navreplay did not write: topic and frame mapping, frame checks, initialisation, references.

:func:`navreplay.logs.prepare.open_log` turns a ROS 2 bag (MCAP file, rosbag2 folder, ``.db3``)
and :class:`navreplay.logs.options.LogOptions` (``--topic``, ``--frame``, ``--init``,
``--reference`` and the ``[topics]``, ``[frames]``, ``[initial]`` tables) into the windows of its
streams the filters replay unchanged (a :class:`~navreplay.logs.prepare.LogSource`): its vectors
in NED/FRD, checked against gravity and the earth's field, a reference as its truth stream and an
initial solution in ``metadata.initial_nav``. docs/real-logs.md walks through it.
"""
