"""Propeller-RPM speed log and the sea-current kinematics it needs.

The sensor of docs/methods/rpm-aided-ins.md §3.

The RPM axis v is the body x axis rotated by the small misalignment m = [0, m_y, m_z]:
``C_bv = exp([m x])``. The vehicle moves through the water along that axis with the
water-relative speed u, and the water moves with the sea current v_c_n:

    v_w_b = C_bv [u, 0, 0]            water-relative velocity in the body frame
    v_n   = C_nb v_w_b + v_c_n        ground velocity (:func:`ground_velocity`)
    rpm   = (1 + k) u / c_rpm + noise (:meth:`SpeedLogModel.measure`)

with the scale-factor error k and the misalignment m random constants per run, and
c_rpm the nominal propeller law [(m/s)/rpm]. A filter converts back with
``u_hat = c_rpm rpm / (1 + k_hat)``.

Examples
--------
>>> import numpy as np
>>> log = SpeedLogModel(scale_factor=0.0, misalignment=0.0, noise=0.0)
>>> errors = log.draw(np.random.default_rng(0))
>>> log.measure(errors, np.array([14.0]), np.random.default_rng(1))["rpm"]
array([1400.])
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from navreplay.core.params import check_nonnegative, check_positive
from navreplay.core.units import DEG
from navreplay.geo.rotations import quat_conj, quat_rotate, rotvec_to_dcm
from navreplay.sensors._common import FieldUnit, RealisedErrors


@dataclasses.dataclass(frozen=True, kw_only=True)
class SpeedLogModel:
    """1-sigma error specification of a propeller-RPM speed log (SI)."""

    field_units: ClassVar[Mapping[str, FieldUnit]] = {
        "scale_factor": FieldUnit("", "%"),
        "misalignment": FieldUnit("rad", "deg"),
        "noise": FieldUnit("rpm", "rpm"),
        "speed_per_rpm": FieldUnit("m/s/rpm", "m/s/rpm"),
        "rate": FieldUnit("Hz", "Hz"),
    }
    """Unit of each field in SI and in datasheets (the noise in rev/min, as the stream)."""
    error_terms: ClassVar[Mapping[str, str]] = {
        "scale_factor": "RPM scale factor", "misalignment": "RPM-axis misalignment",
        "noise": "RPM noise"}
    """The fields that are error magnitudes, each with what it is
    (:attr:`navreplay.sensors.imu.ImuModel.error_terms`)."""

    scale_factor: float = 0.02
    """RPM scale-factor error k, random constant [-]."""
    misalignment: float = 0.1 * DEG
    """RPM-axis misalignment m_y and m_z, random constants [rad]."""
    noise: float = 5.0
    """White noise per sample [rev/min]."""
    speed_per_rpm: float = 0.01
    """Nominal propeller law c_rpm: water speed per shaft speed [(m/s)/(rev/min)]."""
    rate: float = 10.0
    """Output rate [Hz]."""

    def __post_init__(self) -> None:
        check_nonnegative(self, "scale_factor", "misalignment", "noise")
        check_positive(self, "speed_per_rpm", "rate")

    def draw(self, rng: np.random.Generator) -> SpeedLogErrors:
        """Draw k and m = [0, m_y, m_z] of one run."""
        k = float(rng.standard_normal() * self.scale_factor)
        m = np.zeros(3)
        m[1:] = rng.standard_normal(2) * self.misalignment
        return SpeedLogErrors(scale_factor=k, misalignment=m)

    def measure(
        self, errors: SpeedLogErrors, u: np.ndarray, rng: np.random.Generator
    ) -> dict[str, np.ndarray]:
        """Shaft speed readings.

        Parameters
        ----------
        errors : SpeedLogErrors
        u : ndarray, shape (M,)
            True water-relative speed along the (misaligned) RPM axis [m/s].
        rng : numpy.random.Generator

        Returns
        -------
        dict
            ``{"rpm": (M,) [rev/min]}``, the SPEED_LOG stream columns.
        """
        u = np.asarray(u, dtype=float)
        if u.ndim != 1:
            raise ValueError(f"u must have shape (M,), got {u.shape}")
        rpm = (1.0 + errors.scale_factor) * u / self.speed_per_rpm
        if self.noise > 0.0:
            rpm += rng.standard_normal(u.shape) * self.noise
        return {"rpm": rpm}


@dataclasses.dataclass(frozen=True, kw_only=True)
class SpeedLogErrors(RealisedErrors):
    """Random constants of one run.

    Attributes
    ----------
    scale_factor : float
        k [-]: the log reads (1 + k) times the true speed.
    misalignment : ndarray, shape (3,)
        m = [0, m_y, m_z] [rad]; ``C_bv = exp([m x])``.
    """

    scale_factor: float
    misalignment: np.ndarray


def rpm_axis_b(misalignment: np.ndarray) -> np.ndarray:
    """Unit RPM axis in the body frame: first column of ``C_bv = exp([m x])``.

    Parameters
    ----------
    misalignment : array_like, shape (3,)
        m [rad].

    Returns
    -------
    ndarray, shape (3,)
    """
    return rotvec_to_dcm(np.asarray(misalignment, dtype=float))[:, 0]


def ground_velocity(
    q_nb: np.ndarray, u: np.ndarray, misalignment: np.ndarray, v_c_n: np.ndarray
) -> np.ndarray:
    """Ground velocity of a vehicle moving through a current: ``C_nb C_bv [u, 0, 0] + v_c_n``.

    Parameters
    ----------
    q_nb : ndarray, shape (M, 4)
        True attitude.
    u : ndarray, shape (M,)
        Water-relative speed along the RPM axis [m/s].
    misalignment : array_like, shape (3,)
        RPM-axis misalignment m [rad].
    v_c_n : array_like, shape (3,) or (M, 3)
        Sea-current velocity NED [m/s].

    Returns
    -------
    ndarray, shape (M, 3)
        [m/s].
    """
    v_w_b = np.asarray(u, dtype=float)[:, None] * rpm_axis_b(misalignment)
    return quat_rotate(q_nb, v_w_b) + np.asarray(v_c_n, dtype=float)


def water_speed_along_axis(
    q_nb: np.ndarray, v_n: np.ndarray, misalignment: np.ndarray, v_c_n: np.ndarray
) -> np.ndarray:
    """Inverse of :func:`ground_velocity` for the along-axis part:
    ``[C_bv^T C_bn (v_n - v_c_n)]_x``.

    Parameters
    ----------
    q_nb : ndarray, shape (M, 4)
    v_n : ndarray, shape (M, 3)
        Ground velocity [m/s].
    misalignment : array_like, shape (3,)
        m [rad].
    v_c_n : array_like, shape (3,) or (M, 3)
        Current [m/s].

    Returns
    -------
    ndarray, shape (M,)
        u [m/s].
    """
    q_bn = quat_conj(np.asarray(q_nb, dtype=float))
    v_w_b = quat_rotate(q_bn, np.asarray(v_n, dtype=float) - np.asarray(v_c_n, dtype=float))
    return v_w_b @ rpm_axis_b(misalignment)
