"""Datasheet units in SI, and quantities written with their unit ("0.15 deg/sqrt(h)").

Constants
    Multiply a datasheet value by the constant to get SI: ``0.3 * DEG_PER_HOUR`` [rad/s].

Unit expressions
    :func:`parse_quantity` reads ``"NUMBER UNIT"`` where UNIT is an expression of the names of
    :data:`UNIT_NAMES` with ``*``, ``/`` (left to right: ``deg/h/g`` is ``(deg/h)/g``),
    ``^N`` (also ``^-1``, ``^0.5``, ``^(1/2)``) and ``sqrt(...)``; :func:`format_quantity`
    writes a value in a chosen unit. Every unit has a dimension over angle, length, time and
    magnetic flux density, and a conversion is refused, with one line naming what was expected,
    when the dimensions differ: ``"3 deg/h"`` is not an angle random walk. A pure angle also
    accepts a dimensionless value (a cross-axis sensitivity of ``1 %`` is a 10 mrad
    misalignment).

Examples
--------
>>> round(parse_quantity("0.15 deg/sqrt(h)", "rad/sqrt(s)"), 9)
4.3633e-05
>>> round(parse_quantity("60 ug/sqrt(Hz)", "m/s/sqrt(s)") * 1e6, 3)
588.399
>>> format_quantity(parse_quantity("10 deg/h/g", "rad/s/(m/s^2)"), "rad/s/(m/s^2)", "deg/h/g")
'10 deg/h/g'
>>> parse_quantity("3 deg/h", "rad/sqrt(s)")
Traceback (most recent call last):
...
navreplay.core.units.UnitError: "3 deg/h" is in rad/s, not in rad/s^(1/2)
"""

from __future__ import annotations

import functools
import math
import re
from fractions import Fraction
from typing import NamedTuple

G0 = 9.80665
"""Standard gravity used for g-based datasheet units [m/s^2]."""

DEG = math.pi / 180.0
ARCMIN = DEG / 60.0
ARCSEC = DEG / 3600.0
MIL = 2.0 * math.pi / 6400.0
"""NATO mil [rad]."""
DEG_PER_HOUR = DEG / 3600.0
"""deg/h -> rad/s."""
DEG_PER_SECOND = DEG
"""deg/s -> rad/s."""
DEG_PER_SQRT_HOUR = DEG / 60.0
"""deg/sqrt(h) (angle random walk) -> rad/sqrt(s)."""
DEG_PER_HOUR_PER_G = DEG_PER_HOUR / G0
"""deg/h/g (g-sensitivity) -> (rad/s)/(m/s^2)."""
MILLI_G = 1e-3 * G0
MICRO_G = 1e-6 * G0
MICRO_G_PER_SQRT_HZ = MICRO_G
"""ug/sqrt(Hz) (velocity random walk) -> m/s/sqrt(s)."""
PPM = 1e-6
PERCENT = 1e-2
FOOT = 0.3048
KNOT = 1852.0 / 3600.0
GAUSS = 1e-4
"""Gauss -> tesla."""
NANOTESLA = 1e-9


# -- unit expressions -------------------------------------------------------------------------

DIMENSIONS = ("rad", "m", "s", "T")
"""The base dimensions of a unit: angle, length, time, magnetic flux density (their SI units)."""

Dims = tuple[Fraction, Fraction, Fraction, Fraction]


class UnitError(ValueError):
    """A unit expression that does not parse, or a quantity of the wrong dimension."""


class Unit(NamedTuple):
    """A parsed unit: ``factor`` SI units per unit, and the exponents of :data:`DIMENSIONS`."""

    factor: float
    dims: Dims

    def __mul__(self, other: object) -> Unit:
        if not isinstance(other, Unit):
            return NotImplemented
        return Unit(self.factor * other.factor,
                    tuple(a + b for a, b in zip(self.dims, other.dims, strict=True)))  # type: ignore[arg-type]

    def __truediv__(self, other: Unit) -> Unit:
        return self * other ** -1

    def __pow__(self, n: Fraction | int) -> Unit:
        n = Fraction(n)
        return Unit(self.factor ** float(n), tuple(d * n for d in self.dims))  # type: ignore[arg-type]


def _u(factor: float, rad: int = 0, m: int = 0, s: int = 0, T: int = 0) -> Unit:
    return Unit(factor, (Fraction(rad), Fraction(m), Fraction(s), Fraction(T)))


