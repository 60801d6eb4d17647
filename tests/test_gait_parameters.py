"""Gait parameters per stride (``footnav.pipeline.gait.parameters``): the definitions on a track built by
hand, then measured against the emulator's truth and the PyShoe motion capture through the Python API."""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from footnav.app import gait_parameters, navigate, read_recording
from footnav.app.api.gait_export import GAIT_COLUMNS
from footnav.app.commands.demo import DemoOptions, run_demo
from footnav.app.commands.export import run_export
from footnav.app.config import defaults
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.gait.parameters import (
    MAX_STRIDE_S,
    _filled_stance,
    footfalls,
    stance_ends,
    stride_parameters,
    summarize,
)
from numpy.typing import NDArray

F64 = NDArray[np.float64]
RATE_HZ = 100.0


def _walk(strides: list[tuple[float, float, float, float]]) -> tuple[F64, F64, F64, NDArray[np.bool_], F64]:
    """A track by hand: 1 s standing, then per stride a stance and a swing (stance s, swing s, forward m,
    heading change rad), the swing moving the foot along a half-sine bump 2 cm to the left and 10 cm up;
    1 s standing at the end. Returns t, pos, quat, stance, clearance."""
    pos, yaw, stance = [np.zeros(3)], [0.0], [True]

    def stand(seconds: float) -> None:
        for _ in range(round(seconds * RATE_HZ)):
            pos.append(pos[-1])
            yaw.append(yaw[-1])
            stance.append(True)

    stand(1.0)
    for stance_s, swing_s, forward_m, turn_rad in strides:
        stand(stance_s)
        start, heading = pos[-1], yaw[-1]
        ahead = np.array([math.cos(heading), math.sin(heading), 0.0])
        left = np.array([-ahead[1], ahead[0], 0.0])
        n = round(swing_s * RATE_HZ)
        for k in range(1, n + 1):
            u = k / n
            bump = math.sin(math.pi * u)
            pos.append(start + forward_m * u * ahead + 0.02 * bump * left + [0.0, 0.0, 0.10 * bump])
            yaw.append(heading + turn_rad * u)
            stance.append(False)
    stand(1.0)
    p = np.array(pos)
    y = np.array(yaw)
    quat = np.column_stack([np.cos(y / 2), np.zeros_like(y), np.zeros_like(y), np.sin(y / 2)])
    return np.arange(p.shape[0]) / RATE_HZ, p, quat, np.array(stance), p[:, 2].copy()


def test_a_stride_runs_from_footfall_to_footfall_with_its_phases_length_and_turn() -> None:
    plan = [(0.4, 0.6, 1.2, 0.0), (0.4, 0.6, 1.3, 0.2), (0.5, 0.7, 1.1, -0.1), (0.4, 0.6, 1.2, 0.0)]
    t, pos, quat, stance, clearance = _walk(plan)
    s = stride_parameters(t, pos, quat, stance, clearance)
    # four swings: footfalls at the end of each; three strides between them
    assert len(s) == 3
    np.testing.assert_allclose(s.duration_s, [0.4 + 0.6, 0.5 + 0.7, 0.4 + 0.6], atol=1e-9)
    np.testing.assert_allclose(s.swing_s, [0.6, 0.7, 0.6], atol=1e-9)
    np.testing.assert_allclose(s.stance_s, [0.4, 0.5, 0.4], atol=1e-9)
    np.testing.assert_allclose(s.stance_share + s.swing_share, 1.0)
    np.testing.assert_allclose(s.cadence_spm, 120.0 / s.duration_s)
    np.testing.assert_allclose(s.length_m, [1.3, 1.1, 1.2], atol=1e-9)  # the swing that ends each stride
    np.testing.assert_allclose(s.speed_mps, s.length_m / s.duration_s)
    np.testing.assert_allclose(s.turning_rad, [0.2, -0.1, 0.0], atol=1e-9)
    np.testing.assert_allclose(s.lateral_m, 0.02, atol=2e-4)  # the bump's 2 cm, sampled
    np.testing.assert_allclose(s.max_clearance_m, 0.10, atol=2e-4)
    # the mid-swing minimum of a single bump lies at a quarter of the swing: 10 cm × sin(π/4)
    np.testing.assert_allclose(s.min_clearance_m, 0.10 * math.sin(math.pi / 4), atol=3e-3)
    assert np.isnan(s.turning_sd_rad).all()  # no covariance given
    np.testing.assert_array_equal(t[s.end_index[:-1]], t[s.start_index[1:]])


