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

Scoring error states: ``Filter.truth_keys``
-------------------------------------------
A filter maps an output name (a state name or an extras key) to the truth of that quantity:

``"nav:<q>"``
    The state is an error of the navigation solution (an error-state filter): its estimation
    error is the solution's error in ``q`` minus the state estimate, ``e = (nav_hat - truth)_q -
    x``; ``q`` is one of ``lat, lon, h, depth`` (rad, rad, m, m positive down), ``v_N, v_E,
    v_D`` (m/s), ``phi_N, phi_E, phi_D`` (rad).
``"truth:<column>"`` or ``"truth:<column>[i]"``
    A column of the truth stream (interpolated to the estimate times): ``e = x - truth``.
``"<key>"``, ``"<key>.<subkey>"``, optionally ``[i]`` or ``[i][j]``
    A constant in ``metadata.true_errors``: ``e = x - value``.

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
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy import stats

from navreplay.geo import earth
from navreplay.geo.rotations import (
    attitude_error,
    quat_to_dcm,
    quat_to_euler,
    wrap_angle,
)
from navreplay.replay.result import RunResult
from navreplay.streams import Recording, StreamKind, seconds

CEP50_FACTOR = 0.5887
"""CEP50 = CEP50_FACTOR (LatRMS + LongRMS) (circular approximation for similar axes)."""

NAV_QUANTITIES = ("lat", "lon", "h", "depth", "v_N", "v_E", "v_D", "phi_N", "phi_E", "phi_D")
"""Quantities of ``"nav:<q>"`` truth keys."""


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
    lo, hi = stats.chi2.ppf([a, 1.0 - a], runs * dof) / runs
    return float(lo), float(hi)


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


def truth_at(recording: Recording, t: np.ndarray) -> dict[str, np.ndarray]:
    """The truth stream's columns at filter times ``t`` [s since the recording start].

    Samples at equal times are taken as they are; between samples, vectors are interpolated
    linearly (longitude unwrapped) and quaternions normalised-linearly. Times outside the
    truth are clipped to its ends.

    Parameters
    ----------
    recording : Recording
        Must hold a truth stream.
    t : ndarray, shape (M,)

    Returns
    -------
    dict
        Column name -> array (M, ...).
    """
    if StreamKind.TRUTH not in recording:
        raise ValueError("the recording has no truth stream to score against")
    truth = recording[StreamKind.TRUTH]
    ts = seconds(truth.t_ns, recording.t0_ns)
    t = np.asarray(t, dtype=float)
    j = np.clip(np.searchsorted(ts, t, side="left"), 1, max(len(ts) - 1, 1))
    i = j - 1
    if len(ts) == 1:
        w = np.zeros_like(t)
        i = j = np.zeros_like(t, dtype=int)
    else:
        w = np.clip((t - ts[i]) / (ts[j] - ts[i]), 0.0, 1.0)
    out = {}
    for name, col in truth.columns.items():
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
    return out


def distance_travelled(recording: Recording, t: np.ndarray | None = None) -> np.ndarray | float:
    """Length of the true path, ``integral |v_n| dt`` [m] (trapezoid over the truth samples).

    Parameters
    ----------
    recording : Recording
    t : ndarray, shape (M,), optional
        Filter times [s]: return the distance from the truth's start up to each (M,).

    Returns
    -------
    float or ndarray
    """
    truth = recording[StreamKind.TRUTH]
    ts = seconds(truth.t_ns, recording.t0_ns)
    if "v_n" in truth.columns:
        speed = np.linalg.norm(truth["v_n"], axis=1)
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(ts))])
    else:  # a reference without velocity: the length of its polyline
        step = np.linalg.norm(np.diff(position_error_ned(truth["pos"], truth["pos"][:1]),
                                      axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(step)])
    if t is None:
        return float(cum[-1])
    return np.interp(t, ts, cum)


# --------------------------------------------------------------------------------------------
# navigation errors


