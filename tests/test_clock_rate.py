"""The sample rate from the unit's own clock: measured from the device ticks, robust to lost packets,
repeats and wraps, and used by a live session without configuration; the rate divider's 4-bit field."""

from __future__ import annotations

import asyncio
import contextlib
import math

import numpy as np
import pytest
from footnav.app.session import UnitAddress, run_device_session
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.protocol.imu import CLOCK_RATE_INTERVALS, TICK_HZ, TICK_WRAP, TickUnwrapper, clock_rate_hz
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavConfig, Navigator
from footnav.pipeline.navigation.profiles import get_profile
from footnav.pipeline.samples import ImuBatch


@pytest.mark.parametrize("rate_hz", [1000.0, 819.2, 250.0, 31.25, 7.8125])
def test_the_clock_gives_the_nominal_rate_despite_lost_packets_repeats_and_a_wrap(rate_hz: float) -> None:
    step = round(TICK_HZ / rate_hz)
    ticks = (TICK_WRAP - 5 * step + step * np.arange(40)) % TICK_WRAP  # wraps after 5 samples
    ticks = np.delete(ticks, [11, 12, 20])  # lost packets
    ticks = np.insert(ticks, 30, ticks[29])  # a repeated sample
    t_s = TickUnwrapper().update(ticks.astype(np.uint32))
    assert clock_rate_hz(t_s) == rate_hz  # exactly: whole ticks


def test_no_rate_before_enough_intervals() -> None:
    t_s = np.arange(CLOCK_RATE_INTERVALS) / 1000.0  # one interval short
    assert clock_rate_hz(t_s) is None
    assert clock_rate_hz(np.append(t_s, t_s[-1] + 0.001)) == 1000.0
    assert clock_rate_hz(np.zeros(50)) is None  # repeats only


def test_a_31_hz_stream_is_navigated_at_31_hz_without_configuration() -> None:
    """A unit with a 250 Hz base rate asked for every 8th sample (K = 3) streams at 31.25 Hz, where a
    1 kHz unit would have streamed at 125 Hz: the session takes the rate from the unit's clock, through
    the real serial path on the emulator's pseudo-terminal, and says so."""
    base_hz, k = 250.0, 3
    truth = simulate_walk("rectangle", 60.0, rate_hz=base_hz, seed=1)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, base_hz, IMU_GRADES["mpu6500x4"], seed=2)
    navigator = Navigator(NavConfig(profile=get_profile("mpu6500x4")), 1000.0 / 2**k)
    got: list[NavBatch] = []
    told: list[tuple[float, float]] = []

    async def session() -> float | None:
        with PtyShoeServer(truth.t_s, acc, gyr, speed=math.inf, record=False) as server:
            result = await run_device_session(
                UnitAddress("serial", server.port),
                navigator,
                [got.append],
                rate_divider_log2=k,
                expect_samples=truth.t_s.size // 2**k,
                source_done=server.finished.is_set,
                on_rate=lambda clock, asked: told.append((clock, asked)),
            )
        return result.clock_rate_hz

    assert asyncio.run(session()) == 31.25
    assert navigator.rate_hz == 31.25 and told == [(31.25, 125.0)]
    n = sum(len(b) for b in got)
    assert n == navigator.stats.samples_out > 0.9 * truth.t_s.size / 2**k
    last = got[-1]
    error_m = float(np.linalg.norm(last.pos_n_m[-1] - truth.pos_n_m[round(float(last.t_s[-1]) * base_hz)]))
    assert error_m < 0.05 * truth.distance_m  # 2.2 % measured: 31 Hz degrades (docs: results/accuracy)


@pytest.mark.parametrize("k", [0, 7, 14])
async def test_the_emulator_streams_at_every_divider(k: int) -> None:
    """d = K + 1 up to 15: one packet every 2**K samples of the base rate, stamped by the clock."""
    n = 40_000  # 40 s at 1 kHz: three packets at K = 14
    t = np.arange(n) / 1000.0
    acc = np.tile([0.0, 0.0, 9.81], (n, 1))
    gyr = np.zeros((n, 3))
    batches: list[ImuBatch] = []
    with PtyShoeServer(t, acc, gyr, speed=math.inf) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start_imu_stream(rate_divider_log2=k)
            expected = math.ceil(n / 2**k)
            async with asyncio.timeout(30), contextlib.aclosing(unit.imu_batches()) as stream:
                async for batch in stream:
                    batches.append(batch)
                    if sum(len(b) for b in batches) >= expected:
                        break
            await unit.stop()
    got = ImuBatch.concat(batches)
    assert len(got) == expected
    np.testing.assert_allclose(np.diff(got.t_s), 2**k / 1000.0, rtol=1e-9)  # whole 64 MHz ticks
    assert clock_rate_hz(got.t_s) == (None if k == 14 else 1000.0 / 2**k)  # K = 14: three packets


