"""The one adapter between a run and its exports and report: :class:`FilterOutput` (a
:class:`~navreplay.filters.result.RunResult` block with its metrics, the navigation covariance in
the order :data:`NAV_ROWS`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from navreplay.filters.base import MeasurementKind, Nav, NavError, State
from navreplay.filters.result import InnovationSeries, RunResult
from navreplay.geo import earth

NAV_AXES = ("north", "east", "down")


NAV_ROWS = (*NAV_AXES, "v_N", "v_E", "v_D", "phi_N", "phi_E", "phi_D")
"""Order of :attr:`FilterOutput.nav_cov`: position error NED [m], velocity error [m/s],
attitude error phi [rad]."""


_NAV_ROWS: dict[Nav, int] = {
    Nav.LAT: 0, Nav.LON: 1, Nav.H: 2, Nav.DEPTH: 2,
    Nav.V_N: 3, Nav.V_E: 4, Nav.V_D: 5,
    Nav.PHI_N: 6, Nav.PHI_E: 7, Nav.PHI_D: 8,
}
"""Row of each navigation quantity in the 9x9 navigation covariance (north, east, down
position; velocity NED; attitude error phi)."""


@dataclasses.dataclass
class FilterOutput:
    """What leaves navreplay of one filter run (built by :func:`filter_output`).

    Attributes
    ----------
    label : str
    t0_ns : int
        Recording start [ns].
    t : ndarray, shape (M,)
        Estimate times [s since t0_ns].
    state_names, state_units : tuple of str
    x, sigma : ndarray, shape (M, n)
        State vector and its 1-sigma.
    nav_pos, nav_v_n, nav_q_nb : ndarray (M, 3), (M, 3), (M, 4) or None
        Navigation solution (lat, lon [rad], h [m]; NED velocity; q_nb scalar first).
    nav_cov : ndarray, shape (M, 9, 9) or None
        Covariance of the navigation errors in the order of :data:`NAV_ROWS`; NaN rows and
        columns where the filter has no state for a quantity.
    metrics : RunMetrics or None
        Errors against the reference (None without one).
    nis : dict[str, tuple[ndarray (K,), ndarray (K,), int]]
        Per measurement: update times [s], NIS, dof.
    nav_states : tuple of str
        The states that are errors of the navigation solution (they make ``nav_cov``).
    navigation : tuple of str
        The parts of the solution the filter outputs (``pos``, ``v_n``, ``q_nb``;
        ``RunResult.navigation``): the CSV carries their columns only.
    innovations : dict[str, InnovationSeries]
        The updates of each measurement (``RunResult.innovations``).
    measurements : tuple of MeasurementKind
        The filter's declarations of its measurements (empty when it declares none).
    """

    label: str
    t0_ns: int
    t: np.ndarray
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    x: np.ndarray
    sigma: np.ndarray
    nav_pos: np.ndarray | None
    nav_v_n: np.ndarray | None
    nav_q_nb: np.ndarray | None
    nav_cov: np.ndarray | None
    metrics: Any
    nis: dict[str, tuple[np.ndarray, np.ndarray, int]]
    nav_states: tuple[str, ...] = ()
    navigation: tuple[str, ...] = ("pos", "v_n", "q_nb")
    innovations: dict[str, InnovationSeries] = dataclasses.field(default_factory=dict)
    measurements: tuple[MeasurementKind, ...] = ()

    def has(self, part: str) -> bool:
        """Whether the output holds part ``part`` (``pos``, ``v_n``, ``q_nb``) of a solution."""
        return part in self.navigation and getattr(self, f"nav_{part}") is not None

    @property
    def has_nav(self) -> bool:
        """A whole navigation solution (a pose: what TUM and odometry need)."""
        return self.has("pos") and self.has("v_n") and self.has("q_nb")

    @property
    def stamps_ns(self) -> np.ndarray:
        """Absolute estimate times [ns]."""
        return np.int64(self.t0_ns) + np.rint(self.t * 1e9).astype(np.int64)


def filter_output(result: RunResult, metrics: Any = None) -> FilterOutput:
    """The one place that reads a run's estimates for exports and reports (a block of them,
    or a whole run: one block).

    Parameters
    ----------
    result : RunResult
    metrics : RunMetrics, optional
        The rows' scores (:func:`navreplay.metrics.run_metrics`); None without a reference.
    """
    return FilterOutput(
        label=result.label,
        t0_ns=int(result.t0_ns),
        t=np.asarray(result.t, dtype=float),
        state_names=tuple(result.state_names),
        state_units=tuple(st.unit for st in result.states),
        x=np.asarray(result.x, dtype=float),
        sigma=result.sigma,
        nav_pos=result.nav_pos,
        nav_v_n=result.nav_v_n,
        nav_q_nb=result.nav_q_nb,
        nav_cov=_nav_covariance(result) if result.nav_pos is not None else None,
        metrics=metrics,
        nis={name: (s.t, s.nis, int(s.nu.shape[1])) for name, s in result.innovations.items()},
        nav_states=nav_state_names(result.states),
        navigation=result.navigation,
        innovations=dict(result.innovations),
        measurements=tuple(result.measurements),
    )


def nav_state_names(states: Sequence[State]) -> tuple[str, ...]:
    """The declared states that are errors of the navigation solution."""
    return tuple(st.name for st in states if isinstance(st.truth, NavError))


def _nav_covariance(result: RunResult) -> np.ndarray:
    """Covariance (M, 9, 9) of the navigation errors from the states declared as navigation
    errors (lat/lon scaled to metres, height negated to down); NaN where none is."""
    M = result.t.shape[0]
    assert result.nav_pos is not None  # a result with a navigation solution
    lat, h = result.nav_pos[:, 0], result.nav_pos[:, 2]
    R_M, R_N = earth.radii(lat)
    scale_of = {Nav.LAT: R_M + h, Nav.LON: (R_N + h) * np.cos(lat), Nav.H: -np.ones(M)}
    idx, rows, scales = [], [], []
    for i, st in enumerate(result.states):
        if not isinstance(st.truth, NavError):
            continue
        q = st.truth.q
        if _NAV_ROWS[q] not in rows:
            idx.append(i)
            rows.append(_NAV_ROWS[q])
            scales.append(scale_of.get(q, np.ones(M)))
    # NaN where no state is (every element is written when all nine are)
    out = np.empty((M, 9, 9)) if len(rows) == 9 else np.full((M, 9, 9), np.nan)
    if idx:
        s = np.stack(scales, axis=1)
        sub = result.P[:, _block(idx), _block(idx, True)]
        at = _block(rows), _block(rows, True)
        if isinstance(at[0], slice):  # the products formed in place (no temporaries)
            view = out[:, at[0], at[1]]
            np.multiply(sub, s[:, :, None], out=view)
            view *= s[:, None, :]
        else:
            out[:, at[0], at[1]] = sub * s[:, :, None] * s[:, None, :]
    return out


def _block(index: list[int], column: bool = False) -> slice | np.ndarray:
    """Rows (or, ``column``, columns) ``index`` of a matrix: a slice when they are
    consecutive (a view, no gather), else an index array shaped to broadcast."""
    if index == list(range(index[0], index[0] + len(index))):
        return slice(index[0], index[0] + len(index))
    ix = np.array(index)
    return ix[None, :] if column else ix[:, None]
