"""Typed parameters: frozen dataclasses set from ``-p key=value`` strings or a TOML table.

Scenarios and filters declare their parameters as frozen, keyword-only dataclasses with SI units
in the field docstrings; this module turns user text into such an instance with clear errors.
The ``check_*`` functions are the range checks those dataclasses (and the sensor error models)
run in ``__post_init__``; each raises ``ValueError`` naming the class and the field.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import threading
import tomllib
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from navreplay.core.streams import jsonable


class ParamError(ValueError):
    """A parameter that does not exist or has a value of the wrong type or range."""


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and math.isfinite(v)


def check_nonnegative(owner: object, *names: str) -> None:
    """Raise ``ValueError`` naming the first field that is not a finite number >= 0.

    Scalars and sequences (tuples, lists) of numbers are both accepted.
    """
    for name in names:
        value = getattr(owner, name)
        values = value if isinstance(value, tuple | list) else (value,)
        if not all(_is_number(v) and v >= 0.0 for v in values):
            raise ValueError(
                f"{type(owner).__name__}.{name} must be finite and >= 0, got {value!r}"
            )


def check_positive(owner: object, *names: str) -> None:
    """Raise ``ValueError`` naming the first field that is not a finite number > 0."""
    for name in names:
        v = getattr(owner, name)
        if not (_is_number(v) and v > 0.0):
            raise ValueError(f"{type(owner).__name__}.{name} must be finite and > 0, got {v!r}")


def check_divides(owner: object, fast: str, slow: str) -> None:
    """Raise ``ValueError`` unless rate field ``slow`` [Hz] divides rate field ``fast`` [Hz] a
    whole number of times (a sensor sampled at every k-th truth sample)."""
    a, b = getattr(owner, fast), getattr(owner, slow)
    k = a / b
    if round(k) < 1 or abs(k - round(k)) > 1e-9 * k:
        raise ValueError(f"{slow} ({b:g} Hz) must divide {fast} ({a:g} Hz) a whole number of times")


def check_whole_intervals(owner: object, duration: str, rate: str) -> None:
    """Raise ``ValueError`` unless field ``duration`` [s] is a whole number of sample intervals
    of rate field ``rate`` [Hz]."""
    d, r = getattr(owner, duration), getattr(owner, rate)
    n = d * r
    if abs(n - round(n)) > 1e-6:
        raise ValueError(f"{duration} ({d:g} s) must be a whole number of {rate} intervals "
                         f"(1/{r:g} s)")


def parse_assignments(items: Iterable[str]) -> dict[str, str]:
    """Split ``key=value`` strings; raise :class:`ParamError` on a malformed item."""
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ParamError(f"parameter {item!r} is not of the form key=value")
        out[key.strip()] = value.strip()
    return out


def load_toml(
    path: str | Path,
    table: str | None = None,
    *,
    tables: Mapping[str, Iterable[str] | None] | None = None,
) -> dict[str, Any]:
    """Read a TOML file (optionally one table of it) as parameter values.

    ``tables`` makes the file strict: it maps each table the command reads to the names its
    sub-tables may have (None: a table of plain values, e.g. ``scenario``; for ``filter``, the
    filter names, a sub-table named like a ``MODULE:CLASS`` reference or a ``name[...]`` label is
    accepted too). Any other table, sub-table or a key outside every table is a
    :class:`ParamError` naming the file and line.
    """
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
        data = tomllib.loads(text)
    except FileNotFoundError:
        raise ParamError(f"{path}: no such config file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ParamError(f"{path}: cannot read the config file: {e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ParamError(f"{path}: invalid TOML: {e}") from None
    if tables is not None:
        _check_tables(path, text, data, tables)
    if table is not None:
        data = data.get(table, {})
        if not isinstance(data, dict):
            raise ParamError(f"{path}: [{table}] is not a table")
    return data


def _check_tables(path: Path, text: str, data: Mapping[str, Any],
                  tables: Mapping[str, Iterable[str] | None]) -> None:
    for key, value in data.items():
        if key not in tables:
            if isinstance(value, dict):
                raise ParamError(f"{path}:{_line(text, key)}: unknown table [{key}] (this command "
                                 f"reads {', '.join(f'[{t}]' for t in tables) or 'no table'})")
            raise ParamError(f"{path}:{_line(text, key, top=True)}: {key} = ... is outside any "
                             f"table (put it under {' or '.join(f'[{t}]' for t in tables)})")
        names = tables[key]
        if not isinstance(value, dict):
            raise ParamError(f"{path}:{_line(text, key, top=True)}: {key} must be a table")
        if names is None:
            continue
        allowed = set(names)
        for sub, sub_value in value.items():
            if sub in allowed or ":" in sub or "[" in sub:
                if not isinstance(sub_value, dict):
                    raise ParamError(f"{path}:{_line(text, f'{key}.{sub}')}: {key}.{sub} must "
                                     "be a table")
                continue
            raise ParamError(f"{path}:{_line(text, f'{key}.{sub}')}: [{key}.{sub}]: no such "
                             f"{key} (known: {', '.join(sorted(allowed))})")


def _line(text: str, dotted: str, top: bool = False) -> int:
    """Line (1-based) of the header of table ``dotted`` or, with ``top``, of the key before any
    header; 1 when not found (a key written in another form)."""
    parts = dotted.split(".")
    table = 0
    for no, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if line.startswith("["):
            table += 1
            inner = line.strip("[]").split("#")[0].strip()
            names = [p.strip().strip("\"'") for p in inner.split(".")]
            if not top and names[: len(parts)] == parts:
                return no
        elif top and not table:
            key = line.split("=", 1)[0].strip().strip("\"'").split(".")[0].strip()
            if "=" in line and key == parts[0]:
                return no
        elif not top and "=" in line and not table:
            key = line.split("=", 1)[0].strip().strip("\"'")
            if key.split(".")[: len(parts)] == parts:
                return no
    return 1


def _coerce(name: str, tp: Any, value: Any, nested: bool = False) -> Any:
    """``value`` (text, or a TOML value) as type ``tp``. A sequence in text separates its
    items by commas (or semicolons); a sequence of sequences (``tuple[tuple[float, float],
    ...]``) its inner items by colons: ``"120:30,300:60"``."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        members = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None or (isinstance(value, str) and value.lower() in ("none", "null", "")):
            if len(members) < len(typing.get_args(tp)):
                return None
        return _coerce(name, members[0], value)
    if origin in (tuple, list):
        args = typing.get_args(tp)
        if isinstance(value, str):
            seps = ":" if nested else ",;"
            for sep in seps[1:]:
                value = value.replace(sep, seps[0])
            parts = [p for p in value.split(seps[0]) if p.strip()]
        elif isinstance(value, int | float) and args and args[-1] is Ellipsis:
            parts = [value]  # one number for a list of any length
        else:
            try:
                parts = list(value)
            except TypeError:
                raise ParamError(f"parameter {name}: expected a list, got {value!r}") from None
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(parts) != len(args):
                how = " separated by ':'" if nested and isinstance(value, str) else ""
                raise ParamError(f"parameter {name}: expected {len(args)} values{how}, got "
                                 f"{len(parts)}" + (f" ({value!r})" if how else ""))
            elem_types = list(args)
        else:
            elem_types = [args[0] if args else float] * len(parts)
        return origin(_coerce(name, t, p, nested=True)
                      for t, p in zip(elem_types, parts, strict=True))
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        try:
            return tp(value) if not isinstance(value, tp) else value
        except ValueError:
            choices = ", ".join(str(m.value) for m in tp)
            raise ParamError(f"parameter {name}: {value!r} is not one of {choices}") from None
    if tp is bool:
        if isinstance(value, bool):
            return value
        if not isinstance(value, str):  # a TOML number is not a boolean
            raise ParamError(f"parameter {name}: {value!r} is not a boolean (true/false)")
        s = str(value).strip().lower()
        if s in ("1", "true", "yes", "on"):
            return True
        if s in ("0", "false", "no", "off"):
            return False
        raise ParamError(f"parameter {name}: {value!r} is not a boolean (true/false)")
    if tp is int:
        if isinstance(value, bool):
            raise ParamError(f"parameter {name}: expected an integer, got {value!r}")
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise ParamError(f"parameter {name}: {value!r} is not an integer") from None
        if not f.is_integer():
            raise ParamError(f"parameter {name}: {value!r} is not an integer")
        return int(f)
    if tp is float:
        if isinstance(value, bool):  # TOML true is not 1.0
            raise ParamError(f"parameter {name}: expected a number, got {value!r}")
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise ParamError(f"parameter {name}: {value!r} is not a number") from None
        if not math.isfinite(f):
            raise ParamError(f"parameter {name}: {value!r} is not finite")
        return f
    if tp is str:
        if not isinstance(value, str):
            raise ParamError(f"parameter {name}: expected a string, got {value!r}")
        return value
    return value


