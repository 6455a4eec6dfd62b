"""Bridging an IMU gap: the navigation solution and its error covariance without IMU samples.

During a gap nothing says how the vehicle moved. The bridge assumes the least:
constant velocity and attitude (dead reckoning, eq. 2 of :mod:`navreplay.filters.ins_error`)::

    lat += v_N T / R_Mh,   lon += v_E T / (R_Nh cos lat),   h -= v_D T           (1)

and covers what it cannot know with the error covariance. The unknown motion is an
acceleration ``a`` (NED, 1-sigma ``accel_sigma`` per axis) and a body rate ``w`` (1-sigma
``rate_sigma`` per axis) held over the gap, so that tau seconds into it the velocity and
attitude errors have grown by ``s_a tau`` and ``s_w tau`` (1-sigma): the errors of a turn or a
speed change add up coherently instead of averaging out like white noise. The filter may be
brought through a gap in pieces (to the aiding samples inside it); a piece from tau_1 to tau_2
adds the growth of that variance as a random walk of intensity ``q_a = s_a^2 (tau_1 + tau_2)``
(so the pieces sum to ``s_a^2 tau^2`` whatever their number) with its position terms::

    Phi = I + F_pv T  (position from the velocity error; F_pv of eq. 10)         (2)
    Q[v, v] = q_a T,  Q[r, v] = q_a T^2 / 2,  Q[r, r] = q_a T^3 / 3,  T = tau_2 - tau_1  (3)
    Q[phi, phi] = s_w^2 (tau_2^2 - tau_1^2)                                      (4)
    P <- Phi P Phi^T + Q + diag(q) T                                             (5)

with, for first-order Markov states (``markov``: 1 / tau > 0), their own transition and noise
(:func:`navreplay.filters.kalman.markov_transition`) in Phi and in place of ``q T``.

with r in metres N, E, D (converted to the position states by
:func:`navreplay.filters.ins_error.position_scale`) and ``diag(q) T`` the filter's own process
noise (sensor noise and bias random walks). The first IMU sample after the gap is then
integrated over one nominal interval only.

:func:`motion_noise` is eqs. (3)-(4) alone, for a filter that carries its own motion through
the gap (rpm-aided-ins holds the last IMU sample, :func:`held_samples`, through its own
mechanization and error model, and adds the covariance of an unknown *change* of motion);
:func:`held_variance` is the variance growth itself, for filters with other state layouts.
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.filters import ins_error as ie
from navreplay.filters import kalman
from navreplay.geo import earth, strapdown


def held_variance(sigma: float, tau: tuple[float, float]) -> float:
    """Growth of the variance of the integral of an unknown rate held over a gap, from tau_1
    to tau_2 seconds into it: ``sigma^2 (tau_2^2 - tau_1^2)`` (eqs. 3 and 4; the pieces of a gap
    add up to ``(sigma tau)^2``).

    Parameters
    ----------
    sigma : float
        1-sigma of the held rate per axis (an acceleration [m/s^2] for a velocity, a body rate
        [rad/s] for an attitude).
    tau : (float, float)
        Start and end of the piece, seconds since the start of the gap, 0 <= tau_1 <= tau_2.

    Examples
    --------
    >>> held_variance(0.1, (0.0, 1.0)) + held_variance(0.1, (1.0, 2.0)) == (0.1 * 2.0) ** 2
    True
    """
    t1, t2 = float(tau[0]), float(tau[1])
    if not (0.0 <= t1 <= t2 and math.isfinite(t2)):
        raise ValueError(f"a gap piece needs 0 <= tau_1 <= tau_2, got {tau}")
    return sigma * sigma * (t2 * t2 - t1 * t1)


def bridge(
    nav: np.ndarray,
    P: np.ndarray,
    tau: tuple[float, float],
    accel_sigma: float,
    rate_sigma: float,
    q: np.ndarray,
    vertical: ie.Vertical = ie.Vertical.HEIGHT,
    markov: np.ndarray | None = None,
    phi_out: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The navigation vector and covariance after a piece of a gap (eqs. 1-5).

    Parameters
    ----------
    nav : ndarray, shape (10,)
        Navigation vector (:mod:`navreplay.geo.strapdown`) at the start of the piece.
    P : ndarray, shape (n, n), n >= 15
        Error covariance at the start of the piece (the 15 states of ``ins_error`` first).
    tau : (float, float)
        Start and end of the piece, seconds since the start of the gap, 0 <= tau_1 < tau_2.
    accel_sigma : float
        1-sigma of the unknown acceleration per NED axis [m/s^2].
    rate_sigma : float
        1-sigma of the unknown body rate per axis [rad/s].
    q : ndarray, shape (n,)
        Process noise density diagonal of the filter [state^2/s].
    vertical : Vertical
    markov : ndarray, shape (n,), optional
        1 / tau [1/s] of the first-order Markov states, 0 for the others.
    phi_out : ndarray, shape (n, n), optional
        Receives the transition Phi of (2) (for a smoother).

    Returns
    -------
    nav : ndarray, shape (10,)
    P : ndarray, shape (n, n)
    """
    t1, t2 = float(tau[0]), float(tau[1])
    if not (0.0 <= t1 < t2 and math.isfinite(t2)):
        raise ValueError(f"a gap piece needs 0 <= tau_1 < tau_2, got {tau}")
    T = t2 - t1
    nav = np.array(nav, dtype=np.float64)
    lat, lon, h = nav[strapdown.POS]
    v_n = nav[strapdown.VEL]
    R_M, R_N = earth.radii(lat)
    nav[strapdown.POS] = (lat + v_n[0] * T / (float(R_M) + h),
                          lon + v_n[1] * T / ((float(R_N) + h) * math.cos(lat)),
                          h - v_n[2] * T)  # (1)
    n = P.shape[0]
    rate = np.zeros(n) if markov is None else np.asarray(markov, dtype=np.float64)
    a, qd = kalman.markov_transition(rate, q, T)
    Phi = np.diag(a)
    Phi[ie.POS, ie.VEL] = np.diag(_per_metre(nav, vertical) * T)  # (2)
    Q = np.diag(qd)
    Q += motion_noise(nav, n, (t1, t2), accel_sigma, rate_sigma, vertical)  # (3), (4)
    P = Phi @ P @ Phi.T + Q  # (5)
    if phi_out is not None:
        phi_out[:, :] = Phi
    return nav, 0.5 * (P + P.T)


