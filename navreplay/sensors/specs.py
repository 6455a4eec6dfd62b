"""Sensor specifications as data: the error models of this package as records, in SI inside and
datasheet units at the edges.

A recording's sensors are described by one record per sensor kind, the error-model dataclass
the simulator draws from (:data:`SPEC_KINDS`):

=============  ==========================================  =====================================
kind           record                                      what it states (1 sigma)
=============  ==========================================  =====================================
``imu``        :class:`~navreplay.sensors.imu.ImuModel`    white noise (ARW, VRW), bias
                                                           instability + correlation time, rate
                                                           and acceleration random walk,
                                                           turn-on bias, scale factor,
                                                           misalignment, g-sensitivity
``gps``        :class:`~navreplay.sensors.gps.GpsModel`    white and Gauss-Markov position and
                                                           velocity errors, rate
``mag``        :class:`~navreplay.sensors.magnetometer.    scale factor, misalignment, hard-iron
               MagnetometerModel`                          bias, noise, rate
``speed_log``  :class:`~navreplay.sensors.speed_log.       scale factor, misalignment, noise,
               SpeedLogModel`                              propeller law, rate
``depth``      :class:`~navreplay.sensors.depth.           bias, noise, rate
               DepthModel`
``master_ins`` :class:`~navreplay.sensors.master_ins.      platform tilt, synchro errors,
               MasterInsModel`                             velocity errors, rate
=============  ==========================================  =====================================

:class:`SensorSpecs` holds the records of one recording and, per kind, which fields are known
(a datasheet or an Allan fit may give only some) and where the record came from. It travels
in the recording's metadata (``Metadata.sensors``, SI, :meth:`SensorSpecs.to_metadata` /
:meth:`SensorSpecs.from_metadata`) and is read from ``[sensors.KIND]`` TOML tables in
datasheet units (:func:`specs_from_tables`), which :func:`specs_toml` writes back.

TOML tables
-----------
The key is the field name and the value a number in SI or a string ``"NUMBER UNIT"``
(:func:`navreplay.core.units.parse_quantity`); the unit may instead end the key
(``gyro_arw_deg_per_sqrt_h = 0.15``, :func:`navreplay.core.units.key_unit`). Per-axis fields
(GNSS sigmas N, E, D) take one value or an array of three. In ``[sensors.imu]`` the key
``grade`` starts from a built-in grade (:class:`~navreplay.sensors.imu.ImuGrade`) that the other
keys override::

    [sensors.imu]
    grade = "mems"
    gyro_arw = "0.15 deg/sqrt(h)"
    accel_vrw = "60 ug/sqrt(Hz)"
    gyro_bias_instability = "3 deg/h"
    gyro_bias_tau = "600 s"

Every value is converted once, here, and checked against the field's dimension; a mistake is
one line naming the table, the key and what was expected.

Examples
--------
>>> from navreplay.core.units import DEG_PER_SQRT_HOUR
>>> specs = specs_from_tables({"imu": {"grade": "tactical", "gyro_arw": "0.15 deg/sqrt(h)"}})
>>> round(specs.imu.gyro_arw / DEG_PER_SQRT_HOUR, 6), specs.source("imu")
(0.15, '[sensors.imu]: grade tactical, with gyro_arw')
>>> back = SensorSpecs.from_metadata(specs.to_metadata())
>>> back.imu == specs.imu
True
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import typing
from collections.abc import Iterable, Mapping
from typing import Any, TypeVar

from navreplay.core import units
from navreplay.core.params import ParamError, describe
from navreplay.core.streams import StreamKind
from navreplay.core.units import UnitError
from navreplay.sensors._common import FieldUnit
from navreplay.sensors.depth import DepthModel
from navreplay.sensors.gps import GpsModel
from navreplay.sensors.imu import ImuGrade, ImuModel, imu_grade
from navreplay.sensors.magnetometer import MagnetometerModel
from navreplay.sensors.master_ins import MasterInsModel
from navreplay.sensors.speed_log import SpeedLogModel

SPEC_KINDS: dict[str, type] = {
    "imu": ImuModel,
    "gps": GpsModel,
    "mag": MagnetometerModel,
    "speed_log": SpeedLogModel,
    "depth": DepthModel,
    "master_ins": MasterInsModel,
}
"""Sensor kinds (the ``[sensors.KIND]`` tables, the keys of ``Metadata.sensors``) and their
records."""

M = TypeVar("M")

SPEC_STREAMS: dict[str, tuple[StreamKind, ...]] = {
    "imu": (StreamKind.IMU,),
    "gps": (StreamKind.GPS, StreamKind.GPS_VEL),
    "mag": (StreamKind.MAG,),
    "speed_log": (StreamKind.SPEED_LOG,),
    "depth": (StreamKind.DEPTH,),
    "master_ins": (StreamKind.MASTER_INS,),
}
"""The streams each sensor kind's record describes."""