def test_flicker_is_stance_a_pause_is_no_stride_and_shuffling_is_left_out() -> None:
    t, pos, quat, stance, clearance = _walk(
        [(0.4, 0.6, 1.2, 0.0), (0.4, 0.6, 1.2, 0.0), (MAX_STRIDE_S, 0.6, 1.2, 0.0), (0.4, 0.6, 0.03, 0.0)]
    )
    falls = footfalls(t, stance)
    assert falls.size == 4
    flicker = stance.copy()
    middle = falls[1] + 20
    flicker[middle : middle + 5] = False  # 50 ms of the detector letting go in mid-stance
    np.testing.assert_array_equal(footfalls(t, flicker), falls)
    assert _filled_stance(t, flicker, 0.15)[middle]
    s = stride_parameters(t, pos, quat, flicker, clearance)
    # stride 2 holds a stance of MAX_STRIDE_S (a pause); stride 3 moves the foot 3 cm
    assert len(s) == 1 and s.start_index[0] == falls[0]
    np.testing.assert_array_equal(stance_ends(stance, falls[:2]), falls[:2] + np.array([40, 250]) - 1)
    np.testing.assert_array_equal(stance_ends(stance, falls[:2] - 1), falls[:2] - 1)  # in no stance: itself
    np.testing.assert_array_equal(s.start_pos_index, (falls[0] + stance_ends(stance, falls[:1])) // 2)


def test_spatial_parameters_are_taken_in_mid_stance_or_at_the_footfalls() -> None:
    t, pos, quat, stance, clearance = _walk([(0.4, 0.6, 1.2, 0.0)] * 3)
    falls = footfalls(t, stance)
    pos = pos.copy()
    for k in falls:  # the foot slides 1 cm forward as it lands
        pos[k : k + 5, 0] -= np.linspace(0.01, 0.002, 5)
    middle = stride_parameters(t, pos, quat, stance, clearance)
    at_falls = stride_parameters(t, pos, quat, stance, clearance, at="footfall")
    np.testing.assert_allclose(middle.length_m, 1.2, atol=1e-9)
    np.testing.assert_allclose(at_falls.length_m, 1.2, atol=1e-9)  # each footfall 1 cm short: no change
    pos[falls[-1], 0] += 0.05  # a jump at the last footfall alone
    assert stride_parameters(t, pos, quat, stance, clearance, at="footfall").length_m[-1] == pytest.approx(1.25)
    assert stride_parameters(t, pos, quat, stance, clearance).length_m[-1] == pytest.approx(1.2)


def test_the_summary_is_mean_sample_sd_and_cv() -> None:
    plan = [(0.4, 0.6, length, 0.0) for length in (1.0, 1.2, 1.4, 1.3, 1.1)]
    t, pos, quat, stance, clearance = _walk(plan)
    s = stride_parameters(t, pos, quat, stance, clearance)
    summary = summarize(s)
    lengths = s.length_m
    np.testing.assert_allclose(lengths, [1.2, 1.4, 1.3, 1.1], atol=1e-9)
    assert summary["length_m"].mean == pytest.approx(lengths.mean())
    assert summary["length_m"].sd == pytest.approx(np.std(lengths, ddof=1))
    assert summary["length_m"].cv == pytest.approx(np.std(lengths, ddof=1) / lengths.mean())
    assert math.isnan(summary["turning_rad"].cv)
    assert math.isnan(summarize(stride_parameters(t[:300], pos[:300], quat[:300], stance[:300], clearance[:300]))[
        "length_m"
    ].mean)  # fmt: skip


def _true_clearance(stance: NDArray[np.bool_], z: F64) -> F64:
    """Height above the last stance, as ``NavBatch.clearance_m`` is without ToF sensors."""
    last = np.maximum.accumulate(np.where(stance, np.arange(stance.size), 0))
    return z - z[last]


@pytest.mark.parametrize("course", ["rectangle", "stairs"])
def test_emulated_walks_against_their_truth(course: str) -> None:
    """Measured (seed 0, 120 s, mpu6500x4 errors, causal filter), rectangle / stairs: stride length error
    −0.5 / −0.4 mm mean, 2.3 / 1.5 mm at most; duration against the true footfalls 0.0 ± 2.6 / 4.7 ms (7 /
    23 ms at most); turning angle 0.2 / 0.3 mrad at most. The detector's stance is 85 / 88 ms longer than the
    emulator's exactly-still one, a stance share 0.080 / 0.078 over the true 0.36: its footfall comes 51 / 54
    ms before the still phase (the emulator's 40 ms heel-strike transient, not still, passes the detector) and
    its toe-off 34 ms after (the foot leaves the ground gently: its first millimetres per second look still)."""
    truth = simulate_walk(course, 120.0, rate_hz=1000.0, seed=0)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=7)
    result = navigate(acc, gyr, truth.t_s, profile="mpu6500x4")
    s = gait_parameters(result)
    true_clear = _true_clearance(truth.stance, truth.pos_n_m[:, 2])
    true_events = stride_parameters(truth.t_s, truth.pos_n_m, truth.quat_nb_wxyz, truth.stance, true_clear)
    assert len(s) == len(true_events) == truth.n_strides - 1
    early = true_events.start_s - s.start_s  # the same strides: the detector's footfall comes first
    assert early.min() > 0.035 and early.max() < 0.075
    np.testing.assert_array_less(np.abs(s.duration_s - true_events.duration_s), 0.03)
    assert np.std(s.duration_s - true_events.duration_s) < 0.006
    shift = s.stance_share - true_events.stance_share
    assert 0.06 < shift.mean() < 0.10 and shift.std() < 0.01
    # the same strides' quantities from the true motion: the navigation's error alone
    falls = footfalls(result.t_s, result.stance)
    same = stride_parameters(truth.t_s, truth.pos_n_m, truth.quat_nb_wxyz, result.stance, true_clear, falls=falls)
    np.testing.assert_array_equal(same.start_index, s.start_index)
    assert np.abs(s.length_m - same.length_m).max() < 0.004
    assert np.abs(s.speed_mps - same.speed_mps).max() < 0.004
    assert np.abs(s.turning_rad - same.turning_rad).max() < 0.001
    assert np.abs(s.lateral_m - same.lateral_m).max() < 0.004
    clearance_error = np.abs(s.max_clearance_m - same.max_clearance_m)
    # on stairs the floor of the stance left is the truth's and the estimate's alike, except in the three strides
    # where a flight turns (measured 0.7 mm at the 95th percentile, 0.21 m in those three)
    assert np.percentile(clearance_error, 95) < 0.002 and np.count_nonzero(clearance_error > 0.01) <= 3
    assert np.nanpercentile(np.abs(s.min_clearance_m - same.min_clearance_m), 95) < 0.002
    # heading uncertainty: the growth of the filter's variance; it is conservative here (measured: the errors'
    # RMS is 0.09 σ), as the profile's process noise covers more than the emulated sensor's errors
    z = (s.turning_rad - same.turning_rad) / s.turning_sd_rad
    assert np.all(np.isfinite(z)) and np.sqrt(np.mean(z**2)) < 1.0


