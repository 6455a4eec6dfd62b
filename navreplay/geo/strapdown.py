"""Strapdown INS mechanization in the local-level NED frame: the one integrator every filter uses.

Navigation state
----------------
A flat float64 vector of ``NAV_SIZE = 10`` elements:

=====  ==========  =======  =====================================================
index  symbol      unit     meaning
=====  ==========  =======  =====================================================
0      lat         rad      geodetic latitude (WGS84)
1      lon         rad      longitude, wrapped to [-pi, pi]
2      h           m        ellipsoidal height
3-5    v_n         m/s      ground velocity, North-East-Down
6-9    q_nb        -        attitude quaternion b -> n, Hamilton, scalar first
=====  ==========  =======  =====================================================

Slices ``POS``, ``VEL`` and ``QUAT`` name the blocks.

IMU samples
-----------
Sample k (time stamp t_k) is the mean body rate ``omega_ib_b`` and mean specific force ``f_b``
over (t_{k-1}, t_k], so the increments are ``dtheta_k = omega_k dt_k`` and ``dv_k = f_k dt_k``.

Algorithm (free 3-D mechanization on the rotating WGS84 earth, second order)
----------------------------------------------------------------------------
Mid-point quantities use ``lat_m = (lat_{k-1} + lat_k)/2``, ``h_m`` likewise and
``v_m = (v_{k-1} + v_k)/2``::

    (1) w_ie = W [cos lat, 0, -sin lat]                            earth rate in n
        w_en = [v_E/(R_N+h), -v_N/(R_M+h), -v_E tan(lat)/(R_N+h)]  transport rate in n
        zeta = (w_ie + w_en)(mid) dt                               n-frame rotation over dt
    (2) alpha_k = dtheta_k + 1/12 dtheta_{k-1} x dtheta_k          two-sample coning
    (3) q_k = q{-zeta} (x) q_{k-1} (x) q{alpha_k}                  q{x} = [cos|x|/2,
                                                                           sin(|x|/2) x/|x|]
    (4) dv_b = dv_k + 1/2 dtheta_k x dv_k                          rotation compensation
               + 1/12 (dtheta_{k-1} x dv_k + dv_{k-1} x dtheta_k)  two-sample sculling
    (5) dv_n = (I - 1/2 [zeta x]) C(q_{k-1}) dv_b                  resolved in n at mid-interval
    (6) v_k = v_{k-1} + dv_n + (g_n - (2 w_ie + w_en) x v)(mid) dt g_n = [0, 0, gamma(lat, h)]
    (7) h_k = h_{k-1} - 1/2 (v_D,{k-1} + v_D,k) dt                 trapezoid
    (8) lat_k = lat_{k-1} + vbar_N dt / (R_M(lat') + h_m),
        lat' = lat_{k-1} + 1/2 vbar_N dt / (R_M(lat_{k-1}) + h_m)  vbar = (v_{k-1} + v_k)/2
    (9) lon_k = lon_{k-1} + vbar_E dt / ((R_N(lat_m) + h_m) cos lat_m)

gamma is the Somigliana normal gravity with the second-order height term
(:func:`navreplay.geo.earth.gravity`); R_M, R_N are the meridian and transverse radii.
Equations (1) and (5)-(9) are implicit through the mid-point; they are solved by a predictor
(mid-point = start of the interval) and one corrector pass, which leaves a residual of order
``(2 W dt)^2 |dv|``, below 1e-12 m/s per step at 100 Hz.

The previous increments ``dtheta_{k-1}``, ``dv_{k-1}`` come from the previous sample of the
same call; for the first sample they are those passed as ``prev`` (zero when omitted, which
drops the coning and sculling terms of that one sample). Calling :func:`propagate` block by
block with ``prev`` set to the last sample of the previous block is bit-identical to one
:func:`integrate` over the whole record.

:func:`navreplay.sim.kinematics.imu_from_truth` inverts (1)-(6) exactly and
:func:`navreplay.sim.kinematics.integrate_position` is (7)-(9), so a perfect IMU generated
from a truth trajectory reproduces it to rounding error.

With true mean-rate samples (a real IMU) the two-sample terms make the attitude error converge
faster than second order in dt (about 3.5 orders under 1 Hz coning; tests/geo/test_strapdown.py).

The mechanization is singular at the poles (tan lat, 1/cos lat).

Examples
--------
A stationary, level IMU at 45 deg latitude reads the earth rate and -g; the INS stays put:

>>> import numpy as np
>>> from navreplay.geo.earth import gravity, omega_ie_n
>>> lat = np.deg2rad(45.0)
>>> nav0 = nav_vector([lat, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])
>>> k = 100
>>> omega = np.tile(omega_ie_n(lat), (k, 1))
>>> f = np.tile([0.0, 0.0, -gravity(lat, 0.0)], (k, 1))
>>> nav1 = propagate(nav0, omega, f, np.full(k, 0.01))
>>> bool(np.abs(nav1[VEL]).max() < 1e-9)
True
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from navreplay.core.jit import kernel
from navreplay.geo import earth, kernels, rotations

__all__ = [
    "NAV_SIZE",
    "POS",
    "QUAT",
    "VEL",
    "integrate",
    "integrate_kernel",
    "inverse_kernel",
    "nav_vector",
    "position_kernel",
    "propagate",
    "propagate_kernel",
    "propagate_reference",
]

POS = slice(0, 3)
"""Latitude [rad], longitude [rad], height [m]."""
VEL = slice(3, 6)
"""Velocity NED [m/s]."""
QUAT = slice(6, 10)
"""Attitude quaternion q_nb, scalar first."""
NAV_SIZE = 10


def nav_vector(pos: ArrayLike, v_n: ArrayLike, q_nb: ArrayLike) -> np.ndarray:
    """Pack a navigation state.

    Parameters
    ----------
    pos : array_like, shape (3,)
        Latitude [rad], longitude [rad], ellipsoidal height [m].
    v_n : array_like, shape (3,)
        Velocity NED [m/s].
    q_nb : array_like, shape (4,)
        Attitude quaternion b -> n, scalar first; normalised here.

    Returns
    -------
    ndarray, shape (10,)
    """
    nav = np.empty(NAV_SIZE)
    nav[POS] = pos
    nav[VEL] = v_n
    q = np.asarray(q_nb, dtype=np.float64)
    nav[QUAT] = q / np.linalg.norm(q)
    return nav


# --------------------------------------------------------------------------------------------
# numba kernels (scalar code: no temporaries in the inner loop; the earth model and rotation
# helpers are those of navreplay.geo.kernels)
# --------------------------------------------------------------------------------------------


@kernel(inline="always")
def _solve_skew(ax, ay, az, bx, by, bz):
    """x with (I + [a x]) x = b: x = (b - a x b + (a.b) a) / (1 + |a|^2)."""
    cx, cy, cz = kernels.cross(ax, ay, az, bx, by, bz)
    d = ax * bx + ay * by + az * bz
    s = 1.0 / (1.0 + ax * ax + ay * ay + az * az)
    return (bx - cx + d * ax) * s, (by - cy + d * ay) * s, (bz - cz + d * az) * s


@kernel(inline="always")
def _position_step(lat0, lon0, h0, vn, ve, vd, dt):
    """Eqs. (7)-(9) with the interval-mean velocity (vn, ve, vd); returns lat, lon, h."""
    h1 = h0 - vd * dt  # (7)
    h_m = 0.5 * (h0 + h1)
    r_m, _ = kernels.radii(lat0)
    lat_p = lat0 + 0.5 * vn * dt / (r_m + h_m)  # (8) predictor of the mid latitude
    r_m, _ = kernels.radii(lat_p)
    lat1 = lat0 + vn * dt / (r_m + h_m)  # (8)
    lat_m = 0.5 * (lat0 + lat1)
    _, r_n = kernels.radii(lat_m)
    lon1 = lon0 + ve * dt / ((r_n + h_m) * math.cos(lat_m))  # (9)
    if lon1 > math.pi:
        lon1 -= 2.0 * math.pi
    elif lon1 < -math.pi:
        lon1 += 2.0 * math.pi
    return lat1, lon1, h1


@kernel(inline="always")
def _mid_terms(lat_m, h_m, vn, ve, vd, dt):
    """Eq. (1) and the non-inertial terms of (6) at the mid-point.

    Returns zeta (3 values, [rad]) and the acceleration g_n - (2 w_ie + w_en) x v_m (3 values,
    [m/s^2]).
    """
    ie_n, _, ie_d = kernels.earth_rate(lat_m)  # (1) earth rate and transport rate
    en_n, en_e, en_d = kernels.transport_rate(lat_m, h_m, vn, ve)
    g = kernels.gravity(lat_m, h_m)  # normal gravity (geo.earth.gravity)
    # (6) Coriolis: (2 w_ie + w_en) x v
    cx, cy, cz = kernels.cross(2.0 * ie_n + en_n, en_e, 2.0 * ie_d + en_d, vn, ve, vd)
    return (ie_n + en_n) * dt, en_e * dt, (ie_d + en_d) * dt, -cx, -cy, g - cz


@kernel(inline="always")
def _step(nav, out, tx, ty, tz, ax, ay, az, ptx, pty, ptz, pax, pay, paz, dt):
    """One update, eqs. (1)-(9): ``nav`` (10,) at t_{k-1} -> ``out`` (10,) at t_k.

    (tx, ty, tz) and (ax, ay, az) are this sample's increments dtheta_k [rad] and dv_k [m/s],
    (ptx, ...) and (pax, ...) the previous sample's.
    """
    lat0 = nav[0]
    lon0 = nav[1]
    h0 = nav[2]
    vn0 = nav[3]
    ve0 = nav[4]
    vd0 = nav[5]
    q0 = nav[6]
    q1 = nav[7]
    q2 = nav[8]
    q3 = nav[9]
    # (4) rotation and sculling compensation, in b(k-1)
    rx, ry, rz = kernels.cross(tx, ty, tz, ax, ay, az)
    sx, sy, sz = kernels.cross(ptx, pty, ptz, ax, ay, az)
    ux, uy, uz = kernels.cross(pax, pay, paz, tx, ty, tz)
    bx = ax + 0.5 * rx + (sx + ux) / 12.0
    by = ay + 0.5 * ry + (sy + uy) / 12.0
    bz = az + 0.5 * rz + (sz + uz) / 12.0
    # (5), first factor: C(q_{k-1}) dv_b
    un, ue, ud = kernels.rotate(q0, q1, q2, q3, bx, by, bz)
    # (5)-(9) by a predictor (mid-point = start) and one corrector pass
    lat1 = lat0
    lon1 = lon0
    h1 = h0
    vn1 = vn0
    ve1 = ve0
    vd1 = vd0
    zn = 0.0
    ze = 0.0
    zd = 0.0
    for _ in range(2):
        zn, ze, zd, an, ae, ad = _mid_terms(
            0.5 * (lat0 + lat1),
            0.5 * (h0 + h1),
            0.5 * (vn0 + vn1),
            0.5 * (ve0 + ve1),
            0.5 * (vd0 + vd1),
            dt,
        )
        cn, ce, cd = kernels.cross(zn, ze, zd, un, ue, ud)
        vn1 = vn0 + un - 0.5 * cn + an * dt  # (5), (6)
        ve1 = ve0 + ue - 0.5 * ce + ae * dt
        vd1 = vd0 + ud - 0.5 * cd + ad * dt
        lat1, lon1, h1 = _position_step(
            lat0, lon0, h0, 0.5 * (vn0 + vn1), 0.5 * (ve0 + ve1), 0.5 * (vd0 + vd1), dt
        )
    # (2) coning, (3) attitude
    cx, cy, cz = kernels.cross(ptx, pty, ptz, tx, ty, tz)
    b0, b1, b2, b3 = kernels.rotvec_to_quat(tx + cx / 12.0, ty + cy / 12.0, tz + cz / 12.0)
    n0, n1, n2, n3 = kernels.rotvec_to_quat(-zn, -ze, -zd)
    p0, p1, p2, p3 = kernels.quat_mult(q0, q1, q2, q3, b0, b1, b2, b3)
    p0, p1, p2, p3 = kernels.quat_mult(n0, n1, n2, n3, p0, p1, p2, p3)
    norm = 1.0 / math.sqrt(p0 * p0 + p1 * p1 + p2 * p2 + p3 * p3)
    out[0] = lat1
    out[1] = lon1
    out[2] = h1
    out[3] = vn1
    out[4] = ve1
    out[5] = vd1
    out[6] = p0 * norm
    out[7] = p1 * norm
    out[8] = p2 * norm
    out[9] = p3 * norm


@kernel(inline="always")
def _first_bad(nav, omega, f, dt, prev):
    """Index of the first non-finite sample or non-positive dt; -1 if all are valid,
    -2 for a non-finite state or ``prev``."""
    for i in range(nav.shape[0]):
        if not math.isfinite(nav[i]):
            return -2
    for i in range(prev.shape[0]):
        if not math.isfinite(prev[i]):
            return -2
    for k in range(dt.shape[0]):
        if not (dt[k] > 0.0 and math.isfinite(dt[k])):
            return k
        for j in range(3):
            if not (math.isfinite(omega[k, j]) and math.isfinite(f[k, j])):
                return k
    return -1


@kernel
def propagate_kernel(nav, omega, f, dt, prev, out):
    """numba kernel of :func:`propagate` (no validation; callable from other numba code).

    Parameters
    ----------
    nav : ndarray, shape (10,)
    omega, f : ndarray, shape (k, 3)
        Mean body rate [rad/s] and specific force [m/s^2] per sample.
    dt : ndarray, shape (k,)
        Sample intervals [s].
    prev : ndarray, shape (6,)
        Increments dtheta [rad] and dv [m/s] of the sample before ``omega[0]`` (zeros if none).
    out : ndarray, shape (10,)
        Receives the state at the end of the block (may be ``nav`` itself).

    Returns
    -------
    int
        Index of the first invalid sample (non-finite or dt <= 0), -2 for a non-finite
        ``nav`` or ``prev``, -1 when all samples were valid and integrated.
    """
    bad = _first_bad(nav, omega, f, dt, prev)
    if bad != -1:
        return bad
    ptx, pty, ptz, pax, pay, paz = prev[0], prev[1], prev[2], prev[3], prev[4], prev[5]
    tmp = np.empty(NAV_SIZE)
    for i in range(NAV_SIZE):  # (loops: array assignment compiles a formatted shape error)
        out[i] = nav[i]
    for k in range(dt.shape[0]):
        d = dt[k]
        tx, ty, tz = omega[k, 0] * d, omega[k, 1] * d, omega[k, 2] * d
        ax, ay, az = f[k, 0] * d, f[k, 1] * d, f[k, 2] * d
        for i in range(NAV_SIZE):
            tmp[i] = out[i]
        _step(tmp, out, tx, ty, tz, ax, ay, az, ptx, pty, ptz, pax, pay, paz, d)
        ptx, pty, ptz, pax, pay, paz = tx, ty, tz, ax, ay, az
    return -1


@kernel
def integrate_kernel(nav0, omega, f, dt, prev, hist):
    """numba kernel of :func:`integrate`: fills ``hist`` (k+1, 10); returns as
    :func:`propagate_kernel`."""
    bad = _first_bad(nav0, omega, f, dt, prev)
    if bad != -1:
        return bad
    ptx, pty, ptz, pax, pay, paz = prev[0], prev[1], prev[2], prev[3], prev[4], prev[5]
    for i in range(NAV_SIZE):  # (loops: array assignment compiles a formatted shape error)
        hist[0, i] = nav0[i]
    for k in range(dt.shape[0]):
        d = dt[k]
        tx, ty, tz = omega[k, 0] * d, omega[k, 1] * d, omega[k, 2] * d
        ax, ay, az = f[k, 0] * d, f[k, 1] * d, f[k, 2] * d
        _step(hist[k], hist[k + 1], tx, ty, tz, ax, ay, az, ptx, pty, ptz, pax, pay, paz, d)
        ptx, pty, ptz, pax, pay, paz = tx, ty, tz, ax, ay, az
    return -1


@kernel
def inverse_kernel(t, pos, v_n, q_nb, omega_out, f_out):
    """Exact inverse of eqs. (1)-(6): the IMU samples that carry the state from each truth
    sample to the next.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Strictly increasing times [s].
    pos, v_n : ndarray, shape (N, 3)
        Truth position (lat, lon, h) and velocity NED, position consistent with
        :func:`position_kernel`.
    q_nb : ndarray, shape (N, 4)
        Unit truth quaternions.
    omega_out, f_out : ndarray, shape (N-1, 3)
        Receive the mean body rate [rad/s] and specific force [m/s^2]; row k-1 is the sample
        stamped t[k]. The first sample has no predecessor (zero coning/sculling terms).
    """
    ptx = pty = ptz = 0.0
    pax = pay = paz = 0.0
    for k in range(1, t.shape[0]):
        dt = t[k] - t[k - 1]
        zn, ze, zd, an, ae, ad = _mid_terms(
            0.5 * (pos[k - 1, 0] + pos[k, 0]),
            0.5 * (pos[k - 1, 2] + pos[k, 2]),
            0.5 * (v_n[k - 1, 0] + v_n[k, 0]),
            0.5 * (v_n[k - 1, 1] + v_n[k, 1]),
            0.5 * (v_n[k - 1, 2] + v_n[k, 2]),
            dt,
        )
        q0, q1, q2, q3 = q_nb[k - 1, 0], q_nb[k - 1, 1], q_nb[k - 1, 2], q_nb[k - 1, 3]
        # (3): q{alpha} = q_{k-1}^* (x) q{zeta} (x) q_k = q{C_bn(k-1) zeta} (x) q_{k-1}^* (x) q_k
        # (the second form keeps full relative precision of slow body motion)
        zx, zy, zz = kernels.rotate_inverse(q0, q1, q2, q3, zn, ze, zd)
        n0, n1, n2, n3 = kernels.rotvec_to_quat(zx, zy, zz)
        p0, p1, p2, p3 = kernels.quat_mult(q0, -q1, -q2, -q3,
                                           q_nb[k, 0], q_nb[k, 1], q_nb[k, 2], q_nb[k, 3])
        p0, p1, p2, p3 = kernels.quat_mult(n0, n1, n2, n3, p0, p1, p2, p3)
        alx, aly, alz = kernels.quat_to_rotvec(p0, p1, p2, p3)
        # (2): (I + [dtheta_{k-1}/12 x]) dtheta_k = alpha_k
        tx, ty, tz = _solve_skew(ptx / 12.0, pty / 12.0, ptz / 12.0, alx, aly, alz)
        # (6) -> dv_n, (5) -> dv_b: C^T (I - [zeta/2 x])^-1 dv_n
        wn = v_n[k, 0] - v_n[k - 1, 0] - an * dt
        we = v_n[k, 1] - v_n[k - 1, 1] - ae * dt
        wd = v_n[k, 2] - v_n[k - 1, 2] - ad * dt
        wn, we, wd = _solve_skew(-0.5 * zn, -0.5 * ze, -0.5 * zd, wn, we, wd)
        bx, by, bz = kernels.rotate_inverse(q0, q1, q2, q3, wn, we, wd)
        # (4): (I + [(dtheta_k/2 + dtheta_{k-1}/12) x]) dv_k = dv_b - dv_{k-1} x dtheta_k / 12
        cx, cy, cz = kernels.cross(pax, pay, paz, tx, ty, tz)
        ax, ay, az = _solve_skew(
            0.5 * tx + ptx / 12.0,
            0.5 * ty + pty / 12.0,
            0.5 * tz + ptz / 12.0,
            bx - cx / 12.0,
            by - cy / 12.0,
            bz - cz / 12.0,
        )
        omega_out[k - 1, 0] = tx / dt
        omega_out[k - 1, 1] = ty / dt
        omega_out[k - 1, 2] = tz / dt
        f_out[k - 1, 0] = ax / dt
        f_out[k - 1, 1] = ay / dt
        f_out[k - 1, 2] = az / dt
        ptx, pty, ptz, pax, pay, paz = tx, ty, tz, ax, ay, az


@kernel
def position_kernel(t, v_n, pos0, out):
    """Eqs. (7)-(9) along a velocity history: ``out`` (N, 3) receives lat, lon, h from
    ``pos0`` (3,) and ``v_n`` (N, 3) [m/s] at times ``t`` (N,) [s]."""
    out[0, 0] = pos0[0]
    out[0, 1] = pos0[1]
    out[0, 2] = pos0[2]
    for k in range(1, t.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = _position_step(
            out[k - 1, 0],
            out[k - 1, 1],
            out[k - 1, 2],
            0.5 * (v_n[k - 1, 0] + v_n[k, 0]),
            0.5 * (v_n[k - 1, 1] + v_n[k, 1]),
            0.5 * (v_n[k - 1, 2] + v_n[k, 2]),
            t[k] - t[k - 1],
        )


# --------------------------------------------------------------------------------------------
# Python API
# --------------------------------------------------------------------------------------------

_NO_PREV = np.zeros(6)


def _as_f64(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64)


def _inputs(nav, omega_ib_b, f_b, dt, prev):
    nav = _as_f64(nav)
    omega = _as_f64(omega_ib_b)
    f = _as_f64(f_b)
    if nav.shape != (NAV_SIZE,):
        raise ValueError(f"nav must have shape ({NAV_SIZE},), got {nav.shape}")
    if omega.ndim != 2 or omega.shape[1] != 3:
        raise ValueError(f"omega_ib_b must have shape (k, 3), got {omega.shape}")
    if f.shape != omega.shape:
        raise ValueError(f"f_b must have the shape of omega_ib_b {omega.shape}, got {f.shape}")
    dt = np.asarray(dt, dtype=np.float64)
    if dt.ndim == 0:
        dt = np.full(omega.shape[0], dt)
    elif dt.shape != omega.shape[:1]:
        raise ValueError(f"dt must have shape ({omega.shape[0]},), got {dt.shape}")
    else:
        dt = np.ascontiguousarray(dt)
    if prev is None:
        p = _NO_PREV
    else:
        w_prev, f_prev, dt_prev = prev
        p = np.empty(6)
        p[:3] = w_prev
        p[3:] = f_prev
        p *= dt_prev
    return nav, omega, f, dt, p


def _raise_bad(bad: int, omega: np.ndarray, f: np.ndarray, dt: np.ndarray) -> None:
    if bad == -2:
        raise ValueError("navigation state or prev is not finite")
    raise ValueError(
        f"IMU sample {bad}: dt = {float(dt[bad])!r} s must be finite and > 0, samples finite "
        f"(omega_ib_b = {omega[bad]}, f_b = {f[bad]})"
    )


def propagate(
    nav: ArrayLike,
    omega_ib_b: ArrayLike,
    f_b: ArrayLike,
    dt: ArrayLike,
    *,
    prev: tuple[ArrayLike, ArrayLike, float] | None = None,
) -> np.ndarray:
    """Propagate a navigation state through a block of IMU samples.

    Parameters
    ----------
    nav : array_like, shape (10,)
        State at the start of the block: lat [rad], lon [rad], h [m], v_n [m/s], q_nb.
    omega_ib_b : array_like, shape (k, 3)
        Body rate w.r.t. inertial space, FRD [rad/s]; each the mean over its interval.
    f_b : array_like, shape (k, 3)
        Specific force, FRD [m/s^2]; each the mean over its interval.
    dt : array_like, shape (k,) or scalar
        Interval of each sample [s], > 0.
    prev : (omega_ib_b (3,), f_b (3,), dt) or None, optional
        The sample just before this block (for the coning and sculling terms of the first
        sample). Pass the previous block's last sample to match :func:`integrate` exactly.

    Returns
    -------
    ndarray, shape (10,)
        A new state at the end of the block.

    Raises
    ------
    ValueError
        On wrong shapes, non-finite values, or dt <= 0 (naming the sample).
    """
    nav0, omega, f, steps, p = _inputs(nav, omega_ib_b, f_b, dt, prev)
    out = np.empty(NAV_SIZE)
    bad = propagate_kernel(nav0, omega, f, steps, p, out)
    if bad != -1:
        _raise_bad(bad, omega, f, steps)
    return out


def integrate(
    nav0: ArrayLike,
    omega_ib_b: ArrayLike,
    f_b: ArrayLike,
    dt: ArrayLike,
    *,
    prev: tuple[ArrayLike, ArrayLike, float] | None = None,
) -> np.ndarray:
    """Integrate a record of IMU samples and keep the whole history.

    Parameters are those of :func:`propagate`.

    Returns
    -------
    ndarray, shape (k+1, 10)
        Row 0 is ``nav0``, row k the state after sample k.
    """
    start, omega, f, steps, p = _inputs(nav0, omega_ib_b, f_b, dt, prev)
    hist = np.empty((steps.shape[0] + 1, NAV_SIZE))
    bad = integrate_kernel(start, omega, f, steps, p, hist)
    if bad != -1:
        _raise_bad(bad, omega, f, steps)
    return hist


# --------------------------------------------------------------------------------------------
# Reference path: the same equations in plain numpy, one sample at a time
# --------------------------------------------------------------------------------------------


def _ref_position(pos0: np.ndarray, v_mean: np.ndarray, dt: float) -> np.ndarray:
    lat0, lon0, h0 = pos0
    h1 = h0 - v_mean[2] * dt  # (7)
    h_m = 0.5 * (h0 + h1)
    r_m0, _ = earth.radii(lat0)
    lat_p = lat0 + 0.5 * v_mean[0] * dt / (r_m0 + h_m)
    r_mp, _ = earth.radii(lat_p)
    lat1 = lat0 + v_mean[0] * dt / (r_mp + h_m)  # (8)
    lat_m = 0.5 * (lat0 + lat1)
    _, r_n = earth.radii(lat_m)
    lon1 = lon0 + v_mean[1] * dt / ((r_n + h_m) * np.cos(lat_m))  # (9)
    lon1 = lon1 - 2.0 * np.pi if lon1 > np.pi else lon1 + 2.0 * np.pi if lon1 < -np.pi else lon1
    return np.array([lat1, lon1, h1])


def _ref_step(nav, dtheta, dv, dtheta_prev, dv_prev, dt):
    pos0, v0, q0 = nav[POS], nav[VEL], nav[QUAT]
    # (4) rotation and sculling compensation
    dv_b = (
        dv
        + 0.5 * np.cross(dtheta, dv)
        + (np.cross(dtheta_prev, dv) + np.cross(dv_prev, dtheta)) / 12.0
    )
    u = rotations.quat_to_dcm(q0) @ dv_b
    pos1, v1 = pos0, v0
    for _ in range(2):  # predictor (mid-point = start), one corrector
        lat_m, h_m = 0.5 * (pos0[0] + pos1[0]), 0.5 * (pos0[2] + pos1[2])
        v_m = 0.5 * (v0 + v1)
        w_ie = earth.omega_ie_n(lat_m)
        w_en = earth.omega_en_n(lat_m, h_m, v_m)
        zeta = (w_ie + w_en) * dt  # (1)
        dv_n = (np.eye(3) - 0.5 * rotations.skew(zeta)) @ u  # (5)
        g_n = earth.gravity_n(lat_m, h_m)
        v1 = v0 + dv_n + (g_n - np.cross(2.0 * w_ie + w_en, v_m)) * dt  # (6)
        pos1 = _ref_position(pos0, 0.5 * (v0 + v1), dt)  # (7)-(9)
    alpha = dtheta + np.cross(dtheta_prev, dtheta) / 12.0  # (2)
    q1 = rotations.quat_mult(  # (3)
        rotations.rotvec_to_quat(-zeta), rotations.quat_mult(q0, rotations.rotvec_to_quat(alpha))
    )
    return np.concatenate([pos1, v1, q1 / np.linalg.norm(q1)])


def propagate_reference(
    nav: ArrayLike,
    omega_ib_b: ArrayLike,
    f_b: ArrayLike,
    dt: ArrayLike,
    *,
    prev: tuple[ArrayLike, ArrayLike, float] | None = None,
) -> np.ndarray:
    """Readable numpy version of :func:`propagate` (same equations, ~1000x slower).

    It is built from :mod:`navreplay.geo` and serves as the cross-check of the numba kernel and
    as the baseline of the benchmark. Parameters and return as :func:`propagate`.
    """
    state, omega, f, steps, p = _inputs(nav, omega_ib_b, f_b, dt, prev)
    dtheta_prev, dv_prev = p[:3], p[3:]
    for k in range(steps.shape[0]):
        dtheta, dv = omega[k] * steps[k], f[k] * steps[k]
        state = _ref_step(state, dtheta, dv, dtheta_prev, dv_prev, steps[k])
        dtheta_prev, dv_prev = dtheta, dv
    return state
