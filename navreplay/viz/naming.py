"""Entity paths, display units and plot grouping for the Rerun output (no rerun import here).

Values are SI inside navreplay; plots show them in the units a navigation engineer reads
(degrees, deg/h, mg). A name's SI unit comes from the caller (``units={"db_g_x": "rad/s"}``)
or, failing that, from the naming conventions of the project's filters
(:mod:`navreplay.filters.ins_error`: ``dlat``, ``dv_N``, ``phi_D``, ``db_a_x``, ``db_g_z``, ...);
an unknown name is plotted unscaled and titled ``[SI]``.

Examples
--------
>>> guess_si_unit("db_g_x"), display_unit("rad/s").label
('rad/s', 'deg/h')
>>> quantity_of("dv_N"), group_of("db_a_z")
(<Quantity.VELOCITY: 'velocity'>, 'db_a')
>>> entity_path("gps-ins[match=vel]", "state", "phi_N")
'/gps-ins\\\\[match\\\\=vel\\\\]/state/phi_N'
"""

from __future__ import annotations

import dataclasses
import enum
import re
from collections.abc import Mapping

from navreplay.units import DEG, DEG_PER_HOUR, MILLI_G


class Quantity(enum.StrEnum):
    """Which tab of the default blueprint a named quantity belongs to."""

    ATTITUDE = "attitude"
    VELOCITY = "velocity"
    POSITION = "position"
    SENSOR = "sensor"
    """Sensor and other error states (biases, scale factors, misalignments, current, ...)."""


@dataclasses.dataclass(frozen=True)
class DisplayUnit:
    """Unit shown in a plot: ``shown = si_value * scale``."""

    label: str
    scale: float


SI_TO_DISPLAY: dict[str, DisplayUnit] = {
    "rad": DisplayUnit("deg", 1.0 / DEG),
    "rad/s": DisplayUnit("deg/h", 1.0 / DEG_PER_HOUR),
    "m/s^2": DisplayUnit("mg", 1.0 / MILLI_G),
    "m": DisplayUnit("m", 1.0),
    "m/s": DisplayUnit("m/s", 1.0),
    "s": DisplayUnit("s", 1.0),
    "-": DisplayUnit("-", 1.0),
}
"""Display unit for each SI unit string; other strings are shown as given, unscaled."""

UNKNOWN = DisplayUnit("SI", 1.0)

# (pattern, SI unit, quantity), first match wins; names follow navreplay.filters.ins_error.
_RULES: tuple[tuple[re.Pattern[str], str, Quantity], ...] = tuple(
    (re.compile(p), unit, q)
    for p, unit, q in (
        (r"^(roll|pitch|yaw|heading)$", "rad", Quantity.ATTITUDE),
        (r"^d?(phi|psi|theta|att)_?[NEDxyz0-9]?$", "rad", Quantity.ATTITUDE),
        (r"^d?q(_?[a-z]{2})?_?[0-3]$", "-", Quantity.ATTITUDE),
        (r"^d?v_?[NED]$", "m/s", Quantity.VELOCITY),
        (r"^d?(lat|lon|L|lambda)$", "rad", Quantity.POSITION),
        (r"^d?(h|d|depth|alt)$", "m", Quantity.POSITION),
        (r"^d?(p|r|pos)_?[NED]$", "m", Quantity.POSITION),
        (r"^d?(b_?a|bias_a|acc_bias)(_?[xyz0-9])?$", "m/s^2", Quantity.SENSOR),
        (r"^d?(b_?g|bias_g|gyro_bias)(_?[xyz0-9])?$", "rad/s", Quantity.SENSOR),
        (r"^d?(s|sf|k)_?[ag](_?[xyz0-9])?$", "-", Quantity.SENSOR),
        (r"^d?(mu|m|misalign\w*|gamma)_?[NEDxyz0-9]?$", "rad", Quantity.SENSOR),
        (r"^d?(lever\w*|l)_?[xyz0-9]?$", "m", Quantity.SENSOR),
        (r"^d?[vV]c_?[NED]$", "m/s", Quantity.SENSOR),
        (r"^d?(T|tau|delay)$", "s", Quantity.SENSOR),
    )
)

NAV_NAMES: dict[Quantity, tuple[str, ...]] = {
    Quantity.ATTITUDE: ("roll", "pitch", "yaw"),
    Quantity.VELOCITY: ("v_N", "v_E", "v_D"),
    Quantity.POSITION: ("p_N", "p_E", "p_D"),
}
"""Navigation-solution quantities plotted under ``/<label>/nav`` and ``/<label>/error``;
positions are local NED offsets [m] from the reference point of the 3D view."""

NAV_UNITS: dict[str, str] = {
    **{n: "rad" for n in NAV_NAMES[Quantity.ATTITUDE]},
    **{n: "m/s" for n in NAV_NAMES[Quantity.VELOCITY]},
    **{n: "m" for n in NAV_NAMES[Quantity.POSITION]},
}

NAV_TITLES: dict[str, str] = {
    "roll": "roll",
    "pitch": "pitch",
    "yaw": "yaw",
    "v_N": "velocity N",
    "v_E": "velocity E",
    "v_D": "velocity D",
    "p_N": "position N",
    "p_E": "position E",
    "p_D": "position D",
}
"""Plot titles of the navigation quantities (the unit is appended)."""

_COMPONENT = re.compile(r"(_[NEDxyz]|_?[0-9]+)$")


def guess_si_unit(name: str) -> str | None:
    """SI unit of a state or output named by the project's conventions, or None."""
    if name in NAV_UNITS:
        return NAV_UNITS[name]
    for pattern, unit, _ in _RULES:
        if pattern.match(name):
            return unit
    return None


def quantity_of(name: str) -> Quantity:
    """Tab of a state or output: attitude, velocity, position, or sensor (anything else)."""
    for q, names in NAV_NAMES.items():
        if name in names:
            return q
    for pattern, _, q in _RULES:
        if pattern.match(name):
            return q
    return Quantity.SENSOR


def group_of(name: str) -> str:
    """Name without its component suffix (``_x``, ``_N``, ``2``), to plot components together."""
    stem = _COMPONENT.sub("", name)
    return stem or name


def display_unit(si_unit: str | None) -> DisplayUnit:
    """Plot unit for an SI unit string (:data:`SI_TO_DISPLAY`); unknown -> shown as is."""
    if si_unit is None or si_unit == "":
        return UNKNOWN
    return SI_TO_DISPLAY.get(si_unit, DisplayUnit(si_unit, 1.0))


def resolve_unit(name: str, units: Mapping[str, str] | None = None) -> DisplayUnit:
    """Display unit of ``name``: the caller's SI unit if given, else the naming guess."""
    if units is not None and name in units:
        return display_unit(units[name])
    return display_unit(guess_si_unit(name))


def entity_path(*parts: str) -> str:
    """Entity path from unescaped parts: ``entity_path("a b", "state") == "/a\\\\ b/state"``."""
    return "/" + "/".join(_escape(p) for p in parts)


def _escape(part: str) -> str:
    # the rule of rerun.escape_entity_path_part, kept here so this module stays rerun-free
    return "".join(c if (c.isalnum() or c in "_-.") else "\\" + c for c in part)


def title(name: str, unit: DisplayUnit, what: str = "") -> str:
    """Plot title with its unit: ``title("roll", deg, "error") == "roll error [deg]"``."""
    base = NAV_TITLES.get(name, name)
    return f"{base} {what} [{unit.label}]" if what else f"{base} [{unit.label}]"
