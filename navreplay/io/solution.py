"""A recorded navigation solution: what an estimator that ran when the log was made (PX4's
EKF2, a vendor INS, a ship's master INS) output, as columns, to be shown, scored and exported
beside the filters replayed over the log (``run --onboard``, docs/real-logs.md).

Examples
--------
>>> import numpy as np
>>> t = np.arange(3, dtype=np.int64) * 10**8
>>> nan = np.full((3, 3), np.nan)
>>> sol = RecordedSolution("ins", "/ins/odom", t, np.zeros((3, 3)), nan, np.tile([1.0, 0, 0, 0],
...                        (3, 1)), np.ones((3, 3)), nan, nan)
>>> sol.parts(), sol.with_sigma()
(('pos', 'q_nb'), ('pos',))
>>> len(sol.cut(10**8, None).t_ns)
2
"""

from __future__ import annotations

import dataclasses

import numpy as np

PARTS = ("pos", "v_n", "q_nb")
"""The parts of a navigation solution, as columns."""
SIGMAS = {"pos": "pos_sigma", "v_n": "vel_sigma", "q_nb": "att_sigma"}
"""The column of each part's 1-sigma."""


@dataclasses.dataclass
class RecordedSolution:
    """A recorded navigation solution at its sample times; a part the log does not give is
    NaN throughout, and so is a 1-sigma it does not give.

    Attributes
    ----------
    label : str
        Its label beside the filters' (its row in tables, its colour and entity in the view,
        its export files).
    source : str
        What was read (topics or file), for messages.
    t_ns : (M,) int64
        Sample times [ns], increasing.
    pos : (M, 3)
        Latitude, longitude [rad], ellipsoidal height [m].
    v_n : (M, 3)
        Velocity NED [m/s].
    q_nb : (M, 4)
        Attitude, FRD body to NED, Hamilton, scalar first.
    pos_sigma, vel_sigma : (M, 3)
        1-sigma north, east, down [m], [m/s].
    att_sigma : (M, 3)
        1-sigma of the attitude error about north, east, down [rad].
    """

    label: str
    source: str
    t_ns: np.ndarray
    pos: np.ndarray
    v_n: np.ndarray
    q_nb: np.ndarray
    pos_sigma: np.ndarray
    vel_sigma: np.ndarray
    att_sigma: np.ndarray

    def parts(self) -> tuple[str, ...]:
        """The parts the solution gives (finite in some row)."""
        return tuple(p for p in PARTS if np.isfinite(getattr(self, p)).any())

    def with_sigma(self) -> tuple[str, ...]:
        """The parts given with their 1-sigma in every row where the part is given."""
        out = []
        for p in self.parts():
            value, sigma = getattr(self, p), getattr(self, SIGMAS[p])
            given = np.isfinite(value).all(axis=1)
            if given.any() and np.all(np.isfinite(sigma[given]) & (sigma[given] > 0)):
                out.append(p)
        return tuple(out)

    def rows(self, keep: np.ndarray) -> RecordedSolution:
        """The solution at the rows ``keep`` (a mask or indices)."""
        return dataclasses.replace(self, **{f.name: getattr(self, f.name)[keep]
                                            for f in dataclasses.fields(self)
                                            if isinstance(getattr(self, f.name), np.ndarray)})

    def cut(self, lo_ns: int | None, hi_ns: int | None) -> RecordedSolution:
        """The rows from ``lo_ns`` to ``hi_ns`` (either end open when None)."""
        a = 0 if lo_ns is None else int(np.searchsorted(self.t_ns, lo_ns))
        b = len(self.t_ns) if hi_ns is None else int(np.searchsorted(self.t_ns, hi_ns,
                                                                      side="right"))
        return self.rows(np.arange(a, max(a, b)))

    def complete(self) -> tuple[RecordedSolution, int]:
        """The rows where every part the solution gives is finite, with its 1-sigma where the
        solution gives one for the part, and how many were left out (a position before the
        estimator had one, a gap the estimator flagged, an infinite variance: PX4 says so
        before it has a global origin)."""
        keep = np.ones(len(self.t_ns), dtype=bool)
        for p in self.parts():
            keep &= np.isfinite(getattr(self, p)).all(axis=1)
            sigma = getattr(self, SIGMAS[p])
            valid = (np.isfinite(sigma) & (sigma > 0)).all(axis=1)
            if valid.any():
                keep &= valid
        return self.rows(keep), int((~keep).sum())
