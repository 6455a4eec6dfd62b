"""Datasheet units expressed in SI. Multiply a datasheet value by the constant to get SI."""

import math

G0 = 9.80665
"""Standard gravity used for g-based datasheet units [m/s^2]."""

DEG = math.pi / 180.0
ARCMIN = DEG / 60.0
ARCSEC = DEG / 3600.0
MIL = 2.0 * math.pi / 6400.0
"""NATO mil [rad]."""
DEG_PER_HOUR = DEG / 3600.0
"""deg/h -> rad/s."""
DEG_PER_SQRT_HOUR = DEG / 60.0
"""deg/sqrt(h) (angle random walk) -> rad/sqrt(s)."""
DEG_PER_HOUR_PER_G = DEG_PER_HOUR / G0
"""deg/h/g (g-sensitivity) -> (rad/s)/(m/s^2)."""
MILLI_G = 1e-3 * G0
MICRO_G = 1e-6 * G0
MICRO_G_PER_SQRT_HZ = MICRO_G
"""ug/sqrt(Hz) (velocity random walk) -> m/s/sqrt(s)."""
PPM = 1e-6
FOOT = 0.3048
KNOT = 1852.0 / 3600.0
GAUSS = 1e-4
"""Gauss -> tesla."""
NANOTESLA = 1e-9