def test_a_retimed_navigator_is_one_built_for_that_rate() -> None:
    truth = simulate_walk("line", 20.0, rate_hz=250.0, seed=3)
    t, acc, gyr = truth.t_s[::4], truth.acc_b_mps2[::4], truth.gyr_b_radps[::4]
    n = t.size
    batch = ImuBatch(t, acc, gyr, np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64))
    config = NavConfig(profile=get_profile("mpu6500x4"))
    built = Navigator(config, 62.5).process(batch)
    retimed_navigator = Navigator(config, 1000.0)
    retimed_navigator.retime(62.5)
    retimed = retimed_navigator.process(batch)
    assert built is not None and retimed is not None
    np.testing.assert_array_equal(retimed.pos_n_m, built.pos_n_m)
    np.testing.assert_array_equal(retimed.stance, built.stance)
    with pytest.raises(RuntimeError, match="before the first sample"):
        retimed_navigator.retime(125.0)


def test_retiming_a_step_smoother_resizes_its_windows() -> None:
    from footnav.pipeline.smoothing.stepwise import StepSmoothingNavigator

    config = NavConfig(profile=get_profile("mpu6500x4"))
    retimed = StepSmoothingNavigator(config, 1000.0)
    retimed.retime(62.5)
    built = StepSmoothingNavigator(config, 62.5)
    assert (retimed.close_after, retimed.max_window) == (built.close_after, built.max_window)
    assert retimed.detector.window == built.detector.window and retimed.rate_hz == 62.5


def _imu(t_s: np.ndarray) -> ImuBatch:
    n = t_s.size
    acc = np.tile([0.0, 0.0, 9.81], (n, 1))
    return ImuBatch(t_s, acc, np.zeros((n, 3)), np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64))


async def _through_clock(items: list[object], navigator: Navigator) -> tuple[list[object], list[tuple[float, float]]]:
    from footnav.app.stream import SerialSessionResult, at_clock_rate

    async def source():  # type: ignore[no-untyped-def]
        for item in items:
            yield item

    told: list[tuple[float, float]] = []
    out = [x async for x in at_clock_rate(source(), navigator, SerialSessionResult(), lambda a, b: told.append((a, b)))]
    return out, told


def test_the_held_samples_and_readings_pass_in_order_and_a_tick_of_jitter_is_no_other_rate() -> None:
    from footnav.pipeline.aiding.tof_types import RangeBatch

    t = np.arange(40) / 1000.0
    t[5] += 1 / TICK_HZ  # one tick of jitter
    reading = RangeBatch(np.array([0.004]), np.array([0]), np.array([0.1]), np.array([0]))
    items: list[object] = [_imu(t[:3]), reading, _imu(t[3:20]), _imu(t[20:])]
    navigator = Navigator(NavConfig(profile=get_profile("mpu6500x4")), 1000.0)
    out, told = asyncio.run(_through_clock(items, navigator))
    assert out == items and told == [] and navigator.rate_hz == 1000.0


def test_a_stream_that_ends_before_the_clock_gives_a_rate_is_still_passed_on() -> None:
    items: list[object] = [_imu(np.arange(5) / 31.25)]
    navigator = Navigator(NavConfig(profile=get_profile("mpu6500x4")), 125.0)
    out, told = asyncio.run(_through_clock(items, navigator))
    assert out == items and told == [] and navigator.rate_hz == 125.0


def test_a_dual_imu_navigator_is_retimed_like_a_built_one() -> None:
    from footnav.pipeline.dual_imu.navigator import DualNavConfig, DualNavigator

    retimed = DualNavigator(DualNavConfig(), 1000.0)
    retimed.retime(250.0)
    built = DualNavigator(DualNavConfig(), 250.0)
    assert retimed.rate_hz == 250.0 and retimed.detector.window == built.detector.window
