"""Text rows of numeric columns written by one compiled kernel: the same characters as
Python's ``fmt % value`` for every value (CSV and TUM files), without a Python call per value.

A column's format is ``%d``, ``%.Nf`` (N <= 15), ``%.Ng`` (1 <= N <= 17) or
:data:`SECONDS_NS` (integer nanoseconds as seconds with nine decimals). Digits come from
integer arithmetic: a value is scaled by an exact power of ten (one correctly rounded
multiplication or division; the decimal exponent estimated from the binary one in its bits)
and rounded to an integer, whose digits are written four at a time (two pairs from a table),
then the decimal point is put in and ``%g``'s trailing zeros are dropped. Where that rounding
could differ from the correctly rounded decimal Python prints (the scaled value within 1e-6 of
a half beyond its rounding error, or outside the exactly representable range) the value is
formatted by Python instead (the kernel leaves a mark where it goes), as is every value of any
other format.

Examples
--------
>>> import numpy as np
>>> format_rows([(np.array([1, -20]), "%d"), (np.array([0.5, 1e-7]), "%.9g")])
'1,0.5\\n-20,1e-07\\n'
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Iterator, Sequence

import numpy as np

from navreplay.core.jit import kernel

SECONDS_NS = "seconds.nanoseconds"
"""Format of an int64 column of nanoseconds printed as ``f"{s}.{ns:09d}"`` (``divmod`` by 1e9)."""

BLOCK_ROWS = 1024
"""Rows formatted at once."""

_PYTHON, _INT, _FIXED, _GENERAL, _SECONDS = -1, 0, 1, 2, 3  # kinds of column
_FIXED_RE = re.compile(r"%\.(\d+)f")
_GENERAL_RE = re.compile(r"%\.(\d+)g")
_CELL = 34  # the longest cell the kernel writes: "-" + 15 + "." + 15 digits, and a separator

_kernel = kernel(error_model="numpy", _nrt=False, nogil=True)
"""The kernels allocate nothing, so they run without numba's reference counting of arrays: its
atomic counts on every call between them cost about as much as formatting a value. They
release Python's lock (an export written in its own thread runs beside the replay)."""

_inline = kernel(error_model="numpy", _nrt=False, inline="always")
"""The helpers of :func:`_write`, inlined into it by numba (its IR): an eighth faster than calls
between compiled functions."""

_POW10 = np.array([float(10**k) for k in range(23)])  # exact doubles
_POW10_INT = np.array([10**k for k in range(19)], dtype=np.int64)
_POW10_UINT = _POW10_INT.astype(np.uint64)
_TEN, _HUNDRED, _TEN_THOUSAND = np.uint64(10), np.uint64(100), np.uint64(10_000)  # unsigned
_ZERO = np.uint64(48)  # the digit 0
_DIGIT_PAIRS = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode(), np.uint8).copy()
_TIE = 1e-6
_LOG10_2_MUL, _LOG10_2_SHIFT = 78913, 18  # (b * 78913) >> 18 == floor(b * log10(2))
_INT64_MIN = -(2**63)


def format_rows(columns: Sequence[tuple[np.ndarray, str]], sep: str = ",",
                end: str = "\n") -> str:
    """Rows of text: each column's values as ``fmt % value``, separated by ``sep``, each row
    ended by ``end``.

    Parameters
    ----------
    columns : sequence of (ndarray (M,), str)
        Values and format of each column (all of M rows).
    sep, end : str
        One ASCII character each: between the values of a row; after each row.
    """
    return b"".join(row_blocks(columns, sep, end)).decode("ascii")


def row_blocks(columns: Sequence[tuple[np.ndarray, str]], sep: str = ",",
               end: str = "\n") -> Iterator[bytes | memoryview]:
    """The rows of :func:`format_rows` as ASCII bytes, :data:`BLOCK_ROWS` rows at a time (for
    a binary file: no text built, decoded or encoded). A block is a view of the kernel's own
    buffer (each block its own: they may all be kept), not a copy of it."""
    if not columns:
        return
    k = len(columns)
    arrays = [np.asarray(v) for v, _ in columns]
    fmts = [f for _, f in columns]
    kinds = np.array([_kind(a.dtype, f) for a, f in zip(arrays, fmts, strict=True)],
                     dtype=np.int64)
    kind, prec = kinds // 100 - 1, kinds % 100
    ints = [a.dtype.kind in "iu" for a in arrays]
    n = arrays[0].shape[0]
    for a in range(0, n, BLOCK_ROWS):
        b = min(n, a + BLOCK_ROWS)
        # one row per column (contiguous copies); the kernel reads each column's own row
        F = np.empty((k, b - a))
        Ii = np.empty((k, b - a), dtype=np.int64)
        for j, v in enumerate(arrays):
            if ints[j]:
                Ii[j] = v[a:b]
            else:
                F[j] = v[a:b]
        buf = np.empty((b - a) * (k * _CELL + 1), dtype=np.uint8)
        marks = np.empty(2 * (b - a) * k, dtype=np.int64)
        size, count = _write(F, F.view(np.int64), Ii, kind, prec, ord(sep), ord(end), buf,
                             marks)
        if not count:
            yield buf[:size].data
            continue
        text, done = [], 0  # the values left to Python go in at their marks
        for pos, flat in marks[:2 * count].reshape(count, 2).tolist():
            r, j = divmod(flat, k)
            value = arrays[j][a + r:a + r + 1].tolist()[0]
            text += [buf[done:pos].tobytes(), _python(value, fmts[j]).encode("ascii")]
            done = pos
        text.append(buf[done:size].tobytes())
        yield b"".join(text)


