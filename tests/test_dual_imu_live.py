"""The dual-IMU board live: the streaming navigator is batch-invariant, and ``footnav demo --dual-imu``
runs the board's 0x28 stream through the real serial path and session into a recording."""

from __future__ import annotations

import itertools
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from footnav.device.emulator.sensors.dual_imu import DEFAULT_LEVER_B_M, simulate_dual_imu
from footnav.device.protocol.raw_imu import RawImuBatch
from footnav.pipeline.dual_imu.board_eskf import run_dual_eskf
from footnav.pipeline.dual_imu.navigator import DualNavConfig, DualNavigator
from footnav.pipeline.navigation.batches import zupt_ratio
from footnav.pipeline.stance.detectors import DetectorParams, StreamingDetector
from footnav.views.paths import TIMELINE, DualPaths, FootPaths
from rerun.chunk import RrdReader


def test_streaming_dual_navigator_equals_the_whole_record_filter_however_batched() -> None:
    rec = simulate_dual_imu("stairs", seed=9)
    n = len(rec.t_s)
    acc, gyr = rec.acc_b_mps2.copy(), rec.gyr_b_radps.copy()
    acc[30_000:30_400, 1] = np.nan  # IMU 2 drops out for 0.4 s
    gyr[30_000:30_400, 1] = np.nan
    stat, threshold, stance = StreamingDetector(DetectorParams(), 1000.0).update(acc[:, 0].copy(), gyr[:, 0].copy())
    lever = np.asarray(DEFAULT_LEVER_B_M)
    whole = run_dual_eskf(rec.t_s, acc, gyr, stance, lever, 1000.0, zupt_ratio=zupt_ratio(stat, threshold))
    nav, outs = _navigate_in_batches(DualNavConfig(stance_levels=False), rec.t_s, acc, gyr, cuts=300)
    pos = np.concatenate([o.pos_n_m for o in outs])
    assert pos.shape == (n, 3) and nav.stats.samples_out == n and nav.stats.aligned_at_s == 0.0
    np.testing.assert_array_equal(np.concatenate([o.stance for o in outs]), stance)
    np.testing.assert_array_equal(pos, whole.pos1_n_m)  # bit for bit
    assert nav.messages == whole.messages and "IMU 2 unusable" in nav.messages[0]


def _navigate_in_batches(
    config: DualNavConfig, t: np.ndarray, acc: np.ndarray, gyr: np.ndarray, cuts: int
) -> tuple[DualNavigator, list]:  # type: ignore[type-arg]
    n = t.size
    nav = DualNavigator(config, 1000.0)
    edges = np.unique(np.concatenate([[0, n], np.random.default_rng(0).integers(1, n, cuts)])) if cuts else [0, n]
    outs = []
    for a, b in itertools.pairwise(edges):
        batch = RawImuBatch((0, 1), t[a:b], acc[a:b], gyr[a:b], None, None, np.arange(a, b), np.zeros(b - a, np.int64))
        out = nav.process(batch)
        if out is not None:
            outs.append(out)
    return nav, outs


def test_dual_navigator_stance_levels_hold_the_height_however_batched() -> None:
    """With the gyroscopes' datasheet scale and cross-axis errors the board's height drifts; the stance
    height constraint holds it on the floor of the rectangle (stance height error 0.14 / 0.37 cm RMS
    with seeds 1 / 2, against 5.6 / 21.8 cm; on the stairs 0.39 / 2.0 cm against 2.8 / 11.6 cm), and
    batching changes nothing."""
    rec = simulate_dual_imu("rectangle", seed=1, axes="gyro-bias-calibrated")
    true_z = rec.truth.imu1.pos_n_m[:, 2]
    _, whole = _navigate_in_batches(DualNavConfig(), rec.t_s, rec.acc_b_mps2, rec.gyr_b_radps, cuts=0)
    _, batched = _navigate_in_batches(DualNavConfig(), rec.t_s, rec.acc_b_mps2, rec.gyr_b_radps, cuts=200)
    _, off = _navigate_in_batches(DualNavConfig(stance_levels=False), rec.t_s, rec.acc_b_mps2, rec.gyr_b_radps, cuts=0)
    np.testing.assert_array_equal(np.concatenate([o.pos_n_m for o in batched]), whole[0].pos_n_m)
    still = whole[0].stance
    rms = float(np.sqrt(np.mean((whole[0].pos_n_m[still, 2] - true_z[still]) ** 2)))
    rms_off = float(np.sqrt(np.mean((off[0].pos_n_m[still, 2] - true_z[still]) ** 2)))
    assert rms <= 0.01 and rms <= 0.1 * rms_off


def test_dual_navigator_refuses_one_imu_batches() -> None:
    nav = DualNavigator(DualNavConfig(), 1000.0)
    bad = RawImuBatch(
        (0,), np.zeros(3), np.zeros((3, 1, 3)), np.zeros((3, 1, 3)), None, None, np.arange(3), np.zeros(3, np.int64)
    )
    with pytest.raises(ValueError, match="two IMUs"):
        nav.process(bad)


