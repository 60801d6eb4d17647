"""The navigator's estimates against those it gave before its kernels were restructured for compile time
and its batch loop for speed (issue 27).

``tests/reference/navigate_before_issue27.npz`` holds the estimates of the code before that change
(commit eb03177), every 500th sample of an emulated 2-minute walk at 1 kHz and every 50th of x-io's
``short_walk.csv`` (causal, RTS- and step-smoothed), with the last sample of each and every stance
flag. The stance flags must be identical; the estimates agree to 1e-12: calls between the compiled
kernels, which were inlined before, move where LLVM fuses a multiply and an add (measured: at most
1.0e-13 m on every recording of ``../shared/data``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from footnav.app import navigate as navigate_recording
from footnav.app import read_recording
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavConfig, navigate

REFERENCE = np.load(Path(__file__).parent / "reference" / "navigate_before_issue27.npz")
FIELDS = ("pos_n_m", "vel_n_mps", "quat_nb_wxyz", "cov_pos_yaw")
STEPS = {"emulated": 500, "xio_causal": 50, "xio_rts": 50, "xio_step": 50}


def _assert_as_before(name: str, nav: NavBatch) -> None:
    n = int(REFERENCE[f"{name}/n"])
    assert len(nav) == n
    stance = np.unpackbits(REFERENCE[f"{name}/stance"], count=n).astype(bool)
    np.testing.assert_array_equal(nav.stance, stance)
    assert stance.any() and not stance.all()
    every = slice(None, None, STEPS[name])
    for field in FIELDS:
        now = getattr(nav, field)
        np.testing.assert_allclose(
            np.concatenate([now[every], now[-1:]]), REFERENCE[f"{name}/{field}"], rtol=0, atol=1e-12
        )


def test_one_batch_of_an_emulated_walk_navigates_as_before() -> None:
    truth = simulate_walk("rectangle", 120.0, 1000.0, seed=1)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, 1000.0, "mpu6500x4", seed=2)
    nav, stats = navigate(truth.t_s, acc, gyr, 1000.0, NavConfig())
    assert nav is not None and stats.zero_velocity_updates > 10_000
    assert float(np.abs(nav.pos_n_m).max()) > 5.0  # it walked: the comparison is not of a standing foot
    _assert_as_before("emulated", nav)


@pytest.mark.parametrize(("smooth", "name"), [(False, "xio_causal"), ("whole", "xio_rts"), ("step", "xio_step")])
def test_a_real_recording_navigates_as_before(shared_data: Path, smooth: bool | str, name: str) -> None:
    rec = read_recording(shared_data / "xio-gait-tracking" / "short_walk.csv")
    result = navigate_recording(rec, smooth=smooth)
    _assert_as_before(name, result.nav)
