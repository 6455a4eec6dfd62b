"""Strapdown IMU error model: gyro and accelerometer triads.

Each sample is the mean body rate and specific force over the preceding sample interval (the
``navreplay`` IMU convention). The measured values are

    omega_meas = (I + S_g + M_g) omega_ib_b + b_g(t) + K_g f_b + n_g
    f_meas     = (I + S_a + M_a) f_b        + b_a(t)           + n_a

with, per triad,

- S = diag(s_x, s_y, s_z): scale-factor errors, random constants;
- M: misalignment / non-orthogonality, the six off-diagonal terms, random constants (zero
  diagonal); M[i, j] couples true axis j into sensor axis i;
- b(t) = b0 + b_GM(t) + b_RW(t): a random-constant bias, a first-order Gauss-Markov bias
  instability (sigma, tau) and an optional rate / acceleration random walk starting at 0;
- K_g: the gyro g-sensitivity (mass unbalance), a full 3x3 random-constant matrix
  [(rad/s)/(m/s^2)] acting on the true specific force;
- n: white noise of density N (ARW, VRW); the per-sample sigma of a mean over dt is N / sqrt(dt).

All 1-sigma values are SI; convert datasheet values with :mod:`navreplay.units` and the helpers
of :mod:`navreplay.sensors.noise` (e.g. white noise quoted as the 1-sigma of a 1-s average).

Examples
--------
>>> import numpy as np
>>> from navreplay.units import DEG_PER_HOUR, MICRO_G, PPM, ARCMIN
>>> model = ImuModel(gyro_bias=0.6 * DEG_PER_HOUR, gyro_scale_factor=300 * PPM,
...                  gyro_misalignment=ARCMIN, accel_bias=250 * MICRO_G)
>>> rng = np.random.default_rng(0)
>>> errors = model.draw(rng)
>>> omega = np.zeros((100, 3)); f = np.tile([0.0, 0.0, -9.8], (100, 1))
>>> out = model.measure(errors, omega, f, 0.01, rng)
>>> out.omega_ib_b.shape, out.gyro_bias.shape
((100, 3), (101, 3))
"""

from __future__ import annotations

import dataclasses
import enum

import numpy as np

from navreplay import units
from navreplay.sensors._common import RealisedErrors, check_nonnegative, check_positive
from navreplay.sensors.noise import gauss_markov, random_walk, sample_sigma


