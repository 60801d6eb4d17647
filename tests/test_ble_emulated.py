"""BLE through bleak's public API, on the bumble backend, against the emulated unit as a GATT peripheral.

No mocks: BleakScanner/BleakClient -> device/emulator/serving/ble_backend.py -> bumble host + virtual
controller -> LocalLink -> virtual controller + host -> GATT server of device/emulator/serving/ble_peripheral.py.
The link budget and connection interval are emulated time; the emulator runs faster than real time.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import sys
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from bleak import BleakClient, BleakScanner
from bumble.link import LocalLink
from footnav.device import discovery
from footnav.device.emulator.serving.ble_backend import BumbleAdapter, BumbleClient, BumbleScanner, bumble_backend
from footnav.device.emulator.serving.ble_peripheral import BleShoePeripheral, Profile, link_budget_bps
from footnav.device.errors import DeviceError
from footnav.device.links import ble as ble_link
from footnav.device.links.ble import BleBackend, BleLink
from footnav.device.links.reconnecting import LinkEvent, ReconnectingLink
from footnav.device.protocol import commands as protocol
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.samples import ImuBatch

HANG_GUARD = 6.0
"""The waits below only guard against a hang: each is this many times what an idle machine needs, so
that a machine busy with other work (a CPU-bound process on each core, ``.ci/under-load``) passes."""


def synth(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, acc, gyr) at 1 kHz."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0
    acc = np.column_stack([np.sin(t), np.cos(t), 9.81 + 0.1 * rng.standard_normal(n)])
    gyr = 0.5 * rng.standard_normal((n, 3))
    return t, acc, gyr


@dataclass
class Radio:
    link: LocalLink
    adapter: BumbleAdapter

    def backend(self, mtu: int) -> BleBackend:
        return bumble_backend(self.adapter, mtu=mtu)


@pytest.fixture
async def radio() -> AsyncIterator[Radio]:
    link = LocalLink()
    adapter = BumbleAdapter(link)
    yield Radio(link, adapter)
    await adapter.close()


@contextlib.asynccontextmanager
async def peripheral(radio: Radio, n: int, **kwargs: object) -> AsyncIterator[BleShoePeripheral]:
    t, acc, gyr = synth(n)
    p = BleShoePeripheral(radio.link, t, acc, gyr, **kwargs)  # type: ignore[arg-type]
    await p.start()
    try:
        yield p
    finally:
        await p.stop()


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


async def stream_through_bleak(radio: Radio, *, mtu: int, n: int, divider_log2: int, timeout_s: float) -> None:
    """Stream ``n`` base-rate samples at 1 kHz / 2**divider_log2 and check that all arrive intact."""
    _, acc, gyr = synth(n)
    expected = len(range(0, n, 1 << divider_log2))
    async with peripheral(radio, n, name="FOOT-L", speed=math.inf) as p:
        async with BleLink("FOOT-L", backend=radio.backend(mtu), scan_timeout_s=5 * HANG_GUARD) as link:
            assert link.mtu == mtu
            unit = OpenShoeUnit(link)
            await unit.start_imu_stream(rate_divider_log2=divider_log2)
            batch = await collect(unit, expected, timeout_s)
            stats = unit.stats
        notifications, biggest = p.stats.notifications, p.stats.max_notification
        assert p.stats.packets_dropped_overflow == 0
        assert p.stats.oversize_writes == 0
    assert len(batch) == expected
    np.testing.assert_array_equal(batch.counter, np.arange(1, expected + 1))
    np.testing.assert_array_equal(batch.acc_b_mps2, acc[:: 1 << divider_log2].astype(np.float32))
    np.testing.assert_array_equal(batch.gyr_b_radps, gyr[:: 1 << divider_log2].astype(np.float32))
    np.testing.assert_allclose(np.diff(batch.t_s), (1 << divider_log2) / 1000, atol=1e-6)
    assert (stats.lost_packets, stats.duplicates, stats.checksum_errors, stats.bytes_skipped) == (0, 0, 0, 0)
    assert biggest == mtu - 3  # notifications were filled to ATT_MTU - 3, never more
    assert notifications >= expected * 34 / (mtu - 3)


@pytest.mark.slow
async def test_60_s_at_1_khz_over_mtu_247_arrive_without_loss(radio: Radio) -> None:
    await stream_through_bleak(radio, mtu=247, n=60_000, divider_log2=0, timeout_s=60 * HANG_GUARD)


@pytest.mark.slow
async def test_60_s_at_250_hz_over_mtu_23_arrive_without_loss(radio: Radio) -> None:
    # 34-byte packets over 20-byte notifications: every packet spans two notifications.
    await stream_through_bleak(radio, mtu=23, n=60_000, divider_log2=2, timeout_s=60 * HANG_GUARD)


async def test_1_khz_does_not_fit_mtu_23_and_the_loss_is_counted(radio: Radio) -> None:
    # 6 notifications of 20 bytes per 7.5 ms = 16 kB/s < 34 kB/s of 1 kHz normal-IMU packets.
    assert link_budget_bps(23) == pytest.approx(16_000)
    assert link_budget_bps(23) < 1000 * 34 < link_budget_bps(247)
    assert link_budget_bps(23) > 250 * 34
    n = 3000
    async with peripheral(radio, n, name="FOOT-L", speed=math.inf) as p:
        async with BleLink("FOOT-L", backend=radio.backend(23)) as link:
            unit = OpenShoeUnit(link)
            await unit.start_imu_stream(rate_divider_log2=0)
            async with asyncio.timeout(20 * HANG_GUARD):
                await p.finished.wait()
            received = 0
            async with contextlib.aclosing(unit.imu_batches()) as stream:
                async for batch in stream:
                    received += len(batch)
                    if int(batch.counter[-1]) >= p.stats.packets_queued + p.stats.packets_dropped_overflow - 5:
                        break
            stats = unit.stats
        dropped = p.stats.packets_dropped_overflow
    assert 0.3 * n < dropped < 0.7 * n  # about half cannot be carried
    assert stats.lost_packets > 0.3 * n  # and the host sees it as package-number gaps
    assert stats.checksum_errors == 0  # whole packets are dropped, never cut


@pytest.mark.parametrize("profile", ["mimu", "nus", "hm10"])
async def test_profiles_scan_by_service_and_stream(radio: Radio, profile: Profile) -> None:
    async with peripheral(radio, 1600, name=f"U-{profile}", profile=profile, speed=math.inf) as p:
        found = await BleakScanner.discover(
            0.3,
            return_adv=True,
            service_uuids=[p.service_uuid],
            backend=BumbleScanner,
            bumble_adapter=radio.adapter,
        )
        ((_, ad),) = found.values()
        assert ad.local_name == f"U-{profile}"
        assert ad.service_uuids == [p.service_uuid]
        async with BleLink(None, backend=radio.backend(23)) as link:  # the first unit with a known service
            assert link.uart is not None
            assert link.uart.service == ble_link.KNOWN_SERVICES[p.service_uuid]
            assert not link.uart.write_with_response  # write without response preferred
            if profile == "hm10":
                assert link.uart.notify is link.uart.write  # one characteristic both ways
            unit = OpenShoeUnit(link)
            await unit.start_imu_stream(rate_divider_log2=2)  # 250 Hz fits MTU 23
            batch = await collect(unit, 400, timeout_s=10 * HANG_GUARD)
    np.testing.assert_array_equal(batch.counter, np.arange(1, 401))


async def test_writes_are_chunked_to_the_allowed_size(radio: Radio) -> None:
    pings = bytes.fromhex("03 00 03") * 20  # 60 bytes
    async with peripheral(radio, 10, name="FOOT-L") as p:
        async with BleLink("C0:11:22:33:44:01", backend=radio.backend(23)) as link:  # by address
            assert link.max_write_size == 20
            await link.write(pings)
            async with asyncio.timeout(5 * HANG_GUARD):
                got = b""
                while len(got) < 80:
                    got += await link.read()
        assert p.stats.oversize_writes == 0
        assert [c.cmd_id for c in p.commands] == [0x03] * 20  # commands cut across writes reassemble
    assert got == bytes.fromhex("A0 03 00 A3") * 20


async def test_raw_bleak_client_sees_packets_split_across_notifications(radio: Radio) -> None:
    async with peripheral(radio, 50, name="FOOT-L", speed=math.inf) as p:
        device = await BleakScanner.find_device_by_name("FOOT-L", backend=BumbleScanner, bumble_adapter=radio.adapter)
        assert device is not None
        sizes: list[int] = []
        done = asyncio.Event()
        async with BleakClient(device, backend=BumbleClient, bumble_adapter=radio.adapter, mtu=23) as client:
            assert client.mtu_size == 23

            def on_notify(_c: object, data: bytearray) -> None:
                sizes.append(len(data))
                if sum(sizes) >= 4 + 50 * 34:
                    done.set()

            await client.start_notify(ble_link.MIMU_NOTIFY, on_notify)
            await client.write_gatt_char(ble_link.MIMU_WRITE, bytes.fromhex("40 01 00 41"), response=False)
            async with asyncio.timeout(10 * HANG_GUARD):
                await done.wait()
        assert p.stats.mtus == [23]
    assert max(sizes) == 20
    assert sum(sizes) == 4 + 50 * 34  # ACK + 50 packets, cut into 20-byte notifications


async def test_unknown_device_is_a_device_error(radio: Radio) -> None:
    async with peripheral(radio, 10, name="FOOT-L"):
        with pytest.raises(DeviceError, match=r"no BLE device named 'NOPE' within 0\.3 s"):
            await BleLink("NOPE", backend=radio.backend(23), scan_timeout_s=0.3).open()


async def test_device_side_disconnect_reconnects_and_reports_the_gap(radio: Radio) -> None:
    n = 6000
    events: list[LinkEvent] = []
    async with peripheral(radio, n, name="FOOT-L", speed=4.0) as p:
        link = ReconnectingLink.ble("FOOT-L", backend=radio.backend(247), on_event=events.append)
        async with link:
            unit = OpenShoeUnit(link)
            await unit.start_imu_stream()
            batches: list[ImuBatch] = []
            received = 0
            async with asyncio.timeout(20 * HANG_GUARD), contextlib.aclosing(unit.imu_batches()) as stream:
                async for batch in stream:
                    batches.append(batch)
                    received += len(batch)
                    if received >= 1000 and p.stats.connections == 1:
                        await p.disconnect()  # the unit keeps streaming; the module drops bytes meanwhile
                    if int(batch.counter[-1]) >= n:
                        break
            stats, health = unit.stats, link.health
        lost_unconnected = p.stats.packets_dropped_disconnected
    batch = ImuBatch.concat(batches)
    assert p.stats.connections == 2
    assert health.reconnects == 1
    (gap,) = health.gaps
    assert gap.reconnect_attempts >= 1
    assert gap.duration_s is not None and 0 < gap.duration_s < 5
    assert gap.packets_missing is not None and gap.packets_missing >= lost_unconnected > 0
    assert gap.packets_missing == stats.lost_packets  # the unit's own count agrees
    assert gap.bytes_missing == gap.packets_missing * 34
    assert [e.kind for e in events] == ["disconnected", "reconnected", "resumed"]
    assert np.all(np.diff(batch.counter) >= 1)  # in order across the gap
    assert int(batch.counter[-1]) == n
    assert len(batch) == n - gap.packets_missing


async def test_unit_reset_on_disconnect_is_restarted_by_the_resume_sequence(radio: Radio) -> None:
    n = 3000
    async with (
        peripheral(radio, n, name="FOOT-L", speed=4.0) as p,
        ReconnectingLink.ble("FOOT-L", backend=radio.backend(247)) as link,
    ):
        unit = OpenShoeUnit(link)
        await unit.start_imu_stream(rate_divider_log2=1)
        received, after_reset = 0, 0
        async with asyncio.timeout(20 * HANG_GUARD), contextlib.aclosing(unit.imu_batches()) as stream:
            async for batch in stream:
                received += len(batch)
                if p.stats.connections == 2:
                    after_reset += len(batch)
                if received >= 200 and p.stats.connections == 1:
                    await p.disconnect(reset=True)  # a rebooted unit waits for the start command
                if after_reset >= 200:  # on however busy a machine: samples from after the reset
                    break
        gap = link.health.gaps[0]
        lost = unit.stats.lost_packets
        await stream.aclose()
        in_flight = p.stats.notified_bytes - unit.stats.bytes_received  # sent, never read (now: the stream is shut)
    assert [c.cmd_id for c in p.commands] == [0x40, 0x40]  # the learned start, replayed
    assert p.commands[1].payload == bytes([2])  # with its rate divider (500 Hz)
    # A stopped unit numbers nothing while stopped: only what was in the module's FIFO, or already notified
    # but lost with the link (a busy host reads behind the radio), is missing.
    assert gap.packets_missing == lost
    assert gap.packets_missing * 34 <= p.stats.fifo_bytes_cleared + max(in_flight, 0) + 34


@pytest.mark.skipif(sys.platform != "linux", reason="forces the no-D-Bus path of bleak's BlueZ backend")
async def test_no_bluetooth_stack_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DBUS_SYSTEM_BUS_ADDRESS", "unix:path=/nonexistent/footnav-test-bus")
    with pytest.raises(DeviceError) as info:
        await BleLink("MIMU22BL", scan_timeout_s=1).open()
    message = str(info.value)
    assert message.startswith("no Bluetooth stack available")
    assert "\n" not in message
    report = await discovery.scan(0.5, list_ports=list)
    assert report.ble_error is not None and report.ble_error.startswith("no Bluetooth stack available")
    assert report.lines()[-1].startswith("ble     no Bluetooth stack available")
    assert all("\n" not in line for line in report.lines())


async def test_scan_lists_ble_units_by_service(radio: Radio) -> None:
    async with (
        peripheral(radio, 10, name="FOOT-L", address="C0:11:22:33:44:01"),
        peripheral(radio, 10, name="FOOT-R", address="C0:11:22:33:44:02", profile="nus"),
    ):
        report = await discovery.scan(0.3, radio.backend(23), list_ports=list)
    assert report.ble_error is None
    assert sorted((b.name, b.profile) for b in report.ble) == [
        ("FOOT-L", "MIMU22BL/Oblu UART (CDD0)"),
        ("FOOT-R", "Nordic UART"),
    ]
    assert report.serial == ()


async def test_stepwise_dead_reckoning_over_ble_acks_resends_and_dedup_give_the_emulated_track(
    radio: Radio,
) -> None:
    """SWDR through bleak's public API: every packet ACKed (resends too), each package number applied
    once, the track equal to the emulator's step sums."""
    from footnav.device.emulator.motion.gait import simulate_walk
    from footnav.device.emulator.scripts import steps_from_truth, yaw_from_quat_wxyz
    from footnav.device.modes import StepwiseMode
    from footnav.device.protocol.stepwise import StepBatch

    walk = simulate_walk("rectangle", 25.0, seed=1)
    steps = steps_from_truth(walk.t_s, walk.pos_n_m, yaw_from_quat_wxyz(walk.quat_nb_wxyz), walk.stance)
    n = len(steps)
    # Resend at every connection event (7.5 ms emulated): the host's ACK takes longer than that to come
    # back over the emulated radio, so most packets arrive more than once.
    p = BleShoePeripheral(
        radio.link, walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps, name="FOOT-L", speed=math.inf,
        steps=steps, resend_interval_s=0.005,
    )  # fmt: skip
    await p.start()
    try:
        async with BleLink("FOOT-L", backend=radio.backend(23)) as link:
            unit = OpenShoeUnit(link)
            await unit.start(StepwiseMode())
            got: list[StepBatch] = []
            async with asyncio.timeout(30 * HANG_GUARD), contextlib.aclosing(unit.batches()) as stream:
                async for batch in stream:
                    if isinstance(batch, StepBatch):
                        got.append(batch)
                        if int(batch.counter[-1]) >= n:
                            break
            assert await unit.stop()
            stats, tracker = unit.stats, unit.steps
        fw = p.firmware
        assert fw.acked_numbers == list(range(1, n + 1))  # every packet ACKed with its exact number
        resends = fw.resends
    finally:
        await p.stop()
    counter = np.concatenate([b.counter for b in got])
    np.testing.assert_array_equal(counter, np.arange(1, n + 1))  # each package number applied once
    np.testing.assert_allclose(np.concatenate([b.pos_n_m for b in got]), steps.pos_n_m, atol=3e-3)
    np.testing.assert_allclose(np.concatenate([b.heading_rad for b in got]), steps.heading_rad, atol=1e-5)
    assert stats.duplicates == resends > n  # every resend arrived and was dropped as a repeat
    assert tracker.repeats_ignored == 0
    assert stats.acks_sent == stats.packets  # resends ACKed too
    assert stats.lost_packets == 0 and stats.checksum_errors == 0
    np.testing.assert_allclose(tracker.pos_n_m, steps.pos_n_m[-1], atol=3e-3)
    still = int(np.count_nonzero(np.linalg.norm(steps.dx_m, axis=1) < 0.05))
    assert (tracker.stationary, tracker.steps) == (still, n - still)


