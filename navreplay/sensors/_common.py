"""Helpers shared by the sensor models: per-axis fields, random-constant draws and realised
errors as plain JSON values."""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import numpy as np

from navreplay.core.streams import jsonable

Vec3 = tuple[float, float, float]
"""Three per-axis values (N, E, D or x, y, z)."""


class FieldUnit(NamedTuple):
    """Units of a field of an error specification: the unit its value is held in (SI, or the
    unit the field's docstring names) and the datasheet unit it is written in
    (:mod:`navreplay.sensors.specs`); both expressions of :mod:`navreplay.core.units`."""

    si: str
    datasheet: str


def as_vec3(owner: object, name: str) -> None:
    """Normalise field ``name`` of a frozen dataclass to a tuple of three floats.

    A scalar applies to all three axes; anything else must have exactly three elements.
    """
    value = getattr(owner, name)
    vec: tuple[float, ...]
    if isinstance(value, int | float):
        vec = (float(value),) * 3
    else:
        try:
            vec = tuple(float(v) for v in value)
        except (TypeError, ValueError):
            raise ValueError(
                f"{type(owner).__name__}.{name} must be a number or three numbers, got {value!r}"
            ) from None
        if len(vec) != 3:
            raise ValueError(
                f"{type(owner).__name__}.{name} needs three values, got {len(vec)}"
            )
    object.__setattr__(owner, name, vec)


def draw_misalignment(rng: np.random.Generator, sigma: float) -> np.ndarray:
    """Random-constant misalignment M of a sensor triad: six off-diagonal N(0, sigma^2) terms,
    zero diagonal, shape (3, 3) [rad] (draws a full 3x3 block)."""
    m = rng.standard_normal((3, 3)) * sigma
    np.fill_diagonal(m, 0.0)
    return m


def triad_matrix(scale_factor: np.ndarray, misalignment: np.ndarray) -> np.ndarray:
    """``I + S + M`` of a sensor triad: S = diag(scale_factor), M the misalignment; (3, 3)."""
    return np.eye(3) + np.diag(scale_factor) + misalignment


class RealisedErrors:
    """Mixin for the dataclasses of realised (drawn) sensor errors."""

    def as_dict(self) -> dict[str, Any]:
        """Field name -> value, with arrays as (nested) lists: JSON-serialisable."""
        return {f.name: jsonable(getattr(self, f.name)) for f in dataclasses.fields(self)}  # type: ignore[arg-type]