@dataclasses.dataclass
class NavErrors:
    """Errors of a navigation solution, estimate minus truth, each (M, 3).

    Attributes
    ----------
    pos_ned : north, east, down [m].
    v_n : velocity NED [m/s].
    phi : attitude error phi, NED [rad] (``C_hat = (I - [phi x]) C``).
    euler : roll, pitch, yaw differences [rad], yaw wrapped to [-pi, pi).
    """

    pos_ned: np.ndarray
    v_n: np.ndarray
    phi: np.ndarray
    euler: np.ndarray


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
    pos: np.ndarray, v_n: np.ndarray, q_nb: np.ndarray, truth: Mapping[str, np.ndarray]
) -> NavErrors:
    """Errors of a navigation solution against the truth at the same times.

    Parameters
    ----------
    pos, v_n : ndarray, shape (M, 3)
    q_nb : ndarray, shape (M, 4)
    truth : mapping
        ``pos``, ``v_n``, ``q_nb`` arrays at the same times (:func:`truth_at`).

    Returns
    -------
    NavErrors
    """
    nan = np.full(np.shape(pos), np.nan)  # a reference without this quantity
    has_q = "q_nb" in truth
    return NavErrors(
        pos_ned=position_error_ned(pos, truth["pos"]) if "pos" in truth else nan,
        v_n=np.asarray(v_n) - truth["v_n"] if "v_n" in truth else nan,
        phi=attitude_error(quat_to_dcm(q_nb), quat_to_dcm(truth["q_nb"])) if has_q else nan,
        euler=wrap_angle(quat_to_euler(q_nb) - quat_to_euler(truth["q_nb"])) if has_q else nan,
    )


def _nav_quantity(q: str, result: RunResult, truth: Mapping[str, np.ndarray],
                  phi: np.ndarray) -> np.ndarray:
    """Error of the navigation solution in quantity q (units of the corresponding state)."""
    if result.nav_pos is None:
        raise ValueError(f"truth key nav:{q} needs a navigation solution in the result")
    if q == "lat":
        return result.nav_pos[:, 0] - truth["pos"][:, 0]
    if q == "lon":
        return wrap_angle(result.nav_pos[:, 1] - truth["pos"][:, 1])
    if q == "h":
        return result.nav_pos[:, 2] - truth["pos"][:, 2]
    if q == "depth":
        return -(result.nav_pos[:, 2] - truth["pos"][:, 2])
    if q in ("v_N", "v_E", "v_D"):
        return result.nav_v_n[:, "NED".index(q[-1])] - truth["v_n"][:, "NED".index(q[-1])]
    if q in ("phi_N", "phi_E", "phi_D"):
        return phi[:, "NED".index(q[-1])]
    raise ValueError(f"unknown navigation quantity nav:{q}; known: {', '.join(NAV_QUANTITIES)}")


_INDEX = re.compile(r"^(.*?)((?:\[\d+\])*)$")


def _lookup(key: str, true_errors: Mapping[str, Any]) -> float:
    path, idx = _INDEX.match(key).groups()  # type: ignore[union-attr]
    value: Any = true_errors
    for part in path.split("."):
        if not isinstance(value, Mapping) or part not in value:
            raise KeyError(f"metadata.true_errors has no {path!r} (truth key {key!r})")
        value = value[part]
    arr = np.asarray(value, dtype=float)
    for i in re.findall(r"\[(\d+)\]", idx):
        arr = arr[int(i)]
    if arr.ndim != 0:
        raise ValueError(f"truth key {key!r} does not select a single value (shape {arr.shape})")
    return float(arr)


def state_errors(
    result: RunResult,
    truth: Mapping[str, np.ndarray],
    true_errors: Mapping[str, Any],
    truth_keys: Mapping[str, str],
    phi: np.ndarray | None = None,
) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Estimation errors of the states that have a truth (see the module docstring).

    Parameters
    ----------
    result : RunResult
    truth : mapping
        Truth columns at ``result.t`` (:func:`truth_at`).
    true_errors : mapping
        ``metadata.true_errors``.
    truth_keys : mapping
        The filter's ``truth_keys``; keys that are not state names are skipped.
    phi : ndarray, shape (M, 3), optional
        Attitude error of the navigation solution, if already computed.

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
    for i, name in enumerate(result.state_names):
        key = truth_keys.get(name)
        if key is None:
            continue
        x = result.x[:, i]
        if not _has_truth(key, truth) or (not true_errors and ":" not in key):
            continue  # the reference lacks it (error-state scoring needs true errors)
        if key.startswith("nav:"):
            if phi is None and key.startswith("nav:phi"):
                phi = attitude_error(quat_to_dcm(result.nav_q_nb), quat_to_dcm(truth["q_nb"]))
            e = _nav_quantity(key[4:], result, truth, phi) - x
        elif key.startswith("truth:"):
            col, sub = _INDEX.match(key[6:]).groups()  # type: ignore[union-attr]
            if col not in truth:
                raise KeyError(f"the truth stream has no column {col!r} (truth key {key!r})")
            v = truth[col]
            for j in re.findall(r"\[(\d+)\]", sub):
                v = v[:, int(j)]
            e = x - v
        else:
            e = x - _lookup(key, true_errors)
        names.append(name)
        cols.append(e)
        idx.append(i)
    M = result.t.shape[0]
    if not names:
        return (), np.zeros((M, 0)), np.zeros((M, 0, 0))
    ix = np.array(idx)
    return tuple(names), np.stack(cols, axis=1), result.P[:, ix[:, None], ix[None, :]]


