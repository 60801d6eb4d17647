"""``footnav export`` and ``footnav evaluate`` from the command line, on real recordings."""

from __future__ import annotations

import csv
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from app.export import EXPORT_COLUMNS
from device.capture import MCAP_MAGIC


def _footnav(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "app", *args], capture_output=True, text=True, timeout=300, check=False
    )


def test_export_writes_one_row_per_sample(tmp_path: Path, shared_data: Path) -> None:
    out = tmp_path / "track.csv"
    proc = _footnav("export", str(shared_data / "xio-gait-tracking" / "short_walk.csv"), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    with out.open() as f:
        rows = list(csv.reader(f))
    assert tuple(rows[0]) == EXPORT_COLUMNS
    data = np.array(rows[1:], dtype=float)
    assert data.shape == (16539, len(EXPORT_COLUMNS))
    q = data[:, 7:11]
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    assert set(np.unique(data[:, 11])) == {0.0, 1.0}
    assert (data[:, 12:15] > 0).all()
    np.testing.assert_allclose(data[0, 1:4], 0.0, atol=1e-3)  # origin at the start


def test_export_says_what_it_did_with_doubtful_input(tmp_path: Path, shared_data: Path) -> None:
    """The summary line counts the x-io file's duplicated time stamps (not integrated) and, on the PyShoe
    trial with a mid-swing "stance", the zero-velocity samples the filter skipped (``pipeline.eskf``)."""
    proc = _footnav("export", str(shared_data / "xio-gait-tracking" / "short_walk.csv"), "-o", str(tmp_path / "x.csv"))
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"; \d+ non-positive time steps \(not integrated\)", proc.stdout), proc.stdout
    trial = shared_data / "pyshoe-vicon" / "2017-11-27-11-12-44.mat"
    proc = _footnav("export", str(trial), "-o", str(tmp_path / "p.csv"))
    assert proc.returncode == 0, proc.stderr
    assert "2 zero-velocity samples skipped (the filter saw the foot moving)" in proc.stdout, proc.stdout


def test_export_of_a_wrong_file_names_the_formats(tmp_path: Path) -> None:
    bad = tmp_path / "photo.jpg"
    bad.write_bytes(b"\xff\xd8\xff\xe0garbage")
    proc = _footnav("export", str(bad), "-o", str(tmp_path / "x.csv"))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "expected a PyShoe .mat, an x-io CSV" in proc.stderr


def test_evaluate_prints_a_table_and_summary(shared_data: Path) -> None:
    proc = _footnav(
        "evaluate",
        str(shared_data / "openshoe"),
        str(shared_data / "pyshoe-vicon" / "2017-11-22-11-22-03.mat"),
    )
    assert proc.returncode == 0, proc.stderr
    assert "ARMSE2D" in proc.stdout and "data_inert" in proc.stdout and "2017-11-22-11-22-03" in proc.stdout
    assert "ground truth (1 files)" in proc.stdout and "closed loops (1 files)" in proc.stdout
    # the handling of doubtful input, per file: this trial has a 1-sample mid-swing "stance"
    assert re.search(r"input handling:\n(  .*\n)*  2017-11-22-11-22-03: .*1 zero-velocity samples skipped", proc.stdout)


def test_evaluate_without_the_stance_levels(shared_data: Path) -> None:
    """``--no-stance-levels`` is zero-velocity aiding alone: the x-io loop's height drift comes back
    (3D 0.248 m against 0.051 m with the levels, the horizontal 0.054 against 0.051 m)."""
    loop = shared_data / "xio-gait-tracking" / "short_walk.csv"
    closure = re.compile(r"loop closure 3D mean ([\d.]+) m, 2D mean ([\d.]+) m")
    with_levels, without = _footnav("evaluate", str(loop)), _footnav("evaluate", "--no-stance-levels", str(loop))
    assert with_levels.returncode == 0 and without.returncode == 0, without.stderr
    m1, m0 = closure.search(with_levels.stdout), closure.search(without.stdout)
    assert m1 and m0
    assert float(m1[1]) <= 0.06 and float(m0[1]) > 0.2
    assert abs(float(m1[2]) - float(m0[2])) < 0.02  # the horizontal barely moves


def test_export_of_a_capture_refuses_no_stance_levels(tmp_path: Path) -> None:
    capture = tmp_path / "session.mcap"
    capture.write_bytes(MCAP_MAGIC + b"\x00" * 64)
    proc = _footnav("export", str(capture), "-o", str(tmp_path / "x.csv"), "--no-stance-levels")
    assert proc.returncode != 0 and "--no-stance-levels" in proc.stderr
