"""navreplay's NED / FRD estimates in ROS's ENU / FLU frames: the local ENU frame about the
origin (:class:`LocalFrame`), poses and twists with their covariances rotated
(:func:`ros_poses`; the formulas are in :mod:`navreplay.export`)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from navreplay.core.jit import kernel
from navreplay.core.streams import Stream
from navreplay.geo import earth
from navreplay.geo import kernels as geo_kernels
from navreplay.geo.rotations import dcm_to_quat, quat_to_dcm, skew

WORLD_FRAME = "map"


BODY_FRAME = "base_link"


UNKNOWN_VARIANCE = -1.0
"""Covariance diagonal of an element the filter does not estimate (sensor_msgs convention)."""


T_NED_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
"""NED <-> ENU (its own inverse)."""


F_FRD_FLU = np.diag([1.0, -1.0, -1.0])
"""FRD <-> FLU (its own inverse)."""


@dataclasses.dataclass(frozen=True)
class LocalFrame:
    """The ENU (``map``) frame of the exports: origin on the WGS84 ellipsoid and its axes.

    Attributes
    ----------
    lat, lon, h : float
        Origin [rad, rad, m]: the reference's first sample, else the first filter's first
        navigation estimate.
    source : str
        Where the origin comes from.
    """

    lat: float
    lon: float
    h: float
    source: str

    @property
    def C_enu_e(self) -> np.ndarray:
        """ECEF -> ENU at the origin, (3, 3)."""
        return T_NED_ENU @ earth.C_en(self.lat, self.lon).T

    def position(self, pos: np.ndarray) -> np.ndarray:
        """ENU position [m] (M, 3) of lat, lon, h (M, 3)."""
        dr = earth.lla_to_ecef(pos[:, 0], pos[:, 1], pos[:, 2]) - earth.lla_to_ecef(
            self.lat, self.lon, self.h)
        C = self.C_enu_e  # row by row (the same bits whatever the number of rows)
        return dr[:, 0:1] * C[:, 0] + dr[:, 1:2] * C[:, 1] + dr[:, 2:3] * C[:, 2]

    def rotation(self, pos: np.ndarray) -> np.ndarray:
        """``R = C_enu0<-ned``, (M, 3, 3), the local NED frame at each position to ENU."""
        return np.einsum("ij,mjk->mik", self.C_enu_e, earth.C_en(pos[:, 0], pos[:, 1]))

    def to_json(self) -> dict[str, Any]:
        return {"lat_deg": math.degrees(self.lat), "lon_deg": math.degrees(self.lon),
                "h_m": self.h, "source": self.source}


@dataclasses.dataclass
class Poses:
    """Poses in ROS frames: ENU position [m], q (base_link FLU -> map ENU) xyzw, ENU-frame
    pose covariance (M, 6, 6), body velocity FLU [m/s] and twist covariance (M, 6, 6)."""

    stamps_ns: np.ndarray
    p_enu: np.ndarray
    q_xyzw: np.ndarray
    pose_cov: np.ndarray
    v_flu: np.ndarray
    twist_cov: np.ndarray
    lla: np.ndarray | None = None
    """Latitude, longitude [rad] and height [m] (M, 3): the NavSatFix messages."""
    fix_cov: np.ndarray | None = None
    """Position covariance in the ENU frame at the vehicle [m^2] (M, 3, 3), NaN where the
    filter holds no variance."""


def ros_poses(frame: LocalFrame, stamps_ns: np.ndarray, pos: np.ndarray, v_n: np.ndarray,
              q_nb: np.ndarray, nav_cov: np.ndarray | None) -> Poses:
    """Convert a NED/FRD navigation solution and its error covariance to ROS frames
    (see the module docstring for the formulas).

    The orientation, the body velocity and the covariance products come from one compiled
    kernel, row by row (:func:`_pose_kernel`), with the sums of numpy's products term by term
    (zeros included: a NaN spreads as through numpy's): they may differ from numpy's matrix
    products (BLAS) in the last bit."""
    M = len(stamps_ns)
    cov = np.full((M, 9, 9), np.nan) if nav_cov is None else np.ascontiguousarray(nav_cov,
                                                                                   np.float64)
    zero = not cov.any()  # the reference's (NaN counts as not zero)
    q_xyzw, v_flu = np.empty((M, 4)), np.empty((M, 3))
    pose_cov, lin = np.empty((M, 6, 6)), np.empty((M, 3, 3))
    pos = np.asarray(pos, dtype=np.float64)
    finite = _pose_kernel(pos[:, 0].copy(), pos[:, 1].copy(), frame.C_enu_e,
                          np.ascontiguousarray(q_nb, np.float64),
                          np.ascontiguousarray(v_n, np.float64), cov, not zero, q_xyzw, v_flu,
                          pose_cov, lin)
    if zero:
        if not finite:  # the products' zeros and NaN (of the factors' NaN)
            return _numpy_poses(frame, stamps_ns, pos, v_n, q_nb, cov)
        # the products' zeros, without the products or their factors
        pose_cov, lin, fix_cov = np.zeros((M, 6, 6)), np.zeros((M, 3, 3)), np.zeros((M, 3, 3))
    else:
        fix_cov = T_NED_ENU @ cov[:, :3, :3] @ T_NED_ENU
    # the twist: the linear block, and the angular rate not estimated (unknown: zero rows and
    # columns, UNKNOWN_VARIANCE on the diagonal, as _mark_unknown makes of NaN there)
    twist_cov = np.zeros((M, 6, 6))
    twist_cov[:, :3, :3] = _mark_unknown(lin)
    twist_cov[:, _ANGULAR, _ANGULAR] = UNKNOWN_VARIANCE
    return Poses(np.asarray(stamps_ns, dtype=np.int64), frame.position(pos), q_xyzw,
                 _mark_unknown(pose_cov), v_flu, twist_cov, pos, fix_cov)


@kernel(error_model="numpy", nogil=True)
def _pose_kernel(lat: np.ndarray, lon: np.ndarray, C0: np.ndarray, q_nb: np.ndarray,
                 v_n: np.ndarray, cov: np.ndarray, with_cov: bool, q_out: np.ndarray,
                 v_out: np.ndarray, pose_out: np.ndarray, lin_out: np.ndarray) -> bool:
    """Per row: ``R = C0 C_en(lat, lon)``, ``C_nb`` of ``q_nb``, the quaternion (x, y, z, w;
    Shepperd's method, the scalar part >= 0) of ``R C_nb F``, the FLU body velocity
    ``F C_nb^T v_n``, and (``with_cov``) ``B P_pose B^T`` and ``J P_vel,att J^T`` with
    ``B = diag(R, R)``, ``J = F C_nb^T [I, -[v_n x]]`` (``F``: FRD <-> FLU). Returns whether
    every R, C_nb and v_n is finite. ``C_en``, ``C_nb`` and the quaternion are
    :func:`navreplay.geo.kernels.c_en_entries`, :func:`~navreplay.geo.kernels.dcm_entries`
    and :func:`~navreplay.geo.kernels.dcm_to_quat` (the formulas of :mod:`navreplay.geo.earth`
    and :mod:`navreplay.geo.rotations`); the order of each sum is that of
    :func:`_numpy_poses`."""
    R = np.empty((3, 3))
    Cn = np.empty((3, 3))
    Cb = np.empty((3, 3))
    C = np.empty((3, 3))
    B = np.zeros((6, 6))
    P = np.empty((6, 6))
    T = np.empty((6, 6))
    J = np.empty((3, 6))
    J0 = np.zeros((3, 6))
    A = np.empty((3, 3))
    f = (1.0, -1.0, -1.0)
    finite = True
    for m in range(lat.shape[0]):
        (Cn[0, 0], Cn[0, 1], Cn[0, 2], Cn[1, 0], Cn[1, 1], Cn[1, 2],
         Cn[2, 0], Cn[2, 1], Cn[2, 2]) = geo_kernels.c_en_entries(lat[m], lon[m])  # fmt: skip
        for i in range(3):
            for k in range(3):
                R[i, k] = C0[i, 0] * Cn[0, k] + C0[i, 1] * Cn[1, k] + C0[i, 2] * Cn[2, k]
        (Cb[0, 0], Cb[0, 1], Cb[0, 2], Cb[1, 0], Cb[1, 1], Cb[1, 2],
         Cb[2, 0], Cb[2, 1], Cb[2, 2]) = geo_kernels.dcm_entries(q_nb[m, 0], q_nb[m, 1], q_nb[m, 2],
                                                                 q_nb[m, 3])  # fmt: skip
        for i in range(3):
            for k in range(3):
                finite = finite and np.isfinite(R[i, k]) and np.isfinite(Cb[i, k])
                C[i, k] = (R[i, 0] * Cb[0, k] + R[i, 1] * Cb[1, k] + R[i, 2] * Cb[2, k]) * f[k]
        w, x, y, z = geo_kernels.dcm_to_quat(C[0, 0], C[0, 1], C[0, 2], C[1, 0], C[1, 1],
                                             C[1, 2], C[2, 0], C[2, 1], C[2, 2])
        q_out[m, 0], q_out[m, 1], q_out[m, 2], q_out[m, 3] = x, y, z, w
        v0, v1, v2 = v_n[m, 0], v_n[m, 1], v_n[m, 2]
        finite = finite and np.isfinite(v0) and np.isfinite(v1) and np.isfinite(v2)
        for i in range(3):
            v_out[m, i] = (Cb[0, i] * v0 + Cb[1, i] * v1 + Cb[2, i] * v2) * f[i]
        if not with_cov:
            continue
        for i in range(3):
            for k in range(3):
                B[i, k] = R[i, k]
                B[i + 3, k + 3] = R[i, k]
        for i in range(6):
            for k in range(6):
                P[i, k] = cov[m, _POSE_ROWS[i], _POSE_ROWS[k]]
        _product(B, P, B, T, pose_out[m])
        # J = (F C_nb^T) [I, -[v x]]
        for i in range(3):
            for k in range(3):
                A[i, k] = f[i] * Cb[k, i]
        J0[0, 0], J0[1, 1], J0[2, 2] = 1.0, 1.0, 1.0
        J0[0, 3], J0[0, 4], J0[0, 5] = -0.0, v2, -v1
        J0[1, 3], J0[1, 4], J0[1, 5] = -v2, -0.0, v0
        J0[2, 3], J0[2, 4], J0[2, 5] = v1, -v0, -0.0
        for i in range(3):
            for k in range(6):
                J[i, k] = A[i, 0] * J0[0, k] + A[i, 1] * J0[1, k] + A[i, 2] * J0[2, k]
        for i in range(6):
            for k in range(6):
                P[i, k] = cov[m, 3 + i, 3 + k]
        _product(J, P, J, T, lin_out[m])
    return finite


@kernel(error_model="numpy", inline="always")
def _product(X: np.ndarray, P: np.ndarray, Y: np.ndarray, T: np.ndarray,
             out: np.ndarray) -> None:
    """``out = (X P) Y^T`` for X, Y (n, 6), P (6, 6); ``T``: room for ``X P``. Every term of
    each sum, zeros included."""
    n = X.shape[0]
    for i in range(n):
        for k in range(6):
            acc = X[i, 0] * P[0, k]
            for j in range(1, 6):
                acc += X[i, j] * P[j, k]
            T[i, k] = acc
    for i in range(n):
        for k in range(n):
            acc = T[i, 0] * Y[k, 0]
            for j in range(1, 6):
                acc += T[i, j] * Y[k, j]
            out[i, k] = acc


_POSE_ROWS = (0, 1, 2, 6, 7, 8)
"""Rows of the position and attitude errors in the navigation covariance (of the kernel)."""


def _numpy_poses(frame: LocalFrame, stamps_ns: np.ndarray, pos: np.ndarray, v_n: np.ndarray,
              q_nb: np.ndarray, nav_cov: np.ndarray | None) -> Poses:
    """:func:`ros_poses` by numpy's products: the reference's zero covariance when its
    factors are not all finite (the NaN of the products' rows and columns)."""
    M = len(stamps_ns)
    R = frame.rotation(pos)
    C_nb = quat_to_dcm(q_nb)
    C = R @ C_nb @ F_FRD_FLU
    q = dcm_to_quat(C)
    v_b = np.einsum("mji,mj->mi", C_nb, v_n)
    cov = np.full((M, 9, 9), np.nan) if nav_cov is None else nav_cov
    zero = not cov.any()  # the reference's (NaN counts as not zero)
    if zero and np.isfinite(R).all() and np.isfinite(C_nb).all() and np.isfinite(v_n).all():
        # the products' zeros, without the products or their factors
        pose_cov, lin = np.zeros((M, 6, 6)), np.zeros((M, 3, 3))
        fix_cov = np.zeros((M, 3, 3))
    else:
        B = np.zeros((M, 6, 6))
        B[:, :3, :3] = R
        B[:, 3:, 3:] = R
        J = np.concatenate([np.broadcast_to(np.eye(3), (M, 3, 3)), -skew(v_n)], axis=2)
        J = F_FRD_FLU @ C_nb.transpose(0, 2, 1) @ J
        if zero:  # the products' zeros and NaN (of the factors' NaN), without them
            pose_cov, lin = _zero_product(B), _zero_product(J)
        else:
            pose_cov = B @ cov[:, _POSE[:, None], _POSE[None, :]] @ B.transpose(0, 2, 1)
            lin = J @ cov[:, 3:9, 3:9] @ J.transpose(0, 2, 1)
        fix_cov = T_NED_ENU @ cov[:, :3, :3] @ T_NED_ENU
    # the twist: the linear block, and the angular rate not estimated (unknown: zero rows and
    # columns, UNKNOWN_VARIANCE on the diagonal, as _mark_unknown makes of NaN there)
    twist_cov = np.zeros((M, 6, 6))
    twist_cov[:, :3, :3] = _mark_unknown(lin)
    twist_cov[:, _ANGULAR, _ANGULAR] = UNKNOWN_VARIANCE
    return Poses(np.asarray(stamps_ns, dtype=np.int64), frame.position(pos),
                 np.concatenate([q[:, 1:], q[:, :1]], axis=1), _mark_unknown(pose_cov),
                 v_b * np.diagonal(F_FRD_FLU), twist_cov,
                 np.asarray(pos, dtype=np.float64), fix_cov)


_POSE = np.array([0, 1, 2, 6, 7, 8])
"""Rows of the position and attitude errors in the navigation covariance."""


_ANGULAR = np.arange(3, 6)
"""The angular rate's rows of a twist covariance."""


def _zero_product(A: np.ndarray) -> np.ndarray:
    """``A @ 0 @ A^T`` (M, n, n) for A (M, n, k): NaN in the rows and columns of the rows of A
    with a value that is not finite (times zero), else 0."""
    finite = np.isfinite(A)
    good = finite[:, :, 0].copy()
    for j in range(1, A.shape[2]):  # across the short axis column by column: ten times faster
        good &= finite[:, :, j]
    if good.all():
        return np.zeros(A.shape[:2] + A.shape[1:2])
    bad = ~good
    return np.where(bad[:, :, None] | bad[:, None, :], np.nan, 0.0)


def _mark_unknown(cov: np.ndarray) -> np.ndarray:
    """Rows/columns whose variance is not finite: 0, and UNKNOWN_VARIANCE on the diagonal."""
    if np.isfinite(cov).all():  # nothing to mark
        return cov
    bad = ~np.isfinite(np.diagonal(cov, axis1=1, axis2=2))
    cov = np.where(bad[:, :, None] | bad[:, None, :] | ~np.isfinite(cov), 0.0, cov)
    d = np.arange(cov.shape[1])
    cov[:, d, d] = np.where(bad, UNKNOWN_VARIANCE, cov[:, d, d])
    return cov


def reference_poses(frame: LocalFrame, truth: Stream) -> Poses:
    zero = np.zeros((len(truth), 9, 9))
    n = len(truth)  # parts a reference lacks (a position-only one) are NaN
    pos, v_n, q_nb = (truth.columns.get(c, np.full((n, w), np.nan))
                      for c, w in (("pos", 3), ("v_n", 3), ("q_nb", 4)))
    return ros_poses(frame, truth.t_ns, pos, v_n, q_nb, zero)
