"""Sample checks shared by the writer and the reader: finite values, increasing time, physical
ranges, gaps (those of declared GNSS outages excused), frame ids.

Byte damage in a file without checksums (an uncompressed MCAP without CRCs, a rosbag2 sqlite or
MCAP bag) reads without error; what it changes mostly shows as a value no sensor gives (an
exponent bit flipped), a non-finite value or a time that goes back. So every sample is checked
against generous physical ranges (:data:`PHYSICAL_RANGES`; the IMU's against its measurement
range, :class:`ImuRange`, which ``--imu-range`` narrows to a datasheet's) and a value outside
stops the read with one line naming the file, topic and time.

The IMU range and whether ``--frame`` overrides frame ids are chosen per command
(:class:`ReadPolicy`, set for a block with :func:`read_policy`): the readers consult
:func:`current_policy` wherever they check.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import math
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

import numpy as np

from navreplay.core.outages import recorded_outages
from navreplay.core.streams import Stream, StreamKind
from navreplay.io.convert import BODY_KINDS, NAV_KINDS, Convention, assumed_convention
from navreplay.io.errors import RecordingError

GAP_FACTOR = 5.0
"""An interval longer than this many times a topic's median interval counts as a gap."""

STANDARD_GRAVITY = 9.80665


@dataclasses.dataclass(frozen=True)
class ImuRange:
    """Measurement range of an IMU, per axis: a sample beyond it is damage, not motion.

    The defaults admit any navigation IMU, gun-hardened MEMS included (the widest rate ranges
    sold are about 20,000 deg/s, the widest accelerometer ranges of navigation units a few
    hundred g): 20,000 deg/s and 200 g. ``--imu-range gyro=2000,accel=16`` (deg/s, g) sets a
    datasheet's.

    Attributes
    ----------
    gyro : float
        Largest angular rate magnitude per axis [rad/s].
    accel : float
        Largest specific force magnitude per axis [m/s^2].
    """

    gyro: float = math.radians(20_000.0)
    accel: float = 200.0 * STANDARD_GRAVITY

    def __post_init__(self) -> None:
        for name in ("gyro", "accel"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int | float) and 0 < v < math.inf):
                raise ValueError(f"IMU range {name} must be a positive number, got {v!r}")

    def describe(self) -> str:
        return (f"gyro {math.degrees(self.gyro):g} deg/s, accel "
                f"{self.accel / STANDARD_GRAVITY:g} g")


@dataclasses.dataclass(frozen=True)
class ReadPolicy:
    """How a command checks what it reads.

    Attributes
    ----------
    imu_range : ImuRange
    force_frames : bool
        ``--force-frame``: read topics in the axes ``--frame`` declares even where a frame id
        names other axes (else that is an error).
    """

    imu_range: ImuRange = ImuRange()
    force_frames: bool = False


DEFAULT_POLICY = ReadPolicy()
_POLICY: contextvars.ContextVar[ReadPolicy | None] = contextvars.ContextVar(
    "navreplay_read_policy", default=None)


def current_policy() -> ReadPolicy:
    """The policy of the block being run (:func:`read_policy`), else the defaults."""
    return _POLICY.get() or DEFAULT_POLICY


@contextlib.contextmanager
def read_policy(policy: ReadPolicy | None) -> Iterator[None]:
    """Read with ``policy`` inside the block (None: keep the current one)."""
    if policy is None:
        yield
        return
    token = _POLICY.set(policy)
    try:
        yield
    finally:
        _POLICY.reset(token)


PHYSICAL_RANGES: dict[tuple[StreamKind, str], tuple[str, float, float, str]] = {
    (StreamKind.GPS, "pos"): ("latlon", -math.pi / 2, math.pi / 2, "rad"),
    (StreamKind.MASTER_INS, "pos"): ("latlon", -math.pi / 2, math.pi / 2, "rad"),
    (StreamKind.TRUTH, "pos"): ("latlon", -math.pi / 2, math.pi / 2, "rad"),
    (StreamKind.MASTER_INS, "v_n"): ("abs", 0.0, 2e4, "m/s"),
    (StreamKind.GPS_VEL, "v_n"): ("abs", 0.0, 2e4, "m/s"),
    (StreamKind.TRUTH, "v_n"): ("abs", 0.0, 2e4, "m/s"),
    (StreamKind.MASTER_INS, "euler"): ("abs", 0.0, 2 * math.pi + 1e-6, "rad"),
    (StreamKind.TRUTH, "q_nb"): ("abs", 0.0, 1.0 + 1e-6, ""),
    (StreamKind.MAG, "m_b"): ("abs", 0.0, 1e-2, "T"),
    (StreamKind.SPEED_LOG, "rpm"): ("abs", 0.0, 1e6, "rev/min"),
    (StreamKind.DEPTH, "depth"): ("interval", -1e4, 1.2e4, "m"),
}
"""Generous physical ranges of the standard columns, (kind, column) -> (how, low, high, unit):
``abs`` bounds the magnitude of each component; ``interval`` the value; ``latlon`` a
latitude, longitude and height (latitude within the poles, longitude within +-2 pi, height
within -20 km .. 100,000 km). Velocities up to 20 km/s, fields up to 10 mT (the earth's is about
50 uT; a field in gauss instead of tesla is caught), a master's Euler angles within one turn."""