def _has_truth(key: str, truth: Mapping[str, np.ndarray]) -> bool:
    """Whether a reference (truth-like stream) holds what the truth key needs; a simulated
    truth stream holds pos, v_n and q_nb."""
    if key.startswith("nav:"):
        q = key[4:]
        need = "q_nb" if q.startswith("phi") else "v_n" if q.startswith("v_") else "pos"
        return need in truth and bool(np.isfinite(truth[need]).all())
    if key.startswith("truth:"):
        return _INDEX.match(key[6:]).group(1) in truth  # type: ignore[union-attr]
    return True


def _nav_sigma(result: RunResult, truth_keys: Mapping[str, str]) -> dict[str, np.ndarray]:
    """Predicted 1-sigma of the navigation errors (pos_ned [m], v_n, phi), NaN if unknown."""
    M = result.t.shape[0]
    out = {k: np.full((M, 3), np.nan) for k in ("pos_ned", "v_n", "phi")}
    var = np.diagonal(result.P, axis1=1, axis2=2)
    where = {
        "nav:lat": ("pos_ned", 0), "nav:lon": ("pos_ned", 1), "nav:h": ("pos_ned", 2),
        "nav:depth": ("pos_ned", 2),
        "nav:v_N": ("v_n", 0), "nav:v_E": ("v_n", 1), "nav:v_D": ("v_n", 2),
        "nav:phi_N": ("phi", 0), "nav:phi_E": ("phi", 1), "nav:phi_D": ("phi", 2),
    }
    scale = None
    if result.nav_pos is not None:
        lat, h = result.nav_pos[:, 0], result.nav_pos[:, 2]
        R_M, R_N = earth.radii(lat)
        scale = {"nav:lat": R_M + h, "nav:lon": (R_N + h) * np.cos(lat)}
    for i, name in enumerate(result.state_names):
        key = truth_keys.get(name)
        if key not in where:
            continue
        group, j = where[key]
        s = np.sqrt(np.clip(var[:, i], 0.0, None))
        if key in ("nav:lat", "nav:lon"):
            if scale is None:
                continue
            s = s * scale[key]
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
    distance : ndarray, shape (M,)
        True distance travelled up to each estimate [m].
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

    def summary(self, probability: float = 0.95) -> dict[str, Any]:
        """Scalar scores (SI; see :data:`SUMMARY_UNITS`) for tables and JSON."""
        out: dict[str, Any] = {"duration": float(self.t[-1] - self.t[0]) if self.t.size else 0.0,
                               "distance": float(self.distance[-1]) if self.t.size else 0.0}
        if self.nav is not None and self.t.size:
            p = self.nav.pos_ned
            h = np.hypot(p[:, 0], p[:, 1])
            out["pos_err_final_h"] = float(h[-1])
            out["pos_rms_h"] = float(rms(h, None))
            out["pos_rms_v"] = float(rms(p[:, 2], None))
            out["vel_rms"] = float(rms(np.linalg.norm(self.nav.v_n, axis=1), None))
            out["att_rms_level"] = float(rms(self.nav.phi[:, :2], None))
            out["att_rms_heading"] = float(rms(self.nav.phi[:, 2], None))
            if out["distance"] > 0.0:
                out["pos_err_final_dt"] = 100.0 * out["pos_err_final_h"] / out["distance"]
            out = {k: v for k, v in out.items() if not math.isnan(v)}  # what the reference has
        _chi2_summary(out, "nees", "", self.nees, np.isfinite(self.nees).astype(int),
                      len(self.nees_states), probability)
        for name, (_, v, dof) in self.nis.items():
            _chi2_summary(out, "nis", f"_{name}", v, np.ones(v.shape, int), dof, probability)
        return out


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
    recording: Recording,
    *,
    truth_keys: Mapping[str, str] | None = None,
    nees_states: Sequence[str] | None = None,
) -> RunMetrics:
    """Score one filter run against the recording's truth.

    Parameters
    ----------
    result : RunResult
    recording : Recording
        The recording the filter ran over (truth stream and metadata).
    truth_keys : mapping, optional
        Output name -> truth key; default: the registered filter's ``truth_keys``.
    nees_states : sequence of str, optional
        States of the NEES (a block); default: the filter class's ``nees_states`` attribute
        when it declares one, else every scored state whose variance is positive at some
        epoch.

    Returns
    -------
    RunMetrics
    """
    if StreamKind.TRUTH not in recording:  # no reference: innovation statistics only
        M = result.t.shape[0]
        return RunMetrics(result.label, result.t.copy(), None, {}, (), np.zeros((M, 0)),
                          np.zeros((M, 0)), np.full(M, np.nan), (),
                          {n: (s.t.copy(), s.nis.copy(), int(s.nu.shape[1]))
                           for n, s in result.innovations.items()}, np.zeros(M))
    truth = truth_at(recording, result.t)
    if truth_keys is None or nees_states is None:
        keys, default_nees = _registered_scoring(result.filter_name)
        truth_keys = keys if truth_keys is None else truth_keys
        if nees_states is None and default_nees is not None:
            nees_states = [s for s in default_nees if s in result.state_names
                           and _has_truth(truth_keys.get(s, ""), truth)]
    nav = None
    if result.nav_pos is not None:
        nav = nav_errors(result.nav_pos, result.nav_v_n, result.nav_q_nb, truth)
    names, e, P = state_errors(result, truth, recording.metadata.true_errors, truth_keys,
                               phi=None if nav is None else nav.phi)
    var = np.diagonal(P, axis1=1, axis2=2).copy()
    if nees_states is None:
        sel = [i for i in range(len(names)) if np.any(var[:, i] > 0.0)]
    else:
        missing = [s for s in nees_states if s not in names]
        if missing:
            raise ValueError(f"NEES states without a truth: {', '.join(missing)} "
                             f"(scored: {', '.join(names)})")
        sel = [names.index(s) for s in nees_states]
    ix = np.array(sel, dtype=int)
    nees_v = nees(e[:, ix], P[:, ix[:, None], ix[None, :]])
    nis = {name: (s.t.copy(), s.nis.copy(), int(s.nu.shape[1]))
           for name, s in result.innovations.items()}
    return RunMetrics(
        label=result.label,
        t=result.t.copy(),
        nav=nav,
        nav_sigma=_nav_sigma(result, truth_keys),
        state_names=names,
        state_error=e,
        state_var=var,
        nees=nees_v,
        nees_states=tuple(names[i] for i in sel),
        nis=nis,
        distance=np.asarray(distance_travelled(recording, result.t)),
    )


