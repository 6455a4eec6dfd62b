"""Scoring filter runs against the truth: navigation errors, error-state errors, RMS, CEP50, %DT,
NEES and NIS, for single runs and for Monte Carlo ensembles.

All errors are estimate minus truth. Position errors are north, east, down in metres; the
attitude error is the phi angle of :func:`navreplay.geo.attitude_error`
(``C_hat = (I - [phi x]) C``); Euler-angle errors are differences of ZYX angles with the yaw
difference wrapped to [-pi, pi).

Definitions
-----------
::

    x_N = (lat_hat - lat)(R_M + h),  x_E = (lon_hat - lon)(R_N + h) cos lat,  x_D = -(h_hat - h)
    RMS over runs i = 1..N:  LatRMS = sqrt(mean_i x_N,i^2),  LongRMS = sqrt(mean_i x_E,i^2)
    CEP50  = 0.5887 (LatRMS + LongRMS)                       [m]    (eq. 29)
    DT     = integral |v_n| dt of the truth (mean over runs)   [m]
    DT CEP50 = CEP50 / DT x 100                               [%]    (eq. 30)
    NEES   = e^T P^-1 e over the scored states (e = estimation error, P its covariance)
    NIS    = nu^T S^-1 nu per measurement update
    95 % bounds of a mean over N runs of a chi-square quantity with d dof:
             chi2.ppf([0.025, 0.975], N d) / N                          (single run: N = 1)

Eqs. 29 and 30 are those of the RPM-aided INS paper (docs/methods/rpm-aided-ins.md §6).

Scoring against a reference
---------------------------
A run is scored against a :class:`Reference`: a truth-like stream (the recording's truth, or
an external reference) with whichever of ``pos``, ``v_n``, ``q_nb`` it has, plus the true
constants of ``metadata.true_errors``. What is absent is not scored: a reference with positions
only gives position errors and leaves velocity, attitude and the states that need them out.

Which states are scored, and against what, the filter declares once
(:class:`navreplay.filters.base.State`, copied into ``RunResult.states``): a ``NavError(q)``
state has ``e = (nav_hat - ref)_q - x`` (``q`` in :class:`navreplay.filters.base.Nav`), a
``TruthColumn`` state ``e = x - ref[column][index]``, a ``TrueConstant`` state ``e = x -
true_errors[key][index]``. The NEES is over the states declared with ``nees=True`` that are
scored.

Examples
--------
>>> import numpy as np
>>> round(chi2_bounds(3)[1], 3), [round(b, 3) for b in chi2_bounds(2, runs=50)]
(9.348, [1.484, 2.591])
>>> round(float(cep50(np.array([3.0, -4.0]), np.array([0.0, 0.0]))), 3)
2.081
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay import chi2
from navreplay.consistency import ConsistencyStats, EnsembleConsistency
from navreplay.filters.base import (
    NAV_PART,
    NAV_PARTS,
    Nav,
    NavError,
    State,
    TrueConstant,
    TruthColumn,
)
from navreplay.geo import earth
from navreplay.geo.rotations import (
    attitude_error,
    quat_to_dcm,
    quat_to_euler,
    wrap_angle,
)
from navreplay.replay.result import RunResult
from navreplay.streams import Recording, Stream, StreamKind, seconds

CEP50_FACTOR = 0.5887
"""CEP50 = CEP50_FACTOR (LatRMS + LongRMS) (circular approximation for similar axes)."""

NAV_COLUMNS = ("pos", "v_n", "q_nb")
"""Reference columns of the navigation errors: position [lat, lon rad, h m], velocity NED [m/s],
attitude quaternion (scalar first)."""


# --------------------------------------------------------------------------------------------
# basic statistics


def chi2_bounds(dof: int, runs: int = 1, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided bounds of the mean over ``runs`` of a chi-square variable with ``dof`` dof.

    Parameters
    ----------
    dof : int
        Degrees of freedom of one sample (state or measurement dimension).
    runs : int
        Number of independent samples averaged (Monte Carlo runs, or epochs of a white
        sequence).
    probability : float
        Probability inside the bounds.

    Returns
    -------
    lo, hi : float
        ``chi2.ppf([(1 - p)/2, (1 + p)/2], runs dof) / runs``.
    """
    if dof < 1 or runs < 1:
        raise ValueError(f"dof and runs must be >= 1, got {dof}, {runs}")
    a = 0.5 * (1.0 - probability)
    k = runs * dof
    return chi2.ppf(a, k) / runs, chi2.ppf(1.0 - a, k) / runs


