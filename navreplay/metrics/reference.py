"""What runs are scored against: a truth-like stream (the recording's truth, or an external
reference) with whichever of ``pos``, ``v_n``, ``q_nb`` it has, plus the true constants of
``metadata.true_errors``, interpolated to the estimate times."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

from navreplay.core.outages import recorded_outages
from navreplay.core.streams import Recording, Stream, StreamKind, seconds
from navreplay.geo.rotations import wrap_angle
from navreplay.metrics.errors import position_error_ned


@dataclasses.dataclass(frozen=True)
class Reference:
    """What runs are scored against.

    Attributes
    ----------
    stream : Stream
        Truth-like columns: any of ``pos`` (lat, lon [rad], h [m]), ``v_n`` [m/s], ``q_nb``
        (scalar first), and further columns that ``TruthColumn`` states name.
    t0_ns : int
        Recording start [ns]: filter time 0.
    true_errors : mapping
        The constants ``TrueConstant`` states name (``metadata.true_errors``).
    outages : tuple of (start, end)
        The recording's GNSS outages [s since its start] (``metadata.extra["gnss_outages"]``,
        :func:`navreplay.core.outages.recorded_outages`), scored one by one
        (:mod:`navreplay.metrics.outages`).
    """

    stream: Stream
    t0_ns: int
    true_errors: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    outages: tuple[tuple[float, float], ...] = ()

    @classmethod
    def of(cls, source: Recording | Reference) -> Reference:
        """The reference of a recording (its truth stream and true errors)."""
        if isinstance(source, Reference):
            return source
        if StreamKind.TRUTH not in source:
            raise ValueError("the recording has no truth stream to score against")
        return cls(source[StreamKind.TRUTH], source.t0_ns, source.metadata.true_errors,
                   recorded_outages(source.metadata.extra))

    def __contains__(self, column: str) -> bool:
        return column in self.stream.columns

    def at(self, t: np.ndarray, columns: Collection[str] | None = None) -> dict[str, np.ndarray]:
        """The columns at filter times ``t`` [s since the recording start] (those of
        ``columns`` only, when given).

        Samples at equal times are taken as they are; between samples, vectors are interpolated
        linearly (longitude unwrapped) and quaternions normalised-linearly. Times within half a
        sample interval outside the reference take its end sample; times further outside are
        NaN (not scored: a reference that ends early does not freeze).

        Returns
        -------
        dict
            Column name -> array (M, ...).
        """
        ref = self.stream
        ts = self._times
        t = np.asarray(t, dtype=float)
        j = np.clip(np.searchsorted(ts, t, side="left"), 1, max(len(ts) - 1, 1))
        i = j - 1
        if len(ts) == 1:
            w = np.zeros_like(t)
            i = j = np.zeros_like(t, dtype=int)
        else:
            w = np.clip((t - ts[i]) / (ts[j] - ts[i]), 0.0, 1.0)
        out = {}
        for name, col in ref.columns.items():
            if columns is not None and name not in columns:
                continue
            a, b = col[i], col[j]
            if name == "pos":
                b = b.copy()
                b[:, 1] = a[:, 1] + wrap_angle(b[:, 1] - a[:, 1])
            if name.startswith("q_") and col.ndim == 2 and col.shape[1] == 4:
                sign = np.where(np.einsum("ki,ki->k", a, b) < 0.0, -1.0, 1.0)
                q = (1.0 - w)[:, None] * a + (w * sign)[:, None] * b
                out[name] = q / np.linalg.norm(q, axis=1, keepdims=True)
                continue
            ww = w.reshape((-1,) + (1,) * (col.ndim - 1))
            v = (1.0 - ww) * a + ww * b
            if name == "pos":
                v[:, 1] = wrap_angle(v[:, 1])
            out[name] = v
        if len(ts) > 1:
            half = 0.5 * float(np.median(np.diff(ts)))
            outside = (t < ts[0] - half) | (t > ts[-1] + half)
            if outside.any():
                for v in out.values():
                    v[outside] = np.nan
        return out

    def distance(self, t: np.ndarray | None = None) -> np.ndarray | float:
        """Length of the reference path [m]: ``integral |v_n| dt`` (trapezoid), or the sum of
        the position steps when there is no velocity; NaN with neither.

        With filter times ``t`` (M,): the distance up to each."""
        cum = self._travelled
        if cum is None:
            return np.full(np.shape(t), np.nan) if t is not None else math.nan
        if t is None:
            return float(cum[-1])
        return np.interp(t, self._times, cum)

    @functools.cached_property
    def _times(self) -> np.ndarray:
        """The reference's times [s since the recording start]."""
        return seconds(self.stream.t_ns, self.t0_ns)

    @functools.cached_property
    def _travelled(self) -> np.ndarray | None:
        """Length of the path up to each sample [m] (None without velocity or position)."""
        ref = self.stream
        if "v_n" in ref.columns:
            speed = np.linalg.norm(ref["v_n"], axis=1)
            steps = 0.5 * (speed[1:] + speed[:-1]) * np.diff(self._times)
        elif "pos" in ref.columns:
            steps = np.linalg.norm(position_error_ned(ref["pos"][1:], ref["pos"][:-1]), axis=1)
        else:
            return None
        return np.concatenate([[0.0], np.cumsum(steps)])


def truth_at(recording: Recording | Reference, t: np.ndarray) -> dict[str, np.ndarray]:
    """The reference's columns at filter times ``t`` (:meth:`Reference.at`)."""
    return Reference.of(recording).at(t)
