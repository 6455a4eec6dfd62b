"""The initial state a run started from, as the summary JSON's ``initial`` entry and as one line
of text (the run's text summary and the report's context row ``initial state``).

``metadata.initial_nav`` (:func:`navreplay.filters.ins.initial_solution` reads it) becomes, in
datasheet-friendly units, the parts it has:

========================  =====  =========================================================
key                       unit   meaning
========================  =====  =========================================================
``source``                -      where it came from: ``recording`` (the file's own),
                                 ``reference``, ``align (HOW)``, ``[initial]``; a method
                                 with ``[initial]`` values over it adds ``+ [initial] KEYS``
``t``                     s      time, from the recording's start (``--start`` included)
``t_ns``                  ns     time, UNIX
``lat_deg, lon_deg, h``   deg, m geodetic position, ellipsoidal height
``v_n``                   m/s    NED velocity
``roll_deg`` ...          deg    attitude FRD -> NED (ZYX Euler: roll, pitch, yaw)
``sigma``                 -      1-sigma: ``pos_ned`` [m], ``v_n`` [m/s], ``att_deg`` [deg]
========================  =====  =========================================================

Examples
--------
>>> import math
>>> nav = {"t_ns": 2_000_000_000, "pos": [math.radians(45.0), math.radians(7.0), 300.0],
...        "v_n": [0.0, 0.0, 0.0], "q_nb": [1.0, 0.0, 0.0, 0.0], "method": "[initial]",
...        "sigma": {"pos_ned": [2.0, 2.0, 5.0], "v_n": [0.1] * 3, "phi": [0.01] * 3}}
>>> state = initial_state(nav, 0)
>>> state["t"], round(state["lat_deg"], 9), state["sigma"]["att_deg"][0]
(2.0, 45.0, 0.572958)
>>> format_initial_state(state).split("; ")  # doctest: +NORMALIZE_WHITESPACE
['from [initial] at t = 2.000 s: 45.0000000 deg N, 7.0000000 deg E, 300.00 m',
 'v_NED 0.00, 0.00, 0.00 m/s', 'roll 0.00, pitch 0.00, yaw 0.00 deg',
 '1-sigma 2, 2, 5 m, 0.1, 0.1, 0.1 m/s, 0.573, 0.573, 0.573 deg']
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay.geo.rotations import quat_to_euler

RECORDING = "recording"
"""The ``source`` of an initial solution the recording holds (its metadata)."""


def initial_state(nav: Mapping[str, Any], t0_ns: int) -> dict[str, Any] | None:
    """The documented ``initial`` entry (module docstring) of ``metadata.initial_nav``; None
    for a run without one (filters that start themselves)."""
    if not nav or "t_ns" not in nav:
        return None
    out: dict[str, Any] = {"source": str(nav.get("method", RECORDING)),
                           "t": round((int(nav["t_ns"]) - int(t0_ns)) * 1e-9, 9),
                           "t_ns": int(nav["t_ns"])}
    if nav.get("pos") is not None:
        lat, lon, h = (float(x) for x in nav["pos"])
        out.update(lat_deg=math.degrees(lat), lon_deg=math.degrees(lon), h=h)
    if nav.get("v_n") is not None:
        out["v_n"] = [float(x) for x in nav["v_n"]]
    if nav.get("q_nb") is not None:
        euler = np.degrees(quat_to_euler(np.asarray(nav["q_nb"], dtype=float)))
        out.update(roll_deg=float(euler[0]), pitch_deg=float(euler[1]), yaw_deg=float(euler[2]))
    sigma = nav.get("sigma") or {}
    shown = {}
    for key, name, scale in (("pos_ned", "pos_ned", 1.0), ("v_n", "v_n", 1.0),
                             ("phi", "att_deg", 180.0 / math.pi)):
        if key in sigma:
            shown[name] = [round(float(x) * scale, 6) for x in np.ravel(sigma[key])]
    if shown:
        out["sigma"] = shown
    return out


def _f(x: float, digits: int = 2) -> str:
    """``x`` with ``digits`` decimals, never ``-0.00``."""
    return f"{round(float(x), digits) + 0.0:.{digits}f}"


def format_initial_state(state: Mapping[str, Any] | None) -> str:
    """An :func:`initial_state` in one line ("" for None): where from, when, the values."""
    if not state:
        return ""
    parts = []
    if "lat_deg" in state:
        parts.append(f"{state['lat_deg']:.7f} deg N, {state['lon_deg']:.7f} deg E, "
                     f"{state['h']:.2f} m")
    if "v_n" in state:
        parts.append("v_NED " + ", ".join(_f(v) for v in state["v_n"]) + " m/s")
    if "yaw_deg" in state:
        parts.append(f"roll {_f(state['roll_deg'])}, pitch {_f(state['pitch_deg'])}, "
                     f"yaw {_f(state['yaw_deg'])} deg")
    sigma = state.get("sigma", {})
    units = {"pos_ned": "m", "v_n": "m/s", "att_deg": "deg"}
    if sigma:
        parts.append("1-sigma " + ", ".join(
            ", ".join(f"{v:.3g}" for v in values) + f" {units[k]}" for k, values in sigma.items()))
    return f"from {state['source']} at t = {state['t']:.3f} s: " + "; ".join(parts)