def build(cls: type, values: Mapping[str, Any] | None = None, *, where: str = "") -> Any:
    """Instantiate parameter dataclass ``cls`` from user values (strings or TOML values).

    Unknown keys raise :class:`ParamError` listing the valid ones; the dataclass's own
    ``__post_init__`` validation errors are re-raised as :class:`ParamError`.
    """
    values = dict(values or {})
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(values) - set(fields))
    prefix = f"{where}: " if where else ""
    if unknown:
        raise ParamError(
            f"{prefix}unknown parameter(s) {', '.join(unknown)}; valid: {', '.join(fields)}"
        )
    kwargs = {k: _coerce(k, hints[k], v) for k, v in values.items()}
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as e:
        raise ParamError(f"{prefix}{e}") from None


def as_dict(params: Any) -> dict[str, Any]:
    """JSON-friendly dict of a parameter dataclass (enums by value, tuples as lists)."""
    return {f.name: jsonable(getattr(params, f.name)) for f in dataclasses.fields(params)}


_PARSING = threading.Lock()
"""Source parsed by one thread at a time: CPython 3.11's parser fails ("AST constructor
recursion depth mismatch") when threads (a Dask worker's) parse at once."""


def describe(cls: type) -> list[tuple[str, str, Any, str]]:
    """(name, type, default, docstring) of each field, for listings."""
    import ast
    import inspect
    import textwrap

    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):  # inherited fields keep their base class's docstring
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            with _PARSING:
                tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError, SyntaxError):
            continue
        body = tree.body[0].body  # type: ignore[attr-defined]
        for a, b in zip(body, body[1:], strict=False):
            if (isinstance(a, ast.AnnAssign) and isinstance(a.target, ast.Name)
                    and isinstance(b, ast.Expr) and isinstance(b.value, ast.Constant)
                    and isinstance(b.value.value, str)):
                docs[a.target.id] = " ".join(b.value.value.split())
    hints = typing.get_type_hints(cls)
    rows = []
    for f in dataclasses.fields(cls):
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        tp = hints.get(f.name, f.type)
        rows.append((f.name, getattr(tp, "__name__", str(tp)), default, docs.get(f.name, "")))
    return rows
