"""The emulated ToF sensors (footnav.device.emulator.sensors.tof) and the floor they range (floors)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from footnav.device.emulator.motion import paths
from footnav.device.emulator.motion.floors import floor_of
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.tof import TofMount, TofSensorModel, ray_cast, tof_readings
from footnav.device.protocol import extensions


def test_stair_floor_is_the_gait_models_floor_under_the_imu() -> None:
    walk = simulate_walk("stairs", 60.0, seed=3)
    floor = floor_of("stairs").height_m(walk.pos_n_m[:, 0], walk.pos_n_m[:, 1])
    np.testing.assert_allclose(floor, walk.floor_z_m, atol=1e-9)
    assert walk.floor_z_m.max() == pytest.approx(paths.STAIR_N_STEPS * paths.STAIR_RISER_M)


def test_ray_cast_on_treads_and_risers() -> None:
    floor = floor_of("stairs")
    tread, riser = paths.STAIR_TREAD_M, paths.STAIR_RISER_M
    down = np.array([[0.0, 0.0, -1.0]])
    # straight down from 0.5 m above the ground, then above tread 1
    rng, cos = ray_cast(np.array([[0.0, 0.0, 0.5]]), down, floor, 2.0)
    assert rng[0] == pytest.approx(0.5) and cos[0] == pytest.approx(1.0)
    rng, _ = ray_cast(np.array([[tread, 0.0, 0.5]]), down, floor, 2.0)
    assert rng[0] == pytest.approx(0.5 - riser)
    # 45° forward from just before the first edge, low: hits the first riser
    d = np.array([[math.sqrt(0.5), 0.0, -math.sqrt(0.5)]])
    x0 = 0.5 * tread - 0.05
    rng, cos = ray_cast(np.array([[x0, 0.0, 0.10]]), d, floor, 2.0)
    assert rng[0] == pytest.approx(0.05 / math.sqrt(0.5)) and cos[0] == pytest.approx(math.sqrt(0.5))
    # same ray from higher up clears the edge and lands on tread 1
    rng, _ = ray_cast(np.array([[x0, 0.0, 0.30]]), d, floor, 2.0)
    assert rng[0] == pytest.approx((0.30 - riser) / math.sqrt(0.5))
    # pointing up, or beyond the range: no hit
    rng, _ = ray_cast(
        np.array([[0.0, 0.0, 0.1], [0.0, 0.0, 3.0]]), np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]), floor, 2.0
    )
    assert np.isnan(rng).all()


def test_readings_rate_stagger_noise_and_statuses() -> None:
    walk = simulate_walk("line", 30.0, seed=2)
    model = TofSensorModel(seed=4)
    s = tof_readings(walk.t_s, walk.pos_n_m, walk.quat_nb_wxyz, floor_of("line"), model)
    assert np.all(np.diff(s.t_s) > 0)
    for j in range(3):
        tj = s.t_s[s.sensor == j]
        assert np.allclose(np.diff(tj), model.period_s)  # 33 Hz each
    np.testing.assert_allclose(np.diff(s.t_s), model.period_s / 3, atol=1e-9)  # staggered: 100 Hz in all
    # at rest the mid sensor (3 cm up, looking down) reads 3 cm with 1 cm noise
    idx = np.searchsorted(walk.t_s, s.t_s)
    rest = walk.stance[np.minimum(idx, len(walk) - 1)] & (s.sensor == 1) & (s.status == 0)
    assert np.mean(s.range_m[rest]) == pytest.approx(0.03, abs=0.002)
    assert np.std(s.range_m[rest]) == pytest.approx(0.01, rel=0.15)
    # invalid readings have a status and no range; time-outs at about the configured rate
    bad = s.status != extensions.TOF_VALID
    assert np.isnan(s.range_m[bad]).all() and np.isfinite(s.range_m[~bad]).all()
    assert np.mean(s.status == extensions.TOF_TIMEOUT) == pytest.approx(model.timeout_rate, rel=0.5)


def test_tilt_and_range_limits_give_status_codes() -> None:
    n = 200
    t = np.arange(n) / 100.0
    pos = np.zeros((n, 3))
    pos[:, 2] = np.linspace(0.0, 2.5, n)  # rises beyond the 2 m range
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    tilted = TofMount((0.0, 0.0, 0.03), (math.sin(math.radians(50)), 0.0, -math.cos(math.radians(50))))
    down = TofMount((0.0, 0.0, 0.03), (0.0, 0.0, -1.0))
    s = tof_readings(t, pos, quat, floor_of("line"), TofSensorModel(mounts=(down, tilted), timeout_rate=0.0))
    assert set(s.status[s.sensor == 1].tolist()) <= {extensions.TOF_WEAK_SIGNAL, extensions.TOF_NO_TARGET}
    z_at = np.interp(s.t_s, t, pos[:, 2])
    far = (s.sensor == 0) & (z_at + 0.03 > 2.0 + 0.01)
    near = (s.sensor == 0) & (z_at + 0.03 < 2.0 - 0.05)
    assert far.any() and np.all(s.status[far] == extensions.TOF_NO_TARGET)
    assert np.all(s.status[near] == extensions.TOF_VALID)


def test_spurious_reflections_are_longer_and_seeded() -> None:
    walk = simulate_walk("line", 20.0, seed=2)
    clean = tof_readings(
        walk.t_s, walk.pos_n_m, walk.quat_nb_wxyz, floor_of("line"), TofSensorModel(seed=5, sigma_m=0.0)
    )
    shiny = tof_readings(
        walk.t_s,
        walk.pos_n_m,
        walk.quat_nb_wxyz,
        floor_of("line"),
        TofSensorModel(seed=5, sigma_m=0.0, spurious_rate=0.1),
    )
    again = tof_readings(
        walk.t_s,
        walk.pos_n_m,
        walk.quat_nb_wxyz,
        floor_of("line"),
        TofSensorModel(seed=5, sigma_m=0.0, spurious_rate=0.1),
    )
    np.testing.assert_array_equal(shiny.range_m, again.range_m)
    diff = shiny.range_m - clean.range_m
    ok = np.isfinite(diff)
    assert 0.05 < np.mean(diff[ok] > 0.049) < 0.15
    assert np.all(diff[ok] > -1e-12)
