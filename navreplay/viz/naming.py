"""Entity paths, display units and plot grouping for the Rerun output (no rerun import here).

Values are SI inside navreplay; plots show them in the units a navigation engineer reads
(degrees, deg/h, mg). States and scored extras carry their SI unit and quantity in their
declarations (:class:`navreplay.filters.base.State`): :func:`tab_of` maps a quantity to its tab.
Measurements carry the rows and units of their innovations in theirs
(:class:`navreplay.filters.base.MeasurementKind`, :func:`innovation_rows`). Only for what is
not declared (other extras, the measurements of a filter that declares none, truth columns) the
unit comes from the caller (``units={"dk": "-"}``) or, failing that, from the naming conventions of
the project's filters (``dlat``, ``dv_N``, ``phi_D``, ``db_a_x``, ...); an unknown name is plotted
unscaled and titled ``[-]``.

Examples
--------
>>> guess_si_unit("db_g_x"), display_unit("rad/s").label
('rad/s', 'deg/h')
>>> quantity_of("dv_N"), group_of("db_a_z")
(<Tab.VELOCITY: 'velocity'>, 'db_a')
>>> entity_path("gps-ins[match=vel]", "state", "phi_N")
'/gps-ins\\\\[match\\\\=vel\\\\]/state/phi_N'
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import re
from collections.abc import Mapping

from navreplay.core.units import DEG, DEG_PER_HOUR, MILLI_G
from navreplay.filters.base import MeasurementKind
from navreplay.filters.base import Quantity as StateQuantity


class Tab(enum.StrEnum):
    """Which tab of the default blueprint a state or output belongs to."""

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
    "T": DisplayUnit("nT", 1e9),
    "-": DisplayUnit("-", 1.0),
}
"""Display unit for each SI unit string; other strings are shown as given, unscaled."""

UNKNOWN = DisplayUnit("-", 1.0)

# (pattern, SI unit, quantity), first match wins; names follow navreplay.filters.ins_error.
_RULES: tuple[tuple[re.Pattern[str], str, Tab], ...] = tuple(
    (re.compile(p), unit, q)
    for p, unit, q in (
        (r"^(roll|pitch|yaw|heading)$", "rad", Tab.ATTITUDE),
        (r"^d?(phi|psi|theta|att)_?[NEDxyz0-9]?$", "rad", Tab.ATTITUDE),
        (r"^d?q(_?[a-z]{2})?_?[0-3]$", "-", Tab.ATTITUDE),
        (r"^d?v_?[NED]$", "m/s", Tab.VELOCITY),
        (r"^d?(lat|lon|L|lambda)$", "rad", Tab.POSITION),
        (r"^d?(h|d|depth|alt)$", "m", Tab.POSITION),
        (r"^d?(p|r|pos)_?[NED]$", "m", Tab.POSITION),
        (r"^d?(b_?a|bias_a|acc_bias)(_?[xyz0-9])?$", "m/s^2", Tab.SENSOR),
        (r"^d?(b_?g|bias_g|gyro_bias)(_?[xyz0-9])?$", "rad/s", Tab.SENSOR),
        (r"^d?(s|sf|k)_?[ag](_?[xyz0-9])?$", "-", Tab.SENSOR),
        (r"^d?(mu|m|misalign\w*|gamma)_?[NEDxyz0-9]?$", "rad", Tab.SENSOR),
        (r"^d?m_?[ag]_?[xyz]{2}$", "rad", Tab.SENSOR),  # misalignment m_a_xy, m_g_zx
        (r"^d?(lever\w*|l)_?[xyz0-9]?$", "m", Tab.SENSOR),
        (r"^d?[vV]c_?[NED]$", "m/s", Tab.SENSOR),
        (r"^d?(T|tau|delay)$", "s", Tab.SENSOR),
        # measurement names (innovations): positions in m, velocities and speeds in m/s
        (r"^\w*(pos|position|range)\w*$", "m", Tab.SENSOR),
        (r"^\w*(vel|velocity|speed|rpm|dvl)\w*$", "m/s", Tab.SENSOR),
    )
)

NAV_NAMES: dict[Tab, tuple[str, ...]] = {
    Tab.ATTITUDE: ("roll", "pitch", "yaw"),
    Tab.VELOCITY: ("v_N", "v_E", "v_D"),
    Tab.POSITION: ("p_N", "p_E", "p_D"),
}
"""Navigation-solution quantities plotted under ``/<label>/nav``; positions are local NED
offsets [m] from the reference point of the 3D view."""

NAV_ERROR_NAMES: dict[Tab, tuple[str, ...]] = {
    Tab.ATTITUDE: ("phi_N", "phi_E", "phi_D"),
    Tab.VELOCITY: ("v_N", "v_E", "v_D"),
    Tab.POSITION: ("p_N", "p_E", "p_D"),
}
"""Navigation errors plotted under ``/<label>/error`` (:func:`navreplay.metrics.nav_errors`):
attitude as phi, the quantity and sign of the attitude-error states."""

NAV_UNITS: dict[str, str] = {
    **{n: "rad" for n in NAV_NAMES[Tab.ATTITUDE] + NAV_ERROR_NAMES[Tab.ATTITUDE]},
    **{n: "m/s" for n in NAV_NAMES[Tab.VELOCITY]},
    **{n: "m" for n in NAV_NAMES[Tab.POSITION]},
}

NAV_TITLES: dict[str, str] = {
    "roll": "roll",
    "pitch": "pitch",
    "yaw": "yaw (unwrapped)",
    "v_N": "velocity N",
    "v_E": "velocity E",
    "v_D": "velocity D",
    "p_N": "position N",
    "p_E": "position E",
    "p_D": "position D",
    "phi_N": "attitude phi_N",
    "phi_E": "attitude phi_E",
    "phi_D": "heading phi_D",
}
"""Plot titles of the navigation quantities (the unit is appended)."""

_COMPONENT = re.compile(r"(_[NEDxyz]|_[xyz]{2}|_?[0-9]+)$")


def guess_si_unit(name: str) -> str | None:
    """SI unit of a state or output named by the project's conventions, or None."""
    if name in NAV_UNITS:
        return NAV_UNITS[name]
    for pattern, unit, _ in _RULES:
        if pattern.match(name):
            return unit
    return None


