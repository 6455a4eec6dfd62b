"""IMU gaps in a replay: found before the run, bridged by the filter or refused.

An IMU interval longer than :data:`GAP_FACTOR` times the median interval is a gap. The samples
after a gap cannot say how the vehicle moved during it, so the engine does not let the filter
integrate the first of them over the whole gap: it asks the filter to *bridge* the gap
(``filter.bridge_imu_gap(t, since)``: bring the state to time ``t`` without IMU samples since
``since``, with a covariance that covers the unknown motion) up to each aiding sample inside the gap
and up to one nominal interval before the next IMU sample, which is then integrated as usual. A
filter without that method cannot be replayed over a gap: any gap stops the run with one line naming
the filter, the recording, the gap and its time. A gap longer than ``max_gap`` stops the run with
one line naming the recording, the topic and the time; so does an IMU stream too short to replay.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from navreplay.io.checks import GAP_FACTOR

MAX_IMU_GAP = 6.0
"""Default longest IMU gap a replay bridges [s] (``--max-imu-gap``): about the longest over
which a turning land vehicle's heading change stays within the small-angle error model of the
filters (heading 1-sigma 0.6 rad at the INS filters' default ``gap_rate_sigma``)."""
MIN_IMU_SAMPLES = 10
"""Fewer IMU samples give no usable rate or motion: the recording is refused."""


def check_max_gap(max_gap: float | None) -> float:
    """The longest IMU gap allowed [s] (None: :data:`MAX_IMU_GAP`); ``ValueError`` unless a
    positive number."""
    limit = MAX_IMU_GAP if max_gap is None else float(max_gap)
    if not limit > 0.0:
        raise ValueError(f"--max-imu-gap must be a positive number of seconds, got {max_gap}")
    return limit


def find_gaps(
    t: np.ndarray, max_gap: float | None, where: str, unbridged: str | None = None,
    nominal: float | None = None,
) -> tuple[np.ndarray, float]:
    """Indices of the IMU samples that follow a gap, and the nominal (median) interval [s].

    Parameters
    ----------
    t : ndarray, shape (k,)
        IMU sample times [s], increasing.
    max_gap : float or None
        Longest gap allowed [s] (None: :data:`MAX_IMU_GAP`).
    where : str
        Recording and topic, for messages.
    unbridged : str, optional
        Name of a filter that cannot bridge a gap (it has no ``bridge_imu_gap``): any gap is
        refused.
    nominal : float, optional
        The nominal interval when already known (a later window of a streamed replay); the
        samples need not then be many.

    Raises
    ------
    ValueError
        Too few samples, a gap longer than ``max_gap``, or any gap for an ``unbridged`` filter
        (one line naming ``where`` and the time).
    """
    limit = check_max_gap(max_gap)
    if nominal is None and len(t) < MIN_IMU_SAMPLES:
        raise ValueError(f"{where}: only {len(t)} IMU sample(s); at least {MIN_IMU_SAMPLES} "
                         "are needed to replay a filter")
    dt = np.diff(t)
    nominal = float(np.median(dt)) if nominal is None else nominal
    gaps = np.flatnonzero(dt > GAP_FACTOR * nominal) + 1
    if gaps.size:
        worst = int(gaps[np.argmax(dt[gaps - 1])])
        length = float(dt[worst - 1])
        if unbridged is not None:
            raise ValueError(
                f"{where}: no IMU sample for {length:.3f} s after t = {t[worst - 1]:.3f} s, "
                f"and filter {unbridged!r} cannot bridge an IMU gap (it has no bridge_imu_gap;"
                " --max-imu-gap applies to filters that have)"
            )
        if length > limit:
            raise ValueError(
                f"{where}: no IMU sample for {length:.3f} s after t = {t[worst - 1]:.3f} s, "
                f"longer than the {limit:g} s a filter may bridge (--max-imu-gap)"
            )
    return gaps.astype(np.int64), nominal


class ImuFeeder:
    """Hands IMU samples to a filter in blocks, bridging the gaps (see the module docstring).

    Parameters
    ----------
    propagate : callable
        ``propagate(t, columns)`` of the filter.
    bridge : callable or None
        ``bridge_imu_gap(t, since)`` of the filter (None only when there is no gap).
    t : ndarray, shape (k,)
        Sample times [s].
    columns : sequence of (name, ndarray)
    gaps : ndarray of int
        Indices of the samples that follow a gap.
    nominal : float
        Nominal sample interval [s].
    """

    def __init__(
        self,
        propagate: Callable[[np.ndarray, Mapping[str, np.ndarray]], Any],
        bridge: Callable[[float, float], Any] | None,
        t: np.ndarray,
        columns: Sequence[tuple[str, np.ndarray]],
        gaps: np.ndarray,
        nominal: float,
    ) -> None:
        self._propagate = propagate
        self._bridge = bridge
        self._t = t
        self._columns = columns
        self._gaps = gaps.tolist()
        self._nominal = nominal
        self._g = 0
        self.start = 0
        """Samples handed over so far."""
        self._bridged = -np.inf

    def advance(self, end: int, t_now: float) -> None:
        """Hand over samples ``[start, end)``; when ``t_now`` falls in a gap, bridge up to it."""
        gaps = self._gaps
        while True:
            stop = end
            pending = self._g < len(gaps)
            if pending and gaps[self._g] < end:
                stop = gaps[self._g]
            if stop > self.start:
                a, b = self.start, stop
                self._propagate(self._t[a:b], {k: v[a:b] for k, v in self._columns})
                self.start = stop
            if not (pending and gaps[self._g] == self.start):
                return
            if self.start < end:  # across the gap: up to one interval before the next sample
                self._bridge_to(float(self._t[self.start]) - self._nominal)
                self._g += 1
                continue
            self._bridge_to(t_now)  # an aiding sample inside the gap
            return

    def clean(self, end: int) -> bool:
        """Whether samples ``[start, end)`` hold no gap to bridge (:meth:`take` may hand them
        over in one block)."""
        return not (self._g < len(self._gaps) and self._gaps[self._g] <= end)

    def take(self, end: int) -> tuple[np.ndarray, dict[str, np.ndarray], int]:
        """Samples ``[start, end)`` as (t, columns, start) for a batch; they count as handed
        over. Only when :meth:`clean`."""
        a = self.start
        self.start = max(end, a)
        return self._t[a:end], {k: v[a:end] for k, v in self._columns}, a

    def _bridge_to(self, t: float) -> None:
        if self._bridge is not None and t > self._bridged and t > self._t[self.start - 1]:
            self._bridge(t, float(self._t[self.start - 1]))
            self._bridged = t
