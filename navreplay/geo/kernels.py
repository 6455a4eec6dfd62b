"""numba kernels of :mod:`navreplay.geo` for compiled code: one position, quaternion or DCM.

The formulas of :mod:`navreplay.geo.earth` and :mod:`navreplay.geo.rotations`, written once
for a single value so that compiled code (the strapdown integrator, the filters' error models
and covariance steps) calls them without array temporaries. Conventions are those of
:mod:`navreplay.geo`: NED, Hamilton quaternions scalar first, ``C(q_nb) = C_nb``, ZYX Euler
angles ``[roll, pitch, yaw]``.

Two kinds of kernels:

- scalar forms take and return floats (tuples), for inner loops: :func:`cross`,
  :func:`quat_mult`, :func:`dcm_entries`, :func:`dcm_to_quat`, :func:`rotate`,
  :func:`rotate_inverse`, :func:`rotvec_to_quat`, :func:`quat_to_rotvec` and the earth model
  (:func:`c_en_entries`, :func:`radii`, :func:`radii_derivatives`, :func:`gravity`,
  :func:`gravity_derivatives`, :func:`earth_rate`, :func:`transport_rate`);
- array forms return a new small array: :func:`quat_to_dcm` (3, 3),
  :func:`quat_left_matrix` and :func:`quat_right_matrix` (4, 4), :func:`euler_to_quat` (4,),
  :func:`quat_to_euler` (3,).

They are also callable from Python (numba dispatchers); tests/geo/test_geo.py checks each
against its numpy counterpart. Differences from the numpy functions, all deliberate:
:func:`euler_to_quat` does not flip the sign to ``q0 >= 0``, :func:`quat_to_euler` takes the
pitch from ``asin`` (valid away from gimbal lock), and :func:`rotvec_to_quat` has no series
branch (``sin(a/2)/a`` has no cancellation down to 0).

Compilation
-----------
The kernels are compiled with ``error_model="numpy"``: a division by zero gives inf or nan as
in numpy instead of raising ``ZeroDivisionError``, which also keeps the checks out of the
inner loops and lets LLVM inline the kernels into their callers. Callers check their results
for finiteness.

They are compiled with ``cache=True``. numba keys a cached function on its own source
file only: a cached function in another module that calls one of these kernels is *not*
recompiled when this file changes and keeps the old machine code. After editing this module,
delete the numba cache files of the package (``__pycache__/*.nbi``, ``*.nbc``) or point
``NUMBA_CACHE_DIR`` to a new directory.

Examples
--------
>>> import numpy as np
>>> from navreplay.geo import rotations
>>> q = rotations.euler_to_quat([0.1, -0.2, 0.3])
>>> bool(np.allclose(quat_to_dcm(q), rotations.quat_to_dcm(q)))
True
>>> R_M, R_N = radii(0.0)
>>> round(R_N, 3), round(R_M, 3)
(6378137.0, 6335439.327)
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.core.jit import kernel
from navreplay.geo import earth

__all__ = [
    "c_en_entries",
    "cross",
    "dcm_entries",
    "dcm_to_quat",
    "earth_rate",
    "euler_to_quat",
    "gravity",
    "gravity_derivatives",
    "quat_left_matrix",
    "quat_mult",
    "quat_right_matrix",
    "quat_to_dcm",
    "quat_to_euler",
    "quat_to_rotvec",
    "radii",
    "radii_derivatives",
    "rotate",
    "rotate_inverse",
    "rotvec_to_quat",
    "transport_rate",
]

# WGS84 constants, read once so that numba folds them into the machine code
_A = earth.A
_E2 = earth.E2
_F = earth.F
_W = earth.OMEGA_IE
_GAMMA_E = earth.GAMMA_E
_K_SOM = earth.K_SOMIGLIANA
_M_GRAV = earth.M_GRAV

# --------------------------------------------------------------------------------------------
# earth model (geo.earth)


@kernel(error_model="numpy", inline="always")
def radii(lat):
    """Meridian and transverse radii ``(R_M, R_N)`` [m] at latitude ``lat`` [rad]."""
    s = math.sin(lat)
    w = 1.0 - _E2 * s * s
    sw = math.sqrt(w)
    return _A * (1.0 - _E2) / (w * sw), _A / sw  # independent: a short dependency chain


@kernel(error_model="numpy", inline="always")
def c_en_entries(lat, lon):
    """The nine entries, row by row, of the DCM from NED to ECEF at ``lat``, ``lon`` [rad]
    (:func:`navreplay.geo.earth.C_en`)."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return (-sl * co, -so, -cl * co,
            -sl * so, co, -cl * so,
            cl, 0.0, -sl)  # fmt: skip