@dataclasses.dataclass(frozen=True, kw_only=True)
class ImuModel:
    """1-sigma error specification of a strapdown IMU (SI units, per axis).

    Every random constant is drawn independently per axis (per matrix entry) and run.
    """

    gyro_bias: float = 0.0
    """Gyro bias, random constant [rad/s]."""
    gyro_bias_instability: float = 0.0
    """Gyro bias instability: steady-state sigma of a first-order Gauss-Markov process [rad/s]."""
    gyro_bias_tau: float = 3600.0
    """Correlation time of the gyro Gauss-Markov bias [s]."""
    gyro_scale_factor: float = 0.0
    """Gyro scale-factor error, random constant [-] (1e-6 = 1 ppm)."""
    gyro_misalignment: float = 0.0
    """Gyro misalignment / non-orthogonality, each of six off-diagonal terms [rad]."""
    gyro_g_sensitivity: float = 0.0
    """Gyro g-sensitivity (mass unbalance), each of the nine K_g entries [(rad/s)/(m/s^2)]."""
    gyro_arw: float = 0.0
    """Gyro white-noise density, angle random walk [rad/sqrt(s)]."""
    gyro_rrw: float = 0.0
    """Gyro rate random walk density [(rad/s)/sqrt(s)]."""
    accel_bias: float = 0.0
    """Accelerometer bias, random constant [m/s^2]."""
    accel_bias_instability: float = 0.0
    """Accelerometer bias instability: Gauss-Markov steady-state sigma [m/s^2]."""
    accel_bias_tau: float = 3600.0
    """Correlation time of the accelerometer Gauss-Markov bias [s]."""
    accel_scale_factor: float = 0.0
    """Accelerometer scale-factor error, random constant [-]."""
    accel_misalignment: float = 0.0
    """Accelerometer misalignment / non-orthogonality, each of six off-diagonal terms [rad]."""
    accel_vrw: float = 0.0
    """Accelerometer white-noise density, velocity random walk [(m/s)/sqrt(s)]."""
    accel_rw: float = 0.0
    """Accelerometer bias random walk density [(m/s^2)/sqrt(s)]."""

    def __post_init__(self) -> None:
        check_nonnegative(
            self,
            "gyro_bias", "gyro_bias_instability", "gyro_scale_factor", "gyro_misalignment",
            "gyro_g_sensitivity", "gyro_arw", "gyro_rrw",
            "accel_bias", "accel_bias_instability", "accel_scale_factor", "accel_misalignment",
            "accel_vrw", "accel_rw",
        )
        check_positive(self, "gyro_bias_tau", "accel_bias_tau")

    def draw(self, rng: np.random.Generator) -> ImuErrors:
        """Draw the random constants of one run.

        Parameters
        ----------
        rng : numpy.random.Generator

        Returns
        -------
        ImuErrors
        """
        def offdiag(sigma: float) -> np.ndarray:
            m = rng.standard_normal((3, 3)) * sigma
            np.fill_diagonal(m, 0.0)
            return m

        return ImuErrors(
            gyro_bias=rng.standard_normal(3) * self.gyro_bias,
            gyro_scale_factor=rng.standard_normal(3) * self.gyro_scale_factor,
            gyro_misalignment=offdiag(self.gyro_misalignment),
            gyro_g_sensitivity=rng.standard_normal((3, 3)) * self.gyro_g_sensitivity,
            accel_bias=rng.standard_normal(3) * self.accel_bias,
            accel_scale_factor=rng.standard_normal(3) * self.accel_scale_factor,
            accel_misalignment=offdiag(self.accel_misalignment),
        )

    def measure(
        self,
        errors: ImuErrors,
        omega_ib_b: np.ndarray,
        f_b: np.ndarray,
        dt: float,
        rng: np.random.Generator,
    ) -> ImuMeasurement:
        """Apply the errors to ideal IMU samples.

        Parameters
        ----------
        errors : ImuErrors
            Random constants of this run (from :meth:`draw`).
        omega_ib_b : ndarray, shape (M, 3)
            Ideal mean body rate over each sample interval [rad/s].
        f_b : ndarray, shape (M, 3)
            Ideal mean specific force over each sample interval [m/s^2].
        dt : float
            Sample interval [s] (uniform).
        rng : numpy.random.Generator
            Source of the time-varying errors (Gauss-Markov, random walks, white noise).

        Returns
        -------
        ImuMeasurement
            Measured samples and the true total biases over time.
        """
        omega_ib_b = np.asarray(omega_ib_b, dtype=float)
        f_b = np.asarray(f_b, dtype=float)
        if omega_ib_b.ndim != 2 or omega_ib_b.shape[1] != 3 or f_b.shape != omega_ib_b.shape:
            raise ValueError(
                f"omega_ib_b and f_b must both have shape (M, 3), got {omega_ib_b.shape}"
                f" and {f_b.shape}"
            )
        if not dt > 0.0:
            raise ValueError(f"dt must be > 0, got {dt!r}")
        m = omega_ib_b.shape[0]

        gyro_bias = gauss_markov(m + 1, dt, self.gyro_bias_instability, self.gyro_bias_tau, rng)
        gyro_bias += random_walk(m + 1, dt, self.gyro_rrw, rng)
        gyro_bias += errors.gyro_bias
        omega = omega_ib_b @ errors.gyro_matrix().T
        omega += gyro_bias[1:]
        if np.any(errors.gyro_g_sensitivity):
            omega += f_b @ errors.gyro_g_sensitivity.T
        if self.gyro_arw > 0.0:
            omega += rng.standard_normal((m, 3)) * sample_sigma(self.gyro_arw, dt)

        accel_bias = gauss_markov(
            m + 1, dt, self.accel_bias_instability, self.accel_bias_tau, rng
        )
        accel_bias += random_walk(m + 1, dt, self.accel_rw, rng)
        accel_bias += errors.accel_bias
        f = f_b @ errors.accel_matrix().T
        f += accel_bias[1:]
        if self.accel_vrw > 0.0:
            f += rng.standard_normal((m, 3)) * sample_sigma(self.accel_vrw, dt)

        return ImuMeasurement(omega_ib_b=omega, f_b=f, gyro_bias=gyro_bias, accel_bias=accel_bias)


@dataclasses.dataclass(frozen=True, kw_only=True)
class ImuErrors(RealisedErrors):
    """Random constants of one run (SI).

    Attributes
    ----------
    gyro_bias : ndarray, shape (3,)
        [rad/s].
    gyro_scale_factor : ndarray, shape (3,)
        [-].
    gyro_misalignment : ndarray, shape (3, 3)
        Off-diagonal non-orthogonality [rad], zero diagonal.
    gyro_g_sensitivity : ndarray, shape (3, 3)
        K_g [(rad/s)/(m/s^2)].
    accel_bias : ndarray, shape (3,)
        [m/s^2].
    accel_scale_factor : ndarray, shape (3,)
        [-].
    accel_misalignment : ndarray, shape (3, 3)
        Off-diagonal non-orthogonality [rad], zero diagonal.
    """

    gyro_bias: np.ndarray
    gyro_scale_factor: np.ndarray
    gyro_misalignment: np.ndarray
    gyro_g_sensitivity: np.ndarray
    accel_bias: np.ndarray
    accel_scale_factor: np.ndarray
    accel_misalignment: np.ndarray

    def gyro_matrix(self) -> np.ndarray:
        """``I + S_g + M_g``, shape (3, 3)."""
        return np.eye(3) + np.diag(self.gyro_scale_factor) + self.gyro_misalignment

    def accel_matrix(self) -> np.ndarray:
        """``I + S_a + M_a``, shape (3, 3)."""
        return np.eye(3) + np.diag(self.accel_scale_factor) + self.accel_misalignment


