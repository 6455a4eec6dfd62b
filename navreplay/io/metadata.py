"""The ``navreplay`` MCAP metadata record: :class:`~navreplay.core.streams.Metadata` as string
pairs.

Keys (all values are strings; JSON where noted):

=====================  ==========================================================================
``format_version``     version of the recording layout (``"1"``)
``scenario``           scenario name, ``""`` for a recording not simulated here
``seed``               integer seed, ``""`` when unknown
``params``             JSON object, scenario parameters (SI)
``sensors``            JSON object, the sensor specifications (SI; per kind its fields and
                       ``source``, :mod:`navreplay.sensors.specs`); absent when unknown
``true_errors``        JSON object, true values of the simulated error states (SI)
``initial_nav``        JSON object, the initial navigation solution handed to filters
``navreplay_version``  version of navreplay that simulated the recording
``extra``              JSON object, anything else
``t0_ns``              recording start [ns since the UNIX epoch]
``truth_columns``      JSON list of ``{"name": str, "shape": [int, ...]}``: the truth message's
                       ``aux`` layout
=====================  ==========================================================================
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay import __version__
from navreplay.core.streams import Metadata
from navreplay.io.convert import AuxColumn
from navreplay.io.errors import RecordingError
from navreplay.io.schemas import FORMAT_VERSION

_JSON_KEYS = ("params", "true_errors", "initial_nav", "extra", "sensors")


def _builtin(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"{type(obj).__name__} is not JSON-serialisable")


def _dumps(obj: Any) -> str:
    return json.dumps(obj, default=_builtin, separators=(",", ":"))


def encode_metadata(meta: Metadata, t0_ns: int, aux: list[AuxColumn]) -> dict[str, str]:
    """The metadata record's string pairs.

    numpy scalars and arrays inside the JSON fields are stored as numbers and lists.
    An empty ``navreplay_version`` is written as the running navreplay version.

    Raises
    ------
    ValueError
        If a JSON field holds something JSON cannot represent.
    """
    out = {
        "format_version": FORMAT_VERSION,
        "scenario": meta.scenario,
        "seed": "" if meta.seed is None else str(int(meta.seed)),
    }
    for key in _JSON_KEYS:
        try:
            out[key] = _dumps(getattr(meta, key))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"metadata field {key!r}: {exc}") from None
    out["navreplay_version"] = meta.navreplay_version or __version__
    out["t0_ns"] = str(int(t0_ns))
    out["truth_columns"] = _dumps([c.to_json() for c in aux])
    # Keep a fixed key order (the record is part of the byte-identical file).
    order = (
        "format_version",
        "scenario",
        "seed",
        *_JSON_KEYS[:3],
        "navreplay_version",
        "extra",
        "t0_ns",
        "truth_columns",
    ) + (("sensors",) if meta.sensors else ())
    return {k: out[k] for k in order}


def decode_metadata(
    pairs: Mapping[str, str], where: str
) -> tuple[Metadata, int | None, list[AuxColumn]]:
    """Metadata, start time and truth aux layout of a metadata record.

    Parameters
    ----------
    pairs : mapping of str to str
        The record's key/value pairs.
    where : str
        The file, for error messages.

    Returns
    -------
    tuple
        ``(metadata, t0_ns or None, aux columns)``.

    Raises
    ------
    RecordingError
        If a value does not parse.
    """

    def load(key: str, default: Any) -> Any:
        if key not in pairs or pairs[key] == "":
            return default
        try:
            return json.loads(pairs[key])
        except ValueError as exc:
            raise RecordingError(f"{where}: metadata {key!r} is not valid JSON ({exc})") from None

    def integer(key: str) -> int | None:
        text = pairs.get(key, "")
        if text == "":
            return None
        try:
            return int(text)
        except ValueError:
            raise RecordingError(
                f"{where}: metadata {key!r} = {text!r} is not an integer"
            ) from None

    meta = Metadata(
        scenario=pairs.get("scenario", ""),
        seed=integer("seed"),
        params=load("params", {}),
        true_errors=load("true_errors", {}),
        initial_nav=load("initial_nav", {}),
        navreplay_version=pairs.get("navreplay_version", ""),
        extra=load("extra", {}),
        sensors=load("sensors", {}),
    )
    if not isinstance(meta.sensors, dict):
        raise RecordingError(f"{where}: metadata 'sensors' is not a JSON object")
    try:
        aux = [AuxColumn.from_json(c) for c in load("truth_columns", [])]
    except (KeyError, TypeError, ValueError) as exc:
        raise RecordingError(f"{where}: metadata 'truth_columns' is malformed ({exc})") from None
    return meta, integer("t0_ns"), aux
