"""A recorded navigation solution as a row of the pipeline: fed the same windows as the
filters' sessions, it hands out its samples as blocks of estimates, so that the scoring, the
view, the exports and the report treat it as they treat a filter's (``run --onboard``).

Its estimates are its samples, at their own times (no interpolation, no filter running). As
an error-state filter's are, its states are the errors of the parts of its solution that come
with variances, zero (the solution is its own best estimate) with the logged variances as
their covariance: the NEES of those parts is the recorded estimator's own consistency, and a
part without variances is scored without one.

Examples
--------
>>> import numpy as np
>>> from navreplay.io.solution import RecordedSolution
>>> t = np.arange(1, 6, dtype=np.int64) * 10**9
>>> pos = np.tile([0.8, 0.1, 100.0], (5, 1))
>>> nan = np.full((5, 3), np.nan)
>>> sol = RecordedSolution("ins", "test", t, pos, nan, np.full((5, 4), np.nan),
...                        np.full((5, 3), 2.0), nan, nan)
>>> session = RecordedSession(sol, source="log", t0_ns=0)
>>> session.feed({}, known={StreamKind.IMU: 3 * 10**9}).t.tolist()
[1.0, 2.0, 3.0]
>>> block = session.feed({}, final=True)
>>> block.t.tolist(), block.navigation, [s.name for s in block.states]
([4.0, 5.0], ('pos',), ['dlat', 'dlon', 'dh'])
>>> round(float(np.sqrt(block.P[0, 2, 2])), 6)
2.0
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from navreplay.core.streams import Stream, StreamKind
from navreplay.filters.base import Nav, NavError, Quantity, State
from navreplay.filters.result import RunResult
from navreplay.geo.earth import radii
from navreplay.io.solution import SIGMAS, RecordedSolution

FILTER_NAME = "recorded"
"""The ``filter_name`` of a recorded solution's results."""

_STATES = {
    "pos": (State("dlat", "rad", Quantity.POSITION, NavError(Nav.LAT), nees=True),
            State("dlon", "rad", Quantity.POSITION, NavError(Nav.LON), nees=True),
            State("dh", "m", Quantity.POSITION, NavError(Nav.H), nees=True)),
    "v_n": tuple(State(f"dv_{a}", "m/s", Quantity.VELOCITY, NavError(Nav(f"v_{a}")),
                       nees=True) for a in "NED"),
    "q_nb": tuple(State(f"phi_{a}", "rad", Quantity.ATTITUDE, NavError(Nav(f"phi_{a}")),
                        nees=True) for a in "NED"),
}
"""The error states of each part, as the INS filters declare them."""


class RecordedSession:
    """A recorded solution fed window by window (the interface of
    :class:`~navreplay.replay.session.ReplaySession` that :func:`~navreplay.replay.replay_file`
    uses): each :meth:`feed` returns its samples up to the time the IMU is known to.

    Parameters
    ----------
    solution : RecordedSolution
    source : str
        The recording, for the results.
    t0_ns : int
        The recording's start [ns].
    """

    settings = None
    live_rows = 0

    def __init__(self, solution: RecordedSolution, *, source: str, t0_ns: int) -> None:
        self.solution = solution
        self.label = solution.label
        self.source, self.t0_ns = source, t0_ns
        self.navigation = solution.parts()
        self.states = tuple(st for p in solution.with_sigma() for st in _STATES[p])
        self._next = 0

    def feed(self, window: Mapping[StreamKind, Stream], final: bool = False,
             known: Mapping[StreamKind, int] | None = None) -> RunResult:
        """The samples not handed out yet up to the time the window's IMU is complete to
        (all of them with ``final``)."""
        t = self.solution.t_ns
        if final or not known:
            end = len(t)
        else:
            bound = known.get(StreamKind.IMU, max(known.values()))
            end = int(np.searchsorted(t, bound, side="right"))
        a, self._next = self._next, max(self._next, end)
        return self._block(a, self._next)

    def _block(self, a: int, b: int) -> RunResult:
        s = self.solution
        m = b - a
        n = len(self.states)
        P = np.zeros((m, n, n))
        k = 0
        for part in s.with_sigma():
            sigma = getattr(s, SIGMAS[part])[a:b]
            if part == "pos":  # north and east [m] -> latitude and longitude [rad]
                R_M, R_N = radii(s.pos[a:b, 0])
                h = s.pos[a:b, 2]
                sigma = np.column_stack([sigma[:, 0] / (R_M + h),
                                         sigma[:, 1] / ((R_N + h) * np.cos(s.pos[a:b, 0])),
                                         sigma[:, 2]])
            idx = np.arange(k, k + 3)
            P[:, idx, idx] = sigma**2
            k += 3

        def nav(name: str) -> np.ndarray:
            value = getattr(s, name)[a:b]
            return value if name in self.navigation else np.full(value.shape, np.nan)

        return RunResult(FILTER_NAME, self.label, self.source, self.t0_ns,
                         (s.t_ns[a:b] - self.t0_ns) * 1e-9, self.states, np.zeros((m, n)), P,
                         nav_pos=nav("pos"), nav_v_n=nav("v_n"), nav_q_nb=nav("q_nb"),
                         navigation=self.navigation)