UNIT_NAMES: dict[str, Unit] = {
    # angle
    "rad": _u(1.0, rad=1), "mrad": _u(1e-3, rad=1), "urad": _u(1e-6, rad=1),
    "µrad": _u(1e-6, rad=1), "deg": _u(DEG, rad=1), "°": _u(DEG, rad=1),
    "arcmin": _u(ARCMIN, rad=1), "arcsec": _u(ARCSEC, rad=1), "mil": _u(MIL, rad=1),
    "rev": _u(2.0 * math.pi, rad=1),
    # time and frequency
    "s": _u(1.0, s=1), "sec": _u(1.0, s=1), "ms": _u(1e-3, s=1), "us": _u(1e-6, s=1),
    "min": _u(60.0, s=1), "h": _u(3600.0, s=1), "hr": _u(3600.0, s=1),
    "Hz": _u(1.0, s=-1), "kHz": _u(1e3, s=-1),
    "rpm": _u(2.0 * math.pi / 60.0, rad=1, s=-1),
    # length and speed
    "m": _u(1.0, m=1), "km": _u(1e3, m=1), "cm": _u(1e-2, m=1), "mm": _u(1e-3, m=1),
    "ft": _u(FOOT, m=1), "kn": _u(KNOT, m=1, s=-1),
    # acceleration in units of standard gravity
    "g": _u(G0, m=1, s=-2), "mg": _u(MILLI_G, m=1, s=-2), "ug": _u(MICRO_G, m=1, s=-2),
    "µg": _u(MICRO_G, m=1, s=-2),
    # dimensionless
    "ppm": _u(PPM), "%": _u(PERCENT),
    # magnetic flux density
    "T": _u(1.0, T=1), "mT": _u(1e-3, T=1), "uT": _u(1e-6, T=1), "µT": _u(1e-6, T=1),
    "nT": _u(NANOTESLA, T=1), "G": _u(GAUSS, T=1), "mG": _u(1e-3 * GAUSS, T=1),
    "gauss": _u(GAUSS, T=1), "mgauss": _u(1e-3 * GAUSS, T=1),
}
"""Unit names (case-sensitive: ``g`` is standard gravity, ``G`` gauss) and their SI values."""

DIMENSIONLESS = _u(1.0)

_TOKEN = re.compile(r"\s*(?:(?P<num>\d+(?:\.\d*)?(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?)"
                    r"|(?P<name>[A-Za-zµ°%]+)|(?P<op>[*/^()+-]))")


def _tokens(text: str) -> list[str]:
    out, pos = [], 0
    text = text.strip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise UnitError(f"unit {text!r}: cannot read {text[pos:]!r}")
        out.append(m.group(m.lastgroup))  # type: ignore[arg-type]
        pos = m.end()
    return out