SOURCE_KEY = "source"
"""The key of a kind's entry in ``Metadata.sensors`` that says where the record came from."""

GRADE_KEY = "grade"
"""The key of ``[sensors.imu]`` that starts from a built-in grade."""


def spec_fields(cls: type) -> tuple[str, ...]:
    """The specification fields of a record, in declaration order."""
    return tuple(f.name for f in dataclasses.fields(cls))


def _is_vector(cls: type, name: str) -> bool:
    """Whether field ``name`` holds three per-axis values."""
    return "tuple" in str(typing.get_type_hints(cls)[name])


@dataclasses.dataclass(frozen=True)
class SensorSpecs:
    """The sensor specifications of one recording.

    Attributes
    ----------
    models : mapping str -> record
        One record per kind present (:data:`SPEC_KINDS`).
    known : mapping str -> frozenset of str
        Per kind, the fields that are stated; the others hold the record's default and are
        not to be used (a datasheet table without ``grade`` that gives only the noise). A kind
        absent here has every field known.
    sources : mapping str -> str
        Per kind, where the record came from (``"grade mems"``, ``"scenario vehicle-drive"``,
        ``"[sensors.imu] of drive.toml"``).
    """

    models: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    known: Mapping[str, frozenset[str]] = dataclasses.field(default_factory=dict)
    sources: Mapping[str, str] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        for kind, model in self.models.items():
            cls = SPEC_KINDS.get(kind)
            if cls is None:
                raise ValueError(f"unknown sensor kind {kind!r} (kinds: {', '.join(SPEC_KINDS)})")
            if not isinstance(model, cls):
                raise TypeError(f"sensor {kind}: expected {cls.__name__}, got {model!r}")
        object.__setattr__(self, "models", dict(self.models))
        object.__setattr__(self, "known", {k: frozenset(v) for k, v in self.known.items()})
        object.__setattr__(self, "sources", dict(self.sources))

    # -- access ----------------------------------------------------------------------------

    def __bool__(self) -> bool:
        return bool(self.models)

    def __contains__(self, kind: object) -> bool:
        return kind in self.models

    def get(self, kind: str) -> Any:
        """The record of ``kind``, or None."""
        return self.models.get(kind)

    def require(self, model: type[M]) -> M:
        """The record of the kind whose class is ``model`` (``specs.require(GpsModel)``), for
        code that cannot run without it; a ValueError naming the kind when there is none."""
        kind = next(k for k, cls in SPEC_KINDS.items() if cls is model)
        found = self.models.get(kind)
        if found is None:
            raise ValueError(
                f"no {kind} specification (sensors: {', '.join(self.models) or 'none'})"
            )
        return found  # checked against SPEC_KINDS on creation

    @property
    def imu(self) -> ImuModel | None:
        return self.models.get("imu")

    @property
    def gps(self) -> GpsModel | None:
        return self.models.get("gps")

    @property
    def mag(self) -> MagnetometerModel | None:
        return self.models.get("mag")

    @property
    def speed_log(self) -> SpeedLogModel | None:
        return self.models.get("speed_log")

    @property
    def depth(self) -> DepthModel | None:
        return self.models.get("depth")

    @property
    def master_ins(self) -> MasterInsModel | None:
        return self.models.get("master_ins")

    def known_fields(self, kind: str) -> frozenset[str]:
        """The stated fields of ``kind`` (empty when the kind is absent)."""
        if kind not in self.models:
            return frozenset()
        return self.known.get(kind, frozenset(spec_fields(SPEC_KINDS[kind])))

    def has(self, kind: str, *fields: str) -> bool:
        """Whether ``kind`` is present with every one of ``fields`` stated."""
        return kind in self.models and set(fields) <= self.known_fields(kind)

    def source(self, kind: str) -> str:
        """Where the record of ``kind`` came from (``""`` when absent or not said)."""
        return self.sources.get(kind, "")

    # -- combining -------------------------------------------------------------------------

    def present_terms(self, kind: str) -> dict[str, str]:
        """The error terms (:attr:`~navreplay.sensors.imu.ImuModel.error_terms`) of ``kind``
        that are stated and not zero (on some axis), each with what it is; empty when the kind
        is absent."""
        model = self.models.get(kind)
        if model is None:
            return {}
        terms = getattr(type(model), "error_terms", {})
        known = self.known_fields(kind)
        out = {}
        for name, what in terms.items():
            value = getattr(model, name)
            values = value if isinstance(value, tuple) else (value,)
            if name in known and any(v != 0.0 for v in values):
                out[name] = what
        return out

    def with_model(self, kind: str, model: Any, source: str,
                   known: Iterable[str] | None = None) -> SensorSpecs:
        """A copy with the record of ``kind`` replaced (``known``: its stated fields, all by
        default)."""
        known_map = {k: v for k, v in self.known.items() if k != kind}
        if known is not None and set(known) != set(spec_fields(SPEC_KINDS[kind])):
            known_map[kind] = frozenset(known)
        return SensorSpecs({**self.models, kind: model}, known_map,
                           {**self.sources, kind: source})

    def overridden_by(self, other: SensorSpecs) -> SensorSpecs:
        """These specs with the stated fields of ``other`` written over them, kind by kind
        (a kind only in ``other`` is taken as it is)."""
        out = self
        for kind, model in other.models.items():
            if kind not in out.models:
                out = out.with_model(kind, model, other.source(kind), other.known_fields(kind))
                continue
            if other.known_fields(kind) == frozenset(spec_fields(SPEC_KINDS[kind])):
                out = out.with_model(kind, model, other.source(kind))
                continue
            given = other.known_fields(kind)
            merged = dataclasses.replace(out.models[kind],
                                         **{f: getattr(model, f) for f in given})
            source = f"{out.source(kind)}, with {other.source(kind)}".strip(", ")
            out = out.with_model(kind, merged, source, out.known_fields(kind) | given)
        return out

    # -- metadata (SI) ---------------------------------------------------------------------

    def to_metadata(self) -> dict[str, Any]:
        """``Metadata.sensors``: per kind its stated fields in SI (vectors as lists) and
        ``source``."""
        out: dict[str, Any] = {}
        for kind, model in self.models.items():
            entry: dict[str, Any] = {}
            if self.source(kind):
                entry[SOURCE_KEY] = self.source(kind)
            for name in spec_fields(type(model)):
                if name in self.known_fields(kind):
                    value = getattr(model, name)
                    entry[name] = list(value) if isinstance(value, tuple) else value
            out[kind] = entry
        return out

    @classmethod
    def from_metadata(cls, data: Mapping[str, Any] | None, where: str = "") -> SensorSpecs:
        """The specs of ``Metadata.sensors`` (the inverse of :meth:`to_metadata`).

        Raises
        ------
        ValueError
            One line naming ``where``, the kind and the field when an entry is malformed.
        """
        prefix = f"{where}: " if where else ""
        models: dict[str, Any] = {}
        known: dict[str, frozenset[str]] = {}
        sources: dict[str, str] = {}
        for kind, entry in (data or {}).items():
            rec = SPEC_KINDS.get(kind)
            if rec is None:
                raise ValueError(f"{prefix}metadata sensors: unknown kind {kind!r} (kinds: "
                                 f"{', '.join(SPEC_KINDS)})")
            if not isinstance(entry, Mapping):
                raise ValueError(f"{prefix}metadata sensors.{kind} is not an object")
            values = {k: v for k, v in entry.items() if k != SOURCE_KEY}
            names = set(spec_fields(rec))
            unknown = sorted(set(values) - names)
            if unknown:
                raise ValueError(f"{prefix}metadata sensors.{kind}: unknown field(s) "
                                 f"{', '.join(unknown)}")
            try:
                models[kind] = rec(**{k: tuple(v) if isinstance(v, list) else v
                                      for k, v in values.items()})
            except (TypeError, ValueError) as e:
                raise ValueError(f"{prefix}metadata sensors.{kind}: {e}") from None
            if set(values) != names:
                known[kind] = frozenset(values)
            sources[kind] = str(entry.get(SOURCE_KEY, ""))
        return cls(models, known, sources)


