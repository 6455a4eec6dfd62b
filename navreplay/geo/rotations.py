"""Rotations: Hamilton scalar-first quaternions, DCMs, ZYX Euler angles, rotation vectors.

Every function broadcasts over leading dimensions: a quaternion array has shape (..., 4), a
DCM (..., 3, 3), a vector (..., 3). ``q_nb`` rotates b to n and ``C(q_nb) = C_nb``.
Euler angles are ``[roll, pitch, yaw]`` with ``C_nb = Rz(yaw) Ry(pitch) Rx(roll)``.

Examples
--------
>>> import numpy as np
>>> q = euler_to_quat([0.1, -0.2, 0.3])
>>> np.allclose(quat_to_euler(q), [0.1, -0.2, 0.3])
True
"""

from __future__ import annotations

import numpy as np

# Below this angle [rad], series expansions replace sin(x)/x-type ratios.
_SMALL = 1e-7


def skew(v):
    """Skew-symmetric cross-product matrix ``[v x]``, shape (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    if v.shape == (3,):  # one vector: a third of the time of the general path
        x, y, z = v.tolist()
        return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def vee(M):
    """Inverse of :func:`skew` applied to the skew part of M, shape (..., 3)."""
    M = np.asarray(M, dtype=float)
    return 0.5 * np.stack(
        [M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]],
        axis=-1,
    )


def quat_mult(p, q):
    """Hamilton product ``p (x) q``, shape (..., 4)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    p0, p1, p2, p3 = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
        ],
        axis=-1,
    )


def quat_conj(q):
    """Conjugate (inverse of a unit quaternion), shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q):
    """Unit quaternion with a non-negative scalar part, shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_left_matrix(p):
    """4x4 matrix ``L(p)`` with ``p (x) q = L(p) q``, shape (..., 4, 4)."""
    p = np.asarray(p, dtype=float)
    p0, p1, p2, p3 = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    rows = [
        [p0, -p1, -p2, -p3],
        [p1, p0, -p3, p2],
        [p2, p3, p0, -p1],
        [p3, -p2, p1, p0],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def quat_right_matrix(q):
    """4x4 matrix ``M(q)`` with ``p (x) q = M(q) p``, shape (..., 4, 4)."""
    q = np.asarray(q, dtype=float)
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        [q0, -q1, -q2, -q3],
        [q1, q0, q3, -q2],
        [q2, -q3, q0, q1],
        [q3, q2, -q1, q0],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def quat_to_dcm(q):
    """DCM of a unit quaternion: ``C(q_nb) = C_nb``, shape (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    C = np.empty(q.shape[:-1] + (3, 3))
    C[..., 0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    C[..., 0, 1] = 2.0 * (q1 * q2 - q0 * q3)
    C[..., 0, 2] = 2.0 * (q1 * q3 + q0 * q2)
    C[..., 1, 0] = 2.0 * (q1 * q2 + q0 * q3)
    C[..., 1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    C[..., 1, 2] = 2.0 * (q2 * q3 - q0 * q1)
    C[..., 2, 0] = 2.0 * (q1 * q3 - q0 * q2)
    C[..., 2, 1] = 2.0 * (q2 * q3 + q0 * q1)
    C[..., 2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
    return C


def dcm_to_quat(C):
    """Unit quaternion (scalar part >= 0) of a DCM, by Shepperd's method, shape (..., 4)."""
    C = np.asarray(C, dtype=float)
    tr = C[..., 0, 0] + C[..., 1, 1] + C[..., 2, 2]
    d = np.stack([tr, C[..., 0, 0], C[..., 1, 1], C[..., 2, 2]], axis=-1)
    k = np.argmax(d, axis=-1)
    q = np.empty(C.shape[:-2] + (4,))
    # four candidate formulas, each well conditioned when its pivot is largest
    cand = np.empty(C.shape[:-2] + (4, 4))
    s0 = np.sqrt(np.maximum(1.0 + tr, 0.0)) * 2.0
    s1 = np.sqrt(np.maximum(1.0 + C[..., 0, 0] - C[..., 1, 1] - C[..., 2, 2], 0.0)) * 2.0
    s2 = np.sqrt(np.maximum(1.0 - C[..., 0, 0] + C[..., 1, 1] - C[..., 2, 2], 0.0)) * 2.0
    s3 = np.sqrt(np.maximum(1.0 - C[..., 0, 0] - C[..., 1, 1] + C[..., 2, 2], 0.0)) * 2.0
    with np.errstate(divide="ignore", invalid="ignore"):
        cand[..., 0, :] = np.stack(
            [0.25 * s0, (C[..., 2, 1] - C[..., 1, 2]) / s0, (C[..., 0, 2] - C[..., 2, 0]) / s0,
             (C[..., 1, 0] - C[..., 0, 1]) / s0], axis=-1)
        cand[..., 1, :] = np.stack(
            [(C[..., 2, 1] - C[..., 1, 2]) / s1, 0.25 * s1, (C[..., 0, 1] + C[..., 1, 0]) / s1,
             (C[..., 0, 2] + C[..., 2, 0]) / s1], axis=-1)
        cand[..., 2, :] = np.stack(
            [(C[..., 0, 2] - C[..., 2, 0]) / s2, (C[..., 0, 1] + C[..., 1, 0]) / s2, 0.25 * s2,
             (C[..., 1, 2] + C[..., 2, 1]) / s2], axis=-1)
        cand[..., 3, :] = np.stack(
            [(C[..., 1, 0] - C[..., 0, 1]) / s3, (C[..., 0, 2] + C[..., 2, 0]) / s3,
             (C[..., 1, 2] + C[..., 2, 1]) / s3, 0.25 * s3], axis=-1)
    q = np.take_along_axis(cand, k[..., None, None], axis=-2)[..., 0, :]
    return quat_normalize(q)


def euler_to_dcm(euler):
    """DCM ``C_nb = Rz(yaw) Ry(pitch) Rx(roll)`` from ``[roll, pitch, yaw]``, shape (..., 3, 3)."""
    e = np.asarray(euler, dtype=float)
    cr, sr = np.cos(e[..., 0]), np.sin(e[..., 0])
    cp, sp = np.cos(e[..., 1]), np.sin(e[..., 1])
    cy, sy = np.cos(e[..., 2]), np.sin(e[..., 2])
    C = np.empty(e.shape[:-1] + (3, 3))
    C[..., 0, 0] = cp * cy
    C[..., 0, 1] = sr * sp * cy - cr * sy
    C[..., 0, 2] = cr * sp * cy + sr * sy
    C[..., 1, 0] = cp * sy
    C[..., 1, 1] = sr * sp * sy + cr * cy
    C[..., 1, 2] = cr * sp * sy - sr * cy
    C[..., 2, 0] = -sp
    C[..., 2, 1] = sr * cp
    C[..., 2, 2] = cr * cp
    return C


def dcm_to_euler(C):
    """ZYX Euler angles ``[roll, pitch, yaw]`` of a DCM, shape (..., 3).

    At gimbal lock (pitch = +-90 deg) roll and yaw are not separable; the split returned puts the
    whole rotation about the vertical into yaw (roll = 0), so that ``euler_to_dcm`` of the result
    reproduces C. Near the lock the angles stay accurate: pitch comes from atan2 (not arcsin,
    which loses half the digits near +-1) and yaw from the columns of ``C Rx(roll)^T``, which
    stay well conditioned whatever the pitch.
    """
    C = np.asarray(C, dtype=float)
    cp = np.hypot(C[..., 2, 1], C[..., 2, 2])
    lock = cp < 1e-15  # below rounding noise of a unit DCM: roll is not observable
    roll = np.where(lock, 0.0, np.arctan2(C[..., 2, 1], C[..., 2, 2]))
    pitch = np.arctan2(-C[..., 2, 0], cp)
    # C Rx(roll)^T = Rz(yaw) Ry(pitch), whose column 1 is [-sin(yaw), cos(yaw), 0]
    sr, cr = np.sin(roll), np.cos(roll)
    yaw = np.arctan2(C[..., 0, 2] * sr - C[..., 0, 1] * cr, C[..., 1, 1] * cr - C[..., 1, 2] * sr)
    return np.stack([roll, pitch, yaw], axis=-1)


def euler_to_quat(euler):
    """Quaternion ``q_nb`` of ZYX Euler angles ``[roll, pitch, yaw]``, shape (..., 4)."""
    e = np.asarray(euler, dtype=float) * 0.5
    cr, sr = np.cos(e[..., 0]), np.sin(e[..., 0])
    cp, sp = np.cos(e[..., 1]), np.sin(e[..., 1])
    cy, sy = np.cos(e[..., 2]), np.sin(e[..., 2])
    q = np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=-1,
    )
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_to_euler(q):
    """ZYX Euler angles ``[roll, pitch, yaw]`` of a unit quaternion, shape (..., 3)."""
    return dcm_to_euler(quat_to_dcm(q))