class _Parser:
    """Recursive descent over the tokens of a unit expression (see the module docstring)."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.toks = _tokens(text)
        self.i = 0

    def fail(self, what: str) -> UnitError:
        return UnitError(f"unit {self.text!r}: {what}")

    def peek(self) -> str | None:
        return self.toks[self.i] if self.i < len(self.toks) else None

    def take(self, expected: str | None = None) -> str:
        tok = self.peek()
        if tok is None or (expected is not None and tok != expected):
            raise self.fail(f"expected {expected or 'more'} at the end" if tok is None
                            else f"expected {expected!r}, found {tok!r}")
        self.i += 1
        return tok

    def parse(self) -> Unit:
        unit = self.expr()
        if self.peek() is not None:
            raise self.fail(f"unexpected {self.peek()!r}")
        return unit

    def expr(self) -> Unit:
        unit = self.term()
        while self.peek() in ("*", "/"):
            op = self.take()
            rhs = self.term()
            unit = unit * rhs if op == "*" else unit / rhs
        return unit

    def term(self) -> Unit:
        unit = self.factor()
        if self.peek() == "^":
            self.take()
            unit = unit ** self.exponent()
        return unit

    def exponent(self) -> Fraction:
        if self.peek() == "(":
            self.take()
            sign = -1 if self.peek() == "-" and self.take() else 1
            n = self.number()
            if self.peek() == "/":
                self.take()
                n /= self.number()
            self.take(")")
            return sign * n
        sign = -1 if self.peek() == "-" and self.take() else 1
        return sign * self.number()

    def number(self) -> Fraction:
        tok = self.take()
        try:
            return Fraction(tok)
        except ValueError:
            raise self.fail(f"expected a number, found {tok!r}") from None

    def factor(self) -> Unit:
        tok = self.take()
        if tok == "(":
            unit = self.expr()
            self.take(")")
            return unit
        if tok == "sqrt":
            self.take("(")
            unit = self.expr()
            self.take(")")
            return unit ** Fraction(1, 2)
        if tok[0].isdigit() or tok[0] == ".":
            return Unit(float(tok), DIMENSIONLESS.dims)
        if tok in UNIT_NAMES:
            return UNIT_NAMES[tok]
        raise self.fail(f"unknown unit {tok!r} (known: {', '.join(UNIT_NAMES)})")


@functools.lru_cache(maxsize=256)
def parse_unit(text: str) -> Unit:
    """The :class:`Unit` of an expression such as ``"deg/h/sqrt(Hz)"``; ``""`` or ``"1"`` is
    dimensionless. Raises :class:`UnitError`."""
    if not text.strip():
        return DIMENSIONLESS
    return _Parser(text).parse()


def dimension_text(dims: Dims) -> str:
    """A dimension as its SI unit, e.g. ``rad/s^(1/2)``; ``1`` when dimensionless."""
    def power(name: str, e: Fraction) -> str:
        if e == 1:
            return name
        return f"{name}^{e}" if e.denominator == 1 else f"{name}^({e})"

    num = [power(n, e) for n, e in zip(DIMENSIONS, dims, strict=True) if e > 0]
    den = [power(n, -e) for n, e in zip(DIMENSIONS, dims, strict=True) if e < 0]
    text = "*".join(num) or "1"
    if den:
        text += "/" + ("/".join(den))
    return text


def dimension_phrase(dims: Dims) -> str:
    """``in rad/s^(1/2)``, or ``dimensionless``."""
    return "dimensionless" if not any(dims) else f"in {dimension_text(dims)}"


def _compatible(got: Dims, want: Dims) -> bool:
    """Equal dimensions, or a dimensionless value for a pure angle."""
    angle = (Fraction(1), Fraction(0), Fraction(0), Fraction(0))
    return got == want or (want == angle and got == DIMENSIONLESS.dims)


def convert(value: float, unit: str, to: str) -> float:
    """``value`` in ``unit`` expressed in ``to`` (same dimension, else :class:`UnitError`)."""
    src, dst = parse_unit(unit), parse_unit(to)
    if not _compatible(src.dims, dst.dims):
        raise UnitError(f"{unit or '1'} is {dimension_phrase(src.dims)}, not "
                        f"{dimension_phrase(dst.dims)}")
    return value * src.factor / dst.factor


_NUMBER = re.compile(r"\s*([-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


def parse_quantity(text: str | float | int, to: str) -> float:
    """A quantity ``"NUMBER UNIT"`` (or a bare number or numeric string, taken as already in
    ``to``) in unit ``to``.

    Parameters
    ----------
    text : str or float
        E.g. ``"0.15 deg/sqrt(h)"``, ``"2 mg"``, ``"300 ppm"``, ``0.002``.
    to : str
        Unit of the result, e.g. ``"rad/sqrt(s)"``.

    Raises
    ------
    UnitError
        Unreadable text, an unknown unit, or a dimension other than that of ``to``.
    """
    if isinstance(text, bool):
        raise UnitError(f"{text!r} is not a number")
    if isinstance(text, int | float):
        value = float(text)
        if not math.isfinite(value):
            raise UnitError(f"{text!r} is not finite")
        return value
    m = _NUMBER.match(str(text))
    if m is None:
        raise UnitError(f"{text!r} is not a number followed by a unit (e.g. \"0.15 deg/sqrt(h)\")")
    value, unit = float(m.group(1)), m.group(2)
    if not math.isfinite(value):
        raise UnitError(f"{text!r} is not finite")
    if not unit:  # a bare number is already in ``to``
        return value
    src, dst = parse_unit(unit), parse_unit(to)
    if not _compatible(src.dims, dst.dims):
        raise UnitError(f"\"{text}\" is {dimension_phrase(src.dims)}, not "
                        f"{dimension_phrase(dst.dims)}")
    return value * src.factor / dst.factor


def format_quantity(value: float, unit: str, display: str, digits: int = 6) -> str:
    """``value`` [``unit``] written in ``display`` units: ``"0.15 deg/sqrt(h)"``."""
    shown = convert(value, unit, display)
    text = f"{shown:.{digits}g}"
    return f"{text} {display}" if display else text


# -- units written in a key: gyro_arw_deg_per_sqrt_h ----------------------------------------

_KEY_ALIASES = {"hz": "Hz", "khz": "kHz", "dph": "deg/h", "dps": "deg/s", "pct": "%",
                "percent": "%", "ppm": "ppm", "ut": "uT", "nt": "nT", "mt": "mT"}


def key_unit(suffix: str) -> str:
    """The unit expression of a key suffix: words joined by ``_``, ``per`` for ``/``, ``sqrt``
    applying to the next word, a trailing digit for a power (``s2``: s^2).

    >>> key_unit("deg_per_sqrt_h")
    'deg/sqrt(h)'
    >>> key_unit("m_per_s2_per_sqrt_s")
    'm/s^2/sqrt(s)'
    >>> key_unit("ug_per_sqrt_hz")
    'ug/sqrt(Hz)'
    """
    words = [w for w in suffix.split("_") if w]
    out: list[str] = []
    sqrt = False
    for w in words:
        if w == "per":
            out.append("/")
            continue
        if w == "sqrt":
            sqrt = True
            continue
        m = re.fullmatch(r"([A-Za-zµ%]+?)(\d*)", w)
        if m is None:
            raise UnitError(f"cannot read the unit {suffix!r} of a key")
        name, power = m.groups()
        if name not in UNIT_NAMES:
            name = _KEY_ALIASES.get(name.lower(), name)
        if name not in UNIT_NAMES and "/" not in name:
            raise UnitError(f"unknown unit {w!r} in the key suffix {suffix!r}")
        part = f"{name}^{power}" if power else name
        if sqrt:
            part, sqrt = f"sqrt({part})", False
        if out and out[-1] != "/":
            out.append("*")
        out.append(part)
    if not out or out[-1] == "/" or sqrt:
        raise UnitError(f"cannot read the unit {suffix!r} of a key")
    return "".join(out)
