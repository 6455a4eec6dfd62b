"""GNSS-only constant-velocity Kalman filter: position and velocity from position fixes.

The vehicle is modelled as moving at constant velocity, disturbed by white acceleration noise.
It uses no IMU: when the recording has one, the replay engine's IMU blocks only advance the
filter clock, so the filter has outputs between fixes. Heading is the course over ground
(attitude with zero roll and pitch), held below a minimum speed.

State (total state, NED, relative to the first fix)
---------------------------------------------------
=====  ======  =====  =====  =========================================
index  symbol  frame  unit   meaning
=====  ======  =====  =====  =========================================
0:3    p_n     n      m      position N, E, D from the first fix
3:6    v_n     n      m/s    velocity N, E, D
=====  ======  =====  =====  =========================================

Error definition: estimate minus truth. The states are declared once (``states``): the
velocity is scored against the truth stream's ``v_n`` column and counts in the NEES; the
position, relative to the first fix, is scored through the navigation solution instead.

Models
------
::

    d p_n / dt = v_n                                                  (1)
    d v_n / dt = w,        E[w w^T] = q I3 delta(t - s)               (2)
    Phi = [[I3, I3 dt], [0, I3]]                                      (3)
    Qd  = q [[I3 dt^3 / 3, I3 dt^2 / 2], [I3 dt^2 / 2, I3 dt]]        (4)
    z   = p_n + e,  H = [I3, 0],  R = diag(k pos_sigma)^2             (5)

The fix (latitude, longitude, height) is mapped to ``z`` with curvilinear coordinates around
the first fix (lat0, lon0, h0), using the radii of curvature there (accurate to centimetres over
tens of kilometres)::

    p_N = (lat - lat0) (R_M + h0),  p_E = (lon - lon0) (R_N + h0) cos lat0,  p_D = h0 - h   (6)
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay.core.streams import StreamKind
from navreplay.filters import kalman
from navreplay.filters.base import (
    Estimate,
    Filter,
    FilterParams,
    Innovation,
    MeasurementKind,
    NavSolution,
    Quantity,
    State,
    TruthColumn,
)
from navreplay.geo import euler_to_quat, radii

POS = slice(0, 3)
VEL = slice(3, 6)
N_STATES = 6


@dataclasses.dataclass(frozen=True, kw_only=True)
class GpsCvParams(FilterParams):
    """Parameters of :class:`GpsConstantVelocity`."""

    accel_psd: float = 0.5
    """White acceleration noise power spectral density per axis, q in (2) [m^2/s^3]."""
    init_vel_sigma: float = 10.0
    """1-sigma of the initial velocity (the first fix gives no velocity) [m/s]."""
    pos_sigma_scale: float = 1.0
    """Factor k on the receiver's reported 1-sigma position error in (5) [-]."""
    min_course_speed: float = 0.5
    """Horizontal speed below which the course (heading) is held [m/s]."""

    def __post_init__(self) -> None:
        for name in ("accel_psd", "init_vel_sigma", "pos_sigma_scale"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        if not (math.isfinite(self.min_course_speed) and self.min_course_speed >= 0.0):
            raise ValueError(f"min_course_speed must be >= 0, got {self.min_course_speed}")


class GpsConstantVelocity(Filter):
    """GNSS-only constant-velocity Kalman filter (position + velocity, course as heading)."""

    name = "gps-cv"
    summary = "GNSS-only constant-velocity KF (example plug-in): position, velocity, course"
    requires = (StreamKind.GPS,)
    Params = GpsCvParams
    states = (
        *(State(f"p_{a}", "m", Quantity.POSITION) for a in "NED"),
        *(State(f"v_{a}", "m/s", Quantity.VELOCITY, TruthColumn("v_n", (i,)), nees=True)
          for i, a in enumerate("NED")),
    )
    measurements = (MeasurementKind("gps_pos", ("N", "E", "D"), "m"),)  # z of (5), (6)

    def __init__(self, params: GpsCvParams, context: Any) -> None:
        super().__init__(params, context)
        self.t = 0.0
        self.x = np.zeros(N_STATES)
        self.P = np.zeros((N_STATES, N_STATES))
        self.ref: np.ndarray | None = None  # first fix: lat, lon [rad], h [m]
        self.scale = np.ones(3)  # (6): metres per rad of lat, rad of lon, -1 per m of height
        self.yaw = 0.0

    # -- the three calls of the replay engine --------------------------------------------

    def propagate(self, t: np.ndarray, imu: Mapping[str, np.ndarray]) -> None:
        """The IMU is not used: its block only advances the clock to its last sample."""
        self._predict(float(t[-1]))

    def update(self, kind: StreamKind, t: float, sample: Mapping[str, Any]) -> list[Innovation]:
        pos = np.asarray(sample["pos"], dtype=float)
        R = np.square(self.params.pos_sigma_scale * np.asarray(sample["pos_sigma"], dtype=float))
        if self.ref is None:  # initialise at the first fix
            self.ref = pos.copy()
            R_M, R_N = radii(pos[0])
            self.scale = np.array([R_M + pos[2], (R_N + pos[2]) * math.cos(pos[0]), -1.0])
            self.t = t
            self.P[POS, POS] = np.diag(R)
            self.P[VEL, VEL] = np.eye(3) * self.params.init_vel_sigma**2
            return []
        self._predict(t)
        z = (pos - self.ref) * self.scale  # (6)
        H = np.zeros((3, N_STATES))
        H[:, POS] = np.eye(3)
        c = kalman.correct(self.x, self.P, z, H, R, t=t)
        self.x, self.P = c.x, c.P
        return [c.innovation("gps_pos", t)]

    def estimate(self) -> Estimate | None:
        if self.ref is None:
            return None
        v_n = self.x[VEL]
        if math.hypot(v_n[0], v_n[1]) >= self.params.min_course_speed:
            self.yaw = math.atan2(v_n[1], v_n[0])
        nav = NavSolution(
            pos=self.ref + self.x[POS] / self.scale,  # (6) inverted
            v_n=v_n.copy(),
            q_nb=euler_to_quat([0.0, 0.0, self.yaw]),
        )
        return Estimate(self.t, self.x.copy(), self.P.copy(), nav)

    # -- models ----------------------------------------------------------------------------

    def _predict(self, t: float) -> None:
        dt = t - self.t
        if self.ref is None or dt <= 0.0:
            return
        Phi = np.eye(N_STATES)
        Phi[POS, VEL] = np.eye(3) * dt  # (3)
        q = self.params.accel_psd
        Qd = np.zeros((N_STATES, N_STATES))  # (4)
        Qd[POS, POS] = np.eye(3) * (q * dt**3 / 3.0)
        Qd[POS, VEL] = Qd[VEL, POS] = np.eye(3) * (q * dt**2 / 2.0)
        Qd[VEL, VEL] = np.eye(3) * (q * dt)
        self.x, self.P = kalman.predict(self.x, self.P, Phi, Qd, t=t)
        self.t = t
