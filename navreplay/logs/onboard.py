"""Recorded estimators (``run --onboard SOURCE``): the navigation solution a log already holds,
read as a row beside the replayed filters (:class:`~navreplay.io.solution.RecordedSolution`).

Sources
-------
``ekf2``
    PX4's estimate in a ULog file (:func:`navreplay.io.ulog.ekf2_solution`):
    ``vehicle_local_position`` (velocity and its variances), ``vehicle_global_position``
    (position and its variances), ``vehicle_attitude``.
``master_ins``
    The recording's master-INS stream (navreplay's ship scenarios: the ship's INS that
    transfer alignment aligns to): position, velocity and attitude, without variances.
a topic or a file
    Whatever ``--reference`` reads (``nav_msgs/Odometry``, ``PoseStamped``,
    ``PoseWithCovarianceStamped``, ``NavSatFix``, TUM / CSV files, GINS ``.nav`` files; a local
    position placed on the earth as a reference's is), with the variances the messages carry
    (NavSatFix ``position_covariance``, the pose and twist covariances of Odometry).

The row's label is the source as given (a file by its name); its NEES counts the parts that
come with variances.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.core.streams import Recording, StreamKind
from navreplay.geo.rotations import euler_to_quat
from navreplay.io.convert import Convention
from navreplay.io.errors import RecordingError
from navreplay.io.solution import RecordedSolution
from navreplay.io.source import Source
from navreplay.logs.reference import ReferenceError, read_reference, reference_stream

EKF2 = "ekf2"
MASTER_INS = StreamKind.MASTER_INS.value
NAMED = (EKF2, MASTER_INS)
"""The sources named rather than given as a topic or file."""


def onboard_label(spec: str) -> str:
    """The label of the row of ``--onboard spec``: the source as given, a file (a name with a
    suffix: a topic name has no dot) by its name."""
    path = Path(spec)
    return path.name if spec not in NAMED and path.suffix else spec


@contextlib.contextmanager
def _as_onboard(spec: str) -> Iterator[None]:
    """A reference's error, said of ``--onboard``."""
    try:
        yield
    except ReferenceError as exc:
        text = str(exc)
        text = text.removeprefix(f"reference {spec}: ").removeprefix("reference ")
        raise RecordingError(f"--onboard {spec}: {text}") from None


def read_onboard(spec: str, log: Path, recording: Recording, source: Source, *,
                 frames: Mapping[str, Convention], time: str,
                 initial: Mapping[str, Any]) -> tuple[RecordedSolution, str]:
    """The recorded solution ``spec`` names (module docstring) in the log ``log`` (read as
    ``recording`` by ``source``), and one line saying what it holds.

    Raises
    ------
    RecordingError
        The source is not in the log, cannot be a navigation solution, or holds fewer than
        two complete samples.
    """
    label = onboard_label(spec)
    if spec == EKF2:
        from navreplay.io.ulog import ULogSource

        if not isinstance(source, ULogSource):
            raise RecordingError(f"{log}: --onboard {EKF2} reads PX4's estimate from a ULog "
                                 f"file; this log is {source.kind} (name a topic or file "
                                 "instead)")
        solution = source.estimate(label)
    elif spec == MASTER_INS:
        if StreamKind.MASTER_INS not in recording:
            raise RecordingError(f"{log}: --onboard {MASTER_INS}: the log has no master-INS "
                                 "stream")
        m = recording[StreamKind.MASTER_INS]
        nan = np.full((len(m), 3), np.nan)
        solution = RecordedSolution(label, f"{log}: stream {MASTER_INS}", m.t_ns.copy(),
                                    m["pos"].copy(), m["v_n"].copy(), euler_to_quat(m["euler"]),
                                    nan, nan.copy(), nan.copy())
    else:
        with _as_onboard(spec):
            ref = read_reference(spec, log, recording, frames.get("reference"), time)
            stream, _ = reference_stream(ref, recording, initial)
        order = np.argsort(ref.t_ns, kind="stable")
        keep = np.append(True, np.diff(ref.t_ns[order]) > 0)
        rows = order[keep]
        n = len(stream)
        nan = np.full((n, 3), np.nan)

        def part(column: str, width: int) -> np.ndarray:
            return np.asarray(stream[column]) if column in stream.columns \
                else np.full((n, width), np.nan)

        def sigma(value: np.ndarray | None) -> np.ndarray:
            return nan.copy() if value is None else np.asarray(value)[rows]

        solution = RecordedSolution(label, ref.source, stream.t_ns, part("pos", 3),
                                    part("v_n", 3), part("q_nb", 4), sigma(ref.pos_sigma),
                                    sigma(ref.vel_sigma), sigma(ref.att_sigma))
    solution, dropped = solution.complete()
    if len(solution.t_ns) < 2:
        raise RecordingError(f"{log}: --onboard {spec}: fewer than 2 samples with every part "
                             "of its solution")
    return solution, _note(solution, dropped)


def _note(solution: RecordedSolution, dropped: int) -> str:
    parts = solution.parts()
    names = {"pos": "position", "v_n": "velocity", "q_nb": "attitude"}
    sigma = solution.with_sigma()
    nees = (f"variances of {', '.join(names[p] for p in sigma)} (NEES)" if sigma
            else "no variances (no NEES)")
    t = solution.t_ns
    rate = (len(t) - 1) / ((t[-1] - t[0]) * 1e-9) if t[-1] > t[0] else math.nan
    left = f"; {dropped} samples without all of it left out" if dropped else ""
    return (f"onboard {solution.label}: {solution.source}: "
            f"{', '.join(names[p] for p in parts)} at {rate:.3g} Hz, {nees}{left}")
