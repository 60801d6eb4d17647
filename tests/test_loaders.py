"""Loaders of other tools' recordings: real files from ../shared/data, and bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from footnav.device.files.recordings import CsvMapping, detect_format, load_generic_csv, load_recording
from footnav.pipeline.errors import InputFormatError

G0 = 9.80665


def _rest_norm(rec) -> float:  # type: ignore[no-untyped-def]
    return float(np.linalg.norm(rec.acc_b_mps2[:50].mean(axis=0)))


def test_pyshoe_mat(shared_data: Path) -> None:
    path = shared_data / "pyshoe-vicon" / "2017-11-22-11-22-03.mat"
    assert detect_format(path) == "pyshoe"
    rec = load_recording(path)
    assert len(rec) == 6490 and rec.rate_hz == pytest.approx(200, rel=0.01)
    assert rec.gt_pos_m is not None and rec.gt_pos_m.shape == (6490, 3)
    assert _rest_norm(rec) == pytest.approx(G0, abs=0.3)  # already m/s²
    assert any("left-handed" in n for n in rec.notes)
    from scipy.io import loadmat

    raw_gt = loadmat(str(path))["gt"]
    np.testing.assert_allclose(rec.gt_pos_m[:, 1], -raw_gt[:, 1])  # mirrored into a right-handed frame


def test_xio_csv(shared_data: Path) -> None:
    rec = load_recording(shared_data / "xio-gait-tracking" / "short_walk.csv")
    assert rec.format == "xio" and rec.closed_loop
    assert _rest_norm(rec) == pytest.approx(G0, abs=0.3)  # g -> m/s²
    assert rec.rate_hz == pytest.approx(400, rel=0.05)
    assert (np.diff(rec.t_s) <= 0).sum() > 0  # duplicated stamps are kept as recorded


def test_openshoe_txt(shared_data: Path) -> None:
    rec = load_recording(shared_data / "openshoe" / "data_inert.txt")
    assert rec.format == "openshoe" and rec.closed_loop
    assert rec.rate_hz == pytest.approx(250, rel=0.02)
    assert _rest_norm(rec) == pytest.approx(G0, abs=0.3)
    assert np.abs(rec.gyr_b_radps[:50]).max() < 0.1  # rad/s at rest


def test_generic_csv_with_mapping(tmp_path: Path) -> None:
    n = 100
    t_ms = np.arange(n) * 5.0
    rows = np.column_stack([t_ms, np.zeros(n), np.zeros(n), np.ones(n), np.full(n, 10.0), np.zeros(n), np.zeros(n)])
    path = tmp_path / "walk.csv"
    np.savetxt(path, rows, delimiter=",", header="ts,ax,ay,az,wx,wy,wz", comments="")
    rec = load_generic_csv(path, CsvMapping.parse("time=ts:ms,acc=ax;ay;az:g,gyr=wx;wy;wz:deg/s,profile=gx3"))
    assert rec.rate_hz == pytest.approx(200.0)
    np.testing.assert_allclose(rec.acc_b_mps2[0], [0, 0, G0])
    np.testing.assert_allclose(rec.gyr_b_radps[0, 0], np.radians(10.0))
    assert rec.profile == "gx3"


def test_generic_csv_names_missing_columns(tmp_path: Path) -> None:
    path = tmp_path / "x.csv"
    path.write_text("time,a,b\n0,1,2\n1,1,2\n")
    with pytest.raises(InputFormatError, match="columns t, ax"):
        load_generic_csv(path)


def test_unknown_file_names_the_expected_formats(tmp_path: Path) -> None:
    path = tmp_path / "notes.txt"
    path.write_text("hello\n")
    with pytest.raises(InputFormatError, match=r"PyShoe \.mat, an x-io CSV, an OpenShoe"):
        load_recording(path)


def test_truncated_mat_is_a_format_error(tmp_path: Path, shared_data: Path) -> None:
    src = (shared_data / "pyshoe-vicon" / "2017-11-22-11-22-03.mat").read_bytes()
    path = tmp_path / "cut.mat"
    path.write_bytes(src[:2000])
    with pytest.raises(InputFormatError, match="PyShoe"):
        load_recording(path)