def rms(a: np.ndarray, axis: int | tuple[int, ...] | None = 0) -> np.ndarray:
    """Root mean square along ``axis`` (NaNs ignored)."""
    return np.sqrt(np.nanmean(np.square(a), axis=axis))


def cep50(north: np.ndarray, east: np.ndarray, axis: int = 0) -> np.ndarray:
    """CEP50 [m] of north and east errors [m] over runs (along ``axis``).

    ``0.5887 (LatRMS + LongRMS)`` with the RMS taken over the runs.
    """
    return CEP50_FACTOR * (rms(north, axis) + rms(east, axis))


def nees(e: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared ``e^T P^-1 e`` per epoch.

    Solved on the correlation form of P (robust to states of very different units); an epoch
    whose P is singular (a zero variance, or perfectly correlated states) gives NaN.

    Parameters
    ----------
    e : ndarray, shape (M, k)
        Estimation errors.
    P : ndarray, shape (M, k, k)
        Their covariances.

    Returns
    -------
    ndarray, shape (M,)
    """
    e = np.asarray(e, dtype=float)
    P = np.asarray(P, dtype=float)
    out = np.full(e.shape[0], np.nan)
    if e.shape[1] == 0:
        return out
    d = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
    ok = np.all(d > 0.0, axis=1) & np.all(np.isfinite(e), axis=1)
    if not ok.any():
        return out
    s = d[ok]
    en = e[ok] / s
    C = P[ok] / s[:, :, None] / s[:, None, :]
    try:
        L = np.linalg.cholesky(C)
        w = np.linalg.solve(L, en[..., None])[..., 0]
        out[ok] = np.einsum("ki,ki->k", w, w)
    except np.linalg.LinAlgError:
        vals = np.empty(en.shape[0])
        for i in range(en.shape[0]):
            try:
                L = np.linalg.cholesky(C[i])
                w = np.linalg.solve(L, en[i])
                vals[i] = w @ w
            except np.linalg.LinAlgError:
                vals[i] = np.nan
        out[ok] = vals
    return out


# --------------------------------------------------------------------------------------------
# truth


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
    """

    stream: Stream
    t0_ns: int
    true_errors: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    @classmethod
    def of(cls, source: Recording | Reference) -> Reference:
        """The reference of a recording (its truth stream and true errors)."""
        if isinstance(source, Reference):
            return source
        if StreamKind.TRUTH not in source:
            raise ValueError("the recording has no truth stream to score against")
        return cls(source[StreamKind.TRUTH], source.t0_ns, source.metadata.true_errors)

    def __contains__(self, column: str) -> bool:
        return column in self.stream.columns

    def at(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """The columns at filter times ``t`` [s since the recording start].

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
        ts = seconds(ref.t_ns, self.t0_ns)
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
        ref = self.stream
        ts = seconds(ref.t_ns, self.t0_ns)
        if "v_n" in ref.columns:
            speed = np.linalg.norm(ref["v_n"], axis=1)
            steps = 0.5 * (speed[1:] + speed[:-1]) * np.diff(ts)
        elif "pos" in ref.columns:
            steps = np.linalg.norm(position_error_ned(ref["pos"][1:], ref["pos"][:-1]), axis=1)
        else:
            return np.full(np.shape(t), np.nan) if t is not None else math.nan
        cum = np.concatenate([[0.0], np.cumsum(steps)])
        if t is None:
            return float(cum[-1])
        return np.interp(t, ts, cum)


def truth_at(recording: Recording | Reference, t: np.ndarray) -> dict[str, np.ndarray]:
    """The reference's columns at filter times ``t`` (:meth:`Reference.at`)."""
    return Reference.of(recording).at(t)


# --------------------------------------------------------------------------------------------
# navigation errors


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
        phi = attitude_error(quat_to_dcm(q_nb), quat_to_dcm(truth["q_nb"]))
        euler = wrap_angle(quat_to_euler(q_nb) - quat_to_euler(truth["q_nb"]))
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
        return v[(slice(None), *t.index)] if t.index else v
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
        Their covariance (the block of ``result.P``).
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
    ix = np.array(idx)
    return tuple(names), np.stack(cols, axis=1), result.P[:, ix[:, None], ix[None, :]]


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


# --------------------------------------------------------------------------------------------
# one run


@dataclasses.dataclass
class RunMetrics:
    """Compact scores of one filter run (picklable; what an ensemble accumulates).

    Attributes
    ----------
    label : str
    t : ndarray, shape (M,)
        Estimate times [s].
    nav : NavErrors or None
        Navigation errors (None for a filter without a navigation solution).
    nav_sigma : dict[str, ndarray (M, 3)]
        Predicted 1-sigma of ``pos_ned`` [m], ``v_n`` [m/s], ``phi`` [rad]; NaN where the
        filter has no state for it.
    state_names : tuple of str
        States scored against a truth.
    state_error : ndarray, shape (M, k)
        Their estimation errors.
    state_var : ndarray, shape (M, k)
        Their predicted variances.
    nees : ndarray, shape (M,)
        NEES over ``nees_states`` (NaN where their covariance is singular).
    nees_states : tuple of str
    nis : dict[str, tuple[ndarray (K,), ndarray (K,), int]]
        Per measurement: update times [s], NIS, dof.
    nis_rows : dict[str, dict[str, ndarray (K,)]]
        Per measurement of several rows: the NIS of each row by its declared name
        (:func:`row_nis`).
    distance : ndarray, shape (M,)
        True distance travelled up to each estimate [m].
    extra_error : dict[str, ndarray (M, ...)]
        Errors of the scored extras (``RunResult.scored_extras``).
    states : tuple of State
        The declarations of the scored states (``state_names``, same order): units and
        quantities for tables, exports and plots.
    """

    label: str
    t: np.ndarray
    nav: NavErrors | None
    nav_sigma: dict[str, np.ndarray]
    state_names: tuple[str, ...]
    state_error: np.ndarray
    state_var: np.ndarray
    nees: np.ndarray
    nees_states: tuple[str, ...]
    nis: dict[str, tuple[np.ndarray, np.ndarray, int]]
    distance: np.ndarray
    extra_error: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    states: tuple[State, ...] = ()
    nis_rows: dict[str, dict[str, np.ndarray]] = dataclasses.field(default_factory=dict)

    def summary(self, probability: float = 0.95) -> dict[str, Any]:
        """Scalar scores (SI; see :data:`SUMMARY_UNITS`) for tables and JSON."""
        out: dict[str, Any] = {"duration": float(self.t[-1] - self.t[0]) if self.t.size else 0.0}
        if self.t.size and np.isfinite(self.distance[-1]):
            out["distance"] = float(self.distance[-1])
        elif not self.t.size:
            out["distance"] = 0.0
        if self.nav is not None and self.t.size:
            p = self.nav.pos_ned
            if np.isfinite(p).any():
                h = np.hypot(p[:, 0], p[:, 1])
                out["pos_err_final_h"] = float(h[np.isfinite(h)][-1])
                out["pos_rms_h"] = float(rms(h, None))
                out["pos_rms_v"] = float(rms(p[:, 2], None))
                if out.get("distance", 0.0) > 0.0:
                    out["pos_err_final_dt"] = 100.0 * out["pos_err_final_h"] / out["distance"]
            if np.isfinite(self.nav.v_n).any():
                out["vel_rms"] = float(rms(np.linalg.norm(self.nav.v_n, axis=1), None))
            if np.isfinite(self.nav.phi).any():
                out["att_rms_level"] = float(rms(self.nav.phi[:, :2], None))
                out["att_rms_heading"] = float(rms(self.nav.phi[:, 2], None))
        _chi2_summary(out, "nees", "", self.nees, np.isfinite(self.nees).astype(int),
                      len(self.nees_states), probability)
        for name, (_, v, dof) in self.nis.items():
            _chi2_summary(out, "nis", f"_{name}", v, np.ones(v.shape, int), dof, probability)
            for row, w in self.nis_rows.get(name, {}).items():
                _chi2_summary(out, "nis", f"_{name}.{row}", w, np.ones(w.shape, int), 1,
                              probability)
        return out


def row_nis(result: RunResult, name: str) -> dict[str, np.ndarray]:
    """The normalised innovation squared of each row of measurement ``name``,
    ``nu_i^2 / S_ii`` (chi-square of one degree of freedom for a consistent filter), by the
    row names the filter declares (else ``"0"``, ``"1"``, ...); empty for a measurement of one
    row (its NIS is that of the row). Which row of a measurement is inconsistent."""
    s = result.innovations[name]
    m = s.nu.shape[1]
    if m < 2:
        return {}
    declared = result.measurement(name)
    rows = declared.rows if declared is not None else tuple(str(i) for i in range(m))
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.square(s.nu) / np.diagonal(s.S, axis1=1, axis2=2)
    return {row: v[:, i] for i, row in enumerate(rows)}


def _chi2_summary(out: dict, kind: str, suffix: str, values: np.ndarray, count: np.ndarray,
                  dof: int, probability: float) -> None:
    """Add ``<kind>_dof<suffix>``, ``<kind>_mean<suffix>`` and ``<kind>_in_bounds<suffix>``
    (the fraction of indexes inside the chi-square bounds of their run count) of a NEES or NIS
    series to ``out``."""
    ok = count > 0
    if dof == 0 or not ok.any():
        return
    v = values[ok]
    out[f"{kind}_dof{suffix}"] = dof
    out[f"{kind}_mean{suffix}"] = float(np.mean(v))
    lo, hi = chi2_bounds_per_count(dof, count[ok], probability)
    out[f"{kind}_in_bounds{suffix}"] = float(np.mean((v >= lo) & (v <= hi)))


def chi2_bounds_per_count(
    dof: int, count: np.ndarray, probability: float = 0.95
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`chi2_bounds` elementwise for means over ``count`` runs (NaN where the count is 0).

    Parameters
    ----------
    dof : int
    count : ndarray of int, shape (M,)
        Runs averaged at each index.
    probability : float

    Returns
    -------
    lo, hi : ndarray, shape (M,)
    """
    lo = np.full(count.shape, np.nan)
    hi = np.full(count.shape, np.nan)
    for c in np.unique(count[count > 0]):
        lo[count == c], hi[count == c] = chi2_bounds(dof, int(c), probability)
    return lo, hi


def run_metrics(
    result: RunResult,
    reference: Recording | Reference | None,
    *,
    states: tuple[State, ...] | None = None,
) -> RunMetrics:
    """Score one filter run against a reference (the recording's truth, or any
    :class:`Reference`); what the reference lacks is left unscored. Without a reference (None,
    or a recording without a truth stream) only the innovation statistics are kept.

    Parameters
    ----------
    result : RunResult
    reference : Recording or Reference or None
        The recording the filter ran over (truth stream and ``metadata.true_errors``), or a
        reference built from elsewhere, or None.
    states : tuple of State, optional
        Score with these declarations instead of ``result.states`` (same names and order),
        e.g. against other truth columns.

    Returns
    -------
    RunMetrics
    """
    nis = {name: (s.t.copy(), s.nis.copy(), int(s.nu.shape[1]))
           for name, s in result.innovations.items()}
    nis_rows = {name: rows for name in result.innovations if (rows := row_nis(result, name))}
    M = result.t.shape[0]
    if reference is None or (isinstance(reference, Recording)
                             and StreamKind.TRUTH not in reference):
        return RunMetrics(
            label=result.label, t=result.t.copy(), nav=None, nav_sigma=nav_sigma(result),
            state_names=(), state_error=np.zeros((M, 0)), state_var=np.zeros((M, 0)),
            nees=np.full(M, np.nan), nees_states=(), nis=nis, distance=np.full(M, np.nan),
            nis_rows=nis_rows,
        )
    ref = Reference.of(reference)
    states = result.states if states is None else states
    if tuple(s.name for s in states) != result.state_names:
        raise ValueError(f"{result.label}: the scoring declarations name other states than "
                         f"the result ({', '.join(result.state_names)})")
    truth = ref.at(result.t)
    nav = None
    if result.nav_pos is not None:
        nav = nav_errors(result.nav_pos, result.nav_v_n, result.nav_q_nb, truth,
                         result.navigation)
    nav_for_states = nav if nav is not None else NavErrors(*(np.full((M, 3), np.nan),) * 4)
    names, e, P = state_errors(result, truth, ref.true_errors, states, nav_for_states)
    by_name = {st.name: st for st in states}
    var = np.diagonal(P, axis1=1, axis2=2).copy()
    in_nees = {s.name for s in states if s.nees}
    sel = [i for i, n in enumerate(names) if n in in_nees]
    ix = np.array(sel, dtype=int)
    nees_v = nees(e[:, ix], P[:, ix[:, None], ix[None, :]])
    return RunMetrics(
        label=result.label,
        t=result.t.copy(),
        nav=nav,
        nav_sigma=nav_sigma(result, states),
        state_names=names,
        state_error=e,
        state_var=var,
        nees=nees_v,
        nees_states=tuple(names[i] for i in sel),
        nis=nis,
        nis_rows=nis_rows,
        distance=np.asarray(ref.distance(result.t)),
        states=tuple(by_name[n] for n in names),
        extra_error=extra_errors(result, truth, ref.true_errors),
    )


# --------------------------------------------------------------------------------------------
# ensembles


class _Acc:
    """Per-index running sums that grow with the longest run."""

    def __init__(self) -> None:
        self.sum: np.ndarray | None = None
        self.sq: np.ndarray | None = None
        self.n: np.ndarray | None = None

    def add(self, a: np.ndarray) -> None:
        a = np.asarray(a, dtype=float)
        ok = np.isfinite(a)
        v = np.where(ok, a, 0.0)
        if self.sum is None:
            self.sum = np.zeros_like(v)
            self.sq = np.zeros_like(v)
            self.n = np.zeros(v.shape, dtype=np.int64)
        m = v.shape[0]
        if m > self.sum.shape[0]:
            grow = ((0, m - self.sum.shape[0]),) + ((0, 0),) * (v.ndim - 1)
            self.sum = np.pad(self.sum, grow)
            self.sq = np.pad(self.sq, grow)
            self.n = np.pad(self.n, grow)
        if v.shape[1:] != self.sum.shape[1:]:
            raise ValueError(f"runs disagree in shape: {v.shape[1:]} vs {self.sum.shape[1:]}")
        self.sum[:m] += v
        self.sq[:m] += v * v
        self.n[:m] += ok

    def mean(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.sum / self.n

    def rms(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sqrt(self.sq / self.n)


@dataclasses.dataclass
class EnsembleResult:
    """Statistics of N runs per time index (see :class:`EnsembleStats`).

    Attributes
    ----------
    label : str
    runs : int
    t : ndarray, shape (M,)
    rms : dict[str, ndarray (M, 3)]
        RMS over runs of the ``pos_ned``, ``v_n``, ``phi``, ``euler`` errors (those scored in
        any run).
    mean : dict[str, ndarray (M, 3)]
        Mean over runs of the same errors.
    sigma : dict[str, ndarray (M, 3)]
        ``sqrt(mean predicted variance)`` of ``pos_ned``, ``v_n``, ``phi``.
    state_names : tuple of str
    states : tuple of State
        Their declarations (units, quantities).
    state_rms, state_mean, state_sigma : ndarray, shape (M, k)
    nees_mean : ndarray, shape (M,)
    nees_count : ndarray, shape (M,)
        Runs with a finite NEES per index.
    nees_dof : int
    nees_bounds : tuple of ndarray (M,)
    nis_mean : dict[str, tuple[ndarray (K,) t, ndarray (K,) mean, ndarray (K,) count, int dof]]
    nis_rows_mean : dict[str, dict[str, ndarray (K,)]]
        Per measurement of several rows: each row's NIS (:func:`row_nis`) averaged over the
        runs (the counts of ``nis_mean``).
    cep50 : ndarray, shape (M,)
        ``0.5887 (LatRMS + LongRMS)`` [m].
    distance : ndarray, shape (M,)
        Mean true distance travelled [m].
    consistency : EnsembleConsistency or None
        Per-axis RMS/sigma with intervals and checks, and the per-run time-averaged NEES tests
        (:mod:`navreplay.consistency`).
    """

    label: str
    runs: int
    t: np.ndarray
    rms: dict[str, np.ndarray]
    mean: dict[str, np.ndarray]
    sigma: dict[str, np.ndarray]
    state_names: tuple[str, ...]
    states: tuple[State, ...]
    state_rms: np.ndarray
    state_mean: np.ndarray
    state_sigma: np.ndarray
    nees_mean: np.ndarray
    nees_count: np.ndarray
    nees_dof: int
    nees_bounds: tuple[np.ndarray, np.ndarray]
    nis_mean: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, int]]
    cep50: np.ndarray
    distance: np.ndarray
    nis_rows_mean: dict[str, dict[str, np.ndarray]] = dataclasses.field(default_factory=dict)
    consistency: EnsembleConsistency | None = None

    @property
    def dt_cep50(self) -> np.ndarray:
        """CEP50 / DT x 100 [%] per index (NaN before the vehicle moved)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.distance > 0.0, 100.0 * self.cep50 / self.distance, np.nan)

    def summary(self, probability: float = 0.95) -> dict[str, Any]:
        """Scalar scores at the final index and over time (SI; see :data:`SUMMARY_UNITS`)."""
        out: dict[str, Any] = {"runs": self.runs}
        if self.t.size == 0:
            return out
        out["duration"] = float(self.t[-1] - self.t[0])
        out["distance"] = float(self.distance[-1])
        if "pos_ned" in self.rms and np.isfinite(self.rms["pos_ned"]).any():
            r = self.rms["pos_ned"][-1]
            out["lat_rms_final"] = float(r[0])
            out["long_rms_final"] = float(r[1])
            out["cep50_final"] = float(self.cep50[-1])
            if self.distance[-1] > 0.0:
                out["dt_cep50_final"] = float(self.dt_cep50[-1])
            out["pos_rms_h"] = float(np.sqrt(np.nanmean(np.sum(self.rms["pos_ned"][:, :2] ** 2,
                                                                 axis=1))))
        if "phi" in self.rms and np.isfinite(self.rms["phi"]).any():
            out["att_rms_level"] = float(rms(self.rms["phi"][:, :2], None))
            out["att_rms_heading"] = float(rms(self.rms["phi"][:, 2], None))
        _chi2_summary(out, "nees", "", self.nees_mean, self.nees_count, self.nees_dof,
                      probability)
        for name, (_, m, c, dof) in self.nis_mean.items():
            _chi2_summary(out, "nis", f"_{name}", m, c, dof, probability)
            for row, v in self.nis_rows_mean.get(name, {}).items():
                _chi2_summary(out, "nis", f"_{name}.{row}", v, c, 1, probability)
        if self.consistency is not None:
            out.update(self.consistency.summary())
        return out


class EnsembleStats:
    """Monte Carlo statistics accumulated run by run, without keeping the runs.

    Keeps running sums per time index of the errors, their squares and the predicted
    variances, the NEES and the NIS; :meth:`result` turns them into RMS, mean, filter sigma,
    run-averaged NEES / NIS with their chi-square bounds, CEP50 and DT CEP50. Runs must share
    their output times (the same scenario and rates); a longer run extends the arrays.

    Examples
    --------
    >>> stats = EnsembleStats()
    >>> for m in run_metrics_list:                 # doctest: +SKIP
    ...     stats.add(m)
    >>> res = stats.result()                       # doctest: +SKIP
    >>> print(format_table({"gps-ins": res.summary()}))  # doctest: +SKIP
    """

    def __init__(self, label: str = "") -> None:
        self.label = label
        self.runs = 0
        self._t: np.ndarray | None = None
        self._nav = {k: _Acc() for k in ("pos_ned", "v_n", "phi", "euler")}
        self._var = {k: _Acc() for k in ("pos_ned", "v_n", "phi")}
        self._state = _Acc()
        self._state_var = _Acc()
        self._nees = _Acc()
        self._dist = _Acc()
        self._nis: dict[str, tuple[_Acc, list, int]] = {}
        self._nis_rows: dict[str, dict[str, _Acc]] = {}
        self._consistency = ConsistencyStats()
        self._state_names: tuple[str, ...] | None = None
        self._nees_states: tuple[str, ...] | None = None
        self._states: tuple[State, ...] = ()

    def add(self, m: RunMetrics) -> None:
        """Add one run's metrics."""
        if self._t is None or m.t.shape[0] > self._t.shape[0]:
            ref = self._t
            if ref is not None and not np.allclose(m.t[: ref.shape[0]], ref, atol=1e-6):
                raise ValueError(f"run {self.runs + 1} ({m.label}) has other output times")
            self._t = m.t.copy()
        elif not np.allclose(m.t, self._t[: m.t.shape[0]], atol=1e-6):
            raise ValueError(f"run {self.runs + 1} ({m.label}) has other output times")
        if self._state_names is None:
            self._state_names, self._nees_states = m.state_names, m.nees_states
            self._states = m.states
            self.label = self.label or m.label
        elif m.state_names != self._state_names or m.nees_states != self._nees_states:
            raise ValueError(f"run {self.runs + 1} ({m.label}) scores other states")
        if m.nav is not None:
            for k, acc in self._nav.items():
                acc.add(getattr(m.nav, k))
            for k, acc in self._var.items():
                acc.add(m.nav_sigma[k] ** 2)
        self._state.add(m.state_error)
        self._state_var.add(m.state_var)
        self._consistency.add(m.state_error, m.state_var, m.nees,
                              np.array([m.state_names.index(n) for n in m.nees_states], int))
        self._nees.add(m.nees)
        self._dist.add(m.distance)
        for name, (t, v, dof) in m.nis.items():
            if name not in self._nis:
                self._nis[name] = (_Acc(), [t.copy()], dof)
            acc, tref, d = self._nis[name]
            if d != dof:
                raise ValueError(f"measurement {name}: dof {dof} differs from {d}")
            if t.shape[0] > tref[0].shape[0]:
                tref[0] = t.copy()
            acc.add(v)
            for row, w in m.nis_rows.get(name, {}).items():
                self._nis_rows.setdefault(name, {}).setdefault(row, _Acc()).add(w)
        self.runs += 1

    def result(self) -> EnsembleResult:
        """The statistics of the runs added so far."""
        if self._t is None:
            raise ValueError("no runs added")
        M = self._t.shape[0]
        nan3 = np.full((M, 3), np.nan)
        # errors never scored (a part of the solution the filters do not output, a column the
        # reference lacks) are absent
        scored = {k: a for k, a in self._nav.items() if a.sum is not None and a.n.any()}
        rms_ = {k: a.rms() for k, a in scored.items()}
        mean = {k: a.mean() for k, a in scored.items()}
        sigma = {k: np.sqrt(a.mean()) if a.sum is not None else nan3
                 for k, a in self._var.items()}
        k_states = len(self._state_names or ())
        empty = np.zeros((M, k_states))
        nees_count = self._nees.n if self._nees.n is not None else np.zeros(M, int)
        dof = len(self._nees_states or ())
        if dof:
            lo, hi = chi2_bounds_per_count(dof, nees_count)
        else:
            lo, hi = np.full(M, np.nan), np.full(M, np.nan)
        if "pos_ned" in rms_:
            c50 = CEP50_FACTOR * (rms_["pos_ned"][:, 0] + rms_["pos_ned"][:, 1])
        else:
            c50 = np.full(M, np.nan)
        return EnsembleResult(
            label=self.label,
            runs=self.runs,
            t=self._t.copy(),
            rms=rms_,
            mean=mean,
            sigma=sigma,
            state_names=self._state_names or (),
            states=self._states,
            state_rms=self._state.rms() if self._state.sum is not None else empty,
            state_mean=self._state.mean() if self._state.sum is not None else empty,
            state_sigma=(np.sqrt(self._state_var.mean()) if self._state_var.sum is not None
                         else empty),
            nees_mean=self._nees.mean() if self._nees.sum is not None else np.full(M, np.nan),
            nees_count=nees_count,
            nees_dof=dof,
            nees_bounds=(lo, hi),
            nis_mean={name: (tref[0], acc.mean(), acc.n, d)
                      for name, (acc, tref, d) in self._nis.items()},
            cep50=c50,
            distance=self._dist.mean(),
            nis_rows_mean={name: {row: acc.mean() for row, acc in rows.items()}
                           for name, rows in self._nis_rows.items()},
            consistency=self._consistency.result(self._state_names or (),
                                                 self._nees_states or ()),
        )
