"""The data rows of a CSV of plain decimal numbers, parsed by a compiled kernel with the values ``np.loadtxt`` gives.

``np.loadtxt`` took 0.15 s of a 10-minute recording's export (120 000 rows of 7 values) and parses each value
through Python's string-to-float conversion. Here a plain number (``[+-]digits[.digits][e[+-]digits]``) is read as
an integer ``m`` of its digits and a power of ten ``k``; when ``m < 2**53`` and ``|k| <= 22`` both are exact doubles
and one multiplication or division rounds correctly (Clinger, "How to read floating point numbers accurately",
PLDI 1990, the fast path), so the value is bit for bit the correctly rounded one that ``np.loadtxt`` gives. Anything
else in the text (a comment, a blank line, spaces, quotes, ``nan``, 17 significant digits, rows of unequal length, a
lone ``\\r`` ending a skipped line, which ``np.loadtxt`` takes for a line end) makes :func:`read_plain_rows` return
None, and the caller reads the file with ``np.loadtxt``, which parses it or says what is wrong
(tests/test_numeric_csv.py compares both bit for bit).
"""

from __future__ import annotations

import numpy as np
from footnav.pipeline.jit import njit
from numpy.typing import NDArray

_POW10 = np.array([float(10**k) for k in range(23)])
"""The powers of ten that are exact doubles."""
_MAX_DIGITS = 18
"""Significant digits an int64 holds for certain; more is left to ``np.loadtxt``."""
_EXACT_INT = float(2**53)


@njit(cache=True, error_model="numpy", inline="always")
def _digits(text, pos):  # type: ignore[no-untyped-def]
    """``[digits][.digits]`` at ``text[pos:]`` as ``(m, power, pos after)``, value ``m * 10**power``; ``pos`` -1:
    no digit, or more significant digits than :data:`_MAX_DIGITS`."""
    n = text.shape[0]
    m = 0
    digits = 0
    power = 0
    seen = False
    point = False
    while pos < n:
        c = text[pos]
        if c == 46 and not point:  # .
            point = True
        elif 48 <= c <= 57:
            if m > 0 or c > 48:
                if digits == _MAX_DIGITS:
                    return 0, 0, -1
                m = m * 10 + (c - 48)
                digits += 1
            power -= 1 if point else 0
            seen = True
        else:
            break
        pos += 1
    return m, power, pos if seen else -1


@njit(cache=True, error_model="numpy", inline="always")
def _exponent(text, pos):  # type: ignore[no-untyped-def]
    """``[e[+-]digits]`` at ``text[pos:]`` as ``(exponent, pos after)``; ``pos`` -1: an ``e`` without digits."""
    n = text.shape[0]
    if pos >= n or (text[pos] != 101 and text[pos] != 69):  # e E
        return 0, pos
    pos += 1
    sign = 1
    if pos < n and (text[pos] == 45 or text[pos] == 43):  # - +
        sign = -1 if text[pos] == 45 else 1
        pos += 1
    e = 0
    start = pos
    while pos < n and 48 <= text[pos] <= 57 and e < 10_000:
        e = e * 10 + (text[pos] - 48)
        pos += 1
    return sign * e, pos if pos > start else -1


@njit(cache=True, error_model="numpy", inline="always")
def _number(text, pos):  # type: ignore[no-untyped-def]
    """A plain number at ``text[pos:]`` as ``(value, pos after)``; ``pos`` -1: not one, or not on the fast path."""
    negative = False
    if pos < text.shape[0] and (text[pos] == 45 or text[pos] == 43):  # - +
        negative = text[pos] == 45
        pos += 1
    m, power, pos = _digits(text, pos)
    if pos < 0:
        return 0.0, -1
    e, pos = _exponent(text, pos)
    power += e
    if m == 0:
        v = 0.0
    elif m >= _EXACT_INT or power > 22 or power < -22:
        return 0.0, -1
    elif power >= 0:
        v = m * _POW10[power]
    else:
        v = m / _POW10[-power]
    return (-v if negative else v), pos


@njit(cache=True, error_model="numpy", inline="always")
def _after(text, pos, byte):  # type: ignore[no-untyped-def]
    """The position after ``byte`` at ``text[pos]`` (a line end: ``\\n``, ``\\r\\n`` or the end), or -1."""
    n = text.shape[0]
    if byte == 10:
        if pos < n and text[pos] == 13:
            pos += 1
            if pos >= n:
                return -1
        if pos >= n:
            return pos
    if pos < n and text[pos] == byte:
        return pos + 1
    return -1


@njit(cache=True, error_model="numpy")
def _parse_rows(text, pos, out):  # type: ignore[no-untyped-def]
    """Rows of ``out.shape[1]`` plain numbers from ``text[pos:]`` (uint8) into ``out``; returns the rows read, or -1
    at the first byte that is not part of such a row (or beyond ``out``'s rows)."""
    rows, cols = out.shape
    i = 0
    while pos < text.shape[0]:
        if i == rows:
            return -1
        for j in range(cols):
            out[i, j], pos = _number(text, pos)
            if pos >= 0:
                pos = _after(text, pos, 44 if j < cols - 1 else 10)  # , or a line end
            if pos < 0:
                return -1
        i += 1
    return i


def read_plain_rows(data: bytes, skip: int) -> NDArray[np.float64] | None:
    """The rows after the first ``skip`` lines of ``data`` as an (N, C) array, C the first row's fields, when
    every row holds C plain decimal numbers separated by commas (``\\n`` or ``\\r\\n`` line ends); otherwise None
    (read it with ``np.loadtxt``)."""
    text = np.frombuffer(data, np.uint8)
    all_ends = np.flatnonzero(text == 10)
    if all_ends.size < skip:
        return None
    start = int(all_ends[skip - 1]) + 1 if skip else 0
    returns = np.flatnonzero(text[:start] == 13)
    if np.any(text[returns + 1] != 10):  # a lone \r ends a line for np.loadtxt too: lines are counted otherwise
        return None
    line_ends = all_ends[skip:] - start
    first = text[start:]
    first_row = first[: line_ends[0]] if line_ends.size else first
    if first_row.size == 0:
        return None
    cols = int(np.count_nonzero(first_row == 44)) + 1
    if line_ends.size * cols > (first.size + 1) // 2:  # more values than the text can hold: not such rows
        return None
    out = np.empty((line_ends.size + 1, cols))
    rows = _parse_rows(text, start, out)
    return None if rows <= 0 else out[:rows]


def build_kernel() -> None:
    """Compile the parser (by reading two rows)."""
    read_plain_rows(b"t,a\n0,1.5\n1e-3,-2\n", 1)
