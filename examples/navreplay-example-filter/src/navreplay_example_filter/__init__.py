"""Example navreplay plug-in: a GNSS-only constant-velocity Kalman filter (``gps-cv``)."""

from navreplay_example_filter.gps_cv import GpsConstantVelocity, GpsCvParams

__all__ = ["GpsConstantVelocity", "GpsCvParams"]
