"""Helpers shared by the sensor models: field validation and JSON-friendly realised errors."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

Vec3 = tuple[float, float, float]
"""Three per-axis values (N, E, D or x, y, z)."""


def check_nonnegative(owner: object, *names: str) -> None:
    """Raise ``ValueError`` naming the first field that is not a finite number >= 0.

    Scalars and 3-tuples are both accepted.
    """
    for name in names:
        value = getattr(owner, name)
        values = value if isinstance(value, tuple) else (value,)
        for v in values:
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0.0):
                raise ValueError(
                    f"{type(owner).__name__}.{name} must be finite and >= 0, got {value!r}"
                )


def check_positive(owner: object, *names: str) -> None:
    """Raise ``ValueError`` naming the first field that is not a finite number > 0."""
    for name in names:
        v = getattr(owner, name)
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0.0):
            raise ValueError(f"{type(owner).__name__}.{name} must be finite and > 0, got {v!r}")


def as_vec3(owner: object, name: str) -> None:
    """Normalise field ``name`` of a frozen dataclass to a tuple of three floats.

    A scalar applies to all three axes; anything else must have exactly three elements.
    """
    value = getattr(owner, name)
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


def jsonable(value: Any) -> Any:
    """Convert arrays, numpy scalars and tuples (recursively) to plain lists and floats."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, tuple | list):
        return [jsonable(v) for v in value]
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    return value


class RealisedErrors:
    """Mixin for the dataclasses of realised (drawn) sensor errors."""

    def as_dict(self) -> dict[str, Any]:
        """Field name -> value, with arrays as (nested) lists: JSON-serialisable."""
        return {f.name: jsonable(getattr(self, f.name)) for f in dataclasses.fields(self)}  # type: ignore[arg-type]
