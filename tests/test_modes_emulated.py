"""Every output mode over real pyserial on the emulated unit's pty: SWDR with ACKs and resends, lossless
resend when the ACK is withheld, the 2014 probe and fallback, raw multi-IMU, INS states, extension states,
MCU id, link budget, unknown packets. No mocks."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time

import numpy as np
import pytest
from footnav.device.emulator.firmware import ShoeFirmware
from footnav.device.emulator.motion.floors import floor_of
from footnav.device.emulator.motion.gait import GaitTruth, simulate_walk
from footnav.device.emulator.scripts import (
    InsTruth,
    baro_from_height,
    steps_from_truth,
    yaw_from_quat_wxyz,
)
from footnav.device.emulator.sensors.tof import tof_readings
from footnav.device.emulator.serving.pty import BT_UART_BUDGET_BPS, PtyShoeServer
from footnav.device.errors import DeviceError, ProtocolError
from footnav.device.links.serial import SerialLink
from footnav.device.modes import InsMode, NormalImuMode, RawImuMode, StepwiseMode
from footnav.device.protocol import commands as protocol
from footnav.device.protocol import extensions, raw_imu
from footnav.device.protocol.extensions import BaroBatch, TofBatch
from footnav.device.protocol.framer import DataPacket, DeviceAck, Framer
from footnav.device.protocol.ins_states import InsStateBatch
from footnav.device.protocol.raw_imu import RawImuBatch
from footnav.device.protocol.stepwise import StepBatch
from footnav.device.unit import Batch, OpenShoeUnit
from footnav.pipeline.samples import ImuBatch


@pytest.fixture(scope="module")
def walk() -> GaitTruth:
    return simulate_walk("rectangle", 25.0, seed=1)


def synth(n: int, k: int = 4, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0
    acc = rng.normal(0, 5, (n, 3))
    gyr = rng.normal(0, 2, (n, 3))
    return t, acc, gyr, rng.normal(0, 20, (n, k, 3)), rng.normal(0, 5, (n, k, 3))


async def gather(
    unit: OpenShoeUnit, kind: type, n: int, timeout_s: float = 10.0, also: type | None = None
) -> list[Batch]:
    """Batches until ``n`` records of ``kind`` (and ``n`` // 50 of ``also``) arrived; other kinds kept too."""
    out: list[Batch] = []
    got = got_also = 0
    async with asyncio.timeout(timeout_s), contextlib.aclosing(unit.batches()) as stream:
        async for batch in stream:
            out.append(batch)
            got += len(batch) if isinstance(batch, kind) else 0
            got_also += len(batch) if also is not None and isinstance(batch, also) else 0
            if got >= n and (also is None or got_also >= n // 50):
                break
    return out


def of(batches: list[Batch], kind: type) -> list:
    return [b for b in batches if isinstance(b, kind)]


async def test_swdr_acks_resends_and_dedup_reproduce_the_emulated_track(walk: GaitTruth) -> None:
    steps = steps_from_truth(walk.t_s, walk.pos_n_m, yaw_from_quat_wxyz(walk.quat_nb_wxyz), walk.stance)
    n = len(steps)
    # Resend every 1 ms: most packets arrive several times before the host's ACK gets back.
    with PtyShoeServer(
        walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps, speed=math.inf, steps=steps, resend_interval_s=0.0
    ) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start(StepwiseMode())
            got = of(await gather(unit, StepBatch, n), StepBatch)
            assert await unit.stop()
            stats = unit.stats
        fw = server.firmware
        assert fw.acked_numbers == list(range(1, n + 1))  # every packet ACKed with its exact number
        assert fw.resends > 0
    counter = np.concatenate([b.counter for b in got])
    np.testing.assert_array_equal(counter, np.arange(1, n + 1))  # each package number applied once
    pos = np.concatenate([b.pos_n_m for b in got])
    np.testing.assert_allclose(pos, steps.pos_n_m, atol=3e-3)  # float32 steps sum to the truth
    np.testing.assert_allclose(np.concatenate([b.heading_rad for b in got]), steps.heading_rad, atol=1e-5)
    assert stats.duplicates > 0 and stats.acks_sent == stats.packets
    assert stats.lost_packets == 0 and stats.firmware == "2015"
    still = int(np.count_nonzero(np.linalg.norm(steps.dx_m, axis=1) < 0.05))
    assert still == 4  # 3 s standing at the start, the rest at the end: zero steps, not steps
    assert (unit.steps.stationary, unit.steps.steps) == (still, n - still)
    assert [c.cmd_id for c in server.commands if c.cmd_id != 0x01] == [0x34, 0x32, 0x22]
    cov = got[-1].cov_4x4[-1]
    assert np.all(np.linalg.eigvalsh(cov) > 0) and cov[0, 0] > got[0].cov_4x4[0][0, 0]


async def test_lossless_resend_until_the_exact_number_is_acked(walk: GaitTruth) -> None:
    steps = steps_from_truth(walk.t_s, walk.pos_n_m, yaw_from_quat_wxyz(walk.quat_nb_wxyz), walk.stance)
    cmds = protocol.Commands2015()
    with PtyShoeServer(walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps, speed=math.inf, steps=steps) as server:
        async with SerialLink(server.port) as link:
            framer = Framer()
            arrivals: list[tuple[float, object]] = []

            async def read_for(seconds: float) -> None:
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(seconds):
                        while True:
                            data = await link.read()
                            arrivals.extend((time.monotonic(), f) for f in framer.feed(data))

            await link.write(cmds.stepwise_dead_reckoning().frame)
            await read_for(0.45)  # no ACK: the first packet comes again every ≈128 ms
            frames = [f for _, f in arrivals]
            assert frames[0] == DeviceAck(0x34)
            copies = [(t, f) for t, f in arrivals if isinstance(f, DataPacket)]
            assert len(copies) in (3, 4) and {f.number for _, f in copies} == {1}
            gaps = np.diff([t for t, _ in copies])
            assert np.all((gaps > 0.1) & (gaps < 0.2))
            await link.write(cmds.ack(2).frame)  # a wrong number is ignored
            await link.write(cmds.ack(1).frame)
            arrivals.clear()
            await read_for(0.05)
            numbers = [f.number for _, f in arrivals if isinstance(f, DataPacket)]
            assert numbers[0] == 2  # released by the exact ACK
    assert server.firmware.acked_numbers == [1]


async def test_probe_falls_back_to_2014_and_never_mixes_sets(walk: GaitTruth) -> None:
    steps = steps_from_truth(walk.t_s, walk.pos_n_m, yaw_from_quat_wxyz(walk.quat_nb_wxyz), walk.stance)
    with PtyShoeServer(
        walk.t_s,
        walk.acc_b_mps2,
        walk.gyr_b_radps,
        speed=math.inf,
        steps=steps,
        command_set=protocol.CommandSet.V2014,
    ) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            t0 = time.monotonic()
            await unit.start(StepwiseMode(), probe_timeout_s=0.3)
            assert time.monotonic() - t0 < 1.0
            assert unit.command_set is protocol.CommandSet.V2014
            got = of(await gather(unit, StepBatch, 5), StepBatch)
            with pytest.raises(ProtocolError, match="refusing to send"):
                await unit._send(protocol.Commands2015().outputs_off())
            assert await unit.stop()
            with pytest.raises(DeviceError, match=r"2014 .*firmware"):
                await unit.start(NormalImuMode())
        sent = [c.cmd_id for c in server.commands if c.cmd_id != 0x01]
    # 34 00 34 was dropped unparsed by the 2014 parser; then only old IDs: 14, 27 (processing off), 21.
    assert sent == [0x14, 0x27, 0x21]
    np.testing.assert_allclose(np.concatenate([b.pos_n_m for b in got])[:5], steps.pos_n_m[:5], atol=3e-3)


async def test_2015_unit_is_detected_by_its_start_ack() -> None:
    t, acc, gyr, _, _ = synth(2000)
    with PtyShoeServer(t, acc, gyr, speed=math.inf) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start(NormalImuMode(rate_divider_log2=1))
            assert unit.command_set is protocol.CommandSet.V2015
            assert await unit.request_mcu_id() == server.firmware._mcu_id
            await unit.stop()
    assert [c.cmd_id for c in server.commands] == [0x40, 0x04, 0x32, 0x22]


@pytest.mark.parametrize(("mask", "k"), [(0b1111, 4), (raw_imu.DUAL_IMU_MASK, 2), (0b0100, 3)])
async def test_raw_imu_any_subset(mask: int, k: int) -> None:
    n = 1500
    t, acc, gyr, imu_acc, imu_gyr = synth(n, k=k)
    with PtyShoeServer(t, acc, gyr, speed=math.inf, imu_acc_b_mps2=imu_acc, imu_gyr_b_radps=imu_gyr) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start(RawImuMode(imu_mask=mask, rate_divider_log2=0))
            got = of(await gather(unit, RawImuBatch, n), RawImuBatch)
            await unit.stop()
        assert [c.cmd_id for c in server.commands][:3] == [0x32, 0x30, 0x28]  # probe, READ_INERTIAL, start
    ids = list(raw_imu.mask_to_ids(mask))
    acc_rx = np.concatenate([b.acc_b_mps2 for b in got])[:n]
    gyr_rx = np.concatenate([b.gyr_b_radps for b in got])[:n]
    assert got[0].imu_ids == tuple(ids) and acc_rx.shape == (n, len(ids), 3)
    np.testing.assert_allclose(acc_rx, imu_acc[:, ids], atol=raw_imu.ACC_SCALE_MPS2_PER_LSB)
    np.testing.assert_allclose(gyr_rx, imu_gyr[:, ids], atol=raw_imu.GYR_SCALE_RADPS_PER_LSB)
    np.testing.assert_allclose(np.diff(np.concatenate([b.t_s for b in got])), 0.001, atol=1e-7)


async def test_ins_states_in_footnav_frame(walk: GaitTruth) -> None:
    n = 2000
    cov = np.tile(np.diag(np.arange(1.0, 10.0)) * 1e-4, (len(walk), 1, 1))
    truth = InsTruth(walk.pos_n_m, walk.vel_n_mps, walk.quat_nb_wxyz, cov)
    with PtyShoeServer(walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps, speed=math.inf, ins=truth) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start(InsMode(state_ids=(0x01, 0x20, 0x21, 0x22, 0x23), rate_divider_log2=2))
            got = of(await gather(unit, InsStateBatch, n // 4), InsStateBatch)
            await unit.stop()
        assert [c.cmd_id for c in server.commands][:2] == [0x33, 0x21]
    idx = np.arange(0, n, 4)
    pos = np.concatenate([b.pos_n_m for b in got])[: idx.size]
    quat = np.concatenate([b.quat_nb_wxyz for b in got])[: idx.size]
    np.testing.assert_allclose(pos, walk.pos_n_m[idx], atol=1e-5)
    np.testing.assert_allclose(quat, walk.quat_nb_wxyz[idx], atol=1e-6)
    np.testing.assert_allclose(got[0].cov_9x9[0], cov[0], rtol=1e-6)
    np.testing.assert_allclose(np.diff(np.concatenate([b.t_s for b in got])), 0.004, atol=1e-7)


async def test_extension_states_interleave_with_the_imu_stream(walk: GaitTruth) -> None:
    tof = tof_readings(walk.t_s, walk.pos_n_m, walk.quat_nb_wxyz, floor_of("line"))
    baro = baro_from_height(walk.t_s, walk.pos_n_m[:, 2])
    with PtyShoeServer(walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps, speed=math.inf, tof=tof, baro=baro) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start(NormalImuMode(rate_divider_log2=3))
            await unit.enable_extensions(tof=True, baro=True)
            got = await gather(unit, ImuBatch, 1500, also=BaroBatch)
            await unit.stop()
            stats = unit.stats
    imu = ImuBatch.concat(of(got, ImuBatch))
    tofs = of(got, TofBatch)
    baros = of(got, BaroBatch)
    assert tofs and baros
    t_tof = np.concatenate([b.t_s for b in tofs])
    sensor = np.concatenate([b.sensor for b in tofs])
    rng = np.concatenate([b.range_m for b in tofs])
    t0 = imu.t_s[0] - walk.t_s[0]  # one device clock for every packet kind
    j = np.searchsorted(tof.t_s, t_tof[0] - t0 - 1e-6)
    np.testing.assert_allclose(t_tof - t0, tof.t_s[j : j + t_tof.size], atol=1e-6)
    np.testing.assert_array_equal(sensor, tof.sensor[j : j + t_tof.size])
    np.testing.assert_allclose(rng, tof.range_m[j : j + t_tof.size], atol=6e-4)
    assert set(sensor.tolist()) == {0, 1, 2}
    p = np.concatenate([b.pressure_pa for b in baros])
    assert np.all(np.abs(p - 101325 * (1 - 2.25577e-5 * 100) ** 5.25588) < 50)
    assert stats.lost_packets == 0 and stats.unexpected_packets == 0  # one counter shared by all outputs


async def test_unknown_packets_are_counted_and_logged_once(caplog: pytest.LogCaptureFixture) -> None:
    t, acc, gyr, _, _ = synth(3000)
    tof = tof_readings(t, np.zeros((t.size, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1)), floor_of("line"))
    with PtyShoeServer(t, acc, gyr, speed=math.inf, tof=tof) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start(NormalImuMode())
            # Switch the ToF state on behind the unit's back: its packets are of no expected kind.
            await unit._send(protocol.Commands2015().output_state(extensions.STATE_TOF, 0x01))
            with caplog.at_level(logging.WARNING, logger="footnav.device.unit"):
                got = await gather(unit, ImuBatch, 3000)
            await unit.stop()
            stats = unit.stats
    assert not of(got, TofBatch)
    assert stats.unexpected_packets > 10
    assert len([r for r in caplog.records if "9-byte payload" in r.getMessage()]) == 1


async def test_link_budget_caps_the_byte_rate() -> None:
    t, acc, gyr, _, _ = synth(5000)
    with PtyShoeServer(t, acc, gyr, speed=math.inf, link_budget_bps=BT_UART_BUDGET_BPS) as server:
        async with await OpenShoeUnit.open_serial(server.port) as unit:
            await unit.start(NormalImuMode())
            t0 = time.monotonic()
            got = await gather(unit, ImuBatch, 200)
            elapsed = time.monotonic() - t0
            await unit.stop()
    rate = sum(len(b) for b in got) * 34 / elapsed
    assert 0.7 * BT_UART_BUDGET_BPS < rate < 1.15 * BT_UART_BUDGET_BPS


@pytest.mark.parametrize("again_after_events", range(1, 9))
def test_a_start_sent_again_while_streaming_outputs_each_sample_once(again_after_events: int) -> None:
    """The reconnect's resume sequence replays the start command while the unit streams: the firmware must
    go on where it is (an earlier emulator re-sent the sample at the command's instant when one fell on it)."""
    n, interval_s = 300, 0.0075  # 7.5 ms connection events: every other one ends on a 1 kHz sample
    t, acc, gyr, _, _ = synth(n)
    fw = ShoeFirmware(t, acc, gyr, speed=1.0)
    fw.receive(protocol.normal_imu_command(), 0.0)
    now = 0.0
    for event in range(1, 30):
        now += interval_s
        fw.produce(now)
        if event == again_after_events:
            fw.receive(protocol.normal_imu_command(), now)
    fw.produce(now + 1.0)
    frames = Framer().feed(b"".join(data for data, _ in fw.out))
    numbers = [f.number for f in frames if isinstance(f, DataPacket)]
    assert numbers == list(range(1, n + 1))


def test_an_output_started_beside_a_streaming_one_sends_its_own_first_sample() -> None:
    """Where another output has just sent the sample at the command's instant, a newly started output still
    sends its own sample of that instant (each output resumes after what it sent itself)."""
    n = 100
    t, acc, gyr, imu_acc, imu_gyr = synth(n)
    fw = ShoeFirmware(t, acc, gyr, speed=1.0, imu_acc_b_mps2=imu_acc, imu_gyr_b_radps=imu_gyr)
    fw.receive(protocol.normal_imu_command(), 0.0)
    fw.produce(0.0)  # the normal output's sample at t = 0 is sent
    fw.receive(protocol.commands_for(fw.command_set).raw_imu(0b1111).frame, 0.0)
    fw.produce(0.01)
    frames = Framer().feed(b"".join(data for data, _ in fw.out))
    packets = [f for f in frames if isinstance(f, DataPacket)]
    raw = [p for p in packets if len(p.payload) != len(packets[0].payload)]
    assert len(packets) - len(raw) == 11 and len(raw) == 11  # t = 0 .. 10 ms, each output
