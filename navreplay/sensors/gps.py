"""GNSS receiver error model: position fix and NED velocity.

    pos_meas = pos + (white_N,E,D + gm_N,E,D)  (NED metres, mapped to latitude/longitude/height)
    v_meas   = v_n + (white_N,E,D + gm_N,E,D)  (m/s)

The white parts are independent per epoch and axis; the optional Gauss-Markov parts (per-axis
steady-state sigma, one correlation time each) model the slowly wandering errors of a real
receiver (multipath, atmosphere). The reported ``pos_sigma`` and ``vel_sigma`` are the total
stationary 1-sigma per axis, sqrt(white^2 + gm^2).

Outages
    A schedule of ``(start, length)`` pairs [s since the recording start] during which the
    receiver gives nothing: every epoch in ``[start, start + length)`` is dropped from the
    fixes and the velocities (:func:`outage_mask`); the Gauss-Markov errors keep wandering
    underneath. Scenarios with GNSS take it as the parameter ``gps_outages``
    (``-p gps_outages=120:30,300:60``, or ``gps_outages = [[120, 30], [300, 60]]`` in TOML;
    :func:`check_outages`) and record it in ``metadata.extra["gnss_outages"]`` as
    ``[[start, end], ...]`` [s] (:data:`navreplay.core.outages.OUTAGES_KEY`, read by
    :func:`navreplay.core.outages.recorded_outages`), where the
    scoring and the view find it whatever the scenario.

Examples
--------
>>> import numpy as np
>>> gps = GpsModel(pos_sigma=(2.0, 2.0, 4.0), vel_sigma=0.05)
>>> rng = np.random.default_rng(1)
>>> pos = np.tile([0.6, 2.2, 40.0], (5, 1)); v = np.zeros((5, 3))
>>> out = gps.measure(gps.draw(rng), pos, v, rng)
>>> sorted(out.fix_columns()), sorted(out.velocity_columns())
(['pos', 'pos_sigma'], ['v_n', 'vel_sigma'])
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from typing import ClassVar

import numpy as np

from navreplay.core.params import check_nonnegative, check_positive
from navreplay.geo.earth import radii
from navreplay.sensors._common import FieldUnit, RealisedErrors, Vec3, as_vec3
from navreplay.sensors.noise import gauss_markov


@dataclasses.dataclass(frozen=True, kw_only=True)
class GpsModel:
    """1-sigma error specification of a GNSS receiver (SI). A scalar applies to all axes."""

    field_units: ClassVar[Mapping[str, FieldUnit]] = {
        "pos_sigma": FieldUnit("m", "m"),
        "pos_gm_sigma": FieldUnit("m", "m"),
        "pos_gm_tau": FieldUnit("s", "s"),
        "vel_sigma": FieldUnit("m/s", "m/s"),
        "vel_gm_sigma": FieldUnit("m/s", "m/s"),
        "vel_gm_tau": FieldUnit("s", "s"),
        "rate": FieldUnit("Hz", "Hz"),
    }
    """Unit of each field in SI and in datasheets."""
    error_terms: ClassVar[Mapping[str, str]] = {
        "pos_sigma": "white position noise",
        "pos_gm_sigma": "time-correlated (Gauss-Markov) position error",
        "vel_sigma": "white velocity noise",
        "vel_gm_sigma": "time-correlated (Gauss-Markov) velocity error",
    }
    """The fields that are error magnitudes, each with what it is
    (:attr:`navreplay.sensors.imu.ImuModel.error_terms`)."""

    pos_sigma: float | Vec3 = (2.5, 2.5, 5.0)
    """White position noise per axis N, E, D [m]."""
    pos_gm_sigma: float | Vec3 = 0.0
    """Steady-state sigma of the Gauss-Markov position error per axis N, E, D [m]."""
    pos_gm_tau: float = 300.0
    """Correlation time of the Gauss-Markov position error [s]."""
    vel_sigma: float | Vec3 = 0.05
    """White velocity noise per axis N, E, D [m/s]."""
    vel_gm_sigma: float | Vec3 = 0.0
    """Steady-state sigma of the Gauss-Markov velocity error per axis N, E, D [m/s]."""
    vel_gm_tau: float = 10.0
    """Correlation time of the Gauss-Markov velocity error [s]."""
    rate: float = 1.0
    """Output rate [Hz]."""

    def __post_init__(self) -> None:
        for name in ("pos_sigma", "pos_gm_sigma", "vel_sigma", "vel_gm_sigma"):
            as_vec3(self, name)
        check_nonnegative(self, "pos_sigma", "pos_gm_sigma", "vel_sigma", "vel_gm_sigma")
        check_positive(self, "pos_gm_tau", "vel_gm_tau", "rate")

    def total_pos_sigma(self) -> np.ndarray:
        """Stationary 1-sigma of the position error per axis N, E, D, white and Gauss-Markov
        together [m], shape (3,)."""
        return np.hypot(self.pos_sigma, self.pos_gm_sigma)

    def total_vel_sigma(self) -> np.ndarray:
        """Stationary 1-sigma of the velocity error per axis N, E, D [m/s], shape (3,)."""
        return np.hypot(self.vel_sigma, self.vel_gm_sigma)

    def draw(self, rng: np.random.Generator) -> GpsErrors:
        """Draw the random constants of one run: the initial Gauss-Markov position error."""
        return GpsErrors(pos_gm0_ned=rng.standard_normal(3) * np.asarray(self.pos_gm_sigma))

    def measure(
        self,
        errors: GpsErrors,
        pos: np.ndarray,
        v_n: np.ndarray,
        rng: np.random.Generator,
    ) -> GpsMeasurement:
        """Fixes and velocities at the given truth samples, taken at ``rate``.

        Parameters
        ----------
        errors : GpsErrors
        pos : ndarray, shape (M, 3)
            True position [rad, rad, m] at the GPS epochs (1 / rate apart).
        v_n : ndarray, shape (M, 3)
            True ground velocity NED [m/s] at the GPS epochs.
        rng : numpy.random.Generator

        Returns
        -------
        GpsMeasurement
        """
        pos = np.asarray(pos, dtype=float)
        v_n = np.asarray(v_n, dtype=float)
        if pos.ndim != 2 or pos.shape[1] != 3 or v_n.shape != pos.shape:
            raise ValueError(f"pos and v_n must have shape (M, 3), got {pos.shape}, {v_n.shape}")
        m = pos.shape[0]
        dt = 1.0 / self.rate
        gm_sigma = np.asarray(self.pos_gm_sigma)
        white = np.asarray(self.pos_sigma)
        gm = gauss_markov(m, dt, gm_sigma, self.pos_gm_tau, rng, x0=errors.pos_gm0_ned)
        err_ned = gm + rng.standard_normal((m, 3)) * white
        vel_err = rng.standard_normal((m, 3)) * np.asarray(self.vel_sigma)
        vel_err += gauss_markov(m, dt, np.asarray(self.vel_gm_sigma), self.vel_gm_tau, rng)

        R_M, R_N = radii(pos[:, 0])
        h = pos[:, 2]
        meas = pos.copy()
        meas[:, 0] += err_ned[:, 0] / (R_M + h)
        meas[:, 1] += err_ned[:, 1] / ((R_N + h) * np.cos(pos[:, 0]))
        meas[:, 2] -= err_ned[:, 2]
        pos_sigma = np.broadcast_to(self.total_pos_sigma(), (m, 3))
        vel_sigma = np.broadcast_to(self.total_vel_sigma(), (m, 3))
        return GpsMeasurement(
            pos=meas,
            pos_sigma=np.array(pos_sigma),
            v_n=v_n + vel_err,
            vel_sigma=np.array(vel_sigma),
            pos_error_ned=err_ned,
            vel_error_n=vel_err,
            pos_gm_ned=gm,
        )


@dataclasses.dataclass(frozen=True, kw_only=True)
class GpsErrors(RealisedErrors):
    """Random constants of one run.

    Attributes
    ----------
    pos_gm0_ned : ndarray, shape (3,)
        Gauss-Markov position error at the first epoch, N, E, D [m].
    """

    pos_gm0_ned: np.ndarray


@dataclasses.dataclass(frozen=True, kw_only=True)
class GpsMeasurement:
    """Output of :meth:`GpsModel.measure`; all arrays have M rows.

    Attributes
    ----------
    pos : ndarray, shape (M, 3)
        Measured latitude [rad], longitude [rad], height [m].
    pos_sigma : ndarray, shape (M, 3)
        Reported 1-sigma N, E, D [m].
    v_n : ndarray, shape (M, 3)
        Measured velocity NED [m/s].
    vel_sigma : ndarray, shape (M, 3)
        Reported 1-sigma velocity N, E, D [m/s].
    pos_error_ned : ndarray, shape (M, 3)
        True position error N, E, D [m] (measured minus true).
    vel_error_n : ndarray, shape (M, 3)
        True velocity error NED [m/s].
    pos_gm_ned : ndarray, shape (M, 3)
        Its Gauss-Markov part N, E, D [m] (part of ``pos_error_ned``).
    """

    pos: np.ndarray
    pos_sigma: np.ndarray
    v_n: np.ndarray
    vel_sigma: np.ndarray
    pos_error_ned: np.ndarray
    vel_error_n: np.ndarray
    pos_gm_ned: np.ndarray

    def fix_columns(self) -> dict[str, np.ndarray]:
        """Columns of the GPS stream (``FIELDS[StreamKind.GPS]``)."""
        return {"pos": self.pos, "pos_sigma": self.pos_sigma}

    def velocity_columns(self) -> dict[str, np.ndarray]:
        """Columns of the GPS velocity stream (``FIELDS[StreamKind.GPS_VEL]``)."""
        return {"v_n": self.v_n, "vel_sigma": self.vel_sigma}


# -- outages ----------------------------------------------------------------------------------

Outages = tuple[tuple[float, float], ...]
"""A GNSS outage schedule: ``(start, length)`` pairs [s since the recording start]."""


def check_outages(outages: Iterable[Iterable[float]], duration: float,
                  name: str = "gps_outages") -> Outages:
    """An outage schedule as ``((start, length), ...)``, checked against a recording of
    ``duration`` [s]: each outage starts at or after 0, lasts more than 0 s, ends by the end of
    the recording (its end error is scored there), and starts after the previous one ended.
    Raises ``ValueError`` naming ``name`` and the outage.

    >>> check_outages([(120, 30), (300, 60.0)], 600.0)
    ((120.0, 30.0), (300.0, 60.0))
    >>> check_outages([(120, 30), (140, 10)], 600.0)
    Traceback (most recent call last):
    ...
    ValueError: gps_outages: the outage 140:10 starts before the previous one ends (150 s)
    """
    out: list[tuple[float, float]] = []
    end = 0.0
    for item in outages:
        pair = tuple(item)
        text = ":".join(f"{v:g}" if isinstance(v, int | float) else str(v) for v in pair)
        if len(pair) != 2 or not all(isinstance(v, int | float) and math.isfinite(v)
                                     for v in pair):
            raise ValueError(f"{name}: an outage is START:LENGTH in seconds, got {text!r}")
        start, length = float(pair[0]), float(pair[1])
        if start < 0.0 or length <= 0.0:
            raise ValueError(f"{name}: the outage {text} must start at or after 0 s and last "
                             "more than 0 s")
        if start + length > duration + 1e-9:
            raise ValueError(f"{name}: the outage {text} ends after the recording "
                             f"({duration:g} s)")
        if out and start < end:
            raise ValueError(f"{name}: the outage {text} starts before the previous one ends "
                             f"({end:g} s)")
        out.append((start, length))
        end = start + length
    return tuple(out)


def outage_mask(t: np.ndarray, outages: Outages) -> np.ndarray:
    """Which of the epochs ``t`` [s since the recording start] fall in an outage
    ``[start, start + length)``, shape of ``t``, bool."""
    t = np.asarray(t, dtype=float)
    inside = np.zeros(t.shape, dtype=bool)
    for start, length in outages:
        inside |= (t >= start - 1e-9) & (t < start + length - 1e-9)
    return inside


def outages_extra(outages: Outages) -> list[list[float]]:
    """The ``metadata.extra`` entry (:data:`navreplay.core.outages.OUTAGES_KEY`) of a
    schedule: ``[[start, end], ...]`` [s]."""
    return [[start, start + length] for start, length in outages]