def _speed_footfalls(t_s: F64, gt_pos_m: F64, below_mps: float = 0.3) -> NDArray[np.intp]:
    """Footfalls of the motion capture: where the marker's speed (over 50 ms) drops below ``below_mps``."""
    speed = np.linalg.norm(np.gradient(gt_pos_m, t_s, axis=0), axis=1)
    smooth = np.convolve(speed, np.ones(10) / 10, mode="same")
    return footfalls(t_s, smooth < below_mps)


def test_pyshoe_motion_capture(shared_data: Path) -> None:
    """The 9 PyShoe VICON trials (walking, running, stairs), causal filter: stride length against the motion
    capture's positions at the same samples, −33 mm mean, 35 mm SD, 48 mm RMS, 184 mm at most (205 strides;
    the RTS smoother: −30 / 32 / 44 mm); the tracks are 2-6 % short of the motion capture's in every trial
    (a scale fitted per trial, 0.94-0.99), which is the mean. Duration against the footfalls of the
    capture (marker speed under 0.3 m/s), matched within 0.2 s: −0.8 ms mean, 45 ms SD (163 strides)."""
    length_errors, duration_errors = [], []
    for path in sorted((shared_data / "pyshoe-vicon").glob("*.mat")):
        rec = read_recording(path)
        assert rec.gt_pos_m is not None
        s = gait_parameters(navigate(rec))
        true_length = np.linalg.norm(rec.gt_pos_m[s.end_pos_index, :2] - rec.gt_pos_m[s.start_pos_index, :2], axis=1)
        length_errors.append(s.length_m - true_length)
        falls_t = rec.t_s[_speed_footfalls(rec.t_s, rec.gt_pos_m)]
        k = np.clip(np.searchsorted(falls_t, s.start_s), 1, falls_t.size - 1)
        k -= np.abs(falls_t[k - 1] - s.start_s) < np.abs(falls_t[k] - s.start_s)
        ok = (np.abs(falls_t[k] - s.start_s) < 0.2) & (k + 1 < falls_t.size)
        ok[ok] &= np.abs(falls_t[k[ok] + 1] - s.end_s[ok]) < 0.2
        duration_errors.append(s.duration_s[ok] - (falls_t[k[ok] + 1] - falls_t[k[ok]]))
    length_error = np.concatenate(length_errors)
    duration_error = np.concatenate(duration_errors)
    assert length_error.size > 200 and duration_error.size > 150
    assert -0.04 < length_error.mean() < -0.025 and np.sqrt(np.mean(length_error**2)) < 0.052
    assert abs(duration_error.mean()) < 0.005 and duration_error.std() < 0.05


