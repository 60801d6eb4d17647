"""The unit over real pyserial (serial_asyncio_fast) on a pty served by the emulated shoe. No mocks."""

from __future__ import annotations

import array
import asyncio
import contextlib
import fcntl
import math
import os
import termios
import time
import tty
from collections.abc import Iterator

import numpy as np
import pytest
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.errors import DeviceError
from footnav.device.links.serial import SerialLink
from footnav.device.protocol.framer import DataPacket, Framer
from footnav.device.protocol.imu import TICK_HZ
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.samples import ImuBatch


def synth(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, acc, gyr) at 1 kHz; stand-in for the gait simulator."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0
    acc = np.column_stack([np.sin(t), np.cos(t), 9.81 + 0.1 * rng.standard_normal(n)])
    gyr = 0.5 * rng.standard_normal((n, 3))
    return t, acc, gyr


async def collect(unit: OpenShoeUnit, n: int, timeout_s: float) -> ImuBatch:
    batches: list[ImuBatch] = []
    total = 0
    async with asyncio.timeout(timeout_s), contextlib.aclosing(unit.imu_batches()) as stream:
        async for batch in stream:
            batches.append(batch)
            total += len(batch)
            if total >= n:
                break
    return ImuBatch.concat(batches)


@pytest.fixture
def bare_pty() -> Iterator[str]:
    """A pty nobody answers on (a silent or wrong device)."""
    master, slave = os.openpty()
    tty.setraw(slave, termios.TCSANOW)
    yield os.ttyname(slave)
    os.close(master)
    os.close(slave)


@pytest.mark.slow
async def test_60_s_at_1_khz_arrives_complete_and_in_order() -> None:
    n = 60_000
    t, acc, gyr = synth(n)
    rx = bytearray()
    with PtyShoeServer(t, acc, gyr, speed=math.inf) as server:
        async with await OpenShoeUnit.open_serial(
            server.port, capture=lambda d, _ns, data: rx.extend(data) if d == "rx" else None
        ) as unit:
            await unit.start_imu_stream(rate_divider_log2=0)
            batch = await collect(unit, n, timeout_s=30)
            assert await unit.stop()
            stats = unit.stats
        assert server.finished.is_set()
        assert server.packets_sent == n
        assert bytes(rx) == server.sent_bytes  # every byte sent was read, nothing else
    assert len(batch) == n
    np.testing.assert_array_equal(batch.counter, np.arange(1, n + 1))
    np.testing.assert_allclose(batch.t_s - batch.t_s[0], t, atol=1 / TICK_HZ)  # across the tick wrap at 20 s
    np.testing.assert_array_equal(batch.acc_b_mps2, acc.astype(np.float32))
    np.testing.assert_array_equal(batch.gyr_b_radps, gyr.astype(np.float32))
    assert np.all(np.diff(batch.host_ns) >= 0)
    assert (stats.packets, stats.samples, stats.acks) == (n, n, 3)  # 0x40, 0x32, 0x22
    assert (stats.lost_packets, stats.duplicates, stats.bytes_skipped, stats.checksum_errors) == (0, 0, 0, 0)


async def test_rate_divider_and_stop() -> None:
    t, acc, gyr = synth(4000)
    with PtyShoeServer(t, acc, gyr, speed=math.inf) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start_imu_stream(rate_divider_log2=2)  # 250 Hz
            batch = await collect(unit, 1000, timeout_s=10)
            assert await unit.stop()
    assert [c.cmd_id for c in server.commands] == [0x40, 0x32, 0x22]
    np.testing.assert_array_equal(batch.counter, np.arange(1, 1001))
    np.testing.assert_allclose(np.diff(batch.t_s), 0.004, atol=1e-9)
    np.testing.assert_array_equal(batch.acc_b_mps2, acc[::4].astype(np.float32))


async def test_split_glued_writes_and_garbage_lose_no_valid_packet() -> None:
    n = 5000
    t, acc, gyr = synth(n, seed=3)
    with PtyShoeServer(
        t, acc, gyr, speed=math.inf, split_writes_max=7, garbage_every=25, garbage_max_len=20, seed=5
    ) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start_imu_stream(rate_divider_log2=0)
            batch = await collect(unit, n, timeout_s=20)
            stats = unit.stats
    np.testing.assert_array_equal(batch.counter, np.arange(1, n + 1))
    np.testing.assert_array_equal(batch.gyr_b_radps, gyr.astype(np.float32))
    assert stats.lost_packets == 0
    assert stats.bytes_skipped > 0
    assert stats.checksum_errors > 0  # the fake headers were seen and rejected
    offline = Framer(accepted_lengths={28}).feed(server.sent_bytes)
    assert sum(isinstance(f, DataPacket) for f in offline) == n


