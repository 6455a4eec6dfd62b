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

All 1-sigma values are SI; convert datasheet values with :mod:`navreplay.core.units` and the helpers
of :mod:`navreplay.sensors.noise` (e.g. white noise quoted as the 1-sigma of a 1-s average).

Examples
--------
>>> import numpy as np
>>> from navreplay.core.units import DEG_PER_HOUR, MICRO_G, PPM, ARCMIN
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
from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from navreplay.core import units
from navreplay.core.params import check_nonnegative, check_positive
from navreplay.geo import earth
from navreplay.geo.rotations import euler_to_quat, quat_to_dcm, quat_to_euler
from navreplay.sensors._common import FieldUnit, RealisedErrors, draw_misalignment, triad_matrix
from navreplay.sensors.noise import gauss_markov, random_walk, sample_sigma


@dataclasses.dataclass(frozen=True, kw_only=True)
class ImuModel:
    """1-sigma error specification of a strapdown IMU (SI units, per axis).

    Every random constant is drawn independently per axis (per matrix entry) and run. The
    record is the IMU's sensor specification (:mod:`navreplay.sensors.specs`): the simulator
    draws from it and the filters derive their noise and initial uncertainties from it.
    """

    field_units: ClassVar[Mapping[str, FieldUnit]] = {
        "gyro_bias": FieldUnit("rad/s", "deg/h"),
        "gyro_bias_instability": FieldUnit("rad/s", "deg/h"),
        "gyro_bias_tau": FieldUnit("s", "s"),
        "gyro_scale_factor": FieldUnit("", "ppm"),
        "gyro_misalignment": FieldUnit("rad", "mrad"),
        "gyro_g_sensitivity": FieldUnit("rad/s/(m/s^2)", "deg/h/g"),
        "gyro_arw": FieldUnit("rad/sqrt(s)", "deg/sqrt(h)"),
        "gyro_rrw": FieldUnit("rad/s/sqrt(s)", "deg/h/sqrt(h)"),
        "accel_bias": FieldUnit("m/s^2", "mg"),
        "accel_bias_instability": FieldUnit("m/s^2", "ug"),
        "accel_bias_tau": FieldUnit("s", "s"),
        "accel_scale_factor": FieldUnit("", "ppm"),
        "accel_misalignment": FieldUnit("rad", "mrad"),
        "accel_vrw": FieldUnit("m/s/sqrt(s)", "ug/sqrt(Hz)"),
        "accel_rw": FieldUnit("m/s^2/sqrt(s)", "ug/sqrt(s)"),
    }
    """Unit of each field in SI and in datasheets (``gyro_arw``: rad/sqrt(s), deg/sqrt(h))."""
    error_terms: ClassVar[Mapping[str, str]] = {
        "gyro_bias": "gyro turn-on bias",
        "gyro_bias_instability": "gyro bias instability",
        "gyro_scale_factor": "gyro scale factor",
        "gyro_misalignment": "gyro misalignment",
        "gyro_g_sensitivity": "gyro g-sensitivity",
        "gyro_arw": "gyro angle random walk",
        "gyro_rrw": "gyro rate random walk",
        "accel_bias": "accelerometer turn-on bias",
        "accel_bias_instability": "accelerometer bias instability",
        "accel_scale_factor": "accelerometer scale factor",
        "accel_misalignment": "accelerometer misalignment",
        "accel_vrw": "accelerometer velocity random walk",
        "accel_rw": "accelerometer bias random walk",
    }
    """The fields that are error magnitudes (the others, correlation times, parametrise them),
    each with what it is; a filter declares those it models
    (:meth:`navreplay.filters.base.Filter.modelled_terms`)."""

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
        return ImuErrors(
            gyro_bias=rng.standard_normal(3) * self.gyro_bias,
            gyro_scale_factor=rng.standard_normal(3) * self.gyro_scale_factor,
            gyro_misalignment=draw_misalignment(rng, self.gyro_misalignment),
            gyro_g_sensitivity=rng.standard_normal((3, 3)) * self.gyro_g_sensitivity,
            accel_bias=rng.standard_normal(3) * self.accel_bias,
            accel_scale_factor=rng.standard_normal(3) * self.accel_scale_factor,
            accel_misalignment=draw_misalignment(rng, self.accel_misalignment),
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
        g_sens = f_b @ errors.gyro_g_sensitivity.T if np.any(errors.gyro_g_sensitivity) else None
        omega, gyro_bias = _measure_triad(
            omega_ib_b, errors.gyro_matrix(), errors.gyro_bias, self.gyro_bias_instability,
            self.gyro_bias_tau, self.gyro_rrw, self.gyro_arw, dt, rng, coupling=g_sens,
        )
        f, accel_bias = _measure_triad(
            f_b, errors.accel_matrix(), errors.accel_bias, self.accel_bias_instability,
            self.accel_bias_tau, self.accel_rw, self.accel_vrw, dt, rng,
        )
        return ImuMeasurement(omega_ib_b=omega, f_b=f, gyro_bias=gyro_bias, accel_bias=accel_bias)


def _measure_triad(
    ideal: np.ndarray,
    matrix: np.ndarray,
    bias: np.ndarray,
    instability: float,
    tau: float,
    walk: float,
    white: float,
    dt: float,
    rng: np.random.Generator,
    coupling: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One triad of the module's model: ``(I + S + M) x + b(t) [+ coupling] + n``.

    Parameters
    ----------
    ideal : ndarray, shape (M, 3)
        Ideal interval means x.
    matrix : ndarray, shape (3, 3)
        ``I + S + M``.
    bias : ndarray, shape (3,)
        Random-constant bias b0.
    instability, tau : float
        Gauss-Markov steady-state sigma and correlation time [s] of the bias instability.
    walk : float
        Bias random-walk density.
    white : float
        White-noise density N; per-sample sigma N / sqrt(dt).
    dt : float
        Sample interval [s].
    rng : numpy.random.Generator
        Draws, in order: the Gauss-Markov bias, the random walk, the white noise.
    coupling : ndarray, shape (M, 3), optional
        A further error term (the gyro's g-sensitivity K_g f_b).

    Returns
    -------
    measured : ndarray, shape (M, 3)
    total_bias : ndarray, shape (M + 1, 3)
        b0 + b_GM + b_RW at the truth samples (row k applies to sample k, k = 1..M).
    """
    m = ideal.shape[0]
    total_bias = gauss_markov(m + 1, dt, instability, tau, rng)
    total_bias += random_walk(m + 1, dt, walk, rng)
    total_bias += bias
    out = ideal @ matrix.T
    out += total_bias[1:]
    if coupling is not None:
        out += coupling
    if white > 0.0:
        out += rng.standard_normal((m, 3)) * sample_sigma(white, dt)
    return out, total_bias


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
        return triad_matrix(self.gyro_scale_factor, self.gyro_misalignment)

    def accel_matrix(self) -> np.ndarray:
        """``I + S_a + M_a``, shape (3, 3)."""
        return triad_matrix(self.accel_scale_factor, self.accel_misalignment)


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


def effective_biases(
    errors: ImuErrors, meas: ImuMeasurement, q_nb: np.ndarray, pos: np.ndarray, *,
    level: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """The biases a filter without scale-factor and misalignment states estimates.

    A bias state absorbs every error that is constant while the vehicle is at rest: the true
    total bias plus the scale-factor, misalignment (and, for the gyro, g-sensitivity) errors
    acting on the rest values of the inputs, the gravity reaction ``f_0^b = -C_bn g^n`` and the
    earth rate ``w_ie^b = C_bn w_ie^n``::

        b_a,eff = b_a + (S_a + M_a) f_0^b
        b_g,eff = b_g + (S_g + M_g) w_ie^b + K_g f_0^b

    ``C_bn`` is the true attitude's, or with ``level`` that of the level attitude at the true
    heading (roll and pitch 0): the rest values of a vehicle whose specific force stays along
    its z axis while it drives up a slope or banks into a coordinated turn, so the bias is the
    one it has at 1 g; then ``f_0^b = (0, 0, -g)``.

    Parameters
    ----------
    errors : ImuErrors
    meas : ImuMeasurement
        Its ``gyro_bias`` and ``accel_bias`` rows align with ``q_nb`` and ``pos``.
    q_nb : ndarray, shape (M + 1, 4)
        True attitude.
    pos : ndarray, shape (M + 1, 3)
        True latitude, longitude [rad] and height [m].
    level : bool
        The rest values of the level attitude at the true heading.

    Returns
    -------
    gyro_bias_eff, accel_bias_eff : ndarray, shape (M + 1, 3)
        [rad/s] and [m/s^2].
    """
    if level:
        euler = quat_to_euler(q_nb)
        euler[:, :2] = 0.0
        q_nb = euler_to_quat(euler)
    C_bn = np.swapaxes(quat_to_dcm(q_nb), -1, -2)
    f0 = -np.einsum("kij,kj->ki", C_bn, earth.gravity_n(pos[:, 0], pos[:, 2]))
    w_ie = np.einsum("kij,kj->ki", C_bn, earth.omega_ie_n(pos[:, 0]))
    eye = np.eye(3)
    accel = meas.accel_bias + f0 @ (errors.accel_matrix() - eye).T
    gyro = (meas.gyro_bias + w_ie @ (errors.gyro_matrix() - eye).T
            + f0 @ errors.gyro_g_sensitivity.T)
    return gyro, accel


class ImuGrade(enum.StrEnum):
    """Preset IMU error levels (typical datasheet values, 1 sigma; the values are in
    ``_GRADES`` and in docs/sensors.md)."""

    IDEAL = "ideal"
    """No errors at all."""
    NAVIGATION = "navigation"
    """Navigation grade (ring-laser / high-end FOG): 0.01 deg/h, 25 ug."""
    TACTICAL = "tactical"
    """Tactical grade (FOG / high-end MEMS): 1 deg/h, 0.3 mg."""
    MEMS = "mems"
    """Industrial MEMS: 10 deg/h, 3 mg."""
    CONSUMER = "consumer"
    """Consumer MEMS (phone, automotive consumer 6-axis IMU): 0.1 deg/s turn-on bias,
    20 deg/h in-run instability, 0.4 deg/sqrt(h); 20 mg, 0.5 % scale factors, 0.5 deg
    misalignments."""


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
    >>> from navreplay.core.units import DEG_PER_HOUR
    >>> round(imu_grade("tactical").gyro_bias / DEG_PER_HOUR, 6)
    1.0
    """
    return _GRADES[ImuGrade(grade)]


_GRADES: dict[ImuGrade, ImuModel] = {
    ImuGrade.IDEAL: ImuModel(),
    ImuGrade.NAVIGATION: ImuModel(
        gyro_bias=0.01 * units.DEG_PER_HOUR,
        gyro_bias_instability=0.003 * units.DEG_PER_HOUR,
        gyro_bias_tau=3600.0,
        gyro_scale_factor=10 * units.PPM,
        gyro_misalignment=5 * units.ARCSEC,
        gyro_g_sensitivity=0.0,
        gyro_arw=0.002 * units.DEG_PER_SQRT_HOUR,
        accel_bias=25 * units.MICRO_G,
        accel_bias_instability=5 * units.MICRO_G,
        accel_bias_tau=3600.0,
        accel_scale_factor=50 * units.PPM,
        accel_misalignment=5 * units.ARCSEC,
        accel_vrw=5 * units.MICRO_G_PER_SQRT_HZ,
    ),
    ImuGrade.TACTICAL: ImuModel(
        gyro_bias=1.0 * units.DEG_PER_HOUR,
        gyro_bias_instability=0.3 * units.DEG_PER_HOUR,
        gyro_bias_tau=600.0,
        gyro_scale_factor=100 * units.PPM,
        gyro_misalignment=0.5e-3,
        gyro_g_sensitivity=1.0 * units.DEG_PER_HOUR_PER_G,
        gyro_arw=0.1 * units.DEG_PER_SQRT_HOUR,
        accel_bias=0.3 * units.MILLI_G,
        accel_bias_instability=0.05 * units.MILLI_G,
        accel_bias_tau=600.0,
        accel_scale_factor=300 * units.PPM,
        accel_misalignment=0.5e-3,
        accel_vrw=50 * units.MICRO_G_PER_SQRT_HZ,
    ),
    ImuGrade.MEMS: ImuModel(
        gyro_bias=10.0 * units.DEG_PER_HOUR,
        gyro_bias_instability=3.0 * units.DEG_PER_HOUR,
        gyro_bias_tau=300.0,
        gyro_scale_factor=1000 * units.PPM,
        gyro_misalignment=1e-3,
        gyro_g_sensitivity=10.0 * units.DEG_PER_HOUR_PER_G,
        gyro_arw=0.3 * units.DEG_PER_SQRT_HOUR,
        accel_bias=3.0 * units.MILLI_G,
        accel_bias_instability=0.1 * units.MILLI_G,
        accel_bias_tau=300.0,
        accel_scale_factor=1000 * units.PPM,
        accel_misalignment=1e-3,
        accel_vrw=100 * units.MICRO_G_PER_SQRT_HZ,
    ),
    # A consumer 6-axis MEMS IMU as in phones and consumer automotive modules (datasheet
    # typicals of that class: zero-rate offset +-0.5 deg/s max, noise density ~0.007
    # deg/s/sqrt(Hz), sensitivity tolerance +-0.5 %, cross-axis +-1 %, zero-g offset +-40 mg,
    # noise ~150 ug/sqrt(Hz)), 1 sigma: the in-run (Allan) instability is tens of deg/h, the
    # turn-on bias a fifth of the max offset.
    ImuGrade.CONSUMER: ImuModel(
        gyro_bias=0.1 * units.DEG_PER_SECOND,
        gyro_bias_instability=20.0 * units.DEG_PER_HOUR,
        gyro_bias_tau=100.0,
        gyro_scale_factor=0.5 * units.PERCENT,
        gyro_misalignment=0.5 * units.DEG,
        gyro_g_sensitivity=100.0 * units.DEG_PER_HOUR_PER_G,
        gyro_arw=0.4 * units.DEG_PER_SQRT_HOUR,
        accel_bias=20.0 * units.MILLI_G,
        accel_bias_instability=0.2 * units.MILLI_G,
        accel_bias_tau=100.0,
        accel_scale_factor=0.5 * units.PERCENT,
        accel_misalignment=0.5 * units.DEG,
        accel_vrw=150 * units.MICRO_G_PER_SQRT_HZ,
    ),
}
