"""The compiled track writer (``footnav.device.files.table_csv``) writes the bytes of the writer it replaced:
``csv.writer`` rows of ``f"{v:.9g}"`` (``int`` for the stance), kept here as the reference."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np
import pytest
from footnav.app.commands.export import EXPORT_COLUMNS, navigate_recording, write_track_csv
from footnav.device.files.recordings import load_recording
from footnav.device.files.table_csv import format_rows, write_table_csv
from footnav.pipeline.nav_types import NavBatch
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray


def reference_rows(table: NDArray[np.float64], integer: frozenset[int] = frozenset()) -> bytes:
    """The writer before the compiled one: ``csv.writer`` over a Python formatting of each value."""
    buf = io.StringIO(newline="")
    csv.writer(buf).writerows([int(v) if i in integer else f"{v:.9g}" for i, v in enumerate(row)] for row in table)
    return buf.getvalue().encode("ascii")


def reference_track_csv(nav: NavBatch, path: Path) -> None:
    """``write_track_csv`` as it was (inertial track: no clearance columns)."""
    var = np.diagonal(nav.pos_cov_n_m2, axis1=1, axis2=2)
    table = np.column_stack([nav.t_s, nav.pos_n_m, nav.vel_n_mps, nav.quat_nb_wxyz, nav.stance.astype(np.float64), var])
    stance_col = EXPORT_COLUMNS.index("stance")
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(EXPORT_COLUMNS)
        writer.writerows([int(v) if i == stance_col else f"{v:.9g}" for i, v in enumerate(row)] for row in table)


def test_a_real_recordings_track_is_written_byte_for_byte_as_before(shared_data: Path, tmp_path: Path) -> None:
    nav, _ = navigate_recording(load_recording(shared_data / "pyshoe-vicon" / "2017-11-27-11-12-44.mat"))
    assert nav.floor_z_m is None  # an inertial unit: the columns the reference writes
    reference_track_csv(nav, tmp_path / "old.csv")
    write_track_csv(nav, tmp_path / "new.csv")
    old, new = (tmp_path / "old.csv").read_bytes(), (tmp_path / "new.csv").read_bytes()
    assert old.count(b"\r\n") == len(nav) + 1
    assert new == old


SPECIAL = [
    0.0,
    -0.0,
    math.nan,
    math.inf,
    -math.inf,
    5e-324,
    1.7976931348623157e308,
    1e-5,
    1e-4,
    0.0001234567895,
    99999999.95,
    999999999.5,
    100000000.5,  # an exact half at the ninth digit: rounded by Python (half to even)
    100000001.5,
    123456789012.0,
    -2.5e-17,
    1e22,
    1e23,
]


def test_values_at_the_edges_of_the_format_are_written_as_python_formats_them() -> None:
    table = np.array(SPECIAL).reshape(-1, 1)
    assert format_rows(table) == reference_rows(table)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=3, max_size=3), min_size=1, max_size=40),
    st.lists(st.integers(-(10**6), 10**6), min_size=1, max_size=1),
)
def test_any_floats_are_written_as_python_formats_them(rows: list[list[float]], ints: list[int]) -> None:
    table = np.column_stack([np.array(rows), np.full(len(rows), float(ints[0]))])
    assert format_rows(table, frozenset({3})) == reference_rows(table, frozenset({3}))


def test_many_scales_and_rounded_values_match() -> None:
    rng = np.random.default_rng(7)
    values = np.concatenate(
        [
            rng.normal(size=50_000) * 10.0 ** rng.integers(-30, 30, 50_000),
            np.round(rng.normal(size=20_000) * 1000, 3),
            rng.integers(-(10**6), 10**6, 20_000).astype(float),
        ]
    )
    table = values.reshape(-1, 3)
    assert format_rows(table) == reference_rows(table)


def test_an_unwritable_path_is_a_footnav_error(tmp_path: Path) -> None:
    from footnav.pipeline.errors import FootnavError

    with pytest.raises(FootnavError, match="cannot write"):
        write_table_csv(tmp_path / "missing" / "t.csv", ("a",), np.zeros((1, 1)))