async def _background_cpu_share(window_s: float = 0.5) -> float:
    """The CPU this process uses while it waits, per wall second: threads earlier tests left running."""
    wall0, cpu0 = time.monotonic(), time.process_time()
    await asyncio.sleep(window_s)
    return (time.process_time() - cpu0) / (time.monotonic() - wall0)


async def test_real_time_pacing_does_not_spin() -> None:
    t, acc, gyr = synth(600)
    idle_share = await _background_cpu_share()
    with PtyShoeServer(t, acc, gyr, speed=1.0) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start_imu_stream(rate_divider_log2=0)
            wall0, cpu0 = time.monotonic(), time.process_time()
            batch = await collect(unit, 600, timeout_s=10)
            wall, cpu = time.monotonic() - wall0, time.process_time() - cpu0
            await unit.stop()
    assert len(batch) == 600
    assert 0.5 < wall < 3.0  # 0.6 s of data at real time
    # the reader and the emulator's thread use about 0.45 and 0.2 of a core at 1 kHz; either of them spinning would
    # add a whole core (what the process used while idle, threads of earlier tests, is not theirs)
    assert cpu - idle_share * wall < 1.0 * wall, (cpu, wall, idle_share)
    assert len(np.unique(batch.host_ns)) > 50  # arrived in many small chunks, not at once


async def test_no_ack_is_a_device_error(bare_pty: str) -> None:
    async with await OpenShoeUnit.open_serial(bare_pty) as unit:
        t0 = time.monotonic()
        with pytest.raises(DeviceError, match=r"no answer from .* to the start command within 0\.3 s"):
            await unit.start_imu_stream(timeout_s=0.3)
        assert time.monotonic() - t0 < 2.0


async def test_the_port_is_polled_only_while_a_read_waits() -> None:
    """Between reads the unit's bytes wait in the kernel's tty queue, not in the event loop (one
    wake-up per read instead of one per packet: README "Speed"); the next read returns them all."""
    master, slave = os.openpty()
    tty.setraw(slave, termios.TCSANOW)
    try:
        async with SerialLink(os.ttyname(slave)) as link:
            os.write(master, b"a")
            assert await link.read() == b"a"
            for _ in range(5):
                os.write(master, b"bc")
                await asyncio.sleep(0.02)  # the event loop runs, the port is not read
            waiting = array.array("i", [0])
            fcntl.ioctl(slave, termios.FIONREAD, waiting)
            assert waiting[0] == 10
            assert await link.read() == b"bc" * 5
    finally:
        os.close(master)
        os.close(slave)


async def test_missing_port_is_a_device_error() -> None:
    with pytest.raises(DeviceError, match=r"no such port /dev/ttyNOPE0 — is the unit plugged in\?"):
        await OpenShoeUnit.open_serial("/dev/ttyNOPE0")


async def test_busy_port_is_a_device_error(bare_pty: str) -> None:
    async with SerialLink(bare_pty):
        with pytest.raises(DeviceError, match="is busy"):
            await SerialLink(bare_pty).open()


async def test_unplug_mid_stream_is_a_device_error() -> None:
    t, acc, gyr = synth(20_000)
    with PtyShoeServer(t, acc, gyr, speed=1.0) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start_imu_stream(rate_divider_log2=0)
            received = 0
            with pytest.raises(DeviceError, match="was disconnected"):
                async with asyncio.timeout(10), contextlib.aclosing(unit.imu_batches()) as stream:
                    async for batch in stream:
                        received += len(batch)
                        if received >= 100 and server.packets_sent < len(t):
                            await asyncio.to_thread(server.unplug)
            assert 100 <= received < len(t)


async def test_emulator_is_silent_until_started_and_answers_like_firmware() -> None:
    t, acc, gyr = synth(100)
    with PtyShoeServer(t, acc, gyr, speed=math.inf) as server:
        async with SerialLink(server.port) as link:
            with pytest.raises(TimeoutError):
                async with asyncio.timeout(0.2):
                    await link.read()  # no data before a start command (a real unit waits too)
            # Junk IDs are dropped byte by byte, a bad checksum drops the frame, a ping is ACKed.
            await link.write(bytes.fromhex("FF 60 03 00 04") + bytes.fromhex("03 00 03"))
            async with asyncio.timeout(5):
                assert await link.read() == bytes.fromhex("A0 03 00 A3")
    assert [c.cmd_id for c in server.commands] == [0x03]
    assert server.packets_sent == 0