@functools.lru_cache(maxsize=256)
def _kind(dtype: np.dtype, fmt: str) -> int:
    """100 * (kind + 1) + precision of a column of ``dtype`` (the same for every block of a
    file: cached)."""
    integer = dtype.kind in "iu" and dtype.itemsize <= 8 and not (
        dtype.kind == "u" and dtype.itemsize == 8)
    if fmt == "%d" and integer:
        return 100 * (_INT + 1)
    if fmt == SECONDS_NS and integer:
        return 100 * (_SECONDS + 1)
    if dtype.kind == "f":
        if (m := _FIXED_RE.fullmatch(fmt)) and int(m.group(1)) <= 15:
            return 100 * (_FIXED + 1) + int(m.group(1))
        if (m := _GENERAL_RE.fullmatch(fmt)) and 1 <= int(m.group(1)) <= 17:
            return 100 * (_GENERAL + 1) + int(m.group(1))
    return 0  # Python's


def _python(value: object, fmt: str) -> str:
    if fmt == SECONDS_NS:
        s, ns = divmod(int(value), 1_000_000_000)  # type: ignore[call-overload]
        return f"{s}.{ns:09d}"
    return fmt % value


@_inline
def _scaled(ax: float, k: int) -> float:
    if k >= 0:
        return ax * _POW10[k]
    return ax / _POW10[-k]


@_inline
def _tie(m: float) -> bool:
    """``m`` (within m * 2**-53 of the exact product) may round either way."""
    return abs(m - math.floor(m) - 0.5) < _TIE + m * 4.5e-16


@_inline
def _general_digits(ax: float, bits: int, p: int) -> tuple[int, int, bool]:
    """(p significant digits as an integer, decimal exponent, in doubt) of finite ax > 0 whose
    IEEE 754 bits are ``bits``."""
    b = ((bits >> 52) & 0x7FF) - 1023  # ax in [2**b, 2**(b+1)) (a subnormal: in doubt)
    if b == -1023:
        return 0, 0, True
    # floor(b * log10(2)) exactly for |b| < 1650: the decimal exponent or one below it
    e = (b * _LOG10_2_MUL) >> _LOG10_2_SHIFT
    m = 0.0
    for _ in range(4):
        k = p - 1 - e
        if k > 22 or k < -22:
            return 0, e, True
        m = _scaled(ax, k)
        if m < _POW10[p - 1]:
            e -= 1
        elif m >= _POW10[p]:
            e += 1
        else:
            break
    else:
        return 0, e, True
    r = int(np.rint(m))
    if r == _POW10_INT[p]:
        r = _POW10_INT[p - 1]
        e += 1
    return r, e, _tie(m)


@_inline
def _count_digits(u: np.uint64, least: int) -> int:
    """Decimal digits of ``u`` < 10**19, at least ``least`` (>= 1)."""
    count = least
    while count < 19 and u >= _POW10_UINT[count]:
        count += 1
    return count


@_inline
def _put_uint(buf: np.ndarray, pos: int, v: int, width: int) -> int:
    """Non-negative ``v`` in decimal, zero-padded to ``width`` digits (0: as many as it has)."""
    u = np.uint64(v)
    return _put_digits(buf, pos, u, _count_digits(u, max(width, 1)))


@_inline
def _put3(buf: np.ndarray, pos: int, a: int, b: int, c: int) -> int:
    buf[pos], buf[pos + 1], buf[pos + 2] = a, b, c
    return pos + 3


@_inline
def _point(buf: np.ndarray, pos: int, whole: int) -> None:
    """Digits written from ``pos + 1`` on: their first ``whole`` moved one place left and a
    decimal point put after them."""
    for i in range(pos, pos + whole):
        buf[i] = buf[i + 1]
    buf[pos + whole] = 46  # "."


@_inline
def _trim(buf: np.ndarray, end: int) -> int:
    """The end of a number with a decimal point once its trailing zeros (and then a trailing
    point) are dropped, as ``%g`` does."""
    while buf[end - 1] == 48:
        end -= 1
    if buf[end - 1] == 46:
        end -= 1
    return end