@kernel(error_model="numpy")
def radii_derivatives(lat):
    """``(dR_M/dlat, dR_N/dlat)`` [m/rad]."""
    s, c = math.sin(lat), math.cos(lat)
    w = 1.0 - _E2 * s * s
    return 3.0 * _A * (1.0 - _E2) * _E2 * s * c / w**2.5, _A * _E2 * s * c / w**1.5


@kernel(error_model="numpy", inline="always")
def gravity(lat, h):
    """Normal gravity [m/s^2]: Somigliana with the second-order height term (h [m])."""
    s = math.sin(lat)
    s2 = s * s
    return (
        _GAMMA_E
        * (1.0 + _K_SOM * s2)
        / math.sqrt(1.0 - _E2 * s2)
        * (1.0 - 2.0 / _A * (1.0 + _F + _M_GRAV - 2.0 * _F * s2) * h + 3.0 / (_A * _A) * h * h)
    )


@kernel(error_model="numpy")
def gravity_derivatives(lat, h):
    """Derivatives of :func:`gravity`: ``(dg/dlat [m/s^2 per rad], dg/dh [m/s^2 per m])``."""
    s, c = math.sin(lat), math.cos(lat)
    s2 = s * s
    w = 1.0 - _E2 * s2
    g0 = _GAMMA_E * (1.0 + _K_SOM * s2) / math.sqrt(w)
    dg0 = _GAMMA_E * (
        2.0 * _K_SOM * s * c / math.sqrt(w) + (1.0 + _K_SOM * s2) * _E2 * s * c / w**1.5
    )
    k = 1.0 + _F + _M_GRAV - 2.0 * _F * s2
    hfac = 1.0 - 2.0 / _A * k * h + 3.0 / _A**2 * h * h
    dhfac_dlat = 8.0 * _F * s * c * h / _A
    dhfac_dh = -2.0 / _A * k + 6.0 * h / _A**2
    return dg0 * hfac + g0 * dhfac_dlat, g0 * dhfac_dh


@kernel(error_model="numpy", inline="always")
def earth_rate(lat):
    """Earth rate in NED ``(w_N, w_E, w_D)`` [rad/s]; w_E is 0."""
    return _W * math.cos(lat), 0.0, -_W * math.sin(lat)


@kernel(error_model="numpy", inline="always")
def transport_rate(lat, h, v_N, v_E):
    """Transport rate w_en in NED ``(w_N, w_E, w_D)`` [rad/s] at height h [m], velocity [m/s]."""
    R_M, R_N = radii(lat)
    return (
        v_E / (R_N + h),
        -v_N / (R_M + h),
        -v_E * (math.sin(lat) / math.cos(lat)) / (R_N + h),
    )


# --------------------------------------------------------------------------------------------
# rotations, scalar forms (geo.rotations)


@kernel(error_model="numpy", inline="always")
def cross(ax, ay, az, bx, by, bz):
    """``a x b``."""
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@kernel(error_model="numpy", inline="always")
def quat_mult(p0, p1, p2, p3, q0, q1, q2, q3):
    """Hamilton product ``p (x) q``."""
    return (
        p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
        p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
        p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
        p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
    )