# -- datasheet tables ---------------------------------------------------------------------


def _suggest(key: str, names: Iterable[str]) -> str:
    close = difflib.get_close_matches(key, list(names), n=1)
    return f"; did you mean {close[0]}?" if close else ""


def _split_key(cls: type, key: str) -> tuple[str, str | None]:
    """(field, unit in the key or None): ``gyro_arw_deg_per_sqrt_h`` -> (gyro_arw,
    deg/sqrt(h)); the longest field name the key starts with."""
    names = spec_fields(cls)
    if key in names:
        return key, None
    prefixes = [n for n in names if key.startswith(n + "_")]
    if not prefixes:
        raise KeyError(key)
    name = max(prefixes, key=len)
    return name, units.key_unit(key[len(name) + 1:])


def _value(cls: Any, name: str, raw: Any, key_unit: str | None) -> Any:
    """The value of field ``name`` in its own unit from a TOML value."""
    si = cls.field_units[name].si

    def one(v: Any) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float | str):
            raise UnitError(f"{v!r} is not a number or a \"NUMBER UNIT\" string")
        if key_unit is not None:
            if isinstance(v, str):
                raise UnitError(f"the key gives the unit ({key_unit}); the value must be a "
                                f"number, got {v!r}")
            return units.convert(float(v), key_unit, si)
        return units.parse_quantity(v, si)

    if _is_vector(cls, name) and isinstance(raw, list):
        if len(raw) != 3:
            raise UnitError(f"expected one value or three (N, E, D), got {len(raw)}")
        return tuple(one(v) for v in raw)
    if isinstance(raw, list):
        raise UnitError(f"expected one value, got a list of {len(raw)}")
    return one(raw)