def _beyond(kind: StreamKind, name: str, flat: np.ndarray,
            imu: ImuRange) -> tuple[np.ndarray, str] | None:
    """Rows of a column beyond its physical range, and the range in words."""
    with np.errstate(invalid="ignore"):
        if kind is StreamKind.IMU and name in ("omega_ib_b", "f_b"):
            limit = imu.gyro if name == "omega_ib_b" else imu.accel
            unit = "rad/s" if name == "omega_ib_b" else "m/s^2"
            return ((np.abs(flat) > limit).any(axis=1),
                    f"the IMU's range (+-{limit:.6g} {unit} per axis; {imu.describe()}; "
                    "--imu-range sets the sensor's)")
        spec = PHYSICAL_RANGES.get((kind, name))
        if spec is None:
            return None
        how, lo, hi, unit = spec
        if how == "abs":
            return np.asarray((np.abs(flat) > hi).any(axis=1)), f"+-{hi:g} {unit}"
        if how == "interval":
            return np.asarray(((flat < lo) | (flat > hi)).any(axis=1)), f"{lo:g} .. {hi:g} {unit}"
        bad = ((np.abs(flat[:, 0]) > hi) | (np.abs(flat[:, 1]) > 2 * math.pi)
               | (flat[:, 2] < -2e4) | (flat[:, 2] > 1e8))
        return bad, "latitude +-pi/2, longitude +-2 pi rad, height -2e4 .. 1e8 m"


def when(t_ns: int, t0_ns: int) -> str:
    """``t = <s> s (<ns> ns)``: a time relative to the recording start and absolute."""
    return f"t = {(int(t_ns) - int(t0_ns)) * 1e-9:.9f} s ({int(t_ns)} ns)"


def first_problem(stream: Stream, t0_ns: int, ranges: bool = True) -> str | None:
    """Describe the first bad sample or timestamp, or return None.

    Bad: a non-finite value, a negative standard deviation (columns named ``*_sigma``), with
    ``ranges`` a value beyond its physical range (:data:`PHYSICAL_RANGES`, the IMU's
    :class:`ImuRange` of the current :class:`ReadPolicy`; the readers and the writer check
    them, the engine's check of an in-memory recording does not), a timestamp that repeats or
    goes backwards.
    """
    t = stream.t_ns
    n = len(t)
    if n == 0:
        return None
    bad_row = n
    bad_col = ""
    bad_what = ""
    imu = current_policy().imu_range
    for name, col in stream.columns.items():
        flat = col.reshape(n, -1)
        good = np.isfinite(flat).all(axis=1)
        what = "non-finite value"
        if name.endswith("_sigma"):
            good &= ~(flat < 0).any(axis=1)
            what = "non-finite or negative value"
        beyond = _beyond(stream.kind, name, flat, imu) if ranges else None
        bad = ~good if beyond is None else ~good | beyond[0]
        if bad.any():
            row = int(np.argmax(bad))
            if row < bad_row:
                bad_row, bad_col = row, name
                bad_what = (what if not good[row] or beyond is None
                            else f"value beyond {beyond[1]}")
    step = np.diff(t)
    back = np.flatnonzero(step <= 0)
    if back.size and back[0] + 1 <= bad_row:
        i = int(back[0]) + 1
        how = "repeats" if t[i] == t[i - 1] else "goes backwards"
        return (
            f"timestamp {how} at {when(t[i], t0_ns)}; the previous message is at "
            f"{when(t[i - 1], t0_ns)}"
        )
    if bad_row < n:
        value = stream.columns[bad_col][bad_row]
        return f"{bad_what} in column {bad_col!r} ({value}) at {when(t[bad_row], t0_ns)}"
    return None


def declared_outages(kind: StreamKind, extra: Mapping[str, Any], t0_ns: int) -> np.ndarray:
    """The spans a recording declares its ``kind`` stream silent in, (K, 2) int64 [ns]: the
    GNSS outages of ``metadata.extra["gnss_outages"]`` (:mod:`navreplay.core.outages`) for the
    GNSS fix and velocity streams, none for the others. A malformed entry declares nothing here
    (the scoring, which reads the same entry, names it)."""
    if kind not in (StreamKind.GPS, StreamKind.GPS_VEL):
        return NO_SPANS
    try:
        spans = recorded_outages(extra)
    except ValueError:
        return NO_SPANS
    if not spans:
        return NO_SPANS
    return t0_ns + np.round(np.asarray(spans, dtype=float) * 1e9).astype(np.int64)


