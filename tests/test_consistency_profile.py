"""The consistency benchmark's "emulated" profile holds exactly the emulator's error model."""

from __future__ import annotations

import math

import pytest
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES
from footnav.pipeline.navigation.navigator import filter_parameters
from footnav.pipeline.navigation.profiles import get_profile

from benchmarks.consistency import profile_of_grade


@pytest.mark.parametrize("rate_hz", [200.0, 1000.0])
def test_per_sample_noise_and_bias_terms_match_the_emulator(rate_hz: float) -> None:
    grade = IMU_GRADES["mpu6500x4"]
    profile = profile_of_grade(grade, get_profile("mpu6500x4"))
    par = filter_parameters(profile, rate_hz, 9.80665, 0.05)
    assert par.sig_acc == pytest.approx(grade.acc_noise_sigma_mps2(rate_hz), rel=1e-12)
    assert par.sig_gyr == pytest.approx(grade.gyr_noise_sigma_radps(rate_hz), rel=1e-12)
    assert par.acc_scale == 0.0 and par.gyr_scale == 0.0
    # the Gauss-Markov drift's driving density: its variance grows 2 σ² t / τ for t ≪ τ
    tau = grade.bias_correlation_time_s
    assert par.bg_rw**2 * tau == pytest.approx(2.0 * grade.gyr_bias_instability_radps**2, rel=1e-12)
    assert profile.gyr_bias_init_radps == pytest.approx(
        math.hypot(grade.gyr_bias_sigma_radps, grade.gyr_bias_instability_radps)
    )
