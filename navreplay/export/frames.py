"""navreplay's NED / FRD estimates in ROS's ENU / FLU frames: the local ENU frame about the
origin (:class:`LocalFrame`), poses and twists with their covariances rotated
(:func:`ros_poses`; the formulas are in :mod:`navreplay.export`)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from navreplay.core.streams import Stream
from navreplay.geo import earth
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
    (see the module docstring for the formulas)."""
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
