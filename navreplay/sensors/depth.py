"""Depth sensor: ``depth_meas = depth + bias + white noise`` (depth positive down, d = -h).

Examples
--------
>>> import numpy as np
>>> model = DepthModel(bias=0.0, noise=0.0)
>>> model.measure(model.draw(np.random.default_rng(0)), np.array([50.0]),
...               np.random.default_rng(1))["depth"]
array([50.])
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from navreplay.core.params import check_nonnegative, check_positive
from navreplay.sensors._common import FieldUnit, RealisedErrors


@dataclasses.dataclass(frozen=True, kw_only=True)
class DepthModel:
    """1-sigma error specification of a depth (pressure) sensor (SI)."""

    field_units: ClassVar[Mapping[str, FieldUnit]] = {
        "bias": FieldUnit("m", "m"), "noise": FieldUnit("m", "m"), "rate": FieldUnit("Hz", "Hz"),
    }
    """Unit of each field in SI and in datasheets."""
    error_terms: ClassVar[Mapping[str, str]] = {"bias": "depth bias", "noise": "depth noise"}
    """The fields that are error magnitudes, each with what it is
    (:attr:`navreplay.sensors.imu.ImuModel.error_terms`)."""

    bias: float = 0.0
    """Bias, random constant [m]."""
    noise: float = 0.1
    """White noise per sample [m]."""
    rate: float = 1.0
    """Output rate [Hz]."""

    def __post_init__(self) -> None:
        check_nonnegative(self, "bias", "noise")
        check_positive(self, "rate")

    def draw(self, rng: np.random.Generator) -> DepthErrors:
        """Draw the bias of one run."""
        return DepthErrors(bias=float(rng.standard_normal() * self.bias))

    def measure(
        self, errors: DepthErrors, depth: np.ndarray, rng: np.random.Generator
    ) -> dict[str, np.ndarray]:
        """Depth readings.

        Parameters
        ----------
        errors : DepthErrors
        depth : ndarray, shape (M,)
            True depth [m], positive down (``-h`` with the sea surface on the ellipsoid).
        rng : numpy.random.Generator

        Returns
        -------
        dict
            ``{"depth": (M,) [m]}``, the DEPTH stream columns.
        """
        depth = np.asarray(depth, dtype=float)
        if depth.ndim != 1:
            raise ValueError(f"depth must have shape (M,), got {depth.shape}")
        out = depth + errors.bias
        if self.noise > 0.0:
            out += rng.standard_normal(depth.shape) * self.noise
        return {"depth": out}


@dataclasses.dataclass(frozen=True, kw_only=True)
class DepthErrors(RealisedErrors):
    """Random constants of one run.

    Attributes
    ----------
    bias : float
        [m].
    """

    bias: float
