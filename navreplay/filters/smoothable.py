"""What a filter declares to be smoothed: the :class:`Smoothable` side of the filter contract.

A fixed-interval smoother (:mod:`navreplay.filters.rts`) runs backward over what the forward
pass stored at every estimate the filter output. A filter opts in by deriving from
:class:`Smoothable` as well as :class:`~navreplay.filters.base.Filter` and implementing its
three methods; the replay then, with ``--smooth``:

1. calls :meth:`Smoothable.start_smoothing` once, before the first event (the filter then
   keeps the transition of its error state since its last output);
2. after every estimate it records, calls :meth:`Smoothable.smoothing_step` and stores the
   estimate and the step on disk; a filter whose :meth:`Filter.run_events` writes its
   estimates in a compiled run hands the steps of those estimates over with them instead
   (:class:`SmoothingSteps`, :meth:`navreplay.filters.base.EventRun.add_rows`);
3. after the last window, runs the backward pass over the stored chunks, latest first, and
   hands each smoothed correction to :meth:`Smoothable.apply_smoothed`, which turns the forward
   estimate into the smoothed one (as its feedback turns an update into a corrected solution).

Filters stay free of I/O: the storing and the backward pass are the replay's
(:mod:`navreplay.replay.smoothing`). Method and equations: docs/smoothing.md.
"""

from __future__ import annotations

import abc
import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class SmoothingStep:
    """What the backward pass needs of one output epoch k, beside the estimate (x_k, P_k, nav).

    Attributes
    ----------
    phi : ndarray, shape (n, n)
        Transition of the error state from the previous output (after its feedback reset) to
        this one: the product of the filter's covariance-step transitions in between.
    P_prior : ndarray, shape (n, n)
        Covariance before this epoch's updates, ``Phi P_{k-1} Phi^T + Qd`` (the process noise
        accumulated since the previous output is ``Qd = P_prior - Phi P_{k-1} Phi^T``); the
        estimate's P when no update was made.
    dx : ndarray, shape (n,)
        The error state the updates at this epoch estimated (and fed back, for a filter with
        feedback), before the reset; zeros without update. Several updates at one epoch: their
        sum.
    reset : ndarray, shape (n, n), or None
        How the feedback reset maps the error state (``dx_after = G dx_before``); None: the
        identity (a filter that corrects its solution but leaves its covariance as it is).
    """

    phi: np.ndarray
    P_prior: np.ndarray
    dx: np.ndarray
    reset: np.ndarray | None = None


@dataclasses.dataclass(frozen=True)
class SmoothingSteps:
    """The :class:`SmoothingStep` of each of m estimates a compiled run of events wrote
    (:meth:`navreplay.filters.base.EventRun.add_rows`), stacked: ``phi`` (m, n, n),
    ``P_prior`` (m, n, n), ``dx`` (m, n); the reset is the identity."""

    phi: np.ndarray
    P_prior: np.ndarray
    dx: np.ndarray


class Smoothable(abc.ABC):
    """A filter that can be smoothed (see the module docstring); mix into a ``Filter``."""

    @abc.abstractmethod
    def start_smoothing(self) -> None:
        """Before the first event: keep what :meth:`smoothing_step` returns (the transition
        since the last output, the covariance before the updates, the updates' estimates)."""

    @abc.abstractmethod
    def smoothing_step(self) -> SmoothingStep:
        """Right after an estimate is recorded: what happened since the previous one; the
        filter then starts collecting the next step."""

    @abc.abstractmethod
    def apply_smoothed(self, x: np.ndarray, nav: np.ndarray | None, d: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray | None]:
        """Forward estimates of a chunk, ``x`` (m, n) and navigation vectors ``nav`` (m, 10)
        of :mod:`navreplay.geo.strapdown` (None without a solution), corrected by the smoothed
        error states ``d`` (m, n) as the filter's feedback would correct them; new arrays.
        Pure (called after the forward pass, possibly on another instance's data)."""


def is_smoothable(cls: type) -> bool:
    """Whether a filter class declares :class:`Smoothable`."""
    return isinstance(cls, type) and issubclass(cls, Smoothable)
