"""The dual-IMU board in the emulator: rigid-body truth (lever-arm terms), independent errors, one lap,
and the two-IMU 0x28 stream through the real device layer into footnav's dual filter."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from footnav.device.emulator.motion import paths
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.dual_imu import (
    DEFAULT_LEVER_B_M,
    angular_acceleration,
    rigid_board,
    simulate_dual_imu,
)
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.modes import RawImuMode
from footnav.device.protocol import raw_imu
from footnav.device.protocol.raw_imu import RawImuBatch
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.dual_imu.board_eskf import run_dual_eskf
from footnav.pipeline.dual_imu.model import quat_to_mats
from footnav.pipeline.stance.detectors import DetectorParams, StreamingDetector
from test_gait import _strapdown
from test_modes_emulated import gather, of


def test_imu2_strapdown_reproduces_p1_plus_rotated_lever_arm() -> None:
    truth = simulate_walk("rectangle", 20.0, seed=2)
    m = np.array([0.01, 0.01, 0.0])
    board = rigid_board(truth, m)
    R = quat_to_mats(truth.quat_nb_wxyz)
    np.testing.assert_allclose(board.pos2_n_m, truth.pos_n_m + R @ m, atol=1e-12)
    imu2 = dataclasses.replace(
        truth, pos_n_m=board.pos2_n_m, vel_n_mps=board.vel2_n_mps, acc_b_mps2=board.acc_b_mps2[:, 1]
    )
    pos, vel, _ = _strapdown(imu2)
    # the same bound test_gait holds IMU 1 to: the lever-arm terms (tenths of m/s² in swing) are right
    assert np.max(np.linalg.norm(pos - board.pos2_n_m, axis=1)) < 2e-3
    assert np.max(np.abs(vel - board.vel2_n_mps)) < 2e-4
    # without the ω̇ × m term the same integration is visibly off
    wrong = dataclasses.replace(imu2, acc_b_mps2=imu2.acc_b_mps2 - np.cross(board.angacc_b_radps2, m))
    assert np.max(np.abs(_strapdown(wrong)[1] - board.vel2_n_mps)) > 10 * 2e-4


def test_angular_acceleration_is_fourth_order() -> None:
    t = np.arange(2000) / 1000.0
    w = np.column_stack([np.sin(7 * t), np.cos(5 * t), t**3])
    exact = np.column_stack([7 * np.cos(7 * t), -5 * np.sin(5 * t), 3 * t**2])
    np.testing.assert_allclose(angular_acceleration(w, 1000.0)[2:-2], exact[2:-2], atol=1e-8)


def test_one_lap_of_each_course_with_independent_errors() -> None:
    for course, rise_m in (("rectangle", 0.0), ("stairs", paths.STAIR_N_STEPS * paths.STAIR_RISER_M)):
        rec = simulate_dual_imu(course, seed=4)
        t = rec.truth.imu1
        feet = paths.footholds(course, 1, 1.4 * paths.stride_period_s(1.4))
        assert t.n_strides == feet.lap_strides
        np.testing.assert_allclose(t.pos_n_m[-1], 0.0, atol=1e-9)  # back at the start, once round
        assert math.isclose(float(t.floor_z_m.max()), rise_m, abs_tol=1e-9)
        e1, e2 = rec.errors
        assert e1.grade.name == e2.grade.name == "icm20948"
        # independent draws: different turn-on biases, uncorrelated noise of the expected size
        assert not np.allclose(e1.gyr_turn_on_bias_b_radps, e2.gyr_turn_on_bias_b_radps)
        corr = np.corrcoef(e1.acc_noise_b_mps2[:, 0], e2.acc_noise_b_mps2[:, 0])[0, 1]
        assert abs(corr) < 0.02
        sigma = IMU_GRADES["icm20948"].acc_noise_sigma_mps2(1000.0)
        assert math.isclose(float(np.std(e2.acc_noise_b_mps2)), sigma, rel_tol=0.02)
        # equal rates in truth; the specific forces differ by the lever-arm terms only in swing
        np.testing.assert_array_equal(rec.truth.gyr_b_radps[:, 0], rec.truth.gyr_b_radps[:, 1])
        d = rec.truth.acc_b_mps2[:, 1] - rec.truth.acc_b_mps2[:, 0]
        assert np.max(np.abs(d[t.stance])) < 1e-3 and np.max(np.abs(d)) > 0.1


async def test_two_imu_raw_stream_through_the_device_layer_navigates() -> None:
    rec = simulate_dual_imu("rectangle", seed=5)
    n = len(rec.t_s)
    with PtyShoeServer(
        rec.t_s,
        rec.acc_b_mps2[:, 0],
        rec.gyr_b_radps[:, 0],
        speed=math.inf,
        imu_acc_b_mps2=rec.acc_b_mps2,
        imu_gyr_b_radps=rec.gyr_b_radps,
    ) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start(RawImuMode(imu_mask=raw_imu.DUAL_IMU_MASK))
            got = of(await gather(unit, RawImuBatch, n, timeout_s=60.0), RawImuBatch)
            await unit.stop()
    acc = np.concatenate([b.acc_b_mps2 for b in got])[:n]
    gyr = np.concatenate([b.gyr_b_radps for b in got])[:n]
    t = np.concatenate([b.t_s for b in got])[:n]
    assert got[0].imu_ids == (0, 1) and acc.shape == (n, 2, 3)
    np.testing.assert_allclose(acc, rec.acc_b_mps2, atol=raw_imu.ACC_SCALE_MPS2_PER_LSB)
    _, _, stance = StreamingDetector(DetectorParams(), 1000.0).update(acc[:, 0].copy(), gyr[:, 0].copy())
    track = run_dual_eskf(t - t[0], acc, gyr, stance, np.asarray(DEFAULT_LEVER_B_M), 1000.0)
    err = np.linalg.norm(track.pos1_n_m - rec.truth.imu1.pos_n_m, axis=1)
    assert err.max() < 0.15, err.max()
    assert track.messages == ()


@pytest.mark.parametrize("bad", [(0.01, 0.01), [0.01, 0.01, 0.0, 0.0]])
def test_lever_arm_must_be_three_numbers(bad: object) -> None:
    with pytest.raises(ValueError, match=r"size|reshape"):
        rigid_board(simulate_walk("line", 4.0), bad)  # type: ignore[arg-type]
