"""Three-axis magnetometer: the earth field from the World Magnetic Model and a sensor error model.

Earth field
    :func:`earth_field_n` evaluates the WMM (pygeomag, offline) for a site and decimal year,
    choosing the coefficients by date: WMM2015 for 2015.0 <= year < 2020.0, WMM2020 for
    2020.0 <= year < 2025.0, WMM2025 for 2025.0 <= year < 2030.0 (:class:`WmmEpoch`). Other
    dates raise ``ValueError``.

Sensor
    ``m_b = (I + S + M) C_bn h_n + b + n``: scale factors S (diagonal), optional
    non-orthogonality M (off-diagonal), hard-iron bias b (random constants) and white noise n
    of a given per-sample sigma (instantaneous readings; use
    :func:`navreplay.sensors.noise.nyquist_sample_sigma` for a datasheet density).

Examples
--------
>>> import numpy as np
>>> h = earth_field_n(np.radians(37.55), np.radians(126.80), 0.0, 2017.0)
>>> np.round(h / 1e-9).astype(int).tolist()          # nT, N E D
[29419, -4307, 41627]
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import enum
import functools
import math
from collections.abc import Mapping
from typing import ClassVar

import numpy as np
from pygeomag import GeoMag

from navreplay.core.params import check_nonnegative, check_positive
from navreplay.core.units import NANOTESLA
from navreplay.geo.rotations import quat_conj, quat_rotate
from navreplay.sensors._common import FieldUnit, RealisedErrors, draw_misalignment, triad_matrix


class WmmEpoch(enum.StrEnum):
    """World Magnetic Model releases and the years they are valid for."""

    WMM2015 = "WMM2015"
    """Valid 2015.0 to 2020.0."""
    WMM2020 = "WMM2020"
    """Valid 2020.0 to 2025.0."""
    WMM2025 = "WMM2025"
    """Valid 2025.0 to 2030.0."""

    @property
    def start(self) -> float:
        """First valid decimal year."""
        return float(self.value[3:])

    @classmethod
    def for_year(cls, decimal_year: float) -> WmmEpoch:
        """The release valid at ``decimal_year``; ``ValueError`` outside 2015.0-2030.0."""
        for epoch in cls:
            if epoch.start <= decimal_year < epoch.start + 5.0:
                return epoch
        raise ValueError(
            f"no World Magnetic Model for decimal year {decimal_year}: the models cover"
            f" 2015.0 to 2030.0 (WMM2015, WMM2020, WMM2025)"
        )


@functools.cache
def _geomag(epoch: WmmEpoch) -> GeoMag:
    if epoch is WmmEpoch.WMM2015:
        from pygeomag.wmm.wmm_2015 import WMM_2015 as data
    elif epoch is WmmEpoch.WMM2020:
        from pygeomag.wmm.wmm_2020 import WMM_2020 as data
    else:
        from pygeomag.wmm.wmm_2025 import WMM_2025 as data
    return GeoMag(coefficients_data=data)


def earth_field_n(lat: float, lon: float, h: float, decimal_year: float) -> np.ndarray:
    """Main geomagnetic field at a point, from the World Magnetic Model.

    Parameters
    ----------
    lat, lon : float
        Geodetic latitude and longitude [rad].
    h : float
        Height above the WGS84 ellipsoid [m].
    decimal_year : float
        Date as a decimal year (see :func:`decimal_year`), 2015.0 <= year < 2030.0.

    Returns
    -------
    ndarray, shape (3,)
        Flux density N, E, D [T].

    Raises
    ------
    ValueError
        Outside the years any bundled model covers.
    """
    epoch = WmmEpoch.for_year(float(decimal_year))
    lon_deg = (math.degrees(lon) + 180.0) % 360.0 - 180.0
    r = _geomag(epoch).calculate(
        glat=math.degrees(lat), glon=lon_deg, alt=h / 1000.0, time=float(decimal_year)
    )
    return np.array([r.x, r.y, r.z]) * NANOTESLA


def decimal_year(when: _dt.datetime | _dt.date) -> float:
    """Decimal year of a date or UTC date-time (2017-07-02T12:00 -> 2017.5).

    Parameters
    ----------
    when : datetime.date or datetime.datetime
        A naive date-time is taken as UTC.

    Returns
    -------
    float

    Examples
    --------
    >>> import datetime
    >>> decimal_year(datetime.date(2017, 1, 1))
    2017.0
    """
    if not isinstance(when, _dt.datetime):
        when = _dt.datetime(when.year, when.month, when.day)
    if when.tzinfo is not None:
        when = when.astimezone(_dt.UTC).replace(tzinfo=None)
    start = _dt.datetime(when.year, 1, 1)
    end = _dt.datetime(when.year + 1, 1, 1)
    return when.year + (when - start) / (end - start)


@dataclasses.dataclass(frozen=True, kw_only=True)
class MagnetometerModel:
    """1-sigma error specification of a three-axis magnetometer (SI, per axis)."""

    field_units: ClassVar[Mapping[str, FieldUnit]] = {
        "scale_factor": FieldUnit("", "%"),
        "misalignment": FieldUnit("rad", "deg"),
        "bias": FieldUnit("T", "nT"),
        "noise": FieldUnit("T", "nT"),
        "rate": FieldUnit("Hz", "Hz"),
    }
    """Unit of each field in SI and in datasheets."""
    error_terms: ClassVar[Mapping[str, str]] = {
        "scale_factor": "magnetometer scale factor", "misalignment": "magnetometer misalignment",
        "bias": "magnetometer hard-iron bias", "noise": "magnetometer noise"}
    """The fields that are error magnitudes, each with what it is
    (:attr:`navreplay.sensors.imu.ImuModel.error_terms`)."""

    scale_factor: float = 0.0
    """Scale-factor error, random constant per axis [-]."""
    misalignment: float = 0.0
    """Non-orthogonality, each of six off-diagonal terms, random constant [rad]."""
    bias: float = 0.0
    """Hard-iron bias, random constant per axis [T]."""
    noise: float = 0.0
    """White noise, 1-sigma per sample and axis [T]."""
    rate: float = 10.0
    """Output rate [Hz]."""

    def __post_init__(self) -> None:
        check_nonnegative(self, "scale_factor", "misalignment", "bias", "noise")
        check_positive(self, "rate")

    def draw(self, rng: np.random.Generator) -> MagnetometerErrors:
        """Draw the random constants of one run."""
        scale = rng.standard_normal(3) * self.scale_factor
        mis = draw_misalignment(rng, self.misalignment)
        bias = rng.standard_normal(3) * self.bias
        return MagnetometerErrors(scale_factor=scale, misalignment=mis, bias=bias)

    def measure(
        self,
        errors: MagnetometerErrors,
        q_nb: np.ndarray,
        h_n: np.ndarray,
        rng: np.random.Generator,
    ) -> dict[str, np.ndarray]:
        """Magnetometer readings at the given truth samples.

        Parameters
        ----------
        errors : MagnetometerErrors
        q_nb : ndarray, shape (M, 4)
            True attitude at the sample times.
        h_n : ndarray, shape (3,) or (M, 3)
            Earth field NED [T].
        rng : numpy.random.Generator

        Returns
        -------
        dict
            ``{"m_b": (M, 3) [T]}``, the MAG stream columns.
        """
        q_nb = np.asarray(q_nb, dtype=float)
        if q_nb.ndim != 2 or q_nb.shape[1] != 4:
            raise ValueError(f"q_nb must have shape (M, 4), got {q_nb.shape}")
        h_b = quat_rotate(quat_conj(q_nb), np.asarray(h_n, dtype=float))
        m_b = h_b @ errors.matrix().T + errors.bias
        if self.noise > 0.0:
            m_b += rng.standard_normal(m_b.shape) * self.noise
        return {"m_b": m_b}


@dataclasses.dataclass(frozen=True, kw_only=True)
class MagnetometerErrors(RealisedErrors):
    """Random constants of one run.

    Attributes
    ----------
    scale_factor : ndarray, shape (3,)
        [-].
    misalignment : ndarray, shape (3, 3)
        Off-diagonal non-orthogonality [rad], zero diagonal.
    bias : ndarray, shape (3,)
        Hard-iron bias [T].
    """

    scale_factor: np.ndarray
    misalignment: np.ndarray
    bias: np.ndarray

    def matrix(self) -> np.ndarray:
        """``I + S + M``, shape (3, 3)."""
        return triad_matrix(self.scale_factor, self.misalignment)
