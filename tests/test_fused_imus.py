"""``footnav live --mode raw``: a four-IMU unit's raw registers (0x28) averaged into one IMU, as the
unit's own array firmware averages them, navigated live through the serial path and captured; the
capture replays to the same estimates."""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import numpy as np
import pytest
from footnav.app.commands.live import LiveOptions, live_session
from footnav.app.commands.replay import ReplayOptions, run_replay
from footnav.app.config import defaults
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.files.capture import read_capture_info
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.nav_types import NavBatch, concat_batches


def test_four_raw_imus_averaged_live_and_replayed_alike(tmp_path: Path) -> None:
    walk = simulate_walk("rectangle", 30.0, rate_hz=1000.0, seed=2)
    signals = [corrupt(walk.acc_b_mps2, walk.gyr_b_radps, 1000.0, IMU_GRADES["mpu6500x4"], seed=i) for i in range(4)]
    acc = np.stack([s[0] for s in signals], axis=1)
    gyr = np.stack([s[1] for s in signals], axis=1)
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    live: list[NavBatch] = []
    n = walk.t_s.size

    async def session() -> None:
        with PtyShoeServer(walk.t_s, acc[:, 0], gyr[:, 0], speed=math.inf, imu_acc_b_mps2=acc,
                           imu_gyr_b_radps=gyr) as server:  # fmt: skip
            opts = LiveOptions(
                ports={"foot": server.port}, config=cfg, viewer=False, collect=lambda _foot: live.append,
                fused_imu_mask=0x0F,
            )  # fmt: skip
            task = asyncio.create_task(live_session(opts))
            async with asyncio.timeout(120):
                while sum(len(b) for b in live) < n - 1000 and not task.done():
                    await asyncio.sleep(0.2)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task

    asyncio.run(session())
    track = concat_batches(live)
    k = round(float(track.t_s[-1]) * 1000.0)
    assert np.linalg.norm(track.pos_n_m[-1] - walk.pos_n_m[k]) < 0.003 * walk.distance_m
    capture = next(tmp_path.glob("*.mcap"))
    settings = read_capture_info(capture).units[0].settings
    assert settings["mode"] == "raw_imu_fused" and settings["fused_imu_mask"] == 0x0F
    replayed: list[NavBatch] = []
    collect = replayed.append
    assert run_replay(ReplayOptions(path=capture, config=defaults(), viewer=False, collect=lambda _f: collect)) == 0
    again = concat_batches(replayed)
    m = min(len(again), len(track))
    assert m >= n - 1000
    np.testing.assert_array_equal(again.pos_n_m[:m], track.pos_n_m[:m])  # bit for bit


async def test_raw_mode_takes_the_raw_outputs_divider_limit(tmp_path: Path) -> None:
    cfg = defaults()
    cfg.set("unit.rate_divider", 7, "test")
    opts = LiveOptions(ports={"foot": str(tmp_path / "none")}, config=cfg, viewer=False, fused_imu_mask=0x0F)
    with pytest.raises(FootnavError, match=r"rate divider must be 0\.\.6 for the raw output 0x28, got 7"):
        await live_session(opts)
