"""``footnav export`` and ``footnav evaluate`` from the command line, on real recordings."""

from __future__ import annotations

import csv
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
from footnav.app.commands.export import EXPORT_COLUMNS, STEP_COLUMNS
from footnav.device.files.capture import MCAP_MAGIC


def _footnav(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "footnav.app", *args], capture_output=True, text=True, timeout=300, check=False
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
    trial with a mid-swing "stance", the zero-velocity samples the filter skipped
    (``footnav.pipeline.navigation.eskf``)."""
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
    # the handling of doubtful input, per file: this trial has a 1-sample mid-swing "stance", and its
    # gyroscope clips on the pitch axis (footnav.pipeline.navigation.saturation)
    assert re.search(r"input handling:\n(  .*\n)*  2017-11-22-11-22-03: .*1 zero-velocity samples skipped", proc.stdout)
    assert "82 gyroscope values taken as clipped at the sensor's range (36 raised by the reconstruction" in proc.stdout


def test_evaluate_smoothed_whole_or_step_by_step(shared_data: Path) -> None:
    """``--smooth`` (the whole recording) and ``--step-smoothing`` (each step once it has ended, as a
    --step-smoothing session shows it) take no value, so a path may follow either; not both at once.
    On this slow 2018 trial: causal 0.046 m, step-smoothed 0.023 m, whole 0.024 m (measured 2026-12-02)."""
    trial = str(shared_data / "pyshoe-vicon" / "2018-02-09-11-16-53.mat")
    armse = re.compile(r"ARMSE-2D mean ([\d.]+) m")
    runs = {mode: _footnav("evaluate", *flags, trial) for mode, flags in (
        ("causal", ()), ("whole", ("--smooth",)), ("step", ("--step-smoothing",)))}  # fmt: skip
    values = {}
    for mode, proc in runs.items():
        assert proc.returncode == 0, proc.stderr
        m = armse.search(proc.stdout)
        assert m, proc.stdout
        values[mode] = float(m[1])
    assert values["step"] <= 0.03 and values["whole"] <= 0.03 and values["causal"] >= 0.04
    both = _footnav("evaluate", "--smooth", "--step-smoothing", trial)
    assert both.returncode == 2 and "not allowed with" in both.stderr


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


def _read_steps(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.reader(f))
    assert tuple(rows[0]) == STEP_COLUMNS
    return {name: np.array([float(r[i]) if r[i] else np.nan for r in rows[1:]]) for i, name in enumerate(rows[0])}


def test_export_steps_against_the_motion_capture(tmp_path: Path, shared_data: Path) -> None:
    """``--steps``: OpenShoe's stepwise output from the track. On a PyShoe walking trial the step
    lengths match the motion capture's displacement between the same samples (measured: 23 steps,
    median difference 1.8 cm, 90th percentile 2.8 cm, the largest 6.1 cm on the last, a 13 cm shuffle;
    1.6 % short on average) and the steps add up to the track."""
    from footnav.device.files.recordings import load_recording

    trial = shared_data / "pyshoe-vicon" / "2017-11-22-11-22-03.mat"
    track_path, steps_path = tmp_path / "track.csv", tmp_path / "steps.csv"
    proc = _footnav("export", str(trial), "-o", str(track_path), "--steps", str(steps_path))
    assert proc.returncode == 0, proc.stderr
    assert re.search(r", 23 steps \(\d+ rows\) to ", proc.stdout), proc.stdout
    steps = _read_steps(steps_path)
    track = np.loadtxt(track_path, delimiter=",", skiprows=1)
    index = steps["index"].astype(int)
    walking = steps["is_step"] == 1
    # the epochs' positions and headings are the track's, and each row's displacement is the
    # difference of two epochs in the earlier one's heading frame
    np.testing.assert_allclose(np.column_stack([steps["x"], steps["y"], steps["z"]]), track[index, 1:4], atol=1e-6)
    prev = np.concatenate([[0], index[:-1]])
    yaw0 = np.concatenate([[steps["yaw"][0] - steps["dyaw"][0]], steps["yaw"][:-1]])
    d = track[index, 1:3] - track[prev, 1:3]
    along = np.cos(yaw0) * d[:, 0] + np.sin(yaw0) * d[:, 1]
    np.testing.assert_allclose(along[1:], steps["dx"][1:], atol=1e-6)
    np.testing.assert_allclose(steps["length"], np.hypot(steps["dx"], steps["dy"]), atol=1e-6)
    # against the motion capture (the track starts at the recording's first sample here)
    rec = load_recording(trial)
    assert track[0, 0] == rec.t_s[0]
    gt = rec.gt_pos_m
    gt_length = np.linalg.norm(gt[index, :2] - gt[prev, :2], axis=1)
    error = np.abs(steps["length"] - gt_length)[walking]
    assert np.median(error) < 0.025 and np.quantile(error, 0.9) < 0.035 and error.max() < 0.07
    # the covariance of each step is a covariance: its upper triangle rebuilt is positive semi-definite
    upper = np.triu_indices(4)
    for k in np.flatnonzero(walking):
        c = np.zeros((4, 4))
        c[upper] = [steps[name][k] for name in STEP_COLUMNS[14:]]
        c = c + np.triu(c, 1).T
        assert np.linalg.eigvalsh(c).min() > -1e-12 and c[0, 0] > 0 and c[3, 3] > 0
    assert np.all(steps["duration"][walking] > 0.5) and np.all(steps["clearance_max"][walking] > 0.05)


def test_export_steps_of_a_running_trial_and_of_a_smoothed_track(tmp_path: Path, shared_data: Path) -> None:
    """Running stances last 5-25 ms: each still gives an epoch (0.73 s strides); a smoothed track has
    no step covariance (the smoother gives none between epochs), so those columns are empty."""
    trial = shared_data / "pyshoe-vicon" / "2017-11-27-11-18-11.mat"
    proc = _footnav("export", str(trial), "-o", str(tmp_path / "t.csv"), "--steps", str(tmp_path / "s.csv"), "--smooth")
    assert proc.returncode == 0, proc.stderr
    steps = _read_steps(tmp_path / "s.csv")
    walking = steps["is_step"] == 1
    assert walking.sum() >= 30
    assert 0.6 < np.median(steps["duration"][walking]) < 0.9
    assert np.isnan(steps["c_xx"]).all() and np.isfinite(steps["dx"]).all()