def _registered_scoring(filter_name: str) -> tuple[Mapping[str, str], Sequence[str] | None]:
    """``truth_keys`` and ``nees_states`` (or None) of a registered filter."""
    from navreplay.filters.registry import FilterLoadError, load_filter

    try:
        cls = load_filter(filter_name)
    except FilterLoadError:
        return {}, None
    return cls.truth_keys, getattr(cls, "nees_states", None)


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
        RMS over runs of the ``pos_ned``, ``v_n``, ``phi``, ``euler`` errors.
    mean : dict[str, ndarray (M, 3)]
        Mean over runs of the same errors.
    sigma : dict[str, ndarray (M, 3)]
        ``sqrt(mean predicted variance)`` of ``pos_ned``, ``v_n``, ``phi``.
    state_names : tuple of str
    state_rms, state_mean, state_sigma : ndarray, shape (M, k)
    nees_mean : ndarray, shape (M,)
    nees_count : ndarray, shape (M,)
        Runs with a finite NEES per index.
    nees_dof : int
    nees_bounds : tuple of ndarray (M,)
    nis_mean : dict[str, tuple[ndarray (K,) t, ndarray (K,) mean, ndarray (K,) count, int dof]]
    cep50 : ndarray, shape (M,)
        ``0.5887 (LatRMS + LongRMS)`` [m].
    distance : ndarray, shape (M,)
        Mean true distance travelled [m].
    """

    label: str
    runs: int
    t: np.ndarray
    rms: dict[str, np.ndarray]
    mean: dict[str, np.ndarray]
    sigma: dict[str, np.ndarray]
    state_names: tuple[str, ...]
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
        if "pos_ned" in self.rms:
            r = self.rms["pos_ned"][-1]
            out["lat_rms_final"] = float(r[0])
            out["long_rms_final"] = float(r[1])
            out["cep50_final"] = float(self.cep50[-1])
            if self.distance[-1] > 0.0:
                out["dt_cep50_final"] = float(self.dt_cep50[-1])
            out["pos_rms_h"] = float(np.sqrt(np.nanmean(np.sum(self.rms["pos_ned"][:, :2] ** 2,
                                                                 axis=1))))
            out["att_rms_level"] = float(rms(self.rms["phi"][:, :2], None))
            out["att_rms_heading"] = float(rms(self.rms["phi"][:, 2], None))
        _chi2_summary(out, "nees", "", self.nees_mean, self.nees_count, self.nees_dof,
                      probability)
        for name, (_, m, c, dof) in self.nis_mean.items():
            _chi2_summary(out, "nis", f"_{name}", m, c, dof, probability)
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
        self._state_names: tuple[str, ...] | None = None
        self._nees_states: tuple[str, ...] | None = None

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
        self.runs += 1

    def result(self) -> EnsembleResult:
        """The statistics of the runs added so far."""
        if self._t is None:
            raise ValueError("no runs added")
        M = self._t.shape[0]
        nan3 = np.full((M, 3), np.nan)
        rms_ = {k: a.rms() for k, a in self._nav.items() if a.sum is not None}
        mean = {k: a.mean() for k, a in self._nav.items() if a.sum is not None}
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
        )


# --------------------------------------------------------------------------------------------
# tables

SUMMARY_UNITS: dict[str, tuple[str, float]] = {
    "runs": ("", 1.0),
    "duration": ("s", 1.0),
    "distance": ("km", 1e-3),
    "pos_err_final_h": ("m", 1.0),
    "pos_err_final_dt": ("%DT", 1.0),
    "pos_rms_h": ("m", 1.0),
    "pos_rms_v": ("m", 1.0),
    "vel_rms": ("m/s", 1.0),
    "att_rms_level": ("mrad", 1e3),
    "att_rms_heading": ("mrad", 1e3),
    "lat_rms_final": ("m", 1.0),
    "long_rms_final": ("m", 1.0),
    "cep50_final": ("m", 1.0),
    "dt_cep50_final": ("%", 1.0),
    "nees_mean": ("", 1.0),
    "nees_dof": ("", 1.0),
    "nees_in_bounds": ("%", 100.0),
}
"""Display unit and factor from SI for each summary key (``nis_*`` keys like ``nees_*``)."""


def _unit(key: str) -> tuple[str, float]:
    if key in SUMMARY_UNITS:
        return SUMMARY_UNITS[key]
    for prefix in ("nis_mean_", "nis_dof_", "nis_in_bounds_"):
        if key.startswith(prefix):
            return SUMMARY_UNITS[prefix.replace("nis", "nees").rstrip("_")]
    return ("", 1.0)


def format_table(
    summaries: Mapping[str, Mapping[str, Any]], keys: Sequence[str] | None = None
) -> str:
    """A compact text table of summary dicts, one row per label.

    Parameters
    ----------
    summaries : mapping
        Label -> summary dict (:meth:`RunMetrics.summary`, :meth:`EnsembleResult.summary`).
    keys : sequence of str, optional
        Columns; default: every numeric key present in any summary, in first-seen order.

    Returns
    -------
    str

    Examples
    --------
    >>> print(format_table({"ins": {"pos_rms_h": 812.0, "att_rms_level": 0.00123},
    ...                     "gps-ins": {"pos_rms_h": 0.9}}))
    label    pos_rms_h  att_rms_level
             [m]        [mrad]
    ins      812        1.23
    gps-ins  0.9        -
    """
    if keys is None:
        keys = []
        for s in summaries.values():
            for k, v in s.items():
                if k not in keys and isinstance(v, int | float) and not isinstance(v, bool):
                    keys.append(k)
    header = ["label", *keys]
    units = ["", *(f"[{_unit(k)[0]}]" if _unit(k)[0] else "" for k in keys)]
    rows = []
    for label, s in summaries.items():
        row = [label]
        for k in keys:
            v = s.get(k)
            if v is None or (isinstance(v, float) and not math.isfinite(v)):
                row.append("-")
            else:
                row.append(f"{float(v) * _unit(k)[1]:.3g}")
        rows.append(row)
    table = [header, units, *rows]
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
             for r in table]
    return "\n".join(line for line in lines if line)
