"""The filter interface: what the replay engine calls and what a filter hands back.

A filter is a class registered under a name (see :mod:`navreplay.filters.registry`). The replay
engine owns the loop: it merges the recording's streams by time and, for every aiding sample,
first hands the filter the IMU samples up to that time as one block (:meth:`Filter.propagate`),
then the sample itself (:meth:`Filter.update`). After every event, and at the output ticks of a
recording without aiding samples, it asks for :meth:`Filter.estimate` and stores it in columns.

Filters never print, never touch files and never import rerun.

Time inside a filter is float seconds since the recording start.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from navreplay.streams import Metadata, StreamKind


@dataclasses.dataclass(frozen=True, kw_only=True)
class FilterParams:
    """Base of every filter's parameters: a frozen, keyword-only dataclass in SI units.

    Subclasses document the unit of each field in its docstring and validate in
    ``__post_init__`` (raise ``ValueError`` naming the field and the accepted range, e.g. with
    :func:`check_number`).
    """


def check_number(
    params: object, name: str, *, positive: bool = False, upper: float | None = None
) -> None:
    """Raise ``ValueError`` unless the field ``name`` of ``params`` is None or a finite number
    ``>= 0`` (``> 0`` with ``positive``) and ``<= upper`` when given.

    Examples
    --------
    >>> import dataclasses
    >>> @dataclasses.dataclass
    ... class P:
    ...     dt: float = 0.0
    >>> check_number(P(), "dt", positive=True)
    Traceback (most recent call last):
    ...
    ValueError: dt must be finite and > 0, got 0.0
    """
    v = getattr(params, name)
    if v is None:
        return
    ok = isinstance(v, int | float) and math.isfinite(v) and (v > 0.0 if positive else v >= 0.0)
    if ok and upper is not None:
        ok = v <= upper
    if not ok:
        band = "> 0" if positive else ">= 0"
        if upper is not None:
            band += f" and <= {upper:g}"
        raise ValueError(f"{name} must be finite and {band}, got {v!r}")


@dataclasses.dataclass(frozen=True)
class FilterContext:
    """What a filter may know before the first sample.

    Attributes
    ----------
    metadata : Metadata
        The recording's metadata. ``metadata.initial_nav`` is the externally supplied initial
        solution; a filter must not read ``metadata.true_errors`` (that is for scoring).
    t0_ns : int
        Recording start [ns]; filter time t = 0 here.
    streams : frozenset[StreamKind]
        Streams the recording holds.
    """

    metadata: Metadata
    t0_ns: int
    streams: frozenset[StreamKind]


@dataclasses.dataclass(frozen=True)
class NavSolution:
    """Standard navigation solution.

    pos : (3,) latitude [rad], longitude [rad], height [m]; v_n : (3,) [m/s]; q_nb : (4,).
    """

    pos: np.ndarray
    v_n: np.ndarray
    q_nb: np.ndarray

    @classmethod
    def from_vector(cls, nav: np.ndarray) -> NavSolution:
        """From a navigation vector ``[lat, lon, h, v_N, v_E, v_D, q0, q1, q2, q3]`` (10,), the
        layout of :mod:`navreplay.strapdown`; the fields are views of ``nav``."""
        return cls(pos=nav[0:3], v_n=nav[3:6], q_nb=nav[6:10])


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A filter's output at one time.

    Attributes
    ----------
    t : float
        Time [s since the recording start].
    x : ndarray, shape (n,)
        Named state vector (``Filter.state_names``); for an error-state filter with feedback,
        the *total* estimates of the error quantities it tracks (e.g. the bias estimate), or the
        error estimate itself where there is no total (document which in the filter).
    P : ndarray, shape (n, n)
        Covariance of the state's error.
    nav : NavSolution | None
        The navigation solution, when the filter has one.
    extras : dict[str, ndarray]
        Further named outputs of fixed shape (e.g. ``"misalignment_euler"``), SI. Scored against
        ``Metadata.true_errors`` through ``Filter.truth_keys``.
    """

    t: float
    x: np.ndarray
    P: np.ndarray
    nav: NavSolution | None = None
    extras: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class Innovation:
    """One measurement update: innovation ``nu = z - H x`` and its covariance ``S``.

    ``name`` identifies the measurement (e.g. ``"gps_pos"``); ``nu`` has shape (m,), ``S`` (m, m).
    """

    name: str
    t: float
    nu: np.ndarray
    S: np.ndarray


class Filter(abc.ABC):
    """Base class of every filter.

    Class attributes
    ----------------
    name : str
        Registry name (``navreplay run NAME``), lowercase with dashes.
    summary : str
        One line for ``navreplay filters``.
    requires : tuple[StreamKind, ...]
        Streams that must be present; ``run`` fails before starting otherwise.
    optional : tuple[StreamKind, ...]
        Streams used when present.
    required_columns : dict[StreamKind, tuple[str, ...]]
        For a required stream, the columns the filter needs when not all the standard ones of
        :data:`navreplay.streams.FIELDS` (e.g. ``{StreamKind.IMU: ("f_b",)}`` for an
        accelerometer-only filter); the engine checks them before running.
    Params : type[FilterParams]
        Parameter dataclass.
    truth_keys : dict[str, str]
        Maps an ``Estimate`` output (a state name or an extras key) to the key of
        ``Metadata.true_errors`` (or to ``"truth:<column>"`` for a truth-stream column) holding
        its true value, so metrics can score error states.

    Instance attributes
    -------------------
    state_names : tuple[str, ...]
        Names of the entries of ``Estimate.x`` (may depend on parameters, e.g. variants).
    """

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    requires: ClassVar[tuple[StreamKind, ...]] = ()
    optional: ClassVar[tuple[StreamKind, ...]] = ()
    required_columns: ClassVar[Mapping[StreamKind, tuple[str, ...]]] = {}
    Params: ClassVar[type[FilterParams]] = FilterParams
    truth_keys: ClassVar[dict[str, str]] = {}

    state_names: tuple[str, ...] = ()

    def __init__(self, params: FilterParams, context: FilterContext) -> None:
        self.params = params
        self.context = context

    @abc.abstractmethod
    def propagate(self, t: np.ndarray, imu: Mapping[str, np.ndarray]) -> None:
        """Advance over a block of IMU samples.

        Parameters
        ----------
        t : ndarray, shape (k,)
            Sample times [s]; each sample is the mean over (t[i-1], t[i]] (the previous block's
            last time for i = 0).
        imu : mapping
            ``omega_ib_b`` (k, 3) [rad/s] and ``f_b`` (k, 3) [m/s^2], FRD.
        """

    @abc.abstractmethod
    def update(
        self, kind: StreamKind, t: float, sample: Mapping[str, Any]
    ) -> list[Innovation] | None:
        """Process one aiding sample (one row of the stream, columns by name) at time t [s].

        Returns the innovations of the updates made (for NIS), or None.
        """

    @abc.abstractmethod
    def estimate(self) -> Estimate | None:
        """The current estimate, or None before the filter is initialised."""