@_inline
def _put_float(buf: np.ndarray, pos: int, x: float, bits: int, kd: int, p: int) -> int:
    """``%.{p}f`` (kd _FIXED) or ``%.{p}g`` (_GENERAL) of ``x`` (IEEE 754 bits ``bits``); -1
    where the digits might not be Python's."""
    if x != x:
        return _put3(buf, pos, 110, 97, 110)  # "nan"
    if bits < 0:
        buf[pos] = 45  # "-"
        pos += 1
    ax = abs(x)
    if math.isinf(ax):
        return _put3(buf, pos, 105, 110, 102)  # "inf"
    if kd == _FIXED:
        m = ax * _POW10[p]
        if not m < 9e14 or _tie(m):
            return -1
        u = np.uint64(np.rint(m))
        if not p:
            return _put_digits(buf, pos, u, _count_digits(u, 1))
        count = _count_digits(u, p + 1)  # at least one digit before the point
        _put_digits(buf, pos + 1, u, count)
        _point(buf, pos, count - p)
        return pos + count + 1
    if ax == 0.0:
        buf[pos] = 48
        return pos + 1
    r, e, doubt = _general_digits(ax, bits, p)
    if doubt:
        return -1
    u = np.uint64(r)
    if -4 <= e < p:
        if e < 0:  # 0.000ddd
            buf[pos] = 48
            buf[pos + 1] = 46
            pos += 2
            for _ in range(-e - 1):
                buf[pos] = 48
                pos += 1
            return _trim(buf, _put_digits(buf, pos, u, p))
        _put_digits(buf, pos + 1, u, p)  # integer digits, ".", the rest
        _point(buf, pos, e + 1)
        return _trim(buf, pos + p + 1)
    _put_digits(buf, pos + 1, u, p)  # d.ddde+XX
    _point(buf, pos, 1)
    pos = _trim(buf, pos + p + 1)
    buf[pos] = 101  # "e"
    buf[pos + 1] = 45 if e < 0 else 43
    return _put_uint(buf, pos + 2, abs(e), 2)


@_inline
def _put_digits(buf: np.ndarray, pos: int, u: np.uint64, count: int) -> int:
    """The last ``count`` decimal digits of ``u`` (leading zeros included): four at a time,
    each group's two pairs of digits looked up (only the division by 10**4 waits for the one
    before). Unsigned: a signed division by a constant costs twice as much (Python's rounding
    towards minus infinity)."""
    i = pos + count
    while i >= pos + 4:
        q = u // _TEN_THOUSAND
        g = u - q * _TEN_THOUSAND
        hi = g // _HUNDRED
        a, b = 2 * int(hi), 2 * int(g - hi * _HUNDRED)
        buf[i - 4], buf[i - 3] = _DIGIT_PAIRS[a], _DIGIT_PAIRS[a + 1]
        buf[i - 2], buf[i - 1] = _DIGIT_PAIRS[b], _DIGIT_PAIRS[b + 1]
        u = q
        i -= 4
    if i >= pos + 2:
        q = u // _HUNDRED
        a = 2 * int(u - q * _HUNDRED)
        buf[i - 2], buf[i - 1] = _DIGIT_PAIRS[a], _DIGIT_PAIRS[a + 1]
        u = q
        i -= 2
    if i > pos:
        buf[pos] = _ZERO + u % _TEN
    return pos + count


@_kernel
def _write(F: np.ndarray, Fb: np.ndarray, Ii: np.ndarray, kind: np.ndarray, prec: np.ndarray,
           sep: int, end: int, buf: np.ndarray, marks: np.ndarray) -> tuple[int, int]:
    """Write the rows into ``buf`` (``Fb``: the bits of ``F``); a value left to Python is
    skipped, its position and ``r * k + j`` appended to ``marks``. Returns the bytes written
    and the marks."""
    k, n = F.shape
    pos = 0
    count = 0
    for r in range(n):
        for j in range(k):
            if j:
                buf[pos] = sep
                pos += 1
            kd = kind[j]
            if kd == _INT or kd == _SECONDS:
                v = Ii[j, r]
                python = v == _INT64_MIN if kd == _INT else v < 0
            else:
                python = kd == _PYTHON
                if not python:
                    at = _put_float(buf, pos, F[j, r], Fb[j, r], kd, prec[j])
                    python = at < 0
                    if not python:
                        pos = at
                        continue
            if python:
                marks[2 * count] = pos
                marks[2 * count + 1] = r * k + j
                count += 1
            elif kd == _INT:
                if v < 0:
                    buf[pos] = 45
                    pos += 1
                    v = -v
                pos = _put_uint(buf, pos, v, 0)
            elif kd == _SECONDS:
                pos = _put_uint(buf, pos, v // 1_000_000_000, 0)
                buf[pos] = 46
                pos = _put_uint(buf, pos + 1, v % 1_000_000_000, 9)
        buf[pos] = end
        pos += 1
    return pos, count
