"""Array conversions behind the Rerun output: truth at output times, navigation errors, local
NED positions, position covariance in metres, 3-sigma ellipsoids, chi-square bounds.

Pure numpy; no rerun import, so everything here is testable alone.
All angles in radians, positions as ``[lat, lon, h]`` (rad, rad, m), quaternions ``q_nb``
scalar first; the xyzw order appears only in :func:`ellipsoids`, whose output goes to Rerun.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from navreplay.geo import (
    dcm_to_quat,
    lla_to_ned_offset,
    quat_to_euler,
    quat_wxyz_to_xyzw,
    radii,
)


@dataclasses.dataclass(frozen=True)
class NavColumns:
    """A navigation solution as columns.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time [s since the recording start].
    pos : ndarray, shape (N, 3)
        Latitude, longitude [rad], height [m].
    v_n : ndarray, shape (N, 3)
        Velocity NED [m/s].
    q_nb : ndarray, shape (N, 4)
        Attitude quaternion b -> n, scalar first.
    """

    t: np.ndarray
    pos: np.ndarray
    v_n: np.ndarray
    q_nb: np.ndarray

    def __post_init__(self) -> None:
        n = self.t.shape[0]
        for name, shape in (("pos", (n, 3)), ("v_n", (n, 3)), ("q_nb", (n, 4))):
            if getattr(self, name).shape != shape:
                raise ValueError(f"{name} has shape {getattr(self, name).shape}, expected {shape}")

    def at(self, t: np.ndarray) -> NavColumns:
        """Linear interpolation at times ``t`` [s] (quaternions: normalised linear blend on the
        shorter arc); NaN outside the covered interval."""
        t = np.asarray(t, dtype=np.float64)
        src = self.t
        if src.shape[0] == 0:
            nan = np.full((t.shape[0], 1), np.nan)
            return NavColumns(t, nan.repeat(3, 1), nan.repeat(3, 1), nan.repeat(4, 1))
        k = np.clip(np.searchsorted(src, t, side="right") - 1, 0, max(src.shape[0] - 2, 0))
        k1 = np.minimum(k + 1, src.shape[0] - 1)
        dt = src[k1] - src[k]
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(dt > 0, (t - src[k]) / np.where(dt > 0, dt, 1.0), 0.0)
        w = np.clip(w, 0.0, 1.0)[:, None]
        outside = (t < src[0]) | (t > src[-1])

        def lerp(a: np.ndarray) -> np.ndarray:
            out = a[k] * (1.0 - w) + a[k1] * w
            out[outside] = np.nan
            return out

        q0, q1 = self.q_nb[k], self.q_nb[k1]
        q1 = np.where(np.sum(q0 * q1, axis=1, keepdims=True) < 0.0, -q1, q1)
        q = q0 * (1.0 - w) + q1 * w
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        q[outside] = np.nan
        return NavColumns(t, lerp(self.pos), lerp(self.v_n), q)


def finite_rows(a: np.ndarray) -> np.ndarray:
    """Whether each row of ``a`` (N, k) is finite throughout (column by column: a reduction
    along the short axis of every row costs several times as much)."""
    ok = np.isfinite(a[:, 0])
    for j in range(1, a.shape[1]):
        ok &= np.isfinite(a[:, j])
    return ok


def local_ned(pos: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """NED offsets [m] of positions ``pos`` (N, 3) from the reference ``ref`` (3,), via ECEF."""
    pos = np.asarray(pos, dtype=np.float64)
    return lla_to_ned_offset(ref[0], ref[1], ref[2], pos[:, 0], pos[:, 1], pos[:, 2])


def euler(q_nb: np.ndarray) -> np.ndarray:
    """ZYX Euler angles ``[roll, pitch, yaw]`` [rad] of quaternions (N, 4)."""
    return quat_to_euler(q_nb)


def nav_values(nav: NavColumns, ref: np.ndarray,
               ned: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Plotted navigation quantities (SI): roll, pitch, yaw [rad], v_N.. [m/s], p_N.. [m]
    (``ned``: the positions' :func:`local_ned` from ``ref``, when known)."""
    e = euler(nav.q_nb)
    p = local_ned(nav.pos, ref) if ned is None else ned
    return {
        "roll": e[:, 0], "pitch": e[:, 1], "yaw": e[:, 2],
        "v_N": nav.v_n[:, 0], "v_E": nav.v_n[:, 1], "v_D": nav.v_n[:, 2],
        "p_N": p[:, 0], "p_E": p[:, 1], "p_D": p[:, 2],
    }  # fmt: skip