def rotvec_to_quat(rv):
    """Quaternion of a rotation vector (axis times angle [rad]), shape (..., 4)."""
    rv = np.asarray(rv, dtype=float)
    a = np.linalg.norm(rv, axis=-1, keepdims=True)
    half = 0.5 * a
    small = a < _SMALL
    k = np.where(small, 0.5 - a * a / 48.0, np.sin(half) / np.where(small, 1.0, a))
    return np.concatenate([np.cos(half), k * rv], axis=-1)


def quat_to_rotvec(q):
    """Rotation vector [rad] of a unit quaternion (angle in [0, pi]), shape (..., 3)."""
    q = quat_normalize(q)
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    small = s < _SMALL
    k = np.where(small, 2.0 / np.maximum(q[..., :1], _SMALL), angle / np.where(small, 1.0, s))
    return k * v


def rotvec_to_dcm(rv):
    """DCM ``exp([rv x])`` of a rotation vector, shape (..., 3, 3)."""
    return quat_to_dcm(rotvec_to_quat(rv))


def dcm_to_rotvec(C):
    """Rotation vector ``log(C)`` [rad], shape (..., 3)."""
    return quat_to_rotvec(dcm_to_quat(C))


def quat_rotate(q, v):
    """Rotate vectors: ``C(q) @ v``, shape (..., 3)."""
    return np.einsum("...ij,...j->...i", quat_to_dcm(q), np.asarray(v, dtype=float))


def attitude_error(C_hat, C_true):
    """Small-angle attitude error phi [rad] with ``C_hat C_true^T = I - [phi x]``, shape (..., 3).

    phi is resolved in the reference (navigation) frame; a positive phi_D means the estimated
    heading is smaller than the true heading (the estimate is rotated by -phi).
    """
    E = np.einsum("...ij,...kj->...ik", np.asarray(C_hat), np.asarray(C_true))
    return -vee(E)


def wrap_angle(a):
    """Wrap angles [rad] to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def quat_wxyz_to_xyzw(q):
    """Reorder for scipy and Rerun, which want ``[x, y, z, w]``."""
    q = np.asarray(q)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def quat_xyzw_to_wxyz(q_xyzw):
    """Reorder a scipy / Rerun quaternion to scalar first."""
    q_xyzw = np.asarray(q_xyzw)
    return np.concatenate([q_xyzw[..., 3:], q_xyzw[..., :3]], axis=-1)
