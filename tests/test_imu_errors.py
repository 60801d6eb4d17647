"""IMU error model: noise levels per grade, biases, the Gauss-Markov drift, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
from footnav.device.emulator.sensors.imu_errors import (
    AXIS_ERRORS,
    ICM20948_PAPER_RANGE,
    IMU_GRADES,
    FullScale,
    ImuGrade,
    corrupt,
    gauss_markov,
)

NOISY_GRADES = [name for name in IMU_GRADES if name != "ideal"]


@pytest.mark.parametrize("name", NOISY_GRADES)
@pytest.mark.parametrize("rate_hz", [1000.0, 819.2])
def test_white_noise_std_matches_density_times_root_half_rate(name: str, rate_hz: float) -> None:
    grade = IMU_GRADES[name]
    zeros = np.zeros((100_000, 3))
    acc, gyr, applied = corrupt(zeros, zeros, rate_hz, grade, seed=11)
    acc_sigma = grade.acc_noise_density_mps2_rthz * math.sqrt(rate_hz / 2)
    gyr_sigma = grade.gyr_noise_density_radps_rthz * math.sqrt(rate_hz / 2)
    assert grade.acc_noise_sigma_mps2(rate_hz) == pytest.approx(acc_sigma)
    np.testing.assert_allclose((acc - applied.acc_bias_b_mps2).std(axis=0), acc_sigma, rtol=0.02)
    np.testing.assert_allclose((gyr - applied.gyr_bias_b_radps).std(axis=0), gyr_sigma, rtol=0.02)
    np.testing.assert_allclose(
        np.abs(applied.acc_noise_b_mps2.mean(axis=0)), 0.0, atol=5 * acc_sigma / math.sqrt(len(zeros))
    )


def test_measurement_is_truth_plus_bias_plus_noise() -> None:
    rng = np.random.default_rng(0)
    truth_acc = rng.normal(size=(5000, 3))
    truth_gyr = rng.normal(size=(5000, 3))
    acc, gyr, applied = corrupt(truth_acc, truth_gyr, 1000.0, "mpu6500x4", seed=2)
    np.testing.assert_allclose(acc, truth_acc + applied.acc_bias_b_mps2 + applied.acc_noise_b_mps2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(
        gyr, truth_gyr + applied.gyr_bias_b_radps + applied.gyr_noise_b_radps, rtol=0, atol=1e-15
    )
    assert applied.acc_bias_b_mps2.shape == applied.gyr_bias_b_radps.shape == (5000, 3)


def test_adis16367_noise_integrates_to_the_datasheet_random_walks() -> None:
    grade = IMU_GRADES["adis16367"]
    rate_hz = 1000.0
    zeros = np.zeros((600_000, 3))
    _, _, applied = corrupt(zeros, zeros, rate_hz, grade, seed=5)
    # Angle / velocity gained over each 1 s window has std N·√(1 s): ARW 2°/√h, VRW 0.2 m/s/√h.
    angle_rad = applied.gyr_noise_b_radps.reshape(-1, 1000, 3).sum(axis=1) / rate_hz
    dvel_mps = applied.acc_noise_b_mps2.reshape(-1, 1000, 3).sum(axis=1) / rate_hz
    assert angle_rad.std() == pytest.approx(math.radians(2.0) / 60.0, rel=0.06)
    assert dvel_mps.std() == pytest.approx(0.2 / 60.0, rel=0.06)


def test_turn_on_bias_spread_across_seeds_matches_the_grade() -> None:
    grade = IMU_GRADES["icm20948"]
    one = np.zeros((1, 3))
    acc_b0 = []
    gyr_b0 = []
    for seed in range(400):
        _, _, applied = corrupt(one, one, 1000.0, grade, seed=seed)
        acc_b0.append(applied.acc_turn_on_bias_b_mps2)
        gyr_b0.append(applied.gyr_turn_on_bias_b_radps)
    assert np.std(acc_b0) == pytest.approx(grade.acc_bias_sigma_mps2, rel=0.08)
    assert np.std(gyr_b0) == pytest.approx(grade.gyr_bias_sigma_radps, rel=0.08)


def test_bias_series_is_turn_on_plus_a_bounded_drift() -> None:
    grade = IMU_GRADES["gx3"]
    zeros = np.zeros((60_000, 3))
    _, _, applied = corrupt(zeros, zeros, 1000.0, grade, seed=9)
    drift = applied.gyr_bias_b_radps - applied.gyr_turn_on_bias_b_radps
    # 60 s of a 100 s-correlated drift: slow (tiny sample-to-sample steps) and of the datasheet size.
    step_sigma = grade.gyr_bias_instability_radps * math.sqrt(2.0 / (1000.0 * grade.bias_correlation_time_s))
    assert np.diff(drift, axis=0).std() == pytest.approx(step_sigma, rel=0.05)
    assert np.abs(drift).max() < 6 * grade.gyr_bias_instability_radps
    assert np.abs(drift).max() > 0.05 * grade.gyr_bias_instability_radps


def test_gauss_markov_has_the_stationary_std_and_correlation() -> None:
    sigma, tau_s, rate_hz = 2.0, 0.05, 1000.0
    seq = gauss_markov(400_000, sigma, tau_s, rate_hz, rng=np.random.default_rng(1), n_axes=2)
    np.testing.assert_allclose(seq.std(axis=0), sigma, rtol=0.03)
    lag1 = [np.corrcoef(seq[:-1, j], seq[1:, j])[0, 1] for j in range(2)]
    np.testing.assert_allclose(lag1, math.exp(-1.0 / (rate_hz * tau_s)), atol=1e-3)
    lag_tau = [np.corrcoef(seq[:-50, j], seq[50:, j])[0, 1] for j in range(2)]
    np.testing.assert_allclose(lag_tau, math.exp(-1.0), atol=0.03)


def test_gauss_markov_matches_the_plain_recursion() -> None:
    n, sigma, tau_s, rate_hz = 3000, 1.5, 0.02, 1000.0  # spans several closed-form blocks
    fast = gauss_markov(n, sigma, tau_s, rate_hz, rng=np.random.default_rng(4), n_axes=3)
    rng = np.random.default_rng(4)
    phi = math.exp(-1.0 / (rate_hz * tau_s))
    drive = sigma * math.sqrt(1.0 - phi**2) * rng.standard_normal((n, 3))
    slow = np.empty((n, 3))
    slow[0] = sigma * rng.standard_normal(3)
    for k in range(1, n):
        slow[k] = phi * slow[k - 1] + drive[k - 1]
    np.testing.assert_allclose(fast, slow, rtol=1e-9, atol=1e-12)


def test_same_seed_same_errors_other_seed_other_errors() -> None:
    zeros = np.zeros((2000, 3))
    a = corrupt(zeros, zeros, 819.2, "mpu6500x4", seed=1)
    b = corrupt(zeros, zeros, 819.2, "mpu6500x4", seed=1)
    c = corrupt(zeros, zeros, 819.2, "mpu6500x4", seed=2)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    np.testing.assert_array_equal(a[2].gyr_bias_b_radps, b[2].gyr_bias_b_radps)
    assert not np.array_equal(a[0], c[0])


def test_grade_by_name_equals_grade_object() -> None:
    zeros = np.zeros((100, 3))
    by_name = corrupt(zeros, zeros, 1000.0, "adis16367", seed=0)
    by_object = corrupt(zeros, zeros, 1000.0, IMU_GRADES["adis16367"], seed=0)
    np.testing.assert_array_equal(by_name[0], by_object[0])


def test_ideal_grade_returns_the_truth() -> None:
    rng = np.random.default_rng(3)
    truth_acc = rng.normal(size=(1000, 3))
    truth_gyr = rng.normal(size=(1000, 3))
    acc, gyr, applied = corrupt(truth_acc, truth_gyr, 1000.0, "ideal", seed=0)
    np.testing.assert_array_equal(acc, truth_acc)
    np.testing.assert_array_equal(gyr, truth_gyr)
    assert not applied.acc_bias_b_mps2.any()


def test_grades_are_ordered_sensibly() -> None:
    mimu, adis = IMU_GRADES["mpu6500x4"], IMU_GRADES["adis16367"]
    # Four averaged MPU-6500s: half of one sensor's 0.01 °/s/√Hz and 300 µg/√Hz.
    assert mimu.gyr_noise_density_radps_rthz == pytest.approx(math.radians(0.005))
    assert mimu.acc_noise_density_mps2_rthz == pytest.approx(150e-6 * 9.80665)
    assert adis.gyr_bias_instability_radps == pytest.approx(math.radians(0.007))
    assert all(isinstance(g, ImuGrade) and g.name == name for name, g in IMU_GRADES.items())


def test_bad_inputs_are_refused() -> None:
    zeros = np.zeros((10, 3))
    with pytest.raises(ValueError, match="unknown IMU grade"):
        corrupt(zeros, zeros, 1000.0, "navigation-grade", seed=0)
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        corrupt(zeros, np.zeros((9, 3)), 1000.0, "ideal", seed=0)
    with pytest.raises(ValueError, match="rate"):
        corrupt(zeros, zeros, 0.0, "ideal", seed=0)


def test_gyroscope_delay_reads_the_true_rate_earlier() -> None:
    rate_hz = 200.0
    t = np.arange(400) / rate_hz
    truth_gyr = np.stack([np.sin(3.0 * t), t, t**2], axis=1)
    zeros = np.zeros_like(truth_gyr)
    _, gyr0, _ = corrupt(zeros, truth_gyr, rate_hz, "ideal", seed=1)
    np.testing.assert_array_equal(gyr0, truth_gyr)  # no delay: unchanged
    acc, gyr, _ = corrupt(zeros, truth_gyr, rate_hz, "ideal", seed=1, gyr_delay_s=0.0075)  # 1.5 samples
    np.testing.assert_array_equal(acc, zeros)  # the accelerometer is not delayed
    # the linear axis is read exactly 7.5 ms earlier (held at the first sample before the start)
    np.testing.assert_allclose(gyr[2:, 1], t[2:] - 0.0075, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gyr[:2, 1], 0.0, atol=1e-12)
    # a negative delay reads ahead; a whole-sample delay is a shift of the samples
    _, ahead, _ = corrupt(zeros, truth_gyr, rate_hz, "ideal", seed=1, gyr_delay_s=-0.01)
    np.testing.assert_allclose(ahead[:-2], truth_gyr[2:], rtol=0, atol=1e-12)
    # the same seed draws the same errors with and without a delay
    _, _, app_a = corrupt(zeros, truth_gyr, rate_hz, "mpu6500x4", seed=3)
    _, _, app_b = corrupt(zeros, truth_gyr, rate_hz, "mpu6500x4", seed=3, gyr_delay_s=0.002)
    np.testing.assert_array_equal(app_a.gyr_noise_b_radps, app_b.gyr_noise_b_radps)
    with pytest.raises(ValueError, match="finite"):
        corrupt(zeros, truth_gyr, rate_hz, "ideal", seed=1, gyr_delay_s=float("nan"))


def test_axis_errors_multiply_the_truth_and_leave_biases_and_noise_as_they_were() -> None:
    rng = np.random.default_rng(3)
    truth_acc = rng.normal(size=(4000, 3))
    truth_gyr = rng.normal(size=(4000, 3))
    plain_acc, plain_gyr, plain = corrupt(truth_acc, truth_gyr, 1000.0, "mpu6500x4", seed=4)
    acc, gyr, applied = corrupt(truth_acc, truth_gyr, 1000.0, "mpu6500x4", seed=4, axes="gyro-bias-calibrated")
    np.testing.assert_array_equal(plain.acc_axes, np.eye(3))
    np.testing.assert_array_equal(applied.gyr_noise_b_radps, plain.gyr_noise_b_radps)
    np.testing.assert_array_equal(applied.acc_bias_b_mps2, plain.acc_bias_b_mps2)
    np.testing.assert_allclose(acc - plain_acc, truth_acc @ (applied.acc_axes - np.eye(3)).T, atol=1e-13)
    np.testing.assert_allclose(gyr - plain_gyr, truth_gyr @ (applied.gyr_axes - np.eye(3)).T, atol=1e-13)


def test_axis_error_spread_across_seeds_matches_the_setting() -> None:
    axes = AXIS_ERRORS["gyro-bias-calibrated"]
    gyr = np.array([axes.draw(seed)[1] for seed in range(300)])
    scale = gyr[:, [0, 1, 2], [0, 1, 2]] - 1.0
    cross = gyr[:, [0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1]]
    assert scale.std() == pytest.approx(axes.gyr_scale_sigma, rel=0.08)
    assert cross.std() == pytest.approx(axes.gyr_cross_axis_sigma, rel=0.08)
    np.testing.assert_array_equal(axes.draw(7)[0], axes.draw(7)[0])
    with pytest.raises(ValueError, match="unknown axis errors"):
        corrupt(np.zeros((2, 3)), np.zeros((2, 3)), 1000.0, "ideal", seed=0, axes="factory")


def test_full_scale_saturates_and_quantises_to_the_adc_step() -> None:
    """±8 g / ±1000 °/s, 16 bits (the dual-IMU paper's ICM-20948 setting): a heel strike of 10 g and a
    1200 °/s swing read full scale, every reading is a whole number of ADC steps, and the counts say
    which samples clipped."""
    fs = ICM20948_PAPER_RANGE
    g = 9.80665
    truth_acc = np.array([[0.0, 0.0, g], [10.0 * g, 0.0, g], [0.0, -9.0 * g, 0.0], [1e-4, 0.0, 0.0]])
    truth_gyr = np.array([[0.0, 0.0, 0.0], [0.0, math.radians(1200.0), 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    acc, gyr, applied = corrupt(truth_acc, truth_gyr, 100.0, "ideal", seed=0, full_scale=fs)
    acc_step, gyr_step = 8.0 * g / 32768.0, math.radians(1000.0) / 32768.0
    assert acc[1, 0] == pytest.approx(8.0 * g) and acc[2, 1] == pytest.approx(-8.0 * g)
    assert gyr[1, 1] == pytest.approx(math.radians(1000.0))
    np.testing.assert_allclose(acc / acc_step, np.round(acc / acc_step), atol=1e-9)
    np.testing.assert_allclose(gyr / gyr_step, np.round(gyr / gyr_step), atol=1e-9)
    assert np.abs(acc - np.clip(truth_acc, -8.0 * g, 8.0 * g)).max() <= acc_step / 2.0 + 1e-12
    assert acc[3, 0] == 0.0  # below half a step
    assert (applied.acc_clipped, applied.gyr_clipped) == (2, 1)
    # without a full scale nothing is clipped or rounded
    plain_acc, _, plain = corrupt(truth_acc, truth_gyr, 100.0, "ideal", seed=0)
    np.testing.assert_array_equal(plain_acc, truth_acc)
    assert (plain.acc_clipped, plain.gyr_clipped) == (0, 0)
    assert FullScale(1.0, 1.0, bits=8).apply(np.full((1, 3), 0.3), np.zeros((1, 3)))[0][0, 0] == 38 / 128


def test_uncalibrated_icm20948_draws_the_datasheet_tolerances() -> None:
    """The dual-IMU paper's parts: DS-000189 typical tolerances as 1σ (±0.5 % / ±2 % accelerometer,
    ±1.5 % / ±2 % gyroscope, ±50 mg board-level zero-g)."""
    axes = AXIS_ERRORS["icm20948-datasheet"]
    acc = np.array([axes.draw(seed)[0] for seed in range(400)])
    gyr = np.array([axes.draw(seed)[1] for seed in range(400)])
    diag, off = [0, 1, 2], ([0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1])
    assert (acc[:, diag, diag] - 1.0).std() == pytest.approx(0.005, rel=0.08)
    assert (gyr[:, diag, diag] - 1.0).std() == pytest.approx(0.015, rel=0.08)
    assert acc[:, off[0], off[1]].std() == pytest.approx(0.02, rel=0.08)
    assert gyr[:, off[0], off[1]].std() == pytest.approx(0.02, rel=0.08)
    zeros = np.zeros((2, 3))
    biases = np.array(
        [corrupt(zeros, zeros, 100.0, "icm20948-board", s)[2].acc_turn_on_bias_b_mps2 for s in range(400)]
    )
    assert biases.std() == pytest.approx(0.050 * 9.80665, rel=0.08)
