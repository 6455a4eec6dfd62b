"""Command-line configuration of the jobs: the filter-list grammar (``a,b[k=v,...]``,
``module:Class``, ``-p`` and TOML tables, with their precedence) and scenario parameter values."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from typing import Any

from navreplay.core import params as _params
from navreplay.filters.base import Filter
from navreplay.filters.registry import load_filter
from navreplay.filters.settings import ParamValues, Source
from navreplay.replay.spec import FilterSpec


def split_filter_list(text: str) -> list[str]:
    """Split ``a,b[k=v,k2=1,2],c`` on the commas outside brackets.

    >>> split_filter_list("ins,gps-ins[gps_pos_sigma_scale=2,lever_arm_b=0.1,0,0]")
    ['ins', 'gps-ins[gps_pos_sigma_scale=2,lever_arm_b=0.1,0,0]']
    """
    items: list[str] = []
    cur: list[str] = []
    depth = 0
    for ch in text:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
            if depth < 0:
                raise _params.ParamError(f"filter list {text!r}: unbalanced ']'")
        if ch == "," and depth == 0:
            items.append("".join(cur).strip())
            cur = []
        else:
            cur.append(ch)
    if depth:
        raise _params.ParamError(f"filter list {text!r}: unbalanced '['")
    items.append("".join(cur).strip())
    if any(not it for it in items):
        raise _params.ParamError(f"filter list {text!r} has an empty entry")
    return items


def _inline_params(item: str) -> tuple[str, dict[str, str]]:
    """``name[k=v,k2=1,2,3]`` -> (name, {k: v, k2: "1,2,3"}): a comma-separated piece without
    ``=`` continues the previous value (a vector); ``;`` before a ``key=`` is an error naming
    the comma form (``;`` between a vector's items is fine)."""
    if "[" not in item:
        return item, {}
    if not item.endswith("]"):
        raise _params.ParamError(f"filter {item!r}: text after ']'")
    ref, _, inner = item[:-1].partition("[")
    if re.search(r";\s*[A-Za-z_]\w*\s*=", inner):  # pairs split as in other tools
        fixed = re.sub(r";(\s*[A-Za-z_]\w*\s*=)", r",\1", inner)
        raise _params.ParamError(f"filter {item!r}: separate KEY=VALUE pairs with ',' (not "
                                 f"';'): '{ref.strip()}[{fixed}]'")
    values: dict[str, str] = {}
    last: str | None = None
    for piece in inner.split(","):
        if "=" in piece:
            key, _, val = piece.partition("=")
            last = key.strip()
            values[last] = val.strip()
        elif last is not None:
            values[last] += "," + piece.strip()
        elif piece.strip():
            raise _params.ParamError(f"filter {item!r}: {piece!r} is not key=value")
    return ref.strip(), values


def filter_specs(
    names: str | None = None,
    refs: Sequence[str] = (),
    assignments: Sequence[str] = (),
    config: Mapping[str, Any] | None = None,
) -> tuple[FilterSpec, ...]:
    """Filter specs from the command line.

    Parameters
    ----------
    names : str, optional
        ``FILTER[,FILTER...]``; each may carry inline parameters, ``gps-ins[key=value,...]``,
        and is labelled by its text (so one filter can run in several variants).
    refs : sequence of str
        ``--filter package.module:Class`` references (labelled by the class's ``name``).
    assignments : sequence of str
        ``-p key=value`` items. With several filters, ``label.key=value`` or
        ``name.key=value`` targets one; a plain ``key=value`` goes to every filter that has
        the parameter (an error if none has it).
    config : mapping, optional
        A TOML document: ``[filter.<label or name>]`` tables of parameter values.

    Precedence: inline > ``-p`` > config > the recording's sensor specifications > the
    filter's defaults (:mod:`navreplay.filters.settings`); each spec's ``params`` says where
    each value came from. Every filter is loaded and its parameters are validated here, so
    mistakes surface before any work.
    """
    items = split_filter_list(names) if names else []
    parsed: list[tuple[str, str, dict[str, Any], type[Filter]]] = []  # label, ref, inline, cls
    for item in items:
        ref, inline = _inline_params(item)
        parsed.append((item, ref, inline, load_filter(ref)))
    for ref in refs:
        cls = load_filter(ref)
        parsed.append((getattr(cls, "name", "") or ref.rpartition(":")[2], ref, {}, cls))
    if not parsed:
        raise _params.ParamError("no filter given (see `navreplay filters`)")
    labels = [p[0] for p in parsed]
    dupes = sorted({x for x in labels if labels.count(x) > 1})
    if dupes:
        raise _params.ParamError(
            f"filter {', '.join(dupes)} given twice; give variants their own parameters, "
            "e.g. gps-ins[gps_pos_sigma_scale=1],gps-ins[gps_pos_sigma_scale=2]"
        )
    values: list[ParamValues] = [ParamValues() for _ in parsed]
    tables = dict((config or {}).get("filter", {}) or {})
    for i, (label, ref, _, cls) in enumerate(parsed):
        for key in (cls.name, ref, label):
            table = tables.get(key)
            if isinstance(table, Mapping):
                values[i].update(table)
                values[i].sources.update(dict.fromkeys(table, Source.TOML))
    fields = [{f.name for f in dataclasses.fields(p[3].Params)} for p in parsed]
    for key, val in _params.parse_assignments(assignments).items():
        prefix, dot, name = key.rpartition(".")
        if dot:
            hit = [i for i, p in enumerate(parsed) if prefix in (p[0], p[1], p[3].name)]
            if not hit:
                raise _params.ParamError(
                    f"-p {key}: no filter {prefix!r} in this run (filters: {', '.join(labels)})"
                )
        elif len(parsed) == 1:
            hit = [0]
        else:
            hit = [i for i in range(len(parsed)) if name in fields[i]]
            if not hit:
                raise _params.ParamError(
                    f"-p {key}: none of the filters {', '.join(labels)} has a parameter {name!r}"
                )
        for i in hit:
            values[i][name] = val
            values[i].sources[name] = Source.OPTION
    specs = []
    for (label, ref, inline, cls), vals in zip(parsed, values, strict=True):
        vals.update(inline)
        vals.sources.update(dict.fromkeys(inline, Source.INLINE))
        specs.append(FilterSpec(ref, vals, label, cls=cls).resolve())  # typed and checked now
    return tuple(specs)


def scenario_values(
    assignments: Sequence[str] = (),
    config: Mapping[str, Any] | None = None,
    duration: float | None = None,
) -> dict[str, Any]:
    """Scenario parameter values: ``[scenario]`` table of a TOML config < ``-p`` < --duration;
    the config's ``[sensors.KIND]`` tables and ``-p sensors.KIND.FIELD=VALUE`` items (which
    win) under ``"sensors"`` (:func:`navreplay.sim.scenario.scenario_inputs`).

    >>> scenario_values(["sensors.imu.grade=mems", "duration=60"])
    {'sensors': {'imu': {'grade': 'mems'}}, 'duration': '60'}
    """
    from navreplay.sim.scenario import SENSORS_KEY

    values: dict[str, Any] = {}
    sensors: dict[str, dict[str, Any]] = {}
    if config:
        table = config.get("scenario")
        if isinstance(table, Mapping):
            values.update(table)
        for kind, table in (config.get(SENSORS_KEY) or {}).items():
            sensors[kind] = dict(table)
    for key, value in _params.parse_assignments(assignments).items():
        head, _, rest = key.partition(".")
        if head != SENSORS_KEY:
            values[key] = value
            continue
        kind, _, name = rest.partition(".")
        if not kind or not name:
            raise _params.ParamError(f"-p {key}: write sensors.KIND.FIELD=VALUE, e.g. "
                                     "sensors.imu.gyro_arw=\"0.15 deg/sqrt(h)\"")
        sensors.setdefault(kind, {})[name] = value
    if sensors:
        values = {SENSORS_KEY: sensors, **values}
    if duration is not None:
        values["duration"] = duration
    return values


def check_scenario(scenario: str, values: Mapping[str, Any]) -> None:
    """Raise :class:`navreplay.core.params.ParamError` (one line) unless ``values`` make a run of
    ``scenario`` (parameters and ``[sensors.*]`` tables)."""
    from navreplay.sim.scenario import get_scenario, scenario_inputs

    scenario_inputs(get_scenario(scenario), values)
