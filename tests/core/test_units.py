"""Unit expressions: datasheet quantities to SI, dimensions checked, and back."""

from __future__ import annotations

import math

import pytest

from navreplay.core import units
from navreplay.core.units import (
    ARCSEC,
    DEG,
    DEG_PER_HOUR,
    DEG_PER_HOUR_PER_G,
    DEG_PER_SQRT_HOUR,
    G0,
    MICRO_G,
    MICRO_G_PER_SQRT_HZ,
    MILLI_G,
    PPM,
    UnitError,
    convert,
    format_quantity,
    key_unit,
    parse_quantity,
    parse_unit,
)


@pytest.mark.parametrize(
    ("text", "si", "expected"),
    [
        # the datasheet forms of the [sensors.imu] key contract
        ("0.15 deg/sqrt(h)", "rad/sqrt(s)", 0.15 * DEG_PER_SQRT_HOUR),
        ("60 ug/sqrt(Hz)", "m/s/sqrt(s)", 60 * MICRO_G_PER_SQRT_HZ),
        ("3 deg/h", "rad/s", 3 * DEG_PER_HOUR),
        ("600 s", "s", 600.0),
        ("0.02 deg/h/sqrt(h)", "rad/s/sqrt(s)", 0.02 * DEG_PER_HOUR / 60.0),
        ("1e-5 m/s^2/sqrt(s)", "m/s^2/sqrt(s)", 1e-5),
        ("2 mg", "m/s^2", 2 * MILLI_G),
        ("300 ppm", "", 300 * PPM),
        ("0.5 mrad", "rad", 0.5e-3),
        ("10 deg/h/g", "rad/s/(m/s^2)", 10 * DEG_PER_HOUR_PER_G),
        # other spellings of the same quantities
        ("0.0025 deg/s/sqrt(Hz)", "rad/sqrt(s)", 0.0025 * DEG),  # deg/s/sqrt(Hz) = deg/sqrt(s)
        ("0.15 deg/h/sqrt(Hz)", "rad/sqrt(s)", 0.15 * DEG_PER_HOUR),
        ("0.06 m/s/sqrt(h)", "m/s/sqrt(s)", 0.001),
        ("5 arcsec", "rad", 5 * ARCSEC),
        ("1 %", "rad", 0.01),  # a cross-axis sensitivity as a misalignment
        ("0.5 %", "", 0.005),
        ("250 µg", "m/s^2", 250 * MICRO_G),
        ("100 nT", "T", 1e-7),
        ("3 mG", "T", 3e-7),
        ("5 rpm", "rpm", 5.0),
        ("1 rpm", "rad/s", 2 * math.pi / 60),
        ("3 deg/h^(1/2)", "rad/sqrt(s)", 3 * DEG_PER_SQRT_HOUR),
        ("2 m*s^-1", "m/s", 2.0),
        ("  7   ", "m", 7.0),  # a bare number is in the target unit
        (0.002, "rad/sqrt(s)", 0.002),
    ],
)
def test_datasheet_quantities_in_si(text, si, expected):
    assert parse_quantity(text, si) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(
    ("text", "si", "message"),
    [
        ("3 deg/h", "rad/sqrt(s)", '"3 deg/h" is in rad/s, not in rad/s^(1/2)'),
        ("2 mg", "m/s/sqrt(s)", "is in m/s^2, not in m/s^(3/2)"),
        ("300 ppm", "rad/s", "is dimensionless, not in rad/s"),
        ("3 deg", "", "is in rad, not dimensionless"),
        ("3 furlongs", "m", "unknown unit 'furlongs'"),
        ("3 deg/", "rad", "expected more at the end"),
        ("3 sqrt(h", "s^(1/2)", "expected ) at the end"),
        ("deg", "rad", "is not a number followed by a unit"),
        ("nan deg", "rad", "is not a number followed by a unit"),
        (True, "rad", "is not a number"),
    ],
)
def test_bad_quantities_are_one_line_errors(text, si, message):
    with pytest.raises(UnitError) as e:
        parse_quantity(text, si)
    assert message in str(e.value) and "\n" not in str(e.value)


def test_dimensions_and_factors_are_consistent():
    # g and the constants of the module agree
    assert parse_unit("g").factor == G0 and parse_unit("mg").factor == pytest.approx(MILLI_G)
    # powers and roots: sqrt(h) is 60 sqrt(s); Hz^-1/2 is sqrt(s)
    assert parse_unit("sqrt(h)").factor == pytest.approx(60.0)
    assert parse_unit("Hz^(-1/2)").dims == parse_unit("sqrt(s)").dims
    assert parse_unit("deg/h/sqrt(Hz)").dims == parse_unit("rad/sqrt(s)").dims
    assert parse_unit("ug/sqrt(Hz)").dims == parse_unit("m/s/sqrt(s)").dims
    # case matters: g is gravity, G is gauss
    assert parse_unit("G").dims != parse_unit("g").dims
    assert units.dimension_text(parse_unit("m/s^2/sqrt(s)").dims) == "m/s^(5/2)"


def test_format_is_the_inverse_of_parse():
    for si, shown, value in [("rad/sqrt(s)", "deg/sqrt(h)", 4.3633e-5),
                             ("m/s/sqrt(s)", "ug/sqrt(Hz)", 5.9e-4),
                             ("rad/s/(m/s^2)", "deg/h/g", 4.9e-6),
                             ("", "ppm", 3e-4)]:
        text = format_quantity(value, si, shown)
        assert text.endswith(" " + shown)
        assert parse_quantity(text, si) == pytest.approx(value, rel=1e-5)  # 6 digits
    with pytest.raises(UnitError, match="is in rad/s, not in rad"):
        convert(1.0, "deg/h", "deg")


@pytest.mark.parametrize(
    ("suffix", "unit"),
    [("deg_per_sqrt_h", "deg/sqrt(h)"), ("ug_per_sqrt_hz", "ug/sqrt(Hz)"),
     ("deg_per_h", "deg/h"), ("dph", "deg/h"), ("m_per_s2_per_sqrt_s", "m/s^2/sqrt(s)"),
     ("ppm", "ppm"), ("mrad", "mrad"), ("deg_per_h_per_g", "deg/h/g"), ("s", "s")],
)
def test_units_written_in_keys(suffix, unit):
    assert key_unit(suffix) == unit
    parse_unit(key_unit(suffix))


@pytest.mark.parametrize("suffix", ["per_h", "deg_per", "deg_sqrt", "furlong"])
def test_unreadable_key_units(suffix):
    with pytest.raises(UnitError):
        parse_unit(key_unit(suffix))