@kernel(error_model="numpy", inline="always")
def correct_quat(a, b, c, q0, q1, q2, q3):
    """Attitude feedback of a small error phi = 2 (a, b, c): ``[1, a, b, c] (x) q``
    normalised, its scalar part made non-negative."""
    r0, r1, r2, r3 = quat_mult(1.0, a, b, c, q0, q1, q2, q3)
    k = 1.0 / math.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    if r0 < 0.0:
        k = -k
    return r0 * k, r1 * k, r2 * k, r3 * k


@kernel(error_model="numpy", inline="always")
def dcm_entries(q0, q1, q2, q3):
    """The nine entries of C(q), row by row."""
    return (
        q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3,
        2.0 * (q1 * q2 - q0 * q3),
        2.0 * (q1 * q3 + q0 * q2),
        2.0 * (q1 * q2 + q0 * q3),
        q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3,
        2.0 * (q2 * q3 - q0 * q1),
        2.0 * (q1 * q3 - q0 * q2),
        2.0 * (q2 * q3 + q0 * q1),
        q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3,
    )


@kernel(error_model="numpy", inline="always")
def dcm_to_quat(c00, c01, c02, c10, c11, c12, c20, c21, c22):
    """Unit quaternion (scalar part >= 0) of the DCM of the nine entries (row by row), by
    Shepperd's method with the pivot of :func:`navreplay.geo.rotations.dcm_to_quat` (numpy's
    argmax of the trace and the diagonal: the first largest, the first NaN)."""
    tr = c00 + c11 + c22
    piv, best = 0, tr
    if not math.isnan(tr):
        for k, d in ((1, c00), (2, c11), (3, c22)):
            if math.isnan(d):
                piv = k
                break
            if d > best:
                piv, best = k, d
    if piv == 0:
        s = _twice_root(1.0 + tr)
        w, x, y, z = 0.25 * s, (c21 - c12) / s, (c02 - c20) / s, (c10 - c01) / s
    elif piv == 1:
        s = _twice_root(1.0 + c00 - c11 - c22)
        w, x, y, z = (c21 - c12) / s, 0.25 * s, (c01 + c10) / s, (c02 + c20) / s
    elif piv == 2:
        s = _twice_root(1.0 - c00 + c11 - c22)
        w, x, y, z = (c02 - c20) / s, (c01 + c10) / s, 0.25 * s, (c12 + c21) / s
    else:
        s = _twice_root(1.0 - c00 - c11 + c22)
        w, x, y, z = (c10 - c01) / s, (c02 + c20) / s, (c12 + c21) / s, 0.25 * s
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    if w < 0.0:
        return -w, -x, -y, -z
    return w, x, y, z


@kernel(error_model="numpy", inline="always")
def _twice_root(x):
    """``2 sqrt(max(x, 0))`` (a NaN stays NaN)."""
    return math.sqrt(0.0 if x < 0.0 else x) * 2.0


@kernel(error_model="numpy", inline="always")
def rotate(q0, q1, q2, q3, x, y, z):
    """``C(q) v`` for v = (x, y, z)."""
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = dcm_entries(q0, q1, q2, q3)
    return (
        c00 * x + c01 * y + c02 * z,
        c10 * x + c11 * y + c12 * z,
        c20 * x + c21 * y + c22 * z,
    )


@kernel(error_model="numpy")
def rotate_inverse(q0, q1, q2, q3, x, y, z):
    """``C(q)^T v = C(q*) v`` for v = (x, y, z)."""
    return rotate(q0, -q1, -q2, -q3, x, y, z)


@kernel(error_model="numpy", inline="always")
def rotvec_to_quat(x, y, z):
    """Quaternion of the rotation vector (x, y, z) [rad]."""
    a = math.sqrt(x * x + y * y + z * z)
    k = 0.5 if a == 0.0 else math.sin(0.5 * a) / a  # no cancellation: exact down to a -> 0
    return math.cos(0.5 * a), k * x, k * y, k * z


