"""ReconnectingLink over real pyserial on ptys: unplug/replug at a stable path, the idle watchdog, resume."""

from __future__ import annotations

import asyncio
import contextlib
import os
import termios
import time
import tty
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from footnav.device.emulator.serving.pty import DEFAULT_TICK0, PtyShoeServer
from footnav.device.errors import DeviceError
from footnav.device.links.reconnecting import LinkEvent, LinkGap, ReconnectingLink, backoff_s
from footnav.device.protocol import commands as protocol
from footnav.device.protocol.imu import encode_packets
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.samples import ImuBatch


def synth(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0
    acc = np.column_stack([np.sin(t), np.cos(t), 9.81 + 0.1 * rng.standard_normal(n)])
    gyr = 0.5 * rng.standard_normal((n, 3))
    return t, acc, gyr


def plug(path: Path, server: PtyShoeServer) -> None:
    """Point the stable port path at ``server``'s pty, atomically (like udev's /dev/serial/by-id links)."""
    tmp = path.with_name(path.name + ".new")
    os.symlink(server.port, tmp)
    os.replace(tmp, path)


def test_backoff_doubles_from_100_ms_to_a_2_s_cap() -> None:
    assert [backoff_s(k) for k in range(7)] == [0.1, 0.2, 0.4, 0.8, 1.6, 2.0, 2.0]
    assert backoff_s(10_000) == 2.0


def test_gap_counts_missing_packets_across_the_counter_wrap() -> None:
    gap = LinkGap("x", start_ns=0, detected_ns=0, end_ns=2_500_000_000, last_packet_before=65_530, packet_len=34)
    gap.first_packet_after = 4  # 65531..65535, 0..3 missing
    assert gap.packets_missing == 9
    assert gap.bytes_missing == 9 * 34
    assert gap.duration_s == 2.5
    gap.first_packet_after = 65_531
    assert gap.packets_missing == 0
    assert "9" not in str(gap) and "2.50 s" in str(gap)


async def test_serial_unplug_replug_continues_the_session_and_reports_the_gap(tmp_path: Path) -> None:
    n, lost_while_unplugged = 4000, 300
    t, acc, gyr = synth(n)
    port = tmp_path / "ttyFOOT0"
    events: list[LinkEvent] = []
    first = PtyShoeServer(t, acc, gyr, speed=2.0)
    first.start()
    plug(port, first)
    servers = [first]

    async def unplug_and_replug() -> None:
        await asyncio.to_thread(first.unplug)
        port.unlink()  # the device node is gone while unplugged
        await asyncio.sleep(0.5)
        # A battery-powered unit keeps numbering while its cable is out: it resumes further on.
        k = first.packets_sent + lost_while_unplugged
        second = PtyShoeServer(
            t[k:], acc[k:], gyr[k:], speed=2.0, first_packet_number=k + 1, tick0=DEFAULT_TICK0 + k * 64_000
        )
        second.start()
        servers.append(second)
        plug(port, second)

    link = ReconnectingLink.serial(str(port), on_event=events.append)
    fault: asyncio.Task[None] | None = None
    try:
        await link.open()
        unit = OpenShoeUnit(link)
        await unit.start_imu_stream()
        batches: list[ImuBatch] = []
        received = 0
        async with asyncio.timeout(20), contextlib.aclosing(unit.imu_batches()) as stream:
            async for batch in stream:
                batches.append(batch)
                received += len(batch)
                if fault is None and received >= 500:
                    fault = asyncio.create_task(unplug_and_replug())
                if int(batch.counter[-1]) >= n:
                    break
        stats, health = unit.stats, link.health
        assert fault is not None
        await fault
    finally:
        await link.close()
        for server in servers:
            server.stop()
    batch = ImuBatch.concat(batches)
    assert len(servers) == 2
    assert [c.cmd_id for c in servers[1].commands][:1] == [protocol.CMD_NORMAL_IMU]  # the resume sequence
    (gap,) = health.gaps
    assert health.reconnects == 1
    assert gap.reconnect_attempts >= 2  # the port was missing for a while: backoff retries
    assert gap.packets_missing is not None and gap.packets_missing >= lost_while_unplugged
    assert gap.packets_missing == stats.lost_packets
    assert gap.duration_s is not None and 0.5 < gap.duration_s < 5
    assert [e.kind for e in events] == ["disconnected", "reconnected", "resumed"]
    assert "was disconnected" in events[0].message
    assert int(batch.counter[-1]) == n and len(batch) == n - gap.packets_missing
    assert np.all(np.diff(batch.counter) >= 1)
    # Device time continues across the gap (one clock), so the gap is visible in time too.
    jump = int(np.argmax(np.diff(batch.counter)))
    assert batch.t_s[jump + 1] - batch.t_s[jump] == pytest.approx((gap.packets_missing + 1) / 1000, abs=1e-6)


@pytest.fixture
def fake_unit_pty() -> Iterator[tuple[int, str]]:
    """A pty whose master the test drives by hand, playing a unit that goes silent."""
    master, slave = os.openpty()
    tty.setraw(slave, termios.TCSANOW)
    os.set_blocking(master, False)
    yield master, os.ttyname(slave)
    os.close(master)
    os.close(slave)


async def read_command(master: int, timeout_s: float) -> bytes:
    async with asyncio.timeout(timeout_s):
        while True:
            with contextlib.suppress(BlockingIOError):
                return os.read(master, 64)
            await asyncio.sleep(0.01)


def packets(first: int, count: int) -> bytes:
    numbers = np.arange(first, first + count)
    ticks = numbers * 64_000
    return encode_packets(numbers, ticks, np.ones((count, 3)), np.zeros((count, 3)))


async def test_a_unit_that_stops_streaming_is_noticed_within_a_second_and_restarted(
    fake_unit_pty: tuple[int, str],
) -> None:
    master, path = fake_unit_pty
    events: list[LinkEvent] = []
    async with ReconnectingLink.serial(path, on_event=events.append) as link:
        unit = OpenShoeUnit(link)
        start = asyncio.create_task(unit.start_imu_stream(timeout_s=2))
        command = await read_command(master, 2)
        assert command == protocol.normal_imu_command(0)
        os.write(master, protocol.device_ack(protocol.CMD_NORMAL_IMU) + packets(1, 100))
        await start
        got: list[ImuBatch] = []
        async with contextlib.aclosing(unit.imu_batches()) as stream:
            async with asyncio.timeout(5):
                while sum(map(len, got)) < 100:
                    got.append(await anext(stream))
            silent_since = time.monotonic()
            # The unit goes silent; the watchdog notices and re-sends the start command.
            reader = asyncio.create_task(anext(stream))
            resent = await read_command(master, 3)
            noticed_after = time.monotonic() - silent_since
            assert resent == protocol.normal_imu_command(0)
            os.write(master, protocol.device_ack(protocol.CMD_NORMAL_IMU) + packets(151, 50))
            async with asyncio.timeout(5):
                got.append(await reader)
                while sum(map(len, got)) < 150:
                    got.append(await anext(stream))
        health = link.health
    assert 0.9 < noticed_after < 1.6
    assert [e.kind for e in events] == ["stalled", "resumed"]
    (gap,) = health.gaps
    assert health.stalls == 1 and health.reconnects == 0 and gap.reconnect_attempts == 0
    assert gap.packets_missing == 50  # 101..150 never came
    assert gap.duration_s is not None and gap.duration_s > 0.9
    batch = ImuBatch.concat(got)
    np.testing.assert_array_equal(batch.counter, np.r_[1:101, 151:201])


async def test_stop_is_learned_and_no_watchdog_runs_after_it(fake_unit_pty: tuple[int, str]) -> None:
    master, path = fake_unit_pty
    async with ReconnectingLink.serial(path, idle_timeout_s=0.2) as link:
        await link.write(protocol.normal_imu_command(2))
        assert link.resume_bytes == protocol.normal_imu_command(2)
        await link.write(protocol.processing_off_command() + protocol.outputs_off_command())
        assert link.resume_bytes == protocol.processing_off_command() + protocol.outputs_off_command()
        await read_command(master, 1)
        reader = asyncio.create_task(link.read())
        await asyncio.sleep(0.6)  # silent, but no stream is expected: no stall
        assert link.health.stalls == 0
        reader.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await reader


async def test_a_missing_port_fails_at_open_and_a_closed_link_reads_empty(tmp_path: Path) -> None:
    link = ReconnectingLink.serial(str(tmp_path / "ttyNOPE"))
    with pytest.raises(DeviceError, match="no such port"):
        await link.open()
    await link.close()
    assert await link.read() == b""


async def test_giving_up_makes_read_raise(tmp_path: Path) -> None:
    t, acc, gyr = synth(2000)
    port = tmp_path / "ttyFOOT0"
    server = PtyShoeServer(t, acc, gyr, speed=1.0)
    server.start()
    plug(port, server)
    async with ReconnectingLink.serial(str(port), give_up_after_s=0.3) as link:
        await link.write(protocol.normal_imu_command(0))
        assert await link.read()
        await asyncio.to_thread(server.unplug)
        port.unlink()
        with pytest.raises(DeviceError, match=r"gave up reconnecting to .*ttyFOOT0 after"):
            async with asyncio.timeout(5):
                while True:
                    await link.read()
        assert link.health.state == "failed"