def _per_metre(nav: np.ndarray, vertical: ie.Vertical) -> np.ndarray:
    return 1.0 / ie.position_scale(np.asarray(nav[strapdown.POS], dtype=np.float64), vertical)


def motion_noise(
    nav: np.ndarray,
    n: int,
    tau: tuple[float, float],
    accel_sigma: float,
    rate_sigma: float,
    vertical: ie.Vertical = ie.Vertical.HEIGHT,
) -> np.ndarray:
    """The covariance of the unknown motion over a piece of a gap (eqs. 3 and 4).

    Parameters
    ----------
    nav : ndarray, shape (10,)
        Navigation vector (for the metres-to-position-state scale).
    n : int
        Number of states (the 15 of ``ins_error`` first), n >= 15.
    tau : (float, float)
        Start and end of the piece, seconds since the start of the gap, 0 <= tau_1 <= tau_2.
    accel_sigma, rate_sigma : float
        1-sigma of the unknown acceleration per NED axis [m/s^2] and body rate per axis [rad/s].
    vertical : Vertical

    Returns
    -------
    ndarray, shape (n, n)
    """
    t1, t2 = float(tau[0]), float(tau[1])
    T = t2 - t1
    per_metre = _per_metre(nav, vertical)
    q_a = accel_sigma * accel_sigma * (t1 + t2)
    Q = np.zeros((n, n))
    Q[ie.VEL, ie.VEL] = np.eye(3) * held_variance(accel_sigma, (t1, t2))  # (3): q_a T
    cross = np.diag(per_metre * q_a * T * T / 2.0)
    Q[ie.POS, ie.VEL] = cross
    Q[ie.VEL, ie.POS] = cross
    Q[ie.POS, ie.POS] = np.diag(per_metre**2 * q_a * T**3 / 3.0)
    Q[ie.ATT, ie.ATT] = np.eye(3) * held_variance(rate_sigma, (t1, t2))  # (4)
    return Q


def held_samples(t0: float, t: float, step: float) -> np.ndarray:
    """Times of the samples that carry the last IMU sample from t0 to t [s]: every ``step``
    seconds, the last one at t (a bridge that holds the last measured rate and specific force
    integrates them with the filter's own mechanization and error model)."""
    k = max(1, math.ceil((t - t0) / step - 1e-9))
    return t0 + (t - t0) * np.arange(1, k + 1) / k
