"""The compiled column formatter prints every value as Python's ``fmt % value`` does."""

from __future__ import annotations

import numpy as np
import pytest

from navreplay.export.numbers import BLOCK_ROWS, SECONDS_NS, format_rows

EDGES = [0.0, -0.0, np.nan, -np.nan, np.inf, -np.inf, 1e300, -1e-300, 5e-324, 0.5, 1.5, 2.5,
         0.125, 1e-4, 1e-5, 99999999.95, 999999999.5, 1e9, 1e8, 123456789.0, 1234567890123.0,
         9.9999999995e-5, 0.00012345678949999, 2.0**53, 1e22, 1e23, 40.123456789012345,
         -116.5, 0.05, 0.15, 0.25, 0.35, 1.0000000005, 2.675, 2.2250738585072014e-308,
         1.7976931348623157e308, 1e-308]
# the powers of ten and their neighbours: where the decimal exponent estimated from the binary
# one is one too low, where rounding carries into a new digit, and %g's switches to exponents
POWERS = np.array([s * np.nextafter(10.0 ** k, d) for k in range(-30, 31)
                   for d in (0.0, np.inf) for s in (1.0, -1.0)]
                  + [10.0 ** k for k in range(-30, 31)] + [9.5 * 10.0 ** k for k in range(-8, 9)]
                  + [9.9999999996 * 10.0 ** k for k in range(-8, 9)])


def _values(seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    n = 20_000
    return [np.array(EDGES), POWERS,
            np.ldexp(rng.choice([-1.0, 1.0], size=n // 4) * rng.uniform(1.0, 2.0, size=n // 4),
                     rng.integers(-1074, 1024, size=n // 4)),  # every binary exponent
            rng.normal(size=n) * 10.0 ** rng.integers(-12, 14, size=n),
            rng.uniform(-1.0, 1.0, size=n),
            np.round(rng.normal(size=n) * 1000.0, 3),  # decimal ties in binary
            np.round(rng.normal(size=n), 1) / 8.0,
            np.arange(n) * 0.001 + 1e5,
            rng.normal(size=n).astype(np.float32)]


@pytest.mark.parametrize("fmt", ["%.4f", "%.10f", "%.6f", "%.9f", "%.1f", "%.0f", "%.15f", "%g",
                                 "%.25f", "%e", *(f"%.{p}g" for p in range(1, 18))])
def test_floats_as_python_prints_them(fmt: str) -> None:
    for v in _values(7):
        assert format_rows([(v, fmt)]) == "".join(fmt % x + "\n" for x in v.tolist())


def test_integers_and_seconds() -> None:
    rng = np.random.default_rng(8)
    i64 = np.iinfo(np.int64)
    ints = np.concatenate([rng.integers(-2**62, 2**62, size=5000),
                           [0, -1, 1, i64.min, i64.max, 10**18, 10**18 - 1]]).astype(np.int64)
    assert format_rows([(ints, "%d")]) == "".join(f"{x}\n" for x in ints.tolist())
    ns = np.concatenate([rng.integers(0, 2**62, size=5000),
                         [0, 1, 999_999_999, 10**9, -1, -10**9 - 5]]).astype(np.int64)
    want = "".join("{}.{:09d}\n".format(*divmod(x, 10**9)) for x in ns.tolist())
    assert format_rows([(ns, SECONDS_NS)]) == want


def test_rows_across_blocks_with_separators() -> None:
    rng = np.random.default_rng(9)
    n = BLOCK_ROWS + 17
    cols = [(np.arange(n, dtype=np.int64) * 10_000_019, SECONDS_NS),
            (np.round(rng.normal(size=n), 4), "%.4f"),  # many values left to Python
            (rng.normal(size=n) * 1e-6, "%.9g"),
            (np.arange(n, dtype=np.int64) - 5, "%d")]
    text = [[("{}.{:09d}".format(*divmod(x, 10**9)) if f == SECONDS_NS else f % x)
             for x in v.tolist()] for v, f in cols]
    want = "".join(" ".join(row) + ";" for row in zip(*text, strict=True))
    assert format_rows(cols, sep=" ", end=";") == want
    assert format_rows([]) == ""
    assert format_rows([(np.zeros(0), "%.9g")]) == ""
