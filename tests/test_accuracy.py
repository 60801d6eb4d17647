"""Accuracy with the one default configuration: real recordings and long emulated walks.

The real-data bounds guard against regressions at the level measured when they were written (see the
README's accuracy table); the issue's targets are tighter and are reported by ``footnav evaluate``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from footnav.app.commands.evaluate import format_table, run_evaluate
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.pipeline.navigation.navigator import NavConfig, navigate
from footnav.pipeline.navigation.profiles import get_profile


@pytest.fixture(scope="module")
def evaluations(shared_data: Path):  # type: ignore[no-untyped-def]
    rows, problems = run_evaluate([shared_data])
    print(format_table(rows))
    assert not problems
    return {r.name: r for r in rows}


def test_pyshoe_vicon_trials(evaluations) -> None:  # type: ignore[no-untyped-def]
    armse = np.array([r.armse_2d_m for r in evaluations.values() if r.format == "pyshoe"])
    assert armse.size == 9
    # measured 0.067 / 0.058 / 0.130 m (mean / median / max); 0.072 / 0.063 / 0.169 without the rate
    # noise of clipped gyro samples (footnav.pipeline.navigation.saturation), 0.070 / 0.063 / 0.156 with the earlier
    # choice of the stretches to reconstruct as well, 0.073 / 0.068 / 0.156 without the gate of
    # unsure zero-velocity samples (footnav.pipeline.navigation.eskf), 0.079 / 0.065 / 0.157 with the ZARU gate
    # testing against the update's noise instead of the gyroscope's (footnav.pipeline.navigation.eskf), 0.078 / 0.065 /
    # 0.157 with the ZUPT's vertical noise not following the detector's T/γ too, 0.081 / 0.069 / 0.157
    # with the ZARU gate at 99 % (footnav.pipeline.navigation.navigator) too, 0.094 / 0.069 / 0.270 without the
    # debounce's hysteresis (footnav.pipeline.stance.detectors) too, 0.100 / 0.075 / 0.282 without reconstructing the
    # saturated gyro stretches as well (footnav.pipeline.navigation.saturation)
    assert armse.mean() <= 0.069 and armse.max() <= 0.15
    # pyshoe with one fixed threshold averages 2.29 m on this dataset (DATA.md)
    assert np.median(armse) <= 0.062
    # ATE-3D after a yaw + translation fit: mean 0.086 m (0.102 before the clipped-rate noise); 0.149
    # without the stance height constraint (footnav.pipeline.stance.levels), 0.164 with a hard vertical ZUPT too
    ate_3d = np.array([r.ate_3d_m for r in evaluations.values() if r.format == "pyshoe"])
    assert ate_3d.mean() <= 0.10


def test_pyshoe_vicon_trials_smoothed(shared_data: Path) -> None:
    """The issue's 0.06 m mean ARMSE-2D, with the RTS smoother of replay and evaluation
    (``footnav evaluate --smooth``): measured 0.059 / 0.048 / 0.120 m (mean / median / max)."""
    rows, problems = run_evaluate([shared_data / "pyshoe-vicon"], smooth="whole")
    assert not problems
    armse = np.array([r.armse_2d_m for r in rows])
    assert armse.size == 9
    assert armse.mean() <= 0.060 and np.median(armse) <= 0.05 and armse.max() <= 0.13


def test_pyshoe_vicon_trials_step_smoothed(shared_data: Path) -> None:
    """Live, each step smoothed once the foot stands again, as a live session shows it
    (``footnav.pipeline.smoothing.stepwise``, ``footnav evaluate --step-smoothing``): measured 0.0600 (0.06004) /
    0.051 / 0.118 m (mean / median / max), the causal filter 0.0670, the whole smoother 0.0592
    (2026-12-02; 0.0599, 0.0669 and 0.0591 before a standing foot's turn entered the zero-rate update,
    ``footnav.pipeline.navigation.eskf``: it meets the issue's 0.06 m to its stated precision, not below it)."""
    rows, problems = run_evaluate([shared_data / "pyshoe-vicon"], smooth="step")
    assert not problems
    armse = np.array([r.armse_2d_m for r in rows])
    assert armse.size == 9
    assert armse.mean() <= 0.0605 and np.median(armse) <= 0.052 and armse.max() <= 0.12


def test_clipped_rates_are_navigated_as_uncertain(shared_data: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The running trial clips its pitch and yaw rates 390 times: with their rotation uncertain along
    the clipped axes (``footnav.pipeline.navigation.saturation``) 0.130 m, without that noise 0.169 m."""
    import footnav.pipeline.navigation.saturation as saturation_module
    from footnav.app.commands.evaluate import evaluate_file

    path = shared_data / "pyshoe-vicon" / "2017-11-27-11-18-11.mat"
    uncertain = evaluate_file(path)
    monkeypatch.setattr(saturation_module, "CLIPPED_RATE_SIGMA_SHARE", 0.0)
    trusted = evaluate_file(path)
    assert uncertain.armse_2d_m <= 0.14 and trusted.armse_2d_m >= 0.16


def test_a_mid_swing_stance_is_not_taken(shared_data: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """2017-11-27-11-12-44 has a 2-sample "stance" in mid-swing (the foot at 1.9 m/s, the filter knows
    it): the zero-velocity gate of unsure samples skips it (``footnav.pipeline.navigation.eskf``), 0.070 → 0.044 m."""
    import footnav.pipeline.navigation.navigator as navigator_module
    from footnav.app.commands.evaluate import evaluate_file

    path = shared_data / "pyshoe-vicon" / "2017-11-27-11-12-44.mat"
    gated = evaluate_file(path)
    monkeypatch.setattr(navigator_module, "ZUPT_GATE_NIS", float("inf"))
    ungated = evaluate_file(path)
    assert gated.armse_2d_m <= 0.05 and ungated.armse_2d_m >= 0.06


def test_closed_loops(evaluations) -> None:  # type: ignore[no-untyped-def]
    xio, openshoe = evaluations["short_walk"], evaluations["data_inert"]
    # measured 3D / 2D (2026-12-02): x-io 0.057 / 0.057 m, OpenShoe 0.041 / 0.041 m; before a standing
    # foot's turn about the vertical entered the zero-rate update (footnav.pipeline.navigation.eskf) 0.050 / 0.050 and
    # 0.097 / 0.097 m.
    assert xio.loop_2d_m <= 0.06 and xio.loop_3d_m <= 0.06  # the 0.06 m in 3D
    assert openshoe.loop_2d_m <= 0.07 and openshoe.loop_3d_m <= 0.07  # the 0.07 m in 3D


@pytest.mark.parametrize("path", ["rectangle", "figure8"])
def test_emulated_walk_of_several_minutes(path: str) -> None:
    truth = simulate_walk(path, 240.0, rate_hz=1000.0, seed=0)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=7)
    nav, stats = navigate(truth.t_s, acc, gyr, truth.rate_hz, NavConfig(profile=get_profile("mpu6500x4")))
    assert nav is not None and stats.samples_before_alignment == 0
    error_m = float(np.linalg.norm(nav.pos_n_m[-1] - truth.pos_n_m[-1]))
    assert truth.distance_m > 250
    assert error_m / truth.distance_m <= 0.003  # issue 4: at most 0.3 % of distance


def test_stairs_have_no_false_zero_velocity_in_swing() -> None:
    """The ballistic middle of a stair swing looks like rest to any inertial statistic for a few ms."""
    truth = simulate_walk("stairs", 60.0, rate_hz=1000.0, seed=0)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=1)
    nav, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, NavConfig(profile=get_profile("mpu6500x4")))
    assert nav is not None
    speed = np.linalg.norm(truth.vel_n_mps[-len(nav) :], axis=1)
    assert speed[nav.stance].max() < 0.1
    assert np.linalg.norm(nav.pos_n_m[-1] - truth.pos_n_m[-1]) / truth.distance_m <= 0.003


def test_stairs_with_error_free_signals_keep_their_height() -> None:
    """Zero-velocity aiding alone on the emulator's exact signals: what is left is the stance labels'
    timing against the motion. Stance samples inside the heel-strike transient took the foot down
    about 2 mm per stride (final height error −15 mm after 60 s) while the ZUPT's vertical noise did
    not follow the detector's T/γ (footnav.pipeline.navigation.eskf); −1.7 mm since."""
    truth = simulate_walk("stairs", 60.0, rate_hz=1000.0, seed=0)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "ideal", seed=0)
    nav, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, NavConfig(profile=get_profile("mpu6500x4")))
    assert nav is not None
    assert abs(nav.pos_n_m[-1, 2] - truth.pos_n_m[-1, 2]) <= 0.005