@dataclasses.dataclass(frozen=True, kw_only=True)
class ImuMeasurement:
    """Output of :meth:`ImuModel.measure`.

    Attributes
    ----------
    omega_ib_b : ndarray, shape (M, 3)
        Measured body rate [rad/s].
    f_b : ndarray, shape (M, 3)
        Measured specific force [m/s^2].
    gyro_bias : ndarray, shape (M + 1, 3)
        True total gyro bias (constant + Gauss-Markov + random walk) [rad/s]; row 0 at the
        start of the first interval, row k the value applied to sample k (k = 1..M, i.e. to
        ``omega_ib_b[k - 1]``), so the rows align with truth samples t[0..M].
    accel_bias : ndarray, shape (M + 1, 3)
        True total accelerometer bias [m/s^2], aligned like ``gyro_bias``.
    """

    omega_ib_b: np.ndarray
    f_b: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray

    def columns(self) -> dict[str, np.ndarray]:
        """The IMU stream columns (``FIELDS[StreamKind.IMU]``)."""
        return {"omega_ib_b": self.omega_ib_b, "f_b": self.f_b}


class ImuGrade(enum.StrEnum):
    """Preset IMU error levels (typical datasheet values, 1 sigma)."""

    IDEAL = "ideal"
    """No errors at all."""
    NAVIGATION = "navigation"
    """Navigation grade (ring-laser / high-end FOG): 0.01 deg/h, 25 ug."""
    TACTICAL = "tactical"
    """Tactical grade (FOG / high-end MEMS): 1 deg/h, 0.3 mg."""
    MEMS = "mems"
    """Industrial MEMS: 10 deg/h, 3 mg."""


def imu_grade(grade: ImuGrade | str) -> ImuModel:
    """The :class:`ImuModel` of a preset grade.

    Parameters
    ----------
    grade : ImuGrade or str

    Returns
    -------
    ImuModel

    Examples
    --------
    >>> from navreplay.units import DEG_PER_HOUR
    >>> round(imu_grade("tactical").gyro_bias / DEG_PER_HOUR, 6)
    1.0
    """
    grade = ImuGrade(grade)
    u = units
    if grade is ImuGrade.IDEAL:
        return ImuModel()
    if grade is ImuGrade.NAVIGATION:
        return ImuModel(
            gyro_bias=0.01 * u.DEG_PER_HOUR,
            gyro_bias_instability=0.003 * u.DEG_PER_HOUR,
            gyro_bias_tau=3600.0,
            gyro_scale_factor=10 * u.PPM,
            gyro_misalignment=5 * u.ARCSEC,
            gyro_g_sensitivity=0.0,
            gyro_arw=0.002 * u.DEG_PER_SQRT_HOUR,
            accel_bias=25 * u.MICRO_G,
            accel_bias_instability=5 * u.MICRO_G,
            accel_bias_tau=3600.0,
            accel_scale_factor=50 * u.PPM,
            accel_misalignment=5 * u.ARCSEC,
            accel_vrw=5 * u.MICRO_G_PER_SQRT_HZ,
        )
    if grade is ImuGrade.TACTICAL:
        return ImuModel(
            gyro_bias=1.0 * u.DEG_PER_HOUR,
            gyro_bias_instability=0.3 * u.DEG_PER_HOUR,
            gyro_bias_tau=600.0,
            gyro_scale_factor=100 * u.PPM,
            gyro_misalignment=0.5e-3,
            gyro_g_sensitivity=1.0 * u.DEG_PER_HOUR_PER_G,
            gyro_arw=0.1 * u.DEG_PER_SQRT_HOUR,
            accel_bias=0.3 * u.MILLI_G,
            accel_bias_instability=0.05 * u.MILLI_G,
            accel_bias_tau=600.0,
            accel_scale_factor=300 * u.PPM,
            accel_misalignment=0.5e-3,
            accel_vrw=50 * u.MICRO_G_PER_SQRT_HZ,
        )
    return ImuModel(
        gyro_bias=10.0 * u.DEG_PER_HOUR,
        gyro_bias_instability=3.0 * u.DEG_PER_HOUR,
        gyro_bias_tau=300.0,
        gyro_scale_factor=1000 * u.PPM,
        gyro_misalignment=1e-3,
        gyro_g_sensitivity=10.0 * u.DEG_PER_HOUR_PER_G,
        gyro_arw=0.3 * u.DEG_PER_SQRT_HOUR,
        accel_bias=3.0 * u.MILLI_G,
        accel_bias_instability=0.1 * u.MILLI_G,
        accel_bias_tau=300.0,
        accel_scale_factor=1000 * u.PPM,
        accel_misalignment=1e-3,
        accel_vrw=100 * u.MICRO_G_PER_SQRT_HZ,
    )
