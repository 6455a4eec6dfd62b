"""GNSS outages scored one by one, as a field test reports them: for each outage of a
recording (``metadata.extra["gnss_outages"]``, :func:`navreplay.core.outages.recorded_outages`)
the horizontal and vertical position error at its end, the last estimate before the GNSS
returns, against the filter's predicted sigma there, and the RMS of both errors over the
outage.

A run's scores accumulate block by block (:class:`OutageScores`, inside
:class:`~navreplay.metrics.summary.RunSummary`); an ensemble's come from its statistics per
epoch (:func:`ensemble_outages`): the RMS over the runs of the error at each outage's end over
the RMS predicted sigma there, checked as a mean of one chi-square(1) sample per run (a
horizontal error has between one and two degrees of freedom: the band is conservative), at the
false alarm :data:`navreplay.metrics.consistency.CHECK_FALSE_ALARM` for the outages together.

Examples
--------
>>> import numpy as np
>>> s = OutageScores(((2.0, 4.0),))
>>> t = np.arange(6.0)
>>> e = np.zeros((6, 3)); e[:, 0] = t      # 1 m/s north, no error east or down
>>> s.add(t, e, np.ones((6, 3)))
>>> {k: round(v, 3) for k, v in s.result()[0].items()}  # doctest: +NORMALIZE_WHITESPACE
{'start': 2.0, 'end': 4.0, 't_end': 3.0, 'err_end_h': 3.0, 'err_end_v': 0.0,
 'sigma_end_h': 1.414, 'sigma_end_v': 1.0, 'rms_h': 2.55, 'rms_v': 0.0}
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from navreplay.metrics import consistency

Outage = tuple[float, float]
"""A GNSS outage: start and end [s since the recording start]; no fix at or after the start and
before the end."""

_TOL = 1e-6
"""Slack [s] on the outage bounds: an estimate at the end itself follows the fix there."""


def inside(t: np.ndarray, outage: Outage) -> np.ndarray:
    """Which estimate times ``t`` [s] fall in the outage (at or after its start, before its
    end)."""
    start, end = outage
    return (t >= start - _TOL) & (t < end - _TOL)


class OutageScores:
    """The scores of each outage of one run, accumulated from its blocks of estimates.

    Parameters
    ----------
    outages : sequence of (start, end)
        [s since the recording start], in order.
    """

    def __init__(self, outages: Sequence[Outage]) -> None:
        self.outages = tuple((float(a), float(b)) for a, b in outages)
        n = len(self.outages)
        self._sq = np.zeros((n, 2))  # sums of squares of the horizontal and vertical errors
        self._count = np.zeros((n, 2), dtype=np.int64)
        self._end: list[dict[str, float] | None] = [None] * n

    def add(self, t: np.ndarray, pos_err: np.ndarray, pos_sigma: np.ndarray) -> None:
        """A block of estimates (later than those before): times [s], position errors and
        predicted sigmas N, E, D [m] (M, 3)."""
        for i, outage in enumerate(self.outages):
            k = np.flatnonzero(inside(t, outage))
            if not k.shape[0]:
                continue
            hv = np.stack([np.hypot(pos_err[k, 0], pos_err[k, 1]), pos_err[k, 2]], axis=1)
            ok = np.isfinite(hv)
            self._sq[i] += np.sum(np.where(ok, hv, 0.0) ** 2, axis=0)
            self._count[i] += ok.sum(axis=0)
            j = k[-1]
            self._end[i] = {
                "t_end": float(t[j]),
                "err_end_h": float(hv[-1, 0]),
                "err_end_v": float(hv[-1, 1]),
                "sigma_end_h": float(np.hypot(pos_sigma[j, 0], pos_sigma[j, 1])),
                "sigma_end_v": float(pos_sigma[j, 2]),
            }

    def result(self) -> list[dict[str, float]]:
        """Per outage: ``start``, ``end`` [s] and, when an estimate fell inside it, ``t_end``
        (the last estimate before the GNSS returns) [s], the horizontal and vertical errors
        there ``err_end_h``, ``err_end_v`` and the predicted sigmas ``sigma_end_h`` (of the
        horizontal error, ``sqrt(sigma_N^2 + sigma_E^2)``), ``sigma_end_v``, the RMS of the
        errors over the outage ``rms_h``, ``rms_v`` [m]."""
        out = []
        for i, (start, end) in enumerate(self.outages):
            row: dict[str, float] = {"start": start, "end": end}
            end_row = self._end[i]
            if end_row is not None:
                row.update(end_row)
                for j, key in enumerate(("rms_h", "rms_v")):
                    n = self._count[i, j]
                    row[key] = math.sqrt(self._sq[i, j] / n) if n else math.nan
            out.append(row)
        return out


def ensemble_outages(t: np.ndarray, rms: np.ndarray, sigma: np.ndarray, runs: int,
                     outages: Sequence[Outage]) -> list[dict[str, Any]]:
    """The scores of each outage of an ensemble.

    Parameters
    ----------
    t : ndarray, shape (M,)
        Estimate times [s].
    rms, sigma : ndarray, shape (M, 3)
        RMS over the runs of the position error N, E, D and RMS predicted sigma [m].
    runs : int
    outages : sequence of (start, end)
        [s], shared by the runs.

    Returns
    -------
    list of dict
        Per outage: ``start``, ``end``, and where an estimate fell inside it ``t_end``,
        ``err_end_h``, ``err_end_v`` (RMS over the runs at the end), ``sigma_end_h``,
        ``sigma_end_v``, ``rms_h``, ``rms_v`` (over the runs and the outage's estimates) [m],
        ``ratio_end_h`` (``err_end_h / sigma_end_h``), its ``band`` and whether it is inside
        (``passed``).
    """
    out: list[dict[str, Any]] = []
    lo, hi = consistency.mean_band(1, max(runs, 1),
                                   consistency.CHECK_FALSE_ALARM / max(len(outages), 1))
    band = [math.sqrt(lo), math.sqrt(hi)]
    for outage in outages:
        row: dict[str, Any] = {"start": float(outage[0]), "end": float(outage[1])}
        k = np.flatnonzero(inside(t, outage))
        if k.shape[0] and runs > 0:
            j = k[-1]
            h2 = rms[k, 0] ** 2 + rms[k, 1] ** 2
            err_h = float(np.hypot(rms[j, 0], rms[j, 1]))
            sigma_h = float(np.hypot(sigma[j, 0], sigma[j, 1]))
            ratio = err_h / sigma_h if sigma_h > 0.0 else math.nan
            row.update({
                "t_end": float(t[j]),
                "err_end_h": err_h,
                "err_end_v": float(rms[j, 2]),
                "sigma_end_h": sigma_h,
                "sigma_end_v": float(sigma[j, 2]),
                "rms_h": float(np.sqrt(np.nanmean(h2))),
                "rms_v": float(np.sqrt(np.nanmean(rms[k, 2] ** 2))),
                "ratio_end_h": ratio,
                "band": band,
                "passed": bool(band[0] <= ratio <= band[1]),
            })
        out.append(row)
    return out