def spec_from_table(
    kind: str, table: Mapping[str, Any], where: str = "", base: Any = None,
) -> tuple[Any, frozenset[str], str]:
    """The record of one ``[sensors.KIND]`` table.

    Parameters
    ----------
    kind : str
        A key of :data:`SPEC_KINDS`.
    table : mapping
        The table's keys and TOML values (see the module docstring).
    where : str
        The file, for error messages.
    base : record, optional
        What the table's keys are written over (the scenario's sensor when simulating); a
        ``grade`` key replaces it.

    Returns
    -------
    record, frozenset of str, str
        The record, the fields the table states (all of them with a grade) and a source text.

    Raises
    ------
    navreplay.core.params.ParamError
        One line naming the file, the table and the key: an unknown key, an unreadable value,
        a unit of the wrong dimension (with the expected one) or a value out of range.
    """
    cls = SPEC_KINDS.get(kind)
    head = f"{where}: [sensors.{kind}]" if where else f"[sensors.{kind}]"
    if cls is None:
        raise ParamError(f"{head}: no such sensor kind (kinds: {', '.join(SPEC_KINDS)})")
    if not isinstance(table, Mapping):
        raise ParamError(f"{head} must be a table")
    values: dict[str, Any] = {}
    source = ""
    for key, raw in table.items():
        if key == GRADE_KEY and cls is ImuModel:
            try:
                base = imu_grade(str(raw))
            except ValueError:
                raise ParamError(f"{head} grade = {raw!r}: no such grade (grades: "
                                 f"{', '.join(g.value for g in ImuGrade)})") from None
            source = f"grade {ImuGrade(str(raw)).value}"
            continue
        try:
            name, key_unit = _split_key(cls, key)
        except KeyError:
            extra = " or grade" if cls is ImuModel else ""
            raise ParamError(f"{head} {key}: no such key{_suggest(key, spec_fields(cls))} "
                             f"(keys: {', '.join(spec_fields(cls))}{extra})") from None
        except UnitError as e:
            raise ParamError(f"{head} {key}: {e}") from None
        if name in values:
            raise ParamError(f"{head} {key}: {name} is given twice")
        try:
            values[name] = _value(cls, name, raw, key_unit)
        except UnitError as e:
            raise ParamError(f"{head} {key}: {e} ({_expected(cls, name)})") from None
    start = base if base is not None else cls()
    try:
        model = dataclasses.replace(start, **values)
    except (TypeError, ValueError) as e:
        raise ParamError(f"{head}: {e}") from None
    known = frozenset(spec_fields(cls)) if source else frozenset(values)
    given = "" if set(values) == set(spec_fields(cls)) else ", ".join(values)
    if source and given:
        source = f"{source}, with {given}"
    elif not source:
        source = given
    return model, known, source