@dataclasses.dataclass(frozen=True)
class PositionStates:
    """Indices of the position-error states and how to turn them into NED metres.

    Attributes
    ----------
    index : tuple[int, int, int]
        State indices.
    geodetic : bool
        True for (latitude [rad], longitude [rad], vertical [m]); False for N, E, D [m].
    vertical_sign : float
        For geodetic states: +1 when the vertical state is positive down (depth), -1 when it is
        positive up (height).
    """

    index: tuple[int, int, int]
    geodetic: bool
    vertical_sign: float = -1.0


def position_cov_ned(P: np.ndarray, states: PositionStates, pos: np.ndarray | None) -> np.ndarray:
    """Position-error covariance in NED metres, (M, 3, 3).

    Parameters
    ----------
    P : ndarray, shape (M, n, n)
    states : PositionStates
    pos : ndarray, shape (M, 3), optional
        Latitude [rad] and height [m] at each row, needed for geodetic states.
    """
    idx = np.asarray(states.index)
    block = P[:, idx[:, None], idx[None, :]]
    if not states.geodetic:
        return block
    if pos is None:
        raise ValueError("geodetic position states need the navigation position")
    R_M, R_N = radii(pos[:, 0])
    h = pos[:, 2]
    T = np.zeros((P.shape[0], 3, 3))
    T[:, 0, 0] = R_M + h
    T[:, 1, 1] = (R_N + h) * np.cos(pos[:, 0])
    T[:, 2, 2] = states.vertical_sign
    return T @ block @ T.transpose(0, 2, 1)


def ellipsoids(P_ned: np.ndarray, n_sigma: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """Half sizes [m] and orientations of n-sigma ellipsoids of covariances (K, 3, 3).

    Returns
    -------
    half_sizes : ndarray, shape (K, 3)
    q_xyzw : ndarray, shape (K, 4)
        Rotation from the ellipsoid's principal axes to NED, in Rerun's [x, y, z, w] order.
    """
    sym = 0.5 * (P_ned + P_ned.transpose(0, 2, 1))
    lam, V = np.linalg.eigh(sym)
    # right-handed principal frame so that V is a rotation
    V[:, :, 2] *= np.sign(np.linalg.det(V))[:, None]
    half = n_sigma * np.sqrt(np.clip(lam, 0.0, None))
    return half, quat_wxyz_to_xyzw(dcm_to_quat(V))


def decimate(t: np.ndarray, rate_hz: float, after: float = -np.inf) -> np.ndarray:
    """Indices of the first sample in each 1/rate_hz slot of ``t`` [s] later than ``after``."""
    t = np.asarray(t, dtype=np.float64)
    slot = np.floor(t * rate_hz)
    keep = np.ones(t.shape[0], dtype=bool)
    keep[1:] = slot[1:] != slot[:-1]
    if np.isfinite(after):
        keep &= slot > np.floor(after * rate_hz)
    keep &= np.isfinite(t)
    return np.flatnonzero(keep)


def chi2_bounds(dof: int, runs: int = 1, p: float = 0.95) -> tuple[float, float]:
    """Two-sided ``p`` interval of the average of ``runs`` independent chi-square(dof) values.

    For the NEES of an n-state filter averaged over N Monte Carlo runs use ``dof=n, runs=N``;
    for a single run's NIS use ``dof=m`` (the measurement dimension).

    Examples
    --------
    >>> lo, hi = chi2_bounds(3, runs=50)
    >>> round(lo, 3), round(hi, 3)
    (2.36, 3.716)
    """
    if dof < 1 or runs < 1 or not 0.0 < p < 1.0:
        raise ValueError(
            f"chi2_bounds needs dof >= 1, runs >= 1, 0 < p < 1; got {dof}, {runs}, {p}"
        )
    from navreplay.core import chi2  # not scipy.stats: its import costs more than a view

    k = dof * runs
    a = 0.5 * (1.0 - p)
    return chi2.ppf(a, k) / runs, chi2.ppf(1.0 - a, k) / runs
