"""The :class:`~navreplay.filters.smoothable.Smoothable` side of the INS filters with feedback
(``ins``, ``gps-ins``, ``rpm-aided-ins``): what their forward pass keeps for the smoother and
how a smoothed error state corrects their estimates.

The transition of the error state between two outputs is the product of the covariance steps'
transitions (``Phi = I + F T + (F T)^2 / 2`` each), kept by the compiled time update itself
(:meth:`~navreplay.filters.ins_time_update.TimeUpdate.keep_transition`); an IMU gap bridged
in between adds its own (:func:`navreplay.filters.imu_gap.bridge`). The updates' corrections
are summed as they are fed back, and the covariance before the first update of an output is
kept, in arrays that ``gps-ins``'s compiled runs of events update as well
(:class:`navreplay.filters.gps_ins_events.Smoothing`). The filters reset their error state to 0
after each feedback and leave P as it is, so the reset Jacobian is the identity. A smoothed error
state ``d`` corrects an output as the feedback does: the navigation solution by
:func:`~navreplay.filters.ins_error.apply_correction` and each estimate held in ``x`` (biases, scale
factors, ...) by ``x - d``; the navigation error states of ``x`` stay 0.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import numpy as np

from navreplay.filters import ins_error as ie
from navreplay.filters.ins_time_update import TimeUpdate
from navreplay.filters.smoothable import Smoothable, SmoothingStep


class _Log:
    """What the forward pass keeps between two outputs for the smoother, in arrays that a
    compiled run of events updates in place: the covariance before the first update
    (``P_prior``, valid when ``has_prior[0]`` is 1) and the sum of the corrections fed back
    (``dx``)."""

    def __init__(self, n: int) -> None:
        self.P_prior = np.zeros((n, n))
        self.has_prior = np.zeros(1)
        self.dx = np.zeros(n)


class InsSmoothing(Smoothable):
    """Mix-in for an INS filter with feedback: its ``_time_update`` (a :class:`TimeUpdate`),
    ``P``, and calls of :meth:`_smoothing_prior` before each correction and of
    :meth:`_smoothing_feedback` in its feedback."""

    _time_update: TimeUpdate
    P: np.ndarray
    _sync_covariance: Callable[[], None]
    _smoothing: _Log | None = None
    smoothing_vertical: ClassVar[ie.Vertical] = ie.Vertical.HEIGHT
    """How the third error state is the error of the solution (height or depth)."""

    def start_smoothing(self) -> None:
        self._time_update.keep_transition()
        self._smoothing = _Log(self.P.shape[0])

    def _smoothing_prior(self) -> None:
        """Before a correction: the covariance before this output's first update."""
        log = self._smoothing
        if log is not None and not log.has_prior[0]:
            log.P_prior[:, :] = self.P
            log.has_prior[0] = 1.0

    def _smoothing_feedback(self, dx: np.ndarray) -> None:
        """The errors an update fed back."""
        if self._smoothing is not None:
            self._smoothing.dx += dx

    def _smoothing_transition(self, phi: np.ndarray) -> None:
        """A transition applied to P outside the covariance steps (an IMU gap's bridge)."""
        if self._smoothing is not None:
            Phi = self._time_update.work.Phi
            Phi[:, :] = phi @ Phi

    def smoothing_step(self) -> SmoothingStep:
        log = self._smoothing
        if log is None:
            raise RuntimeError("smoothing_step before start_smoothing")
        self._sync_covariance()
        step = SmoothingStep(self._time_update.take_transition(),
                             (log.P_prior if log.has_prior[0] else self.P).copy(),
                             log.dx.copy())
        log.has_prior[0] = 0.0
        log.dx[:] = 0.0
        return step

    def apply_smoothed(self, x: np.ndarray, nav: np.ndarray | None, d: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray | None]:
        x_s = x - d
        x_s[:, ie.NAV] = x[:, ie.NAV]
        if nav is None:
            return x_s, None
        vertical = self.smoothing_vertical
        nav_s = np.array([ie.apply_correction(nav[i], d[i], vertical) for i in range(len(d))])
        return x_s, nav_s.reshape(nav.shape)