def test_demo_dual_imu_end_to_end_reports_a_board_mounted_differently(tmp_path: Path) -> None:
    out = tmp_path / "dual-demo.rrd"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "demo", "--dual-imu", "--duration", "20", "--pace", "max",
         "--save", str(out), "--sessions", str(tmp_path), "--board-lever-arm", "0", "0.014", "0"],
        capture_output=True, text=True, timeout=300, env=env, check=False,
    )  # fmt: skip
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0, text
    assert "dual-IMU board (icm20948)" in text
    m = re.search(r"samples navigated: (\d+) of (\d+) \(lost packets: (\d+)\)", text)
    assert m and int(m[1]) == int(m[2]) == 20_000 and int(m[3]) == 0
    assert float(re.search(r"= ([\d.]+) % of distance", text)[1]) < 1.0  # type: ignore[index]
    assert "both IMUs usable at every sample" in text
    assert "disagrees with the data" in text and "mounted differently" in text
    store = RrdReader(out).stream().collect()

    def rows(entity: str) -> int:
        return int(store.reader(index=TIMELINE, contents=[f"/{entity}"]).to_arrow_table().num_rows)

    assert rows(FootPaths().track) == 20_000
    # the board's own views, live: both IMUs' tracks and the constraint residuals over time
    dual = DualPaths("foot")
    assert rows(dual.imu("imu1")) == rows(dual.imu("imu2")) >= 2_000
    assert rows(dual.residual("rate_diff_dps", "x")) >= 1_500  # one per 10 samples, both IMUs usable
    assert rows(dual.residual("force_diff_mps2", "z")) >= 2_000  # stance samples


async def test_live_dual_imu_over_the_serial_path_follows_the_walk(tmp_path: Path) -> None:
    """``footnav live --dual-imu --port PTY``: the board's 0x28 stream through the real serial code
    into the dual-IMU navigator; the capture holds the session."""
    import asyncio
    import math

    from footnav.app.commands.live import LiveOptions, live_session
    from footnav.app.config import defaults
    from footnav.device.emulator.serving.pty import PtyShoeServer
    from footnav.pipeline.nav_types import NavBatch

    rec = simulate_dual_imu("rectangle", seed=3)
    truth = rec.truth.imu1
    n = truth.t_s.size
    got: list[NavBatch] = []
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    with PtyShoeServer(
        truth.t_s, rec.acc_b_mps2[:, 0], rec.gyr_b_radps[:, 0], speed=math.inf,
        imu_acc_b_mps2=rec.acc_b_mps2, imu_gyr_b_radps=rec.gyr_b_radps,
    ) as server:  # fmt: skip
        opts = LiveOptions(
            ports={"foot": server.port}, config=cfg, viewer=False, collect=lambda _foot: got.append,
            dual_imu_lever_b_m=DEFAULT_LEVER_B_M,
        )  # fmt: skip
        task = asyncio.create_task(live_session(opts))
        async with asyncio.timeout(120):
            while sum(len(b) for b in got) < n - 1000 and not task.done():
                await asyncio.sleep(0.2)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
    navigated = sum(len(b) for b in got)
    assert navigated >= n - 1000
    end = got[-1]
    k = int(np.rint(end.t_s[-1] * truth.rate_hz))  # session time starts at the first sample
    error_m = float(np.linalg.norm(end.pos_n_m[-1] - truth.pos_n_m[k]))
    assert error_m < 0.01 * truth.distance_m, error_m
    assert list(tmp_path.glob("*.mcap"))


def test_dual_imu_capture_replays_exactly_as_live(tmp_path: Path) -> None:
    from footnav.app.commands.demo import DemoOptions, run_demo
    from footnav.app.commands.replay import ReplayOptions, run_replay
    from footnav.app.config import defaults
    from footnav.pipeline.nav_types import NavBatch, concat_batches

    live: list[NavBatch] = []
    replayed: list[NavBatch] = []
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    opts = DemoOptions(
        duration_s=15.0, viewer=False, realtime=float("inf"), dual_imu=True, grade="icm20948", config=cfg,
        collect=lambda _foot: live.append,
    )  # fmt: skip
    assert run_demo(opts) == 0
    (capture,) = tmp_path.glob("*.mcap")
    replay = ReplayOptions(path=capture, config=defaults(), viewer=False, collect=lambda _foot: replayed.append)
    assert run_replay(replay) == 0
    a, b = concat_batches(live), concat_batches(replayed)
    assert len(a) == len(b) > 10_000
    np.testing.assert_array_equal(a.pos_n_m, b.pos_n_m)  # the same navigator on the same bytes
    np.testing.assert_array_equal(a.t_s, b.t_s)
