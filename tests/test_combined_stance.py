"""The dual-IMU paper's three-condition stance detector (``footnav.pipeline.stance.combined``)."""

from __future__ import annotations

import numpy as np
from footnav.device.emulator.sensors.dual_imu import simulate_dual_imu
from footnav.pipeline.stance.combined import CombinedDetectorParams, combined_stance


def test_on_emulated_walks_it_calls_no_mid_swing_still_and_finds_most_stances() -> None:
    for course, rate_hz in (("rectangle", 1000.0), ("stairs", 100.0)):
        rec = simulate_dual_imu(course, seed=1, rate_hz=rate_hz)
        still = combined_stance(rec.acc_b_mps2[:, 0], rec.gyr_b_radps[:, 0], rec.rate_hz)
        true_still = rec.truth.imu1.stance
        # no swing sample is called still, but for a few at its ends (the foot slows into a stance on the stairs)
        edge = np.convolve(true_still, np.ones(2 * round(0.05 * rate_hz) + 1), mode="same") > 0
        assert not np.any(still & ~edge), course
        assert np.count_nonzero(still) > 0.7 * np.count_nonzero(true_still), course


def test_each_condition_vetoes_a_still_foot() -> None:
    rate_hz = 100.0
    n = 200
    acc = np.tile([0.0, 0.0, 9.81], (n, 1))
    gyr = np.zeros((n, 3))
    assert combined_stance(acc, gyr, rate_hz).all()
    turning = gyr.copy()
    turning[80:120, 2] = np.radians(60.0)  # C3: faster than 50 °/s
    assert not combined_stance(acc, turning, rate_hz)[85:115].any()
    heavy = acc.copy()
    heavy[80:120, 2] = 11.5  # C1: |a| above 11 m/s²
    assert not combined_stance(heavy, gyr, rate_hz)[85:115].any()
    shaking = acc.copy()
    shaking[80:120:2, 2] = 9.81 + 4.0  # C2: σ of |a| above 3 m/s² (and C1 on every other sample)
    shaking[81:120:2, 2] = 9.81 - 4.0
    assert not combined_stance(shaking, gyr, rate_hz, CombinedDetectorParams(acc_min_mps2=0.0, acc_max_mps2=99.0))[
        85:115
    ].any()


def test_the_median_filter_fills_a_one_sample_gap() -> None:
    acc = np.tile([0.0, 0.0, 9.81], (100, 1))
    gyr = np.zeros((100, 3))
    gyr[50, 0] = 2.0  # one fast sample inside a stance
    assert combined_stance(acc, gyr, 100.0).all()
    assert not combined_stance(acc, gyr, 100.0, CombinedDetectorParams(median_s=0.0))[50]
