"""Truth kinematics: ideal IMU samples from a truth trajectory, truth position from velocity.

A trajectory generator describes the motion by attitude (q_nb or Euler angles) and NED
velocity sampled at times t, integrates the position with :func:`integrate_position`, and
derives the ideal IMU with :func:`imu_from_truth`. Both are the exact counterparts of
:mod:`navreplay.geo.strapdown`: integrating the ideal IMU reproduces the truth to rounding error,
so any difference a filter sees comes from the sensor models.

:func:`imu_from_truth` refines the increment formula of docs/methods/transfer-alignment.md
§3.2, step 3::

    dtheta = log(C_nb(k-1)^T C_nb(k)) + C_bn(mid) w_in^n dt
    dv     = C_bn(mid) [v(k) - v(k-1) - (g^n - (2 w_ie^n + w_en^n) x v) dt]

into the exact inverse of the mechanization (strapdown eqs. (1)-(6)): the n-frame rotation is
taken out as a quaternion, ``q{alpha} = q_{k-1}^* (x) q{zeta} (x) q_k``, and the coning,
rotation and sculling terms are inverted sample by sample. Both agree with that formula to
second order in dt; the refinement makes the round trip exact.

For the round trip to be exact, ``pos`` must come from :func:`integrate_position` at the same
times (a position integrated at a finer rate differs by the trapezoid error, micrometres to
millimetres over a long run).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from navreplay.geo import strapdown

__all__ = [
    "body_rates_to_euler_rates",
    "euler_rates_to_body_rates",
    "imu_from_truth",
    "integrate_position",
]


def _times(t: ArrayLike) -> np.ndarray:
    t = np.ascontiguousarray(t, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] < 2:
        raise ValueError(f"t must have shape (N,) with N >= 2, got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("t has non-finite values")
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        k = int(bad[0]) + 1
        raise ValueError(
            f"t must be strictly increasing: t[{k}] = {t[k]!r} <= t[{k - 1}] = {t[k - 1]!r}"
        )
    return t


def _column(x: ArrayLike, name: str, n: int, width: int) -> np.ndarray:
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.shape != (n, width):
        raise ValueError(f"{name} must have shape ({n}, {width}), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(
            f"{name} has non-finite values (first at row {np.argwhere(~np.isfinite(x))[0, 0]})"
        )
    return x


def imu_from_truth(
    t: ArrayLike, pos: ArrayLike, v_n: ArrayLike, q_nb: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Ideal strapdown IMU samples that reproduce a truth trajectory.

    Parameters
    ----------
    t : array_like, shape (N,)
        Strictly increasing sample times [s].
    pos : array_like, shape (N, 3)
        Latitude [rad], longitude [rad], ellipsoidal height [m]; for an exact round trip, the
        output of :func:`integrate_position` for ``v_n`` at ``t``.
    v_n : array_like, shape (N, 3)
        Ground velocity NED [m/s].
    q_nb : array_like, shape (N, 4)
        Attitude b -> n, Hamilton, scalar first (normalised here; the sign may flip between
        samples).

    Returns
    -------
    omega_ib_b : ndarray, shape (N-1, 3)
        Body rate w.r.t. inertial space, FRD [rad/s]. Row k-1 is the sample stamped t[k]: the
        mean over (t[k-1], t[k]].
    f_b : ndarray, shape (N-1, 3)
        Specific force, FRD [m/s^2], same stamping.

    Notes
    -----
    The first sample has no predecessor, so it carries no coning or sculling term; integrate
    the output with ``prev=None`` (the default) from the state at ``t[0]``.

    Examples
    --------
    A level body turning at 0.1 rad/s about its z axis at the equator, at rest:

    >>> import numpy as np
    >>> from navreplay.geo.rotations import euler_to_quat
    >>> t = np.arange(0.0, 1.001, 0.01)
    >>> euler = np.zeros((t.size, 3)); euler[:, 2] = 0.1 * t
    >>> pos = np.zeros((t.size, 3)); v_n = np.zeros((t.size, 3))
    >>> omega, f = imu_from_truth(t, pos, v_n, euler_to_quat(euler))
    >>> (np.round(omega[0], 6) + 0.0).tolist(), (np.round(f[0], 4) + 0.0).tolist()
    ([7.3e-05, 0.0, 0.1], [0.0, 0.0, -9.7803])
    """
    t = _times(t)
    n = t.shape[0]
    pos = _column(pos, "pos", n, 3)
    v_n = _column(v_n, "v_n", n, 3)
    q = _column(q_nb, "q_nb", n, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    omega = np.empty((n - 1, 3))
    f = np.empty((n - 1, 3))
    strapdown.inverse_kernel(t, pos, v_n, q, omega, f)
    return omega, f


def integrate_position(t: ArrayLike, v_n: ArrayLike, pos0: ArrayLike) -> np.ndarray:
    """Position history from a velocity history, as the strapdown integrator computes it.

    Trapezoid on velocity with the curvature radii at the interval mid-point (strapdown
    eqs. (7)-(9)); longitude wrapped to [-pi, pi].

    Parameters
    ----------
    t : array_like, shape (N,)
        Strictly increasing times [s].
    v_n : array_like, shape (N, 3)
        Velocity NED [m/s].
    pos0 : array_like, shape (3,)
        Position at t[0]: latitude [rad], longitude [rad], ellipsoidal height [m].

    Returns
    -------
    ndarray, shape (N, 3)
        Latitude [rad], longitude [rad], height [m]; row 0 is ``pos0``.

    Examples
    --------
    1000 s north at 10 m/s on the equator covers 10 km of meridian, 10 km / R_M(0) rad:

    >>> import numpy as np
    >>> t = np.linspace(0.0, 1000.0, 1001)
    >>> v = np.tile([10.0, 0.0, 0.0], (t.size, 1))
    >>> pos = integrate_position(t, v, [0.0, 0.0, 0.0])
    >>> round(float(np.rad2deg(pos[-1, 0])) * 3600.0, 3)   # arcsec
    325.573
    """
    t = _times(t)
    v_n = _column(v_n, "v_n", t.shape[0], 3)
    p0 = np.ascontiguousarray(pos0, dtype=np.float64)
    if p0.shape != (3,) or not np.all(np.isfinite(p0)):
        raise ValueError(f"pos0 must be 3 finite values, got {pos0!r}")
    out = np.empty((t.shape[0], 3))
    strapdown.position_kernel(t, v_n, p0, out)
    return out


def euler_rates_to_body_rates(euler: ArrayLike, euler_dot: ArrayLike) -> np.ndarray:
    """Body rate w.r.t. the navigation frame from ZYX Euler angle rates.

    ``omega_nb_b = [roll' - yaw' sin(pitch),
                    pitch' cos(roll) + yaw' sin(roll) cos(pitch),
                    -pitch' sin(roll) + yaw' cos(roll) cos(pitch)]``

    Parameters
    ----------
    euler : array_like, shape (..., 3)
        ``[roll, pitch, yaw]`` [rad] with ``C_nb = Rz(yaw) Ry(pitch) Rx(roll)``.
    euler_dot : array_like, shape (..., 3)
        Their time derivatives [rad/s].

    Returns
    -------
    ndarray, shape (..., 3)
        omega_nb_b [rad/s], resolved in b. Add ``C_bn w_in^n`` for the gyro reading.
    """
    e = np.asarray(euler, dtype=np.float64)
    d = np.asarray(euler_dot, dtype=np.float64)
    sr, cr = np.sin(e[..., 0]), np.cos(e[..., 0])
    sp, cp = np.sin(e[..., 1]), np.cos(e[..., 1])
    return np.stack(
        [
            d[..., 0] - d[..., 2] * sp,
            d[..., 1] * cr + d[..., 2] * sr * cp,
            -d[..., 1] * sr + d[..., 2] * cr * cp,
        ],
        axis=-1,
    )


def body_rates_to_euler_rates(euler: ArrayLike, omega_nb_b: ArrayLike) -> np.ndarray:
    """Inverse of :func:`euler_rates_to_body_rates` (singular at pitch = +-90 deg).

    Parameters
    ----------
    euler : array_like, shape (..., 3)
        ``[roll, pitch, yaw]`` [rad].
    omega_nb_b : array_like, shape (..., 3)
        Body rate w.r.t. n, resolved in b [rad/s].

    Returns
    -------
    ndarray, shape (..., 3)
        ``[roll', pitch', yaw']`` [rad/s].
    """
    e = np.asarray(euler, dtype=np.float64)
    w = np.asarray(omega_nb_b, dtype=np.float64)
    sr, cr = np.sin(e[..., 0]), np.cos(e[..., 0])
    tp, cp = np.tan(e[..., 1]), np.cos(e[..., 1])
    yaw_dot = (w[..., 1] * sr + w[..., 2] * cr) / cp
    return np.stack(
        [
            w[..., 0] + (w[..., 1] * sr + w[..., 2] * cr) * tp,
            w[..., 1] * cr - w[..., 2] * sr,
            yaw_dot,
        ],
        axis=-1,
    )