@kernel(error_model="numpy")
def quat_to_rotvec(q0, q1, q2, q3):
    """Rotation vector [rad] of a unit quaternion (principal value, angle <= pi)."""
    if q0 < 0.0:
        q0, q1, q2, q3 = -q0, -q1, -q2, -q3
    s = math.sqrt(q1 * q1 + q2 * q2 + q3 * q3)
    k = 2.0 / q0 if s == 0.0 else 2.0 * math.atan2(s, q0) / s
    return k * q1, k * q2, k * q3


# --------------------------------------------------------------------------------------------
# rotations, array forms


@kernel(error_model="numpy")
def quat_to_dcm(q):
    """DCM ``C(q)``, shape (3, 3), of a unit quaternion q (4,)."""
    C = np.empty((3, 3))
    (C[0, 0], C[0, 1], C[0, 2], C[1, 0], C[1, 1], C[1, 2],
     C[2, 0], C[2, 1], C[2, 2]) = dcm_entries(q[0], q[1], q[2], q[3])  # fmt: skip
    return C


@kernel(error_model="numpy")
def quat_left_matrix(p):
    """``L(p)`` with ``p (x) q = L(p) q``, shape (4, 4)."""
    L = np.empty((4, 4))
    L[0, 0], L[0, 1], L[0, 2], L[0, 3] = p[0], -p[1], -p[2], -p[3]
    L[1, 0], L[1, 1], L[1, 2], L[1, 3] = p[1], p[0], -p[3], p[2]
    L[2, 0], L[2, 1], L[2, 2], L[2, 3] = p[2], p[3], p[0], -p[1]
    L[3, 0], L[3, 1], L[3, 2], L[3, 3] = p[3], -p[2], p[1], p[0]
    return L


@kernel(error_model="numpy")
def quat_right_matrix(q):
    """``M(q)`` with ``p (x) q = M(q) p``, shape (4, 4)."""
    M = np.empty((4, 4))
    M[0, 0], M[0, 1], M[0, 2], M[0, 3] = q[0], -q[1], -q[2], -q[3]
    M[1, 0], M[1, 1], M[1, 2], M[1, 3] = q[1], q[0], q[3], -q[2]
    M[2, 0], M[2, 1], M[2, 2], M[2, 3] = q[2], -q[3], q[0], q[1]
    M[3, 0], M[3, 1], M[3, 2], M[3, 3] = q[3], q[2], -q[1], q[0]
    return M


@kernel(error_model="numpy")
def euler_to_quat(euler):
    """Quaternion of ZYX ``[roll, pitch, yaw]`` [rad], shape (4,) (q0 of either sign)."""
    r, p, y = 0.5 * euler[0], 0.5 * euler[1], 0.5 * euler[2]
    cr, sr = math.cos(r), math.sin(r)
    cp, sp = math.cos(p), math.sin(p)
    cy, sy = math.cos(y), math.sin(y)
    q = np.empty(4)
    q[0] = cr * cp * cy + sr * sp * sy
    q[1] = sr * cp * cy - cr * sp * sy
    q[2] = cr * sp * cy + sr * cp * sy
    q[3] = cr * cp * sy - sr * sp * cy
    return q


@kernel(error_model="numpy")
def quat_to_euler(q):
    """ZYX ``[roll, pitch, yaw]`` [rad] of a unit quaternion away from gimbal lock, (3,)."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    e = np.empty(3)
    e[0] = math.atan2(2.0 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3)
    e[1] = math.asin(max(-1.0, min(1.0, -2.0 * (q1 * q3 - q0 * q2))))
    e[2] = math.atan2(2.0 * (q1 * q2 + q0 * q3), q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3)
    return e
