"""Recordings that start in motion: every sample navigated, the lead-in before the first still period
backwards in time from it (``footnav.pipeline.navigation.lead_in``), on an emulated walk against its truth
and on the real PyShoe trials."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from footnav.app.commands.export import lead_in_note, navigate_recording, run_export
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.device.files.recordings import load_recording
from footnav.pipeline.metrics import ate
from footnav.pipeline.navigation.lead_in import _onto_forward, heading_difference, navigate_every_sample
from footnav.pipeline.navigation.navigator import NavConfig, NavStats, navigate
from footnav.pipeline.navigation.profiles import get_profile
from footnav.pipeline.navigation.quaternion import quat_from_euler_zyx
from footnav.pipeline.smoothing.rts import smooth_recording
from footnav.pipeline.smoothing.stepwise import step_smooth_recording

RATE_HZ = 1000.0
CONFIG = NavConfig(profile=get_profile("mpu6500x4"))
CUT = 3300
"""The emulated walk stands for its first 3 s: cut 3.3 s off and it starts in mid-stride; its first
still period is then the rest after the last stride, and almost all of it is lead-in."""
RUNS = {"causal": navigate, "whole": smooth_recording, "step": step_smooth_recording}


@pytest.fixture(scope="module")
def walk():  # type: ignore[no-untyped-def]
    truth = simulate_walk("rectangle", 40.0, rate_hz=RATE_HZ, seed=3)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, RATE_HZ, "mpu6500x4", seed=3)
    return truth, acc, gyr


@pytest.mark.parametrize("mode", sorted(RUNS))
def test_a_walk_that_starts_in_motion_is_navigated_from_its_first_sample(walk, mode: str) -> None:  # type: ignore[no-untyped-def]
    """Measured (seed 3, 47.5 m, 35 354 of 36 700 samples lead-in), causal / whole / step: position error
    at most 2.0 / 1.8 / 2.0 cm, velocity RMS 1.0 / 0.7 / 0.8 cm/s, heading within 0.07°."""
    truth, acc, gyr = walk
    t = truth.t_s[CUT:]
    nav, stats = navigate_every_sample(t, acc[CUT:], gyr[CUT:], RATE_HZ, CONFIG, run=RUNS[mode])
    assert nav is not None
    s = stats.samples_navigated_backwards
    assert len(nav) == t.size and stats.samples_out == t.size
    assert s == stats.samples_before_alignment > 0.9 * t.size
    np.testing.assert_array_equal(nav.t_s, t)
    # the forward estimates are those of the run alone, bit for bit
    forward, _ = RUNS[mode](t, acc[CUT:], gyr[CUT:], RATE_HZ, CONFIG)
    assert forward is not None
    np.testing.assert_array_equal(nav.pos_n_m[s:], forward.pos_n_m)
    # the truth in the track's frame: its origin and heading are the track's at the first still sample
    psi = heading_difference(nav.quat_nb_wxyz[s], truth.quat_nb_wxyz[CUT + s])
    c, si = math.cos(psi), math.sin(psi)
    rot = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
    pos = (truth.pos_n_m[CUT:] - truth.pos_n_m[CUT + s]) @ rot.T + nav.pos_n_m[s]
    err = np.linalg.norm(nav.pos_n_m - pos, axis=1)[:s]
    assert err.max() < 0.03  # 0.06 % of the distance
    vel_err = np.linalg.norm(nav.vel_n_mps - truth.vel_n_mps[CUT:] @ rot.T, axis=1)[:s]
    assert math.sqrt(np.mean(vel_err**2)) < 0.02  # not negated back, it would be the walking speed
    yaw_err = [heading_difference(nav.quat_nb_wxyz[k], truth.quat_nb_wxyz[CUT + k]) - psi for k in range(0, s, 100)]
    assert np.max(np.abs(yaw_err)) < math.radians(0.2)
    # the covariance grows away from the still period, and the error stays within it
    var = np.trace(nav.pos_cov_n_m2, axis1=1, axis2=2)[:s]
    assert math.sqrt(var[0]) > 20 * math.sqrt(var[-1])
    assert np.mean(err**2 > 9 * var) < 0.01
    yaw_var = nav.cov_pos_yaw[:s, 3, 3]
    assert yaw_var[0] > yaw_var[-1]


def test_the_backward_track_is_turned_and_moved_onto_the_forward_one(walk) -> None:  # type: ignore[no-untyped-def]
    """A lead-in given in another frame (turned by 40° and moved, velocities reversed, last sample first)
    comes back in the forward track's frame."""
    truth, acc, gyr = walk
    nav, stats = navigate_every_sample(truth.t_s[CUT:], acc[CUT:], gyr[CUT:], RATE_HZ, CONFIG)
    assert nav is not None and nav.cov_pos_yaw is not None
    s = stats.samples_navigated_backwards
    psi = math.radians(40.0)
    c, si = math.cos(psi), math.sin(psi)
    rot = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
    t4 = np.eye(4)
    t4[:3, :3] = rot
    w, x, y, z = nav.quat_nb_wxyz[s::-1].T  # (cos ψ/2, 0, 0, sin ψ/2) ⊗ q
    cz, sz = math.cos(psi / 2), math.sin(psi / 2)
    cov = t4 @ nav.cov_pos_yaw[s::-1] @ t4.T
    backward = dataclasses.replace(
        nav,
        t_s=nav.t_s[s::-1],
        pos_n_m=nav.pos_n_m[s::-1] @ rot.T + [5.0, -2.0, 0.3],
        vel_n_mps=-nav.vel_n_mps[s::-1] @ rot.T,
        quat_nb_wxyz=np.column_stack([cz * w - sz * z, cz * x - sz * y, cz * y + sz * x, cz * z + sz * w]),
        pos_cov_n_m2=cov[:, :3, :3],
        cov_pos_yaw=cov,
        stance=nav.stance[s::-1],
        detector_stat=nav.detector_stat[s::-1],
        detector_threshold=nav.detector_threshold[s::-1],
        clearance_m=nav.clearance_m[s::-1],
        host_ns=nav.host_ns[s::-1],
    )
    forward = dataclasses.replace(nav, pos_n_m=nav.pos_n_m[s:], quat_nb_wxyz=nav.quat_nb_wxyz[s:])
    lead_in = _onto_forward(backward, 0, forward, nav.t_s[:s])
    np.testing.assert_allclose(lead_in.pos_n_m, nav.pos_n_m[:s], rtol=0, atol=1e-9)
    np.testing.assert_allclose(lead_in.vel_n_mps, nav.vel_n_mps[:s], rtol=0, atol=1e-12)
    sign = np.sign(np.sum(lead_in.quat_nb_wxyz * nav.quat_nb_wxyz[:s], axis=1))[:, None]
    np.testing.assert_allclose(lead_in.quat_nb_wxyz * sign, nav.quat_nb_wxyz[:s], rtol=0, atol=1e-12)
    assert lead_in.cov_pos_yaw is not None
    np.testing.assert_allclose(lead_in.cov_pos_yaw, nav.cov_pos_yaw[:s], rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(lead_in.stance, nav.stance[:s])


def test_a_recording_that_starts_still_is_navigated_as_before(walk) -> None:  # type: ignore[no-untyped-def]
    truth, acc, gyr = walk
    nav, stats = navigate_every_sample(truth.t_s, acc, gyr, RATE_HZ, CONFIG)
    alone, stats_alone = navigate(truth.t_s, acc, gyr, RATE_HZ, CONFIG)
    assert nav is not None and alone is not None
    assert stats.samples_before_alignment == stats.samples_navigated_backwards == 0
    np.testing.assert_array_equal(nav.pos_n_m, alone.pos_n_m)
    np.testing.assert_array_equal(nav.pos_cov_n_m2, alone.pos_cov_n_m2)
    assert stats == stats_alone


def test_the_heading_difference_is_the_turn_about_the_vertical() -> None:
    for roll, pitch in ((0.0, 0.0), (3.0, 0.3), (-0.5, 1.2)):
        a = quat_from_euler_zyx(roll, pitch, 2.5)
        b = quat_from_euler_zyx(roll, pitch, -1.0)
        assert heading_difference(a, b) == pytest.approx(3.5 - 2 * math.pi, abs=1e-12)


def test_the_summary_says_what_became_of_the_samples_before_the_first_still_period() -> None:
    assert lead_in_note(NavStats()) == ""
    both = lead_in_note(NavStats(samples_before_alignment=52, samples_navigated_backwards=40))
    assert both == (
        ", 40 samples before the first still period navigated backwards from it"
        ", 12 samples before the first still period not navigated"
    )


def test_export_writes_one_row_per_sample_of_every_pyshoe_trial(tmp_path: Path, shared_data: Path) -> None:
    """Before the lead-in was navigated, 2017-11-22-11-49-29 (it stands for less than the 0.5 s of an
    alignment, then walks for 7.2 s) wrote 9 676 rows of its 11 121 samples."""
    trials = sorted((shared_data / "pyshoe-vicon").glob("*.mat"))
    assert len(trials) == 9
    summaries = {}
    for trial in trials:
        out = tmp_path / f"{trial.stem}.csv"
        summaries[trial.stem] = run_export(trial, out, fmt=None, columns=None, profile=None, smooth=None)
        rows = out.read_text().count("\n") - 1  # the header
        assert rows == len(load_recording(trial)), trial.name
    lead_ins = {name for name, text in summaries.items() if "navigated backwards" in text}
    assert lead_ins == {"2017-11-22-11-49-29"}
    assert "1445 samples before the first still period navigated backwards from it" in summaries["2017-11-22-11-49-29"]
    assert not any("not navigated" in text for text in summaries.values())


@pytest.mark.parametrize("smooth", [None, "whole", "step"])
def test_the_lead_in_of_a_pyshoe_trial_against_the_motion_capture(shared_data: Path, smooth: str | None) -> None:
    """2017-11-22-11-49-29's 7.2 s lead-in (9 m, 8 stances), in the frame the forward track is fitted in
    (yaw and translation on the samples after the lead-in): measured 2D error mean 0.081 / 0.078 / 0.078 m
    (causal / whole / step), against 0.034 m after it; the whole track's ATE-2D 0.047 / 0.045 / 0.045 m."""
    rec = load_recording(shared_data / "pyshoe-vicon" / "2017-11-22-11-49-29.mat")
    assert rec.gt_pos_m is not None
    nav, stats = navigate_recording(rec, smooth=smooth)
    s = stats.samples_navigated_backwards
    assert s == 1445 and len(nav) == len(rec)
    fit = ate(nav.pos_n_m[s:], rec.gt_pos_m[s:], mirror_test=False)
    c, si = math.cos(fit.yaw_rad), math.sin(fit.yaw_rad)
    rot = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
    moved = (nav.pos_n_m - nav.pos_n_m[s:].mean(axis=0)) @ rot.T + rec.gt_pos_m[s:].mean(axis=0)
    err = np.linalg.norm((moved - rec.gt_pos_m)[:, :2], axis=1)
    assert err[:s].mean() < 0.1 and err[:s].max() < 0.25
    assert ate(nav.pos_n_m, rec.gt_pos_m, mirror_test=False).rmse_2d_m < 0.055