NO_SPANS = np.zeros((0, 2), dtype=np.int64)
"""No declared outage."""


def gap_steps(t_ns: np.ndarray, median: float, factor: float = GAP_FACTOR,
              declared: np.ndarray = NO_SPANS) -> np.ndarray:
    """Indices ``i`` of the intervals ``t_ns[i] -> t_ns[i + 1]`` longer than ``factor`` x
    ``median`` [ns] that no declared outage explains (:func:`declared_outages`): an outage
    explains a gap whose two samples lie within ``factor`` x ``median`` of its span."""
    step = np.diff(t_ns)
    gaps = np.flatnonzero(step > factor * median)
    if gaps.size and len(declared):
        slack = factor * median
        before, after = t_ns[gaps][:, None], t_ns[gaps + 1][:, None]
        explained = ((before >= declared[:, 0] - slack)
                     & (after <= declared[:, 1] + slack)).any(axis=1)
        gaps = gaps[~explained]
    return gaps


def gap_report(stream: Stream, t0_ns: int, factor: float = GAP_FACTOR,
               declared: np.ndarray = NO_SPANS) -> str | None:
    """Describe intervals longer than ``factor`` x the median interval that no ``declared``
    outage explains (:func:`gap_steps`), or return None."""
    if len(stream) < 3:
        return None
    step = np.diff(stream.t_ns)
    median = float(np.median(step))
    if median <= 0:
        return None
    gaps = gap_steps(stream.t_ns, median, factor, declared)
    if not gaps.size:
        return None
    worst = int(gaps[np.argmax(step[gaps])])
    return gap_text(gaps.size, median, int(step[worst]), int(stream.t_ns[worst]), t0_ns, factor)


def gap_text(count: int, median_ns: float, longest_ns: int, start_ns: int, t0_ns: int,
             factor: float = GAP_FACTOR) -> str:
    """The line of :func:`gap_report`: how many gaps, the median interval, the longest."""
    return (
        f"{count} gap(s) longer than {factor:g} x the median interval ({median_ns * 1e-9:.6g} s); "
        f"the longest, {longest_ns * 1e-9:.6g} s, starts at {when(start_ns, t0_ns)}"
    )


# --------------------------------------------------------------------------------------------
# frame ids

_NAMED = {kind: (Convention.FRD, Convention.FLU) for kind in BODY_KINDS} | {
    kind: (Convention.NED, Convention.ENU) for kind in NAV_KINDS}


def named_convention(kind: StreamKind, frame_id: str) -> Convention | None:
    """The axes a frame id names outright (``imu_frd``, ``base_link_flu``, ``ned``, ``odom_enu``;
    REP-103 suffixes), or None when it does not (``imu_link``: FLU only by convention)."""
    name = frame_id.lower()
    for conv in _NAMED.get(kind, ()):
        if name == conv.value or name.endswith(f"_{conv.value}"):
            return conv
    return None


def check_frame_ids(kind: StreamKind, label: str, frame_ids: Iterable[str],
                    declared: Convention | None, used: str = "") -> str | None:
    """Check the frame ids of a topic against each other and against ``--frame``.

    For a stream with frame-dependent vectors (IMU, magnetometer, GNSS velocity): frame ids
    that change between messages and with them the axes they give (``imu_frd``, then
    ``imu_link``, FLU by REP-103) are an error unless ``--frame`` declares the axes (the data
    cannot tell which messages are in which axes), and a declaration contradicting a frame id
    that names its axes outright is an error unless the :class:`ReadPolicy` forces frames.

    Returns
    -------
    str or None
        A note when the frame id changes and that is no error (``used``: the one kept).

    Raises
    ------
    RecordingError
    """
    ids = sorted(set(frame_ids))
    note = f"frame_id changes between messages ({ids}); using {used!r}" if len(ids) > 1 \
        else None
    if kind not in _NAMED:
        return note
    axes = "|".join(c.value for c in _NAMED[kind])
    if len({assumed_convention(kind, i)[0] for i in ids}) > 1 and declared is None:
        raise RecordingError(
            f"{label}: frame_id changes between messages ({ids}), and with it the axes "
            f"their names give: which axes the vectors are in cannot be told; declare them "
            f"with --frame {kind.value}={axes} (or [frames])")
    if declared is not None and not current_policy().force_frames:
        for frame_id in ids:
            named = named_convention(kind, frame_id)
            if named is not None and named is not declared:
                raise RecordingError(
                    f"{label}: --frame {kind.value}={declared.value} contradicts frame id "
                    f"{frame_id!r}, which names {named.value.upper()} axes; drop the "
                    "declaration, or add --force-frame to read the topic as declared")
    return note