def quantity_of(name: str) -> Tab:
    """Tab of a state or output: attitude, velocity, position, or sensor (anything else)."""
    for q, names in NAV_NAMES.items():
        if name in names or name in NAV_ERROR_NAMES[q]:
            return q
    for pattern, _, q in _RULES:
        if pattern.match(name):
            return q
    return Tab.SENSOR


_PART_OF_TAB = {Tab.POSITION: "pos", Tab.VELOCITY: "v_n", Tab.ATTITUDE: "q_nb"}


def nav_part(name: str) -> str | None:
    """The part of the navigation solution (``pos``, ``v_n``, ``q_nb``) a plotted navigation
    quantity or error (``roll``, ``v_N``, ``p_E``, ``phi_D``) belongs to; None for others."""
    if name not in NAV_UNITS and not any(name in v for v in NAV_ERROR_NAMES.values()):
        return None
    return _PART_OF_TAB.get(quantity_of(name))


_TAB_OF_QUANTITY = {
    StateQuantity.POSITION: Tab.POSITION,
    StateQuantity.VELOCITY: Tab.VELOCITY,
    StateQuantity.ATTITUDE: Tab.ATTITUDE,
}


def tab_of(quantity: StateQuantity) -> Tab:
    """Tab of a declared quantity: position, velocity, attitude; everything else (biases,
    scale factors, misalignments, lever arms, currents, clocks) goes to the sensor tab."""
    return _TAB_OF_QUANTITY.get(StateQuantity(quantity), Tab.SENSOR)


def group_of(name: str) -> str:
    """Name without its component suffix (``_x``, ``_N``, ``2``, a misalignment's ``_xy``), to
    plot components together."""
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


def innovation_rows(name: str, dim: int, declared: MeasurementKind | None = None,
                    units: Mapping[str, str] | None = None) -> list[tuple[str, DisplayUnit]]:
    """Row name and display unit of each of the ``dim`` rows of measurement ``name``'s
    innovation: from its declaration; for a filter that declares none (or a declaration of
    another size), rows ``N, E, D`` (three rows) or ``0, 1, ...`` and the unit of
    :func:`resolve_unit` (the caller's, else guessed from the name).

    >>> from navreplay.filters.base import MeasurementKind
    >>> innovation_rows("rpm", 3,
    ...                 MeasurementKind("rpm", ("forward", "lateral", "vertical"), "m/s"))[1]
    ('lateral', DisplayUnit(label='m/s', scale=1.0))
    >>> innovation_rows("gps_pos", 3)[2]
    ('D', DisplayUnit(label='m', scale=1.0))
    """
    if declared is not None and declared.dim == dim:
        return [(r, display_unit(u)) for r, u in zip(declared.rows, declared.units, strict=True)]
    u = resolve_unit(name, units)
    return [("NED"[i] if dim == 3 else str(i), u) for i in range(dim)]


def entity_path(*parts: str) -> str:
    """Entity path from unescaped parts: ``entity_path("a b", "state") == "/a\\\\ b/state"``."""
    return "/" + "/".join(_escape(p) for p in parts)


@functools.lru_cache(maxsize=4096)
def _escape(part: str) -> str:
    # the rule of rerun.escape_entity_path_part, kept here so this module stays rerun-free
    return "".join(c if (c.isalnum() or c in "_-.") else "\\" + c for c in part)


def title(name: str, unit: DisplayUnit, what: str = "") -> str:
    """Plot title with its unit: ``title("roll", deg, "error") == "roll error [deg]"``."""
    base = NAV_TITLES.get(name, name)
    return f"{base} {what} [{unit.label}]" if what else f"{base} [{unit.label}]"


_VARIANT = re.compile(r"([A-Za-z0-9_.-]+)\[([^\]]*)\]")


LEGEND_CHARS = 30
"""Longest legend entry; longer ones lose their middle."""


def legend_name(name: str) -> str:
    """A series' name as its legend shows it: a variant label ``filter[key=value,...]`` with
    each key cut to its last word and a long filter name (over 14 characters) to its initials,
    at most :data:`LEGEND_CHARS` characters (the plot titles keep the whole label).

    >>> legend_name("gps-ins[gps_pos_sigma_scale=2] b_g_x")
    'gps-ins[scale=2] b_g_x'
    >>> legend_name("transfer-alignment[match=vel_only]")
    'ta[match=vel_only]'
    """
    def short(m: re.Match[str]) -> str:
        base = m.group(1)
        if len(base) > 14:
            base = "".join(w[0] for w in re.split(r"[-_]", base) if w)
        params = ",".join(
            f"{k.rsplit('_', 1)[-1]}={v}" if v else k
            for k, _, v in (p.partition("=") for p in m.group(2).split(","))
        )
        return f"{base}[{params}]"

    out = _VARIANT.sub(short, name)
    if len(out) > LEGEND_CHARS:
        half = (LEGEND_CHARS - 1) // 2
        out = out[:half] + "…" + out[-(LEGEND_CHARS - 1 - half):]
    return out
