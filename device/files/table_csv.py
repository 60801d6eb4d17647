"""A table of numbers to CSV fast: the bytes Python's ``csv.writer`` writes for ``f"{v:.9g}"`` of each value.

``footnav export`` writes one row per sample (120 000 rows for ten minutes at 200 Hz); formatting each value in
Python took most of the export's time. Here the values are formatted by a compiled kernel: each one is scaled to
nine significant digits with a single correctly rounded multiplication or division by an exact power of ten, and
the few whose rounding that cannot decide (within 1e-6 of a half, or beyond the exact powers of ten) are formatted
by Python's own ``format`` instead, so every value's text is the one ``f"{v:.9g}"`` gives (tests/test_csv_writer.py
compares the files byte for byte with ``csv.writer``'s).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.jit import njit
from numpy.typing import NDArray

_CHUNK_ROWS = 16384
_POW10 = np.array([10.0**k for k in range(23)])


@njit(cache=True, error_model="numpy", inline="always")
def _nine_digits(a: float) -> tuple[int, int]:
    """``a > 0`` rounded to nine significant digits as ``(m, x)``, ``a ≈ m * 10**(x - 8)`` with ``m`` of nine
    digits; ``m`` is 0 when that rounding is not certain (within 1e-6 of a half) or needs a power of ten beyond
    10**22 (inexact), for Python to format."""
    # a in [2**(e - 1), 2**e): the decimal exponent is this or one more (the loop settles it)
    x = math.floor((math.frexp(a)[1] - 1) * 0.30102999566398120)
    for _ in range(4):
        k = 8 - x
        if k > 22 or k < -22:
            return 0, 0
        s = a * _POW10[k] if k >= 0 else a / _POW10[-k]  # one correctly rounded operation: error <= 1.2e-7 here
        if s < 1e8:
            x -= 1
        elif s >= 1e9:
            x += 1
        else:
            r = math.floor(s)
            f = s - r
            if abs(f - 0.5) < 1e-6:
                return 0, 0
            m = int(r) + (1 if f > 0.5 else 0)
            if m == 1_000_000_000:
                return 100_000_000, x + 1
            return m, x
    return 0, 0


@njit(cache=True, error_model="numpy", inline="always")
def _put_int(out: NDArray[np.uint8], pos: int, n: int, min_digits: int) -> int:
    """The decimal digits of ``n >= 0`` (at least ``min_digits``) at ``out[pos:]``; returns the position after."""
    width = 1
    p = 10
    while p <= n:
        width += 1
        p *= 10
    width = max(width, min_digits)
    for w in range(width - 1, -1, -1):
        out[pos + w] = 48 + n % 10
        n //= 10
    return pos + width


@njit(cache=True, error_model="numpy", inline="always")
def _put_digits(out, end, m, nd, point):  # type: ignore[no-untyped-def]
    """The ``nd`` digits of ``m`` ending before ``out[end]``, a point before the last ``point`` of them (none: 0)."""
    p = end - 1
    for w in range(nd):
        if w == point and point > 0:
            out[p] = 46  # .
            p -= 1
        out[p] = 48 + m % 10
        m //= 10
        p -= 1


@njit(cache=True, error_model="numpy", inline="always")
def _put_fast(out, pos, negative, m, x):  # type: ignore[no-untyped-def]
    """``f"{v:.9g}"`` of a value ``±m * 10**(x - 8)`` (``m`` of nine digits) at ``out[pos:]``; returns the position
    after."""
    nd = 9
    while nd > 1 and m % 10 == 0:
        m //= 10
        nd -= 1
    if negative:
        out[pos] = 45  # -
        pos += 1
    if 0 <= x < 9:
        if nd <= x + 1:  # an integer: its digits, then zeros
            _put_digits(out, pos + nd, m, nd, 0)
            for w in range(pos + nd, pos + x + 1):
                out[w] = 48
            return pos + x + 1
        _put_digits(out, pos + nd + 1, m, nd, nd - x - 1)
        return pos + nd + 1
    if -4 <= x < 0:
        out[pos] = 48
        out[pos + 1] = 46
        pos += 2
        for _ in range(-x - 1):
            out[pos] = 48
            pos += 1
        _put_digits(out, pos + nd, m, nd, 0)
        return pos + nd
    width = nd + 1 if nd > 1 else 1
    _put_digits(out, pos + width, m, nd, nd - 1)
    pos += width
    out[pos] = 101  # e
    out[pos + 1] = 45 if x < 0 else 43  # - or +
    return _put_int(out, pos + 2, abs(x), 2)


@njit(cache=True, error_model="numpy", inline="always")
def _put_word(out, pos, w0, w1, w2):  # type: ignore[no-untyped-def]
    out[pos], out[pos + 1], out[pos + 2] = w0, w1, w2
    return pos + 3


@njit(cache=True, error_model="numpy", inline="always")
def _put_value(out, pos, v, integer):  # type: ignore[no-untyped-def]
    """``f"{v:.9g}"`` (``int(v)`` when ``integer``) at ``out[pos:]``; returns the position after, or -1: left to
    Python."""
    if integer:
        if not abs(v) < 1e18:
            return -1
        if v <= -1.0:
            out[pos] = 45
            pos += 1
        return _put_int(out, pos, int(abs(v)), 1)
    if math.isnan(v):
        return _put_word(out, pos, 110, 97, 110)  # nan
    if v == 0.0:
        if math.copysign(1.0, v) < 0:
            out[pos] = 45
            pos += 1
        out[pos] = 48
        return pos + 1
    a = abs(v)
    if a == np.inf:
        if v < 0:
            out[pos] = 45
            pos += 1
        return _put_word(out, pos, 105, 110, 102)  # inf
    m, x = _nine_digits(a)
    if m == 0:
        return -1
    return _put_fast(out, pos, v < 0, m, x)


@njit(cache=True, error_model="numpy")
def _render(values, integer, out, slow_at, slow_index):  # type: ignore[no-untyped-def]
    """Every row's text into ``out``, but for the values left to Python: their flat index in ``slow_index`` and
    where their text goes in ``slow_at``; returns the bytes written and the number left."""
    rows, cols = values.shape
    pos = 0
    q = 0
    for i in range(rows):
        for j in range(cols):
            end = _put_value(out, pos, values[i, j], integer[j])
            if end < 0:
                slow_at[q] = pos
                slow_index[q] = i * cols + j
                q += 1
            else:
                pos = end
            if j < cols - 1:
                out[pos] = 44  # ,
                pos += 1
        out[pos] = 13
        out[pos + 1] = 10
        pos += 2
    return pos, q


def format_rows(table: NDArray[np.float64], integer_columns: frozenset[int] = frozenset()) -> bytes:
    """The CSV text of ``table``'s rows, as ``csv.writer`` writes them (``\\r\\n`` line ends) for each value
    ``f"{v:.9g}"``, or ``int(v)`` in ``integer_columns``."""
    values = np.ascontiguousarray(table, dtype=np.float64)
    if values.ndim != 2:
        raise ValueError(f"a table has two dimensions, got {values.ndim}")
    if values.size == 0:
        return b"\r\n" * len(values)
    cols = values.shape[1]
    integer = np.array([j in integer_columns for j in range(cols)])
    out = np.empty(values.size * 24 + len(values) * 2, np.uint8)
    slow_at = np.empty(values.size, np.int64)
    slow_index = np.empty(values.size, np.int64)
    n, slow = _render(values, integer, out, slow_at, slow_index)
    if not slow:
        return out[:n].tobytes()
    flat = values.ravel()
    parts, start = [], 0
    for at, q in zip(slow_at[:slow].tolist(), slow_index[:slow].tolist(), strict=True):
        v = float(flat[q])
        parts += [out[start:at].tobytes(), (str(int(v)) if q % cols in integer_columns else f"{v:.9g}").encode()]
        start = at
    parts.append(out[start:n].tobytes())
    return b"".join(parts)


def build_kernel() -> None:
    """Compile the renderer (by formatting one row with an integer column): the argument types of every call."""
    format_rows(np.zeros((1, 2)), frozenset({1}))


def write_table_csv(
    path: Path, header: tuple[str, ...], table: NDArray[np.float64], integer_columns: frozenset[int] = frozenset()
) -> None:
    """``header`` and the rows of ``table`` (:func:`format_rows`) to ``path``.

    Raises
    ------
    FootnavError
        the file cannot be written.
    """
    try:
        with path.open("wb") as f:
            f.write((",".join(header) + "\r\n").encode("utf-8"))
            for a in range(0, len(table), _CHUNK_ROWS):
                f.write(format_rows(table[a : a + _CHUNK_ROWS], integer_columns))
    except OSError as exc:
        raise FootnavError(f"cannot write {path}: {exc.strerror}") from None
