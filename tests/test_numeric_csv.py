"""The compiled CSV parser (``footnav.device.files.numeric_csv``) against ``np.loadtxt``: the same values bit for
bit where it reads a file, None where ``np.loadtxt`` must read or refuse it."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from footnav.device.files.numeric_csv import read_plain_rows
from footnav.device.files.recordings import load_recording

FORMATS = ("{:.9g}", "{:.15g}", "{:.6f}", "{:.3e}", "{:.12E}", "{:+.4f}", "{:.0f}")
"""Spellings of values within the fast path: at most 16 significant digits, powers of ten within ±22."""


def _loadtxt(text: str, skip: int = 1) -> np.ndarray:
    return np.loadtxt(io.StringIO(text), delimiter=",", skiprows=skip, ndmin=2)


def _same_bits(a: np.ndarray | None, b: np.ndarray) -> bool:
    return a is not None and a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _values(rng: np.random.Generator, n: int) -> np.ndarray:
    """Values over 12 orders of magnitude and both signs, with zeros, negative zeros and integers among them."""
    v = rng.choice([-1.0, 1.0], n) * rng.uniform(0.1, 10.0, n) * 10.0 ** rng.integers(-5, 7, n)
    v[rng.random(n) < 0.05] = 0.0
    v[rng.random(n) < 0.05] = -0.0
    integers = rng.random(n) < 0.05
    v[integers] = np.round(v[integers])
    return v


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("line_end", ["\n", "\r\n"])
def test_plain_numbers_read_as_loadtxt_reads_them(fmt: str, line_end: str) -> None:
    rng = np.random.default_rng(7)
    table = _values(rng, 4000).reshape(-1, 8)
    text = "t,a,b,c,d,e,f,g" + line_end + line_end.join(",".join(fmt.format(v) for v in row) for row in table)
    for ending in ("", line_end):  # with and without a last line end
        expected = _loadtxt(text + ending)
        assert _same_bits(read_plain_rows((text + ending).encode(), 1), expected)


def test_hand_picked_spellings_read_as_loadtxt_reads_them() -> None:
    rows = [
        "0,-0,+0,-0.0,0.000",
        "1.,.5,-.25,+7,1e3",
        "1E-3,2e+2,-3.5e-07,4.e1,007.50",
        "0.1,0.2,0.3,1e22,1e-22",
        "9007199254740991,123456789012345e-10,0.000000000000000000001,5e-324e0,1",
    ]
    text = "a,b,c,d,e\n" + "\n".join(rows[:-1]) + "\n"
    assert _same_bits(read_plain_rows(text.encode(), 1), _loadtxt(text))
    assert read_plain_rows(("a,b,c,d,e\n" + rows[-1] + "\n").encode(), 1) is None  # '5e-324e0' is not a number


@pytest.mark.parametrize(
    "data_rows",
    [
        "1,2\n# a comment\n3,4\n",  # comments
        "1,2\n\n3,4\n",  # a blank line
        "1, 2\n3,4\n",  # spaces
        '"1",2\n3,4\n',  # quotes
        "1,nan\n3,4\n",  # nan
        "1,inf\n3,4\n",  # inf
        "1,2\n3\n",  # rows of unequal length
        "1,2\n3,4,5\n",
        "1,,2\n",  # an empty field
        "0.12345678901234567,1\n",  # more digits than the fast path's exact integers
        "1e23,1\n",  # a power of ten beyond the exact ones
        "1e-23,1\n",
        "12345678901234567890,1\n",
        "1_000,2\n",  # what Python's float() takes, but no CSV writer writes
        "1.2.3,4\n",
        "1e,2\n",
        "-,2\n",
        "1\r2,3\n",
        "",  # no data rows
    ],
)
def test_anything_else_is_left_to_loadtxt(data_rows: str) -> None:
    assert read_plain_rows(("a,b\n" + data_rows).encode(), 1) is None


def test_a_file_without_a_header_line_end_is_left_to_loadtxt() -> None:
    assert read_plain_rows(b"a,b", 1) is None


def test_a_header_ended_by_a_lone_carriage_return_is_left_to_loadtxt(tmp_path: Path) -> None:
    """``np.loadtxt`` of a path reads text lines, which a lone ``\\r`` ends: the first row is data there."""
    path = tmp_path / "cr.csv"
    path.write_bytes(b"t,a\r1,2\n3,4\n5,6\n")
    assert read_plain_rows(path.read_bytes(), 1) is None
    assert np.loadtxt(path, delimiter=",", skiprows=1).shape == (3, 2)
    assert read_plain_rows(b"t,a\r\n1,2\n3,4\n", 1) is not None  # CR LF is one line end for both


def test_more_fields_than_the_text_can_hold_are_left_to_loadtxt_without_allocating_them() -> None:
    """A first row of 200 000 fields above 200 000 short rows: 4e10 values would need 298 GiB."""
    data = b"a\n" + b"0" + b",0" * 200_000 + b"\n" + b"0,0\n" * 200_000
    assert read_plain_rows(data, 1) is None


def test_a_generic_csv_recording_loads_the_same_values(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    n = 2000
    t = np.arange(n) / 200.0
    imu = rng.standard_normal((n, 6)) * [1, 1, 1, 0.1, 0.1, 0.1] + [0, 0, 9.81, 0, 0, 0]
    path = tmp_path / "walk.csv"
    np.savetxt(path, np.column_stack([t, imu]), delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="", fmt="%.9g")
    rec = load_recording(path)
    expected = np.loadtxt(path, delimiter=",", skiprows=1)
    assert np.array_equal(rec.acc_b_mps2, expected[:, 1:4]) and np.array_equal(rec.gyr_b_radps, expected[:, 4:7])
    assert np.array_equal(rec.t_s, expected[:, 0] - expected[0, 0])
