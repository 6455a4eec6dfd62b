"""Errors of a run against its reference: the navigation solution (north, east, down position,
velocity, the attitude error phi, Euler angles), the declared states and the scored extras, and
the predicted sigmas of the navigation errors. All errors are estimate minus reference."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay.filters.base import (
    NAV_PART,
    NAV_PARTS,
    Nav,
    NavError,
    State,
    TrueConstant,
    TruthColumn,
)
from navreplay.filters.result import RunResult
from navreplay.geo import earth
from navreplay.geo.rotations import attitude_error, dcm_to_euler, quat_to_dcm, wrap_angle


@dataclasses.dataclass
class NavErrors:
    """Errors of a navigation solution, estimate minus reference, each (M, 3); NaN where the
    reference lacks the column (``pos``, ``v_n``, ``q_nb``) or the filter does not output that
    part of the solution (``RunResult.navigation``).

    Attributes
    ----------
    pos_ned : north, east, down [m]: ``(lat_hat - lat)(R_M + h)``, ``(lon_hat - lon)(R_N + h)
        cos lat``, ``-(h_hat - h)`` (the height error, positive when the estimate is too deep).
    v_n : velocity NED [m/s].
    phi : attitude error phi, NED [rad] (``C_hat = (I - [phi x]) C``: a positive phi_D is an
        estimated heading *smaller* than the reference's).
    euler : roll, pitch, yaw differences [rad], yaw wrapped to [-pi, pi) (yaw ~ -phi_D).
    """

    pos_ned: np.ndarray
    v_n: np.ndarray
    phi: np.ndarray
    euler: np.ndarray

    def columns(self) -> dict[str, np.ndarray]:
        """The errors by the names of the view and the tables: ``p_N, p_E, p_D`` [m],
        ``v_N, v_E, v_D`` [m/s], ``phi_N, phi_E, phi_D`` [rad]."""
        out = {}
        for prefix, arr in (("p", self.pos_ned), ("v", self.v_n), ("phi", self.phi)):
            for i, axis in enumerate("NED"):
                out[f"{prefix}_{axis}"] = arr[:, i]
        return out


def position_error_ned(pos_hat: np.ndarray, pos_true: np.ndarray) -> np.ndarray:
    """North, east, down position error [m] of latitude/longitude/height arrays (..., 3)."""
    pos_hat = np.asarray(pos_hat, dtype=float)
    pos_true = np.asarray(pos_true, dtype=float)
    lat, h = pos_true[..., 0], pos_true[..., 2]
    R_M, R_N = earth.radii(lat)
    d = pos_hat - pos_true
    return np.stack(
        [d[..., 0] * (R_M + h), wrap_angle(d[..., 1]) * (R_N + h) * np.cos(lat), -d[..., 2]],
        axis=-1,
    )


def nav_errors(
    pos: np.ndarray, v_n: np.ndarray, q_nb: np.ndarray, truth: Mapping[str, np.ndarray],
    navigation: tuple[str, ...] = NAV_PARTS,
) -> NavErrors:
    """Errors of a navigation solution against the reference at the same times: the one
    navigation-error computation of navreplay (tables, ensembles and the Rerun view).

    Parameters
    ----------
    pos, v_n : ndarray, shape (M, 3)
    q_nb : ndarray, shape (M, 4)
    truth : mapping
        Any of ``pos``, ``v_n``, ``q_nb`` at the same times (:meth:`Reference.at`); the errors
        of absent columns are NaN.
    navigation : tuple of str
        The parts of the solution the filter outputs; the errors of the others are NaN.

    Returns
    -------
    NavErrors
    """
    nan = np.full((np.shape(pos)[0], 3), np.nan)
    truth = {k: v for k, v in truth.items() if k not in NAV_PARTS or k in navigation}
    pos_ned = position_error_ned(pos, truth["pos"]) if "pos" in truth else nan
    dv = np.asarray(v_n) - truth["v_n"] if "v_n" in truth else nan
    if "q_nb" in truth:
        C_hat, C_true = quat_to_dcm(q_nb), quat_to_dcm(truth["q_nb"])
        phi = attitude_error(C_hat, C_true)
        euler = wrap_angle(dcm_to_euler(C_hat) - dcm_to_euler(C_true))  # as quat_to_euler
    else:
        phi = euler = nan
    return NavErrors(pos_ned=pos_ned, v_n=dv, phi=phi, euler=euler)


_NAV_COMPONENT: dict[Nav, tuple[int, float]] = {
    Nav.LAT: (0, 1.0), Nav.LON: (1, 1.0), Nav.H: (2, 1.0), Nav.DEPTH: (2, -1.0),
    Nav.V_N: (0, 1.0), Nav.V_E: (1, 1.0), Nav.V_D: (2, 1.0),
    Nav.PHI_N: (0, 1.0), Nav.PHI_E: (1, 1.0), Nav.PHI_D: (2, 1.0),
}
"""Component and sign of each navigation quantity in its part (``NAV_PART``)."""


def _nav_quantity(q: Nav, result: RunResult, truth: Mapping[str, np.ndarray],
                  nav: NavErrors) -> np.ndarray | None:
    """Error of the navigation solution in quantity q (units of the state), or None when the
    result has no solution or the reference lacks the column."""
    column = NAV_PART[q]
    i, sign = _NAV_COMPONENT[q]
    if not result.has(column) or column not in truth:
        return None
    if column == "pos":
        assert result.nav_pos is not None  # has("pos")
        d = result.nav_pos[:, i] - truth["pos"][:, i]
        return sign * (wrap_angle(d) if i == 1 else d)
    if column == "v_n":
        return nav.v_n[:, i]
    return nav.phi[:, i]


def _constant(truth: TrueConstant, true_errors: Mapping[str, Any]) -> np.ndarray | None:
    value: Any = true_errors
    for part in truth.key.split("."):
        if not isinstance(value, Mapping) or part not in value:
            return None
        value = value[part]
    arr = np.asarray(value, dtype=float)
    return arr[truth.index] if truth.index else arr


def reference_value(state: State, truth: Mapping[str, np.ndarray],
                    true_errors: Mapping[str, Any]) -> np.ndarray | None:
    """The reference of a ``TruthColumn`` or ``TrueConstant`` declaration at the output times
    (None when the reference lacks it)."""
    t = state.truth
    if isinstance(t, TruthColumn):
        if t.column not in truth:
            return None
        v = truth[t.column]
        columns: tuple[Any, ...] = (slice(None), *t.index)
        return v[columns] if t.index else v
    if isinstance(t, TrueConstant):
        return _constant(t, true_errors)
    return None


def state_errors(
    result: RunResult,
    truth: Mapping[str, np.ndarray],
    true_errors: Mapping[str, Any],
    states: tuple[State, ...],
    nav: NavErrors,
) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Estimation errors of the declared states that the reference can score.

    Parameters
    ----------
    result : RunResult
    truth : mapping
        Reference columns at ``result.t`` (:meth:`Reference.at`).
    true_errors : mapping
        ``metadata.true_errors``.
    states : tuple of State
        Declarations of the columns of ``result.x``.
    nav : NavErrors
        Errors of the result's navigation solution.

    Returns
    -------
    names : tuple of str
        Scored states, in state order.
    e : ndarray, shape (M, k)
        Estimation errors.
    P : ndarray, shape (M, k, k)
        Their covariance (the block of ``result.P``; a read-only use: it may be a view).
    """
    names, cols, idx = [], [], []
    for i, st in enumerate(states):
        x = result.x[:, i]
        if isinstance(st.truth, NavError):
            err = _nav_quantity(st.truth.q, result, truth, nav)
            e = None if err is None else err - x
        else:
            ref = reference_value(st, truth, true_errors)
            e = None if ref is None else x - ref
        if e is None:
            continue
        if e.shape != x.shape:
            raise ValueError(f"{result.label}: the reference of state {st.name} ({st.truth}) "
                             f"has shape {e.shape[1:]}, not a single value per row")
        names.append(st.name)
        cols.append(e)
        idx.append(i)
    M = result.t.shape[0]
    if not names:
        return (), np.zeros((M, 0)), np.zeros((M, 0, 0))
    a, b = idx[0], idx[-1] + 1
    if b - a == len(idx):  # consecutive states: a view of their block, no copy
        P = result.P[:, a:b, a:b]
    else:
        ix = np.array(idx)
        P = np.take(np.take(result.P, ix, axis=1), ix, axis=2)  # twice as fast as P[:, ix, ix.T]
    return tuple(names), np.stack(cols, axis=1), P


def extra_errors(result: RunResult, truth: Mapping[str, np.ndarray],
                 true_errors: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """Errors ``extra - reference`` of the scored extras the reference has, (M, ...) each."""
    out = {}
    for st in result.scored_extras:
        if st.name not in result.extras:
            continue
        ref = reference_value(st, truth, true_errors)
        if ref is None:
            continue
        out[st.name] = np.asarray(result.extras[st.name], dtype=float) - ref
    return out


_NAV_SIGMA: dict[Nav, tuple[str, int]] = {
    Nav.LAT: ("pos_ned", 0), Nav.LON: ("pos_ned", 1), Nav.H: ("pos_ned", 2),
    Nav.DEPTH: ("pos_ned", 2), Nav.V_N: ("v_n", 0), Nav.V_E: ("v_n", 1), Nav.V_D: ("v_n", 2),
    Nav.PHI_N: ("phi", 0), Nav.PHI_E: ("phi", 1), Nav.PHI_D: ("phi", 2),
}


def nav_sigma(result: RunResult, states: tuple[State, ...] | None = None) -> dict[str, np.ndarray]:
    """Predicted 1-sigma of the navigation errors (``pos_ned`` [m], ``v_n`` [m/s], ``phi``
    [rad], each (M, 3)) from the ``NavError`` states; NaN where the filter has none."""
    states = result.states if states is None else states
    M = result.t.shape[0]
    out = {k: np.full((M, 3), np.nan) for k in ("pos_ned", "v_n", "phi")}
    var = np.diagonal(result.P, axis1=1, axis2=2)
    scale = None
    if result.has("pos"):
        assert result.nav_pos is not None  # has("pos")
        lat, h = result.nav_pos[:, 0], result.nav_pos[:, 2]
        R_M, R_N = earth.radii(lat)
        scale = {Nav.LAT: R_M + h, Nav.LON: (R_N + h) * np.cos(lat)}
    for i, st in enumerate(states):
        if not isinstance(st.truth, NavError):
            continue
        group, j = _NAV_SIGMA[st.truth.q]
        s = np.sqrt(np.clip(var[:, i], 0.0, None))
        if st.truth.q in (Nav.LAT, Nav.LON):
            if scale is None:
                continue
            s = s * scale[st.truth.q]
        out[group][:, j] = s
    return out