async def test_live_over_ble_at_250_hz_carries_on_through_a_disconnect(radio: Radio, tmp_path: Path) -> None:
    """``footnav live --ble FOOT-L`` in-process, with bumble's backend injected through the test-only
    ``LiveOptions.ble_backend``: 250 Hz by default over BLE, a drop reconnected and recorded."""
    from footnav.app.commands.live import LiveOptions, live_session
    from footnav.app.config import CLI, defaults
    from footnav.device.emulator.motion.gait import simulate_walk
    from footnav.device.files.capture import read_capture_info, summarize_capture
    from footnav.pipeline.nav_types import NavBatch

    walk = simulate_walk("rectangle", 16.0, seed=1)
    navigated: list[NavBatch] = []
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), CLI)
    opts = LiveOptions(
        ports={"foot": "ble:FOOT-L"},
        config=cfg,
        viewer=False,
        ble_backend=radio.backend(23),
        collect=lambda _foot: navigated.append,
    )

    def samples() -> int:
        return sum(len(b) for b in navigated)

    async def until(condition: Callable[[], bool], timeout_s: float) -> None:
        async with asyncio.timeout(timeout_s):
            while not condition():
                await asyncio.sleep(0.02)

    p = BleShoePeripheral(radio.link, walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps, name="FOOT-L", speed=4.0)
    await p.start()
    try:
        task = asyncio.create_task(live_session(opts))
        await until(lambda: samples() >= 500 or task.done(), 20 * HANG_GUARD)
        await p.disconnect()  # the unit keeps streaming; the module drops bytes until the host is back
        await until(lambda: (p.stats.connections == 2 and samples() >= 1500) or task.done(), 20 * HANG_GUARD)
        task.cancel()  # Ctrl-C
        with contextlib.suppress(asyncio.CancelledError):
            await task
    finally:
        await p.stop()
    # The start at rate divider 2 (250 Hz), then the same start again from the link on reconnect.
    start = (protocol.CMD_NORMAL_IMU, bytes([protocol.imu_mode_byte(2)]))
    assert [(c.cmd_id, c.payload) for c in p.commands if c.cmd_id == protocol.CMD_NORMAL_IMU] == [start] * 2
    assert p.stats.packets_dropped_overflow == 0  # 250 Hz fits MTU 23
    t = np.concatenate([b.t_s for b in navigated])
    assert np.median(np.diff(t)) == pytest.approx(0.004)  # navigated at 250 Hz
    (capture,) = tmp_path.glob("live-*.mcap")
    (unit,) = read_capture_info(capture).units
    assert (unit.transport, unit.port, unit.settings["rate_hz"]) == ("ble", "ble:FOOT-L", 250.0)
    events = summarize_capture(capture).events["foot"]
    assert [e["kind"] for e in events if e["event"] == "link"] == ["disconnected", "reconnected", "resumed"]