def _expected(cls: Any, name: str) -> str:
    """How field ``name`` is written, e.g. ``rad/s^(1/2), such as "0.1 deg/sqrt(h)"``."""
    unit = cls.field_units[name]
    dims = units.dimension_phrase(units.parse_unit(unit.si).dims)
    return f"{name} is {dims}, e.g. \"1 {unit.datasheet}\""


def specs_from_tables(
    tables: Mapping[str, Mapping[str, Any]] | None, where: str = "",
    base: SensorSpecs | None = None,
) -> SensorSpecs:
    """The specs of a config's ``[sensors.*]`` tables, each written over the same kind of
    ``base`` (the scenario's sensors when simulating; none for a log from elsewhere).

    ``where`` names the file in error messages and in the records' sources.
    """
    base = base or SensorSpecs()
    out = base
    for kind, table in (tables or {}).items():
        model, known, source = spec_from_table(kind, table, where, base.get(kind))
        label = f"[sensors.{kind}]" + (f" of {where}" if where else "")
        detail = f"{label}: {source}" if source else label
        if kind in base and not (kind == "imu" and GRADE_KEY in table):
            detail = f"{base.source(kind)}, with {detail}" if base.source(kind) else detail
            known = known | base.known_fields(kind)
        out = out.with_model(kind, model, detail, known)
    return out


def spec_table(model: Any, known: Iterable[str] | None = None) -> dict[str, Any]:
    """A record as a ``[sensors.KIND]`` table in datasheet units: field -> ``"NUMBER UNIT"``
    (a list of three for per-axis fields whose axes differ); only ``known`` fields when
    given."""
    cls = type(model)
    names = spec_fields(cls) if known is None else [n for n in spec_fields(cls) if n in known]
    out: dict[str, Any] = {}
    for name in names:
        unit = cls.field_units[name]
        value = getattr(model, name)

        def text(v: float, unit: FieldUnit = unit) -> str:
            if not unit.datasheet:
                return f"{v:.6g}"
            return units.format_quantity(v, unit.si, unit.datasheet)

        if isinstance(value, tuple):
            out[name] = text(value[0]) if len(set(value)) == 1 else [text(v) for v in value]
        else:
            out[name] = text(value)
    return out


def _toml_value(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{value!r} cannot be written to TOML")
    return repr(value)


def specs_toml(specs: SensorSpecs, comments: bool = True) -> str:
    """``[sensors.KIND]`` tables of ``specs`` in datasheet units, as TOML text that
    :func:`specs_from_tables` reads back to the same records (to the 6 digits written).

    With ``comments``, each key is followed by its field's description and each table starts
    with the record's source.
    """
    lines: list[str] = []
    for kind, model in specs.models.items():
        if lines:
            lines.append("")
        if comments and specs.source(kind):
            lines.append(f"# {specs.source(kind)}")
        lines.append(f"[sensors.{kind}]")
        docs = {name: doc for name, _, _, doc in describe(type(model))} if comments else {}
        table = spec_table(model, specs.known_fields(kind))
        width = max((len(k) for k in table), default=0)
        for key, value in table.items():
            line = f"{key:<{width}} = {_toml_value(value)}"
            if docs.get(key):
                line += f"  # {docs[key]}"
            lines.append(line)
    return "\n".join(lines) + ("\n" if lines else "")


def describe_specs(specs: SensorSpecs) -> list[str]:
    """Lines for ``navreplay info``: per kind its source, then its stated fields in datasheet
    units."""
    lines = []
    for kind, model in specs.models.items():
        source = specs.source(kind)
        lines.append(f"  {kind}" + (f" ({source})" if source else "") + ":")
        table = spec_table(model, specs.known_fields(kind))
        width = max((len(k) for k in table), default=0)
        for key, value in table.items():
            shown = ", ".join(value) if isinstance(value, list) else value
            lines.append(f"    {key:<{width}}  {shown}")
    return lines
