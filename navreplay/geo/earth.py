"""WGS84 earth model in the NED frame: radii, normal gravity, earth and transport rate, ECEF.

All functions broadcast over leading array dimensions. Latitude and longitude in radians,
height in metres above the ellipsoid.
"""

from __future__ import annotations

import numpy as np

A = 6378137.0
"""WGS84 semi-major axis [m]."""
F = 1.0 / 298.257223563
"""WGS84 flattening."""
B = A * (1.0 - F)
"""Semi-minor axis [m]."""
E2 = F * (2.0 - F)
"""First eccentricity squared."""
OMEGA_IE = 7.292115e-5
"""Earth rotation rate [rad/s]."""
GM = 3.986004418e14
"""Earth gravitational constant [m^3/s^2]."""
GAMMA_E = 9.7803253359
"""Normal gravity at the equator [m/s^2]."""
GAMMA_P = 9.8321849378
"""Normal gravity at the poles [m/s^2]."""
K_SOMIGLIANA = B * GAMMA_P / (A * GAMMA_E) - 1.0
M_GRAV = OMEGA_IE**2 * A**2 * B / GM


def radii(lat):
    """Meridian and transverse (prime-vertical) radii of curvature.

    Parameters
    ----------
    lat : array_like
        Geodetic latitude [rad].

    Returns
    -------
    R_M, R_N : ndarray
        Meridian radius and transverse radius [m].

    Examples
    --------
    >>> R_M, R_N = radii(0.0)
    >>> round(float(R_N), 3), round(float(R_M), 3)
    (6378137.0, 6335439.327)
    """
    s2 = np.sin(lat) ** 2
    w = 1.0 - E2 * s2
    R_N = A / np.sqrt(w)
    R_M = A * (1.0 - E2) / w**1.5
    return R_M, R_N


def radii_derivatives(lat):
    """Derivatives dR_M/dlat and dR_N/dlat [m/rad]."""
    s = np.sin(lat)
    c = np.cos(lat)
    w = 1.0 - E2 * s * s
    dR_M = 3.0 * A * (1.0 - E2) * E2 * s * c / w**2.5
    dR_N = A * E2 * s * c / w**1.5
    return dR_M, dR_N


def gravity(lat, h):
    """Normal gravity magnitude: Somigliana on the ellipsoid with the second-order height term.

    Parameters
    ----------
    lat : array_like
        Geodetic latitude [rad].
    h : array_like
        Ellipsoidal height [m].

    Returns
    -------
    ndarray
        Gravity magnitude [m/s^2], positive (points down in NED).

    Examples
    --------
    >>> round(float(gravity(0.0, 0.0)), 7)
    9.7803253
    """
    s2 = np.sin(lat) ** 2
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / np.sqrt(1.0 - E2 * s2)
    h = np.asarray(h, dtype=float)
    return g0 * (
        1.0 - 2.0 / A * (1.0 + F + M_GRAV - 2.0 * F * s2) * h + 3.0 / A**2 * h**2
    )


def gravity_n(lat, h):
    """Normal gravity vector in NED [m/s^2], shape (..., 3): ``[0, 0, g]``."""
    g = np.asarray(gravity(lat, h))
    out = np.zeros(g.shape + (3,))
    out[..., 2] = g
    return out


def omega_ie_n(lat):
    """Earth rate resolved in NED [rad/s], shape (..., 3)."""
    lat = np.asarray(lat, dtype=float)
    out = np.zeros(lat.shape + (3,))
    out[..., 0] = OMEGA_IE * np.cos(lat)
    out[..., 2] = -OMEGA_IE * np.sin(lat)
    return out


def omega_en_n(lat, h, v_n):
    """Transport rate (n relative to e) resolved in NED [rad/s], shape (..., 3).

    Parameters
    ----------
    lat, h : array_like
        Latitude [rad] and height [m].
    v_n : array_like, shape (..., 3)
        Ground velocity in NED [m/s].
    """
    v_n = np.asarray(v_n, dtype=float)
    R_M, R_N = radii(lat)
    h = np.asarray(h, dtype=float)
    out = np.empty(np.broadcast_shapes(np.shape(R_M), h.shape, v_n.shape[:-1]) + (3,))
    out[..., 0] = v_n[..., 1] / (R_N + h)
    out[..., 1] = -v_n[..., 0] / (R_M + h)
    out[..., 2] = -v_n[..., 1] * np.tan(lat) / (R_N + h)
    return out


def lla_to_ecef(lat, lon, h):
    """Geodetic to ECEF coordinates [m], shape (..., 3)."""
    lat = np.asarray(lat, dtype=float)
    _, R_N = radii(lat)
    cl = np.cos(lat)
    x = (R_N + h) * cl * np.cos(lon)
    y = (R_N + h) * cl * np.sin(lon)
    z = (R_N * (1.0 - E2) + h) * np.sin(lat)
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1)


def ecef_to_lla(r_e):
    """ECEF [m] to geodetic (lat, lon, h), by Bowring's initial value and Newton refinement.

    Accurate to well below a micrometre for heights from -1e5 to 1e7 m.
    """
    r_e = np.asarray(r_e, dtype=float)
    x, y, z = r_e[..., 0], r_e[..., 1], r_e[..., 2]
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    ep2 = E2 / (1.0 - E2)
    theta = np.arctan2(z * A, p * B)
    lat = np.arctan2(z + ep2 * B * np.sin(theta) ** 3, p - E2 * A * np.cos(theta) ** 3)
    for _ in range(3):
        _, R_N = radii(lat)
        # height from whichever of p, z is better conditioned
        cl, sl = np.cos(lat), np.sin(lat)
        h = np.where(np.abs(cl) > 0.5, p / np.where(cl == 0, 1, cl) - R_N,
                     z / np.where(sl == 0, 1, sl) - R_N * (1.0 - E2))
        lat = np.arctan2(z, p * (1.0 - E2 * R_N / (R_N + h)))
    _, R_N = radii(lat)
    cl, sl = np.cos(lat), np.sin(lat)
    h = p * cl + z * sl - A * np.sqrt(1.0 - E2 * sl * sl)
    return lat, lon, h


def C_en(lat, lon):
    """DCM from NED to ECEF (maps n-frame vectors to e-frame), shape (..., 3, 3)."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    out = np.empty(np.broadcast_shapes(lat.shape, lon.shape) + (3, 3))
    out[..., 0, 0] = -sl * co
    out[..., 0, 1] = -so
    out[..., 0, 2] = -cl * co
    out[..., 1, 0] = -sl * so
    out[..., 1, 1] = co
    out[..., 1, 2] = -cl * so
    out[..., 2, 0] = cl
    out[..., 2, 1] = 0.0
    out[..., 2, 2] = -sl
    return out


def ned_offset_to_lla(lat0, lon0, h0, d_ned):
    """Small NED displacement [m] from a reference point to (lat, lon, h), exact via ECEF."""
    r0 = lla_to_ecef(lat0, lon0, h0)
    r = r0 + np.einsum("...ij,...j->...i", C_en(lat0, lon0), np.asarray(d_ned, dtype=float))
    return ecef_to_lla(r)


def lla_to_ned_offset(lat0, lon0, h0, lat, lon, h):
    """NED displacement [m] of (lat, lon, h) from a reference point, exact via ECEF."""
    dr = lla_to_ecef(lat, lon, h) - lla_to_ecef(lat0, lon0, h0)
    return np.einsum("...ji,...j->...i", C_en(lat0, lon0), dr)