def test_export_writes_a_row_per_stride_and_prints_the_summary(tmp_path: Path) -> None:
    """``footnav export --gait``: the strides of ``gait_parameters(navigate(read_recording(...)))``, and a
    summary line of mean ± SD and CV."""
    truth = simulate_walk("rectangle", 40.0, rate_hz=200.0, seed=5)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=6)
    walk = tmp_path / "walk.csv"
    np.savetxt(walk, np.column_stack([truth.t_s, acc, gyr]), delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="")
    columns = "time=t:s,acc=ax;ay;az:m/s2,gyr=gx;gy;gz:rad/s,profile=mpu6500x4"
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "export", str(walk), "--columns", columns, "-o", str(tmp_path / "t.csv"),
         "--gait", str(tmp_path / "g.csv")],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    expected = gait_parameters(navigate(read_recording(walk, columns=columns)))
    with (tmp_path / "g.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == GAIT_COLUMNS and len(rows) == len(expected) > 20
    for name, values in expected.columns().items():
        np.testing.assert_allclose([float(r[name]) for r in rows], values, rtol=1e-8)
    summary = summarize(expected)["length_m"]
    line = proc.stdout.splitlines()[-1]
    assert (
        line.startswith(f"gait (mean ± SD, CV): {len(expected)} strides; length ") and str(tmp_path / "g.csv") in line
    )
    assert f"length {summary.mean:.3f} ± {summary.sd:.3f} m, {100 * summary.cv:.1f} %;" in line


def test_a_two_feet_capture_exports_each_foots_strides(tmp_path: Path) -> None:
    """A footnav capture (the live estimates, replayed): a gait file and a summary line per foot."""
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    assert run_demo(DemoOptions(duration_s=20.0, viewer=False, realtime=math.inf, feet=2, config=cfg)) == 0
    (capture,) = tmp_path.glob("*.mcap")
    out = run_export(capture, tmp_path / "t.csv", fmt=None, columns=None, profile=None, smooth=None,
                     gait_out=tmp_path / "g.csv")  # fmt: skip
    lines = out.splitlines()
    assert [line.split(" (")[0] for line in lines[1:]] == ["gait left", "gait right"], out
    for foot in ("left", "right"):
        with (tmp_path / f"g-{foot}.csv").open() as f:
            rows = list(csv.DictReader(f))
        assert len(rows) >= 8
        lengths = np.array([float(r["length_m"]) for r in rows])
        assert 1.1 < np.median(lengths) < 1.7  # the emulated walk's strides
        assert all(r["turning_sd_rad"] for r in rows)  # the causal filter's: with its uncertainty
    # the Python API reads a capture's samples, one foot at a time, and navigates them as a recording
    with pytest.raises(FootnavError, match="holds the feet left, right"):
        read_recording(capture)
    rec = read_recording(capture, foot="right")
    assert rec.format == "capture" and rec.name.endswith("-right") and rec.profile == "mpu6500x4"
    assert 19.0 < rec.t_s[-1] - rec.t_s[0] < 21.0 and rec.rate_hz == pytest.approx(1000.0, rel=1e-3)
    strides = gait_parameters(navigate(rec))
    assert len(strides) >= 8 and 1.1 < np.median(strides.length_m) < 1.7
