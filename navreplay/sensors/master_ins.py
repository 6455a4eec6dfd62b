"""Master (gimballed) INS output model: Euler attitude, NED velocity and position.

Attitude (docs/methods/transfer-alignment.md §3.2, step 4). The stabilised platform p is tilted
from the navigation frame by the small random-constant angles eps = [eps_N, eps_E, eps_D]:

    C_np = exp(-[eps x])            (exact rotation, not the small-angle I - [eps x])
    C_pr = C_np C_nr                (indicated attitude of the master's body frame r)
    euler_meas = euler(C_pr) + synchro_bias + synchro_noise   (per roll, pitch, yaw)

To first order this is the paper's eqs. (20)-(22) with psi_tilde = psi - eps_D (erratum E14 in
docs/methods/transfer-alignment.md):
roll gains -(eps_N cos psi + eps_E sin psi) / cos theta, pitch gains
eps_N sin psi - eps_E cos psi, and yaw gains -eps_D - tan theta (eps_N cos psi + eps_E sin psi).

Velocity: ``v_meas = v_n + vel_bias + white noise`` per NED axis. Position: the truth.

Examples
--------
>>> import numpy as np
>>> from navreplay.geo.rotations import euler_to_quat
>>> model = MasterInsModel()                       # no errors
>>> q = euler_to_quat([[0.1, -0.05, 0.5]])
>>> out = model.measure(model.draw(np.random.default_rng(0)), q,
...                     np.zeros((1, 3)), np.zeros((1, 3)), np.random.default_rng(1))
>>> np.allclose(out["euler"], [[0.1, -0.05, 0.5]])
True
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from navreplay.core.params import check_nonnegative, check_positive
from navreplay.geo.rotations import dcm_to_euler, quat_to_dcm, rotvec_to_dcm, wrap_angle
from navreplay.sensors._common import FieldUnit, RealisedErrors, Vec3, as_vec3


@dataclasses.dataclass(frozen=True, kw_only=True)
class MasterInsModel:
    """1-sigma error specification of a master gimballed INS (SI). A scalar applies to all
    three axes / angles."""

    field_units: ClassVar[Mapping[str, FieldUnit]] = {
        "tilt": FieldUnit("rad", "arcmin"),
        "synchro_bias": FieldUnit("rad", "arcmin"),
        "synchro_noise": FieldUnit("rad", "arcmin"),
        "vel_bias": FieldUnit("m/s", "m/s"),
        "vel_noise": FieldUnit("m/s", "m/s"),
        "rate": FieldUnit("Hz", "Hz"),
    }
    """Unit of each field in SI and in datasheets."""
    error_terms: ClassVar[Mapping[str, str]] = {
        "tilt": "master platform tilt", "synchro_bias": "master synchro bias",
        "synchro_noise": "master synchro noise", "vel_bias": "master velocity bias",
        "vel_noise": "master velocity noise"}
    """The fields that are error magnitudes, each with what it is
    (:attr:`navreplay.sensors.imu.ImuModel.error_terms`)."""

    tilt: float | Vec3 = 0.0
    """Platform tilt eps_N, eps_E, eps_D, random constant [rad]."""
    synchro_bias: float | Vec3 = 0.0
    """Synchro (angle readout) error per roll, pitch, yaw, random constant [rad]."""
    synchro_noise: float | Vec3 = 0.0
    """Synchro white noise per roll, pitch, yaw, per sample [rad]."""
    vel_bias: float | Vec3 = 0.0
    """Velocity error per N, E, D axis, random constant [m/s]."""
    vel_noise: float | Vec3 = 0.0
    """Velocity white noise per N, E, D axis, per sample [m/s]."""
    rate: float = 10.0
    """Output rate [Hz]."""

    def __post_init__(self) -> None:
        names = ("tilt", "synchro_bias", "synchro_noise", "vel_bias", "vel_noise")
        for name in names:
            as_vec3(self, name)
        check_nonnegative(self, *names)
        check_positive(self, "rate")

    def draw(self, rng: np.random.Generator) -> MasterInsErrors:
        """Draw the random constants of one run."""
        return MasterInsErrors(
            tilt=rng.standard_normal(3) * np.asarray(self.tilt),
            synchro_bias=rng.standard_normal(3) * np.asarray(self.synchro_bias),
            vel_bias=rng.standard_normal(3) * np.asarray(self.vel_bias),
        )

    def measure(
        self,
        errors: MasterInsErrors,
        q_nr: np.ndarray,
        v_n: np.ndarray,
        pos: np.ndarray,
        rng: np.random.Generator,
    ) -> dict[str, np.ndarray]:
        """Master INS output at the given truth samples.

        Parameters
        ----------
        errors : MasterInsErrors
        q_nr : ndarray, shape (M, 4)
            True attitude of the master's body frame r (rotates r to n).
        v_n : ndarray, shape (M, 3)
            True velocity of the master NED [m/s].
        pos : ndarray, shape (M, 3)
            True position [rad, rad, m].
        rng : numpy.random.Generator

        Returns
        -------
        dict
            The MASTER_INS stream columns: ``euler`` (M, 3) roll, pitch, yaw [rad] (yaw wrapped
            to [-pi, pi)), ``v_n`` (M, 3) [m/s], ``pos`` (M, 3) [rad, rad, m].
        """
        q_nr = np.asarray(q_nr, dtype=float)
        v_n = np.asarray(v_n, dtype=float)
        pos = np.asarray(pos, dtype=float)
        m = q_nr.shape[0]
        if q_nr.shape != (m, 4) or v_n.shape != (m, 3) or pos.shape != (m, 3):
            raise ValueError(
                f"expected q_nr (M, 4), v_n (M, 3), pos (M, 3); got {q_nr.shape}, {v_n.shape},"
                f" {pos.shape}"
            )
        C_np = rotvec_to_dcm(-errors.tilt)  # platform frame p, exact rotation
        C_pr = C_np @ quat_to_dcm(q_nr)
        euler = dcm_to_euler(C_pr)
        euler += errors.synchro_bias
        euler += rng.standard_normal((m, 3)) * np.asarray(self.synchro_noise)
        euler[:, 2] = wrap_angle(euler[:, 2])
        v_meas = v_n + errors.vel_bias + rng.standard_normal((m, 3)) * np.asarray(self.vel_noise)
        return {"euler": euler, "v_n": v_meas, "pos": pos.copy()}


@dataclasses.dataclass(frozen=True, kw_only=True)
class MasterInsErrors(RealisedErrors):
    """Random constants of one run.

    Attributes
    ----------
    tilt : ndarray, shape (3,)
        Platform tilt eps_N, eps_E, eps_D [rad]; ``C_np = exp(-[eps x])``.
    synchro_bias : ndarray, shape (3,)
        Added to roll, pitch, yaw [rad].
    vel_bias : ndarray, shape (3,)
        Added to the NED velocity [m/s].
    """

    tilt: np.ndarray
    synchro_bias: np.ndarray
    vel_bias: np.ndarray
