"""``footnav replay`` of recordings from other tools: the real recordings reach the viewer, read back
from the ``.rrd`` written, with the same track ``footnav export`` writes."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from footnav.app.commands.replay_recording import truth_on_estimate
from rerun.chunk import RrdReader


def _footnav(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "footnav.app", *args], capture_output=True, text=True, timeout=300, check=False
    )


def _positions(rrd: Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(times, s; positions, m) of ``entity``'s rows, one per time on the ``imu_time`` timeline."""
    store = RrdReader(rrd).stream().collect()
    table = store.reader(index="imu_time", contents=[entity]).to_arrow_table()
    t_s = table["imu_time"].cast("int64").to_numpy() / 1e9
    return t_s, np.array(table[f"{entity}:Points3D:positions"].to_pylist())[:, 0, :]


def test_an_xio_recording_reaches_the_viewer_as_export_navigates_it(tmp_path: Path, shared_data: Path) -> None:
    recording = shared_data / "xio-gait-tracking" / "short_walk.csv"
    rrd, track_csv = tmp_path / "xio.rrd", tmp_path / "track.csv"
    proc = _footnav("replay", str(recording), "--no-viewer", "--save", str(rrd))
    assert proc.returncode == 0, proc.stderr
    assert "samples navigated: 16539 of 16539" in proc.stdout
    assert _footnav("export", str(recording), "-o", str(track_csv)).returncode == 0
    with track_csv.open() as f:
        exported = np.array(list(csv.reader(f))[1:], dtype=float)
    # the file repeats 205 time stamps: the viewer keeps one row per time, so compare the others
    times, counts = np.unique(exported[:, 0], return_counts=True)
    once = np.isin(exported[:, 0], times[counts == 1])
    t_s, shown = _positions(rrd, "/world/foot/track")
    assert len(t_s) == len(times) > 16_000
    after = np.clip(np.searchsorted(t_s, exported[once, 0]), 1, len(t_s) - 1)
    nearest = np.where(
        np.abs(t_s[after] - exported[once, 0]) < np.abs(t_s[after - 1] - exported[once, 0]), after, after - 1
    )
    assert np.abs(t_s[nearest] - exported[once, 0]).max() < 1e-6  # the CSV's times have 9 digits
    shown_once = shown[nearest]
    np.testing.assert_allclose(shown_once, exported[once, 1:4], atol=1e-6)  # the same track (9 digits in the CSV)


def test_a_pyshoe_trial_shows_its_motion_capture_truth_on_the_track(tmp_path: Path, shared_data: Path) -> None:
    rrd = tmp_path / "pyshoe.rrd"
    proc = _footnav("replay", str(shared_data / "pyshoe-vicon" / "2017-11-22-11-22-03.mat"), "--smooth",
                    "--no-viewer", "--save", str(rrd))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    (_, track), (_, truth) = _positions(rrd, "/world/foot/track"), _positions(rrd, "/world/truth/foot")
    assert track.shape == truth.shape
    rms_2d = float(np.sqrt(np.mean(np.sum((track[:, :2] - truth[:, :2]) ** 2, axis=1))))
    assert rms_2d < 0.1, rms_2d  # the evaluation's ATE-2D of this trial is a few cm


def test_truth_on_estimate_inverts_a_turn_and_a_shift() -> None:
    rng = np.random.default_rng(3)
    est = np.cumsum(rng.normal(size=(500, 3)), axis=0)
    c, s = np.cos(0.7), np.sin(0.7)
    gt = est @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T + np.array([4.0, -2.0, 0.5])
    np.testing.assert_allclose(truth_on_estimate(est, gt), est, atol=1e-9)
    mirrored = gt * np.array([1.0, -1.0, 1.0])
    np.testing.assert_allclose(truth_on_estimate(est, mirrored), est, atol=1e-9)


@pytest.mark.parametrize(
    ("option", "needle"),
    [
        (["--start", "3"], "--start does not apply"),
        (["--speed", "1x", "--without-tof"], "--speed, --without-tof do not apply"),
    ],
)
def test_capture_options_are_refused_for_a_recording(option: list[str], needle: str, shared_data: Path) -> None:
    proc = _footnav("replay", str(shared_data / "xio-gait-tracking" / "short_walk.csv"), *option, "--no-viewer")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "a recording from another tool" in proc.stderr and needle in proc.stderr


def test_recording_options_are_refused_for_a_capture(tmp_path: Path) -> None:
    proc = _footnav("demo", "--duration", "6", "--pace", "max", "--no-viewer", "--sessions", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    capture = next(tmp_path.glob("*.mcap"))
    proc = _footnav("replay", str(capture), "--smooth", "--no-viewer")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "a footnav capture" in proc.stderr and "--smooth does not apply" in proc.stderr


def test_a_file_of_no_known_kind_names_every_kind(tmp_path: Path) -> None:
    path = tmp_path / "notes.bin"
    path.write_bytes(b"hello")
    proc = _footnav("replay", str(path), "--no-viewer")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "unknown recording format" in proc.stderr and "a footnav capture (.mcap)" in proc.stderr
